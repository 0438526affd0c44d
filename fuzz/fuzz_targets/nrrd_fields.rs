//! Structure-aware NRRD: the header's fields (magic version, type spelling, dimension and
//! sizes with a dropped size-1 axis, endian, encoding, spacings or space directions, origin or
//! axis mins, line and byte skips, comments and `key:=value` pairs) and the payload (raw,
//! text, gzip) are chosen by the fuzzer and assembled into a file, so that inputs reach the
//! data decoders and gzip, which mutated bytes rarely do. Whatever parses is rendered
//! (`render_small`) when the first byte says so (one input in 16: rendering costs
//! some 20 parses, and these targets are for the decoders).
#![no_main]
mod fields;
mod render_small;

use libfuzzer_sys::arbitrary::{Result, Unstructured};
use std::fmt::Write as _;

/// NRRD type spellings with their (kind, bytes); `block` must be refused.
const TYPES: [(&str, char, usize); 12] = [
    ("uchar", 'u', 1),
    ("signed char", 'i', 1),
    ("short", 'i', 2),
    ("unsigned short", 'u', 2),
    ("int", 'i', 4),
    ("uint", 'u', 4),
    ("longlong", 'i', 8),
    ("uint64", 'u', 8),
    ("float", 'f', 4),
    ("double", 'f', 8),
    ("block", 'u', 1),
    ("int8_t", 'i', 1),
];

fn build(u: &mut Unstructured) -> Result<Vec<u8>> {
    let mut h = String::new();
    let version = u.int_in_range(1u8..=6)?;
    writeln!(h, "NRRD000{version}").ok();
    let &(ty, kind, bytes) = u.choose(&TYPES)?;
    writeln!(h, "type: {ty}").ok();
    let mut sizes: Vec<i64> = (0..3).map(|_| fields::size(u)).collect::<Result<_>>()?;
    match u.int_in_range(0u8..=7)? {
        0 => sizes.insert(0, 1),
        1 => sizes.push(1),
        2 => sizes.push(fields::size(u)?),
        3 => {
            sizes.pop();
        }
        _ => {}
    }
    writeln!(h, "dimension: {}", sizes.len()).ok();
    let list: Vec<String> = sizes.iter().map(i64::to_string).collect();
    writeln!(h, "sizes: {}", list.join(" ")).ok();
    let big: bool = u.arbitrary()?;
    if !u.ratio(1u8, 8)? {
        writeln!(h, "endian: {}", if big { "big" } else { "little" }).ok();
    }
    let encoding = *u.choose(&["raw", "gzip", "text", "ascii", "gz", "hex", "bzip2"])?;
    writeln!(h, "encoding: {encoding}").ok();
    let float = |u: &mut Unstructured| -> Result<String> {
        Ok(match u.int_in_range(0u8..=15)? {
            0 => "nan".into(),
            1 => "none".into(),
            2 => "1e400".into(),
            _ => format!("{}", fields::float(u)?),
        })
    };
    match u.int_in_range(0u8..=3)? {
        0 => {
            let s: Vec<String> = sizes.iter().map(|_| float(u)).collect::<Result<_>>()?;
            writeln!(h, "spacings: {}", s.join(" ")).ok();
        }
        1 => {
            writeln!(h, "space: right-anterior-superior").ok();
            let mut v = Vec::new();
            for _ in 0..sizes.len().min(3) {
                v.push(format!("({},{},{})", float(u)?, float(u)?, float(u)?));
            }
            if sizes.len() > 3 {
                v.insert(0, "none".into());
            }
            writeln!(h, "space directions: {}", v.join(" ")).ok();
            if u.arbitrary()? {
                let o = format!("({},{},{})", float(u)?, float(u)?, float(u)?);
                writeln!(h, "space origin: {o}").ok();
            }
        }
        2 => {
            let s: Vec<String> = sizes.iter().map(|_| float(u)).collect::<Result<_>>()?;
            writeln!(h, "axis mins: {}", s.join(" ")).ok();
        }
        _ => {}
    }
    if u.ratio(1u8, 6)? {
        writeln!(h, "# a comment\nkey:=value\nkinds: domain domain domain").ok();
    }
    let line_skip = if u.ratio(1u8, 8)? {
        u.int_in_range(0..=3)?
    } else {
        0
    };
    if line_skip > 0 {
        writeln!(h, "line skip: {line_skip}").ok();
    }
    let byte_skip: i64 = match u.int_in_range(0u8..=9)? {
        0 => -1,
        1 => u.int_in_range(1..=16)?,
        _ => 0,
    };
    if byte_skip != 0 {
        writeln!(h, "byte skip: {byte_skip}").ok();
    }
    h.push('\n');
    for _ in 0..line_skip {
        h.push_str("skipped line\n");
    }
    let count = sizes
        .iter()
        .map(|&d| usize::try_from(d).unwrap_or(0))
        .product::<usize>()
        .min(8192);
    let values = fields::values(u, count)?;
    let mut data = vec![0u8; usize::try_from(byte_skip).unwrap_or(0)];
    let text = matches!(encoding, "text" | "ascii");
    if text {
        let mut t = String::new();
        for v in &values {
            write!(t, "{v} ").ok();
        }
        data.extend(t.into_bytes());
    } else if u.ratio(1u8, 8)? {
        data.extend_from_slice(u.bytes(u.len().min(count * bytes))?);
    } else {
        for &v in &values {
            fields::store(&mut data, v, kind, bytes, big);
        }
    }
    let mut file = h.into_bytes();
    if matches!(encoding, "gzip" | "gz") {
        file.extend(fields::compress(u, &data, false)?);
    } else {
        file.extend(data);
    }
    if u.ratio(1u8, 16)? {
        let keep = u.int_in_range(0..=file.len())?;
        file.truncate(keep);
    }
    Ok(file)
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    render_small::parse_built(data, |u| build(u).map(|f| (f, "fuzz.nrrd")));
});
