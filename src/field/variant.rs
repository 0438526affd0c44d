//! The shader variant a field needs and the field's part of the kernel constants. The renderers
//! add their own choices to a [`Variant`] (`raycast::gpu`, `splat::gpu`).
//!
//! Variants are compile-time choices passed to shaderc as macros (DESIGN §7): basis
//! (`MLS_TERMS`), weight (`MLS_WEIGHT`), gradient (`MLS_ANALYTIC_GRADIENT`) and neighbour
//! structure (`MLS_NEIGHBOURS`).

use super::Field;
use crate::data::Storage;
use crate::gpu_types::{RenderParams, binding, binding_defines};
use crate::recon::NeighbourMode;
use crate::recon::mls::{Basis, GradientMode, Weight};
use crate::view::shading::MAX_ISOSURFACES;
use crate::view::{AdaptiveCriterion, IntervalModel, Method};
use crate::vk::{ComputePipeline, Context, ShaderCompiler, ShaderSource, VkError};

/// The compile-time choices of a kernel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Variant {
    pub basis: Basis,
    /// Support radius in sample spacings (sizes the grid specialisation's fixed loops).
    pub support: f64,
    pub weight: Weight,
    pub gradient: GradientMode,
    pub neighbours: NeighbourMode,
    /// Per-sample supports: diagonal metrics only, or full ones (octree path).
    pub full_metric: bool,
    /// The octree's leaves are read as inline records, not coded references
    /// (`OCTREE_INLINE`, [`super::records`]).
    pub inline_records: bool,
    /// Texels of an inline record (`RECORD_STRIDE`: 1 packed, 2, or 3 with full metrics;
    /// [`super::records::record_stride`]).
    pub record_stride: usize,
    /// The ray caster's integrator (`None` for kernels that do not integrate).
    pub method: Option<Method>,
    /// Adaptive stack entries (levels of subdivision).
    pub adaptive_levels: usize,
    /// The adaptive integrator's acceptance test.
    pub adaptive: AdaptiveCriterion,
    /// How the fixed-step integrator composites an interval.
    pub interval: IntervalModel,
    /// Table lookups take their opacity from the transfer function's integral
    /// (`PREINT_EXACT_OPACITY`; `render.exact_opacity`).
    pub exact_opacity: bool,
    /// With it, the transfer function's point count where its scan is unrolled over the
    /// parameters' `TfBlock` (`PREINT_TF_POINTS`; 0: read from the texel view).
    pub tf_points: u32,
    /// The Hermite criterion's pieces of change where its sensitivity scan is unrolled over
    /// the parameters' `SensitivityBlock` (`TF_SENSITIVITY_PIECES`; `None`: it reads the
    /// texel view, as every kernel without that criterion is compiled).
    pub sensitivity_pieces: Option<u32>,
    /// Isosurfaces of the scene (0 compiles no isosurface code).
    pub isosurfaces: usize,
    /// Rays are clipped to a boundary hull (else to the domain's box).
    pub hull: bool,
    /// Crossings of the hull a ray may have (`HULL_MAX_HITS`): the kernel keeps them in a
    /// local array whose every dynamically indexed access costs in proportion to its length on
    /// lavapipe, so frames start with [`super::gpu::FIRST_HULL_HITS`] and only a frame with a ray past
    /// them is rendered again with `bvh::MAX_HITS` (the CPU twin's bound).
    pub hull_hits: u32,
    /// Whether the ray caster keeps the hull segments it walks, or reads kept ones
    /// ([`crate::raycast::segments`]).
    pub hull_cache: HullCache,
    /// The Gaussian-sum field instead of MLS (`reconstruction.method = "gaussian"`).
    pub gaussian: bool,
    /// The generator's analytic field instead of a reconstruction (`"exact"`).
    pub exact: bool,
    /// The fast path's refinement factor (`reconstruction.resample`; 0: none).
    pub resample: u32,
    /// Whether the kernel evaluates the fast path (the ray caster, mls_eval) or the general one
    /// (recon_resample, which computes the fine grid from it).
    pub resampled: bool,
    /// The fast path's fine grid is paged ([`crate::recon::pages`]): one page-table read
    /// before the corners'.
    pub paged: bool,
    /// The fast path's cells with a barely determined corner are solved by the general path
    /// (`RESAMPLE_DIRECT`; `Reconstruction::resample_direct`): recon_resample marks those
    /// corners, the ray caster solves there.
    pub resample_direct: bool,
    /// Empty-space skipping in the ray caster ([`super::skip`]).
    pub skip: bool,
    /// Rays clipped to a brick's box ([`Field::piece`]), steps anchored to the undivided ray.
    pub clip: bool,
    /// How the grid's values are stored on the device (`GRID_BITS`, `GRID_SIGNED`): 8- and
    /// 16-bit samples stay at their size and the kernel converts them. F32 off the grid path.
    pub grid: Storage,
}

/// How the ray caster comes by each ray's inside segments of a mesh's hull
/// ([`crate::raycast::segments`], `HULL_CACHED`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HullCache {
    /// It walks the hull's BVH in every chunk.
    Off,
    /// It walks it, and the chunks that start rays keep the segments in the frame's cache.
    Keep,
    /// It reads the segments a frame of the same camera kept; the walk is not compiled in.
    Read,
}

impl Variant {
    /// The variant a field needs.
    pub fn of(field: &Field) -> Self {
        let r = field.reconstruction;
        Self {
            basis: r.basis,
            support: r.support,
            weight: r.weight,
            gradient: r.gradient,
            neighbours: if field.uses_octree() {
                NeighbourMode::Octree
            } else {
                NeighbourMode::Grid
            },
            full_metric: field.has_full_metric(),
            inline_records: field.uses_octree() && field.octree_inline(),
            record_stride: field.record_stride(),
            hull: false,
            hull_hits: crate::samples::bvh::MAX_HITS as u32,
            hull_cache: HullCache::Off,
            gaussian: r.method == crate::recon::ReconMethod::Gaussian,
            exact: r.method == crate::recon::ReconMethod::Exact,
            resample: r.resample,
            resampled: r.resample > 0,
            paged: field.fine_pages().is_some(),
            resample_direct: r.resample > 0 && r.resample_direct,
            skip: false,
            clip: false,
            method: None,
            adaptive_levels: 1,
            adaptive: AdaptiveCriterion::Mls2008,
            interval: IntervalModel::Linear,
            exact_opacity: false,
            tf_points: 0,
            sensitivity_pieces: None,
            isosurfaces: 0,
            grid: if field.uses_octree() {
                Storage::F32
            } else {
                field.samples.values.storage()
            },
        }
    }

    /// The binding the grid is read through ([`grid_binding`]).
    pub fn grid_binding(&self) -> u32 {
        grid_binding(self.grid)
    }

    /// shaderc macro definitions (plus the binding numbers).
    pub fn defines(&self) -> Vec<(String, String)> {
        let mut d = binding_defines();
        // Grid points per axis that can fall inside a support of radius s (in spacings).
        d.push((
            "MLS_GRID_BOX".into(),
            ((2.0 * self.support).floor() as u32 + 1).to_string(),
        ));
        // Units (an rgba32f texel of f32 samples, an r32ui word of 8- or 16-bit ones) covering
        // a row window: up to unit − 1 leading values plus the box.
        let unit = if self.grid == Storage::F32 {
            4
        } else {
            32 / self.grid.bits()
        };
        d.push((
            "MLS_GRID_WINDOW".into(),
            ((2.0 * self.support).floor() as u32 + unit)
                .div_ceil(unit)
                .to_string(),
        ));
        d.push(("GRID_BITS".into(), self.grid.bits().to_string()));
        let flag = |b: bool| if b { "1" } else { "0" }.to_string();
        d.push(("MLS_TERMS".into(), self.basis.terms().to_string()));
        d.push((
            "MLS_WEIGHT".into(),
            flag(self.weight == Weight::Interpolating),
        ));
        d.push((
            "MLS_ANALYTIC_GRADIENT".into(),
            flag(self.gradient == GradientMode::Analytic),
        ));
        d.push((
            "MLS_NEIGHBOURS".into(),
            flag(self.neighbours == NeighbourMode::Octree),
        ));
        d.push(("MLS_FULL_METRIC".into(), flag(self.full_metric)));
        d.push(("OCTREE_INLINE".into(), flag(self.inline_records)));
        // The coded layout reads `Sample`s (three texels) whatever the metric.
        let stride = if self.inline_records {
            self.record_stride
        } else {
            3
        };
        d.push(("RECORD_STRIDE".into(), stride.to_string()));
        d.push(("GRID_SIGNED".into(), flag(self.grid.signed())));
        d.push(("MLS_GAUSSIAN".into(), flag(self.gaussian)));
        d.push(("MLS_EXACT".into(), flag(self.exact)));
        d.push((
            "MLS_RESAMPLED".into(),
            if self.resampled { self.resample } else { 0 }.to_string(),
        ));
        d.push(("RESAMPLE_FACTOR".into(), self.resample.max(1).to_string()));
        d.push((
            "RESAMPLE_PAGED".into(),
            flag(self.paged && self.resample > 0),
        ));
        d.push((
            "RESAMPLE_PAGE".into(),
            crate::recon::pages::PAGE.to_string(),
        ));
        d.push((
            "RESAMPLE_SLOT_CONSTANT".into(),
            format!("{}u", crate::recon::pages::SLOT_CONSTANT),
        ));
        d.push(("RESAMPLE_DIRECT".into(), flag(self.resample_direct)));
        d.push(("SKIP".into(), flag(self.skip)));
        d.push(("CLIP".into(), flag(self.clip)));
        d.push(("SKIP_BLOCK".into(), super::skip::SKIP_BLOCK.to_string()));
        d.push(("SKIP_RUN".into(), super::skip::SKIP_RUN.to_string()));
        d.push(("RUN_NUDGE".into(), format!("{:e}", super::skip::RUN_NUDGE)));
        d.extend(super::exact::defines());
        d.push(("HULL".into(), flag(self.hull)));
        d.push(("HULL_MAX_HITS".into(), self.hull_hits.to_string()));
        let cached = match self.hull_cache {
            _ if !self.hull => 0,
            HullCache::Off => 0,
            HullCache::Read => 1,
            HullCache::Keep => 2,
        };
        d.push(("HULL_CACHED".into(), cached.to_string()));
        let ray_method = match self.method {
            Some(Method::Fixed) => 1,
            Some(Method::Adaptive) => 2,
            _ => 0,
        };
        d.push(("RAY_METHOD".into(), ray_method.to_string()));
        d.push(("ADAPTIVE_LEVELS".into(), self.adaptive_levels.to_string()));
        d.push((
            "ADAPTIVE_CRITERION".into(),
            match self.adaptive {
                AdaptiveCriterion::Mls2008 => "0",
                AdaptiveCriterion::Hermite => "1",
            }
            .into(),
        ));
        d.push((
            "INTERVAL_HERMITE".into(),
            flag(self.interval == IntervalModel::Hermite),
        ));
        d.extend(crate::view::preintegration::exact_opacity_defines(
            self.exact_opacity,
            self.tf_points,
        ));
        d.push((
            "TF_SENSITIVITY_PIECES".into(),
            self.sensitivity_pieces
                .map_or("-1".into(), |n| n.to_string()),
        ));
        d.push((
            "MAX_ISO".into(),
            self.isosurfaces.min(MAX_ISOSURFACES).to_string(),
        ));
        d
    }

    /// Human-readable name, reported in `--stats` as `variant`.
    pub fn name(&self, kernel: &str) -> String {
        format!(
            "{kernel}:{}-{}-{}-{}{}",
            match (self.gaussian, self.basis) {
                _ if self.exact => "exact",
                (true, _) => "gaussian",
                (false, Basis::Constant) => "constant",
                (false, Basis::Linear) => "linear",
                (false, Basis::Quadratic) => "quadratic",
            },
            match self.weight {
                Weight::Wendland => "wendland",
                Weight::Interpolating => "interpolating",
            },
            match self.gradient {
                GradientMode::Local => "local",
                GradientMode::Analytic => "analytic",
            },
            match self.neighbours {
                NeighbourMode::Grid => "grid",
                NeighbourMode::Octree => match (self.full_metric, self.inline_records) {
                    (true, true) => "octree-ellipsoid-inline",
                    (true, false) => "octree-ellipsoid",
                    (false, true) if self.record_stride == 1 => "octree-packed",
                    (false, true) => "octree-inline",
                    (false, false) => "octree",
                },
            },
            self.method
                .map(|m| match (m, self.adaptive, self.interval) {
                    (Method::Adaptive, AdaptiveCriterion::Hermite, _) => {
                        "-adaptive-hermite".into()
                    }
                    (Method::Fixed, _, IntervalModel::Hermite) => "-fixed-hermite".into(),
                    _ => format!("-{}", m.name()),
                })
                .unwrap_or_default()
        ) + &if !self.hull {
            String::new()
        } else if self.hull_hits as usize >= crate::samples::bvh::MAX_HITS {
            "-hull".to_string()
        } else {
            format!("-hull{}", self.hull_hits)
        } + match self.hull_cache {
            _ if !self.hull => "",
            HullCache::Off => "",
            HullCache::Read => "-cached",
            HullCache::Keep => "-keep",
        } + &if self.resampled {
            format!("-resample{}", self.resample)
        } else {
            String::new()
        } + if self.paged && self.resample > 0 {
            "-paged"
        } else {
            ""
        } + if self.resample_direct { "-direct" } else { "" }
            + if self.skip { "-skip" } else { "" }
            + if self.exact_opacity {
                "-exactopacity"
            } else {
                ""
            }
            + if self.clip { "-clip" } else { "" }
            + &if self.grid == Storage::F32 {
                String::new()
            } else {
                format!("-{}", self.grid.name())
            }
            + &if self.isosurfaces > 0 {
                format!("-iso{}", self.isosurfaces)
            } else {
                String::new()
            }
    }
}

pub fn v4(v: glam::DVec3, w: f64) -> [f32; 4] {
    [v.x as f32, v.y as f32, v.z as f32, w as f32]
}

/// The field's part of the kernel constants (the lattice, supports, octree root); a renderer
/// fills in the rest.
pub fn field_params(field: &Field) -> RenderParams {
    let mut p = RenderParams::default();
    if field.grid().is_some() || field.reconstruction.resample > 0 {
        // A grid's points, or for irregular data on the fast path the fine grid's lattice
        // where a grid's would be (recon_resample and resampled_evaluate read only these).
        let l = field.lattice();
        p.field.grid_origin = v4(l.origin.into(), 0.0);
        p.field.grid_inv_spacing = [
            (1.0 / l.spacing[0]) as f32,
            (1.0 / l.spacing[1]) as f32,
            (1.0 / l.spacing[2]) as f32,
            0.0,
        ];
        p.field.grid_dims = [l.dims[0] as i32, l.dims[1] as i32, l.dims[2] as i32, 0];
    }
    if let Some(g) = field.grid() {
        let inv_h = g.inv_support();
        p.field.inv_support = [inv_h[0] as f32, inv_h[1] as f32, inv_h[2] as f32, 0.0];
        p.field.support_cells = g.support as f32;
        if field.reconstruction.method == crate::recon::ReconMethod::Gaussian {
            let h = g.spacing.map(|s| s * g.support);
            let metric = crate::samples::supports::diagonal(h);
            p.field.gauss_weight = (field.kernel_volumes().get(0)
                * crate::recon::gaussian::gaussian_norm(field.reconstruction.sigma, &metric))
                as f32;
        }
    }
    p.field.gauss_sigma = field.reconstruction.sigma as f32;
    if let Some(o) = field.octree_if_built() {
        p.field.octree_root = v4(o.root_center.into(), o.root_half);
    }
    p
}

/// The pipeline of `kernel` in `variant`, reading the `data` bindings and the constants.
pub fn pipeline_for(
    ctx: &Context,
    compiler: &ShaderCompiler,
    kernel: &str,
    variant: &Variant,
    data: &[u32],
    push: u32,
) -> Result<ComputePipeline, VkError> {
    let spirv = compiler.compile(ShaderSource::File(kernel), &variant.defines())?;
    let kinds: Vec<(u32, crate::vk::BindingKind)> = data
        .iter()
        .chain(&[binding::PARAMS])
        .map(|&b| (b, binding::kind(b)))
        .collect();
    ComputePipeline::with_kinds(ctx, &variant.name(kernel), &spirv, &kinds, push)
}

/// Workgroups covering `count` invocations of `group` each, as a 2D grid when one dimension's
/// limit (65 535) is not enough; kernels flatten the index and skip invocations past `count`.
pub fn groups_2d(count: u32, group: u32) -> [u32; 3] {
    let groups = count.div_ceil(group).max(1);
    if groups > 65535 {
        [65535, groups.div_ceil(65535), 1]
    } else {
        [groups, 1, 1]
    }
}

/// The binding a grid of `storage` values is read through: rgba32f texels of f32 samples, or
/// r32ui words of 8- and 16-bit ones.
pub fn grid_binding(storage: Storage) -> u32 {
    if storage == Storage::F32 {
        binding::GRID
    } else {
        binding::GRID_WORDS
    }
}
