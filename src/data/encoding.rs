//! Typed samples and gzip streams shared by the readers (NRRD, NIfTI, legacy and XML VTK): the
//! element types files store ([`Scalar`]), their binary and text decoding to f32/f64 or, for
//! grids, to [`Values`] kept at 8 or 16 bits, and bounded gzip inflation with its trailers
//! checked.
//!
//! Samples become f32 (or f64 where a reader needs coordinates exactly): 32/64-bit integers
//! and doubles lose precision past f32's 24-bit mantissa, which we accept because rendering
//! works in f32; a double outside the f32 range becomes infinite and is rejected like any
//! non-finite value.

use super::{DataError, Storage, Values};
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
