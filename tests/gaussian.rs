//! The Gaussian-sum field (`reconstruction.method = "gaussian"`, the field splatting
//! integrates): the GPU evaluation against the f64 CPU twin on a grid and on scattered points,
//! a constant grid field reproduced within the Poisson-summation ripple, and GPU ray casting of
//! the field against the CPU reference integrator.
mod common;

use common::*;
use vmls::data::dataset::Geometry;
use vmls::field::Field;
use vmls::field::gpu::{GpuField, evaluate};
use vmls::probe::Lcg;
use vmls::raycast::raycast_image;
use vmls::recon::{OctreeSettings, ReconMethod};
use vmls::renderer::Renderer;
use vmls::scene::Scene;

fn gaussian_scene(extra: &[&str]) -> Scene {
    let mut o: Vec<String> = [
        "reconstruction.method=\"gaussian\"",
        "volume.resolution=13",
        "camera.width=24",
        "camera.height=20",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    o.extend(extra.iter().map(|s| s.to_string()));
    common::general_scene(&o)
}

fn scattered_field() -> Field {
    let mut rng = Lcg::new(11);
    let points: Vec<[f64; 3]> = (0..3000)
        .map(|_| [rng.next_f64(), rng.next_f64(), rng.next_f64()])
        .collect();
    let d = point_data(Geometry::Points { points }, |p| {
        0.5 + 0.3 * (4.0 * p[0]).sin() * p[1]
    });
    splat::field_of(splat::point_samples(&d, Some(true)), &gaussian_scene(&[]))
}

/// Largest |GPU − CPU| relative to the largest |value|, and how many points disagree about
/// whether the field is defined.
fn gpu_vs_cpu(field: &Field, points: &[[f64; 3]]) -> (f64, usize) {
    let (ctx, compiler) = gpu();
    let gpu_field = GpuField::upload(&ctx, field).expect("upload");
    let (out, _) = evaluate(&ctx, &compiler, field, &gpu_field, points, 1).expect("mls_eval");
    drop(gpu_field);
    finish(ctx);
    let n = field.neighbours().expect("neighbours");
    let (mut worst, mut scale, mut undefined) = (0.0f64, 0.0f64, 0);
    for (g, p) in out.iter().zip(points) {
        match field.evaluate(n.as_ref(), *p) {
            Some(c) if g.terms > 0 => {
                worst = worst.max((f64::from(g.value) - c.value).abs());
                for (gk, ck) in g.gradient.iter().zip(c.gradient) {
                    worst = worst.max((f64::from(*gk) - ck).abs() * 1e-2);
                }
                scale = scale.max(c.value.abs());
            }
            None if g.terms == 0 => {}
            _ => undefined += 1,
        }
    }
    (worst / scale.max(1e-30), undefined)
}

#[test]
fn gpu_gaussian_field_matches_the_cpu_twin_on_a_grid_and_on_scattered_points() {
    let grid = gaussian_scene(&[]).field(|_| {}).expect("field");
    assert_eq!(grid.reconstruction.method, ReconMethod::Gaussian);
    let mut rng = Lcg::new(3);
    let (lo, hi) = grid.bounds();
    let pts: Vec<[f64; 3]> = (0..2000)
        .map(|_| {
            let t = [rng.next_f64(), rng.next_f64(), rng.next_f64()];
            [0, 1, 2].map(|a| lo[a] + t[a] * (hi[a] - lo[a]))
        })
        .collect();
    // f32 sums of ≈100 terms with exp: 1e-5 of the largest value. Gradients are compared at a
    // hundredth of their size (they are ~100× the values on a 13³ grid).
    let (err, undefined) = gpu_vs_cpu(&grid, &pts);
    assert!(
        err < 1e-5 && undefined == 0,
        "grid: {err:.2e}, {undefined} undefined"
    );

    let cloud = scattered_field();
    let (lo, hi) = cloud.bounds();
    let pts: Vec<[f64; 3]> = (0..2000)
        .map(|_| {
            let t = [rng.next_f64(), rng.next_f64(), rng.next_f64()];
            [0, 1, 2].map(|a| lo[a] + t[a] * (hi[a] - lo[a]))
        })
        .collect();
    let (err, undefined) = gpu_vs_cpu(&cloud, &pts);
    assert!(
        err < 1e-5 && undefined <= 2,
        "points: {err:.2e}, {undefined} undefined"
    );
}

#[test]
fn a_constant_grid_field_comes_back_within_the_ripple() {
    // σ = 0.25 × 2.4 spacings = 0.6: Poisson summation bounds the ripple of a Gaussian sum over a
    // grid by about 3 × 2·exp(−2π²σ²) = 4.9e-3 (three axes), away from the boundary; the kernels
    // are cut at ρ = 1 (4σ), which loses P(χ²₃ > 16) = 1.1e-3 of their mass. Measured: 5.4e-3.
    let volume = volume_from([17; 3], [0.125; 3], [-1.0; 3], |_| 1.0);
    let s = gaussian_scene(&[]);
    let field =
        Field::new(volume, s.reconstruction, &OctreeSettings::default(), |_| {}).expect("field");
    let n = field.neighbours().expect("neighbours");
    let mut rng = Lcg::new(5);
    let mut worst: f64 = 0.0;
    for _ in 0..500 {
        let p = [0, 1, 2].map(|_| -0.5 + rng.next_f64());
        let v = field.evaluate(n.as_ref(), p).expect("defined").value;
        worst = worst.max((v - 1.0).abs());
    }
    assert!(worst < 6.0e-3, "constant field off by {worst:.2e}");
    assert!(worst > 1e-6, "a Gaussian sum is not exact: {worst:.2e}");
}

#[test]
fn gpu_ray_casting_of_the_gaussian_field_matches_the_cpu_reference() {
    let (ctx, _) = gpu();
    let s = gaussian_scene(&[
        "render.method=\"reference\"",
        "render.reference_step=0.25",
        "transfer.isosurfaces=[{value=0.5, color=[1.0,0.8,0.3], opacity=0.8}]",
    ]);
    let field = s.field(|_| {}).expect("field");
    let setup = s.ray_setup(&field).expect("setup");
    let cpu = raycast_image(&setup, &field, &s.transfer, None).expect("CPU twin");
    let mut renderer = Renderer::new(&ctx, field).expect("renderer");
    let gpu = splat::scene_frame(&mut renderer, &s);
    assert!(gpu.variant.contains("gaussian"), "{}", gpu.variant);
    let diff = gpu
        .pixels
        .iter()
        .zip(&cpu)
        .flat_map(|(g, c)| (0..4).map(move |k| (f64::from(g[k]) - c.rgba[k]).abs()))
        .fold(0.0, f64::max);
    // As the MLS reference's GPU/CPU bound (tests/render.rs): f32 along ≈100 steps.
    // Measured 1.6e-5 on lavapipe (f32 along ≈100 steps, each a sum of exp terms).
    eprintln!("Gaussian field image, GPU vs CPU: {diff:.2e}");
    assert!(diff < 5e-5, "GPU vs CPU {diff:.2e}");
    drop(renderer);
    finish(ctx);
}

/// The volumes a pre-shaded frame's first upload computes for its kept kernels alone are the
/// field's own to the bit; the next request computes every volume and keeps them.
#[test]
fn kernel_volumes_of_kept_samples_equal_the_fields() {
    let field = scattered_field();
    let fresh = field.clone();
    let all = field.kernel_volumes();
    let keep = |i: usize| i.is_multiple_of(3);
    let partial = fresh.kernel_volumes_where(&keep);
    assert!(
        matches!(partial, std::borrow::Cow::Owned(_)),
        "computed alone"
    );
    for i in (0..field.samples.len()).filter(|&i| keep(i)) {
        assert_eq!(partial.get(i).to_bits(), all.get(i).to_bits(), "sample {i}");
    }
    let again = fresh.kernel_volumes_where(&keep);
    assert!(
        matches!(again, std::borrow::Cow::Borrowed(_)),
        "kept the second time"
    );
    assert_eq!(*again, *all);
}
