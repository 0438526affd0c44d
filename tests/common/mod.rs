//! Shared test helpers: every GPU test runs with the Khronos validation layer on and fails on
//! any validation error or leaked allocation.
#![allow(dead_code)]

use vmls::data::{Volume, marschner_lobb};
use vmls::recon::{Basis, GradientMode, OctreeSettings, Weight};
use vmls::render::Field;
use vmls::scene::{NeighbourMode, Reconstruction};
use vmls::vk::{Context, ContextOptions, ShaderCompiler};

/// A validated context on the default device (lavapipe in CI) and a shader compiler.
pub fn gpu() -> (Context, ShaderCompiler) {
    gpu_with(false)
}

/// As [`gpu`], optionally forcing the staging upload/readback path of discrete GPUs.
pub fn gpu_with(force_staging: bool) -> (Context, ShaderCompiler) {
    let ctx = Context::new(&ContextOptions {
        validation: Some(true),
        device: None,
        force_staging,
    })
    .unwrap_or_else(|e| panic!("no Vulkan device for the tests (run tools/setup): {e}"));
    (ctx, ShaderCompiler::new().expect("shaderc"))
}

/// Asserts the context saw no validation error and holds no allocation.
pub fn finish(ctx: Context) {
    assert_eq!(ctx.validation_errors(), 0, "Vulkan validation errors");
    assert_eq!(ctx.live_allocations(), 0, "GPU allocations leaked");
}

pub fn recon(
    basis: Basis,
    weight: Weight,
    gradient: GradientMode,
    neighbours: NeighbourMode,
    support: f64,
) -> Reconstruction {
    Reconstruction {
        basis,
        weight,
        gradient,
        support,
        neighbours,
    }
}

/// Marschner–Lobb field of resolution n.
pub fn ml_field(n: usize, r: Reconstruction) -> Field {
    Field::new(
        marschner_lobb::generate(n),
        r,
        &OctreeSettings::default(),
        |_| {},
    )
    .expect("field")
}

/// A grid sampling `f` at its points.
pub fn volume_from(
    dims: [usize; 3],
    spacing: [f64; 3],
    origin: [f64; 3],
    f: impl Fn([f64; 3]) -> f64,
) -> Volume {
    let mut values = Vec::new();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = [
                    origin[0] + i as f64 * spacing[0],
                    origin[1] + j as f64 * spacing[1],
                    origin[2] + k as f64 * spacing[2],
                ];
                values.push(f(p) as f32);
            }
        }
    }
    Volume {
        dims,
        origin,
        spacing,
        values,
    }
}
