//! The renderer above both methods: [`Renderer`], the persistent renderer of one dataset, which
//! renders a frame and reads it back ([`Renderer::render`]) or records it into the
//! application's command buffer ([`Renderer::record`], module `record`); and [`render`], one
//! ray-cast frame without a renderer; the ray caster's frame stages are in [`crate::raycast::frame`], the
//! splatter's in [`crate::splat::gpu`].
//!
//! [`Renderer`] owns the field's GPU data (uploaded once), its compiled pipelines, the
//! preintegration tables (rebuilt and re-uploaded only when the transfer function, lengths,
//! resolution or scalar range change) and the frame buffers (reallocated only when the image
//! size changes). A new camera therefore costs only the constants and the dispatches.

use crate::field::gpu::GpuField;
use crate::field::skip::SkipReport;
use crate::field::variant::{HullCache, Variant};
use crate::field::{Field, RenderError, scalar_range};
use crate::raycast::frame::FrameTargets;
use crate::raycast::frame::{
    Bands, FramePipelines, Readback, frame_bindings, frame_constants, frame_pipeline,
    frame_targets, later_chunks_setup, next_pipeline, read_image, run_bands, table_buffer,
    write_tables,
};
pub use crate::raycast::frame::{default_chunk, outer_steps};
use crate::raycast::gpu::variant_for_render;
use crate::raycast::{RaySetup, check_table_size};
use crate::splat::SplatCounts;
use crate::splat::gpu::{GpuKernels, SplatPipelines, SplatTargets};
use crate::view::View;
use crate::view::preintegration::PreintegrationTables;
use crate::view::table_cache::TableCache;
use crate::view::transfer::TransferFunction;
use crate::vk::{Buffer, ComputePipeline, Context, ShaderCompiler, VkError};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

mod record;
mod segments;
mod splatting;
pub mod target;
pub mod tolerance;

pub use crate::vk::{Access, ExternalCommands, Target, TargetFormat};
pub use record::{FrameInFlight, RecordedFrame, next_groups};
pub use segments::HullSegments;

/// Renderer identities, so that a frame is retired only by the renderer that recorded it.
static NEXT_RENDERER: AtomicU64 = AtomicU64::new(1);

/// A rendered image as the GPU produced it.
#[derive(Debug, Clone)]
pub struct GpuImage {
    /// RGBA per pixel, row 0 at the top: (C + T·background, 1 − T).
    pub pixels: Vec<[f32; 4]>,
    /// MLS evaluations per pixel.
    pub counts: Vec<u32>,
    /// Sum of the bands' GPU times.
    pub gpu_ms: f64,
    /// Submissions (bands × chunks).
    pub bands: u32,
    pub variant: String,
    /// The kernels the frame ran: GLSL file and macro definitions, in dispatch order (what
    /// `vmls bench --variant` prints and `--dump-spirv` compiles).
    pub shaders: Vec<(&'static str, Vec<(String, String)>)>,
    /// What splatting did (the splatting methods only).
    pub splat: Option<SplatReport>,
    /// What empty-space skipping did (ray casting with `render.skip` in effect only).
    pub skip: Option<SkipReport>,
    /// The adaptive integrator only: per pixel, the ray's error estimate, the sum of its
    /// accepted intervals' local estimates weighted by the transmittance before them
    /// (DESIGN.md §4), plus what early termination left
    /// ([`crate::raycast::adaptive::pixel_estimate`]); in the measure of
    /// [`tolerance::pixel_errors`], the tables' error not included.
    pub error_estimate: Option<Vec<f32>>,
}

impl GpuImage {
    /// A ray-cast frame as read back, rendered by `variant` in `bands` submissions.
    fn ray_cast(readback: Readback, variant: &Variant, gpu_ms: f64, bands: u32) -> Self {
        Self {
            pixels: readback.pixels,
            counts: readback.counts,
            gpu_ms,
            bands,
            variant: variant.name("raycast"),
            shaders: vec![("raycast/raycast.comp", variant.defines())],
            splat: None,
            skip: readback.skip,
            error_estimate: readback.error_estimate,
        }
    }
}

/// A splatting frame's counters and per-stage GPU time.
#[derive(Debug, Clone, PartialEq)]
pub struct SplatReport {
    pub counts: SplatCounts,
    /// GPU ms of `crate::splat::frame::STAGES`.
    pub stage_ms: [f64; 5],
    /// Sheets in the frame and their thickness in world units.
    pub slabs: u32,
    pub slab_world: f64,
    /// Image tile edge in pixels, pixels per `splat_raster` workgroup (with the apron) and
    /// its invocations.
    pub tile: u32,
    pub group_size: u32,
    pub invocations: u32,
    /// Tile rows per `splat_raster` dispatch (`SplatSetup::band_rows`).
    pub band_rows: u32,
    /// Post-shaded: the ring size (sheet shares per entry and pixel; 0 without) and the rule
    /// of its shares.
    pub ring: u32,
    pub sheet_share: crate::view::SheetShare,
}

fn check_tables(setup: &RaySetup, tables: Option<&PreintegrationTables>) -> Result<(), VkError> {
    if setup.method.preintegrated() && tables.is_none() {
        return Err(VkError::Usage(format!(
            "method '{}' needs preintegration tables",
            setup.method.name()
        )));
    }
    Ok(())
}

/// Ray casts the field once with the setup's method; `tables` must be the setup's
/// preintegration tables for the preintegrated methods. `progress` gets the fraction of rows
/// done. For many frames of one dataset, [`Renderer`] keeps everything between them.
#[allow(clippy::too_many_arguments)]
pub fn render(
    ctx: &Context,
    compiler: &ShaderCompiler,
    field: &Field,
    gpu_field: &GpuField,
    tf: &TransferFunction,
    tables: Option<&PreintegrationTables>,
    setup: &RaySetup,
    mut progress: impl FnMut(f64),
) -> Result<GpuImage, VkError> {
    check_tables(setup, tables)?;
    let mut resolved = setup.clone();
    // Stateless: nothing keeps hull segments for a next frame.
    resolved.hull_cache = HullCache::Off;
    resolved.resolve_skip(gpu_field.blocks(), tf, field);
    // The exact opacity as the setup has it (the caller's tables follow the same setup), with
    // what the kernel's scans of the transfer function unroll over.
    resolved.record_transfer(tf);
    let tables = tables.filter(|_| resolved.method.preintegrated());
    let table = tables.map(|t| table_buffer(ctx, t)).transpose()?;
    let (w, h) = (resolved.camera.width, resolved.camera.height);
    let targets = frame_targets(ctx, u64::from(w) * u64::from(h))?;
    let next = next_pipeline(ctx, compiler)?;
    // Once more with every crossing the CPU twin allows if a ray had more than the first
    // variant keeps (Bands::HullHits).
    let (variant, gpu_ms, bands) = loop {
        let variant = variant_for_render(field, &resolved);
        let pipeline = frame_pipeline(
            ctx,
            compiler,
            &variant,
            &frame_bindings(gpu_field, &resolved, tables.is_some(), variant.skip),
        )?;
        let constants = frame_constants(ctx, field, &resolved, tf, tables, variant.skip)?;
        match run_bands(
            ctx,
            FramePipelines {
                raycast: &pipeline,
                next: &next,
                read_segments: None,
            },
            gpu_field,
            &constants,
            &targets,
            table.as_ref(),
            &resolved,
            &mut progress,
            None,
        )? {
            Bands::Done(ms, bands, _) => break (variant, ms, bands),
            Bands::HullHits => resolved.hull_hits = crate::samples::bvh::MAX_HITS as u32,
            Bands::Stopped => {
                return Err(VkError::Usage(
                    "raycast: stopped without a stop request".into(),
                ));
            }
        }
    };
    let readback = read_image(ctx, &targets, &resolved, variant.skip)?;
    Ok(GpuImage::ray_cast(readback, &variant, gpu_ms, bands))
}

/// What one frame cost, and what it could reuse.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameStats {
    /// GPU time of the dispatches (timestamp queries).
    pub gpu_ms: f64,
    /// Host time of the whole frame.
    pub wall_ms: f64,
    /// Preintegration tables were built (and uploaded) for this frame.
    pub tables_built: bool,
    pub table_ms: f64,
    /// The pipeline was compiled for this frame (a new variant).
    pub pipeline_built: bool,
    /// Frame buffers were (re)allocated (a new image size).
    pub targets_allocated: bool,
    pub bands: u32,
    /// `render.skip = "auto"`: the fraction of ray length it found in empty blocks (skipping
    /// is compiled in at [`crate::raycast::setup::SKIP_AUTO_FRACTION`] or more); `None` where
    /// "auto" did not decide (skipping set, or no fast path).
    pub skip_estimate: Option<f64>,
    /// What `render.tolerance` chose for this view (its pilot frames ran for the first frame
    /// of the view only).
    pub tolerance: Option<tolerance::ToleranceReport>,
    /// A mesh, ray cast or splatted post-shaded: whether the frame found its rays' hull segments
    /// or reused those of an earlier frame of the same camera (`None` without a hull, where the
    /// cache does not fit, or splatting pre-shaded).
    pub hull_segments: Option<HullSegments>,
}

/// A compiled variant: its macro definitions, its bindings and the pipeline.
type CachedPipeline = (Vec<(String, String)>, Vec<u32>, ComputePipeline);

/// The host half of a ray-cast frame ([`Renderer::ray_frame`]).
struct RayFrame {
    setup: RaySetup,
    tables_built: bool,
    table_ms: f64,
}

/// The persistent renderer of one dataset: upload once, render many frames.
pub struct Renderer {
    ctx: Context,
    compiler: ShaderCompiler,
    field: Field,
    gpu_field: GpuField,
    /// Compiled variants with the bindings they were built for.
    pipelines: Vec<CachedPipeline>,
    tables: TableCache,
    /// The uploaded tables and the build they came from (shared with recorded frames that
    /// still read them).
    table_buffer: Option<(usize, Arc<Buffer>)>,
    targets: Option<FrameTargets>,
    /// Splatting: the kernels (uploaded at the first splatting frame), compiled variants and
    /// frame buffers.
    splat_kernels: Option<Arc<GpuKernels>>,
    splat_pipelines: Vec<SplatPipelines>,
    splat_targets: Option<SplatTargets>,
    /// Set from elsewhere (a Ctrl-C handler) to end a frame after its current submission with
    /// [`RenderError::Interrupted`].
    stop: Option<Arc<AtomicBool>>,
    /// MLS or footprint evaluations a frame may plan (`None`: no limit); see
    /// [`Renderer::set_work_budget`].
    budget: Option<f64>,
    /// [`Renderer::set_splat_raster_chunk`].
    splat_raster_chunk: Option<u32>,
    /// Ray casting: a chunk the loop limit taught a frame (`Bands::Done`'s), with the chunk the
    /// setup asked for then; later frames whose setup asks the same use it and are not cut
    /// short again.
    ray_chunk: Option<(u32, u32)>,
    /// This renderer's identity, carried by the frames it records.
    id: u64,
    /// Recorded frames' resources, one slot per frame in flight ([`Renderer::record`]).
    slots: Vec<record::Slot>,
    record: record::RecordState,
    /// The settings `render.tolerance` chose for the last view that had one.
    tolerance: Option<tolerance::Resolved>,
    /// Frames keep their hull segments but do not read kept ones (a tolerance's pilots).
    segments_keep_only: bool,
}

impl Drop for Renderer {
    fn drop(&mut self) {
        // A frame recorded and never retired may still be executing: its buffers must not be
        // freed under it.
        if self.frames_in_flight() > 0
            && let Err(e) = self.ctx.wait_queue_idle()
        {
            eprintln!("vmls: waiting for recorded frames before freeing them failed: {e}");
        }
    }
}

impl Renderer {
    /// Lets `flag` stop frames: once it is set, a frame ends after the submission in flight
    /// (a ray-casting band, or a splatting frame's projection or group of sheets) with
    /// [`RenderError::Interrupted`] and returns no image.
    pub fn set_stop(&mut self, flag: Arc<AtomicBool>) {
        self.stop = Some(flag);
    }

    /// Refuses frames that plan more than `budget` evaluations with
    /// [`RenderError::Budget`] (`None`, the default: no limit; the CLI sets
    /// [`crate::view::WORK_BUDGET`] unless `--force`). Ray casting is checked before any
    /// work of the frame ([`RaySetup::check_budget`]); splatting checks its sheets before any
    /// work and its binned footprints after the projection, before the accumulation
    /// ([`SplatSetup::check_budget`]).
    pub fn set_work_budget(&mut self, budget: Option<f64>) {
        self.budget = budget;
    }

    /// The walk cost one dispatch of `splat_raster` spends per tile
    /// ([`crate::splat::plan::RasterWalk`]; `None`, the default:
    /// [`crate::splat::plan::RASTER_CHUNK`], below llvmpipe's loop limit). It changes how a
    /// tile's walk of its entries is split among passes, never the image: tests force small
    /// ones to exercise the passes on small scenes.
    pub fn set_splat_raster_chunk(&mut self, chunk: Option<u32>) {
        self.splat_raster_chunk = chunk;
    }

    /// Uploads the field's hull; its samples (grid, fast path or samples and octree) follow at
    /// the first ray-cast frame, which builds a deferred octree first: splatting reads
    /// neither.
    pub fn new(ctx: &Context, field: Field) -> Result<Self, RenderError> {
        let gpu_field = GpuField::upload_hull(ctx, &field)?;
        Ok(Self {
            ctx: ctx.clone(),
            compiler: ShaderCompiler::new()?,
            field,
            gpu_field,
            pipelines: Vec::new(),
            tables: TableCache::default(),
            table_buffer: None,
            targets: None,
            splat_kernels: None,
            splat_pipelines: Vec::new(),
            splat_targets: None,
            stop: None,
            budget: None,
            splat_raster_chunk: None,
            ray_chunk: None,
            id: NEXT_RENDERER.fetch_add(1, Ordering::Relaxed),
            slots: Vec::new(),
            record: record::RecordState::default(),
            tolerance: None,
            segments_keep_only: false,
        })
    }

    /// The dataset's field.
    pub fn field(&self) -> &Field {
        &self.field
    }

    /// GPU milliseconds the fast path's fine grid took to build at upload (0 without it): a
    /// cost of the first frame only.
    pub fn fast_path_build_ms(&self) -> f64 {
        self.gpu_field.resample_ms()
    }

    /// The preintegration tables of the last frame that used any.
    pub fn tables(&self) -> Option<&PreintegrationTables> {
        self.tables.current()
    }

    /// Renders one frame; only what the view changed is rebuilt.
    pub fn render(
        &mut self,
        view: &View<'_>,
        mut progress: impl FnMut(f64),
    ) -> Result<(GpuImage, FrameStats), RenderError> {
        let start = Instant::now();
        if let Some((settings, report)) = self.tolerance_settings(view)? {
            let resolved = View {
                settings: &settings,
                ..*view
            };
            let (image, mut stats) = self.render(&resolved, progress)?;
            stats.wall_ms = start.elapsed().as_secs_f64() * 1e3;
            stats.tolerance = Some(report);
            return Ok((image, stats));
        }
        if let Some(shading) = view.settings.method.splat_shading() {
            return self.render_splat(view, shading, start, &mut progress);
        }
        let RayFrame {
            mut setup,
            tables_built,
            table_ms,
        } = self.ray_frame(view)?;
        let has_tables = setup.method.preintegrated();
        let pixels = u64::from(setup.camera.width) * u64::from(setup.camera.height);
        let targets_allocated = self.targets.as_ref().map(|t| t.pixels) != Some(pixels);
        if targets_allocated {
            self.targets = None;
            self.targets = Some(frame_targets(&self.ctx, pixels)?);
        }
        let mut pipeline_built = false;
        // Once more with every crossing the CPU twin allows if a ray had more than the first
        // variant keeps (Bands::HullHits).
        let own_chunk = setup.chunk.unwrap_or_else(|| default_chunk(&setup));
        if let Some((own, learned)) = self.ray_chunk
            && own == own_chunk
        {
            setup.chunk = Some(learned);
        }
        let (variant, gpu_ms, bands, hull_segments) = loop {
            let found = self.render_segments(&mut setup)?;
            let variant = variant_for_render(&self.field, &setup);
            let bindings = frame_bindings(&self.gpu_field, &setup, has_tables, variant.skip);
            let (index, built) = self.ray_pipeline(&variant, bindings)?;
            pipeline_built |= built;
            // The later chunks of a frame that keeps its segments read them (BandCommands).
            let read_index = match later_chunks_setup(&setup) {
                Some(read) => {
                    let variant = variant_for_render(&self.field, &read);
                    let bindings = frame_bindings(&self.gpu_field, &read, has_tables, variant.skip);
                    let (i, built) = self.ray_pipeline(&variant, bindings)?;
                    pipeline_built |= built;
                    Some(i)
                }
                None => None,
            };
            let tables = self.tables.current().filter(|_| has_tables);
            let with_table = tables.is_some();
            let constants = frame_constants(
                &self.ctx,
                &self.field,
                &setup,
                view.transfer,
                tables,
                variant.skip,
            )?;
            if self.record.next.is_none() {
                self.record.next = Some(next_pipeline(&self.ctx, &self.compiler)?);
            }
            let (Some(targets), Some(next)) = (self.targets.as_ref(), self.record.next.as_ref())
            else {
                return Err(VkError::Usage("frame buffers missing".into()).into());
            };
            let table = if with_table {
                self.table_buffer.as_ref().map(|(_, b)| &**b)
            } else {
                None
            };
            match run_bands(
                &self.ctx,
                FramePipelines {
                    raycast: &self.pipelines[index].2,
                    next,
                    read_segments: read_index.map(|i| &self.pipelines[i].2),
                },
                &self.gpu_field,
                &constants,
                targets,
                table,
                &setup,
                &mut progress,
                self.stop.as_deref(),
            )? {
                Bands::Done(ms, bands, chunk) => {
                    if chunk < setup.chunk.unwrap_or(own_chunk) {
                        self.ray_chunk = Some((own_chunk, chunk));
                    }
                    self.segments_stored(&setup);
                    break (variant, ms, bands, found);
                }
                Bands::HullHits => setup.hull_hits = crate::samples::bvh::MAX_HITS as u32,
                Bands::Stopped => return Err(RenderError::Interrupted),
            }
        };
        let Some(targets) = self.targets.as_ref() else {
            return Err(VkError::Usage("frame buffers missing".into()).into());
        };
        let readback = read_image(&self.ctx, targets, &setup, variant.skip)?;
        Ok((
            GpuImage::ray_cast(readback, &variant, gpu_ms, bands),
            FrameStats {
                gpu_ms,
                wall_ms: start.elapsed().as_secs_f64() * 1e3,
                tables_built,
                table_ms,
                pipeline_built,
                targets_allocated,
                bands,
                skip_estimate: setup.skip_estimate,
                tolerance: None,
                hull_segments,
            },
        ))
    }

    /// The host half of a ray-cast frame, shared by [`Renderer::render`] and
    /// [`Renderer::record`]: the ray setup (checked against the work budget), the field's data
    /// on the device (uploaded at the first ray-cast frame), the skipping decision, and the
    /// preintegration tables, built and uploaded only when what they depend on changed.
    fn ray_frame(&mut self, view: &View<'_>) -> Result<RayFrame, RenderError> {
        let mut setup = RaySetup::new(
            view.camera,
            view.settings,
            view.isosurfaces,
            view.lighting,
            &self.field,
        )?;
        if let Some(budget) = self.budget {
            setup.check_budget(budget)?;
        }
        self.choose_hull_cache(&mut setup);
        if !self.gpu_field.has_data() {
            self.field.octree()?;
            self.gpu_field.upload_data(&self.ctx, &self.field)?;
        }
        setup.resolve_skip(self.gpu_field.blocks(), view.transfer, &self.field);
        setup.resolve_exact_opacity(view.transfer, &self.field);
        let lengths = if setup.method.preintegrated() {
            setup.table_lengths(view.transfer)
        } else {
            Vec::new()
        };
        let range = scalar_range(&self.field);
        let (tables_built, table_ms) =
            self.ensure_tables(view, lengths, range, setup.exact_opacity)?;
        let tables = self
            .tables
            .current()
            .filter(|_| setup.method.preintegrated());
        check_tables(&setup, tables)?;
        Ok(RayFrame {
            setup,
            tables_built,
            table_ms,
        })
    }

    /// The preintegration tables of these `lengths` over the scalar `range` for `view`'s
    /// transfer function (none: no tables), checked against the device, built and uploaded
    /// only when what they depend on changed (ray casting's and post-shaded splatting's
    /// alike): whether they were built now, and the milliseconds it took.
    fn ensure_tables(
        &mut self,
        view: &View<'_>,
        lengths: Vec<f64>,
        range: (f64, f64),
        exact_opacity: bool,
    ) -> Result<(bool, f64), RenderError> {
        if lengths.is_empty() {
            return Ok((false, 0.0));
        }
        check_table_size(
            &lengths,
            view.settings.table_resolution,
            (16 * self.ctx.info().max_texel_buffer_elements).min(self.ctx.info().max_heap_bytes),
        )?;
        let builds = self.tables.builds();
        let table_start = Instant::now();
        self.tables.get(
            view.transfer,
            range,
            lengths,
            view.settings.table_resolution,
            exact_opacity,
            |_| {},
        );
        let tables_built = self.tables.builds() != builds;
        let table_ms = if tables_built {
            table_start.elapsed().as_secs_f64() * 1e3
        } else {
            0.0
        };
        if let Some(t) = self.tables.current()
            && self.table_buffer.as_ref().map(|(b, _)| *b) != Some(self.tables.builds())
        {
            let bytes = t.bytes();
            // New tables go into the last ones' buffer where no recorded frame holds it and
            // it is large enough without wasting half: on lavapipe a fresh buffer is fresh
            // pages, and faulting in hundreds of MiB took a third of a tolerance's pilots.
            let reusable = self
                .table_buffer
                .as_mut()
                .and_then(|(_, b)| Arc::get_mut(b))
                .filter(|b| (bytes..=2 * bytes).contains(&b.size()));
            match reusable {
                Some(buffer) => write_tables(&self.ctx, buffer, t)?,
                None => {
                    // The old buffer goes first, so that the two are never held together.
                    self.table_buffer = None;
                    self.table_buffer = Some((0, Arc::new(table_buffer(&self.ctx, t)?)));
                }
            }
            if let Some((built, _)) = &mut self.table_buffer {
                *built = self.tables.builds();
            }
        }
        Ok((tables_built, table_ms))
    }

    /// The pipeline of a ray-caster variant with these bindings (compiled at its first use):
    /// its index in the cache and whether it was compiled now.
    fn ray_pipeline(
        &mut self,
        variant: &Variant,
        bindings: Vec<u32>,
    ) -> Result<(usize, bool), RenderError> {
        let defines = variant.defines();
        if let Some(i) = self
            .pipelines
            .iter()
            .position(|(d, b, _)| *d == defines && *b == bindings)
        {
            return Ok((i, false));
        }
        let p = frame_pipeline(&self.ctx, &self.compiler, variant, &bindings)?;
        self.pipelines.push((defines, bindings, p));
        Ok((self.pipelines.len() - 1, true))
    }
}
