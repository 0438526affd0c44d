//! Issue 25 §4, capacity: 8- and 16-bit grids stay at their size from the file to the kernel
//! and render exactly as their f32 twins, and a grid larger than one storage binding (lavapipe:
//! 128 MiB) renders, because the grid is bound as a texel view. `vmls` runs with validation on,
//! so a binding past a device limit would also fail these tests.

mod common;

use common::cli::{dir, s, small_render, vmls};
use std::path::Path;

/// Writes a little-endian raw NRRD of `dims` over [-1, 1]³ with `values` of NRRD type `ty`.
fn nrrd(path: &Path, dims: [usize; 3], ty: &str, data: &[u8]) {
    let h = dims.map(|d| 2.0 / (d - 1) as f64);
    let mut bytes = format!(
        "NRRD0004\ntype: {ty}\ndimension: 3\nsizes: {} {} {}\nspace dimension: 3\n\
         space origin: (-1,-1,-1)\nspace directions: ({},0,0) (0,{},0) (0,0,{})\n\
         endian: little\nencoding: raw\n\n",
        dims[0], dims[1], dims[2], h[0], h[1], h[2]
    )
    .into_bytes();
    bytes.extend_from_slice(data);
    std::fs::write(path, bytes).expect("write nrrd");
}

/// A smooth field over [-1, 1]³ mapped to [lo, hi] and rounded: a ball brighter at its centre.
fn ball(dims: [usize; 3], lo: f64, hi: f64) -> Vec<f64> {
    let mut v = Vec::new();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = [i, j, k]
                    .map(|c| c as f64)
                    .iter()
                    .zip(dims)
                    .map(|(c, d)| -1.0 + 2.0 * c / (d - 1) as f64)
                    .collect::<Vec<_>>();
                let r2 = p[0] * p[0] + 0.6 * p[1] * p[1] + 0.8 * p[2] * p[2] + 0.3 * p[0] * p[2];
                let t = (1.0 - r2).clamp(0.0, 1.0);
                v.push((lo + (hi - lo) * t).round());
            }
        }
    }
    v
}

/// Renders `file` at 16×16 with a transfer function spread over [lo, hi], with `--stats`; `fast`
/// asks for the fast path.
fn render(file: &Path, lo: f64, hi: f64, png: &Path, fast: bool) -> serde_json::Value {
    let at = |t: f64| lo + t * (hi - lo);
    let points = format!(
        "transfer.points=[[{},0,0,0,0],[{},0.2,0.4,1,2],[{},1,0.9,0.7,40],[{},1,0.5,0.1,3]]",
        at(0.0),
        at(0.4),
        at(0.6),
        at(1.0)
    );
    let volume = format!("volume.file={:?}", s(file));
    let stats = png.with_extension("json");
    let mut args = small_render(png, &["--set", &volume, "--set", &points]);
    if fast {
        // The fast path whatever the image size ("auto" declines it for a 16×16 first frame).
        args.extend(["--set", "reconstruction.resample=2"]);
    }
    args.extend([
        "--set",
        "camera.width=16",
        "--set",
        "camera.height=16",
        "--stats",
        s(&stats),
    ]);
    let out = vmls(&args);
    assert!(
        out.status.success(),
        "render of {}: {}",
        file.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json")
}

#[test]
fn integer_grids_render_exactly_as_their_f32_twins() {
    let d = dir("capacity-int");
    // Odd sizes: rows start at every offset within a packed word.
    let dims = [23, 17, 13];
    let cases: [(&str, &str, f64, f64); 4] = [
        ("uint16", "uint16", 0.0, 65535.0),
        ("int16", "int16", -32768.0, 32767.0),
        ("uint8", "uint8", 0.0, 255.0),
        ("int8", "int8", -128.0, 127.0),
    ];
    for (ty, storage, lo, hi) in cases {
        let values = ball(dims, lo, hi);
        let packed: Vec<u8> = match ty {
            "uint16" => values
                .iter()
                .flat_map(|&v| (v as u16).to_le_bytes())
                .collect(),
            "int16" => values
                .iter()
                .flat_map(|&v| (v as i16).to_le_bytes())
                .collect(),
            "uint8" => values.iter().map(|&v| v as u8).collect(),
            _ => values.iter().map(|&v| (v as i8) as u8).collect(),
        };
        let floats: Vec<u8> = values
            .iter()
            .flat_map(|&v| (v as f32).to_le_bytes())
            .collect();
        let (int_file, f32_file) = (d.join(format!("{ty}.nrrd")), d.join(format!("{ty}-f.nrrd")));
        nrrd(&int_file, dims, ty, &packed);
        nrrd(&f32_file, dims, "float", &floats);
        let (int_png, f32_png) = (d.join(format!("{ty}.png")), d.join(format!("{ty}-f.png")));
        let a = render(&int_file, lo, hi, &int_png, true);
        let b = render(&f32_file, lo, hi, &f32_png, true);
        assert_eq!(a["sample_storage"], storage, "{ty}: {a}");
        assert_eq!(b["sample_storage"], "float32", "{ty}: {b}");
        let variant = a["variant"].as_str().expect("variant");
        assert!(variant.ends_with(&format!("-{storage}")), "{ty}: {variant}");
        // The fast path's fine grid is computed from the packed grid too.
        assert_eq!(
            a["fast_path"]["fine_points"], b["fast_path"]["fine_points"],
            "{ty}"
        );
        assert!(
            a["fast_path"]["fine_points"].as_u64() > Some(0),
            "{ty}: {a}"
        );
        let (pa, pb) = (
            std::fs::read(&int_png).expect("png"),
            std::fs::read(&f32_png).expect("png"),
        );
        assert_eq!(pa, pb, "{ty}: the image differs from the f32 grid's");
        let img = image::load_from_memory(&pa).expect("decode").to_rgba8();
        let lit = img.pixels().filter(|p| p.0[..3] != [0, 0, 0]).count();
        assert!(lit > 40, "{ty}: only {lit} of 256 pixels show the ball");
    }
}

#[test]
fn a_grid_past_one_storage_binding_renders() {
    let d = dir("capacity-big");
    // 1024 × 1024 × 33 floats: 138 MB, past lavapipe's 128 MiB storage bindings, which refused
    // it before the grid became a texel view ("buffer 'grid' needs … (maxStorageBufferRange)").
    let dims = [1024, 1024, 33];
    let mut data = Vec::with_capacity(dims.iter().product::<usize>() * 4);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let v = 0.5 + 0.4 * ((i as f32 * 0.01).sin() * (j as f32 * 0.013).cos())
                    - 0.01 * k as f32;
                data.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    assert!(data.len() > 128 << 20);
    let file = d.join("big.nrrd");
    nrrd(&file, dims, "float", &data);
    drop(data);
    let png = d.join("big.png");
    let stats = render(&file, 0.0, 1.0, &png, false);
    assert_eq!(stats["sample_storage"], "float32");
    let img = image::open(&png).expect("png").to_rgba8();
    let lit = img.pixels().filter(|p| p.0[..3] != [0, 0, 0]).count();
    assert!(lit > 20, "only {lit} of 256 pixels show the slab");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_grid_the_device_cannot_hold_is_refused_from_its_header() {
    let d = dir("capacity-header");
    // The header declares 1024³ uint8 (1 GiB: 256 M r32ui texels, past lavapipe's 128 M per
    // view); the file holds 4 bytes of data. Refused from the header, naming the samples, the
    // bytes and the limit: the data is never read (it would be "cut short" otherwise).
    let file = d.join("huge.nrrd");
    std::fs::write(
        &file,
        "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 1024 1024 1024\nencoding: raw\n\n\0\0\0\0",
    )
    .expect("write");
    let png = d.join("x.png");
    let volume = format!("volume.file={:?}", s(&file));
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_vmls"))
        .args(small_render(&png, &["--set", &volume]))
        .env("VMLS_VALIDATION", "1")
        .env("VMLS_HOST_MEMORY", "1000000000000")
        .env_remove("VMLS_DEVICE")
        .output()
        .expect("run vmls");
    common::cli::assert_fails(
        &out,
        &[
            "huge.nrrd",
            "1073741824 uint8 samples",
            "1073741872 bytes",
            "maxTexelBufferElements",
            "crop or downsample",
        ],
        &png,
    );
}

/// VTK files keep 8- and 16-bit scalars at their size too: legacy BINARY (big-endian) and XML
/// ImageData inline base64, with the values exactly as written; ASCII stays f32.
#[test]
fn vtk_files_keep_8_and_16_bit_scalars() {
    use base64::Engine;
    use vmls::data::{Storage, Values, load_dataset};
    let d = dir("capacity-vtk");
    let values: Vec<u16> = (0..60).map(|i| (i * 1097 % 65536) as u16).collect();
    let header = "# vtk DataFile Version 3.0\nt\nBINARY\nDATASET STRUCTURED_POINTS\n\
                  DIMENSIONS 5 4 3\nSPACING 1 1 1\nORIGIN 0 0 0\nPOINT_DATA 60\n\
                  SCALARS s unsigned_short 1\nLOOKUP_TABLE default\n";
    let mut legacy = header.as_bytes().to_vec();
    legacy.extend(values.iter().flat_map(|v| v.to_be_bytes()));
    let legacy_path = d.join("u16.vtk");
    std::fs::write(&legacy_path, &legacy).expect("write");
    let ascii = header.replace("BINARY", "ASCII")
        + &values
            .iter()
            .map(u16::to_string)
            .collect::<Vec<_>>()
            .join(" ");
    let ascii_path = d.join("u16-ascii.vtk");
    std::fs::write(&ascii_path, ascii).expect("write");
    let mut payload = ((values.len() * 2) as u32).to_le_bytes().to_vec();
    payload.extend(values.iter().flat_map(|v| v.to_le_bytes()));
    let xml = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" \
         byte_order=\"LittleEndian\" header_type=\"UInt32\">\n<ImageData WholeExtent=\"0 4 0 3 \
         0 2\" Origin=\"0 0 0\" Spacing=\"1 1 1\">\n<Piece Extent=\"0 4 0 3 0 2\">\n<PointData \
         Scalars=\"s\">\n<DataArray type=\"UInt16\" Name=\"s\" format=\"binary\">{}</DataArray>\n\
         </PointData>\n</Piece>\n</ImageData>\n</VTKFile>\n",
        base64::engine::general_purpose::STANDARD.encode(&payload)
    );
    let xml_path = d.join("u16.vti");
    std::fs::write(&xml_path, xml).expect("write");
    let want: Vec<f32> = values.iter().map(|&v| f32::from(v)).collect();
    for (path, storage) in [
        (&legacy_path, Storage::U16),
        (&xml_path, Storage::U16),
        (&ascii_path, Storage::F32),
    ] {
        let set = load_dataset(path).expect("load");
        let a = &set.arrays[0];
        assert_eq!(a.values.storage(), storage, "{}", path.display());
        assert!(a.values == want, "{}: values differ", path.display());
        if storage == Storage::U16 {
            assert!(a.values == Values::U16(values.clone()));
        }
    }
}
