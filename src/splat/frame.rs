//! One splatting frame's commands, for [`splat_frame`] (`Renderer::render`) and for a frame
//! recorded into an application's command buffer ([`SplatRecording`], `Renderer::record`).
//!
//! Both run the same stages on the same buffers: `splat_segments` (post-shaded over a hull),
//! `splat_project`, the three passes of `splat_scan`, `splat_walks`, `splat_bin`, the two of
//! `splat_order` and `splat_raster`. `splat_raster` runs in bands of tile rows
//! ([`RASTER_BAND_ROWS`](super::plan::RASTER_BAND_ROWS) on lavapipe, wider on a GPU: `SplatSetup::band_rows`), each band in as many passes as its longest tile walk takes ([`RasterWalk`]: llvmpipe
//! ends an invocation's loops after 65 535 iterations in a dispatch, and a tile of a dense
//! point cloud walks more entries than that); a pass leaves the walks it could not finish,
//! pixels' registers and all, to the next. The two ways differ in how the accumulation learns
//! the projection's outcome:
//! - [`splat_frame`] is a few submissions. The first runs the projection and the scan; the host
//!   reads the counters, the total of entries and each band's longest walk, to check the work
//!   budget, size the entry list ([`check_projection`]) and count each band's passes. Then
//!   each band is one submission, so that every band is timed and a stop request
//!   ([`FrameControl::stop`]) ends the frame within one band.
//! - A recorded frame has no host between its commands: its entry list is sized before it is
//!   recorded (from an earlier count), and `splat_plan` reads the total and the counters on the
//!   GPU and dispatches `splat_bin`, both passes of `splat_order` and each band of
//!   `splat_raster` indirectly, or none of them where the entries do not fit or a check fails
//!   ([`plan_groups`], its twin). Each
//!   band's later passes are recorded as many times as an earlier count found needed
//!   (`PlanPush::resumes`), those a band does not need dispatching nothing.
//!   `Renderer::retire` reads the same numbers and names what stopped the frame.

use super::gpu::{GpuKernels, ORDER_BINDINGS, SCAN_BINDINGS, SplatPipelines, SplatTargets};
use super::plan::{
    ARGS_BIN, ARGS_ORDER, GROUP, RasterWalk, args_slot, order_groups, order_large_groups,
    plan_groups, raster_bands, resumes_needed, stat_band_entries, walk_push,
};
use super::{Shading, SplatCounts, SplatSetup};
use crate::field::RenderError;
use crate::gpu_types::{PlanPush, ScanPush, SplatParams, binding, params_copies, splat_stat};
use crate::view::preintegration::PreintegrationTables;
use crate::view::transfer::TransferFunction;
use crate::vk::{BindGroup, Buffer, BufferUsage, Context, Recorder, VkError};
use std::sync::atomic::{AtomicBool, Ordering};

/// A splatted frame as the GPU produced it.
#[derive(Debug, Clone)]
pub struct SplatGpuImage {
    /// (C + T·background, 1 − T) per pixel, row 0 at the top.
    pub pixels: Vec<[f32; 4]>,
    pub counts: SplatCounts,
    /// GPU milliseconds of `STAGES`.
    pub stage_ms: [f64; 5],
    pub submissions: u32,
    pub variant: String,
    /// Post-shaded over a hull: whether the pixels' hull segments were those an earlier frame
    /// of the same camera left in the frame buffers (`splat_segments` did not run).
    pub segments_reused: Option<bool>,
}

/// The names of [`SplatGpuImage::stage_ms`]: `splat_sort` is `splat_scan`, `splat_walks` and
/// `splat_bin`, `splat_order` both passes of that stage.
pub const STAGES: [&str; 5] = [
    "splat_project",
    "splat_sort",
    "splat_raster",
    "splat_segments",
    "splat_order",
];

impl SplatGpuImage {
    /// GPU milliseconds of the whole frame.
    pub fn gpu_ms(&self) -> f64 {
        self.stage_ms.iter().sum()
    }
}

/// The frame's parameters; `tf_count` is the length of `tf`'s GPU table, `tables` the
/// preintegration table of post-shaded intervals (`SplatSetup::table_lengths`).
pub(super) fn params(
    setup: &SplatSetup,
    kernels: &GpuKernels,
    tf: &TransferFunction,
    tf_count: u32,
    tables: Option<&PreintegrationTables>,
) -> SplatParams {
    let v = |d: glam::DVec3| [d.x as f32, d.y as f32, d.z as f32, 0.0];
    let l = &setup.lighting;
    let bg = setup.background;
    SplatParams {
        camera: setup.camera.gpu_block(&setup.basis, setup.eye),
        box_min: v(setup.box_lo),
        box_max: v(setup.box_hi),
        background: [bg[0] as f32, bg[1] as f32, bg[2] as f32, 0.0],
        lighting: [
            l.ambient as f32,
            l.diffuse as f32,
            l.specular as f32,
            l.shininess as f32,
        ],
        near: setup.near as f32,
        focal: setup.focal as f32,
        centre_x: setup.centre[0] as f32,
        centre_y: setup.centre[1] as f32,
        slab0_world: setup.slab0 as f32,
        slab_world: setup.slab_world as f32,
        early_termination: setup.early_termination as f32,
        zero_extinction: tf.lookup(0.0).1 as f32,
        cutoff: setup.settings.cutoff as f32,
        lowpass: setup.settings.lowpass as f32,
        sigma: setup.sigma as f32,
        lateral_x: setup.lateral[0].min(f64::from(f32::MAX)) as f32,
        lateral_y: setup.lateral[1].min(f64::from(f32::MAX)) as f32,
        tf_count,
        iso_count: setup.isosurfaces.len() as u32,
        slabs: setup.slabs,
        tiles_x: setup.tiles().0,
        kernel_count: kernels.count,
        sheet_first: setup.window.1[0],
        sheet_last: setup.window.1[1],
        cell_min: v(setup.cell.map_or(glam::DVec3::NEG_INFINITY, |c| c.0)),
        cell_max: v(setup.cell.map_or(glam::DVec3::INFINITY, |c| c.1)),
        pixel_window: setup.window.0,
        tables: tables.map_or_else(Default::default, |t| t.gpu_block(tf)),
        tf: tf.gpu_block(),
    }
}

fn sum_ms(timings: &[crate::vk::DispatchTiming], stage_ms: &mut [f64; 5]) {
    for t in timings {
        let i = match t.label.as_str() {
            "splat_project" => 0,
            "splat_scan" | "splat_walks" | "splat_bin" => 1,
            "splat_raster" => 2,
            "splat_order" => 4,
            _ => 3,
        };
        stage_ms[i] += t.gpu_ms.unwrap_or(0.0);
    }
}

/// What the caller of [`splat_frame`] lets a frame do and hears from it.
pub struct FrameControl<'a> {
    /// With a budget, a frame whose binned entries plan more evaluations
    /// ([`SplatSetup::check_budget`]) ends after the projection, before any accumulation.
    pub budget: Option<f64>,
    /// Once set, the frame ends after the submission in flight with
    /// [`RenderError::Interrupted`]: checked after the projection and after each submission of
    /// the second pass.
    pub stop: Option<&'a AtomicBool>,
    /// The fraction of the frame's submissions done, after each.
    pub progress: &'a mut dyn FnMut(f64),
}

impl FrameControl<'_> {
    fn check_stop(&self) -> Result<(), RenderError> {
        match self.stop {
            Some(s) if s.load(Ordering::Relaxed) => Err(RenderError::Interrupted),
            _ => Ok(()),
        }
    }
}

/// The frame's constants as the kernels read them: parameters, transfer function,
/// isosurfaces.
pub struct ConstantData {
    pub params: Vec<u8>,
    pub tf: Vec<u8>,
    pub iso: Vec<u8>,
}

impl ConstantData {
    /// Points of the transfer function's GPU table.
    pub fn tf_count(&self) -> u32 {
        (self.tf.len() / std::mem::size_of::<crate::gpu_types::TfPoint>()) as u32
    }

    /// The constants of a setup with `tf` over `kernels`, and the preintegration `tables`
    /// its intervals read (`SplatSetup::table_lengths`; None for the projection alone).
    pub fn new(
        setup: &SplatSetup,
        kernels: &GpuKernels,
        tf: &TransferFunction,
        tables: Option<&PreintegrationTables>,
    ) -> Self {
        let gpu_tf = tf.to_gpu();
        let p = params(setup, kernels, tf, gpu_tf.len() as u32, tables);
        let isos = crate::view::shading::iso_buffer_data(&setup.isosurfaces);
        Self {
            params: bytemuck::cast_slice(&params_copies(p)).to_vec(),
            tf: bytemuck::cast_slice(&gpu_tf).to_vec(),
            iso: bytemuck::cast_slice(&isos).to_vec(),
        }
    }
}

/// The buffers of a frame's constants.
pub struct SplatConstants {
    pub params: Buffer,
    pub tf: Buffer,
    pub iso: Buffer,
}

impl SplatConstants {
    /// Buffers with room for `data` (written later, by a recorded frame's commands).
    pub fn new(ctx: &Context, data: &ConstantData) -> Result<Self, VkError> {
        let storage = |name: &str, bytes: &[u8]| {
            Buffer::new(
                ctx,
                name,
                (bytes.len() as u64).max(16),
                BufferUsage::Storage,
            )
        };
        Ok(Self {
            params: storage("splat params", &data.params)?,
            tf: storage("transfer function", &data.tf)?,
            iso: storage("isosurfaces", &data.iso)?,
        })
    }

    /// Buffers holding `data`, written from the host.
    pub fn upload(ctx: &Context, data: &ConstantData) -> Result<Self, VkError> {
        let c = Self::new(ctx, data)?;
        c.params.write(ctx, &data.params)?;
        c.tf.write(ctx, &data.tf)?;
        c.iso.write(ctx, &data.iso)?;
        Ok(c)
    }

    /// The uploaded constants of a frame of `setup` with `tf` over `kernels`, and how its
    /// walks split among passes (which the transfer function's length enters).
    pub fn with_walk(
        ctx: &Context,
        setup: &SplatSetup,
        kernels: &GpuKernels,
        tf: &TransferFunction,
        tables: Option<&PreintegrationTables>,
    ) -> Result<(Self, RasterWalk), RenderError> {
        let data = ConstantData::new(setup, kernels, tf, tables);
        let walk = RasterWalk::new(setup, data.tf_count())?;
        Ok((Self::upload(ctx, &data)?, walk))
    }

    /// Whether `data` fits these buffers.
    pub fn fits(&self, data: &ConstantData) -> bool {
        self.params.size() >= data.params.len() as u64
            && self.tf.size() >= data.tf.len() as u64
            && self.iso.size() >= data.iso.len() as u64
    }

    /// Writes `data` into these buffers as commands of `rec`.
    pub fn record_update(
        &self,
        rec: &mut Recorder<'_>,
        data: &ConstantData,
    ) -> Result<(), VkError> {
        rec.update(&self.params, &data.params)?;
        rec.update(&self.tf, &data.tf)?;
        rec.update(&self.iso, &data.iso)
    }
}

/// The entries a frame's list may hold on this device: one `rg32ui` texel each, within
/// `maxTexelBufferElements` and the largest heap.
pub fn entry_limit(ctx: &Context) -> u64 {
    ctx.info()
        .max_texel_buffer_elements
        .min(ctx.info().max_heap_bytes / 8)
}

/// The bind groups of the projection: `splat_segments` (post-shaded over a hull),
/// `splat_project` and the passes of `splat_scan`.
struct ProjectionGroups<'a> {
    segments: Option<BindGroup<'a>>,
    project: BindGroup<'a>,
    scan: [BindGroup<'a>; 3],
    walks: BindGroup<'a>,
}

impl<'a> ProjectionGroups<'a> {
    fn new(
        ctx: &Context,
        pipelines: &SplatPipelines,
        kernels: &'a GpuKernels,
        t: &'a SplatTargets,
        constants: &'a SplatConstants,
        hull: &[(u32, &'a Buffer)],
    ) -> Result<Self, VkError> {
        let mut project_bind = vec![
            (binding::PARAMS, &constants.params),
            (binding::SPLAT_KERNELS, &kernels.buffer),
            (binding::SPLATS, &t.splats),
            (binding::SPLAT_WORDS, &t.splats),
            (binding::BUCKET_COUNTS, &t.counts),
            (binding::SPLAT_STATS, &t.stats),
        ];
        if pipelines.variant().shading == Shading::Pre {
            project_bind.push((binding::TRANSFER, &constants.tf));
        }
        if pipelines.variant().surfaces {
            project_bind.push((binding::ISO, &constants.iso));
        }
        // Each pass binds a prefix of the same buffers (SCAN_BINDINGS).
        let scan_buffers = [&t.counts, &t.sums, &t.offsets, &t.cursors];
        let scan_bind: Vec<(u32, &Buffer)> = SCAN_BINDINGS.into_iter().zip(scan_buffers).collect();
        // No hull bindings: the frame's camera's segments are in `t` already, and
        // splat_segments does not run.
        let segments = match pipelines.segments.as_ref().filter(|_| !hull.is_empty()) {
            Some(p) => {
                let mut b = vec![
                    (binding::PARAMS, &constants.params),
                    (binding::PIXEL_SEGMENTS, t.segments()?),
                    (binding::SPLAT_STATS, &t.stats),
                ];
                b.extend(hull.iter().copied());
                Some(BindGroup::new(ctx, p, &b)?)
            }
            None => None,
        };
        Ok(Self {
            segments,
            project: BindGroup::new(ctx, &pipelines.project, &project_bind)?,
            scan: [
                BindGroup::new(ctx, &pipelines.scan[0], &scan_bind[..2])?,
                BindGroup::new(ctx, &pipelines.scan[1], &scan_bind[..3])?,
                BindGroup::new(ctx, &pipelines.scan[2], &scan_bind)?,
            ],
            walks: BindGroup::new(
                ctx,
                &pipelines.walks,
                &[
                    (binding::BUCKET_OFFSETS, &t.offsets),
                    (binding::SPLAT_STATS, &t.stats),
                ],
            )?,
        })
    }

    /// Records the counters' reset, then the projection, the scan and `splat_walks`.
    fn record(
        &self,
        rec: &mut Recorder<'_>,
        pipelines: &SplatPipelines,
        t: &SplatTargets,
        setup: &SplatSetup,
        kernels: &GpuKernels,
    ) -> Result<(), VkError> {
        let buckets = setup.buckets();
        let blocks = buckets.div_ceil(u64::from(super::SCAN_BLOCK)) as u32;
        let scan_push = ScanPush {
            buckets: buckets as u32,
            blocks,
            _pad: [0; 2],
        };
        rec.fill(&t.counts, 0);
        rec.fill(&t.stats, 0);
        if let (Some(p), Some(g)) = (&pipelines.segments, &self.segments) {
            rec.dispatch(p, g, &[], pixel_groups(setup), "splat_segments")?;
        }
        rec.dispatch(
            &pipelines.project,
            &self.project,
            &[],
            [kernel_groups(kernels), 1, 1],
            "splat_project",
        )?;
        let push = bytemuck::bytes_of(&scan_push);
        let passes: [[u32; 3]; 3] = [[blocks, 1, 1], [1, 1, 1], [blocks, 1, 1]];
        for ((p, g), groups) in pipelines.scan.iter().zip(&self.scan).zip(passes) {
            rec.dispatch(p, g, push, groups, "splat_scan")?;
        }
        let push = walk_push(setup);
        rec.dispatch(
            &pipelines.walks,
            &self.walks,
            bytemuck::bytes_of(&push),
            order_groups(push.tiles),
            "splat_walks",
        )
    }

    fn detach(self) -> Vec<BindGroup<'static>> {
        let mut v: Vec<BindGroup<'static>> =
            self.segments.into_iter().map(BindGroup::detach).collect();
        v.push(self.project.detach());
        v.extend(self.scan.into_iter().map(BindGroup::detach));
        v.push(self.walks.detach());
        v
    }
}

/// One workgroup of 8 × 8 per pixel block (`splat_segments`).
fn pixel_groups(setup: &SplatSetup) -> [u32; 3] {
    [
        setup.camera.width.div_ceil(8),
        setup.camera.height.div_ceil(8),
        1,
    ]
}

/// Workgroups of the per-kernel stages (`splat_project`, `splat_bin`: each loops over the
/// kernels by the grid's stride).
fn kernel_groups(kernels: &GpuKernels) -> u32 {
    kernels.count.div_ceil(GROUP).clamp(1, 65_535)
}

/// `splat_order`'s push constants: the buckets.
fn order_push(setup: &SplatSetup) -> ScanPush {
    ScanPush {
        buckets: setup.buckets() as u32,
        blocks: 0,
        _pad: [0; 2],
    }
}

/// The bind groups of the accumulation: `splat_bin`, `splat_order` and `splat_raster`.
struct AccumulationGroups<'a> {
    bin: BindGroup<'a>,
    order: [BindGroup<'a>; 2],
    raster: BindGroup<'a>,
}

impl<'a> AccumulationGroups<'a> {
    fn new(
        ctx: &Context,
        pipelines: &SplatPipelines,
        t: &'a SplatTargets,
        constants: &'a SplatConstants,
        table: Option<&'a Buffer>,
        setup: &SplatSetup,
    ) -> Result<Self, VkError> {
        let Some(list) = t.list.as_ref() else {
            return Err(VkError::Usage("splat entry list missing".into()));
        };
        let bin = BindGroup::new(
            ctx,
            &pipelines.bin,
            &[
                (binding::PARAMS, &constants.params),
                (binding::SPLAT_WORDS, &t.splats),
                (binding::BUCKET_CURSORS, &t.cursors),
                (binding::SPLAT_LIST, list),
            ],
        )?;
        let order_buffers = [&t.offsets, list, &t.stats, &t.cursors];
        let order_bind: Vec<(u32, &Buffer)> =
            ORDER_BINDINGS.into_iter().zip(order_buffers).collect();
        let order = [
            BindGroup::new(ctx, &pipelines.order[0], &order_bind)?,
            BindGroup::new(ctx, &pipelines.order[1], &order_bind)?,
        ];
        let mut raster_bind = vec![
            (binding::PARAMS, &constants.params),
            (binding::SPLATS, &t.splats),
            (binding::SPLAT_WORDS, &t.splats),
            (binding::OFFSET_TEXELS, &t.offsets),
            (binding::SPLAT_LIST, list),
            (binding::IMAGE, &t.image),
            (binding::SPLAT_STATS, &t.stats),
            (binding::SPLAT_RASTER_STATE, t.raster_state()?),
        ];
        if setup.shading == Shading::Post {
            raster_bind.push((binding::TRANSFER, &constants.tf));
            raster_bind.push((binding::TRANSFER_TEXELS, &constants.tf));
            if !setup.isosurfaces.is_empty() {
                raster_bind.push((binding::ISO, &constants.iso));
            }
        }
        if pipelines.variant().hull {
            raster_bind.push((binding::PIXEL_SEGMENTS, t.segments()?));
        }
        if pipelines.variant().reads_tables() {
            let Some(table) = table else {
                return Err(VkError::Usage(
                    "post-shaded intervals need the preintegration table".into(),
                ));
            };
            raster_bind.push((binding::PREINT, table));
        }
        Ok(Self {
            bin,
            order,
            raster: BindGroup::new(ctx, &pipelines.raster, &raster_bind)?,
        })
    }
}

/// Refuses a frame whose projection left what the accumulation cannot take, as
/// [`splat_frame`] finds it after its first submission and `Renderer::retire` after a recorded
/// frame: a pixel with more inside segments than kept (post-shaded over a hull), a kernel with
/// more entries than one invocation writes, more entries than the work `budget` allows or than
/// the list can hold on this device (`limit`).
pub fn check_projection(
    setup: &SplatSetup,
    stats: &[u32],
    total: u64,
    budget: Option<f64>,
    limit: u64,
) -> Result<(), RenderError> {
    let stat = |i: usize| stats.get(i).copied().unwrap_or(0);
    let hull = setup.hull && setup.shading == Shading::Post;
    let n = stat(splat_stat::SEGMENT_OVERFLOW);
    if hull && n > 0 {
        return Err(VkError::Usage(format!(
            "splatting: the rays of {n} pixels cross the domain's boundary into more than {} \
             inside segments; post-shaded splatting keeps {0} per pixel: ray cast this mesh",
            super::PIXEL_SEGMENTS
        ))
        .into());
    }
    let oversized = stat(splat_stat::OVERSIZED);
    if oversized > 0 {
        return Err(VkError::Usage(format!(
            "splatting: {oversized} kernels cover more than {} tile × sheet entries each (one \
             invocation writes them); raise splat.slab or splat.tile, or lower the image size",
            super::MAX_KERNEL_ENTRIES
        ))
        .into());
    }
    if let Some(budget) = budget {
        setup.check_budget(total, budget)?;
    }
    if total > limit {
        return Err(VkError::Usage(format!(
            "splatting: {total} binned footprints exceed the entry list's limit of {limit} \
             (maxTexelBufferElements); raise splat.slab or splat.tile, or lower the image size"
        ))
        .into());
    }
    Ok(())
}

/// Refuses a frame in which a tile's walk of its entries was cut short
/// (`splat_stat::RASTER_TRUNCATED`, counted by `splat_raster`): by llvmpipe's loop limit,
/// where [`RasterWalk`] undercounted a walk's loops, or past the band's last pass. Its image
/// would be missing sheets in those tiles.
pub fn check_raster(stats: &[u32]) -> Result<(), RenderError> {
    match stats.get(splat_stat::RASTER_TRUNCATED).copied() {
        Some(n) if n > 0 => Err(RenderError::Setting {
            key: "splat.slab",
            message: format!(
                "expected thicker sheets for this image: walks of image tiles through their \
                 (tile, sheet) entries ended before their last sheet ({n} invocations), cut \
                 short by the 65 535 loop iterations that llvmpipe allows an invocation in a \
                 dispatch although their passes were counted to stay below it; raise \
                 splat.slab (fewer sheets to composite per pass)"
            ),
        }),
        _ => Ok(()),
    }
}

/// The counters of a finished frame; `total` is the scan's total of entries.
fn frame_counts(stats: &[u32], total: u64, invocations: u32) -> SplatCounts {
    let s = |i: usize| u64::from(stats.get(i).copied().unwrap_or(0));
    // splat_raster counts entries once per invocation of the tile's workgroup.
    let per_group = |n: u64| n / u64::from(invocations.max(1));
    SplatCounts {
        projected: s(0),
        culled_near: s(1),
        culled_outside: s(2),
        culled_degenerate: s(3),
        culled_empty: s(4),
        left_out: 0,
        entries: total,
        skipped_occluded: per_group(s(6) | s(13) << 32),
        accumulated: per_group(s(7) | s(14) << 32),
        oversized: s(splat_stat::OVERSIZED),
        evaluated: s(9) | s(11) << 32,
        contributions: s(10) | s(12) << 32,
        unordered: s(splat_stat::UNORDERED),
        large_buckets: s(splat_stat::LARGE_BUCKETS),
        resumed: per_group(s(splat_stat::RESUMED)),
        clear_skipped: s(splat_stat::CLEAR_SKIPPED) | s(splat_stat::CLEAR_SKIPPED_HIGH) << 32,
    }
}

/// A splatting frame recorded into an application's command buffer: its bind groups, built
/// before recording and kept alive (detached) while the frame is in flight.
pub struct SplatRecording<'a> {
    pipelines: &'a SplatPipelines,
    kernels: &'a GpuKernels,
    targets: &'a SplatTargets,
    constants: &'a SplatConstants,
    args: &'a Buffer,
    projection: ProjectionGroups<'a>,
    plan: BindGroup<'a>,
    accumulation: AccumulationGroups<'a>,
    push: PlanPush,
    walk: RasterWalk,
}

impl<'a> SplatRecording<'a> {
    /// The bind groups of a frame of `setup` into `targets`, whose entry list and raster
    /// state must be allocated; `max_entries` is what the work budget allows (`u32::MAX`: no
    /// budget), `walk` and `resumes` how each band's passes are counted and how many after
    /// its first are recorded.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        ctx: &Context,
        pipelines: &'a SplatPipelines,
        kernels: &'a GpuKernels,
        targets: &'a SplatTargets,
        constants: &'a SplatConstants,
        table: Option<&'a Buffer>,
        args: &'a Buffer,
        hull: &[(u32, &'a Buffer)],
        setup: &SplatSetup,
        max_entries: u32,
        walk: RasterWalk,
        resumes: u32,
    ) -> Result<Self, VkError> {
        if !targets.fits(setup, kernels) {
            return Err(VkError::Usage(
                "splat frame buffers do not fit the setup".into(),
            ));
        }
        let Some(plan) = &pipelines.plan else {
            return Err(VkError::Usage("splat_plan is not compiled".into()));
        };
        let (tiles_x, tiles_y) = setup.tiles();
        Ok(Self {
            pipelines,
            kernels,
            targets,
            constants,
            args,
            projection: ProjectionGroups::new(ctx, pipelines, kernels, targets, constants, hull)?,
            plan: BindGroup::new(
                ctx,
                plan,
                &[
                    (binding::BUCKET_OFFSETS, &targets.offsets),
                    (binding::SPLAT_STATS, &targets.stats),
                    (binding::DISPATCH_ARGS, args),
                ],
            )?,
            accumulation: AccumulationGroups::new(
                ctx, pipelines, targets, constants, table, setup,
            )?,
            push: PlanPush {
                buckets: u32::try_from(setup.buckets()).unwrap_or(u32::MAX),
                capacity: u32::try_from(targets.list_capacity()).unwrap_or(u32::MAX),
                max_entries,
                bin_groups: kernel_groups(kernels),
                tiles_x,
                tiles_y,
                segments: u32::from(pipelines.segments.is_some()),
                band_rows: walk.band_rows,
                chunk: walk.chunk,
                sheet_cost: walk.sheet_cost,
                steps: walk.steps,
                resumes,
            },
            walk,
        })
    }

    /// What `splat_plan` was told: the twin [`plan_groups`] of the read-back counters says
    /// whether the accumulation ran.
    pub fn plan(&self) -> PlanPush {
        self.push
    }

    /// Records the frame: constants, projection, scan, `splat_walks`, `splat_plan`, then
    /// `splat_bin`, both passes of `splat_order` and each band's passes of `splat_raster`,
    /// indirect. Returns the dispatches recorded.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        data: &ConstantData,
        setup: &SplatSetup,
    ) -> Result<u32, VkError> {
        let (pipelines, args) = (self.pipelines, self.args);
        let Some(plan) = &pipelines.plan else {
            return Err(VkError::Usage("splat_plan is not compiled".into()));
        };
        self.constants.record_update(rec, data)?;
        self.projection
            .record(rec, pipelines, self.targets, setup, self.kernels)?;
        rec.dispatch(
            plan,
            &self.plan,
            bytemuck::bytes_of(&self.push),
            [1, 1, 1],
            "splat_plan",
        )?;
        rec.dispatch_indirect(
            &pipelines.bin,
            &self.accumulation.bin,
            &[],
            args,
            16 * ARGS_BIN as u64,
            "splat_bin",
        )?;
        let order = order_push(setup);
        let push = bytemuck::bytes_of(&order);
        for ((p, g), slot) in pipelines
            .order
            .iter()
            .zip(&self.accumulation.order)
            .zip(ARGS_ORDER)
        {
            rec.dispatch_indirect(p, g, push, args, 16 * slot as u64, "splat_order")?;
        }
        // Segments, project, three scan passes, walks, plan, bin and two of order, then the
        // bands' passes.
        let mut dispatches = u32::from(self.projection.segments.is_some()) + 9;
        let resumes = self.push.resumes;
        let bands = self.push.tiles_y.div_ceil(self.push.band_rows);
        for band in 0..bands {
            for pass in 0..=resumes {
                let push = self.walk.push(band * self.push.band_rows, pass, resumes);
                rec.dispatch_indirect(
                    &pipelines.raster,
                    &self.accumulation.raster,
                    bytemuck::bytes_of(&push),
                    args,
                    16 * args_slot(bands, resumes, band, pass) as u64,
                    "splat_raster",
                )?;
                dispatches += 1;
            }
        }
        Ok(dispatches)
    }

    /// The bind groups, to keep while the frame is in flight.
    pub fn detach(self) -> Vec<BindGroup<'static>> {
        let mut v = self.projection.detach();
        v.push(self.plan.detach());
        v.push(self.accumulation.bin.detach());
        v.extend(self.accumulation.order.into_iter().map(BindGroup::detach));
        v.push(self.accumulation.raster.detach());
        v
    }
}

/// How a recorded frame ended ([`retired_counts`]).
pub enum Retired {
    /// It ran whole: its counters.
    Counts(SplatCounts),
    /// It binned this many entries, more than its list held, and accumulated nothing; its
    /// walks would have taken this many passes after each band's first.
    Overflowed(u64, u32),
    /// A band's tiles walked more entries than the passes recorded for it take: this many
    /// passes after each band's first would have served.
    Unfinished(u32),
}

/// A retired recorded frame's counters: reads the counters and the total back, refuses the
/// frame as [`check_projection`] would, says where the entries exceeded the list's `capacity`
/// (the plan's) or the bands' walks the passes recorded, and otherwise returns its counts.
pub fn retired_counts(
    ctx: &Context,
    targets: &SplatTargets,
    setup: &SplatSetup,
    plan: &PlanPush,
    budget: Option<f64>,
    invocations: u32,
) -> Result<Retired, RenderError> {
    let (stats, total) = read_counters(ctx, targets, setup)?;
    let needed = resumes_needed(setup, RasterWalk::of_plan(plan), &stats);
    if plan_groups(plan, total, &stats)[0][0] == 0 {
        check_projection(setup, &stats, u64::from(total), budget, entry_limit(ctx))?;
        if total > plan.max_entries {
            return Err(RenderError::Budget {
                planned: setup.work_bound(u64::from(total)),
                unit: "footprint-pixel evaluations",
                budget: budget.unwrap_or(0.0),
                hint: "raise splat.slab or take a smaller image".into(),
            });
        }
        // What is left: the entries did not fit the list.
        return Ok(Retired::Overflowed(u64::from(total), needed));
    }
    if needed > plan.resumes {
        return Ok(Retired::Unfinished(needed));
    }
    check_raster(&stats)?;
    Ok(Retired::Counts(frame_counts(
        &stats,
        u64::from(total),
        invocations,
    )))
}

/// The projection as one submission (pass 1 of [`splat_frame`]): the counters, the total of
/// entries (the one number the host needs: how many entries the sort will write) and the
/// dispatches' timings.
fn project(
    ctx: &Context,
    pipelines: &SplatPipelines,
    kernels: &GpuKernels,
    t: &SplatTargets,
    constants: &SplatConstants,
    setup: &SplatSetup,
    hull: &[(u32, &Buffer)],
) -> Result<(Vec<u32>, u64, Vec<crate::vk::DispatchTiming>), RenderError> {
    let projection = ProjectionGroups::new(ctx, pipelines, kernels, t, constants, hull)?;
    let timings = ctx.submit(|rec| projection.record(rec, pipelines, t, setup, kernels))?;
    drop(projection);
    let (stats, total) = read_counters(ctx, t, setup)?;
    Ok((stats, u64::from(total), timings))
}

/// The projection's counters and the scan's total of entries, read back.
fn read_counters(
    ctx: &Context,
    t: &SplatTargets,
    setup: &SplatSetup,
) -> Result<(Vec<u32>, u32), VkError> {
    let stats: Vec<u32> = t.stats.read(ctx)?;
    let total: Vec<u32> = t.offsets.read_range(ctx, setup.buckets() as usize, 1)?;
    Ok((stats, total.first().copied().unwrap_or(0)))
}

/// The entries a frame of `setup` bins, and the passes after each band's first that its
/// walks take ([`resumes_needed`]), from a projection of its own (one submission and a
/// wait): how a recorded frame's list is sized and its passes counted before anything
/// counted them. Refuses what [`check_projection`] refuses.
#[allow(clippy::too_many_arguments)]
pub fn count_entries(
    ctx: &Context,
    pipelines: &SplatPipelines,
    kernels: &GpuKernels,
    targets: &SplatTargets,
    setup: &SplatSetup,
    tf: &TransferFunction,
    hull: &[(u32, &Buffer)],
    budget: Option<f64>,
) -> Result<(u64, u32), RenderError> {
    if !targets.fits(setup, kernels) {
        return Err(VkError::Usage("splat frame buffers do not fit the setup".into()).into());
    }
    let (constants, walk) = SplatConstants::with_walk(ctx, setup, kernels, tf, None)?;
    let (stats, total, _) = project(ctx, pipelines, kernels, targets, &constants, setup, hull)?;
    check_projection(setup, &stats, total, budget, entry_limit(ctx))?;
    Ok((total, resumes_needed(setup, walk, &stats)))
}

/// Renders one frame; `targets` must fit the setup (see [`SplatTargets::fits`]); `hull` are the
/// field's hull bindings (`GpuField::hull_bindings`), read by post-shaded frames over a hull;
/// `tables` the preintegration table of post-shaded intervals and its buffer
/// (`SplatSetup::table_lengths`, `raycast::frame::table_buffer`'s layout).
#[allow(clippy::too_many_arguments)]
pub fn splat_frame(
    ctx: &Context,
    pipelines: &SplatPipelines,
    kernels: &GpuKernels,
    targets: &mut SplatTargets,
    setup: &SplatSetup,
    tf: &TransferFunction,
    tables: Option<(&PreintegrationTables, &Buffer)>,
    hull: &[(u32, &Buffer)],
    control: FrameControl<'_>,
) -> Result<SplatGpuImage, RenderError> {
    if !targets.fits(setup, kernels) {
        return Err(VkError::Usage("splat frame buffers do not fit the setup".into()).into());
    }
    let (constants, walk) =
        SplatConstants::with_walk(ctx, setup, kernels, tf, tables.map(|t| t.0))?;
    let mut stage_ms = [0.0; 5];
    let (tiles_x, tiles_y) = setup.tiles();
    // The hull segments of this camera, where the last frame of these buffers left them.
    let reused = targets.plan_segments(setup, false);
    let hull = if reused { &[][..] } else { hull };
    let (stats, total, timings) =
        project(ctx, pipelines, kernels, targets, &constants, setup, hull)?;
    sum_ms(&timings, &mut stage_ms);
    let band = walk.band_rows;
    let submissions_planned = 1 + tiles_y.div_ceil(band);
    (control.progress)(1.0 / f64::from(submissions_planned));
    control.check_stop()?;
    let limit = entry_limit(ctx);
    check_projection(setup, &stats, total, control.budget, limit)?;
    targets.reserve_entries(ctx, total, limit)?;
    targets.reserve_raster_state(ctx, pipelines.variant(), tiles_x, band)?;
    let mut band_passes = stat_band_entries(&stats, raster_bands(setup)).map(|e| walk.passes(e));

    // Pass 2: the scatter, then the tiles in bands of rows.
    let t = &*targets;
    let groups =
        AccumulationGroups::new(ctx, pipelines, t, &constants, tables.map(|t| t.1), setup)?;
    let mut submissions = 1;
    let mut row = 0;
    while row < tiles_y {
        let rows = band.min(tiles_y - row);
        let first = row == 0;
        let passes = band_passes.next().unwrap_or(1);
        let timings = ctx.submit(|rec| {
            if first {
                rec.dispatch(
                    &pipelines.bin,
                    &groups.bin,
                    &[],
                    [kernel_groups(kernels), 1, 1],
                    "splat_bin",
                )?;
                let order = order_push(setup);
                let push = bytemuck::bytes_of(&order);
                let buckets = setup.buckets() as u32;
                let groups_of = [
                    order_groups(buckets),
                    order_large_groups(buckets, u32::try_from(total).unwrap_or(u32::MAX)),
                ];
                for ((p, g), n) in pipelines.order.iter().zip(&groups.order).zip(groups_of) {
                    rec.dispatch(p, g, push, n, "splat_order")?;
                }
            }
            for pass in 0..passes {
                let push = walk.push(row, pass, passes - 1);
                rec.dispatch(
                    &pipelines.raster,
                    &groups.raster,
                    bytemuck::bytes_of(&push),
                    [tiles_x, rows, 1],
                    "splat_raster",
                )?;
            }
            Ok(())
        })?;
        sum_ms(&timings, &mut stage_ms);
        submissions += 1;
        row += rows;
        (control.progress)(f64::from(submissions) / f64::from(submissions_planned));
        control.check_stop()?;
    }
    drop(groups);
    let image: Vec<[f32; 4]> = t.image.read(ctx)?;
    let stats: Vec<u32> = t.stats.read(ctx)?;
    check_raster(&stats)?;
    let segments_reused = t.has_segments().then_some(reused);
    targets.hold_segments(setup);
    let bg = setup.background.map(|c| c as f32);
    let n = (setup.camera.width * setup.camera.height) as usize;
    let pixels = image
        .iter()
        .take(n)
        .map(|&a| crate::view::shading::composite_background(a, bg))
        .collect();
    Ok(SplatGpuImage {
        pixels,
        counts: {
            let mut c = frame_counts(&stats, total, pipelines.variant().group);
            c.add_left_out(kernels.left_out());
            c
        },
        stage_ms,
        submissions,
        variant: pipelines.variant().name(),
        segments_reused,
    })
}
