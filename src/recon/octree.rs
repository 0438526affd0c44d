//! The redundant octree of [OCT] as used by [MLS] §5.2: a leaf lists every sample whose support
//! box intersects the leaf's cell, so a query descends to the leaf containing x and loops over
//! that list — no neighbour search, no backtracking.
//!
//! GPU layout (twin: `octree_leaf` in `glsl/include/neighbours.glsl`): `nodes[i] =
//! (child, begin, count, 0)`; `child = 0` marks a leaf (the root is node 0 and never a child),
//! otherwise the node's 8 children are `child..child+8` in octant order `x | y<<1 | z<<2`
//! (bit set = upper half). A leaf's samples are `indices[begin..begin+count]`.
//!
//! Subdivision ([OCT]): a node is split while it holds more than `leaf_budget` references, its
//! side exceeds `leaf_size` × the mean support radius of its samples, and it is shallower than
//! `max_depth`. Memory is bounded: the build fails with a clear error past `max_references`.

use super::ReconError;
use super::mls::Neighbours;

/// A scattered sample with an axis-aligned ellipsoidal support.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SamplePoint {
    pub position: [f64; 3],
    pub value: f64,
    /// 1 / support radius per axis.
    pub inv_support: [f64; 3],
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
    /// Largest number of references (the index buffer's length).
    pub max_references: u64,
}

impl Default for OctreeSettings {
    fn default() -> Self {
        Self {
            leaf_budget: 16,
            max_depth: 12,
            leaf_size: 0.6,
            // 128 MiB of u32: lavapipe's maxStorageBufferRange.
            max_references: 32 << 20,
        }
    }
}

/// The flattened octree plus its samples.
#[derive(Debug, Clone)]
pub struct Octree {
    pub root_center: [f64; 3],
    pub root_half: f64,
    pub nodes: Vec<[u32; 4]>,
    pub indices: Vec<u32>,
    pub samples: Vec<SamplePoint>,
}

struct Pending {
    node: usize,
    center: [f64; 3],
    half: f64,
    depth: u32,
    members: Vec<u32>,
}

impl Octree {
    /// Builds the octree; `progress` is called with the fraction of the root volume finished.
    pub fn build(
        samples: Vec<SamplePoint>,
        settings: &OctreeSettings,
        mut progress: impl FnMut(f64),
    ) -> Result<Self, ReconError> {
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
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for s in &samples {
            for a in 0..3 {
                let h = 1.0 / s.inv_support[a];
                lo[a] = lo[a].min(s.position[a] - h);
                hi[a] = hi[a].max(s.position[a] + h);
            }
        }
        let root_center = [
            0.5 * (lo[0] + hi[0]),
            0.5 * (lo[1] + hi[1]),
            0.5 * (lo[2] + hi[2]),
        ];
        let root_half = 0.5 * (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max) * (1.0 + 1e-6);
        // Cells are widened by this much in the overlap test so that an f32 descent that lands
        // in a neighbouring leaf (x within rounding of a face) still finds every sample.
        let slack = root_half * 1e-6;
        let mut tree = Self {
            root_center,
            root_half,
            nodes: vec![[0; 4]],
            indices: Vec::new(),
            samples,
        };
        let n = u32::try_from(tree.samples.len()).map_err(|_| ReconError::TooManyReferences {
            refs: tree.samples.len() as u64,
            limit: u64::from(u32::MAX),
        })?;
        let mut stack = vec![Pending {
            node: 0,
            center: root_center,
            half: root_half,
            depth: 0,
            members: (0..n).collect(),
        }];
        let mut done = 0.0;
        while let Some(p) = stack.pop() {
            let mean_radius = p
                .members
                .iter()
                .map(|&i| {
                    let s = &tree.samples[i as usize];
                    (1.0 / s.inv_support[0] + 1.0 / s.inv_support[1] + 1.0 / s.inv_support[2]) / 3.0
                })
                .sum::<f64>()
                / p.members.len().max(1) as f64;
            let split = p.members.len() > settings.leaf_budget
                && 2.0 * p.half > settings.leaf_size * mean_radius
                && p.depth < settings.max_depth;
            if !split {
                let begin = tree.indices.len();
                let refs = (begin + p.members.len()) as u64;
                if refs > settings.max_references {
                    return Err(ReconError::TooManyReferences {
                        refs,
                        limit: settings.max_references,
                    });
                }
                tree.nodes[p.node] = [0, begin as u32, p.members.len() as u32, 0];
                tree.indices.extend_from_slice(&p.members);
                done += (p.half / root_half).powi(3);
                progress(done);
                continue;
            }
            let child = tree.nodes.len();
            tree.nodes[p.node] = [child as u32, 0, 0, 0];
            tree.nodes.extend(std::iter::repeat_n([0u32; 4], 8));
            let half = 0.5 * p.half;
            for octant in 0..8usize {
                let mut center = p.center;
                for (a, c) in center.iter_mut().enumerate() {
                    *c += if octant >> a & 1 == 1 { half } else { -half };
                }
                let members = p
                    .members
                    .iter()
                    .copied()
                    .filter(|&i| {
                        let s = &tree.samples[i as usize];
                        (0..3).all(|a| {
                            let h = 1.0 / s.inv_support[a];
                            s.position[a] - h <= center[a] + half + slack
                                && s.position[a] + h >= center[a] - half - slack
                        })
                    })
                    .collect();
                stack.push(Pending {
                    node: child + octant,
                    center,
                    half,
                    depth: p.depth + 1,
                    members,
                });
            }
        }
        Ok(tree)
    }

    /// The reference list of the leaf containing x (empty outside the root cube).
    pub fn leaf(&self, x: [f64; 3]) -> &[u32] {
        let mut center = self.root_center;
        let mut half = self.root_half;
        if (0..3).any(|a| (x[a] - center[a]).abs() > half) {
            return &[];
        }
        let mut node = 0usize;
        loop {
            let [child, begin, count, _] = self.nodes[node];
            if child == 0 {
                return &self.indices[begin as usize..(begin + count) as usize];
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
}

impl Neighbours for Octree {
    fn for_each(&self, x: [f64; 3], visit: &mut dyn FnMut([f64; 3], f64, [f64; 3])) {
        for &i in self.leaf(x) {
            let s = &self.samples[i as usize];
            visit(s.position, s.value, s.inv_support);
        }
    }
}
