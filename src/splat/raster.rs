//! Stages `splat_scan`, `splat_bin` and `splat_raster`: f64 twins of the GLSL kernels of the
//! same names, and [`splat_image`], the whole frame on the CPU.
//!
//! - `splat_scan` + `splat_bin` + `splat_order` ([`splat_bin`]): a counting sort of the
//!   (kernel, tile, sheet) entries by bucket `tile · sheets + sheet`: `offsets[b]..offsets[b +
//!   1]` of the sorted list are bucket b's kernels, in kernel order (a sheet is a sum, and one
//!   order of its terms makes every run give the same bits; the GPU's atomics fill a bucket in
//!   any order and `splat_order` sorts it).
//! - `splat_raster` ([`splat_raster`], one tile): the tile walks sheet k = 0, 1, … front to
//!   back. Every pixel of the tile (and of its one-pixel apron when post-shaded isosurfaces
//!   need gradients) adds each entry's `splat_footprint` over the sheet's depth range to its
//!   own sheet accumulator; pre-shaded pixels already opaque skip the evaluation. When the
//!   sheet ends each pixel of the tile composites:
//!   - pre-shaded: surface splats first (coverage min(W, 1), normalised opacity and colour),
//!     then α = 1 − e^(−D), C += T·(E/D)·α, T ·= 1 − α: exact emission–absorption for a
//!     colour constant within the sheet;
//!   - post-shaded ([BLUR]): one sheet behind (its gradient needs the next sheet), the sheet's
//!     mean value v = S/Δs is classified like a ray caster's midpoint sample over the part ℓ of
//!     the slab inside the domain (α = 1 − e^(−τ(v)ℓ)); isosurfaces crossed between the
//!     previous sheet's value and this one are located by linear interpolation, shaded with the
//!     ray caster's lighting, the gradient by central differences within the sheet (pixel
//!     neighbours, one pixel = t/focal world units; one-sided at the image border) and across
//!     sheets, and composited first.
//!
//!   With `splat.occlusion` the tile stops before a sheet once every pixel of it is past the
//!   early-termination opacity ([BLUR]'s early splat elimination, per tile): such pixels never
//!   composite again, so stopping changes no pixel.

use super::footprint::{sheet_share, splat_footprint, splat_profile};
use super::project::KernelKind;
use super::project::{Cull, Kernel, Splat, splat_project};
use super::surface::surface_kernels;
use super::{Shading, SheetInterval, SplatCounts, SplatSetup};
use crate::field::Field;
use crate::view::camera::clip_box;
use crate::view::preintegration::PreintegrationTables;
use crate::view::shading::shade_surface;
use crate::view::transfer::TransferFunction;
use glam::DVec3;

/// Pre-shaded sheet channels: D, E.rgb, then (with surface splats) W, Σq·α, C.rgb.
pub const SHEET: usize = 9;

/// The kernels of a field, frame-relative.
pub fn kernels(field: &Field) -> impl Iterator<Item = Kernel> + '_ {
    (0..field.samples.len()).map(|i| kernel(field, i))
}

/// Sample i's kernel, frame-relative.
pub fn kernel(field: &Field, i: usize) -> Kernel {
    kernel_of_volume(field, i, field.kernel_volumes().get(i))
}

/// Sample i's kernel with its volume given.
pub fn kernel_of_volume(field: &Field, i: usize, volume: f64) -> Kernel {
    let s = &field.samples;
    Kernel {
        position: s.position(i),
        value: f64::from(s.values.get(i)),
        metric: s.metric(i),
        volume,
        kind: KernelKind::Volume,
    }
}

/// A rendered splatting frame.
#[derive(Debug, Clone)]
pub struct SplatImage {
    /// (C + T·background, 1 − T) per pixel, row 0 at the top.
    pub pixels: Vec<[f64; 4]>,
    pub counts: SplatCounts,
}

/// The sorted entries: bucket b = tile · sheets + sheet holds `list[offsets[b]..offsets[b + 1]]`.
pub struct Bins {
    pub offsets: Vec<u32>,
    pub list: Vec<u32>,
}

/// `splat_scan` + `splat_bin` + `splat_order`: the counting sort of every kept splat's (tile,
/// sheet) entries, each bucket in kernel order.
pub fn splat_bin(setup: &SplatSetup, splats: &[Splat]) -> Bins {
    let (tiles_x, _) = setup.tiles();
    let slabs = setup.slabs as usize;
    let buckets = setup.buckets() as usize;
    let entries = |s: &Splat| {
        let r = setup.tile_rect(s.bbox);
        // With ring registers, one entry per tile and per `ring` sheets, at the first.
        let [s0, s1] = s.slabs;
        let step = setup.ring.max(1) as usize;
        (r[1]..=r[3]).flat_map(move |ty| {
            (r[0]..=r[2]).flat_map(move |tx| {
                let tile = (ty * tiles_x + tx) as usize;
                (s0..=s1)
                    .step_by(step)
                    .map(move |k| tile * slabs + k as usize)
            })
        })
    };
    let mut offsets = vec![0u32; buckets + 1];
    for s in splats {
        for b in entries(s) {
            offsets[b + 1] += 1;
        }
    }
    for b in 0..buckets {
        offsets[b + 1] += offsets[b];
    }
    let mut cursor = offsets.clone();
    let mut list = vec![0u32; offsets[buckets] as usize];
    for (i, s) in splats.iter().enumerate() {
        for b in entries(s) {
            list[cursor[b] as usize] = i as u32;
            cursor[b] += 1;
        }
    }
    Bins { offsets, list }
}

/// One invocation of a `splat_raster` workgroup.
struct Lane {
    x: i32,
    y: i32,
    /// A pixel of the tile (not of its apron, which only splats for its neighbours).
    own: bool,
    color: [f64; 3],
    transmittance: f64,
    /// Pre-shaded: the sheet's channels. Post-shaded: `sheet[0]` is the sheet's field integral.
    sheet: [f64; SHEET],
    /// Post-shaded with ring registers: the integrals of the sheets after the current one.
    ahead: std::collections::VecDeque<f64>,
    /// Post-shaded: mean values of sheets j − 2, j − 1, j (= k − 1) and k; k < 0 reads 0.
    values: [f64; 4],
    /// Post-shaded isosurfaces: the lateral gradients (right, up) of sheets j − 1, j and k.
    lateral: [[f64; 2]; 3],
    /// Post-shaded, and in a brick's frame: the pixel's ray. Post-shaded: its inside segments.
    ray: (DVec3, DVec3),
    inside_segments: Vec<(f64, f64)>,
    /// Where the ray leaves the domain: its last inside segment's end (-∞: it never enters).
    exit: f64,
}

/// `splat_raster` of one tile: writes the tile's pixels as (premultiplied colour,
/// transmittance) into `color` and `transmittance` (image-sized).
#[allow(clippy::too_many_arguments)]
pub fn splat_raster(
    setup: &SplatSetup,
    tf: &TransferFunction,
    tables: Option<&PreintegrationTables>,
    splats: &[Splat],
    bins: &Bins,
    tile: (u32, u32),
    segments: Option<&[Vec<(f64, f64)>]>,
    counts: &mut SplatCounts,
    out: &mut [([f64; 3], f64)],
) {
    let t = setup.tile as i32;
    let a = setup.apron() as i32;
    let (w, h) = (setup.camera.width as i32, setup.camera.height as i32);
    let edge = t + 2 * a;
    let post = setup.shading == Shading::Post;
    // The quadrature's largest 1/deviation: thinner kernels are shared as if that thick
    // (SplatSetup::share_deviation).
    let widest_inv = setup
        .share_deviation()
        .map_or(f64::INFINITY, |dev| 1.0 / dev);
    let (x0, y0) = (tile.0 as i32 * t - a, tile.1 as i32 * t - a);
    let mut lanes: Vec<Lane> = (0..edge * edge)
        .map(|l| {
            let (x, y) = (x0 + l % edge, y0 + l / edge);
            let inside = x >= 0 && y >= 0 && x < w && y < h;
            let own =
                inside && (a..a + t).contains(&(l % edge)) && (a..a + t).contains(&(l / edge));
            let ray = if (post || setup.cell.is_some()) && own {
                setup
                    .camera
                    .ray(&setup.basis, setup.frame_origin, x as u32, y as u32)
            } else {
                (DVec3::ZERO, DVec3::ZERO)
            };
            let inside_segments = match (post && own, segments) {
                (false, _) => Vec::new(),
                (true, Some(s)) => s[(y * w + x) as usize].clone(),
                (true, None) => clip_box(ray.0, ray.1, setup.box_lo, setup.box_hi)
                    .into_iter()
                    .collect(),
            };
            let exit = inside_segments
                .iter()
                .map(|s| s.1)
                .fold(f64::NEG_INFINITY, f64::max);
            Lane {
                x,
                y,
                own,
                color: [0.0; 3],
                transmittance: 1.0,
                sheet: [0.0; SHEET],
                ahead: std::collections::VecDeque::new(),
                values: [0.0; 4],
                lateral: [[0.0; 2]; 3],
                ray,
                inside_segments,
                exit,
            }
        })
        .collect();
    let done = |l: &Lane| 1.0 - l.transmittance > setup.early_termination;
    // Post-shaded, a lane whose ray left the domain before sheet k's intervals start (slab0 +
    // (k - 1.5) slabs; a sheet's margin) composites nothing more (twin of pixel_live in
    // glsl/splat/raster_pixel.glsl); a ray that misses the domain never does.
    let past_exit =
        |l: &Lane, k: u32| post && setup.slab0 + (f64::from(k) - 2.0) * setup.slab_world >= l.exit;
    let (tiles_x, _) = setup.tiles();
    let first_bucket = (tile.1 * tiles_x + tile.0) as usize * setup.slabs as usize;
    let steps = setup.slabs + u32::from(post);
    // Post-shaded isosurfaces vote at their lateral exchange's barrier, after the sheet's
    // entries (as the kernel does); every other variant before them.
    let vote_late = setup.apron() > 0;
    let end = first_bucket + setup.slabs as usize;
    for k in 0..steps {
        let opaque = setup.settings.occlusion
            && lanes
                .iter()
                .filter(|l| l.own)
                .all(|l| done(l) || past_exit(l, k));
        if opaque && !vote_late {
            let from = first_bucket + (k as usize).min(setup.slabs as usize);
            counts.skipped_occluded += u64::from(bins.offsets[end] - bins.offsets[from]);
            break;
        }
        if k < setup.slabs {
            // Whole kernels: the footprint is the whole line integral.
            let (ta, tb) = if setup.split {
                setup.slab_bounds(k)
            } else {
                (f64::NEG_INFINITY, f64::INFINITY)
            };
            let b = first_bucket + k as usize;
            for &i in &bins.list[bins.offsets[b] as usize..bins.offsets[b + 1] as usize] {
                counts.accumulated += 1;
                let s = &splats[i as usize];
                for l in lanes.iter_mut() {
                    let in_box = l.x >= s.bbox[0]
                        && l.x <= s.bbox[2]
                        && l.y >= s.bbox[1]
                        && l.y <= s.bbox[3];
                    if !in_box || (!post && setup.settings.occlusion && done(l)) {
                        continue;
                    }
                    let (px, py) = (f64::from(l.x), f64::from(l.y));
                    if setup.ring > 0 {
                        // One evaluation of the lateral footprint, shared out to every sheet
                        // the kernel crosses.
                        counts.evaluated += 1;
                        let Some((amplitude, m, inv)) = splat_profile(s, setup, px, py) else {
                            continue;
                        };
                        counts.contributions += 1;
                        let inv = inv.min(widest_inv);
                        let share = |(a, b): (f64, f64)| {
                            amplitude * sheet_share(setup.sheet_share, (a - m) * inv, (b - m) * inv)
                        };
                        l.sheet[0] += share((ta, tb));
                        let last = s.slabs[1].min(k + setup.ring - 1);
                        for (d, j) in (k + 1..=last).enumerate() {
                            if l.ahead.len() <= d {
                                l.ahead.push_back(0.0);
                            }
                            l.ahead[d] += share(setup.slab_bounds(j));
                        }
                        continue;
                    }
                    let g = splat_footprint(s, setup, px, py, ta, tb);
                    counts.evaluated += 1;
                    // Post-shaded weights carry the data's sign: only zero is nothing.
                    if g == 0.0 {
                        continue;
                    }
                    counts.contributions += 1;
                    let e = &mut l.sheet;
                    match setup.shading {
                        Shading::Pre if s.opacity > 0.0 => {
                            e[4] += g;
                            e[5] += g * s.opacity;
                            for c in 0..3 {
                                e[c + 6] += g * s.color[c];
                            }
                        }
                        Shading::Pre => {
                            e[0] += g;
                            for c in 0..3 {
                                e[c + 1] += g * s.color[c];
                            }
                        }
                        Shading::Post => e[0] += g,
                    }
                }
            }
        }
        if opaque {
            let from = first_bucket + (k as usize + 1).min(setup.slabs as usize);
            counts.skipped_occluded += u64::from(bins.offsets[end] - bins.offsets[from]);
            break;
        }
        if post {
            composite_post(setup, tf, tables, &mut lanes, edge, k);
        } else {
            for l in lanes.iter_mut() {
                let owned = setup.owns(l.ray, k);
                composite_pre(l, setup.early_termination, owned);
            }
        }
    }
    for l in lanes.iter().filter(|l| l.own) {
        out[(l.y * w + l.x) as usize] = (l.color, l.transmittance);
    }
}

/// Pre-shaded: composites the sheet's channels into the pixel (where the frame `owned` the
/// sheet) and clears them.
fn composite_pre(l: &mut Lane, early_termination: f64, owned: bool) {
    let e = std::mem::take(&mut l.sheet);
    let done = |l: &Lane| 1.0 - l.transmittance > early_termination;
    if !l.own || !owned || done(l) {
        return;
    }
    if e[4] > 0.0 {
        // Surface splats first: coverage min(W, 1), normalised opacity and colour.
        let cover = e[4].min(1.0) / e[4];
        for c in 0..3 {
            l.color[c] += l.transmittance * e[c + 6] * cover;
        }
        l.transmittance *= 1.0 - e[5] * cover;
    }
    // A surface may have made the pixel opaque.
    if e[0] <= 0.0 || done(l) {
        return;
    }
    let alpha = 1.0 - (-e[0]).exp();
    for c in 0..3 {
        l.color[c] += l.transmittance * e[c + 1] / e[0] * alpha;
    }
    l.transmittance *= 1.0 - alpha;
}

/// Post-shaded, after sheet k: takes its mean value (and lateral gradient), composites sheet
/// j = k − 1, and shifts the per-pixel sheet registers.
fn composite_post(
    setup: &SplatSetup,
    tf: &TransferFunction,
    tables: Option<&PreintegrationTables>,
    lanes: &mut [Lane],
    edge: i32,
    k: u32,
) {
    let (w, h) = (setup.camera.width as i32, setup.camera.height as i32);
    for l in lanes.iter_mut() {
        l.values[3] = l.sheet[0] / setup.slab_world;
        l.sheet[0] = l.ahead.pop_front().unwrap_or(0.0);
    }
    let isosurfaces = !setup.isosurfaces.is_empty();
    if isosurfaces {
        // Lateral central differences of sheet k, from the neighbours' lanes (the apron holds
        // every own pixel's neighbours); one-sided at the image border.
        let (a, b) = setup.slab_bounds(k);
        let pixel = if setup.orthographic() {
            1.0 / setup.focal
        } else {
            0.5 * (a + b) / setup.focal
        };
        let value = |lanes: &[Lane], l: usize, dx: i32, dy: i32| {
            lanes[(l as i32 + dy * edge + dx) as usize].values[3]
        };
        for l in 0..lanes.len() {
            if !lanes[l].own {
                continue;
            }
            let (x, y) = (lanes[l].x, lanes[l].y);
            let diff = |c: i32, n: i32, horizontal: bool| {
                let (m, p) = ((c - 1).max(0), (c + 1).min(n - 1));
                if p == m {
                    return 0.0;
                }
                let (dm, dp) = (m - c, p - c);
                let (vm, vp) = if horizontal {
                    (value(lanes, l, dm, 0), value(lanes, l, dp, 0))
                } else {
                    (value(lanes, l, 0, dm), value(lanes, l, 0, dp))
                };
                (vp - vm) / (f64::from(p - m) * pixel)
            };
            // Pixel rows grow downwards, against `up`.
            lanes[l].lateral[2] = [diff(x, w, true), -diff(y, h, false)];
        }
    }
    let j = i64::from(k) - 1;
    for l in lanes.iter_mut() {
        let done = 1.0 - l.transmittance > setup.early_termination;
        let owned = j >= 0 && setup.owns(l.ray, j as u32);
        if l.own && owned && !done && !l.inside_segments.is_empty() {
            composite_sheet(setup, tf, tables, l, j);
        }
        l.values = [l.values[1], l.values[2], l.values[3], 0.0];
        l.lateral = [l.lateral[1], l.lateral[2], [0.0; 2]];
    }
}

/// The length of [a, b] inside the pixel's domain segments.
fn inside(l: &Lane, a: f64, b: f64) -> f64 {
    l.inside_segments
        .iter()
        .map(|&(t_in, t_out)| (b.min(t_out) - a.max(t_in)).max(0.0))
        .sum()
}

/// Post-shaded intervals: the field from `s_f` to `s_b` over [lo, hi], half a sheet (the
/// table's length), composited over its part inside the domain. A part r of the half keeps
/// the whole half's colour per opacity and takes its opacity from the half's optical depth
/// scaled by r over the half's length (exact for a constant field; only halves a domain
/// boundary clips are scaled).
fn composite_half(
    tables: &PreintegrationTables,
    l: &mut Lane,
    (lo, hi): (f64, f64),
    (s_f, s_b): (f64, f64),
) {
    let r = inside(l, lo, hi);
    let e = tables.entry(0, s_f, s_b);
    let f = r / (hi - lo);
    let alpha = if f >= 1.0 {
        e[3]
    } else {
        1.0 - (1.0 - e[3]).max(1e-30).powf(f)
    };
    let scale = if e[3] > 0.0 { alpha / e[3] } else { 0.0 };
    for (acc, c) in l.color.iter_mut().zip(&e[..3]) {
        *acc += l.transmittance * c * scale;
    }
    l.transmittance *= 1.0 - alpha;
}

/// Post-shaded: composites sheet j (values[2]) into one pixel, with the isosurfaces crossed
/// since sheet j − 1 (values[1]). With intervals between sheet middles (`tables`), the
/// interval from sheet j − 1's middle to sheet j's instead, in two halves split at the sheet
/// boundary, the isosurfaces between them.
fn composite_sheet(
    setup: &SplatSetup,
    tf: &TransferFunction,
    tables: Option<&PreintegrationTables>,
    l: &mut Lane,
    j: i64,
) {
    let overlap = |l: &Lane, j: i64| {
        let (a, b) = setup.slab_bounds(j as u32);
        inside(l, a, b)
    };
    let len = overlap(l, j);
    let [v_2, v0, v, v1] = l.values;
    // Before the first sheet nothing is composited, and its value extends backwards (the
    // sheets may start at the near plane inside the field).
    let p0 = if j == 0 { v } else { v0 };
    let p_2 = if j <= 1 { p0 } else { v_2 };
    // The field at the interval's middle (the sheet boundary): the Catmull–Rom cubic through
    // the four sheet values around it ([MLS] §4's Hermite intervals with central-difference
    // slopes), or the straight line.
    let mid = match setup.interval {
        SheetInterval::Hermite => (9.0 * (p0 + v) - p_2 - v1) / 16.0,
        _ => 0.5 * (p0 + v),
    };
    let (a, _) = setup.slab_bounds(j as u32);
    let half = 0.5 * setup.slab_world;
    if let Some(t) = tables.filter(|_| j > 0) {
        composite_half(t, l, (a - half, a), (p0, mid));
    }
    let d = l.ray.1;
    let s = setup.basis;
    let gradient = |lateral: [f64; 2], across: f64| {
        lateral[0] * s.right + lateral[1] * s.up + across / (2.0 * setup.slab_world) * d
    };
    if j >= 1 && len > 0.0 && overlap(l, j - 1) > 0.0 && !setup.isosurfaces.is_empty() {
        let mut hits = Vec::new();
        for iso in &setup.isosurfaces {
            let crosses =
                (v0 - iso.value) * (v - iso.value) < 0.0 || (v == iso.value && v0 != iso.value);
            if !crosses {
                continue;
            }
            let a = (iso.value - v0) / (v - v0);
            let g0 = gradient(l.lateral[0], v - v_2);
            let g1 = gradient(l.lateral[1], v1 - v0);
            let g = g0 + (g1 - g0) * a;
            let rgb = shade_surface(iso, &setup.lighting, g.to_array(), d);
            hits.push((a, rgb, iso.opacity));
        }
        hits.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (_, rgb, opacity) in hits {
            for (acc, c) in l.color.iter_mut().zip(rgb) {
                *acc += l.transmittance * c;
            }
            l.transmittance *= 1.0 - opacity;
        }
    }
    if let Some(t) = tables {
        composite_half(t, l, (a, a + half), (mid, v));
    } else if len > 0.0 {
        let (c, tau) = tf.lookup(v);
        let alpha = 1.0 - (-tau * len).exp();
        for (acc, ci) in l.color.iter_mut().zip(c) {
            *acc += l.transmittance * ci * alpha;
        }
        l.transmittance *= 1.0 - alpha;
    }
}

/// Stage `splat_segments` (post-shaded over a hull): every pixel's inside segments, as the ray
/// caster clips its rays. The GPU keeps at most `PIXEL_SEGMENTS` and fails beyond.
pub fn splat_segments(setup: &SplatSetup, field: &Field) -> Option<Vec<Vec<(f64, f64)>>> {
    let hull = field
        .hull
        .as_ref()
        .filter(|_| setup.shading == Shading::Post)?;
    let (w, h) = (setup.camera.width, setup.camera.height);
    Some(
        (0..w * h)
            .map(|p| {
                let (o, d) = setup
                    .camera
                    .ray(&setup.basis, setup.frame_origin, p % w, p / w);
                match hull.segments(o.to_array(), d.to_array()) {
                    crate::samples::bvh::Segments::List(s) => s,
                    crate::samples::bvh::Segments::Overflow => Vec::new(),
                }
            })
            .collect(),
    )
}

/// The whole frame on the CPU, stage by stage as on the GPU.
pub fn splat_image(
    setup: &SplatSetup,
    field: &Field,
    tf: &TransferFunction,
) -> Result<SplatImage, crate::recon::ReconError> {
    let mut counts = SplatCounts::default();
    let mut splats = Vec::new();
    let surfaces = if setup.settings.surface {
        surface_kernels(field, &setup.isosurfaces)?
    } else {
        Vec::new()
    };
    for kernel in kernels(field).chain(surfaces) {
        counts.projected += 1;
        match splat_project(setup, tf, &kernel) {
            Ok(s) => splats.push(s),
            Err(c) => Cull::count(c, &mut counts),
        }
    }
    let bins = splat_bin(setup, &splats);
    counts.entries = bins.list.len() as u64;
    let lengths = setup.table_lengths();
    let tables = (!lengths.is_empty()).then(|| {
        let mut t = PreintegrationTables::build(
            tf,
            setup.table_range(field, tf),
            &lengths,
            setup.table_resolution,
            |_| {},
        );
        t.set_exact_opacity(setup.exact_opacity.then_some(tf));
        t
    });
    let segments = splat_segments(setup, field);
    let (w, h) = (setup.camera.width as usize, setup.camera.height as usize);
    let mut out = vec![([0.0; 3], 1.0); w * h];
    let (tx, ty) = setup.tiles();
    for y in 0..ty {
        for x in 0..tx {
            splat_raster(
                setup,
                tf,
                tables.as_ref(),
                &splats,
                &bins,
                (x, y),
                segments.as_deref(),
                &mut counts,
                &mut out,
            );
        }
    }
    let bg = setup.background;
    let pixels = out
        .iter()
        .map(|(c, t)| {
            [
                c[0] + t * bg[0],
                c[1] + t * bg[1],
                c[2] + t * bg[2],
                1.0 - t,
            ]
        })
        .collect();
    Ok(SplatImage { pixels, counts })
}
