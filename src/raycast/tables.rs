//! Preintegration tables for a ray setup: built and sized against the device (the cache that
//! keeps them between frames is [`crate::view::table_cache::TableCache`]).

use super::setup::RaySetup;
use crate::field::{Field, RenderError, scalar_range};
use crate::view::preintegration::PreintegrationTables;
use crate::view::transfer::TransferFunction;

/// Builds the preintegration tables a setup needs (`None` for the direct methods), with the
/// exact opacity where the setup takes it. The scalar
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
    let mut tables =
        PreintegrationTables::build(tf, scalar_range(field), &lengths, resolution, progress);
    tables.set_exact_opacity(setup.exact_opacity.then_some(tf));
    Some(tables)
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
