//! Shared by the structure-aware targets: fuzzer-chosen numbers that are mostly plausible and
//! sometimes hostile, so that generated headers reach the checks past the first one.

use libfuzzer_sys::arbitrary::{Result, Unstructured};

/// A float: usually a small plausible value, sometimes an edge (0, negative, tiny, huge, NaN,
/// infinite), sometimes any bit pattern.
pub fn float(u: &mut Unstructured) -> Result<f64> {
    const PICKS: [f64; 14] = [
        1.0,
        0.5,
        2.0,
        0.25,
        3.0,
        -1.0,
        0.0,
        -0.0,
        1e-30,
        1e30,
        1e308,
        f64::NAN,
        f64::INFINITY,
        -7.5,
    ];
    Ok(match u.int_in_range(0u8..=9)? {
        0..=6 => *u.choose(&PICKS[..6])?,
        7 | 8 => *u.choose(&PICKS)?,
        _ => f64::from_bits(u.arbitrary()?),
    })
}

/// A size along an axis: usually 1–9, sometimes 0, negative or any 16-bit value.
pub fn size(u: &mut Unstructured) -> Result<i64> {
    Ok(match u.int_in_range(0u8..=15)? {
        0..=12 => u.int_in_range(1..=9)?,
        13 => u.int_in_range(-2..=0)?,
        _ => i64::from(u.arbitrary::<i16>()?),
    })
}

/// `n` sample values as f64: a smooth ramp (renders), a constant, or fuzzed floats.
pub fn values(u: &mut Unstructured, n: usize) -> Result<Vec<f64>> {
    Ok(match u.int_in_range(0u8..=3)? {
        0 | 1 => (0..n).map(|i| ((i * 7) % 11) as f64 / 10.0).collect(),
        2 => vec![float(u)?; n],
        _ => (0..n).map(|_| float(u)).collect::<Result<_>>()?,
    })
}

/// One value stored as the little- or big-endian bytes of a scalar type (by its size and
/// kind: 'i' signed, 'u' unsigned, 'f' float), saturating like `as`.
pub fn store(out: &mut Vec<u8>, v: f64, kind: char, bytes: usize, big: bool) {
    let mut b: Vec<u8> = match (kind, bytes) {
        ('f', 4) => (v as f32).to_le_bytes().to_vec(),
        ('f', _) => v.to_le_bytes().to_vec(),
        ('i', 1) => (v as i8).to_le_bytes().to_vec(),
        ('i', 2) => (v as i16).to_le_bytes().to_vec(),
        ('i', 4) => (v as i32).to_le_bytes().to_vec(),
        ('i', _) => (v as i64).to_le_bytes().to_vec(),
        (_, 1) => (v as u8).to_le_bytes().to_vec(),
        (_, 2) => (v as u16).to_le_bytes().to_vec(),
        (_, 4) => (v as u32).to_le_bytes().to_vec(),
        _ => (v as u64).to_le_bytes().to_vec(),
    };
    if big {
        b.reverse();
    }
    out.extend(b);
}

/// Compresses with gzip (or zlib when `zlib`), at a fuzzer-chosen level; sometimes cut short,
/// sometimes with one byte flipped (a gzip trailer's CRC-32 and length must catch it).
pub fn compress(u: &mut Unstructured, data: &[u8], zlib: bool) -> Result<Vec<u8>> {
    use std::io::Write;
    let level = flate2::Compression::new(u.int_in_range(0..=9)?);
    let mut out = if zlib {
        let mut e = flate2::write::ZlibEncoder::new(Vec::new(), level);
        let _ = e.write_all(data);
        e.finish().unwrap_or_default()
    } else {
        let mut e = flate2::write::GzEncoder::new(Vec::new(), level);
        let _ = e.write_all(data);
        e.finish().unwrap_or_default()
    };
    if u.ratio(1u8, 16)? {
        let keep = u.int_in_range(0..=out.len())?;
        out.truncate(keep);
    }
    if !out.is_empty() && u.ratio(1u8, 16)? {
        let at = u.int_in_range(0..=out.len() - 1)?;
        out[at] ^= 1 << u.int_in_range(0..=7u8)?;
    }
    Ok(out)
}
