//! One ray of the CPU twins: its front-to-back accumulation ([`Ray`]) and its view of
//! empty-space skipping ([`Skip`], stages `skip_block` and `skip_run`), shared by the midpoint,
//! fixed-step and adaptive integrators.

use crate::field::Field;
use crate::field::skip::{Blocks, SkipTable};
use crate::recon::mls::Neighbours;
use glam::DVec3;

/// Empty-space skipping's data for one frame: the field's block ranges and the frame's table.
#[derive(Debug, Clone, Copy)]
pub struct Skip<'a> {
    pub blocks: &'a Blocks,
    pub table: &'a SkipTable,
}

impl Skip<'_> {
    /// Stage `skip_block`.
    pub(super) fn lookup(&self, o: DVec3, d: DVec3, t: f64) -> (bool, f64) {
        self.blocks.lookup(self.table, o, d, t)
    }

    /// Stages `skip_block` then `skip_run` (twin of skip_span): whether the block at t is
    /// empty and, if so, where the run of empty blocks from it ends; else where the run of
    /// occupied blocks from it ends, the next place a check can find an empty block (the
    /// integrators check again there instead of at each occupied block's exit: the same
    /// decisions, fewer of them, up to an empty block's corner a nudge thin, which a run
    /// passes over as empty runs already do).
    pub(super) fn span(&self, o: DVec3, d: DVec3, t: f64, t_end: f64) -> (bool, f64) {
        let (empty, exit) = self.lookup(o, d, t);
        (empty, self.run(o, d, exit, t_end, empty))
    }

    /// Stage `skip_reaches_end`: a run of empty blocks ending at `exit` covers the ray to
    /// `t_end`.
    pub(super) fn reaches_end(&self, exit: f64, t_end: f64) -> bool {
        self.blocks.reaches_end(exit, t_end)
    }

    /// Stage `skip_run`: across blocks that are all `empty` or all occupied.
    pub(super) fn run(&self, o: DVec3, d: DVec3, t: f64, t_end: f64, empty: bool) -> f64 {
        self.blocks.run(self.table, o, d, t, t_end, empty)
    }
}

/// Front-to-back accumulation along one ray.
pub(super) struct Ray<'a> {
    pub(super) o: DVec3,
    pub(super) d: DVec3,
    pub(super) field: &'a Field,
    pub(super) neighbours: &'a dyn Neighbours,
    pub(super) skip: Option<Skip<'a>>,
    pub(super) color: [f64; 3],
    pub(super) transmittance: f64,
    pub(super) evaluations: u32,
    /// Ray length skipped and evaluations saved so far.
    pub(super) skipped: f64,
    pub(super) saved: u32,
    /// The adaptive integrator's error estimate so far.
    pub(super) error_estimate: f64,
}

impl Ray<'_> {
    /// Outer steps skipped over `len` of the ray, of which `restart` knots are evaluated
    /// anyway (twin of count_skip).
    pub(super) fn count_skip(&mut self, len: f64, steps: u64, restart: u64) {
        self.skipped += len;
        // A pending knot counted as saved comes back as a restart without steps.
        self.saved = (u64::from(self.saved) + steps - restart) as u32;
    }

    /// Stage `count_error`: adds an accepted interval of `len` whose criterion estimated
    /// `error` per sample spacing `h`, capped by the most that length can add (`peak`, the
    /// transfer function's largest τ or τ·c_k; twin of count_error).
    pub(super) fn count_error(&mut self, error: f64, len: f64, h: f64, peak: f64) {
        self.error_estimate += error.min(self.transmittance * peak * h) * (len / h);
    }

    /// Composites a premultiplied segment (C, α) behind what is accumulated.
    pub(super) fn composite(&mut self, c: [f64; 3], alpha: f64) {
        for (acc, ci) in self.color.iter_mut().zip(c) {
            *acc += self.transmittance * ci;
        }
        self.transmittance *= 1.0 - alpha;
    }
}

/// Where the integrators resume after an empty block: the first of the intervals of length `l`
/// starting at t0 (numbered from 0) that reaches past `exit`, no earlier than `next`.
pub fn resume_interval(t0: f64, l: f64, exit: f64, next: u64) -> u64 {
    let j = ((exit - t0) / l).floor();
    if j.is_finite() && j > next as f64 {
        j.min(u32::MAX as f64) as u64
    } else {
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resume_skips_only_whole_intervals() {
        assert_eq!(resume_interval(0.0, 1.0, 3.5, 1), 3);
        assert_eq!(resume_interval(0.0, 1.0, 0.5, 1), 1);
        assert_eq!(resume_interval(0.0, 1.0, f64::INFINITY, 1), 1);
    }
}
