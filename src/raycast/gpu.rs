//! The ray caster's side of the GPU driver: its kernel variant and constants. The field's side
//! (the variant's reconstruction choices, uploads, `pipeline_for`) is [`crate::field::gpu`].

use super::adaptive;
use super::preintegration::PreintegrationTables;
use super::setup::RaySetup;
use crate::field::Field;
use crate::field::variant::{Variant, field_params, v4};
use crate::gpu_types::RenderParams;
use crate::view::camera::Projection;

/// `RenderParams::projection` of an orthographic camera (0 is perspective).
const PROJECTION_ORTHOGRAPHIC: u32 = 1;

/// The ray caster's variant for a field and a ray setup.
pub fn variant_for_render(field: &Field, setup: &RaySetup) -> Variant {
    Variant {
        method: Some(setup.method),
        adaptive_levels: adaptive::stack_size(setup.l_max_world, setup.l_min_world),
        adaptive: setup.adaptive,
        interval: setup.interval,
        isosurfaces: setup.isosurfaces.len(),
        hull: field.hull.is_some(),
        hull_hits: setup.hull_hits,
        skip: setup.skip,
        ..Variant::of(field)
    }
}

/// Kernel constants for a field and a ray setup.
pub fn render_params(field: &Field, setup: &RaySetup, tf_count: u32) -> RenderParams {
    let mut p = RenderParams {
        tf_count,
        ..field_params(field)
    };
    let r = setup;
    match r.camera.projection {
        Projection::Perspective { fov_y_degrees } => {
            p.tan_half_fov = (fov_y_degrees.to_radians() * 0.5).tan() as f32;
        }
        Projection::Orthographic { view_height } => {
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
    p.step = r.step_world as f32;
    p.min_transmittance = r.min_transmittance as f32;
    p.integrator = [
        r.epsilon as f32,
        r.early_termination as f32,
        r.spacing_world as f32,
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
    p.preint_range[3] = r.l_min_world as f32;
    p
}

/// Adds the tables' description to the kernel constants.
pub fn table_params(p: &mut RenderParams, tables: &PreintegrationTables) {
    p.preint_range[0] = tables.s_min as f32;
    p.preint_range[1] = tables.s_max as f32;
    p.preint_range[2] = tables.lengths[0] as f32;
    p.preint_dims = [tables.resolution as u32, tables.lengths.len() as u32, 0, 0];
}
