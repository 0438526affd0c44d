//! Recording a frame into the application's command buffer (issue 28 §2):
//! [`Renderer::record`] records every dispatch of one frame, ray cast or splatted (the
//! splatting half is `splatting.rs`), and the write of its pixels into the application's
//! [`Target`], and returns a [`FrameInFlight`]; the application
//! submits the command buffer when it likes and hands the token back to
//! [`Renderer::retire`] once the submission has completed (its fence signalled, or its
//! timeline semaphore reached the value). Several frames may be in flight: each has its own
//! constants, frame buffers, descriptor set and timestamps (a *slot*), reused only after retire.
//!
//! # Synchronisation contract
//! - vmls's commands read the field's buffers, the preintegration tables and the slot's
//!   constants, and write only the slot's buffers and the target. The target is written once,
//!   by a transfer, after waiting for the target's `before` access; the write is made
//!   available and visible to its `after` access, and an image is left in its `new_layout`.
//! - The frame's last command is a barrier that makes vmls's writes visible to the host, which
//!   [`Renderer::retire`] reads (the frame's per-pixel status).
//! - Submit the command buffer on the context's queue (`RawContext::queue`), or on another queue
//!   of the same family that the application synchronises with it. vmls's barriers use
//!   `VK_QUEUE_FAMILY_IGNORED` (no ownership transfer), and the target's `Access` stages must be
//!   ones that family supports (a compute-only family has no fragment stage).
//! - Some calls submit to and wait on the context's queue under vmls's own lock: `render`,
//!   `prepare`, a `record` whose tables changed on a device whose memory the host cannot map,
//!   the first splatting `record` of a renderer that `prepare` did not count entries for,
//!   `retire` where it cannot map the frame's status, and dropping a renderer with frames in
//!   flight. Do not call them while another thread of the application uses that queue.
//! - Keep the target alive and untouched by other work until the frame's submission has
//!   completed; retire every frame before dropping the renderer (a renderer dropped with frames
//!   still in flight waits for its queue to go idle first).
//! - A `record` that fails may leave part of the frame's commands in the command buffer: reset
//!   or discard it rather than submit it.
//! - A frame whose transfer function or table resolution changed builds and uploads its
//!   preintegration tables before recording, and a frame of a new variant compiles its pipeline
//!   (unless [`Renderer::prepare`] did both before): host work, and on devices whose memory the
//!   host cannot map, an upload submission of vmls's own.
//!
//! # What `render()` does that a recorded frame cannot
//! The blocking [`Renderer::render`] records each band exactly as a recorded frame does
//! (`raycast::frame::BandCommands`: the first chunk, then each later chunk indirect, its size
//! set by `raycast_next` from the band's rays) but submits it alone and reads its rays' status
//! back before the next: progress and a stop request act between bands, a band that lavapipe's
//! loop limit cut short runs again in smaller chunks, and a frame with a ray of more hull
//! crossings than the first variant keeps renders again with every crossing. A recorded frame
//! records every band up front, and [`Renderer::retire`] reports a frame that the loop limit or
//! the hull cut short as an error, after which the renderer records with smaller chunks or every
//! hull crossing, so that the next frame is right.
//!
//! A splatting frame in `render()` reads its count of footprints back after the projection, to
//! size the entry list and check the budget. A recorded one reserves its list beforehand, and
//! `splat_plan` dispatches the accumulation indirectly, or not at all where the count exceeds
//! the list or the budget; `retire` names which, and after an overflow the next frames reserve
//! the count it saw. Its sheets are rasterized in one dispatch (`render()` submits bands of
//! tile rows, for progress and Ctrl-C), and its background is composited by `target_pack`.

use super::Renderer;
use super::segments::{HullSegments, decide, mark, retire_segments};
use crate::field::RenderError;
use crate::field::skip::SkipReport;
use crate::field::variant::{HullCache, Variant};
use crate::gpu_types::ray_count;
use crate::raycast::RaySetup;
use crate::raycast::frame::{
    BandCommands, FrameConstants, FrameTargets, band_groups, band_rows, constant_data,
    default_chunk, frame_bindings, frame_buffers, frame_targets, later_chunks_setup, next_group,
    next_pipeline, outer_steps, skip_report, smaller_chunk,
};
use crate::raycast::gpu::variant_for_render;
use crate::splat::gpu::GpuKernels;
use crate::view::View;
use crate::vk::{
    BindGroup, Buffer, BufferUsage, ComputePipeline, Context, ExternalCommands, FrameTimer,
    Recorder, Target, TargetFormat, VkError,
};
use std::sync::Arc;

/// A recorded frame. Hand it to [`Renderer::retire`] after its submission completed; until
/// then vmls reuses none of its buffers. Retiring it early is an error that leaves it in flight
/// (retire it again later); retiring it twice is an error.
#[derive(Debug)]
#[must_use = "a recorded frame must be retired, or its buffers are never reused"]
pub struct FrameInFlight {
    renderer: u64,
    slot: usize,
    generation: u32,
}

/// What a retired frame did.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedFrame {
    /// GPU time between the frame's first and last command (`None` where the queue has no
    /// timestamps).
    pub gpu_ms: Option<f64>,
    /// MLS evaluations over all pixels (ray casting), or footprint evaluations (splatting).
    pub evaluations: u64,
    /// Dispatches recorded: the ray caster's (bands × chunks, later chunks indirect), the
    /// `raycast_next` before each later chunk, and the format conversion; or the splatting
    /// stages (`splat_plan`, then `splat_bin`, `splat_order` and `splat_raster` indirect).
    pub dispatches: u32,
    /// The kernel variant, as `--stats` names it.
    pub variant: String,
    /// What empty-space skipping did, where the frame skipped.
    pub skip: Option<SkipReport>,
    /// What splatting did (the splatting methods only).
    pub splat: Option<crate::splat::SplatCounts>,
    /// A mesh, ray cast or splatted post-shaded: whether the frame found its rays' hull
    /// segments or read those of an earlier frame of its slot with the same camera.
    pub hull_segments: Option<HullSegments>,
}

/// The buffers, descriptor sets and timestamps of one frame in flight.
pub(super) struct Slot {
    in_flight: bool,
    generation: u32,
    /// The frame in flight splats (its buffers are `splat`'s).
    splatting: bool,
    /// Constant buffers, reallocated when a frame needs more room.
    constants: Option<FrameConstants>,
    pub(super) targets: Option<FrameTargets>,
    /// The pixels in the target image's format, where it is not RGBA32F (or, splatting, over
    /// a background).
    pub(super) packed: Option<Buffer>,
    /// The bands' indirect dispatch arguments (`raycast_next`), 16 bytes a band.
    args: Option<Buffer>,
    /// The generation of the last frame of this slot that completed: the frame's last command
    /// writes it, so that `retire` can tell a completed frame from one not yet executed.
    pub(super) marker: Buffer,
    /// The tables the frame reads, kept alive while it is in flight.
    pub(super) table: Option<Arc<Buffer>>,
    /// The splat kernels a splatting frame reads, kept alive while it is in flight (a later
    /// frame of another transfer function uploads others).
    pub(super) kernels: Option<Arc<GpuKernels>>,
    groups: Vec<BindGroup<'static>>,
    pub(super) timer: FrameTimer,
    variant: Option<Variant>,
    hull_hits: u32,
    hull_segments: Option<HullSegments>,
    chunk: u32,
    dispatches: u32,
    /// Splatting frames' buffers, from the slot's first splatting frame on.
    pub(super) splat: Option<SplatSlot>,
}

impl Slot {
    /// A free slot's buffers for a first frame.
    fn new(ctx: &Context) -> Result<Self, VkError> {
        Ok(Self {
            in_flight: false,
            generation: 0,
            splatting: false,
            constants: None,
            targets: None,
            packed: None,
            args: None,
            marker: Buffer::new(ctx, "frame completion", 4, BufferUsage::Storage)?,
            table: None,
            kernels: None,
            groups: Vec::new(),
            timer: FrameTimer::new(ctx)?,
            variant: None,
            hull_hits: 0,
            hull_segments: None,
            chunk: 0,
            dispatches: 0,
            splat: None,
        })
    }

    /// Drops the bind groups of the slot's last frame (retired, or never submitted).
    pub(super) fn reset_groups(&mut self) {
        self.groups.clear();
    }

    /// Keeps bind groups alive while the frame is in flight.
    pub(super) fn keep_groups(&mut self, groups: impl IntoIterator<Item = BindGroup<'static>>) {
        self.groups.extend(groups);
    }

    /// Room for `bytes` of packed pixels (`None`: the frame packs nothing).
    pub(super) fn ensure_packed(
        &mut self,
        ctx: &Context,
        bytes: Option<u64>,
    ) -> Result<(), VkError> {
        match (bytes, &self.packed) {
            (Some(n), Some(b)) if b.size() >= n => {}
            (Some(n), _) => {
                self.packed = None;
                self.packed = Some(Buffer::new(ctx, "target pixels", n, BufferUsage::Storage)?);
            }
            (None, _) => {}
        }
        Ok(())
    }

    /// The generation the slot's next frame writes at its end.
    pub(super) fn next_generation(&self) -> u32 {
        self.generation.wrapping_add(1)
    }

    /// Dispatches of the slot's frame in flight.
    pub(super) fn dispatches(&self) -> u32 {
        self.dispatches
    }

    /// Marks the slot in flight with a frame of `generation` just recorded, and returns its
    /// token.
    pub(super) fn begin(
        &mut self,
        index: usize,
        generation: u32,
        dispatches: u32,
        splatting: bool,
        renderer: u64,
    ) -> FrameInFlight {
        self.dispatches = dispatches;
        self.splatting = splatting;
        self.in_flight = true;
        self.generation = generation;
        FrameInFlight {
            renderer,
            slot: index,
            generation,
        }
    }
}

/// A slot's splatting buffers (kept for the slot's next splatting frames) and what its frame
/// in flight needs at retire.
pub(super) struct SplatSlot {
    pub(super) constants: Option<crate::splat::frame::SplatConstants>,
    pub(super) targets: Option<crate::splat::gpu::SplatTargets>,
    /// `splat_plan`'s indirect arguments: splat_bin's, splat_order's two, then each band of
    /// splat_raster's.
    pub(super) args: Option<Buffer>,
    pub(super) setup: Option<crate::splat::SplatSetup>,
    pub(super) plan: crate::gpu_types::PlanPush,
    pub(super) budget: Option<f64>,
    pub(super) variant: String,
    pub(super) invocations: u32,
}

/// What the renderer learnt from retired frames, applied to the next recordings.
#[derive(Default)]
pub(super) struct RecordState {
    /// Outer steps per dispatch after a retired frame was cut short by the loop limit.
    pub(super) chunk: Option<u32>,
    /// Hull crossings after a retired frame had a ray with more than the variant kept.
    pub(super) hull_hits: Option<u32>,
    /// Compiled `target_pack` pipelines by format.
    pub(super) pack: Vec<(TargetFormat, ComputePipeline)>,
    /// The `raycast_next` pipeline (compiled at the first recorded frame).
    pub(super) next: Option<ComputePipeline>,
    /// Splatting: the most entries a frame was seen to bin, which recorded frames' lists make
    /// room for (`None`: the next recorded frame counts them first).
    pub(super) splat_entries: Option<u64>,
    /// Splatting: the most passes after a band's first that a frame's walks were seen to take
    /// (`splat::plan::resumes_needed`), which recorded frames record.
    pub(super) splat_resumes: u32,
}

impl RecordState {
    /// Records the end of a frame: the write of its `image` (`size` pixels) into `target`,
    /// through `target_pack` into `packed` where `pack` is given (a format to convert to, or a
    /// `background` to composite, which is then not black), else copied as it is; then, last,
    /// the frame's generation into its completion `marker`, which `retire` reads back. Returns
    /// the dispatches recorded.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn record_finish(
        &self,
        rec: &mut Recorder<'_>,
        pack: Option<(usize, &BindGroup<'_>)>,
        background: [f32; 3],
        (image, packed): (&Buffer, Option<&Buffer>),
        target: &Target,
        size: (u32, u32),
        (marker, generation): (&Buffer, u32),
    ) -> Result<u32, VkError> {
        let dispatches = self.record_write(rec, pack, background, image, packed, target, size)?;
        rec.fill(marker, generation);
        Ok(dispatches)
    }
}

/// Bytes needed for `data`, at least 16 (a zero-sized binding is invalid).
fn room(data: &[u8]) -> u64 {
    (data.len() as u64).max(16)
}

impl Renderer {
    /// Prepares everything a frame of `view` needs, so that recording it builds nothing: the
    /// field's data on the device, the preintegration tables, the pipelines; for splatting the
    /// kernels, the pipelines and the count of the frame's entries that sizes recorded frames'
    /// lists (a projection of its own: one submission and a wait on the context's queue).
    pub fn prepare(&mut self, view: &View<'_>) -> Result<(), RenderError> {
        if let Some((settings, _)) = self.tolerance_settings(view)? {
            let resolved = View {
                settings: &settings,
                ..*view
            };
            return self.prepare(&resolved);
        }
        if let Some(shading) = view.settings.method.splat_shading() {
            return self.prepare_splat(view, shading);
        }
        let mut setup = self.record_setup(view)?;
        // A mesh's frames have two variants: the one that walks the hull and keeps its
        // segments, and the one that reads them at a camera's later frames.
        let modes: &[HullCache] = match setup.hull_cache {
            HullCache::Off => &[HullCache::Off],
            _ => &[HullCache::Keep, HullCache::Read],
        };
        for &mode in modes {
            setup.hull_cache = mode;
            self.record_pipeline(&setup)?;
        }
        Ok(())
    }

    /// A slot with no frame in flight (a new one if every slot has one).
    pub(super) fn free_slot(&mut self) -> Result<usize, RenderError> {
        if let Some(i) = self.slots.iter().position(|s| !s.in_flight) {
            return Ok(i);
        }
        self.slots.push(Slot::new(&self.ctx)?);
        Ok(self.slots.len() - 1)
    }

    /// The host half of a recorded frame ([`Renderer::ray_frame`] with what retired frames
    /// taught): its ray setup.
    fn record_setup(&mut self, view: &View<'_>) -> Result<RaySetup, RenderError> {
        let mut setup = self.ray_frame(view)?.setup;
        if let Some(h) = self.record.hull_hits {
            setup.hull_hits = h;
        }
        Ok(setup)
    }

    /// A recorded frame's variant, the ray caster's pipeline (its index) and `raycast_next`'s.
    fn record_pipeline(&mut self, setup: &RaySetup) -> Result<(Variant, usize), RenderError> {
        let has_tables = setup.method.preintegrated();
        let variant = variant_for_render(&self.field, setup);
        let bindings = frame_bindings(&self.gpu_field, setup, has_tables, variant.skip);
        let (index, _) = self.ray_pipeline(&variant, bindings)?;
        if self.record.next.is_none() {
            self.record.next = Some(next_pipeline(&self.ctx, &self.compiler)?);
        }
        Ok((variant, index))
    }

    /// Records one frame of `view` (ray cast or splatted) into `cmd` and the write of its pixels into
    /// `target` (see the module documentation for the synchronisation contract). Nothing is
    /// submitted; the returned token must be retired after the submission completes.
    pub fn record(
        &mut self,
        cmd: ExternalCommands,
        view: &View<'_>,
        target: &Target,
    ) -> Result<FrameInFlight, RenderError> {
        if let Some((settings, _)) = self.tolerance_settings(view)? {
            let resolved = View {
                settings: &settings,
                ..*view
            };
            return self.record(cmd, &resolved, target);
        }
        if let Some(shading) = view.settings.method.splat_shading() {
            return self.record_splat(cmd, view, target, shading);
        }
        let mut setup = self.record_setup(view)?;
        let slot_index = self.free_slot()?;
        let hull_segments = decide(
            self.ctx.info(),
            self.slots[slot_index].targets.as_ref(),
            &mut setup,
        );
        let (variant, index) = self.record_pipeline(&setup)?;
        // The later chunks of a frame that keeps its segments read them (BandCommands).
        let read_setup = later_chunks_setup(&setup);
        let read_index = match &read_setup {
            Some(read) => Some(self.record_pipeline(read)?.1),
            None => None,
        };
        // A chunk learned from a cut-short frame applies only where it is smaller than this
        // setup's own (the adaptive integrator's default is far smaller than the others').
        let own = setup.chunk.unwrap_or_else(|| default_chunk(&setup));
        let chunk = self.record.chunk.map_or(own, |learned| learned.min(own));
        let (w, h) = (setup.camera.width, setup.camera.height);
        let pixels = u64::from(w) * u64::from(h);
        target.check(pixels)?;
        let has_tables = setup.method.preintegrated();
        let format = target.format();
        let pack = match format {
            TargetFormat::Rgba32f => None,
            f => Some(self.pack_pipeline(f)?),
        };
        let tables = self.tables.current().filter(|_| has_tables);
        let data = constant_data(&self.field, &setup, view.transfer, tables, variant.skip);
        let ctx = self.ctx.clone();
        let table = if has_tables {
            self.table_buffer.as_ref().map(|(_, b)| b.clone())
        } else {
            None
        };
        let slot = &mut self.slots[slot_index];
        slot.reset_groups();
        // Room for this frame's constants and pixels, kept for the next frames of the slot.
        let fits = slot.constants.as_ref().is_some_and(|c| {
            c.params.size() >= room(&data.params)
                && c.tf.size() >= room(&data.tf)
                && c.iso.size() >= room(&data.iso)
                && match (&data.skip, &c.skip) {
                    (Some(d), Some(b)) => b.size() >= room(d),
                    (None, None) => true,
                    // frame_buffers binds the slot's skip table whenever it has one.
                    _ => false,
                }
        });
        if !fits {
            slot.constants = None;
            let storage =
                |name: &str, bytes: u64| Buffer::new(&ctx, name, bytes, BufferUsage::Storage);
            slot.constants = Some(FrameConstants {
                params: storage("render params", room(&data.params))?,
                tf: storage("transfer function", room(&data.tf))?,
                iso: storage("isosurfaces", room(&data.iso))?,
                skip: data
                    .skip
                    .as_ref()
                    .map(|d| storage("skip table", room(d)))
                    .transpose()?,
            });
        }
        if slot.targets.as_ref().map(|t| t.pixels) != Some(pixels) {
            slot.targets = None;
            slot.targets = Some(frame_targets(&ctx, pixels)?);
        }
        slot.ensure_packed(&ctx, pack.map(|_| pixels * format.bytes()))?;
        let rows_per_band = band_rows(&setup);
        let bands = h.div_ceil(rows_per_band.max(1));
        let args_bytes = 16 * u64::from(bands.max(1));
        if slot.args.as_ref().is_none_or(|a| a.size() < args_bytes) {
            slot.args = None;
            slot.args = Some(Buffer::new(
                &ctx,
                "band dispatch arguments",
                args_bytes,
                BufferUsage::Storage,
            )?);
        }
        slot.table = table;
        if let Some(t) = slot.targets.as_mut() {
            mark(&ctx, t, &setup, true)?;
        }
        let (Some(constants), Some(targets), Some(args), Some(next)) = (
            slot.constants.as_ref(),
            slot.targets.as_ref(),
            slot.args.as_ref(),
            self.record.next.as_ref(),
        ) else {
            return Err(VkError::Usage("recorded frame buffers missing".into()).into());
        };
        let pipeline = &self.pipelines[index].2;
        let bind = |pipeline: &ComputePipeline, setup: &RaySetup| {
            let buffers = frame_buffers(
                &self.gpu_field,
                constants,
                targets,
                slot.table.as_deref(),
                setup,
            );
            BindGroup::new(&ctx, pipeline, &buffers)
        };
        let group = bind(pipeline, &setup)?;
        let read_group = match (read_index, &read_setup) {
            (Some(i), Some(read)) => {
                let p = &self.pipelines[i].2;
                Some((p, bind(p, read)?))
            }
            _ => None,
        };
        let pack_group = match pack {
            Some(p) => Some(
                self.record
                    .pack_group(&ctx, p, &targets.image, &slot.packed)?,
            ),
            None => None,
        };
        let next_group = next_group(&ctx, next, constants, targets, args)?;
        let outer = outer_steps(&setup);
        let generation = slot.next_generation();
        let mut dispatches = 0u32;
        ctx.record_into(cmd, Some(&slot.timer), |rec| {
            rec.update(&constants.params, &data.params)?;
            rec.update(&constants.tf, &data.tf)?;
            rec.update(&constants.iso, &data.iso)?;
            if let (Some(b), Some(d)) = (&constants.skip, &data.skip) {
                rec.update(b, d)?;
            }
            // Every band; each later chunk of a band only for as many workgroups as
            // raycast_next finds rays unfinished (none once they all ended).
            let commands = BandCommands {
                pipeline,
                group: &group,
                later: read_group.as_ref().map(|(p, g)| (*p, g)),
                next,
                next_group: &next_group,
                args,
                cols: (0, w),
                outer,
            };
            let mut row = 0;
            let mut band = 0u32;
            while row < h {
                let rows = rows_per_band.min(h - row);
                dispatches += commands.record(rec, row, rows, chunk, band)?;
                row += rows;
                band += 1;
            }
            dispatches += self.record.record_finish(
                rec,
                pack.zip(pack_group.as_ref()),
                [0.0; 3],
                (&targets.image, slot.packed.as_ref()),
                target,
                (w, h),
                (&slot.marker, generation),
            )?;
            Ok(())
        })?;
        let mut groups = vec![group.detach(), next_group.detach()];
        groups.extend(read_group.map(|(_, g)| g.detach()));
        groups.extend(pack_group.map(|g| g.detach()));
        slot.keep_groups(groups);
        slot.variant = Some(variant);
        slot.hull_hits = setup.hull_hits;
        slot.hull_segments = hull_segments;
        slot.chunk = chunk;
        Ok(slot.begin(slot_index, generation, dispatches, false, self.id))
    }

    /// Takes back a recorded frame whose submission has completed: reads its per-pixel status
    /// and frees its slot for the next frame. A frame cut short (lavapipe's loop limit, or a
    /// ray with more hull crossings than the variant kept) is an error naming what happened;
    /// the renderer then records smaller chunks or every crossing, and the next frame is right.
    pub fn retire(&mut self, frame: &FrameInFlight) -> Result<RecordedFrame, RenderError> {
        let stale = || {
            RenderError::Retired(
                "the frame was not recorded by this renderer, or was retired already".into(),
            )
        };
        if frame.renderer != self.id {
            return Err(stale());
        }
        let ctx = self.ctx.clone();
        let slot = self.slots.get_mut(frame.slot).ok_or_else(stale)?;
        if !slot.in_flight || slot.generation != frame.generation {
            return Err(stale());
        }
        // A frame not yet executed leaves its slot in flight, to be retired again later.
        let marker: Vec<u32> = slot.marker.read(&ctx)?;
        if marker.first() != Some(&frame.generation) {
            return Err(VkError::NotReady(
                "a recorded frame was retired before the GPU completed it: retire a frame only \
                 after the fence or semaphore value of the submission that holds it"
                    .into(),
            )
            .into());
        }
        let gpu_ms = slot.timer.gpu_ms()?;
        slot.in_flight = false;
        slot.groups.clear();
        slot.table = None;
        let kernels = slot.kernels.take();
        if slot.splatting {
            let left_out = kernels.map_or(0, |k| k.left_out());
            return self.retire_splat(frame.slot, gpu_ms, left_out);
        }
        if let Some(t) = slot.targets.as_mut() {
            retire_segments(t);
        }
        let (Some(targets), Some(variant)) = (slot.targets.as_ref(), slot.variant) else {
            return Err(VkError::Usage("retire: the frame's buffers are missing".into()).into());
        };
        let counts: Vec<u32> = targets.counts.read(&ctx)?;
        let counts = &counts[..(targets.pixels as usize).min(counts.len())];
        let skip = if variant.skip {
            let rays: Vec<[f32; 4]> = targets.ray_stats.read(&ctx)?;
            Some(skip_report(&rays[..counts.len().min(rays.len())]))
        } else {
            None
        };
        let (hull_hits, chunk, dispatches) = (slot.hull_hits, slot.chunk, slot.dispatches);
        let slot_segments = slot.hull_segments;
        if counts.iter().any(|c| c & ray_count::HULL_OVERFLOW != 0)
            && (hull_hits as usize) < crate::samples::bvh::MAX_HITS
        {
            self.record.hull_hits = Some(crate::samples::bvh::MAX_HITS as u32);
            return Err(RenderError::Recorded(format!(
                "a ray crossed the hull more than the {hull_hits} times the variant keeps; the \
                 next frames keep {} (record again)",
                crate::samples::bvh::MAX_HITS
            )));
        }
        if let Some(i) = counts
            .iter()
            .position(|c| c & ray_count::HULL_OVERFLOW != 0)
        {
            return Err(RenderError::Recorded(format!(
                "the ray through pixel {i} crosses the domain's boundary more than {} times; \
                 the mesh is too convoluted for the hull clipper",
                crate::samples::bvh::MAX_HITS
            )));
        }
        if counts.iter().any(|c| c & ray_count::TRUNCATED != 0) {
            let Some(smaller) = smaller_chunk(chunk) else {
                return Err(RenderError::Recorded(
                    "the device ended a loop early even for one step per dispatch (llvmpipe \
                     allows 65 535 loop iterations per invocation); this view cannot be \
                     rendered with these settings"
                        .into(),
                ));
            };
            self.record.chunk = Some(smaller);
            return Err(RenderError::Recorded(format!(
                "the device's loop limit cut rays short at {chunk} steps per dispatch; the next \
                 frames record {smaller} (record again)"
            )));
        }
        if let Some(i) = counts.iter().position(|c| c & ray_count::DONE == 0) {
            return Err(RenderError::Recorded(format!(
                "pixel {i} was not finished after every recorded step"
            )));
        }
        Ok(RecordedFrame {
            gpu_ms,
            evaluations: counts
                .iter()
                .map(|c| u64::from(c & ray_count::EVALUATIONS))
                .sum(),
            dispatches,
            variant: variant.name("raycast"),
            skip,
            splat: None,
            hull_segments: slot_segments,
        })
    }

    /// Frames recorded and not yet retired.
    pub fn frames_in_flight(&self) -> usize {
        self.slots.iter().filter(|s| s.in_flight).count()
    }
}

/// Stage `raycast_next`: the workgroup counts of a band's next chunk from its rays' counts
/// after this one (its rows' pixels): the band's groups (`cols` × `rows`) while any ray is
/// unfinished, none (x = 0) once every ray is done or once a ray was cut short
/// (`ray_count::TRUNCATED`: the band is rendered again, so its later chunks would be wasted).
pub fn next_groups(counts: &[u32], cols: u32, rows: u32) -> [u32; 3] {
    let truncated = counts.iter().any(|c| c & ray_count::TRUNCATED != 0);
    if !truncated && counts.iter().any(|c| c & ray_count::DONE == 0) {
        band_groups(cols, rows)
    } else {
        [0, 1, 1]
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn next_groups_stop_a_band_once_its_rays_are_done() {
        use crate::gpu_types::ray_count::DONE;
        assert_eq!(super::next_groups(&[DONE, DONE, 7], 20, 12), [3, 2, 1]);
        assert_eq!(super::next_groups(&[DONE | 5, DONE], 20, 12), [0, 1, 1]);
    }

    #[test]
    fn next_groups_stop_a_band_with_a_truncated_ray() {
        use crate::gpu_types::ray_count::{DONE, TRUNCATED};
        assert_eq!(
            super::next_groups(&[DONE, 7 | TRUNCATED, 3], 20, 12),
            [0, 1, 1]
        );
        assert_eq!(super::next_groups(&[DONE, 7, 3], 20, 12), [3, 2, 1]);
    }

    #[test]
    fn room_is_never_zero() {
        assert_eq!(super::room(&[]), 16);
        assert_eq!(super::room(&[0; 40]), 40);
    }
}
