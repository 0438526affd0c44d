//! The redundant octree of [OCT] as used by [MLS] §5.2: a leaf lists every sample whose support
//! ellipsoid intersects the leaf's cell, so a query descends to the leaf containing x and loops
//! over that list — no neighbour search, no backtracking.
//!
//! GPU layout (twin: `octree_leaf` in `glsl/field/neighbours.glsl`): `nodes[i] =
//! (child, begin, count, scale)`; `child = 0` marks a leaf (the root is node 0 and never a
//! child), otherwise the node's 8 children are `child..child+8` in octant order
//! `x | y<<1 | z<<2` (bit set = upper half). A leaf's samples are `count` codes from word
//! `begin` of `codes` ([`super::octree_codes`]: 16-bit gaps, two to a word); `scale` holds the
//! f32 bits of 1 / the leaf's mean support radius, the basis scale of every evaluation inside
//! the leaf ([`Neighbours::basis_scale`]).
//!
//! Subdivision ([OCT]): a node is split while it holds more than `leaf_budget` references, its
//! side exceeds `leaf_size` × the mean support radius of its samples, and it is shallower than
//! `max_depth`. Subtrees are built in parallel (rayon) and flattened in octant order, so the
//! result does not depend on the thread count. The build reads the samples in Morton order and
//! each leaf lists their own indices, ascending. Memory is bounded: the build fails with a clear
//! error past `max_references`.
//!
//! Overlap test (conservative and tight): a sample is referenced by a cell unless a separating
//! plane exists between its ellipsoid and the cell. Candidate planes are the three axis planes
//! (the ellipsoid's exact bounding box) and the plane normal to M(b − x_i) at b, the cell point
//! nearest to x_i in the metric, found by projected coordinate descent. Only a proven separation
//! drops a sample, so the test never loses a neighbour; the last plane makes it tight (for a
//! sphere it is the exact sphere–box test).

use super::ReconError;
use super::mls::{Neighbours, Visit};
use super::octree_codes::{self, LeafCodes};
use crate::samples::{Metric, SampleSet, metric_apply, metric_rho2, supports};
use rayon::prelude::*;

/// A scattered sample with an ellipsoidal support.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SamplePoint {
    pub position: [f64; 3],
    pub value: f64,
    /// The support's metric: ρ² = (x − x_i)ᵀ M (x − x_i).
    pub metric: Metric,
}

/// Build parameters (scene keys `[octree]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OctreeSettings {
    /// Split nodes holding more references than this.
    pub leaf_budget: usize,
    /// Never split deeper than this.
    pub max_depth: u32,
    /// Never split a node whose side is below this fraction of its mean support radius.
    pub leaf_size: f64,
    /// Largest length of the reference buffer, in 32-bit words (two references to a word,
    /// [`super::octree_codes`]; the name is the scene key's).
    pub max_references: u64,
    /// How kernels read a leaf's samples (`octree.records`): `Some(true)` as inline records,
    /// `Some(false)` through the coded references, `None` ("auto") inline where the records
    /// fit (`crate::field::records`).
    pub records: Option<bool>,
    /// Most texels the inline records may take: the device's texel-view limit, like
    /// `max_references`.
    pub max_record_texels: u64,
}

impl Default for OctreeSettings {
    fn default() -> Self {
        Self {
            leaf_budget: 16,
            max_depth: 12,
            leaf_size: 0.6,
            // 2^27 words (512 MiB, about 2^28 references): lavapipe's maxTexelBufferElements.
            // Kernels read the codes through an r32ui texel view (binding::kind), so one
            // storage binding's 128 MiB does not bound them (it refused 10⁶ scattered points,
            // 33.5 M references); `Scene::field_on` lowers this to the device's own view limit.
            max_references: 1 << 27,
            records: None,
            max_record_texels: 1 << 27,
        }
    }
}

/// What `--stats` and `vmls info` report about an octree.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OctreeStats {
    pub nodes: usize,
    pub leaves: usize,
    pub references: usize,
    /// References per sample.
    pub redundancy: f64,
    pub depth: u32,
    /// Bytes of nodes + reference codes + samples as uploaded.
    pub bytes: u64,
    pub build_ms: f64,
}

/// Most sample references one leaf may hold. An MLS evaluation loops over every reference of
/// its leaf, so a leaf bounds the work of every evaluation; and a device may cut long loops
/// short (llvmpipe ends every loop after 65 535 iterations per invocation, LAVAPIPE.md), which
/// a leaf of tens of thousands of references reaches in one evaluation. Real data stays far
/// below: splitting stops at `leaf_budget` (16) references unless a node is already smaller
/// than the supports or at `max_depth`.
pub const MAX_LEAF_REFERENCES: usize = 4096;

/// Most codes one leaf may hold ([`super::octree_codes`]: its references and the jumps over
/// index gaps of 65 535 or more), for the same loop limit.
pub const MAX_LEAF_CODES: usize = 16_384;

/// The flattened octree plus its samples.
#[derive(Debug, Clone)]
pub struct Octree {
    pub root_center: [f64; 3],
    pub root_half: f64,
    pub nodes: Vec<[u32; 4]>,
    /// Every leaf's sample indices, coded ([`super::octree_codes`]).
    pub codes: Vec<u32>,
    /// References over all leaves.
    pub references: usize,
    pub samples: Vec<SamplePoint>,
    pub build_ms: f64,
}

/// A subtree before flattening. A leaf holds its samples coded as soon as it is made
/// ([`octree_codes::encode_leaf`]): 16-bit codes take about half the memory of the indices, and
/// the tree holds every leaf at once (10⁶ scattered points: 108 M references).
enum Built {
    Leaf(CodedLeaf),
    Inner(Box<[Built; 8]>),
}

/// A leaf's samples, coded, and what the flat layout needs of them.
struct CodedLeaf {
    words: Vec<u32>,
    codes: usize,
    references: usize,
    scale: f32,
}

impl CodedLeaf {
    fn new(members: &[u32], scale: f32) -> Self {
        let (words, codes) = octree_codes::encode_leaf(members);
        Self {
            words,
            codes,
            references: members.len(),
            scale,
        }
    }
}

/// Per-sample data the build reads.
struct Prepared<'a> {
    /// The samples in the Morton order of their positions: a node's candidates, ascending in
    /// this order, are then read from nearby memory (a point file's own order is often random:
    /// on 10⁶ random points this order took 14–18% off the build).
    samples: &'a [SamplePoint],
    /// Each of those samples' index in the octree's samples, which its leaves list.
    original: &'a [u32],
    /// Half extents of each support's bounding box.
    extent: Vec<[f64; 3]>,
    /// Geometric-mean radius of each support.
    radius: Vec<f64>,
    slack: f64,
    settings: OctreeSettings,
}

impl Prepared<'_> {
    fn overlaps(&self, i: u32, center: [f64; 3], half: f64) -> bool {
        let s = &self.samples[i as usize];
        let e = self.extent[i as usize];
        let h = half + self.slack;
        let lo = center.map(|c| c - h);
        let hi = center.map(|c| c + h);
        // Axis planes: the ellipsoid's bounding box against the cell.
        if (0..3).any(|a| s.position[a] - e[a] > hi[a] || s.position[a] + e[a] < lo[a]) {
            return false;
        }
        if (0..3).all(|a| s.position[a] >= lo[a] && s.position[a] <= hi[a]) {
            return true;
        }
        // b: the cell point nearest to x_i in the metric (coordinate descent on the convex
        // quadratic (b − x)ᵀM(b − x) over the box).
        let m = &s.metric;
        let mut b = [0, 1, 2].map(|a| s.position[a].clamp(lo[a], hi[a]));
        let diag = [m[0], m[1], m[2]];
        // For a diagonal metric the quadratic is separable and the clamp is already exact.
        let rotated = crate::samples::supports::is_rotated(m);
        for _ in 0..if rotated { 8 } else { 0 } {
            for a in 0..3 {
                let d = [0, 1, 2].map(|k| b[k] - s.position[k]);
                let g = metric_apply(m, d)[a];
                b[a] = (b[a] - g / diag[a]).clamp(lo[a], hi[a]);
            }
        }
        let d = [0, 1, 2].map(|k| b[k] - s.position[k]);
        if metric_rho2(m, d) <= 1.0 {
            return true;
        }
        // Plane through the ellipsoid's support point along n = M d: separated when the whole
        // cell lies beyond the ellipsoid's extent √(nᵀM⁻¹n) = √(dᵀMd) along n.
        let n = metric_apply(m, d);
        let reach = metric_rho2(m, d).sqrt();
        let nearest_corner: f64 = (0..3)
            .map(|a| n[a] * if n[a] >= 0.0 { lo[a] } else { hi[a] } - n[a] * s.position[a])
            .sum();
        nearest_corner <= reach
    }

    fn build(&self, members: Vec<u32>, center: [f64; 3], half: f64, depth: u32) -> Built {
        let mean_radius = members
            .iter()
            .map(|&i| self.radius[i as usize])
            .sum::<f64>()
            / members.len().max(1) as f64;
        let split = members.len() > self.settings.leaf_budget
            && 2.0 * half > self.settings.leaf_size * mean_radius
            && depth < self.settings.max_depth;
        if !split {
            let scale = if members.is_empty() {
                0.0
            } else {
                (1.0 / mean_radius) as f32
            };
            return Built::Leaf(self.leaf(members, scale));
        }
        let parallel = members.len() > 4096;
        let reach: Vec<u8> = if parallel {
            members
                .par_iter()
                .map(|&i| self.octants_reached(i, center, half))
                .collect()
        } else {
            members
                .iter()
                .map(|&i| self.octants_reached(i, center, half))
                .collect()
        };
        let child = |octant: usize| {
            let h = 0.5 * half;
            let c = [0, 1, 2].map(|a| center[a] + if octant >> a & 1 == 1 { h } else { -h });
            let inside: Vec<u32> = members
                .iter()
                .zip(&reach)
                .filter(|&(&i, &r)| r >> octant & 1 == 1 && self.overlaps(i, c, h))
                .map(|(&i, _)| i)
                .collect();
            self.build(inside, c, h, depth + 1)
        };
        let children: Vec<Built> = if parallel {
            (0..8).into_par_iter().map(child).collect()
        } else {
            (0..8).map(child).collect()
        };
        match <[Built; 8]>::try_from(children) {
            Ok(c) => Built::Inner(Box::new(c)),
            // Unreachable (8 octants in, 8 out); a leaf keeps the tree valid regardless.
            Err(_) => Built::Leaf(self.leaf(members, (1.0 / mean_radius) as f32)),
        }
    }

    /// A leaf of `members` (in the build's order), listing their indices in ascending order.
    fn leaf(&self, mut members: Vec<u32>, scale: f32) -> CodedLeaf {
        members
            .iter_mut()
            .for_each(|m| *m = self.original[*m as usize]);
        members.sort_unstable();
        CodedLeaf::new(&members, scale)
    }

    /// The octants of the cell (`center`, `half`) that sample i's support box may reach, as
    /// bits `x | y<<1 | z<<2` (set: the upper half): every octant whose [`Self::overlaps`] does
    /// not reject i by its axis planes, and perhaps more, so that the children's lists are
    /// exactly those of testing all eight. The margin covers the slack and the rounding of the
    /// child's bounds (one ulp each of its centre and half side).
    fn octants_reached(&self, i: u32, center: [f64; 3], half: f64) -> u8 {
        let s = &self.samples[i as usize];
        let e = self.extent[i as usize];
        // The octants in the upper half along x, y, z.
        const UPPER: [u8; 3] = [0xAA, 0xCC, 0xF0];
        let mut mask = 0xFF;
        for a in 0..3 {
            let margin = 2.0 * self.slack + 8.0 * f64::EPSILON * (center[a].abs() + half);
            if s.position[a] - e[a] > center[a] + margin {
                mask &= UPPER[a];
            }
            if s.position[a] + e[a] < center[a] - margin {
                mask &= !UPPER[a];
            }
        }
        mask
    }
}

impl Octree {
    /// The octree over every sample of a sample set.
    pub fn from_samples(
        set: &SampleSet,
        settings: &OctreeSettings,
        progress: impl FnMut(f64),
    ) -> Result<Self, ReconError> {
        let points = (0..set.len())
            .map(|i| SamplePoint {
                position: set.position(i),
                value: f64::from(set.values.get(i)),
                metric: set.metric(i),
            })
            .collect();
        Self::build(points, settings, progress)
    }

    /// Builds the octree; `progress` is called with the fraction of the work finished.
    pub fn build(
        samples: Vec<SamplePoint>,
        settings: &OctreeSettings,
        mut progress: impl FnMut(f64),
    ) -> Result<Self, ReconError> {
        let start = std::time::Instant::now();
        if samples.is_empty() {
            return Err(ReconError::Empty);
        }
        if settings.leaf_budget == 0 {
            return Err(ReconError::Setting {
                key: "octree.leaf_budget",
                value: "0".into(),
                expected: "at least 1",
            });
        }
        if !(settings.leaf_size > 0.0 && settings.leaf_size.is_finite()) {
            return Err(ReconError::Setting {
                key: "octree.leaf_size",
                value: settings.leaf_size.to_string(),
                expected: "a positive number",
            });
        }
        let n = u32::try_from(samples.len()).map_err(|_| ReconError::TooManyReferences {
            refs: samples.len() as u64,
            words: samples.len() as u64,
            limit: u64::from(u32::MAX),
        })?;
        let positions: Vec<[f64; 3]> = samples.iter().map(|s| s.position).collect();
        let original = supports::morton_order(&positions);
        drop(positions);
        let ordered: Vec<SamplePoint> = original.iter().map(|&i| samples[i as usize]).collect();
        let extent: Vec<[f64; 3]> = ordered
            .par_iter()
            .map(|s| supports::extent(&s.metric))
            .collect();
        let radius: Vec<f64> = ordered
            .par_iter()
            .map(|s| supports::mean_radius(&s.metric))
            .collect();
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for (s, e) in ordered.iter().zip(&extent) {
            for a in 0..3 {
                lo[a] = lo[a].min(s.position[a] - e[a]);
                hi[a] = hi[a].max(s.position[a] + e[a]);
            }
        }
        let root_center = [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a]));
        let root_half = 0.5 * (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max) * (1.0 + 1e-6);
        if !root_half.is_finite() || root_half <= 0.0 {
            return Err(ReconError::Setting {
                key: "samples",
                value: format!("bounds {lo:?}..{hi:?}"),
                expected: "finite positions and supports",
            });
        }
        // Cells are widened by this much in the overlap test so that an f32 descent that lands
        // in a neighbouring leaf (x within rounding of a face) still finds every sample.
        let prepared = Prepared {
            samples: &ordered,
            original: &original,
            extent,
            radius,
            slack: root_half * 1e-6,
            settings: *settings,
        };
        let built = prepared.build((0..n).collect(), root_center, root_half, 0);
        drop(prepared);
        drop(ordered);
        progress(0.9);
        let (node_count, words, references) = check_leaves(&built)?;
        if words as u64 > settings.max_references {
            return Err(ReconError::TooManyReferences {
                refs: references as u64,
                words: words as u64,
                limit: settings.max_references,
            });
        }
        // Sized once: growing by doubling held up to 1.5× the codes while copying them.
        let mut nodes = Vec::with_capacity(node_count);
        nodes.push([0u32; 4]);
        let mut codes = Vec::with_capacity(words);
        flatten(built, 0, &mut nodes, &mut codes);
        progress(1.0);
        Ok(Self {
            root_center,
            root_half,
            nodes,
            codes,
            references,
            samples,
            build_ms: start.elapsed().as_secs_f64() * 1e3,
        })
    }

    /// The leaf containing x: (its sample indices, basis scale); empty outside the root cube.
    pub fn leaf(&self, x: [f64; 3]) -> (LeafCodes<'_>, f64) {
        match self.leaf_cell(x) {
            Some((node, _, _)) => {
                let [_, begin, count, scale] = self.nodes[node];
                (
                    LeafCodes::new(&self.codes, begin, count),
                    f64::from(f32::from_bits(scale)),
                )
            }
            None => (LeafCodes::empty(), 0.0),
        }
    }

    /// The leaf containing x as a cell: its node index (the same for every point of the
    /// leaf), centre and half size; `None` outside the root cube.
    pub fn leaf_cell(&self, x: [f64; 3]) -> Option<(usize, [f64; 3], f64)> {
        let mut center = self.root_center;
        let mut half = self.root_half;
        if (0..3).any(|a| (x[a] - center[a]).abs() > half) {
            return None;
        }
        let mut node = 0usize;
        loop {
            let child = self.nodes[node][0];
            if child == 0 {
                return Some((node, center, half));
            }
            half *= 0.5;
            let mut octant = 0;
            for a in 0..3 {
                if x[a] >= center[a] {
                    octant |= 1 << a;
                    center[a] += half;
                } else {
                    center[a] -= half;
                }
            }
            node = child as usize + octant;
        }
    }

    /// Whether the leaf at node `node` ([`Octree::leaf_cell`]) lists any sample.
    pub fn leaf_is_empty(&self, node: usize) -> bool {
        self.nodes[node][2] == 0
    }

    /// Depth of the deepest leaf.
    pub fn depth(&self) -> u32 {
        fn walk(nodes: &[[u32; 4]], n: usize) -> u32 {
            let child = nodes[n][0] as usize;
            if child == 0 {
                0
            } else {
                1 + (0..8).map(|o| walk(nodes, child + o)).max().unwrap_or(0)
            }
        }
        walk(&self.nodes, 0)
    }

    /// Size, redundancy, depth, memory and build time. `sample_bytes` is the GPU size of one
    /// sample.
    /// Number of leaf nodes.
    pub fn leaf_count(&self) -> usize {
        self.nodes.iter().filter(|n| n[0] == 0).count()
    }

    pub fn stats(&self, sample_bytes: u64) -> OctreeStats {
        OctreeStats {
            nodes: self.nodes.len(),
            leaves: self.leaf_count(),
            references: self.references,
            redundancy: self.references as f64 / self.samples.len().max(1) as f64,
            depth: self.depth(),
            bytes: self.nodes.len() as u64 * 16
                + self.codes.len() as u64 * 4
                + self.samples.len() as u64 * sample_bytes,
            build_ms: self.build_ms,
        }
    }
}

/// The flat layout's (nodes, code words, references) of `built`, after checking every leaf in
/// octant order against [`MAX_LEAF_REFERENCES`] and [`MAX_LEAF_CODES`].
fn check_leaves(built: &Built) -> Result<(usize, usize, usize), ReconError> {
    match built {
        Built::Leaf(leaf) => {
            if leaf.references > MAX_LEAF_REFERENCES {
                return Err(ReconError::LeafTooLarge {
                    refs: leaf.references,
                    limit: MAX_LEAF_REFERENCES,
                });
            }
            if leaf.codes > MAX_LEAF_CODES {
                return Err(ReconError::LeafTooLarge {
                    refs: leaf.codes,
                    limit: MAX_LEAF_CODES,
                });
            }
            Ok((1, leaf.words.len(), leaf.references))
        }
        Built::Inner(children) => children.iter().try_fold((1, 0, 0), |sum, c| {
            let (n, w, r) = check_leaves(c)?;
            Ok((sum.0 + n, sum.1 + w, sum.2 + r))
        }),
    }
}

/// Appends `built` as node `at` (already allocated) in octant order, freeing each leaf's
/// words once they are copied.
fn flatten(built: Built, at: usize, nodes: &mut Vec<[u32; 4]>, codes: &mut Vec<u32>) {
    match built {
        Built::Leaf(leaf) => {
            let begin = codes.len();
            codes.extend_from_slice(&leaf.words);
            nodes[at] = [0, begin as u32, leaf.codes as u32, leaf.scale.to_bits()];
        }
        Built::Inner(children) => {
            let child = nodes.len();
            nodes[at] = [child as u32, 0, 0, 0];
            nodes.extend(std::iter::repeat_n([0u32; 4], 8));
            for (o, c) in (*children).into_iter().enumerate() {
                flatten(c, child + o, nodes, codes);
            }
        }
    }
}

impl Neighbours for Octree {
    fn basis_scale(&self, x: [f64; 3]) -> [f64; 3] {
        [self.leaf(x).1; 3]
    }

    fn for_each(&self, x: [f64; 3], visit: &mut Visit<'_>) {
        for i in self.leaf(x).0 {
            let s = &self.samples[i as usize];
            visit(i as usize, s.position, s.value, &s.metric);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::random::Lcg;

    /// Ellipsoids of radii 0.05–0.3, a third of them rotated, around `offset`.
    fn cloud(n: usize, offset: f64, rng: &mut Lcg) -> Vec<SamplePoint> {
        (0..n)
            .map(|k| {
                let position = [0, 1, 2].map(|_| offset + rng.next_f64());
                let r = [0, 1, 2].map(|_| 0.05 + 0.25 * rng.next_f64());
                let d = r.map(|r| 1.0 / (r * r));
                // Positive definite: normalised, off-diagonals of 0.2 and -0.1 against a unit
                // diagonal.
                let (m01, m02) = if k % 3 == 0 {
                    (0.2 * (d[0] * d[1]).sqrt(), -0.1 * (d[0] * d[2]).sqrt())
                } else {
                    (0.0, 0.0)
                };
                let metric = [d[0], d[1], d[2], m01, m02, 0.0];
                SamplePoint {
                    position,
                    value: 0.0,
                    metric,
                }
            })
            .collect()
    }

    /// The octant pre-test drops only samples that the full test's axis planes reject: on
    /// random ellipsoids, and on spheres whose box edge is pinned within a few ulps and slacks
    /// of the split plane, near the origin and at 10¹², where an ulp passes the slack. It also
    /// drops some, so a mask of all eight fails.
    #[test]
    fn octants_reached_keep_every_octant_the_overlap_test_accepts() {
        let mut rng = Lcg::new(7);
        let slack = 1e-6;
        for offset in [0.0, 1.0e12] {
            let (mut accepted, mut dropped) = (0, 0);
            for _ in 0..40 {
                let half = 0.02 + 0.3 * rng.next_f64();
                let center = [0, 1, 2].map(|_| offset + rng.next_f64());
                let mut samples = cloud(100, offset, &mut rng);
                let ulp = f64::EPSILON * (offset + 1.0);
                for (k, delta) in [
                    -2.0 * slack,
                    -slack,
                    -4.0 * ulp,
                    -ulp,
                    0.0,
                    ulp,
                    4.0 * ulp,
                    slack,
                ]
                .into_iter()
                .enumerate()
                {
                    let r = 0.1;
                    let a = k % 3;
                    let mut position = [0, 1, 2].map(|b| center[b] + half * (rng.next_f64() - 0.5));
                    // The box's lower edge at the plane + delta, then its upper edge at - delta.
                    position[a] = center[a] + r + delta;
                    let mut upper = position;
                    upper[a] = center[a] - r - delta;
                    let metric = [1.0 / (r * r), 1.0 / (r * r), 1.0 / (r * r), 0.0, 0.0, 0.0];
                    for position in [position, upper] {
                        samples.push(SamplePoint {
                            position,
                            value: 0.0,
                            metric,
                        });
                    }
                }
                let identity: Vec<u32> = (0..samples.len() as u32).collect();
                let prepared = Prepared {
                    samples: &samples,
                    original: &identity,
                    extent: samples
                        .iter()
                        .map(|s| supports::extent(&s.metric))
                        .collect(),
                    radius: samples
                        .iter()
                        .map(|s| supports::mean_radius(&s.metric))
                        .collect(),
                    slack,
                    settings: OctreeSettings::default(),
                };
                for i in 0..samples.len() as u32 {
                    let mask = prepared.octants_reached(i, center, half);
                    for o in 0..8 {
                        let h = 0.5 * half;
                        let c = [0, 1, 2].map(|a| center[a] + if o >> a & 1 == 1 { h } else { -h });
                        if prepared.overlaps(i, c, h) {
                            accepted += 1;
                            assert_eq!(mask >> o & 1, 1, "sample {i}, octant {o}, offset {offset}");
                        } else if mask >> o & 1 == 0 {
                            dropped += 1;
                        }
                    }
                }
            }
            assert!(
                accepted > 1000 && dropped > 5000,
                "{accepted} accepted, {dropped} dropped"
            );
        }
    }

    /// The build reads the samples in Morton order, but leaves list indices into the samples as
    /// given: the same cloud given in reverse builds the same nodes, each leaf listing the
    /// reversed indices of the same samples (scales to f32 rounding: the mean radius is summed
    /// in another order).
    #[test]
    fn leaves_list_the_samples_as_given_whatever_their_order() {
        let mut rng = Lcg::new(5);
        let samples = cloud(2000, 0.0, &mut rng);
        let reversed: Vec<SamplePoint> = samples.iter().rev().copied().collect();
        let settings = OctreeSettings::default();
        let a = Octree::build(samples.clone(), &settings, |_| {}).unwrap();
        let b = Octree::build(reversed, &settings, |_| {}).unwrap();
        assert_eq!(a.nodes.len(), b.nodes.len());
        assert_eq!(a.references, b.references);
        let n = samples.len() as u32;
        let mut leaves = 0;
        for (p, q) in a.nodes.iter().zip(&b.nodes) {
            assert_eq!((p[0], p[2] > 0), (q[0], q[2] > 0));
            if p[0] != 0 || p[2] == 0 {
                continue;
            }
            leaves += 1;
            let mut given: Vec<u32> = LeafCodes::new(&a.codes, p[1], p[2]).collect();
            let listed: Vec<u32> = LeafCodes::new(&b.codes, q[1], q[2]).collect();
            assert!(listed.windows(2).all(|w| w[0] < w[1]), "not ascending");
            given.iter_mut().for_each(|i| *i = n - 1 - *i);
            given.sort_unstable();
            assert_eq!(given, listed);
            let (sa, sb) = (f32::from_bits(p[3]), f32::from_bits(q[3]));
            assert!((sa - sb).abs() <= 2.0 * f32::EPSILON * sa, "{sa} {sb}");
        }
        assert!(leaves > 100, "{leaves} leaves");
    }

    /// The flat layout is allocated once at its length, and decodes to each leaf's members.
    #[test]
    fn the_flat_codes_are_sized_once_and_hold_every_leaf() {
        let mut rng = Lcg::new(11);
        let samples = cloud(3000, 0.0, &mut rng);
        let tree = Octree::build(samples.clone(), &OctreeSettings::default(), |_| {}).unwrap();
        assert_eq!(tree.codes.capacity(), tree.codes.len());
        assert_eq!(tree.nodes.capacity(), tree.nodes.len());
        assert!(tree.leaf_count() > 100, "{} leaves", tree.leaf_count());
        let mut references = 0;
        for x in (0..200).map(|_| [0, 1, 2].map(|_| rng.next_f64())) {
            let (leaf, _) = tree.leaf(x);
            let members: Vec<u32> = leaf.collect();
            assert!(members.windows(2).all(|w| w[0] < w[1]));
            // Every sample whose support holds x is in x's leaf.
            for (i, s) in samples.iter().enumerate() {
                let d = [0, 1, 2].map(|a| x[a] - s.position[a]);
                if metric_rho2(&s.metric, d) <= 1.0 {
                    assert!(members.binary_search(&(i as u32)).is_ok(), "{i} at {x:?}");
                    references += 1;
                }
            }
        }
        assert!(references > 1000, "{references}");
    }
}
