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
//! and no index is read. The same candidates in the same order make the same sums, so at
//! strides 2 and 3 the images equal the coded layout's to the bit; what it costs is memory, each sample once per
//! leaf that lists it (the octree's redundancy, 59-144 on the data measured) instead of two
//! bytes per reference.
//!
//! A record is `RECORD_STRIDE` rgba32 texels (read through an rgba32ui view, floats as their
//! bits): position and value, then the metric's diagonal with the Gaussian weight in w
//! (stride 2); a full metric keeps the sample's three texels ([`Sample`]'s layout, weight in the
//! third's z). A leaf node's (first, count) name records instead of code words.
//!
//! Isotropic supports (every metric `I / h²`, the default for scattered points and meshes) pack
//! a record into one texel (stride 1, [`PackedFrame`]): the position as three 21-bit steps from
//! a corner of the leaf's records, then the value (the Gaussian sum's `w f`, its only use of
//! either) and `1 / h²`. The leaf's first texel is that corner and step. Half the memory, so
//! twice the data fits "auto"'s cap; an evaluation's speed measured the same (BENCHMARKS.md
//! "Packed octree records"). A position moves by at most half a step (2.4e-7 of the records'
//! extent, where f32 rounds a coordinate by up to 6e-8 of its magnitude), so evaluations err
//! against the f64 twin up to about three times the f32 layouts' (`tests/octree_records.rs`),
//! and images agree with theirs within f32 rounding, not to the bit.

use crate::gpu_types::Sample;
use crate::recon::Octree;
use crate::recon::octree_codes::LeafCodes;
use rayon::prelude::*;

/// The largest inline records "auto" takes, in bytes: beyond that the coded references serve
/// (the 68 921 scattered points of issue 26 take 166 MB packed, 321 MB at stride 2; 250 000
/// take 366 MB packed; 10⁶ would take 1.7 GB).
pub const AUTO_MAX_BYTES: u64 = 512 << 20;

/// Bytes of one rgba32 texel.
pub const TEXEL_BYTES: u64 = 16;

/// Bits of each packed coordinate: three fit two words.
pub const PACKED_BITS: u32 = 21;

/// The largest packed coordinate step.
const PACKED_MAX: u32 = (1 << PACKED_BITS) - 1;

/// Texels per record: 3 with full metrics (their off-diagonal terms), 1 where every support is
/// isotropic (packed), else 2.
pub fn record_stride(full_metric: bool, isotropic: bool) -> usize {
    if full_metric {
        3
    } else if isotropic {
        1
    } else {
        2
    }
}

/// The texels of `s`'s record at stride 2 or 3 (only the first `stride` are stored), as bits.
pub fn record_texels(s: &Sample, stride: usize) -> [[u32; 4]; 3] {
    let bits = |t: [f32; 4]| t.map(f32::to_bits);
    if stride == 2 {
        let [xx, yy, zz, _] = s.metric;
        // The diagonal's fourth component (xy) is read only with full metrics: the weight
        // takes its place.
        [
            bits(s.pos_value),
            bits([xx, yy, zz, s.metric_off[2]]),
            [0; 4],
        ]
    } else {
        [bits(s.pos_value), bits(s.metric), bits(s.metric_off)]
    }
}

/// Texels that inline records of `octree` at `stride` take (at stride 1, a frame per leaf
/// too).
pub fn record_texel_count(octree: &Octree, stride: usize) -> u64 {
    let frames = if stride == 1 {
        octree.leaf_count() as u64
    } else {
        0
    };
    octree.references as u64 * stride as u64 + frames
}

/// A packed leaf's frame (its first texel): the corner `lo` of its records' box and the step
/// of their 21-bit coordinates (twin of `leaf_frame` in glsl/field/neighbours.glsl).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PackedFrame {
    pub lo: [f32; 3],
    pub step: f32,
}

impl PackedFrame {
    /// The frame of records at `positions`: their smallest corner, and a step that spans
    /// their largest extent in [`PACKED_MAX`] steps.
    pub fn of(positions: impl Iterator<Item = [f32; 3]> + Clone) -> Self {
        let lo = positions.clone().fold([f32::INFINITY; 3], |a, p| {
            std::array::from_fn(|k| a[k].min(p[k]))
        });
        let lo = lo.map(|v| if v.is_finite() { v } else { 0.0 });
        let extent = positions.fold(0.0f64, |e, p| {
            (0..3).fold(e, |e, k| e.max(p[k] as f64 - lo[k] as f64))
        });
        // Rounded up, so that the farthest record's steps stay within PACKED_MAX.
        let step = (extent / PACKED_MAX as f64) as f32;
        let step = if step as f64 * (PACKED_MAX as f64) < extent {
            f32::from_bits(step.to_bits() + 1)
        } else {
            step
        };
        Self {
            lo,
            step: if step > 0.0 { step } else { 1.0 },
        }
    }

    /// The frame's texel.
    pub fn texel(&self) -> [u32; 4] {
        [
            self.lo[0].to_bits(),
            self.lo[1].to_bits(),
            self.lo[2].to_bits(),
            self.step.to_bits(),
        ]
    }

    /// A record's texel: `p`'s steps (x in bits 0–20 of word 0, y in its bits 21–31 and bits
    /// 0–9 of word 1, z in bits 10–30 of word 1), then the value's and metric's bits.
    pub fn pack(&self, p: [f32; 3], value: f32, metric: f32) -> [u32; 4] {
        let q: [u32; 3] = std::array::from_fn(|k| {
            let steps = (p[k] as f64 - self.lo[k] as f64) / self.step as f64;
            steps.round().clamp(0.0, PACKED_MAX as f64) as u32
        });
        [
            q[0] | (q[1] << PACKED_BITS),
            (q[1] >> (32 - PACKED_BITS)) | (q[2] << (2 * PACKED_BITS - 32)),
            value.to_bits(),
            metric.to_bits(),
        ]
    }

    /// The position a record's texel decodes to, as the kernel computes it (its offset from a
    /// query x is `(lo − x) + q · step` there).
    pub fn position(&self, t: [u32; 4]) -> [f64; 3] {
        let q = Self::steps(t);
        std::array::from_fn(|k| self.lo[k] as f64 + q[k] as f64 * self.step as f64)
    }

    /// A record's three coordinate steps.
    pub fn steps(t: [u32; 4]) -> [u32; 3] {
        [
            t[0] & PACKED_MAX,
            (t[0] >> PACKED_BITS) | ((t[1] << (32 - PACKED_BITS)) & PACKED_MAX),
            (t[1] >> (2 * PACKED_BITS - 32)) & PACKED_MAX,
        ]
    }
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
    pub texels: Vec<[u32; 4]>,
    pub stride: usize,
}

impl InlineLeaves {
    /// Stage `octree_records` on the host: [`InlineLeaves::write`] into a vector (`None` as
    /// there).
    pub fn build(
        octree: &Octree,
        samples: &[Sample],
        stride: usize,
        gaussian: bool,
    ) -> Option<Self> {
        let mut texels = vec![[0; 4]; record_texel_count(octree, stride) as usize];
        let nodes = Self::write(octree, samples, stride, gaussian, &mut texels)?;
        Some(Self {
            nodes,
            texels,
            stride,
        })
    }

    /// Stage `octree_records`: every leaf's members (in their coded order) copied from
    /// `samples` (the octree's samples as uploaded, one per sample) into `out`, which the
    /// device's buffer may be itself (`Buffer::fill`: no host copy of the records); returns
    /// the nodes, each leaf's (first record, record count) in place of its codes' (first
    /// word, count), or `None` where `out` is not the [`record_texel_count`] it fills
    /// exactly. At stride 1 a leaf's first texel is its [`PackedFrame`], and `gaussian`
    /// stores `w f` as the value. Leaves are counted first, then filled in parallel, each its
    /// own part of `out`: the result does not depend on the thread count.
    pub fn write(
        octree: &Octree,
        samples: &[Sample],
        stride: usize,
        gaussian: bool,
        out: &mut [[u32; 4]],
    ) -> Option<Vec<[u32; 4]>> {
        if out.len() as u64 != record_texel_count(octree, stride) {
            return None;
        }
        let frame = usize::from(stride == 1);
        let mut nodes = octree.nodes.clone();
        let mut parts = Vec::new();
        let mut rest = out;
        let mut at = 0;
        for node in nodes.iter_mut().filter(|n| n[0] == 0) {
            let codes = LeafCodes::new(&octree.codes, node[1], node[2]);
            let members = codes.clone().count();
            let len = frame + members * stride;
            if len > rest.len() {
                return None;
            }
            let (part, tail) = std::mem::take(&mut rest).split_at_mut(len);
            rest = tail;
            parts.push((part, codes));
            node[1] = (at / stride) as u32;
            node[2] = members as u32;
            at += len;
        }
        if !rest.is_empty() {
            return None;
        }
        parts.into_par_iter().for_each(|(part, codes)| {
            if stride == 1 {
                let pos = |i: u32| {
                    let p = samples[i as usize].pos_value;
                    [p[0], p[1], p[2]]
                };
                let frame = PackedFrame::of(codes.clone().map(pos));
                part[0] = frame.texel();
                for (texel, i) in part[1..].iter_mut().zip(codes) {
                    let s = &samples[i as usize];
                    let f = s.pos_value[3];
                    let value = if gaussian {
                        (f as f64 * s.metric_off[2] as f64) as f32
                    } else {
                        f
                    };
                    *texel = frame.pack(pos(i), value, s.metric[0]);
                }
            } else {
                for (record, i) in part.chunks_exact_mut(stride).zip(codes) {
                    record.copy_from_slice(&record_texels(&samples[i as usize], stride)[..stride]);
                }
            }
        });
        Some(nodes)
    }

    /// The records of leaf `node` as the kernel reads them: record r of the leaf at texel
    /// `stride · (first + r)`, or at stride 1 `first + 1 + r` (after the frame).
    pub fn leaf(&self, node: usize) -> impl Iterator<Item = &[[u32; 4]]> + '_ {
        let [_, first, count, _] = self.nodes[node];
        let skip = u32::from(self.stride == 1);
        (first + skip..first + skip + count).map(move |r| {
            let at = r as usize * self.stride;
            &self.texels[at..at + self.stride]
        })
    }

    /// A packed leaf's frame (stride 1).
    pub fn frame(&self, node: usize) -> Option<PackedFrame> {
        let t = self.texels[self.nodes[node][1] as usize];
        (self.stride == 1).then(|| PackedFrame {
            lo: [t[0], t[1], t[2]].map(f32::from_bits),
            step: f32::from_bits(t[3]),
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
    /// variant reads, and the Gaussian weight — at every stride; packed positions within half
    /// a step (and f32 rounding) of the sample's.
    #[test]
    fn every_leafs_records_are_its_coded_members_in_order() {
        let (tree, samples) = octree(3000);
        let bits = |t: [f32; 4]| t.map(f32::to_bits);
        for (stride, gaussian) in [(1, false), (1, true), (2, false), (3, false)] {
            let leaves = InlineLeaves::build(&tree, &samples, stride, gaussian).expect("records");
            let count = record_texel_count(&tree, stride) as usize;
            assert_eq!(leaves.texels.len(), count);
            // A buffer of another length is refused, not partly filled or overrun.
            for wrong in [count - 1, count + 1] {
                let mut out = vec![[0; 4]; wrong];
                let written = InlineLeaves::write(&tree, &samples, stride, gaussian, &mut out);
                assert_eq!(written, None, "stride {stride}, {wrong} texels for {count}");
            }
            let mut checked = 0;
            let mut worst_steps = 0.0f64;
            for (node, n) in tree.nodes.iter().enumerate().filter(|(_, n)| n[0] == 0) {
                let coded: Vec<u32> = LeafCodes::new(&tree.codes, n[1], n[2]).collect();
                let records: Vec<&[[u32; 4]]> = leaves.leaf(node).collect();
                assert_eq!(coded.len(), records.len(), "leaf {node}");
                assert_eq!(leaves.nodes[node][3], n[3], "leaf {node}'s scale");
                for (&i, r) in coded.iter().zip(&records) {
                    let s = &samples[i as usize];
                    match stride {
                        1 => {
                            let frame = leaves.frame(node).expect("a packed leaf's frame");
                            let p = frame.position(r[0]);
                            for (pk, sk) in p.iter().zip(s.pos_value) {
                                let e = (pk - sk as f64).abs();
                                worst_steps = worst_steps.max(e / frame.step as f64);
                                assert!(e <= 0.5 * frame.step as f64 * (1.0 + 1e-6), "leaf {node}");
                            }
                            let f = s.pos_value[3];
                            let value = if gaussian { f * s.metric_off[2] } else { f };
                            let stored = f32::from_bits(r[0][2]);
                            assert!(
                                (stored - value).abs() <= 1e-6 * value.abs(),
                                "{stored} {value}"
                            );
                            assert_eq!(r[0][3], s.metric[0].to_bits());
                        }
                        2 => {
                            assert_eq!(r[0], bits(s.pos_value));
                            assert_eq!(r[1][..3], bits(s.metric)[..3]);
                            assert_eq!(r[1][3], s.metric_off[2].to_bits(), "the weight in w");
                        }
                        _ => {
                            assert_eq!(r[0], bits(s.pos_value));
                            assert_eq!((r[1], r[2]), (bits(s.metric), bits(s.metric_off)));
                        }
                    }
                    checked += 1;
                }
            }
            assert_eq!(checked, tree.references);
            assert!(tree.references > 3000, "leaves share samples");
            if stride == 1 {
                // Rounding to the nearest step, so some record lands near half a step.
                assert!(worst_steps > 0.4, "{worst_steps}");
            }
        }
    }

    /// Every coordinate of a packed texel decodes to the steps packed, at both ends of the
    /// range and across the word boundary that y straddles.
    #[test]
    fn packed_steps_round_trip() {
        let frame = PackedFrame {
            lo: [0.0; 3],
            step: 1.0,
        };
        for q in [
            [0, 0, 0],
            [PACKED_MAX, PACKED_MAX, PACKED_MAX],
            [1, 1 << 10, 1 << 11],
            [PACKED_MAX, 2047, 0],
            [12345, 1_048_577, 2_000_001],
        ] {
            let t = frame.pack(q.map(|v| v as f32), 0.5, 2.0);
            assert_eq!(PackedFrame::steps(t), q);
            assert_eq!(t[1] >> 31, 0, "bit 63 unused");
        }
        let f = PackedFrame::of([[1.0, -2.0, 0.5], [1.5, -2.0, 3.0]].into_iter());
        assert_eq!(f.lo, [1.0, -2.0, 0.5]);
        assert!(f.step as f64 * PACKED_MAX as f64 >= 2.5);
        assert_eq!(
            PackedFrame::steps(f.pack([1.5, -2.0, 3.0], 0.0, 0.0))[2],
            PACKED_MAX
        );
    }

    #[test]
    fn auto_takes_inline_records_only_where_they_fit() {
        let (tree, _) = octree(500);
        let texels = record_texel_count(&tree, 2);
        assert_eq!(
            record_texel_count(&tree, 1),
            texels / 2 + tree.leaf_count() as u64
        );
        assert!(inline_chosen(&tree, 2, None, texels));
        assert!(!inline_chosen(&tree, 2, None, texels - 1));
        assert!(!inline_chosen(&tree, 2, Some(false), texels));
        assert!(
            inline_chosen(&tree, 2, Some(true), 0),
            "an explicit choice is kept"
        );
    }
}
