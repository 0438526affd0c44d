//! The regular-grid fast path (DESIGN §7, issue 11 §4): the reconstruction resampled once per
//! dataset on a grid `factor` times finer, then evaluated by trilinear interpolation of value and
//! gradient — 8 texel reads and no solve per evaluation, for any basis.
//!
//! Why this is the same field: on a regular grid with one support, the MLS shape function of
//! sample i depends only on x − x_i ([MLS] §3; DESIGN §7), so the reconstruction is a fixed
//! convolution, smooth at the scale of the support. Its values and gradients at the fine points
//! are computed by the general path itself (stage `recon_resample`, GPU twin
//! `glsl/field/recon_resample.comp`), boundary cells included; only the interpolation between fine
//! points is new, and its error falls as factor⁻² (tested against the direct solve in
//! `tests/resample.rs`, RMSE and maximum over dense random points).
//!
//! Irregular data (meshes, scattered points; issue 27 §1) takes the same path on a [`Lattice`]
//! laid over the domain's box at the median nearest-sample spacing, its fine points computed by
//! the general path through the octree. There the shape functions vary from sample to sample,
//! so the fine grid is an approximation whose error follows the local sample spacing against
//! the lattice's: `tests/resample.rs` bounds it (RMSE and maximum over dense random points
//! inside the hull, per data kind). The lattice is uniform, not adaptive: a mesh graded more
//! than the fine spacing resolves is interpolated more coarsely where its cells are smallest.
//! It is stored only where the field varies: pages where supports reach nothing or one constant
//! share a slot ([`super::pages`]; `tests/resample_pages.rs`).
//!
//! Contract of [`ResampledGrid::evaluate`] (stage `resample_evaluate`, GPU twin
//! `resampled_evaluate` in `glsl/field/neighbours.glsl`):
//! - fine point (i, j, k) sits at `origin + (i, j, k) ⊙ spacing / factor` and holds
//!   (f, ∂f/∂x, ∂f/∂y, ∂f/∂z) of the general path there, zeros where that is undefined (the
//!   scene requires a support of at least one spacing, so inside the box it never is);
//! - x is clamped into the grid's box, so rays clipped to the box never read outside it;
//! - the four channels are interpolated trilinearly; the gradient is the interpolated gradient
//!   (smooth), not the derivative of the interpolant (piecewise constant).
//!
//! The fast field is a convex combination of the corners' first-order Taylor terms, so the fine
//! values widened by half their gradient step bound it rigorously over a block
//! ([`ResampledGrid::block_ranges`], [`point_bounds`]), which is what empty-space skipping needs.

use super::mls::MlsValue;
use super::pages::{PAGE_EDGE, PAGE_POINTS, Pages, Slot};
use rayon::prelude::*;

/// Largest refinement factor (`reconstruction.resample`).
pub const MAX_FACTOR: u32 = 8;
/// The factor `reconstruction.resample = "auto"` picks where the fast path serves: against the
/// direct solve on Marschner–Lobb 21³ (near its Nyquist limit) it is within 1.1e-4 (linear) and
/// 8.5e-3 (quadratic) of the data range in RMSE (BENCHMARKS.md), and it costs 8× the grid's
/// points in memory; larger factors pay much more first-frame time for little.
pub const AUTO_FACTOR: u32 = 2;
/// Largest number of fine points stored: 2 GiB of `vec4`s (checked before anything is built).
pub const MAX_POINTS: u64 = 1 << 27;
/// Largest number of fine points over the lattice, stored or not (a paged grid's table holds
/// one word per 16³ of them: 8 MiB at this bound).
pub const MAX_LATTICE_POINTS: u64 = 1 << 33;

/// Most fine points `reconstruction.resample = "auto"` takes the fast path for: 2^24 (256 MiB on
/// the device, and a first frame that builds them in seconds on lavapipe). A 200³ grid would
/// need 63 M (18.8 s and 2.2 GB for its first 64² frame on lavapipe, issue 25), so "auto"
/// renders it by the general path; an explicit factor still takes it.
pub const AUTO_MAX_POINTS: u64 = 1 << 24;

/// Largest RMSE, relative to the data range, that `"auto"` accepts from the fast path on
/// irregular data ([`pilot_error`] at the scene's pilot points). Measured pilots: the
/// room-fire mesh 1.5e-4, the tetrahedral torus 2.8e-5 (their images within 2e-4 of the
/// direct solve's), 68 921 scattered Marschner–Lobb points 1.0e-2 interpolated everywhere
/// (image RMSE 0.022 against the direct solve's 0.004 from the reference), nearly all of it
/// past the samples, where the linear fit is barely determined; with those cells solved
/// directly ([`DIRECT`]) 2.9e-4.
pub const AUTO_PILOT_RMSE: f64 = 1e-3;

/// Largest share of the pilot's points that `"auto"` lets the fast path solve directly
/// ([`DIRECT`]): a frame then costs about the fast path's plus that share of the general
/// path's (more where a SIMD row mixes both), so past half the general path alone is near.
pub const AUTO_MAX_DIRECT_SHARE: f64 = 0.5;

/// Device bytes per fine point: f and ∇f as one rgba32f texel.
pub const FINE_POINT_DEVICE_BYTES: u64 = 16;

/// The coarse grid a fine grid refines: a regular grid's own points, or for irregular data a
/// lattice over the domain's box ([`Lattice::covering`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lattice {
    pub dims: [usize; 3],
    pub origin: [f64; 3],
    pub spacing: [f64; 3],
}

impl Lattice {
    /// The lattice with points at `lo` and `hi` and at most `spacing` between neighbours along
    /// each axis (a flat axis gets one point); `spacing` must be positive.
    pub fn covering(lo: [f64; 3], hi: [f64; 3], spacing: f64) -> Self {
        let mut dims = [1usize; 3];
        let mut step = [spacing; 3];
        for a in 0..3 {
            let extent = (hi[a] - lo[a]).max(0.0);
            if extent > 0.0 {
                // At most 2^20 points per axis: far past MAX_POINTS, which the caller checks.
                let cells = (extent / spacing).ceil().clamp(1.0, f64::from(1u32 << 20));
                dims[a] = cells as usize + 1;
                step[a] = extent / cells;
            }
        }
        Self {
            dims,
            origin: lo,
            spacing: step,
        }
    }

    /// Fine points of this lattice refined `factor` times.
    pub fn fine_points(&self, factor: u32) -> u64 {
        fine_points(self.dims, factor)
    }
}

/// A fine point where the general path is undefined (no sample's support reaches it): NaN in
/// the value, which the GPU stores as the quiet NaN [`UNDEFINED_BITS`]. Interpolating a zero
/// there instead blended the outer shell of a scattered set's domain, where supports thin out,
/// towards 0 and through the transfer function's bands (RMSE 0.022 against 0.004 for the
/// direct solve on 68 921 scattered Marschner–Lobb points at 512²).
pub const UNDEFINED: [f64; 4] = [f64::NAN, 0.0, 0.0, 0.0];
/// The f32 bits of an undefined fine point's value on the GPU (`RESAMPLE_UNDEFINED`).
pub const UNDEFINED_BITS: u32 = 0x7FC0_0000;

/// A fine point whose fit the samples barely determine (its [`mls_evaluate_margin`] below
/// [`DIRECT_MARGIN`]): every fine cell it is a corner of is solved by the general path instead
/// of interpolated (`Reconstruction::resample_direct`). Told from [`UNDEFINED`] by the infinite
/// first gradient component, which the GPU stores too, beside the value bits [`DIRECT_BITS`].
///
/// [`mls_evaluate_margin`]: super::mls::mls_evaluate_margin
pub const DIRECT: [f64; 4] = [f64::NAN, f64::INFINITY, 0.0, 0.0];
/// The f32 bits of a direct fine point's value on the GPU (`RESAMPLE_DIRECT_BITS`).
pub const DIRECT_BITS: u32 = 0x7FC0_0001;
/// `MlsValue::terms` of [`ResampledGrid::evaluate`] in a cell with a direct corner: the caller
/// solves x by the general path ([`crate::field::Field::evaluate`]).
pub const DIRECT_TERMS: u32 = u32::MAX;
/// The margin below which a fine point is [`DIRECT`]: 5× the pivot tolerance. On 68 921
/// scattered Marschner–Lobb points (linear MLS) the fast path erred by 1.6e-2 of the data range
/// in RMSE at points uniform in the supports' box, nearly all of it where the field extrapolates
/// past the samples (the linear fit falls back to the constant one there, a jump); with cells
/// at margins below 0.02, 0.05, 0.1 solved directly, the rest erred by 5.3e-4, 3.2e-4, 2.9e-4,
/// and 21%, 23%, 25% of the points were solved directly (BENCHMARKS.md).
pub const DIRECT_MARGIN: f64 = 0.05;

/// Whether fine point `p` is [`DIRECT`].
pub fn is_direct(p: &[f64; 4]) -> bool {
    p[0].is_nan() && p[1] == f64::INFINITY
}

/// Fine points per axis for a grid of `dims` points refined `factor` times.
pub fn fine_dims(dims: [usize; 3], factor: u32) -> [usize; 3] {
    dims.map(|d| (d.max(1) - 1) * factor as usize + 1)
}

/// Number of fine points, without overflow.
pub fn fine_points(dims: [usize; 3], factor: u32) -> u64 {
    fine_dims(dims, factor).iter().map(|&d| d as u64).product()
}

/// The reconstruction sampled on the fine grid: f and ∇f per fine point, x fastest.
#[derive(Debug, Clone)]
pub struct ResampledGrid {
    pub dims: [usize; 3],
    /// Position of fine point (0, 0, 0) (the coarse grid's first point).
    pub origin: [f64; 3],
    /// Coarse spacing; fine points are `spacing / factor` apart.
    pub spacing: [f64; 3],
    pub factor: u32,
    /// The page table of a paged fine grid ([`super::pages`]); `None`: dense, x fastest.
    pub pages: Option<Pages>,
    /// The points: dense, or the pool's slots one after the other.
    pub data: Vec<[f64; 4]>,
}

impl ResampledGrid {
    /// Stage `recon_resample`: `eval` (the general path) at every fine point of a grid with
    /// `dims` points at `origin` and `spacing`, dense.
    pub fn build(
        dims: [usize; 3],
        origin: [f64; 3],
        spacing: [f64; 3],
        factor: u32,
        eval: impl Fn([f64; 3]) -> Option<MlsValue> + Sync,
    ) -> Self {
        Self::build_paged(dims, origin, spacing, factor, None, eval)
    }

    /// [`ResampledGrid::build`] into `pages` where given: `eval` at the points of the solved
    /// slots only, the shared slots filled with their value.
    pub fn build_paged(
        dims: [usize; 3],
        origin: [f64; 3],
        spacing: [f64; 3],
        factor: u32,
        pages: Option<Pages>,
        eval: impl Fn([f64; 3]) -> Option<MlsValue> + Sync,
    ) -> Self {
        let fine = fine_dims(dims, factor);
        let step = spacing.map(|s| s / f64::from(factor));
        let solve = |idx: [usize; 3]| {
            let x = std::array::from_fn(|a| origin[a] + idx[a] as f64 * step[a]);
            eval(x).map_or(UNDEFINED, |m| {
                if m.terms == DIRECT_TERMS {
                    DIRECT
                } else {
                    [m.value, m.gradient[0], m.gradient[1], m.gradient[2]]
                }
            })
        };
        let data = match &pages {
            None => (0..fine[0] * fine[1] * fine[2])
                .into_par_iter()
                .map(|n| {
                    solve([
                        n % fine[0],
                        (n / fine[0]) % fine[1],
                        n / (fine[0] * fine[1]),
                    ])
                })
                .collect(),
            Some(p) => (0..p.slots.len() * PAGE_POINTS)
                .into_par_iter()
                .map(|n| match p.slots[n / PAGE_POINTS] {
                    Slot::Solved(page) => solve(p.fine_index(page, n % PAGE_POINTS)),
                    Slot::Constant(c) if c.is_nan() => UNDEFINED,
                    Slot::Constant(c) => [c, 0.0, 0.0, 0.0],
                })
                .collect(),
        };
        Self {
            dims: fine,
            origin,
            spacing,
            factor,
            pages,
            data,
        }
    }

    /// Where fine point `idx` is stored in `data`.
    pub fn index(&self, idx: [usize; 3]) -> usize {
        point_index(self.dims, self.pages.as_ref(), idx)
    }

    /// Continuous fine-grid coordinate of x, clamped into the box.
    fn coordinate(&self, x: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| {
            let g = (x[a] - self.origin[a]) / self.spacing[a] * f64::from(self.factor);
            g.clamp(0.0, (self.dims[a] - 1) as f64)
        })
    }

    /// Stage `resample_evaluate`: trilinear interpolation of (f, ∇f) at x; undefined
    /// (`terms` 0) in a fine cell with an undefined corner, [`DIRECT_TERMS`] in one with a
    /// [`DIRECT`] corner (whatever its other corners).
    pub fn evaluate(&self, x: [f64; 3]) -> MlsValue {
        let g = self.coordinate(x);
        // The cell's lower corner (the last cell for points on the upper face) and the offset
        // to the next point per axis (none along an axis with one point).
        let mut cell = [0usize; 3];
        let mut u = [0.0; 3];
        let mut next = [0usize; 3];
        // Dense: the grid's strides; paged: the slot's, from the cell's corner in its page.
        let strides = match self.pages {
            None => [1, self.dims[0], self.dims[0] * self.dims[1]],
            Some(_) => [1, PAGE_EDGE, PAGE_EDGE * PAGE_EDGE],
        };
        for a in 0..3 {
            let last = self.dims[a].saturating_sub(2);
            cell[a] = (g[a].floor() as usize).min(last);
            u[a] = g[a] - cell[a] as f64;
            next[a] = if self.dims[a] > 1 { strides[a] } else { 0 };
        }
        let base = self.index(cell);
        let h = self.spacing.map(|s| s / f64::from(self.factor));
        let mut v = [0.0; 4];
        let at = |corner: usize| {
            let b = [corner & 1, (corner >> 1) & 1, corner >> 2];
            &self.data[base + b[0] * next[0] + b[1] * next[1] + b[2] * next[2]]
        };
        if (0..8).any(|c| is_direct(at(c))) {
            return MlsValue {
                value: 0.0,
                gradient: [0.0; 3],
                neighbours: 8,
                terms: DIRECT_TERMS,
            };
        }
        for corner in 0..8 {
            let b = [corner & 1, (corner >> 1) & 1, corner >> 2];
            let w = (0..3)
                .map(|a| if b[a] == 1 { u[a] } else { 1.0 - u[a] })
                .product::<f64>();
            let d = at(corner);
            if d[0].is_nan() {
                return MlsValue {
                    value: 0.0,
                    gradient: [0.0; 3],
                    neighbours: 8,
                    terms: 0,
                };
            }
            // Half the corner's first-order Taylor step towards x: exact for quadratics.
            let step: f64 = (0..3).map(|a| d[1 + a] * (u[a] - b[a] as f64) * h[a]).sum();
            v[0] += w * (d[0] + 0.5 * step);
            for c in 1..4 {
                v[c] += w * d[c];
            }
        }
        MlsValue {
            value: v[0],
            gradient: [v[1], v[2], v[3]],
            neighbours: 8,
            terms: 1,
        }
    }

    /// Per block of `block`³ fine cells: see [`block_ranges`].
    pub fn block_ranges(&self, block: usize) -> ([usize; 3], Vec<[f64; 2]>) {
        let h = self.spacing.map(|s| s / f64::from(self.factor));
        block_ranges(self.dims, block, self.pages.as_ref(), |at| {
            point_bounds(self.data[at], h)
        })
    }
}

/// Where fine point `idx` of a grid of `dims` fine points is stored: x fastest, or in its
/// page's slot.
pub fn point_index(dims: [usize; 3], pages: Option<&Pages>, idx: [usize; 3]) -> usize {
    match pages {
        None => idx[0] + dims[0] * (idx[1] + dims[1] * idx[2]),
        Some(p) => p.locate(idx),
    }
}

/// What [`pilot_error`] measured: the fast field's difference from the general path relative
/// to the data range, and the share of points it solves directly.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PilotError {
    pub rmse: f64,
    pub max: f64,
    pub direct_share: f64,
}

/// The fast path's own error estimated at `points` before any fine grid exists: at each point
/// the 8 corners of its fine cell are solved by `corner` (the general path with the analytic
/// gradient, as the fine grid stores it) and interpolated as [`ResampledGrid::evaluate`] does,
/// against `direct` (the scene's general path). Returns the RMSE and max of the difference
/// relative to `range` over the points where both are defined, and the share of those points
/// that fall in a cell with a [`DIRECT`] corner (solved directly there: no difference); `None`
/// where no point is defined.
pub fn pilot_error(
    lattice: &Lattice,
    factor: u32,
    points: &[[f64; 3]],
    corner: impl Fn([f64; 3]) -> Option<MlsValue> + Sync,
    direct: impl Fn([f64; 3]) -> Option<MlsValue>,
    range: f64,
) -> Option<PilotError> {
    let h: [f64; 3] = std::array::from_fn(|a| lattice.spacing[a] / f64::from(factor));
    let fine = fine_dims(lattice.dims, factor);
    let (mut sum, mut worst, mut count, mut direct_count) = (0.0, 0.0f64, 0usize, 0usize);
    for &x in points {
        // The fine cell's lower corner, as `evaluate` picks it.
        let lo: [f64; 3] = std::array::from_fn(|a| {
            let g = ((x[a] - lattice.origin[a]) / h[a]).clamp(0.0, (fine[a] - 1) as f64);
            let cell = (g.floor() as usize).min(fine[a].saturating_sub(2));
            lattice.origin[a] + cell as f64 * h[a]
        });
        let cell = ResampledGrid::build([2, 2, 2], lo, h, 1, &corner);
        let Some(d) = direct(x) else {
            continue;
        };
        let fast = cell.evaluate(x);
        if fast.terms == DIRECT_TERMS {
            count += 1;
            direct_count += 1;
            continue;
        }
        if fast.terms == 0 {
            continue;
        }
        let e = (fast.value - d.value).abs() / range.max(f64::MIN_POSITIVE);
        sum += e * e;
        worst = worst.max(e);
        count += 1;
    }
    (count > 0).then(|| PilotError {
        rmse: (sum / count as f64).sqrt(),
        max: worst,
        direct_share: direct_count as f64 / count as f64,
    })
}

/// What fine point (f, ∇f) can contribute to the fast field anywhere in the fine cells around
/// it (fine spacing h): the field is a convex combination of the corners' f_c + ½ ∇f_c·(x − x_c)
/// with |x − x_c| ≤ h per axis, so each corner stays within f_c ± ½ Σ|∂f_c/∂x_a| h_a.
pub fn point_bounds(p: [f64; 4], h: [f64; 3]) -> [f64; 2] {
    // The general path's field near a direct point is bounded by nothing known here.
    if is_direct(&p) {
        return [f64::NEG_INFINITY, f64::INFINITY];
    }
    let e = 0.5 * (p[1].abs() * h[0] + p[2].abs() * h[1] + p[3].abs() * h[2]);
    [p[0] - e, p[0] + e]
}

/// Per block of `block`³ fine cells (x fastest) of a fine grid with `dims` points: the smallest
/// lower and the largest upper bound `bounds(at)` ([`point_bounds`]) of the stored points at
/// its (block + 1)³ fine points (`at` an index into the grid's data; paged: every copy of a point
/// on a face between pages, since a cell reads its own page's, and a block whose pages all share
/// one constant slot is that constant without reading its points). They bound the fast field
/// over the block rigorously (tested against dense sampling in `tests/resample.rs`), widened by
/// 8 ulps of their magnitude for the interpolant's own rounding. Undefined
/// points (NaN bounds) are left out: the field is undefined in every cell they touch; a block of
/// undefined points only gets [+∞, −∞], an empty range. Returns the block counts per axis and
/// the ranges.
pub fn block_ranges(
    dims: [usize; 3],
    block: usize,
    pages: Option<&Pages>,
    bounds: impl Fn(usize) -> [f64; 2] + Sync,
) -> ([usize; 3], Vec<[f64; 2]>) {
    let cells = dims.map(|d| d.saturating_sub(1).max(1));
    let blocks = cells.map(|c| c.div_ceil(block));
    let ranges = (0..blocks[0] * blocks[1] * blocks[2])
        .into_par_iter()
        .map(|n| {
            let b = [
                n % blocks[0],
                (n / blocks[0]) % blocks[1],
                n / (blocks[0] * blocks[1]),
            ];
            let lo = b.map(|v| v * block);
            let hi: [usize; 3] =
                std::array::from_fn(|a| ((b[a] + 1) * block).min(dims[a].saturating_sub(1)));
            let mut r = [f64::INFINITY, f64::NEG_INFINITY];
            let mut add = |v: [f64; 2]| r = [r[0].min(v[0]), r[1].max(v[1])];
            if let Some(c) = pages.and_then(|p| p.constant_over(lo, hi)) {
                add([c, c]);
                return r;
            }
            for k in lo[2]..=hi[2] {
                for j in lo[1]..=hi[1] {
                    for i in lo[0]..=hi[0] {
                        match pages {
                            None => add(bounds(i + dims[0] * (j + dims[1] * k))),
                            Some(p) => p.copies([i, j, k]).for_each(|at| add(bounds(at))),
                        }
                    }
                }
            }
            // The interpolant's own rounding: a convex combination of equal corners (one
            // sample's constant fit) may come out an ulp past them. A range at 0 stays exact.
            let ulps = 8.0 * f64::EPSILON * r[0].abs().max(r[1].abs());
            if ulps.is_finite() {
                r = [r[0] - ulps, r[1] + ulps];
            }
            r
        })
        .collect();
    (blocks, ranges)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A page of undefined points reaches the GPU as the undefined bits, and the pages' fine
    /// dimensions are the fine grid's.
    #[test]
    fn pages_agree_with_the_fine_grid() {
        use crate::recon::pages::{Constants, Reach, grid_reach};
        let fine = fine_dims([41, 41, 2], 2);
        let p = Pages::classify(fine, &[Reach::NONE; 25], Constants::Never).expect("paged");
        assert_eq!(p.gpu_slots()[0][1], UNDEFINED_BITS);
        let r = grid_reach([41, 41, 2], fine, 2, [1.0; 3], |_| 0.0);
        assert_eq!(r.len(), Pages::counts(fine).iter().product::<usize>());
    }

    /// A trilinear function is reproduced exactly, gradient channels included.
    #[test]
    fn trilinear_fields_are_exact() {
        let f = |x: [f64; 3]| 0.3 + 2.0 * x[0] - x[1] + 0.5 * x[2] + 0.25 * x[0] * x[1] * x[2];
        let grid = ResampledGrid::build([4, 3, 5], [-1.0, 0.5, 2.0], [0.5, 0.25, 1.0], 3, |x| {
            Some(MlsValue {
                value: f(x),
                gradient: [1.0, 2.0, 3.0],
                neighbours: 1,
                terms: 1,
            })
        });
        assert_eq!(grid.dims, [10, 7, 13]);
        for p in [
            [-0.9, 0.6, 2.1],
            [0.49, 0.99, 5.9],
            [0.0, 0.75, 4.0],
            [0.5, 1.0, 6.0],
        ] {
            let m = grid.evaluate(p);
            assert!(
                (m.value - f(p)).abs() < 1e-12,
                "{p:?}: {} vs {}",
                m.value,
                f(p)
            );
            assert!((m.gradient[2] - 3.0).abs() < 1e-12);
        }
        // Outside the box: clamped to the nearest point of the box.
        let m = grid.evaluate([-5.0, 0.6, 2.1]);
        assert!((m.value - f([-1.0, 0.6, 2.1])).abs() < 1e-12);
    }

    /// An undefined fine point makes every cell it touches undefined and leaves the block
    /// ranges; a block of undefined points only has an empty range.
    #[test]
    fn undefined_fine_points_stay_undefined() {
        let grid = ResampledGrid::build([3, 2, 2], [0.0; 3], [1.0; 3], 1, |x| {
            (x[0] < 1.5).then_some(MlsValue {
                value: x[1],
                gradient: [0.0, 1.0, 0.0],
                neighbours: 1,
                terms: 1,
            })
        });
        assert_eq!(grid.evaluate([0.5, 0.5, 0.5]).terms, 1);
        assert!((grid.evaluate([0.5, 0.25, 0.5]).value - 0.25).abs() < 1e-12);
        let m = grid.evaluate([1.5, 0.5, 0.5]);
        assert_eq!(
            (m.terms, m.value),
            (0, 0.0),
            "a cell with an undefined corner"
        );
        let (_, ranges) = block_ranges(grid.dims, 1, None, |at| {
            point_bounds(grid.data[at], [1.0; 3])
        });
        assert!(ranges[0][0] <= ranges[0][1] && ranges[0][1].is_finite());
        assert!(
            ranges[1][0] <= ranges[1][1],
            "defined corners still bound block 1"
        );
        let (_, ranges) = block_ranges([1, 1, 1], 1, None, |_| [f64::NAN; 2]);
        assert!(
            ranges[0][0] > ranges[0][1],
            "no defined point: {:?}",
            ranges[0]
        );
    }

    /// A block whose points all hold one value (one sample's constant fit) still bounds the
    /// interpolant, whose convex combination of equal corners may round an ulp past them.
    #[test]
    fn block_ranges_of_equal_points_allow_for_rounding() {
        let c = 0.259_439_796_209_335_3;
        let grid = ResampledGrid::build([4, 4, 4], [0.0; 3], [1.0; 3], 1, |_| {
            Some(MlsValue {
                value: c,
                gradient: [0.0; 3],
                neighbours: 1,
                terms: 1,
            })
        });
        let (_, ranges) = grid.block_ranges(4);
        let mut off = 0;
        for n in 0..4000 {
            let t = |k: u32| (n as f64 * 0.618_034 * f64::from(k)).fract();
            let v = grid.evaluate([t(1) * 3.0, t(2) * 3.0, t(3) * 3.0]).value;
            off += usize::from(v != c);
            assert!(
                v >= ranges[0][0] && v <= ranges[0][1],
                "{v} not in {:?}",
                ranges[0]
            );
        }
        assert!(
            off > 0,
            "every value rounded to c: the case is not exercised"
        );
    }

    /// Block ranges contain every value of the interpolant inside the block, and are attained.
    #[test]
    fn block_ranges_bound_the_interpolant() {
        let grid = ResampledGrid::build([6, 5, 4], [0.0; 3], [1.0; 3], 2, |x| {
            Some(MlsValue {
                value: (3.0 * x[0]).sin() * (2.0 * x[1]).cos() + x[2],
                gradient: [0.0; 3],
                neighbours: 1,
                terms: 1,
            })
        });
        let block = 3;
        let (blocks, ranges) = grid.block_ranges(block);
        assert_eq!(blocks, [4, 3, 2]);
        let h = 0.5 * block as f64;
        for n in 0..4000 {
            let t = |k: u32| (n as f64 * 0.618_034 * f64::from(k)).fract();
            let p = [t(1) * 5.0, t(2) * 4.0, t(3) * 3.0];
            let b = p.map(|c| (c / h).floor() as usize);
            let b = [b[0].min(3), b[1].min(2), b[2].min(1)];
            let r = ranges[b[0] + 4 * (b[1] + 3 * b[2])];
            let v = grid.evaluate(p).value;
            assert!(
                v >= r[0] - 1e-12 && v <= r[1] + 1e-12,
                "{p:?}: {v} not in {r:?}"
            );
        }
    }
}
