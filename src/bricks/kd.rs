//! The kd decomposition (issue 30 §2): one axis-aligned box per rank, cut at sample-count
//! medians, and the boxes' visibility order from an eye.
//!
//! Each split halves the ranks (⌊n/2⌋ below the plane, the rest above) along the box's longest
//! axis, at the quantile of the samples' coordinates that gives each side its ranks' share.
//! The quantile is read from a subsample of about [`SUBSAMPLE`] samples: every sample costs
//! about the same (a kernel to splat; an MLS solve over a support that holds about the same
//! count of samples everywhere, kNN supports being sized so), so the count is the cost. A grid
//! is cut at one of its sample planes, so that every brick is a sub-grid whose faces carry
//! samples. The boxes tile the domain's bounding box: a point belongs to the box it falls in,
//! a point on a plane to the box above it ([`KdTree::owner`]).

use super::{Aabb, BrickError};
use crate::data::dataset::grid_point;
use crate::samples::{Positions, SampleSet};

/// Samples the quantiles are read from: a grid's every s-th, scattered samples' about this
/// many ([`picked`]).
pub const SUBSAMPLE: usize = 1 << 16;

/// A node of the tree: a rank's box, or a plane with the nodes below and above it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum KdNode {
    Leaf {
        rank: usize,
    },
    Split {
        axis: usize,
        plane: f64,
        below: usize,
        above: usize,
    },
}

/// The decomposition: nodes (the root first) and each rank's box.
#[derive(Debug, Clone, PartialEq)]
pub struct KdTree {
    pub nodes: Vec<KdNode>,
    pub boxes: Vec<Aabb>,
}

/// Where rays come from: a perspective eye, or (orthographic) the direction every ray travels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Viewpoint {
    Eye([f64; 3]),
    Direction([f64; 3]),
}

/// A grid's planes, where a grid is cut.
#[derive(Debug, Clone, Copy)]
struct Planes {
    origin: [f64; 3],
    spacing: [f64; 3],
    dims: [usize; 3],
}

/// Every how many samples of `n` the quantiles read one.
pub fn subsample_stride(n: usize) -> usize {
    n.div_ceil(SUBSAMPLE).max(1)
}

/// The subsample of a grid's `n` samples at `position(i)` that the quantiles are read from:
/// every [`subsample_stride`]-th by index.
fn subsample(n: usize, position: impl Fn(usize) -> [f64; 3]) -> Vec<[f64; 3]> {
    (0..n).step_by(subsample_stride(n)).map(position).collect()
}

/// Whether scattered samples' subsample holds the sample at `p`, one in `stride` of them: by a
/// hash of its coordinates' bits, not by its index, so that ranks that read a file's pieces
/// apart pick the same samples as one process that read it whole, whatever order the pieces
/// left them in and whichever copies of a shared point were merged (SplitMix64's finaliser
/// over the three coordinates).
pub fn picked(p: [f64; 3], stride: usize) -> bool {
    let mix = |mut z: u64| {
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    let h = p
        .iter()
        .fold(0x9e37_79b9_7f4a_7c15u64, |h, c| mix(h ^ c.to_bits()));
    h % stride.max(1) as u64 == 0
}

/// Of `points`, part of a scattered set of `total` samples, those its subsample holds
/// ([`picked`]).
pub fn picked_of(points: impl Iterator<Item = [f64; 3]>, total: usize) -> Vec<[f64; 3]> {
    let stride = subsample_stride(total);
    points.filter(|&p| picked(p, stride)).collect()
}

impl KdTree {
    /// Cuts the bounding box of `samples`' domain into `ranks` boxes.
    pub fn decompose(samples: &SampleSet, ranks: usize) -> Result<Self, BrickError> {
        let planes = match &samples.positions {
            Positions::Grid {
                dims,
                origin,
                spacing,
            } => Some(Planes {
                origin: *origin,
                spacing: *spacing,
                dims: *dims,
            }),
            Positions::Scattered(_) => None,
        };
        let points = match planes {
            Some(_) => subsample(samples.len(), |i| samples.position(i)),
            None => picked_of(
                (0..samples.len()).map(|i| samples.position(i)),
                samples.len(),
            ),
        };
        Self::build(points, planes, samples.domain_box(), ranks)
    }

    /// The tree of scattered samples in `domain` from `points`, a subsample of them taken by
    /// the caller (as [`picked`] takes it from the whole set: the samples of a parallel file
    /// that the ranks read in parts), or any subsample for a tree that only routes samples.
    pub fn decompose_points(
        points: Vec<[f64; 3]>,
        domain: Aabb,
        ranks: usize,
    ) -> Result<Self, BrickError> {
        Self::build(points, None, domain, ranks)
    }

    /// [`KdTree::decompose`] of a regular grid's samples (`dims` points from `origin`,
    /// `spacing` apart) in the domain box `domain`, known without its values: the same tree.
    pub fn decompose_grid(
        dims: [usize; 3],
        origin: [f64; 3],
        spacing: [f64; 3],
        domain: Aabb,
        ranks: usize,
    ) -> Result<Self, BrickError> {
        let planes = Planes {
            origin,
            spacing,
            dims,
        };
        let points = subsample(dims.iter().product(), |i| {
            grid_point(dims, origin, spacing, i)
        });
        Self::build(points, Some(planes), domain, ranks)
    }

    /// The tree of the subsample `points` in `domain`, cut at grid `planes` if any.
    fn build(
        points: Vec<[f64; 3]>,
        planes: Option<Planes>,
        domain: Aabb,
        ranks: usize,
    ) -> Result<Self, BrickError> {
        if ranks == 0 {
            return Err(BrickError::Ranks(
                "a decomposition needs at least one rank".into(),
            ));
        }
        if let Some(p) = planes {
            // Every brick needs two sample planes along each axis it is cut on.
            let most: usize = p.dims.iter().map(|d| d.saturating_sub(1)).product();
            if ranks > most.max(1) {
                return Err(BrickError::Ranks(format!(
                    "{ranks} ranks cannot share a grid of {}x{}x{} samples (at most {most} \
                     bricks of one cell)",
                    p.dims[0], p.dims[1], p.dims[2]
                )));
            }
        }
        let mut tree = KdTree {
            nodes: Vec::new(),
            boxes: vec![domain; ranks],
        };
        tree.split(points, domain, 0, ranks, planes)?;
        Ok(tree)
    }

    /// Builds the node of ranks first .. first + n over `bounds`; returns its index.
    fn split(
        &mut self,
        mut points: Vec<[f64; 3]>,
        bounds: Aabb,
        first: usize,
        n: usize,
        planes: Option<Planes>,
    ) -> Result<usize, BrickError> {
        let index = self.nodes.len();
        if n == 1 {
            self.nodes.push(KdNode::Leaf { rank: first });
            self.boxes[first] = bounds;
            return Ok(index);
        }
        let (lo, hi) = bounds;
        let mut axis = (0..3)
            .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
            .unwrap_or(0);
        let below = n / 2;
        let share = below as f64 / n as f64;
        // The coordinate below which `share` of the points lie (sorting them along `axis`).
        let quantile = |points: &mut Vec<[f64; 3]>, axis: usize| {
            points.sort_by(|p, q| p[axis].total_cmp(&q[axis]));
            match points.len() {
                0 => lo[axis] + share * (hi[axis] - lo[axis]),
                n => points[((n as f64 * share) as usize).min(n - 1)][axis],
            }
        };
        let mut plane = quantile(&mut points, axis);
        if let Some(p) = planes {
            // A grid plane strictly inside the box, the nearest to the quantile; the longest
            // axis with room for one (the count check guarantees one).
            let inner = |a: usize| {
                let first_plane = ((lo[a] - p.origin[a]) / p.spacing[a]).round() as i64 + 1;
                let last_plane = ((hi[a] - p.origin[a]) / p.spacing[a]).round() as i64 - 1;
                (first_plane <= last_plane).then_some((first_plane, last_plane))
            };
            if inner(axis).is_none() {
                axis = (0..3).find(|&a| inner(a).is_some()).unwrap_or(axis);
                plane = quantile(&mut points, axis);
            }
            let Some((a0, a1)) = inner(axis) else {
                return Err(BrickError::Ranks(format!(
                    "{n} ranks cannot share a brick of the grid with one cell along every axis"
                )));
            };
            let k = (((plane - p.origin[axis]) / p.spacing[axis]).round() as i64).clamp(a0, a1);
            plane = p.origin[axis] + k as f64 * p.spacing[axis];
        } else if !(lo[axis] < plane && plane < hi[axis]) {
            plane = 0.5 * (lo[axis] + hi[axis]);
        }
        let (mut under, mut over) = (Vec::new(), Vec::new());
        for p in points {
            if p[axis] < plane {
                under.push(p);
            } else {
                over.push(p);
            }
        }
        let (mut hi_below, mut lo_above) = (hi, lo);
        hi_below[axis] = plane;
        lo_above[axis] = plane;
        self.nodes.push(KdNode::Leaf { rank: usize::MAX });
        let b = self.split(under, (lo, hi_below), first, below, planes)?;
        let a = self.split(over, (lo_above, hi), first + below, n - below, planes)?;
        self.nodes[index] = KdNode::Split {
            axis,
            plane,
            below: b,
            above: a,
        };
        Ok(index)
    }

    /// The rank whose box holds `p` (points on a plane go above it; points outside every box
    /// to the nearest one along the descent).
    pub fn owner(&self, p: [f64; 3]) -> usize {
        let mut node = 0;
        loop {
            match self.nodes[node] {
                KdNode::Leaf { rank } => return rank,
                KdNode::Split {
                    axis,
                    plane,
                    below,
                    above,
                } => node = if p[axis] < plane { below } else { above },
            }
        }
    }

    /// The ranks front to back as seen from `view`: at every plane the side a ray crosses it
    /// from first (the side holding a perspective eye; for parallel rays, the side their
    /// direction leaves). Every ray meets the boxes in this order (the boxes are the cells of
    /// a binary space partition), which is the order their images composite in.
    pub fn visibility_order(&self, view: Viewpoint) -> Vec<usize> {
        let mut order = Vec::with_capacity(self.boxes.len());
        let mut stack = vec![0usize];
        while let Some(node) = stack.pop() {
            match self.nodes[node] {
                KdNode::Leaf { rank } => order.push(rank),
                KdNode::Split {
                    axis,
                    plane,
                    below,
                    above,
                } => {
                    let below_first = match view {
                        Viewpoint::Eye(eye) => eye[axis] < plane,
                        // Rays parallel to the plane never cross it: either order.
                        Viewpoint::Direction(forward) => forward[axis] > 0.0,
                    };
                    let (near, far) = if below_first {
                        (below, above)
                    } else {
                        (above, below)
                    };
                    stack.push(far);
                    stack.push(near);
                }
            }
        }
        order
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::Values;
    use crate::samples::{Domain, Provenance, Supports};

    fn grid(dims: [usize; 3]) -> SampleSet {
        let n = dims.iter().product();
        let hi = [0, 1, 2].map(|a| (dims[a] - 1) as f64 * 0.1);
        SampleSet {
            positions: Positions::Grid {
                dims,
                origin: [0.0; 3],
                spacing: [0.1; 3],
            },
            values: Values::F32(vec![0.0; n]),
            supports: Supports::Uniform([0.24; 3]),
            domain: Domain::Box { lo: [0.0; 3], hi },
            spacing: 0.1,
            provenance: Provenance {
                kind: "regular grid",
                array: "f".into(),
                location: crate::data::dataset::Location::Point,
                merged: 0,
                inverted_cells: 0,
                support_kind: "uniform",
            },
        }
    }

    #[test]
    fn boxes_tile_the_domain_and_grids_are_cut_at_their_planes() {
        let set = grid([21, 11, 6]);
        for ranks in 1..=9 {
            let tree = KdTree::decompose(&set, ranks).unwrap();
            let volume: f64 = tree
                .boxes
                .iter()
                .map(|(lo, hi)| (0..3).map(|a| hi[a] - lo[a]).product::<f64>())
                .sum();
            assert!(
                (volume - 2.0 * 1.0 * 0.5).abs() < 1e-12,
                "{ranks}: {volume}"
            );
            for (lo, hi) in &tree.boxes {
                for a in 0..3 {
                    for v in [lo[a], hi[a]] {
                        let k = v / 0.1;
                        assert!((k - k.round()).abs() < 1e-9, "{v} is not a grid plane");
                    }
                    assert!(hi[a] > lo[a]);
                }
            }
            // Every rank owns samples.
            let mut counts = vec![0usize; ranks];
            for i in 0..set.len() {
                counts[tree.owner(set.position(i))] += 1;
            }
            assert!(counts.iter().all(|&c| c > 0), "{ranks}: {counts:?}");
        }
    }

    #[test]
    fn visibility_order_puts_the_eyes_side_first() {
        let tree = KdTree::decompose(&grid([41, 5, 5]), 4).unwrap();
        // Cuts along x only (the longest axis twice over): from x < 0 the order is by x.
        let order = tree.visibility_order(Viewpoint::Eye([-5.0, 0.2, 0.2]));
        let xs: Vec<f64> = order.iter().map(|&r| tree.boxes[r].0[0]).collect();
        assert!(xs.windows(2).all(|w| w[0] < w[1]), "{xs:?}");
        let back = tree.visibility_order(Viewpoint::Eye([9.0, 0.2, 0.2]));
        assert_eq!(back, order.iter().rev().copied().collect::<Vec<_>>());
        // Parallel rays along +x meet the boxes by increasing x wherever the camera stands.
        assert_eq!(
            tree.visibility_order(Viewpoint::Direction([1.0, 0.0, 0.0])),
            order
        );
        assert_eq!(
            tree.visibility_order(Viewpoint::Direction([-0.6, 0.8, 0.0])),
            back
        );
    }

    #[test]
    fn more_ranks_than_cells_are_refused() {
        assert!(KdTree::decompose(&grid([3, 2, 2]), 3).is_err());
        assert!(KdTree::decompose(&grid([3, 2, 2]), 2).is_ok());
        assert!(KdTree::decompose(&grid([3, 2, 2]), 0).is_err());
    }
}
