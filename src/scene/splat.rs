//! Scene section `[splat]`: the splatting renderer's settings (`crate::splat::SplatSettings`).

use super::{SceneError, Section};
use crate::splat::{
    Antialias, Prefetch, RASTER_PIXELS, RINGS, SheetInterval, SheetShare, SplatSettings, TILE_SIZES,
};
use toml::Value;

/// Keys of `[splat]`.
pub(super) const KEYS: &[&str] = &[
    "slab",
    "cutoff",
    "lowpass",
    "antialias",
    "occlusion",
    "surface",
    "footprint",
    "tile",
    "split",
    "sheet_share",
    "interval",
    "ring",
    "band_rows",
    "pixels",
    "branches",
    "prefetch",
];

/// Reads `[splat]`; every key is optional.
pub(super) fn parse(sec: &Section<'_>) -> Result<SplatSettings, SceneError> {
    let d = SplatSettings::default();
    Ok(SplatSettings {
        slab_spacings: sec.positive("slab", d.slab_spacings, 1e3)?,
        cutoff: sec.float("cutoff", d.cutoff, 1.0, 6.0)?,
        lowpass: sec.float("lowpass", d.lowpass, 0.0, 100.0)?,
        antialias: sec.choice(
            "antialias",
            d.antialias,
            &[
                ("ewa", Antialias::Ewa),
                ("auto", Antialias::Auto),
                ("swan", Antialias::Swan),
                ("none", Antialias::None),
            ],
        )?,
        occlusion: flag(sec, "occlusion", d.occlusion)?,
        surface: flag(sec, "surface", d.surface)?,
        exact: sec.choice("footprint", d.exact, &[("exact", true), ("affine", false)])?,
        split: optional_flag(sec, "split")?,
        sheet_share: sec.choice(
            "sheet_share",
            d.sheet_share,
            &[
                ("auto", None),
                ("erfc", Some(SheetShare::Erfc)),
                ("quadrature", Some(SheetShare::Quadrature)),
                ("midpoint", Some(SheetShare::Midpoint)),
            ],
        )?,
        interval: sec.choice(
            "interval",
            d.interval,
            &[
                ("auto", None),
                ("constant", Some(SheetInterval::Constant)),
                ("linear", Some(SheetInterval::Linear)),
                ("hermite", Some(SheetInterval::Hermite)),
            ],
        )?,
        ring: listed(sec, "ring", &RINGS, "4, 8 or 16 (sheets)")?,
        tile: listed(sec, "tile", &TILE_SIZES, "8, 16 or 32 (pixels)")?,
        band_rows: match sec.get("band_rows") {
            None => d.band_rows,
            Some(Value::Integer(r)) if (1..=4096).contains(r) => Some(*r as u32),
            Some(v) => return Err(sec.err("band_rows", "tile rows per dispatch, 1 to 4096", v)),
        },
        pixels: listed(
            sec,
            "pixels",
            &RASTER_PIXELS,
            "1, 2, 4 or 8 (per invocation)",
        )?,
        branches: optional_flag(sec, "branches")?,
        prefetch: sec.choice(
            "prefetch",
            d.prefetch,
            &[
                ("auto", None),
                ("none", Some(Prefetch::None)),
                ("list", Some(Prefetch::List)),
                ("records", Some(Prefetch::Records)),
            ],
        )?,
    })
}

/// An optional integer key that takes one of `allowed` (unset: None, as every such default).
fn listed(
    sec: &Section<'_>,
    key: &str,
    allowed: &[u32],
    expected: &str,
) -> Result<Option<u32>, SceneError> {
    match sec.get(key) {
        None => Ok(None),
        Some(Value::Integer(v)) if allowed.iter().any(|&x| i64::from(x) == *v) => {
            Ok(Some(*v as u32))
        }
        Some(v) => Err(sec.err(key, expected, v)),
    }
}

/// An optional true-or-false key (unset: None, chosen later, as every such default).
fn optional_flag(sec: &Section<'_>, key: &str) -> Result<Option<bool>, SceneError> {
    match sec.get(key) {
        None => Ok(None),
        Some(_) => flag(sec, key, true).map(Some),
    }
}

fn flag(sec: &Section<'_>, key: &str, default: bool) -> Result<bool, SceneError> {
    match sec.get(key) {
        None => Ok(default),
        Some(Value::Boolean(b)) => Ok(*b),
        Some(v) => Err(sec.err(key, "true or false", v)),
    }
}
