//! Loaders of irregular data: every VTK legacy dataset type (fixtures written by VTK itself in
//! tests/data/legacy, see tools/fixtures/vtk_legacy.py, plus files built byte by byte here for
//! the other layouts and the malformed cases), CSV and PLY points.

use std::path::{Path, PathBuf};
use vmls::data::dataset::{CellType, DataArray, Dataset, Geometry, Location};
use vmls::data::{self, DataError, vtk};

// ---------------------------------------------------------------- helpers

/// A file in the temporary directory, deleted when dropped.
struct TempFile(PathBuf);

impl std::ops::Deref for TempFile {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Writes `bytes` to a temporary file whose name ends with `name` (the extension picks the
/// reader); the process id keeps concurrent test runs apart.
fn file(name: &str, bytes: &[u8]) -> TempFile {
    let pid = std::process::id();
    let path = std::env::temp_dir().join(format!("vmls-irregular-{pid}-{name}"));
    std::fs::write(&path, bytes).unwrap();
    TempFile(path)
}

fn load(name: &str, bytes: &[u8]) -> Dataset {
    let path = file(name, bytes);
    data::load_dataset(&path).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Loads `bytes` saved as `name` and checks the error's variant (by its Debug name) and that
/// its message names the file and contains `text`.
fn fails(name: &str, bytes: &[u8], variant: &str, text: &str) -> DataError {
    let path = file(name, bytes);
    let e = data::load_dataset(&path).unwrap_err();
    assert!(
        format!("{e:?}").starts_with(variant),
        "{name}: expected {variant}, got {e:?}"
    );
    let msg = e.to_string();
    let shown = path.file_name().unwrap().to_string_lossy().into_owned();
    assert!(msg.contains(&shown), "{msg:?} does not name {shown}");
    assert!(msg.contains(text), "{msg:?} lacks {text:?}");
    e
}

fn array<'a>(d: &'a Dataset, name: &str) -> &'a DataArray {
    d.arrays
        .iter()
        .find(|a| a.name == name)
        .unwrap_or_else(|| panic!("no array {name} in {:?}", names(d)))
}

fn names(d: &Dataset) -> Vec<(&str, Location)> {
    d.arrays
        .iter()
        .map(|a| (a.name.as_str(), a.location))
        .collect()
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/legacy")
        .join(name)
}

// ---------------------------------------------------------------- VTK fixtures written by VTK

/// The arrays every fixture carries (see the script): f = x + 2y + 3z, g = point id (first of
/// two components), cid = 100 + cell id; VECTORS "v" is never an array.
fn check_fixture_arrays(d: &Dataset, cell_data: bool) {
    let n = d.geometry.point_count();
    let f = array(d, "f");
    assert_eq!(
        (f.location, f.components, f.values.len()),
        (Location::Point, 1, n)
    );
    for i in 0..n {
        let [x, y, z] = d.geometry.point(i);
        assert_eq!(
            f.values.get(i),
            (x + 2.0 * y + 3.0 * z) as f32,
            "f at point {i}"
        );
    }
    let g = array(d, "g");
    assert_eq!((g.location, g.components), (Location::Point, 2));
    assert_eq!(g.values, (0..n).map(|i| i as f32).collect::<Vec<_>>());
    assert!(d.arrays.iter().all(|a| a.name != "v"), "{:?}", names(d));
    if cell_data {
        let cid = array(d, "cid");
        assert_eq!(cid.location, Location::Cell);
        let want: Vec<f32> = (0..d.geometry.cell_count())
            .map(|c| 100.0 + c as f32)
            .collect();
        assert_eq!(cid.values, want);
        assert_eq!(d.arrays.len(), 3);
    } else {
        assert_eq!(d.arrays.len(), 2, "{:?}", names(d));
    }
}

fn for_each_fixture(kind: &str, check: impl Fn(&Dataset)) {
    for version in ["42", "51"] {
        for enc in ["ascii", "binary"] {
            let path = fixture(&format!("{kind}-{version}-{enc}.vtk"));
            let d = data::load_dataset(&path).unwrap_or_else(|e| panic!("{e}"));
            check(&d);
        }
    }
}

#[test]
fn vtk_fixture_structured_points() {
    for_each_fixture("image", |d| {
        let want = Geometry::Image {
            dims: [3, 4, 2],
            origin: [-1.0, 0.5, 2.0],
            spacing: [0.5, 0.25, 2.0],
        };
        assert_eq!(d.geometry, want);
        assert_eq!(d.geometry.cell_count(), 6);
        check_fixture_arrays(d, true);
    });
    // The volume API still reads it, taking the first scalar point array.
    let v = vtk::load(&fixture("image-51-binary.vtk"), None).unwrap();
    assert_eq!((v.dims, v.values.get(1)), ([3, 4, 2], 6.5));
}

#[test]
fn vtk_fixture_rectilinear_grid() {
    for_each_fixture("rectilinear", |d| {
        let coords = [
            vec![0.0, 0.5, 2.0],
            vec![-1.0, 0.0, 1.0, 3.0],
            vec![0.0, 10.0],
        ];
        assert_eq!(d.geometry, Geometry::Rectilinear { coords });
        check_fixture_arrays(d, true);
    });
}

#[test]
fn vtk_fixture_structured_grid() {
    for_each_fixture("structured", |d| {
        let Geometry::Structured { dims, points } = &d.geometry else {
            panic!("{:?}", d.geometry.kind());
        };
        assert_eq!(*dims, [3, 3, 2]);
        let mut want = Vec::new();
        for k in 0..2 {
            for j in 0..3 {
                for i in 0..3 {
                    let (i, j, k) = (i as f64, j as f64, k as f64);
                    want.push([i + 0.125 * j, j + 0.25 * k, 0.5 * k + 0.0625 * i]);
                }
            }
        }
        assert_eq!(*points, want);
        check_fixture_arrays(d, true);
    });
}

#[test]
fn vtk_fixture_unstructured_grid_classic_and_51_cells() {
    for_each_fixture("unstructured", |d| {
        let Geometry::Unstructured { points, cells } = &d.geometry else {
            panic!("{:?}", d.geometry.kind());
        };
        assert_eq!(points.len(), 16);
        assert_eq!(points[13], [0.5, 0.5, 0.5]);
        use CellType::*;
        assert_eq!(cells.types, [Hexahedron, Voxel, Tetra, Wedge, Pyramid]);
        assert_eq!(cells.offsets, [0, 8, 16, 20, 26, 31]);
        assert_eq!(cells.cell(0), [0, 1, 5, 4, 8, 9, 13, 12]);
        assert_eq!(cells.cell(2), [2, 3, 6, 10]);
        assert_eq!(cells.cell(4), [10, 11, 15, 14, 3]);
        check_fixture_arrays(d, true);
    });
}

#[test]
fn vtk_fixture_polydata_points_all_kept_cell_data_dropped() {
    for_each_fixture("polydata", |d| {
        let Geometry::Points { points } = &d.geometry else {
            panic!("{:?}", d.geometry.kind());
        };
        // Point 6 is referenced by a line only, point 5 by no vertex: both stay samples.
        let want: Vec<[f64; 3]> = (0..7)
            .map(|i| [0.25 * i as f64, 0.5 * (i % 3) as f64, -0.125 * i as f64])
            .collect();
        assert_eq!(*points, want);
        check_fixture_arrays(d, false);
    });
}

// ---------------------------------------------------------------- VTK files built here

#[derive(Clone, Copy)]
enum Ty {
    I32,
    I64,
    F32,
    F64,
}

/// `values` as ASCII text or big-endian binary of type `ty`, ended by a newline.
fn nums(binary: bool, ty: Ty, values: &[f64]) -> Vec<u8> {
    let mut out = Vec::new();
    if binary {
        for &v in values {
            match ty {
                Ty::I32 => out.extend((v as i32).to_be_bytes()),
                Ty::I64 => out.extend((v as i64).to_be_bytes()),
                Ty::F32 => out.extend((v as f32).to_be_bytes()),
                Ty::F64 => out.extend(v.to_be_bytes()),
            }
        }
    } else {
        let words: Vec<String> = values.iter().map(|v| v.to_string()).collect();
        out.extend(words.join(" ").bytes());
    }
    out.push(b'\n');
    out
}

fn head(binary: bool, kind: &str) -> Vec<u8> {
    let form = if binary { "BINARY" } else { "ASCII" };
    format!("# vtk DataFile Version 5.1\nbuilt by hand\n{form}\nDATASET {kind}\n").into_bytes()
}

/// Five points of a pyramid and a tetra sharing its base corner 0.
const PTS: [f64; 15] = [0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0., 0.5, 0.5, 1.];

/// Cells as (type, points), written in the classic or the 5.1 layout.
fn cells_section(binary: bool, modern: bool, cells: &[(u32, &[u32])]) -> Vec<u8> {
    let size: usize = cells.iter().map(|c| c.1.len()).sum();
    let mut b = Vec::new();
    if modern {
        b.extend(format!("CELLS {} {size}\nOFFSETS vtktypeint64\n", cells.len() + 1).bytes());
        let mut offsets = vec![0.0];
        for c in cells {
            offsets.push(offsets.last().unwrap() + c.1.len() as f64);
        }
        b.extend(nums(binary, Ty::I64, &offsets));
        b.extend(b"CONNECTIVITY vtktypeint64\n");
        let conn: Vec<f64> = cells
            .iter()
            .flat_map(|c| c.1.iter().map(|&p| p as f64))
            .collect();
        b.extend(nums(binary, Ty::I64, &conn));
    } else {
        b.extend(format!("CELLS {} {}\n", cells.len(), size + cells.len()).bytes());
        let flat: Vec<f64> = cells
            .iter()
            .flat_map(|c| std::iter::once(c.1.len() as f64).chain(c.1.iter().map(|&p| p as f64)))
            .collect();
        b.extend(nums(binary, Ty::I32, &flat));
    }
    b.extend(format!("CELL_TYPES {}\n", cells.len()).bytes());
    let types: Vec<f64> = cells.iter().map(|c| c.0 as f64).collect();
    b.extend(nums(binary, Ty::I32, &types));
    b
}

/// An unstructured grid of the five points with `cells`, then `rest`.
fn ugrid(binary: bool, modern: bool, cells: &[(u32, &[u32])], rest: &[u8]) -> Vec<u8> {
    let mut b = head(binary, "UNSTRUCTURED_GRID");
    b.extend(b"POINTS 5 double\n");
    b.extend(nums(binary, Ty::F64, &PTS));
    b.extend(cells_section(binary, modern, cells));
    b.extend(rest);
    b
}

const GOOD: [(u32, &[u32]); 2] = [(14, &[0, 1, 2, 3, 4]), (10, &[0, 1, 3, 4])];

#[test]
fn vtk_unstructured_both_layouts_cell_data_first_color_scalars() {
    for binary in [false, true] {
        for modern in [false, true] {
            let mut rest = b"CELL_DATA 2\nSCALARS c3 double 3\nLOOKUP_TABLE default\n".to_vec();
            rest.extend(nums(binary, Ty::F64, &[1.5, 0., 0., -2.5, 0., 0.]));
            rest.extend(b"POINT_DATA 5\nCOLOR_SCALARS rgb 3\n");
            if binary {
                rest.extend([0, 1, 2, 51, 1, 2, 102, 1, 2, 153, 1, 2, 255, 1, 2, b'\n']);
            } else {
                rest.extend(b"0 1 1 0.2 1 1 0.4 1 1 0.6 1 1 1 1 1\n");
            }
            rest.extend(b"SCALARS id vtktypeint64\n");
            rest.extend(nums(binary, Ty::I64, &[5., 6., 7., 8., 9.]));
            let name = format!("u-{binary}-{modern}.vtk");
            let d = load(&name, &ugrid(binary, modern, &GOOD, &rest));
            let Geometry::Unstructured { points, cells } = &d.geometry else {
                panic!()
            };
            assert_eq!(points[4], [0.5, 0.5, 1.0]);
            assert_eq!(cells.types, [CellType::Pyramid, CellType::Tetra]);
            assert_eq!(cells.cell(1), [0, 1, 3, 4]);
            let c3 = array(&d, "c3");
            assert_eq!((c3.location, c3.components), (Location::Cell, 3));
            assert_eq!(c3.values, [1.5, -2.5]);
            let rgb = array(&d, "rgb");
            assert_eq!(rgb.values, [0.0, 0.2, 0.4, 0.6, 1.0]);
            assert_eq!(array(&d, "id").values, [5., 6., 7., 8., 9.]);
        }
    }
}

#[test]
fn vtk_unstructured_without_cells_and_cell_type_names() {
    let mut b = head(false, "UNSTRUCTURED_GRID");
    b.extend(b"POINTS 5 float\n0 0 0 1 0 0 1 1 0 0 1 0 0.5 0.5 1\nPOINT_DATA 5\n");
    b.extend(b"SCALARS s int\n1 2 3 4 5\n");
    let d = load("nocells.vtk", &b);
    assert_eq!(d.geometry.cell_count(), 0);
    assert_eq!(array(&d, "s").values, [1., 2., 3., 4., 5.]);
}

#[test]
fn vtk_malformed_cells() {
    for binary in [false, true] {
        for modern in [false, true] {
            let tag = format!("{binary}-{modern}");
            let out: [(u32, &[u32]); 2] = [(10, &[0, 1, 2, 3]), (10, &[0, 1, 9, 4])];
            let b = ugrid(binary, modern, &out, b"");
            let text = "cell 1 refers to point 9, but there are only 5 points";
            fails(&format!("range-{tag}.vtk"), &b, "IndexOutOfRange", text);

            let tri: [(u32, &[u32]); 2] = [(10, &[0, 1, 2, 3]), (5, &[0, 1, 2])];
            let b = ugrid(binary, modern, &tri, b"");
            let text = "cell 1 (CELL_TYPES at line";
            let e = fails(&format!("tri-{tag}.vtk"), &b, "UnsupportedCell", text);
            assert!(e.to_string().contains("cell type 5 (VTK_TRIANGLE)"), "{e}");

            let five: [(u32, &[u32]); 1] = [(10, &[0, 1, 2, 3, 4])];
            let b = ugrid(binary, modern, &five, b"");
            let text = "cell 0: expected 4 points for a tetra, found 5";
            fails(&format!("count-{tag}.vtk"), &b, "Format", text);
        }
    }
    // CELL_TYPES not matching CELLS, CELLS without CELL_TYPES, a classic size that lies.
    let mut b = ugrid(false, false, &GOOD, b"");
    let at = b.windows(12).position(|w| w == b"CELL_TYPES 2").unwrap();
    b.truncate(at);
    b.extend(b"CELL_TYPES 1\n10\n");
    fails(
        "types.vtk",
        &b,
        "Format",
        "expected CELL_TYPES 2 (one per cell of CELLS)",
    );
    b.truncate(at);
    fails("notypes.vtk", &b, "Format", "expected CELL_TYPES before");
    let mut b = head(false, "UNSTRUCTURED_GRID");
    b.extend(b"POINTS 5 float\n0 0 0 1 0 0 1 1 0 0 1 0 0.5 0.5 1\n");
    b.extend(b"CELLS 1 6\n4 0 1 2 3 4\nCELL_TYPES 1\n10\n");
    fails(
        "size.vtk",
        &b,
        "Format",
        "line 7: expected 6 entries for 1 cells, found 5 used",
    );
    // 5.1 offsets that do not end at the connectivity size, or decrease.
    let mut b = head(false, "UNSTRUCTURED_GRID");
    b.extend(b"POINTS 5 float\n0 0 0 1 0 0 1 1 0 0 1 0 0.5 0.5 1\n");
    b.extend(b"CELLS 2 4\nOFFSETS vtktypeint64\n0 3\nCONNECTIVITY vtktypeint64\n0 1 2 3\n");
    fails(
        "offsets.vtk",
        &b,
        "Format",
        "a last offset equal to the connectivity size 4",
    );
    let b = String::from_utf8(b).unwrap().replace("0 3\n", "4 0\n");
    fails(
        "offsets0.vtk",
        b.as_bytes(),
        "Format",
        "offsets starting at 0",
    );
    // A negative index.
    let mut b = head(false, "UNSTRUCTURED_GRID");
    b.extend(b"POINTS 5 float\n0 0 0 1 0 0 1 1 0 0 1 0 0.5 0.5 1\n");
    b.extend(b"CELLS 1 5\n4 0 1 -2 3\nCELL_TYPES 1\n10\n");
    fails("negative.vtk", &b, "Format", "found -2 (value 4)");
}

#[test]
fn vtk_non_finite_coordinates_and_values() {
    for binary in [false, true] {
        let mut pts = PTS;
        pts[7] = f64::NAN;
        let mut b = head(binary, "POLYDATA");
        b.extend(b"POINTS 5 float\n");
        b.extend(nums(binary, Ty::F32, &pts));
        fails(
            &format!("nanpt-{binary}.vtk"),
            &b,
            "NonFiniteCoordinate",
            "point 2 has",
        );

        let mut b = head(binary, "POLYDATA");
        b.extend(b"POINTS 5 float\n");
        b.extend(nums(binary, Ty::F32, &PTS));
        b.extend(b"POINT_DATA 5\nSCALARS s double\n");
        b.extend(nums(binary, Ty::F64, &[0., 1., f64::INFINITY, 3., 4.]));
        fails(
            &format!("infval-{binary}.vtk"),
            &b,
            "NonFiniteValue",
            "'s' element 2",
        );
    }
}

#[test]
fn vtk_truncated_binary() {
    let b = ugrid(true, true, &GOOD, b"");
    let at = b.windows(12).position(|w| w == b"CONNECTIVITY").unwrap();
    // The header line, then 2 of the 9 eight-byte connectivity entries.
    let cut = at + "CONNECTIVITY vtktypeint64\n".len() + 16;
    fails(
        "trunc-conn.vtk",
        &b[..cut],
        "Truncated",
        "expected 72 bytes/values, found 16",
    );
    let mut b = head(true, "STRUCTURED_GRID");
    b.extend(b"DIMENSIONS 2 2 1\nPOINTS 4 double\n");
    b.extend(&nums(true, Ty::F64, &[0.0; 12])[..95]);
    fails(
        "trunc-pts.vtk",
        &b,
        "Truncated",
        "expected 96 bytes/values, found 95",
    );
}

#[test]
fn vtk_wrong_array_lengths() {
    let grid = |rest: &[u8]| {
        let mut b = head(false, "STRUCTURED_GRID");
        b.extend(b"DIMENSIONS 2 2 1\nPOINTS 4 float\n0 0 0 1 0 0 0 1 0 1 1 0\n");
        b.extend(rest);
        b
    };
    let b = grid(b"POINT_DATA 5\nSCALARS s float\n1 2 3 4 5\n");
    fails(
        "pd.vtk",
        &b,
        "Format",
        "line 8: expected POINT_DATA 4 (the point count)",
    );
    let b = grid(b"CELL_DATA 2\nSCALARS s float\n1 2\n");
    fails(
        "cd.vtk",
        &b,
        "Format",
        "line 8: expected CELL_DATA 1 (the cell count)",
    );
    let b = grid(b"POINT_DATA 4\nFIELD f 1\nshort 1 3 float\n1 2 3\n");
    fails(
        "field.vtk",
        &b,
        "Format",
        "line 10: expected 4 tuples (one per point), found 3",
    );
    let b = grid(b"POINT_DATA 4\nSCALARS s float\n1 2 3 4 5\n");
    fails("more.vtk", &b, "Format", "line 10: expected an attribute");
    let b = grid(b"POINT_DATA 4\nSCALARS s float\n1 2 3\n");
    fails(
        "less.vtk",
        &b,
        "Truncated",
        "expected 4 bytes/values, found 3",
    );
    let b = grid(b"CELL_DATA 1\nSCALARS s float\n1\nPOINT_DATA 4\nSCALARS s float\n1 2 3\n");
    fails(
        "less2.vtk",
        &b,
        "Truncated",
        "expected 4 bytes/values, found 3",
    );
    // Structured POINTS not matching DIMENSIONS.
    let mut b = head(false, "STRUCTURED_GRID");
    b.extend(b"DIMENSIONS 2 2 2\nPOINTS 4 float\n0 0 0 1 0 0 0 1 0 1 1 0\n");
    fails(
        "spts.vtk",
        &b,
        "Format",
        "line 6: expected POINTS 8 (the product of DIMENSIONS)",
    );
}

#[test]
fn vtk_absurd_counts_fail_fast() {
    for (i, section) in [
        "POINTS 99999999999 float\n0 0 0\n",
        "POINTS 1 float\n0 0 0\nCELLS 99999999999 5\n",
        "POINTS 1 float\n0 0 0\nCELLS 1 99999999999\n",
        "POINTS 1 float\n0 0 0\nCELL_TYPES 18446744073709551615\n",
    ]
    .iter()
    .enumerate()
    {
        let mut b = head(false, "UNSTRUCTURED_GRID");
        b.extend(section.bytes());
        fails(
            &format!("absurd{i}.vtk"),
            &b,
            "TooLarge",
            "exceed the limit",
        );
    }
    // Within the limit, but not backed by data: fails on the data, not on an allocation.
    for binary in [false, true] {
        let mut b = head(binary, "UNSTRUCTURED_GRID");
        b.extend(b"POINTS 1000000000 float\n");
        b.extend(nums(binary, Ty::F32, &[0.0; 3]));
        fails(&format!("big-{binary}.vtk"), &b, "Truncated", "expected");
    }
    let mut b = head(false, "RECTILINEAR_GRID");
    b.extend(b"DIMENSIONS 100000 100000 100000\n");
    fails("dims.vtk", &b, "TooLarge", "exceed the limit");
}

#[test]
fn vtk_rectilinear_must_increase_and_match_dimensions() {
    let grid = |x: &str| {
        let mut b = head(false, "RECTILINEAR_GRID");
        b.extend(format!("DIMENSIONS 3 1 1\nX_COORDINATES {x}\n").bytes());
        b.extend(b"Y_COORDINATES 1 float\n0\nZ_COORDINATES 1 double\n5\n");
        b
    };
    let d = load("rect.vtk", &grid("3 float\n0 1 2.5"));
    assert_eq!(d.geometry.point(2), [2.5, 0.0, 5.0]);
    let b = grid("3 float\n0 2 1");
    let e = fails("mono.vtk", &b, "Format", "x coordinates 1 and 2");
    assert!(e.to_string().contains("strictly increasing"), "{e}");
    let b = grid("2 float\n0 2");
    fails(
        "xlen.vtk",
        &b,
        "Format",
        "line 6: expected X_COORDINATES 3 (DIMENSIONS)",
    );
}

#[test]
fn vtk_polydata_vertices_checked_other_sections_and_keywords() {
    let poly = |sections: &[u8]| {
        let mut b = head(false, "POLYDATA");
        b.extend(b"POINTS 3 float\n0 0 0 1 0 0 2 0 0\n");
        b.extend(sections);
        b
    };
    let b = poly(b"VERTICES 2 4\n1 0\n1 3\n");
    fails(
        "vert.vtk",
        &b,
        "IndexOutOfRange",
        "cell 1 refers to point 3",
    );
    let b = poly(b"VERTICES 1 2\n1 0\nPOLYGONS 1 4\n3 0 1 7\n");
    fails(
        "poly.vtk",
        &b,
        "IndexOutOfRange",
        "cell 1 refers to point 7",
    );
    let b = poly(b"TRIANGLE_STRIPS 1 4\n3 0 1 2\nCELL_DATA 1\nSCALARS c float\n7\n");
    let d = load("strips.vtk", &b);
    assert_eq!((d.geometry.point_count(), d.arrays.len()), (3, 0));
    let b = poly(b"CELLS 1 2\n1 0\n");
    fails(
        "kw.vtk",
        &b,
        "Format",
        "line 7: expected POINTS, VERTICES, LINES",
    );
    let b = poly(b"POINT_DATA 3\nSCALARS s float\n1 2 3\n\x00garbage\n");
    fails(
        "garbage.vtk",
        &b,
        "Format",
        "line 10: expected an attribute",
    );
    let b = b"# vtk DataFile Version 3.0\nx\nASCII\nDATASET GRAPH\n".to_vec();
    fails(
        "graph.vtk",
        &b,
        "Unsupported",
        "line 4: unsupported DATASET GRAPH",
    );
    let b = b"# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\n".to_vec();
    fails(
        "nopoints.vtk",
        &b,
        "Format",
        "expected POINTS before the point and cell data",
    );
}

// ---------------------------------------------------------------- CSV

fn points(d: &Dataset) -> &[[f64; 3]] {
    match &d.geometry {
        Geometry::Points { points } => points,
        g => panic!("{}", g.kind()),
    }
}

#[test]
fn csv_paraview_and_plain_headers() {
    // As ParaView's "Save Data" writes it: quoted names, Points:0..2 last, vector components.
    let pv = "\"temp\",\"label\",\"v:0\",\"v:1\",\"Points:0\",\"Points:1\",\"Points:2\"\n\
              1.5,a,0,1,0.25,-1,2\n\
              -2,b c,3,4,1e3,0,0.5\n";
    let d = load("pv.csv", pv.as_bytes());
    assert_eq!(points(&d), [[0.25, -1.0, 2.0], [1000.0, 0.0, 0.5]]);
    assert_eq!(d.arrays.len(), 3, "{:?}", names(&d));
    assert_eq!(array(&d, "temp").values, [1.5, -2.0]);
    assert_eq!(array(&d, "v:1").values, [1.0, 4.0]);
    assert!(d.arrays.iter().all(|a| a.location == Location::Point));

    let plain = "\u{feff}X, y ,Z,density\r\n0,0,0, 7\r\n\r\n1,2,3,8\r\n";
    let d = load("plain.csv", plain.as_bytes());
    assert_eq!(points(&d), [[0.0; 3], [1.0, 2.0, 3.0]]);
    assert_eq!(array(&d, "density").values, [7.0, 8.0]);
}

#[test]
fn csv_malformed() {
    let e = fails(
        "nonnum.csv",
        b"x,y,z,s\n0,0,0,1\n1,1,oops,2\n",
        "Format",
        "line 3",
    );
    assert!(e.to_string().contains("column 3 ('z')"), "{e}");
    assert!(e.to_string().contains("found 'oops'"), "{e}");
    fails(
        "nonnum2.csv",
        b"x,y,z,s\n0,0,0,1\n1,1,1,-\n",
        "Format",
        "line 3, column 4 ('s')",
    );
    fails(
        "nox.csv",
        b"a,y,z\n1,2,3\n",
        "Format",
        "expected an x (or Points:0) column",
    );
    fails(
        "noz.csv",
        b"x,y\n1,2\n",
        "Format",
        "expected a z (or Points:2) column",
    );
    fails(
        "twice.csv",
        b"x,Points:0,y,z\n1,1,2,3\n",
        "Format",
        "one column per axis",
    );
    fails("ragged.csv", b"x,y,z\n1,2,3\n4,5\n", "Format", "line 3");
    fails(
        "ragged.csv",
        b"x,y,z\n1,2,3\n4,5\n",
        "Format",
        "2 fields (the header has 3)",
    );
    fails(
        "empty.csv",
        b"",
        "Format",
        "line 1: expected a header row, found an empty file",
    );
    fails(
        "header.csv",
        b"x,y,z\n",
        "Format",
        "expected at least one point",
    );
    fails(
        "nan.csv",
        b"x,y,z\n1,2,3\n1,nan,3\n",
        "NonFiniteCoordinate",
        "point 1",
    );
    fails(
        "inf.csv",
        b"x,y,z,s\n1,2,3,1e300\n",
        "NonFiniteValue",
        "'s' element 0",
    );
}

// ---------------------------------------------------------------- PLY

/// A PLY file with an element before the vertices, vertices (x y z float, intensity uchar,
/// a list, q double) and faces after them.
fn ply(format: &str, vertices: &[(f32, f32, f32, u8, f64)]) -> Vec<u8> {
    let mut b = format!(
        "ply\nformat {format} 1.0\ncomment made by hand\nelement camera 1\nproperty float k\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property uchar intensity\nproperty list uchar int tags\nproperty double q\n\
         element face 1\nproperty list uchar int vertex_indices\nend_header\n",
        vertices.len()
    )
    .into_bytes();
    let big = format.contains("big");
    let le = format.contains("little");
    macro_rules! put {
        ($v:expr) => {
            if big {
                b.extend($v.to_be_bytes())
            } else {
                b.extend($v.to_le_bytes())
            }
        };
    }
    if big || le {
        put!(0.5f32);
        for &(x, y, z, i, q) in vertices {
            put!(x);
            put!(y);
            put!(z);
            b.push(i);
            b.push(2);
            put!(7i32);
            put!(8i32);
            put!(q);
        }
        b.push(3);
        for i in 0..3i32 {
            put!(i);
        }
    } else {
        b.extend(b"0.5\n");
        for &(x, y, z, i, q) in vertices {
            b.extend(format!("{x} {y} {z} {i} 2 7 8 {q}\n").bytes());
        }
        b.extend(b"3 0 1 2\n");
    }
    b
}

const VERTS: [(f32, f32, f32, u8, f64); 3] = [
    (0.0, 0.5, -1.0, 0, 0.1),
    (1.25, 2.0, 3.0, 200, -2.5),
    (-4.0, 0.0, 1e-3, 255, 1e10),
];

#[test]
fn ply_all_three_encodings() {
    for format in ["ascii", "binary_little_endian", "binary_big_endian"] {
        let d = load(&format!("{format}.ply"), &ply(format, &VERTS));
        let want: Vec<[f64; 3]> = VERTS
            .iter()
            .map(|v| [v.0 as f64, v.1 as f64, v.2 as f64])
            .collect();
        assert_eq!(points(&d), want, "{format}");
        assert_eq!(
            names(&d),
            [("intensity", Location::Point), ("q", Location::Point)]
        );
        assert_eq!(array(&d, "intensity").values, [0.0, 200.0, 255.0]);
        assert_eq!(array(&d, "q").values, [0.1f64 as f32, -2.5, 1e10]);
    }
}

#[test]
fn ply_malformed() {
    let no_vertex = b"ply\nformat ascii 1.0\nelement point 1\nproperty float x\nend_header\n1\n";
    fails(
        "nov.ply",
        no_vertex,
        "Format",
        "expected a 'vertex' element, found elements [point]",
    );
    let no_z = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
                 end_header\n1 2\n";
    fails("noz.ply", no_z, "Format", "a scalar vertex property 'z'");
    let b = ply("binary_little_endian", &VERTS);
    let cut = b.len() - 30;
    fails(
        "trunc.ply",
        &b[..cut],
        "Format",
        "(start of the 'vertex' data)",
    );
    let mut simple = b"ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty double x\n\
                       property double y\nproperty double z\nend_header\n"
        .to_vec();
    simple.extend([0u8; 40]);
    fails(
        "short.ply",
        &simple,
        "Truncated",
        "expected 48 bytes/values, found 40",
    );
    let bad = String::from_utf8(ply("ascii", &VERTS))
        .unwrap()
        .replace("1.25", "one");
    let e = fails(
        "text.ply",
        bad.as_bytes(),
        "Format",
        "line 18: expected 3 'vertex' elements",
    );
    assert!(
        e.to_string().contains("found 'one 2 3 200 2 7 8 -2.5'"),
        "{e}"
    );
    let short = String::from_utf8(ply("ascii", &VERTS))
        .unwrap()
        .replace("3 0 1 2\n", "");
    let short = short.replace("-4 0 0.001 255 2 7 8 10000000000\n", "");
    fails(
        "eof.ply",
        short.as_bytes(),
        "Format",
        "line 19: expected 3 'vertex' elements",
    );
    let nan = [(0.0, f32::NAN, 0.0, 1, 1.0)];
    fails(
        "nan.ply",
        &ply("binary_big_endian", &nan),
        "NonFiniteCoordinate",
        "point 0",
    );
    fails("garbage.ply", b"\x89PNG\r\n", "Format", "header");
    let huge = b"ply\nformat ascii 1.0\nelement vertex 99999999999\nproperty float x\n\
                 property float y\nproperty float z\nend_header\n";
    fails("huge.ply", huge, "TooLarge", "exceed the limit");
}
