//! Loader round trips and bad-input cases for VTK legacy, NRRD and NIfTI-1. Every file is built
//! byte by byte here, so the expected values are known exactly.

use flate2::{Compression, write::GzEncoder};
use std::io::Write;
use std::path::{Path, PathBuf};
use vmls::data::{self, DataError, MAX_SAMPLES, Volume, nifti, nrrd, vtk};

#[derive(Clone, Copy, Debug)]
enum T {
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

impl T {
    /// Sample `i` of a ramp that uses the type's range (negative values, values past i32, 10 as
    /// a u8 so that binary data contains a newline byte).
    fn value(self, i: usize) -> f64 {
        let i = i as f64;
        match self {
            T::I8 => i * 5.0 - 60.0,
            T::U8 => i * 10.0,
            T::I16 => i * 1000.0 - 12000.0,
            T::U16 => i * 2500.0,
            T::I32 => i * 100_000.0 - 1_000_000.0,
            T::U32 => i * 150_000_000.0,
            T::I64 => i * 1e12 - 5e12,
            T::U64 => i * 5e17,
            T::F32 => i * 0.25 - 3.0,
            T::F64 => i * 0.1 - 1.2,
        }
    }

    fn bytes(self, v: f64, big: bool) -> Vec<u8> {
        macro_rules! b {
            ($x:expr) => {
                if big {
                    $x.to_be_bytes().to_vec()
                } else {
                    $x.to_le_bytes().to_vec()
                }
            };
        }
        match self {
            T::I8 => b!(v as i8),
            T::U8 => b!(v as u8),
            T::I16 => b!(v as i16),
            T::U16 => b!(v as u16),
            T::I32 => b!(v as i32),
            T::U32 => b!(v as u32),
            T::I64 => b!(v as i64),
            T::U64 => b!(v as u64),
            T::F32 => b!(v as f32),
            T::F64 => b!(v),
        }
    }

    fn text(self, v: f64) -> String {
        match self {
            T::U64 => (v as u64).to_string(),
            T::F32 | T::F64 => v.to_string(),
            _ => (v as i64).to_string(),
        }
    }
}

const DIMS: [usize; 3] = [2, 3, 4];
const N: usize = 24;

fn ramp(t: T) -> Vec<f64> {
    (0..N).map(|i| t.value(i)).collect()
}

fn packed(t: T, values: &[f64], big: bool) -> Vec<u8> {
    values.iter().flat_map(|&v| t.bytes(v, big)).collect()
}

fn as_text(t: T, values: &[f64]) -> String {
    let words: Vec<String> = values.iter().map(|&v| t.text(v)).collect();
    words.chunks(5).map(|c| c.join(" ") + "\n").collect()
}

/// Writes `bytes` to a file of this name in a per-process temporary directory.
fn file(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vmls-loaders-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut e = GzEncoder::new(Vec::new(), Compression::default());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-6 * b.abs().max(1.0)
}

fn check(v: &Volume, dims: [usize; 3], spacing: [f64; 3], origin: [f64; 3], expected: &[f64]) {
    assert_eq!(v.dims, dims);
    assert_eq!(v.values.len(), expected.len());
    for a in 0..3 {
        assert!(
            close(v.spacing[a], spacing[a]),
            "spacing {:?} != {spacing:?}",
            v.spacing
        );
        assert!(
            close(v.origin[a], origin[a]),
            "origin {:?} != {origin:?}",
            v.origin
        );
    }
    for (i, (&got, &want)) in v.values.iter().zip(expected).enumerate() {
        assert!(close(got as f64, want), "sample {i}: {got} != {want}");
    }
}

/// Asserts that the message names the file and contains `location` (e.g. "line 7").
fn mentions(e: &DataError, path: &Path, location: &str) {
    let msg = e.to_string();
    let name = path.file_name().unwrap().to_string_lossy();
    assert!(msg.contains(&*name), "{msg:?} does not name {name}");
    assert!(msg.contains(location), "{msg:?} lacks {location:?}");
}

// ---------------------------------------------------------------- VTK

const GEOM: &str = "DIMENSIONS 2 3 4\nSPACING 0.5 1 2\nORIGIN -1 0 3.5\n";
const SP: [f64; 3] = [0.5, 1.0, 2.0];
const OR: [f64; 3] = [-1.0, 0.0, 3.5];

fn vtk_head(version: &str, binary: bool, geometry: &str) -> Vec<u8> {
    let form = if binary { "BINARY" } else { "ASCII" };
    let head =
        format!("# vtk DataFile Version {version}\nvolume\n{form}\nDATASET STRUCTURED_POINTS\n");
    (head + geometry).into_bytes()
}

fn vtk_data(t: T, values: &[f64], binary: bool) -> Vec<u8> {
    let mut out = if binary {
        packed(t, values, true)
    } else {
        as_text(t, values).into_bytes()
    };
    if binary {
        out.push(b'\n');
    }
    out
}

const VTK_TYPES: [(&str, T); 22] = [
    ("unsigned_char", T::U8),
    ("char", T::I8),
    ("signed_char", T::I8),
    ("short", T::I16),
    ("unsigned_short", T::U16),
    ("int", T::I32),
    ("unsigned_int", T::U32),
    ("long", T::I64),
    ("unsigned_long", T::U64),
    ("float", T::F32),
    ("double", T::F64),
    ("vtktypeint8", T::I8),
    ("vtktypeuint8", T::U8),
    ("vtktypeint16", T::I16),
    ("vtktypeuint16", T::U16),
    ("vtktypeint32", T::I32),
    ("vtktypeuint32", T::U32),
    ("vtktypeint64", T::I64),
    ("vtktypeuint64", T::U64),
    ("vtktypefloat32", T::F32),
    ("vtktypefloat64", T::F64),
    ("vtkIdType", T::I32),
];

#[test]
fn vtk_every_scalar_type_ascii_and_binary_all_versions() {
    for (name, t) in VTK_TYPES {
        for binary in [false, true] {
            for version in ["2.0", "3.0", "4.2", "5.1"] {
                for table in [true, false] {
                    let mut b = vtk_head(version, binary, GEOM);
                    b.extend(format!("POINT_DATA 24\nSCALARS density {name} 1\n").bytes());
                    if table {
                        b.extend(b"LOOKUP_TABLE default\n");
                    }
                    b.extend(vtk_data(t, &ramp(t), binary));
                    let file_name = format!("t-{name}-{binary}-{version}-{table}.vtk");
                    let v = data::load(&file(&file_name, &b), None).unwrap();
                    check(&v, DIMS, SP, OR, &ramp(t));
                }
            }
        }
    }
}

#[test]
fn vtk_multi_component_scalars_take_first_component() {
    for binary in [false, true] {
        let tuples: Vec<f64> = (0..N)
            .flat_map(|i| [i as f64, -1.0, 100.0 + i as f64])
            .collect();
        let mut b = vtk_head(
            "4.2",
            binary,
            "ASPECT_RATIO 0.5 1 2\nORIGIN -1 0 3.5\nDIMENSIONS 2 3 4\n",
        );
        b.extend(b"POINT_DATA 24\nSCALARS rgb float 3\nLOOKUP_TABLE default\n");
        b.extend(vtk_data(T::F32, &tuples, binary));
        let v = vtk::parse(Path::new("mem.vtk"), &b, None).unwrap();
        check(
            &v,
            DIMS,
            SP,
            OR,
            &(0..N).map(|i| i as f64).collect::<Vec<_>>(),
        );
    }
}

#[test]
fn vtk_color_scalars_first_component_in_unit_range() {
    let ascii: Vec<f64> = (0..N).flat_map(|i| [i as f64 / 24.0, 0.5]).collect();
    let mut b = vtk_head("3.0", false, GEOM);
    b.extend(b"POINT_DATA 24\nCOLOR_SCALARS colour 2\n");
    b.extend(vtk_data(T::F32, &ascii, false));
    let v = vtk::parse(Path::new("c.vtk"), &b, None).unwrap();
    check(
        &v,
        DIMS,
        SP,
        OR,
        &(0..N).map(|i| i as f64 / 24.0).collect::<Vec<_>>(),
    );

    let bytes: Vec<f64> = (0..N).flat_map(|i| [i as f64 * 10.0, 7.0]).collect();
    let mut b = vtk_head("3.0", true, GEOM);
    b.extend(b"POINT_DATA 24\nCOLOR_SCALARS colour 2\n");
    b.extend(vtk_data(T::U8, &bytes, true));
    let v = vtk::parse(Path::new("c.vtk"), &b, None).unwrap();
    check(
        &v,
        DIMS,
        SP,
        OR,
        &(0..N).map(|i| i as f64 * 10.0 / 255.0).collect::<Vec<_>>(),
    );
}

/// A 5.1-style file: dataset FIELD, CELL_DATA before POINT_DATA, a FIELD of two arrays with a
/// METADATA block and a NULL_ARRAY, and a %-escaped name.
fn vtk_field_file(binary: bool) -> Vec<u8> {
    let mut b = vtk_head("5.1", binary, "");
    b.extend(b"FIELD FieldData 1\nTIME 1 1 double\n");
    b.extend(vtk_data(T::F64, &[2.5], binary));
    b.extend(GEOM.bytes());
    b.extend(b"CELL_DATA 6\nSCALARS cellid int 1\nLOOKUP_TABLE default\n");
    b.extend(vtk_data(T::I32, &[1., 2., 3., 4., 5., 6.], binary));
    b.extend(b"VECTORS flow float\n");
    b.extend(vtk_data(T::F32, &[9.0; 18], binary));
    b.extend(b"POINT_DATA 24\nVECTORS velocity double\n");
    b.extend(vtk_data(T::F64, &[0.5; 72], binary));
    b.extend(b"FIELD FieldData 3\npressure 1 24 float\n");
    b.extend(vtk_data(T::F32, &ramp(T::F32), binary));
    b.extend(b"METADATA\nINFORMATION 1\nNAME L2_NORM_RANGE LOCATION vtkDataArray\nDATA 2 0 3\n\n");
    b.extend(b"NULL_ARRAY\nwall%20temp 2 24 short\n");
    let pairs: Vec<f64> = ramp(T::I16).iter().flat_map(|&v| [v, 1.0]).collect();
    b.extend(vtk_data(T::I16, &pairs, binary));
    b.extend(b"SCALARS last unsigned_char\nLOOKUP_TABLE default\n");
    b.extend(vtk_data(T::U8, &ramp(T::U8), binary));
    b
}

#[test]
fn vtk_field_arrays_cell_data_and_selection_by_name() {
    for binary in [false, true] {
        let path = file(&format!("field-{binary}.vtk"), &vtk_field_file(binary));
        let first = vtk::load(&path, None).unwrap();
        check(&first, DIMS, SP, OR, &ramp(T::F32));
        let second = vtk::load(&path, Some("wall temp")).unwrap();
        check(&second, DIMS, SP, OR, &ramp(T::I16));
        let last = data::load(&path, Some("last")).unwrap();
        check(&last, DIMS, SP, OR, &ramp(T::U8));

        let e = vtk::load(&path, Some("cellid")).unwrap_err();
        assert!(
            matches!(&e, DataError::NoSuchArray { name, available, .. }
            if name == "cellid" && available == "pressure, wall temp, last"),
            "{e:?}"
        );
        mentions(&e, &path, "pressure, wall temp, last");
    }
}

#[test]
fn vtk_structured_points_that_are_not_the_last_section() {
    let mut b = vtk_head("2.0", false, GEOM);
    b.extend(b"POINT_DATA 24\nSCALARS s double\nLOOKUP_TABLE default\n");
    b.extend(vtk_data(T::F64, &ramp(T::F64), false));
    b.extend(b"CELL_DATA 6\nSCALARS c float\nLOOKUP_TABLE default\n1 2 3 4 5 6\n");
    let v = vtk::parse(Path::new("m.vtk"), &b, None).unwrap();
    check(&v, DIMS, SP, OR, &ramp(T::F64));
}

fn vtk_error(name: &str, bytes: &[u8], array: Option<&str>) -> (PathBuf, DataError) {
    let path = file(name, bytes);
    let e = vtk::load(&path, array).unwrap_err();
    (path, e)
}

#[test]
fn vtk_missing_file_names_the_path() {
    let path = std::env::temp_dir().join("vmls-no-such-dir/absent.vtk");
    let e = data::load(&path, None).unwrap_err();
    assert!(matches!(e, DataError::Io { .. }), "{e:?}");
    assert!(e.to_string().contains(&path.display().to_string()), "{e}");
}

#[test]
fn vtk_truncated_binary_and_ascii() {
    let mut b = vtk_head("5.1", true, GEOM);
    b.extend(b"POINT_DATA 24\nSCALARS s float 1\nLOOKUP_TABLE default\n");
    b.extend(&packed(T::F32, &ramp(T::F32), true)[..90]);
    let (path, e) = vtk_error("trunc-bin.vtk", &b, None);
    assert!(
        matches!(
            e,
            DataError::Truncated {
                expected: 96,
                found: 90,
                ..
            }
        ),
        "{e:?}"
    );
    mentions(&e, &path, "expected 96");

    let mut b = vtk_head("2.0", false, GEOM);
    b.extend(b"POINT_DATA 24\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2 3\n");
    let (path, e) = vtk_error("trunc-ascii.vtk", &b, None);
    assert!(
        matches!(
            e,
            DataError::Truncated {
                expected: 24,
                found: 3,
                ..
            }
        ),
        "{e:?}"
    );
    mentions(&e, &path, "found 3");
}

#[test]
fn vtk_wrong_counts() {
    let mut b = vtk_head("2.0", false, GEOM);
    b.extend(b"POINT_DATA 20\nSCALARS s float 1\n");
    let (path, e) = vtk_error("count-pd.vtk", &b, None);
    assert!(matches!(e, DataError::Format { .. }), "{e:?}");
    mentions(&e, &path, "line 8");
    mentions(&e, &path, "POINT_DATA 20");

    // One value too many: found on line 15 (24 values take lines 10 to 14, five per line).
    let mut b = vtk_head("2.0", false, GEOM);
    b.extend(b"POINT_DATA 24\nSCALARS s float 1\n");
    b.extend(vtk_data(T::F32, &ramp(T::F32), false));
    b.extend(b"7\n");
    let (path, e) = vtk_error("count-more.vtk", &b, None);
    assert!(matches!(e, DataError::Format { .. }), "{e:?}");
    mentions(&e, &path, "line 15");

    // One value short, then the next keyword: reported where the keyword stands (line 15).
    let mut b = vtk_head("2.0", false, GEOM);
    b.extend(b"POINT_DATA 24\nSCALARS s float 1\n");
    b.extend(vtk_data(T::F32, &ramp(T::F32)[..23], false));
    b.extend(b"CELL_DATA 6\n");
    let (path, e) = vtk_error("count-less.vtk", &b, None);
    assert!(matches!(e, DataError::Format { .. }), "{e:?}");
    mentions(&e, &path, "line 15");
    mentions(&e, &path, "value 24 of 24");
}

#[test]
fn vtk_unknown_type_and_string_arrays() {
    let mut b = vtk_head("2.0", false, GEOM);
    b.extend(b"POINT_DATA 24\nSCALARS s quaternion 1\n");
    let (path, e) = vtk_error("type.vtk", &b, None);
    assert!(matches!(e, DataError::Format { .. }), "{e:?}");
    mentions(&e, &path, "line 9");
    mentions(&e, &path, "quaternion");

    let mut b = vtk_head("2.0", false, GEOM);
    b.extend(b"POINT_DATA 24\nFIELD f 1\nnames 1 24 string\n");
    let (path, e) = vtk_error("string.vtk", &b, None);
    assert!(matches!(e, DataError::Unsupported { .. }), "{e:?}");
    mentions(&e, &path, "line 10");
}

#[test]
fn vtk_non_finite_values_name_the_sample() {
    for (binary, bad) in [(false, "nan"), (false, "-inf"), (true, "inf")] {
        let mut values = ramp(T::F32);
        values[13] = bad.parse().unwrap();
        let mut b = vtk_head("2.0", binary, GEOM);
        b.extend(b"POINT_DATA 24\nSCALARS s float\n");
        b.extend(vtk_data(T::F32, &values, binary));
        let (path, e) = vtk_error(&format!("nan-{binary}-{bad}.vtk"), &b, None);
        assert!(
            matches!(
                e,
                DataError::NonFinite {
                    index: 13,
                    x: 1,
                    y: 0,
                    z: 2,
                    ..
                }
            ),
            "{e:?}"
        );
        mentions(&e, &path, "sample 13");
    }
}

#[test]
fn vtk_dimensions_overflow_and_limit() {
    for (dims, reason) in [
        ("4294967296 4294967296 2", "overflows"),
        ("2048 1024 1024", "exceed the limit"),
        ("0 4 4", "at least 1"),
    ] {
        let mut b = vtk_head("2.0", false, &format!("DIMENSIONS {dims}\n"));
        b.extend(b"POINT_DATA 8\nSCALARS s float\n1 2 3 4 5 6 7 8\n");
        let (path, e) = vtk_error("huge.vtk", &b, None);
        assert!(matches!(e, DataError::TooLarge { .. }), "{e:?}");
        mentions(&e, &path, reason);
    }
    assert!(2048u64 * 1024 * 1024 > MAX_SAMPLES);
}

#[test]
fn vtk_unsupported_datasets() {
    for ty in [
        "STRUCTURED_GRID",
        "RECTILINEAR_GRID",
        "UNSTRUCTURED_GRID",
        "POLYDATA",
    ] {
        let b = format!("# vtk DataFile Version 3.0\nx\nASCII\nDATASET {ty}\nPOINTS 0 float\n");
        let (path, e) = vtk_error("ds.vtk", b.as_bytes(), None);
        assert!(matches!(e, DataError::Unsupported { .. }), "{e:?}");
        mentions(&e, &path, "line 4");
        mentions(&e, &path, ty);
    }
}

#[test]
fn vtk_bad_headers_garbage_and_empty() {
    let cases: [(&str, &[u8], &str); 5] = [
        ("empty.vtk", b"", "line 1"),
        ("garbage.vtk", b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR", "line 1"),
        (
            "form.vtk",
            b"# vtk DataFile Version 2.0\nt\nTEXT\n",
            "line 3",
        ),
        (
            "spacing.vtk",
            b"# vtk DataFile Version 2.0\nt\nASCII\nDATASET STRUCTURED_POINTS\nSPACING 1 0 1\n",
            "line 5",
        ),
        (
            "nodims.vtk",
            b"# vtk DataFile Version 2.0\nt\nASCII\nDATASET STRUCTURED_POINTS\nPOINT_DATA 1\n",
            "line 5",
        ),
    ];
    for (name, bytes, location) in cases {
        let (path, e) = vtk_error(name, bytes, None);
        assert!(matches!(e, DataError::Format { .. }), "{name}: {e:?}");
        mentions(&e, &path, location);
    }
    // Binary garbage where the next keyword should be: the location gives the byte offset.
    let mut b = vtk_head("2.0", true, GEOM);
    b.extend(b"POINT_DATA 24\nSCALARS s unsigned_char\nLOOKUP_TABLE default\n");
    let header_len = b.len();
    b.extend(packed(T::U8, &ramp(T::U8), true));
    b.extend(b"\xff\xfe\n");
    let (path, e) = vtk_error("surplus.vtk", &b, None);
    assert!(matches!(e, DataError::Format { .. }), "{e:?}");
    mentions(&e, &path, &format!("byte {}", header_len + N));
}

// ---------------------------------------------------------------- NRRD

const NRRD_TYPES: [(&str, T); 10] = [
    ("signed char", T::I8),
    ("uchar", T::U8),
    ("short int", T::I16),
    ("unsigned short", T::U16),
    ("int32_t", T::I32),
    ("uint", T::U32),
    ("long long", T::I64),
    ("unsigned long long int", T::U64),
    ("float", T::F32),
    ("double", T::F64),
];

fn nrrd_file(fields: &str, data: &[u8]) -> Vec<u8> {
    let mut b = format!("NRRD0004\n# comment\nunits:=mm\n{fields}\n").into_bytes();
    b.extend(data);
    b
}

#[test]
fn nrrd_raw_both_endians_every_type() {
    for (name, t) in NRRD_TYPES {
        for (endian, big) in [("little", false), ("big", true)] {
            let fields = format!(
                "type: {name}\ndimension: 3\nsizes: 2 3 4\nendian: {endian}\nencoding: raw\n\
                 spacings: 0.5 1 2\naxis mins: -1 0 3.5\n"
            );
            let b = nrrd_file(&fields, &packed(t, &ramp(t), big));
            let v = data::load(&file(&format!("t-{name}-{endian}.nrrd"), &b), None).unwrap();
            check(&v, DIMS, SP, OR, &ramp(t));
        }
    }
}

#[test]
fn nrrd_gzip_text_directions_and_skips() {
    let t = T::I16;
    let spatial = "space: right-anterior-superior\nspace directions: (0,0.5,0) (0.6,0.8,0) (0,0,-2)\n\
                   space origin: (-1, 0, 3.5)\n";
    let gz = nrrd_file(
        &format!("type: int16\ndimension: 3\nsizes: 2 3 4\nendian: big\nencoding: gzip\n{spatial}"),
        &gzip(&packed(t, &ramp(t), true)),
    );
    check(
        &nrrd::parse(Path::new("g.nrrd"), &gz).unwrap(),
        DIMS,
        SP,
        OR,
        &ramp(t),
    );

    let text = nrrd_file(
        &format!("type: short\ndimension: 3\nsizes: 2 3 4\nencoding: ascii\n{spatial}"),
        as_text(t, &ramp(t)).as_bytes(),
    );
    check(
        &nrrd::parse(Path::new("a.nrrd"), &text).unwrap(),
        DIMS,
        SP,
        OR,
        &ramp(t),
    );

    // A leading size-1 axis is dropped; line and byte skips; the default spacing is 1.
    let mut data = b"junk line\n\x00\x01\x02".to_vec();
    data.extend(packed(T::F32, &ramp(T::F32), false));
    let skipped = nrrd_file(
        "type: float\ndimension: 4\nsizes: 1 2 3 4\nendian: little\nencoding: raw\n\
         line skip: 1\nbyte skip: 3\nspace directions: none (1,0,0) (0,1,0) (0,0,1)\n",
        &data,
    );
    let v = nrrd::parse(Path::new("s.nrrd"), &skipped).unwrap();
    check(&v, DIMS, [1.0; 3], [0.0; 3], &ramp(T::F32));

    // byte skip -1: the data is the last bytes of the file.
    let mut data = b"whatever precedes".to_vec();
    data.extend(packed(T::U16, &ramp(T::U16), false));
    let tail = nrrd_file(
        "type: uint16\ndimension: 3\nsizes: 2 3 4\nendian: little\nencoding: raw\nbyte skip: -1\n",
        &data,
    );
    check(
        &nrrd::parse(Path::new("t.nrrd"), &tail).unwrap(),
        DIMS,
        [1.0; 3],
        [0.0; 3],
        &ramp(T::U16),
    );
}

#[test]
fn nrrd_errors() {
    let raw = packed(T::F32, &ramp(T::F32), false);
    let base = "type: float\ndimension: 3\nsizes: 2 3 4\nendian: little\n";
    let gz_fields = format!("{base}encoding: gzip\n");
    let gz_data_at = format!("byte {}", nrrd_file(&gz_fields, &[]).len());
    let cases: Vec<(&str, Vec<u8>, &str, &str)> = vec![
        ("empty.nrrd", vec![], "format", "line 1"),
        ("magic.nrrd", b"NRRX0004\n\n".to_vec(), "format", "line 1"),
        (
            "detached.nrrd",
            nrrd_file(&format!("{base}encoding: raw\ndata file: v.raw\n"), &[]),
            "unsupported",
            "line 9",
        ),
        (
            "bzip.nrrd",
            nrrd_file(&format!("{base}encoding: bzip2\n"), &raw),
            "unsupported",
            "line 8",
        ),
        (
            "dim2.nrrd",
            nrrd_file(
                "type: float\ndimension: 2\nsizes: 4 6\nencoding: raw\nendian: little\n",
                &raw,
            ),
            "unsupported",
            "line 5",
        ),
        (
            "type.nrrd",
            nrrd_file("type: complex\n", &raw),
            "format",
            "line 4",
        ),
        (
            "endian.nrrd",
            nrrd_file(
                "type: float\ndimension: 3\nsizes: 2 3 4\nencoding: raw\n",
                &raw,
            ),
            "format",
            "line 8",
        ),
        (
            "sizes.nrrd",
            nrrd_file(&format!("{base}encoding: raw\nspacings: 1 1\n"), &raw),
            "format",
            "line 9",
        ),
        (
            "noend.nrrd",
            b"NRRD0004\ntype: float\n".to_vec(),
            "format",
            "line 2",
        ),
        (
            "truncated.nrrd",
            nrrd_file(&format!("{base}encoding: raw\n"), &raw[..95]),
            "truncated",
            "expected 96",
        ),
        (
            "truncgz.nrrd",
            nrrd_file(&gz_fields, &gzip(&raw)[..30]),
            "truncated",
            "expected 96",
        ),
        (
            "corruptgz.nrrd",
            nrrd_file(&gz_fields, b"not gzip at all"),
            "format",
            &gz_data_at,
        ),
        (
            "surplus.nrrd",
            nrrd_file(
                "type: int\ndimension: 3\nsizes: 1 1 2\nencoding: text\n",
                b"1 2\n3\n",
            ),
            "format",
            "line 10",
        ),
        (
            "overflow.nrrd",
            nrrd_file(
                "type: float\ndimension: 3\nsizes: 4294967296 4294967296 2\nencoding: raw\nendian: big\n",
                &raw,
            ),
            "too large",
            "overflows",
        ),
        (
            "limit.nrrd",
            nrrd_file(
                "type: float\ndimension: 3\nsizes: 1024 1024 1025\nencoding: raw\nendian: big\n",
                &raw,
            ),
            "too large",
            "exceed the limit",
        ),
    ];
    for (name, bytes, kind, location) in cases {
        let path = file(name, &bytes);
        let e = nrrd::load(&path).unwrap_err();
        let ok = match kind {
            "format" => matches!(e, DataError::Format { .. }),
            "unsupported" => matches!(e, DataError::Unsupported { .. }),
            "truncated" => matches!(e, DataError::Truncated { .. }),
            _ => matches!(e, DataError::TooLarge { .. }),
        };
        assert!(ok, "{name}: expected {kind}, got {e:?}");
        mentions(&e, &path, location);
    }

    let mut values = ramp(T::F64);
    values[23] = f64::NAN;
    let b = nrrd_file(
        "type: double\ndimension: 3\nsizes: 2 3 4\nencoding: raw\nendian: big\n",
        &packed(T::F64, &values, true),
    );
    let path = file("nan.nrrd", &b);
    let e = nrrd::load(&path).unwrap_err();
    assert!(
        matches!(
            e,
            DataError::NonFinite {
                index: 23,
                x: 1,
                y: 2,
                z: 3,
                ..
            }
        ),
        "{e:?}"
    );
    mentions(&e, &path, "sample 23");
}

// ---------------------------------------------------------------- NIfTI

const NIFTI_TYPES: [(i16, T); 10] = [
    (2, T::U8),
    (4, T::I16),
    (8, T::I32),
    (16, T::F32),
    (64, T::F64),
    (256, T::I8),
    (512, T::U16),
    (768, T::U32),
    (1024, T::I64),
    (1280, T::U64),
];

/// A NIfTI-1 header with fields that tests change, then the data.
#[derive(Clone)]
struct Nii {
    big: bool,
    dim: [i16; 8],
    code: i16,
    pixdim: [f32; 3],
    vox_offset: f32,
    slope: f32,
    inter: f32,
    qform: Option<[f32; 3]>,
    sform: Option<[f32; 3]>,
    magic: [u8; 4],
}

impl Default for Nii {
    fn default() -> Self {
        Nii {
            big: false,
            dim: [3, 2, 3, 4, 1, 1, 1, 1],
            code: 16,
            pixdim: [0.5, -1.0, 2.0],
            vox_offset: 352.0,
            slope: 0.0,
            inter: 0.0,
            qform: None,
            sform: None,
            magic: *b"n+1\0",
        }
    }
}

impl Nii {
    fn build(&self, data: &[u8]) -> Vec<u8> {
        let mut h = vec![0u8; 352];
        let big = self.big;
        let mut put =
            |offset: usize, bytes: Vec<u8>| h[offset..offset + bytes.len()].copy_from_slice(&bytes);
        put(0, T::I32.bytes(348.0, big));
        for (i, &d) in self.dim.iter().enumerate() {
            put(40 + 2 * i, T::I16.bytes(d.into(), big));
        }
        put(70, T::I16.bytes(self.code.into(), big));
        for (i, &p) in self.pixdim.iter().enumerate() {
            put(80 + 4 * i, T::F32.bytes(p.into(), big));
        }
        put(108, T::F32.bytes(self.vox_offset.into(), big));
        put(112, T::F32.bytes(self.slope.into(), big));
        put(116, T::F32.bytes(self.inter.into(), big));
        if let Some(q) = self.qform {
            put(252, T::I16.bytes(1.0, big));
            (0..3).for_each(|a| put(268 + 4 * a, T::F32.bytes(q[a].into(), big)));
        }
        if let Some(s) = self.sform {
            put(254, T::I16.bytes(2.0, big));
            (0..3).for_each(|a| put(292 + 16 * a, T::F32.bytes(s[a].into(), big)));
        }
        put(344, self.magic.to_vec());
        h.extend(data);
        h
    }
}

#[test]
fn nifti_every_type_both_endians_plain_and_gzip() {
    for (code, t) in NIFTI_TYPES {
        for big in [false, true] {
            let nii = Nii {
                big,
                code,
                qform: Some([-1.0, 0.0, 3.5]),
                sform: Some([9.0; 3]),
                ..Nii::default()
            };
            let bytes = nii.build(&packed(t, &ramp(t), big));
            let v = data::load(&file(&format!("t{code}-{big}.nii"), &bytes), None).unwrap();
            check(&v, DIMS, SP, OR, &ramp(t));
            let v =
                data::load(&file(&format!("t{code}-{big}.nii.gz"), &gzip(&bytes)), None).unwrap();
            check(&v, DIMS, SP, OR, &ramp(t));
        }
    }
}

#[test]
fn nifti_scaling_sform_origin_and_pixdim_defaults() {
    let nii = Nii {
        code: 4,
        slope: 0.5,
        inter: -10.0,
        sform: Some([-1.0, 0.0, 3.5]),
        pixdim: [0.0, f32::NAN, 2.0],
        dim: [4, 2, 3, 4, 1, 0, 0, 0],
        vox_offset: 400.0,
        ..Nii::default()
    };
    let mut data = vec![0u8; 48];
    data.extend(packed(T::I16, &ramp(T::I16), false));
    let v = nifti::parse(Path::new("s.nii"), &nii.build(&data)).unwrap();
    let want: Vec<f64> = ramp(T::I16).iter().map(|r| 0.5 * r - 10.0).collect();
    check(&v, DIMS, [1.0, 1.0, 2.0], OR, &want);
}

#[test]
fn nifti_errors() {
    let raw = packed(T::F32, &ramp(T::F32), false);
    let good = Nii::default();
    let two = Nii {
        magic: *b"ni1\0",
        ..good.clone()
    };
    let series = Nii {
        dim: [4, 2, 3, 4, 2, 1, 1, 1],
        ..good.clone()
    };
    let rgb = Nii {
        code: 128,
        ..good.clone()
    };
    let odd = Nii {
        code: 3,
        ..good.clone()
    };
    let offset = Nii {
        vox_offset: 100.5,
        ..good.clone()
    };
    let negative = Nii {
        dim: [3, 2, -3, 4, 1, 1, 1, 1],
        ..good.clone()
    };
    let huge = Nii {
        dim: [3, 32767, 32767, 32767, 1, 1, 1, 1],
        ..good.clone()
    };
    let gz = gzip(&good.build(&raw));
    let mut nifti2 = good.build(&raw);
    nifti2[..4].copy_from_slice(&540i32.to_le_bytes());
    let cases: Vec<(&str, Vec<u8>, &str, &str)> = vec![
        ("empty.nii", vec![], "format", "byte 0"),
        (
            "garbage.nii",
            b"this is not a nifti file at all".to_vec(),
            "format",
            "byte 0",
        ),
        (
            "short.nii",
            good.build(&raw)[..200].to_vec(),
            "truncated",
            "expected 348",
        ),
        ("nifti2.nii", nifti2, "unsupported", "byte 0"),
        ("pair.nii", two.build(&raw), "unsupported", "byte 344"),
        ("series.nii", series.build(&raw), "unsupported", "byte 40"),
        ("rgb.nii", rgb.build(&raw), "unsupported", "byte 70"),
        ("code.nii", odd.build(&raw), "format", "byte 70"),
        ("offset.nii", offset.build(&raw), "format", "byte 108"),
        ("negative.nii", negative.build(&raw), "format", "byte 44"),
        (
            "huge.nii",
            huge.build(&raw),
            "too large",
            "exceed the limit",
        ),
        (
            "trunc.nii",
            good.build(&raw[..50]),
            "truncated",
            "expected 96",
        ),
        (
            "trunc.nii.gz",
            gz[..gz.len() - 20].to_vec(),
            "truncated",
            "expected 96",
        ),
        (
            "garbage.nii.gz",
            vec![0x1f, 0x8b, 0, 1, 2, 3, 4, 5, 6, 7],
            "format",
            "byte 0",
        ),
    ];
    for (name, bytes, kind, location) in cases {
        let path = file(name, &bytes);
        let e = data::load(&path, None).unwrap_err();
        let ok = match kind {
            "format" => matches!(e, DataError::Format { .. }),
            "unsupported" => matches!(e, DataError::Unsupported { .. }),
            "truncated" => matches!(e, DataError::Truncated { .. }),
            _ => matches!(e, DataError::TooLarge { .. }),
        };
        assert!(ok, "{name}: expected {kind}, got {e:?}");
        mentions(&e, &path, location);
    }

    let mut values = ramp(T::F32);
    values[7] = f64::INFINITY;
    let path = file("inf.nii", &good.build(&packed(T::F32, &values, false)));
    let e = nifti::load(&path).unwrap_err();
    assert!(
        matches!(
            e,
            DataError::NonFinite {
                index: 7,
                x: 1,
                y: 0,
                z: 1,
                ..
            }
        ),
        "{e:?}"
    );
    mentions(&e, &path, "sample 7");
}

#[test]
fn unknown_extension_is_rejected() {
    let path = file("volume.raw", b"whatever");
    let e = data::load(&path, None).unwrap_err();
    assert!(matches!(e, DataError::UnknownFormat { .. }), "{e:?}");
    mentions(&e, &path, ".nrrd");
}
