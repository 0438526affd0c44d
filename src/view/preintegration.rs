//! Preintegration tables ([MLS] §4, DESIGN §4): for a piecewise-linear transfer function and a
//! scalar that varies linearly along a ray segment of length l from s_f to s_b,
//! α = 1 − exp(−∫₀ˡ τ dλ) and C = ∫₀ˡ c τ exp(−∫₀^λ τ dλ′) dλ, tabulated over (s_f, s_b) for the
//! lengths l_max, l_max/2, …, l_min that adaptive subdivision produces.
//!
//! Accuracy is controlled, not assumed (stage `preintegrate`, [`segment_integral`]): the segment
//! is split where s crosses a transfer-function point (found by binary search, stage
//! `segment_pieces`); inside a piece c and τ are linear in λ and the optical depth D is
//! quadratic, so α is exact, and integration by parts leaves one smooth scalar integral
//! ∫(1 − e^{−D}) per piece whose colour varies, integrated by 5-point Gauss–Legendre on
//! sub-intervals of optical depth ≤ 0.5 to ~3e-10 relative, stopping once e^{−D} underflows
//! (so huge τ costs no more than moderate τ). Tables are built by windows over the cells
//! between table nodes ([`PreintegrationTables::build`]), so their cost grows with
//! resolution × (resolution + points), not with resolution² × points. [`direct_quadrature`] is
//! the independent f64 reference
//! the tests compare against.
//!
//! Scalars outside the transfer function's domain use its clamped values, exactly as the
//! direct lookup does; the table's own s-range is chosen by the caller (it must cover the data).

use crate::view::transfer::TransferFunction;
use rayon::prelude::*;

/// The exact opacity's smallest scalar range, as a fraction of the tables' (kernel twin:
/// `PREINT_MIN_WIDTH` in preintegration.glsl): a zero-length segment takes τ just above its
/// value ([`TransferFunction::mean`]).
pub const EXACT_MIN_WIDTH: f64 = 1e-6;
/// Below this table opacity the exact opacity's colour is that of the transfer function's point
/// `mean_tau` names (kernel twin: `PREINT_MIN_ALPHA`).
pub const EXACT_MIN_ALPHA: f64 = 1e-12;

/// The kernels' macros of the exact opacity (`PREINT_EXACT_OPACITY` on or off, and its
/// constants), so that the kernels and [`PreintegrationTables::entry`] share one copy.
///
/// `points`: the transfer function's points where the scan reads them from the parameters'
/// [`crate::gpu_types::TfBlock`] (at most [`crate::gpu_types::TF_BLOCK_POINTS`]), 0 where it
/// reads the texel view.
/// The transfer-function points a kernel's exact-opacity scan unrolls over from the
/// parameters' `TfBlock` (`PREINT_TF_POINTS`): `points` where the exact opacity is on and they
/// fit, else 0 (off, or read from the texel view). Only the exact opacity may set it: without,
/// a function of another length must not cost a pipeline.
pub fn unrolled_tf_points(exact_opacity: bool, points: u32) -> u32 {
    if exact_opacity && points as usize <= crate::gpu_types::TF_BLOCK_POINTS {
        points
    } else {
        0
    }
}

pub fn exact_opacity_defines(on: bool, points: u32) -> Vec<(String, String)> {
    vec![
        ("PREINT_EXACT_OPACITY".into(), u8::from(on).to_string()),
        ("PREINT_TF_POINTS".into(), points.to_string()),
        ("PREINT_MIN_WIDTH".into(), format!("{EXACT_MIN_WIDTH:e}")),
        ("PREINT_MIN_ALPHA".into(), format!("{EXACT_MIN_ALPHA:e}")),
    ]
}

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

/// ∫ₐᵇ g(λ) dλ by the Gauss–Legendre rule `nodes`, `weights` on [−1, 1].
fn gauss(nodes: &[f64], weights: &[f64], a: f64, b: f64, g: impl Fn(f64) -> f64) -> f64 {
    let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
    nodes
        .iter()
        .zip(weights)
        .map(|(x, w)| w * g(mid + half * x))
        .sum::<f64>()
        * half
}

/// F = ∫₀ˡᵉⁿ (1 − e^{−D(λ)}) dλ for one piece, D(λ) = τ₀λ + kλ²/2 with k = (τ₁ − τ₀)/len,
/// τ ≥ 0 (so D is non-decreasing). The piece is cut where D crosses multiples of
/// `DEPTH_STEP`; on each sub-interval the integrand is an entire function of a quadratic
/// whose range is at most 0.5, which 5-point Gauss–Legendre integrates to ~3e-10 relative
/// (fewer nodes are not enough even for a tiny piece: D's quadratic term makes D² a quartic,
/// which a 2-point rule already misses by 1e-5 of a piece of depth 0.01). Past `DEPTH_LIMIT`
/// the integrand is 1 to f64's resolution and the rest of the piece counts its length.
fn depth_integral(tau0: f64, tau1: f64, len: f64) -> f64 {
    let k = (tau1 - tau0) / len;
    let depth = |x: f64| tau0 * x + 0.5 * k * x * x;
    // λ at which the depth reaches d.
    let at_depth = |d: f64| {
        let disc = (tau0 * tau0 + 2.0 * k * d).max(0.0);
        let denom = tau0 + disc.sqrt();
        if denom > 0.0 { 2.0 * d / denom } else { len }
    };
    let total = depth(len);
    if total <= 0.0 {
        return 0.0;
    }
    let g = |x: f64| -(-depth(x)).exp_m1();
    let (mut a, mut d, mut sum) = (0.0, 0.0, 0.0);
    loop {
        let target = d + DEPTH_STEP;
        let b = if target >= total {
            len
        } else {
            at_depth(target).clamp(a, len)
        };
        sum += gauss(&GL_NODES, &GL_WEIGHTS, a, b, g);
        if b >= len {
            return sum;
        }
        if target > DEPTH_LIMIT {
            return sum + (len - b);
        }
        a = b;
        d = target;
    }
}

/// One piece as a [`Span`]: C = ∫₀ˡᵉⁿ c(λ) τ(λ) e^{−D(λ)} dλ with c and τ linear in λ. Since
/// τ = D′, integration by parts gives c₁(1 − e^{−D(len)}) − (c₁ − c₀)·F/len with F from
/// [`depth_integral`]: the colour's variation needs one scalar quadrature per piece, and a
/// piece of constant colour none. No cancellation: F/len ≤ 1 − e^{−D(len)}, and τ ≡ 0 gives
/// 0. One exponential gives both opacity and transmittance (expm1 where the depth is small,
/// so neither loses precision).
fn piece_integral(c0: [f64; 3], c1: [f64; 3], tau0: f64, tau1: f64, len: f64) -> Span {
    let depth = 0.5 * (tau0 + tau1) * len;
    let (opacity, transmittance) = if depth < 0.5 {
        let e = (-depth).exp_m1();
        (-e, 1.0 + e)
    } else {
        let t = (-depth).exp();
        (1.0 - t, t)
    };
    let mean = if c0 != c1 && opacity > 0.0 {
        depth_integral(tau0, tau1, len) / len
    } else {
        0.0
    };
    Span {
        color: std::array::from_fn(|k| c1[k] * opacity - (c1[k] - c0[k]) * mean),
        depth,
        transmittance,
    }
}

/// (rgb, τ) at one end of a piece.
type Knot = ([f64; 3], f64);

/// Stage `segment_pieces`: calls `visit(u₀, u₁, start, end)` for each piece of positive
/// length of a segment with s linear from s_f to s_b, in order, where u ∈ [0, 1] is the
/// fraction along the segment: the segment is cut where s crosses a transfer-function point,
/// found by binary search (so a segment costs O(log n + pieces), not O(n) per lookup), and
/// each end carries the one-sided value a traversal sees there (a step in the function
/// belongs to the piece on its side). Stops when `visit` returns false.
fn segment_pieces(
    tf: &TransferFunction,
    s_f: f64,
    s_b: f64,
    mut visit: impl FnMut(f64, f64, Knot, Knot) -> bool,
) {
    if s_f == s_b {
        // A constant scalar sees one value, the direct lookup's, even on a step.
        let v = tf.lookup(s_f);
        visit(0.0, 1.0, v, v);
        return;
    }
    let up = s_b > s_f;
    let ds = s_b - s_f;
    let mut u0 = 0.0;
    let mut v0 = tf.limit(s_f, up);
    let points = tf.points();
    let inside = tf.inside(s_f.min(s_b), s_f.max(s_b));
    let mut step = |q: &[f64; 5], u0: &mut f64, v0: &mut Knot| {
        let u = ((q[0] - s_f) / ds).clamp(*u0, 1.0);
        let v = ([q[1], q[2], q[3]], q[4]);
        let go_on = u <= *u0 || visit(*u0, u, *v0, v);
        *u0 = u;
        *v0 = v;
        go_on
    };
    let go_on = if up {
        points[inside].iter().all(|q| step(q, &mut u0, &mut v0))
    } else {
        points[inside]
            .iter()
            .rev()
            .all(|q| step(q, &mut u0, &mut v0))
    };
    if go_on && u0 < 1.0 {
        visit(u0, 1.0, v0, tf.limit(s_b, !up));
    }
}

/// A run of consecutive segments composited front to back: premultiplied colour C, optical
/// depth D (α = 1 − e^{−D}, kept as a depth so that a faint α keeps its precision) and
/// transmittance e^{−D} (kept so that compositing needs no exponential).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    pub color: [f64; 3],
    pub depth: f64,
    pub transmittance: f64,
}

impl Span {
    /// Nothing: the identity of [`Span::then`].
    pub const EMPTY: Span = Span {
        color: [0.0; 3],
        depth: 0.0,
        transmittance: 1.0,
    };

    /// This run followed by `back` (the over operator; associative, so runs compose in any
    /// grouping).
    pub fn then(self, back: Span) -> Span {
        Span {
            color: std::array::from_fn(|k| self.color[k] + self.transmittance * back.color[k]),
            depth: self.depth + back.depth,
            transmittance: self.transmittance * back.transmittance,
        }
    }

    /// (C, α).
    pub fn result(self) -> SegmentResult {
        (self.color, -(-self.depth).exp_m1())
    }
}

/// The [`Span`] of a segment of length l with s linear from s_f to s_b: its pieces
/// composited front to back.
pub fn segment_span(tf: &TransferFunction, s_f: f64, s_b: f64, l: f64) -> Span {
    if l <= 0.0 {
        return Span::EMPTY;
    }
    let mut span = Span::EMPTY;
    segment_pieces(tf, s_f, s_b, |u0, u1, start, end| {
        add_piece(&mut span, (u0, u1, start, end), l)
    });
    span
}

/// One piece of a segment: its ends as fractions of the segment, and the values there.
type Piece = (f64, f64, Knot, Knot);

/// Composites `piece` of a segment of length l behind `span`; false once nothing behind can
/// show (e^{−D} underflows).
fn add_piece(span: &mut Span, (u0, u1, (c0, tau0), (c1, tau1)): Piece, l: f64) -> bool {
    *span = span.then(piece_integral(c0, c1, tau0, tau1, (u1 - u0) * l));
    span.depth <= 745.0
}

/// The pieces of the segment from s_f to s_b ([`segment_pieces`]), kept for integrating it at
/// many lengths.
fn pieces_of(tf: &TransferFunction, s_f: f64, s_b: f64) -> Vec<Piece> {
    let mut pieces = Vec::new();
    segment_pieces(tf, s_f, s_b, |u0, u1, start, end| {
        pieces.push((u0, u1, start, end));
        true
    });
    pieces
}

/// [`segment_span`] of a segment of length l > 0 from its kept pieces.
fn pieces_span(pieces: &[Piece], l: f64) -> Span {
    let mut span = Span::EMPTY;
    for &piece in pieces {
        if !add_piece(&mut span, piece, l) {
            break;
        }
    }
    span
}

/// Exact (to quadrature rounding) α and C of a segment of length l with s linear from s_f to
/// s_b (stage `preintegrate`): the direct twin of one table entry.
pub fn segment_integral(tf: &TransferFunction, s_f: f64, s_b: f64, l: f64) -> SegmentResult {
    segment_span(tf, s_f, s_b, l).result()
}

/// Stage `preintegrate_windows`: the aggregates `op(cells[i], …, cells[i + m − 1])` of every
/// window of m consecutive cells, in O(cells) operations whatever m (the two-stacks
/// decomposition: within blocks of m cells, suffix and prefix aggregates; a window is the
/// suffix of one block followed by the prefix of the next). `op` must be associative.
pub fn windows<T: Copy>(cells: &[T], m: usize, op: impl Fn(T, T) -> T) -> Vec<T> {
    let n = cells.len();
    if m == 0 || m > n {
        return Vec::new();
    }
    let mut prefix = cells.to_vec();
    let mut suffix = cells.to_vec();
    for i in 1..n {
        if i % m != 0 {
            prefix[i] = op(prefix[i - 1], cells[i]);
        }
    }
    for i in (0..n - 1).rev() {
        if (i + 1) % m != 0 {
            suffix[i] = op(cells[i], suffix[i + 1]);
        }
    }
    (0..=n - m)
        .map(|i| {
            let last = i + m - 1;
            if i % m == 0 {
                prefix[last]
            } else {
                op(suffix[i], prefix[last])
            }
        })
        .collect()
}

/// The zero-length limit of a segment: the τ-weighted mean colour ∫cτ du / ∫τ du (the limit of
/// C/α as l → 0) and the mean extinction τ̄ = ∫τ du, u ∈ [0, 1] along the segment. α of any
/// length l is exactly 1 − e^{−l τ̄}. Exact per piece: τ is linear and cτ quadratic in u
/// (Simpson's rule is exact for both).
pub fn segment_limits(tf: &TransferFunction, s_f: f64, s_b: f64) -> [f64; 4] {
    let (mut tau_sum, mut ctau) = (0.0, [0.0; 3]);
    segment_pieces(tf, s_f, s_b, |u0, u1, (c0, t0), (c1, t1)| {
        let du = u1 - u0;
        let tm = 0.5 * (t0 + t1);
        tau_sum += tm * du;
        for k in 0..3 {
            let cm = 0.5 * (c0[k] + c1[k]);
            ctau[k] += du / 6.0 * (c0[k] * t0 + 4.0 * cm * tm + c1[k] * t1);
        }
        true
    });
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

/// The s-range a table over the data range `s_range` spans (a constant field gets a unit
/// range around its value).
pub(super) fn table_range(s_range: (f64, f64)) -> (f64, f64) {
    if s_range.1 > s_range.0 {
        s_range
    } else {
        (s_range.0 - 0.5, s_range.0 + 0.5)
    }
}

/// Values of m integrated at once by [`PreintegrationTables::build`].
const WINDOW_GROUP: usize = 64;

/// The zero-length limits of every entry ([`segment_limits`]) by the same windows as the
/// tables: per cell ∫τ ds and ∫cτ ds (sums of non-negative terms, so no cancellation), summed
/// over the m cells an entry crosses; the limits do not depend on the direction.
fn limits_table(tf: &TransferFunction, t: &PreintegrationTables, n: usize) -> Vec<[f32; 4]> {
    let cells: Vec<[f64; 4]> = (0..n - 1)
        .into_par_iter()
        .map(|j| {
            let width = t.node(j + 1) - t.node(j);
            let mut sums = [0.0; 4];
            segment_pieces(
                tf,
                t.node(j),
                t.node(j + 1),
                |u0, u1, (c0, t0), (c1, t1)| {
                    let ds = (u1 - u0) * width;
                    let tm = 0.5 * (t0 + t1);
                    sums[3] += tm * ds;
                    for k in 0..3 {
                        let cm = 0.5 * (c0[k] + c1[k]);
                        sums[k] += ds / 6.0 * (c0[k] * t0 + 4.0 * cm * tm + c1[k] * t1);
                    }
                    true
                },
            );
            sums
        })
        .collect();
    let add = |a: [f64; 4], b: [f64; 4]| std::array::from_fn(|k| a[k] + b[k]);
    let mut limits = vec![[0.0f32; 4]; n * n];
    for i in 0..n {
        limits[i + n * i] = segment_limits(tf, t.node(i), t.node(i)).map(|x| x as f32);
    }
    let ms: Vec<usize> = (1..n).collect();
    for group in ms.chunks(WINDOW_GROUP) {
        let sums: Vec<(usize, Vec<[f64; 4]>)> = group
            .par_iter()
            .map(|&m| (m, windows(&cells, m, add)))
            .collect();
        for (m, windows) in sums {
            scatter_limits(tf, t, &mut limits, m, windows);
        }
    }
    limits
}

/// Writes the limits of the entries m cells apart from their window sums (both orders).
fn scatter_limits(
    tf: &TransferFunction,
    t: &PreintegrationTables,
    limits: &mut [[f32; 4]],
    m: usize,
    windows: Vec<[f64; 4]>,
) {
    let n = t.resolution;
    for (lo, sum) in windows.into_iter().enumerate() {
        let hi = lo + m;
        let width = t.node(hi) - t.node(lo);
        let v = if sum[3] > 0.0 {
            [
                sum[0] / sum[3],
                sum[1] / sum[3],
                sum[2] / sum[3],
                sum[3] / width,
            ]
        } else {
            // No extinction: the colour never shows; take the ends' mean, as the direct
            // limit does.
            let (c0, _) = tf.lookup(t.node(lo));
            let (c1, _) = tf.lookup(t.node(hi));
            std::array::from_fn(|k| if k < 3 { 0.5 * (c0[k] + c1[k]) } else { 0.0 })
        };
        let v = v.map(|x| x as f32);
        limits[lo + n * hi] = v;
        limits[hi + n * lo] = v;
    }
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
    /// Per length, the bins of nodes that touch a cell with extinction (`occupied`, in
    /// `view::table_occupancy`, which computes them after each build).
    pub occupied: Vec<u64>,
    /// `render.exact_opacity` taken: the transfer function the tables were built from, whose
    /// integral gives each length table's opacity exactly ([`Self::entry`]; the kernels'
    /// `PREINT_EXACT_OPACITY`). `None`: the tables' own.
    pub exact_opacity: Option<TransferFunction>,
}

impl PreintegrationTables {
    /// The tables as the kernels' `TableBlock` describes them, with `tf`'s peak.
    pub fn gpu_block(&self, tf: &TransferFunction) -> crate::gpu_types::TableBlock {
        crate::gpu_types::TableBlock {
            s_min: self.s_min as f32,
            s_max: self.s_max as f32,
            longest_world: self.lengths[0] as f32,
            resolution: self.resolution as u32,
            lengths: self.lengths.len() as u32,
            peak: tf.peak() as f32,
            occupied: {
                let m = self.occupied.first().copied().unwrap_or(u64::MAX);
                [m as u32, (m >> 32) as u32]
            },
        }
    }

    /// Scalar value of node i.
    pub fn node(&self, i: usize) -> f64 {
        self.s_min + (self.s_max - self.s_min) * i as f64 / (self.resolution - 1) as f64
    }

    /// Builds the tables on all cores; `progress` gets the fraction done.
    ///
    /// An entry (f, b) is the segment from node f to node b: it crosses the m = |b − f| cells
    /// between consecutive nodes, each of world length l/m, so it is the composite of m cell
    /// [`Span`]s. Per length and per m the cells' spans are integrated once (both directions)
    /// and every window of m of them composited by [`windows`]: a table costs
    /// O(resolution × (resolution + points)) piece integrals instead of one walk over every
    /// crossed point per entry, and equals [`segment_integral`] per entry to rounding (cutting
    /// a piece at a node changes no integral).
    pub fn build(
        tf: &TransferFunction,
        s_range: (f64, f64),
        lengths: &[f64],
        resolution: usize,
        progress: impl Fn(f64) + Sync,
    ) -> Self {
        Self::build_reusing(tf, s_range, lengths, resolution, &mut Vec::new(), progress)
    }

    /// [`PreintegrationTables::build`], taking from `spare` each table of `lengths` at this
    /// resolution that it holds (built by this function for the same transfer function and
    /// range, which the caller guarantees) instead of building it again: a table depends on
    /// nothing else, so it is the same to the bit. A step ladder that halves its step shares all
    /// lengths but one with the rung before, and a tolerance's checks of finer tables return to
    /// the coarser ones (`renderer::tolerance`). The tables are moved, not copied: at 2048² a
    /// table is 64 MiB, and a copy into fresh pages cost more than building one.
    pub fn build_reusing(
        tf: &TransferFunction,
        s_range: (f64, f64),
        lengths: &[f64],
        resolution: usize,
        spare: &mut Vec<SpareTable>,
        progress: impl Fn(f64) + Sync,
    ) -> Self {
        let n = resolution.max(2);
        let mut reuse = |l: f64| {
            spare
                .iter()
                .position(|t| t.resolution == n && t.length.to_bits() == l.to_bits())
                .map(|i| spare.remove(i).entries)
        };
        let (s_min, s_max) = table_range(s_range);
        let mut tables = Self {
            s_min,
            s_max,
            resolution: n,
            lengths: lengths.to_vec(),
            tables: Vec::new(),
            limits: Vec::new(),
            occupied: Vec::new(),
            exact_opacity: None,
        };
        let done = std::sync::atomic::AtomicUsize::new(0);
        let total = (lengths.len() * (n - 1)).max(1);
        let entry = |r: SegmentResult| {
            let (c, a) = r;
            [c[0] as f32, c[1] as f32, c[2] as f32, a as f32]
        };
        let t = &tables;
        // The cells' pieces, upwards and (nearest the top first, so that window i starts at
        // node n − 1 − i) downwards: the same at every length and m.
        let (up_cells, down_cells): (Vec<_>, Vec<_>) = (0..n - 1)
            .into_par_iter()
            .map(|j| {
                let down = n - 2 - j;
                (
                    pieces_of(tf, t.node(j), t.node(j + 1)),
                    pieces_of(tf, t.node(down + 1), t.node(down)),
                )
            })
            .unzip();
        let spans = |m: usize, l: f64| {
            let len = l / m as f64;
            let up: Vec<Span> = up_cells.iter().map(|p| pieces_span(p, len)).collect();
            let down: Vec<Span> = down_cells.iter().map(|p| pieces_span(p, len)).collect();
            let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(k as f64 / total as f64);
            (
                m,
                windows(&up, m, Span::then),
                windows(&down, m, Span::then),
            )
        };
        let mut built = Vec::with_capacity(lengths.len());
        for &l in lengths {
            if let Some(table) = reuse(l) {
                built.push(table);
                continue;
            }
            let mut table = vec![[0.0f32; 4]; n * n];
            for i in 0..n {
                table[i + n * i] = entry(segment_integral(tf, t.node(i), t.node(i), l));
            }
            // Groups of m bound the memory of the windows at any resolution.
            let ms: Vec<usize> = (1..n).collect();
            for group in ms.chunks(WINDOW_GROUP) {
                let results: Vec<_> = group.par_iter().map(|&m| spans(m, l)).collect();
                for (m, up, down) in results {
                    for (f, span) in up.into_iter().enumerate() {
                        table[f + n * (f + m)] = entry(span.result());
                    }
                    for (i, span) in down.into_iter().enumerate() {
                        let f = n - 1 - i;
                        table[f + n * (f - m)] = entry(span.result());
                    }
                }
            }
            built.push(table);
        }
        let limits = limits_table(tf, t, n);
        tables.occupied = built.iter().map(|table| tables.occupied(table)).collect();
        tables.tables = built;
        tables.limits = limits;
        tables
    }

    /// Bytes of the tables and the limits.
    pub fn bytes(&self) -> u64 {
        let entries = self.tables.iter().map(Vec::len).sum::<usize>() + self.limits.len();
        entry_bytes(entries)
    }

    /// The tables, each with its length and the resolution, for a later
    /// [`PreintegrationTables::build_reusing`].
    pub fn into_spares(self) -> impl Iterator<Item = SpareTable> {
        let resolution = self.resolution;
        self.lengths
            .into_iter()
            .zip(self.tables)
            .map(move |(length, entries)| SpareTable {
                resolution,
                length,
                entries,
            })
    }

    /// The position of scalar `s` among the nodes (node i at i), clamped to the table.
    pub fn grid(&self, s: f64) -> f64 {
        let n1 = (self.resolution - 1) as f64;
        ((s - self.s_min) * (n1 / (self.s_max - self.s_min))).clamp(0.0, n1)
    }

    /// Bilinear lookup of `table` at (s_f, s_b), clamped to the table's range.
    pub fn lookup(&self, table: &[[f32; 4]], s_f: f64, s_b: f64) -> [f64; 4] {
        let n = self.resolution;
        let (x, y) = (self.grid(s_f), self.grid(s_b));
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

    /// Takes each length table's opacity from `tf`'s integral (`Some`, the transfer function
    /// the tables were built from) or from the tables (`None`): see [`Self::entry`].
    pub fn set_exact_opacity(&mut self, tf: Option<&TransferFunction>) {
        self.exact_opacity = tf.cloned();
    }

    /// Table `k` at (s_f, s_b) (stage `preint_lookup`): the bilinear [`Self::lookup`], or with
    /// [`Self::exact_opacity`] ([LUM]'s integral function, DESIGN §4) its α replaced by
    /// 1 − exp(−l τ̄), τ̄ the exact mean extinction over the clamped [s_f, s_b]
    /// ([`TransferFunction::mean_tau`]), and its colour scaled to keep the tables' C/α. For s
    /// linear along the segment that α is exact, where the tables' errs by a cell's square
    /// over a feature's width; C/α is exact for a constant colour and, for another, varies as
    /// slowly as the colour does. Where the tables hold no opacity at all (a zero-width range
    /// on a node next to a feature thinner than a cell) the colour is that of the point
    /// `mean_tau` names.
    pub fn entry(&self, k: usize, s_f: f64, s_b: f64) -> [f64; 4] {
        let e = self.lookup(&self.tables[k], s_f, s_b);
        let Some(tf) = &self.exact_opacity else {
            return e;
        };
        let clamp = |s: f64| s.clamp(self.s_min, self.s_max);
        let (tau, at) = tf.mean_tau(
            clamp(s_f),
            clamp(s_b),
            (self.s_max - self.s_min) * EXACT_MIN_WIDTH,
        );
        let alpha = -(-self.lengths[k] * tau).exp_m1();
        let colour: [f64; 3] = if e[3] > EXACT_MIN_ALPHA {
            std::array::from_fn(|c| e[c] / e[3])
        } else {
            let p = tf.points()[at];
            [p[1], p[2], p[3]]
        };
        [
            colour[0] * alpha,
            colour[1] * alpha,
            colour[2] * alpha,
            alpha,
        ]
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
                let e = self.entry(k, s_at(done), s_at((done + l).min(r)));
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
            let e = self.entry(smallest, s0, s1);
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

/// One table of an earlier build, kept for the next ([`PreintegrationTables::build_reusing`]).
#[derive(Debug)]
pub struct SpareTable {
    pub resolution: usize,
    /// World units.
    pub length: f64,
    pub entries: Vec<[f32; 4]>,
}

impl SpareTable {
    pub(super) fn bytes(&self) -> u64 {
        entry_bytes(self.entries.len())
    }
}

/// Bytes of `n` RGBA f32 table entries.
pub(super) fn entry_bytes(n: usize) -> u64 {
    (n * std::mem::size_of::<[f32; 4]>()) as u64
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
    fn windows_equal_the_naive_aggregates() {
        let cells: Vec<u64> = (1..=23).map(|i| i * 7 % 13).collect();
        for m in 1..=cells.len() {
            let naive: Vec<u64> = cells.windows(m).map(|w| w.iter().sum()).collect();
            assert_eq!(windows(&cells, m, |a, b| a + b), naive, "m = {m}");
        }
        assert!(windows(&cells, 24, |a, b| a + b).is_empty());
        // Not commutative: the order of composition is kept.
        let ends: Vec<(usize, usize)> = (0..7).map(|i| (i, i)).collect();
        let joined = windows(&ends, 3, |a, b| (a.0, b.1));
        assert_eq!(joined, [(0, 2), (1, 3), (2, 4), (3, 5), (4, 6)]);
    }

    /// Transfer functions that stress the windowed build: a step, a transparent gap, a point
    /// on a node, extinction from 0 to 1e6, and a thousand points finer than the table.
    fn hard_functions() -> Vec<TransferFunction> {
        let dense = (0..1000)
            .map(|i| {
                let s = -0.1 + 1.2 * f64::from(i) / 999.0;
                [
                    s,
                    s.abs(),
                    (7.0 * s).sin().abs(),
                    0.5,
                    30.0 * (31.0 * s).sin().abs(),
                ]
            })
            .collect();
        vec![
            TransferFunction::new(vec![
                [0.0, 1.0, 0.0, 0.0, 0.0],
                [0.25, 1.0, 0.0, 0.0, 0.0],
                [0.5, 0.0, 1.0, 0.0, 40.0],
                [0.5, 0.0, 0.0, 1.0, 2.0],
                [0.7, 0.3, 0.3, 0.3, 1e6],
                [0.72, 0.3, 0.3, 0.3, 0.0],
            ]),
            TransferFunction::new(dense),
        ]
    }

    #[test]
    fn windowed_tables_equal_the_direct_integral_per_entry() {
        let n = 41;
        let lengths = [0.8, 0.4, 0.003];
        for tf in hard_functions() {
            let t = PreintegrationTables::build(&tf, (0.0, 1.0), &lengths, n, |_| {});
            let mut worst = 0.0f64;
            for (k, &l) in lengths.iter().enumerate() {
                for b in 0..n {
                    for f in 0..n {
                        let (c, a) = segment_integral(&tf, t.node(f), t.node(b), l);
                        let e = t.tables[k][f + n * b];
                        let direct = [c[0], c[1], c[2], a];
                        for (x, y) in e.iter().zip(direct) {
                            // f32 storage: relative 1e-6 of the larger, or 1e-7 absolute.
                            let err = (f64::from(*x) - y).abs() / y.abs().max(0.1);
                            worst = worst.max(err);
                        }
                    }
                }
            }
            assert!(worst < 1e-6, "largest entry error {worst:.2e}");
            let mut worst = 0.0f64;
            for b in 0..n {
                for f in 0..n {
                    let direct = segment_limits(&tf, t.node(f), t.node(b));
                    let e = t.limits[f + n * b];
                    for (x, y) in e.iter().zip(direct) {
                        worst = worst.max((f64::from(*x) - y).abs() / y.abs().max(1.0));
                    }
                }
            }
            assert!(worst < 1e-6, "largest limit error {worst:.2e}");
        }
    }

    #[test]
    fn piece_integral_is_exact_for_constant_tau() {
        let c = piece_integral([1.0, 0.5, 0.0], [1.0, 0.5, 0.0], 3.0, 3.0, 0.7).color;
        let exact = 1.0 - (-2.1f64).exp();
        assert!(
            (c[0] - exact).abs() < 1e-12 && (c[1] - 0.5 * exact).abs() < 1e-12,
            "{c:?} vs {exact}"
        );
    }
}
