//! How a frame's accumulation is divided among dispatches, and the twins of the two stages
//! that decide it on the GPU in a recorded frame: `splat_walks` ([`band_entries`]: each band's
//! longest tile walk) and `splat_plan` ([`plan_groups`]: every indirect dispatch's workgroups).
//!
//! llvmpipe ends an invocation's loops after 65 535 iterations in a dispatch, and a tile of a
//! dense point cloud walks more (tile, sheet) entries than that: `splat_raster` runs each band
//! of [`RASTER_BAND_ROWS`] tile rows in as many passes as its longest walk takes
//! ([`RasterWalk`]), each continuing, pixels' registers and all, the walks the pass before
//! left.

use super::{Shading, SplatSetup};
use crate::field::RenderError;
use crate::gpu_types::{ORDER_INSERTION_MAX, PlanPush, RasterPush, WalkPush, splat_stat};

/// Tile rows per dispatch of `splat_raster` on a CPU device (a GPU's are wider:
/// [`SplatSetup::fit_device`]). Small bands are faster on lavapipe: at 512²
/// (64 tile rows) two rows a band took 6–9% less GPU and wall time than eight (BENCHMARKS.md,
/// "Splatting frames recorded"), at 256² 5% less than four. In
/// [`splat_frame`](super::frame::splat_frame) each band is also one submission, so that
/// Ctrl-C and the progress bar act within a fraction of a frame.
pub const RASTER_BAND_ROWS: u32 = 2;

/// Invocations per workgroup of the one-dimensional kernels.
pub(super) const GROUP: u32 = 64;

/// The walk cost a pass of `splat_raster` spends per tile at most, in loop iterations: 15/16
/// of the 65 535 llvmpipe allows an invocation in a dispatch, the rest left to the kernel's
/// other loops (a few per pixel, and the walk loop's last trip).
pub const RASTER_CHUNK: u32 = 61_440;

/// The largest walk cost a pass may be given
/// ([`crate::renderer::Renderer::set_splat_raster_chunk`]): the kernel adds it to list
/// positions in 32 bits.
pub const RASTER_CHUNK_MAX: u32 = 1 << 30;

/// Bands of `setup.band_rows` tile rows in a frame of `setup`.
pub fn raster_bands(setup: &SplatSetup) -> u32 {
    setup.tiles().1.div_ceil(setup.band_rows.max(1))
}

/// How `splat_raster` splits a tile's walk among passes (the twin of its `cost`, and of the
/// passes `splat_plan` and `splat_raster` count, `glsl/splat/walks.glsl`). A walk costs one
/// per entry and `sheet_cost` per sheet, which counts what llvmpipe's limit counts: every
/// trip of every loop, the last one whose condition fails included (a loop there ends by
/// masking lanes, then runs its body's end once more), whether or not a lane is active. Per
/// sheet that is the sheet loop's trip and the entry loop's last; post-shaded also, for each
/// pixel of an invocation, the transfer function's segment search and the isosurface
/// crossings' three loops. A pass stops before its cost would pass `chunk`; one stopped
/// inside a sheet charges that sheet again in the next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RasterWalk {
    pub chunk: u32,
    pub sheet_cost: u32,
    /// Sheets a walk steps through: the sheets, and post-shaded one more (compositing lags a
    /// sheet behind).
    pub steps: u32,
    /// Tile rows per band.
    pub band_rows: u32,
}

impl RasterWalk {
    /// The walk of a frame of `setup` whose transfer function has `tf_count` points on the
    /// GPU; `setup.raster_chunk` overrides [`RASTER_CHUNK`].
    pub fn new(setup: &SplatSetup, tf_count: u32) -> Result<Self, RenderError> {
        let post = setup.shading == Shading::Post;
        let sheet_cost = if post {
            // The segment search: count - 1 trips and the last; the crossings: the isosurface
            // loop (n + 1), the insertion of the i-th crossing (at most i + 1), the shading
            // loop (n + 1).
            let n = setup.isosurfaces.len() as u32;
            let crossings = if n > 0 {
                2 * n + 2 + n * (n + 1) / 2
            } else {
                0
            };
            2 + setup.raster_pixels() * (tf_count + crossings)
        } else {
            2
        };
        match setup.raster_chunk {
            Some(chunk) if !(3 * sheet_cost..=RASTER_CHUNK_MAX).contains(&chunk) => {
                Err(RenderError::Setting {
                    key: "splat_raster_chunk",
                    message: format!(
                        "{chunk}: expected a walk cost per pass from {} (three sheets of this \
                         frame) to {RASTER_CHUNK_MAX}",
                        3 * sheet_cost
                    ),
                })
            }
            None if RASTER_CHUNK < 3 * sheet_cost => Err(RenderError::Setting {
                key: "transfer.points",
                message: format!(
                    "expected fewer transfer function points for post-shaded splatting: \
                     compositing one sheet of a tile loops {sheet_cost} times, and one dispatch \
                     of splat_raster may loop {RASTER_CHUNK} (below llvmpipe's limit)"
                ),
            }),
            chunk => Ok(Self {
                chunk: chunk.unwrap_or(RASTER_CHUNK),
                sheet_cost,
                steps: setup.slabs + u32::from(post),
                band_rows: setup.band_rows.max(1),
            }),
        }
    }

    /// The walk of a recorded frame, as `splat_plan` was told it.
    pub fn of_plan(push: &PlanPush) -> Self {
        Self {
            chunk: push.chunk,
            sheet_cost: push.sheet_cost,
            steps: push.steps,
            band_rows: push.band_rows.max(1),
        }
    }

    /// Passes of a band whose tiles walk at most `entries` entries: one where the whole walk
    /// fits a pass; else every pass but the last makes more than `chunk − 2·sheet_cost` of
    /// progress (it stops within a sheet's cost of `chunk`, and may charge the sheet it
    /// stopped in twice).
    pub fn passes(&self, entries: u32) -> u32 {
        let walk = u64::from(entries) + u64::from(self.steps) * u64::from(self.sheet_cost);
        if walk <= u64::from(self.chunk) {
            1
        } else {
            let progress = u64::from(self.chunk - 2 * self.sheet_cost);
            u32::try_from(walk.div_ceil(progress)).unwrap_or(u32::MAX)
        }
    }

    /// The push constants of pass `pass` of the band at `tile_row`, whose last recorded pass
    /// is `last_pass`.
    pub fn push(&self, tile_row: u32, pass: u32, last_pass: u32) -> RasterPush {
        RasterPush {
            tile_row,
            pass,
            last_pass,
            chunk: self.chunk,
            sheet_cost: self.sheet_cost,
            band: tile_row / self.band_rows,
            _pad: [0; 2],
        }
    }
}

/// `splat_walks`' push constants for a frame of `setup`.
pub fn walk_push(setup: &SplatSetup) -> WalkPush {
    let (tiles_x, tiles_y) = setup.tiles();
    WalkPush {
        tiles: tiles_x * tiles_y,
        tiles_x,
        slabs: setup.slabs,
        band_rows: setup.band_rows.max(1),
    }
}

/// Stage `splat_walks` (GLSL: `glsl/splat/splat_walks.comp`): the most entries any tile of
/// each band walks, from the bucket `offsets` (the scan's, with the total after the last).
pub fn band_entries(push: &WalkPush, offsets: &[u32]) -> Vec<u32> {
    let (tiles, tiles_x, slabs) = (
        push.tiles as usize,
        push.tiles_x as usize,
        push.slabs as usize,
    );
    let rows = push.band_rows.max(1) as usize;
    let mut bands = vec![0; tiles.div_ceil(tiles_x).div_ceil(rows)];
    for tile in 0..tiles {
        let entries = offsets[(tile + 1) * slabs] - offsets[tile * slabs];
        let band = tile / tiles_x / rows;
        bands[band] = bands[band].max(entries);
    }
    bands
}

/// Each band's longest walk in entries, as `splat_walks` left it in the counters.
pub(super) fn stat_band_entries(stats: &[u32], bands: u32) -> impl Iterator<Item = u32> + '_ {
    (0..bands as usize).map(|b| {
        stats
            .get(splat_stat::BAND_ENTRIES + b)
            .copied()
            .unwrap_or(0)
    })
}

/// Workgroups of `splat_order`'s first pass, one invocation per bucket, and of `splat_walks`,
/// one per tile: rows of at most 65 535 workgroups (twin of `splat_plan`'s).
pub fn order_groups(buckets: u32) -> [u32; 3] {
    let groups = buckets.div_ceil(GROUP).max(1);
    let x = groups.min(65_535);
    [x, groups.div_ceil(x), 1]
}

/// Workgroups of `splat_order`'s second pass, one invocation per bucket its first pass could
/// hand it: at most one per bucket, and one per `ORDER_INSERTION_MAX + 1` of the frame's
/// `total` entries. (A fixed grid of 1 024 invocations, before, ran out of llvmpipe's loop
/// limit at about 60 buckets each, and left the rest out of kernel order: 13 339 of 20 051 in
/// a 512² frame of 4 913 large kernels, 679 705 at 10⁷ points.)
pub fn order_large_groups(buckets: u32, total: u32) -> [u32; 3] {
    order_groups(buckets.min(total / (ORDER_INSERTION_MAX + 1)))
}

/// Stage `splat_plan` (GLSL: `glsl/splat/splat_plan.comp`): the workgroup counts of
/// `splat_bin`, of `splat_order`'s two passes, then of each band of `push.band_rows` tile rows
/// of `splat_raster`, then of each band's `push.resumes` later passes, in a recorded frame,
/// from the scan's `total` and the projection's counters `stats` (with the bands' longest
/// walks): the whole frame, each band's passes as many as it needs ([`RasterWalk::passes`]),
/// or none (x = 0) where the entries exceed the list or the budget, or a kernel or pixel
/// overflowed.
pub fn plan_groups(push: &PlanPush, total: u32, stats: &[u32]) -> Vec<[u32; 3]> {
    let stat = |i: usize| stats.get(i).copied().unwrap_or(0);
    let run = total <= push.capacity
        && total <= push.max_entries
        && stat(splat_stat::OVERSIZED) == 0
        && (push.segments == 0 || stat(splat_stat::SEGMENT_OVERFLOW) == 0);
    let rows = push.band_rows.max(1);
    let bands = push.tiles_y.div_ceil(rows);
    let mut groups = vec![[0, 1, 1]; args_count(bands, push.resumes)];
    if !run {
        return groups;
    }
    groups[ARGS_BIN] = [push.bin_groups, 1, 1];
    groups[ARGS_ORDER[0]] = order_groups(push.buckets);
    groups[ARGS_ORDER[1]] = order_large_groups(push.buckets, total);
    let walk = RasterWalk::of_plan(push);
    for (b, entries) in (0..bands).zip(stat_band_entries(stats, bands)) {
        let rows_of_band = rows.min(push.tiles_y - b * rows);
        for pass in 0..walk.passes(entries).min(push.resumes + 1) {
            groups[args_slot(bands, push.resumes, b, pass)] = [push.tiles_x, rows_of_band, 1];
        }
    }
    groups
}

/// Where a recorded frame's indirect arguments hold pass `pass` of band `band`, for `bands`
/// bands of `resumes` passes after their first: after `splat_bin`'s and `splat_order`'s two
/// come every band's first pass, then each band's later passes (twin of `splat_plan`'s
/// layout).
pub fn args_slot(bands: u32, resumes: u32, band: u32, pass: u32) -> usize {
    let (bands, resumes) = (bands as usize, resumes as usize);
    let (band, pass) = (band as usize, pass as usize);
    if pass == 0 {
        ARGS_BEFORE_BANDS + band
    } else {
        ARGS_BEFORE_BANDS + bands + band * resumes + pass - 1
    }
}

/// Where a recorded frame's indirect arguments hold `splat_bin`'s workgroups.
pub const ARGS_BIN: usize = 0;
/// Where they hold `splat_order`'s two passes'.
pub const ARGS_ORDER: [usize; 2] = [1, 2];
/// Indirect arguments of a recorded frame before its bands': `splat_bin`'s and `splat_order`'s.
const ARGS_BEFORE_BANDS: usize = 3;

/// The indirect arguments of a recorded frame of `bands` bands and `resumes` later passes.
pub fn args_count(bands: u32, resumes: u32) -> usize {
    ARGS_BEFORE_BANDS + bands as usize * (1 + resumes as usize)
}

/// Bytes of a recorded frame's indirect arguments ([`args_slot`]).
pub fn plan_args_bytes(setup: &SplatSetup, resumes: u32) -> u64 {
    16 * args_count(raster_bands(setup), resumes) as u64
}

/// The passes after each band's first that the longest walks of a frame's bands take, from
/// its counters.
pub fn resumes_needed(setup: &SplatSetup, walk: RasterWalk, stats: &[u32]) -> u32 {
    stat_band_entries(stats, raster_bands(setup))
        .map(|e| walk.passes(e) - 1)
        .max()
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_groups_cover_every_bucket_within_the_dispatch_limit() {
        for buckets in [1u32, 64, 65, 65_535 * 64, 65_535 * 64 + 1, 1 << 24] {
            let [x, y, z] = order_groups(buckets);
            assert!(x <= 65_535 && y <= 65_535 && z == 1);
            let invocations = u64::from(x) * u64::from(y) * u64::from(GROUP);
            assert!(invocations >= u64::from(buckets), "{buckets}: {x} × {y}");
            assert!(
                invocations < u64::from(buckets) + u64::from(x * GROUP),
                "{buckets}"
            );
        }
    }

    /// Every bucket the first pass can hand over has an invocation of the second: at most
    /// one per bucket, and one per `ORDER_INSERTION_MAX + 1` entries.
    #[test]
    fn the_second_order_pass_has_an_invocation_for_every_large_bucket() {
        let large = ORDER_INSERTION_MAX + 1;
        for (buckets, total) in [
            (1u32, 0u32),
            (10, 10 * large),
            (1_220_608, 596_933),
            (600_000, 80_900_000),
            (1 << 24, u32::MAX),
        ] {
            let [x, y, z] = order_large_groups(buckets, total);
            assert!(x <= 65_535 && y <= 65_535 && z == 1);
            let invocations = u64::from(x) * u64::from(y) * u64::from(GROUP);
            let most = buckets.min(total / large);
            assert!(
                invocations >= u64::from(most),
                "{buckets}, {total}: {x} × {y}"
            );
            assert!(invocations <= u64::from(most) + u64::from(x * GROUP));
        }
    }

    #[test]
    fn plan_runs_the_frame_only_where_it_fits() {
        let push = PlanPush {
            buckets: 10,
            capacity: 100,
            max_entries: 80,
            bin_groups: 3,
            tiles_x: 4,
            tiles_y: 5,
            segments: 1,
            band_rows: 2,
            chunk: 100,
            sheet_cost: 10,
            steps: 3,
            resumes: 0,
        };
        let ok = vec![
            [3, 1, 1],
            [1, 1, 1],
            [1, 1, 1],
            [4, 2, 1],
            [4, 2, 1],
            [4, 1, 1],
        ];
        let none = vec![[0, 1, 1]; 6];
        let clean = [0u32; splat_stat::BAND_ENTRIES + 3];
        assert_eq!(plan_groups(&push, 80, &clean), ok);
        assert_eq!(plan_groups(&push, 81, &clean), none, "over the budget");
        let roomy = PlanPush {
            max_entries: u32::MAX,
            ..push
        };
        assert_eq!(plan_groups(&roomy, 100, &clean), ok);
        assert_eq!(plan_groups(&roomy, 101, &clean), none, "over the list");
        let mut oversized = clean;
        oversized[splat_stat::OVERSIZED] = 1;
        assert_eq!(plan_groups(&push, 1, &oversized), none);
        let mut segments = clean;
        segments[splat_stat::SEGMENT_OVERFLOW] = 2;
        assert_eq!(plan_groups(&push, 1, &segments), none);
        let no_hull = PlanPush {
            segments: 0,
            ..push
        };
        assert_eq!(
            plan_groups(&no_hull, 1, &segments),
            ok,
            "no segments kernel ran"
        );
        // Two passes recorded after each band's first: band 0 walks 70 entries (100 with its
        // sheets: one pass), band 1 200 (230, three of 80), band 2 100 (130, two).
        let resuming = PlanPush { resumes: 2, ..push };
        let mut walks = clean;
        walks[splat_stat::BAND_ENTRIES..].copy_from_slice(&[70, 200, 100]);
        let mut want = ok.clone();
        want.extend([
            [0, 1, 1],
            [0, 1, 1],
            [4, 2, 1],
            [4, 2, 1],
            [4, 1, 1],
            [0, 1, 1],
        ]);
        assert_eq!(plan_groups(&resuming, 80, &walks), want);
        assert_eq!(
            plan_groups(&resuming, 81, &walks),
            vec![[0, 1, 1]; 12],
            "nothing runs"
        );
    }

    /// The walk of one tile as `splat_raster` makes it, sheet by sheet (`entries[k]` in sheet
    /// k), in passes of `walk.chunk`: the passes it takes.
    fn walk_passes(walk: &RasterWalk, entries: &[u32]) -> u32 {
        let steps = walk.steps as usize;
        let (mut k, mut done_in_sheet, mut passes) = (0usize, 0u32, 1u32);
        let mut cost = 0u32;
        while k < steps {
            if cost + walk.sheet_cost > walk.chunk {
                passes += 1;
                cost = 0;
                continue;
            }
            cost += walk.sheet_cost;
            let n = entries.get(k).copied().unwrap_or(0);
            let mut cut = false;
            while done_in_sheet < n {
                if cost >= walk.chunk {
                    cut = true;
                    break;
                }
                cost += 1;
                done_in_sheet += 1;
            }
            if cut {
                passes += 1;
                cost = 0;
                continue;
            }
            done_in_sheet = 0;
            k += 1;
        }
        passes
    }

    struct Below<'a>(&'a mut crate::data::random::Lcg);

    impl Below<'_> {
        fn below(&mut self, n: u32) -> u32 {
            (self.0.next_f64() * f64::from(n)) as u32
        }
    }

    #[test]
    fn a_walk_takes_at_most_the_passes_counted_for_its_entries() {
        let mut lcg = crate::data::random::Lcg::new(7);
        let mut rng = Below(&mut lcg);
        let mut tight = 0;
        for _ in 0..2000 {
            let walk = RasterWalk {
                chunk: 40 + rng.below(400),
                sheet_cost: 1 + rng.below(12),
                steps: 1 + rng.below(60),
                band_rows: 2,
            };
            let entries: Vec<u32> = (0..walk.steps)
                .map(|_| match rng.below(4) {
                    0 => 0,
                    1 => rng.below(3),
                    _ => rng.below(2 * walk.chunk),
                })
                .collect();
            let total: u32 = entries.iter().sum();
            let (took, counted) = (walk_passes(&walk, &entries), walk.passes(total));
            assert!(took <= counted, "{walk:?}, {entries:?}: {took} > {counted}");
            tight += u32::from(took == counted);
        }
        // The count is an upper bound, not a loose one.
        assert!(tight > 500, "{tight} of 2000 walks took the passes counted");
    }
}
