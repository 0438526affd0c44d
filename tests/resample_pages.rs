//! The fast path's fine grid in pages (issue 27 §1, `recon::pages`): where supports reach
//! nothing or only one value, pages share a slot; everywhere else they hold exactly what the
//! dense fine grid would (its points are the direct solve's, checked point by point), on the GPU
//! as on the CPU, in mls_eval and in images with skipping.

mod common;

use common::*;
use vmls::data::dataset::Geometry;
use vmls::data::{Volume, marschner_lobb};
use vmls::field::Field;
use vmls::probe::Lcg;
use vmls::recon::pages::{PAGE_POINTS, Slot};
use vmls::recon::{Basis, GradientMode, OctreeSettings, ReconMethod, Weight};
use vmls::scene::{NeighbourMode, Scene};

/// Marschner–Lobb at n³ inside a ball of radius 0.3, exactly zero outside: the shape of a
/// brain-masked scan, whose background pages the fine grid shares.
fn masked(n: usize) -> Volume {
    let ml = marschner_lobb::generate(n);
    volume_from(ml.dims, ml.spacing, ml.origin, |p| {
        if p.iter().map(|c| c * c).sum::<f64>() < 0.3 * 0.3 {
            marschner_lobb::rho(p[0], p[1], p[2])
        } else {
            0.0
        }
    })
}

fn masked_field(method: ReconMethod, resample: u32) -> Field {
    let mut r = recon(
        Basis::Linear,
        Weight::Wendland,
        GradientMode::Analytic,
        NeighbourMode::Grid,
        2.4,
    );
    r.method = method;
    r.resample = resample;
    Field::new(masked(41), r, &OctreeSettings::default(), |_| {}).expect("field")
}

/// 400 points in a ball of radius 0.3 and eight clusters of 12 near the corners of [−2, 2]³:
/// a scattered set whose box is mostly out of every support.
fn clusters() -> Field {
    let mut rng = Lcg::new(41);
    let mut ball = |centre: [f64; 3], radius: f64, n: usize| {
        let mut out = Vec::new();
        while out.len() < n {
            let p: [f64; 3] = std::array::from_fn(|_| 2.0 * rng.next_f64() - 1.0);
            if p.iter().map(|c| c * c).sum::<f64>() < 1.0 {
                out.push(std::array::from_fn(|a| centre[a] + radius * p[a]));
            }
        }
        out
    };
    let mut points = ball([0.0; 3], 0.3, 400);
    for c in 0..8 {
        let corner = [0, 1, 2].map(|a| if c >> a & 1 == 1 { 1.9 } else { -1.9 });
        points.extend(ball(corner, 0.06, 12));
    }
    let data = point_data(Geometry::Points { points }, |p| {
        0.5 + 0.3 * (4.0 * p[0]).sin() * (3.0 * p[1]).cos() + 0.2 * p[2]
    });
    let mut r = recon(
        Basis::Linear,
        Weight::Wendland,
        GradientMode::Analytic,
        NeighbourMode::Octree,
        2.4,
    );
    r.resample = 2;
    let set = common::splat::point_samples(&data, None);
    Field::from_samples(set, r, &OctreeSettings::default(), |_| {}).expect("field")
}

/// Every `stride`-th fine point of the paged grid against the direct solve at its position
/// (what the dense grid stores there): undefined exactly where the solve is, else within
/// rounding (shared slots hold the constant a solve reaches up to it). Returns how many points
/// of shared slots were checked.
fn check_points(field: &Field, stride: usize) -> usize {
    let grid = field.resampled().expect("fine grid");
    let n = field.neighbours().expect("neighbours");
    let (lo, hi) = field.value_range();
    let h: [f64; 3] = std::array::from_fn(|a| grid.spacing[a] / f64::from(grid.factor));
    let d = grid.dims;
    let mut shared = 0;
    for i in (0..d[0] * d[1] * d[2]).step_by(stride) {
        let idx = [i % d[0], (i / d[0]) % d[1], i / (d[0] * d[1])];
        let at = grid.index(idx);
        let stored = grid.data[at];
        let pages = grid.pages.as_ref().expect("paged");
        if matches!(pages.slots[at / PAGE_POINTS], Slot::Constant(_)) {
            shared += 1;
        }
        let x = std::array::from_fn(|a| grid.origin[a] + idx[a] as f64 * h[a]);
        match field.evaluate_direct(n.as_ref(), x) {
            None => assert!(stored[0].is_nan(), "{idx:?}: stored {stored:?}, undefined"),
            Some(m) => {
                let dv = (stored[0] - m.value).abs() / (hi - lo);
                let dg = (0..3)
                    .map(|a| (stored[1 + a] - m.gradient[a]).abs() * h[a] / (hi - lo))
                    .fold(0.0, f64::max);
                assert!(
                    dv <= 1e-12 && dg <= 1e-9,
                    "{idx:?}: stored {stored:?}, solved {} {:?}",
                    m.value,
                    m.gradient
                );
            }
        }
    }
    shared
}

#[test]
fn paged_fine_grids_hold_what_the_dense_grid_would() {
    for method in [ReconMethod::Mls, ReconMethod::Gaussian] {
        let f = masked_field(method, 2);
        let pages = f.fine_pages().expect("a masked grid is paged");
        let dense = f.lattice().fine_points(2);
        // Measured, both methods: 27 pages solved, 98 sharing one slot of zeros (137 564
        // of 531 441 points stored).
        assert!(
            pages.points() * 2 <= dense,
            "{method:?}: {} of {dense} points stored",
            pages.points()
        );
        assert!(pages.slots.contains(&Slot::Constant(0.0)), "{method:?}");
        assert!(pages.solved_points() < pages.points(), "{method:?}");
        let stats = f.fast_path();
        assert_eq!(stats["stored_points"], pages.points(), "{stats}");
        assert_eq!(stats["fine_points"], dense, "{stats}");
        let shared = check_points(&f, 5);
        assert!(shared > 1000, "{method:?}: {shared} shared points checked");
    }
}

/// Dense random points: the paged fast field never leaves its block's range, also next to the
/// faces where a solved page meets a shared one.
#[test]
fn paged_block_ranges_bound_the_fast_field() {
    let f = masked_field(ReconMethod::Mls, 2);
    let blocks = f.blocks().expect("blocks");
    let n = f.neighbours().expect("neighbours");
    let mut empty = 0;
    for p in vmls::probe::random_points(&f, 20_000, 0.0, 23) {
        let v = f.evaluate(n.as_ref(), p).expect("defined").value;
        let r = blocks.range_at(glam::DVec3::from(p));
        assert!(v >= r[0] && v <= r[1], "{p:?}: {v} outside {r:?}");
        if r[0] == r[1] {
            empty += 1;
        }
    }
    // The background's blocks are the constant 0 exactly (read from the page table).
    assert!(empty > 10_000, "{empty} points in constant blocks");
}

/// Supports too small to cover a grid's cells leave points undefined: a page reached by one
/// value is then not shared (it would be defined where the solve is not).
#[test]
fn grids_with_gaps_between_supports_share_no_constant_pages() {
    let volume = volume_from([129, 33, 33], [1.0; 3], [0.0; 3], |p| {
        if p[0] < 110.0 { 5.0 } else { p[1] }
    });
    let mut shared = Vec::new();
    for support in [0.6, 2.4] {
        let mut r = recon(
            Basis::Linear,
            Weight::Wendland,
            GradientMode::Analytic,
            NeighbourMode::Grid,
            support,
        );
        r.resample = 2;
        let f = Field::new(volume.clone(), r, &OctreeSettings::default(), |_| {}).expect("field");
        shared.push(
            f.fine_pages()
                .is_some_and(|p| p.slots.contains(&Slot::Constant(5.0))),
        );
        if f.fine_pages().is_some() {
            check_points(&f, 97);
        }
    }
    assert_eq!(shared, vec![false, true], "support 0.6, 2.4");
}

#[test]
fn scattered_pages_leave_the_space_between_clusters_undefined() {
    let f = clusters();
    let pages = f.fine_pages().expect("clusters are paged");
    let dense = f.lattice().fine_points(2);
    assert!(
        pages.points() * 4 <= dense,
        "{} of {dense} points stored",
        pages.points()
    );
    assert!(
        pages
            .slots
            .iter()
            .any(|s| matches!(s, Slot::Constant(c) if c.is_nan())),
        "an undefined slot"
    );
    assert!(check_points(&f, 3) > 1000);
    // The fast path on the GPU against its twin, inside the central ball.
    let mut rng = Lcg::new(3);
    let points: Vec<[f64; 3]> = (0..500)
        .map(|_| {
            // Frame-relative: the ball's centre is the world's origin.
            let c = f.frame_origin.to_array();
            std::array::from_fn(|a| 0.4 * (rng.next_f64() - 0.5) - c[a])
        })
        .collect();
    let worst = fast_path_gpu_vs_cpu(&f, &points);
    assert!(worst < 1e-4, "GPU vs CPU {worst:.2e} of the range");
}

#[test]
fn paged_fast_path_matches_the_cpu_twin_on_the_gpu() {
    let f = masked_field(ReconMethod::Mls, 3);
    assert!(f.fine_pages().is_some());
    let points = vmls::probe::random_points(&f, 2000, 0.0, 7);
    let worst = fast_path_gpu_vs_cpu(&f, &points);
    // As the dense grid's test (tests/resample.rs): f32 solves and interpolation.
    assert!(worst < 1e-4, "GPU vs CPU {worst:.2e} of the range");

    // Images, with skipping (block ranges read back from the GPU's pool).
    let s = Scene::load(
        Some(std::path::Path::new("tests/scenes/ml-emission.toml")),
        &[
            "render.step=0.5",
            "render.skip=true",
            "camera.width=48",
            "camera.height=40",
        ]
        .map(String::from),
    )
    .expect("scene");
    let f = masked_field(ReconMethod::Mls, 2);
    let setup = s.ray_setup(&f).expect("setup");
    let cpu = vmls::raycast::raycast_frame(&setup, &f, &s.transfer, s.render.table_resolution)
        .expect("CPU twin");
    let (ctx, _compiler) = gpu();
    let mut renderer = vmls::renderer::Renderer::new(&ctx, f).expect("renderer");
    let image = common::splat::scene_frame(&mut renderer, &s);
    drop(renderer);
    finish(ctx);
    assert!(image.variant.contains("-paged"), "{}", image.variant);
    assert!(image.variant.contains("-skip"), "{}", image.variant);
    let worst = image
        .pixels
        .iter()
        .zip(&cpu)
        .flat_map(|(g, c)| (0..4).map(move |k| (f64::from(g[k]) - c.rgba[k]).abs()))
        .fold(0.0, f64::max);
    let lit = cpu.iter().filter(|p| p.rgba[3] > 0.05).count();
    assert!(lit > 50, "{lit} pixels show the ball");
    eprintln!("paged fast path, skipping, GPU vs CPU: {worst:.2e}");
    // As the dense fast path's images (tests/resample.rs): measured 7–9e-6 there.
    assert!(worst < 3e-5, "GPU vs CPU {worst:.2e}");
}
