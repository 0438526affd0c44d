//! Structure-aware VTK XML image data (.vti): extents, origin and spacing, the array's type,
//! component count and format (ascii, inline base64, appended raw or base64), zlib compression
//! with its block size, header_type and byte order are chosen by the fuzzer; binary payloads
//! get a consistent block header (sometimes with one field replaced) and real zlib streams, so
//! that inputs reach the decoders, which mutated bytes almost never do. Whatever parses is
//! rendered (`render_small`) when the first byte says so (one input in 16: rendering
//! costs some 20 parses, and these targets are for the decoders).
#![no_main]
mod fields;
mod render_small;

use base64::Engine;
use libfuzzer_sys::arbitrary::{Result, Unstructured};
use std::fmt::Write as _;

const TYPES: [(&str, char, usize); 9] = [
    ("Float32", 'f', 4),
    ("Float64", 'f', 8),
    ("Int8", 'i', 1),
    ("UInt8", 'u', 1),
    ("Int16", 'i', 2),
    ("UInt16", 'u', 2),
    ("UInt32", 'u', 4),
    ("Int64", 'i', 8),
    ("String", 'u', 1),
];

/// The binary payload of one array: header integers then data, uncompressed or zlib blocks.
/// Returns (header bytes, data bytes) so that the caller can base64 them as one run or two.
fn payload(
    u: &mut Unstructured,
    data: &[u8],
    zlib: bool,
    wide: bool,
    big: bool,
) -> Result<(Vec<u8>, Vec<u8>)> {
    let mut ints: Vec<u64>;
    let mut body = Vec::new();
    if zlib {
        let block = match u.int_in_range(0u8..=3)? {
            0 => u.int_in_range(1..=64)?,
            1 => 32768,
            _ => u.int_in_range(8..=4096)?,
        };
        // At most 16 blocks: each costs the harness a fresh deflate state, some 300 kB to
        // allocate and clear (a 10 s input with 65 k blocks of one byte was the harness
        // compressing, not vmls decoding; at 256 blocks, perf still put 43% of the samples
        // in the harness's compressors). The reader's block loop is the same from two.
        let block = block.max(data.len().div_ceil(16));
        let chunks: Vec<&[u8]> = if data.is_empty() {
            Vec::new()
        } else {
            data.chunks(block).collect()
        };
        let last = data.len() % block;
        ints = vec![chunks.len() as u64, block as u64, last as u64];
        for c in chunks {
            let z = fields::compress(u, c, true)?;
            ints.push(z.len() as u64);
            body.extend(z);
        }
    } else {
        ints = vec![data.len() as u64];
        body.extend_from_slice(data);
    }
    if u.ratio(1u8, 10)? && !ints.is_empty() {
        let i = u.choose_index(ints.len())?;
        ints[i] = match u.int_in_range(0u8..=2)? {
            0 => ints[i].wrapping_add(1),
            1 => ints[i].wrapping_sub(1),
            _ => u.arbitrary()?,
        };
    }
    let mut header = Vec::new();
    for v in ints {
        let mut b = if wide {
            v.to_le_bytes().to_vec()
        } else {
            (v as u32).to_le_bytes().to_vec()
        };
        if big {
            b.reverse();
        }
        header.extend(b);
    }
    Ok((header, body))
}

fn build(u: &mut Unstructured) -> Result<Vec<u8>> {
    let b64 = base64::engine::general_purpose::STANDARD;
    let big: bool = u.arbitrary()?;
    let wide: bool = u.arbitrary()?;
    let zlib: bool = u.arbitrary()?;
    let sizes: Vec<i64> = (0..3).map(|_| fields::size(u)).collect::<Result<_>>()?;
    let extent: Vec<String> = sizes.iter().map(|s| format!("0 {}", s - 1)).collect();
    let extent = extent.join(" ");
    let origin: Vec<String> = (0..3)
        .map(|_| fields::float(u).map(|v| v.to_string()))
        .collect::<Result<_>>()?;
    let spacing: Vec<String> = (0..3)
        .map(|_| fields::float(u).map(|v| v.to_string()))
        .collect::<Result<_>>()?;
    let &(ty, kind, bytes) = u.choose(&TYPES)?;
    let components: u8 = if u.ratio(1u8, 6)? {
        u.int_in_range(0..=4)?
    } else {
        1
    };
    let count = sizes
        .iter()
        .map(|&d| usize::try_from(d).unwrap_or(0))
        .product::<usize>()
        .min(8192)
        * usize::from(components.max(1));
    let values = fields::values(u, count)?;
    let format = *u.choose(&["ascii", "binary", "appended-raw", "appended-base64"])?;
    let mut data = Vec::new();
    for &v in &values {
        fields::store(&mut data, v, kind, bytes, big);
    }
    let (inline, appended) = match format {
        "ascii" => {
            let mut t = String::new();
            for v in &values {
                write!(t, "{v} ").ok();
            }
            (t, None)
        }
        _ => {
            let (header, body) = payload(u, &data, zlib, wide, big)?;
            if format == "appended-raw" {
                let mut raw = header;
                raw.extend(body);
                (String::new(), Some(("raw", raw)))
            } else {
                let text = if u.arbitrary()? {
                    b64.encode([header, body].concat())
                } else {
                    b64.encode(header) + &b64.encode(body)
                };
                if format == "binary" {
                    (text, None)
                } else {
                    (String::new(), Some(("base64", text.into_bytes())))
                }
            }
        }
    };
    let array_format = if appended.is_some() {
        "appended"
    } else {
        format
    };
    let offset = if appended.is_some() {
        if u.ratio(1u8, 10)? {
            format!(" offset=\"{}\"", u.arbitrary::<i32>()?)
        } else {
            " offset=\"0\"".into()
        }
    } else {
        String::new()
    };
    let mut x = String::new();
    writeln!(x, "<?xml version=\"1.0\"?>").ok();
    write!(
        x,
        "<VTKFile type=\"ImageData\" version=\"{}\" byte_order=\"{}\" header_type=\"{}\"",
        if wide { "1.0" } else { "0.1" },
        if big { "BigEndian" } else { "LittleEndian" },
        if wide { "UInt64" } else { "UInt32" }
    )
    .ok();
    if zlib {
        x.push_str(" compressor=\"vtkZLibDataCompressor\"");
    }
    x.push_str(">\n");
    writeln!(
        x,
        "<ImageData WholeExtent=\"{extent}\" Origin=\"{}\" Spacing=\"{}\">",
        origin.join(" "),
        spacing.join(" ")
    )
    .ok();
    writeln!(x, "<Piece Extent=\"{extent}\">\n<PointData Scalars=\"f\">").ok();
    writeln!(
        x,
        "<DataArray type=\"{ty}\" Name=\"f\" NumberOfComponents=\"{components}\" \
         format=\"{array_format}\"{offset}>{inline}</DataArray>"
    )
    .ok();
    writeln!(x, "</PointData>\n</Piece>\n</ImageData>").ok();
    let mut file = x.into_bytes();
    if let Some((encoding, bytes)) = appended {
        file.extend(format!("<AppendedData encoding=\"{encoding}\">\n_").into_bytes());
        file.extend(bytes);
        file.extend(b"\n</AppendedData>\n");
    }
    file.extend(b"</VTKFile>\n");
    Ok(file)
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    render_small::parse_built(data, |u| build(u).map(|f| (f, "fuzz.vti")));
});
