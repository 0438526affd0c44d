//! Everything a ray needs besides the field: the camera frame, the clip box, the integrator and
//! compositing, in world units relative to the frame origin.

use crate::field::gpu::FIRST_HULL_HITS;
use crate::field::skip::{Blocks, RUN_NUDGE, SkipTable};
use crate::field::variant::HullCache;
use crate::field::{Field, RenderError, scalar_range};
use crate::view::camera::{Camera, Projection, ViewBasis};
use crate::view::preintegration;
use crate::view::shading;
use crate::view::transfer::TransferFunction;
use crate::view::{
    AdaptiveCriterion, ExactOpacity, IntervalModel, Method, RenderSettings, SkipMode,
};
use glam::DVec3;

/// `render.skip = "auto"` compiles skipping in where at least this fraction of the frame's ray
/// length lies in empty blocks ([`skippable_fraction`]). On lavapipe a SIMD row of 8 rays
/// costs what its busiest ray costs and the block lookups run on every lane. Since skipping
/// crosses runs of occupied blocks in one check (`skip_span`), it costs 14% with nothing to
/// skip (the built-in scene, 512²) and 1–10% at 40% skippable (ml-emission), and wins 6–15% at
/// 50% (the fire mesh) and 27% at 54% (ml-iso, 256²) (BENCHMARKS.md, "Skipping across occupied
/// blocks"). It was 0.75 while every occupied block cost a check of its own.
pub const SKIP_AUTO_FRACTION: f64 = 0.45;
/// Rays per image axis [`skippable_fraction`] casts.
const ESTIMATE_RAYS: u32 = 32;

/// The fraction of the ray length inside the setup's box that lies in blocks empty for
/// `table`, over 32 × 32 of the camera's rays: the estimate `render.skip = "auto"` decides by,
/// before the frame (a mesh's hull and early termination are not looked at).
pub fn skippable_fraction(blocks: &Blocks, table: &SkipTable, setup: &RaySetup) -> f64 {
    let nudge = RUN_NUDGE * blocks.size.min_element();
    let (mut inside, mut empty) = (0.0, 0.0);
    let rays = setup
        .camera
        .sample_rays(&setup.basis, setup.frame_origin, ESTIMATE_RAYS);
    for (o, d) in rays {
        let Some((t0, t1)) = crate::view::camera::clip_box(o, d, setup.box_lo, setup.box_hi) else {
            continue;
        };
        inside += t1 - t0;
        let mut t = t0;
        while t < t1 {
            let (is_empty, exit) = blocks.lookup(table, o, d, t + nudge);
            let exit = exit.min(t1);
            if exit <= t {
                break;
            }
            if is_empty {
                empty += exit - t;
            }
            t = exit;
        }
    }
    if inside > 0.0 { empty / inside } else { 0.0 }
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
    /// Step length in world units (fixed, riemann, reference): `render.step` (or
    /// `render.reference_step`) times the sample spacing.
    pub step_world: f64,
    /// Adaptive interval bounds in world units.
    pub l_min_world: f64,
    pub l_max_world: f64,
    pub adaptive: AdaptiveCriterion,
    /// Fixed: how an interval between two knots is composited.
    pub interval: IntervalModel,
    pub epsilon: f64,
    /// The sample spacing in world units: the Hermite criterion's ε is per spacing.
    pub spacing_world: f64,
    /// Preintegrated methods stop at this opacity.
    pub early_termination: f64,
    /// Empty-space skipping: `render.skip` with the fast path ([`crate::field::skip`]).
    pub skip: bool,
    /// `render.skip = "auto"` not yet decided for a frame ([`RaySetup::resolve_skip`]).
    pub skip_auto: bool,
    /// Hull crossings the GPU kernel keeps per ray ([`crate::field::variant::Variant::hull_hits`]).
    pub hull_hits: u32,
    /// How the frame comes by its rays' hull segments ([`super::segments`]): the `Renderer`
    /// keeps or reads them where a mesh's cache fits the device; `Off` walks as without one.
    pub hull_cache: HullCache,
    /// Table lookups take their opacity from the transfer function's integral
    /// (`render.exact_opacity`; [`crate::view::preintegration::PreintegrationTables::entry`]):
    /// `On` as given, and "auto" as [`RaySetup::resolve_exact_opacity`] decides for a frame
    /// (false until then).
    pub exact_opacity: bool,
    pub exact_opacity_auto: bool,
    /// The transfer function's point count, recorded by [`RaySetup::resolve_exact_opacity`]
    /// (0 until then): the exact opacity's scan is unrolled for up to
    /// [`crate::gpu_types::TF_BLOCK_POINTS`] of them.
    pub tf_points: u32,
    /// The transfer function's pieces of change ([`TransferFunction::sensitivity_pieces`]),
    /// recorded with `tf_points`: the Hermite criterion's sensitivity scan is unrolled over
    /// up to [`crate::gpu_types::SENSITIVITY_PIECES`] of them.
    pub sensitivity_pieces: u32,
    /// The fraction of ray length "auto" found in empty blocks when it decided.
    pub skip_estimate: Option<f64>,
    pub background: [f64; 3],
    /// A brick of a decomposed field ([`Field::piece`]): rays integrate only inside this box
    /// (frame-relative), their steps anchored where the undivided field's segments start.
    pub clip: Option<(DVec3, DVec3)>,
    /// A brick's frame over black: the pixels [x0, y0, x1, y1] whose rays can meet its box
    /// ([`Camera::pixel_box`]); only they are dispatched, the others are written as rays that
    /// miss (transparent, finished) without running.
    pub window: Option<[u32; 4]>,
    /// Riemann and reference methods stop below this transmittance.
    pub min_transmittance: f64,
    pub isosurfaces: Vec<shading::Isosurface>,
    pub lighting: shading::Lighting,
    /// Outer steps per GPU dispatch; None: [`super::frame::default_chunk`]. It changes nothing in the
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
            Method::Reference => render.reference_step_spacings,
            _ => render.step_spacings,
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
                        .fast_path_declined()
                        .unwrap_or("reconstruction.resample is 0")
                ),
            });
        }
        if field.clip().is_some() && mls2008 {
            return Err(RenderError::Setting {
                key: "render.adaptive",
                message: "\"mls2008\" does not render a brick of a decomposed field (its top \
                          intervals start at the brick's face, so bricks would not add up to the \
                          one-device image); use \"hermite\", whose intervals keep the \
                          undivided ray's"
                    .into(),
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
            step_world: spacings * unit,
            l_min_world: render.l_min_spacings * unit,
            l_max_world: render.l_max_spacings * unit,
            adaptive: render.adaptive,
            interval: render.interval,
            epsilon: render.epsilon,
            spacing_world: unit,
            early_termination: render.early_termination,
            skip: skip_on,
            skip_auto: render.skip == SkipMode::Auto
                && field.reconstruction.resample > 0
                && !mls2008,
            skip_estimate: None,
            exact_opacity: render.exact_opacity == ExactOpacity::On,
            exact_opacity_auto: render.exact_opacity == ExactOpacity::Auto,
            tf_points: 0,
            sensitivity_pieces: 0,
            hull_hits: FIRST_HULL_HITS,
            hull_cache: HullCache::Off,
            background: render.background,
            clip: field.clip(),
            window: field
                .clip()
                .filter(|_| render.background == [0.0; 3])
                .map(|b| camera.pixel_box(&basis, field.frame_origin, b)),
            min_transmittance: render.min_transmittance,
            isosurfaces: isosurfaces.to_vec(),
            lighting: *lighting,
            chunk: None,
        };
        setup.check_resolution(field)?;
        Ok(setup)
    }

    /// Decides `render.skip = "auto"` for a frame of `tf` over the fast field's `blocks`:
    /// skipping where [`skippable_fraction`] reaches [`SKIP_AUTO_FRACTION`]. The
    /// GPU decides on its own fine grid's blocks and the CPU twin on its f64 ones.
    pub fn resolve_skip(&mut self, blocks: Option<&Blocks>, tf: &TransferFunction, field: &Field) {
        if !self.skip_auto {
            return;
        }
        self.skip_auto = false;
        let Some(blocks) = blocks else {
            return;
        };
        let table = SkipTable::build(tf, &self.isosurfaces, scalar_range(field));
        let fraction = skippable_fraction(blocks, &table, self);
        self.skip_estimate = Some(fraction);
        self.skip = fraction >= SKIP_AUTO_FRACTION;
    }

    /// Decides `render.exact_opacity = "auto"` for a frame of `tf` over `field`
    /// ([`ExactOpacity::resolve`]; the direct methods read no tables and stay off), and records
    /// what the kernel's scans of `tf` unroll over ([`RaySetup::record_transfer`]).
    pub fn resolve_exact_opacity(&mut self, tf: &TransferFunction, field: &Field) {
        self.record_transfer(tf);
        if !self.exact_opacity_auto {
            return;
        }
        self.exact_opacity_auto = false;
        self.exact_opacity =
            self.method.preintegrated() && ExactOpacity::Auto.resolve(tf, scalar_range(field));
    }

    /// Records `tf`'s point count and pieces of change, which the kernel's scans of the
    /// transfer function unroll over.
    pub fn record_transfer(&mut self, tf: &TransferFunction) {
        self.tf_points = tf.points().len() as u32;
        self.sensitivity_pieces = tf.sensitivity_pieces().len() as u32;
    }

    /// The shortest length, in world units, this setup's method steps by: the step (the
    /// reference step for `reference`), or l_min for `adaptive`.
    fn finest_step(&self) -> f64 {
        match self.method {
            Method::Adaptive => self.l_min_world,
            _ => self.step_world,
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
            (Method::Fixed, IntervalModel::Hermite) => (self.step_world, 0.5 * self.step_world),
            (Method::Fixed, IntervalModel::Linear) => (self.step_world, self.step_world),
            (Method::Adaptive, _) => (self.l_max_world, self.l_min_world),
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
