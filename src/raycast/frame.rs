//! The stages of one ray-cast frame (stage `raycast`'s host side), run by
//! [`crate::renderer`]: each its own function.
//! - `frame_pipeline`: the shader variant the field and setup need (compiled, or cached);
//! - `frame_constants`: kernel constants, transfer function and isosurfaces (small, per frame);
//! - `frame_targets`: image, counts, ray-state and skip-report buffers (per image size);
//! - `BandCommands`: one band of rows as commands, its chunks of outer steps after the first
//!   dispatched indirectly by `raycast_next` (what `Renderer::record` records for every band);
//! - `run_bands`: the image a band at a time, one submission each, with the loop-limit
//!   fallback (LAVAPIPE.md: llvmpipe ends loops after 65 535 iterations);
//! - `read_image`: pixels, evaluation counts and the skipping report back to the host.

use super::adaptive::pixel_estimate;
use super::gpu::{render_params, table_params};
use super::setup::RaySetup;
use crate::field::Field;
use crate::field::gpu::GpuField;
use crate::field::skip::{SkipReport, SkipTable};
use crate::field::variant::{HullCache, Variant, pipeline_for};
use crate::gpu_types::{RayPush, binding, params_copies, ray_count};
use crate::view::Method;
use crate::view::preintegration::PreintegrationTables;
use crate::view::shading::iso_buffer_data;
use crate::view::transfer::TransferFunction;
use crate::vk::{
    BindGroup, Buffer, BufferUsage, ComputePipeline, Context, Recorder, ShaderCompiler, VkError,
};
use std::sync::atomic::{AtomicBool, Ordering};

/// Pixels per band (one submission each).
const BAND_PIXELS: u32 = 16 * 1024;

/// Outer steps of the longest possible ray: midpoint steps or fixed intervals of `step`, or
/// adaptive top intervals of l_max, over the box diagonal, plus one per possible segment (each
/// inside segment of a hull rounds its own count up).
pub fn outer_steps(setup: &RaySetup) -> u32 {
    let diagonal = (setup.box_hi - setup.box_lo).length();
    let step = match setup.method {
        Method::Adaptive => setup.l_max_world,
        _ => setup.step_world,
    };
    let segments = (crate::samples::bvh::MAX_HITS / 2 + 1) as f64;
    ((diagonal / step).ceil() + segments).min(f64::from(u32::MAX / 2)) as u32
}

/// Outer steps per dispatch. llvmpipe ends every loop after 65 535 iterations per invocation
/// and dispatch (LAVAPIPE.md), and one MLS evaluation runs 30–60 of them (neighbour rows,
/// octree descent): about 256 evaluations per ray and dispatch leaves a margin of 4 or more.
///
/// An adaptive top interval costs 1 to 2^(levels − 1) evaluations. Sizing chunks for the
/// deepest top (one top per dispatch at 9 levels) made the dispatches, not the evaluations,
/// what an adaptive frame paid on lavapipe: every chunk of a band runs every ray of it again
/// (reloading its state, walking its hull) and then `raycast_next` (BENCHMARKS.md,
/// 2026-12-06 (vii): the same evaluations in a quarter to a third of the time at 64 tops). So
/// adaptive chunks assume tops that split twice on average (4 evaluations); a ray that needs
/// more in one dispatch trips the loop limit, and the band is rendered again at a quarter of
/// the chunk ([`smaller_chunk`]), which the renderer then keeps for its next frames.
pub fn default_chunk(setup: &RaySetup) -> u32 {
    const EVALUATIONS_PER_DISPATCH: u32 = 256;
    /// Splits the adaptive chunk assumes per top: 2^2 evaluations.
    const TYPICAL_SPLITS: usize = 2;
    match setup.method {
        Method::Adaptive => {
            let levels = super::adaptive::stack_size(setup.l_max_world, setup.l_min_world);
            EVALUATIONS_PER_DISPATCH >> (levels - 1).min(TYPICAL_SPLITS)
        }
        _ => EVALUATIONS_PER_DISPATCH,
    }
}

/// The chunk to render a band again with after the driver cut one of its rays short at
/// `chunk` outer steps per dispatch (`ray_count::TRUNCATED`): a quarter, so that a chunk sized
/// for typical rays reaches one step per dispatch in three reruns at most, not six. None at
/// one step already.
pub(crate) fn smaller_chunk(chunk: u32) -> Option<u32> {
    (chunk > 1).then(|| chunk.div_ceil(4))
}

/// The setup of the variant that reads the hull segments a frame of `setup` keeps, for the
/// chunks after a band's first ([`BandCommands`]); None where its frames keep none or a band
/// runs in one chunk (at the setup's own chunk size).
pub(crate) fn later_chunks_setup(setup: &RaySetup) -> Option<RaySetup> {
    let chunk = setup.chunk.unwrap_or_else(|| default_chunk(setup));
    (setup.hull_cache == HullCache::Keep && outer_steps(setup) > chunk).then(|| RaySetup {
        hull_cache: HullCache::Read,
        ..setup.clone()
    })
}

/// Image rows per band: about `BAND_PIXELS` pixels, a multiple of the workgroup's 8 rows.
pub(crate) fn band_rows(setup: &RaySetup) -> u32 {
    let (w, h) = (setup.camera.width, setup.camera.height);
    (BAND_PIXELS / w.max(1))
        .clamp(8, h.max(8))
        .next_multiple_of(8)
}

/// The push constants of the chunk of a band (`rows` rows from `row`, columns `cols`: first
/// and count) that starts at outer step `first`: at most `chunk` steps, none past `outer`.
pub(crate) fn chunk_push(
    (row, rows): (u32, u32),
    cols: (u32, u32),
    first: u32,
    chunk: u32,
    outer: u32,
) -> RayPush {
    RayPush {
        row_offset: row,
        rows,
        first,
        last: first.saturating_add(chunk).min(outer),
        col_offset: cols.0,
        cols: cols.1,
        _pad: [0; 2],
    }
}

/// The workgroups of a band of `rows` rows of `cols` pixels (8 × 8 pixels each).
pub(crate) fn band_groups(cols: u32, rows: u32) -> [u32; 3] {
    [cols.div_ceil(8), rows.div_ceil(8), 1]
}

/// Whether the frame writes the per-pixel ray report (`binding::RAY_STATS`): skipping's
/// lengths and counts, and the adaptive integrator's error estimate.
pub(crate) fn ray_stats(setup: &RaySetup, skip: bool) -> bool {
    skip || setup.method == Method::Adaptive
}

/// Binding numbers of the ray caster for a field and setup.
pub(crate) fn frame_bindings(
    gpu_field: &GpuField,
    setup: &RaySetup,
    with_tables: bool,
    skip: bool,
) -> Vec<u32> {
    let mut ids: Vec<u32> = gpu_field.bindings().iter().map(|(b, _)| *b).collect();
    if skip {
        ids.extend([binding::SKIP_BLOCKS, binding::SKIP_TABLE]);
    }
    if ray_stats(setup, skip) {
        ids.push(binding::RAY_STATS);
    }
    let cache = setup.hull_cache;
    if cache != HullCache::Read {
        ids.extend(gpu_field.hull_bindings().iter().map(|(b, _)| *b));
    }
    if cache != HullCache::Off {
        ids.push(binding::RAY_SEGMENTS);
    }
    ids.extend([
        binding::TRANSFER,
        binding::TRANSFER_TEXELS,
        binding::IMAGE,
        binding::COUNTS,
        binding::RAY_STATE,
    ]);
    if !setup.isosurfaces.is_empty() {
        ids.push(binding::ISO);
    }
    if with_tables {
        ids.push(binding::PREINT);
    }
    ids
}

/// Compiles the ray caster's variant for a field and setup.
pub(crate) fn frame_pipeline(
    ctx: &Context,
    compiler: &ShaderCompiler,
    variant: &Variant,
    bindings: &[u32],
) -> Result<ComputePipeline, VkError> {
    pipeline_for(
        ctx,
        compiler,
        "raycast/raycast.comp",
        variant,
        bindings,
        std::mem::size_of::<RayPush>() as u32,
    )
}

/// The tables as the kernel reads them: every length's table, then the zero-length limits.
pub fn table_buffer(ctx: &Context, tables: &PreintegrationTables) -> Result<Buffer, VkError> {
    // Read through a texel view only: bounded by maxTexelBufferElements (128 M on lavapipe),
    // not by the 128 MiB of maxStorageBufferRange, which held 9 tables to 965² entries.
    let buffer = Buffer::new(
        ctx,
        "preintegration tables",
        tables.bytes(),
        BufferUsage::Texel,
    )?;
    write_tables(ctx, &buffer, tables)?;
    Ok(buffer)
}

/// Writes the tables to the start of `buffer` ([`table_buffer`]'s layout), one part per table
/// and no concatenation on the host (hundreds of MiB at 2048² entries).
pub fn write_tables(
    ctx: &Context,
    buffer: &Buffer,
    tables: &PreintegrationTables,
) -> Result<(), VkError> {
    let parts: Vec<&[u8]> = tables
        .tables
        .iter()
        .chain(std::iter::once(&tables.limits))
        .map(|t| bytemuck::cast_slice(t))
        .collect();
    buffer.write_parts(ctx, &parts)
}

/// Per-frame constants: kernel parameters, transfer function, isosurfaces, skip table.
pub(crate) struct FrameConstants {
    pub(crate) params: Buffer,
    pub(crate) tf: Buffer,
    pub(crate) iso: Buffer,
    /// The frame's [`SkipTable`] (with empty-space skipping).
    pub(crate) skip: Option<Buffer>,
}

/// The bytes of a frame's constants, for buffers made per frame ([`frame_constants`]) or
/// written from a recorded command buffer (`Renderer::record`).
pub(crate) struct ConstantData {
    pub(crate) params: Vec<u8>,
    pub(crate) tf: Vec<u8>,
    pub(crate) iso: Vec<u8>,
    pub(crate) skip: Option<Vec<u8>>,
}

pub(crate) fn constant_data(
    field: &Field,
    setup: &RaySetup,
    tf: &TransferFunction,
    tables: Option<&PreintegrationTables>,
    skip: bool,
) -> ConstantData {
    let gpu_tf = tf.to_gpu();
    let skip = skip.then(|| {
        let table = SkipTable::build(tf, &setup.isosurfaces, crate::field::scalar_range(field));
        bytemuck::cast_slice(&table.gpu_words()).to_vec()
    });
    let mut params = render_params(field, setup, gpu_tf.len() as u32);
    if let Some(t) = tables {
        table_params(&mut params, t, tf);
    }
    ConstantData {
        params: bytemuck::cast_slice(&params_copies(params)).to_vec(),
        tf: bytemuck::cast_slice(&gpu_tf).to_vec(),
        iso: bytemuck::cast_slice(&iso_buffer_data(&setup.isosurfaces)).to_vec(),
        skip,
    }
}

pub(crate) fn frame_constants(
    ctx: &Context,
    field: &Field,
    setup: &RaySetup,
    tf: &TransferFunction,
    tables: Option<&PreintegrationTables>,
    skip: bool,
) -> Result<FrameConstants, VkError> {
    let d = constant_data(field, setup, tf, tables, skip);
    Ok(FrameConstants {
        params: Buffer::from_slice(ctx, "render params", &d.params)?,
        tf: Buffer::from_slice(ctx, "transfer function", &d.tf)?,
        iso: Buffer::from_slice(ctx, "isosurfaces", &d.iso)?,
        skip: d
            .skip
            .map(|w| Buffer::from_slice(ctx, "skip table", &w))
            .transpose()?,
    })
}

/// Image, counts and ray-state buffers for `pixels` pixels.
pub(crate) struct FrameTargets {
    pub(crate) pixels: u64,
    pub(crate) image: Buffer,
    pub(crate) counts: Buffer,
    pub(crate) ray_state: Buffer,
    /// The per-pixel ray report (`binding::RAY_STATS`).
    pub(crate) ray_stats: Buffer,
    /// One band's indirect dispatch arguments (`raycast_next`), for [`run_bands`], which
    /// submits a band at a time.
    pub(crate) args: Buffer,
    /// The hull segments of the last camera (`None` until a frame of a mesh caches them).
    pub(crate) segments: Option<super::segments::SegmentCache>,
}

pub(crate) fn frame_targets(ctx: &Context, pixels: u64) -> Result<FrameTargets, VkError> {
    Ok(FrameTargets {
        pixels,
        image: Buffer::new(ctx, "image", pixels * 16, BufferUsage::Storage)?,
        counts: Buffer::new(ctx, "evaluation counts", pixels * 4, BufferUsage::Storage)?,
        ray_state: Buffer::new(ctx, "ray state", pixels * 16, BufferUsage::Storage)?,
        ray_stats: Buffer::new(ctx, "ray report", pixels * 16, BufferUsage::Storage)?,
        args: Buffer::new(ctx, "band dispatch arguments", 16, BufferUsage::Storage)?,
        segments: None,
    })
}

/// The `raycast_next` pipeline.
pub(crate) fn next_pipeline(
    ctx: &Context,
    compiler: &ShaderCompiler,
) -> Result<ComputePipeline, VkError> {
    let spirv = compiler.compile(
        crate::vk::ShaderSource::File("raycast/raycast_next.comp"),
        &crate::gpu_types::binding_defines(),
    )?;
    let kinds =
        [binding::PARAMS, binding::COUNTS, binding::DISPATCH_ARGS].map(|b| (b, binding::kind(b)));
    ComputePipeline::with_kinds(
        ctx,
        "raycast_next",
        &spirv,
        &kinds,
        std::mem::size_of::<crate::gpu_types::NextPush>() as u32,
    )
}

/// The `raycast_next` bind group of a frame: its parameters, its rays' counts, and the
/// indirect arguments it writes.
pub(crate) fn next_group<'a>(
    ctx: &Context,
    next: &ComputePipeline,
    constants: &'a FrameConstants,
    targets: &'a FrameTargets,
    args: &'a Buffer,
) -> Result<BindGroup<'a>, VkError> {
    BindGroup::new(
        ctx,
        next,
        &[
            (binding::PARAMS, &constants.params),
            (binding::COUNTS, &targets.counts),
            (binding::DISPATCH_ARGS, args),
        ],
    )
}

/// What a band of a ray-cast frame records, for `render()` (a submission per band) and for a
/// recorded frame (every band): the ray caster and `raycast_next` with their bind groups, the
/// indirect arguments, the columns it dispatches (first and count: a brick's window, else the
/// image's) and the frame's outer steps. A frame that keeps its rays' hull segments
/// (`HullCache::Keep`) walks the hull in a band's first chunk only: `later` is the variant that
/// reads them (`HullCache::Read`) with its bindings, for every later chunk.
pub(crate) struct BandCommands<'a> {
    pub(crate) pipeline: &'a ComputePipeline,
    pub(crate) group: &'a BindGroup<'a>,
    pub(crate) later: Option<(&'a ComputePipeline, &'a BindGroup<'a>)>,
    pub(crate) next: &'a ComputePipeline,
    pub(crate) next_group: &'a BindGroup<'a>,
    pub(crate) args: &'a Buffer,
    pub(crate) cols: (u32, u32),
    pub(crate) outer: u32,
}

impl BandCommands<'_> {
    /// Records rows `row .. row + rows` in chunks of `chunk` outer steps: the first chunk
    /// dispatched for the band's groups, each later one indirectly for as many workgroups as
    /// `raycast_next` finds rays unfinished in the band (none once they all ended), from the
    /// arguments at slot `slot` of `args`. Returns the dispatches recorded.
    pub(crate) fn record(
        &self,
        rec: &mut Recorder<'_>,
        row: u32,
        rows: u32,
        chunk: u32,
        slot: u32,
    ) -> Result<u32, VkError> {
        let mut dispatches = 0;
        let mut first = 0;
        while first < self.outer {
            let push = chunk_push((row, rows), self.cols, first, chunk, self.outer);
            if first == 0 {
                rec.dispatch(
                    self.pipeline,
                    self.group,
                    bytemuck::bytes_of(&push),
                    band_groups(self.cols.1, rows),
                    "raycast",
                )?;
            } else {
                let (pipeline, group) = self.later.unwrap_or((self.pipeline, self.group));
                let next_push = crate::gpu_types::NextPush {
                    row_offset: row,
                    rows,
                    args_slot: slot,
                    cols: self.cols.1,
                };
                rec.dispatch(
                    self.next,
                    self.next_group,
                    bytemuck::bytes_of(&next_push),
                    [1, 1, 1],
                    "raycast_next",
                )?;
                rec.dispatch_indirect(
                    pipeline,
                    group,
                    bytemuck::bytes_of(&push),
                    self.args,
                    16 * u64::from(slot),
                    "raycast",
                )?;
                dispatches += 1;
            }
            dispatches += 1;
            first = push.last;
        }
        Ok(dispatches)
    }
}

/// Every buffer of a ray-cast frame at its binding (what [`frame_bindings`] lists).
pub(crate) fn frame_buffers<'a>(
    gpu_field: &'a GpuField,
    constants: &'a FrameConstants,
    targets: &'a FrameTargets,
    table: Option<&'a Buffer>,
    setup: &RaySetup,
) -> Vec<(u32, &'a Buffer)> {
    let mut all = gpu_field.bindings();
    let cache = setup.hull_cache;
    if cache != HullCache::Read {
        all.extend(gpu_field.hull_bindings());
    }
    if let Some(c) = targets
        .segments
        .as_ref()
        .filter(|_| cache != HullCache::Off)
    {
        all.push((binding::RAY_SEGMENTS, &c.texels));
    }
    all.extend([
        (binding::PARAMS, &constants.params),
        (binding::TRANSFER, &constants.tf),
        (binding::TRANSFER_TEXELS, &constants.tf),
        (binding::IMAGE, &targets.image),
        (binding::COUNTS, &targets.counts),
        (binding::RAY_STATE, &targets.ray_state),
    ]);
    if !setup.isosurfaces.is_empty() {
        all.push((binding::ISO, &constants.iso));
    }
    if let Some(t) = table {
        all.push((binding::PREINT, t));
    }
    if let Some(t) = &constants.skip {
        all.extend(gpu_field.skip_bindings());
        all.push((binding::SKIP_TABLE, t));
    }
    if ray_stats(setup, constants.skip.is_some()) {
        all.push((binding::RAY_STATS, &targets.ray_stats));
    }
    all
}

/// How [`run_bands`] ended.
pub(crate) enum Bands {
    /// Every band finished: GPU ms, submissions and the outer steps per dispatch the last band
    /// ran with (smaller than the setup's where the loop limit cut a ray short).
    Done(f64, u32, u32),
    /// The stop flag was raised.
    Stopped,
    /// A ray crossed the hull more often than the variant's `HULL_MAX_HITS`, which is below
    /// `bvh::MAX_HITS`: render the frame again with that.
    HullHits,
}

/// The pipelines a ray-cast frame runs: the ray caster's variant and `raycast_next`.
pub(crate) struct FramePipelines<'a> {
    pub(crate) raycast: &'a ComputePipeline,
    pub(crate) next: &'a ComputePipeline,
    /// Where `raycast` keeps the hull segments it walks: the variant that reads them, for the
    /// chunks after a band's first ([`BandCommands`]).
    pub(crate) read_segments: Option<&'a ComputePipeline>,
}

/// Binds everything and runs the bands: each band is recorded as a recorded frame records it
/// ([`BandCommands`]) and submitted alone, and its rays' counts read back, so that progress and
/// a stop request act between bands and a band that the loop limit cut short runs again in
/// smaller chunks.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_bands(
    ctx: &Context,
    pipelines: FramePipelines<'_>,
    gpu_field: &GpuField,
    constants: &FrameConstants,
    targets: &FrameTargets,
    table: Option<&Buffer>,
    setup: &RaySetup,
    progress: &mut dyn FnMut(f64),
    stop: Option<&AtomicBool>,
) -> Result<Bands, VkError> {
    let all = frame_buffers(gpu_field, constants, targets, table, setup);
    let group = BindGroup::new(ctx, pipelines.raycast, &all)?;
    let read_group = match (pipelines.read_segments, later_chunks_setup(setup)) {
        (Some(p), Some(read)) => {
            let all = frame_buffers(gpu_field, constants, targets, table, &read);
            Some((p, BindGroup::new(ctx, p, &all)?))
        }
        _ => None,
    };
    let next_group = next_group(ctx, pipelines.next, constants, targets, &targets.args)?;
    let (w, h) = (setup.camera.width, setup.camera.height);
    let band_rows = band_rows(setup);
    let outer = outer_steps(setup);
    let commands = BandCommands {
        pipeline: pipelines.raycast,
        group: &group,
        later: read_group.as_ref().map(|(p, g)| (*p, g)),
        next: pipelines.next,
        next_group: &next_group,
        args: &targets.args,
        // A brick's window: its columns only (the others were filled as missing rays).
        cols: setup
            .window
            .map_or((0, w), |[x0, _, x1, _]| (x0, (x1 + 1).min(w) - x0)),
        outer,
    };
    let mut chunk = setup.chunk.unwrap_or_else(|| default_chunk(setup));
    let mut gpu_ms = 0.0;
    let mut bands = 0;
    // A brick's window: the pixels outside it are rays that miss its box, written as a missing
    // ray ends (transparent over black, finished, nothing to report) instead of dispatched:
    // on lavapipe a ray that misses still costs 160 ns (ML 128³ at 512², all rays missing:
    // 43 ms), which every brick would pay for every pixel.
    let (mut row, end) = match setup.window {
        Some([_, y0, _, y1]) => {
            let timings = ctx.submit(|rec| {
                rec.fill(&targets.image, 0);
                rec.fill(&targets.counts, ray_count::DONE);
                rec.fill(&targets.ray_stats, 0);
                Ok(())
            })?;
            gpu_ms += timings.iter().filter_map(|t| t.gpu_ms).sum::<f64>();
            (y0, (y1 + 1).min(h))
        }
        None => (0, h),
    };
    while row < end {
        let rows = band_rows.min(end - row);
        let band_counts: Vec<u32> = loop {
            let timings =
                ctx.submit(|rec| commands.record(rec, row, rows, chunk, 0).map(|_| ()))?;
            gpu_ms += timings.iter().filter_map(|t| t.gpu_ms).sum::<f64>();
            bands += 1;
            if stop.is_some_and(|s| s.load(Ordering::Relaxed)) {
                return Ok(Bands::Stopped);
            }
            let counts = targets
                .counts
                .read_range(ctx, (row * w) as usize, (rows * w) as usize)?;
            if counts.iter().any(|c| c & ray_count::TRUNCATED != 0) {
                // The driver cut a loop short: this band again, from its start, in smaller
                // chunks, which the bands after it keep.
                let Some(smaller) = smaller_chunk(chunk) else {
                    return Err(VkError::Usage(format!(
                        "raycast: the device ended a loop early even for one step per dispatch \
                         (llvmpipe allows 65 535 loop iterations per invocation); rows {row}..{} \
                         cannot be rendered with these settings",
                        row + rows
                    )));
                };
                chunk = smaller;
                continue;
            }
            break counts;
        };
        let pixel_of = |i: usize| (i as u32 % w, row + i as u32 / w);
        if let Some(i) = band_counts
            .iter()
            .position(|c| c & ray_count::HULL_OVERFLOW != 0)
        {
            if (setup.hull_hits as usize) < crate::samples::bvh::MAX_HITS {
                return Ok(Bands::HullHits);
            }
            let (x, y) = pixel_of(i);
            return Err(VkError::Usage(format!(
                "raycast: the ray through pixel ({x}, {y}) crosses the domain's boundary more \
                 than {} times; the mesh is too convoluted for the hull clipper",
                crate::samples::bvh::MAX_HITS
            )));
        }
        if let Some(i) = band_counts.iter().position(|c| c & ray_count::DONE == 0) {
            let (x, y) = pixel_of(i);
            return Err(VkError::Usage(format!(
                "raycast: pixel ({x}, {y}) was not finished after {outer} steps"
            )));
        }
        row += rows;
        progress(f64::from(row) / f64::from(h));
    }
    Ok(Bands::Done(gpu_ms, bands, chunk))
}

/// A ray-cast frame as read back.
pub(crate) struct Readback {
    pub(crate) pixels: Vec<[f32; 4]>,
    /// Evaluations per pixel, flags removed.
    pub(crate) counts: Vec<u32>,
    pub(crate) skip: Option<SkipReport>,
    /// The adaptive integrator's error estimate per pixel ([`pixel_estimate`]).
    pub(crate) error_estimate: Option<Vec<f32>>,
}

/// The skipping report of a frame's per-pixel ray report.
pub(crate) fn skip_report(rays: &[[f32; 4]]) -> SkipReport {
    let mut r = SkipReport::default();
    for p in rays {
        r.add(f64::from(p[0]), p[1] as u64, f64::from(p[2]));
    }
    r
}

/// Pixels and evaluation counts, the skipping report when the frame skipped and the error
/// estimates when it integrated adaptively.
pub(crate) fn read_image(
    ctx: &Context,
    targets: &FrameTargets,
    setup: &RaySetup,
    skip: bool,
) -> Result<Readback, VkError> {
    let n = targets.pixels as usize;
    let rays: Vec<[f32; 4]> = if ray_stats(setup, skip) {
        let mut rays: Vec<[f32; 4]> = targets.ray_stats.read(ctx)?;
        rays.truncate(n);
        rays
    } else {
        Vec::new()
    };
    let report = skip.then(|| skip_report(&rays));
    let mut pixels: Vec<[f32; 4]> = targets.image.read(ctx)?;
    pixels.truncate(n);
    let error_estimate = (setup.method == Method::Adaptive).then(|| {
        rays.iter()
            .zip(&pixels)
            .map(|(r, p)| {
                let (ray, opacity) = (f64::from(r[3]), f64::from(p[3]));
                pixel_estimate(ray, opacity, setup.early_termination) as f32
            })
            .collect()
    });
    let mut counts: Vec<u32> = targets.counts.read(ctx)?;
    counts.truncate(n);
    for c in &mut counts {
        *c &= ray_count::EVALUATIONS;
    }
    Ok(Readback {
        pixels,
        counts,
        skip: report,
        error_estimate,
    })
}
