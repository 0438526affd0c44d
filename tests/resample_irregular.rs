//! The fast path on irregular data (issue 27 §1): the general path sampled on a lattice over the
//! domain's box (`Field::lattice`) and interpolated, per data kind (a tetrahedral mesh,
//! scattered points, a graded rectilinear grid) against the direct solve at dense random points
//! inside the domain; the GPU's fine grid (built through the octree) against its f64 twin; GPU
//! images on a mesh against the CPU twin.

mod common;

use common::*;
use vmls::data::dataset::{Dataset, Geometry};
use vmls::field::Field;
use vmls::probe::Lcg;
use vmls::recon::resample::DIRECT_TERMS;
use vmls::recon::{Basis, GradientMode, OctreeSettings, Weight};
use vmls::scene::NeighbourMode;

/// A smooth field with variation at about the meshes' scale.
fn smooth(p: [f64; 3]) -> f64 {
    0.5 + 0.3 * (2.0 * p[0]).sin() * (1.5 * p[1]).cos() + 0.4 * p[2]
}

fn field_of(d: &Dataset, basis: Basis, resample: u32) -> Field {
    let mut r = recon(
        basis,
        Weight::Wendland,
        GradientMode::Analytic,
        NeighbourMode::Octree,
        2.4,
    );
    r.resample = resample;
    let set = common::splat::point_samples(d, None);
    Field::from_samples(set, r, &OctreeSettings::default(), |_| {}).expect("field")
}

/// `n` random points inside the domain: convex combinations of a random cell's corners for a
/// mesh, uniform in the samples' box otherwise (frame-relative, as the field's).
fn inside(field: &Field, d: &Dataset, n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = Lcg::new(seed);
    let shift = field.frame_origin;
    (0..n)
        .map(|_| match &d.geometry {
            Geometry::Unstructured { points, cells } => {
                let c = cells.cell((rng.next_f64() * cells.len() as f64) as usize % cells.len());
                let w: Vec<f64> = c.iter().map(|_| -rng.next_f64().max(1e-12).ln()).collect();
                let total: f64 = w.iter().sum();
                std::array::from_fn(|a| {
                    c.iter()
                        .zip(&w)
                        .map(|(&i, wi)| points[i as usize][a] * wi / total)
                        .sum::<f64>()
                        - shift[a]
                })
            }
            // The samples' own box: a scattered set's domain reaches a support radius past
            // its outermost samples, where few supports overlap and the fit is extrapolated.
            g => {
                let (lo, hi) = g.bounds();
                std::array::from_fn(|a| lo[a] + rng.next_f64() * (hi[a] - lo[a]) - shift[a])
            }
        })
        .collect()
}

/// RMSE and maximum of |fast − direct| relative to the data range.
fn difference(field: &Field, points: &[[f64; 3]]) -> (f64, f64) {
    let n = field.neighbours().expect("neighbours");
    let (lo, hi) = field.value_range();
    let (mut sum, mut worst, mut count) = (0.0, 0.0f64, 0usize);
    for p in points {
        let Some(direct) = field.evaluate_direct(n.as_ref(), *p) else {
            continue;
        };
        let fast = field.evaluate(n.as_ref(), *p).expect("defined").value;
        let e = (fast - direct.value).abs() / (hi - lo);
        sum += e * e;
        worst = worst.max(e);
        count += 1;
    }
    assert!(
        count * 10 >= points.len() * 9,
        "{count} of {} defined",
        points.len()
    );
    ((sum / count as f64).sqrt(), worst)
}

fn kinds() -> Vec<(&'static str, Dataset)> {
    let mut rng = Lcg::new(5);
    let scattered: Vec<[f64; 3]> = (0..1500)
        .map(|_| std::array::from_fn(|_| 2.0 * rng.next_f64() - 1.0))
        .collect();
    // Graded 4:1 along x, as simulation grids refine towards a wall.
    let graded: Vec<f64> = (0..14)
        .map(|i| (i as f64 / 13.0).powi(2) * 2.0 - 1.0)
        .collect();
    let even: Vec<f64> = (0..10).map(|i| i as f64 / 9.0 * 2.0 - 1.0).collect();
    vec![
        ("mesh", point_data(tet_torus(32, 4), smooth)),
        (
            "points",
            point_data(Geometry::Points { points: scattered }, smooth),
        ),
        (
            "rectilinear",
            point_data(
                Geometry::Rectilinear {
                    coords: [graded, even.clone(), even],
                },
                smooth,
            ),
        ),
    ]
}

#[test]
fn irregular_fast_path_stays_close_to_the_direct_solve() {
    // Relative to the data range, (RMSE, max) bounds about 3× what was measured: mesh x2
    // 3.4e-5 / 1.9e-4, x4 3.6e-6 / 1.7e-5; points x2 3.4e-5 / 5.4e-4, x4 9.4e-6 / 3.9e-4;
    // rectilinear (graded 4:1) x2 2.1e-5 / 2.2e-4, x4 1.3e-5 / 2.4e-4: the uniform lattice
    // under-resolves the finest cells, so refining it helps less there.
    let bounds = [
        ("mesh", [(1e-4, 6e-4), (1.2e-5, 6e-5)]),
        ("points", [(1e-4, 1.5e-3), (3e-5, 1.2e-3)]),
        ("rectilinear", [(6e-5, 7e-4), (4e-5, 7e-4)]),
    ];
    for ((kind, d), (name, bound)) in kinds().into_iter().zip(bounds) {
        assert_eq!(kind, name);
        let mut rmses = Vec::new();
        for (factor, (rmse_bound, max_bound)) in [2u32, 4].into_iter().zip(bound) {
            let f = field_of(&d, Basis::Linear, factor);
            let points = inside(&f, &d, 2000, 9);
            let (rmse, max) = difference(&f, &points);
            assert!(
                rmse <= rmse_bound && max <= max_bound,
                "{kind} x{factor}: rmse {rmse:.2e} (bound {rmse_bound:.0e}), max {max:.2e} \
                 (bound {max_bound:.0e})"
            );
            rmses.push(rmse);
        }
        assert!(rmses[1] < rmses[0], "{kind}: {rmses:?}");
    }
}

/// Past its cap "auto" takes factor 2 over a lattice coarser than the samples' spacing
/// (`Field::set_lattice_scale`): its fine points lie between factor 2's and factor 1's, and so
/// does its error; the GPU's fine grid is built over the same lattice as the twin's.
#[test]
fn a_coarsened_lattice_errs_between_factor_two_and_the_lattice_itself() {
    let (kind, d) = kinds().swap_remove(1);
    assert_eq!(kind, "points");
    let mut rmses = Vec::new();
    for (factor, scale) in [(2u32, 1.0), (2, 1.5), (1, 1.0)] {
        let mut f = field_of(&d, Basis::Linear, factor);
        f.set_lattice_scale(scale);
        // The box's extent in whole cells of at most scale × the samples' spacing.
        let l = f.lattice();
        let target = scale * f.samples.spacing;
        for a in 0..3 {
            let cells = (l.dims[a] - 1) as f64;
            let step = l.spacing[a];
            assert!(
                step <= target * (1.0 + 1e-12) && step > target * (1.0 - 1.0 / cells),
                "axis {a}: {step} for {target}"
            );
        }
        let points = inside(&f, &d, 2000, 9);
        let (rmse, max) = difference(&f, &points);
        eprintln!("x{factor} at {scale}: rmse {rmse:.2e}, max {max:.2e}");
        rmses.push(rmse);
        if scale != 1.0 {
            f.octree().expect("octree");
            let worst = fast_path_gpu_vs_cpu(&f, &points[..1000]);
            assert!(worst < 1e-4, "GPU vs CPU {worst:.2e} of the range");
        }
    }
    assert!(rmses[0] < rmses[1] && rmses[1] < rmses[2], "{rmses:?}");
}

#[test]
fn irregular_gpu_fine_grid_matches_the_cpu_twin() {
    for (kind, d) in kinds() {
        let f = field_of(&d, Basis::Linear, 2);
        f.octree().expect("octree");
        let points = inside(&f, &d, 1000, 4);
        let worst = fast_path_gpu_vs_cpu(&f, &points);
        // f32 MLS at the fine points through the octree, and f32 interpolation.
        assert!(worst < 1e-4, "{kind}: GPU vs CPU {worst:.2e} of the range");
    }
}

/// A ray-cast scene of the fast path at factor 2 (Hermite intervals, one transparent band and two
/// emitting ones, a coloured background) with `camera` and `render.skip = skip`.
fn image_scene(camera: &[&str], skip: &str) -> vmls::scene::Scene {
    let mut o: Vec<String> = camera.iter().map(|c| c.to_string()).collect();
    o.extend(
        [
            "reconstruction.resample=2",
            "transfer.points=[[0.0, 0.2, 0.4, 1.0, 0.0], [0.45, 0.2, 0.4, 1.0, 0.0], [0.5, 0.2, 0.4, 1.0, 3.0], [1.0, 1.0, 0.6, 0.2, 6.0]]",
            "render.background=[0.1, 0.2, 0.3]",
            "render.interval=\"hermite\"",
        ]
        .map(String::from),
    );
    o.push(format!("render.skip={skip}"));
    general_scene(&o)
}

/// The variant holds every one of `parts`, and skipping exactly where `skip` asked for it.
fn check_variant(variant: &str, parts: &[&str], skip: &str) {
    assert!(parts.iter().all(|p| variant.contains(p)), "{variant}");
    assert_eq!(variant.contains("-skip"), skip == "true", "{variant}");
}

#[test]
fn mesh_fast_path_images_match_the_cpu_twin_and_keep_the_hull() {
    let d = point_data(tet_torus(24, 3), smooth);
    let field = field_of(&d, Basis::Linear, 2);
    field.octree().expect("octree");
    for skip in ["false", "true"] {
        // Straight down the torus axis, orthographic: pixel (18, 15) looks into the hole.
        let scene = image_scene(
            &[
                "camera.projection=\"orthographic\"",
                "camera.view_height=3.0",
                "camera.eye=[0.0, 0.0, 4.0]",
                "camera.up=[0.0, 1.0, 0.0]",
                "camera.width=30",
                "camera.height=30",
            ],
            skip,
        );
        let (img, cpu) = gpu_and_cpu_frames(&field, &scene);
        check_variant(&img.variant, &["-hull", "resample2"], skip);
        if skip == "true" {
            let r = img.skip.expect("skip report");
            assert!(r.fraction() > 0.0, "nothing skipped: {r:?}");
        }
        let hole = 15 * 30 + 18;
        assert_eq!(
            img.pixels[hole],
            [0.1, 0.2, 0.3, 0.0],
            "skip {skip}: GPU pixel in the hole"
        );
        assert!(
            cpu[15 * 30 + 25].rgba[3] > 0.2,
            "skip {skip}: the tube is not empty"
        );
        let rgba: Vec<[f64; 4]> = cpu.iter().map(|p| p.rgba).collect();
        let worst = common::splat::max_diff(&img.pixels, &rgba);
        assert!(
            worst < 2e-3,
            "skip {skip}: GPU vs CPU max difference {worst:.2e}"
        );
    }
}

#[test]
fn auto_takes_the_fast_path_on_irregular_data_only_where_its_pilot_finds_it_accurate() {
    // The scenes' "auto" (left out) at 64²: smooth data on the torus passes the pilot; a field
    // that changes sign within a sample spacing on scattered points does not, and `--stats`
    // says why.
    let scene = general_scene(
        &[
            "reconstruction.resample=\"auto\"",
            "camera.eye=[0.0, -3.0, 2.0]",
            "camera.width=64",
            "camera.height=64",
        ]
        .map(String::from),
    );
    let path = std::path::Path::new("test");
    let smooth_mesh = point_data(tet_torus(32, 4), smooth);
    let f = scene
        .field_from_dataset(&smooth_mesh, path, |_| {})
        .expect("field");
    assert_eq!(f.fast_path()["factor"], 2, "{}", f.fast_path());
    let mut rng = Lcg::new(8);
    let scattered: Vec<[f64; 3]> = (0..3000)
        .map(|_| std::array::from_fn(|_| 2.0 * rng.next_f64() - 1.0))
        .collect();
    let rough = point_data(Geometry::Points { points: scattered }, |p| {
        (0.5 + 0.5 * (25.0 * p[0]).sin() * (25.0 * p[1]).cos()).clamp(0.0, 1.0)
    });
    let f = scene
        .field_from_dataset(&rough, path, |_| {})
        .expect("field");
    assert_eq!(f.fast_path()["factor"], 0, "{}", f.fast_path());
    let why = f.fast_path()["declined"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    assert!(
        why.contains("RMSE") && why.contains("resample = 2"),
        "{why}"
    );
}

#[test]
fn the_pilot_of_a_gaussian_field_finishes_on_many_workers() {
    // Found on a 16-core machine: the pilot (a parallel loop over points) asked for the Gaussian
    // sum's kernel volumes in its first evaluation, whose builder is itself a parallel loop; the
    // building worker, waiting for its own jobs, stole an outer job that waited for the volumes,
    // and the render hung. `Field::neighbours` now builds them before any loop fans out. Each
    // trial is a fresh field on a pool of 16 workers (more than this machine's cores, as there).
    const TRIALS: usize = 6;
    let mut rng = Lcg::new(21);
    let scattered: Vec<[f64; 3]> = (0..3000)
        .map(|_| std::array::from_fn(|_| 2.0 * rng.next_f64() - 1.0))
        .collect();
    let d = point_data(Geometry::Points { points: scattered }, smooth);
    for trial in 0..TRIALS {
        let mut r = recon(
            Basis::Linear,
            Weight::Wendland,
            GradientMode::Local,
            NeighbourMode::Octree,
            2.4,
        );
        r.method = vmls::recon::ReconMethod::Gaussian;
        r.resample = 2;
        let set = common::splat::point_samples(&d, None);
        let field = Field::from_samples(set, r, &OctreeSettings::default(), |_| {}).expect("field");
        let points = inside(&field, &d, 256, 40 + trial as u64);
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(16)
                .build()
                .expect("a pool of 16 workers");
            // Sending fails only when the test already gave up waiting.
            let _ = tx.send(pool.install(|| field.fast_path_pilot(&points)));
        });
        let pilot = rx
            .recv_timeout(std::time::Duration::from_secs(300))
            .unwrap_or_else(|_| panic!("trial {trial}: the pilot did not finish in 300 s"));
        let p = pilot.expect("a pilot on defined points");
        assert!(p.rmse.is_finite(), "trial {trial}: pilot RMSE {}", p.rmse);
    }
}

/// `n` points uniform in the field's whole domain box (frame-relative): for scattered samples
/// that box reaches a support radius past the outermost samples, where the fit extrapolates.
fn in_box(field: &Field, n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = Lcg::new(seed);
    let (lo, hi) = field.bounds();
    (0..n)
        .map(|_| std::array::from_fn(|a| lo[a] + rng.next_f64() * (hi[a] - lo[a])))
        .collect()
}

/// RMSE and maximum of |fast − direct| relative to the data range where both are defined, and
/// the share of points defined only by the direct solve (the fast field leaves out a fine cell
/// with an undefined corner).
fn box_difference(field: &Field, points: &[[f64; 3]]) -> (f64, f64, f64) {
    let n = field.neighbours().expect("neighbours");
    let (lo, hi) = field.value_range();
    let (mut sum, mut worst, mut count, mut missing) = (0.0, 0.0f64, 0usize, 0usize);
    for p in points {
        let Some(direct) = field.evaluate_direct(n.as_ref(), *p) else {
            continue;
        };
        let Some(fast) = field.evaluate(n.as_ref(), *p) else {
            missing += 1;
            continue;
        };
        let e = (fast.value - direct.value).abs() / (hi - lo);
        sum += e * e;
        worst = worst.max(e);
        count += 1;
    }
    (
        (sum / count as f64).sqrt(),
        worst,
        missing as f64 / (count + missing) as f64,
    )
}

#[test]
fn direct_cells_keep_the_fast_path_where_scattered_samples_extrapolate() {
    // Past its outermost samples a scattered set's linear fit is barely determined and then
    // falls back to the constant one (a jump), which no lattice interpolates: the fast path's
    // cells around such fine points are solved directly. Measured over the whole domain box
    // (relative to the data range; RMSE, max, share the fast field leaves undefined):
    // interpolated everywhere 4.2e-3, 9.4e-2, 6.9%; with direct cells 1.7e-5, 3.4e-4, 0, with
    // 38% of the points solved directly (a small set: its shell is a large part of the box).
    let mut rng = Lcg::new(5);
    let scattered: Vec<[f64; 3]> = (0..3000)
        .map(|_| std::array::from_fn(|_| 2.0 * rng.next_f64() - 1.0))
        .collect();
    let d = point_data(Geometry::Points { points: scattered }, smooth);
    let mut f = field_of(&d, Basis::Linear, 2);
    let points = in_box(&f, 3000, 17);
    let plain = box_difference(&f, &points);
    f.set_resample_direct(true);
    let direct = box_difference(&f, &points);
    assert!(
        direct.0 <= 1e-4 && direct.1 <= 2e-3 && direct.2 <= 0.01,
        "direct cells: rmse {:.2e}, max {:.2e}, undefined {:.3}",
        direct.0,
        direct.1,
        direct.2
    );
    assert!(
        plain.0 >= 20.0 * direct.0,
        "interpolated everywhere {plain:?} against {direct:?}: direct cells changed little"
    );
    let grid = f.resampled().expect("fine grid");
    let solved_directly = |p: &[f64; 3]| grid.evaluate(*p).terms == DIRECT_TERMS;
    let share = points.iter().filter(|p| solved_directly(p)).count() as f64 / points.len() as f64;
    assert!(
        (0.05..=0.6).contains(&share),
        "{share:.3} of the points solved directly"
    );
    // Inside the samples' box the fit is determined: most of it stays interpolated.
    let inner = inside(&f, &d, 2000, 9);
    let core: Vec<_> = inner
        .iter()
        .filter(|p| p.iter().all(|c| c.abs() < 0.6))
        .collect();
    let core_direct = core.iter().filter(|p| solved_directly(p)).count();
    assert!(
        core_direct * 20 <= core.len(),
        "{core_direct} of {} points in the core solved directly",
        core.len()
    );

    // The GPU: recon_resample marks the same fine points, and the kernel solves their cells.
    f.octree().expect("octree");
    let (ctx, compiler) = gpu();
    let gpu_field = vmls::field::gpu::GpuField::upload(&ctx, &f).expect("upload");
    let (out, _) =
        vmls::field::gpu::evaluate(&ctx, &compiler, &f, &gpu_field, &points, 1).expect("eval");
    drop(gpu_field);
    finish(ctx);
    let variant = vmls::field::variant::Variant::of(&f).name("mls_eval");
    assert!(variant.contains("-direct"), "{variant}");
    let n = f.neighbours().expect("neighbours");
    let (lo, hi) = f.value_range();
    let mut errors = Vec::new();
    for (g, p) in out.iter().zip(&points) {
        let cpu = f.evaluate(n.as_ref(), *p);
        assert_eq!(
            g.terms > 0,
            cpu.is_some(),
            "defined at {p:?}: GPU {g:?}, CPU {cpu:?}"
        );
        if let Some(c) = cpu {
            errors.push((f64::from(g.value) - c.value).abs() / (hi - lo));
        }
    }
    assert!(errors.len() * 2 >= points.len(), "{} defined", errors.len());
    errors.sort_by(f64::total_cmp);
    let p99 = errors[errors.len() * 99 / 100];
    let worst = errors[errors.len() - 1];
    // f32 MLS (directly or at the fine points) and f32 interpolation, as the fast path's test
    // (1e-4). A direct solve past the samples is barely determined, and its pivots (down to the
    // 1e-2 tolerance) amplify f32 rounding: the worst of 3 000 points, at a box corner with 5
    // neighbours, measured 4.8e-4 (its f64 and f32 solves, not the fine grid).
    assert!(
        p99 < 1e-4 && worst < 2e-3,
        "GPU vs CPU: p99 {p99:.2e}, max {worst:.2e} of the range"
    );
}

fn box_points(n: usize, seed: u64) -> Dataset {
    let mut rng = Lcg::new(seed);
    let scattered: Vec<[f64; 3]> = (0..n)
        .map(|_| std::array::from_fn(|_| 2.0 * rng.next_f64() - 1.0))
        .collect();
    point_data(Geometry::Points { points: scattered }, smooth)
}

#[test]
fn auto_solves_extrapolating_cells_directly_where_that_passes_its_pilot() {
    let scene = |method: &str| {
        general_scene(&[
            "reconstruction.resample=\"auto\"".to_string(),
            format!("reconstruction.method=\"{method}\""),
            "camera.eye=[0.0, -3.0, 2.0]".into(),
            "camera.width=128".into(),
            "camera.height=128".into(),
        ])
    };
    let d = box_points(3000, 5);
    let path = std::path::Path::new("test");
    let f = scene("mls")
        .field_from_dataset(&d, path, |_| {})
        .expect("field");
    let stats = f.fast_path();
    assert_eq!(stats["factor"], 2, "{stats}");
    assert_eq!(stats["direct_cells"], true, "{stats}");
    assert!(
        stats["note"]
            .as_str()
            .is_some_and(|n| n.contains("directly")),
        "{stats}"
    );
    // `reconstruction.direct_cells`: false keeps auto from them (it declines), true takes them
    // with an explicit factor too; anything else is refused, naming the key.
    let with = |extra: &[&str]| {
        let mut o = vec![
            "reconstruction.method=\"mls\"".to_string(),
            "camera.width=128".into(),
            "camera.height=128".into(),
        ];
        o.extend(extra.iter().map(|e| e.to_string()));
        general_scene(&o)
            .field_from_dataset(&d, path, |_| {})
            .expect("field")
            .fast_path()
    };
    let off = with(&[
        "reconstruction.resample=\"auto\"",
        "reconstruction.direct_cells=false",
    ]);
    assert_eq!(off["factor"], 0, "{off}");
    let on = with(&[
        "reconstruction.resample=2",
        "reconstruction.direct_cells=true",
    ]);
    assert_eq!(on["direct_cells"], true, "{on}");
    let plain = with(&["reconstruction.resample=2"]);
    assert_eq!(plain["direct_cells"], false, "{plain}");
    let bad = vmls::scene::Scene::load(None, &["reconstruction.direct_cells=\"maybe\"".into()])
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(bad.contains("direct_cells"), "{bad}");
    // The Gaussian sum fades past its samples instead: its pilot passes without them.
    let f = scene("gaussian")
        .field_from_dataset(&d, path, |_| {})
        .expect("field");
    let stats = f.fast_path();
    assert_eq!(stats["factor"], 2, "{stats}");
    assert_eq!(stats["direct_cells"], false, "{stats}");
}

#[test]
fn direct_cell_images_match_the_cpu_twin_with_and_without_skipping() {
    let d = box_points(3000, 5);
    let mut field = field_of(&d, Basis::Linear, 2);
    field.set_resample_direct(true);
    field.octree().expect("octree");
    for skip in ["false", "true"] {
        // Past the samples' corner: rays cross the extrapolating shell and the core.
        let scene = image_scene(
            &[
                "camera.eye=[2.2, -2.6, 1.9]",
                "camera.width=28",
                "camera.height=28",
            ],
            skip,
        );
        let (img, cpu) = gpu_and_cpu_frames(&field, &scene);
        check_variant(&img.variant, &["resample2", "-direct"], skip);
        let rgba: Vec<[f64; 4]> = cpu.iter().map(|p| p.rgba).collect();
        assert!(
            rgba.iter().filter(|p| p[3] > 0.2).count() > 100,
            "skip {skip}: the volume is nearly empty"
        );
        let worst = common::splat::max_diff(&img.pixels, &rgba);
        assert!(
            worst < 2e-3,
            "skip {skip}: GPU vs CPU max difference {worst:.2e}"
        );
        // The cells solved directly show: interpolated everywhere, the twin's image differs
        // (by 0.51 in a channel at most, measured).
        let plain = {
            let mut f = field_of(&d, Basis::Linear, 2);
            f.set_resample_direct(false);
            let setup = scene.ray_setup(&f).expect("setup");
            let tables = vmls::raycast::build_tables(&setup, &f, &scene.transfer, 128, |_| {});
            vmls::raycast::raycast_image(&setup, &f, &scene.transfer, tables.as_ref())
                .expect("CPU twin")
        };
        let apart = rgba
            .iter()
            .zip(&plain)
            .map(|(a, b)| (0..4).map(|c| (a[c] - b.rgba[c]).abs()).fold(0.0, f64::max))
            .fold(0.0, f64::max);
        assert!(
            apart > 1e-2,
            "skip {skip}: without direct cells {apart:.2e} apart"
        );
    }
}
