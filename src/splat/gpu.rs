//! The splatting kernels' device side (`glsl/splat/*.comp`): the kernels' upload, the
//! variant of a setup and its pipelines, and a frame's buffers. A frame's commands are in
//! [`super::frame`].

use super::project::KernelKind;
use super::{Antialias, SCAN_BLOCK, Shading, SplatSetup};
use crate::field::Field;
use crate::gpu_types::{CameraBlock, RasterPush, ScanPush, Splat, WalkPush, binding, splat_stat};
use crate::view::transfer::TransferFunction;
use crate::vk::{
    Buffer, BufferUsage, ComputePipeline, Context, ShaderCompiler, ShaderSource, VkError,
};

/// What `splat_scan`'s passes bind: pass p the first p + 2 of these (counts and block sums;
/// then the offsets it writes; then the cursors it starts).
pub(super) const SCAN_BINDINGS: [u32; 4] = [
    binding::BUCKET_COUNTS,
    binding::SCAN_SUMS,
    binding::BUCKET_OFFSETS,
    binding::BUCKET_CURSORS,
];
/// What both passes of `splat_order` bind: the bucket offsets, the list they sort, the
/// counters, and the bucket cursors (the large buckets' indices, once the scatter is done).
pub(super) const ORDER_BINDINGS: [u32; 4] = [
    binding::OFFSET_TEXELS,
    binding::SPLAT_LIST,
    binding::SPLAT_STATS,
    binding::BUCKET_CURSORS,
];
/// Hull hits `splat_segments` keeps per pixel (`HULL_MAX_HITS` of its variant).
pub const SEGMENT_HITS: usize = 2 * super::PIXEL_SEGMENTS + 4;

/// Words of a pixel's registers that `splat_raster` saves between passes (`SPLAT_PIXEL_WORDS`):
/// the most any variant keeps, post-shaded with a ring of 16 sheets (27).
const RASTER_PIXEL_WORDS: u32 = 28;
/// `SplatCounts` counters in the stats buffer.
/// Counter slots: 0–5 and 8 one word each; 64-bit ones: 9 and 10 with high words 11 and 12,
/// 6 and 7 with high words 13 and 14; 15 the tiles cut short (`splat_stat::RASTER_TRUNCATED`);
/// 16 the buckets left out of kernel order (`splat_stat::UNORDERED`), 17 those handed to
/// `splat_order`'s second pass (`splat_stat::LARGE_BUCKETS`), 18 the walks resumed
/// (`splat_stat::RESUMED`), 19 and 20 (64-bit) the interval halves whose lookups were skipped
/// (`splat_stat::CLEAR_SKIPPED`); then one word per band, its tiles' most entries
/// (`splat_stat::BAND_ENTRIES`).
const STATS: usize = splat_stat::BAND_ENTRIES;

/// The kernels uploaded once per dataset: one `Sample` each, volume in `metric_off.z`.
pub struct GpuKernels {
    pub(super) buffer: Buffer,
    pub(super) count: u32,
    /// The isosurface values whose surface splats follow the volume kernels.
    surface_values: Vec<f64>,
    /// Pre-shaded: the transfer function whose transparent kernels were left out.
    classified_by: Option<TransferFunction>,
    left_out: u64,
}

/// Whether a volume kernel of value `v` is transparent under `tf` with room to spare: τ is zero
/// within a relative 1e-5 of v (of the function's scale), so that `splat_project`'s f32 lookup of
/// the f32 value, whichever segment its rounding picks, gives τ = 0 and culls it as empty.
pub fn transparent_kernel(tf: &TransferFunction, v: f64) -> bool {
    let p = tf.points();
    let scale = v
        .abs()
        .max(p[0][0].abs())
        .max(p[p.len() - 1][0].abs())
        .max(1e-30);
    let margin = 1e-5 * scale;
    v.is_finite() && tf.transparent_on(v - margin, v + margin)
}

impl GpuKernels {
    /// Uploads every sample of the field as a Gaussian kernel, then `surfaces`, the surface
    /// splats of `isosurfaces` (`surface::surface_kernels`; none: no surface splats). A surface
    /// splat keeps its metric's scale in `pos_value.w` and 1 + its isosurface index in
    /// `metric_off.w` (0 for volume kernels).
    ///
    /// With `classify` (pre-shaded frames), the volume kernels that transfer function makes
    /// transparent ([`transparent_kernel`]) are left out: `splat_project` would cull each as
    /// empty, after paying for it in every SIMD lane (llvmpipe runs both sides of a branch).
    /// The frame is the same to the bit, since the kept kernels keep their order.
    pub fn upload(
        ctx: &Context,
        field: &Field,
        isosurfaces: &[crate::view::shading::Isosurface],
        surfaces: Vec<super::project::Kernel>,
        classify: Option<&TransferFunction>,
    ) -> Result<Self, VkError> {
        let values = &field.samples.values;
        let keep: Vec<bool> = (0..field.samples.len())
            .map(|i| classify.is_none_or(|tf| !transparent_kernel(tf, f64::from(values.get(i)))))
            .collect();
        let left_out = keep.iter().filter(|&&k| !k).count() as u64;
        // Only the kept kernels' volumes are needed (all of them without `classify`).
        let volumes = match classify {
            Some(_) => field.kernel_volumes_where(&|i| keep[i]),
            None => std::borrow::Cow::Borrowed(field.kernel_volumes()),
        };
        let data: Vec<crate::gpu_types::Sample> = (0..keep.len())
            .filter(|&i| keep[i])
            .map(|i| super::raster::kernel_of_volume(field, i, volumes.get(i)))
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
        // A buffer of at least one kernel: every kernel may be transparent.
        let bytes: &[u8] = bytemuck::cast_slice(&data);
        let size = (bytes.len() as u64).max(std::mem::size_of::<crate::gpu_types::Sample>() as u64);
        let buffer = Buffer::new(ctx, "splat kernels", size, BufferUsage::Texel)?;
        if !bytes.is_empty() {
            buffer.write(ctx, bytes)?;
        }
        Ok(Self {
            buffer,
            count,
            surface_values: isosurfaces.iter().map(|i| i.value).collect(),
            classified_by: classify.cloned(),
            left_out,
        })
    }

    /// Volume kernels left out as transparent.
    pub fn left_out(&self) -> u64 {
        self.left_out
    }

    /// Whether these kernels carry the surface splats of exactly these isosurfaces and were
    /// classified by `classify` (or not at all, for `None`).
    pub fn serve(
        &self,
        isosurfaces: &[crate::view::shading::Isosurface],
        classify: Option<&TransferFunction>,
    ) -> bool {
        self.classified_by.as_ref() == classify
            && self.surface_values.len() == isosurfaces.len()
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
    /// With ring registers: the sheet-share rule (`SplatSetup::sheet_share`).
    pub sheet_share: super::SheetShare,
    /// The quadrature widens kernels thinner than it serves (`SplatSetup::widen`).
    pub widen: bool,
    /// Post-shaded: how sheets are classified between their middles (`SplatSetup::interval`;
    /// not `Constant`: the raster reads the preintegration table).
    pub interval: super::SheetInterval,
    pub occlusion: bool,
    pub isosurfaces: bool,
    /// Surface splats (pre-shaded isosurfaces).
    pub surfaces: bool,
    /// Post-shaded over a hull: per-pixel inside segments bound the domain.
    pub hull: bool,
    /// A brick's frame: composites only the sheets its cell owns (`SplatSetup::owns`).
    pub brick: bool,
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
    /// Post-shaded: branches around exact zeros, the shares of pixels outside a footprint
    /// (`SplatSetup::branches`) and lookups of all-zero table entries (`SplatSetup::clear_skip`).
    pub branches: bool,
    pub clear_skip: bool,
    /// Post-shaded: lookups of halves outside the domain skipped (`SplatSetup::outside_skip`).
    pub outside_skip: bool,
    /// What the walk loads one entry ahead (`SplatSetup::prefetch`).
    pub prefetch: super::Prefetch,
    /// Post-shaded intervals' lookups take the transfer function's exact opacity
    /// (`SplatSetup::exact_opacity`, `PREINT_EXACT_OPACITY`).
    pub exact_opacity: bool,
    /// With it, the transfer function's points its scan unrolls over from `SplatParams::tf`
    /// ([`crate::view::preintegration::unrolled_tf_points`]).
    pub tf_points: u32,
}

impl SplatVariant {
    /// The variant a setup needs on a device.
    pub fn of(setup: &SplatSetup, device: &crate::vk::DeviceInfo) -> Self {
        let subgroup = device.subgroup_size.clamp(1, 128);
        let pixels = setup.raster_pixels();
        Self {
            shading: setup.shading,
            antialias: setup.settings.antialias,
            orthographic: setup.orthographic(),
            exact: setup.exact_footprints(),
            split: setup.split,
            ring: setup.ring,
            sheet_share: setup.sheet_share,
            widen: setup.widen,
            interval: setup.interval,
            occlusion: setup.settings.occlusion,
            isosurfaces: !setup.isosurfaces.is_empty(),
            surfaces: setup.settings.surface && !setup.isosurfaces.is_empty(),
            hull: setup.hull && setup.shading == Shading::Post,
            brick: setup.cell.is_some(),
            tile: setup.tile,
            apron: setup.apron(),
            pixels,
            group: (setup.group_size() / pixels).next_multiple_of(subgroup.max(8)),
            subgroup_ops: device.subgroup_ops,
            branches: setup.branches,
            clear_skip: setup.clear_skip,
            outside_skip: setup.outside_skip,
            prefetch: setup.prefetch,
            exact_opacity: setup.exact_opacity,
            tf_points: crate::view::preintegration::unrolled_tf_points(
                setup.exact_opacity,
                setup.tf_points,
            ),
        }
    }

    /// Whether `splat_raster` reads the preintegration table (post-shaded intervals between
    /// sheet middles).
    pub fn reads_tables(&self) -> bool {
        self.shading == Shading::Post && self.interval != super::SheetInterval::Constant
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
                    Antialias::Auto => "3",
                }
                .into(),
            ),
            ("SPLAT_ORTHO".into(), flag(self.orthographic)),
            ("SPLAT_EXACT".into(), flag(self.exact)),
            ("SPLAT_SPLIT".into(), flag(self.split)),
            ("SPLAT_RING".into(), self.ring.to_string()),
            (
                "SPLAT_QUADRATURE".into(),
                match self.sheet_share {
                    super::SheetShare::Erfc => "0",
                    super::SheetShare::Quadrature => "1",
                    super::SheetShare::Midpoint => "2",
                }
                .into(),
            ),
            ("SPLAT_WIDEN".into(), flag(self.widen)),
            (
                "SPLAT_INTERVAL".into(),
                match self.interval {
                    super::SheetInterval::Constant => "0",
                    super::SheetInterval::Linear => "1",
                    super::SheetInterval::Hermite => "2",
                }
                .into(),
            ),
            (
                "QUADRATURE_MAX_SHEET".into(),
                format!("{:?}", super::QUADRATURE_MAX_SHEET),
            ),
            ("SPLAT_OCCLUSION".into(), flag(self.occlusion)),
            ("SPLAT_ISOSURFACES".into(), flag(self.isosurfaces)),
            ("SPLAT_SURFACES".into(), flag(self.surfaces)),
            ("SPLAT_HULL".into(), flag(self.hull)),
            ("SPLAT_BRICK".into(), flag(self.brick)),
            ("SPLAT_TILE".into(), self.tile.to_string()),
            ("SPLAT_APRON".into(), self.apron.to_string()),
            ("SPLAT_GROUP".into(), self.group.to_string()),
            ("SPLAT_PIXELS".into(), self.pixels.to_string()),
            ("SPLAT_SUBGROUP_OPS".into(), flag(self.subgroup_ops)),
            ("SPLAT_BRANCHES".into(), flag(self.branches)),
            ("SPLAT_CLEAR_SKIP".into(), flag(self.clear_skip)),
            ("SPLAT_OUTSIDE_SKIP".into(), flag(self.outside_skip)),
            (
                "SPLAT_PREFETCH".into(),
                match self.prefetch {
                    super::Prefetch::None => "0",
                    super::Prefetch::List => "1",
                    super::Prefetch::Records => "2",
                }
                .into(),
            ),
            ("SPLAT_SCAN_BLOCK".into(), SCAN_BLOCK.to_string()),
            (
                "SPLAT_MAX_KERNEL_ENTRIES".into(),
                super::MAX_KERNEL_ENTRIES.to_string(),
            ),
            ("SPLAT_SEGMENTS".into(), super::PIXEL_SEGMENTS.to_string()),
            ("SPLAT_PIXEL_WORDS".into(), RASTER_PIXEL_WORDS.to_string()),
            // Raw hits `splat_segments` keeps per pixel: the crossings of PIXEL_SEGMENTS
            // segments, plus room for coincident hits that are merged after sorting. Not
            // bvh::MAX_HITS: each access to the kernel's hit array costs in proportion to its
            // length on lavapipe (field::gpu::FIRST_HULL_HITS).
            ("HULL_MAX_HITS".into(), SEGMENT_HITS.to_string()),
        ]);
        d.extend(crate::view::preintegration::exact_opacity_defines(
            self.exact_opacity,
            self.tf_points,
        ));
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
            "splat/splat_walks.comp",
            "splat/splat_bin.comp",
            "splat/splat_order.comp",
            "splat/splat_raster.comp",
        ]);
        k
    }

    /// Words of `splat_raster`'s state per tile of a band: per invocation a tag, the walk's
    /// position (three words) and its pixels' registers.
    pub fn raster_tile_words(&self) -> u64 {
        u64::from(self.group) * (4 + u64::from(self.pixels * RASTER_PIXEL_WORDS))
    }

    /// Human-readable name for `--stats`.
    pub fn name(&self) -> String {
        format!(
            "splat {} {} {}{}{}{}{}{}{} tile {}{}{}{}{}{}{}",
            match self.shading {
                Shading::Pre => "pre-shaded",
                Shading::Post => "post-shaded",
            },
            match self.antialias {
                Antialias::Ewa => "ewa",
                Antialias::Swan => "swan",
                Antialias::None => "no-lowpass",
                Antialias::Auto => "auto-lowpass",
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
                // Only the sampled rules widen (SplatSetup::widen).
                let widen = if self.widen {
                    " widening-thin-kernels"
                } else {
                    ""
                };
                format!(" ring {} {}{widen}", self.ring, self.sheet_share.name())
            } else {
                String::new()
            },
            if self.shading == Shading::Post {
                format!(" {}-intervals", self.interval.name())
            } else {
                String::new()
            },
            if self.exact_opacity {
                " exact-opacity"
            } else {
                ""
            },
            self.tile,
            if self.surfaces {
                " surface-splats"
            } else if self.isosurfaces {
                " isosurfaces"
            } else {
                ""
            },
            if self.brick { " brick" } else { "" },
            if self.branches { " branches" } else { "" },
            if self.clear_skip { " clear-skip" } else { "" },
            if self.outside_skip {
                " outside-skip"
            } else {
                ""
            },
            match self.prefetch {
                super::Prefetch::None => String::new(),
                p => format!(" prefetch-{}", p.name()),
            },
        )
    }
}

/// The pipelines of a variant.
pub struct SplatPipelines {
    variant: SplatVariant,
    pub(super) project: ComputePipeline,
    pub(super) scan: [ComputePipeline; 3],
    pub(super) walks: ComputePipeline,
    /// `splat_plan`, compiled for recorded frames only (`SplatPipelines::with_plan`).
    pub(super) plan: Option<ComputePipeline>,
    pub(super) bin: ComputePipeline,
    /// `splat_order`'s two passes.
    pub(super) order: [ComputePipeline; 2],
    pub(super) raster: ComputePipeline,
    pub(super) segments: Option<ComputePipeline>,
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
            SPLAT_RASTER_STATE,
        ];
        if variant.reads_tables() {
            raster.push(PREINT);
        }
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
        let order = |pass: u32| {
            make(
                "splat/splat_order.comp",
                &[("ORDER_PASS".into(), pass.to_string())],
                &ORDER_BINDINGS,
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
            walks: make(
                "splat/splat_walks.comp",
                &[],
                &[BUCKET_OFFSETS, SPLAT_STATS],
                push(std::mem::size_of::<WalkPush>()),
            )?,
            bin: make(
                "splat/splat_bin.comp",
                &[],
                &[PARAMS, SPLAT_WORDS, BUCKET_CURSORS, SPLAT_LIST],
                0,
            )?,
            order: [order(1)?, order(2)?],
            raster: make(
                "splat/splat_raster.comp",
                &[],
                &raster,
                push(std::mem::size_of::<RasterPush>()),
            )?,
            plan: None,
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

    /// Compiles `splat_plan`, which recorded frames run, if these pipelines lack it.
    pub fn with_plan(&mut self, ctx: &Context, compiler: &ShaderCompiler) -> Result<(), VkError> {
        if self.plan.is_some() {
            return Ok(());
        }
        let spirv = compiler.compile(
            ShaderSource::File("splat/splat_plan.comp"),
            &crate::gpu_types::binding_defines(),
        )?;
        let kinds = [
            binding::BUCKET_OFFSETS,
            binding::SPLAT_STATS,
            binding::DISPATCH_ARGS,
        ]
        .map(|b| (b, binding::kind(b)));
        self.plan = Some(ComputePipeline::with_kinds(
            ctx,
            "splat/splat_plan.comp",
            &spirv,
            &kinds,
            std::mem::size_of::<crate::gpu_types::PlanPush>() as u32,
        )?);
        Ok(())
    }
}

/// Frame buffers of one image size, tile size and kernel count, for up to `bucket_capacity`
/// (tile, sheet) buckets (a new camera changes the sheet count: a quarter more is allocated);
/// the entry list grows.
pub struct SplatTargets {
    key: (u32, u32, u32, u32, u32, bool),
    bucket_capacity: u64,
    pub(super) splats: Buffer,
    pub(super) counts: Buffer,
    pub(super) offsets: Buffer,
    pub(super) cursors: Buffer,
    pub(super) sums: Buffer,
    pub(super) image: Buffer,
    pub(super) stats: Buffer,
    pub(super) list: Option<Buffer>,
    /// `splat_raster`'s walks between passes, for one band (`reserve_raster_state`).
    pub(super) raster_state: Option<Buffer>,
    pub(super) segments: Option<Buffer>,
    /// The camera whose pixels' hull segments `segments` holds (post-shaded over a hull): a
    /// frame of that camera skips `splat_segments`. `None`: none yet, or being rewritten.
    segments_held: Option<CameraBlock>,
    /// The camera a recorded frame's `splat_segments` writes for: held once it is retired.
    segments_pending: Option<CameraBlock>,
}

impl SplatTargets {
    fn key(setup: &SplatSetup, kernels: &GpuKernels) -> (u32, u32, u32, u32, u32, bool) {
        (
            setup.camera.width,
            setup.camera.height,
            kernels.count,
            setup.tile,
            setup.band_rows,
            setup.hull && setup.shading == Shading::Post,
        )
    }

    /// What the held segments are compared by: the camera's GPU block, from which the kernel
    /// makes the pixels' rays.
    fn segments_key(setup: &SplatSetup) -> CameraBlock {
        setup.camera.gpu_block(&setup.basis, setup.eye)
    }

    /// Whether these buffers have room for pixels' hull segments (post-shaded over a hull).
    pub fn has_segments(&self) -> bool {
        self.segments.is_some()
    }

    /// Before a frame of `setup`: whether its pixels' hull segments are in these buffers
    /// already (`splat_segments` then does not run). Otherwise they are forgotten until the
    /// frame holds them: [`SplatTargets::hold_segments`] after it, or at a `recorded` frame's
    /// retire ([`SplatTargets::retire_segments`]).
    pub fn plan_segments(&mut self, setup: &SplatSetup, recorded: bool) -> bool {
        let key = Self::segments_key(setup);
        let reused = self.has_segments() && self.segments_held == Some(key);
        self.segments_pending = None;
        if !reused && self.has_segments() {
            self.segments_held = None;
            self.segments_pending = recorded.then_some(key);
        }
        reused
    }

    /// After a frame of `setup` that passed the projection's checks: its segments are held.
    pub fn hold_segments(&mut self, setup: &SplatSetup) {
        if self.has_segments() {
            self.segments_held = Some(Self::segments_key(setup));
        }
    }

    /// Another pass of `splat_segments` (a projection of its own) rewrites them.
    pub fn forget_segments(&mut self) {
        self.segments_held = None;
    }

    /// At a completed recorded frame's retire: `Some(reused)` where these buffers have
    /// segments; what the frame wrote is held from now on.
    pub fn retire_segments(&mut self) -> Option<bool> {
        let pending = self.segments_pending.take();
        if pending.is_some() {
            self.segments_held = pending;
        }
        self.has_segments().then_some(pending.is_none())
    }

    pub(super) fn segments(&self) -> Result<&Buffer, VkError> {
        self.segments
            .as_ref()
            .ok_or_else(|| VkError::Usage("pixel hull segments missing".into()))
    }

    pub(super) fn raster_state(&self) -> Result<&Buffer, VkError> {
        self.raster_state
            .as_ref()
            .ok_or_else(|| VkError::Usage("splat raster state missing".into()))
    }

    /// Whether these buffers fit a setup.
    pub fn fits(&self, setup: &SplatSetup, kernels: &GpuKernels) -> bool {
        self.key == Self::key(setup, kernels) && setup.buckets() <= self.bucket_capacity
    }

    /// The frame's pixels, premultiplied (C, 1 − T), before the background.
    pub fn image(&self) -> &Buffer {
        &self.image
    }

    /// Entries the list holds (0 before the first frame).
    pub fn list_capacity(&self) -> u64 {
        self.list.as_ref().map_or(0, |l| l.size() / 8)
    }

    /// Makes room for `entries` in the list (at most `limit`): a list too small is replaced by
    /// one half as large again, so that frames whose counts creep up do not reallocate each
    /// time.
    pub fn reserve_entries(
        &mut self,
        ctx: &Context,
        entries: u64,
        limit: u64,
    ) -> Result<(), VkError> {
        let needed = 8 * entries.max(1);
        if self.list.as_ref().is_none_or(|l| l.size() < needed) {
            self.list = None;
            let grown = (needed + needed / 2).min(limit * 8).max(needed);
            self.list = Some(Buffer::new(
                ctx,
                "splat entries",
                grown,
                BufferUsage::Texel,
            )?);
        }
        Ok(())
    }

    /// Makes room for the walks of one band of `variant`'s `splat_raster` between its passes
    /// (`band_rows` tile rows of `tiles_x` tiles).
    pub fn reserve_raster_state(
        &mut self,
        ctx: &Context,
        variant: &SplatVariant,
        tiles_x: u32,
        band_rows: u32,
    ) -> Result<(), VkError> {
        let words = variant.raster_tile_words() * u64::from(tiles_x) * u64::from(band_rows);
        if self
            .raster_state
            .as_ref()
            .is_none_or(|b| b.size() < 4 * words)
        {
            self.raster_state = None;
            self.raster_state = Some(Buffer::new(
                ctx,
                "splat raster state",
                4 * words,
                BufferUsage::Storage,
            )?);
        }
        Ok(())
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
            stats: storage(
                "splat counters",
                4 * (STATS as u64 + u64::from(super::plan::raster_bands(setup))),
            )?,
            list: None,
            raster_state: None,
            segments: if setup.hull && setup.shading == Shading::Post {
                Some(storage(
                    "pixel hull segments",
                    8 * super::PIXEL_SEGMENTS as u64 * pixels,
                )?)
            } else {
                None
            },
            segments_held: None,
            segments_pending: None,
        })
    }
}
