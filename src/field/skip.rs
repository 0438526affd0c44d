//! Empty-space skipping (issue 11 §2, DESIGN §4 "Empty-space skipping"): f64 twin of
//! `glsl/field/skip.glsl`.
//!
//! Two parts:
//! - per dataset, [`Blocks`]: a value range of the fast path's field (`reconstruction.resample`)
//!   over blocks of `SKIP_BLOCK` × `SKIP_BLOCK` × `SKIP_BLOCK` grid cells. The fast field is a
//!   convex combination of its fine points' first-order Taylor terms, so their values widened
//!   by half a gradient step bound it *rigorously* over the block
//!   ([`crate::recon::resample::point_bounds`]); the general path has no such bound (linear and
//!   quadratic MLS overshoot their neighbours), so skipping is offered with the fast path only.
//! - per transfer function and isosurface set, [`SkipTable`] (stage `skip_table`): the scalar
//!   axis cut into bins; a bin is occupied when τ > 0 anywhere in it or an isosurface value lies
//!   in it; `prefix[k]` counts occupied bins below k, so a range [a, b] can contribute only if
//!   `prefix[bin(b) + 1] − prefix[bin(a)] > 0` — a range-max query of the extinction in two reads.
//!   The first and last bins reach to −∞ and +∞ with the transfer function's clamped end values,
//!   and a range is widened by one bin each side, so rounding in the bin index never hides
//!   extinction.
//!
//! Integrators (stages `skip_block`, `skip_run`): at an interval start t in a block not yet known
//! to be occupied, look the block up; if empty, follow the run of empty blocks after it (at most
//! [`SKIP_RUN`]) to the first occupied one: every interval (midpoint step, fixed interval) that
//! lies inside [t, end of the run] is skipped and the integration resumes at the first one that
//! reaches past it, with one evaluation for its start knot. Following the run matters when
//! blocks are about one step long (a 1 mm MRI at step 1–2: resuming after each block cost the
//! evaluation it saved). A run that reaches the ray's end (stage `skip_reaches_end`) ends the
//! ray, and with preintegration the start knot, the ray's first included, is pending until an
//! interval needs it: a ray that meets no occupied block evaluates nothing (it used to pay its
//! first knot, one to resume at its last interval and one to close it, which was more than half
//! of a fixed step's evaluations on a thin shell). Midpoint steps in an empty block add
//! nothing, so the midpoint rule gives the same image with and without skipping; preintegrated
//! intervals inside an empty block would add the table's value for a straight line between their
//! end values, which may cross extinction the field never reaches, so skipping changes those
//! images — towards the field (tests bound the change). The adaptive integrator (Hermite
//! criterion) follows a run only at a top interval's start, and resumes at the start of the top
//! holding the run's end.

use crate::recon::resample::ResampledGrid;
use crate::view::shading::Isosurface;
use crate::view::transfer::TransferFunction;
use glam::DVec3;

/// Grid cells per block edge.
pub const SKIP_BLOCK: usize = 2;
/// Bins of the scalar axis in a [`SkipTable`].
pub const SKIP_BINS: usize = 1024;
/// Most blocks one [`Blocks::run`] crosses (the kernel's SKIP_RUN): a bounded loop, and a run
/// that ends early only resumes sooner.
pub const SKIP_RUN: u32 = 64;
/// How far past a point [`Blocks::run`] looks up its block, in block edges.
pub const RUN_NUDGE: f64 = 1e-3;
/// What skipping did in one frame (`--stats` "skip"): summed over the rays.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SkipReport {
    /// Ray length skipped, world units.
    pub skipped_length: f64,
    /// Ray length inside the domain, world units (the rays' whole inside segments).
    pub inside_length: f64,
    /// Knots that skipping did not evaluate: skipped outer steps less the knots evaluated to
    /// resume. Exact for the fixed step and the midpoint rule (what the same frame without
    /// skipping would evaluate more, up to early termination on a slightly different image);
    /// for the adaptive integrator one per skipped top interval, a lower bound.
    pub evaluations_saved: u64,
}

impl SkipReport {
    /// The fraction of the rays' inside length that was skipped.
    pub fn fraction(&self) -> f64 {
        if self.inside_length > 0.0 {
            self.skipped_length / self.inside_length
        } else {
            0.0
        }
    }

    /// Adds one ray's (skipped length, evaluations saved, inside length).
    pub fn add(&mut self, skipped: f64, saved: u64, inside: f64) {
        self.skipped_length += skipped;
        self.evaluations_saved += saved;
        self.inside_length += inside;
    }
}

/// Occupied bins of the scalar axis for one transfer function and isosurface set.
#[derive(Debug, Clone, PartialEq)]
pub struct SkipTable {
    pub lo: f64,
    pub inv_width: f64,
    /// prefix[k] = occupied bins among 0..k; `SKIP_BINS + 1` entries.
    pub prefix: Vec<u32>,
}

impl SkipTable {
    /// Stage `skip_table` over the scalar range [lo, hi] (the preintegration tables' range).
    pub fn build(tf: &TransferFunction, isos: &[Isosurface], range: (f64, f64)) -> Self {
        let (lo, hi) = range;
        let width = (hi - lo).max(1e-30) / SKIP_BINS as f64;
        let edge = |k: usize| match k {
            0 => f64::NEG_INFINITY,
            k if k >= SKIP_BINS => f64::INFINITY,
            k => lo + k as f64 * width,
        };
        let points = tf.points();
        let tau_at = |s: f64| tf.lookup(s).1;
        let mut prefix = Vec::with_capacity(SKIP_BINS + 1);
        let mut count = 0u32;
        prefix.push(0);
        for k in 0..SKIP_BINS {
            let (a, b) = (edge(k), edge(k + 1));
            // τ is piecewise linear: its maximum over [a, b] is at an end or a control point.
            let inner = points.iter().filter(|p| p[0] > a && p[0] < b);
            let tau = inner.map(|p| p[4]).fold(tau_at(a).max(tau_at(b)), f64::max);
            let iso = isos.iter().any(|i| i.value >= a && i.value <= b);
            if tau > 0.0 || iso {
                count += 1;
            }
            prefix.push(count);
        }
        Self {
            lo,
            inv_width: 1.0 / width,
            prefix,
        }
    }

    /// Bin of a value, widened by `widen` bins and clamped.
    fn bin(&self, v: f64, widen: i64) -> usize {
        let b = ((v - self.lo) * self.inv_width).floor();
        let b = if b.is_nan() {
            0
        } else {
            b.clamp(-1.0, 1e9) as i64
        };
        (b + widen).clamp(0, SKIP_BINS as i64 - 1) as usize
    }

    /// Whether no value in [a, b] has extinction or an isosurface (a > b: no value at all, a
    /// block where the fast field is undefined).
    pub fn empty(&self, a: f64, b: f64) -> bool {
        if a > b {
            return true;
        }
        let (b0, b1) = (self.bin(a, -1), self.bin(b, 1));
        self.prefix[b1 + 1] == self.prefix[b0]
    }

    /// The table as the kernel reads it (binding `SKIP_TABLE`, r32ui): lo and 1/width as f32
    /// bits, the bin count, then the prefix counts.
    pub fn gpu_words(&self) -> Vec<u32> {
        let mut w = vec![
            (self.lo as f32).to_bits(),
            (self.inv_width as f32).to_bits(),
            SKIP_BINS as u32,
        ];
        w.extend(&self.prefix);
        w
    }
}

/// Value ranges of the fast field over blocks of `SKIP_BLOCK`³ grid cells (frame-relative).
#[derive(Debug, Clone)]
pub struct Blocks {
    pub dims: [usize; 3],
    pub origin: DVec3,
    /// Block edge lengths (world units).
    pub size: DVec3,
    pub ranges: Vec<[f64; 2]>,
}

impl Blocks {
    /// The blocks of a fine grid (its `factor` × `SKIP_BLOCK` fine cells per block edge).
    pub fn from_resampled(grid: &ResampledGrid) -> Self {
        let (dims, ranges) = grid.block_ranges(grid.factor as usize * SKIP_BLOCK);
        Self::over(grid.origin, grid.spacing, dims, ranges)
    }

    /// Blocks of `SKIP_BLOCK` coarse cells (`spacing`) from `origin`, `dims` of them with their
    /// `ranges` ([`crate::recon::resample::block_ranges`]).
    pub fn over(
        origin: [f64; 3],
        spacing: [f64; 3],
        dims: [usize; 3],
        ranges: Vec<[f64; 2]>,
    ) -> Self {
        Self {
            dims,
            origin: DVec3::from(origin),
            size: DVec3::from(spacing) * SKIP_BLOCK as f64,
            ranges,
        }
    }

    /// Block counts per axis for a grid of `dims` points (the kernel derives them the same way).
    pub fn count(dims: [usize; 3]) -> [usize; 3] {
        dims.map(|d| d.saturating_sub(1).max(1).div_ceil(SKIP_BLOCK))
    }

    /// Stage `skip_block`: the block holding o + t·d (clamped into the grid), whether it is
    /// empty for `table`, and the ray parameter where the ray leaves it.
    pub fn lookup(&self, table: &SkipTable, o: DVec3, d: DVec3, t: f64) -> (bool, f64) {
        let b = self.block_of(o + d * t);
        let lo = self.origin + DVec3::new(b[0] as f64, b[1] as f64, b[2] as f64) * self.size;
        let hi = lo + self.size;
        let mut exit = f64::INFINITY;
        for a in 0..3 {
            let ta = if d[a] > 0.0 {
                (hi[a] - o[a]) / d[a]
            } else if d[a] < 0.0 {
                (lo[a] - o[a]) / d[a]
            } else {
                f64::INFINITY
            };
            exit = exit.min(ta);
        }
        let r = self.ranges[b[0] + self.dims[0] * (b[1] + self.dims[1] * b[2])];
        (table.empty(r[0], r[1]), exit)
    }

    /// The block holding x, clamped into the grid.
    fn block_of(&self, x: DVec3) -> [usize; 3] {
        let g = (x - self.origin) / self.size;
        std::array::from_fn(|a| (g[a].floor().max(0.0) as usize).min(self.dims[a] - 1))
    }

    /// The value range of the block holding x (clamped into the grid).
    pub fn range_at(&self, x: DVec3) -> [f64; 2] {
        let b = self.block_of(x);
        self.ranges[b[0] + self.dims[0] * (b[1] + self.dims[1] * b[2])]
    }

    /// [`RUN_NUDGE`] in world units.
    fn nudge(&self) -> f64 {
        RUN_NUDGE * self.size.min_element()
    }

    /// Stage `skip_reaches_end`: whether a run of empty blocks that stopped at `exit` covers
    /// the ray up to `t_end`. A run stops past `t_end`, or at the grid's far face, which a box
    /// clipped to the grid ends on up to rounding (a nudge's margin): the rest of the ray is
    /// empty and its last interval is left out, as every interval inside the run is, instead
    /// of costing a knot to resume and one to close it.
    pub fn reaches_end(&self, exit: f64, t_end: f64) -> bool {
        exit >= t_end - self.nudge()
    }

    /// Stage `skip_run`: from t, across consecutive empty blocks (with `empty` false:
    /// occupied ones), at most [`SKIP_RUN`] of them and no further once past `t_end`; the ray
    /// parameter where the run stops (t itself when the block at t is not of that kind). Each
    /// block is looked up a thousandth of its edge past the point (`RUN_NUDGE`), since a point
    /// on a face may round into the block just left; a run may therefore pass over a sliver
    /// that thin of a block's corner. A lookup whose exit does not advance ends the run.
    pub fn run(
        &self,
        table: &SkipTable,
        o: DVec3,
        d: DVec3,
        t: f64,
        t_end: f64,
        empty: bool,
    ) -> f64 {
        let nudge = self.nudge();
        let mut t = t;
        for _ in 0..SKIP_RUN {
            if t >= t_end {
                break;
            }
            let (is_empty, exit) = self.lookup(table, o, d, t + nudge);
            if is_empty != empty || exit <= t {
                break;
            }
            t = exit;
        }
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tf() -> TransferFunction {
        TransferFunction::new(vec![
            [0.0, 0.0, 0.0, 0.0, 0.0],
            [0.3, 1.0, 0.0, 0.0, 0.0],
            [0.4, 1.0, 0.0, 0.0, 5.0],
            [0.5, 1.0, 0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0, 0.0, 0.0],
        ])
    }

    #[test]
    fn ranges_are_empty_exactly_where_the_extinction_is_zero() {
        let t = SkipTable::build(&tf(), &[], (0.0, 1.0));
        assert!(t.empty(0.0, 0.29));
        assert!(t.empty(0.51, 0.99));
        assert!(t.empty(-5.0, -1.0), "below the table: τ of the first point");
        assert!(!t.empty(0.29, 0.31), "τ rises right after 0.3");
        assert!(!t.empty(0.0, 1.0));
        assert!(!t.empty(0.45, 0.46));
        // A range inside one bin between the points that carry the spike.
        assert!(!t.empty(0.4, 0.4));
        let iso = Isosurface {
            value: 0.8,
            color: [1.0; 3],
            opacity: 1.0,
        };
        let with_iso = SkipTable::build(&tf(), &[iso], (0.0, 1.0));
        assert!(!with_iso.empty(0.75, 0.85));
        assert!(with_iso.empty(0.6, 0.7));
    }

    #[test]
    fn a_run_crosses_empty_blocks_and_stops_at_the_first_occupied_one() {
        // Eight unit blocks along x: 0..5 empty, 5 occupied, 6..8 empty.
        let mut ranges = vec![[0.0, 0.1]; 8];
        ranges[5] = [0.35, 0.45];
        let blocks = Blocks {
            dims: [8, 1, 1],
            origin: DVec3::ZERO,
            size: DVec3::ONE,
            ranges,
        };
        let table = SkipTable::build(&tf(), &[], (0.0, 1.0));
        let o = DVec3::new(-1.0, 0.5, 0.5);
        let x = DVec3::X;
        // Entering at x = 0 (t = 1), exactly on faces all the way: the run ends at block 5.
        assert!((blocks.run(&table, o, x, 1.0, 100.0, true) - 6.0).abs() < 1e-12);
        // Starting in the occupied block: no run.
        assert_eq!(blocks.run(&table, o, x, 6.5, 100.0, true), 6.5);
        // Past the occupied block the run goes to the grid's end and stops at t_end.
        let end = blocks.run(&table, o, x, 7.0, 100.0, true);
        assert!((end - 9.0).abs() < 1e-12, "{end}");
        assert!(blocks.run(&table, o, x, 1.0, 2.5, true) <= 3.0 + 1e-12);
        // A diagonal ray crossing edges and corners still advances.
        let diag = DVec3::new(1.0, 1e-9, 0.0).normalize();
        assert!(blocks.run(&table, DVec3::new(0.0, 0.5, 0.5), diag, 0.0, 100.0, true) > 4.99);
        // A run of occupied blocks: the one block 5 from inside it, none from an empty block.
        let occupied = blocks.run(&table, o, x, 6.5, 100.0, false);
        assert!((occupied - 7.0).abs() < 1e-12, "{occupied}");
        assert_eq!(blocks.run(&table, o, x, 1.0, 100.0, false), 1.0);
    }
}
