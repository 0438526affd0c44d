//! NRRD reader (`.nrrd`, header and data in one file), plus the typed-sample helpers that the
//! VTK and NIfTI readers share (`Scalar`, `decode`, `parse_text`, `gunzip`).
//!
//! Contract: the magic line `NRRD000X`, then `field: value` lines up to the first empty line;
//! the data follows that empty line. Read fields:
//! - `type`: every NRRD spelling of the 8-, 16-, 32- and 64-bit integers, `float` and `double`
//!   (`block` is unsupported);
//! - `dimension` 3, or 4 when the first or the last axis has size 1 (that axis is dropped: a
//!   one-component axis or a single time step); anything else is unsupported;
//! - `sizes`, `endian` (required for multi-byte types unless the encoding is text);
//! - `encoding`: `raw`, `gzip`/`gz`, `ascii`/`text`/`txt`; `bzip2`/`bz2` and `hex` are
//!   unsupported;
//! - spacing per axis: the length of the `space directions` vector when present (orientation
//!   and any rotation are ignored, only the length is kept), else `|spacings|`, else 1 (a `nan`
//!   spacing or a `none` direction also gives 1, as it means "not a spatial axis"); a direction
//!   of infinite or zero length and an infinite or zero spacing are refused by line;
//! - origin: `space origin` (first three components), else `axis mins`, else 0 (cell centring
//!   is not applied to `axis mins`);
//! - `line skip` and `byte skip` (lines are skipped in the file, bytes after decompression as
//!   NRRD specifies; `byte skip: -1`, "data at the end of the file", works for raw data only).
//!
//! `data file` (detached data) is unsupported. Comments (`#`), `key:=value` pairs and fields we
//! do not use (`kinds`, `space`, `units`, ...) are ignored. Raw data beyond the needed bytes is
//! ignored; surplus values in a text encoding are an error (they signal wrong `sizes`).
//! Header errors name the header line; data errors name the byte offset in the file (for gzip,
//! the offset in the decompressed data).
//!
//! Samples become f32: 32/64-bit integers and doubles lose precision past f32's 24-bit mantissa,
//! which we accept because rendering works in f32; a double outside the f32 range becomes
//! infinite and is rejected like any non-finite value.

use super::{DataError, Storage, Values, Volume, check_finite, checked_grid_count};
use std::io::Read;
use std::path::Path;

/// Element type of stored samples, shared by the three readers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    pub(crate) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    pub(crate) fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "int8",
            Scalar::U8 => "uint8",
            Scalar::I16 => "int16",
            Scalar::U16 => "uint16",
            Scalar::I32 => "int32",
            Scalar::U32 => "uint32",
            Scalar::I64 => "int64",
            Scalar::U64 => "uint64",
            Scalar::F32 => "float32",
            Scalar::F64 => "float64",
        }
    }

    /// How a grid of this type is kept ([`decode_values`]).
    pub(crate) fn storage(self) -> Storage {
        match self {
            Scalar::U8 => Storage::U8,
            Scalar::I8 => Storage::I8,
            Scalar::U16 => Storage::U16,
            Scalar::I16 => Storage::I16,
            _ => Storage::F32,
        }
    }

    /// Inclusive value range of an integer type; `None` for floating point.
    fn int_range(self) -> Option<(i128, i128)> {
        Some(match self {
            Scalar::I8 => (i8::MIN.into(), i8::MAX.into()),
            Scalar::U8 => (0, u8::MAX.into()),
            Scalar::I16 => (i16::MIN.into(), i16::MAX.into()),
            Scalar::U16 => (0, u16::MAX.into()),
            Scalar::I32 => (i32::MIN.into(), i32::MAX.into()),
            Scalar::U32 => (0, u32::MAX.into()),
            Scalar::I64 => (i64::MIN.into(), i64::MAX.into()),
            Scalar::U64 => (0, u64::MAX.into()),
            Scalar::F32 | Scalar::F64 => return None,
        })
    }
}

/// What [`decode`] and [`parse_text`] produce: f32 samples, or f64 where a loader needs
/// coordinates and cell indices without f32 rounding. Integers arrive as i64/u64 so that each
/// conversion rounds once, exactly as a direct cast would.
pub(crate) trait Sample: Copy {
    fn from_i64(v: i64) -> Self;
    fn from_u64(v: u64) -> Self;
    fn from_f64(v: f64) -> Self;
}

impl Sample for f32 {
    fn from_i64(v: i64) -> Self {
        v as f32
    }
    fn from_u64(v: u64) -> Self {
        v as f32
    }
    fn from_f64(v: f64) -> Self {
        v as f32
    }
}

impl Sample for f64 {
    fn from_i64(v: i64) -> Self {
        v as f64
    }
    fn from_u64(v: u64) -> Self {
        v as f64
    }
    fn from_f64(v: f64) -> Self {
        v
    }
}

/// Converts packed binary samples, keeping component 0 of each `ncomp`-component tuple.
/// A partial tuple at the end is ignored: callers size `data` from the header first.
/// int32/int64/double lose precision in f32; that is accepted, the renderer works in f32.
pub(crate) fn decode<T: Sample>(data: &[u8], ty: Scalar, big_endian: bool, ncomp: usize) -> Vec<T> {
    let stride = ty.size().saturating_mul(ncomp.max(1));
    macro_rules! convert {
        ($t:ty, $via:ident, $wide:ty) => {{
            const N: usize = std::mem::size_of::<$t>();
            data.chunks_exact(stride)
                .map(|tuple| {
                    let mut raw = [0u8; N];
                    raw.copy_from_slice(&tuple[..N]);
                    let v = if big_endian {
                        <$t>::from_be_bytes(raw)
                    } else {
                        <$t>::from_le_bytes(raw)
                    };
                    T::$via(<$wide>::from(v))
                })
                .collect()
        }};
    }
    match ty {
        Scalar::I8 => convert!(i8, from_i64, i64),
        Scalar::U8 => convert!(u8, from_i64, i64),
        Scalar::I16 => convert!(i16, from_i64, i64),
        Scalar::U16 => convert!(u16, from_i64, i64),
        Scalar::I32 => convert!(i32, from_i64, i64),
        Scalar::U32 => convert!(u32, from_i64, i64),
        Scalar::I64 => convert!(i64, from_i64, i64),
        Scalar::U64 => convert!(u64, from_u64, u64),
        Scalar::F32 => convert!(f32, from_f64, f64),
        Scalar::F64 => convert!(f64, from_f64, f64),
    }
}

/// Decodes one-component binary samples for a grid: 8- and 16-bit integers stay at their size
/// (the device converts them, [`super::values`]), every other type becomes f32 as in [`decode`].
pub(crate) fn decode_values(data: &[u8], ty: Scalar, big_endian: bool) -> Values {
    macro_rules! keep {
        ($t:ty, $variant:ident) => {{
            const N: usize = std::mem::size_of::<$t>();
            Values::$variant(
                data.chunks_exact(N)
                    .map(|b| {
                        let mut raw = [0u8; N];
                        raw.copy_from_slice(b);
                        if big_endian {
                            <$t>::from_be_bytes(raw)
                        } else {
                            <$t>::from_le_bytes(raw)
                        }
                    })
                    .collect(),
            )
        }};
    }
    match ty {
        Scalar::U8 => Values::U8(data.to_vec()),
        Scalar::I8 => keep!(i8, I8),
        Scalar::U16 => keep!(u16, U16),
        Scalar::I16 => keep!(i16, I16),
        _ => Values::F32(decode(data, ty, big_endian, 1)),
    }
}

/// Parses one text sample of type `ty`; integers must be integral and within the type's range.
/// `nan`/`inf` parse for float types and are rejected later by `check_finite`, which names them.
pub(crate) fn parse_text<T: Sample>(token: &str, ty: Scalar) -> Option<T> {
    match ty.int_range() {
        Some((lo, hi)) => {
            let v = token
                .parse::<i128>()
                .ok()
                .filter(|v| (lo..=hi).contains(v))?;
            match i64::try_from(v) {
                Ok(v) => Some(T::from_i64(v)),
                Err(_) => u64::try_from(v).ok().map(T::from_u64),
            }
        }
        None if ty == Scalar::F32 => token.parse::<f32>().ok().map(|v| T::from_f64(v.into())),
        None => token.parse::<f64>().ok().map(T::from_f64),
    }
}

/// Most bytes a gzip stream may hold past what its header declares: read (and discarded) so
/// that the stream's trailer is reached and checked; more than this is refused.
const GZIP_SLACK: u64 = 1 << 16;

/// Inflates gzip data (all members), producing at most `limit` bytes so that a header cannot
/// make us inflate, or allocate, more than it needs, and checks every member's trailer (CRC-32
/// and length): a flipped byte or a stream cut short is an error naming the file, never wrong
/// values. Bytes after the last member that do not start another one are ignored, as `gzip
/// -d` does. A complete stream that holds less than `limit` yields what it held: the caller
/// compares the length with what it needs and reports `Truncated`. `offset` is where `data`
/// starts in the file, for the error message.
pub(crate) fn gunzip(
    path: &Path,
    data: &[u8],
    offset: usize,
    limit: u64,
) -> Result<Vec<u8>, DataError> {
    let err = |found: String| DataError::Format {
        path: path.to_path_buf(),
        location: format!("byte {offset}"),
        expected: "gzip-compressed data ending in its CRC-32 and length".into(),
        found,
    };
    let describe = |e: std::io::Error| {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            err("a stream that ends early (the file is cut short)".into())
        } else {
            err(e.to_string())
        }
    };
    const MAGIC: [u8; 2] = [0x1f, 0x8b];
    if !data.starts_with(&MAGIC) {
        return Err(err(crate::files::excerpt(&data[..data.len().min(8)])));
    }
    let mut input = data;
    let mut out = Vec::new();
    let mut extra = 0u64;
    while input.starts_with(&MAGIC) {
        let mut member = flate2::bufread::GzDecoder::new(input);
        let room = limit - out.len() as u64;
        (&mut member)
            .take(room)
            .read_to_end(&mut out)
            .map_err(describe)?;
        // Read the member to its end, so that its trailer is checked; what lies past the
        // declared data is counted and discarded.
        extra += std::io::copy(
            &mut (&mut member).take(GZIP_SLACK + 1 - extra),
            &mut std::io::sink(),
        )
        .map_err(describe)?;
        if extra > GZIP_SLACK {
            return Err(err(format!(
                "more than {limit} + {GZIP_SLACK} bytes, where the header declares {limit}"
            )));
        }
        input = member.into_inner();
    }
    Ok(out)
}

/// The first `limit` bytes of gzip data, without reading on to the trailer (to look at a
/// header before deciding how much to inflate; the whole stream is then read by [`gunzip`]).
pub(crate) fn gunzip_head(
    path: &Path,
    data: &[u8],
    offset: usize,
    limit: u64,
) -> Result<Vec<u8>, DataError> {
    let mut out = Vec::new();
    match flate2::read::MultiGzDecoder::new(data)
        .take(limit)
        .read_to_end(&mut out)
    {
        Ok(_) => Ok(out),
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => Ok(out),
        Err(e) => Err(DataError::Format {
            path: path.to_path_buf(),
            location: format!("byte {offset}"),
            expected: "gzip-compressed data".into(),
            found: e.to_string(),
        }),
    }
}

/// Reads and parses a `.nrrd` file.
pub fn load(path: &Path) -> Result<Volume, DataError> {
    let bytes = super::read_file(path)?;
    parse(path, &bytes)
}

#[derive(Clone, Copy, PartialEq)]
enum Encoding {
    Raw,
    Gzip,
    Text,
}

/// A header value with the line it came from.
struct At<T> {
    value: T,
    line: usize,
}

#[derive(Default)]
struct Header {
    ty: Option<At<Scalar>>,
    dimension: Option<At<usize>>,
    sizes: Option<At<Vec<u64>>>,
    encoding: Option<At<Encoding>>,
    big_endian: Option<bool>,
    spacings: Option<At<Vec<f64>>>,
    directions: Option<At<Vec<Option<f64>>>>,
    origin: Option<[f64; 3]>,
    mins: Option<At<Vec<f64>>>,
    byte_skip: Option<At<i64>>,
    line_skip: u64,
}

/// Parses NRRD bytes; `path` only names the file in errors.
pub fn parse(path: &Path, bytes: &[u8]) -> Result<Volume, DataError> {
    let err = |line: usize, expected: &str, found: String| DataError::Format {
        path: path.to_path_buf(),
        location: format!("line {line}"),
        expected: expected.into(),
        found,
    };
    let unsupported = |line: usize, what: String| DataError::Unsupported {
        path: path.to_path_buf(),
        location: format!("line {line}"),
        what,
    };

    let mut lines = Lines {
        bytes,
        pos: 0,
        number: 0,
    };
    let magic = lines.next().unwrap_or_default();
    let version_ok = magic.len() == 8 && magic[4..].iter().all(u8::is_ascii_digit);
    if !magic.starts_with(b"NRRD") || !version_ok {
        return Err(err(
            1,
            "the NRRD magic 'NRRD000X'",
            crate::files::excerpt(magic),
        ));
    }

    let mut h = Header::default();
    let mut ended = false;
    while let Some(raw) = lines.next() {
        let line = lines.number;
        if raw.is_empty() {
            ended = true;
            break;
        }
        let text = String::from_utf8_lossy(raw);
        if text.starts_with('#') {
            continue;
        }
        let Some(colon) = text.find(':') else {
            return Err(err(
                line,
                "'field: value' or a '#' comment",
                crate::files::excerpt(raw),
            ));
        };
        if text[colon + 1..].starts_with('=') {
            continue;
        }
        let field = text[..colon].trim().to_ascii_lowercase();
        let value = text[colon + 1..].trim();
        let bad = |what: &str| err(line, what, crate::files::excerpt(value.as_bytes()));
        let words: Vec<&str> = value.split_ascii_whitespace().collect();
        match field.as_str() {
            "type" => {
                let ty = type_from_name(&value.to_ascii_lowercase()).ok_or_else(|| {
                    if value.eq_ignore_ascii_case("block") {
                        unsupported(line, "type 'block'".into())
                    } else {
                        bad("an NRRD scalar type (int8 ... uint64, float, double)")
                    }
                })?;
                h.ty = Some(At { value: ty, line });
            }
            "dimension" => {
                let d = value.parse().map_err(|_| bad("a dimension count"))?;
                h.dimension = Some(At { value: d, line });
            }
            "sizes" => {
                let s = parse_all(&words, |w| w.parse::<u64>().ok())
                    .ok_or_else(|| bad("whole-number axis sizes"))?;
                h.sizes = Some(At { value: s, line });
            }
            "encoding" => {
                let e = match value.to_ascii_lowercase().as_str() {
                    "raw" => Encoding::Raw,
                    "gzip" | "gz" => Encoding::Gzip,
                    "ascii" | "text" | "txt" => Encoding::Text,
                    "bzip2" | "bz2" | "hex" => {
                        return Err(unsupported(line, format!("encoding '{value}'")));
                    }
                    _ => return Err(bad("encoding raw, gzip or ascii")),
                };
                h.encoding = Some(At { value: e, line });
            }
            "endian" => {
                h.big_endian = Some(match value.to_ascii_lowercase().as_str() {
                    "little" => false,
                    "big" => true,
                    _ => return Err(bad("endian little or big")),
                });
            }
            "spacings" => {
                let s = parse_all(&words, |w| w.parse::<f64>().ok())
                    .ok_or_else(|| bad("numeric spacings (nan for non-spatial axes)"))?;
                h.spacings = Some(At { value: s, line });
            }
            "space directions" => {
                let d = parse_directions(value).ok_or_else(|| {
                    bad("one '(x,y,z)' vector or 'none' per axis, e.g. (1,0,0) (0,1,0) (0,0,1)")
                })?;
                h.directions = Some(At { value: d, line });
            }
            "space origin" => {
                let v = parse_vector(value)
                    .filter(|v| v.iter().all(|c| c.is_finite()))
                    .ok_or_else(|| bad("a finite '(x,y,z)' vector"))?;
                h.origin = Some([0, 1, 2].map(|i| v.get(i).copied().unwrap_or(0.0)));
            }
            "axis mins" | "axismins" => {
                let m = parse_all(&words, |w| w.parse::<f64>().ok())
                    .ok_or_else(|| bad("numeric axis mins"))?;
                h.mins = Some(At { value: m, line });
            }
            "byte skip" | "byteskip" => {
                let b = value
                    .parse::<i64>()
                    .ok()
                    .filter(|&b| b >= -1)
                    .ok_or_else(|| bad("a byte count >= 0, or -1"))?;
                h.byte_skip = Some(At { value: b, line });
            }
            "line skip" | "lineskip" => {
                h.line_skip = value.parse().map_err(|_| bad("a line count >= 0"))?;
            }
            "data file" | "datafile" => {
                return Err(unsupported(line, "detached data ('data file')".into()));
            }
            _ => {}
        }
    }
    let end_line = lines.number;
    if !ended {
        return Err(err(
            end_line,
            "an empty line ending the header, then the data",
            "end of file".into(),
        ));
    }
    let missing = |field: &str| err(end_line, &format!("the '{field}' field"), "none".into());

    let ty = h.ty.as_ref().ok_or_else(|| missing("type"))?.value;
    let dimension = h.dimension.as_ref().ok_or_else(|| missing("dimension"))?;
    let sizes = h.sizes.as_ref().ok_or_else(|| missing("sizes"))?;
    let encoding = h
        .encoding
        .as_ref()
        .ok_or_else(|| missing("encoding"))?
        .value;
    let n = dimension.value;
    if sizes.value.len() != n {
        let found = format!("{} sizes", sizes.value.len());
        return Err(err(sizes.line, &format!("{n} sizes (one per axis)"), found));
    }
    let axes = match (n, sizes.value.first(), sizes.value.last()) {
        (3, _, _) => [0, 1, 2],
        (4, Some(1), _) => [1, 2, 3],
        (4, _, Some(1)) => [0, 1, 2],
        _ => {
            let what = format!(
                "dimension {n} with sizes {:?} (need 3 axes, or 4 with a first or last axis of size 1)",
                sizes.value
            );
            return Err(unsupported(dimension.line, what));
        }
    };
    let dims = axes.map(|a| sizes.value[a]);
    // Text is parsed to f32; binary 8- and 16-bit data stays at its size.
    let storage = match encoding {
        Encoding::Text => Storage::F32,
        _ => ty.storage(),
    };
    let count = checked_grid_count(path, dims, ty.size() as u64, storage)?;
    let big_endian = match (h.big_endian, ty.size(), encoding) {
        (Some(b), _, _) => b,
        (None, 1, _) | (None, _, Encoding::Text) => false,
        (None, _, _) => return Err(missing("endian")),
    };

    let per_axis = |field: &Option<At<Vec<f64>>>, what: &str| -> Result<_, DataError> {
        match field {
            None => Ok(None),
            Some(f) if f.value.len() == n => Ok(Some(axes.map(|a| f.value[a]))),
            Some(f) => Err(err(
                f.line,
                &format!("{n} {what} (one per axis)"),
                format!("{}", f.value.len()),
            )),
        }
    };
    let spacings = per_axis(&h.spacings, "spacings")?;
    let mins = per_axis(&h.mins, "axis mins")?;
    let lengths = match &h.directions {
        None => None,
        Some(d) if d.value.len() == n => Some(axes.map(|a| d.value[a])),
        Some(d) => {
            let found = format!("{} entries", d.value.len());
            return Err(err(
                d.line,
                &format!("{n} space directions (one per axis)"),
                found,
            ));
        }
    };
    let usable = |s: f64| s.is_finite() && s > 0.0;
    // A direction or spacing that is given must be usable: `inf` or a zero vector silently
    // becoming 1 would misplace every sample. `nan` spacings mark non-spatial axes (NRRD).
    for a in 0..3 {
        if let (Some(l), Some(d)) = (lengths.and_then(|l| l[a]), h.directions.as_ref())
            && !usable(l)
        {
            let found = format!("a vector of length {l} for axis {a}");
            return Err(err(
                d.line,
                "space direction vectors of finite, non-zero length",
                found,
            ));
        }
        if let (Some(s), Some(at)) = (spacings.map(|s| s[a]), h.spacings.as_ref())
            && !s.is_nan()
            && !usable(s.abs())
        {
            let found = format!("{s} for axis {a}");
            return Err(err(
                at.line,
                "finite, non-zero spacings (nan for a non-spatial axis)",
                found,
            ));
        }
    }
    let spacing = [0, 1, 2].map(|a| {
        let from_direction = lengths.and_then(|l| l[a]);
        let from_spacings = spacings.map(|s| s[a].abs()).filter(|&s| usable(s));
        from_direction.or(from_spacings).unwrap_or(1.0)
    });
    let origin = h.origin.unwrap_or_else(|| {
        mins.map_or([0.0; 3], |m| m.map(|v| if v.is_finite() { v } else { 0.0 }))
    });

    // Data: `line skip` counts lines of the file, `byte skip` bytes of the decoded stream.
    for _ in 0..h.line_skip {
        if lines.next().is_none() {
            let found = "end of file".into();
            let expected = format!("{} lines to skip", h.line_skip);
            return Err(err(lines.number, &expected, found));
        }
    }
    let start = lines.pos;
    let needed = count as u64 * ty.size() as u64;
    let skip = h.byte_skip.as_ref().map_or(0, |b| b.value);
    let values = match encoding {
        Encoding::Raw => {
            let avail = (bytes.len() - start) as u64;
            let skip = if skip == -1 {
                avail.saturating_sub(needed)
            } else {
                skip as u64
            };
            let found = avail.saturating_sub(skip);
            if found < needed {
                return Err(truncated(path, needed, found));
            }
            let from = start + skip as usize;
            decode_values(&bytes[from..from + needed as usize], ty, big_endian)
        }
        Encoding::Gzip => {
            if let Some(b) = h.byte_skip.as_ref().filter(|b| b.value == -1) {
                let what = "'byte skip: -1' with gzip encoding".into();
                return Err(unsupported(b.line, what));
            }
            let inflated = gunzip(path, &bytes[start..], start, skip as u64 + needed)?;
            let found = (inflated.len() as u64).saturating_sub(skip as u64);
            if found < needed {
                return Err(truncated(path, needed, found));
            }
            let end = (skip as u64 + needed) as usize;
            decode_values(&inflated[skip as usize..end], ty, big_endian)
        }
        Encoding::Text => {
            if let Some(b) = h.byte_skip.as_ref().filter(|b| b.value == -1) {
                let what = "'byte skip: -1' with a text encoding".into();
                return Err(unsupported(b.line, what));
            }
            let from = start.saturating_add(skip as usize).min(bytes.len());
            Values::F32(parse_text_values(path, bytes, from, ty, count)?)
        }
    };
    if let Values::F32(v) = &values {
        check_finite(path, dims.map(|d| d as usize), v)?;
    }
    Ok(Volume {
        dims: dims.map(|d| d as usize),
        origin,
        spacing,
        values,
    })
}

fn truncated(path: &Path, expected: u64, found: u64) -> DataError {
    DataError::Truncated {
        path: path.to_path_buf(),
        expected,
        found,
    }
}

/// Reads exactly `count` whitespace-separated values starting at `from`.
fn parse_text_values(
    path: &Path,
    bytes: &[u8],
    from: usize,
    ty: Scalar,
    count: usize,
) -> Result<Vec<f32>, DataError> {
    let line_of = |at: usize| 1 + bytes[..at].iter().filter(|&&b| b == b'\n').count();
    let err = |at: usize, expected: String, found: &[u8]| DataError::Format {
        path: path.to_path_buf(),
        location: format!("line {}", line_of(at)),
        expected,
        found: crate::files::excerpt(found),
    };
    // Each value takes at least two bytes (digit and separator), which bounds the allocation
    // by the file size rather than by the header.
    let mut values = Vec::with_capacity(count.min((bytes.len() - from) / 2 + 1));
    let mut tokens = Tokens { bytes, pos: from };
    while values.len() < count {
        let Some((at, token)) = tokens.next() else {
            return Err(truncated(path, count as u64, values.len() as u64));
        };
        let value = std::str::from_utf8(token)
            .ok()
            .and_then(|t| parse_text(t, ty))
            .ok_or_else(|| {
                let n = values.len() + 1;
                err(
                    at,
                    format!("a {} value (value {n} of {count})", ty.name()),
                    token,
                )
            })?;
        values.push(value);
    }
    if let Some((at, token)) = tokens.next() {
        return Err(err(at, format!("end of data after {count} values"), token));
    }
    Ok(values)
}

/// Lines of the header, without their `\n` or `\r\n`; `number` is the 1-based number of the
/// line last returned and `pos` the offset just after it.
struct Lines<'a> {
    bytes: &'a [u8],
    pos: usize,
    number: usize,
}

impl<'a> Iterator for Lines<'a> {
    type Item = &'a [u8];

    fn next(&mut self) -> Option<&'a [u8]> {
        let rest = self.bytes.get(self.pos..).filter(|r| !r.is_empty())?;
        let len = rest.iter().position(|&b| b == b'\n');
        self.pos += len.map_or(rest.len(), |n| n + 1);
        self.number += 1;
        let line = &rest[..len.unwrap_or(rest.len())];
        Some(line.strip_suffix(b"\r").unwrap_or(line))
    }
}

/// Whitespace-separated tokens of a byte slice, with their offsets.
struct Tokens<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Iterator for Tokens<'a> {
    type Item = (usize, &'a [u8]);

    fn next(&mut self) -> Option<Self::Item> {
        let rest = self.bytes.get(self.pos..)?;
        let start = self.pos + rest.iter().position(|b| !b.is_ascii_whitespace())?;
        let tail = &self.bytes[start..];
        let len = tail
            .iter()
            .position(u8::is_ascii_whitespace)
            .unwrap_or(tail.len());
        self.pos = start + len;
        Some((start, &tail[..len]))
    }
}

fn parse_all<T>(words: &[&str], f: impl Fn(&str) -> Option<T>) -> Option<Vec<T>> {
    words.iter().map(|w| f(w)).collect()
}

fn type_from_name(name: &str) -> Option<Scalar> {
    let words: Vec<&str> = name.split_ascii_whitespace().collect();
    Some(match words.join(" ").as_str() {
        "signed char" | "int8" | "int8_t" => Scalar::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => Scalar::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            Scalar::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => Scalar::U16,
        "int" | "signed int" | "int32" | "int32_t" => Scalar::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => Scalar::U32,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t" => Scalar::I64,
        "ulonglong" | "unsigned long long" | "unsigned long long int" | "uint64" | "uint64_t" => {
            Scalar::U64
        }
        "float" => Scalar::F32,
        "double" => Scalar::F64,
        _ => return None,
    })
}

/// Parses `(a,b,c)` into its components.
fn parse_vector(text: &str) -> Option<Vec<f64>> {
    let inner = text.trim().strip_prefix('(')?.strip_suffix(')')?;
    inner.split(',').map(|c| c.trim().parse().ok()).collect()
}

/// Parses the `space directions` value into the length of each vector (`None` for `none`).
fn parse_directions(text: &str) -> Option<Vec<Option<f64>>> {
    let mut out = Vec::new();
    let mut rest = text.trim_start();
    while !rest.is_empty() {
        if rest.starts_with('(') {
            let close = rest.find(')')?;
            let v = parse_vector(&rest[..=close])?;
            out.push(Some(v.iter().map(|c| c * c).sum::<f64>().sqrt()));
            rest = &rest[close + 1..];
        } else {
            let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
            if !rest[..end].eq_ignore_ascii_case("none") {
                return None;
            }
            out.push(None);
            rest = &rest[end..];
        }
        rest = rest.trim_start();
    }
    Some(out)
}
