//! The last step of reading a parallel mesh or point file on the ranks together
//! ([`super::parallel_scattered`]): every sample to the rank whose kd box owns it and, as a
//! ghost, to every rank whose box its support reaches ([`super::ghosts::support_reaches`], the
//! rule [`super::piece_of`] applies to the whole field), each brick's samples in the whole
//! set's order; the Gaussian sum's kernel volumes, computed where each sample is owned; and a
//! splatting brick's kernels, chosen by each kernel's owner.

use super::Aabb;
use super::exchange::{Exchange, pod_bytes, pods};
use super::ghosts::{GhostCount, support_reaches};
use super::kd::KdTree;
use super::splat::SplatReach;
use crate::recon::gaussian::KernelVolumes;
use crate::recon::support_index::SupportIndex;
use crate::samples::{Metric, Positions, SampleSet, Supports};

/// Samples as records of `width` f64s, sent to the ranks `to(i)` names.
pub fn route(
    n: usize,
    ranks: usize,
    record: impl Fn(usize, &mut Vec<f64>),
    mut to: impl FnMut(usize, &mut dyn FnMut(usize)),
) -> Vec<Vec<u8>> {
    let mut out: Vec<Vec<f64>> = vec![Vec::new(); ranks];
    for i in 0..n {
        to(i, &mut |r| record(i, &mut out[r]));
    }
    out.iter().map(|v| pod_bytes(v)).collect()
}

/// A received sample's record (position, value, metric, index in the whole set) and its place
/// in the order received.
type Record<'a> = (&'a [f64], usize);

/// What [`distribute`] sent and received.
pub struct Sent {
    /// The records received from each rank.
    got: Vec<Vec<f64>>,
    /// This rank's samples each rank got as ghosts (indices into the set sent).
    ghosts_to: Vec<Vec<usize>>,
}

const RECORD: usize = 11;

/// The records a rank received, split.
pub struct Split<'a> {
    /// Its own samples' and its ghosts' records, each in the whole set's order.
    mine: Vec<Record<'a>>,
    extra: Vec<Record<'a>>,
    /// How many own records came from each rank.
    own_from: Vec<usize>,
}

impl Sent {
    /// Which received records are this rank's own (the owner's rule, applied again) and which
    /// ghosts.
    pub fn split(&self, tree: &KdTree, rank: usize) -> Split<'_> {
        let mut own_from = vec![0; self.got.len()];
        let (mut mine, mut extra): (Vec<Record<'_>>, Vec<Record<'_>>) = (vec![], vec![]);
        for (from, records) in self.got.iter().enumerate() {
            for r in records.chunks_exact(RECORD) {
                if tree.owner([r[0], r[1], r[2]]) == rank {
                    own_from[from] += 1;
                    mine.push((r, mine.len()));
                } else {
                    extra.push((r, extra.len()));
                }
            }
        }
        mine.sort_by(|a, b| a.0[10].total_cmp(&b.0[10]));
        extra.sort_by(|a, b| a.0[10].total_cmp(&b.0[10]));
        Split {
            mine,
            extra,
            own_from,
        }
    }
}

impl Split<'_> {
    /// The own samples' indices in the whole set, in the brick's order.
    pub fn own_index(&self) -> Vec<f64> {
        self.mine.iter().map(|r| r.0[10]).collect()
    }

    pub fn count(&self) -> GhostCount {
        GhostCount {
            own: self.mine.len(),
            ghosts: self.extra.len(),
        }
    }

    /// The brick: own samples first, then ghosts, each in the whole set's order (as the whole
    /// field's brick holds them: the same octree, the same sums on the device), with the
    /// domain, spacing and provenance of `set`.
    pub fn brick(&self, set: &SampleSet) -> SampleSet {
        let all: Vec<&[f64]> = self.mine.iter().chain(&self.extra).map(|r| r.0).collect();
        SampleSet {
            positions: Positions::Scattered(all.iter().map(|r| [r[0], r[1], r[2]]).collect()),
            values: all.iter().map(|r| r[3] as f32).collect::<Vec<f32>>().into(),
            supports: Supports::PerSample(
                all.iter()
                    .map(|r| [r[4], r[5], r[6], r[7], r[8], r[9]])
                    .collect(),
            ),
            domain: set.domain.clone(),
            spacing: set.spacing,
            provenance: set.provenance.clone(),
        }
    }
}

/// Sends each sample of `set` (with its `index` in the whole set) to the rank whose box of
/// `tree` owns it and, as a ghost, to every rank whose box its support reaches.
pub fn distribute<E: Exchange>(ex: &E, set: &SampleSet, index: &[f64], tree: &KdTree) -> Sent {
    let ranks = ex.size();
    let mut ghosts_to: Vec<Vec<usize>> = vec![Vec::new(); ranks];
    let out = route(
        set.len(),
        ranks,
        |i, v| {
            v.extend(set.position(i));
            v.push(f64::from(set.values.get(i)));
            v.extend(set.metric(i));
            v.push(index[i]);
        },
        |i, send| {
            let x = set.position(i);
            let owner = tree.owner(x);
            send(owner);
            let (m, e) = (set.metric(i), set.support_extent(i));
            for s in (0..ranks).filter(|&s| s != owner) {
                if support_reaches(&m, e, x, tree.boxes[s]) {
                    ghosts_to[s].push(i);
                    send(s);
                }
            }
        },
    );
    let got = ex.all_to_all(out).iter().map(|b| pods(b)).collect();
    Sent { got, ghosts_to }
}

/// The Gaussian sum's kernel volumes of `brick` ([`KernelVolumes::compute`]): each owner
/// computes its own samples' (its box holds each, so its brick holds every kernel that reaches
/// it) and returns them to the rank that sent them, which sends them on with the ghosts.
pub fn kernel_volumes<E: Exchange>(
    ex: &E,
    brick: &SampleSet,
    split: &Split<'_>,
    sent: &Sent,
    set: &SampleSet,
    tree: &KdTree,
    sigma: f64,
) -> KernelVolumes {
    let ranks = ex.size();
    let computed = match KernelVolumes::compute(brick, &SupportIndex::new(brick), sigma) {
        KernelVolumes::PerSample(v) => v,
        KernelVolumes::Uniform(v) => vec![v; brick.len()],
    };
    // Back to the senders, in the order received from each.
    let mut received = vec![0.0; split.mine.len()];
    for (p, &(_, r)) in split.mine.iter().enumerate() {
        received[r] = computed[p];
    }
    let mut back = Vec::with_capacity(ranks);
    let mut at = 0;
    for &k in &split.own_from {
        back.push(pod_bytes(&received[at..at + k]));
        at += k;
    }
    // This rank's samples' volumes, in the order it sent them to their owners.
    let returned: Vec<Vec<f64>> = ex.all_to_all(back).iter().map(|b| pods(b)).collect();
    let mut next = vec![0usize; ranks];
    let sent_volume: Vec<f64> = (0..set.len())
        .map(|i| {
            let o = tree.owner(set.position(i));
            next[o] += 1;
            returned[o].get(next[o] - 1).copied().unwrap_or(f64::NAN)
        })
        .collect();
    let on: Vec<Vec<u8>> = sent
        .ghosts_to
        .iter()
        .map(|g| pod_bytes(&g.iter().map(|&i| sent_volume[i]).collect::<Vec<f64>>()))
        .collect();
    let ghost_volumes: Vec<f64> = ex
        .all_to_all(on)
        .iter()
        .flat_map(|b| pods::<f64>(b))
        .collect();
    let mut v = computed[..split.mine.len()].to_vec();
    v.extend(
        split
            .extra
            .iter()
            .map(|&(_, r)| ghost_volumes.get(r).copied().unwrap_or(f64::NAN)),
    );
    KernelVolumes::PerSample(v)
}

/// A splatting brick ([`super::Ghosts::Splat`]): this rank's own samples (the first `own` of
/// `brick`, with whole-set `index` and kernel `volumes`) and, from every rank, each kernel
/// whose reach in the view ([`SplatReach`], projected by the kernel's owner for its own
/// kernels) meets this rank's kd cell, in the whole set's order. `cells` are every rank's.
pub fn splat_ghosts<E: Exchange>(
    ex: &E,
    brick: &SampleSet,
    (own, index, volumes): (usize, &[f64], &[f64]),
    reach: &SplatReach,
    cells: &[Aabb],
) -> (SampleSet, Vec<f64>, GhostCount) {
    let rank = ex.rank();
    let out = route(
        own,
        ex.size(),
        |i, v| {
            v.extend(brick.position(i));
            v.push(f64::from(brick.values.get(i)));
            v.extend(brick.metric(i));
            v.extend([index[i], volumes[i]]);
        },
        |i, send| {
            for (s, &cell) in cells.iter().enumerate() {
                if s != rank && reach.meets(i, cell) {
                    send(s);
                }
            }
        },
    );
    let got: Vec<f64> = ex
        .all_to_all(out)
        .iter()
        .flat_map(|b| pods::<f64>(b))
        .collect();
    let mut extra: Vec<&[f64]> = got.chunks_exact(SPLAT_RECORD).collect();
    extra.sort_by(|a, b| a[10].total_cmp(&b[10]));
    let mut positions: Vec<[f64; 3]> = (0..own).map(|i| brick.position(i)).collect();
    let mut values: Vec<f32> = (0..own).map(|i| brick.values.get(i)).collect();
    let mut metrics: Vec<Metric> = (0..own).map(|i| brick.metric(i)).collect();
    let mut kernel_volumes = volumes[..own].to_vec();
    for r in &extra {
        positions.push([r[0], r[1], r[2]]);
        values.push(r[3] as f32);
        metrics.push([r[4], r[5], r[6], r[7], r[8], r[9]]);
        kernel_volumes.push(r[11]);
    }
    let set = SampleSet {
        positions: Positions::Scattered(positions),
        values: values.into(),
        supports: Supports::PerSample(metrics),
        domain: brick.domain.clone(),
        spacing: brick.spacing,
        provenance: brick.provenance.clone(),
    };
    let count = GhostCount {
        own,
        ghosts: extra.len(),
    };
    (set, kernel_volumes, count)
}

/// A kernel's record: [`RECORD`]'s and its volume.
const SPLAT_RECORD: usize = RECORD + 1;
