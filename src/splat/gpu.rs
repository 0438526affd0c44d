//! Driving the splatting kernels (`glsl/splat_*.comp`): uploads, frame buffers, the variant of
//! a setup, and one frame.
//!
//! A frame is two submissions. The first clears the counters and runs `splat_project`; the host
//! reads one count per sheet back, turns them into offsets (a prefix sum over at most
//! `MAX_SLABS` numbers), sizes the entry list and writes one indirect dispatch per sheet. The
//! second runs `splat_bin`, then per sheet front to back an indirect `splat_accumulate` and a
//! `splat_composite` (post-shaded: one more composite for the last sheet), in submissions of
//! at most `SLABS_PER_SUBMISSION` sheets so that every dispatch is timed and a stop request
//! ([`FrameControl::stop`]) ends the frame within one submission.

use super::surface::KernelKind;
use super::{Antialias, Shading, SplatCounts, SplatSetup, TILE};
use crate::gpu_types::{SlabPush, Splat, SplatParams, binding, params_copies};
use crate::render::transfer::TransferFunction;
use crate::render::{Field, RenderError};
use crate::vk::{
    BindGroup, Buffer, BufferUsage, ComputePipeline, Context, ShaderCompiler, ShaderSource, VkError,
};
use std::sync::atomic::{AtomicBool, Ordering};

/// Sheets per submission of the second pass (two timed dispatches each). Small enough that
/// Ctrl-C and the progress bar act within a fraction of a long frame (a 4096² frame of 764
/// sheets is 12 submissions), large enough that the wait for each submission's fence stays
/// small beside the sheets' work.
const SLABS_PER_SUBMISSION: u32 = 64;
/// Invocations per workgroup of the one-dimensional kernels.
const GROUP: u32 = 64;
/// `SplatCounts` counters in the stats buffer.
/// Counter slots: 0–8 one word each, 9–10 the low and 11–12 the high words of two 64-bit ones.
const STATS: usize = 13;

/// The kernels uploaded once per dataset: one `Sample` each, volume in `metric_off.z`.
pub struct GpuKernels {
    buffer: Buffer,
    count: u32,
    /// The isosurface values whose surface splats follow the volume kernels.
    surface_values: Vec<f64>,
}

impl GpuKernels {
    /// Uploads every sample of the field as a Gaussian kernel, then the surface splats of
    /// `isosurfaces` (none: no surface splats). A surface splat keeps its metric's scale in
    /// `pos_value.w` and 1 + its isosurface index in `metric_off.w` (0 for volume kernels).
    pub fn upload(
        ctx: &Context,
        field: &Field,
        isosurfaces: &[crate::render::shading::Isosurface],
    ) -> Result<Self, VkError> {
        let surfaces = super::surface::surface_kernels(field, isosurfaces);
        let data: Vec<crate::gpu_types::Sample> = super::accumulate::kernels(field)
            .chain(surfaces)
            .map(|k| {
                let m = k.metric.map(|v| v as f32);
                let p = k.position.map(|v| v as f32);
                let (w, tag) = match k.kind {
                    KernelKind::Volume => (k.value, 0.0),
                    KernelKind::Surface { iso, scale } => (scale, 1.0 + iso as f32),
                };
                crate::gpu_types::Sample {
                    pos_value: [p[0], p[1], p[2], w as f32],
                    metric: [m[0], m[1], m[2], m[3]],
                    metric_off: [m[4], m[5], k.volume as f32, tag],
                }
            })
            .collect();
        let count = u32::try_from(data.len())
            .map_err(|_| VkError::Usage(format!("{} kernels exceed 2³² − 1", data.len())))?;
        Ok(Self {
            buffer: Buffer::from_slice(ctx, "splat kernels", &data)?,
            count,
            surface_values: isosurfaces.iter().map(|i| i.value).collect(),
        })
    }

    /// Whether these kernels carry the surface splats of exactly these isosurfaces.
    pub fn has_surfaces_of(&self, isosurfaces: &[crate::render::shading::Isosurface]) -> bool {
        self.surface_values.len() == isosurfaces.len()
            && self
                .surface_values
                .iter()
                .zip(isosurfaces)
                .all(|(v, i)| *v == i.value)
    }
}

/// Compile-time choices of a splatting frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SplatVariant {
    pub shading: Shading,
    pub antialias: Antialias,
    pub orthographic: bool,
    /// Per-pixel ray integrals (perspective, `splat.footprint = "exact"`).
    pub exact: bool,
    pub occlusion: bool,
    pub isosurfaces: bool,
    /// Surface splats (pre-shaded isosurfaces).
    pub surfaces: bool,
    /// Post-shaded over a hull: per-pixel inside segments bound the domain.
    pub hull: bool,
}

impl SplatVariant {
    /// The variant a setup needs.
    pub fn of(setup: &SplatSetup) -> Self {
        Self {
            shading: setup.shading,
            antialias: setup.settings.antialias,
            orthographic: setup.orthographic(),
            exact: setup.exact_footprints(),
            occlusion: setup.settings.occlusion,
            isosurfaces: !setup.isosurfaces.is_empty(),
            surfaces: setup.settings.surface && !setup.isosurfaces.is_empty(),
            hull: setup.hull && setup.shading == Shading::Post,
        }
    }

    /// shaderc macro definitions.
    pub fn defines(&self) -> Vec<(String, String)> {
        let flag = |b: bool| if b { "1" } else { "0" }.to_string();
        let mut d = crate::gpu_types::binding_defines();
        d.extend([
            ("SPLAT_POST".into(), flag(self.shading == Shading::Post)),
            (
                "SPLAT_ANTIALIAS".into(),
                match self.antialias {
                    Antialias::Ewa => "0",
                    Antialias::Swan => "1",
                    Antialias::None => "2",
                }
                .into(),
            ),
            ("SPLAT_ORTHO".into(), flag(self.orthographic)),
            ("SPLAT_EXACT".into(), flag(self.exact)),
            ("SPLAT_OCCLUSION".into(), flag(self.occlusion)),
            ("SPLAT_ISOSURFACES".into(), flag(self.isosurfaces)),
            ("SPLAT_SURFACES".into(), flag(self.surfaces)),
            ("SPLAT_HULL".into(), flag(self.hull)),
            ("SPLAT_BLOCK".into(), super::BLOCK.to_string()),
            ("SPLAT_TILE".into(), super::TILE.to_string()),
            (
                "SPLAT_MAX_KERNEL_ENTRIES".into(),
                super::MAX_KERNEL_ENTRIES.to_string(),
            ),
            ("SPLAT_SEGMENTS".into(), super::PIXEL_SEGMENTS.to_string()),
        ]);
        d
    }

    /// The GLSL files a frame of this variant runs, in dispatch order.
    pub fn kernels(&self) -> Vec<&'static str> {
        let mut k = Vec::new();
        if self.hull {
            k.push("splat_segments.comp");
        }
        k.extend([
            "splat_project.comp",
            "splat_bin.comp",
            "splat_accumulate.comp",
            "splat_composite.comp",
        ]);
        k
    }

    /// Human-readable name for `--stats`.
    pub fn name(&self) -> String {
        format!(
            "splat {} {} {}{}{}{}",
            match self.shading {
                Shading::Pre => "pre-shaded",
                Shading::Post => "post-shaded",
            },
            match self.antialias {
                Antialias::Ewa => "ewa",
                Antialias::Swan => "swan",
                Antialias::None => "no-lowpass",
            },
            if self.orthographic {
                "orthographic"
            } else {
                "perspective"
            },
            if self.exact { " exact-footprints" } else { "" },
            if self.occlusion { " occlusion" } else { "" },
            if self.surfaces {
                " surface-splats"
            } else if self.isosurfaces {
                " isosurfaces"
            } else {
                ""
            },
        )
    }
}

/// The four pipelines of a variant.
pub struct SplatPipelines {
    variant: SplatVariant,
    project: ComputePipeline,
    bin: ComputePipeline,
    accumulate: ComputePipeline,
    composite: ComputePipeline,
    segments: Option<ComputePipeline>,
}

impl SplatPipelines {
    /// Compiles the variant's kernels.
    pub fn new(
        ctx: &Context,
        compiler: &ShaderCompiler,
        variant: &SplatVariant,
    ) -> Result<Self, VkError> {
        use binding::*;
        let defines = variant.defines();
        let post = variant.shading == Shading::Post;
        let make = |kernel: &str, bindings: &[u32], push: u32| {
            let spirv = compiler.compile(ShaderSource::File(kernel), &defines)?;
            let kinds: Vec<(u32, crate::vk::BindingKind)> =
                bindings.iter().map(|&b| (b, binding::kind(b))).collect();
            ComputePipeline::with_kinds(ctx, kernel, &spirv, &kinds, push)
        };
        let push = std::mem::size_of::<SlabPush>() as u32;
        let mut project = vec![PARAMS, SPLAT_KERNELS, SPLATS, SLAB_COUNTS, SPLAT_STATS];
        if !post {
            project.push(TRANSFER);
        }
        if variant.surfaces {
            project.push(ISO);
        }
        let mut composite = vec![PARAMS, SHEETS, IMAGE, OCCLUSION];
        if post {
            composite.push(TRANSFER);
            if variant.isosurfaces {
                composite.push(ISO);
            }
        }
        if variant.hull {
            composite.push(PIXEL_SEGMENTS);
        }
        Ok(Self {
            variant: variant.clone(),
            project: make("splat_project.comp", &project, 0)?,
            bin: make(
                "splat_bin.comp",
                &[PARAMS, SPLATS, SLAB_OFFSETS, SLAB_CURSORS, SPLAT_LIST],
                0,
            )?,
            accumulate: make(
                "splat_accumulate.comp",
                &[
                    PARAMS,
                    SPLATS,
                    SLAB_COUNTS,
                    SLAB_OFFSETS,
                    SPLAT_LIST,
                    SHEETS,
                    IMAGE,
                    OCCLUSION,
                    SPLAT_STATS,
                ],
                push,
            )?,
            composite: make("splat_composite.comp", &composite, push)?,
            segments: if variant.hull {
                Some(make(
                    "splat_segments.comp",
                    &[PARAMS, PIXEL_SEGMENTS, SPLAT_STATS, HULL_NODES, HULL_TRIS],
                    0,
                )?)
            } else {
                None
            },
        })
    }

    /// The variant these pipelines were compiled for.
    pub fn variant(&self) -> &SplatVariant {
        &self.variant
    }
}

/// Frame buffers of one image size and kernel count, for up to `slab_capacity` sheets (a new
/// camera changes the sheet count: a quarter more is allocated); the entry list grows.
pub struct SplatTargets {
    key: (u32, u32, u32, Shading, bool),
    slab_capacity: u32,
    splats: Buffer,
    counts: Buffer,
    offsets: Buffer,
    cursors: Buffer,
    args: Buffer,
    sheets: Buffer,
    image: Buffer,
    occlusion: Buffer,
    stats: Buffer,
    list: Option<Buffer>,
    segments: Option<Buffer>,
}

impl SplatTargets {
    fn key(setup: &SplatSetup, kernels: &GpuKernels) -> (u32, u32, u32, Shading, bool) {
        (
            setup.camera.width,
            setup.camera.height,
            kernels.count,
            setup.shading,
            SplatVariant::of(setup).surfaces,
        )
    }

    fn segments(&self) -> Result<&Buffer, VkError> {
        self.segments
            .as_ref()
            .ok_or_else(|| VkError::Usage("pixel hull segments missing".into()))
    }

    /// Whether these buffers fit a setup.
    pub fn fits(&self, setup: &SplatSetup, kernels: &GpuKernels) -> bool {
        self.key == Self::key(setup, kernels) && setup.slabs <= self.slab_capacity
    }

    /// Allocates the buffers of a setup.
    pub fn new(ctx: &Context, setup: &SplatSetup, kernels: &GpuKernels) -> Result<Self, VkError> {
        let (w, h) = (
            u64::from(setup.camera.width),
            u64::from(setup.camera.height),
        );
        let pixels = w * h;
        let capacity = setup
            .slabs
            .saturating_add(setup.slabs / 4)
            .min(super::MAX_SLABS);
        let slabs = u64::from(capacity);
        let tiles = w.div_ceil(u64::from(TILE)) * h.div_ceil(u64::from(TILE));
        let sheet_floats = match setup.shading {
            Shading::Pre if SplatVariant::of(setup).surfaces => {
                super::accumulate::SHEET as u64 * pixels
            }
            Shading::Pre => 4 * pixels,
            Shading::Post => super::accumulate::RING as u64 * pixels,
        };
        let storage = |name: &str, bytes: u64| Buffer::new(ctx, name, bytes, BufferUsage::Storage);
        Ok(Self {
            key: Self::key(setup, kernels),
            slab_capacity: capacity,
            splats: storage(
                "splats",
                u64::from(kernels.count) * std::mem::size_of::<Splat>() as u64,
            )?,
            counts: storage("sheet entry counts", 4 * slabs)?,
            offsets: storage("sheet offsets", 4 * slabs)?,
            cursors: storage("sheet cursors", 4 * slabs)?,
            args: storage("sheet dispatch arguments", 12 * slabs)?,
            sheets: storage("sheet buffers", 4 * sheet_floats)?,
            image: storage("splat image", 16 * pixels)?,
            occlusion: storage("occlusion map", 4 * tiles)?,
            stats: storage("splat counters", 4 * STATS as u64)?,
            list: None,
            segments: if SplatVariant::of(setup).hull {
                Some(storage(
                    "pixel hull segments",
                    8 * super::PIXEL_SEGMENTS as u64 * pixels,
                )?)
            } else {
                None
            },
        })
    }
}

/// A splatted frame as the GPU produced it.
#[derive(Debug, Clone)]
pub struct SplatGpuImage {
    /// (C + T·background, 1 − T) per pixel, row 0 at the top.
    pub pixels: Vec<[f32; 4]>,
    pub counts: SplatCounts,
    /// GPU milliseconds of project, bin (with splat_segments), accumulate (all sheets), composite
    /// (all sheets).
    pub stage_ms: [f64; 4],
    pub submissions: u32,
    pub variant: String,
}

impl SplatGpuImage {
    /// GPU milliseconds of the whole frame.
    pub fn gpu_ms(&self) -> f64 {
        self.stage_ms.iter().sum()
    }
}

fn params(setup: &SplatSetup, kernels: &GpuKernels, tf_count: u32) -> SplatParams {
    let v = |d: glam::DVec3, w: f64| [d.x as f32, d.y as f32, d.z as f32, w as f32];
    let b = &setup.basis;
    let l = &setup.lighting;
    let (projection, tan, half) = match setup.camera.projection {
        crate::render::camera::Projection::Perspective { fov_y_degrees } => {
            (0, (fov_y_degrees.to_radians() * 0.5).tan(), 0.0)
        }
        crate::render::camera::Projection::Orthographic { view_height } => {
            (1, 0.0, 0.5 * view_height)
        }
    };
    let bg = setup.background;
    SplatParams {
        eye: v(setup.eye, setup.near),
        forward: v(b.forward, setup.focal),
        right: v(b.right, setup.centre[0]),
        up: v(b.up, setup.centre[1]),
        box_min: v(setup.box_lo, setup.slab0),
        box_max: v(setup.box_hi, setup.slab),
        background: [
            bg[0] as f32,
            bg[1] as f32,
            bg[2] as f32,
            setup.early_termination as f32,
        ],
        kernel_filter: [
            setup.settings.cutoff as f32,
            setup.settings.lowpass as f32,
            setup.sigma as f32,
            setup.lateral[0].min(f64::from(f32::MAX)) as f32,
        ],
        lighting: [
            l.ambient as f32,
            l.diffuse as f32,
            l.specular as f32,
            l.shininess as f32,
        ],
        width: setup.camera.width,
        height: setup.camera.height,
        projection,
        tf_count,
        tan_half_fov: tan as f32,
        ortho_half_height: half as f32,
        lateral_y: setup.lateral[1].min(f64::from(f32::MAX)) as f32,
        _pad0: 0.0,
        slabs: setup.slabs,
        tiles_x: setup.camera.width.div_ceil(TILE),
        kernel_count: kernels.count,
        iso_count: setup.isosurfaces.len() as u32,
    }
}

fn sum_ms(timings: &[crate::vk::DispatchTiming], stage_ms: &mut [f64; 4]) {
    for t in timings {
        let i = match t.label.as_str() {
            "splat_project" => 0,
            "splat_bin" | "splat_segments" => 1,
            "splat_accumulate" => 2,
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

/// Renders one frame; `targets` must fit the setup (see [`SplatTargets::fits`]); `hull` are the
/// field's hull bindings (`GpuField::hull_bindings`), read by post-shaded frames over a hull.
#[allow(clippy::too_many_arguments)]
pub fn splat_frame(
    ctx: &Context,
    pipelines: &SplatPipelines,
    kernels: &GpuKernels,
    targets: &mut SplatTargets,
    setup: &SplatSetup,
    tf: &TransferFunction,
    hull: &[(u32, &Buffer)],
    control: FrameControl<'_>,
) -> Result<SplatGpuImage, RenderError> {
    if !targets.fits(setup, kernels) {
        return Err(VkError::Usage("splat frame buffers do not fit the setup".into()).into());
    }
    let gpu_tf = tf.to_gpu();
    let p = params(setup, kernels, gpu_tf.len() as u32);
    let params_buf = Buffer::from_slice(ctx, "splat params", &params_copies(p))?;
    let tf_buf = Buffer::from_slice(ctx, "transfer function", &gpu_tf)?;
    let isos = crate::render::renderer::iso_buffer_data(&setup.isosurfaces);
    let iso_buf = Buffer::from_slice(ctx, "isosurfaces", &isos)?;
    let mut stage_ms = [0.0; 4];
    let groups = kernels.count.div_ceil(GROUP).clamp(1, 65_535);

    // Pass 1: project and count.
    let t = &*targets;
    let mut project_bind = vec![
        (binding::PARAMS, &params_buf),
        (binding::SPLAT_KERNELS, &kernels.buffer),
        (binding::SPLATS, &t.splats),
        (binding::SLAB_COUNTS, &t.counts),
        (binding::SPLAT_STATS, &t.stats),
    ];
    if setup.shading == Shading::Pre {
        project_bind.push((binding::TRANSFER, &tf_buf));
    }
    if pipelines.variant.surfaces {
        project_bind.push((binding::ISO, &iso_buf));
    }
    let group = BindGroup::new(ctx, &pipelines.project, &project_bind)?;
    let tiles = [
        setup.camera.width.div_ceil(TILE),
        setup.camera.height.div_ceil(TILE),
        1,
    ];
    let segments = match &pipelines.segments {
        Some(p) => {
            let mut b = vec![
                (binding::PARAMS, &params_buf),
                (binding::PIXEL_SEGMENTS, t.segments()?),
                (binding::SPLAT_STATS, &t.stats),
            ];
            b.extend(hull.iter().copied());
            Some((p, BindGroup::new(ctx, p, &b)?))
        }
        None => None,
    };
    let timings = ctx.submit(|rec| {
        rec.fill(&t.counts, 0);
        rec.fill(&t.stats, 0);
        if let Some((p, g)) = &segments {
            rec.dispatch(p, g, &[], tiles, "splat_segments")?;
        }
        rec.dispatch(
            &pipelines.project,
            &group,
            &[],
            [groups, 1, 1],
            "splat_project",
        )
    })?;
    drop((group, segments));
    if pipelines.segments.is_some() {
        let stats: Vec<u32> = t.stats.read(ctx)?;
        if let Some(&n) = stats.get(5).filter(|&&n| n > 0) {
            return Err(VkError::Usage(format!(
                "splatting: the rays of {n} pixels cross the domain's boundary into more than {} \
                 inside segments; post-shaded splatting keeps {0} per pixel: ray cast this mesh",
                super::PIXEL_SEGMENTS
            ))
            .into());
        }
    }
    sum_ms(&timings, &mut stage_ms);
    control.check_stop()?;
    let oversized = t.stats.read::<u32>(ctx)?.get(8).copied().unwrap_or(0);
    if oversized > 0 {
        return Err(VkError::Usage(format!(
            "splatting: {oversized} kernels cover more than {} sheet × block entries each (one \
             invocation writes them); raise splat.slab or lower the image size",
            super::MAX_KERNEL_ENTRIES
        ))
        .into());
    }
    let counts: Vec<u32> = t.counts.read(ctx)?;
    let mut offsets = Vec::with_capacity(counts.len());
    let mut args = Vec::with_capacity(3 * counts.len());
    let mut total: u64 = 0;
    for &c in counts.iter().take(setup.slabs as usize) {
        offsets.push(total as u32);
        args.extend([c.div_ceil(GROUP).min(65_535), 1, 1]);
        total += u64::from(c);
    }
    if let Some(budget) = control.budget {
        setup.check_budget(total, budget)?;
    }
    let limit = ctx.info().max_storage_buffer_range / 8;
    if total > limit || total > u64::from(u32::MAX) {
        return Err(VkError::Usage(format!(
            "splatting: {total} binned footprints exceed the entry list's limit of {limit} \
             (maxStorageBufferRange); raise splat.slab or lower the image size"
        ))
        .into());
    }
    t.offsets.write(ctx, bytemuck::cast_slice(&offsets))?;
    t.args.write(ctx, bytemuck::cast_slice(&args))?;
    let needed = 8 * total.max(1);
    if targets.list.as_ref().is_none_or(|l| l.size() < needed) {
        targets.list = None;
        let grown = (needed + needed / 2).min(limit * 8).max(needed);
        targets.list = Some(Buffer::new(
            ctx,
            "splat entries",
            grown,
            BufferUsage::Storage,
        )?);
    }
    let t = &*targets;
    let Some(list) = t.list.as_ref() else {
        return Err(VkError::Usage("splat entry list missing".into()).into());
    };

    // Pass 2: bin, then accumulate and composite sheet after sheet.
    let bin = BindGroup::new(
        ctx,
        &pipelines.bin,
        &[
            (binding::PARAMS, &params_buf),
            (binding::SPLATS, &t.splats),
            (binding::SLAB_OFFSETS, &t.offsets),
            (binding::SLAB_CURSORS, &t.cursors),
            (binding::SPLAT_LIST, list),
        ],
    )?;
    let accumulate = BindGroup::new(
        ctx,
        &pipelines.accumulate,
        &[
            (binding::PARAMS, &params_buf),
            (binding::SPLATS, &t.splats),
            (binding::SLAB_COUNTS, &t.counts),
            (binding::SLAB_OFFSETS, &t.offsets),
            (binding::SPLAT_LIST, list),
            (binding::SHEETS, &t.sheets),
            (binding::IMAGE, &t.image),
            (binding::OCCLUSION, &t.occlusion),
            (binding::SPLAT_STATS, &t.stats),
        ],
    )?;
    let mut composite_bind = vec![
        (binding::PARAMS, &params_buf),
        (binding::SHEETS, &t.sheets),
        (binding::IMAGE, &t.image),
        (binding::OCCLUSION, &t.occlusion),
    ];
    if setup.shading == Shading::Post {
        composite_bind.push((binding::TRANSFER, &tf_buf));
        if !setup.isosurfaces.is_empty() {
            composite_bind.push((binding::ISO, &iso_buf));
        }
    }
    if pipelines.variant.hull {
        composite_bind.push((binding::PIXEL_SEGMENTS, t.segments()?));
    }
    let composite = BindGroup::new(ctx, &pipelines.composite, &composite_bind)?;
    let steps = setup.slabs + u32::from(setup.shading == Shading::Post);
    let mut submissions = 1;
    let mut k = 0;
    while k < steps {
        let end = (k + SLABS_PER_SUBMISSION).min(steps);
        let first = k == 0;
        let timings = ctx.submit(|rec| {
            if first {
                rec.fill(&t.cursors, 0);
                rec.fill(&t.sheets, 0);
                rec.fill(&t.image, 0);
                rec.fill(&t.occlusion, 0);
                rec.dispatch(&pipelines.bin, &bin, &[], [groups, 1, 1], "splat_bin")?;
            }
            for s in k..end {
                let push = SlabPush {
                    slab: s,
                    _pad: [0; 3],
                };
                if s < setup.slabs {
                    rec.dispatch_indirect(
                        &pipelines.accumulate,
                        &accumulate,
                        bytemuck::bytes_of(&push),
                        &t.args,
                        12 * u64::from(s),
                        "splat_accumulate",
                    )?;
                }
                rec.dispatch(
                    &pipelines.composite,
                    &composite,
                    bytemuck::bytes_of(&push),
                    tiles,
                    "splat_composite",
                )?;
            }
            Ok(())
        })?;
        sum_ms(&timings, &mut stage_ms);
        submissions += 1;
        k = end;
        (control.progress)(f64::from(k) / f64::from(steps));
        control.check_stop()?;
    }
    drop((bin, accumulate, composite));
    let image: Vec<[f32; 4]> = t.image.read(ctx)?;
    let stats: Vec<u32> = t.stats.read(ctx)?;
    let bg = setup.background.map(|c| c as f32);
    let n = (setup.camera.width * setup.camera.height) as usize;
    let pixels = image
        .iter()
        .take(n)
        .map(|a| {
            let tr = 1.0 - a[3];
            [
                a[0] + tr * bg[0],
                a[1] + tr * bg[1],
                a[2] + tr * bg[2],
                a[3],
            ]
        })
        .collect();
    let s = |i: usize| u64::from(stats.get(i).copied().unwrap_or(0));
    Ok(SplatGpuImage {
        pixels,
        counts: SplatCounts {
            projected: s(0),
            culled_near: s(1),
            culled_outside: s(2),
            culled_degenerate: s(3),
            culled_empty: s(4),
            entries: total,
            skipped_occluded: s(6),
            accumulated: s(7),
            oversized: s(8),
            evaluated: s(9) | s(11) << 32,
            updates: s(10) | s(12) << 32,
        },
        stage_ms,
        submissions,
        variant: pipelines.variant.name(),
    })
}
