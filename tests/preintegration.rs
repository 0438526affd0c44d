//! Preintegration tables against direct f64 quadrature, and their edge cases ([MLS] §4).
//! Stated bound: every checked node within 1e-5 absolute of the reference (the target);
//! the f32 storage of the tables alone contributes up to 6e-8.

use vmls::view::preintegration::{
    PreintegrationTables, direct_quadrature, remainder_levels, segment_integral, table_lengths,
};
use vmls::view::transfer::TransferFunction;

fn default_tf() -> TransferFunction {
    TransferFunction::new(vec![
        [0.0, 0.0, 0.0, 0.0, 0.0],
        [0.35, 0.1, 0.2, 0.5, 0.3],
        [0.45, 0.2, 0.5, 1.0, 1.5],
        [0.5, 1.0, 0.95, 0.8, 60.0],
        [0.55, 1.0, 0.5, 0.1, 2.0],
        [1.0, 1.0, 0.3, 0.1, 3.0],
    ])
}

/// Largest absolute difference between table nodes and direct quadrature over a sample of nodes
/// (every 7th pair plus the whole diagonal and the corners).
fn max_node_error(
    tf: &TransferFunction,
    s_range: (f64, f64),
    lengths: &[f64],
    n: usize,
    steps: usize,
) -> f64 {
    let t = PreintegrationTables::build(tf, s_range, lengths, n, |_| {});
    let mut worst: f64 = 0.0;
    for (li, &l) in lengths.iter().enumerate() {
        for b in 0..n {
            for f in 0..n {
                let corner = (f == 0 || f == n - 1) && (b == 0 || b == n - 1);
                if !(corner || f == b || (f + n * b).is_multiple_of(7)) {
                    continue;
                }
                let (c, a) = direct_quadrature(tf, t.node(f), t.node(b), l, steps);
                let e = t.tables[li][f + n * b];
                for k in 0..3 {
                    worst = worst.max((f64::from(e[k]) - c[k]).abs());
                }
                worst = worst.max((f64::from(e[3]) - a).abs());
            }
        }
    }
    worst
}

#[test]
fn tables_match_direct_quadrature_at_nodes() {
    // The integrator's lengths for ML 41³ at [MLS]'s settings, in world units (spacing 0.05).
    let lengths: Vec<f64> = table_lengths(2.6, 0.1625)
        .iter()
        .map(|l| l * 0.05)
        .collect();
    let err = max_node_error(&default_tf(), (-0.1, 1.1), &lengths, 48, 20_000);
    eprintln!("default TF, 5 lengths, 48²: max node error {err:.2e}");
    assert!(err < 1e-5, "max node error {err:.2e}");
}

#[test]
fn narrow_spike_is_integrated_exactly() {
    // A spike 1/1000 of the range wide, very dense: between nodes it is invisible, but every
    // node's segment that crosses it must carry its full contribution.
    let tf = TransferFunction::new(vec![
        [0.0, 0.0, 0.0, 0.0, 0.0],
        [0.4995, 0.0, 0.0, 0.0, 0.0],
        [0.5, 1.0, 0.2, 0.1, 500.0],
        [0.5005, 0.0, 0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0, 0.0, 0.0],
    ]);
    let err = max_node_error(&tf, (0.0, 1.0), &[0.13, 0.065], 24, 400_000);
    eprintln!("spike TF, 2 lengths, 24²: max node error {err:.2e}");
    assert!(err < 1e-5, "max node error {err:.2e}");
    // Sanity: a segment across the spike is visibly opaque.
    let (_, a) = segment_integral(&tf, 0.0, 1.0, 0.13);
    let expect = 1.0 - (-500.0f64 * 0.5 * 0.001 * 0.13).exp();
    assert!((a - expect).abs() < 1e-12, "α {a} vs {expect}");
}

#[test]
fn diagonal_matches_the_closed_form() {
    let tf = default_tf();
    for s in [0.0, 0.2, 0.47, 0.5, 0.52, 0.9] {
        for l in [1e-6, 0.01, 0.3, 2.0] {
            let (ct, tau) = tf.lookup(s);
            let a = 1.0 - (-tau * l).exp();
            let (c, alpha) = segment_integral(&tf, s, s, l);
            assert!((alpha - a).abs() < 1e-14, "α({s},{s},{l})");
            for k in 0..3 {
                assert!((c[k] - ct[k] * a).abs() < 1e-14, "C({s},{s},{l})");
            }
        }
    }
}

#[test]
fn scalars_outside_the_domain_use_clamped_values() {
    let tf = default_tf();
    // Entirely above the domain: constant TF = the last point.
    let (c, a) = segment_integral(&tf, 1.5, 3.0, 0.4);
    let expect = 1.0 - (-3.0f64 * 0.4).exp();
    assert!((a - expect).abs() < 1e-14 && (c[0] - expect).abs() < 1e-14);
    // Crossing from below the domain into it.
    let (c1, a1) = segment_integral(&tf, -1.0, 0.7, 0.05);
    let (c2, a2) = direct_quadrature(&tf, -1.0, 0.7, 0.05, 200_000);
    assert!((a1 - a2).abs() < 1e-9);
    for k in 0..3 {
        assert!((c1[k] - c2[k]).abs() < 1e-9);
    }
    // And the tables over a range wider than the domain.
    let err = max_node_error(&tf, (-0.5, 1.5), &[0.05], 32, 20_000);
    assert!(err < 1e-5, "max node error {err:.2e}");
}

#[test]
fn zero_extinction_gives_nothing() {
    let tf = TransferFunction::new(vec![[0.0, 1.0, 1.0, 1.0, 0.0], [1.0, 0.5, 0.5, 0.5, 0.0]]);
    let t = PreintegrationTables::build(&tf, (0.0, 1.0), &[1.0, 0.5], 16, |_| {});
    assert!(t.tables.iter().flatten().all(|e| *e == [0.0; 4]));
}

#[test]
fn huge_extinction_saturates_without_nan() {
    let tf = TransferFunction::new(vec![[0.0, 0.2, 0.4, 0.6, 1e9], [1.0, 1.0, 1.0, 1.0, 1e12]]);
    for (f, b, l) in [
        (0.0, 1.0, 1.0),
        (0.3, 0.3, 10.0),
        (1.0, 0.0, 1e-3),
        (0.5, 0.6, 1e3),
    ] {
        let (c, a) = segment_integral(&tf, f, b, l);
        assert!(a == 1.0, "α = {a}");
        let (front, _) = tf.lookup(f);
        for k in 0..3 {
            // Opaque at once: the colour is the front colour.
            assert!(
                c[k].is_finite() && (c[k] - front[k]).abs() < 1e-6,
                "C = {c:?} front {front:?}"
            );
        }
    }
}

#[test]
fn vanishing_length_is_linear_in_l() {
    let tf = default_tf();
    assert_eq!(segment_integral(&tf, 0.2, 0.6, 0.0), ([0.0; 3], 0.0));
    for l in [1e-4, 1e-7, 1e-10] {
        let (c, a) = segment_integral(&tf, 0.2, 0.6, l);
        let (c_ref, a_ref) = direct_quadrature(&tf, 0.2, 0.6, l, 100_000);
        assert!(a > 0.0 && c.iter().all(|x| x.is_finite()));
        assert!(
            (a - a_ref).abs() <= 1e-9 * a_ref.max(1e-300) + 1e-18,
            "α {a} vs {a_ref} at l = {l}"
        );
        for k in 0..3 {
            assert!(
                (c[k] - c_ref[k]).abs() <= 1e-6 * c_ref[k].abs() + 1e-18,
                "C {c:?} vs {c_ref:?} at l = {l}"
            );
        }
    }
}

/// Pseudo-random scalar pairs in [0, 1] (not on table nodes).
fn pairs(n: usize) -> Vec<(f64, f64)> {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n).map(|_| (next(), next())).collect()
}

#[test]
fn any_length_matches_direct_quadrature_to_table_accuracy() {
    let tf = default_tf();
    let spacing = 0.05;
    let mut lengths: Vec<f64> = table_lengths(2.6, 0.1625)
        .iter()
        .map(|l| l * spacing)
        .collect();
    let l_min = *lengths.last().expect("lengths");
    let extra = remainder_levels(l_min, 60.0);
    for _ in 0..extra {
        let last = *lengths.last().expect("lengths");
        lengths.push(last * 0.5);
    }
    let t = PreintegrationTables::build(&tf, (-0.05, 1.05), &lengths, 256, |_| {});
    // Table accuracy: bilinear lookups of single tables at the same off-node pairs.
    let mut table_error: f64 = 0.0;
    let mut sweep_error: f64 = 0.0;
    let mut sweep = Vec::new();
    for &l in &lengths[..5] {
        sweep.extend([l, l * (1.0 + 1e-3), l * (1.0 - 1e-3), 0.37 * l, 0.71 * l]);
    }
    sweep.extend([1e-6, 1e-4 * spacing, 0.01 * spacing, 0.05 * spacing]);
    sweep.retain(|r| *r <= lengths[0]);
    for (f, b) in pairs(40) {
        for (k, &l) in lengths.iter().enumerate() {
            let e = t.lookup(&t.tables[k], f, b);
            let (c, a) = direct_quadrature(&tf, f, b, l, 20_000);
            table_error = table_error.max((e[3] - a).abs());
            for j in 0..3 {
                table_error = table_error.max((e[j] - c[j]).abs());
            }
        }
        for &r in &sweep {
            let (c, a) = t.segment(f, b, r);
            let (cr, ar) = direct_quadrature(&tf, f, b, r, 20_000);
            let err = (0..3)
                .map(|j| (c[j] - cr[j]).abs())
                .fold((a - ar).abs(), f64::max);
            assert!(err.is_finite());
            sweep_error = sweep_error.max(err);
        }
    }
    eprintln!(
        "256² tables: single-table lookup error {table_error:.2e}, any-length error {sweep_error:.2e}"
    );
    assert!(
        sweep_error <= 2.0 * table_error + 1e-5,
        "any-length error {sweep_error:.2e} vs table accuracy {table_error:.2e}"
    );
}

#[test]
fn tables_are_rebuilt_only_when_their_inputs_change() {
    use vmls::field::Field;
    use vmls::field::scalar_range;
    use vmls::scene::Scene;
    use vmls::scene::load_volume;
    use vmls::view::table_cache::TableCache;
    let set = |extra: &[&str]| {
        let mut o: Vec<String> = [
            "volume.resolution=9",
            "render.table_resolution=16",
            "render.method=\"adaptive\"",
            "reconstruction.resample=0",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        o.extend(extra.iter().map(|s| s.to_string()));
        Scene::load(None, &o).expect("scene")
    };
    let s = set(&[]);
    let field = Field::new(
        load_volume(&s).expect("volume"),
        s.reconstruction,
        &s.octree,
        |_| {},
    )
    .expect("field");
    let mut cache = TableCache::default();
    let setup = s.ray_setup(&field).expect("setup");
    assert!(
        cache
            .get(
                &s.transfer,
                scalar_range(&field),
                setup.table_lengths(&s.transfer),
                16,
                false,
                |_| {}
            )
            .is_some()
    );
    // A new camera does not touch the tables.
    let moved = set(&["camera.eye=[4.0, 1.0, 1.0]"]);
    let setup = moved.ray_setup(&field).expect("setup");
    cache.get(
        &moved.transfer,
        scalar_range(&field),
        setup.table_lengths(&moved.transfer),
        16,
        false,
        |_| {},
    );
    assert_eq!(cache.builds(), 1);
    // A new transfer function, or new lengths, does.
    let tf = set(&["transfer.points=[[0.0, 1, 1, 1, 0.0], [1.0, 1, 1, 1, 2.0]]"]);
    cache.get(
        &tf.transfer,
        scalar_range(&field),
        tf.ray_setup(&field)
            .expect("setup")
            .table_lengths(&tf.transfer),
        16,
        false,
        |_| {},
    );
    assert_eq!(cache.builds(), 2);
    let lengths = set(&[
        "transfer.points=[[0.0, 1, 1, 1, 0.0], [1.0, 1, 1, 1, 2.0]]",
        "render.l_max=1.3",
    ]);
    cache.get(
        &lengths.transfer,
        scalar_range(&field),
        lengths
            .ray_setup(&field)
            .expect("setup")
            .table_lengths(&lengths.transfer),
        16,
        false,
        |_| {},
    );
    assert_eq!(cache.builds(), 3);
}

/// Issue 29's thinnest peak (`tests/scenes/ml-peak-0.002.toml`): half-width 0.002 at 0.5, τ up to
/// 100, with a colour `ramp` (0: constant) across the whole range.
fn thin_peak(ramp: f64) -> TransferFunction {
    let point = |s: f64, tau: f64| [s, 1.0 - ramp * s, 0.6, 0.2 + ramp * s, tau];
    TransferFunction::new(vec![
        point(0.0, 0.0),
        point(0.498, 0.0),
        point(0.5, 100.0),
        point(0.502, 0.0),
        point(1.0, 0.0),
    ])
}

/// Largest RGBA difference of `t.entry` from the direct integral over pairs drawn near and
/// across the peak, at every length.
fn entry_error(t: &PreintegrationTables, tf: &TransferFunction) -> f64 {
    let mut rng = vmls::data::random::Lcg::new(29);
    let mut worst: f64 = 0.0;
    for _ in 0..4000 {
        let near = |r: &mut vmls::data::random::Lcg| 0.49 + 0.02 * r.next_f64();
        let s_f = near(&mut rng);
        let s_b = if rng.next_f64() < 0.5 {
            near(&mut rng)
        } else {
            rng.next_f64()
        };
        for (k, &l) in t.lengths.iter().enumerate() {
            let (c, a) = segment_integral(tf, s_f, s_b, l);
            let e = t.entry(k, s_f, s_b);
            let d = (0..3)
                .map(|i| (e[i] - c[i]).abs())
                .fold((e[3] - a).abs(), f64::max);
            worst = worst.max(d);
        }
    }
    worst
}

#[test]
fn exact_opacity_holds_a_peak_the_tables_cannot_resolve() {
    // 64 nodes over [0, 1]: the peak is a quarter of a cell wide. The tables' bilinear entries
    // miss it by tens of percent; the exact opacity with the tables' C/α is exact for a constant
    // colour (f32 storage aside) and, for a colour that changes across the range, errs by how
    // much the colour changes over a cell.
    for (ramp, bound) in [(0.0, 1e-6), (0.5, 2e-3)] {
        let tf = thin_peak(ramp);
        let mut t = PreintegrationTables::build(&tf, (0.0, 1.0), &[0.05, 0.025], 64, |_| {});
        let tables = entry_error(&t, &tf);
        t.set_exact_opacity(Some(&tf));
        let exact = entry_error(&t, &tf);
        eprintln!("ramp {ramp}: tables {tables:.2e}, exact opacity {exact:.2e}");
        assert!(tables > 0.1, "ramp {ramp}: tables err by only {tables:.2e}");
        assert!(
            exact < bound,
            "ramp {ramp}: exact opacity errs by {exact:.2e}"
        );
    }
}

#[test]
fn transfer_mean_tau_integrates_the_clamped_function_exactly() {
    // Steps, a zero-width range, ranges reversed and past both ends, against a midpoint rule
    // on each piece between the points (exact for a linear τ).
    let tf = TransferFunction::new(vec![
        [0.2, 1.0, 0.0, 0.5, 0.0],
        [0.4, 0.0, 1.0, 0.5, 4.0],
        [0.6, 0.5, 0.5, 0.0, 4.0],
        [0.6, 0.5, 0.5, 0.0, 1.0],
        [0.9, 0.2, 0.1, 1.0, 9.0],
    ]);
    let quadrature = |lo: f64, hi: f64| {
        let mut cuts = vec![lo, hi];
        cuts.extend(
            tf.points()
                .iter()
                .map(|p| p[0])
                .filter(|&s| lo < s && s < hi),
        );
        cuts.sort_by(f64::total_cmp);
        let mut tau = 0.0;
        for piece in cuts.windows(2) {
            let n = 1000;
            let h = (piece[1] - piece[0]) / f64::from(n);
            for i in 0..n {
                tau += tf.limit(piece[0] + (f64::from(i) + 0.5) * h, true).1 * h;
            }
        }
        tau / (hi - lo)
    };
    for (a, b) in [
        (0.3, 0.7),
        (0.7, 0.3),
        (-1.0, 0.25),
        (0.5, 2.0),
        (-3.0, 3.0),
        (0.61, 0.62),
    ] {
        let (m, _) = tf.mean_tau(a, b, 0.0);
        let tau = quadrature(a.min(b), a.max(b));
        assert!(
            (m - tau).abs() < 1e-9 * tau.max(1.0),
            "[{a}, {b}]: τ̄ {m} vs {tau}"
        );
    }
    // The point nearest the largest share: the plateau's (τ = 4) over [0.3, 0.7], the clamped
    // ends' past both ends.
    assert_eq!(tf.mean_tau(0.3, 0.7, 0.0).1, 2);
    assert_eq!(tf.mean_tau(0.95, 3.0, 0.0).1, 4);
    assert_eq!(tf.mean_tau(-3.0, 0.1, 0.0), (0.0, 0));
    // Zero width takes τ just above: at the step, the lower τ; on the plateau, 4.
    assert!((tf.mean_tau(0.6, 0.6, 1e-9).0 - 1.0).abs() < 1e-6);
    assert!((tf.mean_tau(0.5, 0.5, 1e-9).0 - 4.0).abs() < 1e-6);
}
