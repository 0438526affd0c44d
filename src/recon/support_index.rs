//! Every sample whose support may contain a point, without an octree: kd-trees over classes of
//! samples with similar support radii, each class queried at its own largest radius, so that a
//! few wide supports do not widen every query. Memory is O(n) (no references repeated per
//! leaf, unlike the octree's); queries cost a kd-tree search per class. Kernel volumes use it
//! where the octree was deferred (`Field::from_samples_deferred`, splatting): a cloud of 10⁷
//! points gets its Gaussian-sum weights although its octree would not fit.

use super::Neighbours;
use super::mls::Visit;
use crate::samples::{SampleSet, supports};
use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;

type Tree = ImmutableKdTree<f64, u32, 3, 32>;

/// Radii of one class span at most this factor: a query visits at most its cube more
/// candidates than the class's smallest supports need.
const CLASS_SPAN: f64 = 1.5;

/// One class: its kd-tree (items index `members`), the sample indices and the largest radius.
struct Class {
    tree: Tree,
    members: Vec<u32>,
    radius: f64,
}

/// See the module documentation.
pub struct SupportIndex<'a> {
    samples: &'a SampleSet,
    classes: Vec<Class>,
    scale: f64,
}

impl<'a> SupportIndex<'a> {
    /// Sorts the samples by [`supports::reach`] and builds one kd-tree per class of radii within
    /// [`CLASS_SPAN`] of each other.
    pub fn new(samples: &'a SampleSet) -> Self {
        let mut order: Vec<(f64, u32)> = (0..samples.len())
            .map(|i| (supports::reach(&samples.metric(i)), i as u32))
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut classes = Vec::new();
        let mut start = 0;
        while start < order.len() {
            let limit = order[start].0 * CLASS_SPAN;
            let end = start + order[start..].partition_point(|(r, _)| *r <= limit).max(1);
            let members: Vec<u32> = order[start..end].iter().map(|&(_, i)| i).collect();
            let positions: Vec<[f64; 3]> = members
                .iter()
                .map(|&i| samples.position(i as usize))
                .collect();
            classes.push(Class {
                tree: Tree::new_from_slice(&positions),
                members,
                radius: order[end - 1].0,
            });
            start = end;
        }
        let scale = 1.0 / samples.mean_radius().max(f64::MIN_POSITIVE);
        Self {
            samples,
            classes,
            scale,
        }
    }

    /// Number of radius classes (one kd-tree each).
    pub fn classes(&self) -> usize {
        self.classes.len()
    }
}

impl Neighbours for SupportIndex<'_> {
    fn basis_scale(&self, _x: [f64; 3]) -> [f64; 3] {
        [self.scale; 3]
    }

    /// Every sample within its class's largest reach of x: a superset of those whose support
    /// contains x, as the octree's leaf lists are.
    fn for_each(&self, x: [f64; 3], visit: &mut Visit<'_>) {
        let s = self.samples;
        for c in &self.classes {
            for n in c
                .tree
                .within_unsorted::<SquaredEuclidean>(&x, c.radius * c.radius)
            {
                let i = c.members[n.item as usize] as usize;
                visit(i, s.position(i), f64::from(s.values.get(i)), &s.metric(i));
            }
        }
    }
}
