//! A brick's samples: its own and its ghosts (issue 30 §2), so that MLS anywhere in the
//! brick's box equals the undivided field's value.
//!
//! MLS at x reads exactly the samples whose support holds x (w_i(x) = θ(ρ_i(x)) with θ = 0 for
//! ρ ≥ 1, [MLS] §3). A brick's box B therefore needs every sample i with ρ_i(x) < 1 for some
//! x ∈ B, i.e. dist_M(x_i, B) = min over x ∈ B of √((x − x_i)ᵀ M_i (x − x_i)) < 1:
//! - a regular grid brick, cut at sample planes, takes ⌈h_a/Δ_a⌉ − 1 extra sample planes on
//!   each side along each axis a (h the support's radius): the k-th plane outside a face lies
//!   k·Δ from it, and k·Δ < h for exactly those k;
//! - an irregular sample is a ghost of B iff dist_M(x_i, B) < 1, computed exactly
//!   ([`metric_distance2`]: a convex quadratic over a box, minimised over the 27 ways its
//!   coordinates can be free or at a face).
//!
//! A brick keeps the whole field's domain (its hull or box: the rays' segments, and so their
//! step positions, are the undivided field's) and is clipped to its box when rendered.
//!
//! A splatting brick needs other samples: the kernels that add to a sheet it owns in the view
//! it renders ([`super::splat`]); a grid brick takes the sub-grid that holds them all.

use super::Aabb;
use super::splat::SplatReach;
use crate::samples::supports::is_rotated;
use crate::samples::{Metric, Positions, SampleSet, Supports, metric_rho2};
use glam::DVec3;

/// How many of a brick's samples lie in its box (a grid's face planes in both bricks that share
/// them; an irregular brick's own samples come first) and how many are ghosts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GhostCount {
    pub own: usize,
    pub ghosts: usize,
}

/// A brick's samples, their counts, and which samples of the whole set they are (in order).
pub struct BrickSamples {
    pub samples: SampleSet,
    pub count: GhostCount,
    pub indices: Vec<usize>,
}

/// Which samples besides its own a brick takes.
#[derive(Debug, Clone, Copy)]
pub enum Ghosts<'a> {
    /// None: the comparison that shows why ghosts are needed.
    Off,
    /// Every sample whose support reaches the box: MLS anywhere in it is the undivided value.
    Mls,
    /// Every kernel that adds to a sheet the brick's kd cell owns in the view the reach was
    /// made for.
    Splat(&'a SplatReach),
}

/// The kd cell of the brick `bounds` of `samples`: its faces on the domain's box at infinity
/// ([`crate::splat::brick_cell`]).
pub fn cell_of(samples: &SampleSet, bounds: Aabb) -> Aabb {
    let (lo, hi) = samples.domain_box();
    let (a, b) = crate::splat::brick_cell(
        (DVec3::from(bounds.0), DVec3::from(bounds.1)),
        (DVec3::from(lo), DVec3::from(hi)),
    );
    (a.to_array(), b.to_array())
}

/// The samples of the brick `bounds` of `samples` with `ghosts`. `owner(x)` says whether a
/// sample at x belongs to this brick (the kd tree's rule, so that every sample is own in
/// exactly one brick).
pub fn brick_samples(
    samples: &SampleSet,
    bounds: Aabb,
    owner: impl Fn([f64; 3]) -> bool,
    ghosts: Ghosts<'_>,
) -> BrickSamples {
    match (&samples.positions, &samples.supports) {
        (
            Positions::Grid {
                dims,
                origin,
                spacing,
            },
            Supports::Uniform(h),
        ) => grid_brick(samples, *dims, *origin, *spacing, *h, bounds, ghosts),
        _ => scattered_brick(samples, bounds, owner, ghosts),
    }
}

/// A sub-grid: the planes of the box, plus ⌈h/Δ⌉ − 1 on each side where the grid has them
/// (MLS ghosts), or as many as hold every kernel the brick's sheets need (splatting's).
fn grid_brick(
    samples: &SampleSet,
    dims: [usize; 3],
    origin: [f64; 3],
    spacing: [f64; 3],
    h: [f64; 3],
    (lo, hi): Aabb,
    ghosts: Ghosts<'_>,
) -> BrickSamples {
    // A splatting brick's kernels: the index box of those it needs.
    let needed = match ghosts {
        Ghosts::Splat(reach) => {
            let cell = cell_of(samples, (lo, hi));
            let (mut a, mut b) = ([i64::MAX; 3], [i64::MIN; 3]);
            for i in (0..dims.iter().product()).filter(|&i| reach.meets(i, cell)) {
                let ijk = [
                    i % dims[0],
                    (i / dims[0]) % dims[1],
                    i / (dims[0] * dims[1]),
                ];
                for k in 0..3 {
                    a[k] = a[k].min(ijk[k] as i64);
                    b[k] = b[k].max(ijk[k] as i64);
                }
            }
            Some((a, b))
        }
        _ => None,
    };
    let layers = match ghosts {
        Ghosts::Mls => mls_layers(h, spacing),
        _ => [0; 3],
    };
    let (first, count, own) = grid_window(dims, origin, spacing, (lo, hi), layers, needed);
    let mut indices = Vec::with_capacity(count.iter().product());
    for k in 0..count[2] {
        for j in 0..count[1] {
            let row = ((first[2] + k) * dims[1] + first[1] + j) * dims[0] + first[0];
            indices.extend(row..row + count[0]);
        }
    }
    let total = indices.len();
    let samples = SampleSet {
        positions: Positions::Grid {
            dims: count,
            origin: [0, 1, 2].map(|a| origin[a] + first[a] as f64 * spacing[a]),
            spacing,
        },
        values: samples.values.select(&indices),
        supports: samples.supports.clone(),
        domain: samples.domain.clone(),
        spacing: samples.spacing,
        provenance: samples.provenance.clone(),
    };
    BrickSamples {
        samples,
        count: GhostCount {
            own,
            ghosts: total - own,
        },
        indices,
    }
}

/// MLS's ghost planes on each side of a grid brick: ⌈h/Δ⌉ − 1 along each axis.
pub fn mls_layers(h: [f64; 3], spacing: [f64; 3]) -> [i64; 3] {
    [0, 1, 2].map(|a| ((h[a] / spacing[a]).ceil() as i64 - 1).max(0))
}

/// A grid brick's window: the first sample index and the sample count along each axis, and
/// how many of its samples lie in the box `(lo, hi)`: the planes of the box, `layers` more on
/// each side where the grid has them, widened to hold the index box `needed`.
pub fn grid_window(
    dims: [usize; 3],
    origin: [f64; 3],
    spacing: [f64; 3],
    (lo, hi): Aabb,
    layers: [i64; 3],
    needed: Option<([i64; 3], [i64; 3])>,
) -> ([usize; 3], [usize; 3], usize) {
    let mut first = [0usize; 3];
    let mut count = [0usize; 3];
    let mut own = 1usize;
    for a in 0..3 {
        let last = dims[a] as i64 - 1;
        let i0 = (((lo[a] - origin[a]) / spacing[a]).round() as i64).clamp(0, last);
        let i1 = (((hi[a] - origin[a]) / spacing[a]).round() as i64).clamp(0, last);
        let (mut g0, mut g1) = ((i0 - layers[a]).max(0), (i1 + layers[a]).min(last));
        if let Some((n0, n1)) = needed {
            (g0, g1) = (g0.min(n0[a]), g1.max(n1[a]));
        }
        first[a] = g0 as usize;
        count[a] = (g1 - g0 + 1) as usize;
        own *= (i1 - i0 + 1) as usize;
    }
    (first, count, own)
}

/// Own samples first, then every other sample whose support reaches the box.
fn scattered_brick(
    samples: &SampleSet,
    bounds: Aabb,
    owner: impl Fn([f64; 3]) -> bool,
    ghosts: Ghosts<'_>,
) -> BrickSamples {
    let (mut own, mut extra) = (Vec::new(), Vec::new());
    let cell = cell_of(samples, bounds);
    for i in 0..samples.len() {
        let x = samples.position(i);
        let ghost = || match ghosts {
            Ghosts::Off => false,
            Ghosts::Mls => reaches(samples, i, x, bounds),
            Ghosts::Splat(reach) => reach.meets(i, cell),
        };
        if owner(x) {
            own.push(i);
        } else if ghost() {
            extra.push(i);
        }
    }
    let count = GhostCount {
        own: own.len(),
        ghosts: extra.len(),
    };
    own.extend(extra);
    let positions = Positions::Scattered(own.iter().map(|&i| samples.position(i)).collect());
    let supports = match &samples.supports {
        Supports::Uniform(h) => Supports::Uniform(*h),
        Supports::PerSample(m) => Supports::PerSample(own.iter().map(|&i| m[i]).collect()),
    };
    let brick = SampleSet {
        positions,
        values: samples.values.select(&own),
        supports,
        domain: samples.domain.clone(),
        spacing: samples.spacing,
        provenance: samples.provenance.clone(),
    };
    BrickSamples {
        samples: brick,
        count,
        indices: own,
    }
}

/// Whether sample i's support reaches the box: its bounding box first (cheap, and exact for
/// a box that misses it), then the metric distance.
fn reaches(samples: &SampleSet, i: usize, x: [f64; 3], bounds: Aabb) -> bool {
    support_reaches(&samples.metric(i), samples.support_extent(i), x, bounds)
}

/// Whether the support of metric `m` and half extents `e` at x reaches the box: the MLS ghost
/// rule, for a sample held apart from its set.
pub fn support_reaches(m: &Metric, e: [f64; 3], x: [f64; 3], (lo, hi): Aabb) -> bool {
    if (0..3).any(|a| x[a] + e[a] <= lo[a] || x[a] - e[a] >= hi[a]) {
        return false;
    }
    metric_distance2(m, x, lo, hi) < 1.0
}

/// min over y ∈ [lo, hi] of (y − x)ᵀM(y − x), M positive definite: the minimiser has each
/// coordinate free or at a face, and for each of the 27 choices the free coordinates solve
/// M_FF (y_F − x_F) = −M_FC (y_C − x_C) (the gradient's free part vanishes); the feasible
/// candidate with the least value is the minimum (the problem is convex, so its KKT point is
/// among them).
pub fn metric_distance2(m: &Metric, x: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> f64 {
    if !is_rotated(m) {
        let y: [f64; 3] = [0, 1, 2].map(|a| x[a].clamp(lo[a], hi[a]) - x[a]);
        return metric_rho2(m, y);
    }
    let full = [[m[0], m[3], m[4]], [m[3], m[1], m[5]], [m[4], m[5], m[2]]];
    let mut best = f64::INFINITY;
    for code in 0..27usize {
        let state = [code % 3, (code / 3) % 3, code / 9];
        // d = y − x on the fixed coordinates; the free ones are solved below.
        let mut d = [0.0f64; 3];
        let free: Vec<usize> = (0..3).filter(|&a| state[a] == 0).collect();
        for a in 0..3 {
            d[a] = match state[a] {
                1 => lo[a] - x[a],
                2 => hi[a] - x[a],
                _ => 0.0,
            };
        }
        // Right-hand side: −M_FC d_C.
        let rhs: Vec<f64> = free
            .iter()
            .map(|&r| {
                -(0..3)
                    .filter(|c| state[*c] != 0)
                    .map(|c| full[r][c] * d[c])
                    .sum::<f64>()
            })
            .collect();
        let sub = |r: usize, c: usize| full[free[r]][free[c]];
        let solved: Option<Vec<f64>> = match free.len() {
            0 => Some(Vec::new()),
            1 => Some(vec![rhs[0] / sub(0, 0)]),
            2 => {
                let det = sub(0, 0) * sub(1, 1) - sub(0, 1) * sub(1, 0);
                (det != 0.0).then(|| {
                    vec![
                        (rhs[0] * sub(1, 1) - rhs[1] * sub(0, 1)) / det,
                        (sub(0, 0) * rhs[1] - sub(1, 0) * rhs[0]) / det,
                    ]
                })
            }
            // All free: the rhs is zero and so is d; feasible iff x is in the box.
            _ => Some(vec![0.0; 3]),
        };
        let Some(v) = solved else { continue };
        for (k, &a) in free.iter().enumerate() {
            d[a] = v[k];
        }
        let tolerance = 1e-12 * (0..3).map(|a| hi[a] - lo[a]).fold(1.0, f64::max);
        let feasible = free
            .iter()
            .all(|&a| x[a] + d[a] >= lo[a] - tolerance && x[a] + d[a] <= hi[a] + tolerance);
        if feasible {
            best = best.min(metric_rho2(m, d));
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force over a fine lattice of the box, for comparison.
    fn sampled(m: &Metric, x: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> f64 {
        let n = 60;
        let mut best = f64::INFINITY;
        for i in 0..=n {
            for j in 0..=n {
                for k in 0..=n {
                    let y = [i, j, k]
                        .iter()
                        .enumerate()
                        .map(|(a, &t)| lo[a] + (hi[a] - lo[a]) * t as f64 / n as f64 - x[a])
                        .collect::<Vec<_>>();
                    best = best.min(metric_rho2(m, [y[0], y[1], y[2]]));
                }
            }
        }
        best
    }

    #[test]
    fn metric_distance_is_the_minimum_over_the_box() {
        // A rotated ellipsoid, long along (1, 1, 0): M = R diag(1/4, 4, 1) Rᵀ.
        let (c, s) = (0.5f64.sqrt(), 0.5f64.sqrt());
        let (a, b) = (0.25, 4.0);
        let m: Metric = [
            a * c * c + b * s * s,
            a * s * s + b * c * c,
            1.0,
            (a - b) * c * s,
            0.0,
            0.0,
        ];
        let (lo, hi) = ([0.0, 0.0, 0.0], [1.0, 0.5, 0.8]);
        for x in [
            [-1.0, -1.0, 0.4],
            [2.0, -0.3, 1.5],
            [-0.5, 1.2, -0.7],
            [0.5, 0.25, 0.4],
            [1.3, 0.9, 0.2],
        ] {
            let exact = metric_distance2(&m, x, lo, hi);
            let brute = sampled(&m, x, lo, hi);
            // The lattice can only overestimate, by at most its spacing's share.
            assert!(exact <= brute + 1e-12, "{x:?}: {exact} > {brute}");
            assert!(
                brute - exact < 0.05 * brute.max(0.1),
                "{x:?}: {exact} vs {brute}"
            );
        }
        assert_eq!(metric_distance2(&m, [0.5, 0.25, 0.4], lo, hi), 0.0);
    }
}
