//! Helpers of the splatting tests (tests/splat.rs, tests/splat_cases.rs).
#![allow(dead_code)]

use glam::DVec3;
use vmls::render::Field;
use vmls::render::renderer::{Renderer, SplatReport, View};
use vmls::samples::Metric;
use vmls::scene::Scene;
use vmls::splat::{Shading, SplatSetup};

pub fn scene(extra: &[&str]) -> Scene {
    let mut o: Vec<String> = [
        "volume.resolution=13",
        "camera.width=40",
        "camera.height=32",
        "transfer.points=[[0.0,0.0,0.0,0.0,0.0],[0.3,0.2,0.5,1.0,2.0],[0.7,1.0,0.5,0.2,6.0],[1.0,1.0,1.0,1.0,1.0]]",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    o.extend(extra.iter().map(|s| s.to_string()));
    Scene::load(None, &o).expect("scene")
}

pub fn setup(s: &Scene, field: &Field, shading: Shading) -> SplatSetup {
    SplatSetup::new(
        shading,
        &s.render.splat,
        &s.camera,
        s.render.early_termination,
        s.render.background,
        &s.isosurfaces,
        &s.lighting,
        field,
    )
    .expect("splat setup")
}

/// A metric with axes `radii` rotated by `angle` about (1, 1, 1)/√3.
pub fn rotated_metric(radii: [f64; 3], angle: f64) -> Metric {
    let q = glam::DQuat::from_axis_angle(DVec3::ONE.normalize(), angle);
    let r = glam::DMat3::from_quat(q);
    let d = glam::DMat3::from_diagonal(DVec3::from(radii.map(|h| 1.0 / (h * h))));
    let m = r * d * r.transpose();
    [
        m.x_axis.x, m.y_axis.y, m.z_axis.z, m.y_axis.x, m.z_axis.x, m.z_axis.y,
    ]
}

pub fn max_diff(a: &[[f32; 4]], b: &[[f64; 4]]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(p, q)| (0..4).map(move |c| (f64::from(p[c]) - q[c]).abs()))
        .fold(0.0, f64::max)
}

pub fn gpu_frame(renderer: &mut Renderer, s: &Scene) -> (Vec<[f32; 4]>, SplatReport) {
    let (image, _) = renderer
        .render(
            &View {
                camera: &s.camera,
                settings: &s.render,
                transfer: &s.transfer,
                isosurfaces: &s.isosurfaces,
                lighting: &s.lighting,
            },
            |_| {},
        )
        .expect("splat frame");
    assert!(image.pixels.iter().flatten().all(|v| v.is_finite()));
    (image.pixels, image.splat.expect("splat report"))
}

/// f32 kernels against the f64 twin: footprints of ≈100 kernels per pixel, each rounded at
/// ~1e-7 relative, through exp and erfc (A&S, the same polynomial on both sides).
pub const GPU_TOLERANCE: f64 = 2e-3;

pub fn rmse(a: &[[f64; 4]], b: &[[f64; 4]]) -> f64 {
    let n = a.len() as f64 * 3.0;
    (a.iter()
        .zip(b)
        .map(|(p, q)| (0..3).map(|c| (p[c] - q[c]).powi(2)).sum::<f64>())
        .sum::<f64>()
        / n)
        .sqrt()
}
