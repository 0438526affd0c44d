//! An octree's leaves as inline sample records (issue 27 §1; stage `octree_records`, kernel
//! twin: `leaf_first`/`leaf_code` and `RECORD_STRIDE` with `OCTREE_INLINE` in
//! glsl/field/neighbours.glsl).
//!
//! The coded layout ([`crate::recon::octree_codes`]) keeps each sample once and every leaf as
//! a list of 16-bit index gaps: an evaluation gathers a code, then the sample it names, then
//! its metric, two dependent loads per candidate. On lavapipe those candidates' gathers are an
//! octree evaluation's cost (about 150 a point, BENCHMARKS.md "Compact octree references").
//! The inline layout copies each leaf's samples, in the coded list's order, into consecutive
//! records: candidate r of a leaf is at record `first + r`, an address known before any load,
//! and no index is read. The same candidates in the same order make the same sums, so the
//! images equal the coded layout's to the bit; what it costs is memory, each sample once per
//! leaf that lists it (the octree's redundancy, 59-144 on the data measured) instead of two
//! bytes per reference.
//!
//! A record is `RECORD_STRIDE` rgba32f texels: position and value, then the metric's diagonal
//! with the Gaussian weight in w (stride 2); a full metric keeps the sample's three texels
//! ([`Sample`]'s layout, weight in the third's z). A leaf node's (first, count) name records
//! instead of code words.

use crate::gpu_types::Sample;
use crate::recon::Octree;
use crate::recon::octree_codes::LeafCodes;

/// The largest inline records "auto" takes, in bytes: beyond that the coded references serve
/// (the 68 921 scattered points of issue 26 take 317 MB, 10⁶ of them would take 3.4 GB).
pub const AUTO_MAX_BYTES: u64 = 512 << 20;

/// Bytes of one rgba32f texel.
const TEXEL_BYTES: u64 = 16;

/// Texels per record: 3 with full metrics (their off-diagonal terms), else 2.
pub fn record_stride(full_metric: bool) -> usize {
    if full_metric { 3 } else { 2 }
}

/// The texels of `s`'s record at `stride` (only the first `stride` are stored).
pub fn record_texels(s: &Sample, stride: usize) -> [[f32; 4]; 3] {
    if stride == 2 {
        let [xx, yy, zz, _] = s.metric;
        // The diagonal's fourth component (xy) is read only with full metrics: the weight
        // takes its place.
        [s.pos_value, [xx, yy, zz, s.metric_off[2]], [0.0; 4]]
    } else {
        [s.pos_value, s.metric, s.metric_off]
    }
}

/// Texels that inline records of `octree` at `stride` take.
pub fn record_texel_count(octree: &Octree, stride: usize) -> u64 {
    octree.references as u64 * stride as u64
}

/// Whether kernels read `octree`'s leaves as inline records: the scene's choice, or ("auto",
/// `records` = `None`) where the records fit both `max_texels` (the device's texel view) and
/// [`AUTO_MAX_BYTES`].
pub fn inline_chosen(
    octree: &Octree,
    stride: usize,
    records: Option<bool>,
    max_texels: u64,
) -> bool {
    let texels = record_texel_count(octree, stride);
    records.unwrap_or(texels <= max_texels && texels * TEXEL_BYTES <= AUTO_MAX_BYTES)
}

/// An octree's leaves as inline records: the nodes with each leaf's (first record, record
/// count) in place of its (first code word, code count), and the records.
#[derive(Debug, Clone, PartialEq)]
pub struct InlineLeaves {
    pub nodes: Vec<[u32; 4]>,
    pub texels: Vec<[f32; 4]>,
    pub stride: usize,
}

impl InlineLeaves {
    /// Stage `octree_records`: every leaf's members (in their coded order) copied from
    /// `samples` (the octree's samples as uploaded, one per sample).
    pub fn build(octree: &Octree, samples: &[Sample], stride: usize) -> Self {
        let mut texels = Vec::with_capacity(record_texel_count(octree, stride) as usize);
        let mut nodes = octree.nodes.clone();
        for node in nodes.iter_mut().filter(|n| n[0] == 0) {
            let first = texels.len() / stride;
            for i in LeafCodes::new(&octree.codes, node[1], node[2]) {
                let record = record_texels(&samples[i as usize], stride);
                texels.extend_from_slice(&record[..stride]);
            }
            node[1] = first as u32;
            node[2] = (texels.len() / stride - first) as u32;
        }
        Self {
            nodes,
            texels,
            stride,
        }
    }

    /// The records of leaf `node` as the kernel reads them: record r of the leaf at texel
    /// `stride · (first + r)`.
    pub fn leaf(&self, node: usize) -> impl Iterator<Item = &[[f32; 4]]> + '_ {
        let [_, first, count, _] = self.nodes[node];
        (first..first + count).map(move |r| {
            let at = r as usize * self.stride;
            &self.texels[at..at + self.stride]
        })
    }

    /// Bytes on the device (records and nodes).
    pub fn bytes(&self) -> u64 {
        self.texels.len() as u64 * TEXEL_BYTES + self.nodes.len() as u64 * 16
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recon::{OctreeSettings, SamplePoint};

    /// Scattered samples with distinct values, metrics and weights.
    fn octree(n: usize) -> (Octree, Vec<Sample>) {
        let mut rng = 12345u64;
        let mut next = || {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (rng >> 11) as f64 / (1u64 << 53) as f64
        };
        let points: Vec<SamplePoint> = (0..n)
            .map(|i| {
                let h = 0.15 + 0.1 * next();
                let m = 1.0 / (h * h);
                SamplePoint {
                    position: [next() * 2.0 - 1.0, next() * 2.0 - 1.0, next() * 2.0 - 1.0],
                    value: i as f64,
                    metric: [m, 1.1 * m, 0.9 * m, 0.01 * m, 0.02 * m, 0.03 * m],
                }
            })
            .collect();
        let tree = Octree::build(points, &OctreeSettings::default(), |_| {}).expect("octree");
        let samples = tree
            .samples
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let m = s.metric.map(|v| v as f32);
                Sample {
                    pos_value: [
                        s.position[0] as f32,
                        s.position[1] as f32,
                        s.position[2] as f32,
                        s.value as f32,
                    ],
                    metric: [m[0], m[1], m[2], m[3]],
                    metric_off: [m[4], m[5], 1000.0 + i as f32, 0.0],
                }
            })
            .collect();
        (tree, samples)
    }

    /// The twin comparison: every leaf's records, read as the kernel reads them, are its coded
    /// members' samples in the coded order — the position, value, the metric terms the
    /// variant reads, and the Gaussian weight — at both strides.
    #[test]
    fn every_leafs_records_are_its_coded_members_in_order() {
        let (tree, samples) = octree(3000);
        for stride in [2, 3] {
            let leaves = InlineLeaves::build(&tree, &samples, stride);
            assert_eq!(
                leaves.texels.len() as u64,
                record_texel_count(&tree, stride)
            );
            let mut checked = 0;
            for (node, n) in tree.nodes.iter().enumerate().filter(|(_, n)| n[0] == 0) {
                let coded: Vec<u32> = LeafCodes::new(&tree.codes, n[1], n[2]).collect();
                let records: Vec<&[[f32; 4]]> = leaves.leaf(node).collect();
                assert_eq!(coded.len(), records.len(), "leaf {node}");
                assert_eq!(leaves.nodes[node][3], n[3], "leaf {node}'s scale");
                for (&i, r) in coded.iter().zip(&records) {
                    let s = &samples[i as usize];
                    assert_eq!(r[0], s.pos_value);
                    assert_eq!(r[1][..3], s.metric[..3]);
                    if stride == 2 {
                        assert_eq!(r[1][3], s.metric_off[2], "the weight in the metric's w");
                    } else {
                        assert_eq!((r[1], r[2]), (s.metric, s.metric_off));
                    }
                    checked += 1;
                }
            }
            assert_eq!(checked, tree.references);
            assert!(tree.references > 3000, "leaves share samples");
        }
    }

    #[test]
    fn auto_takes_inline_records_only_where_they_fit() {
        let (tree, _) = octree(500);
        let texels = record_texel_count(&tree, 2);
        assert!(inline_chosen(&tree, 2, None, texels));
        assert!(!inline_chosen(&tree, 2, None, texels - 1));
        assert!(!inline_chosen(&tree, 2, Some(false), texels));
        assert!(
            inline_chosen(&tree, 2, Some(true), 0),
            "an explicit choice is kept"
        );
    }
}
