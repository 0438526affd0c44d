//! Adaptive integration, f64 twin of `integrate` (RAY_METHOD 2) in `glsl/raycast/adaptive.glsl`, with
//! two acceptance tests (`render.adaptive`, DESIGN.md §4).
//!
//! The ray is cut into top intervals of l_max (the last one clipped at the exit); inside a top,
//! intervals are dyadic: [a, e] at depth k has length top·2^−k and starts at a multiple of it,
//! so that every full-top interval has its own table. Pending interval ends live on a stack with
//! their depths, strictly deeper towards the top except for the two halves of the last split:
//! at most ⌊log2(l_max/l_min)⌋ + 1 entries. An interval is split (its midpoint evaluated and
//! pushed, the left half processed first, since its α is needed for the right half's test)
//! until it is accepted or its half would be shorter than l_min. The Hermite criterion covers
//! the last top only in whole units of the deepest level, so that every interval it tests has a
//! table, and composites the remainder (shorter than a unit) as the ray's clipped tail. With
//! empty-space skipping it looks at each top's start for a run of empty blocks
//! ([`crate::field::skip::Blocks::run`]) and resumes from a fresh knot at the start of the top
//! holding the run's end, from where the top's intervals are aligned as everywhere else;
//! [MLS]'s criterion does not skip.
//!
//! - `mls2008` ([MLS] §4): C1 = table(len)(s_a, s_e) against C2 = the halves composited (the
//!   midpoint is evaluated for every test). Accepted when (1 − α_acc)·|C1 − C2| ≤ ε·|C1| (|·| the
//!   RGB norm) and the directional derivative does not change sign (∇f(a)·v · ∇f(e)·v ≥ 0,
//!   which could hide an isosurface); accepted intervals composite C2. Each top starts at
//!   depth 0.
//! - `hermite` (one evaluation per accepted interval): with length l, end values f0, f1,
//!   derivatives along the ray g0, g1 and Δ = f1 − f0, the cubic Hermite through the knots
//!   departs from the line the table assumes by at most D = max(|l·g0 − Δ|, |l·g1 − Δ|)/3 and
//!   stays within the hull of its Bézier values {f0, f0 + l·g0/3, f1 − l·g1/3, f1}. The
//!   interval's error per unit length is then at most T·S, T the transmittance so far and S the
//!   transfer function's [`TransferFunction::sensitivity`] to a deviation D over that hull (a
//!   band or a breakpoint the Hermite overshoots into counts, which catches thin features
//!   between monotone-looking knots). The hull is widened by D on both sides (the margin): the
//!   field itself may depart from the Hermite by as much as the Hermite departs from the chord,
//!   and a feature just outside the cubic's hull is then still split for. Without the margin a
//!   long l_max missed features whatever ε (Marschner–Lobb at l_max = 2.6 spacings stopped at
//!   3.1e-3 while ε fell 60-fold; with it, 4.4e-4; BENCHMARKS.md, "A margin on the Hermite
//!   hull"). Accepted when T·S·h ≤ ε, h the sample spacing: ε bounds the
//!   error of optical depth and colour per spacing, so a ray's total is at most ε per spacing
//!   crossed. An interval with exactly one undefined end is split (the domain's edge is inside).
//!   A step controller picks the next interval when the stack is empty: S ∝ D = O(l²) for smooth
//!   f, so the step that just meets ε is l·(ε/E)^½; one level coarser when 0.9 of that is at
//!   least 2l, the same level otherwise, back to the top level after an interval whose error is
//!   zero (its hull met no change of the transfer function), and deeper wherever the position
//!   is not aligned to the coarser level. A rejected interval costs one evaluation (its midpoint; its end stays
//!   pending). Splitting at dyadic midpoints rather than at the Hermite's extremum keeps every
//!   length a table length.
//!
//! **The ray's error estimate** (stage `count_error`, reported per pixel): the local estimates
//! of the intervals the ray composites, each weighted by the transmittance before it, summed.
//! - Hermite: an accepted interval of length l adds T·S·l (its error per spacing × l/h), the
//!   bound on the change of τ and τ·c over it, capped at T·peak·l (`peak` the transfer
//!   function's largest τ or τ·c_k: nothing on l can add more), which an interval with one end
//!   outside the domain meets. The clipped tail is estimated the same way, without a test.
//! - `mls2008`: the halves composited err by about a third of their difference from the whole
//!   (the error of a linear-in-s segment is O(l³), so halving cuts it to a quarter: |C1 − C2|
//!   ≈ ¾ of C1's error, 3× C2's), so an accepted interval adds T·max(|C1 − C2|, |α1 − α2|)/3;
//!   halves that can no longer be split are composited whole without a test, and the test that
//!   rejected their parent counts for them.
//!
//! Both bound the error of the linear-in-s assumption against the field between the knots as
//! the criterion models it (the Hermite through them), not features between knots that no
//! evaluation sees; the tables' resolution and early termination are not in it (the pixel's
//! estimate, [`pixel_estimate`], adds the transmittance a terminated ray left).

use super::interval::{Knot, bezier_hull, emit_interval, hermite_midpoint, knot, knot_segment};
use super::ray::Ray;
use super::ray::resume_interval;
use crate::raycast::RaySetup;
use crate::view::AdaptiveCriterion;
use crate::view::preintegration::PreintegrationTables;
use crate::view::transfer::TransferFunction;

/// A pixel's error estimate from its ray's (`ray`, the sum `count_error` kept): plus, where
/// the ray stopped at opacity `early_termination`, the transmittance it left, the most the
/// rest of the ray could have changed any channel. Twin of nothing on the GPU: the readback
/// applies it to the kernel's sums, the CPU twin to its own.
pub fn pixel_estimate(ray: f64, opacity: f64, early_termination: f64) -> f64 {
    let left = if opacity > early_termination {
        1.0 - opacity
    } else {
        0.0
    };
    ray + left
}

/// Stack entries needed for l_max/l_min (the shader's `ADAPTIVE_STACK`).
pub fn stack_size(l_max: f64, l_min: f64) -> usize {
    let mut levels = 1;
    let mut l = l_max;
    while 0.5 * l >= l_min * (1.0 - 1e-9) {
        l *= 0.5;
        levels += 1;
    }
    levels
}

fn norm(c: [f64; 3]) -> f64 {
    (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
}

/// Stage `hermite_error`: the Hermite criterion's error of [a, e] per sample spacing (see the
/// module documentation), infinite when exactly one end is undefined; and, unless the hull
/// holds an isosurface value, the Hermite's midpoint knot, through which the interval is
/// composited as two halves (the error is then that of the halves' chords).
fn hermite_error(
    ray: &Ray<'_>,
    setup: &RaySetup,
    tf: &TransferFunction,
    a: &Knot,
    e: &Knot,
) -> (f64, Option<Knot>) {
    let (f0, f1) = match (a.s, e.s) {
        (Some(f0), Some(f1)) => (f0, f1),
        (None, None) => return (0.0, None),
        _ => return (f64::INFINITY, None),
    };
    let l = e.t - a.t;
    let (m0, m1) = (l * a.slope(ray), l * e.slope(ray));
    let scale = ray.transmittance * setup.spacing_world;
    let (lo, hi, deviation) = bezier_hull(f0, f1, m0, m1);
    for iso in &setup.isosurfaces {
        if lo <= iso.value && iso.value <= hi {
            // A surface the Hermite overshoots into may be crossed twice between the knots:
            // split ("thin features", DESIGN.md §4).
            let between = f0.min(f1) <= iso.value && iso.value <= f0.max(f1);
            let error = if between {
                scale * tf.sensitivity(lo, hi, deviation)
            } else {
                f64::INFINITY
            };
            return (error, None);
        }
    }
    // The Hermite at u = ½: value and derivative per unit of the whole interval.
    let sm = hermite_midpoint(f0, f1, m0, m1);
    let mm = 1.5 * (f1 - f0) - 0.25 * (m0 + m1);
    let (lo0, hi0, d0) = bezier_hull(f0, sm, 0.5 * m0, 0.5 * mm);
    let (lo1, hi1, d1) = bezier_hull(sm, f1, 0.5 * mm, 0.5 * m1);
    // One pass over the transfer function for both halves: their hulls' union, widened by the
    // whole interval's departure (the margin, module documentation), and the larger departure.
    let error = scale
        * tf.sensitivity(
            lo0.min(lo1) - deviation,
            hi0.max(hi1) + deviation,
            d0.max(d1),
        );
    let mid = Knot {
        t: 0.5 * (a.t + e.t),
        s: Some(sm),
        // Only its component along the ray is ever read.
        gradient: (ray.d * (mm / l)).to_array(),
    };
    (error, Some(mid))
}

/// The Hermite controller's next depth after accepting an interval at `depth` with error
/// `error`: one level coarser when 0.9·(ε/E)^½ ≥ 2, i.e. 0.81·ε ≥ 4·E; the top level after an
/// interval whose hull met no change of the transfer function at all (the position's alignment
/// then decides how coarse the next interval can be).
fn predict_depth(depth: usize, error: f64, epsilon: f64) -> usize {
    if error == 0.0 {
        0
    } else if depth > 0 && 0.81 * epsilon >= 4.0 * error {
        depth - 1
    } else {
        depth
    }
}

/// Integrates [t0, t1] adaptively into `ray` with the setup's criterion, from `head` ≥ t0 (a
/// brick's face, [`super::raycast::anchored`]; only the Hermite criterion renders bricks).
pub(super) fn integrate(
    ray: &mut Ray<'_>,
    setup: &RaySetup,
    tf: &TransferFunction,
    tables: &PreintegrationTables,
    window: (f64, f64, f64),
) {
    let (t0, _, t1) = window;
    match setup.adaptive {
        AdaptiveCriterion::Mls2008 => integrate_mls2008(ray, setup, tables, t0, t1),
        AdaptiveCriterion::Hermite => integrate_hermite(ray, setup, tf, tables, window),
    }
}

/// [MLS]'s criterion. Each pending end carries the depth of the interval it closes, so lengths
/// are exact (top length · 2^−depth) and, for full-length top intervals, equal table `depth`
/// without comparing floats.
fn integrate_mls2008(
    ray: &mut Ray<'_>,
    setup: &RaySetup,
    tables: &PreintegrationTables,
    t0: f64,
    t1: f64,
) {
    let levels = stack_size(setup.l_max_world, setup.l_min_world);
    let mut stack: Vec<(Knot, usize)> = Vec::with_capacity(levels);
    // Top interval k is [t0 + k·l_max, min(t0 + (k+1)·l_max, t1)]: computed from k, not
    // accumulated, so that the kernel can start a chunk at any k.
    let tops = ((t1 - t0) / setup.l_max_world).ceil() as u64;
    let mut a = knot(ray, t0);
    for k in 0..tops {
        let end = t0 + (k + 1) as f64 * setup.l_max_world;
        let full = end <= t1;
        let top = if full { setup.l_max_world } else { t1 - a.t };
        if top <= 0.0 {
            return;
        }
        stack.push((knot(ray, if full { end } else { t1 }), 0));
        while let Some(&(e, depth)) = stack.last() {
            let len = top * 0.5f64.powi(depth as i32);
            let level = full.then_some(depth);
            let whole = knot_segment(tables, &a, &e, len, level);
            let c1 = whole.0;
            let can_split = depth + 1 < levels && (full || 0.5 * len >= setup.l_min_world);
            if can_split {
                let m = knot(ray, 0.5 * (a.t + e.t));
                let half = level.map(|k| k + 1);
                let left = knot_segment(tables, &a, &m, 0.5 * len, half);
                let right = knot_segment(tables, &m, &e, 0.5 * len, half);
                let c2 = [0, 1, 2].map(|k| left.0[k] + (1.0 - left.1) * right.0[k]);
                let diff = norm([0, 1, 2].map(|k| c1[k] - c2[k]));
                let alpha2 = 1.0 - (1.0 - left.1) * (1.0 - right.1);
                let halves_error = ray.transmittance * diff.max((whole.1 - alpha2).abs()) / 3.0;
                let sign_change = a.slope(ray) * e.slope(ray) < 0.0;
                if sign_change || ray.transmittance * diff > setup.epsilon * norm(c1) {
                    // Halves that cannot be split again are composited whole, untested: the
                    // rejected test's estimate stands for them.
                    if depth + 2 >= levels || !(full || 0.25 * len >= setup.l_min_world) {
                        ray.error_estimate += halves_error;
                    }
                    push_half(&mut stack, m, depth);
                    continue;
                }
                ray.error_estimate += halves_error;
                // Accepted: the two halves, each split at any isosurface it crosses.
                emit_interval(ray, setup, tables, &a, &m, 0.5 * len, left);
                emit_interval(ray, setup, tables, &m, &e, 0.5 * len, right);
            } else {
                emit_interval(ray, setup, tables, &a, &e, len, whole);
            }
            stack.pop();
            a = e;
            if 1.0 - ray.transmittance > setup.early_termination {
                return;
            }
        }
    }
}

/// The Hermite criterion with its step controller. Shaped like the kernel: every iteration of
/// the outer loop evaluates f once, at a new end or at a rejected interval's midpoint; the
/// inner loop composites the intervals that pass in between. The position inside a top is
/// counted in units of the deepest level, u = l_max·2^−(levels−1).
///
/// Every interval the loop composites has a table length: the ray's last top (clipped at t1,
/// length r) is covered only up to ⌊r/u⌋ units, by intervals that are dyadic and aligned as in
/// a full top, and the remainder (shorter than u, so never split) is the ray's tail, composited
/// once after the loop. The kernel's loop then never runs the clipped composite, which costs
/// every lane its lookups whenever one lane of a SIMD row needs it (BENCHMARKS.md, "Two lavapipe
/// costs").
fn integrate_hermite(
    ray: &mut Ray<'_>,
    setup: &RaySetup,
    tf: &TransferFunction,
    tables: &PreintegrationTables,
    (t0, head, t1): (f64, f64, f64),
) {
    let levels = stack_size(setup.l_max_world, setup.l_min_world);
    let units = 1u64 << (levels - 1);
    let peak = tf.peak();
    let mut stack: Vec<(Knot, usize)> = Vec::with_capacity(levels);
    let tops = ((t1 - t0) / setup.l_max_world).ceil() as u64;
    // With skipping the first knot (unless at a brick's face) is pending, counted as saved: the
    // first top's start looks for a run of empty blocks and resumes from a fresh knot, at the
    // start itself where its block is occupied (the kernel's PENDING).
    let mut pending = ray.skip.is_some() && head <= t0;
    let mut a = if pending {
        ray.count_skip(0.0, 1, 0);
        Knot {
            t: head,
            s: None,
            gradient: [0.0; 3],
        }
    } else {
        knot(ray, head)
    };
    let mut predicted = 0;
    let (mut k, mut position) = (0u64, 0u64);
    if head > t0 {
        // A brick's face inside the first top: one clipped interval to the first unit of the
        // deepest level past it, from where intervals are the undivided ray's dyadic ones.
        // Past the last covered unit, the tail takes it all.
        let u = setup.l_max_world / units as f64;
        position =
            (((head - t0) / u).ceil() as u64).min(top_limit(t0, t1, setup.l_max_world, units));
        let tb = t0 + position as f64 * u;
        if tb > head {
            let e = knot(ray, tb);
            let len = tb - head;
            let (error, _) = hermite_error(ray, setup, tf, &a, &e);
            ray.count_error(error, len, setup.spacing_world, peak);
            let whole = knot_segment(tables, &a, &e, len, None);
            emit_interval(ray, setup, tables, &a, &e, len, whole);
            a = e;
            if 1.0 - ray.transmittance > setup.early_termination {
                return;
            }
        }
    }
    'tops: while k < tops {
        let (t, depth, next) = loop {
            let start = t0 + k as f64 * setup.l_max_world;
            let limit = top_limit(start, t1, setup.l_max_world, units);
            if position == limit {
                if k + 1 == tops {
                    break 'tops;
                }
                k += 1;
                position = 0;
                continue;
            }
            let Some(&(e, depth)) = stack.last() else {
                // At a top's start: tops inside a run of empty blocks are skipped, and the
                // integration resumes from a fresh knot at the start of the top holding the
                // run's end. The top's empty part then costs at most its splits; a knot at the
                // last unit before the run's end cost the climb back to aligned intervals, about
                // log2(units)/2 evaluations, 1-13% more where rays skip (BENCHMARKS.md, "(ix)").
                if let Some(skip) = ray.skip.filter(|_| position == 0) {
                    let run = skip.run(ray.o, ray.d, start, t1, true);
                    let j = resume_interval(t0, setup.l_max_world, run, k);
                    if j >= tops || skip.reaches_end(run, t1) {
                        ray.count_skip(t1 - start, tops - k, 0);
                        return;
                    }
                    if j > k || pending {
                        ray.count_skip((j - k) as f64 * setup.l_max_world, j - k, 1);
                        break (t0 + j as f64 * setup.l_max_world, 0, Next::Restart(j));
                    }
                }
                // A new end at the controller's depth, or deeper until the interval is aligned
                // and inside the covered part of the top.
                let mut depth = predicted;
                while position % (units >> depth) != 0 || position + (units >> depth) > limit {
                    depth += 1;
                }
                let to = position + (units >> depth);
                let t = start + setup.l_max_world * (to as f64 / units as f64);
                break (t, depth, Next::End);
            };
            let len = setup.l_max_world * 0.5f64.powi(depth as i32);
            let can_split = depth + 1 < levels;
            let (error, mid) = hermite_error(ray, setup, tf, &a, &e);
            if can_split && error > setup.epsilon {
                break (0.5 * (a.t + e.t), depth, Next::Split);
            }
            predicted = predict_depth(depth, error, setup.epsilon);
            ray.count_error(error, len, setup.spacing_world, peak);
            // Accepted: the halves through the predicted midpoint when the hull holds no
            // isosurface value, else the whole interval split at the surfaces it crosses.
            match mid {
                Some(m) => {
                    // Adaptive setups build a table below the deepest level.
                    let half = Some(depth + 1);
                    let left = knot_segment(tables, &a, &m, 0.5 * len, half);
                    let right = knot_segment(tables, &m, &e, 0.5 * len, half);
                    emit_interval(ray, setup, tables, &a, &m, 0.5 * len, left);
                    emit_interval(ray, setup, tables, &m, &e, 0.5 * len, right);
                }
                None => {
                    let whole = knot_segment(tables, &a, &e, len, Some(depth));
                    emit_interval(ray, setup, tables, &a, &e, len, whole);
                }
            }
            stack.pop();
            position += units >> depth;
            a = e;
            if 1.0 - ray.transmittance > setup.early_termination {
                return;
            }
        };
        let m = knot(ray, t);
        match next {
            Next::End => stack.push((m, depth)),
            Next::Split => push_half(&mut stack, m, depth),
            // A restart is looked for only at a top's start, so the position is already 0.
            Next::Restart(j) => {
                a = m;
                pending = false;
                k = j;
            }
        }
    }
    // The tail: from the last covered unit to t1, clipped, without a test (a ray shorter
    // than one unit is all tail, its first knot still pending).
    if pending && k + 1 == tops {
        ray.count_skip(0.0, 0, 1);
        a = knot(ray, t0 + k as f64 * setup.l_max_world);
    }
    let len = t1 - a.t;
    if k + 1 == tops && len > 0.0 {
        let e = knot(ray, t1);
        let (error, _) = hermite_error(ray, setup, tf, &a, &e);
        ray.count_error(error, len, setup.spacing_world, peak);
        let whole = knot_segment(tables, &a, &e, len, None);
        emit_interval(ray, setup, tables, &a, &e, len, whole);
    }
}

/// What the Hermite integrator's one evaluation per iteration is for.
enum Next {
    /// A new pending end.
    End,
    /// The midpoint of the rejected interval on top of the stack.
    Split,
    /// The start of top j, after a run of empty blocks.
    Restart(u64),
}

/// Units of the deepest level that the Hermite integrator covers in the top starting at
/// `start`: all of them in a full top, ⌊r/u⌋ of the last one (length r = t1 − start).
fn top_limit(start: f64, t1: f64, l_max: f64, units: u64) -> u64 {
    if start + l_max <= t1 {
        units
    } else {
        (((t1 - start) / l_max * units as f64).floor().max(0.0) as u64).min(units)
    }
}

/// Both halves of the stack's top interval are one level deeper; the left one (closed by `m`)
/// is processed first.
fn push_half(stack: &mut Vec<(Knot, usize)>, m: Knot, depth: usize) {
    if let Some(top) = stack.last_mut() {
        top.1 = depth + 1;
    }
    stack.push((m, depth + 1));
}

#[cfg(test)]
mod tests {
    use super::super::interval::{bezier_hull, hermite_midpoint};
    use super::{predict_depth, top_limit};

    /// The cubic Hermite on u ∈ [0, 1] with the given end values and derivatives.
    fn hermite(f0: f64, f1: f64, m0: f64, m1: f64, u: f64) -> f64 {
        let (d, a, b) = (f1 - f0, m0 - (f1 - f0), m1 - (f1 - f0));
        f0 + d * u + a * u * (1.0 - u) * (1.0 - u) - b * u * u * (1.0 - u)
    }

    #[test]
    fn bezier_hull_bounds_the_cubic_and_its_departure_from_the_chord() {
        let cases = [
            (0.2, 0.7, 0.5, 0.5),
            (0.0, 0.0, 1.0, -1.0),
            (0.3, 0.1, -2.0, 1.5),
            (1.0, 2.0, 3.0, -0.5),
        ];
        for (f0, f1, m0, m1) in cases {
            let (lo, hi, dev) = bezier_hull(f0, f1, m0, m1);
            let mut worst = 0.0f64;
            for i in 0..=1000 {
                let u = f64::from(i) / 1000.0;
                let h = hermite(f0, f1, m0, m1, u);
                assert!(
                    lo - 1e-12 <= h && h <= hi + 1e-12,
                    "{h} outside [{lo}, {hi}]"
                );
                worst = worst.max((h - (f0 + (f1 - f0) * u)).abs());
            }
            assert!(worst <= dev + 1e-12, "departure {worst} above D = {dev}");
            // D is within a factor 3 of the real departure whenever there is one.
            assert!(
                dev <= 3.0 * worst + 1e-12,
                "D = {dev} loose against {worst}"
            );
        }
        // A line departs from nothing.
        assert_eq!(bezier_hull(0.1, 0.5, 0.4, 0.4).2, 0.0);
    }

    #[test]
    fn predicted_midpoint_is_exact_for_cubics() {
        // hermite_midpoint: 0.5·(f0 + f1) + (m0 − m1)/8, and hermite_error's derivative
        // 1.5·Δ − (m0 + m1)/4, against p(u) = 2u³ − u² + 0.5u + 0.1.
        let p = |u: f64| 2.0 * u * u * u - u * u + 0.5 * u + 0.1;
        let dp = |u: f64| 6.0 * u * u - 2.0 * u + 0.5;
        let (f0, f1, m0, m1) = (p(0.0), p(1.0), dp(0.0), dp(1.0));
        let sm = hermite_midpoint(f0, f1, m0, m1);
        let mm = 1.5 * (f1 - f0) - 0.25 * (m0 + m1);
        assert!((sm - p(0.5)).abs() < 1e-14 && (mm - dp(0.5)).abs() < 1e-14);
    }

    #[test]
    fn controller_grows_one_level_only_with_a_fourfold_margin() {
        // An interval without any error returns to the top level.
        assert_eq!(predict_depth(3, 0.0, 0.01), 0);
        assert_eq!(predict_depth(3, 1e-30, 0.01), 2);
        assert_eq!(predict_depth(3, 0.01 * 0.81 / 4.0, 0.01), 2);
        assert_eq!(predict_depth(3, 0.01 * 0.81 / 4.0 * 1.01, 0.01), 3);
        assert_eq!(predict_depth(0, 0.0, 0.01), 0);
    }

    #[test]
    fn last_top_is_covered_in_whole_units_and_never_past_the_exit() {
        // 16 units of 0.25 in a top of 4.
        assert_eq!(top_limit(0.0, 10.0, 4.0, 16), 16);
        assert_eq!(top_limit(8.0, 12.0, 4.0, 16), 16);
        assert_eq!(top_limit(8.0, 11.9, 4.0, 16), 15);
        assert_eq!(top_limit(8.0, 8.2, 4.0, 16), 0);
        assert_eq!(top_limit(8.0, 7.9, 4.0, 16), 0);
        for i in 0..1000 {
            let r = 4.0 * f64::from(i) / 1000.0;
            let n = top_limit(1.0, 1.0 + r, 4.0, 16);
            let covered = f64::from(n as u32) * 0.25;
            assert!(
                covered <= r + 1e-12 && r - covered < 0.25 + 1e-12,
                "r {r}: {n} units"
            );
        }
    }
}
