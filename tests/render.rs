//! Ray casting: analytic integrals, GPU image against the f64 CPU reference, and properties
//! that must hold whatever the device (staging path, translation invariance).
mod common;

use common::*;
use vmls::render::gpu::{GpuField, GpuImage, render};
use vmls::render::raycast::{PixelResult, raycast_image};
use vmls::render::{Field, RaySetup, load_volume};
use vmls::scene::Scene;
use vmls::vk::Context;

fn scene(overrides: &[&str]) -> Scene {
    let o: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    Scene::load(None, &o).expect("scene")
}

fn field(scene: &Scene) -> Field {
    Field::new(
        load_volume(scene).expect("volume"),
        scene.reconstruction,
        &scene.octree,
        |_| {},
    )
    .expect("field")
}

fn gpu_render(
    ctx: &Context,
    compiler: &vmls::vk::ShaderCompiler,
    scene: &Scene,
    field: &Field,
) -> GpuImage {
    let setup = RaySetup::new(scene, field).expect("setup");
    let gf = GpuField::upload(ctx, field).expect("upload");
    render(ctx, compiler, field, &gf, &scene.transfer, &setup, |_| {}).expect("render")
}

fn cpu_render(scene: &Scene, field: &Field) -> Vec<PixelResult> {
    raycast_image(
        &RaySetup::new(scene, field).expect("setup"),
        field,
        &scene.transfer,
    )
}

fn max_difference(gpu: &GpuImage, cpu: &[PixelResult]) -> f64 {
    gpu.pixels
        .iter()
        .zip(cpu)
        .flat_map(|(g, c)| (0..4).map(move |k| (f64::from(g[k]) - c.rgba[k]).abs()))
        .fold(0.0, f64::max)
}

const SMALL: &[&str] = &[
    "volume.resolution=17",
    "camera.width=24",
    "camera.height=20",
    "render.step=0.5",
];

#[test]
fn constant_field_matches_the_analytic_integral() {
    // f ≡ 0.5 everywhere (a tilted plane has f = 0.5 on no grid point, so use a flat TF instead):
    // the transfer function is constant, τ = 1.7, colour (1, 0.5, 0.25). Orthographic rays along
    // +x cross the whole box, L = 2: α = 1 − exp(−τL), C = c·α, whatever the field values.
    let s = scene(&[
        "volume.resolution=9",
        "transfer.points=[[0.0, 1.0, 0.5, 0.25, 1.7], [1.0, 1.0, 0.5, 0.25, 1.7]]",
        "camera.projection=\"orthographic\"",
        "camera.view_height=1.5",
        "camera.eye=[-4.0, 0.0, 0.0]",
        "camera.target=[0.0, 0.0, 0.0]",
        "camera.width=8",
        "camera.height=8",
        "render.step=0.3",
        "render.background=[0.2, 0.2, 0.2]",
    ]);
    let f = field(&s);
    let alpha = 1.0 - (-1.7f64 * 2.0).exp();
    let expect = [
        alpha + 0.2 * (1.0 - alpha),
        0.5 * alpha + 0.2 * (1.0 - alpha),
        0.25 * alpha + 0.2 * (1.0 - alpha),
        alpha,
    ];
    let (ctx, compiler) = gpu();
    let g = gpu_render(&ctx, &compiler, &s, &f);
    finish(ctx);
    let c = cpu_render(&s, &f);
    for (gp, cp) in g.pixels.iter().zip(&c) {
        for k in 0..4 {
            assert!(
                (cp.rgba[k] - expect[k]).abs() < 1e-12,
                "CPU {:?} vs {expect:?}",
                cp.rgba
            );
            assert!(
                (f64::from(gp[k]) - expect[k]).abs() < 2e-6,
                "GPU {gp:?} vs {expect:?}"
            );
        }
    }
    // 2 / (0.3 · 0.25 spacing) = 26.67 → 27 steps per ray.
    assert!(
        g.counts.iter().all(|&n| n == 27),
        "steps per ray: {:?}",
        &g.counts[..8]
    );
}

#[test]
fn gpu_image_matches_cpu_reference() {
    for extra in [
        vec![],
        vec!["reconstruction.neighbours=\"octree\""],
        vec![
            "reconstruction.basis=\"constant\"",
            "reconstruction.support=1.6",
        ],
        vec![
            "camera.projection=\"orthographic\"",
            "camera.view_height=3.0",
        ],
        // Eye inside the volume: rays start at t = 0.
        vec![
            "camera.eye=[0.1, 0.2, 0.3]",
            "camera.target=[1.0, 0.5, 0.0]",
        ],
    ] {
        let mut o = SMALL.to_vec();
        o.extend(extra.iter().copied());
        let s = scene(&o);
        let f = field(&s);
        let (ctx, compiler) = gpu();
        let g = gpu_render(&ctx, &compiler, &s, &f);
        finish(ctx);
        let c = cpu_render(&s, &f);
        let diff = max_difference(&g, &c);
        // f32 vs f64 through ~100 compositing steps of a dense transfer function.
        assert!(diff < 2e-4, "{extra:?}: max pixel difference {diff:.2e}");
        let count_mismatch = g
            .counts
            .iter()
            .zip(&c)
            .filter(|(a, b)| **a != b.evaluations)
            .count();
        assert!(
            count_mismatch <= g.counts.len() / 50,
            "{extra:?}: {count_mismatch} rays took a different number of steps"
        );
        assert!(
            g.pixels.iter().any(|p| p[3] > 0.5),
            "{extra:?}: image is empty"
        );
    }
}

#[test]
fn staging_path_gives_the_same_image() {
    let s = scene(SMALL);
    let f = field(&s);
    let (ctx, compiler) = gpu_with(false);
    let direct = gpu_render(&ctx, &compiler, &s, &f);
    finish(ctx);
    let (ctx, compiler) = gpu_with(true);
    let staged = gpu_render(&ctx, &compiler, &s, &f);
    finish(ctx);
    assert_eq!(direct.pixels, staged.pixels);
    assert_eq!(direct.counts, staged.counts);
}

#[test]
fn far_from_origin_data_renders_the_same_image() {
    let near = scene(SMALL);
    let shifted_eye = "camera.eye=[10003.6, 10002.4, 10002.9]";
    let shifted_target = "camera.target=[10000.0, 10000.0, 10000.0]";
    let mut o = SMALL.to_vec();
    o.extend([shifted_eye, shifted_target]);
    let far = scene(&o);
    let f_near = field(&near);
    let mut volume = load_volume(&far).expect("volume");
    for x in volume.origin.iter_mut() {
        *x += 1.0e4;
    }
    let f_far = Field::new(volume, far.reconstruction, &far.octree, |_| {}).expect("field");
    let (ctx, compiler) = gpu();
    let a = gpu_render(&ctx, &compiler, &near, &f_near);
    let b = gpu_render(&ctx, &compiler, &far, &f_far);
    finish(ctx);
    let diff = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .flat_map(|(p, q)| (0..4).map(move |k| (p[k] - q[k]).abs()))
        .fold(0.0f32, f32::max);
    // Only the f64 frame subtraction differs; f32 world coordinates would lose ~1e-3 units.
    assert!(
        diff < 1e-4,
        "translated by 1e4: max pixel difference {diff:.2e}"
    );
}

#[test]
fn midpoint_rule_converges_to_the_reference() {
    let mut errors = Vec::new();
    for step in ["render.step=1.0", "render.step=0.5", "render.step=0.25"] {
        let mut o = SMALL.to_vec();
        o.push(step);
        let s = scene(&o);
        let f = field(&s);
        let c = cpu_render(&s, &f);
        let mut r = o.clone();
        r.extend([
            "render.method=\"reference\"",
            "render.reference_step=0.03125",
        ]);
        let rs = scene(&r);
        let reference = cpu_render(&rs, &f);
        let rmse = (c
            .iter()
            .zip(&reference)
            .flat_map(|(a, b)| (0..3).map(move |k| (a.rgba[k] - b.rgba[k]).powi(2)))
            .sum::<f64>()
            / (3 * c.len()) as f64)
            .sqrt();
        errors.push(rmse);
    }
    assert!(
        errors[0] > errors[1] && errors[1] > errors[2],
        "RMSE against the reference does not fall with the step: {errors:?}"
    );
}
