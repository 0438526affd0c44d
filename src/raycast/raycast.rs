//! Emission–absorption ray casting, f64 CPU twin of `glsl/raycast/raycast.comp` (stage `raycast`).
//!
//! Per ray: clip to the sample box, then integrate with the setup's method ([MLS] §4):
//! - `riemann`/`reference`: n = ⌈L/δ⌉ midpoint steps of length δ (the last one shortened to end
//!   at the exit); per step a = 1 − exp(−τ(s)·δ), C += T·a·c(s), T *= 1 − a; stop when
//!   T < min_transmittance;
//! - `fixed`: preintegration, s evaluated at interval ends, one table lookup per interval, or
//!   with `render.interval = "hermite"` two of the half step's table through the cubic
//!   Hermite's predicted midpoint (`hermite_segment`);
//! - `adaptive`: dyadic subdivision with [MLS]'s or the Hermite criterion (see `adaptive`).
//!
//! Where no sample has weight the field is undefined: a midpoint step there adds nothing, and
//! so does a preintegrated interval with an undefined end. Pixel = (C + T·background, 1 − T).

use super::adaptive;
use super::interval::{Knot, emit_crossings, emit_interval, hermite_segment, knot, knot_segment};
use super::ray::{Ray, Skip, resume_interval};
use super::setup::RaySetup;
use crate::field::Field;
use crate::field::skip::{SkipReport, SkipTable};
use crate::recon::ReconError;
use crate::recon::mls::Neighbours;
use crate::samples::bvh::Segments;
use crate::view::camera::clip_box;
use crate::view::preintegration::PreintegrationTables;
use crate::view::transfer::TransferFunction;
use crate::view::{IntervalModel, Method};
use glam::DVec3;
use rayon::prelude::*;

/// One pixel of the reference integrator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelResult {
    pub rgba: [f64; 4],
    /// MLS evaluations spent on this ray.
    pub evaluations: u32,
    /// Empty-space skipping: ray length skipped and evaluations saved (see
    /// [`crate::field::skip::SkipReport`]), and the ray's length inside the domain.
    pub skipped_length: f64,
    pub evaluations_saved: u32,
    pub inside_length: f64,
    /// The adaptive integrator's error estimate of the pixel (0 for the other methods; see
    /// [`crate::renderer::GpuImage::error_estimate`]).
    pub error_estimate: f64,
    /// The ray crossed the hull more often than `bvh::MAX_HITS`: nothing was integrated (the
    /// GPU renderer fails with an error for such a ray).
    pub hull_overflow: bool,
}

/// Midpoint rule (`riemann`, `reference`): n = ⌈L/δ⌉ steps, the last one shortened; isosurfaces
/// crossed between consecutive samples are composited before the later sample's step. With
/// isosurfaces, f is also evaluated at the entry and the exit, so that a surface in the half
/// step before the first sample or after the last is not missed. Steps are counted from t0;
/// the first starts at `head` ≥ t0 (a brick's face, [`anchored`]; t0 otherwise).
fn integrate_riemann(
    ray: &mut Ray<'_>,
    setup: &RaySetup,
    tf: &TransferFunction,
    (t0, head, t1): (f64, f64, f64),
) {
    let steps = ((t1 - t0) / setup.step_world).ceil() as u64;
    let isos = !setup.isosurfaces.is_empty();
    let mut prev: Option<Knot> = isos.then(|| knot(ray, head));
    let mut occupied_until = f64::NEG_INFINITY;
    let mut i = 0;
    while i < steps {
        let ta = (t0 + i as f64 * setup.step_world).max(head);
        let dt = (t0 + (i + 1) as f64 * setup.step_world).min(t1) - ta;
        if dt <= 0.0 {
            break;
        }
        let tm = ta + 0.5 * dt;
        // A midpoint in an empty block adds nothing: resume at the first midpoint past the run
        // of empty blocks; with isosurfaces the knot at its end stands in for the skipped
        // samples.
        if let Some(skip) = ray.skip.filter(|_| tm >= occupied_until) {
            let (empty, exit) = skip.span(ray.o, ray.d, tm, t1);
            if empty {
                let j = resume_interval(t0 - 0.5 * setup.step_world, setup.step_world, exit, i + 1);
                let to = j.min(steps);
                let len = (t0 + to as f64 * setup.step_world).min(t1) - ta;
                ray.count_skip(len, to - i, u64::from(isos));
                if isos {
                    prev = Some(knot(ray, exit.min(t1)));
                }
                i = j;
                continue;
            }
            occupied_until = exit;
        }
        i += 1;
        let k = knot(ray, tm);
        if let Some(p) = prev.filter(|_| isos) {
            emit_crossings(ray, setup, &p, &k);
        }
        prev = Some(k);
        let Some(s) = k.s else {
            continue;
        };
        let (c, tau) = tf.lookup(s);
        let a = 1.0 - (-tau * dt).exp();
        ray.composite(c.map(|x| x * a), a);
        if ray.transmittance < setup.min_transmittance {
            return;
        }
    }
    if let Some(p) = prev.filter(|_| isos) {
        let k = knot(ray, t1);
        emit_crossings(ray, setup, &p, &k);
    }
}

/// Preintegration with a constant step l (`fixed`): s at interval ends, one lookup of the
/// l-table per interval; the last, shorter interval uses the clipped composite, and so does the
/// first where it starts at `head` > t0 (a brick's face, [`anchored`]). With skipping, the knot
/// that starts the ray (unless at a brick's face) or resumes it after a run of empty blocks is
/// pending until an interval needs it, counted as saved until then: a ray that starts inside
/// an empty run does not evaluate where it only skips.
fn integrate_fixed(
    ray: &mut Ray<'_>,
    setup: &RaySetup,
    tables: &PreintegrationTables,
    (t0, head, t1): (f64, f64, f64),
) {
    let l = setup.step_world;
    let steps = ((t1 - t0) / l).ceil() as u64;
    let mut prev = if ray.skip.is_some() && head <= t0 {
        ray.count_skip(0.0, 1, 0);
        None
    } else {
        Some(knot(ray, head))
    };
    let mut occupied_until = f64::NEG_INFINITY;
    let mut i = 0;
    while i < steps {
        let ta = (t0 + i as f64 * l).max(head);
        let tb = (t0 + (i + 1) as f64 * l).min(t1);
        if tb <= ta {
            break;
        }
        // Intervals inside a run of empty blocks are skipped; the first one reaching past it
        // starts from a fresh knot.
        if let Some(skip) = ray.skip.filter(|_| ta >= occupied_until) {
            let (empty, exit) = skip.span(ray.o, ray.d, ta, t1);
            if empty {
                let j = resume_interval(t0, l, exit, i);
                if j >= steps || skip.reaches_end(exit, t1) {
                    ray.count_skip(t1 - ta, steps - i, 0);
                    break;
                }
                if j > i {
                    ray.count_skip((j - i) as f64 * l, j - i, 0);
                    prev = None;
                    i = j;
                    continue;
                }
            } else {
                occupied_until = exit;
            }
        }
        let prev_knot = match prev {
            Some(p) => p,
            None => {
                ray.count_skip(0.0, 0, 1);
                knot(ray, ta)
            }
        };
        let next = knot(ray, tb);
        let full = i + 1 < steps && !(i == 0 && head > t0);
        let hermite = (full && setup.interval == IntervalModel::Hermite)
            .then(|| hermite_segment(ray, setup, tables, &prev_knot, &next, 0))
            .flatten();
        let plain = hermite
            .unwrap_or_else(|| knot_segment(tables, &prev_knot, &next, tb - ta, full.then_some(0)));
        emit_interval(ray, setup, tables, &prev_knot, &next, tb - ta, plain);
        prev = Some(next);
        if 1.0 - ray.transmittance > setup.early_termination {
            break;
        }
        i += 1;
    }
}

/// The part of an inside segment (t0, t1) that a ray integrates: all of it, or for a brick of a
/// decomposed field (`brick`, the ray's parameters inside the brick's box, `None` if it misses
/// the box) the part inside the box, as (start, head, end): steps of length `step` counted
/// from the segment's start t0 as the undivided field's are (so that the bricks' samples are
/// the one-device frame's), `start` the last step position at or before the face, `head` the
/// face. Twin of the window in raycast.comp's main().
pub fn anchored(
    (t0, t1): (f64, f64),
    brick: Option<Option<(f64, f64)>>,
    step: f64,
) -> Option<(f64, f64, f64)> {
    match brick {
        None => Some((t0, t0, t1)),
        Some(None) => None,
        Some(Some((c0, c1))) => {
            let (w0, w1) = (t0.max(c0), t1.min(c1));
            (w1 > w0).then(|| {
                let mut start = t0 + ((w0 - t0) / step).floor() * step;
                // The floor may land a step short when the face is on a step.
                if start + step <= w0 {
                    start += step;
                }
                (start, w0, w1)
            })
        }
    }
}

/// [`clip_box`] for a brick `(lo, hi)` of a domain whose box ends at `domain_hi` (twin of
/// clip_brick in raycast.comp): a ray parallel to a face that lies exactly on a face shared with
/// the next brick up belongs to that brick only (as a sample on a plane does), so that no ray
/// is integrated by two bricks.
pub fn clip_brick(
    o: DVec3,
    d: DVec3,
    (lo, hi): (DVec3, DVec3),
    domain_hi: DVec3,
) -> Option<(f64, f64)> {
    if (0..3).any(|a| d[a].abs() < 1e-30 && o[a] == hi[a] && hi[a] < domain_hi[a]) {
        return None;
    }
    clip_box(o, d, lo, hi)
}

/// Integrates the ray through pixel (px, py) with the setup's method. `tables` must be the
/// setup's preintegration tables for the preintegrated methods; `skip`, the frame's
/// empty-space skipping data when the setup skips.
#[allow(clippy::too_many_arguments)]
pub fn raycast(
    setup: &RaySetup,
    field: &Field,
    neighbours: &dyn Neighbours,
    tf: &TransferFunction,
    tables: Option<&PreintegrationTables>,
    skip: Option<Skip<'_>>,
    px: u32,
    py: u32,
) -> PixelResult {
    let (o, d) = setup.camera.ray(&setup.basis, setup.frame_origin, px, py);
    let mut ray = Ray {
        o,
        d,
        field,
        neighbours,
        skip,
        color: [0.0; 3],
        transmittance: 1.0,
        evaluations: 0,
        skipped: 0.0,
        saved: 0,
        error_estimate: 0.0,
    };
    let (segments, hull_overflow) = match &field.hull {
        None => (
            clip_box(o, d, setup.box_lo, setup.box_hi)
                .into_iter()
                .collect(),
            false,
        ),
        Some(bvh) => match bvh.segments(o.to_array(), d.to_array()) {
            Segments::List(s) => (s, false),
            Segments::Overflow => (Vec::new(), true),
        },
    };
    let inside_length = segments.iter().map(|(t0, t1)| t1 - t0).sum();
    let brick = setup.clip.map(|c| clip_brick(o, d, c, setup.box_hi));
    // Steps (the adaptive integrator's top intervals) are counted from each segment's start.
    let step = match setup.method {
        Method::Adaptive => setup.l_max_world,
        _ => setup.step_world,
    };
    // Each inside segment is integrated on its own, with clipped intervals at its ends
    // ([MLS] §4); the ray stops at the method's termination.
    for segment in segments {
        let Some(window) = anchored(segment, brick, step) else {
            continue;
        };
        match (setup.method, tables) {
            (Method::Fixed, Some(t)) => integrate_fixed(&mut ray, setup, t, window),
            (Method::Adaptive, Some(t)) => adaptive::integrate(&mut ray, setup, tf, t, window),
            _ => integrate_riemann(&mut ray, setup, tf, window),
        }
        let done = match setup.method {
            Method::Fixed | Method::Adaptive => 1.0 - ray.transmittance > setup.early_termination,
            _ => ray.transmittance < setup.min_transmittance,
        };
        if done {
            break;
        }
    }
    let (bg, tr) = (setup.background, ray.transmittance);
    PixelResult {
        rgba: [
            ray.color[0] + tr * bg[0],
            ray.color[1] + tr * bg[1],
            ray.color[2] + tr * bg[2],
            1.0 - tr,
        ],
        evaluations: ray.evaluations,
        skipped_length: ray.skipped,
        evaluations_saved: ray.saved,
        inside_length,
        error_estimate: if setup.method == Method::Adaptive {
            adaptive::pixel_estimate(ray.error_estimate, 1.0 - tr, setup.early_termination)
        } else {
            0.0
        },
        hull_overflow,
    }
}

/// The skipping report of a CPU image (twin of the GPU's `--stats` "skip").
pub fn skip_report(image: &[PixelResult]) -> SkipReport {
    let mut r = SkipReport::default();
    for p in image {
        r.add(
            p.skipped_length,
            u64::from(p.evaluations_saved),
            p.inside_length,
        );
    }
    r
}

/// The CPU twin of a whole frame: builds the preintegration tables the setup's method reads
/// (at `resolution`, as the GPU renderer does) and ray casts every pixel with them.
pub fn raycast_frame(
    setup: &RaySetup,
    field: &Field,
    tf: &TransferFunction,
    resolution: usize,
) -> Result<Vec<PixelResult>, ReconError> {
    let tables = super::build_tables(setup, field, tf, resolution, |_| {});
    raycast_image(setup, field, tf, tables.as_ref())
}

/// Renders the whole image on the CPU (rows split over the available cores); fails only where
/// a deferred octree cannot be built ([`Field::octree`]).
pub fn raycast_image(
    setup: &RaySetup,
    field: &Field,
    tf: &TransferFunction,
    tables: Option<&PreintegrationTables>,
) -> Result<Vec<PixelResult>, ReconError> {
    let neighbours = field.evaluator()?;
    // `render.skip = "auto"` decided on this twin's own f64 blocks.
    let resolved;
    let setup = if setup.skip_auto {
        let mut s = setup.clone();
        s.resolve_skip(field.blocks(), tf, field);
        resolved = s;
        &resolved
    } else {
        setup
    };
    let w = setup.camera.width as usize;
    let h = setup.camera.height as usize;
    let mut out = vec![
        PixelResult {
            rgba: [0.0; 4],
            evaluations: 0,
            skipped_length: 0.0,
            evaluations_saved: 0,
            inside_length: 0.0,
            error_estimate: 0.0,
            hull_overflow: false,
        };
        w * h
    ];
    let table = setup
        .skip
        .then(|| SkipTable::build(tf, &setup.isosurfaces, crate::field::scalar_range(field)));
    let skip = match (&table, field.blocks()) {
        (Some(table), Some(blocks)) => Some(Skip { blocks, table }),
        _ => None,
    };
    // Rows on rayon's persistent workers: a frame spawns no threads, so it returns with no
    // thread of its own still exiting (scoped threads could outlive `scope` by their exit,
    // which LeakSanitizer in the fuzz targets reported as leaks).
    out.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            for (x, px) in row.iter_mut().enumerate() {
                *px = raycast(
                    setup,
                    field,
                    neighbours.as_ref(),
                    tf,
                    tables,
                    skip,
                    x as u32,
                    y as u32,
                );
            }
        });
    Ok(out)
}
