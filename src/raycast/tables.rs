//! Preintegration tables for a ray setup: built, sized against the device, and cached between
//! frames.

use super::preintegration::PreintegrationTables;
use super::setup::RaySetup;
use crate::field::{Field, RenderError, scalar_range};
use crate::view::transfer::TransferFunction;

/// Builds the preintegration tables a setup needs (`None` for the direct methods). The scalar
/// range covers the data with a 5% margin each side, because MLS may overshoot the samples;
/// values beyond it are clamped to the range.
pub fn build_tables(
    setup: &RaySetup,
    field: &Field,
    tf: &TransferFunction,
    resolution: usize,
    progress: impl Fn(f64) + Sync,
) -> Option<PreintegrationTables> {
    let lengths = setup.table_lengths(tf);
    if lengths.is_empty() {
        return None;
    }
    Some(PreintegrationTables::build(
        tf,
        scalar_range(field),
        &lengths,
        resolution,
        progress,
    ))
}

/// Refuses tables the device cannot bind before they are built: `lengths` tables and the
/// zero-length limits, each `resolution`² entries of 16 bytes, in one texel buffer of at most
/// `limit` bytes (the device's maxTexelBufferElements × 16, within its largest heap). The
/// error names the key and the largest resolution this scene can have on this device.
pub fn check_table_size(lengths: &[f64], resolution: usize, limit: u64) -> Result<(), RenderError> {
    let tables = lengths.len() as u64 + 1;
    let bytes = |r: u64| tables * r * r * 16;
    let r = resolution as u64;
    if bytes(r) <= limit {
        return Ok(());
    }
    let largest = ((limit / (16 * tables)) as f64).sqrt().floor() as u64;
    Err(RenderError::Setting {
        key: "render.table_resolution",
        message: format!(
            "expected at most {largest} for this scene on this device: {resolution} needs \
             {} bytes ({tables} tables of {resolution}² entries × 16 bytes), more than the \
             {limit} bytes that one texel buffer may hold on this device \
             (maxTexelBufferElements × 16, within the largest heap)",
            bytes(r)
        ),
    })
}

/// What tables depend on: control points, lengths, resolution, scalar range.
type TableKey = (Vec<[f64; 5]>, Vec<f64>, usize, (f64, f64));

/// Keeps the last preintegration tables and rebuilds them only when what they depend on changes:
/// the transfer function, the lengths, the resolution or the scalar range (for applications
/// that re-render with a new camera, or edit the transfer function interactively).
#[derive(Debug, Default)]
pub struct TableCache {
    key: Option<TableKey>,
    tables: Option<PreintegrationTables>,
    builds: usize,
}

impl TableCache {
    /// The tables for this setup (`None` for the direct methods), built if needed.
    pub fn get(
        &mut self,
        setup: &RaySetup,
        field: &Field,
        tf: &TransferFunction,
        resolution: usize,
        progress: impl Fn(f64) + Sync,
    ) -> Option<&PreintegrationTables> {
        let lengths = setup.table_lengths(tf);
        if lengths.is_empty() {
            return None;
        }
        let key = (
            tf.points().to_vec(),
            lengths,
            resolution,
            scalar_range(field),
        );
        if self.key.as_ref() != Some(&key) {
            // Tables of the same transfer function, resolution and range are reused length by
            // length; only the new lengths are built.
            let previous = self
                .key
                .as_ref()
                .filter(|k| k.0 == key.0 && k.2 == key.2 && k.3 == key.3)
                .and(self.tables.as_ref());
            self.tables = Some(PreintegrationTables::build_reusing(
                tf, key.3, &key.1, resolution, previous, progress,
            ));
            self.key = Some(key);
            self.builds += 1;
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
}
