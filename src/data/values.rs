//! Scalar values as a file stores them: 8- and 16-bit integers stay at their size from the file
//! to the device, where the grid kernels convert them (issue 25 §4: a 512³ 16-bit CT is 256 MiB
//! as stored and 512 MiB as f32); every other type, and any value a format scales (NIfTI's
//! slope and intercept), is f32.
//!
//! Contract: [`Values::get`] is the value every consumer sees, the CPU twins included. An 8- or
//! 16-bit integer converts to f32 exactly, so the kernel's `float(raw)` and `get` agree bit for
//! bit.

use std::borrow::Cow;

/// How values are stored; the kernels' `GRID_BITS`/`GRID_SIGNED` variant.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Storage {
    F32,
    U8,
    I8,
    U16,
    I16,
}

impl Storage {
    /// Bits per value.
    pub fn bits(self) -> u32 {
        match self {
            Storage::F32 => 32,
            Storage::U16 | Storage::I16 => 16,
            Storage::U8 | Storage::I8 => 8,
        }
    }

    /// Bytes per value.
    pub fn bytes(self) -> usize {
        self.bits() as usize / 8
    }

    /// Whether the integer is signed (f32: false).
    pub fn signed(self) -> bool {
        matches!(self, Storage::I8 | Storage::I16)
    }

    /// "float32", "uint8", … for `--stats` and `vmls info`.
    pub fn name(self) -> &'static str {
        match self {
            Storage::F32 => "float32",
            Storage::U8 => "uint8",
            Storage::I8 => "int8",
            Storage::U16 => "uint16",
            Storage::I16 => "int16",
        }
    }
}

/// Scalar values, x fastest for grids.
#[derive(Debug, Clone, PartialEq)]
pub enum Values {
    F32(Vec<f32>),
    U8(Vec<u8>),
    I8(Vec<i8>),
    U16(Vec<u16>),
    I16(Vec<i16>),
}

impl Default for Values {
    fn default() -> Self {
        Values::F32(Vec::new())
    }
}

impl From<Vec<f32>> for Values {
    fn from(v: Vec<f32>) -> Self {
        Values::F32(v)
    }
}

impl FromIterator<f32> for Values {
    fn from_iter<I: IntoIterator<Item = f32>>(iter: I) -> Self {
        Values::F32(iter.into_iter().collect())
    }
}

/// Values equal a list of f32 when every value converts to the list's entry.
impl PartialEq<[f32]> for Values {
    fn eq(&self, other: &[f32]) -> bool {
        self.len() == other.len() && self.iter().zip(other).all(|(a, &b)| a == b)
    }
}

impl PartialEq<Vec<f32>> for Values {
    fn eq(&self, other: &Vec<f32>) -> bool {
        *self == other[..]
    }
}

impl<const N: usize> PartialEq<[f32; N]> for Values {
    fn eq(&self, other: &[f32; N]) -> bool {
        *self == other[..]
    }
}

macro_rules! each {
    ($self:expr, $v:ident => $e:expr) => {
        match $self {
            Values::F32($v) => $e,
            Values::U8($v) => $e,
            Values::I8($v) => $e,
            Values::U16($v) => $e,
            Values::I16($v) => $e,
        }
    };
}

impl Values {
    /// Number of values.
    pub fn len(&self) -> usize {
        each!(self, v => v.len())
    }

    /// True when there is no value.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// How the values are stored.
    pub fn storage(&self) -> Storage {
        match self {
            Values::F32(_) => Storage::F32,
            Values::U8(_) => Storage::U8,
            Values::I8(_) => Storage::I8,
            Values::U16(_) => Storage::U16,
            Values::I16(_) => Storage::I16,
        }
    }

    /// Value `i` as f32 (exact for the integer types).
    pub fn get(&self, i: usize) -> f32 {
        match self {
            Values::F32(v) => v[i],
            Values::U8(v) => f32::from(v[i]),
            Values::I8(v) => f32::from(v[i]),
            Values::U16(v) => f32::from(v[i]),
            Values::I16(v) => f32::from(v[i]),
        }
    }

    /// The values as f32, in order.
    pub fn iter(&self) -> impl Iterator<Item = f32> + '_ {
        (0..self.len()).map(|i| self.get(i))
    }

    /// The values as an f32 slice: borrowed when stored as f32, else converted (a copy at 2 or
    /// 4 times the stored size; grid paths read [`Values::bytes`] instead).
    pub fn as_f32(&self) -> Cow<'_, [f32]> {
        match self {
            Values::F32(v) => Cow::Borrowed(v),
            _ => Cow::Owned(self.iter().collect()),
        }
    }

    /// The values as stored, native endian, for the device.
    pub fn bytes(&self) -> &[u8] {
        each!(self, v => bytemuck::cast_slice(v))
    }

    /// Smallest and largest value.
    pub fn range(&self) -> (f32, f32) {
        self.iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            })
    }

    /// No values yet, room for `n`, stored as `storage`.
    pub fn with_capacity(storage: Storage, n: usize) -> Values {
        match storage {
            Storage::F32 => Values::F32(Vec::with_capacity(n)),
            Storage::U8 => Values::U8(Vec::with_capacity(n)),
            Storage::I8 => Values::I8(Vec::with_capacity(n)),
            Storage::U16 => Values::U16(Vec::with_capacity(n)),
            Storage::I16 => Values::I16(Vec::with_capacity(n)),
        }
    }

    /// The values at `indices`, in that order, stored as these are.
    pub fn select(&self, indices: &[usize]) -> Values {
        match self {
            Values::F32(v) => Values::F32(indices.iter().map(|&i| v[i]).collect()),
            Values::U8(v) => Values::U8(indices.iter().map(|&i| v[i]).collect()),
            Values::I8(v) => Values::I8(indices.iter().map(|&i| v[i]).collect()),
            Values::U16(v) => Values::U16(indices.iter().map(|&i| v[i]).collect()),
            Values::I16(v) => Values::I16(indices.iter().map(|&i| v[i]).collect()),
        }
    }

    /// Appends `more`: kept as stored when both are stored alike, else both become f32.
    pub fn append(&mut self, more: Values) {
        match (&mut *self, more) {
            (Values::F32(a), Values::F32(b)) => a.extend(b),
            (Values::U8(a), Values::U8(b)) => a.extend(b),
            (Values::I8(a), Values::I8(b)) => a.extend(b),
            (Values::U16(a), Values::U16(b)) => a.extend(b),
            (Values::I16(a), Values::I16(b)) => a.extend(b),
            (a, b) => *a = a.iter().chain(b.iter()).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integers_convert_exactly_and_keep_their_size() {
        let v = Values::I16(vec![i16::MIN, -1, 0, 1, i16::MAX]);
        assert_eq!(v.storage().bits(), 16);
        assert!(v.storage().signed());
        assert_eq!(v.bytes().len(), 10);
        assert_eq!(v.range(), (-32768.0, 32767.0));
        assert_eq!(v.get(1), -1.0);
        let u = Values::U8(vec![0, 255]);
        assert_eq!(u.as_f32().as_ref(), &[0.0, 255.0]);
    }
}
