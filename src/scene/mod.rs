//! The scene file: the external contract of `vmls render`.
//!
//! A scene is TOML with the sections `[volume]`, `[reconstruction]`, `[octree]`, `[transfer]`,
//! `[lighting]`, `[camera]`, `[render]` and `[splat]` (in [`splat`]); every key is optional and has the default of the built-in scene
//! (Marschner–Lobb 41³). `--set section.key=value` overrides are applied to the parsed table
//! before validation, with the value read as TOML (falling back to a bare string).
//!
//! Every unknown section or key, wrong type and out-of-range value is a [`SceneError`] that
//! names the key (`camera.fov_y`) and what was expected. Relative paths resolve against the
//! scene file's directory.
//!
//! Where the issue text was ambiguous: `camera.height` is the image height in pixels, so the
//! orthographic view height is `camera.view_height` (world units).

mod field;
mod keys;
mod splat;

pub use field::load_volume;
use keys::{Section, apply_set, check_known, parse_isosurfaces};

use crate::recon::{Basis, GradientMode, OctreeSettings, ReconMethod, Weight, resample};
use crate::view::camera::{Camera, Projection};
use crate::view::shading::{Isosurface, Lighting};
use crate::view::transfer::TransferFunction;

// The configuration types live with the layers that use them; the scene re-exports them so
// that a scene file's vocabulary is in one place.
pub use crate::recon::{NeighbourMode, Reconstruction};
use crate::samples::SampleSettings;
pub use crate::view::{
    AdaptiveCriterion, ExactOpacity, GivenKeys, IntervalModel, Method, RenderSettings, SkipMode,
};
use std::path::{Path, PathBuf};
use toml::{Table, Value};

/// Errors of the scene layer.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    #[error("{path}: expected UTF-8 text, found invalid bytes at byte {offset}")]
    NotText { path: PathBuf, offset: usize },
    #[error("{path}: invalid TOML: {message}")]
    Toml { path: String, message: String },
    #[error("{origin}: key '{key}': expected {expected}, found {found}")]
    Key {
        origin: String,
        key: String,
        expected: String,
        found: String,
    },
    #[error("{origin}: unknown key '{key}' (known keys{context}: {known})")]
    UnknownKey {
        origin: String,
        key: String,
        context: String,
        known: String,
    },
    #[error("--set {arg}: {message}")]
    Set { arg: String, message: String },
}

/// Where the volume comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum VolumeSource {
    MarschnerLobb {
        resolution: usize,
    },
    File {
        path: PathBuf,
        array: Option<String>,
    },
}

/// Largest scene file we read: scenes are a few hundred bytes; a transfer function of
/// [`crate::view::transfer::MAX_POINTS`] points fits many times over.
pub const MAX_SCENE_BYTES: u64 = 4 << 20;

/// A validated scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    pub volume: VolumeSource,
    pub reconstruction: Reconstruction,
    pub octree: OctreeSettings,
    /// How supports of irregular data are derived (`reconstruction.support`, `knn`,
    /// `anisotropic`).
    pub samples: SampleSettings,
    pub transfer: TransferFunction,
    pub isosurfaces: Vec<Isosurface>,
    pub lighting: Lighting,
    pub camera: Camera,
    pub render: RenderSettings,
}

const KNOWN: &[(&str, &[&str])] = &[
    ("volume", &["generator", "resolution", "file", "scalars"]),
    (
        "reconstruction",
        &[
            "method",
            "sigma",
            "basis",
            "weight",
            "support",
            "gradient",
            "neighbours",
            "resample",
            "direct_cells",
            "knn",
            "anisotropic",
        ],
    ),
    (
        "octree",
        &["leaf_budget", "max_depth", "leaf_size", "records"],
    ),
    ("transfer", &["points", "isosurfaces"]),
    (
        "lighting",
        &["ambient", "diffuse", "specular", "shininess", "volume"],
    ),
    (
        "camera",
        &[
            "eye",
            "target",
            "up",
            "fov_y",
            "projection",
            "view_height",
            "width",
            "height",
        ],
    ),
    ("splat", splat::KEYS),
    (
        "render",
        &[
            "method",
            "step",
            "reference_step",
            "background",
            "min_transmittance",
            "l_min",
            "l_max",
            "adaptive",
            "interval",
            "epsilon",
            "early_termination",
            "skip",
            "exact_opacity",
            "table_resolution",
            "tolerance",
        ],
    ),
];

/// The built-in default scene (Marschner–Lobb 41³), as a scene file would spell it.
pub const DEFAULT_SCENE: &str = r#"
[volume]
generator = "marschner-lobb"
resolution = 41
[reconstruction]
method = "mls"
basis = "linear"
weight = "wendland"
# support: 2.4 (× spacing on grids; 1.5 × the 8th-neighbour distance for irregular data)
gradient = "local"
neighbours = "grid"
# The fast path wherever it serves and pays (ray casting, not the reference integrator; every
# scene's default): 2x finer, interpolated.
resample = "auto"
[transfer]
# A translucent blue shell below 0.5, a dense bright band at the 0.5 level set, orange above.
points = [[0.0, 0.0, 0.0, 0.0, 0.0], [0.35, 0.1, 0.2, 0.5, 0.3], [0.45, 0.2, 0.5, 1.0, 1.5],
          [0.5, 1.0, 0.95, 0.8, 60.0], [0.55, 1.0, 0.5, 0.1, 2.0], [1.0, 1.0, 0.3, 0.1, 3.0]]
[camera]
eye = [3.6, 2.4, 2.9]
target = [0.0, 0.0, 0.0]
up = [0.0, 0.0, 1.0]
fov_y = 32.0
width = 256
height = 256
[render]
method = "fixed"
step = 0.25
interval = "hermite"
background = [0.0, 0.0, 0.0]
"#;

/// The keys that a tolerance would choose which `table` sets.
fn given_keys(table: &Table) -> GivenKeys {
    let has = |section: &str, key: &str| {
        table
            .get(section)
            .and_then(Value::as_table)
            .is_some_and(|t| t.contains_key(key))
    };
    GivenKeys {
        step: has("render", "step"),
        reference_step: has("render", "reference_step"),
        epsilon: has("render", "epsilon"),
        adaptive: has("render", "adaptive"),
        l_min: has("render", "l_min"),
        l_max: has("render", "l_max"),
        early_termination: has("render", "early_termination"),
        min_transmittance: has("render", "min_transmittance"),
        table_resolution: has("render", "table_resolution"),
        slab: has("splat", "slab"),
    }
}

/// `render.interval` left out: Hermite intervals, which measured less error than linear ones
/// at the same evaluations on every scene (BENCHMARKS.md: Marschner–Lobb, issue 11; the
/// room-fire mesh, issue 27), wherever the field has slopes; linear for a constant fit with
/// the local gradient, whose slope is zero (the fast path's fine grid would have one, but
/// "auto" may decline it after this is parsed).
fn default_interval(r: &Reconstruction) -> IntervalModel {
    if r.method == ReconMethod::Mls
        && r.basis == Basis::Constant
        && r.gradient == GradientMode::Local
    {
        IntervalModel::Linear
    } else {
        IntervalModel::Hermite
    }
}

/// Largest colour component (background, transfer function, isosurfaces): far beyond any
/// HDR use, and far from f32's overflow when composited.
pub const MAX_COLOUR: f64 = crate::view::transfer::MAX_COLOUR;

/// Smallest step, adaptive interval bound or reference step, in sample spacings. Smaller
/// steps only cost time (the image converges long before); the work budget bounds the rest.
pub const MIN_STEP: f64 = 1e-3;

/// Largest image, in pixels (8192²): every pixel keeps 48 bytes of GPU and host buffers.
pub const MAX_PIXELS: u64 = 1 << 26;

impl Scene {
    /// The data files this scene reads, as (key, path), so that no output can overwrite one.
    pub fn input_files(&self) -> Vec<(&'static str, &Path)> {
        match &self.volume {
            VolumeSource::File { path, .. } => vec![("volume.file", path.as_path())],
            VolumeSource::MarschnerLobb { .. } => Vec::new(),
        }
    }

    /// Loads a scene file (or the built-in default with `None`) and applies `--set` overrides.
    pub fn load(path: Option<&Path>, overrides: &[String]) -> Result<Self, SceneError> {
        let (text, origin, base) = match path {
            Some(p) => (
                String::from_utf8(crate::files::read_input(p, MAX_SCENE_BYTES)?).map_err(|e| {
                    SceneError::NotText {
                        path: p.to_path_buf(),
                        offset: e.utf8_error().valid_up_to(),
                    }
                })?,
                p.display().to_string(),
                p.parent().map(Path::to_path_buf).unwrap_or_default(),
            ),
            None => (
                DEFAULT_SCENE.to_string(),
                "built-in default scene".to_string(),
                PathBuf::from("."),
            ),
        };
        let mut scene = Self::parse(&text, &origin, &base, overrides)?;
        if path.is_none() {
            // The built-in scene spells out some defaults (render.step): only the overrides
            // are the user's choices, which a tolerance must not override.
            let mut table = Table::new();
            for arg in overrides {
                apply_set(&mut table, arg)?;
            }
            scene.render.given = given_keys(&table);
        }
        Ok(scene)
    }

    /// Parses scene text; `origin` names it in errors, `base` resolves relative paths.
    pub fn parse(
        text: &str,
        origin: &str,
        base: &Path,
        overrides: &[String],
    ) -> Result<Self, SceneError> {
        let mut table: Table = text.parse().map_err(|e: toml::de::Error| {
            // toml's Display is a multi-line snippet; the CLI promises one line.
            let at = e.span().map(|span| {
                let before = text.get(..span.start).unwrap_or(text);
                let line = before.matches('\n').count() + 1;
                let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
                format!("line {line}, column {column}: ")
            });
            SceneError::Toml {
                path: origin.to_string(),
                message: format!("{}{}", at.unwrap_or_default(), e.message().trim()),
            }
        })?;
        check_known(&table, origin)?;
        for arg in overrides {
            apply_set(&mut table, arg)?;
        }
        check_known(&table, &format!("{origin} with --set overrides"))?;
        let section = |name: &'static str| Section {
            origin,
            name,
            table: table.get(name).and_then(Value::as_table),
        };

        let vol = section("volume");
        let volume = match (vol.string("generator")?, vol.string("file")?) {
            (Some(_), Some(_)) => {
                return Err(vol.err(
                    "file",
                    "either volume.generator or volume.file, not both",
                    &Value::String("both given".into()),
                ));
            }
            (_, Some(file)) => VolumeSource::File {
                path: base.join(file),
                array: vol.string("scalars")?.map(str::to_string),
            },
            (g, None) => {
                if let Some(scalars) = vol.get("scalars") {
                    return Err(vol.err(
                        "scalars",
                        "no value with a generated volume (volume.scalars picks an array of \
                         volume.file)",
                        scalars,
                    ));
                }
                if let Some(g) = g.filter(|g| *g != "marschner-lobb") {
                    return Err(vol.err(
                        "generator",
                        "\"marschner-lobb\"",
                        &Value::String(g.into()),
                    ));
                }
                VolumeSource::MarschnerLobb {
                    resolution: vol.int("resolution", 41, 2, 1024)? as usize,
                }
            }
        };

        let rec = section("reconstruction");
        // Left out, "auto" (issue 27 §2): the fast path wherever it serves and pays.
        let auto = match rec.get("resample") {
            None => true,
            Some(Value::String(a)) => a == "auto",
            Some(_) => false,
        };
        let mut reconstruction = Reconstruction {
            method: rec.choice(
                "method",
                ReconMethod::Mls,
                &[
                    ("mls", ReconMethod::Mls),
                    ("gaussian", ReconMethod::Gaussian),
                    ("exact", ReconMethod::Exact),
                ],
            )?,
            sigma: rec.float(
                "sigma",
                crate::recon::gaussian::DEFAULT_SIGMA,
                0.05,
                1.0 / 3.0,
            )?,
            basis: rec.choice(
                "basis",
                Basis::Linear,
                &[
                    ("constant", Basis::Constant),
                    ("linear", Basis::Linear),
                    ("quadratic", Basis::Quadratic),
                ],
            )?,
            weight: rec.choice(
                "weight",
                Weight::Wendland,
                &[
                    ("wendland", Weight::Wendland),
                    ("interpolating", Weight::Interpolating),
                ],
            )?,
            gradient: rec.choice(
                "gradient",
                GradientMode::Local,
                &[
                    ("local", GradientMode::Local),
                    ("analytic", GradientMode::Analytic),
                ],
            )?,
            support: rec.float("support", 2.4, 0.5, 16.0)?,
            neighbours: rec.choice(
                "neighbours",
                NeighbourMode::Grid,
                &[
                    ("grid", NeighbourMode::Grid),
                    ("octree", NeighbourMode::Octree),
                ],
            )?,
            resample: match rec.get("resample") {
                None => 0,
                _ if auto => 0,
                Some(Value::Integer(i)) if (0..=i64::from(resample::MAX_FACTOR)).contains(i) => {
                    *i as u32
                }
                Some(v) => {
                    let expected =
                        format!("an integer in [0, {}] or \"auto\"", resample::MAX_FACTOR);
                    return Err(rec.err("resample", &expected, v));
                }
            },
            resample_auto: auto,
            resample_direct: false,
            direct_cells: rec.on_off_auto("direct_cells")?,
        };

        if reconstruction.method == ReconMethod::Exact
            && let VolumeSource::File { path, .. } = &volume
        {
            return Err(SceneError::Key {
                origin: origin.into(),
                key: "reconstruction.method".into(),
                expected: "\"mls\" or \"gaussian\" for a data file (\"exact\", the analytic \
                           field, exists only for volume.generator)"
                    .into(),
                found: format!("\"exact\" with volume.file = {}", path.display()),
            });
        }
        let explicit_support = rec.get("support").is_some();
        let samples = SampleSettings {
            support: reconstruction.support,
            knn_support: if explicit_support {
                reconstruction.support
            } else {
                crate::samples::KNN_SUPPORT
            },
            knn: rec.int("knn", 8, 1, 64)? as usize,
            anisotropic: match rec.get("anisotropic") {
                None => None,
                Some(Value::Boolean(b)) => Some(*b),
                Some(v) => return Err(rec.err("anisotropic", "true or false", v)),
            },
        };

        let oct = section("octree");
        let defaults = OctreeSettings::default();
        let octree = OctreeSettings {
            leaf_budget: oct.int("leaf_budget", defaults.leaf_budget as i64, 1, 1 << 20)? as usize,
            max_depth: oct.int("max_depth", i64::from(defaults.max_depth), 0, 20)? as u32,
            leaf_size: oct.positive("leaf_size", defaults.leaf_size, 1e3)?,
            max_references: defaults.max_references,
            records: oct.choice(
                "records",
                None,
                &[
                    ("auto", None),
                    ("inline", Some(true)),
                    ("coded", Some(false)),
                ],
            )?,
            max_record_texels: defaults.max_record_texels,
        };

        let tf = section("transfer");
        let transfer = match tf.get("points") {
            None => {
                TransferFunction::new(vec![[0.0, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0, 8.0]])
            }
            Some(v) => {
                TransferFunction::from_toml(v).map_err(|expected| tf.err("points", &expected, v))?
            }
        };

        let isosurfaces = match tf.get("isosurfaces") {
            None => Vec::new(),
            Some(v) => {
                parse_isosurfaces(v).map_err(|expected| tf.err("isosurfaces", &expected, v))?
            }
        };
        let lit = section("lighting");
        let defaults = Lighting::default();
        let lighting = Lighting {
            ambient: lit.float("ambient", defaults.ambient, 0.0, 10.0)?,
            diffuse: lit.float("diffuse", defaults.diffuse, 0.0, 10.0)?,
            specular: lit.float("specular", defaults.specular, 0.0, 10.0)?,
            shininess: lit.float("shininess", defaults.shininess, 0.0, 1e4)?,
        };
        if let Some(v) = lit.get("volume").filter(|v| v.as_bool() != Some(false)) {
            return Err(lit.err(
                "volume",
                "false (shading of the volume's emission is not implemented yet)",
                v,
            ));
        }

        let cam = section("camera");
        let projection = cam.choice("projection", 0, &[("perspective", 0), ("orthographic", 1)])?;
        let projection = if projection == 0 {
            if cam.get("view_height").is_some() {
                return Err(cam.err(
                    "view_height",
                    "no view_height with a perspective projection (use fov_y)",
                    cam.get("view_height").unwrap_or(&Value::Boolean(true)),
                ));
            }
            Projection::Perspective {
                fov_y_degrees: cam.float("fov_y", 30.0, 1e-3, 179.0)?,
            }
        } else {
            Projection::Orthographic {
                view_height: cam.positive("view_height", 2.0, 1e12)?,
            }
        };
        let camera = Camera {
            eye: cam.vec3(
                "eye",
                [3.0, 2.0, 2.5],
                -crate::data::MAX_COORDINATE,
                crate::data::MAX_COORDINATE,
            )?,
            target: cam.vec3(
                "target",
                [0.0; 3],
                -crate::data::MAX_COORDINATE,
                crate::data::MAX_COORDINATE,
            )?,
            up: cam.vec3(
                "up",
                [0.0, 0.0, 1.0],
                -crate::data::MAX_COORDINATE,
                crate::data::MAX_COORDINATE,
            )?,
            projection,
            width: cam.int("width", 256, 1, 16384)? as u32,
            height: cam.int("height", 256, 1, 16384)? as u32,
        };
        let pixels = u64::from(camera.width) * u64::from(camera.height);
        if pixels > MAX_PIXELS {
            return Err(SceneError::Key {
                origin: origin.into(),
                key: "camera.width × camera.height".into(),
                expected: format!("at most {MAX_PIXELS} pixels (8192²)"),
                found: format!("{} × {} = {pixels}", camera.width, camera.height),
            });
        }
        if let Err(message) = camera.basis() {
            return Err(SceneError::Key {
                origin: origin.into(),
                key: "camera.eye / camera.target / camera.up".into(),
                expected: "eye ≠ target and up not parallel to the view direction".into(),
                found: message,
            });
        }

        let ren = section("render");
        let adaptive = ren.choice(
            "adaptive",
            AdaptiveCriterion::Mls2008,
            &[
                ("mls2008", AdaptiveCriterion::Mls2008),
                ("hermite", AdaptiveCriterion::Hermite),
            ],
        )?;
        let render = RenderSettings {
            method: ren.choice(
                "method",
                Method::Fixed,
                &[
                    ("fixed", Method::Fixed),
                    ("riemann", Method::Riemann),
                    ("reference", Method::Reference),
                    ("adaptive", Method::Adaptive),
                    ("splat", Method::Splat),
                    ("splat-post", Method::SplatPost),
                ],
            )?,
            step_spacings: ren.float("step", 0.25, MIN_STEP, 1e3)?,
            reference_step_spacings: ren.float("reference_step", 1.0 / 32.0, MIN_STEP, 1e3)?,
            background: ren.vec3("background", [0.0; 3], 0.0, MAX_COLOUR)?,
            min_transmittance: ren.float("min_transmittance", 1e-4, 0.0, 1.0)?,
            l_min_spacings: ren.float("l_min", 0.16, MIN_STEP, 1e3)?,
            l_max_spacings: ren.float("l_max", 2.6, MIN_STEP, 1e3)?,
            adaptive,
            interval: ren.choice(
                "interval",
                default_interval(&reconstruction),
                &[
                    ("linear", IntervalModel::Linear),
                    ("hermite", IntervalModel::Hermite),
                ],
            )?,
            epsilon: ren.float("epsilon", adaptive.default_epsilon(), 0.0, 1e3)?,
            early_termination: ren.float("early_termination", 0.99, 0.0, 1.0)?,
            skip: match ren.on_off_auto("skip")? {
                None => SkipMode::Auto,
                Some(true) => SkipMode::On,
                Some(false) => SkipMode::Off,
            },
            exact_opacity: match ren.on_off_auto("exact_opacity")? {
                None => ExactOpacity::Auto,
                Some(true) => ExactOpacity::On,
                Some(false) => ExactOpacity::Off,
            },
            table_resolution: ren.int(
                "table_resolution",
                crate::view::settings::DEFAULT_TABLE_RESOLUTION as i64,
                2,
                4096,
            )? as usize,
            splat: splat::parse(&section("splat"))?,
            tolerance: match ren.get("tolerance") {
                None => None,
                Some(_) => Some(ren.float("tolerance", 0.0, 1e-6, 0.5)?),
            },
            given: given_keys(&table),
        };
        if render.skip == SkipMode::On && render.method.splat_shading().is_some() {
            return Err(section("render").err(
                "skip",
                "false with a splatting method (empty-space skipping serves ray casting)",
                &Value::Boolean(true),
            ));
        }
        // "auto" chooses the direct solve wherever the fast path cannot serve, and for the
        // reference integrator, whose image is the ground truth of the scene's own field.
        if reconstruction.resample_auto
            && (reconstruction.support < 1.0
                || reconstruction.method == ReconMethod::Exact
                || render.method.splat_shading().is_some()
                || render.method == Method::Reference)
        {
            reconstruction.resample_auto = false;
        }
        if reconstruction.resample > 0 {
            let why = if reconstruction.support < 1.0 {
                Some(
                    "0 with reconstruction.support below 1 (the fast path needs the field defined everywhere in the box)",
                )
            } else if render.method.splat_shading().is_some() {
                Some("0 with a splatting method (the fast path serves ray casting)")
            } else {
                None
            };
            if let Some(expected) = why {
                return Err(rec.err(
                    "resample",
                    expected,
                    &Value::Integer(i64::from(reconstruction.resample)),
                ));
            }
        }
        // Skipping reads the fast path's block ranges: refused here, before any work (a bench
        // checks every configuration at its start), where the scene already rules it out; the
        // ray setup refuses it too where "auto" declines the fast path for the data.
        if render.skip == SkipMode::On {
            let why = if reconstruction.resample == 0 && !reconstruction.resample_auto {
                Some(
                    "false here: skipping needs the fast path, and reconstruction.resample is 0 \
                     (or \"auto\" resolves to 0 for this method or reconstruction)",
                )
            } else if render.method == Method::Adaptive
                && render.adaptive == AdaptiveCriterion::Mls2008
            {
                Some(
                    "false with render.adaptive = \"mls2008\" (the paper's criterion does not skip)",
                )
            } else {
                None
            };
            if let Some(expected) = why {
                return Err(section("render").err("skip", expected, &Value::Boolean(true)));
            }
        }
        if render.l_min_spacings > render.l_max_spacings {
            return Err(ren.err(
                "l_min",
                &format!("at most render.l_max = {}", render.l_max_spacings),
                &Value::Float(render.l_min_spacings),
            ));
        }
        Ok(Self {
            volume,
            reconstruction,
            octree,
            samples,
            transfer,
            isosurfaces,
            lighting,
            camera,
            render,
        })
    }
}
