//! GPU driver of the ray caster and the MLS evaluator: builds the shader variant a scene needs,
//! uploads only the buffers that variant reads, and runs it.
//!
//! Variants are compile-time choices passed to shaderc as macros (DESIGN §7): basis
//! (`MLS_TERMS`), weight (`MLS_WEIGHT`), gradient (`MLS_ANALYTIC_GRADIENT`) and neighbour
//! structure (`MLS_NEIGHBOURS`). The image is rendered in bands of rows, one submission each, so
//! that a long render reports progress and no single dispatch runs for minutes (which a
//! desktop driver's watchdog would kill).

use super::preintegration::PreintegrationTables;
use super::raycast::adaptive;
pub use super::renderer::{GpuImage, default_chunk, outer_steps, render};
use super::shading::MAX_ISOSURFACES;
use super::{Field, RaySetup};
use crate::data::Storage;
use crate::gpu_types::{
    CountPush, GRID_PAD, MlsOut, RenderParams, Sample, binding, binding_defines, params_copies,
};
use crate::recon::NeighbourMode;
use crate::recon::mls::{Basis, GradientMode, Weight};
use crate::render::{AdaptiveCriterion, IntervalModel, Method};
use crate::vk::{
    BindGroup, Buffer, BufferUsage, ComputePipeline, Context, ShaderCompiler, ShaderSource, VkError,
};

/// `RenderParams::projection` of an orthographic camera (0 is perspective).
const PROJECTION_ORTHOGRAPHIC: u32 = 1;

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
    /// The ray caster's integrator (`None` for kernels that do not integrate).
    pub method: Option<Method>,
    /// Adaptive stack entries (levels of subdivision).
    pub adaptive_levels: usize,
    /// The adaptive integrator's acceptance test.
    pub adaptive: AdaptiveCriterion,
    /// How the fixed-step integrator composites an interval.
    pub interval: IntervalModel,
    /// Isosurfaces of the scene (0 compiles no isosurface code).
    pub isosurfaces: usize,
    /// Rays are clipped to a boundary hull (else to the domain's box).
    pub hull: bool,
    /// Crossings of the hull a ray may have (`HULL_MAX_HITS`): the kernel keeps them in a
    /// local array whose every dynamically indexed access costs in proportion to its length on
    /// lavapipe, so frames start with [`FIRST_HULL_HITS`] and only a frame with a ray past
    /// them is rendered again with `bvh::MAX_HITS` (the CPU twin's bound).
    pub hull_hits: u32,
    /// The Gaussian-sum field instead of MLS (`reconstruction.method = "gaussian"`).
    pub gaussian: bool,
    /// The generator's analytic field instead of a reconstruction (`"exact"`).
    pub exact: bool,
    /// The fast path's refinement factor (`reconstruction.resample`; 0: none).
    pub resample: u32,
    /// Whether the kernel evaluates the fast path (the ray caster, mls_eval) or the general one
    /// (recon_resample, which computes the fine grid from it).
    pub resampled: bool,
    /// Empty-space skipping in the ray caster ([`super::skip`]).
    pub skip: bool,
    /// How the grid's values are stored on the device (`GRID_BITS`, `GRID_SIGNED`): 8- and
    /// 16-bit samples stay at their size and the kernel converts them. F32 off the grid path.
    pub grid: Storage,
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
            hull: false,
            hull_hits: crate::samples::bvh::MAX_HITS as u32,
            gaussian: r.method == crate::recon::ReconMethod::Gaussian,
            exact: r.method == crate::recon::ReconMethod::Exact,
            resample: r.resample,
            resampled: r.resample > 0,
            skip: false,
            method: None,
            adaptive_levels: 1,
            adaptive: AdaptiveCriterion::Mls2008,
            interval: IntervalModel::Linear,
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

    /// The ray caster's variant for a field and a ray setup.
    pub fn for_render(field: &Field, setup: &RaySetup) -> Self {
        Self {
            method: Some(setup.method),
            adaptive_levels: adaptive::stack_size(setup.l_max, setup.l_min),
            adaptive: setup.adaptive,
            interval: setup.interval,
            isosurfaces: setup.isosurfaces.len(),
            hull: field.hull.is_some(),
            hull_hits: setup.hull_hits,
            skip: setup.skip,
            ..Self::of(field)
        }
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
        d.push(("GRID_SIGNED".into(), flag(self.grid.signed())));
        d.push(("MLS_GAUSSIAN".into(), flag(self.gaussian)));
        d.push(("MLS_EXACT".into(), flag(self.exact)));
        d.push((
            "MLS_RESAMPLED".into(),
            if self.resampled { self.resample } else { 0 }.to_string(),
        ));
        d.push(("RESAMPLE_FACTOR".into(), self.resample.max(1).to_string()));
        d.push(("SKIP".into(), flag(self.skip)));
        d.push(("SKIP_BLOCK".into(), super::skip::SKIP_BLOCK.to_string()));
        d.push(("SKIP_RUN".into(), super::skip::SKIP_RUN.to_string()));
        d.push(("RUN_NUDGE".into(), format!("{:e}", super::skip::RUN_NUDGE)));
        // The analytic field's constants, from the generator (one copy of each number).
        d.push((
            "ML_F_M".into(),
            format!("{:?}", crate::data::marschner_lobb::F_M),
        ));
        d.push((
            "ML_ALPHA".into(),
            format!("{:?}", crate::data::marschner_lobb::ALPHA),
        ));
        d.push(("HULL".into(), flag(self.hull)));
        d.push(("HULL_MAX_HITS".into(), self.hull_hits.to_string()));
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
                NeighbourMode::Octree if self.full_metric => "octree-ellipsoid",
                NeighbourMode::Octree => "octree",
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
        } + &if self.resampled {
            format!("-resample{}", self.resample)
        } else {
            String::new()
        } + if self.skip { "-skip" } else { "" }
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

pub(super) fn v4(v: glam::DVec3, w: f64) -> [f32; 4] {
    [v.x as f32, v.y as f32, v.z as f32, w as f32]
}

/// Kernel constants for a field (and a ray setup, when rendering).
pub fn render_params(field: &Field, setup: Option<&RaySetup>, tf_count: u32) -> RenderParams {
    let mut p = RenderParams {
        tf_count,
        ..Default::default()
    };
    if field.grid().is_some() || field.reconstruction.resample > 0 {
        // A grid's points, or for irregular data on the fast path the fine grid's lattice
        // where a grid's would be (recon_resample and resampled_evaluate read only these).
        let l = field.lattice();
        p.grid_origin = v4(l.origin.into(), 0.0);
        p.grid_inv_spacing = [
            (1.0 / l.spacing[0]) as f32,
            (1.0 / l.spacing[1]) as f32,
            (1.0 / l.spacing[2]) as f32,
            0.0,
        ];
        p.grid_dims = [l.dims[0] as i32, l.dims[1] as i32, l.dims[2] as i32, 0];
    }
    if let Some(g) = field.grid() {
        let inv_h = g.inv_support();
        p.inv_support = [inv_h[0] as f32, inv_h[1] as f32, inv_h[2] as f32, 0.0];
        p.support_cells = g.support as f32;
        if field.reconstruction.method == crate::recon::ReconMethod::Gaussian {
            let h = g.spacing.map(|s| s * g.support);
            let metric = crate::samples::supports::diagonal(h);
            p.gauss_weight = (field.kernel_volumes().get(0)
                * crate::recon::gaussian::gaussian_norm(field.reconstruction.sigma, &metric))
                as f32;
        }
    }
    p.gauss_sigma = field.reconstruction.sigma as f32;
    if let Some(o) = field.octree_if_built() {
        p.octree_root = v4(o.root_center.into(), o.root_half);
    }
    if let Some(r) = setup {
        match r.camera.projection {
            super::camera::Projection::Perspective { fov_y_degrees } => {
                p.tan_half_fov = (fov_y_degrees.to_radians() * 0.5).tan() as f32;
            }
            super::camera::Projection::Orthographic { view_height } => {
                p.projection = PROJECTION_ORTHOGRAPHIC;
                p.ortho_half_height = (0.5 * view_height) as f32;
            }
        }
        p.eye = v4(glam::DVec3::from(r.camera.eye) - r.frame_origin, 0.0);
        p.forward = v4(r.basis.forward, 0.0);
        p.right = v4(r.basis.right, 0.0);
        p.up = v4(r.basis.up, 0.0);
        p.box_min = v4(r.box_lo, 0.0);
        p.box_max = v4(r.box_hi, 0.0);
        p.background = v4(r.background.into(), 0.0);
        p.width = r.camera.width;
        p.height = r.camera.height;
        p.step = r.step as f32;
        p.min_transmittance = r.min_transmittance as f32;
        p.integrator = [
            r.epsilon as f32,
            r.early_termination as f32,
            r.spacing as f32,
            0.0,
        ];
        let l = &r.lighting;
        p.lighting = [
            l.ambient as f32,
            l.diffuse as f32,
            l.specular as f32,
            l.shininess as f32,
        ];
        p.iso_count = [r.isosurfaces.len() as u32, 0, 0, 0];
        p.preint_range[3] = r.l_min as f32;
    }
    p
}

/// Adds the tables' description to the kernel constants.
pub(super) fn table_params(p: &mut RenderParams, tables: &PreintegrationTables) {
    p.preint_range[0] = tables.s_min as f32;
    p.preint_range[1] = tables.s_max as f32;
    p.preint_range[2] = tables.lengths[0] as f32;
    p.preint_dims = [tables.resolution as u32, tables.lengths.len() as u32, 0, 0];
}

/// The fast path's device data, built from the uploaded neighbour data (all `None` without it).
struct FastPath {
    fine: Option<Buffer>,
    ms: f64,
    blocks: Option<(Buffer, super::skip::Blocks)>,
}

impl FastPath {
    /// The fine grid (`recon_resample` from `data`) and its skipping blocks.
    fn build(ctx: &Context, field: &Field, data: &[(u32, &Buffer)]) -> Result<Self, VkError> {
        let Some((fine, ms)) = super::resample::resample_grid(ctx, field, data)? else {
            return Ok(Self {
                fine: None,
                ms: 0.0,
                blocks: None,
            });
        };
        let blocks = super::resample::block_buffer(ctx, field, &fine)?;
        Ok(Self {
            fine: Some(fine),
            ms,
            blocks: Some(blocks),
        })
    }
}

/// Hull crossings a ray-cast frame first allows per ray ([`Variant::hull_hits`]): the
/// room-fire mesh at 512² took 190–220 ms a frame with 8 against 280–300 with 32.
pub const FIRST_HULL_HITS: u32 = 8;

/// The field's data on the GPU: grid values, or samples + octree.
pub struct GpuField {
    grid: Option<Buffer>,
    /// The grid's binding ([`Variant::grid_binding`]).
    grid_binding: u32,
    /// The fast path's fine grid (`reconstruction.resample`), computed on the GPU at upload.
    resampled: Option<Buffer>,
    /// GPU milliseconds recon_resample took.
    pub resample_ms: f64,
    /// The fast field's range per skipping block, `vec4(min, max, 0, 0)`, and the host's copy.
    blocks: Option<(Buffer, super::skip::Blocks)>,
    octree: Option<[Buffer; 3]>,
    hull: Option<[Buffer; 2]>,
}

impl GpuField {
    /// Uploads what the field's variant reads and nothing else.
    pub fn upload(ctx: &Context, field: &Field) -> Result<Self, VkError> {
        let mut gpu = Self::upload_hull(ctx, field)?;
        gpu.upload_data(ctx, field)?;
        Ok(gpu)
    }

    /// Whether [`GpuField::upload_data`] has run: the samples (a grid, or the samples and
    /// octree) are on the device. Ray casting reads them, splatting only the hull.
    pub fn has_data(&self) -> bool {
        self.grid.is_some() || self.octree.is_some()
    }

    /// Uploads the samples the ray caster reads (the grid and its fast path, or the samples
    /// and octree), once; the octree must have been built ([`Field::octree`]).
    pub fn upload_data(&mut self, ctx: &Context, field: &Field) -> Result<(), VkError> {
        if self.has_data() {
            return Ok(());
        }
        // Only a complete upload replaces anything: a failed one leaves the hull in place.
        let mut data = Self::upload_samples(ctx, field)?;
        data.hull = self.hull.take();
        *self = data;
        Ok(())
    }

    /// The hull's BVH alone (what splatting reads), without the samples.
    pub fn upload_hull(ctx: &Context, field: &Field) -> Result<Self, VkError> {
        let hull = match &field.hull {
            None => None,
            Some(bvh) => {
                // Integer texels: the corners as float bits (uintBitsToFloat in the kernel).
                let nodes: Vec<[u32; 4]> = bvh
                    .nodes
                    .iter()
                    .flat_map(|n| {
                        let [lx, ly, lz] = n.lo.map(|c| (c as f32).to_bits());
                        let [hx, hy, hz] = n.hi.map(|c| (c as f32).to_bits());
                        [[lx, ly, lz, n.first], [hx, hy, hz, n.count]]
                    })
                    .collect();
                let tris: Vec<[f32; 4]> = bvh
                    .triangles
                    .iter()
                    .flat_map(|t| t.map(|v| v4(v.into(), 0.0)))
                    .collect();
                Some([
                    Buffer::from_slice(ctx, "hull nodes", &nodes)?,
                    Buffer::from_slice(ctx, "hull triangles", &tris)?,
                ])
            }
        };
        Ok(Self {
            grid: None,
            grid_binding: binding::GRID,
            resampled: None,
            resample_ms: 0.0,
            blocks: None,
            octree: None,
            hull,
        })
    }

    /// Refuses a regular grid of `samples` values stored as `storage` whose buffer the device
    /// cannot hold or view, before the host builds the field (`Scene::field_on`): the same
    /// buffer and view [`GpuField::upload`] and the kernels' bind groups ask for.
    pub fn check_grid(
        info: &crate::vk::DeviceInfo,
        samples: usize,
        storage: Storage,
    ) -> Result<(), VkError> {
        let bytes = (padded_grid_len(samples) * storage.bytes()) as u64;
        crate::vk::check_size(info, "grid", bytes, BufferUsage::Texel)?;
        crate::vk::check_texel_view(info, "grid", bytes, binding::kind(grid_binding(storage)))
    }

    fn upload_samples(ctx: &Context, field: &Field) -> Result<Self, VkError> {
        let octree = field.octree_if_built();
        if field.uses_octree() && octree.is_none() {
            return Err(VkError::Usage(
                "the field's octree is not built (Field::octree builds a deferred one)".into(),
            ));
        }
        match octree {
            None => {
                // GRID_PAD zeros, the values as stored, zeros to the padded length: written
                // into the buffer part by part, without a padded host copy of the grid.
                let values = &field.samples.values;
                let size = values.storage().bytes();
                let total = padded_grid_len(values.len()) * size;
                let front = vec![0u8; GRID_PAD * size];
                let back = vec![0u8; total - front.len() - values.bytes().len()];
                let grid = Buffer::new(ctx, "grid", total as u64, BufferUsage::Texel)?;
                grid.write_parts(ctx, &[&front, values.bytes(), &back])?;
                let binding = grid_binding(values.storage());
                let fast = FastPath::build(ctx, field, &[(binding, &grid)])?;
                Ok(Self {
                    grid_binding: binding,
                    grid: Some(grid),
                    resampled: fast.fine,
                    resample_ms: fast.ms,
                    blocks: fast.blocks,
                    octree: None,
                    hull: None,
                })
            }
            Some(o) => {
                // The Gaussian field reads each sample's weight v_i·norm_i (`gaussian_weight`).
                let gaussian = field.reconstruction.method == crate::recon::ReconMethod::Gaussian;
                let volumes = gaussian.then(|| field.kernel_volumes());
                let sigma = field.reconstruction.sigma;
                let samples: Vec<Sample> = o
                    .samples
                    .iter()
                    .enumerate()
                    .map(|(i, s)| {
                        let m = s.metric.map(|v| v as f32);
                        let w = volumes.map_or(0.0, |v| {
                            v.get(i) * crate::recon::gaussian::gaussian_norm(sigma, &s.metric)
                        });
                        Sample {
                            pos_value: v4(s.position.into(), s.value),
                            metric: [m[0], m[1], m[2], m[3]],
                            metric_off: [m[4], m[5], w as f32, 0.0],
                        }
                    })
                    .collect();
                // Kernels read all three through texel views (neighbours.glsl): bounded by
                // maxTexelBufferElements, not by one storage binding's range.
                let texel = BufferUsage::Texel;
                let octree = [
                    Buffer::from_slice_as(ctx, "octree samples", &samples, texel)?,
                    Buffer::from_slice_as(ctx, "octree nodes", &o.nodes, texel)?,
                    Buffer::from_slice_as(ctx, "octree reference codes", &o.codes, texel)?,
                ];
                // The fast path's fine grid over the lattice, through the octree.
                let [s, n, i] = &octree;
                let fast = FastPath::build(
                    ctx,
                    field,
                    &[
                        (binding::SAMPLES, s),
                        (binding::NODES, n),
                        (binding::INDICES, i),
                    ],
                )?;
                Ok(Self {
                    grid_binding: binding::GRID,
                    grid: None,
                    resampled: fast.fine,
                    resample_ms: fast.ms,
                    blocks: fast.blocks,
                    octree: Some(octree),
                    hull: None,
                })
            }
        }
    }

    /// (binding, buffer) pairs of the neighbour data.
    pub(super) fn bindings(&self) -> Vec<(u32, &Buffer)> {
        let mut b = Vec::new();
        if let Some(g) = &self.grid {
            b.push((self.grid_binding, g));
        }
        if let Some(r) = &self.resampled {
            b.push((binding::RESAMPLED, r));
        }
        if let Some([s, n, i]) = &self.octree {
            b.push((binding::SAMPLES, s));
            b.push((binding::NODES, n));
            b.push((binding::INDICES, i));
        }
        b
    }

    /// The skipping blocks with their binding (none without the fast path).
    pub(super) fn skip_bindings(&self) -> Vec<(u32, &Buffer)> {
        self.blocks
            .iter()
            .map(|(b, _)| (binding::SKIP_BLOCKS, b))
            .collect()
    }

    /// The host's copy of the skipping blocks (none without the fast path).
    pub fn blocks(&self) -> Option<&super::skip::Blocks> {
        self.blocks.as_ref().map(|(_, b)| b)
    }

    /// The hull's BVH buffers with their bindings (none for a box domain).
    pub fn hull_bindings(&self) -> Vec<(u32, &Buffer)> {
        match &self.hull {
            Some([n, t]) => vec![(binding::HULL_NODES, n), (binding::HULL_TRIS, t)],
            None => Vec::new(),
        }
    }
}

pub(super) fn pipeline_for(
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

/// Evaluates the field at `points` (frame-relative) with `mls_eval.comp`. Returns the results
/// and the GPU milliseconds of each of `repeats` dispatches (for throughput measurement).
pub fn evaluate(
    ctx: &Context,
    compiler: &ShaderCompiler,
    field: &Field,
    gpu_field: &GpuField,
    points: &[[f64; 3]],
    repeats: u32,
) -> Result<(Vec<MlsOut>, Vec<f64>), VkError> {
    let variant = Variant::of(field);
    let data = gpu_field.bindings();
    let mut binding_ids: Vec<u32> = data.iter().map(|(b, _)| *b).collect();
    binding_ids.extend([binding::POINTS, binding::RESULTS]);
    let pipeline = pipeline_for(
        ctx,
        compiler,
        "mls_eval.comp",
        &variant,
        &binding_ids,
        std::mem::size_of::<CountPush>() as u32,
    )?;
    let n = points.len();
    let gpu_points: Vec<[f32; 4]> = points
        .iter()
        .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32, 0.0])
        .collect();
    let params_buf = Buffer::from_slice(
        ctx,
        "mls params",
        &params_copies(render_params(field, None, 0)),
    )?;
    let points_buf = Buffer::from_slice(ctx, "mls points", &gpu_points)?;
    let results = Buffer::new(
        ctx,
        "mls results",
        (n as u64) * std::mem::size_of::<MlsOut>() as u64,
        BufferUsage::Storage,
    )?;
    let mut all = data;
    all.extend([
        (binding::PARAMS, &params_buf),
        (binding::POINTS, &points_buf),
        (binding::RESULTS, &results),
    ]);
    let group = BindGroup::new(ctx, &pipeline, &all)?;
    let push = CountPush {
        count: u32::try_from(n).map_err(|_| VkError::Usage(format!("{n} points")))?,
        iterations: 0,
        _pad: [0; 2],
    };
    let [gx, gy, _] = groups_2d(n as u32, 64);
    let mut times = Vec::new();
    for _ in 0..repeats.max(1) {
        let t = ctx.submit(|rec| {
            rec.dispatch(
                &pipeline,
                &group,
                bytemuck::bytes_of(&push),
                [gx, gy, 1],
                "mls_eval",
            )
        })?;
        times.extend(t.iter().filter_map(|t| t.gpu_ms));
    }
    let mut out: Vec<MlsOut> = results.read(ctx)?;
    out.truncate(n);
    Ok((out, times))
}

/// Workgroups covering `count` invocations of `group` each, as a 2D grid when one dimension's
/// limit (65 535) is not enough; kernels flatten the index and skip invocations past `count`.
pub(super) fn groups_2d(count: u32, group: u32) -> [u32; 3] {
    let groups = count.div_ceil(group).max(1);
    if groups > 65535 {
        [65535, groups.div_ceil(65535), 1]
    } else {
        [groups, 1, 1]
    }
}

/// The binding a grid of `storage` values is read through: rgba32f texels of f32 samples, or
/// r32ui words of 8- and 16-bit ones.
fn grid_binding(storage: Storage) -> u32 {
    if storage == Storage::F32 {
        binding::GRID
    } else {
        binding::GRID_WORDS
    }
}

/// Values in the grid buffer: padded front and back (GRID_PAD) and to a whole number of 4-value
/// units (a vec4 of f32 samples; r32ui words hold 2 or 4 smaller ones).
fn padded_grid_len(samples: usize) -> usize {
    (samples + 3 * GRID_PAD).next_multiple_of(4)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Lavapipe's limits (LAVAPIPE.md): 128 MiB storage bindings, 128 M texels per view.
    fn lavapipe() -> crate::vk::DeviceInfo {
        crate::vk::DeviceInfo {
            name: "llvmpipe".into(),
            device_type: "cpu".into(),
            driver: "test".into(),
            api_version: "1.3".into(),
            max_storage_buffer_range: 1 << 27,
            max_uniform_buffer_range: 1 << 16,
            max_texel_buffer_elements: 1 << 27,
            max_workgroup_count: [65535; 3],
            max_heap_bytes: 1 << 31,
            timestamp_period_ns: Some(1.0),
            subgroup_size: 8,
            subgroup_ops: true,
            storage_texel_formats: crate::vk::TEXEL_FORMATS.to_vec(),
            vendor_id: 0x10005,
            device_id: 0,
            pipeline_cache_uuid: [0; 16],
        }
    }

    #[test]
    fn a_texel_format_the_device_lacks_is_refused_naming_the_buffer() {
        let mut info = lavapipe();
        let list = binding::kind(binding::SPLAT_LIST);
        crate::vk::check_texel_view(&info, "splat entries", 1 << 20, list).expect("rg32ui");
        info.storage_texel_formats
            .retain(|&f| f != ash::vk::Format::R32G32_UINT);
        let err = crate::vk::check_texel_view(&info, "splat entries", 1 << 20, list)
            .expect_err("no rg32ui");
        let text = err.to_string();
        assert!(
            text.contains("splat entries") && text.contains("R32G32_UINT"),
            "{text}"
        );
    }

    #[test]
    fn grids_are_bounded_by_their_texel_view_not_a_storage_binding() {
        let info = lavapipe();
        let n = |side: usize| side * side * side;
        // 512³ float (512 MiB) and 16-bit (256 MiB): past one storage binding, inside a view.
        GpuField::check_grid(&info, n(512), Storage::F32).expect("512³ float fits a view");
        GpuField::check_grid(&info, n(512), Storage::U16).expect("512³ 16-bit fits a view");
        // 1024³ 8-bit: 1 GiB of r32ui words is 256 M texels, past the 128 M a view may span.
        let err = GpuField::check_grid(&info, n(1024), Storage::U8).expect_err("1024³ u8");
        let text = err.to_string();
        assert!(
            text.contains("'grid'") && text.contains("maxTexelBufferElements"),
            "{text}"
        );
        assert!(
            text.contains(&(padded_grid_len(n(1024)) as u64).to_string()),
            "{text}"
        );
        // 1024³ float: 4 GiB, more than the heap.
        let err = GpuField::check_grid(&info, n(1024), Storage::F32).expect_err("1024³ f32");
        assert!(err.to_string().contains("heap"), "{err}");
    }
}
