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

/// Each type with its VTK spellings, its NRRD spellings (separated by '|') and its NIfTI code.
const TYPES: [(T, &str, &str, i16); 10] = [
    (
        T::I8,
        "char|signed_char|vtktypeint8",
        "signed char|int8|int8_t",
        256,
    ),
    (
        T::U8,
        "unsigned_char|vtktypeuint8",
        "uchar|unsigned char|uint8|uint8_t",
        2,
    ),
    (
        T::I16,
        "short|vtktypeint16",
        "short|short int|signed short|signed short int|int16|int16_t",
        4,
    ),
    (
        T::U16,
        "unsigned_short|vtktypeuint16",
        "ushort|unsigned short|unsigned short int|uint16|uint16_t",
        512,
    ),
    (
        T::I32,
        "int|vtktypeint32|vtkIdType",
        "int|signed int|int32|int32_t",
        8,
    ),
    (
        T::U32,
        "unsigned_int|vtktypeuint32",
        "uint|unsigned int|uint32|uint32_t",
        768,
    ),
    (
        T::I64,
        "long|vtktypeint64",
        "longlong|long long|long long int|signed long long|signed long long int|int64|int64_t",
        1024,
    ),
    (
        T::U64,
        "unsigned_long|vtktypeuint64",
        "ulonglong|unsigned long long|unsigned long long int|uint64|uint64_t",
        1280,
    ),
    (T::F32, "float|vtktypefloat32", "float", 16),
    (T::F64, "double|vtktypefloat64", "double", 64),
];

const DIMS: [usize; 3] = [2, 3, 4];
const N: usize = 24;

/// (type, spelling) for every spelling in column `vtk` (true) or NRRD (false) of [`TYPES`].
fn spellings(vtk: bool) -> Vec<(T, &'static str)> {
    let split = |(t, v, n, _): (T, &'static str, &'static str, i16)| {
        let names = if vtk { v } else { n };
        names.split('|').map(move |name| (t, name))
    };
    TYPES.into_iter().flat_map(split).collect()
}

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

/// Writes `bytes` to a temporary file whose name ends with `name` (so the extension picks the
/// reader); the process id keeps concurrent test runs apart.
fn file(name: &str, bytes: &[u8]) -> TempFile {
    let pid = std::process::id();
    let path = std::env::temp_dir().join(format!("vmls-loaders-{pid}-{name}"));
    std::fs::write(&path, bytes).unwrap();
    TempFile(path)
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut e = GzEncoder::new(Vec::new(), Compression::default());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-6 * b.abs().max(1.0)
}

/// Checks a loaded 2×3×4 volume against its geometry and values.
fn check(v: &Volume, spacing: [f64; 3], origin: [f64; 3], expected: &[f64]) {
    assert_eq!(v.dims, DIMS);
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
    for (i, (got, &want)) in v.values.iter().zip(expected).enumerate() {
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

/// Loads `bytes` saved as `name` (the extension picks the reader) and checks the error's
/// variant (by its Debug name) and that its message names the file and contains `location`.
fn fails(name: &str, bytes: &[u8], variant: &str, location: &str) {
    fails_picking(name, bytes, None, variant, location);
}

fn fails_picking(name: &str, bytes: &[u8], array: Option<&str>, variant: &str, location: &str) {
    let path = file(name, bytes);
    let e = data::load(&path, array).unwrap_err();
    assert!(
        format!("{e:?}").starts_with(variant),
        "{name}: expected {variant}, got {e:?}"
    );
    mentions(&e, &path, location);
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

#[test]
fn vtk_every_scalar_type_ascii_and_binary_all_versions() {
    for (t, name) in spellings(true) {
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
                    check(&v, SP, OR, &ramp(t));
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
        let geometry = "ASPECT_RATIO 0.5 1 2\nORIGIN -1 0 3.5\nDIMENSIONS 2 3 4\n";
        let mut b = vtk_head("4.2", binary, geometry);
        b.extend(b"POINT_DATA 24\nSCALARS rgb float 3\nLOOKUP_TABLE default\n");
        b.extend(vtk_data(T::F32, &tuples, binary));
        let v = vtk::parse(Path::new("mem.vtk"), &b, None).unwrap();
        check(&v, SP, OR, &(0..N).map(|i| i as f64).collect::<Vec<_>>());
    }
}

#[test]
fn vtk_color_scalars_first_component_in_unit_range() {
    let ascii: Vec<f64> = (0..N).flat_map(|i| [i as f64 / 24.0, 0.5]).collect();
    let mut b = vtk_head("3.0", false, GEOM);
    b.extend(b"POINT_DATA 24\nCOLOR_SCALARS colour 2\n");
    b.extend(vtk_data(T::F32, &ascii, false));
    let v = vtk::parse(Path::new("c.vtk"), &b, None).unwrap();
    let want: Vec<f64> = (0..N).map(|i| i as f64 / 24.0).collect();
    check(&v, SP, OR, &want);

    let bytes: Vec<f64> = (0..N).flat_map(|i| [i as f64 * 10.0, 7.0]).collect();
    let mut b = vtk_head("3.0", true, GEOM);
    b.extend(b"POINT_DATA 24\nCOLOR_SCALARS colour 2\n");
    b.extend(vtk_data(T::U8, &bytes, true));
    let v = vtk::parse(Path::new("c.vtk"), &b, None).unwrap();
    let want: Vec<f64> = (0..N).map(|i| i as f64 * 10.0 / 255.0).collect();
    check(&v, SP, OR, &want);
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
        let name = format!("field-{binary}.vtk");
        let path = file(&name, &vtk_field_file(binary));
        let first = vtk::load(&path, None).unwrap();
        check(&first, SP, OR, &ramp(T::F32));
        let second = vtk::load(&path, Some("wall temp")).unwrap();
        check(&second, SP, OR, &ramp(T::I16));
        let last = data::load(&path, Some("last")).unwrap();
        check(&last, SP, OR, &ramp(T::U8));
        let listed = "no array named 'cellid' (arrays in the file: pressure, wall temp, last)";
        let bytes = vtk_field_file(binary);
        fails_picking(&name, &bytes, Some("cellid"), "NoSuchArray", listed);
    }
}

#[test]
fn vtk_structured_points_that_are_not_the_last_section() {
    let mut b = vtk_head("2.0", false, GEOM);
    b.extend(b"POINT_DATA 24\nSCALARS s double\nLOOKUP_TABLE default\n");
    b.extend(vtk_data(T::F64, &ramp(T::F64), false));
    b.extend(b"CELL_DATA 6\nSCALARS c float\nLOOKUP_TABLE default\n1 2 3 4 5 6\n");
    let v = vtk::parse(Path::new("m.vtk"), &b, None).unwrap();
    check(&v, SP, OR, &ramp(T::F64));
}

/// A version 2.0 ASCII (or BINARY) file with the standard geometry, then `rest`.
fn vtk_with(binary: bool, rest: &[u8]) -> Vec<u8> {
    let mut b = vtk_head("2.0", binary, GEOM);
    b.extend(rest);
    b
}

#[test]
fn vtk_missing_file_names_the_path() {
    let path = std::env::temp_dir().join("vmls-no-such-dir/absent.vtk");
    let e = data::load(&path, None).unwrap_err();
    assert!(matches!(e, DataError::File(_)), "{e:?}");
    assert!(e.to_string().contains(&path.display().to_string()), "{e}");
}

#[test]
fn vtk_truncated_binary_and_ascii() {
    let rest = b"POINT_DATA 24\nSCALARS s float 1\nLOOKUP_TABLE default\n";
    let mut b = vtk_with(true, rest);
    b.extend(&packed(T::F32, &ramp(T::F32), true)[..90]);
    let expected = "expected 96 bytes/values, found 90";
    fails("trunc-bin.vtk", &b, "Truncated", expected);
    let rest = b"POINT_DATA 24\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2 3\n";
    let b = vtk_with(false, rest);
    let expected = "expected 24 bytes/values, found 3";
    fails("trunc-ascii.vtk", &b, "Truncated", expected);
}

#[test]
fn vtk_wrong_counts() {
    let b = vtk_with(false, b"POINT_DATA 20\nSCALARS s float 1\n");
    let expected = "line 8: expected POINT_DATA 24";
    fails("count-pd.vtk", &b, "Format", expected);

    // One value too many: found on line 15 (24 values take lines 10 to 14, five per line).
    let mut b = vtk_with(false, b"POINT_DATA 24\nSCALARS s float 1\n");
    b.extend(vtk_data(T::F32, &ramp(T::F32), false));
    b.extend(b"7\n");
    fails("count-more.vtk", &b, "Format", "line 15");

    // One value short, then the next keyword: reported where the keyword stands.
    let mut b = vtk_with(false, b"POINT_DATA 24\nSCALARS s float 1\n");
    b.extend(vtk_data(T::F32, &ramp(T::F32)[..23], false));
    b.extend(b"CELL_DATA 6\n");
    let expected = "line 15: expected a float32 value (value 24 of 24)";
    fails("count-less.vtk", &b, "Format", expected);

    // A FIELD array that does not have one tuple per point cannot be the volume.
    let b = vtk_with(false, b"POINT_DATA 24\nFIELD f 1\nshort 1 23 float\n");
    let expected = "line 10: expected 24 tuples";
    fails("count-field.vtk", &b, "Format", expected);
}

#[test]
fn vtk_unknown_type_and_string_arrays() {
    let b = vtk_with(false, b"POINT_DATA 24\nSCALARS s quaternion 1\n");
    fails("type.vtk", &b, "Format", "line 9");
    fails("type.vtk", &b, "Format", "found 'quaternion'");
    let b = vtk_with(false, b"POINT_DATA 24\nFIELD f 1\nnames 1 24 variant\n");
    let expected = "line 10: unsupported variant array";
    fails("variant.vtk", &b, "Unsupported", expected);
    // Strings are read past (tests/paraview_files.rs), but they must all be there.
    let b = vtk_with(
        false,
        b"POINT_DATA 24\nFIELD f 1\nnames 1 24 string\na\nb\n",
    );
    fails("string.vtk", &b, "Truncated", "expected 24");
}

#[test]
fn vtk_non_finite_values_name_the_sample() {
    for (binary, bad) in [(false, "nan"), (false, "-inf"), (true, "inf")] {
        let mut values = ramp(T::F32);
        values[13] = bad.parse().unwrap();
        let mut b = vtk_with(binary, b"POINT_DATA 24\nSCALARS s float\n");
        b.extend(vtk_data(T::F32, &values, binary));
        let name = format!("nan-{binary}-{bad}.vtk");
        fails(&name, &b, "NonFinite", "sample 13 (x=1, y=0, z=2)");
    }
}

#[test]
fn vtk_dimensions_overflow_and_limit() {
    // One layer of 1024×1024 more than MAX_SAMPLES allows.
    let over = format!("1024 1024 {}", MAX_SAMPLES / (1024 * 1024) + 1);
    let cases = [
        ("4294967296 4294967296 2", "overflows 64 bits"),
        (&over, "exceed the limit"),
        ("0 4 4", "at least 1"),
    ];
    for (dims, reason) in cases {
        let mut b = vtk_head("2.0", false, &format!("DIMENSIONS {dims}\n"));
        b.extend(b"POINT_DATA 8\nSCALARS s float\n1 2 3 4 5 6 7 8\n");
        fails("huge.vtk", &b, "TooLarge", reason);
    }
}

#[test]
fn vtk_unsupported_datasets() {
    for ty in "STRUCTURED_GRID RECTILINEAR_GRID UNSTRUCTURED_GRID POLYDATA".split(' ') {
        let b = format!("# vtk DataFile Version 3.0\nx\nASCII\nDATASET {ty}\nPOINTS 0 float\n");
        let expected = format!("line 4: unsupported DATASET {ty}");
        fails("ds.vtk", b.as_bytes(), "Unsupported", &expected);
    }
}

#[test]
fn vtk_bad_headers_garbage_and_empty() {
    const HEAD: &str = "# vtk DataFile Version 2.0\nt\nASCII\nDATASET STRUCTURED_POINTS\n";
    fails("empty.vtk", b"", "Format", "line 1");
    let bytes = b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR";
    fails("garbage.vtk", bytes, "Format", "line 1");
    let bytes = b"# vtk DataFile Version 2.0\nt\nTEXT\n";
    fails("form.vtk", bytes, "Format", "line 3");
    let spacing = format!("{HEAD}SPACING 1 0 1\n");
    fails("spacing.vtk", spacing.as_bytes(), "Format", "line 5");
    let no_dims = format!("{HEAD}POINT_DATA 1\n");
    fails("nodims.vtk", no_dims.as_bytes(), "Format", "line 5");
    // Binary garbage where the next keyword should be: the location gives the byte offset.
    let rest = b"POINT_DATA 24\nSCALARS s unsigned_char\nLOOKUP_TABLE default\n";
    let mut b = vtk_with(true, rest);
    let end_of_data = b.len() + N;
    b.extend(packed(T::U8, &ramp(T::U8), true));
    b.extend(b"\xff\xfe\n");
    let expected = format!("(byte {end_of_data})");
    fails("surplus.vtk", &b, "Format", &expected);
}

// ---------------------------------------------------------------- NRRD

fn nrrd_file(fields: &str, data: &[u8]) -> Vec<u8> {
    let mut b = format!("NRRD0004\n# comment\nunits:=mm\n{fields}\n").into_bytes();
    b.extend(data);
    b
}

#[test]
fn nrrd_raw_both_endians_every_type() {
    for (t, name) in spellings(false) {
        for (endian, big) in [("little", false), ("big", true)] {
            let fields = format!(
                "type: {name}\ndimension: 3\nsizes: 2 3 4\nendian: {endian}\nencoding: raw\n\
                 spacings: 0.5 1 2\naxis mins: -1 0 3.5\n"
            );
            let b = nrrd_file(&fields, &packed(t, &ramp(t), big));
            let v = data::load(&file(&format!("t-{name}-{endian}.nrrd"), &b), None).unwrap();
            check(&v, SP, OR, &ramp(t));
        }
    }
}

/// Files past the first MiB stream their raw data from disk chunk by chunk (nrrd::load, issue
/// 25 §4): values, byte skips (also -1), big-endian data and truncation must come out exactly
/// as parsing the whole file gives them, kept at their 16-bit size.
#[test]
fn large_raw_nrrd_streams_as_it_parses() {
    // 2.6 MB of int16: past the 1 MiB head (several chunks: the 12.6 MB float case below).
    let dims = [700, 611, 3];
    let n = dims.iter().product::<usize>();
    let values: Vec<i16> = (0..n).map(|i| ((i * 7919) % 65536) as u16 as i16).collect();
    for (skip, big) in [("0", false), ("5", true), ("-1", false)] {
        let mut data: Vec<u8> = Vec::new();
        if skip == "5" {
            data.extend([9u8; 5]);
        }
        for v in &values {
            data.extend(if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        }
        let endian = if big { "big" } else { "little" };
        let fields = format!(
            "type: int16\ndimension: 3\nsizes: {} {} {}\nendian: {endian}\nencoding: raw\n\
             byte skip: {skip}\n",
            dims[0], dims[1], dims[2]
        );
        let mut b = nrrd_file(&fields, &data);
        if skip == "-1" {
            // -1: the data is the file's last bytes, whatever comes before it.
            let at = b.len() - data.len();
            b.splice(at..at, [1u8; 3]);
        }
        let p = file(&format!("stream-{skip}.nrrd"), &b);
        let streamed = nrrd::load(&p).expect("streamed");
        let parsed = nrrd::parse(&p, &b).expect("parsed");
        assert!(
            streamed == parsed,
            "skip {skip}: streamed and parsed volumes differ"
        );
        assert!(
            streamed.values == data::Values::I16(values.clone()),
            "skip {skip}: values differ"
        );
        // Cut short: the same error as parsing reports.
        let short = file(
            &format!("stream-{skip}-short.nrrd"),
            &b[..b.len() - data.len() / 2],
        );
        match nrrd::load(&short) {
            Ok(_) => panic!("skip {skip}: a truncated file was accepted"),
            Err(e) => assert!(matches!(e, DataError::Truncated { .. }), "skip {skip}: {e}"),
        }
    }
    // A CRLF header whose blank line's "\r" is the last byte of the first MiB, and a `line skip`
    // line across that boundary: the streamed read must not start the data early.
    let head = 1usize << 20;
    let data: Vec<u8> = (0..600_000u32).map(|i| (i % 251) as u8).collect();
    for skip_line in [false, true] {
        let fields = format!(
            "NRRD0004\r\ntype: uint8\r\ndimension: 3\r\nsizes: 600 1000 1\r\nencoding: raw\r\n{}",
            if skip_line { "line skip: 1\r\n" } else { "" }
        );
        let mut b = fields.into_bytes();
        // A comment that puts the boundary where wanted: in the blank line ("\r" | "\n"),
        // or inside the skipped line.
        let tail = if skip_line { 2 + 10 } else { 1 };
        let fill = head - b.len() - tail;
        b.extend(b"#");
        b.extend(std::iter::repeat_n(b'x', fill - 3));
        b.extend(b"\r\n");
        if skip_line {
            b.extend(b"\r\nskipped line crossing the boundary\r\n");
        } else {
            b.extend(b"\r\n");
        }
        b.extend(&data);
        let p = file(&format!("stream-boundary-{skip_line}.nrrd"), &b);
        let streamed = nrrd::load(&p).expect("streamed");
        let parsed = nrrd::parse(&p, &b).expect("parsed");
        assert!(
            streamed == parsed,
            "line skip {skip_line}: streamed data misplaced"
        );
        assert!(streamed.values == data::Values::U8(data.clone()));
    }
    // Floats over several 8 MiB chunks, non-finite values still refused.
    let dims = [1024, 1024, 3];
    let n = dims.iter().product::<usize>();
    let mut data: Vec<u8> = (0..n)
        .flat_map(|i| (i as f32 * 0.5).to_le_bytes())
        .collect();
    let fields = "type: float\ndimension: 3\nsizes: 1024 1024 3\nendian: little\nencoding: raw\n";
    let b = nrrd_file(fields, &data);
    let v = nrrd::load(&file("stream-float.nrrd", &b)).expect("streamed floats");
    assert_eq!(v.values.len(), n);
    assert!(
        (0..n)
            .step_by(9973)
            .all(|i| v.values.get(i) == i as f32 * 0.5)
    );
    let last = data.len() - 4;
    data[last..].copy_from_slice(&f32::NAN.to_le_bytes());
    match nrrd::load(&file("stream-nan.nrrd", &nrrd_file(fields, &data))) {
        Ok(_) => panic!("a NaN was accepted"),
        Err(e) => assert!(matches!(e, DataError::NonFinite { .. }), "{e}"),
    }
}

#[test]
fn nrrd_gzip_text_directions_and_skips() {
    let t = T::I16;
    // Directions win over spacings (only their length is used); the origin over axis mins.
    let spatial = "space: right-anterior-superior\nspace directions: (0,0.5,0) (0.6,0.8,0) (0,0,-2)\n\
                   space origin: (-1, 0, 3.5)\nspacings: 7 7 7\naxis mins: 5 5 5\n";
    let gz = nrrd_file(
        &format!("type: int16\ndimension: 3\nsizes: 2 3 4\nendian: big\nencoding: gzip\n{spatial}"),
        &gzip(&packed(t, &ramp(t), true)),
    );
    let v = nrrd::parse(Path::new("g.nrrd"), &gz).unwrap();
    check(&v, SP, OR, &ramp(t));

    let text = nrrd_file(
        &format!("type: short\ndimension: 3\nsizes: 2 3 4\nencoding: ascii\n{spatial}"),
        as_text(t, &ramp(t)).as_bytes(),
    );
    let v = nrrd::parse(Path::new("a.nrrd"), &text).unwrap();
    check(&v, SP, OR, &ramp(t));

    // A leading size-1 axis is dropped; line and byte skips; the default spacing is 1.
    let mut data = b"junk line\n\x00\x01\x02".to_vec();
    data.extend(packed(T::F32, &ramp(T::F32), false));
    let skipped = nrrd_file(
        "type: float\ndimension: 4\nsizes: 1 2 3 4\nendian: little\nencoding: raw\n\
         line skip: 1\nbyte skip: 3\nspace directions: none (1,0,0) (0,1,0) (0,0,1)\n",
        &data,
    );
    let v = nrrd::parse(Path::new("s.nrrd"), &skipped).unwrap();
    check(&v, [1.0; 3], [0.0; 3], &ramp(T::F32));

    // byte skip -1: the data is the last bytes of the file.
    let mut data = b"whatever precedes".to_vec();
    data.extend(packed(T::U16, &ramp(T::U16), false));
    let tail = nrrd_file(
        "type: uint16\ndimension: 3\nsizes: 2 3 4\nendian: little\nencoding: raw\nbyte skip: -1\n",
        &data,
    );
    let v = nrrd::parse(Path::new("t.nrrd"), &tail).unwrap();
    check(&v, [1.0; 3], [0.0; 3], &ramp(T::U16));
}

#[test]
fn nrrd_errors() {
    let raw = packed(T::F32, &ramp(T::F32), false);
    let with = |fields: &str, data: &[u8]| {
        let base = "type: float\ndimension: 3\nsizes: 2 3 4\nendian: little\n";
        nrrd_file(&format!("{base}{fields}"), data)
    };
    let gz_at = format!("byte {}", with("encoding: gzip\n", &[]).len());
    fails("empty.nrrd", b"", "Format", "line 1");
    fails("magic.nrrd", b"NRRX0004\n\n", "Format", "line 1");
    let detached = with("encoding: raw\ndata file: v.raw\n", &[]);
    fails("detached.nrrd", &detached, "Unsupported", "line 9");
    let bzip = with("encoding: bzip2\n", &raw);
    fails("bzip.nrrd", &bzip, "Unsupported", "line 8");
    let dim2 = nrrd_file(
        "type: float\ndimension: 2\nsizes: 4 6\nencoding: raw\n",
        &raw,
    );
    fails("dim2.nrrd", &dim2, "Unsupported", "line 5");
    let complex = nrrd_file("type: complex\n", &raw);
    fails("type.nrrd", &complex, "Format", "line 4");
    let endian = nrrd_file(
        "type: float\ndimension: 3\nsizes: 2 3 4\nencoding: raw\n",
        &raw,
    );
    fails("endian.nrrd", &endian, "Format", "line 8");
    let spacings = with("encoding: raw\nspacings: 1 1\n", &raw);
    fails("spacings.nrrd", &spacings, "Format", "line 9");
    fails("noend.nrrd", b"NRRD0004\ntype: float\n", "Format", "line 2");
    let short = with("encoding: raw\n", &raw[..95]);
    fails("truncated.nrrd", &short, "Truncated", "expected 96");
    // A stream cut short, a flipped byte of its CRC-32 or length, or of its payload, is an
    // error naming the stream's byte, never values read from the part that was there.
    let gz = gzip(&raw);
    let short_gz = with("encoding: gzip\n", &gz[..30]);
    fails("truncgz.nrrd", &short_gz, "Format", "cut short");
    let no_trailer = with("encoding: gzip\n", &gz[..gz.len() - 8]);
    fails("notrailer.nrrd", &no_trailer, "Format", "cut short");
    for at in [gz.len() - 8, gz.len() - 3, gz.len() / 2] {
        let mut flipped = gz.clone();
        flipped[at] ^= 0x10;
        fails(
            "crc.nrrd",
            &with("encoding: gzip\n", &flipped),
            "Format",
            &gz_at,
        );
    }
    // Data far beyond what the header declares is refused; a little is read past.
    let big = gzip(&vec![0u8; 96 + (1 << 17)]);
    fails(
        "surplusgz.nrrd",
        &with("encoding: gzip\n", &big),
        "Format",
        "header declares 96",
    );
    let path = file(
        "slackgz.nrrd",
        &with("encoding: gzip\n", &gzip(&[0u8; 100])),
    );
    data::load(&path, None).expect("4 bytes past the data are read past");
    // Bytes after the last member that start no other one are ignored (as gzip -d does), and
    // several members are read in turn, each checked.
    let mut trailing = gz.clone();
    trailing.extend(b"\n\0\0");
    let path = file("trailgz.nrrd", &with("encoding: gzip\n", &trailing));
    data::load(&path, None).expect("trailing bytes");
    let mut members = gzip(&raw[..40]);
    members.extend(gzip(&raw[40..]));
    let path = file("membersgz.nrrd", &with("encoding: gzip\n", &members));
    let v = data::load(&path, None).expect("two members");
    check(&v, [1.0; 3], [0.0; 3], &ramp(T::F32));
    let mut bad_second = members.clone();
    let n = bad_second.len();
    bad_second[n - 6] ^= 0x20;
    fails(
        "member2.nrrd",
        &with("encoding: gzip\n", &bad_second),
        "Format",
        &gz_at,
    );
    let corrupt_gz = with("encoding: gzip\n", b"not gzip at all");
    fails("corruptgz.nrrd", &corrupt_gz, "Format", &gz_at);
    let surplus = nrrd_file(
        "type: int\ndimension: 3\nsizes: 1 1 2\nencoding: text\n",
        b"1 2\n3\n",
    );
    fails("surplus.nrrd", &surplus, "Format", "line 10");
    let sized = |sizes: &str| {
        let fields =
            format!("type: float\ndimension: 3\nsizes: {sizes}\nencoding: raw\nendian: big\n");
        nrrd_file(&fields, &raw)
    };
    let overflow = sized("4294967296 4294967296 2");
    fails("overflow.nrrd", &overflow, "TooLarge", "overflows");
    let limit = sized("1024 1024 1025");
    fails("limit.nrrd", &limit, "TooLarge", "exceed the limit");

    let mut values = ramp(T::F64);
    values[23] = f64::NAN;
    let fields = "type: double\ndimension: 3\nsizes: 2 3 4\nencoding: raw\nendian: big\n";
    let nan = nrrd_file(fields, &packed(T::F64, &values, true));
    let expected = "sample 23 (x=1, y=2, z=3) is NaN";
    fails("nan.nrrd", &nan, "NonFinite", expected);
}

// ---------------------------------------------------------------- NIfTI

/// A NIfTI-1 header (2×3×4, pixdim 0.5 -1 2, data at byte 352) that tests then change.
struct Nii {
    h: Vec<u8>,
    big: bool,
}

impl Nii {
    fn new(big: bool, code: i16) -> Self {
        let mut n = Nii {
            h: vec![0; 352],
            big,
        };
        n.h[344..348].copy_from_slice(b"n+1\0");
        let n = n.set(T::I32, 0, 348.0).dims([3, 2, 3, 4, 1, 1, 1, 1]);
        let n = n.set(T::I16, 70, code.into()).set(T::F32, 108, 352.0);
        n.set(T::F32, 80, 0.5)
            .set(T::F32, 84, -1.0)
            .set(T::F32, 88, 2.0)
    }

    fn set(mut self, t: T, offset: usize, v: f64) -> Self {
        let b = t.bytes(v, self.big);
        self.h[offset..offset + b.len()].copy_from_slice(&b);
        self
    }

    fn dims(self, dim: [i16; 8]) -> Self {
        let set = |n: Self, (i, d): (usize, i16)| n.set(T::I16, 40 + 2 * i, d.into());
        dim.into_iter().enumerate().fold(self, set)
    }

    /// Sets qform_code (252) or sform_code (254) and the matching translation.
    fn origin(self, code_at: usize, first: usize, stride: usize, o: [f64; 3]) -> Self {
        let n = self.set(T::I16, code_at, 1.0).set(T::F32, first, o[0]);
        n.set(T::F32, first + stride, o[1])
            .set(T::F32, first + 2 * stride, o[2])
    }

    fn qform(self, o: [f64; 3]) -> Self {
        self.origin(252, 268, 4, o)
    }

    fn sform(self, o: [f64; 3]) -> Self {
        self.origin(254, 292, 16, o)
    }

    fn data(mut self, data: &[u8]) -> Vec<u8> {
        self.h.extend(data);
        self.h
    }
}

#[test]
fn nifti_every_type_both_endians_plain_and_gzip() {
    for (t, _, _, code) in TYPES {
        for big in [false, true] {
            let nii = Nii::new(big, code).qform(OR).sform([9.0; 3]);
            let bytes = nii.data(&packed(t, &ramp(t), big));
            let path = file(&format!("t{code}-{big}.nii"), &bytes);
            check(&data::load(&path, None).unwrap(), SP, OR, &ramp(t));
            let path = file(&format!("t{code}-{big}.nii.gz"), &gzip(&bytes));
            check(&data::load(&path, None).unwrap(), SP, OR, &ramp(t));
        }
    }
}

#[test]
fn nifti_scaling_sform_origin_and_pixdim_defaults() {
    // 4-D with one time point; 48 extension bytes before the data at 400; pixdim 0 and NaN.
    let nii = Nii::new(false, 4).dims([4, 2, 3, 4, 1, 0, 0, 0]).sform(OR);
    let nii = nii
        .set(T::F32, 112, 0.5)
        .set(T::F32, 116, -10.0)
        .set(T::F32, 108, 400.0);
    let nii = nii.set(T::F32, 80, 0.0).set(T::F32, 84, f64::NAN);
    let mut data = vec![0u8; 48];
    data.extend(packed(T::I16, &ramp(T::I16), false));
    let v = nifti::parse(Path::new("s.nii"), &nii.data(&data)).unwrap();
    let want: Vec<f64> = ramp(T::I16).iter().map(|r| 0.5 * r - 10.0).collect();
    check(&v, [1.0, 1.0, 2.0], OR, &want);
}

#[test]
fn nifti_errors() {
    let raw = packed(T::F32, &ramp(T::F32), false);
    let good = Nii::new(false, 16).data(&raw);
    let gz = gzip(&good);
    let mut nifti2 = good.clone();
    nifti2[..4].copy_from_slice(&540i32.to_le_bytes());
    let mut pair = good.clone();
    pair[344..348].copy_from_slice(b"ni1\0");
    let dims = |d: [i16; 8]| Nii::new(false, 16).dims(d).data(&raw);
    let float = |offset: usize, v: f64| Nii::new(false, 16).set(T::F32, offset, v).data(&raw);
    fails("empty.nii", b"", "Format", "byte 0");
    fails("garbage.nii", b"not a NIfTI file", "Format", "byte 0");
    fails("short.nii", &good[..200], "Truncated", "expected 348");
    fails("nifti2.nii", &nifti2, "Unsupported", "byte 0");
    fails("pair.nii", &pair, "Unsupported", "byte 344");
    let series = dims([4, 2, 3, 4, 2, 1, 1, 1]);
    fails("series.nii", &series, "Unsupported", "byte 40");
    let rgb = Nii::new(false, 128).data(&raw);
    fails("rgb.nii", &rgb, "Unsupported", "byte 70");
    let code = Nii::new(false, 3).data(&raw);
    fails("code.nii", &code, "Format", "byte 70");
    fails("offset.nii", &float(108, 100.5), "Format", "byte 108");
    fails("far.nii", &float(108, 1e30), "Format", "byte 108");
    let nan_origin = Nii::new(false, 16).qform([0.0, f64::NAN, 0.0]).data(&raw);
    fails("origin.nii", &nan_origin, "Format", "byte 272");
    let negative = dims([3, 2, -3, 4, 1, 1, 1, 1]);
    fails("negative.nii", &negative, "Format", "byte 44");
    let huge = dims([3, 32767, 32767, 32767, 1, 1, 1, 1]);
    fails("huge.nii", &huge, "TooLarge", "exceed the limit");
    fails("trunc.nii", &good[..352 + 50], "Truncated", "expected 96");
    let short_gz = &gz[..gz.len() - 20];
    fails("trunc.nii.gz", short_gz, "Format", "cut short");
    for at in [gz.len() - 8, gz.len() - 1] {
        let mut flipped = gz.clone();
        flipped[at] ^= 0x01;
        fails("crc.nii.gz", &flipped, "Format", "byte 0");
    }
    fails(
        "notrailer.nii.gz",
        &gz[..gz.len() - 8],
        "Format",
        "cut short",
    );
    let bad_gz = [0x1f, 0x8b, 0, 1, 2, 3, 4, 5, 6, 7];
    fails("garbage.nii.gz", &bad_gz, "Format", "byte 0");

    let mut values = ramp(T::F32);
    values[7] = f64::INFINITY;
    let inf = Nii::new(true, 16).data(&packed(T::F32, &values, true));
    let expected = "sample 7 (x=1, y=0, z=1) is inf";
    fails("inf.nii", &inf, "NonFinite", expected);
}

#[test]
fn unknown_extension_is_rejected() {
    let path = file("volume.raw", b"whatever");
    let e = data::load(&path, None).unwrap_err();
    assert!(matches!(e, DataError::UnknownFormat { .. }), "{e:?}");
    mentions(&e, &path, ".nrrd");
}
