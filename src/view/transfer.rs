//! Piecewise-linear transfer function: f64 twin of `glsl/common/transfer.glsl`
//! (stage `transfer_lookup`). Colour and extinction τ (per world unit) are interpolated
//! linearly in s between control points and clamped outside their range.

use crate::gpu_types::{SensitivityBlock, TF_BLOCK_POINTS, TfBlock, TfPoint};

/// Most control points a transfer function may have: the kernels scan them per lookup, so the
/// count bounds the work of every sample (1024 is more than any colour-map preset ParaView
/// ships).
pub const MAX_POINTS: usize = 1024;

/// Largest colour component of a control point (as `scene::MAX_COLOUR`).
pub const MAX_COLOUR: f64 = 1e6;

/// Largest extinction per world unit: with the smallest world lengths the domain check allows
/// (1e-12), optical depths of a sample stay moderate; beyond it f32 products overflow.
pub const MAX_TAU: f64 = 1e15;

/// `render.exact_opacity = "auto"` takes the exact opacity where a piece of changing
/// extinction is narrower than this fraction of the scalar range
/// ([`TransferFunction::has_narrow_extinction`]).
pub const EXACT_OPACITY_WIDTH: f64 = 1.0 / 64.0;

/// Control points `[s, r, g, b, τ]`, sorted by s.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferFunction {
    points: Vec<[f64; 5]>,
}

impl TransferFunction {
    /// Wraps validated points (non-empty, s non-decreasing, finite, colour and τ ≥ 0).
    pub fn new(points: Vec<[f64; 5]>) -> Self {
        Self { points }
    }

    /// Reads `[[s, r, g, b, τ], ...]`; the error says what was expected.
    pub fn from_toml(value: &toml::Value) -> Result<Self, String> {
        let expected = "a non-empty array of [s, r, g, b, tau] with s non-decreasing, |s| <= 1e30, colour in [0, 1e6] and tau in [0, 1e15]";
        let rows = value.as_array().filter(|a| !a.is_empty()).ok_or(expected)?;
        if rows.len() > MAX_POINTS {
            return Err(format!(
                "at most {MAX_POINTS} points (found {}): {expected}",
                rows.len()
            ));
        }
        let mut points = Vec::with_capacity(rows.len());
        for (i, row) in rows.iter().enumerate() {
            let row = row
                .as_array()
                .filter(|r| r.len() == 5)
                .ok_or_else(|| format!("{expected} (point {i} is not 5 numbers)"))?;
            let mut p = [0.0; 5];
            for (o, v) in p.iter_mut().zip(row) {
                *o = match v {
                    toml::Value::Float(f) => *f,
                    toml::Value::Integer(n) => *n as f64,
                    _ => return Err(format!("{expected} (point {i} has a non-number)")),
                };
            }
            let in_range = p[0].abs() <= f64::from(crate::data::MAX_VALUE)
                && p[1..4].iter().all(|c| (0.0..=MAX_COLOUR).contains(c))
                && (0.0..=MAX_TAU).contains(&p[4]);
            if !in_range {
                return Err(format!("{expected} (point {i})"));
            }
            if points.last().is_some_and(|q: &[f64; 5]| p[0] < q[0]) {
                return Err(format!(
                    "{expected} (point {i} has s < the previous point's)"
                ));
            }
            points.push(p);
        }
        Ok(Self { points })
    }

    /// The control points.
    pub fn points(&self) -> &[[f64; 5]] {
        &self.points
    }

    /// (rgb, τ) at scalar s.
    pub fn lookup(&self, s: f64) -> ([f64; 3], f64) {
        let p = &self.points;
        let at = |q: &[f64; 5]| ([q[1], q[2], q[3]], q[4]);
        if s <= p[0][0] {
            return at(&p[0]);
        }
        for i in 1..p.len() {
            if s < p[i][0] {
                let t = (s - p[i - 1][0]) / (p[i][0] - p[i - 1][0]);
                let m = |k: usize| p[i - 1][k] + t * (p[i][k] - p[i - 1][k]);
                return ([m(1), m(2), m(3)], m(4));
            }
        }
        at(&p[p.len() - 1])
    }

    /// (rgb, τ) at s as one-sided limits, by binary search: `right` is the value just above s
    /// (what a segment leaving s upwards or arriving at s from above sees), else the value
    /// just below it. They differ only at a step (two points with the same s). Equal to
    /// [`TransferFunction::lookup`] wherever the function is continuous.
    pub fn limit(&self, s: f64, right: bool) -> ([f64; 3], f64) {
        let p = &self.points;
        let i = if right {
            p.partition_point(|q| q[0] <= s)
        } else {
            p.partition_point(|q| q[0] < s)
        };
        let at = |q: &[f64; 5]| ([q[1], q[2], q[3]], q[4]);
        if i == 0 {
            return at(&p[0]);
        }
        if i == p.len() {
            return at(&p[p.len() - 1]);
        }
        let (a, b) = (&p[i - 1], &p[i]);
        let t = ((s - a[0]) / (b[0] - a[0])).clamp(0.0, 1.0);
        let m = |k: usize| a[k] + t * (b[k] - a[k]);
        ([m(1), m(2), m(3)], m(4))
    }

    /// Whether τ is zero everywhere on [lo, hi] (both one-sided limits at each end, and every
    /// point between): a piecewise-linear τ ≥ 0 is largest at one of them.
    pub fn transparent_on(&self, lo: f64, hi: f64) -> bool {
        let tau = |s: f64, right: bool| self.limit(s, right).1;
        lo <= hi
            && [tau(lo, false), tau(lo, true), tau(hi, false), tau(hi, true)]
                .iter()
                .all(|&t| t == 0.0)
            && self.points[self.inside(lo, hi)].iter().all(|p| p[4] == 0.0)
    }

    /// The indices of the points strictly inside (lo, hi), as a range into [`Self::points`].
    pub fn inside(&self, lo: f64, hi: f64) -> std::ops::Range<usize> {
        let p = &self.points;
        let start = p.partition_point(|q| q[0] <= lo);
        let end = p.partition_point(|q| q[0] < hi).max(start);
        start..end
    }

    /// Stage `transfer_sensitivity`: how far τ and τ·c can move when s departs by at most
    /// `deviation` from the line the preintegration tables assume, somewhere in [lo, hi]
    /// (DESIGN.md §4, the Hermite criterion). Over the pieces that meet [lo, hi], the largest
    /// min(rate · deviation, jump), where jump is the largest change of τ or of one τ·c_k across
    /// the piece and rate = jump / its width (a step in the function, width 0, counts its jump).
    /// Per world unit, like τ.
    pub fn sensitivity(&self, lo: f64, hi: f64, deviation: f64) -> f64 {
        let mut m = 0.0f64;
        for pair in self.points.windows(2) {
            let (a, b) = (&pair[0], &pair[1]);
            if b[0] < lo || a[0] > hi {
                continue;
            }
            let jump = (1..4)
                .map(|k| (b[k] * b[4] - a[k] * a[4]).abs())
                .fold((b[4] - a[4]).abs(), f64::max);
            let width = b[0] - a[0];
            let change = if width > 0.0 {
                (jump / width * deviation).min(jump)
            } else {
                jump
            };
            m = m.max(change);
        }
        m
    }

    /// The largest τ or τ·c_k anywhere: the most a unit length of ray can add to the optical
    /// depth or to one channel's emission, so that no interval's error exceeds it per unit
    /// length (it caps the adaptive integrator's error estimate, DESIGN.md §4).
    pub fn peak(&self) -> f64 {
        self.points
            .iter()
            .map(|p| (1..4).map(|k| p[k] * p[4]).fold(p[4], f64::max))
            .fold(0.0, f64::max)
    }

    /// Stage `transfer_mean_tau` ([LUM]'s integral function, DESIGN §4): the mean extinction
    /// ∫τ ds / |b − a| over [a, b] (either order) of the piecewise-linear function, clamped
    /// outside its points, exactly: each piece the range overlaps adds its overlap times τ at
    /// the overlap's middle. With it, the point nearest the largest share of that integral
    /// (of the piece adding most, its end of larger τ; the first or last point for the
    /// clamped ends): the colour [`crate::view::preintegration::PreintegrationTables::entry`]
    /// falls back on. A range narrower than `min_width` is widened upwards to it, so that a
    /// zero-length one gets τ just above a, as a segment leaving a sees it. The kernel does the
    /// same in f32, over the same points in the same order.
    pub fn mean_tau(&self, a: f64, b: f64, min_width: f64) -> (f64, usize) {
        let lo = a.min(b);
        let hi = a.max(b).max(lo + min_width);
        let p = &self.points;
        let below = (hi.min(p[0][0]) - lo).max(0.0) * p[0][4];
        let (mut sum, mut best, mut at) = (below, below, 0);
        for (i, pair) in p.windows(2).enumerate() {
            let (x0, x1) = (pair[0][0], pair[1][0]);
            let (u, v) = (lo.max(x0), hi.min(x1));
            let w = (v - u).max(0.0);
            let t = if w > 0.0 {
                (0.5 * (u + v) - x0) / (x1 - x0)
            } else {
                0.0
            };
            let d = w * (pair[0][4] + (pair[1][4] - pair[0][4]) * t);
            sum += d;
            if d > best {
                best = d;
                at = if pair[1][4] >= pair[0][4] { i + 1 } else { i };
            }
        }
        let last = p.len() - 1;
        let above = (hi - lo.max(p[last][0])).max(0.0) * p[last][4];
        sum += above;
        if above > best {
            at = last;
        }
        (sum / (hi - lo), at)
    }

    /// Whether the preintegration tables' opacity should come from [`Self::mean_tau`] instead
    /// (`render.exact_opacity = "auto"`): some piece over which τ changes is narrower than
    /// [`EXACT_OPACITY_WIDTH`] of the scalar range `range`. Bilinear interpolation in the
    /// tables errs by the square of a cell over such a piece's width, and a table fine enough
    /// for a peak of 1/500 of the range no longer fits a texel buffer on lavapipe
    /// (BENCHMARKS.md, "The thinnest Marschner–Lobb peak").
    pub fn has_narrow_extinction(&self, range: (f64, f64)) -> bool {
        let width = (range.1 - range.0) * EXACT_OPACITY_WIDTH;
        self.points
            .windows(2)
            .any(|q| q[0][4] != q[1][4] && q[1][0] - q[0][0] < width)
    }

    /// The (s, τ) of the first [`TF_BLOCK_POINTS`] points, two a vec4, zero past the last:
    /// the exact opacity's unrolled scan reads them (kernel: `TF_S_TAU`).
    pub fn gpu_block(&self) -> TfBlock {
        let mut block = TfBlock::default();
        for (i, p) in self.points.iter().take(TF_BLOCK_POINTS).enumerate() {
            block.s_tau[i / 2][2 * (i % 2)] = p[0] as f32;
            block.s_tau[i / 2][2 * (i % 2) + 1] = p[4] as f32;
        }
        block
    }

    /// The pieces over which τ or some τ·c_k changes, each (s_a, s_b, rate, jump) as the
    /// kernel's texel scan of [`Self::sensitivity`] computes them, in f32 from the f32 points:
    /// jump the largest change, rate = jump / (s_b − s_a), or −1 for a step (width 0). Flat
    /// pieces add nothing to the sensitivity and are left out. The kernel's unrolled scan reads
    /// them from [`SensitivityBlock`] where there are at most
    /// [`SENSITIVITY_PIECES`](crate::gpu_types::SENSITIVITY_PIECES).
    pub fn sensitivity_pieces(&self) -> Vec<[f32; 4]> {
        let weighted = |p: &[f64; 5]| {
            let (r, g, b, tau) = (p[1] as f32, p[2] as f32, p[3] as f32, p[4] as f32);
            [r * tau, g * tau, b * tau, tau]
        };
        self.points
            .windows(2)
            .filter_map(|pair| {
                let (wa, wb) = (weighted(&pair[0]), weighted(&pair[1]));
                let jump = (0..4).map(|k| (wb[k] - wa[k]).abs()).fold(0.0f32, f32::max);
                let (sa, sb) = (pair[0][0] as f32, pair[1][0] as f32);
                let width = sb - sa;
                let rate = if width > 0.0 { jump / width } else { -1.0 };
                (jump > 0.0).then_some([sa, sb, rate, jump])
            })
            .collect()
    }

    /// [`Self::sensitivity_pieces`], zero past the last, for the kernel constants (unused where
    /// there are more than
    /// [`SENSITIVITY_PIECES`](crate::gpu_types::SENSITIVITY_PIECES)).
    pub fn gpu_sensitivity(&self) -> SensitivityBlock {
        let mut block = SensitivityBlock::default();
        for (slot, piece) in block.pieces.iter_mut().zip(self.sensitivity_pieces()) {
            *slot = piece;
        }
        block
    }

    /// GPU layout.
    pub fn to_gpu(&self) -> Vec<TfPoint> {
        self.points
            .iter()
            .map(|p| TfPoint {
                color_tau: [p[1] as f32, p[2] as f32, p[3] as f32, p[4] as f32],
                s: p[0] as f32,
                tau: p[4] as f32,
                _pad: [0.0; 2],
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_and_clamps() {
        let tf = TransferFunction::new(vec![[0.0, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 0.5, 0.0, 8.0]]);
        let (c, tau) = tf.lookup(0.25);
        assert!(
            (c[0] - 0.25).abs() < 1e-15
                && (c[1] - 0.125).abs() < 1e-15
                && (tau - 2.0).abs() < 1e-15
        );
        assert_eq!(tf.lookup(-3.0), ([0.0; 3], 0.0));
        assert_eq!(tf.lookup(7.0), ([1.0, 0.5, 0.0], 8.0));
    }

    #[test]
    fn transparent_on_finds_exactly_the_ranges_without_extinction() {
        // τ: 0 up to 0.2, a ramp to 4 at 0.4, 0 from a step at 0.6, 0 beyond; 1 at and past 0.9.
        let tf = TransferFunction::new(vec![
            [0.2, 1.0, 0.0, 0.0, 0.0],
            [0.4, 1.0, 0.0, 0.0, 4.0],
            [0.6, 1.0, 0.0, 0.0, 4.0],
            [0.6, 1.0, 0.0, 0.0, 0.0],
            [0.8, 1.0, 0.0, 0.0, 0.0],
            [0.9, 1.0, 0.0, 0.0, 1.0],
        ]);
        assert!(tf.transparent_on(-5.0, 0.2));
        assert!(!tf.transparent_on(-5.0, 0.2000001));
        // The step's lower side has τ = 4 at s = 0.6 itself.
        assert!(!tf.transparent_on(0.6, 0.7));
        assert!(tf.transparent_on(0.6000001, 0.8));
        assert!(!tf.transparent_on(0.7, 0.85));
        assert!(!tf.transparent_on(0.95, 3.0));
        assert!(
            !tf.transparent_on(0.3, 0.1),
            "an empty range is not vouched for"
        );
        // Sampled: wherever it says transparent, τ is 0 at every sample of the range.
        for i in 0..120 {
            for w in [0.0, 0.003, 0.05] {
                let lo = -0.1 + f64::from(i) / 100.0;
                if tf.transparent_on(lo, lo + w) {
                    for k in 0..=50 {
                        let s = lo + w * f64::from(k) / 50.0;
                        assert_eq!(tf.lookup(s).1, 0.0, "[{lo}, {}] at {s}", lo + w);
                    }
                }
            }
        }
    }

    #[test]
    fn sensitivity_pieces_give_the_sensitivity() {
        // The kernel's unrolled scan over the pieces (transfer_sensitivity with
        // TF_SENSITIVITY_PIECES), in f64 over the f32 pieces, against the f64 scan of the
        // points: flat pieces left out, a step (width 0) counting its jump, ranges past the ends.
        let tf = TransferFunction::new(vec![
            [0.0, 0.5, 0.5, 0.5, 0.0],
            [0.2, 0.9, 0.1, 0.3, 0.0],
            [0.3, 1.0, 0.55, 0.15, 4.0],
            [0.3, 0.2, 0.5, 1.0, 1.5],
            [0.5, 0.2, 0.5, 1.0, 1.5],
            [0.6, 0.7, 0.2, 0.1, 6.0],
            [0.9, 0.7, 0.2, 0.1, 6.0],
            [1.0, 0.0, 0.0, 0.0, 0.0],
        ]);
        let pieces = tf.sensitivity_pieces();
        // [0, 0.2] is transparent at both ends and [0.3, 0.5], [0.6, 0.9] are flat.
        assert_eq!(pieces.len(), 4, "{pieces:?}");
        assert_eq!(pieces[1][2], -1.0, "the step at 0.3: {pieces:?}");
        let scan = |lo: f64, hi: f64, deviation: f64| {
            pieces.iter().fold(0.0f64, |m, p| {
                let [sa, sb, rate, jump] = p.map(f64::from);
                let change = if rate < 0.0 {
                    jump
                } else {
                    (rate * deviation).min(jump)
                };
                if sb >= lo && sa <= hi {
                    m.max(change)
                } else {
                    m
                }
            })
        };
        for i in 0..400 {
            // Offset so that no range ends on a point, where f32 and f64 would disagree.
            let lo = -0.1 + 1.2 * (f64::from(i) + 0.37) / 400.0;
            for (width, deviation) in [(0.0, 0.0), (0.01, 0.003), (0.05, 0.02), (0.3, 1.0)] {
                let (a, b) = (
                    scan(lo, lo + width, deviation),
                    tf.sensitivity(lo, lo + width, deviation),
                );
                assert!(
                    (a - b).abs() <= 1e-6 * b.max(1.0),
                    "[{lo}, {}] deviation {deviation}: pieces {a}, points {b}",
                    lo + width
                );
            }
        }
        let block = tf.gpu_sensitivity();
        assert_eq!(&block.pieces[..4], &pieces[..]);
        assert!(block.pieces[4..].iter().all(|p| *p == [0.0; 4]));
    }

    #[test]
    fn sensitivity_bounds_the_change_of_tau_and_tau_c() {
        // τ rises 0 → 4 on [0.2, 0.4] (rate 20, τ·r up to 4), is flat to 0.6, then steps down.
        let tf = TransferFunction::new(vec![
            [0.2, 1.0, 0.0, 0.0, 0.0],
            [0.4, 1.0, 0.0, 0.0, 4.0],
            [0.6, 1.0, 0.0, 0.0, 4.0],
            [0.6, 1.0, 0.0, 0.0, 1.0],
        ]);
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        // Inside the ramp: rate × deviation; capped by the ramp's whole change.
        assert!(close(tf.sensitivity(0.25, 0.3, 0.01), 0.2));
        assert!(close(tf.sensitivity(0.25, 0.3, 1.0), 4.0));
        // On the flat piece nothing changes; the range touching the step counts its jump.
        assert!(close(tf.sensitivity(0.45, 0.55, 0.01), 0.0));
        assert!(close(tf.sensitivity(0.45, 0.6, 0.01), 3.0));
        // Outside the points the function is constant.
        assert!(close(tf.sensitivity(-1.0, 0.1, 0.5), 0.0));
        assert!(close(tf.sensitivity(0.7, 2.0, 0.5), 0.0));
        // Sampled: no change of τ over a deviation exceeds the bound.
        for i in 0..200 {
            let s = 0.15 + 0.5 * f64::from(i) / 200.0;
            let dev = 0.013;
            let bound = tf.sensitivity(s - dev, s + dev, dev);
            let (_, t0) = tf.lookup(s);
            for ds in [-dev, -0.5 * dev, 0.5 * dev, dev] {
                let (_, t1) = tf.lookup(s + ds);
                assert!((t1 - t0).abs() <= bound + 1e-12, "s {s} ds {ds}");
            }
        }
    }
}
