//! Rendering: the reconstructed field as both renderers see it, the ray-casting integrator
//! (f64 CPU reference in [`raycast`], GPU driver in [`gpu`]) and image output.
//!
//! All positions handed to kernels are relative to the *frame origin*, the volume centre, which
//! is subtracted on the host in f64: f32 then keeps its precision for data far from the world
//! origin ([MLS] §3's shifted basis does the same inside each evaluation).

pub mod camera;
pub mod evalmap;
mod fast_path;
mod frame;
pub mod gpu;
pub mod output;
pub mod preintegration;
pub mod raycast;
pub mod renderer;
pub mod resample;
pub mod settings;
pub mod shading;
pub mod skip;
pub mod transfer;

use crate::data::{DataError, Volume};
use crate::recon::ReconMethod;
use crate::recon::gaussian::{KernelVolumes, gaussian_evaluate};
use crate::recon::mls::{MlsSettings, MlsValue, Neighbours, Visit, mls_evaluate};
use crate::recon::resample::ResampledGrid;
use crate::recon::support_index::SupportIndex;
use crate::recon::{GridNeighbours, Octree, OctreeSettings, ReconError};
use crate::recon::{NeighbourMode, Reconstruction};
use crate::samples::bvh::HullBvh;
use crate::samples::{Domain, Positions, Provenance, SampleSet, Supports};
use crate::vk::VkError;
use camera::{Camera, Projection, ViewBasis};
use glam::DVec3;
use preintegration::PreintegrationTables;
pub use settings::{AdaptiveCriterion, IntervalModel, Method, RenderSettings, SkipMode};
use transfer::TransferFunction;

/// Errors of the render layer (and everything below it).
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(transparent)]
    Vk(#[from] VkError),
    #[error(transparent)]
    Recon(#[from] ReconError),
    #[error(transparent)]
    Data(#[from] DataError),
    #[error("camera: expected a valid view frame, found {0}")]
    Camera(String),
    #[error(transparent)]
    Samples(#[from] crate::samples::SampleError),
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    #[error("{key}: {message}")]
    Setting { key: &'static str, message: String },
    #[error("{path}: {message}")]
    Output { path: String, message: String },
    #[error(
        "the render plans up to {planned:.3e} {unit}, more than the work budget of \
         {budget:.1e} ({hint}); pass --force to render anyway"
    )]
    Budget {
        planned: f64,
        /// What is counted: MLS evaluations (ray casting) or footprint-pixel evaluations
        /// (splatting), which cost about the same on lavapipe.
        unit: &'static str,
        budget: f64,
        hint: String,
    },
    #[error("interrupted: the render stopped and wrote nothing")]
    Interrupted,
    #[error(
        "the render produced {count} non-finite pixel values (first at pixel {first}); no image written"
    )]
    NonFinite { count: usize, first: usize },
}

/// The scalar field of a scene: its sample set in frame-relative coordinates, its MLS settings,
/// and the redundant octree over its samples (irregular data always; regular grids with
/// `neighbours = "octree"`).
#[derive(Debug, Clone)]
pub struct Field {
    /// World position subtracted from everything (the centre of the domain's box).
    pub frame_origin: DVec3,
    pub samples: SampleSet,
    pub reconstruction: Reconstruction,
    /// The octree over the samples, where kernels read one (`octree_wanted`): built with the
    /// field, or, for a field made by [`Field::from_samples_deferred`] (splatting, which reads
    /// no octree), at the first [`Field::octree`].
    octree: std::sync::OnceLock<Result<Option<Octree>, ReconError>>,
    octree_settings: OctreeSettings,
    octree_wanted: bool,
    /// Ray-clipping hierarchy over the boundary, for a hull domain.
    pub hull: Option<HullBvh>,
    /// Smallest and largest sample value.
    range: (f64, f64),
    /// Whether any support is a rotated ellipsoid.
    full_metric: bool,
    /// Gaussian kernel volumes, computed at first use (Gaussian field, splatting).
    volumes: std::sync::OnceLock<KernelVolumes>,
    /// Box of every sample's support (frame-relative): where kernels can reach.
    support_box: (DVec3, DVec3),
    /// [`SampleSet::thinnest_support`], computed at first use (post-shaded splatting's
    /// sheet-share rule).
    thinnest: std::sync::OnceLock<f64>,
    /// [`SampleSet::radius_quantiles`] at 64ths, computed at first use (post-shaded
    /// splatting's ring size).
    radii: std::sync::OnceLock<Vec<f64>>,
    /// The fast path's fine grid, built at first CPU use (`reconstruction.resample`; the GPU
    /// builds its own).
    resampled: std::sync::OnceLock<ResampledGrid>,
    /// Block ranges of the CPU fine grid, for empty-space skipping.
    blocks: std::sync::OnceLock<skip::Blocks>,
    /// Why `reconstruction.resample = "auto"` chose the general path, where it did.
    fast_path_declined: Option<String>,
}

impl Field {
    /// A regular grid with one support h = support × spacing (see [`Field::from_samples`]).
    pub fn new(
        volume: Volume,
        reconstruction: Reconstruction,
        octree: &OctreeSettings,
        progress: impl FnMut(f64),
    ) -> Result<Self, ReconError> {
        let (lo, hi) = volume.bounds();
        let samples = SampleSet {
            positions: Positions::Grid {
                dims: volume.dims,
                origin: volume.origin,
                spacing: volume.spacing,
            },
            values: volume.values,
            supports: Supports::Uniform(volume.spacing.map(|s| s * reconstruction.support)),
            domain: Domain::Box { lo, hi },
            spacing: volume.spacing.iter().copied().fold(f64::INFINITY, f64::min),
            provenance: Provenance {
                kind: "regular grid",
                array: "scalars".into(),
                location: crate::data::dataset::Location::Point,
                merged: 0,
                inverted_cells: 0,
                support_kind: "uniform",
            },
        };
        Self::from_samples(samples, reconstruction, octree, progress)
    }

    /// Moves the samples into a frame centred on their domain and builds the octree unless the
    /// implicit grid neighbours serve (a regular grid with `neighbours = "grid"`).
    pub fn from_samples(
        samples: SampleSet,
        reconstruction: Reconstruction,
        octree: &OctreeSettings,
        progress: impl FnMut(f64),
    ) -> Result<Self, ReconError> {
        let field = Self::from_samples_deferred(samples, reconstruction, octree)?;
        if field.octree_wanted {
            let built = Octree::from_samples(&field.samples, octree, progress)?;
            // The lock is new and empty: this sets it.
            let _ = field.octree.set(Ok(Some(built)));
        }
        Ok(field)
    }

    /// [`Field::from_samples`] without building the octree: the first [`Field::octree`] builds
    /// it. For splatting, which reads the samples' kernels and no octree: a cloud of 10⁷
    /// points splats although its octree would not fit.
    pub fn from_samples_deferred(
        mut samples: SampleSet,
        reconstruction: Reconstruction,
        octree: &OctreeSettings,
    ) -> Result<Self, ReconError> {
        let (lo, hi) = samples.domain_box();
        let centre = (DVec3::from(lo) + DVec3::from(hi)) * 0.5;
        samples.translate(centre.to_array());
        let grid = matches!(samples.positions, Positions::Grid { .. })
            && matches!(samples.supports, Supports::Uniform(_));
        // Derived once here: every frame's table key and shader variant read them.
        let range = samples
            .values
            .iter()
            .fold((f64::MAX, f64::MIN), |(l, h), v| {
                (l.min(f64::from(v)), h.max(f64::from(v)))
            });
        let full_metric = samples.has_full_metric();
        let (slo, shi) = samples.support_box();
        let mut field = Self {
            frame_origin: centre,
            samples,
            reconstruction,
            octree: std::sync::OnceLock::new(),
            octree_settings: *octree,
            octree_wanted: !grid || reconstruction.neighbours == NeighbourMode::Octree,
            hull: None,
            range,
            full_metric,
            volumes: std::sync::OnceLock::new(),
            support_box: (DVec3::from(slo), DVec3::from(shi)),
            thinnest: std::sync::OnceLock::new(),
            radii: std::sync::OnceLock::new(),
            resampled: std::sync::OnceLock::new(),
            blocks: std::sync::OnceLock::new(),
            fast_path_declined: None,
        };
        if let Domain::Hull(h) = &field.samples.domain {
            field.hull = Some(HullBvh::build(h));
        }
        field.resolve_auto_resample();
        if field.reconstruction.resample > 0 {
            field.check_resample()?;
        }
        Ok(field)
    }

    /// Implicit grid neighbours, for a regular grid with one support.
    pub fn grid(&self) -> Option<GridNeighbours<'_>> {
        match (&self.samples.positions, &self.samples.supports) {
            (
                Positions::Grid {
                    dims,
                    origin,
                    spacing,
                },
                Supports::Uniform(h),
            ) => Some(GridNeighbours {
                dims: *dims,
                origin: *origin,
                spacing: *spacing,
                values: &self.samples.values,
                support: h[0] / spacing[0],
            }),
            _ => None,
        }
    }

    /// The octree, where kernels read one (`None` for a grid's implicit neighbours); a deferred
    /// one is built here, once, and its build error returned on every call.
    pub fn octree(&self) -> Result<Option<&Octree>, ReconError> {
        let built = self.octree.get_or_init(|| {
            if self.octree_wanted {
                Octree::from_samples(&self.samples, &self.octree_settings, |_| {}).map(Some)
            } else {
                Ok(None)
            }
        });
        match built {
            Ok(o) => Ok(o.as_ref()),
            Err(e) => Err(e.clone()),
        }
    }

    /// The octree if it has been built (statistics; never builds one).
    pub fn octree_if_built(&self) -> Option<&Octree> {
        self.octree
            .get()
            .and_then(|o| o.as_ref().ok())
            .and_then(Option::as_ref)
    }

    /// The neighbour structure in use: the octree when kernels read one (built here if it was
    /// deferred), else the grid. Everything else [`Field::evaluate_direct`] reads is built here
    /// too (the Gaussian sum's kernel volumes), so that callers can fan out over rayon after
    /// it: a lazily built value whose builder itself runs on rayon, first asked for inside a
    /// parallel loop, deadlocks when the building worker, waiting for its own jobs, steals an
    /// outer job that waits for the same value (the pilot of a Gaussian field hung that way on
    /// 16 cores).
    pub fn neighbours(&self) -> Result<Box<dyn Neighbours + Sync + '_>, ReconError> {
        let neighbours: Box<dyn Neighbours + Sync + '_> = match (self.octree()?, self.grid()) {
            (Some(o), _) => Box::new(o),
            (None, Some(g)) => Box::new(g),
            // Every field that is not a uniform grid wants an octree.
            (None, None) => Box::new(NoNeighbours),
        };
        if self.reconstruction.method == ReconMethod::Gaussian {
            self.kernel_volumes();
        }
        Ok(neighbours)
    }

    /// [`Field::neighbours`] with everything [`Field::evaluate`] reads built as well (the fast
    /// path's CPU fine grid): what a CPU twin asks for before its parallel loop.
    pub fn evaluator(&self) -> Result<Box<dyn Neighbours + Sync + '_>, ReconError> {
        let neighbours = self.neighbours()?;
        self.resampled();
        Ok(neighbours)
    }

    /// The volume each sample's Gaussian kernel stands for ([`KernelVolumes`]), computed once.
    pub fn kernel_volumes(&self) -> &KernelVolumes {
        self.volumes.get_or_init(|| {
            // The octree where it was built; a deferred one is not built for this (a kd-tree
            // per class of support radii finds the same kernels in O(n) memory).
            let neighbours: Box<dyn Neighbours + Sync + '_> =
                match (self.octree_if_built(), self.grid()) {
                    (Some(o), _) => Box::new(o),
                    (None, Some(g)) => Box::new(g),
                    (None, None) => Box::new(SupportIndex::new(&self.samples)),
                };
            KernelVolumes::compute(
                &self.samples,
                neighbours.as_ref(),
                self.reconstruction.sigma,
            )
        })
    }

    /// The reconstructed field and its gradient at x (frame-relative), by the scene's method;
    /// `None` where it is undefined. With `reconstruction.resample` it is the fast path's
    /// interpolation of the fine grid (stage `resample_evaluate`), defined everywhere.
    pub fn evaluate(&self, neighbours: &dyn Neighbours, x: [f64; 3]) -> Option<MlsValue> {
        if let Some(r) = self.resampled() {
            return Some(r.evaluate(x)).filter(|v| v.terms > 0);
        }
        self.evaluate_direct(neighbours, x)
    }

    /// The general path: the scene's method solved at x.
    pub fn evaluate_direct(&self, neighbours: &dyn Neighbours, x: [f64; 3]) -> Option<MlsValue> {
        match self.reconstruction.method {
            ReconMethod::Mls => mls_evaluate(&self.mls(), neighbours, x),
            ReconMethod::Gaussian => gaussian_evaluate(
                self.reconstruction.sigma,
                self.kernel_volumes(),
                neighbours,
                x,
            ),
            ReconMethod::Exact => {
                // Stage `exact_evaluate`: the generator's function at x's position relative to
                // the generated grid, whose first sample is the function's (-1, -1, -1) — as
                // the GPU twin computes it, wherever the grid was placed.
                let origin = self.grid()?.origin;
                let [wx, wy, wz] = std::array::from_fn(|a| x[a] - origin[a] - 1.0);
                Some(MlsValue {
                    value: crate::data::marschner_lobb::rho(wx, wy, wz),
                    gradient: crate::data::marschner_lobb::rho_gradient(wx, wy, wz),
                    neighbours: 1,
                    terms: 1,
                })
            }
        }
    }

    /// Whether kernels read the octree (else the implicit grid).
    pub fn uses_octree(&self) -> bool {
        self.octree_wanted
    }

    /// Compile-time MLS choices.
    pub fn mls(&self) -> MlsSettings {
        MlsSettings {
            basis: self.reconstruction.basis,
            weight: self.reconstruction.weight,
            gradient: self.reconstruction.gradient,
        }
    }

    /// Frame-relative bounding box of the domain (rays are clipped to it).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let (lo, hi) = self.samples.domain_box();
        (DVec3::from(lo), DVec3::from(hi))
    }

    /// Frame-relative box of every sample's support: where kernels can reach (splatting's
    /// depth range).
    pub fn support_box(&self) -> (DVec3, DVec3) {
        self.support_box
    }

    /// A lower bound on the shortest half axis of any support ([`SampleSet::thinnest_support`]).
    pub fn thinnest_support(&self) -> f64 {
        *self
            .thinnest
            .get_or_init(|| self.samples.thinnest_support())
    }

    /// Support radii at the quantiles 0, 1/64, …, 1 ([`SampleSet::radius_quantiles`]).
    pub fn radius_quantiles(&self) -> &[f64] {
        self.radii.get_or_init(|| self.samples.radius_quantiles(64))
    }

    /// The unit of `render.step` ([`SampleSet::spacing`]).
    pub fn min_spacing(&self) -> f64 {
        self.samples.spacing
    }

    /// Smallest and largest sample value.
    pub fn value_range(&self) -> (f64, f64) {
        self.range
    }

    /// Whether any support is a rotated ellipsoid (the full-metric shader variant).
    pub fn has_full_metric(&self) -> bool {
        self.full_metric
    }
}

/// No samples anywhere (never used in practice; keeps `neighbours` total).
struct NoNeighbours;

impl Neighbours for NoNeighbours {
    fn basis_scale(&self, _x: [f64; 3]) -> [f64; 3] {
        [1.0; 3]
    }

    fn for_each(&self, _x: [f64; 3], _visit: &mut Visit<'_>) {}
}

impl Neighbours for &Octree {
    fn basis_scale(&self, x: [f64; 3]) -> [f64; 3] {
        (*self).basis_scale(x)
    }

    fn for_each(&self, x: [f64; 3], visit: &mut Visit<'_>) {
        (*self).for_each(x, visit)
    }
}

/// Everything a ray needs besides the field: camera frame, clip box, integrator and compositing.
#[derive(Debug, Clone)]
pub struct RaySetup {
    pub camera: Camera,
    pub basis: ViewBasis,
    pub frame_origin: DVec3,
    pub box_lo: DVec3,
    pub box_hi: DVec3,
    pub method: Method,
    /// Step length in world units (fixed, riemann, reference).
    pub step: f64,
    /// Adaptive interval bounds in world units.
    pub l_min: f64,
    pub l_max: f64,
    pub adaptive: AdaptiveCriterion,
    /// Fixed: how an interval between two knots is composited.
    pub interval: IntervalModel,
    pub epsilon: f64,
    /// The sample spacing in world units: the Hermite criterion's ε is per spacing.
    pub spacing: f64,
    /// Preintegrated methods stop at this opacity.
    pub early_termination: f64,
    /// Empty-space skipping: `render.skip` with the fast path ([`skip`]).
    pub skip: bool,
    /// `render.skip = "auto"` not yet decided for a frame ([`RaySetup::resolve_skip`]).
    pub skip_auto: bool,
    /// Hull crossings the GPU kernel keeps per ray ([`gpu::Variant::hull_hits`]).
    pub hull_hits: u32,
    /// The fraction of ray length "auto" found in empty blocks when it decided.
    pub skip_estimate: Option<f64>,
    pub background: [f64; 3],
    /// Riemann and reference methods stop below this transmittance.
    pub min_transmittance: f64,
    pub isosurfaces: Vec<shading::Isosurface>,
    pub lighting: shading::Lighting,
    /// Outer steps per GPU dispatch; None: [`gpu::default_chunk`]. It changes nothing in the
    /// image, only how the kernel's work is split (tests force large chunks with it).
    pub chunk: Option<u32>,
}

impl RaySetup {
    /// The ray setup of a camera, integrator settings, isosurfaces and lighting for a field.
    pub fn new(
        camera: &Camera,
        render: &RenderSettings,
        isosurfaces: &[shading::Isosurface],
        lighting: &shading::Lighting,
        field: &Field,
    ) -> Result<Self, RenderError> {
        if render.method.splat_shading().is_some() {
            return Err(RenderError::Setting {
                key: "render.method",
                message: format!(
                    "'{}' splats; rays are set up for the ray-casting methods only",
                    render.method.name()
                ),
            });
        }
        let basis = camera.basis().map_err(RenderError::Camera)?;
        let (box_lo, box_hi) = field.bounds();
        let spacings = match render.method {
            Method::Reference => render.reference_step,
            _ => render.step,
        };
        let unit = field.min_spacing();
        let mls2008 =
            render.method == Method::Adaptive && render.adaptive == AdaptiveCriterion::Mls2008;
        let skip_on = render.skip == SkipMode::On;
        if skip_on && field.reconstruction.resample == 0 {
            return Err(RenderError::Setting {
                key: "render.skip",
                message: format!(
                    "true needs the fast path, which this field does not take ({}; skipping \
                     reads the fine grid's block ranges): render.skip = false, or the fast path \
                     on a regular grid with grid neighbours",
                    field
                        .fast_path_declined
                        .as_deref()
                        .unwrap_or("reconstruction.resample is 0")
                ),
            });
        }
        if skip_on && mls2008 {
            return Err(RenderError::Setting {
                key: "render.skip",
                message: "true does not apply to render.adaptive = \"mls2008\" (the paper's \
                          criterion does not skip); use \"hermite\" or render.skip = false"
                    .into(),
            });
        }
        let setup = Self {
            camera: *camera,
            basis,
            frame_origin: field.frame_origin,
            box_lo,
            box_hi,
            method: render.method,
            step: spacings * unit,
            l_min: render.l_min * unit,
            l_max: render.l_max * unit,
            adaptive: render.adaptive,
            interval: render.interval,
            epsilon: render.epsilon,
            spacing: unit,
            early_termination: render.early_termination,
            skip: skip_on,
            skip_auto: render.skip == SkipMode::Auto
                && field.reconstruction.resample > 0
                && !mls2008,
            skip_estimate: None,
            hull_hits: gpu::FIRST_HULL_HITS,
            background: render.background,
            min_transmittance: render.min_transmittance,
            isosurfaces: isosurfaces.to_vec(),
            lighting: *lighting,
            chunk: None,
        };
        setup.check_resolution(field)?;
        Ok(setup)
    }

    /// Decides `render.skip = "auto"` for a frame of `tf` over the fast field's `blocks`:
    /// skipping where [`skip::skippable_fraction`] reaches [`skip::SKIP_AUTO_FRACTION`]. The
    /// GPU decides on its own fine grid's blocks and the CPU twin on its f64 ones.
    pub fn resolve_skip(
        &mut self,
        blocks: Option<&skip::Blocks>,
        tf: &TransferFunction,
        field: &Field,
    ) {
        if !self.skip_auto {
            return;
        }
        self.skip_auto = false;
        let Some(blocks) = blocks else {
            return;
        };
        let table = skip::SkipTable::build(tf, &self.isosurfaces, scalar_range(field));
        let fraction = skip::skippable_fraction(blocks, &table, self);
        self.skip_estimate = Some(fraction);
        self.skip = fraction >= skip::SKIP_AUTO_FRACTION;
    }

    /// The shortest length, in world units, this setup's method steps by: the step (the
    /// reference step for `reference`), or l_min for `adaptive`.
    fn finest_step(&self) -> f64 {
        match self.method {
            Method::Adaptive => self.l_min,
            _ => self.step,
        }
    }

    /// Refuses a step below the f32 resolution of the ray parameter at the far side of the box:
    /// t would not change, and the kernel would stall or return an empty image.
    fn check_resolution(&self, field: &Field) -> Result<(), RenderError> {
        let reach = ray_reach(&self.camera, self.frame_origin, self.box_lo, self.box_hi);
        let resolvable = reach * F32_STEP_RESOLUTION;
        let finest = self.finest_step();
        if finest >= resolvable {
            return Ok(());
        }
        let unit = field.min_spacing();
        Err(RenderError::Setting {
            key: self.method.finest_step_key(),
            message: format!(
                "expected at least {:.3e} sample spacings: {} spacings ({finest:.3e} world \
                 units) is below the f32 resolution of rays reaching {reach:.3e} world units \
                 from camera.eye; take a longer step or move camera.eye closer",
                resolvable / unit,
                finest / unit
            ),
        })
    }

    /// An upper bound of the MLS evaluations this setup's frame makes: every pixel's ray
    /// crosses at most the box's diagonal, in steps of the finest length the method takes
    /// (fixed, riemann: the step; reference: its step; adaptive: l_min, twice for rejected
    /// trials). Isosurface refinement adds a few per crossing and is not counted.
    pub fn work_bound(&self) -> f64 {
        let pixels = f64::from(self.camera.width) * f64::from(self.camera.height);
        let trials = if self.method == Method::Adaptive {
            2.0
        } else {
            1.0
        };
        pixels * self.steps_per_diagonal() * trials
    }

    /// Steps of [`RaySetup::finest_step`] along the box's diagonal.
    fn steps_per_diagonal(&self) -> f64 {
        ((self.box_hi - self.box_lo).length() / self.finest_step()).ceil()
    }

    /// Refuses a frame whose [`RaySetup::work_bound`] exceeds `budget` evaluations, before any
    /// GPU work, so that no valid-looking scene can occupy a device for hours.
    pub fn check_budget(&self, budget: f64) -> Result<(), RenderError> {
        let planned = self.work_bound();
        if planned <= budget {
            return Ok(());
        }
        Err(RenderError::Budget {
            planned,
            unit: "MLS evaluations",
            budget,
            hint: format!(
                "{} × {} rays over a box diagonal of {:.0} steps; take a longer {} or a smaller \
                 image",
                self.camera.width,
                self.camera.height,
                self.steps_per_diagonal(),
                self.method.finest_step_key()
            ),
        })
    }

    /// The table lengths this setup's method reads (longest first), or none: fixed uses the
    /// step (and its half for Hermite intervals), adaptive l_max, l_max/2, … ≥ l_min; both add
    /// halvings for clipped remainders ([`preintegration::remainder_levels`]).
    pub fn table_lengths(&self, tf: &TransferFunction) -> Vec<f64> {
        let (top, bottom) = match (self.method, self.interval) {
            (Method::Fixed, IntervalModel::Hermite) => (self.step, 0.5 * self.step),
            (Method::Fixed, IntervalModel::Linear) => (self.step, self.step),
            (Method::Adaptive, _) => (self.l_max, self.l_min),
            _ => return Vec::new(),
        };
        let mut lengths = vec![top];
        while let Some(&l) = lengths.last() {
            if 0.5 * l < bottom * (1.0 - 1e-9) || lengths.len() >= 24 {
                break;
            }
            lengths.push(0.5 * l);
        }
        let tau_max = tf.points().iter().map(|p| p[4]).fold(0.0, f64::max);
        let last = lengths[lengths.len() - 1];
        // Adaptive intervals accepted at the deepest level are composited as halves through
        // the Hermite's midpoint, which read the table one level down.
        let below = usize::from(self.method == Method::Adaptive);
        for _ in 0..preintegration::remainder_levels(last, tau_max).max(below) {
            let l = lengths[lengths.len() - 1];
            lengths.push(0.5 * l);
        }
        lengths
    }
}

/// Smallest step relative to the distance rays travel: 2^-20, eight f32 ulps of the ray
/// parameter at the far side of the box.
pub const F32_STEP_RESOLUTION: f64 = 1.0 / (1u64 << 20) as f64;

/// The work budget of a frame in MLS evaluations (see [`RaySetup::check_budget`]) or
/// footprint-pixel evaluations (`SplatSetup::check_budget`): about 2.5 minutes of the
/// general path on lavapipe at 30 M evaluations/s, seconds on a GPU; the CLI's `--force`
/// lifts it.
pub const WORK_BUDGET: f64 = 4.0e9;

/// How far from the eye any ray reaches inside the box: the farthest corner, plus the half
/// diagonal of an orthographic view's plane of origins.
fn ray_reach(camera: &Camera, frame_origin: DVec3, lo: DVec3, hi: DVec3) -> f64 {
    let eye = DVec3::from(camera.eye) - frame_origin;
    let corner = (eye - lo).abs().max((eye - hi).abs()).length();
    let plane = match camera.projection {
        Projection::Perspective { .. } => 0.0,
        Projection::Orthographic { view_height } => {
            let aspect = f64::from(camera.width) / f64::from(camera.height);
            0.5 * view_height * (1.0 + aspect * aspect).sqrt()
        }
    };
    corner + plane
}

/// Builds the preintegration tables a setup needs (`None` for the direct methods). The scalar
/// range covers the data with a 5% margin each side, because MLS may overshoot the samples;
/// values beyond it are clamped to the range.
pub fn build_tables(
    setup: &RaySetup,
    field: &Field,
    tf: &TransferFunction,
    resolution: usize,
    progress: impl Fn(f64) + Sync,
) -> Option<PreintegrationTables> {
    let lengths = setup.table_lengths(tf);
    if lengths.is_empty() {
        return None;
    }
    Some(PreintegrationTables::build(
        tf,
        scalar_range(field),
        &lengths,
        resolution,
        progress,
    ))
}

/// Refuses tables the device cannot bind before they are built: `lengths` tables and the
/// zero-length limits, each `resolution`² entries of 16 bytes, in one storage buffer of at
/// most `limit` bytes (the device's maxStorageBufferRange). The error names the key and the
/// largest resolution this scene can have on this device.
pub fn check_table_size(lengths: &[f64], resolution: usize, limit: u64) -> Result<(), RenderError> {
    let tables = lengths.len() as u64 + 1;
    let bytes = |r: u64| tables * r * r * 16;
    let r = resolution as u64;
    if bytes(r) <= limit {
        return Ok(());
    }
    let largest = ((limit / (16 * tables)) as f64).sqrt().floor() as u64;
    Err(RenderError::Setting {
        key: "render.table_resolution",
        message: format!(
            "expected at most {largest} for this scene on this device: {resolution} needs \
             {} bytes ({tables} tables of {resolution}² entries × 16 bytes), more than the \
             device's maxStorageBufferRange of {limit} bytes",
            bytes(r)
        ),
    })
}

/// What tables depend on: control points, lengths, resolution, scalar range.
type TableKey = (Vec<[f64; 5]>, Vec<f64>, usize, (f64, f64));

/// Keeps the last preintegration tables and rebuilds them only when what they depend on changes:
/// the transfer function, the lengths, the resolution or the scalar range (for applications
/// that re-render with a new camera, or edit the transfer function interactively).
#[derive(Debug, Default)]
pub struct TableCache {
    key: Option<TableKey>,
    tables: Option<PreintegrationTables>,
    builds: usize,
}

impl TableCache {
    /// The tables for this setup (`None` for the direct methods), built if needed.
    pub fn get(
        &mut self,
        setup: &RaySetup,
        field: &Field,
        tf: &TransferFunction,
        resolution: usize,
        progress: impl Fn(f64) + Sync,
    ) -> Option<&PreintegrationTables> {
        let lengths = setup.table_lengths(tf);
        if lengths.is_empty() {
            return None;
        }
        let key = (
            tf.points().to_vec(),
            lengths,
            resolution,
            scalar_range(field),
        );
        if self.key.as_ref() != Some(&key) {
            self.tables = build_tables(setup, field, tf, resolution, progress);
            self.key = Some(key);
            self.builds += 1;
        }
        self.tables.as_ref()
    }

    /// The tables of the last `get` that needed any.
    pub fn current(&self) -> Option<&PreintegrationTables> {
        self.tables.as_ref()
    }

    /// How many times tables were built.
    pub fn builds(&self) -> usize {
        self.builds
    }
}

/// The tables' scalar range: the data range with a 5% margin each side. The margin is at
/// least 5·10⁻⁶ of the values' magnitude, so that a constant field far from zero (fuzzing found
/// 1e20 everywhere) keeps a range that f32 resolves on the GPU instead of one of zero width,
/// which made the CPU twin divide 0 by 0.
pub fn scalar_range(field: &Field) -> (f64, f64) {
    let (lo, hi) = field.value_range();
    let magnitude = lo.abs().max(hi.abs());
    let margin = 0.05 * (hi - lo).max(1e-6).max(1e-4 * magnitude);
    (lo - margin, hi + margin)
}
