//! Scattered points from CSV (`.csv`) and PLY (`.ply`) files → [`Geometry::Points`] with one
//! point [`DataArray`] per scalar column or property.
//!
//! CSV contract and choices (read with the `csv` crate, cargo feature `csv`, on by default):
//! - a header row is required (a UTF-8 byte-order mark before it is skipped); fields are
//!   comma-separated, may be quoted, and are trimmed;
//! - positions are the columns named `x`, `y`, `z` or ParaView's `Points:0`, `Points:1`,
//!   `Points:2` (case-insensitive; `Points:*` is what ParaView's "Save Data" writes). All
//!   three are required, and two columns naming the same axis are an error;
//! - every other column whose first data row holds a number becomes an array named by its
//!   header (ParaView's `velocity:0`, `velocity:1`, ... give one array each); a column whose
//!   first data row is not a number is a text column (labels, ids as names) and is ignored
//!   entirely. Once a column is numeric, every later row must hold a number there;
//! - every row must have as many fields as the header; blank lines are skipped; at least one
//!   data row is required;
//! - errors name the line (1-based, the header is line 1) and the column by number and name.
//!
//! PLY contract and choices (read with `ply-rs-bw`):
//! - `ascii`, `binary_little_endian` and `binary_big_endian`;
//! - the `vertex` element's `x`, `y`, `z` are positions (scalar properties of any type) and
//!   every other scalar vertex property becomes an array named by the property; list
//!   properties of the vertex element are skipped;
//! - elements before `vertex` are read past; elements after it (faces, edges) are not read at
//!   all: faces are ignored because vmls renders the vertices as scattered samples;
//! - at least one vertex is required; binary files must hold enough bytes for the declared
//!   vertices (checked before anything is allocated); the crate's own messages are quoted for
//!   syntax errors.
//!
//! Both: coordinates are kept as f64, arrays as f32; counts are limited to [`MAX_SAMPLES`];
//! NaN/Inf coordinates and values are rejected by [`Dataset::validate`], which names the point
//! (point i is data row i, on line i + 2 of a CSV file without quoted line breaks).

use super::dataset::{DataArray, Dataset, Geometry, Location};
use super::{DataError, MAX_SAMPLES};
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{ElementDef, Encoding, Property, PropertyAccess, PropertyType, ScalarType};
use std::io::Cursor;
use std::path::Path;

/// Reads a `.csv` or `.ply` file, choosing by extension.
pub fn load(path: &Path) -> Result<Dataset, DataError> {
    let bytes = super::read_file(path)?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let dataset = if name.ends_with(".ply") {
        parse_ply(path, &bytes)?
    } else {
        parse_csv(path, &bytes)?
    };
    dataset.validate(path)?;
    Ok(dataset)
}

fn format_error(path: &Path, location: String, expected: &str, found: String) -> DataError {
    DataError::Format {
        path: path.to_path_buf(),
        location,
        expected: expected.to_string(),
        found,
    }
}

fn too_many(path: &Path, n: u64, what: &str) -> DataError {
    DataError::TooLarge {
        path: path.to_path_buf(),
        dims: [n, 1, 1],
        reason: format!("{n} {what} exceed the limit of {MAX_SAMPLES}"),
    }
}

/// The axis (0, 1, 2) a CSV header names, if any.
#[cfg(feature = "csv")]
fn axis(header: &str) -> Option<usize> {
    match header.to_ascii_lowercase().as_str() {
        "x" | "points:0" => Some(0),
        "y" | "points:1" => Some(1),
        "z" | "points:2" => Some(2),
        _ => None,
    }
}

/// What a CSV column holds, decided by the header and the first data row.
#[cfg(feature = "csv")]
#[derive(Clone, Copy, PartialEq)]
enum Column {
    Axis(usize),
    /// Index into the arrays.
    Array(usize),
    Text,
}

/// Parses CSV bytes; `path` only names the file in errors.
#[cfg(feature = "csv")]
pub fn parse_csv(path: &Path, bytes: &[u8]) -> Result<Dataset, DataError> {
    // Spreadsheets write a UTF-8 byte-order mark, which would otherwise hide the first name.
    let bytes = bytes.strip_prefix(b"\xef\xbb\xbf").unwrap_or(bytes);
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .from_reader(bytes);
    let csv_error = |e: csv::Error| {
        let line = e.position().map_or(0, |p| p.line());
        let found = match e.kind() {
            csv::ErrorKind::UnequalLengths {
                expected_len, len, ..
            } => format!("{len} fields (the header has {expected_len})"),
            _ => e.to_string(),
        };
        format_error(path, format!("line {line}"), "a CSV row", found)
    };
    let headers: Vec<String> = reader
        .headers()
        .map_err(csv_error)?
        .iter()
        .map(str::to_string)
        .collect();
    if headers.iter().all(String::is_empty) {
        let found = if bytes.is_empty() {
            "an empty file"
        } else {
            "no column names"
        };
        return Err(format_error(
            path,
            "line 1".into(),
            "a header row",
            found.into(),
        ));
    }
    let mut axes: [Option<usize>; 3] = [None; 3];
    for (c, h) in headers.iter().enumerate() {
        if let Some(a) = axis(h) {
            if let Some(first) = axes[a] {
                let found = format!(
                    "columns {} ('{}') and {} ('{h}')",
                    first + 1,
                    headers[first],
                    c + 1
                );
                return Err(format_error(
                    path,
                    "line 1".into(),
                    "one column per axis",
                    found,
                ));
            }
            axes[a] = Some(c);
        }
    }
    if let Some(a) = axes.iter().position(Option::is_none) {
        let expected = [
            "an x (or Points:0) column",
            "a y (or Points:1) column",
            "a z (or Points:2) column",
        ][a];
        let found = format!("columns {}", headers.join(", "));
        return Err(format_error(path, "line 1".into(), expected, found));
    }

    let mut columns: Vec<Column> = Vec::new();
    let mut points: Vec<[f64; 3]> = Vec::new();
    let mut arrays: Vec<DataArray> = Vec::new();
    // Each numeric column's values, moved into its array at the end.
    let mut column_values: Vec<Vec<f32>> = Vec::new();
    let mut record = csv::StringRecord::new();
    while reader.read_record(&mut record).map_err(csv_error)? {
        let line = record.position().map_or(0, |p| p.line());
        if points.len() as u64 >= MAX_SAMPLES {
            return Err(too_many(path, points.len() as u64 + 1, "points"));
        }
        if columns.is_empty() {
            columns = headers
                .iter()
                .enumerate()
                .map(|(c, h)| match axis(h) {
                    Some(a) => Column::Axis(a),
                    None if record.get(c).is_some_and(|v| v.parse::<f64>().is_ok()) => {
                        arrays.push(DataArray {
                            name: if h.is_empty() {
                                format!("column {}", c + 1)
                            } else {
                                h.clone()
                            },
                            location: Location::Point,
                            components: 1,
                            values: Default::default(),
                        });
                        column_values.push(Vec::new());
                        Column::Array(arrays.len() - 1)
                    }
                    None => Column::Text,
                })
                .collect();
        }
        let mut p = [0.0; 3];
        for (c, (field, column)) in record.iter().zip(&columns).enumerate() {
            if *column == Column::Text {
                continue;
            }
            let value = field.parse::<f64>().map_err(|_| {
                let location = format!(
                    "line {line}, column {} ('{}')",
                    c + 1,
                    crate::files::excerpt_text(&headers[c], crate::files::EXCERPT_CHARS)
                );
                format_error(
                    path,
                    location,
                    "a number",
                    crate::files::excerpt(field.as_bytes()),
                )
            })?;
            match *column {
                Column::Axis(a) => p[a] = value,
                Column::Array(i) => column_values[i].push(value as f32),
                Column::Text => {}
            }
        }
        points.push(p);
    }
    if points.is_empty() {
        let found = "no data row after the header".to_string();
        return Err(format_error(
            path,
            "line 2".into(),
            "at least one point",
            found,
        ));
    }
    for (array, values) in arrays.iter_mut().zip(column_values) {
        array.values = values.into();
    }
    Ok(Dataset {
        geometry: Geometry::Points { points },
        arrays,
    })
}

/// Without the `csv` feature (an embedder's build with `default-features = false`), a `.csv`
/// file is refused by name: the CSV reader is the one input format that needs its own crate.
#[cfg(not(feature = "csv"))]
pub fn parse_csv(path: &Path, _bytes: &[u8]) -> Result<Dataset, DataError> {
    Err(DataError::Unsupported {
        path: path.to_path_buf(),
        location: "file".into(),
        what: "CSV points in this build of vmls (it reads them with the cargo feature `csv`)"
            .into(),
    })
}

/// One PLY element as the scalar properties it holds, in header order (lists are skipped).
struct Row(Vec<f64>);

impl PropertyAccess for Row {
    fn new() -> Self {
        Row(Vec::new())
    }

    fn set_property(&mut self, _name: &str, property: Property) {
        let v = match property {
            Property::Char(v) => f64::from(v),
            Property::UChar(v) => f64::from(v),
            Property::Short(v) => f64::from(v),
            Property::UShort(v) => f64::from(v),
            Property::Int(v) => f64::from(v),
            Property::UInt(v) => f64::from(v),
            Property::Float(v) => f64::from(v),
            Property::Double(v) => v,
            _ => return,
        };
        self.0.push(v);
    }
}

fn scalar_size(t: &ScalarType) -> u64 {
    match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

/// Refuses a vertex element that names one property twice: the PLY parser keeps properties
/// by name, so the second would silently shift every value after it.
fn check_unique_properties(path: &Path, bytes: &[u8]) -> Result<(), DataError> {
    let end = bytes
        .windows(10)
        .position(|w| w == b"end_header")
        .unwrap_or(bytes.len().min(1 << 16));
    let header = String::from_utf8_lossy(&bytes[..end]);
    let mut in_vertex = false;
    let mut seen: Vec<&str> = Vec::new();
    for (i, line) in header.lines().enumerate() {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["element", name, ..] => in_vertex = *name == "vertex",
            ["property", .., name] if in_vertex => {
                if seen.contains(name) {
                    let found = format!("'{}' twice", crate::files::excerpt_text(name, 40));
                    let expected = "one vertex property per name";
                    return Err(format_error(
                        path,
                        format!("line {}", i + 1),
                        expected,
                        found,
                    ));
                }
                seen.push(name);
            }
            _ => {}
        }
    }
    Ok(())
}

/// Parses PLY bytes; `path` only names the file in errors.
pub fn parse_ply(path: &Path, bytes: &[u8]) -> Result<Dataset, DataError> {
    check_unique_properties(path, bytes)?;
    let parser = Parser::<Row>::new();
    let mut cursor = Cursor::new(bytes);
    let header = parser
        .read_header(&mut cursor)
        .map_err(|e| format_error(path, "header".into(), "a PLY header", e.to_string()))?;
    let Some(vertex) = header.elements.get("vertex") else {
        let names: Vec<&str> = header.elements.keys().map(String::as_str).collect();
        let found = format!("elements [{}]", names.join(", "));
        return Err(format_error(
            path,
            "header".into(),
            "a 'vertex' element",
            found,
        ));
    };
    // Scalar properties in header order: the order in which `Row` receives them.
    let scalars: Vec<&str> = vertex
        .properties
        .values()
        .filter(|p| matches!(p.data_type, PropertyType::Scalar(_)))
        .map(|p| p.name.as_str())
        .collect();
    let mut axes = [0usize; 3];
    for (a, name) in ["x", "y", "z"].into_iter().enumerate() {
        axes[a] = scalars.iter().position(|&s| s == name).ok_or_else(|| {
            let found = format!("vertex properties [{}]", scalars.join(", "));
            let expected = format!("a scalar vertex property '{name}'");
            format_error(path, "header".into(), &expected, found)
        })?;
    }
    if vertex.count as u64 > MAX_SAMPLES {
        return Err(too_many(path, vertex.count as u64, "vertices"));
    }
    if vertex.count == 0 {
        return Err(format_error(
            path,
            "header".into(),
            "at least one vertex",
            "element vertex 0".into(),
        ));
    }
    let mut rows = Vec::new();
    for (name, element) in &header.elements {
        let at = cursor.position();
        if name == "vertex" {
            check_binary_size(
                path,
                &header.encoding,
                element,
                bytes.len() as u64 - at.min(bytes.len() as u64),
            )?;
        }
        let read = parser.read_payload_for_element(&mut cursor, element, &header);
        let elements = read.map_err(|e| {
            let ascii = header.encoding == Encoding::Ascii;
            payload_error(path, bytes, at, ascii, element, &e)
        })?;
        if name == "vertex" {
            rows = elements;
            break;
        }
    }
    let points = rows
        .iter()
        .map(|r| axes.map(|a| r.0.get(a).copied().unwrap_or(f64::NAN)))
        .collect();
    let arrays = scalars
        .iter()
        .enumerate()
        .filter(|(i, _)| !axes.contains(i))
        .map(|(i, &name)| DataArray {
            name: name.to_string(),
            location: Location::Point,
            components: 1,
            values: rows
                .iter()
                .map(|r| r.0.get(i).map_or(f32::NAN, |&v| v as f32))
                .collect(),
        })
        .collect();
    Ok(Dataset {
        geometry: Geometry::Points { points },
        arrays,
    })
}

/// A payload error of ply-rs-bw, located in the file. The crate numbers an element's lines
/// from 0 in "Line N: ..." and appends parser internals on further lines, which are dropped.
fn payload_error(
    path: &Path,
    bytes: &[u8],
    at: u64,
    ascii: bool,
    element: &ElementDef,
    e: &std::io::Error,
) -> DataError {
    let msg = e.to_string();
    let first = msg.lines().next().unwrap_or_default();
    let (index, text) = first
        .strip_prefix("Line ")
        .and_then(|r| r.split_once(": "))
        .and_then(|(n, t)| Some((n.parse::<usize>().ok()?, t)))
        .unwrap_or((0, first));
    let expected = format!("{} '{}' elements", element.count, element.name);
    let start = usize::try_from(at).unwrap_or(usize::MAX).min(bytes.len());
    if !ascii {
        let location = format!("byte {at} (start of the '{}' data)", element.name);
        return format_error(path, location, &expected, text.to_string());
    }
    let lines_before = bytes[..start].iter().filter(|&&b| b == b'\n').count();
    let content = bytes[start..]
        .split(|&b| b == b'\n')
        .nth(index)
        .map(|l| String::from_utf8_lossy(l).trim().to_string())
        .unwrap_or_default();
    let found = if content.is_empty() {
        text.to_string()
    } else {
        format!("{} ({text})", crate::files::excerpt(content.as_bytes()))
    };
    format_error(
        path,
        format!("line {}", lines_before + 1 + index),
        &expected,
        found,
    )
}

/// In a binary file without list properties, the vertices need `count × row size` bytes.
fn check_binary_size(
    path: &Path,
    encoding: &Encoding,
    element: &ElementDef,
    available: u64,
) -> Result<(), DataError> {
    if *encoding == Encoding::Ascii {
        return Ok(());
    }
    let mut row = 0u64;
    for p in element.properties.values() {
        match &p.data_type {
            PropertyType::Scalar(t) => row += scalar_size(t),
            PropertyType::List(..) => return Ok(()),
        }
    }
    let needed = row.saturating_mul(element.count as u64);
    if needed > available {
        return Err(DataError::Truncated {
            path: path.to_path_buf(),
            expected: needed,
            found: available,
        });
    }
    Ok(())
}
