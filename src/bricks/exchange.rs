//! What the ranks of a decomposition exchange while they read a parallel file together
//! (issue 30 §2): a few collective operations on bytes, so that reading is one algorithm
//! whether the ranks are MPI processes (`crate::distributed`, feature `mpi`) or threads of one
//! process ([`LocalRanks`], which the tests run without MPI).
//!
//! Every rank calls every collective operation in the same order. A rank's local failure goes
//! through [`Exchange::agree`] before the next collective one, so that no rank waits for one
//! that has stopped.

use super::BrickError;
use bytemuck::Pod;
use std::sync::{Barrier, Mutex, PoisonError};

/// Collective operations among the ranks of one decomposition.
pub trait Exchange {
    /// What [`Exchange::agree`] returns when some rank failed.
    type Error: std::fmt::Display;
    fn rank(&self) -> usize;
    fn size(&self) -> usize;
    /// Every rank's `bytes`, in rank order.
    fn all_gather(&self, bytes: Vec<u8>) -> Vec<Vec<u8>>;
    /// Sends `out[r]` to rank r; returns what each rank sent this one, in rank order.
    fn all_to_all(&self, out: Vec<Vec<u8>>) -> Vec<Vec<u8>>;
    /// `Ok` on every rank only if no rank failed; otherwise every rank gets an error, which
    /// names the first failing rank and its message.
    fn agree<T>(&self, local: Result<T, String>) -> Result<T, Self::Error>;
}

/// The bytes of a slice of plain values.
pub fn pod_bytes<T: Pod>(v: &[T]) -> Vec<u8> {
    bytemuck::cast_slice(v).to_vec()
}

/// Plain values from bytes another rank sent ([`pod_bytes`]).
pub fn pods<T: Pod>(b: &[u8]) -> Vec<T> {
    bytemuck::pod_collect_to_vec(&b[..b.len() - b.len() % size_of::<T>()])
}

/// Every rank's `values`, in rank order.
pub fn gather_f64<E: Exchange>(ex: &E, values: &[f64]) -> Vec<Vec<f64>> {
    ex.all_gather(pod_bytes(values))
        .iter()
        .map(|b| pods(b))
        .collect()
}

/// Element-wise minimum of `values` over the ranks.
pub fn all_min<E: Exchange>(ex: &E, values: &[f64]) -> Vec<f64> {
    fold(ex, values, f64::INFINITY, f64::min)
}

/// Element-wise maximum of `values` over the ranks.
pub fn all_max<E: Exchange>(ex: &E, values: &[f64]) -> Vec<f64> {
    fold(ex, values, f64::NEG_INFINITY, f64::max)
}

/// Element-wise sum of `values` over the ranks, in rank order.
pub fn all_sum<E: Exchange>(ex: &E, values: &[f64]) -> Vec<f64> {
    fold(ex, values, 0.0, |a, b| a + b)
}

fn fold<E: Exchange>(ex: &E, values: &[f64], start: f64, f: fn(f64, f64) -> f64) -> Vec<f64> {
    let all = gather_f64(ex, values);
    (0..values.len())
        .map(|i| {
            all.iter()
                .filter_map(|v| v.get(i))
                .fold(start, |a, &b| f(a, b))
        })
        .collect()
}

/// An order-preserving key of a finite f64.
fn key(x: f64) -> u64 {
    let b = x.to_bits();
    if b >> 63 == 1 { !b } else { b | 1 << 63 }
}

fn from_key(k: u64) -> f64 {
    f64::from_bits(if k >> 63 == 1 { k & !(1 << 63) } else { !k })
}

/// The `which[j]`-th smallest (from 0) of the values that all ranks hold together, each rank
/// holding `values` (finite): what sorting the whole set would give, found by bisecting the
/// values' bit patterns with a count over the ranks at each step (64 steps).
pub fn select<E: Exchange>(ex: &E, values: &[f64], which: &[u64]) -> Vec<f64> {
    let mut keys: Vec<u64> = values.iter().map(|&v| key(v)).collect();
    keys.sort_unstable();
    let (mut lo, mut hi) = (vec![0u64; which.len()], vec![u64::MAX; which.len()]);
    for _ in 0..64 {
        let mid: Vec<u64> = lo.iter().zip(&hi).map(|(&l, &h)| l + (h - l) / 2).collect();
        let below: Vec<f64> = mid
            .iter()
            .map(|&m| keys.partition_point(|&k| k <= m) as f64)
            .collect();
        let below = all_sum(ex, &below);
        for j in 0..which.len() {
            if below[j] >= (which[j] + 1) as f64 {
                hi[j] = mid[j];
            } else {
                lo[j] = mid[j] + 1;
            }
        }
    }
    lo.into_iter().map(from_key).collect()
}

/// Ranks as threads of this process: what [`LocalRanks::run`] gives each.
pub struct LocalRank<'a> {
    ranks: &'a LocalRanks,
    rank: usize,
}

/// Threads that exchange through shared cells, with a barrier between writing and reading.
pub struct LocalRanks {
    size: usize,
    barrier: Barrier,
    /// cells[from · size + to]
    cells: Mutex<Vec<Vec<u8>>>,
    failed: Mutex<Vec<Option<String>>>,
}

impl LocalRanks {
    /// Runs `f` on `size` ranks, each a thread, and returns their results in rank order.
    pub fn run<T: Send>(size: usize, f: impl Fn(&LocalRank<'_>) -> T + Sync) -> Vec<T> {
        let ranks = LocalRanks {
            size,
            barrier: Barrier::new(size),
            cells: Mutex::new(vec![Vec::new(); size * size]),
            failed: Mutex::new(vec![None; size]),
        };
        std::thread::scope(|s| {
            let handles: Vec<_> = (0..size)
                .map(|rank| {
                    let (ranks, f) = (&ranks, &f);
                    s.spawn(move || f(&LocalRank { ranks, rank }))
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
                .collect()
        })
    }
}

impl LocalRank<'_> {
    fn cells(&self) -> std::sync::MutexGuard<'_, Vec<Vec<u8>>> {
        self.ranks
            .cells
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }
}

impl Exchange for LocalRank<'_> {
    type Error = BrickError;

    fn rank(&self) -> usize {
        self.rank
    }

    fn size(&self) -> usize {
        self.ranks.size
    }

    fn all_gather(&self, bytes: Vec<u8>) -> Vec<Vec<u8>> {
        let n = self.ranks.size;
        self.cells()[self.rank * n] = bytes;
        self.ranks.barrier.wait();
        let out = (0..n).map(|r| self.cells()[r * n].clone()).collect();
        self.ranks.barrier.wait();
        out
    }

    fn all_to_all(&self, out: Vec<Vec<u8>>) -> Vec<Vec<u8>> {
        let n = self.ranks.size;
        for (to, bytes) in out.into_iter().enumerate().take(n) {
            self.cells()[self.rank * n + to] = bytes;
        }
        self.ranks.barrier.wait();
        let got = (0..n)
            .map(|from| std::mem::take(&mut self.cells()[from * n + self.rank]))
            .collect();
        self.ranks.barrier.wait();
        got
    }

    fn agree<T>(&self, local: Result<T, String>) -> Result<T, BrickError> {
        let failed = || {
            self.ranks
                .failed
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
        };
        failed()[self.rank] = local.as_ref().err().cloned();
        self.ranks.barrier.wait();
        let all = failed().clone();
        self.ranks.barrier.wait();
        match all
            .iter()
            .enumerate()
            .find_map(|(r, m)| Some((r, m.as_ref()?)))
        {
            None => local.map_err(BrickError::Ranks),
            Some((r, m)) => Err(BrickError::Ranks(format!(
                "rank {r} of {}: {m}",
                self.ranks.size
            ))),
        }
    }
}
