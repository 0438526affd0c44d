//! [MLS] §4 adaptive subdivision, f64 twin of `integrate` (RAY_METHOD 2) in
//! `glsl/raycast.comp`.
//!
//! The ray is cut into top intervals of l_max (the last one clipped at the exit). An interval
//! [a, e] with scalars s_a, s_e is compared with its two halves: C1 = table(len)(s_a, s_e),
//! C2 = the halves composited (one new evaluation at the midpoint). It is accepted when
//! (1 − α_acc)·|C1 − C2| ≤ ε·|C1| (|·| the RGB norm) and the directional derivative does not
//! change sign (∇f(a)·v · ∇f(e)·v ≥ 0, which could hide an isosurface), or when its half would
//! be shorter than l_min; accepted intervals composite C2. Otherwise the midpoint is pushed
//! and the left half is processed first, since its α is needed for the right half's test. The
//! stack holds pending interval ends with their depths, strictly deeper towards the top except
//! for the two halves of the last split: at most ⌊log2(l_max/l_min)⌋ + 1 entries.

use super::Ray;
use super::interval::{Knot, emit_interval, knot, knot_segment};
use crate::render::RaySetup;
use crate::render::preintegration::PreintegrationTables;

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

/// Integrates [t0, t1] adaptively into `ray`. Each pending end carries the depth of the interval
/// it closes, so lengths are exact (top length · 2^−depth) and, for full-length top intervals,
/// equal table `depth` without comparing floats.
pub(super) fn integrate(
    ray: &mut Ray<'_>,
    setup: &RaySetup,
    tables: &PreintegrationTables,
    t0: f64,
    t1: f64,
) {
    let levels = stack_size(setup.l_max, setup.l_min);
    let mut stack: Vec<(Knot, usize)> = Vec::with_capacity(levels);
    // Top interval k is [t0 + k·l_max, min(t0 + (k+1)·l_max, t1)]: computed from k, not
    // accumulated, so that the kernel can start a chunk at any k.
    let tops = ((t1 - t0) / setup.l_max).ceil() as u64;
    let mut a = knot(ray, t0);
    for k in 0..tops {
        let end = t0 + (k + 1) as f64 * setup.l_max;
        let full = end <= t1;
        let top = if full { setup.l_max } else { t1 - a.t };
        if top <= 0.0 {
            return;
        }
        stack.push((knot(ray, if full { end } else { t1 }), 0));
        while let Some(&(e, depth)) = stack.last() {
            let len = top * 0.5f64.powi(depth as i32);
            let level = full.then_some(depth);
            let whole = knot_segment(tables, &a, &e, len, level);
            let c1 = whole.0;
            let can_split = depth + 1 < levels && (full || 0.5 * len >= setup.l_min);
            if can_split {
                let m = knot(ray, 0.5 * (a.t + e.t));
                let half = level.map(|k| k + 1);
                let left = knot_segment(tables, &a, &m, 0.5 * len, half);
                let right = knot_segment(tables, &m, &e, 0.5 * len, half);
                let c2 = [0, 1, 2].map(|k| left.0[k] + (1.0 - left.1) * right.0[k]);
                let diff = norm([0, 1, 2].map(|k| c1[k] - c2[k]));
                let sign_change = a.slope(ray) * e.slope(ray) < 0.0;
                if sign_change || ray.transmittance * diff > setup.epsilon * norm(c1) {
                    // Both halves are one level deeper; the left one is processed first.
                    if let Some(top) = stack.last_mut() {
                        top.1 = depth + 1;
                    }
                    stack.push((m, depth + 1));
                    continue;
                }
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
