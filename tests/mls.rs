//! GPU MLS kernels (f32) against the f64 CPU reference, plus analytic properties of MLS.
mod common;

use common::*;
use vmls::data::Volume;

use vmls::field::Field;
use vmls::field::gpu::{GpuField, evaluate};
use vmls::gpu_types::MlsOut;
use vmls::probe::random_points;
use vmls::recon::mls::{MlsSettings, mls_evaluate};
use vmls::recon::{Basis, GradientMode, OctreeSettings, Weight};
use vmls::scene::{NeighbourMode, Reconstruction};

fn field_of(volume: Volume, r: Reconstruction) -> Field {
    Field::new(volume, r, &OctreeSettings::default(), |_| {}).expect("field")
}

struct Comparison {
    max_value_error: f64,
    max_gradient_error: f64,
    terms_mismatch: usize,
    defined: usize,
}

/// Evaluates on the GPU and the CPU at the same points and measures the differences, relative
/// to the data range (values) and to the largest CPU gradient (gradients).
fn compare(field: &Field, points: &[[f64; 3]]) -> Comparison {
    let (ctx, compiler) = gpu();
    let gpu_field = GpuField::upload(&ctx, field).expect("upload");
    let (out, _) = evaluate(&ctx, &compiler, field, &gpu_field, points, 1).expect("mls_eval");
    drop(gpu_field);
    finish(ctx);
    let (lo, hi) = field
        .samples
        .values
        .iter()
        .fold((f64::MAX, f64::MIN), |(l, h), v| {
            (l.min(f64::from(v)), h.max(f64::from(v)))
        });
    let range = (hi - lo).max(1e-30);
    let neighbours = field.neighbours().expect("neighbours");
    let cpu: Vec<_> = points
        .iter()
        .map(|p| mls_evaluate(&field.mls(), neighbours.as_ref(), *p))
        .collect();
    let grad_scale = cpu
        .iter()
        .flatten()
        .map(|m| m.gradient.iter().map(|g| g.abs()).fold(0.0, f64::max))
        .fold(1e-30, f64::max);
    let mut c = Comparison {
        max_value_error: 0.0,
        max_gradient_error: 0.0,
        terms_mismatch: 0,
        defined: 0,
    };
    for (g, m) in out.iter().zip(&cpu) {
        let g: &MlsOut = g;
        assert!(
            g.value.is_finite() && g.gradient.iter().all(|x| x.is_finite()),
            "GPU produced a non-finite value: {g:?}"
        );
        match m {
            None => {
                if g.terms != 0 {
                    c.terms_mismatch += 1;
                }
            }
            Some(m) => {
                if g.terms != m.terms {
                    c.terms_mismatch += 1;
                    continue;
                }
                c.defined += 1;
                c.max_value_error = c
                    .max_value_error
                    .max((f64::from(g.value) - m.value).abs() / range);
                for k in 0..3 {
                    c.max_gradient_error = c
                        .max_gradient_error
                        .max((f64::from(g.gradient[k]) - m.gradient[k]).abs() / grad_scale);
                }
            }
        }
    }
    c
}

#[test]
fn gpu_matches_cpu_for_every_variant() {
    // (basis, support, value tolerance, gradient tolerance): f32 against f64, relative to the
    // data range and to the largest gradient. The quadratic system is the worst conditioned.
    let cases = [
        (Basis::Constant, 1.6, 2e-6, 5e-5),
        (Basis::Linear, 2.4, 5e-6, 1e-4),
        (Basis::Quadratic, 1.8, 5e-5, 2e-3),
    ];
    for (basis, support, tol_v, tol_g) in cases {
        for weight in [Weight::Wendland, Weight::Interpolating] {
            for gradient in [GradientMode::Local, GradientMode::Analytic] {
                for neighbours in [NeighbourMode::Grid, NeighbourMode::Octree] {
                    let field = ml_field(13, recon(basis, weight, gradient, neighbours, support));
                    // A margin of −3% puts some points outside the grid: boundary fallbacks
                    // and undefined points are compared too.
                    let margin = -0.03;
                    let points = random_points(&field, 1500, margin, 11);
                    let c = compare(&field, &points);
                    let label = format!("{basis:?}/{weight:?}/{gradient:?}/{neighbours:?}");
                    assert!(
                        c.defined > 1000,
                        "{label}: only {} defined points",
                        c.defined
                    );
                    assert!(
                        c.terms_mismatch <= 3,
                        "{label}: {} points solved a different basis",
                        c.terms_mismatch
                    );
                    eprintln!(
                        "{label}: value {:.2e} gradient {:.2e} mismatched terms {}",
                        c.max_value_error, c.max_gradient_error, c.terms_mismatch
                    );
                    assert!(
                        c.max_value_error <= tol_v,
                        "{label}: value error {:.2e} > {tol_v:.0e}",
                        c.max_value_error
                    );
                    assert!(
                        c.max_gradient_error <= tol_g,
                        "{label}: gradient error {:.2e} > {tol_g:.0e}",
                        c.max_gradient_error
                    );
                }
            }
        }
    }
}

#[test]
fn linear_basis_reproduces_linear_functions() {
    let f = |p: [f64; 3]| 0.3 + 1.5 * p[0] - 0.7 * p[1] + 2.25 * p[2];
    for weight in [Weight::Wendland, Weight::Interpolating] {
        for gradient in [GradientMode::Local, GradientMode::Analytic] {
            // Anisotropic spacing: the support is a diagonal H.
            let vol = volume_from([9, 7, 6], [0.25, 0.3, 0.4], [-1.0, -0.9, -1.0], f);
            let field = field_of(
                vol,
                recon(Basis::Linear, weight, gradient, NeighbourMode::Grid, 2.4),
            );
            let points = random_points(&field, 400, 0.0, 3);
            let neighbours = field.neighbours().expect("neighbours");
            for p in &points {
                let m = mls_evaluate(&field.mls(), neighbours.as_ref(), *p).expect("defined");
                let world = [
                    p[0] + field.frame_origin.x,
                    p[1] + field.frame_origin.y,
                    p[2] + field.frame_origin.z,
                ];
                assert!(
                    (m.value - f(world)).abs() < 1e-6,
                    "value {} vs {}",
                    m.value,
                    f(world)
                );
                let expect = [1.5, -0.7, 2.25];
                for (k, e) in expect.iter().enumerate() {
                    assert!(
                        (m.gradient[k] - e).abs() < 1e-6,
                        "{weight:?} {gradient:?} gradient {:?}",
                        m.gradient
                    );
                }
            }
            let c = compare(&field, &points);
            assert!(
                c.max_value_error < 1e-5,
                "GPU value error {:.2e}",
                c.max_value_error
            );
            assert!(
                c.max_gradient_error < 1e-4,
                "GPU gradient error {:.2e}",
                c.max_gradient_error
            );
        }
    }
}

#[test]
fn quadratic_basis_reproduces_quadratics() {
    let f = |p: [f64; 3]| 1.0 + p[0] * p[0] - 0.5 * p[1] * p[2] + 0.25 * p[2];
    let vol = volume_from([8, 8, 8], [0.3; 3], [-1.0; 3], f);
    let field = field_of(
        vol,
        recon(
            Basis::Quadratic,
            Weight::Wendland,
            GradientMode::Analytic,
            NeighbourMode::Grid,
            1.8,
        ),
    );
    let neighbours = field.neighbours().expect("neighbours");
    for p in random_points(&field, 300, 0.2, 5) {
        let m = mls_evaluate(&field.mls(), neighbours.as_ref(), p).expect("defined");
        let w = [
            p[0] + field.frame_origin.x,
            p[1] + field.frame_origin.y,
            p[2] + field.frame_origin.z,
        ];
        assert_eq!(m.terms, 10, "quadratic basis solved at {p:?}");
        // The grid stores f32: reproduction is exact up to the data's rounding.
        assert!((m.value - f(w)).abs() < 1e-6, "{} vs {}", m.value, f(w));
        let g = [2.0 * w[0], -0.5 * w[2], -0.5 * w[1] + 0.25];
        for k in 0..3 {
            assert!(
                (m.gradient[k] - g[k]).abs() < 1e-5,
                "gradient {:?} vs {g:?}",
                m.gradient
            );
        }
    }
}

#[test]
fn analytic_gradient_matches_finite_differences() {
    for basis in [Basis::Constant, Basis::Linear, Basis::Quadratic] {
        for weight in [Weight::Wendland, Weight::Interpolating] {
            let support = if basis == Basis::Quadratic { 1.8 } else { 2.4 };
            let field = ml_field(
                15,
                recon(
                    basis,
                    weight,
                    GradientMode::Analytic,
                    NeighbourMode::Grid,
                    support,
                ),
            );
            let mls = MlsSettings {
                gradient: GradientMode::Local,
                ..field.mls()
            };
            let neighbours = field.neighbours().expect("neighbours");
            let eps = 1e-6;
            for p in random_points(&field, 100, 0.1, 9) {
                let m = mls_evaluate(&field.mls(), neighbours.as_ref(), p).expect("defined");
                for k in 0..3 {
                    let (mut a, mut b) = (p, p);
                    a[k] += eps;
                    b[k] -= eps;
                    let fa = mls_evaluate(&mls, neighbours.as_ref(), a)
                        .expect("defined")
                        .value;
                    let fb = mls_evaluate(&mls, neighbours.as_ref(), b)
                        .expect("defined")
                        .value;
                    let fd = (fa - fb) / (2.0 * eps);
                    assert!(
                        (m.gradient[k] - fd).abs() < 1e-5 * (1.0 + fd.abs()),
                        "{basis:?}/{weight:?}: analytic {} vs finite difference {fd}",
                        m.gradient[k]
                    );
                }
            }
        }
    }
}

#[test]
fn coplanar_samples_fall_back_to_a_lower_order_basis() {
    // A single z-layer: the linear and quadratic systems are singular in z.
    let vol = volume_from([9, 9, 1], [0.25; 3], [0.0; 3], |p| p[0] + 2.0 * p[1]);
    for basis in [Basis::Linear, Basis::Quadratic] {
        let field = field_of(
            vol.clone(),
            recon(
                basis,
                Weight::Wendland,
                GradientMode::Analytic,
                NeighbourMode::Grid,
                2.4,
            ),
        );
        let neighbours = field.neighbours().expect("neighbours");
        let p = [0.1, -0.05, 0.0];
        let m = mls_evaluate(&field.mls(), neighbours.as_ref(), p).expect("defined");
        assert_eq!(m.terms, 1, "{basis:?}: expected the constant fallback");
        assert!(m.value.is_finite() && m.gradient.iter().all(|g| g.is_finite()));
        let (ctx, compiler) = gpu();
        let gf = GpuField::upload(&ctx, &field).expect("upload");
        let (out, _) = evaluate(&ctx, &compiler, &field, &gf, &[p], 1).expect("eval");
        drop(gf);
        finish(ctx);
        assert_eq!(out[0].terms, 1);
        assert!((f64::from(out[0].value) - m.value).abs() < 1e-5);
    }
}

#[test]
fn no_weight_means_undefined_not_nan() {
    let field = ml_field(
        9,
        recon(
            Basis::Linear,
            Weight::Wendland,
            GradientMode::Local,
            NeighbourMode::Octree,
            2.4,
        ),
    );
    let far = [[5.0, 0.0, 0.0], [0.0, -3.0, 0.0], [1.0e6, 1.0e6, 1.0e6]];
    let neighbours = field.neighbours().expect("neighbours");
    for p in far {
        assert!(mls_evaluate(&field.mls(), neighbours.as_ref(), p).is_none());
    }
    let (ctx, compiler) = gpu();
    let gf = GpuField::upload(&ctx, &field).expect("upload");
    let (out, _) = evaluate(&ctx, &compiler, &field, &gf, &far, 1).expect("eval");
    drop(gf);
    finish(ctx);
    for o in out {
        assert_eq!(o.terms, 0);
        assert_eq!(o.neighbours, 0);
        assert!(o.value.is_finite());
    }
}

#[test]
fn octree_and_grid_neighbours_agree() {
    for basis in [Basis::Linear, Basis::Quadratic] {
        let support = if basis == Basis::Linear { 2.4 } else { 1.8 };
        let grid = ml_field(
            17,
            recon(
                basis,
                Weight::Wendland,
                GradientMode::Local,
                NeighbourMode::Grid,
                support,
            ),
        );
        let octree = ml_field(
            17,
            recon(
                basis,
                Weight::Wendland,
                GradientMode::Local,
                NeighbourMode::Octree,
                support,
            ),
        );
        let points = random_points(&grid, 2000, -0.02, 21);
        let (gn, on) = (
            grid.neighbours().expect("neighbours"),
            octree.neighbours().expect("neighbours"),
        );
        for p in &points {
            let a = mls_evaluate(&grid.mls(), gn.as_ref(), *p);
            let b = mls_evaluate(&octree.mls(), on.as_ref(), *p);
            match (a, b) {
                (None, None) => {}
                (Some(a), Some(b)) => {
                    assert_eq!(
                        a.neighbours, b.neighbours,
                        "same samples have weight at {p:?}"
                    );
                    assert!(
                        (a.value - b.value).abs() < 1e-12,
                        "{} vs {}",
                        a.value,
                        b.value
                    );
                }
                other => panic!("grid and octree disagree on definedness at {p:?}: {other:?}"),
            }
        }
        let (ctx, compiler) = gpu();
        let (gg, og) = (
            GpuField::upload(&ctx, &grid).expect("upload"),
            GpuField::upload(&ctx, &octree).expect("upload"),
        );
        let (a, _) = evaluate(&ctx, &compiler, &grid, &gg, &points, 1).expect("eval");
        let (b, _) = evaluate(&ctx, &compiler, &octree, &og, &points, 1).expect("eval");
        drop((gg, og));
        finish(ctx);
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.neighbours, y.neighbours);
            // Both f32, through different arithmetic (index offsets vs stored positions).
            assert!(
                (x.value - y.value).abs() < 3e-5,
                "{basis:?}: GPU grid {} vs octree {} ({} terms)",
                x.value,
                y.value,
                x.terms
            );
        }
    }
}

#[test]
fn quadratic_solves_the_full_basis_in_the_interior() {
    let field = ml_field(
        21,
        recon(
            Basis::Quadratic,
            Weight::Wendland,
            GradientMode::Local,
            NeighbourMode::Grid,
            1.8,
        ),
    );
    let neighbours = field.neighbours().expect("neighbours");
    let points = random_points(&field, 2000, 0.1, 17);
    let full = points
        .iter()
        .filter(|p| {
            mls_evaluate(&field.mls(), neighbours.as_ref(), **p).is_some_and(|m| m.terms == 10)
        })
        .count();
    assert_eq!(
        full,
        points.len(),
        "interior points that fell back below the quadratic basis"
    );
}

/// 8- and 16-bit grids stay at their size on the device (issue 25 §4) and the kernel converts
/// them: the GPU result must equal, bit for bit, the same values uploaded as f32 (the
/// conversion is exact and the arithmetic after it is the same), and match the CPU twin within
/// the f32 tolerances above. Odd dimensions put rows at every offset within a word.
#[test]
fn integer_grids_match_f32_grids_and_the_cpu() {
    use vmls::data::{Storage, Values};
    let base = vmls::data::marschner_lobb::generate(13);
    let (lo, hi) = base.value_range();
    let quantised = |a: f32, b: f32| -> Vec<f32> {
        let scale = (b - a) / (hi - lo);
        base.values
            .iter()
            .map(|v| (a + (v - lo) * scale).round())
            .collect()
    };
    let cases = [
        (Storage::U8, quantised(0.0, 255.0)),
        (Storage::I8, quantised(-128.0, 127.0)),
        (Storage::U16, quantised(0.0, 65535.0)),
        (Storage::I16, quantised(-32768.0, 32767.0)),
    ];
    let shapes = [
        (Basis::Constant, 1.6, 2e-6),
        (Basis::Linear, 2.4, 5e-6),
        (Basis::Quadratic, 1.8, 5e-5),
    ];
    for (storage, values) in cases {
        let stored = match storage {
            Storage::U8 => Values::U8(values.iter().map(|&v| v as u8).collect()),
            Storage::I8 => Values::I8(values.iter().map(|&v| v as i8).collect()),
            Storage::U16 => Values::U16(values.iter().map(|&v| v as u16).collect()),
            Storage::I16 => Values::I16(values.iter().map(|&v| v as i16).collect()),
            Storage::F32 => unreachable!("the cases are integer storages"),
        };
        assert_eq!(
            stored, values,
            "{storage:?}: the quantised values fit the type"
        );
        for (basis, support, tol) in shapes {
            let r = recon(
                basis,
                Weight::Wendland,
                GradientMode::Analytic,
                NeighbourMode::Grid,
                support,
            );
            let volume = |values: Values| Volume {
                values,
                ..base.clone()
            };
            let int_field = field_of(volume(stored.clone()), r);
            let f32_field = field_of(volume(Values::F32(values.clone())), r);
            assert_eq!(int_field.samples.values.storage(), storage);
            let points = random_points(&int_field, 800, -0.03, 5);
            let (ctx, compiler) = gpu();
            let run = |field: &Field| {
                let g = GpuField::upload(&ctx, field).expect("upload");
                evaluate(&ctx, &compiler, field, &g, &points, 1)
                    .expect("mls_eval")
                    .0
            };
            let (a, b) = (run(&int_field), run(&f32_field));
            finish(ctx);
            let label = format!("{storage:?}/{basis:?}");
            for (i, (x, y)) in a.iter().zip(&b).enumerate() {
                assert_eq!(
                    (x.value.to_bits(), x.gradient.map(f32::to_bits), x.terms),
                    (y.value.to_bits(), y.gradient.map(f32::to_bits), y.terms),
                    "{label}: point {i} differs from the f32 grid"
                );
            }
            let c = compare(&int_field, &points);
            eprintln!("{label}: value {:.2e}", c.max_value_error);
            assert!(
                c.defined > 500,
                "{label}: only {} defined points",
                c.defined
            );
            assert!(
                c.terms_mismatch <= 3,
                "{label}: {} mismatches",
                c.terms_mismatch
            );
            assert!(
                c.max_value_error <= tol,
                "{label}: value error {:.2e} > {tol:.0e}",
                c.max_value_error
            );
        }
    }
}

/// The grid kernels' row windows hold at the grid's corners for every allowed support and every
/// storage: points within two cells of the first and of the last grid point, where a window
/// starts before the first row or is clamped at the buffer's end, against the CPU twin. (The
/// clamp once used the unpadded length and read the wrong sample there from support 2.5.) The
/// linear and quadratic bases both read rows; the quadratic's sums of x-moments up to the
/// fourth measured 8.7e-6 at most (a wrong power of one term fails it).
#[test]
fn row_windows_hold_at_the_grid_corners_for_every_support() {
    use vmls::data::Values;
    let dims = [65usize, 11, 12];
    let n = dims.iter().product::<usize>();
    let raw: Vec<f32> = (0..n).map(|i| ((i * 7919) % 251) as f32).collect();
    let base = Volume {
        dims,
        origin: [0.0; 3],
        spacing: [1.0; 3],
        values: Values::F32(raw.clone()),
    };
    let far = dims.map(|d| (d - 1) as f64);
    let mut rng = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut corner_points = Vec::new();
    for _ in 0..120 {
        let low = [0, 1, 2].map(|_| 2.0 * next());
        let high = [0, 1, 2].map(|a| far[a] - 2.0 * next());
        corner_points.push(low);
        corner_points.push(high);
    }
    // The quadratic system is worse conditioned: its bound is the every-variant test's.
    for (basis, supports, bound) in [
        (Basis::Linear, &[2.5, 6.5, 9.0, 16.0][..], 1e-5),
        (Basis::Quadratic, &[1.8, 6.5, 16.0][..], 5e-5),
    ] {
        for &support in supports {
            for values in [
                Values::F32(raw.clone()),
                Values::U16(raw.iter().map(|&v| v as u16).collect()),
                Values::U8(raw.iter().map(|&v| v as u8).collect()),
            ] {
                let storage = values.storage();
                let r = recon(
                    basis,
                    Weight::Wendland,
                    GradientMode::Local,
                    NeighbourMode::Grid,
                    support,
                );
                let field = field_of(
                    Volume {
                        values,
                        ..base.clone()
                    },
                    r,
                );
                // Frame-relative positions, as the kernels take them.
                let shift = field.frame_origin.to_array();
                let points: Vec<[f64; 3]> = corner_points
                    .iter()
                    .map(|p| [0, 1, 2].map(|a| p[a] - shift[a]))
                    .collect();
                let c = compare(&field, &points);
                let label = format!("{basis:?}, {storage:?}, support {support}");
                assert!(
                    c.terms_mismatch <= 2,
                    "{label}: {} mismatches",
                    c.terms_mismatch
                );
                assert!(
                    c.max_value_error <= bound,
                    "{label}: value error {:.2e} > {bound:e}",
                    c.max_value_error
                );
            }
        }
    }
}

#[test]
fn octree_leaves_with_index_gaps_past_16_bits_match_the_cpu() {
    // Compact references (recon::octree_codes) write a gap of 65 535 or more as jumps. Put
    // 66 000 filler samples far away between the lower and upper halves of a 13³ lattice, so
    // that every leaf near the lattice's middle jumps over them; GPU and CPU must still agree.
    use vmls::data::dataset::Geometry;
    use vmls::probe::Lcg;
    let lattice = |k: usize, j: usize, i: usize| [i, j, k].map(|c| c as f64 / 6.0 - 1.0);
    let mut points: Vec<[f64; 3]> = Vec::new();
    for k in 0..7 {
        for j in 0..13 {
            for i in 0..13 {
                points.push(lattice(k, j, i));
            }
        }
    }
    let mut rng = Lcg::new(3);
    points.extend((0..66_000).map(|_| std::array::from_fn(|_| 4.0 + rng.next_f64())));
    for k in 7..13 {
        for j in 0..13 {
            for i in 0..13 {
                points.push(lattice(k, j, i));
            }
        }
    }
    let d = point_data(Geometry::Points { points }, |p| {
        0.5 + 0.3 * (2.0 * p[0]).sin() * (1.5 * p[1]).cos() + 0.2 * p[2]
    });
    let set = common::splat::point_samples(&d, None);
    let r = recon(
        Basis::Linear,
        Weight::Wendland,
        GradientMode::Local,
        NeighbourMode::Octree,
        2.4,
    );
    let field = Field::from_samples(set, r, &OctreeSettings::default(), |_| {}).expect("field");
    let shift = field.frame_origin;
    let at = |p: [f64; 3]| std::array::from_fn(|a| p[a] - shift[a]);
    // The leaf at the middle lists samples on both sides of the fillers.
    let octree = field.octree().expect("octree").expect("an octree");
    let (leaf, _) = octree.leaf(at([0.05, 0.02, 0.0]));
    let leaf: Vec<u32> = leaf.collect();
    let widest = leaf.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
    assert!(
        widest >= 66_000,
        "widest gap {widest} in {} references",
        leaf.len()
    );
    let mut rng = Lcg::new(4);
    let queries: Vec<[f64; 3]> = (0..1500)
        .map(|_| at(std::array::from_fn(|_| 1.6 * rng.next_f64() - 0.8)))
        .collect();
    let c = compare(&field, &queries);
    assert!(c.defined > 1400, "only {} defined", c.defined);
    assert_eq!(c.terms_mismatch, 0);
    assert!(
        c.max_value_error <= 5e-6,
        "value error {:.2e}",
        c.max_value_error
    );
    assert!(
        c.max_gradient_error <= 1e-4,
        "gradient error {:.2e}",
        c.max_gradient_error
    );
}
