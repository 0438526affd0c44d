//! The field's GPU form: the buffers a field's kernel variant reads, uploaded once
//! ([`GpuField`]), and the `mls_eval` driver that evaluates the field at points. The variant
//! itself and the field's kernel constants are [`super::variant`].

use super::Field;
use super::records;
use super::variant::{Variant, field_params, grid_binding, groups_2d, pipeline_for, v4};
use crate::data::Storage;
use crate::gpu_types::{CountPush, GRID_PAD, MlsOut, Sample, binding, params_copies};
use crate::vk::{BindGroup, Buffer, BufferUsage, Context, ShaderCompiler, VkError};

/// The fast path's device data, built from the uploaded neighbour data (all `None` without it).
struct FastPath {
    fine: Option<super::resample::FineGrid>,
    blocks: Option<(Buffer, super::skip::Blocks)>,
}

impl FastPath {
    /// The fine grid (`recon_resample` from `data`) and its skipping blocks.
    fn build(ctx: &Context, field: &Field, data: &[(u32, &Buffer)]) -> Result<Self, VkError> {
        let Some(fine) = super::resample::resample_grid(ctx, field, data)? else {
            return Ok(Self {
                fine: None,
                blocks: None,
            });
        };
        let blocks = super::resample::block_buffer(ctx, field, &fine.points)?;
        Ok(Self {
            fine: Some(fine),
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
    /// The fast path's fine grid (`reconstruction.resample`), computed on the GPU at upload,
    /// with its page table where it is paged.
    resampled: Option<super::resample::FineGrid>,
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

    /// Whether the field's mesh hull is on the device (rays are clipped to it).
    pub fn has_hull(&self) -> bool {
        self.hull.is_some()
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
                let octree = if field.octree_inline() {
                    let stride = field.record_stride();
                    let texels = records::record_texel_count(o, stride);
                    let limit = ctx.info().max_texel_buffer_elements;
                    if texels > limit {
                        return Err(VkError::Usage(format!(
                            "octree.records = \"inline\" needs {texels} texels for {} \
                             references, more than the device's maxTexelBufferElements \
                             ({limit}): set octree.records = \"coded\" or \"auto\"",
                            o.references
                        )));
                    }
                    // Written in place (no host copy beside the buffer: 366 MB on 250 000
                    // scattered points).
                    let bytes = texels * records::TEXEL_BYTES;
                    let records = Buffer::new(ctx, "octree records", bytes, texel)?;
                    let nodes = records
                        .fill(ctx, texels as usize, |out| {
                            records::InlineLeaves::write(o, &samples, stride, gaussian, out)
                        })?
                        .ok_or_else(|| {
                            VkError::Usage(format!(
                                "octree records: {texels} texels counted, a different number \
                                 written"
                            ))
                        })?;
                    [
                        records,
                        Buffer::from_slice_as(ctx, "octree nodes", &nodes, texel)?,
                        // Unread by the inline variant; bound because the layout names it.
                        Buffer::from_slice_as(ctx, "octree reference codes", &[0u32], texel)?,
                    ]
                } else {
                    [
                        Buffer::from_slice_as(ctx, "octree samples", &samples, texel)?,
                        Buffer::from_slice_as(ctx, "octree nodes", &o.nodes, texel)?,
                        Buffer::from_slice_as(ctx, "octree reference codes", &o.codes, texel)?,
                    ]
                };
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
                    blocks: fast.blocks,
                    octree: Some(octree),
                    hull: None,
                })
            }
        }
    }

    /// GPU milliseconds recon_resample took (0 without the fast path).
    pub fn resample_ms(&self) -> f64 {
        self.resampled.as_ref().map_or(0.0, |f| f.ms)
    }

    /// (binding, buffer) pairs of the neighbour data.
    pub fn bindings(&self) -> Vec<(u32, &Buffer)> {
        let mut b = Vec::new();
        if let Some(g) = &self.grid {
            b.push((self.grid_binding, g));
        }
        if let Some(r) = &self.resampled {
            b.push((binding::RESAMPLED, &r.points));
            if let Some(p) = &r.pages {
                b.push((binding::RESAMPLE_PAGES, p));
            }
        }
        if let Some([s, n, i]) = &self.octree {
            b.push((binding::SAMPLES, s));
            b.push((binding::NODES, n));
            b.push((binding::INDICES, i));
        }
        b
    }

    /// The skipping blocks with their binding (none without the fast path).
    pub fn skip_bindings(&self) -> Vec<(u32, &Buffer)> {
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
        "field/mls_eval.comp",
        &variant,
        &binding_ids,
        std::mem::size_of::<CountPush>() as u32,
    )?;
    let n = points.len();
    let gpu_points: Vec<[f32; 4]> = points
        .iter()
        .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32, 0.0])
        .collect();
    let params_buf = Buffer::from_slice(ctx, "mls params", &params_copies(field_params(field)))?;
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
