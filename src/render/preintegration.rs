//! Preintegration tables ([MLS] §4, DESIGN §4): for a piecewise-linear transfer function and a
//! scalar that varies linearly along a ray segment of length l from s_f to s_b,
//! α = 1 − exp(−∫₀ˡ τ dλ) and C = ∫₀ˡ c τ exp(−∫₀^λ τ dλ′) dλ, tabulated over (s_f, s_b) for the
//! lengths l_max, l_max/2, …, l_min that adaptive subdivision produces.
//!
//! Accuracy is controlled, not assumed (stage `preintegrate`, [`segment_integral`]): the segment
//! is split where s crosses a transfer-function point; inside a piece c and τ are linear in λ and
//! the optical depth D is quadratic, so α is exact and the colour integrand c·τ·e^{−D} is smooth:
//! 5-point Gauss–Legendre on sub-intervals of optical depth ≤ 0.5 integrates it to ~3e-10
//! relative, stopping once e^{−D} underflows (so huge τ costs no more than moderate τ). [`direct_quadrature`]
//! is the independent f64 reference the tests compare against.
//!
//! Scalars outside the transfer function's domain use its clamped values, exactly as the
//! direct lookup does; the table's own s-range is chosen by the caller (it must cover the data).

use super::transfer::TransferFunction;
use rayon::prelude::*;

/// Gauss–Legendre nodes and weights on [−1, 1], 5 points.
const GL_NODES: [f64; 5] = [
    -0.906_179_845_938_664,
    -0.538_469_310_105_683,
    0.0,
    0.538_469_310_105_683,
    0.906_179_845_938_664,
];
const GL_WEIGHTS: [f64; 5] = [
    0.236_926_885_056_189,
    0.478_628_670_499_366,
    0.568_888_888_888_889,
    0.478_628_670_499_366,
    0.236_926_885_056_189,
];
/// Optical depth per quadrature sub-interval.
const DEPTH_STEP: f64 = 0.5;
/// Beyond this optical depth e^{−D} < 1e-20: nothing further contributes in f64.
const DEPTH_LIMIT: f64 = 46.0;

/// Colour (premultiplied, C) and opacity (α) of one segment.
pub type SegmentResult = ([f64; 3], f64);

/// ∫₀ˡᵉⁿ c(λ) τ(λ) e^{−D(λ)} dλ for one piece, c and τ linear in λ, D(λ) = τ₀λ + kλ²/2 with
/// k = (τ₁ − τ₀)/len. The piece is cut where D crosses multiples of `DEPTH_STEP`; on each
/// sub-interval the integrand is a quadratic times an exponential varying by at most e^{0.5},
/// which 5-point Gauss–Legendre integrates to ~3e-10 relative. No cancellation: τ ≡ 0 gives 0.
fn piece_integral(c0: [f64; 3], c1: [f64; 3], tau0: f64, tau1: f64, len: f64) -> [f64; 3] {
    let k = (tau1 - tau0) / len;
    let depth = |x: f64| tau0 * x + 0.5 * k * x * x;
    // λ at which the depth reaches d (the depth is non-decreasing since τ ≥ 0).
    let at_depth = |d: f64| {
        let disc = (tau0 * tau0 + 2.0 * k * d).max(0.0);
        let denom = tau0 + disc.sqrt();
        if denom > 0.0 { 2.0 * d / denom } else { len }
    };
    let total = depth(len);
    let mut sum = [0.0; 3];
    if total <= 0.0 {
        return sum;
    }
    let (mut a, mut d) = (0.0, 0.0);
    loop {
        d += DEPTH_STEP;
        let b = if d >= total {
            len
        } else {
            at_depth(d).clamp(a, len)
        };
        let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
        for (x, w) in GL_NODES.iter().zip(GL_WEIGHTS) {
            let lambda = mid + half * x;
            let u = lambda / len;
            let tau = tau0 + (tau1 - tau0) * u;
            let weight = w * half * tau * (-depth(lambda)).exp();
            for (acc, (p, q)) in sum.iter_mut().zip(c0.iter().zip(&c1)) {
                *acc += weight * (p + (q - p) * u);
            }
        }
        if d > DEPTH_LIMIT || b >= len {
            return sum;
        }
        a = b;
    }
}

/// Piece boundaries of a segment, as fractions u ∈ [0, 1], where s (linear from s_f to s_b)
/// crosses a transfer-function control point; always starts at 0 and ends at 1.
fn piece_cuts(tf: &TransferFunction, s_f: f64, s_b: f64) -> Vec<f64> {
    let mut cuts = vec![0.0];
    if s_f != s_b {
        let mut inner: Vec<f64> = tf
            .points()
            .iter()
            .map(|p| (p[0] - s_f) / (s_b - s_f))
            .filter(|u| *u > 0.0 && *u < 1.0)
            .collect();
        inner.sort_by(f64::total_cmp);
        cuts.extend(inner);
    }
    cuts.push(1.0);
    cuts
}

/// Exact (to quadrature rounding) α and C of a segment of length l with s linear from s_f to
/// s_b (stage `preintegrate`).
pub fn segment_integral(tf: &TransferFunction, s_f: f64, s_b: f64, l: f64) -> SegmentResult {
    if l <= 0.0 {
        return ([0.0; 3], 0.0);
    }
    let cuts = piece_cuts(tf, s_f, s_b);
    let s_at = |u: f64| s_f + (s_b - s_f) * u;
    let mut color = [0.0; 3];
    let mut depth = 0.0f64;
    for w in cuts.windows(2) {
        let len = (w[1] - w[0]) * l;
        if len <= 0.0 {
            continue;
        }
        let (c0, tau0) = tf.lookup(s_at(w[0]));
        let (c1, tau1) = tf.lookup(s_at(w[1]));
        let transmittance = (-depth).exp();
        let piece = piece_integral(c0, c1, tau0, tau1, len);
        for (acc, p) in color.iter_mut().zip(piece) {
            *acc += transmittance * p;
        }
        depth += 0.5 * (tau0 + tau1) * len;
        if depth > 745.0 {
            break;
        }
    }
    (color, -(-depth).exp_m1())
}

/// The zero-length limit of a segment: the τ-weighted mean colour ∫cτ du / ∫τ du (the limit of
/// C/α as l → 0) and the mean extinction τ̄ = ∫τ du, u ∈ [0, 1] along the segment. α of any
/// length l is exactly 1 − e^{−l τ̄}. Exact per piece: τ is linear and cτ quadratic in u
/// (Simpson's rule is exact for both).
pub fn segment_limits(tf: &TransferFunction, s_f: f64, s_b: f64) -> [f64; 4] {
    let cuts = piece_cuts(tf, s_f, s_b);
    let s_at = |u: f64| s_f + (s_b - s_f) * u;
    let (mut tau_sum, mut ctau) = (0.0, [0.0; 3]);
    for w in cuts.windows(2) {
        let du = w[1] - w[0];
        let (c0, t0) = tf.lookup(s_at(w[0]));
        let (cm, tm) = tf.lookup(s_at(0.5 * (w[0] + w[1])));
        let (c1, t1) = tf.lookup(s_at(w[1]));
        tau_sum += 0.5 * (t0 + t1) * du;
        for k in 0..3 {
            ctau[k] += du / 6.0 * (c0[k] * t0 + 4.0 * cm[k] * tm + c1[k] * t1);
        }
    }
    if tau_sum > 0.0 {
        [
            ctau[0] / tau_sum,
            ctau[1] / tau_sum,
            ctau[2] / tau_sum,
            tau_sum,
        ]
    } else {
        // No extinction: the colour never shows; any value is exact. Take the mean colour.
        let (c0, _) = tf.lookup(s_f);
        let (c1, _) = tf.lookup(s_b);
        [
            0.5 * (c0[0] + c1[0]),
            0.5 * (c0[1] + c1[1]),
            0.5 * (c0[2] + c1[2]),
            0.0,
        ]
    }
}

/// Reference: midpoint rule with `steps` steps and exact per-step exponentials, in f64.
pub fn direct_quadrature(
    tf: &TransferFunction,
    s_f: f64,
    s_b: f64,
    l: f64,
    steps: usize,
) -> SegmentResult {
    let dt = l / steps as f64;
    let mut color = [0.0; 3];
    // Accumulate optical depth, not a product of (1 − a): with a ~ 1e-12 the product's rounding
    // would bias α by 1e-5 relative.
    let mut depth = 0.0f64;
    for i in 0..steps {
        let u = (i as f64 + 0.5) / steps as f64;
        let (c, tau) = tf.lookup(s_f + (s_b - s_f) * u);
        let a = -(-tau * dt).exp_m1();
        let transmittance = (-depth).exp();
        for k in 0..3 {
            color[k] += transmittance * a * c[k];
        }
        depth += tau * dt;
    }
    (color, -(-depth).exp_m1())
}

/// The lengths the integrator uses: l_max, l_max/2, … down to the first length ≤ l_min
/// (so l_min itself when l_max/l_min is a power of two).
pub fn table_lengths(l_max: f64, l_min: f64) -> Vec<f64> {
    let mut lengths = vec![l_max];
    while let Some(&last) = lengths.last() {
        if last <= l_min * (1.0 + 1e-9) || lengths.len() >= 32 {
            break;
        }
        lengths.push(last * 0.5);
    }
    lengths
}

/// Extra halvings below `l_min` for clipped remainders: until the smallest length has optical
/// depth ≤ 0.01 at the largest extinction `tau_max` (at most 12 more tables). Below that, the
/// remainder's colour interpolates linearly in optical depth, with an error of order depth².
pub fn remainder_levels(l_min: f64, tau_max: f64) -> usize {
    let mut levels = 0;
    let mut l = l_min;
    while l * tau_max > 0.01 && levels < 12 {
        l *= 0.5;
        levels += 1;
    }
    levels
}

/// α and C over an N×N grid of (s_f, s_b) for each length.
#[derive(Debug, Clone)]
pub struct PreintegrationTables {
    pub s_min: f64,
    pub s_max: f64,
    pub resolution: usize,
    /// World units, longest first.
    pub lengths: Vec<f64>,
    /// Per length: `resolution²` entries `[C.r, C.g, C.b, α]`, index `f + resolution·b`.
    pub tables: Vec<Vec<[f32; 4]>>,
    /// Zero-length limits `[mean colour rgb, τ̄]` ([`segment_limits`]), same indexing.
    pub limits: Vec<[f32; 4]>,
}

impl PreintegrationTables {
    /// Scalar value of node i.
    pub fn node(&self, i: usize) -> f64 {
        self.s_min + (self.s_max - self.s_min) * i as f64 / (self.resolution - 1) as f64
    }

    /// Builds the tables on all cores; `progress` gets the fraction done.
    pub fn build(
        tf: &TransferFunction,
        s_range: (f64, f64),
        lengths: &[f64],
        resolution: usize,
        progress: impl Fn(f64) + Sync,
    ) -> Self {
        let resolution = resolution.max(2);
        let (s_min, s_max) = if s_range.1 > s_range.0 {
            s_range
        } else {
            (s_range.0 - 0.5, s_range.0 + 0.5)
        };
        let mut tables = Self {
            s_min,
            s_max,
            resolution,
            lengths: lengths.to_vec(),
            tables: Vec::new(),
            limits: Vec::new(),
        };
        let rows_done = std::sync::atomic::AtomicUsize::new(0);
        let total_rows = (resolution * lengths.len()).max(1);
        for &l in lengths {
            let mut table = vec![[0.0f32; 4]; resolution * resolution];
            let t = &tables;
            table
                .par_chunks_mut(resolution)
                .enumerate()
                .for_each(|(b, row)| {
                    let s_b = t.node(b);
                    for (f, entry) in row.iter_mut().enumerate() {
                        let (c, a) = segment_integral(tf, t.node(f), s_b, l);
                        *entry = [c[0] as f32, c[1] as f32, c[2] as f32, a as f32];
                    }
                    let n = rows_done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                    progress(n as f64 / total_rows as f64);
                });
            tables.tables.push(table);
        }
        let mut limits = Vec::with_capacity(resolution * resolution);
        for b in 0..resolution {
            for f in 0..resolution {
                let v = segment_limits(tf, tables.node(f), tables.node(b));
                limits.push(v.map(|x| x as f32));
            }
        }
        tables.limits = limits;
        tables
    }

    /// Bilinear lookup of `table` at (s_f, s_b), clamped to the table's range.
    pub fn lookup(&self, table: &[[f32; 4]], s_f: f64, s_b: f64) -> [f64; 4] {
        let n = self.resolution;
        let scale = (n - 1) as f64 / (self.s_max - self.s_min);
        let grid = |s: f64| ((s - self.s_min) * scale).clamp(0.0, (n - 1) as f64);
        let (x, y) = (grid(s_f), grid(s_b));
        let (x0, y0) = ((x as usize).min(n - 2), (y as usize).min(n - 2));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let at = |i: usize, j: usize| table[i + n * j].map(f64::from);
        let (a, b, c, d) = (
            at(x0, y0),
            at(x0 + 1, y0),
            at(x0, y0 + 1),
            at(x0 + 1, y0 + 1),
        );
        std::array::from_fn(|k| {
            (a[k] * (1.0 - fx) + b[k] * fx) * (1.0 - fy) + (c[k] * (1.0 - fx) + d[k] * fx) * fy
        })
    }

    /// α and C of a segment of any length r ∈ (0, lengths[0]] (stage `preintegrate_clipped`):
    /// binary decomposition over the table lengths, composited front to back with s
    /// interpolated at the split points; the remainder below the smallest length takes α from
    /// τ̄ exactly and its colour from C/α interpolated linearly in optical depth between the
    /// zero-length limit and the smallest table.
    pub fn segment(&self, s_f: f64, s_b: f64, r: f64) -> SegmentResult {
        let mut color = [0.0; 3];
        let mut alpha = 0.0;
        let mut done = 0.0;
        let s_at = |x: f64| s_f + (s_b - s_f) * (x / r);
        let mut add = |c: [f64; 3], a: f64, alpha: &mut f64| {
            for k in 0..3 {
                color[k] += (1.0 - *alpha) * c[k];
            }
            *alpha += (1.0 - *alpha) * a;
        };
        for (k, &l) in self.lengths.iter().enumerate() {
            if r - done >= l * (1.0 - 1e-6) {
                let e = self.lookup(&self.tables[k], s_at(done), s_at((done + l).min(r)));
                add([e[0], e[1], e[2]], e[3], &mut alpha);
                done = (done + l).min(r);
            }
        }
        let rest = r - done;
        if rest > 0.0 {
            let (s0, s1) = (s_at(done), s_f + (s_b - s_f));
            let zero = self.lookup(&self.limits, s0, s1);
            let tau = zero[3];
            let a = -(-rest * tau).exp_m1();
            let smallest = self.lengths.len() - 1;
            let e = self.lookup(&self.tables[smallest], s0, s1);
            let t_small = self.lengths[smallest] * tau;
            let mut c = [zero[0], zero[1], zero[2]];
            if e[3] > 0.0 && t_small > 0.0 {
                let f = (rest * tau / t_small).min(1.0);
                for k in 0..3 {
                    c[k] += (e[k] / e[3] - zero[k]) * f;
                }
            }
            add(c.map(|x| x * a), a, &mut alpha);
        }
        (color, alpha)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_halve_down_to_l_min() {
        let l = table_lengths(2.6, 0.1625);
        assert_eq!(l, vec![2.6, 1.3, 0.65, 0.325, 0.1625]);
        assert_eq!(table_lengths(1.0, 1.0), vec![1.0]);
    }

    #[test]
    fn piece_integral_is_exact_for_constant_tau() {
        let c = piece_integral([1.0, 0.5, 0.0], [1.0, 0.5, 0.0], 3.0, 3.0, 0.7);
        let exact = 1.0 - (-2.1f64).exp();
        assert!(
            (c[0] - exact).abs() < 1e-12 && (c[1] - 0.5 * exact).abs() < 1e-12,
            "{c:?} vs {exact}"
        );
    }
}
