//! Files as ParaView writes them, and as they are corrupted or named (issue 25 §2, §3): field
//! data of every array type, `info` exactly as `render` validates, escaped names, one clear
//! line for each malformed case.

mod common;

use common::cli::{assert_fails, dir, quick_bench, s, small_render, vmls};
use std::path::{Path, PathBuf};
use vmls::data::dataset::Location;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/field")
        .join(name)
}

const FIXTURES: [&str; 8] = [
    "legacy_ascii.vtk",
    "legacy_binary.vtk",
    "xml_ascii.vti",
    "xml_ascii_zlib.vti",
    "xml_binary.vti",
    "xml_binary_zlib.vti",
    "xml_appended.vti",
    "xml_appended_zlib.vti",
];

#[test]
fn field_data_of_every_type_is_read_past() {
    for name in FIXTURES {
        let path = fixture(name);
        let d = vmls::data::load_dataset(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        let f = d
            .arrays
            .iter()
            .find(|a| a.name == "f")
            .unwrap_or_else(|| panic!("{name}: no 'f'"));
        assert_eq!(f.location, Location::Point, "{name}");
        assert_eq!(f.values.len(), 27, "{name}");
        for (i, v) in f.values.iter().enumerate() {
            let (x, y, z) = ((i % 3) as f32, (i / 3 % 3) as f32, (i / 9) as f32);
            let expected = 0.5 * x + 2.0 * 0.5 * y + 3.0 * 0.5 * z;
            assert_eq!(v, expected, "{name}: f[{i}]");
        }
        // Strings never become arrays, and dataset-level field data is metadata.
        let names: Vec<&str> = d.arrays.iter().map(|a| a.name.as_str()).collect();
        for absent in [
            "labels",
            "QA Records",
            "Title",
            "Info Records",
            "ids",
            "TIME",
        ] {
            assert!(!names.contains(&absent), "{name}: {names:?}");
        }
    }
    // `info` describes them too.
    let out = vmls(&["info", s(&fixture("legacy_binary.vtk"))]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_truncated_binary_string_array_is_an_error() {
    let bytes = std::fs::read(fixture("legacy_binary.vtk")).expect("fixture");
    // Cut inside the QA records' strings.
    let d = dir("strings-cut");
    let cut = d.join("cut.vtk");
    std::fs::write(&cut, &bytes[..0x90]).expect("write");
    let e = vmls::data::load_dataset(&cut).expect_err("cut");
    assert!(e.to_string().contains("data ends early"), "{e}");
}

/// A legacy image file of `dims` with `spacing` and values 0, 1, 2, ...
fn legacy(path: &Path, dims: [usize; 3], spacing: &str, name: &str) {
    let n = dims.iter().product::<usize>();
    let values: Vec<String> = (0..n).map(|i| i.to_string()).collect();
    let text = format!(
        "# vtk DataFile Version 3.0\nt\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS {} {} {}\n\
         SPACING {spacing}\nORIGIN 0 0 0\nPOINT_DATA {n}\nSCALARS {name} float 1\n\
         LOOKUP_TABLE default\n{}\n",
        dims[0],
        dims[1],
        dims[2],
        values.join(" ")
    );
    std::fs::write(path, text).expect("write");
}

#[test]
fn info_validates_what_it_builds_as_render_does() {
    let d = dir("info-validates");
    // Spacings that render refuses: info describes the file, says why nothing more is built,
    // and neither panics nor runs away.
    for (name, spacing) in [
        ("tiny.vtk", "1 1e-308 1"),
        ("small.vtk", "1e-30 1e-30 1e-30"),
    ] {
        let path = d.join(name);
        legacy(&path, [8, 7, 6], spacing, "v");
        let out = vmls(&["info", s(&path)]);
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(text.contains("dimensions: 8 × 7 × 6"), "{text}");
        assert!(
            text.contains("render: refused") && text.contains("extent along"),
            "{text}"
        );
        assert!(!text.contains("octree"), "{text}");
        let png = d.join("x.png");
        let key = format!("volume.file=\"{}\"", s(&path));
        let out = vmls(&["render", "-o", s(&png), "--set", &key]);
        assert_fails(&out, &[name, "extent along"], &png);
    }
    // A regular grid is described without an octree, which the renderer would not build.
    let grid = d.join("grid.vtk");
    legacy(&grid, [6, 5, 4], "0.5 0.5 0.5", "v");
    let out = vmls(&["info", s(&grid)]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert!(text.contains("neighbours: implicit regular grid"), "{text}");
    assert!(!text.contains("octree:"), "{text}");
    // Asking for the octree builds it, as the renderer would.
    let out = vmls(&[
        "info",
        s(&grid),
        "--set",
        "reconstruction.neighbours=\"octree\"",
    ]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("octree: "), "{text}");
}

#[test]
fn info_escapes_and_cuts_names() {
    let d = dir("info-names");
    // VTK percent-encodes names: %1B is an escape character once decoded.
    let hostile = d.join("esc.vtk");
    let long = "n".repeat(300_000);
    legacy(&hostile, [2, 2, 2], "1 1 1", &format!("a%1B[31mred{long}"));
    let out = vmls(&["info", s(&hostile)]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert!(!text.contains('\u{1b}'), "raw escape in: {}", &text[..200]);
    assert!(text.contains("\\u{1b}[31mred"), "{}", &text[..400]);
    assert!(text.len() < 4000, "{} characters", text.len());
}

#[test]
fn malformed_inputs_get_one_clear_line() {
    let d = dir("malformed");
    let png = d.join("x.png");
    let render = |file: &Path| {
        let key = format!("volume.file=\"{}\"", s(file));
        vmls(&["render", "-o", s(&png), "--set", &key])
    };
    // A NRRD direction of infinite length.
    let nrrd = d.join("inf.nrrd");
    let mut bytes = b"NRRD0004\ntype: float\ndimension: 3\nsizes: 2 2 2\n\
        space directions: (inf,0,0) (0,1,0) (0,0,1)\nendian: little\nencoding: raw\n\n"
        .to_vec();
    bytes.extend((0..8).flat_map(|i| (i as f32).to_le_bytes()));
    std::fs::write(&nrrd, &bytes).expect("write");
    assert_fails(
        &render(&nrrd),
        &["inf.nrrd", "line 5", "space direction"],
        &png,
    );
    // Zero dimensions are not "too large".
    let zero = d.join("zero.vtk");
    std::fs::write(
        &zero,
        "# vtk DataFile Version 3.0\nt\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 0 8 8\n",
    )
    .expect("write");
    let out = render(&zero);
    assert_fails(&out, &["at least 1"], &png);
    assert!(!String::from_utf8_lossy(&out.stderr).contains("too large"));
    // VTK 5.1 cells with no offsets: the line that was read is quoted.
    let cells = d.join("cells.vtk");
    std::fs::write(
        &cells,
        "# vtk DataFile Version 5.1\nt\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n\
         0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 0 0\nOFFSETS vtktypeint64\nCONNECTIVITY vtktypeint64\n\
         CELL_TYPES 0\n",
    )
    .expect("write");
    let out = render(&cells);
    assert_fails(&out, &["cells.vtk", "at least 1 offset"], &png);
    // No scalar values at all.
    let csv = d.join("points.csv");
    std::fs::write(&csv, "x,y,z,name\n0,0,0,a\n1,0,0,b\n0,1,0,c\n0,0,1,d\n").expect("write");
    let out = render(&csv);
    assert_fails(&out, &["points.csv", "no scalar values"], &png);
    assert!(!String::from_utf8_lossy(&out.stderr).contains("(any scalar array)"));
    // A PLY naming a property twice.
    let ply = d.join("twice.ply");
    std::fs::write(
        &ply,
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float x\n\
         property float y\nproperty float z\nend_header\n0 0 0 0\n1 1 0 0\n0 0 1 0\n0 0 0 1\n",
    )
    .expect("write");
    assert_fails(&render(&ply), &["twice.ply", "line 5", "'x' twice"], &png);
    // A kind vmls does not read is named unsupported.
    let htg = d.join("tree.vti");
    std::fs::write(
        &htg,
        "<VTKFile type=\"HyperTreeGrid\" version=\"1.0\"><HyperTreeGrid/></VTKFile>",
    )
    .expect("write");
    let e = vmls::data::load_dataset(&htg).expect_err("unsupported");
    assert!(
        e.to_string()
            .contains("unsupported VTKFile type HyperTreeGrid"),
        "{e}"
    );
}

#[test]
fn scene_keys_that_would_be_ignored_are_refused() {
    let d = dir("ignored-keys");
    let png = d.join("x.png");
    let run = |extra: &[&str]| vmls(&small_render(&png, extra));
    let out = run(&[
        "--set",
        "render.skip=true",
        "--set",
        "reconstruction.resample=0",
    ]);
    assert_fails(&out, &["render.skip", "fast path"], &png);
    let out = run(&[
        "--set",
        "render.skip=true",
        "--set",
        "render.method=\"splat\"",
    ]);
    assert_fails(&out, &["render.skip", "splatting"], &png);
    let out = run(&["--set", "camera.width=8\ncamera.height = 900"]);
    assert_fails(&out, &["one line", "newline"], &png);
    let out = run(&["--set", "volume.scalars=[1, 2]"]);
    assert_fails(&out, &["volume.scalars", "generated volume"], &png);
    let out = run(&["--frames", "0"]);
    assert_ne!(out.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--frames"));
    assert!(!png.exists());
}

#[cfg(unix)]
#[test]
fn compare_judges_the_names_before_reading() {
    let d = dir("compare-names");
    // A sparse file past the image size limit: the extension is refused before its size.
    let big = d.join("big.txt");
    let f = std::fs::File::create(&big).expect("create");
    f.set_len(5 << 30).expect("sparse");
    let png = d.join("a.png");
    image::RgbaImage::new(2, 2).save(&png).expect("png");
    let out = vmls(&["compare", s(&big), s(&png)]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{e}");
    assert!(
        e.contains("big.txt") && e.contains("unsupported input format"),
        "{e}"
    );
}

#[test]
fn imported_rows_are_printed_escaped() {
    let d = dir("import-escaped");
    let csv = d.join("peer.csv");
    let header = "source,method,settings,device,driver,vmls_version,commit,width,height,frames,\
                  gpu_ms,gpu_ms_min,gpu_ms_max,kernel_ms,wall_ms,first_frame_wall_ms,\
                  first_frame_gpu_ms,prepare_ms,evaluations,evaluations_per_s,\
                  bytes_uploaded_first,bytes_uploaded_next,rmse,max_abs,max_x,max_y,psnr,\
                  non_finite,reference,variant,fma_share,memory_share,bound_by";
    let row = "\"peer\u{1b}]0;owned\u{7}\",\"m\u{1b}[2J\",\"a=\u{1b}[31m\",dev,drv,0,c,8,8,1,\
               ,,,,5.0,5.0,,0,,,,,,,,,,,ref,v,,,\"x\u{1b}[5m\"";
    std::fs::write(&csv, format!("{header}\n{row}\n")).expect("write");
    let out = d.join("out");
    let run = vmls(&quick_bench(&out, &["--import", s(&csv)]));
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(text.contains("imported from peer"), "{text}");
    assert!(
        !text.contains('\u{1b}') && !text.contains('\u{7}'),
        "{text:?}"
    );
}
