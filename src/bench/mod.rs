//! `vmls bench`: sweep methods and settings over one scene, measure each configuration with a
//! persistent renderer, and place it on the speed–error plane next to rows measured elsewhere.
//!
//! Contract:
//! - A configuration is the scene plus one `--methods` entry and one value of every `--sweep`
//!   (their cartesian product, in the order given). Each gets a fresh [`Renderer`], so its first
//!   frame shows the whole cost of a new dataset on the device (upload, kernel compilation,
//!   tables, buffers); then `warmup` frames (and, where `warmup` > 0, more until the warm-up
//!   has lasted [`WARMUP_MIN_MS`]) are rendered and discarded and `repeat` frames are timed.
//!   Times are GPU timestamp queries (median, smallest, largest) and wall clock.
//! - Every configuration's error is measured against one reference image (see [`reference`]),
//!   rendered once per run and cached on disk under a key of everything that affects it.
//! - Results are [`results::Row`]s: `results.csv`, `results.json` (with the run's context:
//!   device, driver, vmls version and commit) and the plot `speed_error.svg`/`.png`.
//! - This module sits above `scene`; nothing below imports it.

pub mod ceiling;
pub mod metrics;
pub mod outputs;
pub mod peer;
pub mod plot;
pub mod reference;
pub mod results;

use crate::field::RenderError;
use crate::renderer::{GpuImage, Renderer};
use crate::scene::{Scene, SceneError};
use crate::vk::{Context, ShaderCompiler, ShaderSource};
use reference::{Reference, ReferenceMode, reference_image};
use results::Row;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The least wall time of a configuration's warm-up frames on a device that is not the CPU
/// (where `--warmup` asks for any). A discrete GPU lowers its clocks after about a second
/// without work and raises them again only under load: while the bench prepared the next
/// field an H200 fell from 1 980 to 345 MHz (nvidia-smi, reason "GPU idle"), and the few short
/// frames after it then ran 5× slower than the same frames back to back (BENCHMARKS.md, "The
/// H200 a fourth time"). After half a second of 1.2 ms frames the clocks were still at
/// 1 755 MHz; a second is asked for. lavapipe runs on the cores that prepare the field, which
/// are never idle meanwhile: it keeps `--warmup` as given.
pub const WARMUP_MIN_MS: f64 = 1000.0;
/// The most frames the warm-up adds to `--warmup` to reach [`WARMUP_MIN_MS`].
const WARMUP_MAX_EXTRA: u32 = 1000;

/// What a bench run can fail with.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error("{path}: {message}")]
    Io { path: String, message: String },
    #[error("{path}, line {line}: {message}")]
    Import {
        path: String,
        line: usize,
        message: String,
    },
    #[error("--sweep {arg}: {message}")]
    Sweep { arg: String, message: String },
    #[error("{what}: {source}")]
    Budget {
        what: String,
        #[source]
        source: Box<RenderError>,
    },
    #[error("{0}")]
    Usage(String),
}

impl From<crate::files::FileError> for BenchError {
    fn from(e: crate::files::FileError) -> Self {
        BenchError::Render(e.into())
    }
}

impl From<crate::vk::VkError> for BenchError {
    fn from(e: crate::vk::VkError) -> Self {
        BenchError::Render(e.into())
    }
}

impl From<crate::recon::ReconError> for BenchError {
    fn from(e: crate::recon::ReconError) -> Self {
        BenchError::Render(e.into())
    }
}

/// One swept key and its values, in the order given.
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep {
    pub key: String,
    pub values: Vec<String>,
}

impl Sweep {
    /// Parses `section.key=v1,v2,…`. Values are TOML as in `--set` (bare words are strings);
    /// commas inside brackets or quotes belong to the value (`camera.eye=[1,2,3],[3,2,1]`).
    pub fn parse(arg: &str) -> Result<Self, BenchError> {
        let err = |message: &str| BenchError::Sweep {
            arg: arg.to_string(),
            message: message.to_string(),
        };
        let (key, list) = arg
            .split_once('=')
            .ok_or_else(|| err("expected section.key=value1,value2,…"))?;
        let key = key.trim();
        if !key.contains('.') {
            return Err(err("expected section.key=value1,value2,…"));
        }
        let mut values = Vec::new();
        let (mut depth, mut quote, mut current) = (0i32, None::<char>, String::new());
        for c in list.chars() {
            match (c, quote) {
                ('"' | '\'', None) => quote = Some(c),
                (q, Some(open)) if q == open => quote = None,
                ('[' | '{', None) => depth += 1,
                (']' | '}', None) => depth -= 1,
                (',', None) if depth == 0 => {
                    values.push(std::mem::take(&mut current).trim().to_string());
                    continue;
                }
                _ => {}
            }
            current.push(c);
        }
        values.push(current.trim().to_string());
        if quote.is_some() || depth != 0 {
            return Err(err("unbalanced quotes or brackets"));
        }
        if values.iter().any(String::is_empty) {
            return Err(err("empty value in the list"));
        }
        Ok(Self {
            key: key.to_string(),
            values,
        })
    }
}

/// The override lists of every configuration: one method (if any are given) times one value
/// of each sweep, the first sweep varying slowest.
pub fn configurations(methods: &[String], sweeps: &[Sweep]) -> Vec<Vec<String>> {
    let mut configs: Vec<Vec<String>> = if methods.is_empty() {
        vec![Vec::new()]
    } else {
        methods
            .iter()
            .map(|m| vec![format!("render.method={}", toml::Value::String(m.clone()))])
            .collect()
    };
    for s in sweeps {
        configs = configs
            .into_iter()
            .flat_map(|c| {
                s.values.iter().map(move |v| {
                    let mut c = c.clone();
                    c.push(format!("{}={v}", s.key));
                    c
                })
            })
            .collect();
    }
    configs
}

/// Everything `vmls bench` was asked to do.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    pub scene: Option<PathBuf>,
    /// Overrides for every configuration and the reference.
    pub set: Vec<String>,
    pub methods: Vec<String>,
    pub sweeps: Vec<Sweep>,
    pub repeat: u32,
    pub warmup: u32,
    pub out: PathBuf,
    pub reference: ReferenceMode,
    /// Overrides for the reference only (e.g. `render.reference_step=0.01`).
    pub reference_set: Vec<String>,
    /// For generated volumes, render the reference from the analytic field
    /// (`reconstruction.method = "exact"`) rather than from the scene's own reconstruction.
    pub analytic_reference: bool,
    /// Reference cache directory (`None`: render the reference every run).
    pub cache: Option<PathBuf>,
    /// Print each configuration's shader variant (its macro definitions).
    pub print_variant: bool,
    /// Write each configuration's SPIR-V here.
    pub dump_spirv: Option<PathBuf>,
    /// Measure the device's ceilings first and report each row's share of them.
    pub ceilings: bool,
    /// Files whose rows are merged into the results (`--import`): inputs no output may be.
    pub imports: Vec<PathBuf>,
    /// Render frames (the reference's and each configuration's) that plan more MLS
    /// evaluations than [`crate::view::WORK_BUDGET`]; without it such a frame ends the run
    /// before its GPU work, naming the configuration.
    pub force: bool,
}

/// What a run reports while it works.
pub enum Event<'a> {
    /// The reference is ready.
    Reference(&'a Reference),
    /// The device's ceilings are measured.
    Ceilings(&'a crate::probe::Ceilings),
    /// Configuration `index` of `total` is starting.
    Start {
        index: usize,
        total: usize,
        settings: &'a str,
    },
    /// The shader variant of a configuration (with `print_variant`).
    Variant {
        name: &'a str,
        kernels: &'a [(&'static str, Vec<(String, String)>)],
    },
    /// A configuration is measured.
    Row(&'a Row),
}

/// The commit the binary's source tree is at (`git describe --always --dirty`), or `unknown`.
pub fn commit() -> String {
    std::process::Command::new("git")
        .args(["describe", "--always", "--dirty", "--abbrev=12"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "unknown".into())
}

fn io_err(path: &Path, e: impl std::fmt::Display) -> BenchError {
    BenchError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// The macro definitions that make a variant (the shared binding numbers left out).
pub fn variant_defines(defines: &[(String, String)]) -> Vec<(String, String)> {
    let shared = crate::gpu_types::binding_defines();
    defines
        .iter()
        .filter(|d| !shared.contains(d))
        .cloned()
        .collect()
}

/// Per-kernel GPU milliseconds of a frame.
fn kernel_ms(image: &GpuImage) -> Vec<(&'static str, f64)> {
    match &image.splat {
        None => vec![("raycast", image.gpu_ms)],
        Some(r) => crate::splat::frame::STAGES
            .iter()
            .copied()
            .zip(r.stage_ms)
            .collect(),
    }
}

/// A scene with its field-independent parts: configurations that agree on this share the
/// CPU preparation of their field.
fn field_key(scene: &Scene) -> String {
    format!(
        "{:?}{:?}{:?}{:?}",
        scene.volume, scene.reconstruction, scene.octree, scene.samples
    )
}

/// Runs the sweep: reference, then every configuration. Rows come back in configuration order.
pub fn run(
    ctx: &Context,
    opts: &BenchOptions,
    mut observe: impl FnMut(Event<'_>),
) -> Result<(Vec<Row>, Reference), BenchError> {
    if opts.repeat == 0 {
        return Err(BenchError::Usage(
            "--repeat must be at least 1 (timed frames per configuration)".into(),
        ));
    }
    // One reference serves every configuration: keys that change the picture itself cannot be
    // swept (run them as separate benches).
    if let Some(s) = opts.sweeps.iter().find(|s| {
        [
            "volume.",
            "camera.",
            "transfer.",
            "lighting.",
            "render.background",
        ]
        .iter()
        .any(|p| s.key.starts_with(p))
    }) {
        return Err(BenchError::Sweep {
            arg: format!("{}={}", s.key, s.values.join(",")),
            message: "every configuration is compared with one reference image, so keys of \
                      [volume], [camera], [transfer], [lighting] and render.background cannot \
                      be swept: run one bench per value (--set)"
                .into(),
        });
    }
    let commit = commit();
    let configs = configurations(&opts.methods, &opts.sweeps);
    // Validate every configuration before any GPU work, so a bad value fails fast.
    let mut scenes = Vec::with_capacity(configs.len());
    for c in &configs {
        let mut set = opts.set.clone();
        set.extend(c.iter().cloned());
        scenes.push(Scene::load(opts.scene.as_deref(), &set)?);
    }
    let budget = (!opts.force).then_some(crate::view::WORK_BUDGET);
    let mut ref_set = opts.set.clone();
    ref_set.push("render.method=\"reference\"".into());
    // [volume] cannot be swept, so every configuration has the base scene's volume.
    let generated = scenes
        .first()
        .is_some_and(|s| matches!(s.volume, crate::scene::VolumeSource::MarschnerLobb { .. }));
    if generated && opts.analytic_reference {
        ref_set.push("reconstruction.method=\"exact\"".into());
    }
    // The field itself, never the fast path's resampling of it (which a `--set
    // reconstruction.resample` for the measured configurations would otherwise select); and no
    // skipping, which needs the fast path.
    ref_set.push("reconstruction.resample=0".into());
    ref_set.push("render.skip=false".into());
    ref_set.extend(opts.reference_set.iter().cloned());
    let ref_scene = Scene::load(opts.scene.as_deref(), &ref_set)?;
    // Images of an earlier run in the same directory must not pass for this run's; only
    // those are removed (outputs::ImagesDir).
    let inputs = inputs(opts, &ref_scene);
    let input_refs = outputs::refs(&inputs);
    let mut images = outputs::ImagesDir::prepare(&opts.out, inputs.clone())?;
    if let Some(dir) = &opts.dump_spirv {
        std::fs::create_dir_all(dir).map_err(|e| io_err(dir, e))?;
    }
    let reference = reference_image(
        &ref_scene,
        opts.reference,
        ctx,
        &commit,
        opts.cache.as_deref(),
        budget,
    )?;
    observe(Event::Reference(&reference));
    let compiler = ShaderCompiler::new()?;
    let ceilings = if opts.ceilings {
        let c = crate::probe::ceilings(ctx, &compiler, 3)?;
        observe(Event::Ceilings(&c));
        Some(c)
    } else {
        None
    };
    let mut prepared: Option<(String, crate::field::Field, f64)> = None;
    // The cost model's k per prepared field: measured once, not per configuration.
    let mut neighbours: Option<(String, f64)> = None;
    let mut rows = Vec::with_capacity(configs.len());
    for (index, (config, scene)) in configs.iter().zip(&scenes).enumerate() {
        let settings = config.join(";");
        observe(Event::Start {
            index,
            total: configs.len(),
            settings: &settings,
        });
        let key = field_key(scene);
        if prepared.as_ref().map(|p| &p.0) != Some(&key) {
            let t = Instant::now();
            let field = scene.field_on(Some(ctx.info()), |_| {})?;
            prepared = Some((key, field, t.elapsed().as_secs_f64() * 1e3));
        }
        let Some((_, field, prepare_ms)) = prepared.as_ref() else {
            return Err(BenchError::Usage("no field prepared".into()));
        };
        let view = scene.view();
        let bytes0 = ctx.bytes_uploaded();
        let first_start = Instant::now();
        let mut renderer = Renderer::new(ctx, field.clone())?;
        renderer.set_work_budget(budget);
        let (mut image, first) = renderer.render(&view, |_| {}).map_err(|e| match e {
            RenderError::Budget { .. } => BenchError::Budget {
                what: format!("configuration {index} ({settings})"),
                source: Box::new(e),
            },
            e => e.into(),
        })?;
        let first_wall = first_start.elapsed().as_secs_f64() * 1e3;
        let bytes_first = ctx.bytes_uploaded() - bytes0;
        let warm_start = Instant::now();
        let warm_ms = if opts.warmup > 0 && ctx.info().device_type != "cpu" {
            WARMUP_MIN_MS
        } else {
            0.0
        };
        let mut warm = 0;
        while warm < opts.warmup
            || (warm < opts.warmup.saturating_add(WARMUP_MAX_EXTRA)
                && warm_start.elapsed().as_secs_f64() * 1e3 < warm_ms)
        {
            renderer.render(&view, |_| {})?;
            warm += 1;
        }
        let (mut gpu, mut wall, mut per_kernel) = (Vec::new(), Vec::new(), Vec::new());
        let mut bytes_next = 0;
        for _ in 0..opts.repeat {
            let before = ctx.bytes_uploaded();
            let (img, frame) = renderer.render(&view, |_| {})?;
            bytes_next = ctx.bytes_uploaded() - before;
            gpu.push(frame.gpu_ms);
            wall.push(frame.wall_ms);
            per_kernel.push(kernel_ms(&img));
            image = img;
        }
        if ctx.validation_errors() > 0 {
            return Err(BenchError::Usage(format!(
                "{} Vulkan validation error(s) while measuring '{settings}'; results discarded",
                ctx.validation_errors()
            )));
        }
        if opts.print_variant {
            observe(Event::Variant {
                name: &image.variant,
                kernels: &image.shaders,
            });
        }
        if let Some(dir) = &opts.dump_spirv {
            for (kernel, defines) in &image.shaders {
                let spirv = compiler.compile(ShaderSource::File(kernel), defines)?;
                let file = kernel.rsplit('/').next().unwrap_or(kernel);
                let stem = file.trim_end_matches(".comp");
                let path = dir.join(format!("{index:03}-{stem}.spv"));
                crate::files::write_output("--dump-spirv", &path, &input_refs, |out| {
                    out.write_all(bytemuck::cast_slice::<u32, u8>(&spirv))
                })?;
            }
        }
        let names: Vec<&str> = per_kernel
            .first()
            .map(|k| k.iter().map(|(n, _)| *n).collect())
            .unwrap_or_default();
        let kernel_ms = names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let times: Vec<f64> = per_kernel.iter().map(|k| k[i].1).collect();
                format!("{n}={:.3}", metrics::spread(&times).0)
            })
            .collect::<Vec<_>>()
            .join(";");
        let (gpu_med, gpu_min, gpu_max) = metrics::spread(&gpu);
        let raycast = image.splat.is_none();
        let evaluations: u64 = image.counts.iter().map(|&c| u64::from(c)).sum();
        let same_size =
            (scene.camera.width, scene.camera.height) == (reference.width, reference.height);
        let error = metrics::image_error(&image.pixels, &reference.pixels, scene.camera.width)
            .filter(|_| same_size);
        if image.pixels.iter().all(|p| p.iter().all(|v| v.is_finite())) {
            images.write(
                index,
                scene.camera.width,
                scene.camera.height,
                &image.pixels,
            )?;
        }
        let shares = match (&ceilings, &image.splat) {
            (Some(c), None) => {
                // k, the model's one measured input: mean weighted neighbours at random points.
                let k = match &neighbours {
                    Some((key, k)) if *key == field_key(scene) => *k,
                    _ => {
                        let points = crate::probe::random_points(field, 4096, 0.0, 7);
                        let k = crate::probe::mls_probe(ctx, &compiler, field, &points, 0)?
                            .mean_neighbours;
                        neighbours = Some((field_key(scene), k));
                        k
                    }
                };
                let cost = ceiling::evaluation_cost(field, k);
                let (f, l) = ceiling::shares(c, cost, evaluations, gpu_med);
                Some((f, l, cost.reads.name()))
            }
            (Some(c), Some(report)) => {
                let exact = image
                    .shaders
                    .iter()
                    .any(|(_, d)| d.contains(&("SPLAT_EXACT".into(), "1".into())));
                let (f, a) = ceiling::splat_shares(c, report, exact, ctx.info().subgroup_size);
                Some((f, a, "stream"))
            }
            _ => None,
        };
        let tolerance = first.tolerance.as_ref();
        let row = Row {
            fma_share: shares.map(|s| s.0),
            memory_share: shares.map(|s| s.1),
            bound_by: match shares {
                Some((f, g, _)) if f >= g => "fma".into(),
                Some((_, _, reads)) => reads.into(),
                None => String::new(),
            },
            source: "vmls".into(),
            method: scene.render.method.name().into(),
            settings,
            device: ctx.info().name.clone(),
            driver: ctx.info().driver.clone(),
            vmls_version: env!("CARGO_PKG_VERSION").into(),
            commit: commit.clone(),
            width: scene.camera.width,
            height: scene.camera.height,
            frames: opts.repeat,
            gpu_ms: Some(gpu_med),
            gpu_ms_min: Some(gpu_min),
            gpu_ms_max: Some(gpu_max),
            kernel_ms,
            wall_ms: metrics::spread(&wall).0,
            first_frame_wall_ms: first_wall,
            first_frame_gpu_ms: Some(first.gpu_ms),
            prepare_ms: *prepare_ms,
            evaluations: raycast.then_some(evaluations),
            evaluations_per_s: raycast.then(|| evaluations as f64 / (gpu_med * 1e-3)),
            bytes_uploaded_first: Some(bytes_first),
            bytes_uploaded_next: Some(bytes_next),
            rmse: error.map(|e| e.rmse),
            max_abs: error.map(|e| e.max_abs),
            max_x: error.map(|e| e.max_x),
            max_y: error.map(|e| e.max_y),
            psnr: error.map(|e| e.psnr),
            non_finite: error.map(|e| e.non_finite),
            p99: error.map(|e| e.p99),
            tolerance: tolerance.map(|t| t.tolerance),
            tolerance_estimate: tolerance.and_then(|t| t.chosen).map(|c| c.2),
            tolerance_met: tolerance.map(|t| t.met),
            error_estimate: image.error_estimate.as_ref().map(|e| {
                crate::renderer::tolerance::p99_of(e.iter().map(|&x| f64::from(x)).collect())
            }),
            reference: reference.description.clone(),
            variant: image.variant.clone(),
        };
        observe(Event::Row(&row));
        rows.push(row);
    }
    Ok((rows, reference))
}

/// The files a run reads, which none of its outputs may be: the scene, its data file and
/// the imported results.
pub fn inputs(opts: &BenchOptions, scene: &Scene) -> outputs::Inputs {
    let mut inputs: outputs::Inputs = opts
        .scene
        .iter()
        .map(|p| ("scene".to_string(), p.clone()))
        .collect();
    inputs.extend(
        scene
            .input_files()
            .into_iter()
            .map(|(r, p)| (r.to_string(), p.to_path_buf())),
    );
    inputs.extend(
        opts.imports
            .iter()
            .map(|p| ("--import".to_string(), p.clone())),
    );
    inputs
}

/// The run's context for `results.json`.
pub fn run_context(
    ctx: &Context,
    opts: &BenchOptions,
    reference: &Reference,
    ceilings: Option<&crate::probe::Ceilings>,
) -> serde_json::Value {
    serde_json::json!({
        "device": ctx.info().name,
        "device_type": ctx.info().device_type,
        "driver": ctx.info().driver,
        "vmls_version": env!("CARGO_PKG_VERSION"),
        "commit": commit(),
        "host_threads": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        "scene": opts.scene.as_ref().map(|p| p.display().to_string()),
        "set": opts.set,
        "methods": opts.methods,
        "sweeps": opts.sweeps.iter().map(|s| serde_json::json!({"key": s.key, "values": s.values})).collect::<Vec<_>>(),
        "repeat": opts.repeat,
        "warmup": opts.warmup,
        "ceilings": ceilings,
        "reference": {
            "description": reference.description,
            "cached": reference.cached,
            "path": reference.path.as_ref().map(|p| p.display().to_string()),
            "set": opts.reference_set,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sweeps_split_at_top_level_commas() {
        let s = Sweep::parse("camera.eye=[1,2,3], [3,2,1]").expect("parse");
        assert_eq!(s.key, "camera.eye");
        assert_eq!(s.values, vec!["[1,2,3]", "[3,2,1]"]);
        let s = Sweep::parse("reconstruction.basis=\"a,b\",linear").expect("parse");
        assert_eq!(s.values, vec!["\"a,b\"", "linear"]);
        assert!(Sweep::parse("render.step").is_err());
        assert!(Sweep::parse("step=1,2").is_err());
        assert!(Sweep::parse("render.step=1,,2").is_err());
        assert!(Sweep::parse("camera.eye=[1,2").is_err());
    }

    #[test]
    fn configurations_are_the_cartesian_product() {
        let sweeps = vec![
            Sweep::parse("render.step=1,0.5").expect("parse"),
            Sweep::parse("reconstruction.basis=linear,quadratic").expect("parse"),
        ];
        let c = configurations(&["fixed".into(), "adaptive".into()], &sweeps);
        assert_eq!(c.len(), 8);
        assert_eq!(
            c[1],
            vec![
                "render.method=\"fixed\"",
                "render.step=1",
                "reconstruction.basis=quadratic"
            ]
        );
        assert_eq!(configurations(&[], &[]), vec![Vec::<String>::new()]);
    }
}
