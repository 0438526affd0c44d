//! Rays clipped to a non-convex mesh: nothing is integrated outside the hull (a ray through the
//! hole of a torus sees exactly the background), GPU images match the f64 reference, and an eye
//! inside the mesh works.
mod common;

use common::*;
use std::path::Path;
use vmls::data::dataset::{DataArray, Dataset, Location};
use vmls::field::Field;
use vmls::raycast::build_tables;
use vmls::raycast::{PixelResult, raycast_image};
use vmls::recon::{Basis, GradientMode, OctreeSettings, Weight};
use vmls::renderer::GpuImage;
use vmls::samples::{SampleSet, SampleSettings};
use vmls::scene::{NeighbourMode, Scene};

/// The field of a sample set by linear MLS over the octree with `support`.
fn linear_octree_field(set: SampleSet, support: f64) -> Field {
    Field::from_samples(
        set,
        recon(
            Basis::Linear,
            Weight::Wendland,
            GradientMode::Local,
            NeighbourMode::Octree,
            support,
        ),
        &OctreeSettings::default(),
        |_| {},
    )
    .expect("field")
}

fn torus_field() -> Field {
    let geometry = tet_torus(24, 3);
    let values = (0..geometry.point_count())
        .map(|i| {
            let p = geometry.point(i);
            (0.5 + 0.4 * p[2] + 0.2 * p[0]) as f32
        })
        .collect();
    let d = Dataset {
        geometry,
        arrays: vec![DataArray {
            name: "f".into(),
            location: Location::Point,
            components: 1,
            values,
        }],
    };
    let set = SampleSet::from_dataset(
        &d,
        Path::new("torus"),
        None,
        &SampleSettings {
            support: 2.0,
            knn_support: 2.0,
            knn: 8,
            anisotropic: None,
        },
    )
    .expect("samples");
    linear_octree_field(set, 2.0)
}

const ORTHO: &str = "camera.projection=\"orthographic\"";
const ORTHO_HEIGHT: &str = "camera.view_height=3.0";

/// With ORTHO: a view straight down the torus axis: pixel column c is at x = (c + 0.5)/w · 3 − 1.5.
fn scene(extra: &[&str]) -> Scene {
    let mut o: Vec<String> = [
        "camera.eye=[0.0, 0.0, 4.0]",
        "camera.target=[0.0, 0.0, 0.0]",
        "camera.up=[0.0, 1.0, 0.0]",
        "camera.width=30",
        "camera.height=30",
        "transfer.points=[[0.0, 0.2, 0.4, 1.0, 3.0], [1.0, 1.0, 0.6, 0.2, 6.0]]",
        "render.background=[0.1, 0.2, 0.3]",
        "render.table_resolution=128",
        "render.step=0.5",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    o.extend(extra.iter().map(|s| s.to_string()));
    common::general_scene(&o)
}

/// The GPU image and the f64 reference of a scene's view of the field.
fn both(field: &Field, scene: &Scene) -> (GpuImage, Vec<PixelResult>) {
    gpu_and_cpu_frames(field, scene)
}

#[test]
fn rays_through_the_hole_see_only_the_background_and_gpu_matches_cpu() {
    let field = torus_field();
    assert!(field.hull.is_some());
    for method in ["fixed", "riemann"] {
        let scene = scene(&[&format!("render.method=\"{method}\""), ORTHO, ORTHO_HEIGHT]);
        let (img, cpu) = both(&field, &scene);
        assert!(img.variant.contains("-hull"), "{}", img.variant);
        let w = 30usize;
        // Pixel (18, 15) looks down at x = 0.35, y = 0.05: inside the hole (radius 0.65), but
        // within reach of the inner wall's supports, so MLS is defined there.
        let hole = 15 * w + 18;
        let bg = [0.1, 0.2, 0.3, 0.0];
        assert_eq!(cpu[hole].rgba, bg, "{method}: CPU pixel in the hole");
        assert_eq!(
            img.pixels[hole],
            bg.map(|v| v as f32),
            "{method}: GPU pixel in the hole"
        );
        assert_eq!(cpu[hole].evaluations, 0);
        // The tube itself (x = 1.05) is not empty.
        let tube = 15 * w + 25;
        assert!(
            cpu[tube].rgba[3] > 0.3,
            "{method}: tube alpha {}",
            cpu[tube].rgba[3]
        );
        let worst = img
            .pixels
            .iter()
            .zip(&cpu)
            .map(|(g, c)| {
                (0..4)
                    .map(|k| (f64::from(g[k]) - c.rgba[k]).abs())
                    .fold(0.0, f64::max)
            })
            .fold(0.0, f64::max);
        // f32 against f64 along ~2 segments of a few steps each.
        assert!(worst < 2e-3, "{method}: GPU vs CPU max difference {worst}");
    }
    // Without the hull (clipped to the bounding box only) the hole pixel would not be empty:
    // the test above could fail.
    let mut boxed = field.clone();
    boxed.hull = None;
    let scene = scene(&[ORTHO, ORTHO_HEIGHT]);
    let setup = scene.ray_setup(&boxed).expect("setup");
    let tables = build_tables(&setup, &boxed, &scene.transfer, 128, |_| {});
    let cpu = raycast_image(&setup, &boxed, &scene.transfer, tables.as_ref()).expect("CPU twin");
    assert!(
        cpu[15 * 30 + 18].rgba[3] > 1e-3,
        "box clipping integrates in the hole"
    );
}

#[test]
fn an_eye_inside_the_mesh_integrates_from_the_eye() {
    let field = torus_field();
    // Perspective eye inside the tube at (1, 0, 0) looking along the tube (+y).
    let scene = scene(&[
        "camera.eye=[1.0, 0.0, 0.0]",
        "camera.target=[1.0, 1.0, 0.0]",
        "camera.up=[0.0, 0.0, 1.0]",
        "camera.width=12",
        "camera.height=12",
    ]);
    let (img, cpu) = both(&field, &scene);
    let centre = 6 * 12 + 6;
    assert!(cpu[centre].rgba[3] > 0.5, "alpha {}", cpu[centre].rgba[3]);
    for (g, c) in img.pixels.iter().zip(&cpu) {
        for k in 0..4 {
            assert!(
                (f64::from(g[k]) - c.rgba[k]).abs() < 2e-3,
                "{g:?} vs {:?}",
                c.rgba
            );
        }
    }
}

#[test]
fn isosurfaces_on_a_mesh_match_the_reference() {
    let field = torus_field();
    // f = 0.5 + 0.4z + 0.2x crosses 0.55 inside the tube.
    let scene = scene(&[
        ORTHO,
        ORTHO_HEIGHT,
        "camera.eye=[0.0, -4.0, 1.5]",
        "camera.up=[0.0, 0.0, 1.0]",
        "transfer.isosurfaces=[{ value = 0.55, color = [1.0, 0.9, 0.7], opacity = 1.0 }]",
    ]);
    let (img, cpu) = both(&field, &scene);
    assert!(img.variant.contains("-iso1"), "{}", img.variant);
    let opaque = cpu.iter().filter(|p| p.rgba[3] > 0.999).count();
    assert!(opaque > 50, "the isosurface covers {opaque} pixels");
    // Pixels may differ where f32 and f64 disagree on a grazing crossing (the isosurface tests'
    // policy): at most 1% of them.
    let differing = img
        .pixels
        .iter()
        .zip(&cpu)
        .filter(|(g, c)| (0..4).any(|k| (f64::from(g[k]) - c.rgba[k]).abs() > 2e-3))
        .count();
    assert!(
        differing * 100 <= img.pixels.len(),
        "{differing} of {} pixels differ by more than 2e-3",
        img.pixels.len()
    );
}

#[test]
fn scattered_points_leave_gaps_empty_and_never_produce_nan() {
    // Two slabs of random points, x in [-1, -0.5] and [0.5, 1], with supports (h ≈ 0.2) far
    // smaller than the gap between them: rays through the gap see the background, nothing is
    // NaN.
    let mut rng = vmls::probe::Lcg::new(17);
    let points: Vec<[f64; 3]> = (0..4000)
        .map(|k| {
            let side = if k % 2 == 0 { -1.0 } else { 0.5 };
            [
                side + 0.5 * rng.next_f64(),
                2.0 * rng.next_f64() - 1.0,
                2.0 * rng.next_f64() - 1.0,
            ]
        })
        .collect();
    let values = points.iter().map(|p| (0.5 + 0.3 * p[1]) as f32).collect();
    let d = Dataset {
        geometry: vmls::data::dataset::Geometry::Points { points },
        arrays: vec![DataArray {
            name: "f".into(),
            location: Location::Point,
            components: 1,
            values,
        }],
    };
    let set = SampleSet::from_dataset(&d, Path::new("slabs"), None, &SampleSettings::default())
        .expect("samples");
    let field = linear_octree_field(set, 2.4);
    assert!(field.hull.is_none());
    // Looking down z: column c is at x = ((c + 0.5)/30 − 0.5) · 3.
    let scene = scene(&[ORTHO, ORTHO_HEIGHT, "render.method=\"fixed\""]);
    let (img, cpu) = both(&field, &scene);
    assert!(img.pixels.iter().flatten().all(|v| v.is_finite()));
    let gap = 15 * 30 + 15; // x = 0.05
    assert_eq!(cpu[gap].rgba, [0.1, 0.2, 0.3, 0.0]);
    assert_eq!(img.pixels[gap], [0.1f32, 0.2, 0.3, 0.0]);
    let slab = 15 * 30 + 24; // x = 0.95, inside the right slab
    assert!(cpu[slab].rgba[3] > 0.3, "slab alpha {}", cpu[slab].rgba[3]);
    // Scattered data is integrated out to the edge of the supports, where only a few samples
    // determine the fit and f32 and f64 can choose different fallback bases: single pixels
    // differ by up to ~0.02 there (grids and meshes agree to 2e-3). Bound the image's RMSE and
    // its largest difference.
    let diffs: Vec<f64> = img
        .pixels
        .iter()
        .zip(&cpu)
        .flat_map(|(g, c)| (0..4).map(move |k| f64::from(g[k]) - c.rgba[k]))
        .collect();
    let rmse = (diffs.iter().map(|d| d * d).sum::<f64>() / diffs.len() as f64).sqrt();
    let worst = diffs.iter().fold(0.0f64, |m, d| m.max(d.abs()));
    assert!(
        rmse < 3e-3 && worst < 0.05,
        "GPU vs CPU: RMSE {rmse}, max {worst}"
    );
}

/// Six cubes in a row, each split into hexahedra of 2×2×2 cells: a ray along the row crosses
/// the hull 12 times.
fn comb_field() -> Field {
    use vmls::data::dataset::{CellType, Cells, Geometry};
    let mut points = Vec::new();
    let mut cells = Cells::default();
    for cube in 0..6 {
        let x0 = -2.75 + cube as f64 * 1.0;
        let base = points.len() as u32;
        for k in 0..3 {
            for j in 0..3 {
                for i in 0..3 {
                    points.push([
                        x0 + 0.25 * i as f64,
                        -0.5 + 0.5 * j as f64,
                        -0.5 + 0.5 * k as f64,
                    ]);
                }
            }
        }
        let id = |i: u32, j: u32, k: u32| base + i + 3 * j + 9 * k;
        for k in 0..2 {
            for j in 0..2 {
                for i in 0..2 {
                    cells.push(
                        CellType::Hexahedron,
                        &[
                            id(i, j, k),
                            id(i + 1, j, k),
                            id(i + 1, j + 1, k),
                            id(i, j + 1, k),
                            id(i, j, k + 1),
                            id(i + 1, j, k + 1),
                            id(i + 1, j + 1, k + 1),
                            id(i, j + 1, k + 1),
                        ],
                    );
                }
            }
        }
    }
    let d = point_data(Geometry::Unstructured { points, cells }, |p| {
        0.5 + 0.2 * p[0] / 3.0 + 0.2 * p[2]
    });
    let set = common::splat::point_samples(&d, None);
    linear_octree_field(set, 2.4)
}

/// Along the comb's row: the central rays cross 12 faces, past the first variant's 8.
fn comb_along() -> Scene {
    scene(&[
        ORTHO,
        "camera.view_height=1.5",
        "camera.eye=[-6.0, 0.0, 0.0]",
        "camera.up=[0.0, 0.0, 1.0]",
        "camera.width=12",
        "camera.height=12",
    ])
}

#[test]
fn rays_with_more_crossings_than_the_first_variant_keeps_render_again_with_all() {
    let field = comb_field();
    let along = comb_along();
    let (img, cpu) = both(&field, &along);
    assert!(img.variant.ends_with("-hull"), "{}", img.variant);
    let centre = 6 * 12 + 6;
    assert!(cpu[centre].rgba[3] > 0.1, "alpha {}", cpu[centre].rgba[3]);
    let rgba: Vec<[f64; 4]> = cpu.iter().map(|p| p.rgba).collect();
    let worst = common::splat::max_diff(&img.pixels, &rgba);
    assert!(worst < 2e-3, "GPU vs CPU {worst:.2e}");
    // Across the row: 2 crossings per ray, the first variant serves.
    let across = scene(&[
        ORTHO,
        "camera.view_height=7.0",
        "camera.eye=[0.0, -6.0, 0.0]",
        "camera.up=[0.0, 0.0, 1.0]",
        "camera.width=24",
        "camera.height=8",
    ]);
    let (img, _) = both(&field, &across);
    assert!(img.variant.ends_with("-hull8"), "{}", img.variant);
}

/// A view of the torus, the same view with another transfer function, and another camera:
/// each with `extra`.
fn three_views(extra: &[&str]) -> [Scene; 3] {
    let with = |more: &[&str]| {
        let mut o = extra.to_vec();
        o.extend([ORTHO, ORTHO_HEIGHT, "camera.up=[0.0, 0.0, 1.0]"]);
        o.extend(more);
        scene(&o)
    };
    [
        with(&["camera.eye=[0.5, -4.0, 1.5]"]),
        with(&[
            "camera.eye=[0.5, -4.0, 1.5]",
            "transfer.points=[[0.0, 1.0, 0.4, 0.2, 1.0], [1.0, 0.2, 0.6, 1.0, 9.0]]",
        ]),
        with(&["camera.eye=[-1.0, -4.0, 2.5]"]),
    ]
}

/// What [`three_views`]' frames do with the hull's segments, one renderer after the other.
const THREE_VIEWS: [vmls::renderer::HullSegments; 3] = [
    vmls::renderer::HullSegments::Found,
    vmls::renderer::HullSegments::Reused,
    vmls::renderer::HullSegments::Found,
];

/// A renderer walks a mesh's hull once per camera and keeps the segments: a frame of the same
/// camera with another transfer function reads them, a frame of another camera walks again,
/// and every image equals the uncached walk's (the stateless `render`) and matches the CPU
/// twin, also for adaptive frames integrated in many chunks.
#[test]
fn hull_segments_are_found_once_per_camera_and_images_equal_the_walk() {
    use vmls::renderer::{HullSegments, Renderer};
    let field = torus_field();
    let [first, other_tf, moved] = three_views(&[]);
    let walked: Vec<_> = [&first, &other_tf, &moved]
        .iter()
        .map(|s| both(&field, s))
        .collect();
    let (ctx, _) = gpu();
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    let expect = THREE_VIEWS;
    for (i, s) in [&first, &other_tf, &moved].iter().enumerate() {
        let (img, stats) = renderer.render(&s.view(), |_| {}).expect("frame");
        let suffix = match expect[i] {
            HullSegments::Found => "-hull8-keep",
            HullSegments::Reused => "-hull8-cached",
        };
        assert!(img.variant.contains(suffix), "{}", img.variant);
        assert_eq!(stats.hull_segments, Some(expect[i]), "frame {i}");
        let (walk, cpu) = &walked[i];
        assert!(!walk.variant.contains("-cached"), "{}", walk.variant);
        let d = gpu_diff(&img.pixels, &walk.pixels);
        assert!(
            d <= 1e-6,
            "frame {i}: cached segments against the walk: {d:e}"
        );
        let rgba: Vec<[f64; 4]> = cpu.iter().map(|p| p.rgba).collect();
        let worst = common::splat::max_diff(&img.pixels, &rgba);
        assert!(worst < 2e-3, "frame {i}: GPU vs CPU {worst:.2e}");
    }
    // A frame's own camera again after the move: found again (the cache holds one camera).
    let (_, stats) = renderer.render(&first.view(), |_| {}).expect("frame");
    assert_eq!(stats.hull_segments, Some(HullSegments::Found));
    // Adaptive with short top intervals: more of them than a chunk holds, so every ray that
    // crosses the box runs in several chunks (only the first keeps the segments).
    let adaptive = scene(&[
        ORTHO,
        ORTHO_HEIGHT,
        "camera.eye=[0.3, -4.0, 1.6]",
        "camera.up=[0.0, 0.0, 1.0]",
        "render.method=\"adaptive\"",
        "render.l_max=0.02",
        "render.l_min=0.0025",
    ]);
    let setup = adaptive.ray_setup(&field).expect("setup");
    let chunk = vmls::renderer::default_chunk(&setup);
    let outer = vmls::renderer::outer_steps(&setup);
    assert!(
        outer > 2 * chunk,
        "{outer} outer steps in chunks of {chunk}"
    );
    let (walk, _) = both(&field, &adaptive);
    for expect in [HullSegments::Found, HullSegments::Reused] {
        let (img, stats) = renderer.render(&adaptive.view(), |_| {}).expect("frame");
        assert_eq!(stats.hull_segments, Some(expect));
        assert!(stats.bands > 0);
        let d = gpu_diff(&img.pixels, &walk.pixels);
        assert!(d <= 1e-6, "adaptive, {expect:?}: against the walk: {d:e}");
    }
    drop(renderer);
    finish(ctx);
}

/// Rays with more crossings than the first variant keeps: the kept segments say so, the
/// renderer renders the frame again with every crossing and keeps those, and the next frame of
/// the camera reads them at that bound.
#[test]
fn cached_segments_past_the_first_bound_render_again_with_all() {
    use vmls::renderer::{HullSegments, Renderer};
    let field = comb_field();
    let along = comb_along();
    let (walk, cpu) = both(&field, &along);
    let (ctx, _) = gpu();
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    for (expect, suffix) in [
        (HullSegments::Found, "-hull-keep"),
        // The segments kept at the larger bound serve the next frame of the camera.
        (HullSegments::Reused, "-hull-cached"),
    ] {
        let (img, stats) = renderer.render(&along.view(), |_| {}).expect("frame");
        assert!(img.variant.ends_with(suffix), "{}", img.variant);
        assert_eq!(stats.hull_segments, Some(expect));
        assert!(gpu_diff(&img.pixels, &walk.pixels) <= 1e-6);
        let rgba: Vec<[f64; 4]> = cpu.iter().map(|p| p.rgba).collect();
        assert!(common::splat::max_diff(&img.pixels, &rgba) < 2e-3);
    }
    drop(renderer);
    finish(ctx);
}

/// Post-shaded splatting over a mesh keeps its pixels' hull segments for the next frames of a
/// camera the same way: a frame of the same camera with another transfer function skips
/// `splat_segments`, and every image equals a fresh renderer's, which finds them.
#[test]
fn splatting_keeps_hull_segments_for_its_camera() {
    use vmls::renderer::{HullSegments, Renderer};
    let field = torus_field();
    let [first, other_tf, moved] = three_views(&["render.method=\"splat-post\""]);
    let (ctx, _) = gpu();
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    let expect = THREE_VIEWS;
    for (i, s) in [&first, &other_tf, &moved].iter().enumerate() {
        let (img, stats) = renderer.render(&s.view(), |_| {}).expect("frame");
        assert_eq!(stats.hull_segments, Some(expect[i]), "frame {i}");
        let mut fresh = Renderer::new(&ctx, field.clone()).expect("renderer");
        let (want, stats) = fresh.render(&s.view(), |_| {}).expect("frame");
        assert_eq!(stats.hull_segments, Some(HullSegments::Found));
        assert!(
            img.pixels.iter().any(|p| p[3] > 0.1),
            "frame {i} draws the torus"
        );
        assert_eq!(img.pixels, want.pixels, "frame {i}");
    }
    drop(renderer);
    finish(ctx);
}
