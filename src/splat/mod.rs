//! EWA volume splatting ([EWA]), pre-shaded and post-shaded with image-aligned sheets
//! ([BLUR]): the second renderer. It reads the same sample set as ray casting.
//!
//! Every sample becomes a Gaussian kernel of covariance `V_i = σ² M_i⁻¹` and weight `v_i`
//! (`recon::gaussian`: the splatted extinction or density is the Gaussian-sum field that
//! `reconstruction.method = "gaussian"` ray casts, up to where each is cut: the field at ρ = 1,
//! i.e. 1/σ standard deviations in 3D, a footprint at `splat.cutoff` deviations across the ray
//! and not along it). A frame runs these stages, each with an f64 CPU twin here and a GLSL
//! kernel of the same name; its shape is 3D Gaussian splatting's tile rasterizer, with
//! [BLUR]'s sheets where 3DGS has depth order:
//! - `splat_setup` (host, [`SplatSetup::new`]): camera frame, focal length in pixels, and the
//!   sheets: slabs of thickness Δs = `splat.slab` × spacing in the distance t from the eye
//!   (spherical shells for a perspective camera, planes for an orthographic one), so that every
//!   pixel's ray is cut at the same t as a ray caster with step Δs would cut it;
//! - `splat_project` ([`project`]): per kernel (pre-shaded on the GPU: per kernel its
//!   transfer function does not make transparent, `gpu::GpuKernels::upload`), the ray-space
//!   Jacobian, footprint, conic, resampling filter, bounding box, depth and sheet range, with
//!   the culling guards; counts one entry per (image tile, sheet) the kernel touches into the
//!   bucket `tile · sheets + sheet`;
//! - `splat_scan`, `splat_bin` and `splat_order` ([`raster::splat_bin`]): a counting sort of
//!   the entries by bucket, all on the GPU (an exclusive scan of the bucket counts, a scatter,
//!   then each bucket in kernel order: frames are the same to the bit on every run), so that
//!   each tile's entries lie together, sheet after sheet;
//! - `splat_raster` ([`raster`]): one workgroup per tile for the whole frame, one invocation
//!   per column of four pixels (one pixel with an apron). The tile walks its entries front to
//!   back at an index that is the same in every lane (on lavapipe a texel gather of one
//!   address: storage-buffer loads are lane loops even then), accumulates them in registers
//!   and composites each sheet as the walk passes it; a subgroup stops once its pixels are
//!   opaque; each pixel is written once. No atomics on pixels, no sheet buffers in memory.
//!   Post-shaded kernels are one entry per tile and `ring` sheets (4, 8 or 16, fitted to the
//!   kernels' spans: [`choose_ring`]), the lateral footprint evaluated once per pixel and
//!   entry and shared out to the sheets ([`SheetShare`]: by default the midpoint rule, the
//!   Gaussian at each sheet's middle by a product recurrence, which widens the few kernels
//!   thinner than a sheet allows, [`SplatSetup::share_deviation`]; where more are that thin,
//!   the erfc at each sheet boundary; a Hermite–Simpson quadrature on request). Post-shaded
//!   sheets are classified between their middles ([`SheetInterval`]: by default the ray
//!   caster's Hermite intervals, the field at each interval's middle from the Catmull–Rom
//!   cubic of the four nearest sheets, each half preintegrated by one table half a sheet
//!   long, [`SplatSetup::table_lengths`]; one sheet more, past the kernels, closes the last
//!   interval).
pub mod footprint;
pub mod frame;
pub mod gpu;
pub mod plan;
pub mod project;
pub mod raster;
pub mod surface;

use crate::view::settings::ExactOpacity;
pub use crate::view::settings::{
    Antialias, Prefetch, Shading, SheetInterval, SheetShare, SplatSettings,
};

use crate::field::{Field, RenderError};
use crate::view::camera::{Camera, Projection, ViewBasis};
use crate::view::shading::{Isosurface, Lighting, MAX_ISOSURFACES};
use crate::view::transfer::TransferFunction;
use glam::DVec3;

/// Image tile sizes (`splat.tile`): one workgroup rasterizes one tile, one invocation per
/// pixel (plus a one-pixel apron when post-shaded isosurfaces need gradients; 32² + apron
/// would pass the 1024 invocations a workgroup may have on lavapipe).
pub const TILE_SIZES: [u32; 3] = [8, 16, 32];
/// Pixels per `splat_raster` invocation it may take (`splat.pixels`): a column of them, which
/// every tile size holds whole.
pub const RASTER_PIXELS: [u32; 4] = [1, 2, 4, 8];
/// Tiles a band of `splat_raster` holds at least on a GPU (rows rounded up): a discrete GPU
/// needs tens of thousands of invocations in flight. In lavapipe's bands of two tile rows a
/// 512² post-shaded frame of 68 921 points gave an H200 128 workgroups a dispatch and took
/// 65.4 ms; in one band of 4 096 tiles, 6.89 (BENCHMARKS.md, "Splatting on a GPU needs wide
/// bands").
pub const GPU_BAND_TILES: u32 = 4096;
/// At most this many (tile × sheet) entries per kernel: `splat_project` counts and `splat_bin`
/// writes them in one invocation's loops, which llvmpipe ends after 65 535 iterations. More is
/// an error naming `splat.slab` and the image size, never a silently truncated list.
pub const MAX_KERNEL_ENTRIES: u64 = 60_000;
/// At most this many (tile × sheet) buckets: the scan's second level is one workgroup of
/// 256 invocations, each summing at most 4 blocks of `SCAN_BLOCK` buckets.
pub const MAX_BUCKETS: u64 = 1 << 24;
/// Buckets per workgroup of `splat_scan`'s first and third levels, 64 per invocation: few
/// workgroups, because their barriers are the scan's cost on lavapipe (1 024, 4 096 and 16 384
/// measured; BENCHMARKS.md, "The splatting sort's scan").
pub const SCAN_BLOCK: u32 = 16384;
/// Post-shaded splatting keeps each pixel's next sheets in `ring − 1` registers, one of these
/// sizes (`SplatSetup::ring`): a kernel is then one entry per tile and per `ring` sheets it
/// crosses, its lateral footprint evaluated once per pixel and entry and shared out to those
/// sheets, where one entry per sheet evaluates it per sheet. Every share of an entry is computed
/// (llvmpipe runs both sides of a branch), so the ring fits the kernels' spans
/// ([`choose_ring`]).
pub const RINGS: [u32; 3] = [4, 8, 16];
/// The work of one entry at one pixel besides its sheet shares (record, lateral footprint,
/// seeds), in sheet shares, and how much dearer a share gets per sheet of ring (registers
/// spill: a 16-sheet ring's shares cost 1.2 times a 4-sheet one's): fitted on lavapipe to
/// `splat_raster`'s times with each ring on the ML points (sheets 0.5, 1 and 2 spacings) and
/// the torus at 512² (issue 26), for both rules.
pub const RING_ENTRY_COST: f64 = 3.0;
pub const RING_SPILL: f64 = 0.2 / 16.0;
/// The quadrature sheet share ([`SheetShare::Quadrature`]) serves sheets at most this many of
/// a kernel's standard deviations thick along the ray: its error is then at most 1.5·10⁻⁴ of
/// the kernel's line integral per sheet (`footprint::sheet_share`), and the kernel's recurrence
/// stays inside f32's range (its seeds lie at most 4 sheets, 6 deviations, from every sheet
/// they serve). A kernel thinner than that along a pixel's ray is shared out as if it were
/// that thick ([`SplatSetup::share_deviation`]).
pub const QUADRATURE_MAX_SHEET: f64 = 1.5;
/// Unset, `splat.sheet_share` takes the midpoint rule for post-shaded splatting (faster than the
/// quadrature and closer to the Gaussian-sum reference on the ML points and the torus,
/// BENCHMARKS.md "Branch-free accumulation") while at most this share of the kernels
/// (estimated from the supports' mean radii) is thinner than it serves, and the erfc beyond.
/// The figures that follow were measured with the quadrature. On the 68 921 scattered Marschner–Lobb points at sheets of one
/// spacing (4.9% of the kernels thinner) the widened quadrature took 0.65 of the erfc's time at
/// the same RMSE to 0.3%; at two spacings (all of them thinner) it doubled the entries and
/// raised the RMSE from 0.058 to 0.078 (BENCHMARKS.md, "The quadrature for every post-shaded
/// scene").
pub const WIDEN_MAX_SHARE: f64 = 0.125;
/// At most this many sheets per frame.
pub const MAX_SLABS: u32 = 16_384;
/// 3DGS's guard: the Jacobian's lateral terms are evaluated at most this far outside the view
/// cone (in units of its half-angle tangent), so kernels far off-screen cannot explode.
pub const LATERAL_CLAMP: f64 = 1.3;
/// Post-shaded splatting over a hull keeps at most this many inside segments per pixel; a ray
/// crossing the boundary more often is an error on the GPU.
pub const PIXEL_SEGMENTS: usize = 4;
/// Smallest footprint variance in px² (keeps the conic finite for needle-thin kernels).
pub const MIN_VARIANCE: f64 = 1e-6;

/// The ring size R of [`RINGS`] with the least work per kernel and tile: Σ E[⌈s/R⌉] ·
/// (R·(1 + `RING_SPILL`·R) + `RING_ENTRY_COST`) over the kernels' spans s (sheets). A kernel
/// of support radius r reaches about cutoff·σ·r along the ray either side of its centre, an
/// interval of L = 2r·`sheets_per_radius` sheets (cutoff·σ/Δs per radius), which touches
/// ⌊L⌋ + 1 sheets or, with probability frac(L), one more; `radii` are quantiles of the
/// supports, each standing for as many kernels. An estimate: a kernel spanning more sheets
/// than its ring is more entries, never a wrong image.
pub fn choose_ring(radii: &[f64], sheets_per_radius: f64) -> u32 {
    let work = |ring: u32| {
        let r = f64::from(ring);
        let entries = |span: f64| (span / r).ceil();
        let per_entry = r * (1.0 + RING_SPILL * r) + RING_ENTRY_COST;
        radii
            .iter()
            .map(|x| {
                let l = 2.0 * x * sheets_per_radius;
                let (f, lo) = (l.fract(), l.floor() + 1.0);
                ((1.0 - f) * entries(lo) + f * entries(lo + 1.0)) * per_entry
            })
            .sum::<f64>()
    };
    RINGS
        .into_iter()
        .min_by(|a, b| work(*a).total_cmp(&work(*b)))
        .unwrap_or(16)
}

/// The host stage `splat_setup`: everything the kernels share in one frame.
#[derive(Debug, Clone)]
pub struct SplatSetup {
    pub shading: Shading,
    pub settings: SplatSettings,
    pub camera: Camera,
    pub basis: ViewBasis,
    /// Eye relative to the frame origin.
    pub eye: DVec3,
    pub frame_origin: DVec3,
    /// Pixels per unit of tangent (perspective) or per world unit (orthographic).
    pub focal: f64,
    /// Pixel coordinates of the optical axis (W/2 − ½, H/2 − ½).
    pub centre: [f64; 2],
    /// Lateral clamp of u₀/u₂ and u₁/u₂ (perspective).
    pub lateral: [f64; 2],
    /// Kernels reaching closer than this to the eye plane are culled.
    pub near: f64,
    /// t where the first sheet starts, sheet thickness, sheet count.
    pub slab0: f64,
    /// Sheet thickness in world units (`splat.slab` times the sample spacing).
    pub slab_world: f64,
    pub slabs: u32,
    /// Gaussian σ as a fraction of the support radius.
    pub sigma: f64,
    /// Domain box (frame-relative): post-shaded sheets integrate only inside it, and only
    /// inside the hull when `hull` (the field's boundary, as the ray caster clips).
    pub box_lo: DVec3,
    pub box_hi: DVec3,
    pub hull: bool,
    /// Pixels stop compositing (and occlude) beyond this opacity.
    pub early_termination: f64,
    pub background: [f64; 3],
    pub isosurfaces: Vec<Isosurface>,
    /// `splat.split` resolved for the method.
    pub split: bool,
    /// `splat.tile` resolved for the image and sheets.
    pub tile: u32,
    /// Post-shaded: the ring size ([`RINGS`]; `splat.ring`, else [`choose_ring`]), so that a
    /// kernel is one entry per tile and per `ring` sheets it crosses; 0 otherwise (one entry
    /// per tile and sheet).
    pub ring: u32,
    /// `splat.sheet_share` resolved (with ring registers; else `Erfc`, which one entry per
    /// sheet uses).
    pub sheet_share: SheetShare,
    /// How post-shaded sheets are classified between their middles (`splat.interval`
    /// resolved; `Constant` pre-shaded). Not `Constant`: the sheets include one more, past the
    /// kernels, of value 0, so that the intervals between sheet middles cover every sheet.
    pub interval: SheetInterval,
    /// Nodes per scalar axis of the intervals' preintegration table (`render.table_resolution`,
    /// which the caller sets; [`crate::view::settings::DEFAULT_TABLE_RESOLUTION`] unset).
    pub table_resolution: usize,
    /// The intervals' table lookups take their opacity from the transfer function's integral
    /// (`render.exact_opacity`, resolved by [`SplatSetup::resolve_exact_opacity`]; false until
    /// then): [`crate::view::preintegration::PreintegrationTables::entry`], as the ray caster's.
    pub exact_opacity: bool,
    /// The transfer function's point count, which the exact opacity's scan unrolls over where
    /// it is at most [`crate::gpu_types::TF_BLOCK_POINTS`] (recorded with it).
    pub tf_points: u32,
    /// The quadrature meets kernels thinner along a ray than it serves, which it widens
    /// ([`SplatSetup::share_deviation`]).
    pub widen: bool,
    pub lighting: Lighting,
    /// A brick's frame (issue 30, the field a piece): its kd cell, frame-relative, the faces on
    /// the domain's boundary moved to infinity so that the cells of a decomposition tile all
    /// space. The frame composites only the sheets it owns ([`SplatSetup::owns`]).
    pub cell: Option<(DVec3, DVec3)>,
    /// The pixels (x0, y0, x1, y1, inclusive) and sheets (first, last) kernels are drawn on:
    /// the whole image and every sheet, but in a brick's frame only those whose rays and
    /// midpoints can meet its cell ([`brick_window`]).
    pub window: ([i32; 4], [u32; 2]),
    /// The walk cost of a pass of `splat_raster` per tile; None: [`plan::RASTER_CHUNK`]. It
    /// changes nothing in the image, only how the walks are split among passes (tests force
    /// small ones with it).
    pub raster_chunk: Option<u32>,
    /// Tile rows per dispatch of `splat_raster` (`splat.band_rows`, else
    /// [`plan::RASTER_BAND_ROWS`] until [`SplatSetup::fit_device`] widens them for a GPU).
    pub band_rows: u32,
    /// Pixels per `splat_raster` invocation where no apron needs one (`splat.pixels`, else
    /// lavapipe's: 4 post-shaded, 8 pre-shaded, until [`SplatSetup::fit_device`] sets one for a
    /// GPU).
    pub pixels: u32,
    /// Post-shaded `splat_raster` returns early from the sheet shares of a pixel outside a
    /// kernel's footprint (`splat.branches`, else none until [`SplatSetup::fit_device`] takes
    /// it on a GPU with rings of 16 sheets).
    pub branches: bool,
    /// Post-shaded `splat_raster` skips the lookups of all-zero table entries (`splat.branches`,
    /// else none until [`SplatSetup::fit_device`] allows it on a GPU), where the frame's table
    /// has some ([`SplatSetup::fit_transfer`]).
    pub clear_skip: bool,
    /// Post-shaded `splat_raster` skips the lookups of interval halves outside the pixel's part
    /// of the domain (`splat.branches`, else none until [`SplatSetup::fit_device`] takes it on a
    /// GPU where the domain is a mesh's hull).
    pub outside_skip: bool,
    /// What `splat_raster`'s walk loads one entry ahead (`splat.prefetch`, else none until
    /// [`SplatSetup::fit_device`] chooses for a GPU).
    pub prefetch: Prefetch,
}

impl SplatSetup {
    /// The setup of a frame. Errors name the scene key at fault.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        shading: Shading,
        settings: &SplatSettings,
        camera: &Camera,
        early_termination: f64,
        background: [f64; 3],
        isosurfaces: &[Isosurface],
        lighting: &Lighting,
        field: &Field,
    ) -> Result<Self, RenderError> {
        if field.reconstruction.method == crate::recon::ReconMethod::Exact {
            return Err(RenderError::Setting {
                key: "reconstruction.method",
                message: "\"exact\" is the analytic field, a ray-casting reference; splatting \
                          integrates the samples' Gaussian kernels (use \"mls\" or \"gaussian\")"
                    .into(),
            });
        }
        if shading == Shading::Pre && !isosurfaces.is_empty() && !settings.surface {
            return Err(RenderError::Setting {
                key: "transfer.isosurfaces",
                message: "pre-shaded splatting draws isosurfaces as surface splats: set \
                          splat.surface = true, or use render.method = \"splat-post\""
                    .into(),
            });
        }
        if isosurfaces.len() > MAX_ISOSURFACES {
            return Err(RenderError::Setting {
                key: "transfer.isosurfaces",
                message: format!(
                    "{} isosurfaces; at most {MAX_ISOSURFACES}",
                    isosurfaces.len()
                ),
            });
        }
        let sigma = field.reconstruction.sigma;
        if settings.cutoff * sigma > 1.0 + 1e-12 {
            return Err(RenderError::Setting {
                key: "splat.cutoff",
                message: format!(
                    "splat.cutoff × reconstruction.sigma = {} × {sigma} reaches past the kernels' \
                     supports, where the Gaussian field ends: at most 1",
                    settings.cutoff
                ),
            });
        }
        if shading == Shading::Post && settings.surface {
            return Err(RenderError::Setting {
                key: "splat.surface",
                message: "surface splats belong to pre-shaded splatting (render.method = \
                          \"splat\"); post-shaded splatting finds isosurfaces in its sheets"
                    .into(),
            });
        }
        if settings.surface && field.clip().is_some() {
            return Err(RenderError::Setting {
                key: "splat.surface",
                message: "surface splats are found on the whole field's isosurfaces, which a \
                          brick of a decomposition does not hold: draw isosurfaces with \
                          render.method = \"splat-post\" or ray casting"
                    .into(),
            });
        }
        let basis = camera.basis().map_err(RenderError::Camera)?;
        let frame_origin = field.frame_origin;
        let eye = DVec3::from(camera.eye) - frame_origin;
        let (w, h) = (f64::from(camera.width), f64::from(camera.height));
        let (box_lo, box_hi) = field.bounds();
        // Kernels reach no further than their supports (ρ = 1 ≥ cutoff·σ, checked above).
        let (lo, hi) = field.support_box();
        let diagonal = (hi - lo).length();
        let (focal, lateral, near, t_min, t_max) = match camera.projection {
            Projection::Perspective { fov_y_degrees } => {
                let tan = (fov_y_degrees.to_radians() * 0.5).tan();
                let near = 1e-4 * diagonal;
                let (t_min, t_max) = depth_range(camera, &basis, eye, (lo, hi));
                (
                    h / (2.0 * tan),
                    [LATERAL_CLAMP * tan * w / h, LATERAL_CLAMP * tan],
                    near,
                    t_min.max(near),
                    t_max,
                )
            }
            Projection::Orthographic { view_height } => {
                let (a, b) = depth_range(camera, &basis, eye, (lo, hi));
                (h / view_height, [f64::MAX; 2], 0.0, a.max(0.0), b)
            }
        };
        let slab = settings.slab_spacings * field.min_spacing();
        let interval = match (settings.interval, shading) {
            (Some(i), Shading::Post) => i,
            (None, Shading::Post) => SheetInterval::Hermite,
            (None, Shading::Pre) => SheetInterval::Constant,
            (Some(i), Shading::Pre) => {
                return Err(RenderError::Setting {
                    key: "splat.interval",
                    message: format!(
                        "\"{}\": intervals between sheets are how post-shaded splatting \
                         (render.method = \"splat-post\") classifies its sheets; pre-shaded \
                         splatting classifies each kernel",
                        i.name()
                    ),
                });
            }
        };
        // Between sheet middles (not Constant), the last interval ends at the last sheet's
        // middle: one sheet more, past the kernels' support box (so of value 0), lets the
        // intervals cover every sheet whole.
        let extra = if interval == SheetInterval::Constant {
            0.0
        } else {
            1.0
        };
        let count = ((t_max - t_min) / slab).ceil().max(1.0) + extra;
        if count > f64::from(MAX_SLABS) || !count.is_finite() {
            return Err(RenderError::Setting {
                key: "splat.slab",
                message: format!(
                    "{} sheets of {slab:.4e} would cover the volume's depth {:.4e}; at most \
                     {MAX_SLABS} are allowed: raise splat.slab",
                    count,
                    t_max - t_min
                ),
            });
        }
        if shading == Shading::Post && settings.split == Some(false) {
            return Err(RenderError::Setting {
                key: "splat.split",
                message: "post-shaded splatting classifies sheets of the field, so every kernel \
                          is split among the sheets it crosses: splat.split = false belongs to \
                          pre-shaded splatting (render.method = \"splat\")"
                    .into(),
            });
        }
        // Post-shaded isosurfaces add a one-pixel apron: 32² + apron would pass the 1024
        // invocations a workgroup may have.
        let apron = shading == Shading::Post && !isosurfaces.is_empty();
        let buckets = |t: u32| {
            u64::from(camera.width.div_ceil(t))
                * u64::from(camera.height.div_ceil(t))
                * count as u64
        };
        let allowed = |t: u32| TILE_SIZES.contains(&t) && !(t == 32 && apron);
        let tile = match settings.tile {
            Some(t) if allowed(t) => t,
            Some(t) => {
                return Err(RenderError::Setting {
                    key: "splat.tile",
                    message: format!(
                        "{t}: one of 8, 16 or 32 pixels (post-shaded isosurfaces: 8 or 16, since \
                         a tile and its one-pixel apron are one workgroup of at most 1024 \
                         invocations)"
                    ),
                });
            }
            // The smallest tile whose buckets fit (small tiles measured fastest on lavapipe).
            None => TILE_SIZES
                .into_iter()
                .filter(|&t| allowed(t))
                .find(|&t| buckets(t) <= MAX_BUCKETS)
                .unwrap_or(if apron { 16 } else { 32 }),
        };
        if buckets(tile) > MAX_BUCKETS {
            return Err(RenderError::Setting {
                key: "splat.slab",
                message: format!(
                    "{} image tiles of {tile}² pixels × {count} sheets are {} (tile, sheet) \
                     buckets; at most {MAX_BUCKETS}: raise splat.slab or splat.tile, or take a \
                     smaller image",
                    buckets(tile) / count as u64,
                    buckets(tile)
                ),
            });
        }
        let post = shading == Shading::Post;
        if let (Some(r), false) = (settings.ring, post) {
            return Err(RenderError::Setting {
                key: "splat.ring",
                message: format!(
                    "{r}: ring registers hold the sheets ahead of post-shaded splatting \
                     (render.method = \"splat-post\")"
                ),
            });
        }
        // The thickest sheet any kernel meets, in its own deviations along the ray: a ray's
        // conditional deviation is at least the kernel's shortest one, σ × the support's
        // shortest half axis. And the share of kernels thinner than the quadrature serves.
        let thickest = slab / (sigma * field.thinnest_support());
        let radii = field.radius_quantiles();
        let thin = radii
            .iter()
            .filter(|&&r| sigma * r * QUADRATURE_MAX_SHEET < slab)
            .count() as f64
            / radii.len().max(1) as f64;
        let sheet_share = match settings.sheet_share {
            Some(rule) if rule.sampled() && !post => {
                return Err(RenderError::Setting {
                    key: "splat.sheet_share",
                    message: "\"quadrature\" and \"midpoint\" share kernels out to the sheets of \
                              post-shaded splatting (render.method = \"splat-post\"); split \
                              pre-shaded kernels use \"erfc\""
                        .into(),
                });
            }
            Some(rule) => rule,
            None if post && thin <= WIDEN_MAX_SHARE => SheetShare::Midpoint,
            None => SheetShare::Erfc,
        };
        let ring = match (post, settings.ring) {
            (false, _) => 0,
            (true, Some(r)) => r,
            (true, None) => choose_ring(field.radius_quantiles(), settings.cutoff * sigma / slab),
        };
        let setup = Self {
            shading,
            settings: *settings,
            camera: *camera,
            basis,
            eye,
            frame_origin,
            focal,
            centre: [0.5 * w - 0.5, 0.5 * h - 0.5],
            lateral,
            near,
            slab0: t_min,
            slab_world: slab,
            slabs: count as u32,
            sigma: field.reconstruction.sigma,
            box_lo,
            box_hi,
            hull: field.hull.is_some(),
            early_termination,
            background,
            isosurfaces: isosurfaces.to_vec(),
            split: settings.split.unwrap_or(shading == Shading::Post),
            tile,
            ring,
            sheet_share,
            interval,
            table_resolution: crate::view::settings::DEFAULT_TABLE_RESOLUTION,
            exact_opacity: false,
            tf_points: 0,
            widen: post && ring > 0 && sheet_share.sampled() && thickest > QUADRATURE_MAX_SHEET,
            lighting: *lighting,
            cell: field.clip().map(|clip| brick_cell(clip, (box_lo, box_hi))),
            window: ([0; 4], [0; 2]),
            raster_chunk: None,
            band_rows: settings.band_rows.unwrap_or(plan::RASTER_BAND_ROWS),
            pixels: settings.pixels.unwrap_or(if post { 4 } else { 8 }),
            branches: post && settings.branches.unwrap_or(false),
            clear_skip: post && settings.branches.unwrap_or(false),
            outside_skip: post
                && interval != SheetInterval::Constant
                && settings.branches.unwrap_or(false),
            prefetch: settings.prefetch.unwrap_or(Prefetch::None),
        };
        let window = brick_window(&setup, (lo, hi), setup.reach());
        Ok(Self { window, ..setup })
    }

    /// What compositing a sheet reads around it: the pixels either side (post-shaded
    /// isosurfaces' lateral gradients: one, and one for rounding) and the sheets before and
    /// after (sheet j reads j − 2 ..= j + 1 for isosurface gradients and Hermite intervals,
    /// j − 1 for linear ones; a sheet more each way for rounding).
    pub fn reach(&self) -> (i32, [i64; 2]) {
        let post = self.shading == Shading::Post;
        let pixels = if post && !self.isosurfaces.is_empty() {
            2
        } else {
            1
        };
        let sheets =
            if post && (!self.isosurfaces.is_empty() || self.interval != SheetInterval::Constant) {
                [2, 3]
            } else {
                [1, 1]
            };
        (pixels, sheets)
    }

    /// The preintegration table lengths post-shaded intervals need: half a sheet (each
    /// interval between sheet middles is composited as two halves, which a domain boundary
    /// may clip); none with `Constant` sheets.
    pub fn table_lengths(&self) -> Vec<f64> {
        if self.interval == SheetInterval::Constant {
            Vec::new()
        } else {
            vec![0.5 * self.slab_world]
        }
    }

    /// The scalar range of the intervals' table: the data's ([`crate::field::scalar_range`]),
    /// 0, which the Gaussian sum takes away from the kernels, and the transfer function's
    /// points. The sum is not bounded by the data: where kernels overlap it passes their values,
    /// and a table clamped to the data's range (with its 5% margin) classified those values as
    /// the range's end, a bias that thinner sheets did not remove (2·10⁻³ RMSE on the
    /// tetrahedral torus of the tests). Beyond the transfer function's points its values are
    /// constant, so clamping there changes only where a segment crosses the last point.
    /// Where 0 lies inside, it is made a node of the table's `table_resolution`: between
    /// nodes the bilinear lookup would give the field's 0 the extinction of values beside it,
    /// a fog over all empty space (2.6·10⁻³ opacity over a ray inside a grid's box).
    pub fn table_range(&self, field: &Field, tf: &TransferFunction) -> (f64, f64) {
        let (lo, hi) = crate::field::scalar_range(field);
        let points = tf.points();
        let first = points.first().map_or(lo, |p| p[0]);
        let last = points.last().map_or(hi, |p| p[0]);
        let (lo, hi) = (lo.min(0.0).min(first), hi.max(0.0).max(last));
        let cells = self.table_resolution.saturating_sub(1) as f64;
        if !(lo < 0.0 && hi > 0.0 && cells >= 2.0) {
            return (lo, hi);
        }
        // One cell wider, 0 on the node at or below lo's.
        let step = (hi - lo) / (cells - 1.0);
        let lo = -(-lo / step).ceil() * step;
        (lo, lo + cells * step)
    }

    /// Whether sheet k of the pixel ray (o, d) belongs to this frame: always, except in a
    /// brick's frame, which owns the sheet when the sheet's midpoint on the ray lies in its cell
    /// (lo ≤ x < hi on every axis, the kd tree's rule for a point on a plane). Every sheet of
    /// every pixel then belongs to exactly one brick, composited whole there: a kernel's share
    /// of a sheet is counted once, and the bricks composited in visibility order are the
    /// undivided frame's sheets in the undivided frame's order.
    pub fn owns(&self, (o, d): (DVec3, DVec3), k: u32) -> bool {
        let Some((lo, hi)) = self.cell else {
            return true;
        };
        let m = self.slab0 + (f64::from(k) + 0.5) * self.slab_world;
        let x = o + m * d;
        x.cmpge(lo).all() && x.cmplt(hi).all()
    }

    /// Whether the camera is orthographic.
    pub fn orthographic(&self) -> bool {
        matches!(self.camera.projection, Projection::Orthographic { .. })
    }

    /// Whether footprints are per-pixel ray integrals (perspective with `splat.footprint =
    /// "exact"`); otherwise affine ([EWA] §4, exact for an orthographic camera).
    pub fn exact_footprints(&self) -> bool {
        self.settings.exact && !self.orthographic()
    }

    /// An upper bound of a frame's per-pixel evaluations once `splat_project` counted
    /// `entries` (kernel, tile, sheet) entries: `splat_raster` evaluates each entry on every
    /// invocation of its tile's workgroup, and composites every pixel once per sheet (plus the
    /// closing step of post-shading). Footprint evaluations and MLS evaluations cost about the
    /// same on lavapipe, so both renderers share [`crate::view::WORK_BUDGET`].
    pub fn work_bound(&self, entries: u64) -> f64 {
        let pixels = f64::from(self.camera.width) * f64::from(self.camera.height);
        let steps = f64::from(self.slabs) + f64::from(u8::from(self.shading == Shading::Post));
        entries as f64 * f64::from(self.group_size()) + steps * pixels
    }

    /// The most binned entries whose [`SplatSetup::work_bound`] stays within `budget`
    /// (`u32::MAX` without one): what a recorded frame's `splat_plan` lets through.
    pub fn max_entries(&self, budget: Option<f64>) -> u32 {
        match budget {
            Some(b) => ((b - self.work_bound(0)) / f64::from(self.group_size()))
                .floor()
                .clamp(0.0, f64::from(u32::MAX)) as u32,
            None => u32::MAX,
        }
    }

    /// Refuses a frame whose [`SplatSetup::work_bound`] exceeds `budget`: with `entries` = 0
    /// before any GPU work (the sheets alone), then with the binned count before the
    /// accumulation.
    pub fn check_budget(&self, entries: u64, budget: f64) -> Result<(), RenderError> {
        let planned = self.work_bound(entries);
        if planned <= budget {
            return Ok(());
        }
        Err(RenderError::Budget {
            planned,
            unit: "footprint-pixel evaluations",
            budget,
            hint: format!(
                "{} sheets of {} × {} pixels and {entries} binned (tile, sheet) footprints; \
                 raise splat.slab or take a smaller image",
                self.slabs, self.camera.width, self.camera.height
            ),
        })
    }

    /// The least deviation along a ray at which the quadrature shares a kernel out, where some
    /// kernel is thinner ([`SplatSetup::widen`]): Δs / [`QUADRATURE_MAX_SHEET`]. A thinner
    /// kernel keeps its lateral footprint and its line integral, and its depth profile through
    /// a pixel is spread to this deviation, over the sheets around its mean: a low-pass in
    /// depth at the sheets' resolution, as [EWA]'s resampling filter is one on screen at the
    /// pixels'. It vanishes as the sheets get thinner, and "erfc" shares every kernel exactly.
    pub fn share_deviation(&self) -> Option<f64> {
        self.widen.then(|| self.slab_world / QUADRATURE_MAX_SHEET)
    }

    /// Sheet k covers t in [slab0 + k·Δs, slab0 + (k+1)·Δs].
    pub fn slab_bounds(&self, k: u32) -> (f64, f64) {
        let a = self.slab0 + f64::from(k) * self.slab_world;
        (a, a + self.slab_world)
    }

    /// The apron of a tile: post-shaded isosurfaces need every pixel's neighbours in the
    /// sheet for their gradients, so a tile also splats the ring of pixels around it.
    pub fn apron(&self) -> u32 {
        u32::from(self.shading == Shading::Post && !self.isosurfaces.is_empty())
    }

    /// Pixels per `splat_raster` invocation, a column of them (each splat record an
    /// invocation loads serves them all): one where the apron's lateral exchange needs a
    /// pixel per invocation, else `pixels`.
    pub fn raster_pixels(&self) -> u32 {
        if self.apron() > 0 { 1 } else { self.pixels }
    }

    /// Fits `splat_raster`'s dispatches to the device where `splat.band_rows` and
    /// `splat.pixels` are unset. A CPU device (`cpu`: lavapipe) keeps bands of
    /// [`plan::RASTER_BAND_ROWS`] rows and four pixels per invocation post-shaded, eight
    /// pre-shaded (a tile's column each: 8–12% faster there than four, post-shaded 12% slower),
    /// which measured fastest there; a GPU takes bands of at least [`GPU_BAND_TILES`] tiles and one pixel per
    /// invocation post-shaded, two pre-shaded, and post-shaded it branches around exact zeros:
    /// the skip of all-zero table lookups ([`SplatSetup::clear_skip`], kept where the table has
    /// some by [`SplatSetup::fit_transfer`]) and, with rings of 16 sheets, the early return
    /// from a footprint's shares ([`SplatSetup::branches`]). On an H200 at 512² the bands made
    /// post-shaded splatting of 68 921 points 28× faster than lavapipe's shape (2.34 against
    /// 65.4 ms; BENCHMARKS.md, "Splatting on a GPU needs wide bands"). There ("The H200 a
    /// third time"), two pixels pre-shaded took 20–27% off its frames; the branches 14% off
    /// the post-shaded points' (ring 16), and the early return alone 8%, while on the torus
    /// (ring 8) it cost 2–3%; the skip of lookups outside the domain 3.5% off the torus's (a
    /// hull), none on the points'. The walk loads the next entry and its record one step ahead
    /// ([`Prefetch::Records`]): 6–13% off pre-shaded frames and 15% off the torus's post-shaded
    /// ones; with rings of 16 sheets the record's registers cost more than they save (+2% on
    /// the points) and the next entry alone is loaded ahead ([`Prefetch::List`]: −6%)
    /// (BENCHMARKS.md, "The H200 a fourth time"). Bands and prefetching change no pixel;
    /// pixels per invocation and branches compile another variant, equal within f32 rounding
    /// (the compiler's fused multiply-adds).
    pub fn fit_device(&mut self, cpu: bool) {
        if cpu {
            return;
        }
        if self.settings.band_rows.is_none() {
            let (tiles_x, tiles_y) = self.tiles();
            self.band_rows = GPU_BAND_TILES.div_ceil(tiles_x).clamp(1, tiles_y.max(1));
        }
        let post = self.shading == Shading::Post;
        if self.settings.pixels.is_none() {
            self.pixels = if post { 1 } else { 2 };
        }
        if self.settings.branches.is_none() {
            self.branches = post && self.ring == 16;
            self.clear_skip = post;
            self.outside_skip = post && self.hull && self.interval != SheetInterval::Constant;
        }
        if self.settings.prefetch.is_none() {
            self.prefetch = if post && self.ring == 16 {
                Prefetch::List
            } else {
                Prefetch::Records
            };
        }
    }

    /// Keeps the skip of all-zero table entries ([`SplatSetup::clear_skip`]) where it can
    /// fire: intervals read from the table, and some lookup of the frame's table clear
    /// ([`crate::view::table_occupancy::clear_somewhere`]). Its test costs where it never
    /// fires: on an H200 it took 4.5% more time on the torus, whose function has extinction
    /// everywhere, and 9% less on the ML points (BENCHMARKS.md, "The H200 a third time").
    pub fn fit_transfer(&mut self, field: &Field, tf: &TransferFunction) {
        self.clear_skip = self.clear_skip
            && self.interval != SheetInterval::Constant
            && crate::view::table_occupancy::clear_somewhere(
                tf,
                self.table_range(field, tf),
                self.table_resolution,
            );
    }

    /// Decides `render.exact_opacity` for a frame of `tf` over `field`: only intervals between
    /// sheet middles read a table (post-shaded, not constant sheets; pre-shaded frames' are
    /// constant), and there [`ExactOpacity::resolve`] decides, "auto" by the data's range as
    /// for ray casting. A thin peak's opacity errs in a table by a cell's square over its
    /// width here too: the 0.002 peak's post-shaded frames at 512² and 2048² tables differed by
    /// 5e-2 (p99), the tables were 3e-3 apart at 2048² and 4096² (BENCHMARKS.md).
    pub fn resolve_exact_opacity(
        &mut self,
        mode: ExactOpacity,
        field: &Field,
        tf: &TransferFunction,
    ) {
        self.exact_opacity = self.interval != SheetInterval::Constant
            && mode.resolve(tf, crate::field::scalar_range(field));
        self.tf_points = tf.points().len() as u32;
    }

    /// Invocations of one `splat_raster` workgroup: the tile and its apron.
    pub fn group_size(&self) -> u32 {
        let e = self.tile + 2 * self.apron();
        e * e
    }

    /// Tiles across and down the image.
    pub fn tiles(&self) -> (u32, u32) {
        let t = self.tile;
        (
            self.camera.width.div_ceil(t),
            self.camera.height.div_ceil(t),
        )
    }

    /// (tile, sheet) buckets of the counting sort.
    pub fn buckets(&self) -> u64 {
        let (x, y) = self.tiles();
        u64::from(x) * u64::from(y) * u64::from(self.slabs)
    }

    /// The inclusive tile range [tx0, ty0, tx1, ty1] whose pixels or aprons meet a pixel box.
    pub fn tile_rect(&self, bbox: [i32; 4]) -> [u32; 4] {
        let t = self.tile as i32;
        let a = self.apron() as i32;
        let (tx, ty) = self.tiles();
        let lo = |v: i32| ((v - a).max(0) / t) as u32;
        [
            lo(bbox[0]),
            lo(bbox[1]),
            (((bbox[2] + a) / t) as u32).min(tx - 1),
            (((bbox[3] + a) / t) as u32).min(ty - 1),
        ]
    }
}

/// A brick's kd cell from its box `clip` and the domain's box `domain`: a face on the domain's
/// boundary is at infinity (the kd tree's root box is the domain's, so a brick's outer faces
/// equal the domain's exactly).
pub fn brick_cell(clip: (DVec3, DVec3), domain: (DVec3, DVec3)) -> (DVec3, DVec3) {
    let (lo, hi) = clip;
    let lo = DVec3::select(lo.cmple(domain.0), DVec3::NEG_INFINITY, lo);
    let hi = DVec3::select(hi.cmpge(domain.1), DVec3::INFINITY, hi);
    (lo, hi)
}

/// The range of t, the distance along a ray (perspective: from the eye; orthographic: from the
/// image plane), at which `camera`'s rays meet the frame-relative box (lo, hi).
fn depth_range(
    camera: &Camera,
    basis: &ViewBasis,
    eye: DVec3,
    (lo, hi): (DVec3, DVec3),
) -> (f64, f64) {
    let corners = (0..8).map(|c| {
        DVec3::new(
            if c & 1 == 0 { lo.x } else { hi.x },
            if c & 2 == 0 { lo.y } else { hi.y },
            if c & 4 == 0 { lo.z } else { hi.z },
        )
    });
    match camera.projection {
        Projection::Perspective { .. } => (
            (eye.clamp(lo, hi) - eye).length(),
            corners.map(|c| (c - eye).length()).fold(0.0, f64::max),
        ),
        Projection::Orthographic { .. } => corners
            .map(|c| (c - eye).dot(basis.forward))
            .fold((f64::MAX, f64::MIN), |(a, b), d| (a.min(d), b.max(d))),
    }
}

/// What a frame draws kernels on (`SplatSetup::window`): all of the image and its sheets, but
/// for a brick only the pixels whose rays meet its cell and the sheets whose midpoints can lie
/// in it — within the supports' box widened by a sheet, since a sheet whose midpoint lies
/// outside that box holds no kernel — widened by `apron` (pixels, sheets below and above) for
/// f32 rounding and for what post-shaded isosurfaces read around a sheet they own. A kernel's
/// entries outside it could only add to sheets other bricks own: it draws none there.
fn brick_window(
    setup: &SplatSetup,
    (slo, shi): (DVec3, DVec3),
    (pixels, [below, above]): (i32, [i64; 2]),
) -> ([i32; 4], [u32; 2]) {
    let (w, h) = (setup.camera.width as i32, setup.camera.height as i32);
    let last = setup.slabs.saturating_sub(1);
    let Some((clo, chi)) = setup.cell else {
        return ([0, 0, w - 1, h - 1], [0, last]);
    };
    let pad = DVec3::splat(setup.slab_world);
    let (lo, hi) = (clo.max(slo - pad), chi.min(shi + pad));
    if lo.cmpgt(hi).any() {
        return ([0, 0, -1, -1], [1, 0]);
    }
    let p = setup
        .camera
        .pixel_box(&setup.basis, setup.frame_origin, (lo, hi))
        .map(|v| v as i32);
    let (t0, t1) = depth_range(&setup.camera, &setup.basis, setup.eye, (lo, hi));
    let sheet = |t: f64| ((t - setup.slab0) / setup.slab_world).floor() as i64;
    let (k0, k1) = (sheet(t0) - below, sheet(t1) + above);
    (
        [
            (p[0] - pixels).max(0),
            (p[1] - pixels).max(0),
            (p[2] + pixels).min(w - 1),
            (p[3] + pixels).min(h - 1),
        ],
        [
            k0.clamp(0, i64::from(last)) as u32,
            k1.clamp(0, i64::from(last)) as u32,
        ],
    )
}

/// What a frame did with its kernels (`--stats`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SplatCounts {
    /// Kernels that went through `splat_project`.
    pub projected: u64,
    /// Culled: behind the eye or reaching the near plane.
    pub culled_near: u64,
    /// Culled: footprint or depth range outside the image or the sheets.
    pub culled_outside: u64,
    /// Culled: degenerate covariance (det ≤ 0 after the guards).
    pub culled_degenerate: u64,
    /// Culled: zero weight (transparent or zero-valued), including those left out.
    pub culled_empty: u64,
    /// Pre-shaded on the GPU: volume kernels the transfer function makes transparent, left out
    /// before projection (`GpuKernels::upload`). Counted in `projected` and `culled_empty` too,
    /// so that those keep their meaning (every kernel; every transparent one); 0 on the CPU
    /// twin, which projects and culls them.
    pub left_out: u64,
    /// Binned entries (kernel × image tile × sheet).
    pub entries: u64,
    /// Entries never walked: their tile had stopped, every pixel in it opaque.
    pub skipped_occluded: u64,
    /// Entries a tile walked (rasterized into its sheet).
    pub accumulated: u64,
    /// Kernels with more than `MAX_KERNEL_ENTRIES` entries (the frame fails).
    pub oversized: u64,
    /// Pixels (with apron pixels) whose footprint `splat_raster` evaluated: inside the
    /// kernel's pixel box and, pre-shaded, not yet opaque.
    pub evaluated: u64,
    /// Evaluations that added to a pixel's sheet in registers (footprint ≠ 0).
    pub contributions: u64,
    /// (tile, sheet) buckets that `splat_order` could not put in kernel order (llvmpipe's loop
    /// limit): their sheets are right but summed in an order that can change between runs, so
    /// the frame is not reproducible to the bit. 0 on the CPU twin, whose buckets are built in
    /// kernel order.
    pub unordered: u64,
    /// Buckets of more entries than `splat_order`'s insertion sort takes, heapsorted by its
    /// second pass (0 on the CPU twin).
    pub large_buckets: u64,
    /// Tile walks continued in a later pass of `splat_raster` (a tile of more entries than a
    /// dispatch may loop over on llvmpipe), per pass; 0 on the CPU twin.
    pub resumed: u64,
    /// Post-shaded interval halves whose table lookups `splat_raster` skipped, every entry
    /// they read zero (`splat.branches`, [`SplatSetup::clear_skip`]); 0 on the CPU twin, which
    /// looks every half up.
    pub clear_skipped: u64,
}

impl SplatCounts {
    /// Counts `n` kernels left out as transparent ([`SplatCounts::left_out`]).
    pub fn add_left_out(&mut self, n: u64) {
        self.left_out += n;
        self.projected += n;
        self.culled_empty += n;
    }

    /// Kernels that survived projection.
    pub fn kept(&self) -> u64 {
        self.projected
            - self.culled_near
            - self.culled_outside
            - self.culled_degenerate
            - self.culled_empty
            - self.oversized
    }
}
