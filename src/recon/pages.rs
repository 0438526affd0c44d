//! The fast path's fine grid in pages (issue 27 §1: the fine grid only where the field varies).
//!
//! A dense fine grid stores every point of the lattice's box, also where nothing varies: outside
//! a mesh's hull or a scattered set's supports (undefined points), and in a brain-masked MRI's
//! zero background. Paged, the fine grid is cut into pages of [`PAGE`]³ fine cells; a page
//! table maps each page to a slot of a pool, [`PAGE_EDGE`]³ points per slot (its cells' corners,
//! the faces shared with the next page stored in both, so that the 8 corners of every fine cell
//! lie in one slot: one table read per evaluation, then the same 8 reads as the dense grid).
//!
//! Stage `resample_pages` (host only): which samples' supports reach each page (the box of each
//! support, a superset of the ellipsoid) decides its slot:
//! - none: the field is undefined on the whole page (no sample has weight), so it shares the
//!   one slot of undefined points;
//! - all of one value c, on a regular grid whose supports cover its whole box (no point is
//!   undefined: the cell centre lies inside its corners' supports) where the reconstruction
//!   reproduces constants (MLS fits a constant exactly, value and analytic gradient; the
//!   Gaussian sum only for c = 0, where every term is zero): the field is c with zero gradient
//!   on the page, which shares the slot of value c;
//! - else the page is solved into a slot of its own (stage `recon_resample`).
//!
//! The shared slots differ from what a solve would store only by the solve's rounding. Paging
//! costs (17/16)³ ≈ 1.2× the points of the pages it solves, so a field takes it only where it
//! stores at most [`PAGED_SHARE`] of the dense grid's points ([`Pages::classify`]); the generator's
//! exact field is never paged (its "samples" are not what it evaluates).

use rayon::prelude::*;

/// Fine cells per page edge.
pub const PAGE: usize = 16;
/// Fine points per slot edge: the page's cells' corners.
pub const PAGE_EDGE: usize = PAGE + 1;
/// Fine points per slot.
pub const PAGE_POINTS: usize = PAGE_EDGE * PAGE_EDGE * PAGE_EDGE;
/// The largest share of the dense grid's points a paged fine grid may store (else the dense
/// grid is kept: paging adds a table read to every evaluation).
pub const PAGED_SHARE: f64 = 0.8;
/// The first word of a shared slot's GPU descriptor ([`Pages::gpu_slots`]); a solved slot's is
/// its page's index, which is below it.
pub const SLOT_CONSTANT: u32 = u32::MAX;

/// What a slot of the pool holds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Slot {
    /// The page of this index (x fastest), solved point by point.
    Solved(u32),
    /// One value with zero gradient at every point (NaN: undefined), shared by every page of it.
    Constant(f64),
}

/// What the supports that reach a page bring: the smallest and largest sample value and how many
/// samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reach {
    pub lo: f64,
    pub hi: f64,
    pub count: u64,
}

impl Reach {
    /// No sample.
    pub const NONE: Reach = Reach {
        lo: f64::INFINITY,
        hi: f64::NEG_INFINITY,
        count: 0,
    };

    fn add(&mut self, v: f64) {
        self.lo = self.lo.min(v);
        self.hi = self.hi.max(v);
        self.count += 1;
    }
}

/// Which constant pages a field may share a slot for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Constants {
    /// Any value (MLS reproduces constants).
    Any,
    /// Zero only (the Gaussian sum).
    Zero,
    /// None: some points of a page its samples reach may lie outside every support, and be
    /// undefined there, not constant (irregular data, or a grid whose supports leave gaps).
    Never,
}

/// The page table and the pool's slots of a paged fine grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Pages {
    /// Fine points per axis of the whole grid.
    pub fine: [usize; 3],
    /// Pages per axis ([`Pages::counts`]).
    pub counts: [usize; 3],
    /// Per page (x fastest), its slot.
    pub table: Vec<u32>,
    pub slots: Vec<Slot>,
}

impl Pages {
    /// Pages per axis of a fine grid with `fine` points per axis (a flat axis has one).
    pub fn counts(fine: [usize; 3]) -> [usize; 3] {
        fine.map(|d| d.saturating_sub(1).max(1).div_ceil(PAGE))
    }

    /// Stage `resample_pages`: slots from each page's reach (x fastest); `None` where paging
    /// would store more than [`PAGED_SHARE`] of the dense grid's points.
    pub fn classify(fine: [usize; 3], reach: &[Reach], constants: Constants) -> Option<Self> {
        let counts = Self::counts(fine);
        debug_assert_eq!(reach.len(), counts.iter().product::<usize>());
        let mut slots = Vec::new();
        // Shared slots by their value's bits (−0 taken as +0).
        let mut shared: std::collections::HashMap<u64, u32> = std::collections::HashMap::new();
        let table = reach
            .iter()
            .enumerate()
            .map(|(p, r)| {
                let constant = if r.count == 0 {
                    Some(f64::NAN)
                } else if r.lo == r.hi
                    && (constants == Constants::Any
                        || (constants == Constants::Zero && r.lo == 0.0))
                {
                    Some(r.lo + 0.0)
                } else {
                    None
                };
                match constant {
                    None => {
                        slots.push(Slot::Solved(p as u32));
                        (slots.len() - 1) as u32
                    }
                    Some(c) => *shared.entry(c.to_bits()).or_insert_with(|| {
                        slots.push(Slot::Constant(c));
                        (slots.len() - 1) as u32
                    }),
                }
            })
            .collect();
        let pages = Self {
            fine,
            counts,
            table,
            slots,
        };
        let dense = fine.iter().map(|&d| d.max(1) as f64).product::<f64>();
        (pages.points() as f64 <= PAGED_SHARE * dense).then_some(pages)
    }

    /// Points the pool stores.
    pub fn points(&self) -> u64 {
        (self.slots.len() * PAGE_POINTS) as u64
    }

    /// Points the pool's solved slots hold: what `recon_resample` solves.
    pub fn solved_points(&self) -> u64 {
        let solved = self
            .slots
            .iter()
            .filter(|s| matches!(s, Slot::Solved(_)))
            .count();
        (solved * PAGE_POINTS) as u64
    }

    /// The pool index of fine point `idx` in the slot of the page that holds it as its own
    /// (the last page also holds the grid's upper face): where a cell starting there reads it.
    pub fn locate(&self, idx: [usize; 3]) -> usize {
        self.in_slot(std::array::from_fn(|a| self.last_page(idx[a], a)), idx)
    }

    /// The pool index of fine point `idx` in the slot of `page`, which holds it.
    fn in_slot(&self, page: [usize; 3], idx: [usize; 3]) -> usize {
        let local: [usize; 3] = std::array::from_fn(|a| idx[a] - page[a] * PAGE);
        let p = page[0] + self.counts[0] * (page[1] + self.counts[1] * page[2]);
        self.table[p] as usize * PAGE_POINTS
            + local[0]
            + PAGE_EDGE * (local[1] + PAGE_EDGE * local[2])
    }

    /// The lowest page along axis `a` whose slots hold fine coordinate `i`: the page below its
    /// own where `i` lies on their shared face.
    fn first_page(&self, i: usize, a: usize) -> usize {
        let below = if i > 0 && i.is_multiple_of(PAGE) {
            i / PAGE - 1
        } else {
            i / PAGE
        };
        below.min(self.counts[a] - 1)
    }

    /// The page along axis `a` that holds fine coordinate `i` as its own (the last page also
    /// holds the grid's upper face).
    fn last_page(&self, i: usize, a: usize) -> usize {
        (i / PAGE).min(self.counts[a] - 1)
    }

    /// Every pool index holding fine point `idx`: a point on a face, edge or corner between
    /// pages is stored in each of their slots (the same value up to the solve's rounding, where
    /// a solved page meets a shared one).
    pub fn copies(&self, idx: [usize; 3]) -> impl Iterator<Item = usize> + '_ {
        let span: [[usize; 2]; 3] =
            std::array::from_fn(|a| [self.first_page(idx[a], a), self.last_page(idx[a], a)]);
        (span[2][0]..=span[2][1]).flat_map(move |k| {
            (span[1][0]..=span[1][1]).flat_map(move |j| {
                (span[0][0]..=span[0][1]).map(move |i| self.in_slot([i, j, k], idx))
            })
        })
    }

    /// The value of the shared slot that holds every fine point of the inclusive box [lo, hi]
    /// (NaN: undefined), or `None` where some page holding one of them is solved or another
    /// value: what block ranges need without reading the points.
    pub fn constant_over(&self, lo: [usize; 3], hi: [usize; 3]) -> Option<f64> {
        let first: [usize; 3] = std::array::from_fn(|a| self.first_page(lo[a], a));
        let last: [usize; 3] = std::array::from_fn(|a| self.last_page(hi[a], a));
        let mut slot = None;
        for k in first[2]..=last[2] {
            for j in first[1]..=last[1] {
                for i in first[0]..=last[0] {
                    let s = self.table[i + self.counts[0] * (j + self.counts[1] * k)];
                    if !matches!(self.slots[s as usize], Slot::Constant(_))
                        || slot.is_some_and(|t| t != s)
                    {
                        return None;
                    }
                    slot = Some(s);
                }
            }
        }
        match self.slots[slot? as usize] {
            Slot::Constant(c) => Some(c),
            Slot::Solved(_) => None,
        }
    }

    /// The fine point a solved slot's point `local` (x fastest within the slot) stands for:
    /// its page's corner plus `local`, clamped into the grid (a last page's points past the
    /// grid are never read).
    pub fn fine_index(&self, page: u32, local: usize) -> [usize; 3] {
        let p = page as usize;
        let corner = [
            p % self.counts[0],
            (p / self.counts[0]) % self.counts[1],
            p / (self.counts[0] * self.counts[1]),
        ];
        let l = [
            local % PAGE_EDGE,
            (local / PAGE_EDGE) % PAGE_EDGE,
            local / (PAGE_EDGE * PAGE_EDGE),
        ];
        std::array::from_fn(|a| (corner[a] * PAGE + l[a]).min(self.fine[a] - 1))
    }

    /// Per slot, `uvec2` for `recon_resample`: (page, 0) for a solved slot, ([`SLOT_CONSTANT`],
    /// the value's f32 bits) for a shared one (undefined: the quiet NaN, which is
    /// `resample::UNDEFINED_BITS`).
    pub fn gpu_slots(&self) -> Vec<[u32; 2]> {
        self.slots
            .iter()
            .map(|s| match *s {
                Slot::Solved(p) => [p, 0],
                Slot::Constant(c) if c.is_nan() => [SLOT_CONSTANT, f32::NAN.to_bits()],
                Slot::Constant(c) => [SLOT_CONSTANT, (c as f32).to_bits()],
            })
            .collect()
    }
}

/// The fine index box of page `p` (x fastest) along each axis, inclusive.
fn page_range(counts: [usize; 3], fine: [usize; 3], p: usize) -> [[usize; 2]; 3] {
    let page = [
        p % counts[0],
        (p / counts[0]) % counts[1],
        p / (counts[0] * counts[1]),
    ];
    std::array::from_fn(|a| {
        let lo = page[a] * PAGE;
        [lo, (lo + PAGE).min(fine[a].saturating_sub(1))]
    })
}

/// Stage `resample_pages` for a regular grid of `dims` samples (`value(i)`, x fastest) refined
/// `factor` times into `fine` points per axis (`resample::fine_dims`), whose supports reach
/// `reach` sample spacings along each axis: per page, the samples within that reach of its box.
pub fn grid_reach(
    dims: [usize; 3],
    fine: [usize; 3],
    factor: u32,
    reach: [f64; 3],
    value: impl Fn(usize) -> f64 + Sync,
) -> Vec<Reach> {
    let counts = Pages::counts(fine);
    let f = f64::from(factor);
    (0..counts.iter().product::<usize>())
        .into_par_iter()
        .map(|p| {
            let r = page_range(counts, fine, p);
            let span: [[usize; 2]; 3] = std::array::from_fn(|a| {
                let lo = (r[a][0] as f64 / f - reach[a]).floor().max(0.0) as usize;
                let hi = ((r[a][1] as f64 / f + reach[a]).ceil() as usize).min(dims[a] - 1);
                [lo, hi]
            });
            let mut out = Reach::NONE;
            for k in span[2][0]..=span[2][1] {
                for j in span[1][0]..=span[1][1] {
                    let row = dims[0] * (j + dims[1] * k);
                    for i in span[0][0]..=span[0][1] {
                        out.add(value(row + i));
                    }
                }
            }
            out
        })
        .collect()
}

/// Stage `resample_pages` for scattered samples: each sample (position, half extents of its
/// support's bounding box, value) counted in every page its box meets, on a fine grid of `fine`
/// points from `origin`, `step` apart.
pub fn scattered_reach(
    fine: [usize; 3],
    origin: [f64; 3],
    step: [f64; 3],
    samples: impl Iterator<Item = ([f64; 3], [f64; 3], f64)>,
) -> Vec<Reach> {
    let counts = Pages::counts(fine);
    let mut out = vec![Reach::NONE; counts.iter().product()];
    let page_of = |c: f64, a: usize| -> usize {
        let g = (c - origin[a]) / step[a] / PAGE as f64;
        (g.floor().max(0.0) as usize).min(counts[a] - 1)
    };
    for (x, e, v) in samples {
        let lo: [usize; 3] = std::array::from_fn(|a| page_of(x[a] - e[a], a));
        let hi: [usize; 3] = std::array::from_fn(|a| page_of(x[a] + e[a], a));
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                for i in lo[0]..=hi[0] {
                    out[i + counts[0] * (j + counts[1] * k)].add(v);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pages reached by nothing share the undefined slot, constant ones (where constants are
    /// reproduced) the slot of their value, the rest get slots of their own; and paging is
    /// declined where it would not save enough.
    #[test]
    fn pages_share_slots_by_what_reaches_them() {
        let fine = [5 * PAGE + 1, PAGE + 1, PAGE + 1];
        let none = Reach::NONE;
        let zero = Reach {
            lo: 0.0,
            hi: 0.0,
            count: 5,
        };
        let two = Reach {
            lo: 2.0,
            hi: 2.0,
            count: 5,
        };
        let varies = Reach {
            lo: 0.0,
            hi: 1.0,
            count: 5,
        };
        let p =
            Pages::classify(fine, &[none, zero, zero, zero, none], Constants::Any).expect("paged");
        assert_eq!(p.counts, [5, 1, 1]);
        assert_eq!(p.table, vec![0, 1, 1, 1, 0]);
        assert!(matches!(p.slots[0], Slot::Constant(c) if c.is_nan()));
        assert_eq!(p.slots[1], Slot::Constant(0.0));
        assert_eq!(p.solved_points(), 0);
        // Irregular data shares only the undefined slot.
        let p = Pages::classify(fine, &[none, zero, zero, none, none], Constants::Never)
            .expect("paged");
        assert_eq!(p.table, vec![0, 1, 2, 0, 0]);
        assert_eq!(p.solved_points(), 2 * PAGE_POINTS as u64);
        // The Gaussian sum shares zero but solves a constant 2.
        let p =
            Pages::classify(fine, &[two, zero, none, none, zero], Constants::Zero).expect("paged");
        assert_eq!(p.slots[0], Slot::Solved(0));
        assert_eq!(p.table, vec![0, 1, 2, 2, 1]);
        assert_eq!(p.points(), 3 * PAGE_POINTS as u64);
        assert_eq!(p.solved_points(), PAGE_POINTS as u64);
        // Three solved pages and two shared slots store more than the dense grid: not paged.
        assert_eq!(
            Pages::classify(fine, &[varies, varies, two, zero, none], Constants::Zero),
            None
        );
    }

    /// Every fine point is found in a slot whose solved page holds it (faces in either page).
    #[test]
    fn located_points_are_the_ones_their_slots_hold() {
        let fine = [2 * PAGE + 5, PAGE + 3, 1];
        let counts = Pages::counts(fine);
        assert_eq!(counts, [3, 2, 1]);
        // A table in reverse order, every page solved (forced, bypassing the share rule).
        let n = counts.iter().product::<usize>();
        let pages = Pages {
            fine,
            counts,
            table: (0..n as u32).rev().collect(),
            slots: (0..n as u32).rev().map(Slot::Solved).collect(),
        };
        for k in 0..fine[2] {
            for j in 0..fine[1] {
                for i in 0..fine[0] {
                    let at = pages.locate([i, j, k]);
                    let Slot::Solved(page) = pages.slots[at / PAGE_POINTS] else {
                        panic!("solved");
                    };
                    assert_eq!(pages.fine_index(page, at % PAGE_POINTS), [i, j, k]);
                }
            }
        }
    }

    /// A point on faces between pages is found in each of their slots; a box whose pages all
    /// share one slot has its constant, and none otherwise.
    #[test]
    fn face_points_have_a_copy_in_every_page_that_holds_them() {
        let fine = [2 * PAGE + 1, 2 * PAGE + 1, 1];
        let p = Pages {
            fine,
            counts: [2, 2, 1],
            table: vec![0, 1, 1, 1],
            slots: vec![Slot::Solved(0), Slot::Constant(0.0)],
        };
        let slots = |idx| p.copies(idx).map(|at| at / PAGE_POINTS).collect::<Vec<_>>();
        assert_eq!(slots([3, 3, 0]), vec![0]);
        assert_eq!(slots([PAGE, 3, 0]), vec![0, 1]);
        assert_eq!(slots([PAGE, PAGE, 0]), vec![0, 1, 1, 1]);
        assert_eq!(slots([2 * PAGE, 2 * PAGE, 0]), vec![1]);
        for idx in [[PAGE, 3, 0], [PAGE, PAGE, 0], [PAGE + 2, PAGE, 0]] {
            for at in p.copies(idx) {
                let Slot::Solved(page) = p.slots[at / PAGE_POINTS] else {
                    continue;
                };
                assert_eq!(p.fine_index(page, at % PAGE_POINTS), idx);
            }
        }
        assert_eq!(
            p.constant_over([PAGE + 1, 1, 0], [PAGE + 4, 4, 0]),
            Some(0.0)
        );
        assert_eq!(
            p.constant_over([PAGE, 1, 0], [PAGE + 4, 4, 0]),
            None,
            "a face of page 0"
        );
        assert_eq!(
            p.constant_over([2, 2, 0], [4, 4, 0]),
            None,
            "the solved page"
        );
    }

    /// A grid page's reach holds the samples within the support of its box, and no others.
    #[test]
    fn grid_reach_spans_the_support_around_each_page() {
        let dims = [40, 3, 3];
        // Values: the sample's x index; factor 2: page 0 covers samples 0..8, page 1 8..16.
        let fine = [79, 5, 5];
        let reach = grid_reach(dims, fine, 2, [2.5, 2.5, 2.5], |i| (i % 40) as f64);
        assert_eq!(reach.len(), 5);
        assert_eq!((reach[0].lo, reach[0].hi), (0.0, 11.0));
        assert_eq!((reach[1].lo, reach[1].hi), (5.0, 19.0));
        assert_eq!((reach[4].lo, reach[4].hi), (29.0, 39.0));
    }

    /// A scattered sample counts in every page its support box meets.
    #[test]
    fn scattered_reach_counts_each_sample_where_its_box_meets() {
        let fine = [3 * PAGE + 1, PAGE + 1, PAGE + 1];
        let step = [1.0; 3];
        let samples = vec![
            ([24.0, 5.0, 5.0], [5.0, 1.0, 1.0], 1.0),
            ([40.0, 5.0, 5.0], [1.0, 1.0, 1.0], 3.0),
        ];
        let r = scattered_reach(fine, [0.0; 3], step, samples.into_iter());
        assert_eq!(r[0], Reach::NONE);
        assert_eq!((r[1].lo, r[1].hi, r[1].count), (1.0, 1.0, 1));
        assert_eq!((r[2].lo, r[2].hi, r[2].count), (3.0, 3.0, 1));
    }
}
