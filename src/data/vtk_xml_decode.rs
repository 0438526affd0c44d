//! The `DataArray` payload encodings of VTK XML files, for [`super::vtk_xml`]: text (`ascii`),
//! inline base64 (`binary`) and the `<AppendedData>` block (`raw` bytes or `base64` text), each
//! uncompressed or zlib-compressed.
//!
//! Binary payloads start with a header of `header_type` integers (UInt32 or UInt64, in the
//! file's byte order): uncompressed, one integer giving the byte count; compressed, the block
//! count `n`, the uncompressed block size, the size of the last block (0 when it is full) and
//! the `n` compressed block sizes, followed by the `n` zlib streams.
//!
//! VTK encodes the header and the data as separate base64 runs when compressing and as one run
//! otherwise. Both read the same way if the text is decoded quantum by quantum, a padded quantum
//! ending its run, which is what [`B64`] does: it never needs to know how the writer split it.
//!
//! Safety against lying headers: every declared size is compared with the bytes that are really
//! there before anything is allocated for it; a compressed block may not claim more than
//! deflate's maximum expansion (1032:1) of its compressed size, and inflating stops one byte past
//! the declared size, so a block larger than its header says is an error, never a large buffer.
//! Output buffers grow with the data really decoded, never with a header's claim.
//!
//! Errors: a byte count that disagrees with the tuples the array must hold is a format error
//! naming the array; data that ends before its header's count (cut base64 text, a cut appended
//! block, an `offset` past its end) is [`DataError::Truncated`]; surplus base64 after an inline
//! array is a format error. Text values are whitespace-separated: integers must be whole and in
//! their type's range, floats use Rust's parser (`nan`/`inf` parse and are rejected later, by
//! `Dataset::validate`, naming the element); errors give the byte offset of the bad token.

use super::DataError;
use super::encoding::Scalar;
use base64::Engine;
use std::borrow::Cow;
use std::io::Read;
use std::path::Path;

/// Deflate cannot expand data by more than about 1032:1; a header claiming more is a lie.
const MAX_INFLATE_RATIO: u64 = 1032;

/// What the `<VTKFile>` element says about every binary payload.
#[derive(Clone, Copy)]
pub(crate) struct Encoding {
    pub big_endian: bool,
    /// Header integers are UInt64 (else UInt32).
    pub header64: bool,
    pub zlib: bool,
}

/// The bytes after the `_` marker of `<AppendedData>`.
pub(crate) struct Appended<'a> {
    pub data: &'a [u8],
    /// Offset of `data` in the file.
    pub at: usize,
    pub base64: bool,
}

/// Where a `DataArray` keeps its values.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Form {
    Ascii,
    Binary,
    Appended(u64),
}

/// A numeric `DataArray` as declared in the XML, with its inline text.
pub(crate) struct ArrayDesc<'a> {
    pub name: String,
    pub ty: Scalar,
    pub components: usize,
    pub form: Form,
    /// Byte offset of the `<DataArray` element in the file.
    pub at: usize,
    pub text: &'a [u8],
    /// Byte offset of `text` in the file.
    pub text_at: usize,
    /// The optional `NumberOfTuples` attribute.
    pub tuples: Option<u64>,
}

/// Everything needed to decode arrays of one file.
pub(crate) struct Decoder<'a> {
    pub path: &'a Path,
    pub encoding: Encoding,
    pub appended: Option<Appended<'a>>,
}

/// Which components of each tuple to keep.
#[derive(Clone, Copy, PartialEq)]
pub(crate) enum Keep {
    First,
    All,
}

impl Decoder<'_> {
    fn format(
        &self,
        location: String,
        expected: impl Into<String>,
        found: impl Into<String>,
    ) -> DataError {
        DataError::Format {
            path: self.path.to_path_buf(),
            location,
            expected: expected.into(),
            found: found.into(),
        }
    }

    fn truncated(&self, expected: u64, found: u64) -> DataError {
        DataError::Truncated {
            path: self.path.to_path_buf(),
            expected,
            found,
        }
    }

    /// Decodes `a`. With `tuples`, the array must hold exactly that many tuples; without, its
    /// length comes from the data (a byte count, or the number of text values). Values are
    /// passed through `f` (f64 holds every integer below 2^53 exactly).
    pub fn values<T>(
        &self,
        a: &ArrayDesc,
        tuples: Option<u64>,
        keep: Keep,
        f: impl Fn(f64) -> T,
    ) -> Result<Vec<T>, DataError> {
        let here = || format!("byte {} (array '{}')", a.at, a.name);
        if let (Some(want), Some(declared)) = (tuples, a.tuples)
            && want != declared
        {
            return Err(self.format(
                here(),
                format!("NumberOfTuples=\"{want}\""),
                format!("NumberOfTuples=\"{declared}\""),
            ));
        }
        let tuples = tuples.or(a.tuples);
        let count = match tuples {
            Some(t) => Some(t.checked_mul(a.components as u64).ok_or_else(|| {
                self.format(
                    here(),
                    "a value count that fits 64 bits",
                    format!("{t} tuples"),
                )
            })?),
            None => None,
        };
        let stride = a.components.max(1);
        if let Form::Ascii = a.form {
            return self.ascii(a, count, keep, f);
        }
        let bytes = self.binary(a, count)?;
        Ok(convert(
            &bytes,
            a.ty,
            self.encoding.big_endian,
            stride,
            keep,
            f,
        ))
    }

    /// Decodes a scalar array (component 0 of each of `tuples` tuples, as [`Decoder::values`]
    /// with [`Keep::First`]): a one-component binary array of 8- or 16-bit integers keeps that
    /// size (the grid kernels convert it, [`super::values`]); anything else becomes f32.
    pub fn scalars(&self, a: &ArrayDesc, tuples: u64) -> Result<super::Values, DataError> {
        let binary = !matches!(a.form, Form::Ascii);
        if a.components == 1 && binary && a.ty.storage() != super::Storage::F32 {
            if let Some(declared) = a.tuples.filter(|&d| d != tuples) {
                return Err(self.format(
                    format!("byte {} (array '{}')", a.at, a.name),
                    format!("NumberOfTuples=\"{tuples}\""),
                    format!("NumberOfTuples=\"{declared}\""),
                ));
            }
            let bytes = self.binary(a, Some(tuples))?;
            return Ok(super::encoding::decode_values(
                &bytes,
                a.ty,
                self.encoding.big_endian,
            ));
        }
        Ok(self
            .values(a, Some(tuples), Keep::First, |v| v as f32)?
            .into())
    }

    /// The bytes of binary array `a` (`count` values, when known), decoded from base64 and
    /// inflated as its encoding says, every size checked against what is there.
    fn binary(&self, a: &ArrayDesc, count: Option<u64>) -> Result<Cow<'_, [u8]>, DataError> {
        let here = || format!("byte {} (array '{}')", a.at, a.name);
        let tuple_bytes = (a.ty.size() * a.components.max(1)) as u64;
        let want_bytes = match count {
            Some(c) => Some(c.checked_mul(a.ty.size() as u64).ok_or_else(|| {
                self.format(
                    here(),
                    "a byte count that fits 64 bits",
                    format!("{c} values"),
                )
            })?),
            None => None,
        };
        let mut source = match a.form {
            Form::Binary | Form::Ascii => {
                let chars: Vec<u8> = a
                    .text
                    .iter()
                    .copied()
                    .filter(|c| !c.is_ascii_whitespace())
                    .collect();
                Source::B64(B64::new(Cow::Owned(chars), a.at))
            }
            Form::Appended(offset) => {
                let app = self.appended.as_ref().ok_or_else(|| {
                    self.format(
                        here(),
                        "an <AppendedData> element for format=\"appended\"",
                        "none",
                    )
                })?;
                // An offset past the end means the appended block was cut short.
                let start = usize::try_from(offset)
                    .ok()
                    .filter(|&o| o <= app.data.len())
                    .ok_or_else(|| self.truncated(offset, app.data.len() as u64))?;
                if app.base64 {
                    Source::B64(B64::new(Cow::Borrowed(&app.data[start..]), app.at + start))
                } else {
                    Source::Raw {
                        data: &app.data[start..],
                        pos: 0,
                        at: app.at + start,
                    }
                }
            }
        };
        let bytes: Cow<[u8]> = if self.encoding.zlib {
            Cow::Owned(self.compressed(&mut source, a, want_bytes)?)
        } else {
            let n = self.header_int(&mut source)?;
            match want_bytes {
                Some(w) if w != n => {
                    let found =
                        format!("a header of {n} bytes ({} values)", n / a.ty.size() as u64);
                    return Err(self.format(
                        here(),
                        format!("{w} bytes ({} values)", count.unwrap_or(0)),
                        found,
                    ));
                }
                _ => {}
            }
            if n > source.available() {
                return Err(self.truncated(n, source.available()));
            }
            source.read(self, n as usize)?
        };
        if !(bytes.len() as u64).is_multiple_of(tuple_bytes) {
            let expected = format!("whole tuples of {tuple_bytes} bytes");
            return Err(self.format(here(), expected, format!("{} bytes", bytes.len())));
        }
        if let (Form::Binary, Source::B64(b)) = (a.form, &source)
            && (b.pos < b.chars.len() || !b.pending.is_empty())
        {
            let found = format!(
                "{} more bytes",
                b.pending.len() + (b.chars.len() - b.pos) / 4 * 3
            );
            return Err(self.format(here(), "the end of the array's base64 data", found));
        }
        Ok(bytes)
    }

    fn header_int(&self, s: &mut Source) -> Result<u64, DataError> {
        let size = if self.encoding.header64 { 8 } else { 4 };
        let raw = s.read(self, size)?;
        let big = self.encoding.big_endian;
        Ok(match (size, raw.as_ref()) {
            (8, &[a, b, c, d, e, f, g, h]) => {
                let b8 = [a, b, c, d, e, f, g, h];
                if big {
                    u64::from_be_bytes(b8)
                } else {
                    u64::from_le_bytes(b8)
                }
            }
            (_, &[a, b, c, d]) => {
                let b4 = [a, b, c, d];
                u64::from(if big {
                    u32::from_be_bytes(b4)
                } else {
                    u32::from_le_bytes(b4)
                })
            }
            _ => return Err(self.truncated(size as u64, raw.len() as u64)),
        })
    }

    /// Reads the block header and inflates every block.
    fn compressed(
        &self,
        s: &mut Source,
        a: &ArrayDesc,
        want: Option<u64>,
    ) -> Result<Vec<u8>, DataError> {
        let here = s.location();
        let blocks = self.header_int(s)?;
        let int_size = if self.encoding.header64 { 8 } else { 4 };
        let header_bytes = blocks.checked_add(2).and_then(|n| n.checked_mul(int_size));
        if header_bytes.is_none_or(|h| h > s.available()) {
            let found = format!("{} bytes for {blocks} blocks", s.available());
            return Err(self.format(here, "a compression header that fits the data", found));
        }
        let block_size = self.header_int(s)?;
        let last = self.header_int(s)?;
        let mut sizes = Vec::with_capacity(blocks as usize);
        for _ in 0..blocks {
            sizes.push(self.header_int(s)?);
        }
        if last > block_size || (blocks > 0 && block_size == 0) {
            let found = format!("block size {block_size}, last block {last}");
            return Err(self.format(here, "a last block no larger than the block size", found));
        }
        let total = match blocks {
            0 => Some(0),
            n if last == 0 => n.checked_mul(block_size),
            n => (n - 1)
                .checked_mul(block_size)
                .and_then(|t| t.checked_add(last)),
        };
        let total = total
            .ok_or_else(|| self.format(here.clone(), "a size that fits 64 bits", "overflow"))?;
        if let Some(w) = want
            && w != total
        {
            let n = a.ty.size() as u64;
            let expected = format!("{w} bytes ({} values)", w / n);
            let found = format!("a header of {total} bytes ({} values)", total / n);
            return Err(self.format(here, expected, found));
        }
        let compressed: u64 = sizes
            .iter()
            .try_fold(0u64, |t, &c| t.checked_add(c))
            .unwrap_or(u64::MAX);
        if compressed > s.available() {
            return Err(self.truncated(compressed, s.available()));
        }
        let mut out = Vec::new();
        for (b, &csize) in sizes.iter().enumerate() {
            let here = s.location();
            let size = if b as u64 + 1 == blocks && last != 0 {
                last
            } else {
                block_size
            };
            if size > csize.saturating_mul(MAX_INFLATE_RATIO) {
                let found = format!("{size} bytes from {csize} compressed bytes");
                return Err(self.format(here, "a block size within deflate's 1032:1 ratio", found));
            }
            let data = s.read(self, csize as usize)?;
            let start = out.len();
            let read = flate2::read::ZlibDecoder::new(data.as_ref())
                .take(size + 1)
                .read_to_end(&mut out);
            if let Err(e) = read {
                return Err(self.format(here, format!("zlib-compressed block {b}"), e.to_string()));
            }
            let got = (out.len() - start) as u64;
            if got != size {
                let found = format!("{got}{} bytes", if got > size { " or more" } else { "" });
                return Err(self.format(
                    here,
                    format!("block {b} to inflate to {size} bytes"),
                    found,
                ));
            }
        }
        Ok(out)
    }

    /// Parses whitespace-separated text values.
    fn ascii<T>(
        &self,
        a: &ArrayDesc,
        count: Option<u64>,
        keep: Keep,
        f: impl Fn(f64) -> T,
    ) -> Result<Vec<T>, DataError> {
        let stride = a.components.max(1) as u64;
        let bound = (a.text.len() / 2 + 1) as u64;
        let capacity = count.unwrap_or(bound).min(bound);
        let capacity = if keep == Keep::First {
            capacity / stride + 1
        } else {
            capacity
        };
        let mut out = Vec::with_capacity(capacity as usize);
        let mut i = 0u64;
        let mut pos = 0;
        let text = a.text;
        while let Some(start) = text
            .get(pos..)
            .and_then(|r| r.iter().position(|c| !c.is_ascii_whitespace()))
        {
            let start = pos + start;
            let len = text[start..]
                .iter()
                .position(u8::is_ascii_whitespace)
                .unwrap_or(text.len() - start);
            let token = &text[start..start + len];
            pos = start + len;
            if count.is_some_and(|c| i >= c) {
                let location = format!("byte {} (array '{}')", a.text_at + start, a.name);
                let expected = format!("{} values", count.unwrap_or(0));
                return Err(self.format(
                    location,
                    expected,
                    format!("more, starting with {}", crate::files::excerpt(token)),
                ));
            }
            let Some(v) = parse_value(token, a.ty) else {
                let location = format!("byte {} (array '{}')", a.text_at + start, a.name);
                return Err(self.format(
                    location,
                    format!("a {} value", a.ty.name()),
                    crate::files::excerpt(token),
                ));
            };
            if keep == Keep::All || i.is_multiple_of(stride) {
                out.push(f(v));
            }
            i += 1;
        }
        let location = format!("byte {} (array '{}')", a.at, a.name);
        match count {
            Some(c) if i != c => {
                Err(self.format(location, format!("{c} values"), format!("{i} values")))
            }
            None if !i.is_multiple_of(stride) => Err(self.format(
                location,
                format!("whole tuples of {stride} values"),
                format!("{i} values"),
            )),
            _ => Ok(out),
        }
    }
}

/// Parses one text value: integers must be integral and in range, floats finite or not (NaN is
/// rejected later, naming the array element).
fn parse_value(token: &[u8], ty: Scalar) -> Option<f64> {
    let text = std::str::from_utf8(token).ok()?;
    let int = |lo: i128, hi: i128| {
        text.parse::<i128>()
            .ok()
            .filter(|v| (lo..=hi).contains(v))
            .map(|v| v as f64)
    };
    match ty {
        Scalar::I8 => int(i8::MIN.into(), i8::MAX.into()),
        Scalar::U8 => int(0, u8::MAX.into()),
        Scalar::I16 => int(i16::MIN.into(), i16::MAX.into()),
        Scalar::U16 => int(0, u16::MAX.into()),
        Scalar::I32 => int(i32::MIN.into(), i32::MAX.into()),
        Scalar::U32 => int(0, u32::MAX.into()),
        Scalar::I64 => int(i64::MIN.into(), i64::MAX.into()),
        Scalar::U64 => int(0, u64::MAX.into()),
        Scalar::F32 => text.parse::<f32>().ok().map(f64::from),
        Scalar::F64 => text.parse::<f64>().ok(),
    }
}

/// Converts packed values, keeping component 0 of each `stride`-value tuple or all of them.
fn convert<T>(
    data: &[u8],
    ty: Scalar,
    big: bool,
    stride: usize,
    keep: Keep,
    f: impl Fn(f64) -> T,
) -> Vec<T> {
    let step = match keep {
        Keep::First => ty.size() * stride,
        Keep::All => ty.size(),
    };
    macro_rules! each {
        ($t:ty) => {{
            const N: usize = std::mem::size_of::<$t>();
            data.chunks_exact(step)
                .map(|c| {
                    let mut raw = [0u8; N];
                    raw.copy_from_slice(&c[..N]);
                    let v = if big {
                        <$t>::from_be_bytes(raw)
                    } else {
                        <$t>::from_le_bytes(raw)
                    };
                    f(v as f64)
                })
                .collect()
        }};
    }
    match ty {
        Scalar::I8 => each!(i8),
        Scalar::U8 => each!(u8),
        Scalar::I16 => each!(i16),
        Scalar::U16 => each!(u16),
        Scalar::I32 => each!(i32),
        Scalar::U32 => each!(u32),
        Scalar::I64 => each!(i64),
        Scalar::U64 => each!(u64),
        Scalar::F32 => each!(f32),
        Scalar::F64 => each!(f64),
    }
}

/// A byte stream over raw appended bytes or base64 text.
enum Source<'a> {
    Raw {
        data: &'a [u8],
        pos: usize,
        at: usize,
    },
    B64(B64<'a>),
}

impl<'a> Source<'a> {
    /// Upper bound of the bytes left.
    fn available(&self) -> u64 {
        match self {
            Source::Raw { data, pos, .. } => (data.len() - pos) as u64,
            Source::B64(b) => (b.pending.len() + (b.chars.len() - b.pos) / 4 * 3) as u64,
        }
    }

    fn location(&self) -> String {
        match self {
            Source::Raw { pos, at, .. } => format!("byte {}", at + pos),
            Source::B64(b) => format!("byte {} (base64 character {})", b.at, b.pos),
        }
    }

    /// Exactly `n` bytes, or `Truncated`.
    fn read(&mut self, d: &Decoder, n: usize) -> Result<Cow<'a, [u8]>, DataError> {
        match self {
            Source::Raw { data, pos, .. } => {
                let data: &'a [u8] = data;
                let Some(out) = data.get(*pos..pos.saturating_add(n)) else {
                    return Err(d.truncated(n as u64, (data.len() - *pos) as u64));
                };
                *pos += n;
                Ok(Cow::Borrowed(out))
            }
            Source::B64(b) => b.read(d, n).map(Cow::Owned),
        }
    }
}

/// Base64 text decoded on demand, quantum-aligned runs at a time (see the module doc).
struct B64<'a> {
    chars: Cow<'a, [u8]>,
    pos: usize,
    /// Decoded bytes of the last quantum not yet consumed.
    pending: Vec<u8>,
    /// Offset of the element or appended block, for messages.
    at: usize,
}

impl<'a> B64<'a> {
    fn new(chars: Cow<'a, [u8]>, at: usize) -> Self {
        Self {
            chars,
            pos: 0,
            pending: Vec::new(),
            at,
        }
    }

    fn read(&mut self, d: &Decoder, n: usize) -> Result<Vec<u8>, DataError> {
        let take = self.pending.len().min(n);
        let mut out: Vec<u8> = self.pending.drain(..take).collect();
        while out.len() < n {
            let rest = &self.chars[self.pos..];
            let need = n - out.len();
            let mut len = need.div_ceil(3).saturating_mul(4).min(rest.len() / 4 * 4);
            if let Some(k) = rest[..len].iter().position(|&c| c == b'=') {
                len = (k / 4 + 1) * 4;
            }
            if len == 0 {
                break;
            }
            let decoded = base64::engine::general_purpose::STANDARD
                .decode(&rest[..len])
                .map_err(|e| {
                    let location = format!("byte {} (base64 character {})", self.at, self.pos);
                    d.format(location, "base64 data", e.to_string())
                })?;
            self.pos += len;
            if decoded.len() > need {
                self.pending.extend_from_slice(&decoded[need..]);
            }
            out.extend_from_slice(&decoded[..need.min(decoded.len())]);
        }
        if out.len() < n {
            return Err(d.truncated(n as u64, out.len() as u64));
        }
        Ok(out)
    }
}
