//! GPU driver of stage `recon_resample` (`glsl/field/recon_resample.comp`; CPU twin
//! [`crate::recon::resample::ResampledGrid::build`]): computes the fast path's fine grid over the
//! field's lattice ([`Field::lattice`]) from the uploaded samples (a grid, or the samples and
//! octree) once per dataset, when the persistent renderer uploads the field.

use super::Field;
use super::variant::{Variant, field_params, groups_2d, pipeline_for};
use crate::gpu_types::{CountPush, binding};
use crate::recon::resample;
use crate::vk::{BindGroup, Buffer, BufferUsage, Context, ShaderCompiler, VkError};

/// Invocations per workgroup of recon_resample.comp.
const GROUP: u32 = 64;

/// The fast path's fine grid on the device: its points (`vec4(f, ∇f)` each, dense or the
/// pool's slots), a paged grid's page table, and the GPU milliseconds `recon_resample` took.
pub struct FineGrid {
    pub points: Buffer,
    pub pages: Option<Buffer>,
    pub ms: f64,
}

/// The fine grid of a field with `reconstruction.resample` > 0, computed on the GPU from the
/// uploaded neighbour data (`data`: the grid's binding, or the octree's three); `None`
/// without the fast path. A paged grid ([`Field::fine_pages`]) solves only its solved slots'
/// points and fills the shared ones.
pub fn resample_grid(
    ctx: &Context,
    field: &Field,
    data: &[(u32, &Buffer)],
) -> Result<Option<FineGrid>, VkError> {
    let factor = field.reconstruction.resample;
    if factor == 0 {
        return Ok(None);
    }
    let points = field.stored_fine_points();
    let count = u32::try_from(points)
        .map_err(|_| VkError::Usage(format!("{points} fine points exceed 2^32")))?;
    let pages = field.fine_pages();
    let compiler = ShaderCompiler::new()?;
    // The general path, with the field's own derivative at every fine point (the fast path's
    // interpolation needs ∇f, not the local fit's slope).
    let variant = Variant {
        resampled: false,
        gradient: crate::recon::GradientMode::Analytic,
        ..Variant::of(field)
    };
    let slots = pages
        .map(|p| Buffer::from_slice(ctx, "resample slots", &p.gpu_slots()))
        .transpose()?;
    let ids: Vec<u32> = data
        .iter()
        .map(|(b, _)| *b)
        .chain([binding::RESAMPLE_TARGET])
        .chain(slots.as_ref().map(|_| binding::RESAMPLE_SLOTS))
        .collect();
    let pipeline = pipeline_for(
        ctx,
        &compiler,
        "field/recon_resample.comp",
        &variant,
        &ids,
        std::mem::size_of::<CountPush>() as u32,
    )?;
    let params = Buffer::from_slice(
        ctx,
        "resample params",
        &crate::gpu_types::params_copies(field_params(field)),
    )?;
    let fine = Buffer::new(ctx, "resampled grid", points * 16, BufferUsage::Texel)?;
    let mut all = data.to_vec();
    all.extend([
        (binding::RESAMPLE_TARGET, &fine),
        (binding::PARAMS, &params),
    ]);
    if let Some(s) = &slots {
        all.push((binding::RESAMPLE_SLOTS, s));
    }
    let group = BindGroup::new(ctx, &pipeline, &all)?;
    // One dispatch covers every point (2D when the groups exceed a dimension's limit): one
    // evaluation per invocation, at most 2^27 of them (resample::MAX_POINTS).
    let [gx, gy, _] = groups_2d(count, GROUP);
    let push = CountPush {
        count,
        iterations: 0,
        _pad: [0; 2],
    };
    let times = ctx.submit(|rec| {
        rec.dispatch(
            &pipeline,
            &group,
            bytemuck::bytes_of(&push),
            [gx, gy, 1],
            "recon_resample",
        )
    })?;
    let ms = times.iter().filter_map(|t| t.gpu_ms).sum();
    drop(group);
    let table = pages
        .map(|p| Buffer::from_slice_as(ctx, "resample pages", &p.table, BufferUsage::Texel))
        .transpose()?;
    Ok(Some(FineGrid {
        points: fine,
        pages: table,
        ms,
    }))
}

/// The skipping blocks of the GPU's fine grid ([`crate::field::skip::Blocks`]), as
/// `vec4(min, max, 0, 0)` per block, and the host's copy (what `render.skip = "auto"` decides
/// by): the fine grid is read in place (through staging where it is not host-visible) and reduced
/// on the host by the same function as the CPU twin's.
pub fn block_buffer(
    ctx: &Context,
    field: &Field,
    fine: &Buffer,
) -> Result<(Buffer, crate::field::skip::Blocks), VkError> {
    let g = field.lattice();
    let factor = field.reconstruction.resample;
    let dims = resample::fine_dims(g.dims, factor);
    let h = g.spacing.map(|s| s / f64::from(factor));
    let (blocks, ranges) = fine.view(ctx, |data: &[[f32; 4]]| {
        resample::block_ranges(
            dims,
            factor as usize * crate::field::skip::SKIP_BLOCK,
            field.fine_pages(),
            |at| resample::point_bounds(data[at].map(f64::from), h),
        )
    })?;
    // Rounded outwards to f32, so that the kernel's ranges contain the f64 ones.
    let texels: Vec<[f32; 4]> = ranges
        .iter()
        .map(|r| {
            [
                next_down(r[0] as f32, r[0]),
                next_up(r[1] as f32, r[1]),
                0.0,
                0.0,
            ]
        })
        .collect();
    let buffer = Buffer::from_slice(ctx, "skipping blocks", &texels)?;
    Ok((
        buffer,
        crate::field::skip::Blocks::over(g.origin, g.spacing, blocks, ranges),
    ))
}

/// The largest f32 not above v (given v rounded to nearest as `x`).
fn next_down(x: f32, v: f64) -> f32 {
    if f64::from(x) > v { x.next_down() } else { x }
}

/// The smallest f32 not below v (given v rounded to nearest as `x`).
fn next_up(x: f32, v: f64) -> f32 {
    if f64::from(x) < v { x.next_up() } else { x }
}
