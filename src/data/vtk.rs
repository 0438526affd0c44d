//! VTK legacy reader (`.vtk`, file versions up to 5.1 as written by VTK 9 and ParaView; like VTK,
//! the version number is not enforced), ASCII or BINARY (big-endian). This module holds the
//! volume API ([`load`], [`parse`]: `DATASET STRUCTURED_POINTS` as a [`Volume`]) and the
//! tokenizer, number decoding and attribute parsing shared with `vtk_legacy.rs`, whose
//! [`super::vtk_legacy::load_dataset`] reads every dataset type vmls renders as a `Dataset`.
//!
//! Contract and choices of the volume API:
//! - geometry: `DIMENSIONS`, `SPACING` (or its old name `ASPECT_RATIO`, each > 0, default 1),
//!   `ORIGIN` (default 0); a dataset-level `FIELD` block (e.g. `TIME`) is skipped;
//! - other dataset types (`STRUCTURED_GRID`, `RECTILINEAR_GRID`, `UNSTRUCTURED_GRID`,
//!   `POLYDATA`, ...) are not volumes: [`load`] reports them as unsupported (use
//!   [`super::vtk_legacy::load_dataset`]); data-object files (no `DATASET`) are unsupported by both;
//! - selectable point-data arrays are `SCALARS` (the `LOOKUP_TABLE` line may be absent),
//!   `COLOR_SCALARS` and the arrays of a `FIELD` block. `array = None` takes the first of them,
//!   a name takes the array of that name (`%XX` escapes in names are decoded, as VTK does);
//! - multi-component arrays give their first component. `COLOR_SCALARS` give their first
//!   component (red, not luminance) in [0, 1]: ASCII files store floats in [0, 1], BINARY files
//!   bytes, which are divided by 255 so both forms give the same volume;
//! - `VECTORS`, `NORMALS`, `TENSORS`, `TEXTURE_COORDINATES`, ids, lookup tables, cell data
//!   (`CELL_DATA`, before or after the point data) and the VTK 5.1 `METADATA` blocks are parsed
//!   past and never selected;
//! - types: `bit`, `char` (signed), `signed_char`, `unsigned_char`, `short`, `unsigned_short`,
//!   `int`, `unsigned_int`, `long`/`unsigned_long` (8 bytes in BINARY files, as written by VTK
//!   on LP64 systems), `vtkIdType` (4 bytes in BINARY files: VTK writes ids as int),
//!   `vtktype{int,uint}{8,16,32,64}`, `vtktypefloat32/64`, `float`, `double`; string and
//!   variant arrays are unsupported because their layout cannot be skipped cheaply;
//! - BINARY data is read by byte offset right after the header line that precedes it; ASCII
//!   values are whitespace-separated tokens and may wrap across lines;
//! - the chosen array must hold exactly one tuple per point (`POINT_DATA n` must equal the
//!   product of `DIMENSIONS`); missing values give `Truncated` (or a format error at the token
//!   where a keyword was found instead of a value), surplus values a format error at the line
//!   after the array. The file past the chosen array is not otherwise validated.
//!
//! Samples become f32: 32/64-bit integers and doubles lose precision past f32's 24-bit mantissa,
//! which we accept because rendering works in f32; a double outside the f32 range becomes
//! infinite and is rejected like any non-finite value.
//!
//! Errors name "line N"; in BINARY files they also give the byte offset, since binary data makes
//! line numbers hard to follow.

use super::dataset::{DataArray, Location};
use super::encoding::{Sample, Scalar, decode, decode_values, parse_text};
use super::{DataError, Volume, check_finite, checked_sample_count};
use super::{Storage, Values};
use std::path::Path;

/// Reads and parses a legacy `.vtk` file; see the module documentation for `array`.
pub fn load(path: &Path, array: Option<&str>) -> Result<Volume, DataError> {
    let bytes = super::read_file(path)?;
    parse(path, &bytes, array)
}

/// Every keyword that may start a line after the geometry; used to recognise surplus values.
const KEYWORDS: &str = "POINT_DATA CELL_DATA SCALARS COLOR_SCALARS LOOKUP_TABLE VECTORS NORMALS \
                        TEXTURE_COORDINATES TENSORS TENSORS6 GLOBAL_IDS PEDIGREE_IDS EDGE_FLAGS \
                        FIELD METADATA";

#[derive(Clone, Copy, PartialEq)]
pub(super) enum Elem {
    Num(Scalar),
    Bit,
    /// Strings (`string`, `utf8_string`, `unicode_string`): read past, never rendered.
    Str,
}

/// A non-blank line split into whitespace-separated tokens.
pub(super) struct Line {
    pub(super) start: usize,
    pub(super) tokens: Vec<String>,
}

impl Line {
    pub(super) fn keyword(&self) -> String {
        self.tokens
            .first()
            .map(|t| t.to_ascii_uppercase())
            .unwrap_or_default()
    }
}

/// Where the point data stands while sections are parsed.
#[derive(Clone, Copy, PartialEq)]
enum Section {
    Geometry,
    Point(u64),
    Cell(u64),
}

pub(super) struct Reader<'a> {
    pub(super) path: &'a Path,
    pub(super) bytes: &'a [u8],
    pub(super) pos: usize,
    pub(super) binary: bool,
}

impl<'a> Reader<'a> {
    pub(super) fn location(&self, at: usize) -> String {
        let at = at.min(self.bytes.len());
        let line = 1 + self.bytes[..at].iter().filter(|&&b| b == b'\n').count();
        if self.binary {
            format!("line {line} (byte {at})")
        } else {
            format!("line {line}")
        }
    }

    pub(super) fn format(
        &self,
        at: usize,
        expected: impl Into<String>,
        found: impl Into<String>,
    ) -> DataError {
        DataError::Format {
            path: self.path.to_path_buf(),
            location: self.location(at),
            expected: expected.into(),
            found: found.into(),
        }
    }

    /// A format error at `line` (or at the end of the input), quoting what was found.
    pub(super) fn unexpected(&self, line: Option<&Line>, expected: impl Into<String>) -> DataError {
        match line {
            Some(l) => self.format(
                l.start,
                expected,
                crate::files::excerpt(l.tokens.join(" ").as_bytes()),
            ),
            None => self.format(self.bytes.len(), expected, "end of file"),
        }
    }

    pub(super) fn unsupported(&self, at: usize, what: impl Into<String>) -> DataError {
        DataError::Unsupported {
            path: self.path.to_path_buf(),
            location: self.location(at),
            what: what.into(),
        }
    }

    /// The next line without its terminator, and its offset; `None` at the end of the input.
    fn raw_line(&mut self) -> Option<(usize, &'a [u8])> {
        let start = self.pos;
        let rest = self.bytes.get(start..).filter(|r| !r.is_empty())?;
        let len = rest.iter().position(|&b| b == b'\n');
        self.pos += len.map_or(rest.len(), |n| n + 1);
        let line = &rest[..len.unwrap_or(rest.len())];
        Some((start, line.strip_suffix(b"\r").unwrap_or(line)))
    }

    /// The next line that is not blank.
    pub(super) fn line(&mut self) -> Option<Line> {
        while let Some((start, raw)) = self.raw_line() {
            let tokens: Vec<String> = String::from_utf8_lossy(raw)
                .split_ascii_whitespace()
                .map(str::to_owned)
                .collect();
            if !tokens.is_empty() {
                return Some(Line { start, tokens });
            }
        }
        None
    }

    pub(super) fn peek_line(&mut self) -> Option<Line> {
        let saved = self.pos;
        let line = self.line();
        self.pos = saved;
        line
    }

    /// The next whitespace-separated token of ASCII data.
    fn token(&mut self) -> Option<(usize, &'a [u8])> {
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

    /// Checks that `line` has exactly `n` tokens.
    pub(super) fn expect_tokens(&self, line: &Line, n: usize, form: &str) -> Result<(), DataError> {
        if line.tokens.len() == n {
            Ok(())
        } else {
            Err(self.unexpected(Some(line), format!("'{form}'")))
        }
    }

    pub(super) fn number<T: std::str::FromStr>(
        &self,
        line: &Line,
        i: usize,
        what: &str,
    ) -> Result<T, DataError> {
        let token = line.tokens.get(i).map_or("", String::as_str);
        token
            .parse()
            .map_err(|_| self.format(line.start, what, format!("'{token}'")))
    }

    pub(super) fn vec3(
        &self,
        line: &Line,
        what: &str,
        ok: impl Fn(f64) -> bool,
    ) -> Result<[f64; 3], DataError> {
        self.expect_tokens(line, 4, &format!("{} x y z", line.keyword()))?;
        let mut v = [0.0; 3];
        for (a, value) in v.iter_mut().enumerate() {
            *value = self.number::<f64>(line, a + 1, what)?;
            if !ok(*value) {
                return Err(self.format(line.start, what, line.tokens[a + 1].clone()));
            }
        }
        Ok(v)
    }

    pub(super) fn elem(&self, line: &Line, name: &str) -> Result<Elem, DataError> {
        let ty = match name.to_ascii_lowercase().as_str() {
            "bit" => return Ok(Elem::Bit),
            "char" | "signed_char" | "vtktypeint8" => Scalar::I8,
            "unsigned_char" | "vtktypeuint8" => Scalar::U8,
            "short" | "vtktypeint16" => Scalar::I16,
            "unsigned_short" | "vtktypeuint16" => Scalar::U16,
            "int" | "vtkidtype" | "vtktypeint32" => Scalar::I32,
            "unsigned_int" | "vtktypeuint32" => Scalar::U32,
            "long" | "vtktypeint64" => Scalar::I64,
            "unsigned_long" | "vtktypeuint64" => Scalar::U64,
            "float" | "vtktypefloat32" => Scalar::F32,
            "double" | "vtktypefloat64" => Scalar::F64,
            "string" | "utf8_string" | "unicode_string" => return Ok(Elem::Str),
            "variant" => {
                return Err(self.unsupported(line.start, format!("{name} array")));
            }
            _ => {
                let expected = "a VTK data type (unsigned_char, char, short, unsigned_short, \
                                int, unsigned_int, long, unsigned_long, float, double, bit, \
                                vtktypeint8 ... vtktypefloat64)";
                return Err(self.format(line.start, expected, format!("'{name}'")));
            }
        };
        Ok(Elem::Num(ty))
    }

    /// [`Reader::elem`] for geometry and cell arrays, which must be numbers: strings are
    /// unsupported there (they are read past only as data arrays).
    pub(super) fn numeric_elem(&self, line: &Line, name: &str) -> Result<Elem, DataError> {
        match self.elem(line, name)? {
            Elem::Str => Err(self.unsupported(
                line.start,
                format!("{name} {} (expected numbers)", line.keyword()),
            )),
            elem => Ok(elem),
        }
    }

    /// The next `nbytes` binary bytes, or `Truncated`.
    fn take(&mut self, nbytes: u64) -> Result<&'a [u8], DataError> {
        let avail = (self.bytes.len() - self.pos) as u64;
        if nbytes > avail {
            return Err(DataError::Truncated {
                path: self.path.to_path_buf(),
                expected: nbytes,
                found: avail,
            });
        }
        let data = &self.bytes[self.pos..self.pos + nbytes as usize];
        self.pos += nbytes as usize;
        Ok(data)
    }

    /// [`Reader::array`] of scalars: one-component binary 8- and 16-bit integers keep their
    /// size ([`super::values`]); everything else becomes f32.
    fn scalars(&mut self, elem: Elem, ncomp: u64, ntuples: u64) -> Result<Values, DataError> {
        match elem {
            Elem::Num(t) if self.binary && ncomp == 1 && t.storage() != Storage::F32 => {
                let nbytes = ntuples.checked_mul(t.size() as u64).ok_or_else(|| {
                    let found = format!("{ntuples} values");
                    self.format(self.pos, "a byte count that fits 64 bits", found)
                })?;
                // Legacy binary data is big-endian.
                Ok(decode_values(self.take(nbytes)?, t, true))
            }
            _ => Ok(self.array::<f32>(elem, ncomp, ntuples, true)?.into()),
        }
    }

    /// Reads `ntuples` tuples of `ncomp` values; with `keep`, returns component 0 of each.
    pub(super) fn array<T: Sample>(
        &mut self,
        elem: Elem,
        ncomp: u64,
        ntuples: u64,
        keep: bool,
    ) -> Result<Vec<T>, DataError> {
        let total = ncomp.checked_mul(ntuples).ok_or_else(|| {
            self.format(
                self.pos,
                "a value count that fits 64 bits",
                format!("{ntuples}×{ncomp}"),
            )
        })?;
        if elem == Elem::Str {
            self.skip_strings(total)?;
            return Ok(Vec::new());
        }
        if self.binary {
            let nbytes = match elem {
                Elem::Num(t) => total.checked_mul(t.size() as u64),
                Elem::Bit | Elem::Str => Some(total.div_ceil(8)),
            };
            let nbytes = nbytes.ok_or_else(|| {
                self.format(
                    self.pos,
                    "a byte count that fits 64 bits",
                    format!("{total} values"),
                )
            })?;
            let data = self.take(nbytes)?;
            return Ok(match (keep, elem) {
                (false, _) => Vec::new(),
                (true, Elem::Num(t)) => decode(data, t, true, ncomp as usize),
                (true, Elem::Bit | Elem::Str) => (0..ntuples)
                    .map(|i| {
                        let bit = i * ncomp;
                        let byte = data.get((bit / 8) as usize).copied().unwrap_or(0);
                        T::from_i64(i64::from((byte >> (7 - bit % 8)) & 1))
                    })
                    .collect(),
            });
        }
        let capacity = if keep {
            ntuples.min((self.bytes.len() - self.pos) as u64 / 2 + 1)
        } else {
            0
        };
        let mut out = Vec::with_capacity(capacity as usize);
        for i in 0..total {
            let Some((at, token)) = self.token() else {
                return Err(DataError::Truncated {
                    path: self.path.to_path_buf(),
                    expected: total,
                    found: i,
                });
            };
            let text = std::str::from_utf8(token).unwrap_or("");
            let value = match elem {
                Elem::Num(t) if keep && i % ncomp == 0 => parse_text(text, t),
                Elem::Bit if keep && i % ncomp == 0 => match text {
                    "0" => Some(T::from_i64(0)),
                    "1" => Some(T::from_i64(1)),
                    _ => None,
                },
                _ => text.parse::<f64>().ok().map(T::from_f64),
            };
            match value {
                Some(v) if keep && i % ncomp == 0 => out.push(v),
                Some(_) => {}
                None => {
                    let ty = match elem {
                        Elem::Num(t) => t.name(),
                        Elem::Bit => "bit",
                        Elem::Str => "string",
                    };
                    let expected = format!("a {ty} value (value {} of {total})", i + 1);
                    return Err(self.format(at, expected, crate::files::excerpt(token)));
                }
            }
        }
        Ok(out)
    }

    /// Skips `total` strings as VTK writes them: in ASCII one per line (percent-encoded, so
    /// an empty line is an empty string); in binary each after a big-endian length whose first
    /// byte's top two bits give its size (11: 6 bits in that byte, 10: 14 bits in two bytes,
    /// 01: 30 bits in four, 00: 62 bits in eight).
    fn skip_strings(&mut self, total: u64) -> Result<(), DataError> {
        let truncated = |found: u64| DataError::Truncated {
            path: self.path.to_path_buf(),
            expected: total,
            found,
        };
        if !self.binary {
            for i in 0..total {
                self.raw_line().ok_or_else(|| truncated(i))?;
            }
            return Ok(());
        }
        for i in 0..total {
            let first = *self.bytes.get(self.pos).ok_or_else(|| truncated(i))?;
            let size = match first >> 6 {
                3 => 1,
                2 => 2,
                1 => 4,
                _ => 8,
            };
            let head = self
                .bytes
                .get(self.pos..self.pos + size)
                .ok_or_else(|| truncated(i))?;
            let len = head[1..]
                .iter()
                .fold(u64::from(first & 0x3f), |acc, &b| (acc << 8) | u64::from(b));
            let end = (self.pos + size) as u64 + len;
            if end > self.bytes.len() as u64 {
                return Err(truncated(i));
            }
            self.pos = end as usize;
        }
        Ok(())
    }

    /// Skips a VTK 5.1 `METADATA` block (ended by an empty line) if one follows.
    pub(super) fn skip_metadata(&mut self) {
        if self.peek_line().is_some_and(|l| l.keyword() == "METADATA") {
            self.line();
            while let Some((_, raw)) = self.raw_line() {
                if raw.iter().all(u8::is_ascii_whitespace) {
                    break;
                }
            }
        }
    }

    /// After the chosen array, the file must go on with a keyword (or, inside a FIELD block with
    /// arrays left, an array header): anything else means more values than points.
    fn check_follows(&mut self, field_arrays_left: u64, values: u64) -> Result<(), DataError> {
        let Some(next) = self.peek_line() else {
            return Ok(());
        };
        let t = &next.tokens;
        let ok = if field_arrays_left > 0 {
            t[0] == "NULL_ARRAY"
                || (t.len() == 4 && t[1].parse::<u64>().is_ok() && t[2].parse::<u64>().is_ok())
        } else {
            KEYWORDS
                .split_ascii_whitespace()
                .any(|k| k == next.keyword())
        };
        if ok {
            return Ok(());
        }
        let expected =
            format!("a keyword or the end of the file after the array's {values} values");
        let found = match self.binary {
            true => crate::files::excerpt(self.bytes.get(next.start..).unwrap_or_default()),
            false => crate::files::excerpt(t.join(" ").as_bytes()),
        };
        Err(self.format(next.start, expected, found))
    }
}

/// Decodes VTK's `%XX` escapes in array names.
fn decode_name(name: &str) -> String {
    let b = name.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = b
            .get(i + 1..i + 3)
            .and_then(|h| std::str::from_utf8(h).ok());
        match hex.and_then(|h| u8::from_str_radix(h, 16).ok()) {
            Some(byte) if b[i] == b'%' => {
                out.push(byte);
                i += 3;
            }
            _ => {
                out.push(b[i]);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// One array about to be read.
struct Candidate {
    name: String,
    elem: Elem,
    ncomp: u64,
    ntuples: u64,
    /// COLOR_SCALARS in a BINARY file: bytes to scale by 1/255.
    scale_bytes: bool,
    /// A scalar array (SCALARS, COLOR_SCALARS or a FIELD array) rather than vectors, normals,
    /// lookup tables and the like.
    scalar: bool,
}

/// Which arrays the attribute parser keeps.
#[derive(Clone, Copy)]
pub(super) enum Pick<'w> {
    /// The volume API: the first scalar point array (or the one of that name); parsing stops
    /// there.
    One(Option<&'w str>),
    /// Every scalar array of the point data, and of the cell data when `cells`.
    All { cells: bool },
}

/// The arrays kept so far.
pub(super) struct Sink<'w> {
    pub(super) pick: Pick<'w>,
    /// Names of the scalar point arrays passed, for [`DataError::NoSuchArray`].
    pub(super) seen: Vec<String>,
    pub(super) kept: Vec<DataArray>,
}

impl<'w> Sink<'w> {
    pub(super) fn new(pick: Pick<'w>) -> Self {
        Self {
            pick,
            seen: Vec::new(),
            kept: Vec::new(),
        }
    }
}

/// Reads the four header lines (magic, title, ASCII/BINARY, `DATASET type`) and returns the
/// reader positioned after them, with the dataset type in upper case and its line's offset.
pub(super) fn open<'a>(
    path: &'a Path,
    bytes: &'a [u8],
) -> Result<(Reader<'a>, String, usize), DataError> {
    let mut r = Reader {
        path,
        bytes,
        pos: 0,
        binary: false,
    };
    let (_, first) = r.raw_line().unwrap_or_default();
    if !first
        .to_ascii_lowercase()
        .starts_with(b"# vtk datafile version")
    {
        return Err(r.format(
            0,
            "the VTK legacy header '# vtk DataFile Version x.y'",
            crate::files::excerpt(first),
        ));
    }
    r.raw_line(); // the title, free text
    let form = r.line();
    match form.as_ref().map(Line::keyword).as_deref() {
        Some("ASCII") => {}
        Some("BINARY") => r.binary = true,
        _ => return Err(r.unexpected(form.as_ref(), "ASCII or BINARY")),
    }
    let dataset = r.line();
    let at = dataset.as_ref().map_or(r.bytes.len(), |l| l.start);
    match dataset.as_ref().map(|l| (l.keyword(), l.tokens.get(1))) {
        Some((k, Some(t))) if k == "DATASET" => {
            let kind = t.to_ascii_uppercase();
            Ok((r, kind, at))
        }
        Some((k, _)) if k == "FIELD" => {
            Err(r.unsupported(at, "data-object file (FIELD without DATASET)"))
        }
        _ => Err(r.unexpected(dataset.as_ref(), "'DATASET type'")),
    }
}

/// Parses legacy VTK bytes; `path` only names the file in errors.
pub fn parse(path: &Path, bytes: &[u8], array: Option<&str>) -> Result<Volume, DataError> {
    let (mut r, kind, at) = open(path, bytes)?;
    if kind != "STRUCTURED_POINTS" {
        let what = format!("DATASET {kind} (only STRUCTURED_POINTS is read as a volume)");
        return Err(r.unsupported(at, what));
    }

    let mut dims: Option<[u64; 3]> = None;
    let mut spacing = [1.0; 3];
    let mut origin = [0.0; 3];
    let mut count = 0usize;
    let mut section = Section::Geometry;
    let mut sink = Sink::new(Pick::One(array));
    while let Some(line) = r.line() {
        let kw = line.keyword();
        match (section, kw.as_str()) {
            (Section::Geometry, "DIMENSIONS") => {
                r.expect_tokens(&line, 4, "DIMENSIONS nx ny nz")?;
                let mut d = [0u64; 3];
                for (a, v) in d.iter_mut().enumerate() {
                    *v = r.number(&line, a + 1, "a whole-number dimension")?;
                }
                dims = Some(d);
            }
            (Section::Geometry, "SPACING" | "ASPECT_RATIO") => {
                let ok = |s: f64| s.is_finite() && s > 0.0;
                spacing = r.vec3(&line, "a finite spacing > 0", ok)?;
            }
            (Section::Geometry, "ORIGIN") => {
                origin = r.vec3(&line, "a finite origin coordinate", f64::is_finite)?;
            }
            (_, "POINT_DATA" | "CELL_DATA") => {
                r.expect_tokens(&line, 2, &format!("{kw} count"))?;
                let n: u64 = r.number(&line, 1, "a whole-number count")?;
                if section == Section::Geometry {
                    let d = dims.ok_or_else(|| {
                        r.format(
                            line.start,
                            format!("DIMENSIONS before {kw}"),
                            format!("'{kw}'"),
                        )
                    })?;
                    count = checked_sample_count(path, d)?;
                }
                if kw == "POINT_DATA" && n != count as u64 {
                    let expected = format!("POINT_DATA {count} (the product of DIMENSIONS)");
                    return Err(r.format(line.start, expected, format!("POINT_DATA {n}")));
                }
                section = if kw == "POINT_DATA" {
                    Section::Point(n)
                } else {
                    Section::Cell(n)
                };
            }
            (Section::Geometry, "FIELD") | (Section::Point(_) | Section::Cell(_), _) => {
                let within = match section {
                    Section::Point(n) => Some((Location::Point, n)),
                    Section::Cell(n) => Some((Location::Cell, n)),
                    Section::Geometry => None,
                };
                let found = attribute(&mut r, &line, within, &mut sink)?;
                if let Some(values) = found {
                    let d = dims.unwrap_or([1; 3]).map(|v| v as usize);
                    if let Values::F32(v) = &values {
                        check_finite(path, d, v)?;
                    }
                    return Ok(Volume {
                        dims: d,
                        origin,
                        spacing,
                        values,
                    });
                }
            }
            _ => {
                let expected = "DIMENSIONS, SPACING, ORIGIN, FIELD, POINT_DATA or CELL_DATA";
                return Err(r.unexpected(Some(&line), expected));
            }
        }
    }
    let end = r.bytes.len();
    match array {
        Some(name) => Err(DataError::NoSuchArray {
            path: path.to_path_buf(),
            name: name.to_string(),
            available: if sink.seen.is_empty() {
                "none".into()
            } else {
                sink.seen.join(", ")
            },
        }),
        None if dims.is_none() => Err(r.format(end, "DIMENSIONS", "end of file")),
        None => Err(r.format(
            end,
            "a point-data array (POINT_DATA with SCALARS, COLOR_SCALARS or FIELD)",
            "end of file",
        )),
    }
}

/// Parses one attribute (`line` is its keyword line) and its data. `within` is the section's
/// location and tuple count (`None` for dataset-level field data). With [`Pick::One`], returns
/// the chosen array when this attribute holds it; with [`Pick::All`], arrays go to the sink.
pub(super) fn attribute(
    r: &mut Reader,
    line: &Line,
    within: Option<(Location, u64)>,
    sink: &mut Sink,
) -> Result<Option<Values>, DataError> {
    let kw = line.keyword();
    let tuples = within.map_or(0, |(_, n)| n);
    let t = &line.tokens;
    let name = || decode_name(t.get(1).map_or("", String::as_str));
    let mut candidates = Vec::new();
    let fixed = |ncomp: u64| -> Result<Candidate, DataError> {
        r.expect_tokens(line, 3, &format!("{kw} name type"))?;
        Ok(Candidate {
            name: name(),
            elem: r.elem(line, &t[2])?,
            ncomp,
            ntuples: tuples,
            scale_bytes: false,
            scalar: false,
        })
    };
    match kw.as_str() {
        "SCALARS" => {
            if !(3..=4).contains(&t.len()) {
                return Err(r.unexpected(Some(line), "'SCALARS name type [numComp]'"));
            }
            let ncomp = if t.len() == 4 {
                r.number(line, 3, "a component count >= 1")?
            } else {
                1
            };
            let elem = r.elem(line, &t[2])?;
            let has_table = if r.binary {
                let rest = r.bytes.get(r.pos..).unwrap_or_default();
                rest.len() >= 12 && rest[..12].eq_ignore_ascii_case(b"LOOKUP_TABLE")
            } else {
                r.peek_line().is_some_and(|l| l.keyword() == "LOOKUP_TABLE")
            };
            if has_table {
                r.line();
            }
            candidates.push(Candidate {
                name: name(),
                elem,
                ncomp,
                ntuples: tuples,
                scale_bytes: false,
                scalar: true,
            });
        }
        "COLOR_SCALARS" => {
            r.expect_tokens(line, 3, "COLOR_SCALARS name nValues")?;
            let elem = Elem::Num(if r.binary { Scalar::U8 } else { Scalar::F32 });
            candidates.push(Candidate {
                name: name(),
                elem,
                ncomp: r.number(line, 2, "a component count >= 1")?,
                ntuples: tuples,
                scale_bytes: r.binary,
                scalar: true,
            });
        }
        "LOOKUP_TABLE" => {
            r.expect_tokens(line, 3, "LOOKUP_TABLE name size")?;
            candidates.push(Candidate {
                name: name(),
                elem: Elem::Num(if r.binary { Scalar::U8 } else { Scalar::F32 }),
                ncomp: 4,
                ntuples: r.number(line, 2, "a table size")?,
                scale_bytes: false,
                scalar: false,
            });
        }
        "VECTORS" | "NORMALS" => candidates.push(fixed(3)?),
        "TENSORS" => candidates.push(fixed(9)?),
        "TENSORS6" => candidates.push(fixed(6)?),
        "GLOBAL_IDS" | "PEDIGREE_IDS" | "EDGE_FLAGS" => candidates.push(fixed(1)?),
        "TEXTURE_COORDINATES" => {
            r.expect_tokens(line, 4, "TEXTURE_COORDINATES name dim type")?;
            candidates.push(Candidate {
                name: name(),
                elem: r.elem(line, &t[3])?,
                ncomp: r.number(line, 2, "a dimension of 1 to 3")?,
                ntuples: tuples,
                scale_bytes: false,
                scalar: false,
            });
        }
        "FIELD" => {
            r.expect_tokens(line, 3, "FIELD name numArrays")?;
            let arrays: u64 = r.number(line, 2, "an array count")?;
            for left in (0..arrays).rev() {
                let Some(header) = r.line() else {
                    let found = format!("end of file after {} arrays", arrays - left - 1);
                    return Err(r.format(r.pos, format!("{arrays} FIELD arrays"), found));
                };
                if header.tokens[0] == "NULL_ARRAY" {
                    continue;
                }
                r.expect_tokens(&header, 4, "arrayName numComponents numTuples dataType")?;
                let c = Candidate {
                    name: decode_name(&header.tokens[0]),
                    elem: r.elem(&header, &header.tokens[3])?,
                    ncomp: r.number(&header, 1, "a component count >= 1")?,
                    ntuples: r.number(&header, 2, "a tuple count")?,
                    scale_bytes: false,
                    scalar: true,
                };
                if let Some(found) = read_candidate(r, &header, c, within, sink, left)? {
                    return Ok(Some(found));
                }
            }
            return Ok(None);
        }
        _ => {
            let expected = "an attribute (SCALARS, COLOR_SCALARS, FIELD, VECTORS, ...), \
                            POINT_DATA or CELL_DATA";
            return Err(r.unexpected(Some(line), expected));
        }
    }
    for c in candidates {
        if let Some(found) = read_candidate(r, line, c, within, sink, 0)? {
            return Ok(Some(found));
        }
    }
    Ok(None)
}

/// Reads or skips one array; returns it when it is the array [`Pick::One`] chose.
fn read_candidate(
    r: &mut Reader,
    header: &Line,
    c: Candidate,
    within: Option<(Location, u64)>,
    sink: &mut Sink,
    field_arrays_left: u64,
) -> Result<Option<Values>, DataError> {
    if c.ncomp == 0 {
        return Err(r.format(header.start, "a component count >= 1", "0"));
    }
    let location = within.map(|(l, _)| l);
    // Strings are read past: metadata (ParaView's QA records, titles), never a field.
    let renderable = c.scalar && c.elem != Elem::Str;
    let (keep, chosen) = match sink.pick {
        Pick::One(want) => {
            let selectable = renderable && location == Some(Location::Point);
            if selectable {
                sink.seen.push(c.name.clone());
            }
            let chosen = selectable && want.is_none_or(|w| w == c.name);
            (chosen, chosen)
        }
        Pick::All { cells } => {
            let wanted = match location {
                Some(Location::Point) => true,
                Some(Location::Cell) => cells,
                None => false,
            };
            (renderable && wanted, false)
        }
    };
    if let (true, Some((location, n))) = (keep, within)
        && c.ntuples != n
    {
        let expected = format!("{n} tuples (one per {})", location.name());
        return Err(r.format(header.start, expected, c.ntuples.to_string()));
    }
    if !keep {
        r.array::<f32>(c.elem, c.ncomp, c.ntuples, false)?;
        r.skip_metadata();
        return Ok(None);
    }
    let values = if c.scale_bytes {
        let values = r.array::<f32>(c.elem, c.ncomp, c.ntuples, true)?;
        values.into_iter().map(|v| v / 255.0).collect()
    } else {
        r.scalars(c.elem, c.ncomp, c.ntuples)?
    };
    r.skip_metadata();
    if chosen {
        r.check_follows(field_arrays_left, c.ntuples * c.ncomp)?;
        return Ok(Some(values));
    }
    sink.kept.push(DataArray {
        name: c.name,
        location: location.unwrap_or(Location::Point),
        components: usize::try_from(c.ncomp).unwrap_or(usize::MAX),
        values,
    });
    Ok(None)
}
