//! Per-sample supports ([MLS] §3 "Support"; DESIGN §1–2): the metric `M_i` of each sample's
//! ellipsoid `{x : (x − x_i)ᵀ M_i (x − x_i) < 1}`.
//!
//! - Isotropic: `h_i = support × d_k(i)`, the distance to the k-th nearest other sample
//!   (k-d tree, `kiddo`), so `M_i = I / h_i²`.
//! - Anisotropic, scattered samples: the shape comes from the second moment of the k nearest
//!   neighbours about x_i, `C = Σ_j (x_j − x_i)(x_j − x_i)ᵀ / k`; its eigenvectors are the
//!   ellipsoid's axes and `√λ` their relative lengths. The shape is then scaled so that the
//!   farthest of those k neighbours lies at ρ = 1/support, which makes the isotropic case
//!   coincide with the rule above.
//! - Anisotropic, unstructured meshes (point data): the same second moment over the point's
//!   one-ring (every point sharing a cell with it) instead of its k nearest neighbours, scaled
//!   so that the farthest one-ring point lies at ρ = 1/support. Cell data, sampled at
//!   centroids, uses the k nearest centroids.
//! - Anisotropic, curvilinear grids: the columns of `E = [e_i e_j e_k]` are the local
//!   index-direction edges (of the two one-sided edges per direction, the longer one, so that
//!   graded grids leave no holes); the ellipsoid is `support × E` applied to the unit ball,
//!   `M = (support² E Eᵀ)⁻¹`, which on a regular grid is the grid's own `h = support × Δ`.
//! - Rectilinear grids: diagonal, `h_a = support × the larger neighbouring gap` on each axis.
//!
//! Regularisation: every ellipsoid's axis lengths are clamped to at least `1/MAX_ASPECT` of its
//! longest axis, so flat or collinear neighbourhoods (points on a plane, a single grid layer)
//! never give a singular metric. MAX_ASPECT = 16 admits the 10:1 spacings of real
//! rectilinear and curvilinear grids unchanged.

use super::Metric;
use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use rayon::prelude::*;
use std::num::NonZero;

/// Largest ratio of an ellipsoid's longest to shortest axis.
pub const MAX_ASPECT: f64 = 16.0;

type Tree = ImmutableKdTree<f64, u32, 3, 32>;

/// Symmetric 3×3 as a full matrix.
fn full(m: &Metric) -> [[f64; 3]; 3] {
    [[m[0], m[3], m[4]], [m[3], m[1], m[5]], [m[4], m[5], m[2]]]
}

fn packed(a: &[[f64; 3]; 3]) -> Metric {
    [a[0][0], a[1][1], a[2][2], a[0][1], a[0][2], a[1][2]]
}

/// Eigen-decomposition of a symmetric 3×3 matrix by cyclic Jacobi rotations: (eigenvalues,
/// eigenvectors as columns of the returned matrix).
pub fn eigen_symmetric(m: &Metric) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut a = full(m);
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..32 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if off <= 1e-15 * scale || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in &mut a {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            let (rp, rq) = (a[p], a[q]);
            for k in 0..3 {
                a[p][k] = c * rp[k] - s * rq[k];
                a[q][k] = s * rp[k] + c * rq[k];
            }
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2]], v)
}

/// Σ_a w_a v_a v_aᵀ for eigenvectors v (columns) and weights w.
fn compose(v: &[[f64; 3]; 3], w: [f64; 3]) -> Metric {
    let mut out = [[0.0; 3]; 3];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, cell) in row.iter_mut().enumerate() {
            *cell = (0..3).map(|a| w[a] * v[r][a] * v[c][a]).sum();
        }
    }
    packed(&out)
}

/// The metric of the ellipsoid whose squared axis lengths are the eigenvalues of `cov`
/// (regularised to [`MAX_ASPECT`]), i.e. `cov⁻¹` with clamped eigenvalues.
pub fn metric_from_covariance(cov: &Metric) -> Metric {
    let (lambda, v) = eigen_symmetric(cov);
    let top = lambda.iter().copied().fold(0.0, f64::max);
    let floor = top / (MAX_ASPECT * MAX_ASPECT);
    compose(&v, lambda.map(|l| 1.0 / l.max(floor)))
}

/// Inverse of a symmetric positive-definite metric.
pub fn inverse(m: &Metric) -> Metric {
    let a = full(m);
    let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    let inv = 1.0 / det;
    [
        (a[1][1] * a[2][2] - a[1][2] * a[1][2]) * inv,
        (a[0][0] * a[2][2] - a[0][2] * a[0][2]) * inv,
        (a[0][0] * a[1][1] - a[0][1] * a[0][1]) * inv,
        (a[0][2] * a[1][2] - a[0][1] * a[2][2]) * inv,
        (a[0][1] * a[1][2] - a[0][2] * a[1][1]) * inv,
        (a[0][1] * a[0][2] - a[0][0] * a[1][2]) * inv,
    ]
}

/// Whether the ellipsoid's axes are not the coordinate axes (off-diagonal terms).
pub fn is_rotated(m: &Metric) -> bool {
    m[3] != 0.0 || m[4] != 0.0 || m[5] != 0.0
}

/// An upper bound on λ_max(M), so 1/√ of it bounds the shortest half axis from below: exact
/// for diagonal metrics, else the largest absolute row sum (Gershgorin).
pub fn largest_eigenvalue_bound(m: &Metric) -> f64 {
    if !is_rotated(m) {
        return m[0].max(m[1]).max(m[2]);
    }
    let (xy, xz, yz) = (m[3].abs(), m[4].abs(), m[5].abs());
    (m[0] + xy + xz).max(m[1] + xy + yz).max(m[2] + xz + yz)
}

/// An upper bound on the distance from the centre to any point of the ellipsoid: the largest
/// half axis for diagonal metrics, else √trace(M⁻¹) (the half diagonal of its bounding box).
pub fn reach(m: &Metric) -> f64 {
    if !is_rotated(m) {
        return 1.0 / m[0].min(m[1]).min(m[2]).sqrt();
    }
    let e = extent(m);
    (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt()
}

/// Half extents of the ellipsoid along the axes: √((M⁻¹)_aa).
pub fn extent(m: &Metric) -> [f64; 3] {
    let inv = inverse(m);
    [inv[0].sqrt(), inv[1].sqrt(), inv[2].sqrt()]
}

/// Geometric mean of the half axes: det(M)^(−1/6).
pub fn mean_radius(m: &Metric) -> f64 {
    let a = full(m);
    let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    det.powf(-1.0 / 6.0)
}

/// The k nearest other samples of every sample (fewer when there are fewer samples).
fn knn(positions: &[[f64; 3]], k: usize) -> KnnLists {
    knn_of_first(positions, positions.len(), k)
}

/// Neighbour lists of one length, flat, nearest first, in the order they were found (the
/// samples' Morton order): sample i's are `indices[r·stride .. (r+1)·stride]` for its rank
/// r = `rank[i]`. One allocation where a list per sample made 10⁷ of them at 10⁷ points,
/// whose freed memory the allocator kept (BENCHMARKS.md, "A point cloud's spacing from its
/// supports' neighbours"), and no second copy to put them in sample order.
pub struct KnnLists {
    stride: usize,
    rank: Vec<u32>,
    indices: Vec<u32>,
}

impl KnnLists {
    /// Sample i's list.
    pub fn get(&self, i: usize) -> &[u32] {
        let r = self.rank[i] as usize;
        &self.indices[r * self.stride..(r + 1) * self.stride]
    }

    /// The lists in sample order.
    pub fn iter(&self) -> impl Iterator<Item = &[u32]> {
        (0..self.rank.len()).map(|i| self.get(i))
    }

    /// The lists in sample order, for rayon.
    pub fn par_iter(&self) -> impl IndexedParallelIterator<Item = &[u32]> {
        (0..self.rank.len()).into_par_iter().map(|i| self.get(i))
    }
}

/// The `k` nearest other samples (indices into `positions`, nearest first) of each of the
/// first `first` samples: a part of a set whose neighbours come with it. Every list has
/// min(k, n − 1) entries for n samples; k ≥ 1 (`reconstruction.knn` is checked).
pub fn knn_of_first(positions: &[[f64; 3]], first: usize, k: usize) -> KnnLists {
    debug_assert!(k >= 1, "k nearest neighbours with k = 0");
    let stride = k.min(positions.len().saturating_sub(1));
    if first == 0 || stride == 0 {
        return KnnLists {
            stride: 0,
            rank: vec![0; first],
            indices: Vec::new(),
        };
    }
    let tree = Tree::new_from_slice(positions);
    let want = NonZero::new((k + 1).min(positions.len())).unwrap_or(NonZero::<usize>::MIN);
    // Queried in Morton order (see in_spatial_order), each list stored at its query's rank.
    let order = morton_order(&positions[..first]);
    let mut indices = vec![0u32; first * stride];
    indices
        .par_chunks_mut(stride)
        .zip(order.par_iter())
        .for_each(|(list, &i)| {
            let found = tree.nearest_n::<SquaredEuclidean>(&positions[i as usize], want);
            let others = found.into_iter().map(|n| n.item).filter(|&j| j != i);
            let filled = list
                .iter_mut()
                .zip(others)
                .map(|(slot, j)| *slot = j)
                .count();
            // want = min(k + 1, n) found, at most one of them i itself.
            debug_assert_eq!(filled, stride, "sample {i}: a short neighbour list");
        });
    let mut rank = vec![0u32; first];
    for (r, &i) in order.iter().enumerate() {
        rank[i as usize] = r as u32;
    }
    KnnLists {
        stride,
        rank,
        indices,
    }
}

/// `f(i)` for every sample i of `positions`, in parallel, returned in index order but computed
/// in the Morton order of the positions. A neighbourhood query then finds most of what it
/// reads in cache from the query before it: kd-tree queries over 10⁶ scattered points took
/// 2.5× less time in this order than in the points' own (BENCHMARKS.md, "A point cloud's
/// first frame"). Each result is `f`'s alone, so the order changes no value.
pub fn in_spatial_order<T, F>(positions: &[[f64; 3]], f: F) -> Vec<T>
where
    T: Send + Default + Clone,
    F: Fn(usize) -> T + Sync,
{
    in_spatial_order_where(positions, &|_| true, f)
}

/// [`in_spatial_order`] for the samples `keep` accepts; the others get `T::default()`.
pub fn in_spatial_order_where<T, F>(
    positions: &[[f64; 3]],
    keep: &(dyn Fn(usize) -> bool + Sync),
    f: F,
) -> Vec<T>
where
    T: Send + Default + Clone,
    F: Fn(usize) -> T + Sync,
{
    let computed: Vec<(u32, T)> = morton_order(positions)
        .into_par_iter()
        .filter(|&i| keep(i as usize))
        .map(|i| (i, f(i as usize)))
        .collect();
    let mut out = vec![T::default(); positions.len()];
    for (i, v) in computed {
        out[i as usize] = v;
    }
    out
}

/// Sample indices sorted by the Morton code of their positions over the points' bounding
/// box (21 bits an axis; ties by index, so the order is deterministic).
pub fn morton_order(positions: &[[f64; 3]]) -> Vec<u32> {
    let (lo, hi) = super::points_box(positions);
    let cells = f64::from((1u32 << 21) - 1);
    let scale = [0, 1, 2].map(|a| {
        let e = hi[a] - lo[a];
        if e > 0.0 && e.is_finite() {
            cells / e
        } else {
            0.0
        }
    });
    // Spreads the low 21 bits of v two bits apart.
    let spread = |v: u64| {
        let mut x = v & 0x1f_ffff;
        x = (x | x << 32) & 0x001f_0000_0000_ffff;
        x = (x | x << 16) & 0x001f_0000_ff00_00ff;
        x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
        x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
        (x | x << 2) & 0x1249_2492_4924_9249
    };
    let mut keyed: Vec<(u64, u32)> = positions
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let q = [0, 1, 2].map(|a| ((p[a] - lo[a]) * scale[a]).clamp(0.0, cells) as u64);
            (
                spread(q[0]) | spread(q[1]) << 1 | spread(q[2]) << 2,
                i as u32,
            )
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// The samples within squared distance r² of any of `balls` (centre, r²; r² = ∞ takes every
/// sample), each once, in index order: what a part of a set sends another part whose k
/// nearest neighbours may lie in it.
pub fn within_any(positions: &[[f64; 3]], balls: &[([f64; 3], f64)]) -> Vec<u32> {
    if positions.is_empty() || balls.is_empty() {
        return Vec::new();
    }
    if balls.iter().any(|b| !b.1.is_finite()) {
        return (0..positions.len() as u32).collect();
    }
    let tree = Tree::new_from_slice(positions);
    let found: Vec<Vec<u32>> = balls
        .par_iter()
        .map(|(c, r2)| {
            tree.within_unsorted::<SquaredEuclidean>(c, *r2)
                .into_iter()
                .map(|n| n.item)
                .collect()
        })
        .collect();
    let mut hit = vec![false; positions.len()];
    found.iter().flatten().for_each(|&i| hit[i as usize] = true);
    (0..positions.len() as u32)
        .filter(|&i| hit[i as usize])
        .collect()
}

/// Median distance from a sample to its nearest other sample.
pub fn nearest_spacing(positions: &[[f64; 3]]) -> f64 {
    if positions.len() < 2 {
        return 1.0;
    }
    // The nearest other sample of each, without a neighbour list per sample (10⁷ small
    // allocations at 10⁷ points).
    let tree = Tree::new_from_slice(positions);
    let two = NonZero::<usize>::MIN.saturating_add(1);
    median(in_spatial_order(positions, |i| {
        let p = positions[i];
        tree.nearest_n::<SquaredEuclidean>(&p, two)
            .into_iter()
            .map(|n| n.item as usize)
            .find(|&j| j != i)
            .map_or(0.0, |j| distance(p, positions[j]))
    }))
}

/// Each of the first samples' distance to its nearest other sample, read off neighbour lists
/// that hold it first ([`knn_of_first`]'s): what [`nearest_spacing`] finds with a tree and a
/// query of its own, the same distances.
pub fn nearest_distances(positions: &[[f64; 3]], neighbours: &KnnLists) -> Vec<f64> {
    positions
        .par_iter()
        .zip(neighbours.par_iter())
        .map(|(p, n)| {
            n.first()
                .map_or(0.0, |&j| distance(*p, positions[j as usize]))
        })
        .collect()
}

/// [`nearest_spacing`] from the neighbour lists ([`nearest_distances`]): the same median.
fn spacing_of_lists(positions: &[[f64; 3]], neighbours: &KnnLists) -> f64 {
    if positions.len() < 2 {
        return 1.0;
    }
    median(nearest_distances(positions, neighbours))
}

/// The median of a non-empty list, by selection (not a sort: 10⁷ distances at 10⁷ points).
fn median(mut d: Vec<f64>) -> f64 {
    let middle = d.len() / 2;
    *d.select_nth_unstable_by(middle, f64::total_cmp).1
}

fn offset(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [b[0] - a[0], b[1] - a[1], b[2] - a[2]]
}

/// |b − a|.
fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    let y = offset(a, b);
    (y[0] * y[0] + y[1] * y[1] + y[2] * y[2]).sqrt()
}

/// The metric of an axis-aligned ellipsoid with half axes h.
pub fn diagonal(h: [f64; 3]) -> Metric {
    [
        1.0 / (h[0] * h[0]),
        1.0 / (h[1] * h[1]),
        1.0 / (h[2] * h[2]),
        0.0,
        0.0,
        0.0,
    ]
}

fn isotropic(h: f64) -> Metric {
    diagonal([h; 3])
}

/// Per-sample supports and the sample spacing ([`nearest_spacing`]). Supports from the k
/// nearest neighbours ([`knn_supports`]) read the spacing off the same lists: a point cloud's
/// spacing needs no second tree and no second query per sample.
pub struct SupportsAndSpacing {
    pub metrics: Vec<Metric>,
    pub spacing: f64,
}

impl SupportsAndSpacing {
    /// Supports found otherwise (grid edges, one-rings), the spacing by its own search.
    pub fn measured(metrics: Vec<Metric>, positions: &[[f64; 3]]) -> Self {
        Self {
            metrics,
            spacing: nearest_spacing(positions),
        }
    }
}

/// The supports of every sample from its k nearest other samples: anisotropic, ellipsoids
/// from their second moment (module docs), else h_i = support × the distance to the k-th.
pub fn knn_supports(
    positions: &[[f64; 3]],
    support: f64,
    k: usize,
    anisotropic: bool,
) -> SupportsAndSpacing {
    let lists = knn(positions, k);
    let metrics = if anisotropic {
        anisotropic_neighbourhoods(positions, lists.par_iter(), support)
    } else {
        isotropic_neighbourhoods(positions, lists.par_iter(), support)
    };
    SupportsAndSpacing {
        metrics,
        spacing: spacing_of_lists(positions, &lists),
    }
}

/// Balls through the farthest of given neighbourhoods (sample indices), scaled by `support`:
/// one per neighbourhood, for the first samples of `positions`.
pub fn isotropic_neighbourhoods<'a>(
    positions: &[[f64; 3]],
    neighbours: impl IndexedParallelIterator<Item = &'a [u32]>,
    support: f64,
) -> Vec<Metric> {
    positions
        .par_iter()
        .zip(neighbours)
        .map(|(p, n)| {
            let d = n
                .iter()
                .map(|&j| distance(*p, positions[j as usize]))
                .fold(0.0, f64::max);
            isotropic(support * d.max(f64::MIN_POSITIVE))
        })
        .collect()
}

/// Ellipsoids from the second moment of given neighbourhoods (sample indices), each scaled so
/// that its farthest neighbour lies at ρ = 1/support, for the first samples of `positions`.
pub fn anisotropic_neighbourhoods<'a>(
    positions: &[[f64; 3]],
    neighbours: impl IndexedParallelIterator<Item = &'a [u32]>,
    support: f64,
) -> Vec<Metric> {
    positions
        .par_iter()
        .zip(neighbours)
        .map(|(p, n)| {
            anisotropic_neighbourhood(*p, n.iter().map(|&j| positions[j as usize]), support)
        })
        .collect()
}

/// The anisotropic support of a sample at `p` from its neighbours' positions, summed in their
/// order ([`anisotropic_neighbourhoods`] of one sample).
pub fn anisotropic_neighbourhood(
    p: [f64; 3],
    neighbours: impl Iterator<Item = [f64; 3]>,
    support: f64,
) -> Metric {
    let ys: Vec<[f64; 3]> = neighbours.map(|q| offset(p, q)).collect();
    let mut cov = [0.0; 6];
    for y in &ys {
        add_outer(&mut cov, y);
    }
    let shape = metric_from_covariance(&cov.map(|c| c / ys.len().max(1) as f64));
    let far = ys
        .iter()
        .map(|y| super::metric_rho2(&shape, *y))
        .fold(0.0, f64::max);
    let scale = 1.0 / (support * support * far.max(f64::MIN_POSITIVE));
    shape.map(|m| m * scale)
}

/// Adds `y yᵀ` to the symmetric `cov` (xx, yy, zz, xy, xz, yz).
fn add_outer(cov: &mut [f64; 6], y: &[f64; 3]) {
    cov[0] += y[0] * y[0];
    cov[1] += y[1] * y[1];
    cov[2] += y[2] * y[2];
    cov[3] += y[0] * y[1];
    cov[4] += y[0] * y[2];
    cov[5] += y[1] * y[2];
}

/// The one-ring of every point of a mesh: the other points of the cells it belongs to.
/// `remap` maps mesh point indices to sample indices (after duplicates were merged).
pub fn one_rings(
    cells: &crate::data::dataset::Cells,
    remap: &[u32],
    samples: usize,
) -> Vec<Vec<u32>> {
    let mut rings: Vec<Vec<u32>> = vec![Vec::new(); samples];
    for c in 0..cells.len() {
        let ids = cells.cell(c);
        for &a in ids {
            for &b in ids {
                let (a, b) = (remap[a as usize], remap[b as usize]);
                if a != b {
                    rings[a as usize].push(b);
                }
            }
        }
    }
    for r in &mut rings {
        r.sort_unstable();
        r.dedup();
    }
    rings
}

/// Diagonal supports of a rectilinear grid (module docs). A single-coordinate axis takes the
/// largest gap of the other axes.
pub fn rectilinear(coords: &[Vec<f64>; 3], support: f64) -> Vec<Metric> {
    let r = RectilinearSupports::new(coords, support);
    let dims = coords.each_ref().map(Vec::len);
    (0..dims[0] * dims[1] * dims[2])
        .map(|i| {
            r.at([
                i % dims[0],
                (i / dims[0]) % dims[1],
                i / (dims[0] * dims[1]),
            ])
        })
        .collect()
}

/// [`rectilinear`]'s supports, one grid index at a time: for a part of the grid whose whole
/// coordinates are known.
pub struct RectilinearSupports {
    gaps: [Vec<f64>; 3],
    widest: f64,
    support: f64,
}

impl RectilinearSupports {
    pub fn new(coords: &[Vec<f64>; 3], support: f64) -> Self {
        let gaps: [Vec<f64>; 3] = coords.clone().map(|c| {
            (0..c.len())
                .map(|i| {
                    let left = if i > 0 { c[i] - c[i - 1] } else { 0.0 };
                    let right = if i + 1 < c.len() {
                        c[i + 1] - c[i]
                    } else {
                        0.0
                    };
                    left.max(right)
                })
                .collect()
        });
        let widest = gaps
            .iter()
            .flatten()
            .copied()
            .fold(f64::MIN_POSITIVE, f64::max);
        Self {
            gaps,
            widest,
            support,
        }
    }

    /// The metric at grid index `idx`.
    pub fn at(&self, idx: [usize; 3]) -> Metric {
        let h = [0, 1, 2].map(|a| {
            let g = self.gaps[a][idx[a]];
            self.support * if g > 0.0 { g } else { self.widest }
        });
        diagonal(h)
    }
}

/// Ellipsoids spanned by the local index-direction edges of a curvilinear grid.
pub fn structured(dims: [usize; 3], points: &[[f64; 3]], support: f64) -> Vec<Metric> {
    (0..points.len())
        .into_par_iter()
        .map(|n| {
            structured_at(grid_index(dims, n), dims, support, |q| {
                points[q[0] + dims[0] * (q[1] + dims[1] * q[2])]
            })
        })
        .collect()
}

/// The (i, j, k) of sample `n` of a grid of `dims` samples, i fastest.
pub fn grid_index(dims: [usize; 3], n: usize) -> [usize; 3] {
    [
        n % dims[0],
        (n / dims[0]) % dims[1],
        n / (dims[0] * dims[1]),
    ]
}

/// The index-direction neighbours of sample `idx` of a grid of `dims` samples, which
/// [`structured_at`] reads: one step either way along every axis with two samples or more.
pub fn edge_neighbours(idx: [usize; 3], dims: [usize; 3]) -> impl Iterator<Item = [usize; 3]> {
    (0..3).filter(move |&a| dims[a] >= 2).flat_map(move |a| {
        [-1isize, 1].into_iter().filter_map(move |d| {
            let v = idx[a] as isize + d;
            (v >= 0 && v < dims[a] as isize).then(|| {
                let mut q = idx;
                q[a] = v as usize;
                q
            })
        })
    })
}

/// The support of sample `idx` of a curvilinear grid of `dims` samples (module docs): from
/// its position and its neighbours' along each index direction, `point(q)` of sample q.
pub fn structured_at(
    idx: [usize; 3],
    dims: [usize; 3],
    support: f64,
    point: impl Fn([usize; 3]) -> [f64; 3],
) -> Metric {
    let here = point(idx);
    let mut cov = [0.0; 6];
    for a in 0..3 {
        if dims[a] < 2 {
            continue;
        }
        let step = |d: isize| -> Option<[f64; 3]> {
            let mut q = idx;
            let v = q[a] as isize + d;
            if v < 0 || v >= dims[a] as isize {
                return None;
            }
            q[a] = v as usize;
            Some(offset(here, point(q)))
        };
        let len2 = |e: &[f64; 3]| e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
        let e = match (step(-1), step(1)) {
            (Some(l), Some(r)) => {
                if len2(&l) > len2(&r) {
                    l
                } else {
                    r
                }
            }
            (Some(e), None) | (None, Some(e)) => e,
            (None, None) => continue,
        };
        add_outer(&mut cov, &e);
    }
    let s2 = support * support;
    metric_from_covariance(&cov.map(|c| c * s2))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neighbour_queries_in_morton_order_keep_their_results() {
        // The corners of a cube, given in reverse: Morton order is x, then y, then z bits.
        let corners: Vec<[f64; 3]> = (0..8)
            .rev()
            .map(|c| [0, 1, 2].map(|a| f64::from(c >> a & 1)))
            .collect();
        assert_eq!(morton_order(&corners), vec![7, 6, 5, 4, 3, 2, 1, 0]);
        // A flat set (all z equal) and coincident points: still a permutation.
        let flat = [[0.5, 0.0, 1.0], [0.0, 0.0, 1.0], [0.5, 0.0, 1.0]];
        assert_eq!(morton_order(&flat), vec![1, 0, 2]);
        let pts: Vec<[f64; 3]> = (0..1000)
            .map(|i| {
                let t = f64::from(i);
                [
                    (t * 0.618).fract(),
                    (t * 0.414).fract(),
                    (t * 0.732).fract(),
                ]
            })
            .collect();
        let doubled = in_spatial_order(&pts, |i| 2 * i);
        assert!(doubled.iter().enumerate().all(|(i, &v)| v == 2 * i));
        // The k nearest neighbours' distances agree with a brute-force search (this lattice
        // has ties, so which of two equidistant samples comes first is not compared).
        let d2 = |i: usize, j: usize| (0..3).map(|a| (pts[i][a] - pts[j][a]).powi(2)).sum::<f64>();
        let knn = knn_of_first(&pts, pts.len(), 4);
        for (i, found) in knn.iter().enumerate().step_by(37) {
            let mut all: Vec<f64> = (0..pts.len())
                .filter(|&j| j != i)
                .map(|j| d2(i, j))
                .collect();
            all.sort_by(f64::total_cmp);
            assert_eq!(found.len(), 4, "sample {i}");
            assert!(!found.contains(&(i as u32)), "sample {i} found itself");
            for (&j, want) in found.iter().zip(&all[..4]) {
                assert!(
                    (d2(i, j as usize) - want).abs() < 1e-12,
                    "sample {i}: {found:?}"
                );
            }
        }
        // A part's lists are the whole set's first ones; fewer samples than k make shorter
        // lists, each without its own sample.
        let part = knn_of_first(&pts, 10, 4);
        assert!((0..10).all(|i| part.get(i) == knn.get(i)));
        assert_eq!(part.iter().count(), 10);
        let few = knn_of_first(&pts[..3], 3, 8);
        for (i, list) in few.iter().enumerate() {
            let mut list = list.to_vec();
            list.sort_unstable();
            let others: Vec<u32> = (0..3).filter(|&j| j != i as u32).collect();
            assert_eq!(list, others, "sample {i}");
        }
        assert_eq!(knn_of_first(&pts[..1], 1, 8).iter().count(), 1);
        assert_eq!(knn_of_first(&pts, 0, 8).iter().count(), 0);
        assert_eq!(
            knn_supports(&pts[..3], 1.5, 8, false).spacing.to_bits(),
            nearest_spacing(&pts[..3]).to_bits()
        );
        // The spacing is the median nearest-neighbour distance, by brute force.
        let mut nearest: Vec<f64> = (0..pts.len())
            .map(|i| {
                (0..pts.len())
                    .filter(|&j| j != i)
                    .map(|j| d2(i, j))
                    .fold(f64::INFINITY, f64::min)
                    .sqrt()
            })
            .collect();
        nearest.sort_by(f64::total_cmp);
        let spacing = nearest_spacing(&pts);
        assert!(
            (spacing - nearest[500]).abs() < 1e-12,
            "{spacing} vs {}",
            nearest[500]
        );
        // The supports' neighbour lists give the same spacing to the bit, also where samples
        // coincide (a copy of every fourth one: 500 of the 1 250 distances are 0).
        assert_eq!(
            knn_supports(&pts, 1.5, 8, false).spacing.to_bits(),
            spacing.to_bits()
        );
        assert_eq!(
            knn_supports(&pts, 1.5, 3, true).spacing.to_bits(),
            spacing.to_bits()
        );
        let mut doubled = pts.clone();
        doubled.extend(pts.iter().step_by(4));
        let with_copies = nearest_spacing(&doubled);
        assert!(with_copies > 0.0 && with_copies < spacing, "{with_copies}");
        assert_eq!(
            knn_supports(&doubled, 1.5, 8, false).spacing.to_bits(),
            with_copies.to_bits()
        );
    }

    #[test]
    fn jacobi_reconstructs_a_rotated_metric() {
        let m: Metric = [4.0, 2.0, 1.0, 0.5, -0.3, 0.2];
        let (l, v) = eigen_symmetric(&m);
        let back = compose(&v, l);
        for (a, b) in m.iter().zip(&back) {
            assert!((a - b).abs() < 1e-12, "{m:?} vs {back:?}");
        }
        let inv = inverse(&m);
        let (li, _) = eigen_symmetric(&inv);
        let mut p: Vec<f64> = l.iter().map(|x| 1.0 / x).collect();
        let mut q = li.to_vec();
        p.sort_by(f64::total_cmp);
        q.sort_by(f64::total_cmp);
        for (a, b) in p.iter().zip(&q) {
            assert!((a - b).abs() < 1e-12);
        }
    }

    #[test]
    fn flat_neighbourhood_is_regularised() {
        // Points on the plane z = 0: the covariance is singular, the metric must not be.
        let mut pts = Vec::new();
        for j in 0..5 {
            for i in 0..5 {
                pts.push([i as f64, j as f64, 0.0]);
            }
        }
        for m in knn_supports(&pts, 1.5, 8, true).metrics {
            let (l, _) = eigen_symmetric(&m);
            let (lo, hi) = (
                l.iter().copied().fold(f64::MAX, f64::min),
                l.iter().copied().fold(0.0, f64::max),
            );
            assert!(
                lo > 0.0 && hi / lo <= MAX_ASPECT * MAX_ASPECT * (1.0 + 1e-9),
                "{l:?}"
            );
        }
    }
}
