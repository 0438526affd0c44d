//! Octree leaves read as inline records (issue 27 §1, `octree.records`): the kernels visit the
//! same candidates in the same order as through the coded references, so evaluations and
//! frames must equal the coded layout's to the bit at record strides 2 and 3 (diagonal metrics,
//! the Gaussian weight in the metric's w; full metrics, three texels), across index gaps the
//! codes write as jumps, in the ray caster's integrators and in the fast path's build through
//! the octree. Packed records (stride 1, isotropic supports) move each position by up to half
//! a 21-bit step of its leaf's records, so there they must agree within f32 rounding's order
//! (bounds below). The coded layout keeps its own comparison with the CPU twin in
//! `tests/mls.rs`; with these, every layout is tied to it.
mod common;

use common::*;
use vmls::data::dataset::Geometry;
use vmls::field::Field;
use vmls::field::gpu::{GpuField, evaluate};
use vmls::gpu_types::MlsOut;
use vmls::probe::Lcg;
use vmls::raycast::build_tables;
use vmls::recon::{Basis, GradientMode, OctreeSettings, ReconMethod, Weight};
use vmls::samples::{SampleSet, Supports};
use vmls::scene::{NeighbourMode, Reconstruction, Scene};

fn settings(inline: bool) -> OctreeSettings {
    OctreeSettings {
        records: Some(inline),
        ..OctreeSettings::default()
    }
}

/// Scattered points with a smooth field; `far` more points far away, listed between the two
/// halves of the near ones, so that leaves in the middle jump over their indices.
fn scattered(n: usize, far: usize, anisotropic: Option<bool>) -> SampleSet {
    let mut rng = Lcg::new(9);
    let mut near = |k: usize| -> Vec<[f64; 3]> {
        (0..k)
            .map(|_| std::array::from_fn(|_| 2.0 * rng.next_f64() - 1.0))
            .collect()
    };
    let mut points = near(n / 2);
    let mut far_rng = Lcg::new(10);
    points.extend((0..far).map(|_| std::array::from_fn(|_| 5.0 + far_rng.next_f64())));
    points.extend(near(n - n / 2));
    let d = point_data(Geometry::Points { points }, |p| {
        0.5 + 0.3 * (2.0 * p[0]).sin() * (1.5 * p[1]).cos() + 0.2 * p[2]
    });
    common::splat::point_samples(&d, anisotropic)
}

/// `set` with every support 10% shorter along y: diagonal metrics that are not balls, so inline
/// records keep stride 2 instead of packing.
fn stretched(set: &SampleSet) -> SampleSet {
    let mut s = set.clone();
    s.supports = Supports::PerSample(
        (0..s.len())
            .map(|i| {
                let mut m = s.metric(i);
                m[1] *= 1.21;
                m
            })
            .collect(),
    );
    assert!(!s.is_isotropic() && !s.has_full_metric());
    s
}

/// Largest value and gradient errors of GPU evaluations against the f64 twin (relative to
/// max(1, |twin|); points the twin leaves undefined are skipped).
fn errors(field: &Field, points: &[[f64; 3]], gpu: &[MlsOut]) -> (f64, f64) {
    let neighbours = field.neighbours().expect("neighbours");
    let rel = |g: f32, t: f64| (f64::from(g) - t).abs() / t.abs().max(1.0);
    points.iter().zip(gpu).fold((0.0, 0.0), |(v, gr), (p, m)| {
        match field.evaluate(neighbours.as_ref(), *p) {
            Some(t) if m.terms > 0 => (
                v.max(rel(m.value, t.value)),
                (0..3).fold(gr, |gr, k| gr.max(rel(m.gradient[k], t.gradient[k]))),
            ),
            _ => (v, gr),
        }
    })
}

fn fields(set: &SampleSet, r: Reconstruction) -> [Field; 2] {
    [false, true].map(|inline| {
        let f = Field::from_samples(set.clone(), r, &settings(inline), |_| {}).expect("field");
        assert_eq!(f.octree_inline(), inline);
        f
    })
}

fn gpu_evaluations(field: &Field, points: &[[f64; 3]]) -> Vec<MlsOut> {
    gpu_evaluations_with(field, points, false)
}

/// As [`gpu_evaluations`], optionally uploading through staging (a discrete GPU's path).
fn gpu_evaluations_with(field: &Field, points: &[[f64; 3]], staged: bool) -> Vec<MlsOut> {
    let (ctx, compiler) = gpu_with(staged);
    let gf = GpuField::upload(&ctx, field).expect("upload");
    let (out, _) = evaluate(&ctx, &compiler, field, &gf, points, 1).expect("mls_eval");
    drop(gf);
    finish(ctx);
    out
}

/// Quadratic MLS with the analytic gradient through the octree (support 2.4).
fn quadratic_octree() -> Reconstruction {
    recon(
        Basis::Quadratic,
        Weight::Wendland,
        GradientMode::Analytic,
        NeighbourMode::Octree,
        2.4,
    )
}

/// Packed records' largest error against the f64 twin, at most this times the coded layout's:
/// a position moves by at most 2.4e-7 of its leaf's records' extent where f32 rounds a
/// coordinate by up to 6e-8 of its magnitude, and an ill-conditioned solve (past the outermost
/// samples) magnifies both alike.
const PACKED_FACTOR: f64 = 2.0;

#[test]
fn inline_records_evaluate_to_the_coded_layouts_bits() {
    let gaussian = |mut r: Reconstruction| {
        r.method = ReconMethod::Gaussian;
        r
    };
    let linear = recon(
        Basis::Linear,
        Weight::Wendland,
        GradientMode::Local,
        NeighbourMode::Octree,
        2.4,
    );
    let quadratic = quadratic_octree();
    let isotropic = scattered(3000, 0, None);
    let diagonal = stretched(&isotropic);
    let anisotropic = scattered(3000, 0, Some(true));
    let jumps = scattered(3000, 70_000, None);
    let cases = [
        ("linear MLS, balls (packed)", &isotropic, linear, 1),
        ("linear MLS, diagonal metrics", &diagonal, linear, 2),
        ("quadratic MLS, full metrics", &anisotropic, quadratic, 3),
        (
            "Gaussian sum, balls (packed)",
            &isotropic,
            gaussian(linear),
            1,
        ),
        (
            "Gaussian sum, diagonal metrics",
            &diagonal,
            gaussian(linear),
            2,
        ),
        (
            "Gaussian sum, full metrics",
            &anisotropic,
            gaussian(linear),
            3,
        ),
        ("linear MLS across index jumps (packed)", &jumps, linear, 1),
    ];
    for (label, set, r, stride) in cases {
        let [coded, inline] = fields(set, r);
        assert_eq!(inline.record_stride(), stride, "{label}");
        if label.contains("jumps") {
            let o = coded.octree().expect("octree").expect("an octree");
            let widest = o
                .nodes
                .iter()
                .filter(|n| n[0] == 0)
                .flat_map(|n| {
                    let m: Vec<u32> =
                        vmls::recon::octree_codes::LeafCodes::new(&o.codes, n[1], n[2]).collect();
                    m.windows(2).map(|w| w[1] - w[0]).max()
                })
                .max()
                .unwrap_or(0);
            assert!(widest >= 65_535, "{label}: widest gap {widest}");
        }
        // In the near points' box and a little past it (undefined points compare too).
        let shift = coded.frame_origin;
        let mut rng = Lcg::new(3);
        let points: Vec<[f64; 3]> = (0..3000)
            .map(|_| std::array::from_fn(|a| 2.2 * rng.next_f64() - 1.1 - shift[a]))
            .collect();
        let a = gpu_evaluations(&coded, &points);
        let b = gpu_evaluations(&inline, &points);
        let defined = a.iter().filter(|m| m.terms > 0).count();
        eprintln!("{label}: {defined} of {} defined", a.len());
        assert!(defined > 1500, "{label}: {defined} defined");
        if stride == 1 {
            // As accurate as the coded layout's f32 positions, against the f64 twin.
            let (cv, cg) = errors(&coded, &points, &a);
            let (pv, pg) = errors(&inline, &points, &b);
            eprintln!("{label}: twin error coded {cv:.2e} / {cg:.2e}, packed {pv:.2e} / {pg:.2e}");
            assert!(
                pv <= PACKED_FACTOR * cv + 1e-6,
                "{label}: value {pv:.2e}, coded {cv:.2e}"
            );
            assert!(
                pg <= PACKED_FACTOR * cg + 1e-5,
                "{label}: gradient {pg:.2e}, coded {cg:.2e}"
            );
            let counts = a.iter().zip(&b).filter(|(x, y)| x.terms != y.terms).count();
            assert!(
                counts <= 3,
                "{label}: {counts} points solved a different basis"
            );
            continue;
        }
        let differing = a
            .iter()
            .zip(&b)
            .filter(|(x, y)| bytemuck::bytes_of(*x) != bytemuck::bytes_of(*y))
            .count();
        assert_eq!(
            differing,
            0,
            "{label}: {differing} of {} evaluations differ",
            a.len()
        );
    }
}

/// Inline records are written straight into their buffer (`Buffer::fill`): into its mapping
/// on unified memory, into a staging buffer on a discrete GPU. Both paths must evaluate to the
/// same bits, packed and at stride 3.
#[test]
fn inline_records_written_in_place_or_through_staging_evaluate_the_same() {
    let quadratic = quadratic_octree();
    let balls = scattered(2000, 0, None);
    let ellipsoids = scattered(2000, 0, Some(true));
    for (label, set, stride) in [("packed", &balls, 1), ("full metrics", &ellipsoids, 3)] {
        let [_, inline] = fields(set, quadratic);
        assert_eq!(inline.record_stride(), stride, "{label}");
        let shift = inline.frame_origin;
        let mut rng = Lcg::new(5);
        let points: Vec<[f64; 3]> = (0..2000)
            .map(|_| std::array::from_fn(|a| 2.0 * rng.next_f64() - 1.0 - shift[a]))
            .collect();
        let mapped = gpu_evaluations_with(&inline, &points, false);
        let staged = gpu_evaluations_with(&inline, &points, true);
        let defined = mapped.iter().filter(|m| m.terms > 0).count();
        assert!(defined > 1000, "{label}: {defined} defined");
        let differing = mapped
            .iter()
            .zip(&staged)
            .filter(|(x, y)| bytemuck::bytes_of(*x) != bytemuck::bytes_of(*y))
            .count();
        assert_eq!(differing, 0, "{label}: {differing} evaluations differ");
    }
}

/// A view of the small tetrahedral torus.
fn torus_scene(extra: &[&str]) -> Scene {
    let mut o: Vec<String> = [
        "camera.eye=[2.5, -2.0, 2.0]",
        "camera.target=[0.0, 0.0, 0.0]",
        "camera.up=[0.0, 0.0, 1.0]",
        "camera.width=40",
        "camera.height=32",
        "transfer.points=[[0.0, 0.2, 0.4, 1.0, 0.0], [0.5, 0.9, 0.6, 0.2, 4.0], [1.0, 1.0, 1.0, 1.0, 8.0]]",
        "render.background=[0.1, 0.2, 0.3]",
        "render.table_resolution=128",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    o.extend(extra.iter().map(|s| s.to_string()));
    general_scene(&o)
}

fn gpu_frame(field: &Field, scene: &Scene) -> (Vec<[f32; 4]>, String) {
    let setup = scene.ray_setup(field).expect("setup");
    let tables = build_tables(&setup, field, &scene.transfer, 128, |_| {});
    let (ctx, compiler) = gpu();
    let gf = GpuField::upload(&ctx, field).expect("upload");
    let image = vmls::renderer::render(
        &ctx,
        &compiler,
        field,
        &gf,
        &scene.transfer,
        tables.as_ref(),
        &setup,
        |_| {},
    )
    .expect("render");
    drop(gf);
    finish(ctx);
    (image.pixels, image.variant)
}

/// Packed records' frames against the coded layout's, per RGBA channel: under a 16-bit level.
const PACKED_PIXEL: f32 = 1.5e-5;

#[test]
fn ray_cast_frames_through_inline_records_equal_the_coded_layouts() {
    let set = splat::torus_samples();
    let direct = recon(
        Basis::Linear,
        Weight::Wendland,
        GradientMode::Local,
        NeighbourMode::Octree,
        2.4,
    );
    let mut fast = direct;
    // The fast path's fine grid is solved through the octree (recon_resample).
    fast.resample = 2;
    let cases: [(&str, Reconstruction, &[&str]); 3] = [
        (
            "fixed steps",
            direct,
            &["render.method=\"fixed\"", "render.step=0.5"],
        ),
        ("adaptive", direct, &["render.method=\"adaptive\""]),
        (
            "fast path",
            fast,
            &["render.method=\"fixed\"", "render.step=0.5"],
        ),
    ];
    let diagonal = stretched(&set);
    for (label, r, keys) in cases {
        let scene = torus_scene(keys);
        for set in [&set, &diagonal] {
            let [coded, inline] = fields(set, r);
            let packed = inline.record_stride() == 1;
            let (a, va) = gpu_frame(&coded, &scene);
            let (b, vb) = gpu_frame(&inline, &scene);
            if label == "fast path" {
                assert!(
                    va.contains("resample") && vb.contains("resample"),
                    "{va}, {vb}"
                );
            } else {
                let name = if packed {
                    "octree-packed"
                } else {
                    "octree-inline"
                };
                assert!(
                    !va.contains("inline") && !va.contains("packed") && vb.contains(name),
                    "{va}, {vb}"
                );
            }
            let lit = a.iter().filter(|p| p[3] > 0.05).count();
            assert!(lit > a.len() / 10, "{label}: {lit} pixels see the torus");
            let max = a
                .iter()
                .zip(&b)
                .flat_map(|(x, y)| x.iter().zip(y).map(|(u, v)| (u - v).abs()))
                .fold(0.0f32, f32::max);
            eprintln!("{label}, packed {packed}: frames differ by {max:.2e} at most");
            if packed {
                assert!(
                    max <= PACKED_PIXEL,
                    "{label}: packed frames differ by {max}"
                );
            } else {
                assert!(a == b, "{label}: frames differ (max {max})");
            }
        }
    }
}

#[test]
fn a_scene_key_chooses_the_records_and_a_bad_one_is_named() {
    let load = |v: &str| Scene::load(None, &[format!("octree.records={v}")]);
    assert_eq!(
        load("\"inline\"").expect("inline").octree.records,
        Some(true)
    );
    assert_eq!(
        load("\"coded\"").expect("coded").octree.records,
        Some(false)
    );
    assert_eq!(load("\"auto\"").expect("auto").octree.records, None);
    let e = load("\"packed\"").expect_err("a bad value").to_string();
    assert!(
        e.contains("octree.records") && e.contains("\"inline\""),
        "{e}"
    );
}
