//! Scene section `[splat]`: the splatting renderer's settings (`crate::splat::SplatSettings`).

use super::{SceneError, Section};
use crate::splat::{Antialias, RASTER_PIXELS, RINGS, SheetShare, SplatSettings, TILE_SIZES};
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
    "ring",
    "band_rows",
    "pixels",
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
                ("swan", Antialias::Swan),
                ("none", Antialias::None),
            ],
        )?,
        occlusion: flag(sec, "occlusion", d.occlusion)?,
        surface: flag(sec, "surface", d.surface)?,
        exact: sec.choice("footprint", d.exact, &[("exact", true), ("affine", false)])?,
        split: match sec.get("split") {
            None => d.split,
            Some(_) => Some(flag(sec, "split", true)?),
        },
        sheet_share: sec.choice(
            "sheet_share",
            d.sheet_share,
            &[
                ("auto", None),
                ("erfc", Some(SheetShare::Erfc)),
                ("quadrature", Some(SheetShare::Quadrature)),
            ],
        )?,
        ring: match sec.get("ring") {
            None => d.ring,
            Some(Value::Integer(r)) if RINGS.iter().any(|&x| i64::from(x) == *r) => Some(*r as u32),
            Some(v) => return Err(sec.err("ring", "4, 8 or 16 (sheets)", v)),
        },
        tile: match sec.get("tile") {
            None => d.tile,
            Some(Value::Integer(t)) if TILE_SIZES.iter().any(|&x| i64::from(x) == *t) => {
                Some(*t as u32)
            }
            Some(v) => return Err(sec.err("tile", "8, 16 or 32 (pixels)", v)),
        },
        band_rows: match sec.get("band_rows") {
            None => d.band_rows,
            Some(Value::Integer(r)) if (1..=4096).contains(r) => Some(*r as u32),
            Some(v) => return Err(sec.err("band_rows", "tile rows per dispatch, 1 to 4096", v)),
        },
        pixels: match sec.get("pixels") {
            None => d.pixels,
            Some(Value::Integer(p)) if RASTER_PIXELS.iter().any(|&x| i64::from(x) == *p) => {
                Some(*p as u32)
            }
            Some(v) => return Err(sec.err("pixels", "1, 2 or 4 (per invocation)", v)),
        },
    })
}

fn flag(sec: &Section<'_>, key: &str, default: bool) -> Result<bool, SceneError> {
    match sec.get(key) {
        None => Ok(default),
        Some(Value::Boolean(b)) => Ok(*b),
        Some(v) => Err(sec.err(key, "true or false", v)),
    }
}
