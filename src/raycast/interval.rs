//! Knots and interval emission, f64 twin of `knot`, `emit_interval` and `locate_crossing` in
//! `glsl/raycast/raycast.comp` (stage `composite_interval`).
//!
//! An interval [a, e] is composited from the tables (its own table when it is a full-length
//! one, else the clipped composite). Where an isosurface value v lies between the interval's end
//! scalars, the interval is split there ([MLS] §4): the crossing is located by regula falsi with
//! the Illinois modification (at most `LOCATE_ITERATIONS` evaluations, stopping when
//! |f − v| ≤ 1e-6 or the bracket is below 1e-6 of the interval), shaded with the MLS gradient
//! there, and composited between the two clipped sub-intervals. A crossing counts for the
//! interval (a, e]: a knot exactly at v belongs to the interval that ends there, never to two.
//!
//! Near-tangent rays cross a surface twice between two knots on the same side of it. Where the
//! directional derivative changes sign across [a, e] and the extremum points towards an
//! isosurface beyond both ends, the cubic Hermite through the knots' values and directional
//! derivatives predicts the extremum (`hermite_extremum`); f is evaluated there (at most
//! `EXTREMUM_ITERATIONS` times, keeping the half where the derivative still changes sign) until
//! it reaches the isosurface. The interval is then split at that knot into two monotone pieces,
//! each composited as above. The search gives up when the predicted excursion beyond the ends is
//! less than half the distance to the surface: the Hermite is exact for quadratics, so a miss
//! needs a large fourth-derivative term.

use super::ray::Ray;
use crate::raycast::RaySetup;
use crate::view::preintegration::PreintegrationTables;
use crate::view::shading::shade_surface;

/// Evaluations spent locating one crossing, at most.
pub(super) const LOCATE_ITERATIONS: u32 = 12;

/// Evaluations spent searching for the extremum between two knots, at most.
pub(super) const EXTREMUM_ITERATIONS: u32 = 3;

/// Bisection steps on the Hermite's derivative (no evaluations of f).
const HERMITE_BISECTIONS: u32 = 24;

/// A point on the ray: parameter, scalar (None where f is undefined) and gradient.
#[derive(Debug, Clone, Copy)]
pub(super) struct Knot {
    pub(super) t: f64,
    pub(super) s: Option<f64>,
    pub(super) gradient: [f64; 3],
}

impl Knot {
    /// Directional derivative along the ray.
    pub(super) fn slope(&self, ray: &Ray<'_>) -> f64 {
        self.gradient[0] * ray.d.x + self.gradient[1] * ray.d.y + self.gradient[2] * ray.d.z
    }
}

/// Evaluates f (one counted evaluation) at parameter t.
pub(super) fn knot(ray: &mut Ray<'_>, t: f64) -> Knot {
    ray.evaluations += 1;
    let x = (ray.o + ray.d * t).to_array();
    match ray.field.evaluate(ray.neighbours, x) {
        Some(m) => Knot {
            t,
            s: Some(m.value),
            gradient: m.gradient,
        },
        None => Knot {
            t,
            s: None,
            gradient: [0.0; 3],
        },
    }
}

/// Whether f crosses v in (a, e].
pub(super) fn crosses(sa: f64, se: f64, v: f64) -> bool {
    (sa - v) * (se - v) < 0.0 || (se == v && sa != v)
}

/// The knot where f = v between a and e (which bracket v), by Illinois regula falsi.
pub(super) fn locate_crossing(ray: &mut Ray<'_>, a: &Knot, e: &Knot, v: f64) -> Knot {
    let (Some(sa), Some(se)) = (a.s, e.s) else {
        return *e;
    };
    if se == v {
        // Knot exactly on the surface: evaluated again for its gradient, as the kernel does.
        return knot(ray, e.t);
    }
    let (mut lo, mut hi) = (*a, *e);
    let (mut flo, mut fhi) = (sa - v, se - v);
    let width = e.t - a.t;
    let mut best = *e;
    for _ in 0..LOCATE_ITERATIONS {
        let t = (lo.t - flo * (hi.t - lo.t) / (fhi - flo)).clamp(lo.t, hi.t);
        let k = knot(ray, t);
        let Some(sk) = k.s else {
            return best;
        };
        best = k;
        let fk = sk - v;
        if fk.abs() <= 1e-6 || (hi.t - lo.t) <= 1e-6 * width {
            break;
        }
        if (fk < 0.0) == (flo < 0.0) {
            lo = k;
            flo = fk;
            fhi *= 0.5;
        } else {
            hi = k;
            fhi = fk;
            flo *= 0.5;
        }
    }
    best
}

/// The extremum of the cubic Hermite on u ∈ [0, 1] with end values p0, p1 and end derivatives
/// m0, m1 (per unit u), which must have opposite signs: (u, p(u)) where p'(u) = 0. p' is the
/// quadratic m0 + 2(3Δ − 2m0 − m1)u + 3(m0 + m1 − 2Δ)u², Δ = p1 − p0, with exactly one root in
/// (0, 1); it is bisected so that the f32 twin takes the same path.
fn hermite_extremum(p0: f64, p1: f64, m0: f64, m1: f64) -> (f64, f64) {
    let delta = p1 - p0;
    let b = 3.0 * delta - 2.0 * m0 - m1;
    let c = m0 + m1 - 2.0 * delta;
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    for _ in 0..HERMITE_BISECTIONS {
        let u = 0.5 * (lo + hi);
        let slope = m0 + u * (2.0 * b + 3.0 * c * u);
        if (slope > 0.0) == (m0 > 0.0) {
            lo = u;
        } else {
            hi = u;
        }
    }
    let u = 0.5 * (lo + hi);
    (u, p0 + u * (m0 + u * (b + c * u)))
}

/// For [a, e] whose directional derivative changes sign: the knot at the extremum between them
/// once f there reaches the nearest isosurface beyond both ends on the extremum's side, or None.
fn split_at_extremum(ray: &mut Ray<'_>, setup: &RaySetup, a: &Knot, e: &Knot) -> Option<Knot> {
    let (sa, se) = (a.s?, e.s?);
    let (ga, ge) = (a.slope(ray), e.slope(ray));
    if ga * ge >= 0.0 {
        return None;
    }
    // Work in the extremum's orientation: a maximum of sign·f.
    let sign = if ga > 0.0 { 1.0 } else { -1.0 };
    let top = (sign * sa).max(sign * se);
    let v = setup
        .isosurfaces
        .iter()
        .map(|iso| sign * iso.value)
        .filter(|&v| v > top)
        .min_by(f64::total_cmp)?;
    let (mut lo, mut hi) = ((a.t, sign * sa, sign * ga), (e.t, sign * se, sign * ge));
    for _ in 0..EXTREMUM_ITERATIONS {
        let w = hi.0 - lo.0;
        let (u, peak) = hermite_extremum(lo.1, hi.1, lo.2 * w, hi.2 * w);
        if v - peak > peak - lo.1.max(hi.1) {
            return None;
        }
        let k = knot(ray, lo.0 + u * w);
        let s = sign * k.s?;
        if s >= v {
            return Some(k);
        }
        let g = sign * k.slope(ray);
        if g > 0.0 {
            lo = (k.t, s, g);
        } else if g < 0.0 {
            hi = (k.t, s, g);
        } else {
            return None;
        }
    }
    None
}

/// The located crossings of [a, e] (scalars sa, se) with every isosurface, sorted along the ray,
/// with the index of the isosurface.
fn crossings(
    ray: &mut Ray<'_>,
    setup: &RaySetup,
    a: &Knot,
    e: &Knot,
    sa: f64,
    se: f64,
) -> Vec<(Knot, usize)> {
    let mut hits: Vec<(Knot, usize)> = Vec::new();
    for (i, iso) in setup.isosurfaces.iter().enumerate() {
        if crosses(sa, se, iso.value) {
            hits.push((locate_crossing(ray, a, e, iso.value), i));
        }
    }
    hits.sort_by(|x, y| x.0.t.total_cmp(&y.0.t));
    hits
}

/// (C, α) of [a, e] of exactly `len` from the tables: table `level` for a full-length interval
/// (whose length is then `lengths[level]` by construction), else the clipped composite.
/// Undefined ends contribute nothing.
pub(super) fn knot_segment(
    tables: &PreintegrationTables,
    a: &Knot,
    e: &Knot,
    len: f64,
    level: Option<usize>,
) -> ([f64; 3], f64) {
    let (Some(sa), Some(se)) = (a.s, e.s) else {
        return ([0.0; 3], 0.0);
    };
    match level {
        Some(k) => {
            let v = tables.entry(k, sa, se);
            ([v[0], v[1], v[2]], v[3])
        }
        None => tables.segment(sa, se, len),
    }
}

/// The Bézier hull [lo, hi] of the cubic Hermite with end values f0, f1 and end derivatives
/// m0, m1 (per unit of its interval), and D, its largest departure from the chord.
pub(super) fn bezier_hull(f0: f64, f1: f64, m0: f64, m1: f64) -> (f64, f64, f64) {
    let delta = f1 - f0;
    let (b1, b2) = (f0 + m0 / 3.0, f1 - m1 / 3.0);
    let lo = f0.min(f1).min(b1.min(b2));
    let hi = f0.max(f1).max(b1.max(b2));
    (lo, hi, (m0 - delta).abs().max((m1 - delta).abs()) / 3.0)
}

/// The cubic Hermite's value at the middle of its interval, from its end values and end
/// derivatives per unit of the interval (exact for cubics).
pub(super) fn hermite_midpoint(f0: f64, f1: f64, m0: f64, m1: f64) -> f64 {
    0.5 * (f0 + f1) + 0.125 * (m0 - m1)
}

/// Stage `hermite_segment` (`render.interval = "hermite"`): (C, α) of the full-length
/// interval [a, e] composited as two halves through the midpoint of the cubic Hermite that
/// the knots' values and directional derivatives define, from table `level + 1` (half the
/// length). The midpoint is exact for cubic f along the ray, where the linear segment's error
/// is of the order of the second derivative. None when an end is undefined or an isosurface
/// value lies in the Hermite's Bézier hull: such an interval stays linear, so that its
/// surfaces are located between its knots as usual.
pub(super) fn hermite_segment(
    ray: &Ray<'_>,
    setup: &RaySetup,
    tables: &PreintegrationTables,
    a: &Knot,
    e: &Knot,
    level: usize,
) -> Option<([f64; 3], f64)> {
    let (f0, f1) = (a.s?, e.s?);
    let l = e.t - a.t;
    let (m0, m1) = (l * a.slope(ray), l * e.slope(ray));
    let (lo, hi, _) = bezier_hull(f0, f1, m0, m1);
    if setup
        .isosurfaces
        .iter()
        .any(|iso| lo <= iso.value && iso.value <= hi)
    {
        return None;
    }
    let sm = hermite_midpoint(f0, f1, m0, m1);
    let c0 = tables.entry(level + 1, f0, sm);
    let c1 = tables.entry(level + 1, sm, f1);
    let through = 1.0 - c0[3];
    Some((
        [
            c0[0] + through * c1[0],
            c0[1] + through * c1[1],
            c0[2] + through * c1[2],
        ],
        c0[3] + through * c1[3],
    ))
}

/// Composites [a, e] (of exactly `len`) into the ray, split at isosurface crossings and, for a
/// near-tangent double crossing, at the extremum between them. `plain` is the interval's
/// [`knot_segment`], which the callers have already looked up; it is used as it is when no
/// isosurface is crossed.
pub(super) fn emit_interval(
    ray: &mut Ray<'_>,
    setup: &RaySetup,
    tables: &PreintegrationTables,
    a: &Knot,
    e: &Knot,
    len: f64,
    plain: ([f64; 3], f64),
) {
    if setup.isosurfaces.is_empty() {
        ray.composite(plain.0, plain.1);
        return;
    }
    match split_at_extremum(ray, setup, a, e) {
        Some(m) => {
            let scale = len / (e.t - a.t);
            emit_monotone(ray, setup, tables, a, &m, (m.t - a.t) * scale, None);
            emit_monotone(ray, setup, tables, &m, e, (e.t - m.t) * scale, None);
        }
        None => emit_monotone(ray, setup, tables, a, e, len, Some(plain)),
    }
}

/// Composites [a, e] (of exactly `len`), split at the isosurfaces it crosses; `plain`, when
/// given, is its table segment, else the clipped composite is looked up.
fn emit_monotone(
    ray: &mut Ray<'_>,
    setup: &RaySetup,
    tables: &PreintegrationTables,
    a: &Knot,
    e: &Knot,
    len: f64,
    plain: Option<([f64; 3], f64)>,
) {
    let (Some(sa), Some(se)) = (a.s, e.s) else {
        return;
    };
    let hits = crossings(ray, setup, a, e, sa, se);
    if hits.is_empty() {
        let (c, alpha) = plain.unwrap_or_else(|| tables.segment(sa, se, len));
        ray.composite(c, alpha);
        return;
    }
    let (mut t, mut s) = (a.t, sa);
    let scale = len / (e.t - a.t);
    for (hit, i) in hits {
        let iso = &setup.isosurfaces[i];
        let piece = (hit.t - t) * scale;
        if piece > 0.0 {
            let (c, alpha) = tables.segment(s, iso.value, piece);
            ray.composite(c, alpha);
        }
        let c = shade_surface(iso, &setup.lighting, hit.gradient, ray.d);
        ray.composite(c, iso.opacity);
        (t, s) = (hit.t, iso.value);
    }
    let piece = (e.t - t) * scale;
    if piece > 0.0 {
        let (c, alpha) = tables.segment(s, se, piece);
        ray.composite(c, alpha);
    }
}

/// Composites the isosurfaces crossed between two midpoint samples (riemann, reference),
/// including near-tangent double crossings.
pub(super) fn emit_crossings(ray: &mut Ray<'_>, setup: &RaySetup, a: &Knot, e: &Knot) {
    match split_at_extremum(ray, setup, a, e) {
        Some(m) => {
            emit_surfaces(ray, setup, a, &m);
            emit_surfaces(ray, setup, &m, e);
        }
        None => emit_surfaces(ray, setup, a, e),
    }
}

/// Composites the shaded isosurfaces crossed in (a, e].
fn emit_surfaces(ray: &mut Ray<'_>, setup: &RaySetup, a: &Knot, e: &Knot) {
    let (Some(sa), Some(se)) = (a.s, e.s) else {
        return;
    };
    for (hit, i) in crossings(ray, setup, a, e, sa, se) {
        let iso = &setup.isosurfaces[i];
        let c = shade_surface(iso, &setup.lighting, hit.gradient, ray.d);
        ray.composite(c, iso.opacity);
    }
}

#[cfg(test)]
mod tests {
    use super::hermite_extremum;

    #[test]
    fn hermite_extremum_is_exact_for_cubics() {
        // p(u) = 1 − 4(u − 0.3)²: maximum 1 at 0.3 (the Hermite reproduces quadratics).
        let (u, p) = hermite_extremum(1.0 - 4.0 * 0.09, 1.0 - 4.0 * 0.49, 2.4, -5.6);
        assert!((u - 0.3).abs() < 1e-6 && (p - 1.0).abs() < 1e-10, "{u} {p}");
        // p(u) = u³ − 1.5u² + 0.5u + 2 has its minimum at (3 + √3)/6 ≈ 0.7887. On [0.3, 1],
        // p' goes from −0.13 to +0.5, and the Hermite there is the cubic itself.
        let p3 = |u: f64| u * u * u - 1.5 * u * u + 0.5 * u + 2.0;
        let d3 = |u: f64| 3.0 * u * u - 3.0 * u + 0.5;
        let (a, b) = (0.3, 1.0);
        let w = b - a;
        let (u, p) = hermite_extremum(p3(a), p3(b), d3(a) * w, d3(b) * w);
        let want = (3.0 + 3f64.sqrt()) / 6.0;
        assert!((a + u * w - want).abs() < 1e-6, "{}", a + u * w);
        assert!((p - p3(want)).abs() < 1e-10, "{p}");
    }
}
