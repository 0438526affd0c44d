//! Driving `raycast.comp`: the stages of one frame, and [`Renderer`], the persistent renderer
//! of one dataset.
//!
//! A frame runs these stages, each its own function:
//! - `frame_pipeline`: the shader variant the field and setup need (compiled, or cached);
//! - `frame_constants`: kernel constants, transfer function and isosurfaces (small, per frame);
//! - `frame_targets`: image, counts and ray-state buffers (per image size);
//! - `run_bands`: the image in bands of rows, one submission per chunk of outer steps, with the
//!   loop-limit fallback (LAVAPIPE.md: llvmpipe ends loops after 65 535 iterations);
//! - `read_image`: pixels and evaluation counts back to the host.
//!
//! [`Renderer`] owns the field's GPU data (uploaded once), its compiled pipelines, the
//! preintegration tables (rebuilt and re-uploaded only when the transfer function, lengths,
//! resolution or scalar range change) and the frame buffers (reallocated only when the image
//! size changes). A new camera therefore costs only the constants and the dispatches.

use super::gpu::{GpuField, Variant, pipeline_for, render_params, table_params};
use super::preintegration::PreintegrationTables;
use super::shading::{Isosurface, Lighting};
use super::skip::{SkipReport, SkipTable};
use super::transfer::TransferFunction;
use super::{Field, Method, RaySetup, RenderError, RenderSettings, TableCache};
use crate::gpu_types::{IsoSurface, RayPush, binding, ray_count};
use crate::render::camera::Camera;
use crate::splat::SplatCounts;
use crate::splat::SplatSetup;
use crate::splat::gpu::{GpuKernels, SplatPipelines, SplatTargets, SplatVariant, splat_frame};
use crate::vk::{
    BindGroup, Buffer, BufferUsage, ComputePipeline, Context, ShaderCompiler, VkError,
};
use std::time::Instant;

/// Pixels per band (one submission each).
const BAND_PIXELS: u32 = 16 * 1024;

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
}

/// A splatting frame's counters and per-stage GPU time.
#[derive(Debug, Clone, PartialEq)]
pub struct SplatReport {
    pub counts: SplatCounts,
    /// GPU ms of splat_project, splat_bin, splat_accumulate (all sheets), splat_composite.
    pub stage_ms: [f64; 4],
    /// Sheets in the frame and their thickness in world units.
    pub slabs: u32,
    pub slab: f64,
}

/// Outer steps of the longest possible ray: midpoint steps or fixed intervals of `step`, or
/// adaptive top intervals of l_max, over the box diagonal, plus one per possible segment (each
/// inside segment of a hull rounds its own count up).
pub fn outer_steps(setup: &RaySetup) -> u32 {
    let diagonal = (setup.box_hi - setup.box_lo).length();
    let step = match setup.method {
        Method::Adaptive => setup.l_max,
        _ => setup.step,
    };
    let segments = (crate::samples::bvh::MAX_HITS / 2 + 1) as f64;
    ((diagonal / step).ceil() + segments).min(f64::from(u32::MAX / 2)) as u32
}

/// Outer steps per dispatch. llvmpipe ends every loop after 65 535 iterations per invocation
/// and dispatch (LAVAPIPE.md), and one MLS evaluation runs 30–60 of them (neighbour rows,
/// octree descent): about 256 evaluations per ray and dispatch leaves a margin of 4 or more.
/// An adaptive top interval costs up to 2^levels evaluations.
pub fn default_chunk(setup: &RaySetup) -> u32 {
    const EVALUATIONS_PER_DISPATCH: u32 = 256;
    match setup.method {
        Method::Adaptive => {
            let levels = super::raycast::adaptive::stack_size(setup.l_max, setup.l_min);
            (EVALUATIONS_PER_DISPATCH >> levels.min(8)).max(1)
        }
        _ => EVALUATIONS_PER_DISPATCH,
    }
}

/// Binding numbers of the ray caster for a field and setup.
fn frame_bindings(
    gpu_field: &GpuField,
    setup: &RaySetup,
    with_tables: bool,
    skip: bool,
) -> Vec<u32> {
    let mut ids: Vec<u32> = gpu_field.bindings().iter().map(|(b, _)| *b).collect();
    if skip {
        ids.extend([
            binding::SKIP_BLOCKS,
            binding::SKIP_TABLE,
            binding::SKIP_STATS,
        ]);
    }
    ids.extend(gpu_field.hull_bindings().iter().map(|(b, _)| *b));
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
fn frame_pipeline(
    ctx: &Context,
    compiler: &ShaderCompiler,
    variant: &Variant,
    bindings: &[u32],
) -> Result<ComputePipeline, VkError> {
    pipeline_for(
        ctx,
        compiler,
        "raycast.comp",
        variant,
        bindings,
        std::mem::size_of::<RayPush>() as u32,
    )
}

/// The tables as the kernel reads them: every length's table, then the zero-length limits.
fn table_buffer(ctx: &Context, tables: &PreintegrationTables) -> Result<Buffer, VkError> {
    let data: Vec<[f32; 4]> = tables
        .tables
        .iter()
        .flatten()
        .chain(&tables.limits)
        .copied()
        .collect();
    Buffer::from_slice(ctx, "preintegration tables", &data)
}

/// Per-frame constants: kernel parameters, transfer function, isosurfaces, skip table.
struct FrameConstants {
    params: Buffer,
    tf: Buffer,
    iso: Buffer,
    /// The frame's [`SkipTable`] (with empty-space skipping).
    skip: Option<Buffer>,
}

fn frame_constants(
    ctx: &Context,
    field: &Field,
    setup: &RaySetup,
    tf: &TransferFunction,
    tables: Option<&PreintegrationTables>,
    skip: bool,
) -> Result<FrameConstants, VkError> {
    let gpu_tf = tf.to_gpu();
    let skip = match skip {
        true => {
            let table = SkipTable::build(tf, &setup.isosurfaces, super::scalar_range(field));
            Some(Buffer::from_slice(ctx, "skip table", &table.gpu_words())?)
        }
        false => None,
    };
    let mut params = render_params(field, Some(setup), gpu_tf.len() as u32);
    if let Some(t) = tables {
        table_params(&mut params, t);
    }
    let isos = iso_buffer_data(&setup.isosurfaces);
    Ok(FrameConstants {
        params: Buffer::from_slice(ctx, "render params", &[params])?,
        tf: Buffer::from_slice(ctx, "transfer function", &gpu_tf)?,
        iso: Buffer::from_slice(ctx, "isosurfaces", &isos)?,
        skip,
    })
}

/// The isosurfaces as kernels read them; never empty, since a zero-sized binding is invalid
/// (the kernel constants say how many are real).
pub fn iso_buffer_data(isosurfaces: &[Isosurface]) -> Vec<IsoSurface> {
    let mut isos: Vec<IsoSurface> = isosurfaces
        .iter()
        .map(|i| IsoSurface {
            color_opacity: [
                i.color[0] as f32,
                i.color[1] as f32,
                i.color[2] as f32,
                i.opacity as f32,
            ],
            value: i.value as f32,
            _pad: [0.0; 3],
        })
        .collect();
    if isos.is_empty() {
        isos.push(IsoSurface::default());
    }
    isos
}

/// Image, counts and ray-state buffers for `pixels` pixels.
struct FrameTargets {
    pixels: u64,
    image: Buffer,
    counts: Buffer,
    ray_state: Buffer,
    skip_stats: Buffer,
}

fn frame_targets(ctx: &Context, pixels: u64) -> Result<FrameTargets, VkError> {
    Ok(FrameTargets {
        pixels,
        image: Buffer::new(ctx, "image", pixels * 16, BufferUsage::Storage)?,
        counts: Buffer::new(ctx, "evaluation counts", pixels * 4, BufferUsage::Storage)?,
        ray_state: Buffer::new(ctx, "ray state", pixels * 16, BufferUsage::Storage)?,
        skip_stats: Buffer::new(ctx, "skip report", pixels * 16, BufferUsage::Storage)?,
    })
}

/// Binds everything and runs the bands; returns (GPU ms, submissions).
#[allow(clippy::too_many_arguments)]
fn run_bands(
    ctx: &Context,
    pipeline: &ComputePipeline,
    gpu_field: &GpuField,
    constants: &FrameConstants,
    targets: &FrameTargets,
    table: Option<&Buffer>,
    setup: &RaySetup,
    progress: &mut dyn FnMut(f64),
) -> Result<(f64, u32), VkError> {
    let mut all = gpu_field.bindings();
    all.extend(gpu_field.hull_bindings());
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
        all.push((binding::SKIP_STATS, &targets.skip_stats));
    }
    let group = BindGroup::new(ctx, pipeline, &all)?;
    let (w, h) = (setup.camera.width, setup.camera.height);
    let band_rows = (BAND_PIXELS / w.max(1))
        .clamp(8, h.max(8))
        .next_multiple_of(8);
    let outer = outer_steps(setup);
    let mut chunk = setup.chunk.unwrap_or_else(|| default_chunk(setup));
    let mut gpu_ms = 0.0;
    let mut bands = 0;
    let mut row = 0;
    while row < h {
        let rows = band_rows.min(h - row);
        let mut first = 0;
        let mut band_counts: Vec<u32> = Vec::new();
        while first < outer {
            let push = RayPush {
                row_offset: row,
                rows,
                first,
                last: first.saturating_add(chunk).min(outer),
            };
            let timings = ctx.submit(|rec| {
                rec.dispatch(
                    pipeline,
                    &group,
                    bytemuck::bytes_of(&push),
                    [w.div_ceil(8), rows.div_ceil(8), 1],
                    "raycast",
                )
            })?;
            gpu_ms += timings.iter().filter_map(|t| t.gpu_ms).sum::<f64>();
            bands += 1;
            band_counts =
                targets
                    .counts
                    .read_range(ctx, (row * w) as usize, (rows * w) as usize)?;
            if band_counts.iter().any(|c| c & ray_count::TRUNCATED != 0) {
                // The driver cut a loop short: this band again, from its start, in halves.
                if chunk == 1 {
                    return Err(VkError::Usage(format!(
                        "raycast: the device ended a loop early even for one step per dispatch \
                         (llvmpipe allows 65 535 loop iterations per invocation); rows {row}..{} \
                         cannot be rendered with these settings",
                        row + rows
                    )));
                }
                chunk = chunk.div_ceil(2);
                first = 0;
                continue;
            }
            if band_counts.iter().all(|c| c & ray_count::DONE != 0) {
                break;
            }
            first = push.last;
        }
        let pixel_of = |i: usize| (i as u32 % w, row + i as u32 / w);
        if let Some(i) = band_counts
            .iter()
            .position(|c| c & ray_count::HULL_OVERFLOW != 0)
        {
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
    Ok((gpu_ms, bands))
}

/// A ray-cast frame as read back.
struct Readback {
    pixels: Vec<[f32; 4]>,
    /// Evaluations per pixel, flags removed.
    counts: Vec<u32>,
    skip: Option<SkipReport>,
}

/// Pixels and evaluation counts, and the skipping report when the frame skipped.
fn read_image(ctx: &Context, targets: &FrameTargets, skip: bool) -> Result<Readback, VkError> {
    let n = targets.pixels as usize;
    let report = if skip {
        let rays: Vec<[f32; 4]> = targets.skip_stats.read(ctx)?;
        let mut r = SkipReport::default();
        for p in rays.iter().take(n) {
            r.add(f64::from(p[0]), p[1] as u64, f64::from(p[2]));
        }
        Some(r)
    } else {
        None
    };
    let mut pixels: Vec<[f32; 4]> = targets.image.read(ctx)?;
    pixels.truncate(n);
    let mut counts: Vec<u32> = targets.counts.read(ctx)?;
    counts.truncate(n);
    for c in &mut counts {
        *c &= ray_count::EVALUATIONS;
    }
    Ok(Readback {
        pixels,
        counts,
        skip: report,
    })
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
    let tables = tables.filter(|_| setup.method.preintegrated());
    let variant = Variant::for_render(field, setup);
    let pipeline = frame_pipeline(
        ctx,
        compiler,
        &variant,
        &frame_bindings(gpu_field, setup, tables.is_some(), variant.skip),
    )?;
    let table = tables.map(|t| table_buffer(ctx, t)).transpose()?;
    let constants = frame_constants(ctx, field, setup, tf, tables, variant.skip)?;
    let (w, h) = (setup.camera.width, setup.camera.height);
    let targets = frame_targets(ctx, u64::from(w) * u64::from(h))?;
    let (gpu_ms, bands) = run_bands(
        ctx,
        &pipeline,
        gpu_field,
        &constants,
        &targets,
        table.as_ref(),
        setup,
        &mut progress,
    )?;
    let Readback {
        pixels,
        counts,
        skip,
    } = read_image(ctx, &targets, variant.skip)?;
    Ok(GpuImage {
        pixels,
        counts,
        gpu_ms,
        bands,
        variant: variant.name("raycast"),
        shaders: vec![("raycast.comp", variant.defines())],
        splat: None,
        skip,
    })
}

/// What a frame is made of besides the dataset.
#[derive(Debug, Clone, Copy)]
pub struct View<'a> {
    pub camera: &'a Camera,
    pub settings: &'a RenderSettings,
    pub transfer: &'a TransferFunction,
    pub isosurfaces: &'a [Isosurface],
    pub lighting: &'a Lighting,
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
}

/// A compiled variant: its macro definitions, its bindings and the pipeline.
type CachedPipeline = (Vec<(String, String)>, Vec<u32>, ComputePipeline);

/// The persistent renderer of one dataset: upload once, render many frames.
pub struct Renderer {
    ctx: Context,
    compiler: ShaderCompiler,
    field: Field,
    gpu_field: GpuField,
    /// Compiled variants with the bindings they were built for.
    pipelines: Vec<CachedPipeline>,
    tables: TableCache,
    /// The uploaded tables and the build they came from.
    table_buffer: Option<(usize, Buffer)>,
    targets: Option<FrameTargets>,
    /// Splatting: the kernels (uploaded at the first splatting frame), compiled variants and
    /// frame buffers.
    splat_kernels: Option<GpuKernels>,
    splat_pipelines: Vec<SplatPipelines>,
    splat_targets: Option<SplatTargets>,
}

impl Renderer {
    /// Uploads the field's samples, octree and hull.
    pub fn new(ctx: &Context, field: Field) -> Result<Self, RenderError> {
        let gpu_field = GpuField::upload(ctx, &field)?;
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
        })
    }

    /// The dataset's field.
    pub fn field(&self) -> &Field {
        &self.field
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
        if let Some(shading) = view.settings.method.splat_shading() {
            return self.render_splat(view, shading, start);
        }
        let setup = RaySetup::new(
            view.camera,
            view.settings,
            view.isosurfaces,
            view.lighting,
            &self.field,
        )?;
        let builds = self.tables.builds();
        let table_start = Instant::now();
        self.tables.get(
            &setup,
            &self.field,
            view.transfer,
            view.settings.table_resolution,
            |_| {},
        );
        let tables_built = self.tables.builds() != builds;
        let tables = self
            .tables
            .current()
            .filter(|_| setup.method.preintegrated());
        let table_ms = if tables_built {
            table_start.elapsed().as_secs_f64() * 1e3
        } else {
            0.0
        };
        check_tables(&setup, tables)?;
        if let Some(t) = tables
            && self.table_buffer.as_ref().map(|(b, _)| *b) != Some(self.tables.builds())
        {
            self.table_buffer = Some((self.tables.builds(), table_buffer(&self.ctx, t)?));
        }
        let variant = Variant::for_render(&self.field, &setup);
        let defines = variant.defines();
        let bindings = frame_bindings(&self.gpu_field, &setup, tables.is_some(), variant.skip);
        let cached = self
            .pipelines
            .iter()
            .position(|(d, b, _)| *d == defines && *b == bindings);
        let pipeline_built = cached.is_none();
        let index = match cached {
            Some(i) => i,
            None => {
                let p = frame_pipeline(&self.ctx, &self.compiler, &variant, &bindings)?;
                self.pipelines.push((defines, bindings, p));
                self.pipelines.len() - 1
            }
        };
        let pixels = u64::from(setup.camera.width) * u64::from(setup.camera.height);
        let targets_allocated = self.targets.as_ref().map(|t| t.pixels) != Some(pixels);
        if targets_allocated {
            self.targets = None;
            self.targets = Some(frame_targets(&self.ctx, pixels)?);
        }
        let constants = frame_constants(
            &self.ctx,
            &self.field,
            &setup,
            view.transfer,
            tables,
            variant.skip,
        )?;
        let Some(targets) = self.targets.as_ref() else {
            return Err(VkError::Usage("frame buffers missing".into()).into());
        };
        let table = if tables.is_some() {
            self.table_buffer.as_ref().map(|(_, b)| b)
        } else {
            None
        };
        let (gpu_ms, bands) = run_bands(
            &self.ctx,
            &self.pipelines[index].2,
            &self.gpu_field,
            &constants,
            targets,
            table,
            &setup,
            &mut progress,
        )?;
        let Readback {
            pixels,
            counts,
            skip,
        } = read_image(&self.ctx, targets, variant.skip)?;
        Ok((
            GpuImage {
                pixels,
                counts,
                gpu_ms,
                bands,
                variant: variant.name("raycast"),
                shaders: vec![("raycast.comp", variant.defines())],
                splat: None,
                skip,
            },
            FrameStats {
                gpu_ms,
                wall_ms: start.elapsed().as_secs_f64() * 1e3,
                tables_built,
                table_ms,
                pipeline_built,
                targets_allocated,
                bands,
            },
        ))
    }

    /// One splatting frame: kernels uploaded once, variants and buffers kept between frames.
    fn render_splat(
        &mut self,
        view: &View<'_>,
        shading: crate::splat::Shading,
        start: Instant,
    ) -> Result<(GpuImage, FrameStats), RenderError> {
        let setup = SplatSetup::new(
            shading,
            &view.settings.splat,
            view.camera,
            view.settings.early_termination,
            view.settings.background,
            view.isosurfaces,
            view.lighting,
            &self.field,
        )?;
        let surfaces: &[Isosurface] = if setup.settings.surface {
            &setup.isosurfaces
        } else {
            &[]
        };
        if !self
            .splat_kernels
            .as_ref()
            .is_some_and(|k| k.has_surfaces_of(surfaces))
        {
            self.splat_kernels = None;
            self.splat_kernels = Some(GpuKernels::upload(&self.ctx, &self.field, surfaces)?);
        }
        let Some(kernels) = self.splat_kernels.as_ref() else {
            return Err(VkError::Usage("splat kernels missing".into()).into());
        };
        let variant = SplatVariant::of(&setup);
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
        let targets_allocated = !self
            .splat_targets
            .as_ref()
            .is_some_and(|t| t.fits(&setup, kernels));
        if targets_allocated {
            self.splat_targets = None;
            self.splat_targets = Some(SplatTargets::new(&self.ctx, &setup, kernels)?);
        }
        let Some(targets) = self.splat_targets.as_mut() else {
            return Err(VkError::Usage("splat frame buffers missing".into()).into());
        };
        let image = splat_frame(
            &self.ctx,
            &self.splat_pipelines[index],
            kernels,
            targets,
            &setup,
            view.transfer,
            &self.gpu_field.hull_bindings(),
        )?;
        let gpu_ms = image.gpu_ms();
        let n = image.pixels.len();
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
                    slab: setup.slab,
                }),
                skip: None,
            },
            FrameStats {
                gpu_ms,
                wall_ms: start.elapsed().as_secs_f64() * 1e3,
                tables_built: false,
                table_ms: 0.0,
                pipeline_built,
                targets_allocated,
                bands: image.submissions,
            },
        ))
    }
}
