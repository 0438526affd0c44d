//! Structure-aware NIfTI-1: the header's fields (sizeof_hdr, rank and dims, datatype and
//! bitpix, pixdim, vox_offset, scaling, qform/sform codes and matrices, magic), the byte order,
//! the payload and gzip are chosen by the fuzzer and assembled into a file, so that inputs get
//! past the header checks and through gzip, which mutated bytes rarely do. Whatever parses is
//! rendered (`render_small`) when the first byte says so (one input in 16: rendering
//! costs some 20 parses, and these targets are for the decoders).
#![no_main]
mod fields;
mod render_small;

use libfuzzer_sys::arbitrary::{Result, Unstructured};

/// NIfTI datatype codes with their (kind, bytes), and codes the reader must refuse.
const TYPES: [(i16, char, usize); 14] = [
    (2, 'u', 1),
    (4, 'i', 2),
    (8, 'i', 4),
    (16, 'f', 4),
    (64, 'f', 8),
    (256, 'i', 1),
    (512, 'u', 2),
    (768, 'u', 4),
    (1024, 'i', 8),
    (1280, 'u', 8),
    (32, 'f', 8),
    (128, 'u', 3),
    (1536, 'f', 16),
    (0, 'u', 1),
];

fn build(u: &mut Unstructured) -> Result<(Vec<u8>, bool)> {
    let big: bool = u.arbitrary()?;
    let gzip: bool = u.arbitrary()?;
    let mut h = vec![0u8; 348];
    let put = |h: &mut Vec<u8>, at: usize, mut b: Vec<u8>| {
        if big {
            b.reverse();
        }
        h[at..at + b.len()].copy_from_slice(&b);
    };
    let sizeof_hdr: i32 = if u.ratio(1u8, 16)? {
        u.arbitrary()?
    } else {
        348
    };
    put(&mut h, 0, sizeof_hdr.to_le_bytes().to_vec());
    let rank: i16 = if u.ratio(1u8, 8)? {
        u.arbitrary()?
    } else {
        u.int_in_range(3..=4)?
    };
    let mut dim = [rank, 1, 1, 1, 1, 1, 1, 1];
    for d in dim.iter_mut().skip(1).take(3) {
        *d = fields::size(u)? as i16;
    }
    for d in dim.iter_mut().skip(4) {
        if u.ratio(1u8, 8)? {
            *d = u.int_in_range(0..=3)?;
        }
    }
    for (i, d) in dim.iter().enumerate() {
        put(&mut h, 40 + 2 * i, d.to_le_bytes().to_vec());
    }
    let &(code, kind, bytes) = u.choose(&TYPES)?;
    put(&mut h, 70, code.to_le_bytes().to_vec());
    let bitpix: i16 = if u.ratio(1u8, 8)? {
        u.arbitrary()?
    } else {
        8 * bytes as i16
    };
    put(&mut h, 72, bitpix.to_le_bytes().to_vec());
    let qfac: f32 = *u.choose(&[1.0, -1.0, 0.0])?;
    put(&mut h, 76, qfac.to_le_bytes().to_vec());
    for i in 1..8 {
        let v = if i <= 3 { fields::float(u)? } else { 1.0 };
        put(&mut h, 76 + 4 * i, (v as f32).to_le_bytes().to_vec());
    }
    let vox_offset: f32 = match u.int_in_range(0u8..=7)? {
        0..=4 => 352.0,
        5 => *u.choose(&[348.0, 0.0, 353.0, 1e9, f32::NAN, 352.5])?,
        _ => fields::float(u)? as f32,
    };
    put(&mut h, 108, vox_offset.to_le_bytes().to_vec());
    let (slope, inter) = if u.ratio(1u8, 2)? {
        (1.0, 0.0)
    } else {
        (fields::float(u)?, fields::float(u)?)
    };
    put(&mut h, 112, (slope as f32).to_le_bytes().to_vec());
    put(&mut h, 116, (inter as f32).to_le_bytes().to_vec());
    let qform: i16 = u.int_in_range(0..=4)?;
    let sform: i16 = u.int_in_range(0..=4)?;
    put(&mut h, 252, qform.to_le_bytes().to_vec());
    put(&mut h, 254, sform.to_le_bytes().to_vec());
    // quatern_b..d, qoffset_x..z, srow_x, srow_y, srow_z.
    for i in 0..18 {
        let identity = [
            0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
            0.0,
        ];
        let v = if u.ratio(1u8, 3)? {
            fields::float(u)?
        } else {
            identity[i]
        };
        put(&mut h, 256 + 4 * i, (v as f32).to_le_bytes().to_vec());
    }
    let magic: [u8; 4] = match u.int_in_range(0u8..=9)? {
        0..=6 => *b"n+1\0",
        7 => *b"ni1\0",
        8 => *b"n+2\0",
        _ => u.arbitrary()?,
    };
    h[344..348].copy_from_slice(&magic);
    // Extension flag and padding up to vox_offset (352 when plausible).
    h.extend([0u8; 4]);
    if vox_offset.is_finite() && (352.0..=4096.0).contains(&vox_offset) {
        h.resize(vox_offset as usize, 0);
    }
    let count = dim[1..4]
        .iter()
        .map(|&d| usize::try_from(d).unwrap_or(0))
        .product::<usize>()
        .min(8192);
    if u.ratio(1u8, 8)? {
        let raw = u.bytes(u.len().min(count * bytes))?;
        h.extend_from_slice(raw);
    } else {
        for v in fields::values(u, count)? {
            fields::store(&mut h, v, kind, bytes.min(8), big);
        }
    }
    if u.ratio(1u8, 16)? {
        let keep = u.int_in_range(0..=h.len())?;
        h.truncate(keep);
    }
    let file = if gzip {
        fields::compress(u, &h, false)?
    } else {
        h
    };
    Ok((file, gzip))
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    render_small::parse_built(data, |u| {
        build(u).map(|(f, gzip)| (f, if gzip { "fuzz.nii.gz" } else { "fuzz.nii" }))
    });
});
