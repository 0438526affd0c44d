//! NIfTI-1 reader: single-file `.nii` (magic `n+1\0` at byte 344) and gzip-compressed `.nii.gz`
//! (recognised by the gzip magic bytes, whatever the file name).
//!
//! Contract and choices:
//! - byte order is detected from `sizeof_hdr` (348 in either order); a NIfTI-2 header (540) and
//!   the two-file `.hdr`/`.img` form (magic `ni1\0`) are unsupported;
//! - `dim[0]` must be 3, or up to 7 with every dimension after the third equal to 1 (a single
//!   time point); smaller ranks and real 4-D series are unsupported;
//! - datatypes: uint8, int8, int16, uint16, int32, uint32, int64, uint64, float32, float64;
//!   complex, RGB(A), float128 and others are unsupported; `bitpix` is not checked, the
//!   datatype alone decides the sample size;
//! - data starts at `vox_offset` (byte 108), which must be a whole number ≥ 348; bytes after the
//!   data are ignored;
//! - values are `scl_slope·raw + scl_inter` when `scl_slope` is finite and non-zero (a
//!   non-finite `scl_inter` then counts as 0), else the raw values;
//! - spacing is `|pixdim[1..=3]|`; a zero or non-finite pixdim becomes 1 without error, since
//!   many writers leave pixdim unset;
//! - origin is `qoffset_x/y/z` when `qform_code > 0`, else the translation column of the sform
//!   when `sform_code > 0`, else 0. Orientation (quaternion, sform rotation, axis flips) is
//!   ignored: the volume is placed axis-aligned with positive spacing.
//!
//! Samples become f32: 32/64-bit integers and doubles lose precision past f32's 24-bit mantissa,
//! which we accept because rendering works in f32; a double outside the f32 range becomes
//! infinite and is rejected like any non-finite value.
//!
//! Errors name byte offsets; in a `.nii.gz` they are offsets in the decompressed stream.

use super::encoding::{Scalar, decode, decode_values, gunzip, gunzip_head};
use super::{DataError, Storage, Values, Volume, check_finite, checked_grid_count};
use std::path::Path;

const HEADER_SIZE: usize = 348;

/// Reads and parses a `.nii` or `.nii.gz` file.
pub fn load(path: &Path) -> Result<Volume, DataError> {
    let bytes = super::read_file(path)?;
    parse(path, &bytes)
}

/// Bytes of a `.nii.gz` read to inflate its header: far more than any deflate stream needs for
/// 352 bytes of output.
const GZIP_HEAD_BYTES: u64 = 64 << 10;

/// The grid's dimensions and how its values will be kept, from the header alone (see
/// [`super::grid_shape`]); `None` where the head does not hold a whole header.
pub fn grid_shape(path: &Path) -> Result<Option<([u64; 3], Storage)>, DataError> {
    let (_, _, head) = crate::files::read_head(path, super::MAX_FILE_BYTES, GZIP_HEAD_BYTES)?;
    let (head, suffix) = if head.starts_with(&[0x1f, 0x8b]) {
        (
            gunzip_head(path, &head, 0, 352)?,
            " of the decompressed data",
        )
    } else {
        (head, "")
    };
    if head.len() < HEADER_SIZE {
        return Ok(None);
    }
    let h = header(path, &head, suffix)?;
    Ok(Some((h.dims.map(|d| d as u64), h.storage)))
}

/// Parses NIfTI-1 bytes, gzip-compressed or not; `path` only names the file in errors.
pub fn parse(path: &Path, bytes: &[u8]) -> Result<Volume, DataError> {
    if !bytes.starts_with(&[0x1f, 0x8b]) {
        return parse_plain(path, bytes, "");
    }
    // Inflate the header first, so that the header (checked against the limits) bounds how much
    // we inflate: a small corrupt or hostile file cannot make us allocate gigabytes.
    let suffix = " of the decompressed data";
    let head = gunzip_head(path, bytes, 0, 352)?;
    let limit = header(path, &head, suffix)?.data_end;
    let inflated = gunzip(path, bytes, 0, limit)?;
    parse_plain(path, &inflated, suffix)
}

/// What the header says about the data.
struct Header {
    big_endian: bool,
    dims: [usize; 3],
    ty: Scalar,
    /// How the values will be kept (`parse_plain`).
    storage: Storage,
    data_start: usize,
    data_end: u64,
}

/// Reads `N` bytes at `offset` in little-endian order (missing bytes read as 0; callers check
/// the length first, this only keeps malformed input from panicking).
fn field<const N: usize>(h: &[u8], offset: usize, big_endian: bool) -> [u8; N] {
    let mut raw = [0u8; N];
    if let Some(src) = h.get(offset..offset + N) {
        raw.copy_from_slice(src);
    }
    if big_endian {
        raw.reverse();
    }
    raw
}

fn header(path: &Path, b: &[u8], suffix: &str) -> Result<Header, DataError> {
    let format = |offset: usize, expected: &str, found: String| DataError::Format {
        path: path.to_path_buf(),
        location: format!("byte {offset}{suffix}"),
        expected: expected.into(),
        found,
    };
    let unsupported = |offset: usize, what: String| DataError::Unsupported {
        path: path.to_path_buf(),
        location: format!("byte {offset}{suffix}"),
        what,
    };
    if b.len() < 4 {
        let found = format!("{} bytes", b.len());
        return Err(format(0, "a NIfTI-1 header (sizeof_hdr = 348)", found));
    }
    let i16_at = |offset: usize, big: bool| i16::from_le_bytes(field(b, offset, big));
    let f32_at = |offset: usize, big: bool| f32::from_le_bytes(field(b, offset, big));
    let little = i32::from_le_bytes(field(b, 0, false));
    let big = i32::from_le_bytes(field(b, 0, true));
    let big_endian = match (little, big) {
        (348, _) => false,
        (_, 348) => true,
        (540, _) | (_, 540) => return Err(unsupported(0, "NIfTI-2 header".into())),
        _ => {
            let found = format!("{little} (or {big} big-endian)");
            return Err(format(0, "sizeof_hdr = 348 (a NIfTI-1 header)", found));
        }
    };
    if b.len() < HEADER_SIZE {
        return Err(DataError::Truncated {
            path: path.to_path_buf(),
            expected: HEADER_SIZE as u64,
            found: b.len() as u64,
        });
    }
    match &b[344..348] {
        b"n+1\0" => {}
        b"ni1\0" => {
            let what = "two-file NIfTI (.hdr/.img pair); convert it to a single .nii".into();
            return Err(unsupported(344, what));
        }
        other => {
            return Err(format(
                344,
                "the magic \"n+1\\0\"",
                crate::files::excerpt(other),
            ));
        }
    }

    let dim: [i16; 8] = std::array::from_fn(|i| i16_at(40 + 2 * i, big_endian));
    let rank = dim[0];
    if !(1..=7).contains(&rank) {
        return Err(format(40, "dim[0] between 1 and 7", rank.to_string()));
    }
    let extra_ok = dim[4..=(rank as usize).max(3)].iter().all(|&d| d == 1);
    if rank < 3 || !extra_ok {
        let what = format!(
            "dim = {:?}: only 3-D volumes (extra dimensions of size 1) are read",
            &dim[..=rank as usize]
        );
        return Err(unsupported(40, what));
    }
    for (i, &d) in dim[1..=3].iter().enumerate() {
        if d < 1 {
            return Err(format(
                42 + 2 * i,
                &format!("dim[{}] >= 1", i + 1),
                d.to_string(),
            ));
        }
    }
    let dims = [dim[1], dim[2], dim[3]].map(|d| d as usize);

    let code = i16_at(70, big_endian);
    let ty = match code {
        2 => Scalar::U8,
        4 => Scalar::I16,
        8 => Scalar::I32,
        16 => Scalar::F32,
        64 => Scalar::F64,
        256 => Scalar::I8,
        512 => Scalar::U16,
        768 => Scalar::U32,
        1024 => Scalar::I64,
        1280 => Scalar::U64,
        32 | 1792 | 2048 => return Err(unsupported(70, format!("complex datatype {code}"))),
        128 | 2304 => return Err(unsupported(70, format!("RGB datatype {code}"))),
        1536 => return Err(unsupported(70, "float128 datatype 1536".into())),
        _ => return Err(format(70, "a NIfTI-1 datatype code", code.to_string())),
    };

    let vox_offset = f32_at(108, big_endian);
    let whole = vox_offset.is_finite() && vox_offset.fract() == 0.0;
    if !whole || vox_offset < HEADER_SIZE as f32 {
        let expected = "vox_offset: a whole number >= 348";
        return Err(format(108, expected, vox_offset.to_string()));
    }
    let data_start = vox_offset as usize;
    // What parse_plain keeps: 8- and 16-bit data at its size unless scaled.
    let storage = if identity_scaling(f32_at(112, big_endian), f32_at(116, big_endian)) {
        ty.storage()
    } else {
        Storage::F32
    };
    let dims64 = dims.map(|d| d as u64);
    let count = checked_grid_count(path, dims64, ty.size() as u64, storage)?;
    let data_end = (data_start as u64)
        .checked_add(count as u64 * ty.size() as u64)
        .ok_or_else(|| format(108, "a vox_offset inside the file", vox_offset.to_string()))?;
    Ok(Header {
        big_endian,
        dims,
        ty,
        storage,
        data_start,
        data_end,
    })
}

/// Whether scl_slope and scl_inter leave values unchanged: a slope of 0 or not finite means "no
/// scaling" (NIfTI-1), and so does slope 1 with no finite, non-zero intercept. Such data keeps
/// its 8- or 16-bit size.
fn identity_scaling(slope: f32, inter: f32) -> bool {
    let scaled = slope.is_finite() && slope != 0.0;
    !scaled || (slope == 1.0 && (inter == 0.0 || !inter.is_finite()))
}

fn parse_plain(path: &Path, b: &[u8], suffix: &str) -> Result<Volume, DataError> {
    let h = header(path, b, suffix)?;
    let f32_at = |offset: usize| f32::from_le_bytes(field(b, offset, h.big_endian));
    let i16_at = |offset: usize| i16::from_le_bytes(field(b, offset, h.big_endian));

    let needed = h.data_end - h.data_start as u64;
    if (b.len() as u64) < h.data_end {
        return Err(DataError::Truncated {
            path: path.to_path_buf(),
            expected: needed,
            found: (b.len() as u64).saturating_sub(h.data_start as u64),
        });
    }
    let data = &b[h.data_start..h.data_end as usize];
    let slope = f32_at(112);
    let inter = f32_at(116);
    let values = if identity_scaling(slope, inter) {
        decode_values(data, h.ty, h.big_endian)
    } else {
        let mut values: Vec<f32> = decode(data, h.ty, h.big_endian, 1);
        let slope = f64::from(slope);
        let inter = if inter.is_finite() {
            f64::from(inter)
        } else {
            0.0
        };
        for v in &mut values {
            *v = (slope * f64::from(*v) + inter) as f32;
        }
        Values::F32(values)
    };
    if let Values::F32(v) = &values {
        check_finite(path, h.dims, v)?;
    }

    let spacing = [80, 84, 88].map(|offset| {
        let s = f64::from(f32_at(offset)).abs();
        if s.is_finite() && s > 0.0 { s } else { 1.0 }
    });
    let offsets = if i16_at(252) > 0 {
        Some([268, 272, 276])
    } else if i16_at(254) > 0 {
        Some([292, 308, 324])
    } else {
        None
    };
    let origin = offsets.map_or([0.0; 3], |o| o.map(|offset| f64::from(f32_at(offset))));
    if let Some(bad) = offsets.and_then(|o| o.into_iter().find(|&off| !f32_at(off).is_finite())) {
        let found = f32_at(bad).to_string();
        return Err(DataError::Format {
            path: path.to_path_buf(),
            location: format!("byte {bad}{suffix}"),
            expected: "a finite origin (qoffset or srow translation)".into(),
            found,
        });
    }
    Ok(Volume {
        dims: h.dims,
        origin,
        spacing,
        values,
    })
}
