//! Structs shared with GLSL, and the binding numbers of every kernel.
//!
//! Each struct is `#[repr(C)]` + `Pod` with explicit padding, a size assertion, and a twin of the
//! same name in `glsl/common/types.glsl` (std430 layout). The test `tests/layout.rs` runs
//! `glsl/probe/layout_probe.comp`, which writes every field of every twin with a distinct value, and
//! checks that each lands in the Rust field of the same name.
//!
//! Binding numbers exist only here: [`binding_defines`] hands them to shaderc as `BINDING_*`
//! macros, so GLSL never spells a number.

use bytemuck::{Pod, Zeroable};

/// Descriptor-set-0 binding numbers, shared by all kernels.
pub mod binding {
    /// `RenderParams` (read-only).
    pub const PARAMS: u32 = 0;
    /// Regular-grid scalars, x fastest (read-only).
    pub const GRID: u32 = 1;
    /// `Sample` array for the octree path (read-only).
    pub const SAMPLES: u32 = 2;
    /// Octree nodes as `uvec4(child, begin, count, 0)` (read-only).
    pub const NODES: u32 = 3;
    /// Octree leaf reference list (read-only).
    pub const INDICES: u32 = 4;
    /// `TfPoint` array (read-only).
    pub const TRANSFER: u32 = 5;
    /// Output pixels, `vec4` per pixel.
    pub const IMAGE: u32 = 6;
    /// Per-pixel (or per-point) count of MLS evaluations.
    pub const COUNTS: u32 = 7;
    /// Evaluation points, `vec4` each (mls_eval).
    pub const POINTS: u32 = 8;
    /// `MlsOut` per point (mls_eval).
    pub const RESULTS: u32 = 9;
    /// Probe output (probe_fma, layout_probe).
    pub const PROBE: u32 = 10;
    /// Preintegration tables, `vec4` entries (read-only).
    pub const PREINT: u32 = 11;
    /// `IsoSurface` array (read-only).
    pub const ISO: u32 = 12;
    /// Per-pixel ray state between chunks of raycast.comp: the last knot, `vec4` per pixel.
    pub const RAY_STATE: u32 = 13;
    /// Hull BVH nodes, two rgba32ui texels each: corner bits and first/count (read-only).
    pub const HULL_NODES: u32 = 14;
    /// Hull triangles, three rgba32f texels (vertices) each, in BVH leaf order (read-only).
    pub const HULL_TRIS: u32 = 15;
    /// Splatting: the kernels, one `Sample` each with its volume in `metric_off.z`, as three
    /// rgba32f texels (read-only). Splatting's large buffers are all read and written through
    /// texel views: bounded by maxTexelBufferElements rather than a storage binding, and read
    /// by one gather per 8 lanes on llvmpipe where a storage-buffer read is a loop over them.
    pub const SPLAT_KERNELS: u32 = 16;
    /// Splatting: one `Splat` per kernel, seven rgba32f texels (written by splat_project; the
    /// integer texels through SPLAT_WORDS).
    pub const SPLATS: u32 = 17;
    /// Splatting: entries per (tile, sheet) bucket (atomic counts of splat_project).
    pub const BUCKET_COUNTS: u32 = 18;
    /// Splatting: first entry of each bucket in the list, one more for the total (splat_scan).
    pub const BUCKET_OFFSETS: u32 = 19;
    /// Splatting: entries written so far per bucket (atomic cursors of splat_bin).
    pub const BUCKET_CURSORS: u32 = 20;
    /// Splatting: the sorted entries, (splat, sheet) each as one `rg32ui` texel, bucket after
    /// bucket.
    pub const SPLAT_LIST: u32 = 21;
    /// Splatting: splat_scan's block sums.
    pub const SCAN_SUMS: u32 = 22;
    /// Splatting: the same buffer as SPLATS through an `rgba32ui` view, for the `Splat`s'
    /// integer texels (a float view could flush their bits as denormals).
    pub const SPLAT_WORDS: u32 = 23;
    /// Splatting: `SplatCounts` counters (atomic).
    pub const SPLAT_STATS: u32 = 24;
    /// Post-shaded splatting over a hull: each pixel's inside segments, `SPLAT_SEGMENTS` ×
    /// `vec2(t_in, t_out)` per pixel (written by splat_segments).
    pub const PIXEL_SEGMENTS: u32 = 25;
    /// probe_memory: the words it reads, as a storage buffer.
    pub const PROBE_SOURCE: u32 = 26;
    /// probe_memory: the same words through a `r32ui` texel-buffer view.
    pub const PROBE_TEXELS: u32 = 27;
    /// The fast path's fine grid, (f, ∇f) per point, as the ray caster reads it (read-only).
    pub const RESAMPLED: u32 = 28;
    /// The same buffer as recon_resample writes it.
    pub const RESAMPLE_TARGET: u32 = 29;
    /// Empty-space skipping: the fast field's range per block, `vec4(min, max, 0, 0)`.
    pub const SKIP_BLOCKS: u32 = 30;
    /// Empty-space skipping: the frame's skip table (`SkipTable::gpu_words`).
    pub const SKIP_TABLE: u32 = 31;
    /// The transfer function's `TfPoint`s as rgba32f texels (two per point), for the Hermite
    /// criterion's loop over its pieces (one gather per read instead of a per-lane loop).
    pub const TRANSFER_TEXELS: u32 = 32;
    /// Per pixel, `vec4(ray length skipped, evaluations saved, ray length inside the domain,
    /// the adaptive criterion's error estimate)`: written by raycast.comp's skipping variants
    /// (xyz) and its adaptive ones (w), bound where either is compiled in.
    pub const RAY_STATS: u32 = 33;
    /// The grid of 8- or 16-bit samples, kept at their size (`data::Values`), as `r32ui`
    /// words (read-only): the twin of GRID for `GRID_BITS` < 32.
    pub const GRID_WORDS: u32 = 34;
    /// Splatting: BUCKET_OFFSETS as `r32ui` texels, as splat_raster reads them.
    pub const OFFSET_TEXELS: u32 = 35;
    /// A recorded frame's pixels packed into the target image's format (`target_pack`):
    /// `u32` words, as many per pixel as `vk::TargetFormat::bytes` / 4.
    pub const TARGET_PACKED: u32 = 36;
    /// A recorded frame's indirect dispatch arguments, `uvec4(x, y, z, 0)` each: one per band
    /// (`raycast_next`), or splat_bin's, splat_order's and splat_raster's (`splat_plan`).
    pub const DISPATCH_ARGS: u32 = 37;
    /// A paged fine grid's page table (`recon::pages`): the slot of each page, as `r32ui`
    /// texels (read-only).
    pub const RESAMPLE_PAGES: u32 = 38;
    /// A paged fine grid's slots as recon_resample fills them: `uvec2` (page, 0), or
    /// (`SLOT_CONSTANT`, the value's bits) for a shared slot.
    pub const RESAMPLE_SLOTS: u32 = 39;
    /// Each pixel's inside segments of a mesh's hull for the frame's camera, as rgba32f texels
    /// (`raycast::segments`): written by the ray casters that walk the hull and keep what they
    /// found (`HULL_CACHED` 2), read by those that read it instead (`HULL_CACHED` 1).
    pub const RAY_SEGMENTS: u32 = 40;
    /// Splatting: where `splat_raster` leaves a tile walk that one dispatch could not finish
    /// (llvmpipe's loop limit) for the next pass of its band: per tile of the band and
    /// invocation a tag, the walk's position and its pixels' registers
    /// (`SplatVariant::raster_tile_words`).
    pub const SPLAT_RASTER_STATE: u32 = 41;

    /// How kernels read a binding: the grid and the octree's samples, nodes and references
    /// through texel-buffer views (one AVX2 gather per 8 lanes on llvmpipe instead of a per-lane
    /// loop; LAVAPIPE.md "Read paths"), the parameters as a uniform buffer (cheaper than a
    /// storage-buffer read on llvmpipe), everything else as storage buffers.
    pub fn kind(b: u32) -> crate::vk::BindingKind {
        use crate::vk::BindingKind;
        match b {
            GRID | RESAMPLED | RESAMPLE_TARGET | PREINT | SKIP_BLOCKS | TRANSFER_TEXELS
            | SPLAT_KERNELS | SPLATS | HULL_TRIS | RAY_SEGMENTS => BindingKind::TexelRgba32Float,
            // The octree's samples or records as their bits: packed records are not floats.
            SAMPLES | NODES | SPLAT_WORDS | HULL_NODES => BindingKind::TexelRgba32Uint,
            SPLAT_LIST => BindingKind::TexelRg32Uint,
            INDICES | PROBE_TEXELS | SKIP_TABLE | GRID_WORDS | OFFSET_TEXELS | RESAMPLE_PAGES => {
                BindingKind::TexelR32Uint
            }
            PARAMS => BindingKind::Uniform,
            _ => BindingKind::Storage,
        }
    }

    /// Every binding with its macro name.
    pub const ALL: [(&str, u32); 42] = [
        ("BINDING_PARAMS", PARAMS),
        ("BINDING_GRID", GRID),
        ("BINDING_SAMPLES", SAMPLES),
        ("BINDING_NODES", NODES),
        ("BINDING_INDICES", INDICES),
        ("BINDING_TRANSFER", TRANSFER),
        ("BINDING_IMAGE", IMAGE),
        ("BINDING_COUNTS", COUNTS),
        ("BINDING_POINTS", POINTS),
        ("BINDING_RESULTS", RESULTS),
        ("BINDING_PROBE", PROBE),
        ("BINDING_PREINT", PREINT),
        ("BINDING_ISO", ISO),
        ("BINDING_RAY_STATE", RAY_STATE),
        ("BINDING_HULL_NODES", HULL_NODES),
        ("BINDING_HULL_TRIS", HULL_TRIS),
        ("BINDING_SPLAT_KERNELS", SPLAT_KERNELS),
        ("BINDING_SPLATS", SPLATS),
        ("BINDING_BUCKET_COUNTS", BUCKET_COUNTS),
        ("BINDING_BUCKET_OFFSETS", BUCKET_OFFSETS),
        ("BINDING_BUCKET_CURSORS", BUCKET_CURSORS),
        ("BINDING_SPLAT_LIST", SPLAT_LIST),
        ("BINDING_SCAN_SUMS", SCAN_SUMS),
        ("BINDING_SPLAT_WORDS", SPLAT_WORDS),
        ("BINDING_SPLAT_STATS", SPLAT_STATS),
        ("BINDING_PIXEL_SEGMENTS", PIXEL_SEGMENTS),
        ("BINDING_PROBE_SOURCE", PROBE_SOURCE),
        ("BINDING_PROBE_TEXELS", PROBE_TEXELS),
        ("BINDING_RESAMPLED", RESAMPLED),
        ("BINDING_RESAMPLE_TARGET", RESAMPLE_TARGET),
        ("BINDING_SKIP_BLOCKS", SKIP_BLOCKS),
        ("BINDING_SKIP_TABLE", SKIP_TABLE),
        ("BINDING_RAY_STATS", RAY_STATS),
        ("BINDING_TRANSFER_TEXELS", TRANSFER_TEXELS),
        ("BINDING_GRID_WORDS", GRID_WORDS),
        ("BINDING_OFFSET_TEXELS", OFFSET_TEXELS),
        ("BINDING_TARGET_PACKED", TARGET_PACKED),
        ("BINDING_DISPATCH_ARGS", DISPATCH_ARGS),
        ("BINDING_RESAMPLE_PAGES", RESAMPLE_PAGES),
        ("BINDING_RESAMPLE_SLOTS", RESAMPLE_SLOTS),
        ("BINDING_RAY_SEGMENTS", RAY_SEGMENTS),
        ("BINDING_SPLAT_RASTER_STATE", SPLAT_RASTER_STATE),
    ];
}

/// Zeros stored before the first grid value (and twice as many after the last): the grid
/// kernels read a row through a window that starts up to ⌈support⌉ ≤ 16 values before the row
/// (`reconstruction.support` ≤ 16) and, at the last row, ends up to 2·GRID_PAD values past it
/// (a window of `MLS_GRID_WINDOW` units, at most 33 values, is never clamped for a point inside
/// the grid: tests/mls.rs `row_windows_hold_at_the_grid_corners_for_every_support`).
pub const GRID_PAD: usize = 16;

/// Copies of `RenderParams`/`SplatParams` in the parameters' uniform buffer: kernels index the
/// block by `gl_WorkGroupID.z` (always 0) so that lavapipe cannot inline its values and recompile
/// the kernel at every dispatch (glsl/common/params.glsl says why); NIR would fold the index of
/// a one-element array, so the block holds two.
pub const PARAMS_COPIES: usize = 2;

/// The contents of a parameters uniform buffer: `p`, [`PARAMS_COPIES`] times.
pub fn params_copies<T: Copy>(p: T) -> [T; PARAMS_COPIES] {
    [p; PARAMS_COPIES]
}

/// raycast.comp's per-pixel count word: evaluations in the low bits, and flags.
pub mod ray_count {
    /// The ray is complete; its pixel holds the final colour.
    pub const DONE: u32 = 1 << 31;
    /// A loop ended before its chunk did (the driver's loop limit): render again in smaller
    /// chunks.
    pub const TRUNCATED: u32 = 1 << 30;
    /// The ray crosses the domain's hull more often than the kernel can hold.
    pub const HULL_OVERFLOW: u32 = 1 << 29;
    /// Mask of the evaluation count.
    pub const EVALUATIONS: u32 = HULL_OVERFLOW - 1;
}

/// The largest bucket `splat_order`'s first pass sorts (by insertion); larger ones go to its
/// second pass (GLSL: `SPLAT_ORDER_INSERTION_MAX`; `splat::plan::order_large_groups`).
pub const ORDER_INSERTION_MAX: u32 = 64;

/// Words of the splatting kernels' counter buffer (`SplatCounts`) that stop a frame before its
/// accumulation.
pub mod splat_stat {
    /// Pixels whose rays cross the hull into more inside segments than `splat_segments` keeps.
    pub const SEGMENT_OVERFLOW: usize = 5;
    /// Kernels that touch more (tile, sheet) buckets than one invocation writes.
    pub const OVERSIZED: usize = 8;
    /// Tiles whose walk of their entries llvmpipe's loop limit cut short (`splat_raster`).
    pub const RASTER_TRUNCATED: usize = 15;
    /// Buckets `splat_order` could not put in kernel order within llvmpipe's loop limit:
    /// correct, but summed in an order that may change between runs.
    pub const UNORDERED: usize = 16;
    /// Buckets too large for `splat_order`'s first pass, handed to its second (their indices
    /// in the bucket cursors, which the scatter no longer needs).
    pub const LARGE_BUCKETS: usize = 17;
    /// Invocations whose tile walk `splat_raster` left unfinished for the band's next pass
    /// (their registers saved): a workgroup's invocations per tile and pass, fewer where
    /// some of its subgroups had stopped, every pixel opaque.
    pub const RESUMED: usize = 18;
    /// Interval halves whose table lookups `splat_raster` skipped, their entries all zero
    /// (`SPLAT_CLEAR_SKIP`): low and high word.
    pub const CLEAR_SKIPPED: usize = 19;
    pub const CLEAR_SKIPPED_HIGH: usize = 20;
    /// The first of one word per band of `band_rows` tile rows: the most entries any
    /// tile of the band walks (`splat_walks`), from which its passes follow
    /// (`splat::plan::RasterWalk::passes`).
    pub const BAND_ENTRIES: usize = 21;
}

/// `#define BINDING_* n` for every binding (and `GRID_PAD`, the `RAY_*` count flags), to pass
/// to the shader compiler.
pub fn binding_defines() -> Vec<(String, String)> {
    let mut d: Vec<(String, String)> = binding::ALL
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    d.push(("GRID_PAD".into(), GRID_PAD.to_string()));
    d.push(("PARAMS_COPIES".into(), PARAMS_COPIES.to_string()));
    use crate::recon::resample::{DIRECT_BITS, DIRECT_MARGIN, DIRECT_TERMS, UNDEFINED_BITS};
    for (k, v) in [
        ("RESAMPLE_UNDEFINED", format!("{UNDEFINED_BITS}u")),
        ("RESAMPLE_DIRECT_BITS", format!("{DIRECT_BITS}u")),
        ("RESAMPLE_DIRECT_TERMS", format!("{DIRECT_TERMS}u")),
        ("RESAMPLE_DIRECT_MARGIN", format!("{DIRECT_MARGIN:e}")),
        (
            "HULL_HIT_MERGE",
            format!("{:e}", crate::samples::bvh::HIT_MERGE),
        ),
    ] {
        d.push((k.into(), v));
    }
    for (k, v) in [
        (
            "SPLAT_STAT_SEGMENT_OVERFLOW",
            splat_stat::SEGMENT_OVERFLOW as u32,
        ),
        ("SPLAT_STAT_OVERSIZED", splat_stat::OVERSIZED as u32),
        (
            "SPLAT_STAT_RASTER_TRUNCATED",
            splat_stat::RASTER_TRUNCATED as u32,
        ),
        ("SPLAT_STAT_UNORDERED", splat_stat::UNORDERED as u32),
        ("SPLAT_STAT_LARGE_BUCKETS", splat_stat::LARGE_BUCKETS as u32),
        ("SPLAT_STAT_RESUMED", splat_stat::RESUMED as u32),
        ("SPLAT_STAT_CLEAR_SKIPPED", splat_stat::CLEAR_SKIPPED as u32),
        (
            "SPLAT_STAT_CLEAR_SKIPPED_HIGH",
            splat_stat::CLEAR_SKIPPED_HIGH as u32,
        ),
        ("SPLAT_STAT_BAND_ENTRIES", splat_stat::BAND_ENTRIES as u32),
        ("SPLAT_ORDER_INSERTION_MAX", ORDER_INSERTION_MAX),
        ("RAY_DONE", ray_count::DONE),
        ("RAY_TRUNCATED", ray_count::TRUNCATED),
        ("RAY_HULL_OVERFLOW", ray_count::HULL_OVERFLOW),
        ("RAY_EVALUATIONS", ray_count::EVALUATIONS),
    ] {
        d.push((k.into(), format!("{v}u")));
    }
    d
}

/// The camera of a frame, one definition for the ray caster and the splatter. GLSL twin:
/// `CameraBlock`. Positions are frame-relative; the vectors' w are unused.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct CameraBlock {
    pub eye: [f32; 4],
    /// Unit view direction.
    pub forward: [f32; 4],
    /// Unit right vector.
    pub right: [f32; 4],
    /// Unit up vector (right × forward).
    pub up: [f32; 4],
    pub width: u32,
    pub height: u32,
    /// 0 = perspective, 1 = orthographic.
    pub projection: u32,
    /// tan(fov_y / 2) (perspective).
    pub tan_half_fov: f32,
    /// Half the view height in world units (orthographic).
    pub ortho_half_height: f32,
    pub _pad: [f32; 3],
}
const _: () = assert!(std::mem::size_of::<CameraBlock>() == 96);

/// The field's lattice, supports and octree. GLSL twin: `FieldBlock`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct FieldBlock {
    /// Position of grid point (0,0,0) (or of the fast path's fine lattice).
    pub grid_origin: [f32; 4],
    /// 1 / grid spacing per axis.
    pub grid_inv_spacing: [f32; 4],
    /// 1 / support radius per axis, h = support × spacing ([MLS] §3, diagonal H).
    pub inv_support: [f32; 4],
    /// Octree root cube: centre xyz, half side w.
    pub octree_root: [f32; 4],
    /// Grid samples per axis (xyz), w unused.
    pub grid_dims: [i32; 4],
    /// Support radius in grid-index units (the grid path's search radius).
    pub support_cells: f32,
    /// Gaussian field: σ (fraction of the support radius), and on a grid every sample's weight
    /// v·norm (octree samples carry theirs in `Sample::metric_off.z`).
    pub gauss_sigma: f32,
    pub gauss_weight: f32,
    pub _pad: f32,
}
const _: () = assert!(std::mem::size_of::<FieldBlock>() == 96);

/// The ray caster's integrator, lengths in world units. GLSL twin: `IntegratorBlock`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct IntegratorBlock {
    /// Ray clip box, min and max corner (w unused).
    pub box_min: [f32; 4],
    pub box_max: [f32; 4],
    /// Background RGB (w unused).
    pub background: [f32; 4],
    /// Midpoint or fixed step.
    pub step_world: f32,
    /// Midpoint rule: stop a ray when its transmittance falls below this.
    pub min_transmittance: f32,
    /// Adaptive: the criterion's ε.
    pub epsilon: f32,
    /// Preintegrated methods: stop a ray once its opacity exceeds this.
    pub early_termination: f32,
    /// The sample spacing (the Hermite criterion's ε is per spacing).
    pub spacing_world: f32,
    /// Adaptive: the shortest interval.
    pub l_min_world: f32,
    /// Transfer-function points and isosurfaces.
    pub tf_count: u32,
    pub iso_count: u32,
    /// A brick's box (the kernel's `CLIP` variant; w unused).
    pub clip_min: [f32; 4],
    pub clip_max: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<IntegratorBlock>() == 112);

/// The preintegration tables. GLSL twin: `TableBlock`. Its default (no tables) marks every bin
/// occupied, so that no lookup could be skipped as clear.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct TableBlock {
    /// s of the first and last table node.
    pub s_min: f32,
    pub s_max: f32,
    /// Length of table 0, the longest (table k has longest · 2^−k).
    pub longest_world: f32,
    /// Nodes per scalar axis, and tables of lengths (the zero-length limits follow them).
    pub resolution: u32,
    pub lengths: u32,
    /// The transfer function's largest τ or τ·c_k per world unit ([`TransferFunction::peak`]):
    /// what an interval's error estimate can be at most per unit length.
    ///
    /// [`TransferFunction::peak`]: crate::view::transfer::TransferFunction::peak
    pub peak: f32,
    /// Table 0's occupied bins, bit i of word i / 32 for bin i % 32 of
    /// [`OCCUPANCY_BINS`](crate::view::table_occupancy::OCCUPANCY_BINS)
    /// (`PreintegrationTables::occupied`).
    pub occupied: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<TableBlock>() == 32);

impl Default for TableBlock {
    fn default() -> Self {
        Self {
            occupied: [u32::MAX; 2],
            ..Zeroable::zeroed()
        }
    }
}

/// Constants of the ray caster and the field's kernels, in named blocks. GLSL twin:
/// `RenderParams`.
///
/// All positions are relative to the scene's frame origin (the volume centre, subtracted on the
/// host in f64) so that f32 keeps its precision for data far from the world origin.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct RenderParams {
    pub camera: CameraBlock,
    pub field: FieldBlock,
    pub integrator: IntegratorBlock,
    pub tables: TableBlock,
    /// Blinn–Phong ambient, diffuse, specular, shininess.
    pub lighting: [f32; 4],
    pub tf: TfBlock,
    pub sensitivity: SensitivityBlock,
}
const _: () = assert!(std::mem::size_of::<RenderParams>() == 864);

/// Points of a transfer function the exact opacity's scan reads from the parameters
/// ([`TfBlock`]) instead of the texel view.
pub const TF_BLOCK_POINTS: usize = 32;

/// The transfer function's (s, τ), two points a vec4 ((s₀, τ₀, s₁, τ₁), …), for the exact
/// opacity's scan (`transfer_mean_tau` with `PREINT_TF_POINTS`): in the parameters, which the
/// kernels copy into registers, an unrolled scan reads them at constant offsets instead of one
/// gather a point from the texel view. Zero past the function's points, and unused where it
/// has more than [`TF_BLOCK_POINTS`]. GLSL twin: `TfBlock`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct TfBlock {
    pub s_tau: [[f32; 4]; TF_BLOCK_POINTS / 2],
}
const _: () = assert!(std::mem::size_of::<TfBlock>() == 256);

/// Pieces of a transfer function the Hermite criterion's sensitivity scans from the parameters
/// ([`SensitivityBlock`]) instead of the texel view.
pub const SENSITIVITY_PIECES: usize = 16;

/// The pieces of the transfer function over which τ or some τ·c_k changes, in order, each
/// (s_a, s_b, rate, jump): the sensitivity's per-piece terms, computed on the host in f32 as
/// the texel scan computes them (rate = jump / (s_b − s_a), −1 for a step of width 0). The
/// kernels copy the block into registers and the adaptive kernel's scan (`transfer_sensitivity`
/// with `TF_SENSITIVITY_PIECES`) unrolls over them: no gather, and flat pieces, which add
/// nothing, are left out. Zero past the last piece, and unused where there are more than
/// [`SENSITIVITY_PIECES`]
/// ([`TransferFunction::sensitivity_pieces`](crate::view::transfer::TransferFunction::sensitivity_pieces)).
/// GLSL twin: `SensitivityBlock`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct SensitivityBlock {
    pub pieces: [[f32; 4]; SENSITIVITY_PIECES],
}
const _: () = assert!(std::mem::size_of::<SensitivityBlock>() == 256);

/// One isosurface. GLSL twin: `IsoSurface`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct IsoSurface {
    /// Colour rgb and opacity.
    pub color_opacity: [f32; 4],
    /// Iso-value.
    pub value: f32,
    pub _pad: [f32; 3],
}
const _: () = assert!(std::mem::size_of::<IsoSurface>() == 32);

/// One transfer-function control point. GLSL twin: `TfPoint`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct TfPoint {
    /// Emitted colour rgb and extinction τ (per world unit).
    pub color_tau: [f32; 4],
    /// Scalar value of the point.
    pub s: f32,
    /// τ again, beside s: the exact opacity's scan (`transfer_mean_tau`) reads one texel a point.
    pub tau: f32,
    pub _pad: [f32; 2],
}
const _: () = assert!(std::mem::size_of::<TfPoint>() == 32);

/// A sample of the octree path. GLSL twin: `Sample`; the kernels read it as three `vec4`
/// texels of an `rgba32f` texel-buffer view (`binding::kind`), in this field order.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct Sample {
    /// Position xyz and value w.
    pub pos_value: [f32; 4],
    /// The support's metric M (ρ² = dᵀMd): xx, yy, zz, xy.
    pub metric: [f32; 4],
    /// The rest of the metric: xz, yz (read only by the full-metric variant); z: the Gaussian
    /// weight v_i·norm_i; w unused.
    pub metric_off: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<Sample>() == 48);

/// Result of one MLS evaluation (mls_eval). GLSL twin: `MlsOut`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct MlsOut {
    /// f(x) and ∇f(x).
    pub value: f32,
    pub gradient: [f32; 3],
    /// Samples with non-zero weight.
    pub neighbours: u32,
    /// Basis terms actually solved for (1, 4; 0 = undefined, no sample has weight).
    pub terms: u32,
    pub _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<MlsOut>() == 32);

/// Push constants of raycast.comp. GLSL twin: `RayPush`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct RayPush {
    /// First image row of this band.
    pub row_offset: u32,
    /// Rows in this band.
    pub rows: u32,
    /// First outer step (midpoint step, fixed interval, adaptive top interval) of this chunk.
    pub first: u32,
    /// One past the last outer step of this chunk.
    pub last: u32,
    /// First image column and columns of the band (a brick's window; else 0 and the width).
    pub col_offset: u32,
    pub cols: u32,
    pub _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<RayPush>() == 32);

/// Push constants of mls_eval.comp, probe_fma.comp and probe_memory.comp. GLSL twin:
/// `CountPush`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct CountPush {
    /// Items to process.
    pub count: u32,
    /// Inner iterations (probe) or unused.
    pub iterations: u32,
    pub _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<CountPush>() == 16);

/// Push constants of `raycast_next`: the band (its first row and rows) and its slot in the
/// indirect argument buffer. GLSL twin: `NextPush`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct NextPush {
    pub row_offset: u32,
    pub rows: u32,
    pub args_slot: u32,
    /// Columns the band's next chunk dispatches (its `RayPush::cols`).
    pub cols: u32,
}
const _: () = assert!(std::mem::size_of::<NextPush>() == 16);

/// Push constants of `target_pack`: the pixels to convert and, for splatting frames, the
/// background composited under them (`composite` = 1). GLSL twin: `PackPush`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct PackPush {
    pub count: u32,
    /// 1: each pixel becomes (C + (1 − α)·background, α) before conversion.
    pub composite: u32,
    pub _pad: [u32; 2],
    /// Background rgb (w unused).
    pub background: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<PackPush>() == 32);

/// Push constants of `splat_plan`: what a recorded splatting frame's accumulation may take.
/// GLSL twin: `PlanPush`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct PlanPush {
    /// (tile, sheet) buckets: the scan's total follows the last one's offset.
    pub buckets: u32,
    /// Entries the frame's list holds.
    pub capacity: u32,
    /// Most entries the work budget allows (`u32::MAX`: no budget).
    pub max_entries: u32,
    /// splat_bin's workgroups.
    pub bin_groups: u32,
    /// splat_raster's workgroups: tiles per row and rows.
    pub tiles_x: u32,
    pub tiles_y: u32,
    /// 1 where `splat_segments` ran: a pixel with too many inside segments stops the frame.
    pub segments: u32,
    /// Tile rows per dispatch of `splat_raster`: one set of arguments per band follows
    /// splat_bin's and splat_order's two passes'.
    pub band_rows: u32,
    /// `RasterPush::chunk` and `sheet_cost`, and the sheets walked (sheets, and one more
    /// post-shaded): with each band's entries (`splat_walks`) they give its passes.
    pub chunk: u32,
    pub sheet_cost: u32,
    pub steps: u32,
    /// Passes recorded after each band's first: their arguments follow the bands', `resumes`
    /// per band; those a band does not need dispatch nothing.
    pub resumes: u32,
}
const _: () = assert!(std::mem::size_of::<PlanPush>() == 48);

/// Constants of the splatting kernels. GLSL twin: `SplatParams`. The camera is the ray
/// caster's [`CameraBlock`], so `camera.glsl` serves both renderers.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct SplatParams {
    pub camera: CameraBlock,
    /// Domain box minimum and maximum (w unused).
    pub box_min: [f32; 4],
    pub box_max: [f32; 4],
    /// Background rgb (w unused).
    pub background: [f32; 4],
    /// Blinn–Phong ambient, diffuse, specular, shininess.
    pub lighting: [f32; 4],
    /// Kernels reaching closer than this to the eye plane are culled.
    pub near: f32,
    /// Focal length in pixels (per tangent unit, or per world unit when orthographic).
    pub focal: f32,
    /// Pixel coordinates of the optical axis.
    pub centre_x: f32,
    pub centre_y: f32,
    /// t where the first sheet starts, and the sheet thickness.
    pub slab0_world: f32,
    pub slab_world: f32,
    /// Pixels stop compositing beyond this opacity.
    pub early_termination: f32,
    /// Post-shaded: the transfer function's extinction at value 0 (0: sheets holding no value
    /// composite nothing, and splat_raster skips them).
    pub zero_extinction: f32,
    /// Footprint cutoff (standard deviations), low-pass variance (px²), Gaussian σ (fraction
    /// of the support), lateral clamps of u₀/u₂ and u₁/u₂.
    pub cutoff: f32,
    pub lowpass: f32,
    pub sigma: f32,
    pub lateral_x: f32,
    pub lateral_y: f32,
    pub tf_count: u32,
    pub iso_count: u32,
    /// Sheets in the frame.
    pub slabs: u32,
    /// Occlusion tiles per image row.
    pub tiles_x: u32,
    /// Kernels to project.
    pub kernel_count: u32,
    /// The sheets a frame's kernels are drawn on, first and last (all but in a brick's frame:
    /// those it can own, `SplatSetup::window`).
    pub sheet_first: u32,
    pub sheet_last: u32,
    /// A brick's frame: its kd cell (w unused; faces on the domain's boundary infinite), where
    /// a sheet's midpoint must lie for the frame to composite it.
    pub cell_min: [f32; 4],
    pub cell_max: [f32; 4],
    /// The pixels a frame's kernels are drawn on: x0, y0, x1, y1 (inclusive; all but in a
    /// brick's frame).
    pub pixel_window: [i32; 4],
    /// Post-shaded intervals between sheet middles: the preintegration table of half a
    /// sheet (`SplatSetup::table_lengths`; zero without).
    pub tables: TableBlock,
    /// The transfer function's (s, τ) for the exact opacity's unrolled scan, as
    /// [`RenderParams::tf`].
    pub tf: TfBlock,
}
const _: () = assert!(std::mem::size_of::<SplatParams>() == 576);

/// One projected kernel (splat_project's output). GLSL twin: `Splat`. The footprint words
/// depend on the projection (`splat::project::Splat` names them):
/// - affine footprint (orthographic, or `splat.footprint = "affine"`): centre x, y, t, depth σ |
///   conic xx, xy, yy, peak | depth slope x, y, 0, 0 | unused;
/// - perspective, exact (per-pixel ray integral): Q xx, xy, yy, xz | Q yz, zz, r.x, r.y |
///   adj(P) xx, xy, yy, xz | adj(P) yz, zz, r.z, w·√det P/(2π).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct Splat {
    pub footprint0: [f32; 4],
    pub footprint1: [f32; 4],
    pub footprint2: [f32; 4],
    pub footprint3: [f32; 4],
    /// Emitted colour (pre-shaded) or a surface splat's shaded colour; w: the surface's opacity
    /// (0 for volume kernels).
    pub color: [f32; 4],
    /// Inclusive pixel box x0, y0, x1, y1.
    pub bbox: [i32; 4],
    /// First and last sheet (first > last: culled), blocks per row, blocks in all.
    pub slabs: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<Splat>() == 112);

/// Push constants of `splat_scan`. GLSL twin: `ScanPush`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct ScanPush {
    /// (tile, sheet) buckets.
    pub buckets: u32,
    /// Blocks of `SCAN_BLOCK` buckets.
    pub blocks: u32,
    pub _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<ScanPush>() == 16);

/// Push constants of `splat_raster`: the frame is rasterized in bands of tile rows (in
/// `render()`, one submission each), each band in passes that continue the walks the pass
/// before left unfinished. GLSL twin: `RasterPush`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct RasterPush {
    /// The band's first tile row.
    pub tile_row: u32,
    /// This pass (0: the walks start), and the band's last recorded pass: a walk left
    /// unfinished by it is counted as cut short.
    pub pass: u32,
    pub last_pass: u32,
    /// Walk cost a pass may spend per tile (loop iterations: one per entry, `sheet_cost` per
    /// sheet), below llvmpipe's 65 535.
    pub chunk: u32,
    pub sheet_cost: u32,
    /// The band's index: its longest walk is in the counters (`splat_stat::BAND_ENTRIES`),
    /// from which the kernel knows the band's last pass where fewer were recorded.
    pub band: u32,
    pub _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<RasterPush>() == 32);

/// Push constants of `splat_walks`. GLSL twin: `WalkPush`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct WalkPush {
    /// Image tiles, tiles per row, sheets (buckets per tile) and tile rows per band.
    pub tiles: u32,
    pub tiles_x: u32,
    pub slabs: u32,
    pub band_rows: u32,
}
const _: () = assert!(std::mem::size_of::<WalkPush>() == 16);
