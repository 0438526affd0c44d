//! The ray caster's side of the GPU driver: its kernel variant and constants. The field's side
//! (the variant's reconstruction choices, uploads, `pipeline_for`) is [`crate::field::gpu`].

use super::adaptive;
use super::setup::RaySetup;
use crate::field::Field;
use crate::field::variant::{Variant, field_params, v4};
use crate::gpu_types::{IntegratorBlock, RenderParams, SENSITIVITY_PIECES};
use crate::view::preintegration::PreintegrationTables;
use crate::view::transfer::TransferFunction;
use crate::view::{AdaptiveCriterion, Method};

/// The ray caster's variant for a field and a ray setup.
pub fn variant_for_render(field: &Field, setup: &RaySetup) -> Variant {
    let exact_opacity = setup.exact_opacity && setup.method.preintegrated();
    Variant {
        method: Some(setup.method),
        adaptive_levels: adaptive::stack_size(setup.l_max_world, setup.l_min_world),
        adaptive: setup.adaptive,
        interval: setup.interval,
        isosurfaces: setup.isosurfaces.len(),
        hull: field.hull.is_some(),
        hull_hits: setup.hull_hits,
        hull_cache: setup.hull_cache,
        skip: setup.skip,
        exact_opacity,
        tf_points: crate::view::preintegration::unrolled_tf_points(exact_opacity, setup.tf_points),
        sensitivity_pieces: (setup.method == Method::Adaptive
            && setup.adaptive == AdaptiveCriterion::Hermite
            && setup.sensitivity_pieces as usize <= SENSITIVITY_PIECES)
            .then_some(setup.sensitivity_pieces),
        clip: setup.clip.is_some(),
        ..Variant::of(field)
    }
}

/// Kernel constants for a field and a ray setup.
pub fn render_params(field: &Field, setup: &RaySetup, tf_count: u32) -> RenderParams {
    let r = setup;
    let l = &r.lighting;
    RenderParams {
        camera: r
            .camera
            .gpu_block(&r.basis, glam::DVec3::from(r.camera.eye) - r.frame_origin),
        integrator: IntegratorBlock {
            box_min: v4(r.box_lo, 0.0),
            box_max: v4(r.box_hi, 0.0),
            background: v4(r.background.into(), 0.0),
            step_world: r.step_world as f32,
            min_transmittance: r.min_transmittance as f32,
            epsilon: r.epsilon as f32,
            early_termination: r.early_termination as f32,
            spacing_world: r.spacing_world as f32,
            l_min_world: r.l_min_world as f32,
            tf_count,
            iso_count: r.isosurfaces.len() as u32,
            clip_min: v4(r.clip.map_or(r.box_lo, |c| c.0), 0.0),
            clip_max: v4(r.clip.map_or(r.box_hi, |c| c.1), 0.0),
        },
        lighting: [
            l.ambient as f32,
            l.diffuse as f32,
            l.specular as f32,
            l.shininess as f32,
        ],
        ..field_params(field)
    }
}

/// Adds the tables' description to the kernel constants, with the peak of the transfer
/// function they were built from and its blocks for the unrolled scans.
pub fn table_params(p: &mut RenderParams, tables: &PreintegrationTables, tf: &TransferFunction) {
    p.tables = tables.gpu_block(tf);
    p.tf = tf.gpu_block();
    p.sensitivity = tf.gpu_sensitivity();
}
