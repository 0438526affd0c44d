//! Stages `splat_bin`, `splat_accumulate` and `splat_composite`: f64 twins of the GLSL kernels
//! of the same names, and [`splat_image`], the whole frame on the CPU.
//!
//! - `splat_bin`: every kept splat is listed once per sheet of its range and per pixel block
//!   (`BLOCK`² pixels) of its bounding box.
//! - `splat_accumulate` (per sheet k, per entry): unless every occlusion tile under the block is
//!   opaque (early splat elimination, [BLUR] §4), adds `splat_footprint` over the sheet's depth
//!   range to every pixel of the block (pre-shaded: every pixel not yet opaque; post-shaded
//!   splats every pixel, since its neighbours' gradients read it, and tests the tiles one
//!   pixel wider). Pre-shaded sheets hold the
//!   optical depth D and the emission E = Σ c·D_i; post-shaded sheets the integral of the field
//!   over the slab.
//! - `splat_composite` (per pixel, after sheet k):
//!   - pre-shaded: α = 1 − e^(−D), C += T·(E/D)·α, T ·= 1 − α: exact emission–absorption for a
//!     colour constant within the sheet;
//!   - post-shaded ([BLUR]): one sheet behind (its gradient needs the next sheet), the sheet's
//!     mean value v = S/Δs is classified like a ray caster's midpoint sample over the part ℓ of
//!     the slab inside the domain box (α = 1 − e^(−τ(v)ℓ)); isosurfaces crossed between the
//!     previous sheet's value and this one are located by linear interpolation, shaded with the
//!     ray caster's lighting, the gradient by central differences within the sheet (pixel
//!     neighbours, one pixel = t/focal world units) and across sheets, and composited first;
//!   - the occlusion map marks tiles where every pixel's opacity exceeds early termination.

use super::project::{Cull, Kernel, Splat, splat_footprint, splat_project};
use super::surface::{KernelKind, surface_kernels};
use super::{BLOCK, Shading, SplatCounts, SplatSetup, TILE, blocks};
use crate::render::Field;
use crate::render::camera::clip_box;
use crate::render::shading::shade_surface;
use crate::render::transfer::TransferFunction;
use glam::DVec3;

/// Post-shaded sheets kept at once: sheets k−3..k are read while k+1's is cleared.
pub const RING: usize = 5;
/// Pre-shaded sheet channels: D, E.rgb, then (with surface splats) W, Σq·α, C.rgb.
pub const SHEET: usize = 9;

/// The kernels of a field, frame-relative.
pub fn kernels(field: &Field) -> impl Iterator<Item = Kernel> + '_ {
    let volumes = field.kernel_volumes();
    let s = &field.samples;
    (0..s.len()).map(move |i| Kernel {
        position: s.position(i),
        value: f64::from(s.values.get(i)),
        metric: s.metric(i),
        volume: volumes.get(i),
        kind: KernelKind::Volume,
    })
}

/// A rendered splatting frame.
#[derive(Debug, Clone)]
pub struct SplatImage {
    /// (C + T·background, 1 − T) per pixel, row 0 at the top.
    pub pixels: Vec<[f64; 4]>,
    pub counts: SplatCounts,
}

/// Frame state of the CPU twin.
struct Frame<'a> {
    setup: &'a SplatSetup,
    w: usize,
    h: usize,
    /// Premultiplied colour and transmittance per pixel.
    color: Vec<[f64; 3]>,
    transmittance: Vec<f64>,
    /// Pre-shaded: per pixel the volume's (D, E.rgb) and the surface splats' (W, Σq·α, C.rgb);
    /// post-shaded: RING sheets of field integrals.
    sheet: Vec<[f64; SHEET]>,
    ring: Vec<Vec<f64>>,
    /// Per occlusion tile: every pixel opaque.
    opaque: Vec<bool>,
    tiles_x: usize,
    /// Post-shaded over a hull: each pixel's inside segments (`splat_segments`).
    segments: Option<Vec<Vec<(f64, f64)>>>,
}

impl Frame<'_> {
    fn done(&self, p: usize) -> bool {
        1.0 - self.transmittance[p] > self.setup.early_termination
    }

    /// Whether every tile under the block's part of the box is opaque.
    fn occluded(&self, bbox: [i32; 4]) -> bool {
        let t = TILE as i32;
        for ty in bbox[1] / t..=bbox[3] / t {
            for tx in bbox[0] / t..=bbox[2] / t {
                if !self.opaque[ty as usize * self.tiles_x + tx as usize] {
                    return false;
                }
            }
        }
        true
    }

    /// Field value of post-shaded sheet k (k < 0: nothing splatted yet) at a clamped pixel.
    fn value(&self, k: i64, x: i64, y: i64) -> f64 {
        if k < 0 {
            return 0.0;
        }
        let x = x.clamp(0, self.w as i64 - 1) as usize;
        let y = y.clamp(0, self.h as i64 - 1) as usize;
        self.ring[k as usize % RING][y * self.w + x] / self.setup.slab
    }

    /// World-space gradient of sheet k at pixel (x, y) along the ray direction d.
    fn gradient(&self, k: i64, x: i64, y: i64, d: DVec3) -> DVec3 {
        let s = self.setup;
        let (a, b) = s.slab_bounds(k as u32);
        let pixel = if s.orthographic() {
            1.0 / s.focal
        } else {
            0.5 * (a + b) / s.focal
        };
        // Central differences, one-sided at the image border.
        let diff = |horizontal: bool| {
            let (c, n) = if horizontal {
                (x, self.w as i64)
            } else {
                (y, self.h as i64)
            };
            let (m, p) = ((c - 1).max(0), (c + 1).min(n - 1));
            if p == m {
                return 0.0;
            }
            let (vm, vp) = if horizontal {
                (self.value(k, m, y), self.value(k, p, y))
            } else {
                (self.value(k, x, m), self.value(k, x, p))
            };
            (vp - vm) / ((p - m) as f64 * pixel)
        };
        let gx = diff(true);
        // Pixel rows grow downwards, against `up`.
        let gy = -diff(false);
        let gt = (self.value(k + 1, x, y) - self.value(k - 1, x, y)) / (2.0 * s.slab);
        gx * s.basis.right + gy * s.basis.up + gt * d
    }
}

/// `splat_bin`: entries (splat, block) per sheet.
pub fn splat_bin(setup: &SplatSetup, splats: &[Splat]) -> Vec<Vec<(u32, u32)>> {
    let mut lists = vec![Vec::new(); setup.slabs as usize];
    for (i, s) in splats.iter().enumerate() {
        let (bx, by) = blocks(s.bbox);
        for k in s.slabs[0]..=s.slabs[1] {
            for b in 0..bx * by {
                lists[k as usize].push((i as u32, b));
            }
        }
    }
    lists
}

/// The pixel box of block b of a splat.
pub fn block_box(bbox: [i32; 4], b: u32) -> [i32; 4] {
    let (bx, _) = blocks(bbox);
    let x0 = bbox[0] + ((b % bx) * BLOCK) as i32;
    let y0 = bbox[1] + ((b / bx) * BLOCK) as i32;
    [
        x0,
        y0,
        (x0 + BLOCK as i32 - 1).min(bbox[2]),
        (y0 + BLOCK as i32 - 1).min(bbox[3]),
    ]
}

fn splat_accumulate(
    frame: &mut Frame<'_>,
    splats: &[Splat],
    list: &[(u32, u32)],
    k: u32,
    counts: &mut SplatCounts,
) {
    let setup = frame.setup;
    let (ta, tb) = setup.slab_bounds(k);
    for &(i, b) in list {
        let s = &splats[i as usize];
        let bb = block_box(s.bbox, b);
        // Post-shaded gradients read every pixel's neighbours: test one pixel wider.
        let probe = match setup.shading {
            Shading::Pre => bb,
            Shading::Post => [
                (bb[0] - 1).max(0),
                (bb[1] - 1).max(0),
                (bb[2] + 1).min(frame.w as i32 - 1),
                (bb[3] + 1).min(frame.h as i32 - 1),
            ],
        };
        if setup.settings.occlusion && frame.occluded(probe) {
            counts.skipped_occluded += 1;
            continue;
        }
        counts.accumulated += 1;
        for y in bb[1]..=bb[3] {
            for x in bb[0]..=bb[2] {
                let p = y as usize * frame.w + x as usize;
                if setup.settings.occlusion && setup.shading == Shading::Pre && frame.done(p) {
                    continue;
                }
                let g = splat_footprint(s, setup, f64::from(x), f64::from(y), ta, tb);
                counts.evaluated += 1;
                // Post-shaded weights carry the data's sign: only zero is nothing.
                if g == 0.0 {
                    continue;
                }
                counts.updates += match setup.shading {
                    Shading::Post => 1,
                    Shading::Pre if s.opacity > 0.0 => 5,
                    Shading::Pre => 4,
                };
                match setup.shading {
                    Shading::Pre if s.opacity > 0.0 => {
                        let e = &mut frame.sheet[p];
                        e[4] += g;
                        e[5] += g * s.opacity;
                        for c in 0..3 {
                            e[c + 6] += g * s.color[c];
                        }
                    }
                    Shading::Pre => {
                        let e = &mut frame.sheet[p];
                        e[0] += g;
                        for c in 0..3 {
                            e[c + 1] += g * s.color[c];
                        }
                    }
                    Shading::Post => frame.ring[k as usize % RING][p] += g,
                }
            }
        }
    }
}

/// Composites one isosurface crossing list (sorted by position) into pixel p.
fn composite_surfaces(frame: &mut Frame<'_>, p: usize, hits: &mut [(f64, [f64; 3], f64)]) {
    hits.sort_by(|a, b| a.0.total_cmp(&b.0));
    for (_, rgb, opacity) in hits.iter() {
        let t = frame.transmittance[p];
        for (acc, c) in frame.color[p].iter_mut().zip(rgb) {
            *acc += t * c;
        }
        frame.transmittance[p] *= 1.0 - opacity;
    }
}

fn splat_composite(frame: &mut Frame<'_>, tf: &TransferFunction, k: u32) {
    let setup = frame.setup;
    let (w, h) = (frame.w, frame.h);
    for p in 0..w * h {
        let (x, y) = ((p % w) as i64, (p / w) as i64);
        match setup.shading {
            Shading::Pre => {
                let e = std::mem::take(&mut frame.sheet[p]);
                if frame.done(p) {
                    continue;
                }
                if e[4] > 0.0 {
                    // Surface splats first: coverage min(W, 1), normalised opacity and colour.
                    let cover = e[4].min(1.0) / e[4];
                    let t = frame.transmittance[p];
                    for c in 0..3 {
                        frame.color[p][c] += t * e[c + 6] * cover;
                    }
                    frame.transmittance[p] *= 1.0 - e[5] * cover;
                }
                // A surface may have made the pixel opaque (as the kernel re-checks).
                if e[0] <= 0.0 || frame.done(p) {
                    continue;
                }
                let alpha = 1.0 - (-e[0]).exp();
                let t = frame.transmittance[p];
                for c in 0..3 {
                    frame.color[p][c] += t * e[c + 1] / e[0] * alpha;
                }
                frame.transmittance[p] *= 1.0 - alpha;
            }
            Shading::Post => {
                let j = i64::from(k) - 1;
                if j < 0 || frame.done(p) {
                    continue;
                }
                let (o, d) = setup
                    .camera
                    .ray(&setup.basis, setup.frame_origin, x as u32, y as u32);
                let inside: Vec<(f64, f64)> = match &frame.segments {
                    Some(s) => s[p].clone(),
                    None => clip_box(o, d, setup.box_lo, setup.box_hi)
                        .into_iter()
                        .collect(),
                };
                if inside.is_empty() {
                    continue;
                }
                let overlap = |j: i64| {
                    let (a, b) = setup.slab_bounds(j as u32);
                    inside
                        .iter()
                        .map(|&(t_in, t_out)| (b.min(t_out) - a.max(t_in)).max(0.0))
                        .sum::<f64>()
                };
                let len = overlap(j);
                let v = frame.value(j, x, y);
                if j >= 1 && len > 0.0 && overlap(j - 1) > 0.0 && !setup.isosurfaces.is_empty() {
                    let v0 = frame.value(j - 1, x, y);
                    let mut hits = Vec::new();
                    for iso in &setup.isosurfaces {
                        let crosses = (v0 - iso.value) * (v - iso.value) < 0.0
                            || (v == iso.value && v0 != iso.value);
                        if !crosses {
                            continue;
                        }
                        let a = (iso.value - v0) / (v - v0);
                        let g0 = frame.gradient(j - 1, x, y, d);
                        let g1 = frame.gradient(j, x, y, d);
                        let g = g0 + (g1 - g0) * a;
                        let rgb = shade_surface(iso, &setup.lighting, g.to_array(), d);
                        hits.push((a, rgb, iso.opacity));
                    }
                    composite_surfaces(frame, p, &mut hits);
                }
                if len > 0.0 {
                    let (c, tau) = tf.lookup(v);
                    let alpha = 1.0 - (-tau * len).exp();
                    let t = frame.transmittance[p];
                    for (acc, ci) in frame.color[p].iter_mut().zip(c) {
                        *acc += t * ci * alpha;
                    }
                    frame.transmittance[p] *= 1.0 - alpha;
                }
            }
        }
    }
    if setup.shading == Shading::Post {
        frame.ring[(k as usize + 1) % RING]
            .iter_mut()
            .for_each(|v| *v = 0.0);
    }
    // Occlusion map: a tile is opaque when every pixel in it (inside the image) is done.
    let tiles_y = h.div_ceil(TILE as usize);
    for ty in 0..tiles_y {
        for tx in 0..frame.tiles_x {
            let mut all = true;
            for y in ty * TILE as usize..((ty + 1) * TILE as usize).min(h) {
                for x in tx * TILE as usize..((tx + 1) * TILE as usize).min(w) {
                    all &= frame.done(y * w + x);
                }
            }
            frame.opaque[ty * frame.tiles_x + tx] = all;
        }
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
pub fn splat_image(setup: &SplatSetup, field: &Field, tf: &TransferFunction) -> SplatImage {
    let mut counts = SplatCounts::default();
    let mut splats = Vec::new();
    let surfaces = if setup.settings.surface {
        surface_kernels(field, &setup.isosurfaces)
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
    let lists = splat_bin(setup, &splats);
    counts.entries = lists.iter().map(|l| l.len() as u64).sum();
    let (w, h) = (setup.camera.width as usize, setup.camera.height as usize);
    let tiles_x = w.div_ceil(TILE as usize);
    let mut frame = Frame {
        setup,
        w,
        h,
        color: vec![[0.0; 3]; w * h],
        transmittance: vec![1.0; w * h],
        sheet: vec![
            [0.0; SHEET];
            if setup.shading == Shading::Pre {
                w * h
            } else {
                0
            }
        ],
        ring: vec![
            vec![0.0; w * h];
            if setup.shading == Shading::Post {
                RING
            } else {
                0
            }
        ],
        opaque: vec![false; tiles_x * h.div_ceil(TILE as usize)],
        tiles_x,
        segments: splat_segments(setup, field),
    };
    for k in 0..setup.slabs {
        splat_accumulate(&mut frame, &splats, &lists[k as usize], k, &mut counts);
        splat_composite(&mut frame, tf, k);
    }
    if setup.shading == Shading::Post {
        // The last sheet is composited one step late.
        splat_composite(&mut frame, tf, setup.slabs);
    }
    let bg = setup.background;
    let pixels = (0..w * h)
        .map(|p| {
            let (c, t) = (frame.color[p], frame.transmittance[p]);
            [
                c[0] + t * bg[0],
                c[1] + t * bg[1],
                c[2] + t * bg[2],
                1.0 - t,
            ]
        })
        .collect();
    SplatImage { pixels, counts }
}
