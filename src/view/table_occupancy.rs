//! Which preintegration-table lookups are all zeros (stage `preint_clear`, GLSL twin in
//! glsl/common/preintegration.glsl): a table's nodes in [`OCCUPANCY_BINS`] bins, a bin
//! occupied where it touches a cell with extinction ([`PreintegrationTables::occupied`]). A
//! lookup whose nodes lie in clear bins interpolates zero entries only, so a kernel may skip
//! it exactly (post-shaded splatting's `SPLAT_CLEAR_SKIP`, [MLS] §4's tables unchanged).

use super::preintegration::{PreintegrationTables, table_range};
use super::transfer::TransferFunction;

/// Bins of table nodes in [`PreintegrationTables::occupied`]: node i is in bin
/// i · 64 / resolution, so that the kernels' mask is two words (`TableBlock::occupied`).
pub const OCCUPANCY_BINS: usize = 64;

/// The bin of node `i` of a table of `n` nodes.
fn bin(i: usize, n: usize) -> usize {
    i * OCCUPANCY_BINS / n
}

/// The bins of a table's nodes that touch an occupied cell (cell c lies between nodes c and
/// c + 1, and sets the bins of both).
fn cell_bins(n: usize, occupied: impl Fn(usize) -> bool) -> u64 {
    (0..n - 1)
        .filter(|&c| occupied(c))
        .fold(0, |bins, c| bins | 1 << bin(c, n) | 1 << bin(c + 1, n))
}

/// The bins of a lookup's window: from one node below the lower of its grid nodes `x`, `y`
/// (floors of their positions) to one above the higher's upper node. The node either side is a
/// margin for a kernel's f32 grid position, which may round to the next node where the
/// host's f64 does not.
fn window_bins(x: usize, y: usize, n: usize) -> u64 {
    let lo = x.min(y).min(n - 2).saturating_sub(1);
    let hi = (x.max(y).min(n - 2) + 2).min(n - 1);
    (bin(lo, n)..=bin(hi, n)).fold(0, |m, i| m | 1 << i)
}

/// Whether some lookup of the tables of `tf` over `s_range` at `resolution` nodes will be
/// [`PreintegrationTables::clear`], decided before they are built (so that a kernel compiles
/// the skip only where it can fire): the bins [`PreintegrationTables::occupied`] would mark,
/// from the cells on which τ is not zero everywhere, leave some node's lookup window clear.
/// Where the quadrature rounds a cell's entries to zero this counts it occupied: it may say no
/// where a skip could fire, never yes where none can.
pub fn clear_somewhere(tf: &TransferFunction, s_range: (f64, f64), resolution: usize) -> bool {
    let n = resolution.max(2);
    let (lo, hi) = table_range(s_range);
    let node = |i: usize| lo + (hi - lo) * i as f64 / (n - 1) as f64;
    let occupied = cell_bins(n, |c| !tf.transparent_on(node(c), node(c + 1)));
    (0..n).any(|i| occupied & window_bins(i, i, n) == 0)
}

impl PreintegrationTables {
    /// The bins of `table`'s nodes that touch a cell with extinction: cell c is occupied where
    /// its one-cell entries (c → c + 1, c + 1 → c) or its nodes' zero-length entries are
    /// nonzero. Entry (f, b) is the composite of the cells between its nodes
    /// ([`PreintegrationTables::build`]), and a cell without extinction adds exact zeros to any
    /// window of them: where a lookup's nodes all lie in clear bins, every entry it
    /// interpolates is zero, and [`PreintegrationTables::clear`] skips it exactly. Read from the
    /// entries, not the transfer function, so that it holds whatever the quadrature made of
    /// each cell (a cell whose extinction rounds away at one length and not at another counts
    /// as occupied).
    pub fn occupied(&self, table: &[[f32; 4]]) -> u64 {
        let n = self.resolution;
        let nonzero = |f: usize, b: usize| table[f + n * b].iter().any(|&x| x != 0.0);
        cell_bins(n, |c| {
            nonzero(c, c + 1) || nonzero(c + 1, c) || nonzero(c, c) || nonzero(c + 1, c + 1)
        })
    }

    /// Whether every entry of table `k` that [`PreintegrationTables::lookup`] interpolates at
    /// (s_f, s_b) is zero by [`PreintegrationTables::occupied`] (twin: preint_clear in
    /// glsl/common/preintegration.glsl): the bins of the lookup's window are clear.
    pub fn clear(&self, k: usize, s_f: f64, s_b: f64) -> bool {
        let (x, y) = (self.grid(s_f) as usize, self.grid(s_b) as usize);
        self.occupied[k] & window_bins(x, y, self.resolution) == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`PreintegrationTables::clear`] skips only zeros, and skips the transparent runs: with
    /// the ML points' transfer function (extinction only in 0.22–0.38 and 0.62–0.78), every
    /// lookup it calls clear is zero in all channels of every table, and every lookup whose
    /// values both lie in 0.42–0.58 (a bin and two nodes inside the run) is clear. A function
    /// with extinction everywhere occupies every bin.
    #[test]
    fn clear_lookups_are_zero_and_transparent_runs_are_clear() {
        let tf = TransferFunction::new(vec![
            [0.0, 0.0, 0.0, 0.0, 0.0],
            [0.22, 1.0, 0.55, 0.15, 0.0],
            [0.30, 1.0, 0.55, 0.15, 4.0],
            [0.38, 1.0, 0.55, 0.15, 0.0],
            [0.62, 0.2, 0.5, 1.0, 0.0],
            [0.70, 0.2, 0.5, 1.0, 6.0],
            [0.78, 0.2, 0.5, 1.0, 0.0],
            [1.0, 0.0, 0.0, 0.0, 0.0],
        ]);
        let t = PreintegrationTables::build(&tf, (0.0, 1.0), &[0.05, 0.025], 256, |_| {});
        assert_eq!(t.occupied.len(), 2);
        // The same pairs on every run.
        let mut rng = crate::data::random::Lcg::new(0x2545_f491_4f6c_dd1d);
        let mut next = || rng.next_f64();
        let (mut cleared, mut inside) = (0, 0);
        for i in 0..100_000 {
            let s_f = t.s_min + (t.s_max - t.s_min) * next();
            // Half the pairs close together, as consecutive samples along a ray are.
            let s_b = if i % 2 == 0 {
                s_f + 0.05 * (next() - 0.5)
            } else {
                t.s_min + (t.s_max - t.s_min) * next()
            };
            for k in 0..2 {
                if t.clear(k, s_f, s_b) {
                    cleared += 1;
                    assert_eq!(t.lookup(&t.tables[k], s_f, s_b), [0.0; 4], "({s_f}, {s_b})");
                }
            }
            if (0.42..0.58).contains(&s_f) && (0.42..0.58).contains(&s_b) {
                inside += 1;
                assert!(
                    t.clear(0, s_f, s_b),
                    "({s_f}, {s_b}) in the transparent run"
                );
            }
        }
        assert!(inside > 1000, "{inside} pairs in the run");
        assert!(cleared > 20_000, "{cleared} lookups cleared of 200 000");
        let opaque =
            TransferFunction::new(vec![[0.0, 1.0, 0.5, 0.2, 1.0], [1.0, 0.2, 0.5, 1.0, 4.0]]);
        let all = PreintegrationTables::build(&opaque, (0.0, 1.0), &[0.05], 256, |_| {});
        assert_eq!(all.occupied, vec![u64::MAX]);
        assert!(!all.clear(0, 0.5, 0.5));
        // Decided before the build, the same way: a skip can fire with the first function,
        // none with the second, nor with τ zero only below 0 on one cell.
        assert!(clear_somewhere(&tf, (0.0, 1.0), 256));
        assert!(!clear_somewhere(&opaque, (0.0, 1.0), 256));
        let ramp =
            TransferFunction::new(vec![[0.0, 1.0, 0.5, 0.2, 0.0], [1.0, 0.2, 0.5, 1.0, 4.0]]);
        assert!(!clear_somewhere(&ramp, (-1.0 / 255.0, 1.0), 256));
        let wide = PreintegrationTables::build(&ramp, (-0.5, 1.0), &[0.05], 256, |_| {});
        assert!(clear_somewhere(&ramp, (-0.5, 1.0), 256));
        assert!(wide.clear(0, -0.3, -0.2) && wide.lookup(&wide.tables[0], -0.3, -0.2) == [0.0; 4]);
    }
}
