//! `reconstruction.method = "exact"`: the analytic Marschner–Lobb field and gradient, on the GPU
//! (`exact_evaluate`) against its f64 twin, in images against the CPU reference integrator, and
//! refused where there is no analytic field.

mod common;

use common::*;
use vmls::data::marschner_lobb::{rho, rho_gradient};
use vmls::field::gpu::{GpuField, evaluate};
use vmls::probe::random_points;
use vmls::recon::{Basis, GradientMode, ReconMethod, Weight};
use vmls::scene::{NeighbourMode, Scene};

#[test]
fn gpu_exact_field_matches_the_analytic_function() {
    for neighbours in [NeighbourMode::Grid, NeighbourMode::Octree] {
        let mut r = recon(
            Basis::Linear,
            Weight::Wendland,
            GradientMode::Local,
            neighbours,
            2.4,
        );
        r.method = ReconMethod::Exact;
        let field = ml_field(13, r);
        let points = random_points(&field, 2000, 0.0, 5);
        let (ctx, compiler) = gpu();
        let gpu_field = GpuField::upload(&ctx, &field).expect("upload");
        let (out, _) = evaluate(&ctx, &compiler, &field, &gpu_field, &points, 1).expect("eval");
        drop(gpu_field);
        finish(ctx);
        let neighbours_cpu = field.neighbours().expect("neighbours");
        let (mut worst_v, mut worst_g) = (0.0f64, 0.0f64);
        for (g, p) in out.iter().zip(&points) {
            // The ML generator's frame is centred on its grid: frame = the function's coordinates.
            let w = (glam::DVec3::from(*p) + field.frame_origin).to_array();
            let (v, grad) = (rho(w[0], w[1], w[2]), rho_gradient(w[0], w[1], w[2]));
            let cpu = field
                .evaluate(neighbours_cpu.as_ref(), *p)
                .expect("exact is defined everywhere");
            assert_eq!(
                (cpu.value, cpu.gradient),
                (v, grad),
                "the CPU twin is the function"
            );
            assert_eq!(g.terms, 1);
            worst_v = worst_v.max((f64::from(g.value) - v).abs());
            for (gg, want) in g.gradient.iter().zip(grad) {
                worst_g = worst_g.max((f64::from(*gg) - want).abs());
            }
        }
        // f32 sin/cos of phases up to 12π: ~1e-6 in the value (range 1), ~1e-5 of the largest
        // gradient (about 7).
        assert!(worst_v < 1e-5, "{neighbours:?}: value error {worst_v:.2e}");
        assert!(
            worst_g < 1e-4,
            "{neighbours:?}: gradient error {worst_g:.2e}"
        );
    }
}

#[test]
fn exact_field_follows_a_moved_grid_on_both_twins() {
    // The same generated grid placed at 1e3: the field moves with it, on the CPU and the GPU.
    let mut r = recon(
        Basis::Linear,
        Weight::Wendland,
        GradientMode::Local,
        NeighbourMode::Grid,
        2.4,
    );
    r.method = ReconMethod::Exact;
    let mut volume = vmls::data::marschner_lobb::generate(9);
    volume.origin = volume.origin.map(|o| o + 1e3);
    let field = vmls::field::Field::new(
        volume.clone(),
        r,
        &vmls::recon::OctreeSettings::default(),
        |_| {},
    )
    .expect("field");
    // At the grid points the field is the sample values (ρ at the function's own grid).
    let points: Vec<[f64; 3]> = [[0usize, 0, 0], [3, 5, 7], [8, 8, 8]]
        .iter()
        .map(|&[i, j, k]| {
            let p = volume.position(i, j, k);
            (glam::DVec3::from(p) - field.frame_origin).to_array()
        })
        .collect();
    let (ctx, compiler) = gpu();
    let gpu_field = GpuField::upload(&ctx, &field).expect("upload");
    let (out, _) = evaluate(&ctx, &compiler, &field, &gpu_field, &points, 1).expect("eval");
    drop(gpu_field);
    finish(ctx);
    let neighbours = field.neighbours().expect("neighbours");
    for (n, ((g, p), ijk)) in out
        .iter()
        .zip(&points)
        .zip([[0, 0, 0], [3, 5, 7], [8, 8, 8]])
        .enumerate()
    {
        let sample = f64::from(volume.values.get(volume.index(ijk[0], ijk[1], ijk[2])));
        let cpu = field
            .evaluate(neighbours.as_ref(), *p)
            .expect("defined")
            .value;
        assert!(
            (cpu - sample).abs() < 1e-6,
            "point {n}: CPU {cpu} vs sample {sample}"
        );
        assert!(
            (f64::from(g.value) - sample).abs() < 1e-5,
            "point {n}: GPU {} vs {sample}",
            g.value
        );
    }
}

#[test]
fn gpu_exact_image_matches_the_cpu_reference() {
    let set = [
        "reconstruction.method=\"exact\"",
        "render.method=\"reference\"",
        "render.reference_step=0.25",
        "camera.width=20",
        "camera.height=16",
    ];
    let scene = common::general_scene(&set.map(String::from));
    let field = scene.field(|_| {}).expect("field");
    let setup = scene.ray_setup(&field).expect("setup");
    let cpu =
        vmls::raycast::raycast_image(&setup, &field, &scene.transfer, None).expect("CPU twin");
    let (ctx, _compiler) = gpu();
    let mut renderer = vmls::renderer::Renderer::new(&ctx, field).expect("renderer");
    let image = common::splat::scene_frame(&mut renderer, &scene);
    drop(renderer);
    finish(ctx);
    let worst = image
        .pixels
        .iter()
        .zip(&cpu)
        .flat_map(|(g, c)| (0..3).map(move |k| (f64::from(g[k]) - c.rgba[k]).abs()))
        .fold(0.0, f64::max);
    // Measured 1.5e-5 on lavapipe (f32 sin/cos of phases up to 12π along each ray).
    eprintln!("exact field image, GPU vs CPU: {worst:.2e}");
    assert!(worst < 5e-5, "largest pixel difference {worst:.2e}");
    assert!(image.variant.contains("exact"), "{}", image.variant);
}

#[test]
fn exact_needs_a_generated_volume_and_ray_casting() {
    let err = Scene::load(
        None,
        &[
            "volume.file=\"x.vti\"".into(),
            "reconstruction.method=\"exact\"".into(),
        ],
    )
    .expect_err("no analytic field for a file");
    let text = err.to_string();
    assert!(
        text.contains("reconstruction.method") && text.contains("x.vti"),
        "{text}"
    );
    let scene = Scene::load(
        None,
        &[
            "reconstruction.method=\"exact\"".into(),
            "render.method=\"splat\"".into(),
        ],
    )
    .expect("scene");
    let field = scene.field(|_| {}).expect("field");
    let err = scene
        .splat_setup(vmls::splat::Shading::Pre, &field)
        .expect_err("splatting has no exact field");
    assert!(err.to_string().contains("reconstruction.method"), "{err}");
}
