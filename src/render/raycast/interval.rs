//! Knots and interval emission, f64 twin of `knot`, `emit_interval` and `locate_crossing` in
//! `glsl/raycast.comp` (stage `composite_interval`).
//!
//! An interval [a, e] is composited from the tables (its own table when it is a full-length
//! one, else the clipped composite). Where an isosurface value v lies between the interval's end
//! scalars, the interval is split there ([MLS] §4): the crossing is located by regula falsi with
//! the Illinois modification (at most `LOCATE_ITERATIONS` evaluations, stopping when
//! |f − v| ≤ 1e-6 or the bracket is below 1e-6 of the interval), shaded with the MLS gradient
//! there, and composited between the two clipped sub-intervals. A crossing counts for the
//! interval (a, e]: a knot exactly at v belongs to the interval that ends there, never to two.

use super::Ray;
use crate::render::RaySetup;
use crate::render::preintegration::PreintegrationTables;
use crate::render::shading::shade_surface;

/// Evaluations spent locating one crossing, at most.
pub(super) const LOCATE_ITERATIONS: u32 = 12;

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
    match crate::recon::mls::mls_evaluate(&ray.mls, ray.neighbours, x) {
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
            let v = tables.lookup(&tables.tables[k], sa, se);
            ([v[0], v[1], v[2]], v[3])
        }
        None => tables.segment(sa, se, len),
    }
}

/// Composites [a, e] (of exactly `len`) into the ray, split at isosurface crossings. `plain` is
/// the interval's [`knot_segment`], which the callers have already looked up; it is used as it
/// is when no isosurface is crossed.
pub(super) fn emit_interval(
    ray: &mut Ray<'_>,
    setup: &RaySetup,
    tables: &PreintegrationTables,
    a: &Knot,
    e: &Knot,
    len: f64,
    plain: ([f64; 3], f64),
) {
    let (Some(sa), Some(se)) = (a.s, e.s) else {
        return;
    };
    let hits = crossings(ray, setup, a, e, sa, se);
    if hits.is_empty() {
        ray.composite(plain.0, plain.1);
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

/// Composites the isosurfaces crossed between two midpoint samples (riemann, reference).
pub(super) fn emit_crossings(ray: &mut Ray<'_>, setup: &RaySetup, a: &Knot, e: &Knot) {
    let (Some(sa), Some(se)) = (a.s, e.s) else {
        return;
    };
    for (hit, i) in crossings(ray, setup, a, e, sa, se) {
        let iso = &setup.isosurfaces[i];
        let c = shade_surface(iso, &setup.lighting, hit.gradient, ray.d);
        ray.composite(c, iso.opacity);
    }
}
