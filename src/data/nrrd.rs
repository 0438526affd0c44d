//! NRRD reader (`.nrrd`, header and data in one file); the typed-sample and gzip helpers it
//! shares with the VTK and NIfTI readers are in [`super::encoding`].
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
//! Binary 8- and 16-bit samples are kept at their size ([`super::values`]); every other type
//! becomes f32 ([`super::encoding`]). Raw data past the first MiB is streamed from the file.

use super::encoding::{Scalar, decode_values, gunzip, parse_text};
use super::{DataError, Storage, Values, Volume, check_finite, checked_grid_count};
use std::io::Read;
use std::path::Path;

/// Bytes read first: enough for any header we expect (comments included). A header longer than
/// this is parsed from the whole file instead.
const HEAD_BYTES: usize = 1 << 20;

/// Bytes of raw data read and decoded at a time.
const CHUNK_BYTES: usize = 8 << 20;

/// Reads and parses a `.nrrd` file. Raw data is streamed from the file into the values, so the
/// host never holds the file's payload and the values at once (issue 25 §4: a 512³ 16-bit CT
/// peaks at its size, not twice it); gzip and text are read whole.
pub fn load(path: &Path) -> Result<Volume, DataError> {
    let (file, size, head) =
        crate::files::read_head(path, super::MAX_FILE_BYTES, HEAD_BYTES as u64)?;
    if head.len() as u64 == size {
        return parse(path, &head);
    }
    match layout(path, &head) {
        // The header and its skipped lines must end inside the head: a line cut at the head's
        // end (a `line skip` line, or "\r" of a blank "\r\n") would misplace the data.
        Ok(l) if l.encoding == Encoding::Raw && l.start < head.len() => {
            stream_raw(path, file, size, &l)
        }
        // gzip, text, or a header the head does not hold (its error, if any, is the whole
        // file's): read whole.
        _ => {
            drop(file);
            parse(path, &super::read_file(path)?)
        }
    }
}

/// The grid's dimensions and how its values will be kept, from the header alone (at most
/// [`HEAD_BYTES`] read): lets the caller check the device before the payload is read. `None`
/// when the head does not hold the whole header.
pub fn grid_shape(path: &Path) -> Result<Option<([u64; 3], Storage)>, DataError> {
    let (_, _, head) = crate::files::read_head(path, super::MAX_FILE_BYTES, HEAD_BYTES as u64)?;
    Ok(layout(path, &head)
        .ok()
        .filter(|l| l.start < head.len())
        .map(|l| (l.dims, l.storage())))
}

/// Reads the raw payload described by `l` from `file` (of `size` bytes, its first bytes the
/// header) chunk by chunk, decoding as it goes.
fn stream_raw(
    path: &Path,
    mut file: std::fs::File,
    size: u64,
    l: &Layout,
) -> Result<Volume, DataError> {
    use std::io::{Seek, SeekFrom};
    let io = |source| {
        DataError::File(crate::files::FileError::Io {
            path: path.to_path_buf(),
            action: "read",
            source,
        })
    };
    let needed = l.count as u64 * l.ty.size() as u64;
    let avail = size - l.start as u64;
    let skip = match l.byte_skip {
        Some((-1, _)) => avail.saturating_sub(needed),
        Some((s, _)) => s as u64,
        None => 0,
    };
    let found = avail.saturating_sub(skip);
    if found < needed {
        return Err(truncated(path, needed, found));
    }
    file.seek(SeekFrom::Start(l.start as u64 + skip))
        .map_err(io)?;
    let mut values = Values::with_capacity(l.storage(), l.count);
    let chunk = CHUNK_BYTES / l.ty.size() * l.ty.size();
    let mut buf = vec![0u8; chunk];
    let mut left = needed as usize;
    while left > 0 {
        let n = left.min(chunk);
        file.read_exact(&mut buf[..n]).map_err(|e| match e.kind() {
            // The file shrank after its size was read.
            std::io::ErrorKind::UnexpectedEof => truncated(path, needed, needed - left as u64),
            _ => io(e),
        })?;
        values.append(decode_values(&buf[..n], l.ty, l.big_endian));
        left -= n;
    }
    l.volume(path, values)
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

/// What a header says: the grid, the type and encoding, and where the data starts.
struct Layout {
    dims: [u64; 3],
    origin: [f64; 3],
    spacing: [f64; 3],
    ty: Scalar,
    big_endian: bool,
    encoding: Encoding,
    /// Offset of the data: after the header and its `line skip` lines.
    start: usize,
    /// Samples: dims[0]·dims[1]·dims[2].
    count: usize,
    /// `byte skip` and its line.
    byte_skip: Option<(i64, usize)>,
}

impl Layout {
    /// How the values are kept: text is parsed to f32, binary 8- and 16-bit data stays at its
    /// size.
    fn storage(&self) -> Storage {
        kept_as(self.encoding, self.ty)
    }

    /// The volume of `values` decoded from this layout's data, finite values checked.
    fn volume(&self, path: &Path, values: Values) -> Result<Volume, DataError> {
        let dims = self.dims.map(|d| d as usize);
        if let Values::F32(v) = &values {
            check_finite(path, dims, v)?;
        }
        Ok(Volume {
            dims,
            origin: self.origin,
            spacing: self.spacing,
            values,
        })
    }
}

/// How values of type `ty` in `encoding` are kept: text is parsed to f32, binary 8- and 16-bit
/// data stays at its size.
fn kept_as(encoding: Encoding, ty: Scalar) -> Storage {
    match encoding {
        Encoding::Text => Storage::F32,
        _ => ty.storage(),
    }
}

/// Parses NRRD bytes; `path` only names the file in errors.
pub fn parse(path: &Path, bytes: &[u8]) -> Result<Volume, DataError> {
    let l = layout(path, bytes)?;
    let unsupported = |line: usize, what: String| DataError::Unsupported {
        path: path.to_path_buf(),
        location: format!("line {line}"),
        what,
    };
    let (ty, big_endian, start, count) = (l.ty, l.big_endian, l.start, l.count);
    let needed = count as u64 * ty.size() as u64;
    let skip = l.byte_skip.map_or(0, |b| b.0);
    let values = match l.encoding {
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
            if let Some((_, line)) = l.byte_skip.filter(|b| b.0 == -1) {
                let what = "'byte skip: -1' with gzip encoding".into();
                return Err(unsupported(line, what));
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
            if let Some((_, line)) = l.byte_skip.filter(|b| b.0 == -1) {
                let what = "'byte skip: -1' with a text encoding".into();
                return Err(unsupported(line, what));
            }
            let from = start.saturating_add(skip as usize).min(bytes.len());
            Values::F32(parse_text_values(path, bytes, from, ty, count)?)
        }
    };
    l.volume(path, values)
}

/// Parses the header at the start of `bytes` (the whole file, or a head of it holding the
/// header and its `line skip` lines) and checks the grid it declares against the host's memory.
fn layout(path: &Path, bytes: &[u8]) -> Result<Layout, DataError> {
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
    let count = checked_grid_count(path, dims, ty.size() as u64, kept_as(encoding, ty))?;
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
    Ok(Layout {
        dims,
        origin,
        spacing,
        ty,
        big_endian,
        encoding,
        start: lines.pos,
        count,
        byte_skip: h.byte_skip.as_ref().map(|b| (b.value, b.line)),
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
