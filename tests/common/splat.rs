//! Helpers of the splatting tests (tests/splat.rs, tests/splat_footprint.rs,
//! tests/splat_cases.rs, tests/splat_raster.rs).
#![allow(dead_code)]

use glam::DVec3;
use std::path::Path;
use vmls::data::dataset::Dataset;
use vmls::field::Field;
use vmls::raycast::raycast_image;
use vmls::recon::OctreeSettings;
use vmls::renderer::{GpuImage, Renderer, SplatReport};
use vmls::samples::Metric;
use vmls::samples::{SampleSet, SampleSettings};
use vmls::scene::Scene;
use vmls::splat::raster::splat_image;
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
    super::general_scene(&o)
}

pub fn setup(s: &Scene, field: &Field, shading: Shading) -> SplatSetup {
    s.splat_setup(shading, field).expect("splat setup")
}

/// ∫ w·G_V(o + t d − p) dt over the whole line, V = σ²M⁻¹ (P = V⁻¹ = M/σ²).
pub fn line_integral(w: f64, sigma: f64, m: &Metric, p: DVec3, o: DVec3, d: DVec3) -> f64 {
    let pm = |y: DVec3| {
        DVec3::new(
            m[0] * y.x + m[3] * y.y + m[4] * y.z,
            m[3] * y.x + m[1] * y.y + m[5] * y.z,
            m[4] * y.x + m[5] * y.y + m[2] * y.z,
        ) / (sigma * sigma)
    };
    let r = o - p;
    let a = d.dot(pm(d));
    let b = d.dot(pm(r));
    let c = r.dot(pm(r));
    let det_p = vmls::recon::gaussian::metric_det(m) / sigma.powi(6);
    let norm = det_p.sqrt() / (2.0 * std::f64::consts::PI).powf(1.5);
    w * norm * (2.0 * std::f64::consts::PI / a).sqrt() * (-0.5 * (c - b * b / a)).exp()
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

/// One frame of a scene's camera, settings, transfer function, isosurfaces and lighting.
pub fn scene_frame(renderer: &mut Renderer, s: &Scene) -> GpuImage {
    let (image, _) = renderer.render(&s.view(), |_| {}).expect("frame");
    image
}

pub fn gpu_frame(renderer: &mut Renderer, s: &Scene) -> (Vec<[f32; 4]>, SplatReport) {
    let image = scene_frame(renderer, s);
    assert!(image.pixels.iter().flatten().all(|v| v.is_finite()));
    (image.pixels, image.splat.expect("splat report"))
}

/// f32 kernels against the f64 twin: footprints of ≈100 kernels per pixel, each rounded at
/// ~1e-7 relative, through exp and erfc (A&S, the same polynomial on both sides). Measured on
/// lavapipe: 1.2e-6 to 1.4e-6 pre-shaded, 4.3e-6 to 7.0e-6 post-shaded (largest: the
/// isosurface); about 4× that, for devices whose exp rounds differently.
pub const GPU_TOLERANCE: f64 = 3e-5;

pub fn rmse(a: &[[f64; 4]], b: &[[f64; 4]]) -> f64 {
    let n = a.len() as f64 * 3.0;
    (a.iter()
        .zip(b)
        .map(|(p, q)| (0..3).map(|c| (p[c] - q[c]).powi(2)).sum::<f64>())
        .sum::<f64>()
        / n)
        .sqrt()
}

/// The sample set of point data `d` (support 2.4, 8 neighbours).
pub fn point_samples(d: &Dataset, anisotropic: Option<bool>) -> SampleSet {
    SampleSet::from_dataset(
        d,
        Path::new("test"),
        None,
        &SampleSettings {
            support: 2.4,
            knn_support: vmls::samples::KNN_SUPPORT,
            knn: 8,
            anisotropic,
        },
    )
    .expect("sample set")
}

/// The small tetrahedral torus of `tests/common` with f = 0.5 + 0.4 sin 3x cos z.
pub fn torus_samples() -> SampleSet {
    let d = super::point_data(super::tet_torus(24, 3), |p| {
        0.5 + 0.4 * (3.0 * p[0]).sin() * p[2].cos()
    });
    point_samples(&d, None)
}

/// A field of a sample set with a scene's reconstruction.
pub fn field_of(set: SampleSet, s: &Scene) -> Field {
    Field::from_samples(set, s.reconstruction, &OctreeSettings::default(), |_| {}).expect("field")
}

/// Post-shaded RMSE against the ray-cast Gaussian field (reference step 1/16), per sheet
/// thickness; `common` are the scene keys both share.
pub fn sheet_convergence(field: &Field, common: &[&str], slabs: &[f64]) -> Vec<(f64, f64)> {
    let mut extra = common.to_vec();
    extra.extend([
        "reconstruction.method=\"gaussian\"",
        "render.method=\"reference\"",
        "render.reference_step=0.0625",
    ]);
    let rs = scene(&extra);
    let setup_r = rs.ray_setup(field).expect("ray setup");
    let reference: Vec<[f64; 4]> = raycast_image(&setup_r, field, &rs.transfer, None)
        .expect("CPU twin")
        .iter()
        .map(|p| p.rgba)
        .collect();
    slabs
        .iter()
        .map(|slab| {
            let mut extra = common.to_vec();
            let key = format!("splat.slab={slab}");
            extra.extend(["render.method=\"splat-post\"", key.as_str()]);
            let s = scene(&extra);
            let image = splat_image(&setup(&s, field, Shading::Post), field, &s.transfer)
                .expect("CPU twin");
            (*slab, rmse(&image.pixels, &reference))
        })
        .collect()
}

/// A regular-grid field with a scene's reconstruction.
pub fn grid_field(volume: vmls::data::Volume, s: &Scene) -> Field {
    Field::new(volume, s.reconstruction, &OctreeSettings::default(), |_| {}).expect("field")
}
