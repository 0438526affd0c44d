//! The renderer's splatting frames: [`Renderer::render`]'s (a few submissions, the host
//! between the projection and the accumulation: `splat::frame::splat_frame`) and recorded ones
//! ([`Renderer::record`] with a splatting method: every command in the application's command
//! buffer, `splat_plan` deciding on the GPU what the host decides in `render()`).
//!
//! A recorded frame's entry list is sized before the frame runs. The first splatting frame
//! that [`Renderer::prepare`] or [`Renderer::record`] meets counts its entries with a
//! projection of its own (one submission and a wait on the context's queue); the list holds
//! half as many again. A later frame that bins more than its list holds runs no
//! accumulation, and [`Renderer::retire`] reports it as [`RenderError::Recorded`] after
//! growing what the next frames reserve.

use super::record::{FrameInFlight, RecordedFrame, Slot, SplatSlot};
use super::segments::HullSegments;
use super::{FrameStats, GpuImage, Renderer, SplatReport};
use crate::field::RenderError;
use crate::gpu_types::PlanPush;
use crate::splat::frame::{
    ConstantData, FrameControl, Retired, SplatConstants, SplatRecording, count_entries,
    entry_limit, retired_counts, splat_frame,
};
use crate::splat::gpu::{GpuKernels, SplatPipelines, SplatTargets, SplatVariant};
use crate::splat::plan::{RasterWalk, plan_args_bytes};
use crate::splat::{Shading, SplatSetup};
use crate::view::View;
use crate::view::preintegration::PreintegrationTables;
use crate::view::shading::Isosurface;
use crate::view::table_cache::TableCache;
use crate::vk::{Buffer, BufferUsage, ExternalCommands, Target, TargetFormat, VkError};
use std::sync::Arc;
use std::time::Instant;

/// A splatting frame's host half: its setup, with the kernels on the device and the
/// variant's pipelines compiled.
struct SplatFrame {
    setup: SplatSetup,
    variant: SplatVariant,
    /// The pipelines' index in `Renderer::splat_pipelines`.
    index: usize,
    pipeline_built: bool,
}

impl Renderer {
    /// The host half of a splatting frame: setup, kernels (uploaded once, again where the
    /// surface splats change), the variant's pipelines (compiled once; with `splat_plan`
    /// where the frame is `recorded`).
    fn splat_setup(
        &mut self,
        view: &View<'_>,
        shading: Shading,
        recorded: bool,
    ) -> Result<SplatFrame, RenderError> {
        let mut setup = SplatSetup::new(
            shading,
            &view.settings.splat,
            view.camera,
            view.settings.early_termination,
            view.settings.background,
            view.isosurfaces,
            view.lighting,
            &self.field,
        )?;
        setup.raster_chunk = self.splat_raster_chunk;
        setup.table_resolution = view.settings.table_resolution;
        setup.fit_device(self.ctx.info().device_type == "cpu");
        setup.fit_transfer(&self.field, view.transfer);
        setup.resolve_exact_opacity(view.settings.exact_opacity, &self.field, view.transfer);
        if let Some(budget) = self.budget {
            setup.check_budget(0, budget)?;
        }
        let surfaces: &[Isosurface] = if setup.settings.surface {
            &setup.isosurfaces
        } else {
            &[]
        };
        // Pre-shaded frames draw only the kernels their transfer function does not make
        // transparent; a recorded frame in flight keeps the kernels it reads.
        let classify = (shading == Shading::Pre).then_some(view.transfer);
        if !self
            .splat_kernels
            .as_ref()
            .is_some_and(|k| k.serve(surfaces, classify))
        {
            self.splat_kernels = None;
            let kernels = crate::splat::surface::surface_kernels(&self.field, surfaces)?;
            self.splat_kernels = Some(Arc::new(GpuKernels::upload(
                &self.ctx,
                &self.field,
                surfaces,
                kernels,
                classify,
            )?));
        }
        let variant = SplatVariant::of(&setup, self.ctx.info());
        let cached = self
            .splat_pipelines
            .iter()
            .position(|p| *p.variant() == variant);
        let pipeline_built = cached.is_none();
        let index = match cached {
            Some(i) => i,
            None => {
                let p = SplatPipelines::new(&self.ctx, &self.compiler, &variant)?;
                self.splat_pipelines.push(p);
                self.splat_pipelines.len() - 1
            }
        };
        if recorded {
            self.splat_pipelines[index].with_plan(&self.ctx, &self.compiler)?;
        }
        Ok(SplatFrame {
            setup,
            variant,
            index,
            pipeline_built,
        })
    }

    /// The preintegration table of `setup`'s post-shaded intervals (none for constant sheets
    /// and pre-shaded frames), built and uploaded where it changed: whether it was built now,
    /// and the milliseconds it took.
    fn ensure_splat_tables(
        &mut self,
        view: &View<'_>,
        setup: &SplatSetup,
    ) -> Result<(bool, f64), RenderError> {
        let range = setup.table_range(&self.field, view.transfer);
        self.ensure_tables(view, setup.table_lengths(), range, setup.exact_opacity)
    }

    /// The renderer's own frame buffers (`render()`'s), fitted to `setup`; whether they were
    /// allocated.
    fn splat_targets_for(&mut self, setup: &SplatSetup) -> Result<bool, RenderError> {
        let Some(kernels) = self.splat_kernels.as_ref() else {
            return Err(VkError::Usage("splat kernels missing".into()).into());
        };
        let fits = self
            .splat_targets
            .as_ref()
            .is_some_and(|t| t.fits(setup, kernels));
        if !fits {
            self.splat_targets = None;
            self.splat_targets = Some(SplatTargets::new(&self.ctx, setup, kernels)?);
        }
        Ok(!fits)
    }

    /// One splatting frame: kernels uploaded once, variants and buffers kept between frames.
    pub(super) fn render_splat(
        &mut self,
        view: &View<'_>,
        shading: Shading,
        start: Instant,
        progress: &mut dyn FnMut(f64),
    ) -> Result<(GpuImage, FrameStats), RenderError> {
        let frame = self.splat_setup(view, shading, false)?;
        let (tables_built, table_ms) = self.ensure_splat_tables(view, &frame.setup)?;
        let targets_allocated = self.splat_targets_for(&frame.setup)?;
        let (Some(kernels), Some(targets)) =
            (self.splat_kernels.as_ref(), self.splat_targets.as_mut())
        else {
            return Err(VkError::Usage("splat frame buffers missing".into()).into());
        };
        let setup = &frame.setup;
        let table = splat_table(&self.tables, &self.table_buffer, &frame.variant)?;
        let tables = table.map(|(t, b)| (t, &**b));
        let image = splat_frame(
            &self.ctx,
            &self.splat_pipelines[frame.index],
            kernels,
            targets,
            setup,
            view.transfer,
            tables,
            &self.gpu_field.hull_bindings(),
            FrameControl {
                budget: self.budget,
                stop: self.stop.as_deref(),
                progress,
            },
        )?;
        let gpu_ms = image.gpu_ms();
        let n = image.pixels.len();
        let variant = &frame.variant;
        Ok((
            GpuImage {
                pixels: image.pixels,
                counts: vec![0; n],
                gpu_ms,
                bands: image.submissions,
                variant: image.variant,
                shaders: variant
                    .kernels()
                    .into_iter()
                    .map(|k| (k, variant.defines()))
                    .collect(),
                splat: Some(SplatReport {
                    counts: image.counts,
                    stage_ms: image.stage_ms,
                    slabs: setup.slabs,
                    slab_world: setup.slab_world,
                    tile: setup.tile,
                    group_size: setup.group_size(),
                    invocations: variant.group,
                    band_rows: setup.band_rows,
                    ring: variant.ring,
                    sheet_share: variant.sheet_share,
                }),
                skip: None,
                error_estimate: None,
            },
            FrameStats {
                gpu_ms,
                wall_ms: start.elapsed().as_secs_f64() * 1e3,
                tables_built,
                table_ms,
                pipeline_built: frame.pipeline_built,
                targets_allocated,
                bands: image.submissions,
                skip_estimate: None,
                tolerance: None,
                hull_segments: image.segments_reused.map(HullSegments::of),
            },
        ))
    }

    /// Counts the entries of a frame of `view` with a projection of its own, and the passes its
    /// walks take, so that recorded frames reserve room for them and record as many; returns
    /// the count.
    fn count_splat_entries(
        &mut self,
        view: &View<'_>,
        frame: &SplatFrame,
    ) -> Result<u64, RenderError> {
        self.splat_targets_for(&frame.setup)?;
        // The count's own splat_segments rewrites the buffers' segments.
        if let Some(t) = self.splat_targets.as_mut() {
            t.forget_segments();
        }
        let (Some(kernels), Some(targets)) =
            (self.splat_kernels.as_ref(), self.splat_targets.as_ref())
        else {
            return Err(VkError::Usage("splat frame buffers missing".into()).into());
        };
        let (total, resumes) = count_entries(
            &self.ctx,
            &self.splat_pipelines[frame.index],
            kernels,
            targets,
            &frame.setup,
            view.transfer,
            &self.gpu_field.hull_bindings(),
            self.budget,
        )?;
        let learned = self.record.splat_entries.unwrap_or(0).max(total);
        self.record.splat_entries = Some(learned);
        self.record.splat_resumes = self.record.splat_resumes.max(resumes);
        Ok(total)
    }

    /// [`Renderer::prepare`] for a splatting view: kernels, pipelines, and the entry count
    /// that recorded frames reserve room for.
    pub(super) fn prepare_splat(
        &mut self,
        view: &View<'_>,
        shading: Shading,
    ) -> Result<(), RenderError> {
        let frame = self.splat_setup(view, shading, true)?;
        self.ensure_splat_tables(view, &frame.setup)?;
        self.count_splat_entries(view, &frame)?;
        Ok(())
    }

    /// [`Renderer::record`] for a splatting view.
    pub(super) fn record_splat(
        &mut self,
        cmd: ExternalCommands,
        view: &View<'_>,
        target: &Target,
        shading: Shading,
    ) -> Result<FrameInFlight, RenderError> {
        let frame = self.splat_setup(view, shading, true)?;
        self.ensure_splat_tables(view, &frame.setup)?;
        let setup = &frame.setup;
        let (w, h) = (setup.camera.width, setup.camera.height);
        let pixels = u64::from(w) * u64::from(h);
        target.check(pixels)?;
        if self.record.splat_entries.is_none() {
            self.count_splat_entries(view, &frame)?;
        }
        let reserve = self.record.splat_entries.unwrap_or(0);
        let background = setup.background.map(|c| c as f32);
        let format = target.format();
        // Splatting composites its background after the accumulation: in `target_pack`.
        let pack = if format == TargetFormat::Rgba32f && background == [0.0; 3] {
            None
        } else {
            Some(self.pack_pipeline(format)?)
        };
        let slot_index = self.free_slot()?;
        let Some(kernels) = self.splat_kernels.as_ref() else {
            return Err(VkError::Usage("splat kernels missing".into()).into());
        };
        let table = splat_table(&self.tables, &self.table_buffer, &frame.variant)?;
        let data = ConstantData::new(setup, kernels, view.transfer, table.map(|t| t.0));
        let table = table.map(|t| t.1.clone());
        let limit = entry_limit(&self.ctx);
        let ctx = self.ctx.clone();
        let slot: &mut Slot = &mut self.slots[slot_index];
        slot.reset_groups();
        // Kept alive while the frame is in flight (released at retire).
        slot.table = table;
        slot.kernels = Some(kernels.clone());
        if slot.splat.is_none() {
            slot.splat = Some(SplatSlot {
                constants: None,
                targets: None,
                args: None,
                setup: None,
                plan: PlanPush::default(),
                budget: None,
                variant: String::new(),
                invocations: 1,
            });
        }
        slot.ensure_packed(&ctx, pack.map(|_| pixels * format.bytes()))?;
        let generation = slot.next_generation();
        let Some(s) = slot.splat.as_mut() else {
            return Err(VkError::Usage("splat slot missing".into()).into());
        };
        if !s.constants.as_ref().is_some_and(|c| c.fits(&data)) {
            s.constants = None;
            s.constants = Some(SplatConstants::new(&ctx, &data)?);
        }
        if !s.targets.as_ref().is_some_and(|t| t.fits(setup, kernels)) {
            s.targets = None;
            s.targets = Some(SplatTargets::new(&ctx, setup, kernels)?);
        }
        // The slot's segments, where its last frame left this camera's: splat_segments does
        // not run; else it does, and they are the slot's once the frame is retired.
        let mut reused = false;
        if let Some(t) = s.targets.as_mut() {
            t.reserve_entries(&ctx, reserve, limit)?;
            t.reserve_raster_state(&ctx, &frame.variant, setup.tiles().0, setup.band_rows)?;
            reused = t.plan_segments(setup, true);
        }
        let resumes = self.record.splat_resumes;
        let args_bytes = plan_args_bytes(setup, resumes);
        if s.args.as_ref().is_none_or(|a| a.size() < args_bytes) {
            s.args = None;
            s.args = Some(Buffer::new(
                &ctx,
                "splat dispatch arguments",
                args_bytes,
                BufferUsage::Storage,
            )?);
        }
        let (Some(constants), Some(targets), Some(args)) =
            (s.constants.as_ref(), s.targets.as_ref(), s.args.as_ref())
        else {
            return Err(VkError::Usage("recorded splat buffers missing".into()).into());
        };
        let max_entries = setup.max_entries(self.budget);
        let pipelines = &self.splat_pipelines[frame.index];
        let hull = if reused {
            Vec::new()
        } else {
            self.gpu_field.hull_bindings()
        };
        let recording = SplatRecording::new(
            &ctx,
            pipelines,
            kernels,
            targets,
            constants,
            slot.table.as_deref(),
            args,
            &hull,
            setup,
            max_entries,
            RasterWalk::new(setup, data.tf_count())?,
            resumes,
        )?;
        let pack_group = match pack {
            Some(p) => Some(
                self.record
                    .pack_group(&ctx, p, targets.image(), &slot.packed)?,
            ),
            None => None,
        };
        let mut dispatches = 0;
        ctx.record_into(cmd, Some(&slot.timer), |rec| {
            dispatches = recording.record(rec, &data, setup)?;
            dispatches += self.record.record_finish(
                rec,
                pack.zip(pack_group.as_ref()),
                background,
                (targets.image(), slot.packed.as_ref()),
                target,
                (w, h),
                (&slot.marker, generation),
            )?;
            Ok(())
        })?;
        s.plan = recording.plan();
        s.setup = Some(frame.setup.clone());
        s.budget = self.budget;
        s.variant = frame.variant.name();
        s.invocations = frame.variant.group;
        let mut groups = recording.detach();
        groups.extend(pack_group.map(|g| g.detach()));
        slot.keep_groups(groups);
        Ok(slot.begin(slot_index, generation, dispatches, true, self.id))
    }

    /// [`Renderer::retire`] for a slot whose frame splatted, once it completed; `left_out` is
    /// what its kernels' upload left out as transparent (`SplatCounts::left_out`).
    pub(super) fn retire_splat(
        &mut self,
        slot: usize,
        gpu_ms: Option<f64>,
        left_out: u64,
    ) -> Result<RecordedFrame, RenderError> {
        let ctx = self.ctx.clone();
        let slot = &mut self.slots[slot];
        let dispatches = slot.dispatches();
        let Some(SplatSlot {
            targets: Some(targets),
            setup: Some(setup),
            plan,
            budget,
            variant,
            invocations,
            ..
        }) = slot.splat.as_mut()
        else {
            return Err(VkError::Usage("retire: the frame's buffers are missing".into()).into());
        };
        match retired_counts(&ctx, targets, setup, plan, *budget, *invocations)? {
            Retired::Counts(mut counts) => {
                counts.add_left_out(left_out);
                let hull_segments = targets.retire_segments().map(HullSegments::of);
                Ok(RecordedFrame {
                    gpu_ms,
                    evaluations: counts.evaluated,
                    dispatches,
                    variant: variant.clone(),
                    skip: None,
                    splat: Some(counts),
                    hull_segments,
                })
            }
            Retired::Unfinished(needed) => {
                let held = plan.resumes + 1;
                self.record.splat_resumes = self.record.splat_resumes.max(needed);
                Err(RenderError::Recorded(format!(
                    "a band's tiles walked more entries than the {held} passes of splat_raster \
                     recorded for it take (llvmpipe's loop limit), and its image is incomplete; \
                     the next frames record {} (record again)",
                    needed + 1
                )))
            }
            Retired::Overflowed(total, needed) => {
                self.record.splat_resumes = self.record.splat_resumes.max(needed);
                let held = plan.capacity;
                let learned = self.record.splat_entries.unwrap_or(0).max(total);
                self.record.splat_entries = Some(learned);
                Err(RenderError::Recorded(format!(
                    "the frame binned {total} footprints, more than the {held} its entry list \
                     held, and was not accumulated; the next frames reserve room for {learned} \
                     (record again)"
                )))
            }
        }
    }
}

/// The table a frame of `variant` reads and its buffer, from the renderer's `tables` and
/// `buffer` (`Renderer::ensure_splat_tables` ran before): None where it reads none. A free
/// function, so that it borrows those two fields only.
fn splat_table<'a>(
    tables: &'a TableCache,
    buffer: &'a Option<(usize, Arc<Buffer>)>,
    variant: &SplatVariant,
) -> Result<Option<(&'a PreintegrationTables, &'a Arc<Buffer>)>, RenderError> {
    if !variant.reads_tables() {
        return Ok(None);
    }
    match (tables.current(), buffer) {
        (Some(t), Some((_, b))) => Ok(Some((t, b))),
        _ => Err(VkError::Usage("post-shaded intervals' table missing".into()).into()),
    }
}
