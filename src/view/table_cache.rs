//! Preintegration tables kept between frames ([`TableCache`]): rebuilt only when what they
//! depend on changes, with the tables of earlier builds of the same transfer function kept as
//! spares for the next ([`PreintegrationTables::build_reusing`]).

use super::preintegration::{PreintegrationTables, SpareTable};
use super::transfer::TransferFunction;

/// What tables depend on: control points, lengths, resolution, scalar range.
type TableKey = (Vec<[f64; 5]>, Vec<f64>, usize, (f64, f64));

/// The spare tables a [`TableCache`] keeps whatever the current tables' size.
const SPARE_FLOOR_BYTES: u64 = 64 << 20;

/// Keeps the last preintegration tables and rebuilds them only when what they depend on changes:
/// the transfer function, the lengths, the resolution or the scalar range (for applications
/// that re-render with a new camera, or edit the transfer function interactively). Shared by
/// ray casting (its integrators' lengths) and post-shaded splatting (its half sheets).
///
/// Tables of earlier builds of the same transfer function and range are kept as spares, newest
/// last, up to half the current tables' bytes (at least [`SPARE_FLOOR_BYTES`]), and a new build
/// takes every length it needs from them: a tolerance's pilots go back and forth between
/// resolutions and levels (`renderer::tolerance`). A new transfer function or range drops
/// them.
#[derive(Debug, Default)]
pub struct TableCache {
    key: Option<TableKey>,
    tables: Option<PreintegrationTables>,
    spare: Vec<SpareTable>,
    builds: usize,
    reused: usize,
}

impl TableCache {
    /// The tables of these `lengths` over the scalar `range` (`None` when no length is
    /// asked for: the direct methods), built if needed, taking their opacity from `tf`'s
    /// integral where `exact_opacity` says so ([`PreintegrationTables::entry`]: the tables'
    /// entries are the same either way).
    pub fn get(
        &mut self,
        tf: &TransferFunction,
        range: (f64, f64),
        lengths: Vec<f64>,
        resolution: usize,
        exact_opacity: bool,
        progress: impl Fn(f64) + Sync,
    ) -> Option<&PreintegrationTables> {
        if lengths.is_empty() {
            return None;
        }
        let key = (tf.points().to_vec(), lengths, resolution, range);
        if self.key.as_ref() != Some(&key) {
            let same_function = self
                .key
                .as_ref()
                .is_some_and(|k| k.0 == key.0 && k.3 == key.3);
            let old = self.tables.take();
            if same_function {
                self.spare
                    .extend(old.into_iter().flat_map(|t| t.into_spares()));
            } else {
                self.spare.clear();
            }
            let before = self.spare.len();
            let tables = PreintegrationTables::build_reusing(
                tf,
                key.3,
                &key.1,
                resolution,
                &mut self.spare,
                progress,
            );
            self.reused += before - self.spare.len();
            let budget = (tables.bytes() / 2).max(SPARE_FLOOR_BYTES);
            let mut kept: u64 = self.spare.iter().map(SpareTable::bytes).sum();
            let mut oldest = 0;
            while kept > budget {
                kept -= self.spare[oldest].bytes();
                oldest += 1;
            }
            self.spare.drain(..oldest);
            self.tables = Some(tables);
            self.key = Some(key);
            self.builds += 1;
        }
        if let Some(t) = self.tables.as_mut()
            && t.exact_opacity.is_some() != exact_opacity
        {
            t.set_exact_opacity(exact_opacity.then_some(tf));
        }
        self.tables.as_ref()
    }

    /// The tables of the last `get` that needed any.
    pub fn current(&self) -> Option<&PreintegrationTables> {
        self.tables.as_ref()
    }

    /// How many times tables were built.
    pub fn builds(&self) -> usize {
        self.builds
    }

    /// How many tables builds took from earlier ones instead of building them.
    pub fn reused(&self) -> usize {
        self.reused
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reused_tables_equal_fresh_ones_to_the_bit() {
        let tf = TransferFunction::new(vec![
            [0.0, 1.0, 0.5, 0.2, 0.0],
            [0.4, 1.0, 0.5, 0.2, 6.0],
            [1.0, 0.2, 0.5, 1.0, 1.0],
        ]);
        let first = PreintegrationTables::build(&tf, (0.0, 1.0), &[0.5, 0.25], 24, |_| {});
        // The next rung of a halving ladder: one length shared, one new.
        let lengths = [0.25, 0.125];
        let mut spare: Vec<SpareTable> = first.clone().into_spares().collect();
        let reused =
            PreintegrationTables::build_reusing(&tf, (0.0, 1.0), &lengths, 24, &mut spare, |_| {});
        let fresh = PreintegrationTables::build(&tf, (0.0, 1.0), &lengths, 24, |_| {});
        assert_eq!(reused.tables, fresh.tables);
        assert_eq!(reused.limits, fresh.limits);
        assert_eq!(
            reused.tables[0], first.tables[1],
            "the shared length was taken over"
        );
        assert_eq!(spare.len(), 1, "the table taken is no longer spare");
        assert_eq!(spare[0].length, 0.5);
        // Another resolution is never taken over.
        let mut spare: Vec<SpareTable> = first.clone().into_spares().collect();
        let other =
            PreintegrationTables::build_reusing(&tf, (0.0, 1.0), &[0.25], 16, &mut spare, |_| {});
        assert_eq!(spare.len(), 2);
        assert_eq!(other.tables[0].len(), 16 * 16);
    }

    #[test]
    fn the_cache_takes_back_tables_of_an_earlier_resolution() {
        let tf = TransferFunction::new(vec![[0.0, 1.0, 0.5, 0.2, 0.0], [1.0, 0.2, 0.5, 1.0, 4.0]]);
        let mut cache = TableCache::default();
        let lengths = vec![0.5, 0.25];
        let get = |cache: &mut TableCache, r: usize| {
            cache
                .get(&tf, (0.0, 1.0), lengths.clone(), r, false, |_| {})
                .cloned()
                .expect("tables")
        };
        let coarse = get(&mut cache, 24);
        let fine = get(&mut cache, 32);
        assert_eq!((cache.builds(), cache.reused()), (2, 0));
        // Back to the coarse tables, as a tolerance does after checking finer ones: both
        // lengths come from the spares, to the bit.
        let again = get(&mut cache, 24);
        assert_eq!((cache.builds(), cache.reused()), (3, 2));
        assert_eq!(again.tables, coarse.tables);
        assert_eq!(get(&mut cache, 32).tables, fine.tables);
        assert_eq!(cache.reused(), 4);
        // Another transfer function drops the spares.
        let other =
            TransferFunction::new(vec![[0.0, 1.0, 0.5, 0.2, 1.0], [1.0, 0.2, 0.5, 1.0, 4.0]]);
        cache.get(&other, (0.0, 1.0), lengths.clone(), 24, false, |_| {});
        cache.get(&tf, (0.0, 1.0), lengths.clone(), 24, false, |_| {});
        assert_eq!((cache.builds(), cache.reused()), (6, 4));
    }
}
