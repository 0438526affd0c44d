//! VTK XML loader: fixtures written by VTK 9 itself (tools/fixtures/vtk_xml.py, every kind in
//! every encoding) checked value by value against the analytic fields the script wrote, and
//! malformed variants derived from those fixtures inside the tests.

use std::path::{Path, PathBuf};
use vmls::data::dataset::{CellType, Dataset, Geometry, Location};
use vmls::data::{self, DataError, vtk_xml};

const ENCODINGS: [&str; 8] = [
    "ascii",
    "binary",
    "binary_zlib",
    "appended",
    "appended_zlib",
    "big_endian",
    "appended_base64",
    "binary_zlib_blocks",
];

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/xml")
        .join(name)
}

fn load(name: &str) -> Dataset {
    let path = fixture(name);
    vtk_xml::load(&path).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Point array "f" = x + 2y + 3z, "g" = point id within its piece (`per_piece` points each),
/// cell array "cell_id" = cell index within its piece (`cells` when the kind keeps cell data).
fn check_arrays(name: &str, d: &Dataset, per_piece: usize, cells: Option<usize>) {
    let n = d.geometry.point_count();
    let names: Vec<&str> = d.arrays.iter().map(|a| a.name.as_str()).collect();
    let expected: &[&str] = if cells.is_some() {
        &["f", "g", "cell_id"]
    } else {
        &["f", "g"]
    };
    assert_eq!(names, expected, "{name}: arrays in file order");
    let f = &d.arrays[0];
    assert_eq!(
        (f.location, f.components, f.values.len()),
        (Location::Point, 1, n)
    );
    for i in 0..n {
        let [x, y, z] = d.geometry.point(i);
        assert_eq!(
            f.values.get(i),
            (x + 2.0 * y + 3.0 * z) as f32,
            "{name}: f at point {i}"
        );
    }
    let g = &d.arrays[1];
    assert_eq!((g.location, g.components), (Location::Point, 3), "{name}");
    for (i, v) in g.values.iter().enumerate() {
        assert_eq!(v, (i % per_piece) as f32, "{name}: g at point {i}");
    }
    if let Some(per_piece) = cells {
        let c = &d.arrays[2];
        assert_eq!(c.location, Location::Cell, "{name}");
        assert_eq!(c.values.len(), d.geometry.cell_count(), "{name}");
        for (i, v) in c.values.iter().enumerate() {
            assert_eq!(v, (i % per_piece) as f32, "{name}: cell_id at cell {i}");
        }
    }
}

#[test]
fn fixtures_cover_the_encodings_they_claim() {
    let text =
        |name: &str| String::from_utf8_lossy(&std::fs::read(fixture(name)).unwrap()).into_owned();
    for ext in ["vti", "vtr", "vts", "vtu", "vtp"] {
        let head = |enc: &str| text(&format!("{ext}_{enc}.{ext}"));
        assert!(head("ascii").contains("format=\"ascii\""));
        assert!(head("binary").contains("format=\"binary\"") && head("binary").contains("UInt32"));
        assert!(
            head("binary_zlib").contains("vtkZLibDataCompressor")
                && head("binary_zlib").contains("UInt64")
        );
        assert!(head("appended").contains("encoding=\"raw\""));
        assert!(
            head("appended_zlib").contains("encoding=\"raw\"")
                && head("appended_zlib").contains("vtkZLib")
        );
        assert!(head("big_endian").contains("BigEndian"));
        assert!(head("appended_base64").contains("encoding=\"base64\""));
        assert!(
            head("binary_zlib_blocks").contains("BigEndian")
                && head("binary_zlib_blocks").contains("UInt32")
        );
    }
}

#[test]
fn image_data_all_encodings() {
    for enc in ENCODINGS {
        let name = format!("vti_{enc}.vti");
        let d = load(&name);
        // WholeExtent 1..4 × 0..2 × 0..1: the first point lies one x-step past Origin.
        let want = Geometry::Image {
            dims: [4, 3, 2],
            origin: [1.5, -2.0, 0.5],
            spacing: [0.5, 0.25, 2.0],
        };
        assert_eq!(d.geometry, want, "{name}");
        check_arrays(&name, &d, 24, Some(6));
    }
}

#[test]
fn rectilinear_grid_all_encodings() {
    for enc in ENCODINGS {
        let name = format!("vtr_{enc}.vtr");
        let d = load(&name);
        let want = Geometry::Rectilinear {
            coords: [
                vec![0.0, 0.5, 1.5, 3.0],
                vec![-1.0, 0.0, 2.0],
                vec![0.0, 1.25],
            ],
        };
        assert_eq!(d.geometry, want, "{name}");
        check_arrays(&name, &d, 24, Some(6));
    }
}

#[test]
fn structured_grid_all_encodings() {
    let mut want = Vec::new();
    for k in 0..2 {
        for j in 0..3 {
            for i in 0..3 {
                let (i, j, k) = (i as f64, j as f64, k as f64);
                want.push([i + 0.125 * j, j + 0.25 * i * k, 1.5 * k + 0.125 * i]);
            }
        }
    }
    for enc in ENCODINGS {
        let name = format!("vts_{enc}.vts");
        let d = load(&name);
        let want = Geometry::Structured {
            dims: [3, 3, 2],
            points: want.clone(),
        };
        assert_eq!(d.geometry, want, "{name}");
        check_arrays(&name, &d, 18, Some(4));
    }
}

const VTU_POINTS: [[f64; 3]; 21] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [1.0, 1.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
    [1.0, 0.0, 1.0],
    [1.0, 1.0, 1.0],
    [0.0, 1.0, 1.0],
    [2.0, 0.0, 0.0],
    [2.0, 1.0, 0.0],
    [2.0, 0.0, 1.0],
    [2.0, 1.0, 1.0],
    [0.5, 0.5, 2.0],
    [3.0, 0.0, 0.0],
    [4.0, 0.0, 0.0],
    [3.0, 1.0, 0.0],
    [4.0, 1.0, 0.0],
    [3.0, 0.0, 0.5],
    [4.0, 0.0, 0.5],
    [3.0, 1.0, 0.5],
    [4.0, 1.0, 0.5],
];

fn vtu_cells() -> Vec<(CellType, Vec<u32>)> {
    vec![
        (CellType::Hexahedron, vec![0, 1, 2, 3, 4, 5, 6, 7]),
        (CellType::Tetra, vec![1, 8, 2, 5]),
        (CellType::Wedge, vec![1, 8, 2, 5, 10, 6]),
        (CellType::Pyramid, vec![4, 5, 6, 7, 12]),
        (CellType::Voxel, vec![13, 14, 15, 16, 17, 18, 19, 20]),
    ]
}

fn check_vtu(name: &str, d: &Dataset, pieces: usize) {
    let Geometry::Unstructured { points, cells } = &d.geometry else {
        panic!("{name}: {:?}", d.geometry.kind());
    };
    assert_eq!(points.len(), 21 * pieces, "{name}");
    assert_eq!(cells.len(), 5 * pieces, "{name}");
    for p in 0..pieces {
        assert_eq!(
            &points[21 * p..21 * (p + 1)],
            &VTU_POINTS[..],
            "{name}: piece {p}"
        );
        for (c, (kind, ids)) in vtu_cells().into_iter().enumerate() {
            let cell = 5 * p + c;
            assert_eq!(cells.types[cell], kind, "{name}: cell {cell}");
            // Piece p's indices are offset by the 21 points of each piece before it.
            let shifted: Vec<u32> = ids.iter().map(|i| i + 21 * p as u32).collect();
            assert_eq!(cells.cell(cell), &shifted[..], "{name}: cell {cell}");
        }
    }
    check_arrays(name, d, 21, Some(5));
}

#[test]
fn unstructured_grid_all_encodings() {
    for enc in ENCODINGS {
        let name = format!("vtu_{enc}.vtu");
        check_vtu(&name, &load(&name), 1);
    }
}

#[test]
fn unstructured_grid_pieces_are_merged() {
    check_vtu("vtu_pieces.vtu", &load("vtu_pieces.vtu"), 2);
}

fn vtp_points() -> Vec<[f64; 3]> {
    (0..7)
        .map(|i| [0.125 * i as f64, 0.5 * (i % 3) as f64, -0.25 * i as f64])
        .collect()
}

#[test]
fn poly_data_all_encodings() {
    for enc in ENCODINGS {
        let name = format!("vtp_{enc}.vtp");
        let d = load(&name);
        let want = Geometry::Points {
            points: vtp_points(),
        };
        assert_eq!(d.geometry, want, "{name}");
        check_arrays(&name, &d, 7, None);
    }
    let d = load("vtp_pieces.vtp");
    let Geometry::Points { points } = &d.geometry else {
        panic!("{:?}", d.geometry.kind());
    };
    assert_eq!(points.len(), 21);
    assert_eq!(points[14..], vtp_points()[..]);
    check_arrays("vtp_pieces.vtp", &d, 7, None);
}

#[test]
fn load_dataset_dispatches_every_extension() {
    for (name, kind) in [
        ("vti_binary.vti", "regular grid"),
        ("vtr_binary.vtr", "rectilinear grid"),
        ("vts_binary.vts", "curvilinear grid"),
        ("vtu_binary.vtu", "unstructured mesh"),
        ("vtp_binary.vtp", "scattered points"),
    ] {
        let d = data::load_dataset(&fixture(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(d.geometry.kind(), kind, "{name}");
    }
}

// ---- malformed variants, derived from the fixtures ----

fn original(name: &str) -> Vec<u8> {
    std::fs::read(fixture(name)).unwrap()
}

fn find(bytes: &[u8], what: &str) -> usize {
    bytes
        .windows(what.len())
        .position(|w| w == what.as_bytes())
        .unwrap_or_else(|| panic!("'{what}' not in the fixture"))
}

/// `bytes` with the first `from` after byte `after` replaced by `to`.
fn replace_after(bytes: &[u8], after: usize, from: &str, to: &str) -> Vec<u8> {
    let at = after + find(&bytes[after..], from);
    [&bytes[..at], to.as_bytes(), &bytes[at + from.len()..]].concat()
}

fn replace(bytes: &[u8], from: &str, to: &str) -> Vec<u8> {
    replace_after(bytes, 0, from, to)
}

/// Loads `bytes` written as `name` (which should fail) and checks the message names the file.
fn fails(name: &str, bytes: &[u8]) -> DataError {
    let dir = std::env::temp_dir().join(format!("vmls-loaders-xml-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    let result = vtk_xml::load(&path);
    let _ = std::fs::remove_file(&path);
    let err = match result {
        Ok(d) => panic!("{name} loaded: {:?}", d.geometry.kind()),
        Err(e) => e,
    };
    let message = err.to_string();
    assert!(
        message.contains(name),
        "{name}: message does not name the file: {message}"
    );
    err
}

/// Where the raw appended data starts (after the `_`), and the `offset` of array `array`.
fn appended_array(bytes: &[u8], array: &str) -> usize {
    let start = find(bytes, "<AppendedData");
    let start = start + find(&bytes[start..], "_") + 1;
    let tag = find(bytes, &format!("Name=\"{array}\""));
    let off = tag + find(&bytes[tag..], "offset=\"") + 8;
    let len = bytes[off..].iter().position(|&b| b == b'"').unwrap();
    let offset: usize = std::str::from_utf8(&bytes[off..off + len])
        .unwrap()
        .parse()
        .unwrap();
    start + offset
}

#[test]
fn truncated_base64_is_truncated() {
    let bytes = original("vtu_binary.vtu");
    let tag = find(&bytes, "Name=\"f\"");
    let start = tag + find(&bytes[tag..], ">") + 1;
    let start = start
        + bytes[start..]
            .iter()
            .position(|b| !b.is_ascii_whitespace())
            .unwrap();
    let len = bytes[start..].iter().position(|&b| b == b'\n').unwrap();
    let cut = [&bytes[..start + len / 2], &bytes[start + len..]].concat();
    let err = fails("truncated_base64.vtu", &cut);
    assert!(
        matches!(err, DataError::Truncated { expected: 168, found, .. } if found < 168),
        "{err}"
    );
}

#[test]
fn bad_base64_character_is_a_format_error() {
    let bytes = original("vtu_binary.vtu");
    let bad = replace(&bytes, "qAAAAAAA", "qAAA*AAA");
    let err = fails("bad_base64.vtu", &bad);
    assert!(
        matches!(err, DataError::Format { ref expected, .. } if expected.contains("base64")),
        "{err}"
    );
}

#[test]
fn bad_zlib_stream_is_a_format_error() {
    let mut bytes = original("vtu_appended_zlib.vtu");
    // Array "f" has one block: 4 UInt64 header words, then the zlib stream.
    let at = appended_array(&bytes, "f") + 32;
    assert_eq!(bytes[at], 0x78, "zlib header");
    bytes[at..at + 6].copy_from_slice(&[0xff; 6]);
    let err = fails("bad_zlib.vtu", &bytes);
    assert!(
        matches!(err, DataError::Format { ref expected, .. } if expected.contains("zlib")),
        "{err}"
    );
}

#[test]
fn byte_count_header_bigger_than_the_data_is_truncated() {
    // Uncompressed: the connectivity's length comes only from its UInt32 byte-count header.
    let mut bytes = original("vtu_appended.vtu");
    let at = appended_array(&bytes, "connectivity");
    assert_eq!(bytes[at..at + 4], 248u32.to_le_bytes(), "31 Int64 indices");
    bytes[at..at + 4].copy_from_slice(&1_000_000u32.to_le_bytes());
    let err = fails("lying_header.vtu", &bytes);
    assert!(
        matches!(
            err,
            DataError::Truncated {
                expected: 1_000_000,
                ..
            }
        ),
        "{err}"
    );

    // Compressed: a block claims more compressed bytes than the file holds.
    let mut bytes = original("vtu_appended_zlib.vtu");
    let at = appended_array(&bytes, "connectivity");
    assert_eq!(bytes[at..at + 8], 1u64.to_le_bytes(), "one block");
    bytes[at + 24..at + 32].copy_from_slice(&(1u64 << 40).to_le_bytes());
    let err = fails("lying_block_size.vtu", &bytes);
    assert!(
        matches!(err, DataError::Truncated { expected, .. } if expected == 1 << 40),
        "{err}"
    );
}

#[test]
fn block_inflating_past_its_header_is_rejected() {
    let mut bytes = original("vtu_appended_zlib.vtu");
    let at = appended_array(&bytes, "connectivity");
    // One block of 248 bytes, recorded as the (partial) last block size.
    assert_eq!(bytes[at + 16..at + 24], 248u64.to_le_bytes());
    bytes[at + 16..at + 24].copy_from_slice(&240u64.to_le_bytes());
    let err = fails("zip_bomb.vtu", &bytes);
    assert!(
        matches!(err, DataError::Format { ref expected, .. } if expected.contains("inflate to 240")),
        "{err}"
    );
}

#[test]
fn wrong_value_counts_are_format_errors() {
    let bytes = original("vti_ascii.vti");
    let short = replace(&bytes, "-1 -0.5 0 0.5", "-0.5 0 0.5");
    let err = fails("short_ascii.vti", &short);
    assert!(
        matches!(err, DataError::Format { ref expected, ref found, .. }
            if expected == "24 values" && found == "23 values"),
        "{err}"
    );
    let long = replace(&bytes, "-1 -0.5 0 0.5", "-1 -0.5 0 0.5 4");
    let err = fails("long_ascii.vti", &long);
    assert!(
        matches!(err, DataError::Format { ref expected, .. } if expected == "24 values"),
        "{err}"
    );

    // Binary: the header's byte count disagrees with NumberOfPoints.
    let bytes = original("vtu_binary.vtu");
    let fewer = replace(&bytes, "NumberOfPoints=\"21\"", "NumberOfPoints=\"20\"");
    let err = fails("wrong_count.vtu", &fewer);
    assert!(
        matches!(err, DataError::Format { ref expected, .. } if expected.starts_with("160 bytes")),
        "{err}"
    );
}

#[test]
fn connectivity_index_out_of_range() {
    let bytes = original("vtu_ascii.vtu");
    let at = find(&bytes, "Name=\"connectivity\"");
    let bad = replace_after(&bytes, at, ">\n          0 ", ">\n          99 ");
    let err = fails("index_out_of_range.vtu", &bad);
    assert!(
        matches!(
            err,
            DataError::IndexOutOfRange {
                cell: 0,
                index: 99,
                points: 21,
                ..
            }
        ),
        "{err}"
    );
    let bytes = original("vtp_ascii.vtp");
    let at = find(&bytes, "<Verts>");
    let bad = replace_after(&bytes, at, "0 1 2", "0 70 2");
    let err = fails("vert_out_of_range.vtp", &bad);
    assert!(
        matches!(
            err,
            DataError::IndexOutOfRange {
                cell: 1,
                index: 70,
                points: 7,
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn triangle_in_an_unstructured_grid_is_unsupported() {
    let bad = replace(
        &original("vtu_ascii.vtu"),
        "12 10 13 14 11",
        "12 10 5 14 11",
    );
    let err = fails("triangle.vtu", &bad);
    assert!(
        matches!(err, DataError::UnsupportedCell { id: 5, name: "VTK_TRIANGLE", ref location, .. }
            if location.starts_with("cell 2 ")),
        "{err}"
    );
}

#[test]
fn non_finite_points_and_values_are_rejected() {
    let bad = replace(
        &original("vtu_ascii.vtu"),
        "0.5 0.5 2 3 0 0",
        "nan 0.5 2 3 0 0",
    );
    let err = fails("nan_point.vtu", &bad);
    assert!(
        matches!(err, DataError::NonFiniteCoordinate { index: 12, .. }),
        "{err}"
    );
    let bad = replace(&original("vti_ascii.vti"), "-1 -0.5 0 0.5", "-1 inf 0 0.5");
    let err = fails("inf_value.vti", &bad);
    assert!(
        matches!(err, DataError::NonFiniteValue { ref array, index: 1, .. } if array == "f"),
        "{err}"
    );
}

#[test]
fn missing_points_is_a_format_error() {
    let bytes = original("vtu_ascii.vtu");
    let (a, b) = (find(&bytes, "<Points>"), find(&bytes, "</Points>") + 9);
    let bad = [&bytes[..a], &bytes[b..]].concat();
    let err = fails("no_points.vtu", &bad);
    assert!(
        matches!(err, DataError::Format { ref expected, .. } if expected.contains("<Points>")),
        "{err}"
    );
}

#[test]
fn unknown_compressor_is_unsupported() {
    let bad = replace(
        &original("vtu_binary_zlib.vtu"),
        "vtkZLibDataCompressor",
        "vtkLZ4DataCompressor",
    );
    let err = fails("lz4.vtu", &bad);
    assert!(
        matches!(err, DataError::Unsupported { ref what, .. } if what.contains("vtkLZ4DataCompressor")),
        "{err}"
    );
}

#[test]
fn rotated_or_split_grids_are_unsupported() {
    let bytes = original("vti_ascii.vti");
    let bad = replace(
        &bytes,
        "Direction=\"1 0 0 0 1 0 0 0 1\"",
        "Direction=\"0 1 0 -1 0 0 0 0 1\"",
    );
    let err = fails("rotated.vti", &bad);
    assert!(
        matches!(err, DataError::Unsupported { ref what, .. } if what.contains("Direction")),
        "{err}"
    );
    let (a, b) = (find(&bytes, "<Piece"), find(&bytes, "</Piece>") + 8);
    let twice = [&bytes[..b], &bytes[a..]].concat();
    let err = fails("two_pieces.vti", &twice);
    assert!(
        matches!(err, DataError::Unsupported { ref what, .. } if what.contains("2 pieces")),
        "{err}"
    );
}

#[test]
fn absurd_sizes_are_rejected_before_allocating() {
    let bytes = original("vti_binary.vti");
    let huge = "0 2000000 0 2000000 0 2000000";
    let bad = replace(&replace(&bytes, "1 4 0 2 0 1", huge), "1 4 0 2 0 1", huge);
    let err = fails("huge_extent.vti", &bad);
    assert!(matches!(err, DataError::TooLarge { .. }), "{err}");
    let bad = replace(
        &original("vtu_binary.vtu"),
        "NumberOfPoints=\"21\"",
        "NumberOfPoints=\"99999999999\"",
    );
    let err = fails("huge_points.vtu", &bad);
    assert!(
        matches!(err, DataError::Format { ref expected, .. } if expected.contains("NumberOfPoints")),
        "{err}"
    );
}

#[test]
fn broken_structure_is_a_format_error() {
    // Cut before <AppendedData>: the arrays point into data that is not there.
    let bytes = original("vtu_appended.vtu");
    let cut = [&bytes[..find(&bytes, "<AppendedData")], b"</VTKFile>"].concat();
    let err = fails("no_appended.vtu", &cut);
    assert!(
        matches!(err, DataError::Format { ref expected, .. } if expected.contains("AppendedData")),
        "{err}"
    );
    // Raw appended data cut short.
    let err = fails("short_appended.vtu", &bytes[..bytes.len() - 200]);
    assert!(matches!(err, DataError::Truncated { .. }), "{err}");
    // XML cut in the middle of the document.
    let bytes = original("vtu_ascii.vtu");
    let err = fails("unclosed.vtu", &bytes[..bytes.len() / 2]);
    assert!(matches!(err, DataError::Format { .. }), "{err}");
    // Pieces must carry the same arrays.
    let bytes = original("vtu_pieces.vtu");
    let second = find(&bytes, "</Piece>");
    let bad = replace_after(&bytes, second, "Name=\"g\"", "Name=\"h\"");
    let err = fails("mismatched_pieces.vtu", &bad);
    assert!(
        matches!(err, DataError::Format { ref expected, .. } if expected.contains("first piece")),
        "{err}"
    );
}
