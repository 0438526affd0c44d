//! The renderer's configuration (scene sections `[render]` and `[splat]`): owned by this layer,
//! read from the scene file by `scene`.

/// The integrator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Preintegration with a constant step `render.step`: one table lookup per interval.
    Fixed,
    /// Midpoint rule with `render.step`, transfer function applied directly (for comparison).
    Riemann,
    /// Midpoint rule with `render.reference_step`: ground truth.
    Reference,
    /// [MLS] adaptive subdivision between `render.l_max` and `render.l_min`.
    Adaptive,
    /// Pre-shaded EWA splatting ([EWA], `crate::splat`).
    Splat,
    /// Post-shaded splatting: the field's sheets classified per pixel ([BLUR], `crate::splat`).
    SplatPost,
}

impl Method {
    /// The scene-file spelling.
    pub fn name(self) -> &'static str {
        match self {
            Method::Fixed => "fixed",
            Method::Riemann => "riemann",
            Method::Reference => "reference",
            Method::Adaptive => "adaptive",
            Method::Splat => "splat",
            Method::SplatPost => "splat-post",
        }
    }

    /// The splatting mode, for the splatting methods.
    pub fn splat_shading(self) -> Option<Shading> {
        match self {
            Method::Splat => Some(Shading::Pre),
            Method::SplatPost => Some(Shading::Post),
            _ => None,
        }
    }

    /// Whether the method reads preintegration tables.
    pub fn preintegrated(self) -> bool {
        matches!(self, Method::Fixed | Method::Adaptive)
    }

    /// The scene key of the shortest length the method steps by (what bounds its work).
    pub fn finest_step_key(self) -> &'static str {
        match self {
            Method::Reference => "render.reference_step",
            Method::Adaptive => "render.l_min",
            _ => "render.step",
        }
    }
}

/// The adaptive integrator's acceptance test (`render.adaptive`, DESIGN.md §4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AdaptiveCriterion {
    /// [MLS] §4: compare an interval with its two halves (two evaluations per accepted
    /// interval); ε is relative, (1 − α)·|C1 − C2| ≤ ε·|C1|.
    Mls2008,
    /// One evaluation per accepted interval: the cubic Hermite through the knots' values and
    /// directional derivatives bounds f's departure from the line the tables assume; ε bounds the
    /// resulting error of optical depth and colour per sample spacing.
    Hermite,
}

impl AdaptiveCriterion {
    /// The scene-file spelling.
    pub fn name(self) -> &'static str {
        match self {
            AdaptiveCriterion::Mls2008 => "mls2008",
            AdaptiveCriterion::Hermite => "hermite",
        }
    }

    /// `render.epsilon` when the scene gives none: [MLS]'s 0.03 for its criterion; for the
    /// Hermite criterion, the ε that matched fixed-step preintegration at step 0.5 in RMSE on
    /// Marschner–Lobb (BENCHMARKS.md, "The Hermite criterion").
    pub fn default_epsilon(self) -> f64 {
        match self {
            AdaptiveCriterion::Mls2008 => 0.03,
            AdaptiveCriterion::Hermite => 0.003,
        }
    }
}

/// How the fixed-step integrator composites the interval between two knots
/// (`render.interval`, DESIGN.md §4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IntervalModel {
    /// f linear between the knots: one lookup of the step's table ([MLS] §4).
    Linear,
    /// Two halves through the midpoint of the cubic Hermite that the knots' values and
    /// directional derivatives define (exact for cubic f along the ray): two lookups of the
    /// half step's table, no further evaluation. Intervals whose Hermite hull holds an isosurface
    /// value stay linear (their surfaces are located between the knots).
    Hermite,
}

/// Integrator settings (scene section `[render]`).
#[derive(Debug, Clone, PartialEq)]
pub struct RenderSettings {
    pub method: Method,
    /// Step in sample spacings (the smallest spacing of the grid): scene key `render.step`.
    pub step_spacings: f64,
    /// Step of the reference method, in sample spacings (`render.reference_step`).
    pub reference_step_spacings: f64,
    pub background: [f64; 3],
    /// Rays stop when the transmittance falls below this (riemann and reference methods).
    pub min_transmittance: f64,
    /// Adaptive: shortest and longest interval, in sample spacings ([MLS]: 0.16 and 2.6;
    /// `render.l_min`, `render.l_max`).
    pub l_min_spacings: f64,
    pub l_max_spacings: f64,
    /// Adaptive: the acceptance test.
    pub adaptive: AdaptiveCriterion,
    /// Fixed: how an interval between two knots is composited.
    pub interval: IntervalModel,
    /// Adaptive: the criterion's tolerance ε ([`AdaptiveCriterion`]).
    pub epsilon: f64,
    /// Preintegrated methods stop a ray once its opacity exceeds this ([MLS]: 0.99).
    pub early_termination: f64,
    /// Empty-space skipping (`render.skip`); it needs the fast path
    /// (`reconstruction.resample`), whose field has exact block bounds ([`crate::field::skip`]).
    pub skip: SkipMode,
    /// Preintegration table resolution per scalar axis.
    pub table_resolution: usize,
    /// `render.exact_opacity`: the length tables' opacity from the transfer function's
    /// integral instead of the tables ([`crate::view::preintegration::PreintegrationTables::entry`]).
    pub exact_opacity: ExactOpacity,
    /// Splatting settings (scene section `[splat]`).
    pub splat: SplatSettings,
    /// `render.tolerance`: the accepted 99th-percentile pixel error against the converged
    /// image; the renderer then chooses the parameters that bound the error
    /// (`renderer::tolerance`) unless `given` says the scene set them.
    pub tolerance: Option<f64>,
    /// Which of the keys that a tolerance chooses the scene gave explicitly.
    pub given: GivenKeys,
}

/// The keys a tolerance would choose that a scene set explicitly (they win over it).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct GivenKeys {
    pub step: bool,
    pub reference_step: bool,
    pub epsilon: bool,
    /// `render.adaptive`: a tolerance takes the Hermite criterion unless the scene names one.
    pub adaptive: bool,
    pub l_min: bool,
    pub l_max: bool,
    pub early_termination: bool,
    pub min_transmittance: bool,
    pub table_resolution: bool,
    pub slab: bool,
}

/// `render.table_resolution` unset: preintegration table nodes per scalar axis.
pub const DEFAULT_TABLE_RESOLUTION: usize = 512;

/// `render.exact_opacity`: where the preintegrated integrators take each table lookup's opacity
/// from ([`crate::view::preintegration::PreintegrationTables::entry`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExactOpacity {
    /// The tables' bilinear opacity.
    Off,
    /// 1 − exp(−l τ̄) with τ̄ the transfer function's exact mean extinction over the segment's
    /// scalar range: one scan of its points per lookup.
    On,
    /// The default: on where the transfer function has a piece of changing extinction
    /// narrower than [`crate::view::transfer::EXACT_OPACITY_WIDTH`] of the data's range
    /// ([`crate::view::transfer::TransferFunction::has_narrow_extinction`]), which tables of a
    /// resolution that fits a device do not resolve.
    Auto,
}

impl ExactOpacity {
    /// Whether a frame of `tf` over data of scalar `range` takes the exact opacity.
    pub fn resolve(self, tf: &super::transfer::TransferFunction, range: (f64, f64)) -> bool {
        match self {
            Self::Off => false,
            Self::On => true,
            Self::Auto => tf.has_narrow_extinction(range),
        }
    }
}

/// `render.skip`: empty-space skipping off, on, or chosen per frame ([`crate::field::skip`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SkipMode {
    Off,
    /// Skipping in every frame (the fast path required).
    On,
    /// The default: skipping compiled in only where the frame's rays would spend at least
    /// [`crate::raycast::setup::SKIP_AUTO_FRACTION`] of their length in empty blocks
    /// ([`crate::raycast::setup::skippable_fraction`]), decided from the transfer function and the
    /// block ranges before the frame; off without the fast path.
    Auto,
}

/// Pre- or post-shaded splatting (`render.method = "splat"` or `"splat-post"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shading {
    /// Classify each kernel, splat extinction and emission, resolve each sheet ([EWA]).
    Pre,
    /// Splat the field into sheets, then classify and shade per pixel ([BLUR]).
    Post,
}

/// `splat.antialias`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Antialias {
    /// [EWA]'s resampling filter: the footprint convolved with the low-pass Gaussian.
    Ewa,
    /// [SWAN]: the footprint scaled uniformly until its minor variance reaches the low-pass's.
    Swan,
    /// The smallest widening that gives every footprint at least the low-pass variance in
    /// every direction: the low-pass is added only along the footprint's eigenvectors whose
    /// variance is below it, up to it (a footprint wider than the low-pass everywhere is
    /// unchanged; one narrower everywhere becomes the low-pass). Band-limited like
    /// [`Antialias::Ewa`], without its blur of footprints that are already wide.
    Auto,
    /// No low-pass filter (aliases under minification).
    None,
}

/// `splat.sheet_share`: how post-shaded splatting shares a kernel's line integral out to the
/// sheets it crosses (with ring registers, one lateral footprint per pixel and entry).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SheetShare {
    /// Φ(z_b) − Φ(z_a) from the erfc at each sheet boundary (|error| ≤ 1.5·10⁻⁷): a division
    /// and an exponential per sheet.
    Erfc,
    /// The Hermite–Simpson rule on each sheet (the Gaussian at both boundaries and the middle,
    /// its slope at both boundaries; exact for quintics), the Gaussians by a product recurrence
    /// from two seeds per entry: a few multiplies per sheet. For sheets at most
    /// [`crate::splat::QUADRATURE_MAX_SHEET`] deviations thick: a kernel thinner along a ray
    /// is shared as if it were that thick (`SplatSetup::share_deviation`).
    Quadrature,
    /// The midpoint rule: each sheet gets h·φ(z_m), the Gaussian at the sheet's middle times
    /// its thickness h in deviations, by the same recurrence, one multiply-add per sheet. A
    /// sheet's value is then the field at its middle on the pixel's ray instead of its mean
    /// over the slab. Widened like the quadrature, a kernel's shares sum to its line integral
    /// within 3.1·10⁻⁴ (Poisson summation: 2e^(−2π²/h²) at h = 1.5).
    Midpoint,
}

impl SheetShare {
    /// A rule of samples of the Gaussian by the recurrence (the quadrature or the midpoint
    /// rule), which serves sheets at most [`crate::splat::QUADRATURE_MAX_SHEET`] deviations
    /// thick and widens thinner kernels; the erfc serves any.
    pub fn sampled(self) -> bool {
        self != SheetShare::Erfc
    }

    /// The rule's name, as `splat.sheet_share` spells it.
    pub fn name(self) -> &'static str {
        match self {
            SheetShare::Erfc => "erfc",
            SheetShare::Quadrature => "quadrature",
            SheetShare::Midpoint => "midpoint",
        }
    }
}

/// `splat.interval`: how post-shaded splatting classifies the field between its sheets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SheetInterval {
    /// Each sheet's value over its whole slab, the transfer function applied to it ([BLUR]'s
    /// sheets): a Riemann sum along the ray, first order in the sheet thickness.
    Constant,
    /// The field linear between consecutive sheet middles, each half sheet preintegrated
    /// ([MLS] §4's tables, one table of half a sheet's length).
    Linear,
    /// As `Linear`, with each interval between sheet middles split at its middle, where the
    /// cubic through the four nearest sheet values (Catmull–Rom: slopes by central
    /// differences of the sheets) puts the field: the ray caster's Hermite intervals with
    /// the sheets' differences for its gradients. No more accumulation than `Constant`, two
    /// table lookups per sheet and pixel.
    Hermite,
}

impl SheetInterval {
    /// The model's name, as `splat.interval` spells it.
    pub fn name(self) -> &'static str {
        match self {
            SheetInterval::Constant => "constant",
            SheetInterval::Linear => "linear",
            SheetInterval::Hermite => "hermite",
        }
    }
}

/// `splat.prefetch`: what `splat_raster`'s walk loads one entry ahead of its use. The loads
/// and the arithmetic are the same, in another order: the image is the same to the bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Prefetch {
    /// Each entry and its kernel's record where they are used (two dependent loads a step).
    None,
    /// The next entry, so that a step's record load has its address at hand (one load a step
    /// waited on).
    List,
    /// The next entry and its record (28 more registers held across a step).
    Records,
}

impl Prefetch {
    /// The level's name, as `splat.prefetch` spells it.
    pub fn name(self) -> &'static str {
        match self {
            Prefetch::None => "none",
            Prefetch::List => "list",
            Prefetch::Records => "records",
        }
    }
}

/// Scene section `[splat]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplatSettings {
    /// Sheet thickness in sample spacings (`splat.slab`).
    pub slab_spacings: f64,
    /// Footprints are cut at this many standard deviations.
    pub cutoff: f64,
    /// Variance of the low-pass filter in px² (1: the identity of [EWA] §6).
    pub lowpass: f64,
    pub antialias: Antialias,
    /// Early splat elimination: a tile stops walking its sheets once every pixel in it is
    /// opaque or, post-shaded, past its ray's exit from the domain (the box's, or its last hull
    /// segment's), where nothing more is composited.
    pub occlusion: bool,
    /// Isosurfaces as surface splats (pre-shaded splatting).
    pub surface: bool,
    /// Perspective footprints: the exact ray integral per pixel, or [EWA]'s affine footprint
    /// (about half the accumulation time; errs where kernels are large or thin for their
    /// distance).
    pub exact: bool,
    /// Image tile edge in pixels (one of `TILE_SIZES`); unset: the smallest whose (tile,
    /// sheet) buckets fit `MAX_BUCKETS`.
    pub tile: Option<u32>,
    /// Each kernel split among the sheets its depth range crosses, by the share of its line
    /// integral in each ([BLUR]'s sheets; exact emission–absorption as the sheets thin), or
    /// (pre-shaded only) composited whole in the sheet of its centre: [EWA]'s image model
    /// and 3D Gaussian splatting's, one footprint per kernel and tile instead of one per
    /// sheet it crosses. Unset: split post-shaded, whole pre-shaded (whose error is its
    /// classification before the sum: BENCHMARKS.md measured the same RMSE both ways, at 13×
    /// the time split).
    pub split: Option<bool>,
    /// The sheet-share rule of post-shaded splatting; unset: the midpoint rule where at most
    /// `WIDEN_MAX_SHARE` of the kernels are thinner than it serves (`QUADRATURE_MAX_SHEET`),
    /// else the erfc.
    pub sheet_share: Option<SheetShare>,
    /// How post-shaded splatting classifies the field between sheets; unset: Hermite
    /// intervals (pre-shaded splatting refuses the key: it classifies kernels, not sheets).
    pub interval: Option<SheetInterval>,
    /// Post-shaded ring size (one of `RINGS`); unset: [`crate::splat::choose_ring`].
    pub ring: Option<u32>,
    /// Tile rows per dispatch of `splat_raster`; unset: chosen for the device (two on
    /// lavapipe, at least 4 096 tiles a band on a GPU: [`crate::splat::SplatSetup::fit_device`]).
    /// Changes no pixel, only the dispatches.
    pub band_rows: Option<u32>,
    /// Pixels per `splat_raster` invocation where no isosurface apron needs one (one of
    /// `RASTER_PIXELS`); unset: on lavapipe four post-shaded and eight pre-shaded, on a GPU one
    /// post-shaded and two pre-shaded. The image agrees within f32
    /// rounding (another compiled variant).
    pub pixels: Option<u32>,
    /// Post-shaded: `splat_raster` branches around work that adds exact zeros (a pixel outside
    /// a kernel's footprint skips its sheet shares; an interval whose table entries are all
    /// zero, or that lies outside the domain, skips its lookups). Unset: on a GPU the lookups'
    /// skips where the frame's table has all-zero entries or the domain is a mesh's hull, and
    /// the shares' with rings of 16 sheets; not on lavapipe, where a
    /// branch runs both sides under a mask and measured slower. The image is the same within
    /// f32 rounding (the early return changes how a compiler fuses the shares' multiply-adds).
    pub branches: Option<bool>,
    /// What `splat_raster`'s walk loads one entry ahead, so that its loads overlap the entry
    /// before's arithmetic. Unset: none on lavapipe, where a load does not stall a lane; on a
    /// GPU [`crate::splat::SplatSetup::fit_device`]'s choice. The image is the same to the bit.
    pub prefetch: Option<Prefetch>,
}

impl Default for SplatSettings {
    fn default() -> Self {
        Self {
            slab_spacings: 0.5,
            cutoff: 3.5,
            lowpass: 1.0,
            antialias: Antialias::Auto,
            occlusion: true,
            surface: false,
            exact: true,
            tile: None,
            split: None,
            sheet_share: None,
            interval: None,
            ring: None,
            band_rows: None,
            pixels: None,
            branches: None,
            prefetch: None,
        }
    }
}
