//! Driving the splatting kernels (`glsl/splat_*.comp`): uploads, frame buffers, the variant of
//! a setup, and one frame.
//!
//! A frame is a few submissions. The first clears the counters and runs `splat_project`
//! (which counts the (tile, sheet) buckets) and the three levels of `splat_scan`; the host
//! reads one number back, the total of entries, to check the work budget and size the entry
//! list. The second runs `splat_bin`; then `splat_raster` runs in bands of tile rows, one
//! submission each, so that every band is timed and a stop request ([`FrameControl::stop`])
//! ends the frame within one band.

use super::project::KernelKind;
use super::{Antialias, SCAN_BLOCK, Shading, SplatCounts, SplatSetup};
use crate::field::{Field, RenderError};
use crate::gpu_types::{RasterPush, ScanPush, Splat, SplatParams, binding, params_copies};
use crate::view::transfer::TransferFunction;
use crate::vk::{
    BindGroup, Buffer, BufferUsage, ComputePipeline, Context, ShaderCompiler, ShaderSource, VkError,
};
use std::sync::atomic::{AtomicBool, Ordering};

/// Bands of tile rows per frame of `splat_raster` (at most): each band is one submission, so
/// that Ctrl-C and the progress bar act within a fraction of a long frame, while the wait for
/// each submission's fence stays small beside the band's work.
const RASTER_BANDS: u32 = 8;
/// What `splat_scan`'s passes bind: pass p the first p + 2 of these (counts and block sums;
/// then the offsets it writes; then the cursors it starts).
const SCAN_BINDINGS: [u32; 4] = [
    binding::BUCKET_COUNTS,
    binding::SCAN_SUMS,
    binding::BUCKET_OFFSETS,
    binding::BUCKET_CURSORS,
];
/// Pixels per `splat_raster` invocation without an apron (every tile size is a multiple).
const RASTER_PIXELS: u32 = 4;
/// Hull hits `splat_segments` keeps per pixel (`HULL_MAX_HITS` of its variant).
pub const SEGMENT_HITS: usize = 2 * super::PIXEL_SEGMENTS + 4;

/// Invocations per workgroup of the one-dimensional kernels.
const GROUP: u32 = 64;
/// `SplatCounts` counters in the stats buffer.
/// Counter slots: 0–5 and 8 one word each; 64-bit ones: 9 and 10 with high words 11 and 12,
/// 6 and 7 with high words 13 and 14.
const STATS: usize = 15;

/// The kernels uploaded once per dataset: one `Sample` each, volume in `metric_off.z`.
pub struct GpuKernels {
    buffer: Buffer,
    count: u32,
    /// The isosurface values whose surface splats follow the volume kernels.
    surface_values: Vec<f64>,
}

impl GpuKernels {
    /// Uploads every sample of the field as a Gaussian kernel, then `surfaces`, the surface
    /// splats of `isosurfaces` (`surface::surface_kernels`; none: no surface splats). A surface
    /// splat keeps its metric's scale in `pos_value.w` and 1 + its isosurface index in
    /// `metric_off.w` (0 for volume kernels).
    pub fn upload(
        ctx: &Context,
        field: &Field,
        isosurfaces: &[crate::view::shading::Isosurface],
        surfaces: Vec<super::project::Kernel>,
    ) -> Result<Self, VkError> {
        let data: Vec<crate::gpu_types::Sample> = super::raster::kernels(field)
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
        let bytes: &[u8] = bytemuck::cast_slice(&data);
        let buffer = Buffer::new(ctx, "splat kernels", bytes.len() as u64, BufferUsage::Texel)?;
        buffer.write(ctx, bytes)?;
        Ok(Self {
            buffer,
            count,
            surface_values: isosurfaces.iter().map(|i| i.value).collect(),
        })
    }

    /// Whether these kernels carry the surface splats of exactly these isosurfaces.
    pub fn has_surfaces_of(&self, isosurfaces: &[crate::view::shading::Isosurface]) -> bool {
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
    /// Kernels split among sheets (`splat.split`).
    pub split: bool,
    /// Post-shaded: ring registers per pixel (`SplatSetup::ring`; 0: none).
    pub ring: u32,
    /// With ring registers: the quadrature sheet share (`SplatSetup::sheet_share`), else the
    /// erfc.
    pub quadrature: bool,
    pub occlusion: bool,
    pub isosurfaces: bool,
    /// Surface splats (pre-shaded isosurfaces).
    pub surfaces: bool,
    /// Post-shaded over a hull: per-pixel inside segments bound the domain.
    pub hull: bool,
    /// Image tile edge and apron in pixels.
    pub tile: u32,
    pub apron: u32,
    /// Pixels per `splat_raster` invocation, a column of them: each splat record an
    /// invocation loads (gathers, the kernel's largest cost on lavapipe) serves them all. One
    /// where the apron's lateral exchange needs a pixel per invocation.
    pub pixels: u32,
    /// Invocations of a `splat_raster` workgroup: the tile and its apron over `pixels`,
    /// rounded up to whole subgroups (so that every subgroup is full for its votes).
    pub group: u32,
    /// The device has the subgroup operations `DeviceInfo::subgroup_ops` names: a subgroup
    /// stops by itself once its pixels are opaque (a vote, no barrier) and sums its counters.
    pub subgroup_ops: bool,
}

impl SplatVariant {
    /// The variant a setup needs on a device.
    pub fn of(setup: &SplatSetup, device: &crate::vk::DeviceInfo) -> Self {
        let subgroup = device.subgroup_size.clamp(1, 128);
        let pixels = Self::pixels_per_invocation(setup);
        Self {
            shading: setup.shading,
            antialias: setup.settings.antialias,
            orthographic: setup.orthographic(),
            exact: setup.exact_footprints(),
            split: setup.split,
            ring: setup.ring,
            quadrature: setup.sheet_share == super::SheetShare::Quadrature,
            occlusion: setup.settings.occlusion,
            isosurfaces: !setup.isosurfaces.is_empty(),
            surfaces: setup.settings.surface && !setup.isosurfaces.is_empty(),
            hull: setup.hull && setup.shading == Shading::Post,
            tile: setup.tile,
            apron: setup.apron(),
            pixels,
            group: (setup.group_size() / pixels).next_multiple_of(subgroup.max(8)),
            subgroup_ops: device.subgroup_ops,
        }
    }

    /// Pixels per `splat_raster` invocation for a setup (see [`SplatVariant::pixels`]).
    pub fn pixels_per_invocation(setup: &SplatSetup) -> u32 {
        if setup.apron() > 0 { 1 } else { RASTER_PIXELS }
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
            ("SPLAT_SPLIT".into(), flag(self.split)),
            ("SPLAT_RING".into(), self.ring.to_string()),
            ("SPLAT_QUADRATURE".into(), flag(self.quadrature)),
            ("SPLAT_OCCLUSION".into(), flag(self.occlusion)),
            ("SPLAT_ISOSURFACES".into(), flag(self.isosurfaces)),
            ("SPLAT_SURFACES".into(), flag(self.surfaces)),
            ("SPLAT_HULL".into(), flag(self.hull)),
            ("SPLAT_TILE".into(), self.tile.to_string()),
            ("SPLAT_APRON".into(), self.apron.to_string()),
            ("SPLAT_GROUP".into(), self.group.to_string()),
            ("SPLAT_PIXELS".into(), self.pixels.to_string()),
            ("SPLAT_SUBGROUP_OPS".into(), flag(self.subgroup_ops)),
            ("SPLAT_SCAN_BLOCK".into(), SCAN_BLOCK.to_string()),
            (
                "SPLAT_MAX_KERNEL_ENTRIES".into(),
                super::MAX_KERNEL_ENTRIES.to_string(),
            ),
            ("SPLAT_SEGMENTS".into(), super::PIXEL_SEGMENTS.to_string()),
            // Raw hits `splat_segments` keeps per pixel: the crossings of PIXEL_SEGMENTS
            // segments, plus room for coincident hits that are merged after sorting. Not
            // bvh::MAX_HITS: each access to the kernel's hit array costs in proportion to its
            // length on lavapipe (field::gpu::FIRST_HULL_HITS).
            ("HULL_MAX_HITS".into(), SEGMENT_HITS.to_string()),
        ]);
        d
    }

    /// The GLSL files a frame of this variant runs, in dispatch order.
    pub fn kernels(&self) -> Vec<&'static str> {
        let mut k = Vec::new();
        if self.hull {
            k.push("splat/splat_segments.comp");
        }
        k.extend([
            "splat/splat_project.comp",
            "splat/splat_scan.comp",
            "splat/splat_bin.comp",
            "splat/splat_raster.comp",
        ]);
        k
    }

    /// Human-readable name for `--stats`.
    pub fn name(&self) -> String {
        format!(
            "splat {} {} {}{}{}{}{} tile {}{}",
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
            if self.split { "" } else { " whole-kernels" },
            if self.ring > 0 {
                let rule = if self.quadrature {
                    "quadrature"
                } else {
                    "erfc"
                };
                format!(" ring {} {rule}", self.ring)
            } else {
                String::new()
            },
            self.tile,
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

/// The pipelines of a variant.
pub struct SplatPipelines {
    variant: SplatVariant,
    project: ComputePipeline,
    scan: [ComputePipeline; 3],
    bin: ComputePipeline,
    raster: ComputePipeline,
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
        let make = |kernel: &str, extra: &[(String, String)], bindings: &[u32], push: u32| {
            let mut d = defines.clone();
            d.extend_from_slice(extra);
            let spirv = compiler.compile(ShaderSource::File(kernel), &d)?;
            let kinds: Vec<(u32, crate::vk::BindingKind)> =
                bindings.iter().map(|&b| (b, binding::kind(b))).collect();
            ComputePipeline::with_kinds(ctx, kernel, &spirv, &kinds, push)
        };
        let mut project = vec![
            PARAMS,
            SPLAT_KERNELS,
            SPLATS,
            SPLAT_WORDS,
            BUCKET_COUNTS,
            SPLAT_STATS,
        ];
        if !post {
            project.push(TRANSFER);
        }
        if variant.surfaces {
            project.push(ISO);
        }
        let mut raster = vec![
            PARAMS,
            SPLATS,
            SPLAT_WORDS,
            OFFSET_TEXELS,
            SPLAT_LIST,
            IMAGE,
            SPLAT_STATS,
        ];
        if post {
            raster.extend([TRANSFER, TRANSFER_TEXELS]);
            if variant.isosurfaces {
                raster.push(ISO);
            }
        }
        if variant.hull {
            raster.push(PIXEL_SEGMENTS);
        }
        let push = |size: usize| size as u32;
        let scan_push = push(std::mem::size_of::<ScanPush>());
        let scan = |pass: u32, bindings: &[u32]| {
            make(
                "splat/splat_scan.comp",
                &[("SCAN_PASS".into(), pass.to_string())],
                bindings,
                scan_push,
            )
        };
        Ok(Self {
            variant: variant.clone(),
            project: make("splat/splat_project.comp", &[], &project, 0)?,
            scan: [
                scan(0, &SCAN_BINDINGS[..2])?,
                scan(1, &SCAN_BINDINGS[..3])?,
                scan(2, &SCAN_BINDINGS)?,
            ],
            bin: make(
                "splat/splat_bin.comp",
                &[],
                &[PARAMS, SPLAT_WORDS, BUCKET_CURSORS, SPLAT_LIST],
                0,
            )?,
            raster: make(
                "splat/splat_raster.comp",
                &[],
                &raster,
                push(std::mem::size_of::<RasterPush>()),
            )?,
            segments: if variant.hull {
                Some(make(
                    "splat/splat_segments.comp",
                    &[],
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

/// Frame buffers of one image size, tile size and kernel count, for up to `bucket_capacity`
/// (tile, sheet) buckets (a new camera changes the sheet count: a quarter more is allocated);
/// the entry list grows.
pub struct SplatTargets {
    key: (u32, u32, u32, u32, bool),
    bucket_capacity: u64,
    splats: Buffer,
    counts: Buffer,
    offsets: Buffer,
    cursors: Buffer,
    sums: Buffer,
    image: Buffer,
    stats: Buffer,
    list: Option<Buffer>,
    segments: Option<Buffer>,
}

impl SplatTargets {
    fn key(setup: &SplatSetup, kernels: &GpuKernels) -> (u32, u32, u32, u32, bool) {
        (
            setup.camera.width,
            setup.camera.height,
            kernels.count,
            setup.tile,
            setup.hull && setup.shading == Shading::Post,
        )
    }

    fn segments(&self) -> Result<&Buffer, VkError> {
        self.segments
            .as_ref()
            .ok_or_else(|| VkError::Usage("pixel hull segments missing".into()))
    }

    /// Whether these buffers fit a setup.
    pub fn fits(&self, setup: &SplatSetup, kernels: &GpuKernels) -> bool {
        self.key == Self::key(setup, kernels) && setup.buckets() <= self.bucket_capacity
    }

    /// Allocates the buffers of a setup.
    pub fn new(ctx: &Context, setup: &SplatSetup, kernels: &GpuKernels) -> Result<Self, VkError> {
        let (w, h) = (
            u64::from(setup.camera.width),
            u64::from(setup.camera.height),
        );
        let pixels = w * h;
        let buckets = (setup.buckets() + setup.buckets() / 4).min(super::MAX_BUCKETS);
        let blocks = buckets.div_ceil(u64::from(SCAN_BLOCK));
        let storage = |name: &str, bytes: u64| Buffer::new(ctx, name, bytes, BufferUsage::Storage);
        Ok(Self {
            key: Self::key(setup, kernels),
            bucket_capacity: buckets,
            splats: Buffer::new(
                ctx,
                "splats",
                u64::from(kernels.count).max(1) * std::mem::size_of::<Splat>() as u64,
                BufferUsage::Texel,
            )?,
            counts: storage("bucket counts", 4 * buckets)?,
            offsets: storage("bucket offsets", 4 * (buckets + 1))?,
            cursors: storage("bucket cursors", 4 * buckets)?,
            sums: storage("scan block sums", 4 * blocks)?,
            image: storage("splat image", 16 * pixels)?,
            stats: storage("splat counters", 4 * STATS as u64)?,
            list: None,
            segments: if setup.hull && setup.shading == Shading::Post {
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
    /// GPU milliseconds of `STAGES`.
    pub stage_ms: [f64; 4],
    pub submissions: u32,
    pub variant: String,
}

/// The names of [`SplatGpuImage::stage_ms`]: `splat_sort` is `splat_scan` and `splat_bin`.
pub const STAGES: [&str; 4] = [
    "splat_project",
    "splat_sort",
    "splat_raster",
    "splat_segments",
];

impl SplatGpuImage {
    /// GPU milliseconds of the whole frame.
    pub fn gpu_ms(&self) -> f64 {
        self.stage_ms.iter().sum()
    }
}

/// The frame's parameters; `tf_count` is the length of `tf`'s GPU table.
fn params(
    setup: &SplatSetup,
    kernels: &GpuKernels,
    tf: &TransferFunction,
    tf_count: u32,
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
        _pad: [0; 2],
    }
}

fn sum_ms(timings: &[crate::vk::DispatchTiming], stage_ms: &mut [f64; 4]) {
    for t in timings {
        let i = match t.label.as_str() {
            "splat_project" => 0,
            "splat_scan" | "splat_bin" => 1,
            "splat_raster" => 2,
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
    let p = params(setup, kernels, tf, gpu_tf.len() as u32);
    let params_buf = Buffer::from_slice(ctx, "splat params", &params_copies(p))?;
    let tf_buf = Buffer::from_slice(ctx, "transfer function", &gpu_tf)?;
    let isos = crate::view::shading::iso_buffer_data(&setup.isosurfaces);
    let iso_buf = Buffer::from_slice(ctx, "isosurfaces", &isos)?;
    let mut stage_ms = [0.0; 4];
    let groups = kernels.count.div_ceil(GROUP).clamp(1, 65_535);
    let buckets = setup.buckets();
    let blocks = buckets.div_ceil(u64::from(SCAN_BLOCK)) as u32;
    let scan_push = ScanPush {
        buckets: buckets as u32,
        blocks,
        _pad: [0; 2],
    };
    let (tiles_x, tiles_y) = setup.tiles();

    // Pass 1: project and count, then the scan of the bucket counts.
    let t = &*targets;
    let mut project_bind = vec![
        (binding::PARAMS, &params_buf),
        (binding::SPLAT_KERNELS, &kernels.buffer),
        (binding::SPLATS, &t.splats),
        (binding::SPLAT_WORDS, &t.splats),
        (binding::BUCKET_COUNTS, &t.counts),
        (binding::SPLAT_STATS, &t.stats),
    ];
    if setup.shading == Shading::Pre {
        project_bind.push((binding::TRANSFER, &tf_buf));
    }
    if pipelines.variant.surfaces {
        project_bind.push((binding::ISO, &iso_buf));
    }
    let group = BindGroup::new(ctx, &pipelines.project, &project_bind)?;
    // Each pass binds a prefix of the same buffers (SCAN_BINDINGS).
    let scan_buffers = [&t.counts, &t.sums, &t.offsets, &t.cursors];
    let scan_bind: Vec<(u32, &Buffer)> = SCAN_BINDINGS.into_iter().zip(scan_buffers).collect();
    let scan = [
        BindGroup::new(ctx, &pipelines.scan[0], &scan_bind[..2])?,
        BindGroup::new(ctx, &pipelines.scan[1], &scan_bind[..3])?,
        BindGroup::new(ctx, &pipelines.scan[2], &scan_bind)?,
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
    let pixel_groups = [
        setup.camera.width.div_ceil(8),
        setup.camera.height.div_ceil(8),
        1,
    ];
    let timings = ctx.submit(|rec| {
        rec.fill(&t.counts, 0);
        rec.fill(&t.stats, 0);
        if let Some((p, g)) = &segments {
            rec.dispatch(p, g, &[], pixel_groups, "splat_segments")?;
        }
        rec.dispatch(
            &pipelines.project,
            &group,
            &[],
            [groups, 1, 1],
            "splat_project",
        )?;
        let push = bytemuck::bytes_of(&scan_push);
        rec.dispatch(
            &pipelines.scan[0],
            &scan[0],
            push,
            [blocks, 1, 1],
            "splat_scan",
        )?;
        rec.dispatch(&pipelines.scan[1], &scan[1], push, [1, 1, 1], "splat_scan")?;
        rec.dispatch(
            &pipelines.scan[2],
            &scan[2],
            push,
            [blocks, 1, 1],
            "splat_scan",
        )
    })?;
    drop((group, scan, segments));
    sum_ms(&timings, &mut stage_ms);
    let band = tiles_y.div_ceil(RASTER_BANDS).max(1);
    let submissions_planned = 1 + tiles_y.div_ceil(band);
    (control.progress)(1.0 / f64::from(submissions_planned));
    let stats: Vec<u32> = t.stats.read(ctx)?;
    if let Some(&n) = stats
        .get(5)
        .filter(|&&n| n > 0 && pipelines.segments.is_some())
    {
        return Err(VkError::Usage(format!(
            "splatting: the rays of {n} pixels cross the domain's boundary into more than {} \
             inside segments; post-shaded splatting keeps {0} per pixel: ray cast this mesh",
            super::PIXEL_SEGMENTS
        ))
        .into());
    }
    control.check_stop()?;
    let oversized = stats.get(8).copied().unwrap_or(0);
    if oversized > 0 {
        return Err(VkError::Usage(format!(
            "splatting: {oversized} kernels cover more than {} tile × sheet entries each (one \
             invocation writes them); raise splat.slab or splat.tile, or lower the image size",
            super::MAX_KERNEL_ENTRIES
        ))
        .into());
    }
    // The one number the host needs: how many entries the sort will write.
    let total: Vec<u32> = t.offsets.read_range(ctx, buckets as usize, 1)?;
    let total = u64::from(total.first().copied().unwrap_or(0));
    if let Some(budget) = control.budget {
        setup.check_budget(total, budget)?;
    }
    // One rg32ui texel per entry: the splat and the sheet.
    let limit = ctx
        .info()
        .max_texel_buffer_elements
        .min(ctx.info().max_heap_bytes / 8);
    if total > limit {
        return Err(VkError::Usage(format!(
            "splatting: {total} binned footprints exceed the entry list's limit of {limit} \
             (maxTexelBufferElements); raise splat.slab or splat.tile, or lower the image size"
        ))
        .into());
    }
    let needed = 8 * total.max(1);
    if targets.list.as_ref().is_none_or(|l| l.size() < needed) {
        targets.list = None;
        let grown = (needed + needed / 2).min(limit * 8).max(needed);
        targets.list = Some(Buffer::new(
            ctx,
            "splat entries",
            grown,
            BufferUsage::Texel,
        )?);
    }
    let t = &*targets;
    let Some(list) = t.list.as_ref() else {
        return Err(VkError::Usage("splat entry list missing".into()).into());
    };

    // Pass 2: the scatter, then the tiles in bands of rows.
    let bin = BindGroup::new(
        ctx,
        &pipelines.bin,
        &[
            (binding::PARAMS, &params_buf),
            (binding::SPLAT_WORDS, &t.splats),
            (binding::BUCKET_CURSORS, &t.cursors),
            (binding::SPLAT_LIST, list),
        ],
    )?;
    let mut raster_bind = vec![
        (binding::PARAMS, &params_buf),
        (binding::SPLATS, &t.splats),
        (binding::SPLAT_WORDS, &t.splats),
        (binding::OFFSET_TEXELS, &t.offsets),
        (binding::SPLAT_LIST, list),
        (binding::IMAGE, &t.image),
        (binding::SPLAT_STATS, &t.stats),
    ];
    if setup.shading == Shading::Post {
        raster_bind.push((binding::TRANSFER, &tf_buf));
        raster_bind.push((binding::TRANSFER_TEXELS, &tf_buf));
        if !setup.isosurfaces.is_empty() {
            raster_bind.push((binding::ISO, &iso_buf));
        }
    }
    if pipelines.variant.hull {
        raster_bind.push((binding::PIXEL_SEGMENTS, t.segments()?));
    }
    let raster = BindGroup::new(ctx, &pipelines.raster, &raster_bind)?;
    let mut submissions = 1;
    let mut row = 0;
    while row < tiles_y {
        let rows = band.min(tiles_y - row);
        let first = row == 0;
        let push = RasterPush {
            tile_row: row,
            _pad: [0; 3],
        };
        let timings = ctx.submit(|rec| {
            if first {
                rec.dispatch(&pipelines.bin, &bin, &[], [groups, 1, 1], "splat_bin")?;
            }
            rec.dispatch(
                &pipelines.raster,
                &raster,
                bytemuck::bytes_of(&push),
                [tiles_x, rows, 1],
                "splat_raster",
            )
        })?;
        sum_ms(&timings, &mut stage_ms);
        submissions += 1;
        row += rows;
        (control.progress)(f64::from(submissions) / f64::from(submissions_planned));
        control.check_stop()?;
    }
    drop((bin, raster));
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
    // splat_raster counts entries once per invocation of the tile's workgroup.
    let per_group = |n: u64| n / u64::from(pipelines.variant.group);
    Ok(SplatGpuImage {
        pixels,
        counts: SplatCounts {
            projected: s(0),
            culled_near: s(1),
            culled_outside: s(2),
            culled_degenerate: s(3),
            culled_empty: s(4),
            entries: total,
            skipped_occluded: per_group(s(6) | s(13) << 32),
            accumulated: per_group(s(7) | s(14) << 32),
            oversized: s(8),
            evaluated: s(9) | s(11) << 32,
            contributions: s(10) | s(12) << 32,
        },
        stage_ms,
        submissions,
        variant: pipelines.variant.name(),
    })
}
