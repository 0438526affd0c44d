//! VTK XML reader for the serial formats ParaView writes: `.vti` (ImageData), `.vtr`
//! (RectilinearGrid), `.vts` (StructuredGrid), `.vtu` (UnstructuredGrid) and `.vtp` (PolyData).
//! The `type` attribute of `<VTKFile>` decides the kind, not the extension.
//!
//! Contract and choices:
//! - `.vti`: the geometry is the `Extent` of the piece (`WholeExtent` when the piece has none).
//!   VTK places point (i, j, k) of the extent at `Origin + (i, j, k)·Spacing`, so an extent that
//!   does not start at 0 moves the first point: the [`Geometry::Image`] origin is
//!   `Origin + start·Spacing`. `Spacing` must be finite and > 0 (a negative spacing mirrors the
//!   grid, which `Geometry::Image` cannot say: unsupported) and a `Direction` other than the
//!   identity is unsupported (a rotated grid is not axis-aligned);
//! - `.vtr`: `<Coordinates>` holds the x, y and z coordinate arrays in that order, one value per
//!   point along each axis of the piece's extent;
//! - `.vts`: `<Points>` holds one 3-component point per grid point;
//! - `.vtu`: `<Points>` and `<Cells>` (`connectivity`, `offsets`, `types`, found by `Name`).
//!   `offsets` holds the end of each cell, `NumberOfCells` values as VTK writes them (a leading
//!   0 makes one value too many and is rejected); they must increase and end at the
//!   connectivity's length. Types 10–14 are read, any other is [`DataError::UnsupportedCell`]
//!   naming the cell (before its points are checked); indices must be whole, >= 0 and below the
//!   piece's `NumberOfPoints` ([`DataError::IndexOutOfRange`] names the piece's count);
//! - `.vtp`: only the `<Points>` are kept ([`Geometry::Points`]); `<Verts>` is checked when
//!   present (offsets increasing, indices in range), `<Lines>`, `<Strips>` and `<Polys>` are not
//!   read, and neither is `<CellData>`, since its values belong to those cells;
//! - pieces: `.vtu` and `.vtp` files with several `<Piece>`s are merged (point indices offset by
//!   the points of the pieces before; every piece must have the same arrays in the same order);
//!   the grid kinds must have exactly one piece (stitching extents is not supported);
//! - `<PointData>` and `<CellData>`: every `DataArray` of a numeric type becomes a
//!   [`DataArray`], in file order, keeping component 0 of each tuple; `String` and `Bit` arrays
//!   are skipped; `<FieldData>` is ignored;
//! - types Int8 ... UInt64, Float32, Float64 everywhere; coordinates are kept in f64, array
//!   values become f32 (precision past f32's mantissa is lost, a value beyond its range becomes
//!   infinite and is rejected like NaN);
//! - sizes: `NumberOfPoints`, `NumberOfCells` (and their sums over pieces) and the extents'
//!   point counts are checked against [`MAX_SAMPLES`] before any array is read; every array must
//!   hold exactly the tuples its place implies (an optional `NumberOfTuples` must agree), except
//!   `connectivity`, whose length comes from the data;
//! - encodings, compression and the safety checks on byte counts are those of
//!   `vtk_xml_decode.rs`; `byte_order` defaults to LittleEndian and `header_type` to UInt32
//!   (file version 0.1); compressors other than `vtkZLibDataCompressor` are unsupported.
//!
//! The raw `<AppendedData>` block is not XML: the file is cut at the first `<AppendedData`, only
//! the part before it is parsed as XML (quick-xml), and the bytes after the `_` marker are the
//! data that `offset` attributes point into. Errors name the byte offset in the file.

use super::dataset::{CellType, Cells, DataArray, Dataset, Geometry, Location, vtk_cell_name};
use super::encoding::Scalar;
use super::vtk_xml_decode::{Appended, ArrayDesc, Decoder, Encoding, Form, Keep};
use super::vtk_xml_tree::{El, build};
use super::{DataError, MAX_SAMPLES};
use std::path::Path;

/// Reads and parses a VTK XML file.
pub fn load(path: &Path) -> Result<Dataset, DataError> {
    let bytes = super::read_file(path)?;
    parse(path, &bytes)
}

/// Parses VTK XML bytes; `path` only names the file in errors.
pub fn parse(path: &Path, bytes: &[u8]) -> Result<Dataset, DataError> {
    let cut = bytes.windows(13).position(|w| w == b"<AppendedData");
    let doc = build(path, &bytes[..cut.unwrap_or(bytes.len())], cut.is_some())?;
    let root = El { doc: &doc, i: 0 };
    if root.name() != "VTKFile" {
        return Err(root.format("a <VTKFile> root element", format!("<{}>", root.name())));
    }
    let kind = root.need_attr("type")?;
    // The kind is judged first: an unsupported kind (a HyperTreeGrid, a multiblock) is named
    // as such, not as a missing element or an unknown compressor.
    if !KINDS.contains(&kind) {
        return Err(unsupported_kind(&root, kind));
    }
    let encoding = Encoding {
        big_endian: match root.attr("byte_order") {
            None | Some("LittleEndian") => false,
            Some("BigEndian") => true,
            Some(o) => return Err(root.format("byte_order LittleEndian or BigEndian", o)),
        },
        header64: match root.attr("header_type") {
            None | Some("UInt32") => false,
            Some("UInt64") => true,
            Some(o) => return Err(root.format("header_type UInt32 or UInt64", o)),
        },
        zlib: match root.attr("compressor") {
            None | Some("") => false,
            Some("vtkZLibDataCompressor") => true,
            Some(o) => {
                let what = format!("compressor {o} (only vtkZLibDataCompressor is read)");
                return Err(root.unsupported(what));
            }
        },
    };
    let appended = match cut {
        Some(at) => Some(appended_block(path, bytes, at)?),
        None => None,
    };
    let dec = Decoder {
        path,
        encoding,
        appended,
    };
    let body = root.need(kind)?;
    let dataset = match kind {
        "ImageData" => image(&dec, body)?,
        "RectilinearGrid" => rectilinear(&dec, body)?,
        "StructuredGrid" => structured(&dec, body)?,
        "UnstructuredGrid" => unstructured(&dec, body, false)?,
        "PolyData" => unstructured(&dec, body, true)?,
        other => return Err(unsupported_kind(&root, other)),
    };
    dataset.validate(path)?;
    Ok(dataset)
}

/// The dataset kinds vmls reads.
const KINDS: [&str; 5] = [
    "ImageData",
    "RectilinearGrid",
    "StructuredGrid",
    "UnstructuredGrid",
    "PolyData",
];

fn unsupported_kind(root: &El<'_, '_>, kind: &str) -> DataError {
    root.unsupported(format!(
        "VTKFile type {} (vmls reads {})",
        crate::files::excerpt_text(kind, 40),
        KINDS.join(", ")
    ))
}

/// Locates the data after the `_` marker of the `<AppendedData` tag at byte `at`.
fn appended_block<'a>(path: &Path, bytes: &'a [u8], at: usize) -> Result<Appended<'a>, DataError> {
    let err = |pos: usize, expected: &str, found: String| DataError::Format {
        path: path.to_path_buf(),
        location: format!("byte {pos}"),
        expected: expected.into(),
        found,
    };
    let rest = &bytes[at..];
    let gt = rest
        .iter()
        .position(|&b| b == b'>')
        .ok_or_else(|| err(at, "'>' closing <AppendedData", "end of file".into()))?;
    // The tag alone is a well-formed XML fragment: let quick-xml read its attributes.
    let tag = std::str::from_utf8(&rest[..=gt])
        .map_err(|_| err(at, "an ASCII tag", "invalid UTF-8".into()))?;
    let doc = build(path, tag.as_bytes(), true)?;
    let el = El { doc: &doc, i: 0 };
    let encoding = el.need_attr("encoding")?;
    let after = at + gt + 1;
    let marker = bytes[after..].iter().position(|b| !b.is_ascii_whitespace());
    let start = match marker {
        Some(m) if bytes[after + m] == b'_' => after + m + 1,
        _ => {
            let found = crate::files::excerpt(bytes.get(after..).unwrap_or_default());
            return Err(err(after, "'_' starting the appended data", found));
        }
    };
    let data = &bytes[start..];
    match encoding {
        "raw" => Ok(Appended {
            data,
            at: start,
            base64: false,
        }),
        "base64" => {
            // Base64 text has no '<': the first one starts </AppendedData>.
            let end = data.iter().position(|&b| b == b'<').unwrap_or(data.len());
            Ok(Appended {
                data: data[..end].trim_ascii_end(),
                at: start,
                base64: true,
            })
        }
        other => Err(DataError::Unsupported {
            path: path.to_path_buf(),
            location: format!("byte {at}"),
            what: format!("AppendedData encoding {other} (raw and base64 are read)"),
        }),
    }
}

/// The description of DataArray `el`; `None` for the non-numeric types we skip.
fn desc<'d>(el: El<'d, '_>) -> Result<Option<ArrayDesc<'d>>, DataError> {
    let ty = match el.need_attr("type")? {
        "Int8" => Scalar::I8,
        "UInt8" => Scalar::U8,
        "Int16" => Scalar::I16,
        "UInt16" => Scalar::U16,
        "Int32" => Scalar::I32,
        "UInt32" => Scalar::U32,
        "Int64" => Scalar::I64,
        "UInt64" => Scalar::U64,
        "Float32" => Scalar::F32,
        "Float64" => Scalar::F64,
        "String" | "Bit" => return Ok(None),
        other => {
            let expected = "a DataArray type (Int8 ... UInt64, Float32, Float64, String, Bit)";
            return Err(el.format(expected, format!("\"{other}\"")));
        }
    };
    let components = match el.attr("NumberOfComponents") {
        None => 1,
        Some(t) => t
            .trim()
            .parse::<usize>()
            .ok()
            .filter(|n| (1..=1 << 20).contains(n))
            .ok_or_else(|| el.format("NumberOfComponents from 1 to 1048576", format!("\"{t}\"")))?,
    };
    let number = |key: &str| -> Result<Option<u64>, DataError> {
        match el.attr(key) {
            None => Ok(None),
            Some(t) => t
                .trim()
                .parse::<u64>()
                .map(Some)
                .map_err(|_| el.format(format!("{key} as a whole number"), format!("\"{t}\""))),
        }
    };
    let form = match el.need_attr("format")? {
        "ascii" => Form::Ascii,
        "binary" => Form::Binary,
        "appended" => Form::Appended(
            number("offset")?.ok_or_else(|| el.format("an offset=\"...\" attribute", "none"))?,
        ),
        other => return Err(el.format("format ascii, binary or appended", format!("\"{other}\""))),
    };
    let e = el.e();
    Ok(Some(ArrayDesc {
        name: el.attr("Name").unwrap_or_default().to_string(),
        ty,
        components,
        form,
        at: el.at(),
        text: &e.text,
        text_at: e.text_at,
        tuples: number("NumberOfTuples")?,
    }))
}

/// A DataArray that must be numeric.
fn numeric<'d>(el: El<'d, '_>) -> Result<ArrayDesc<'d>, DataError> {
    desc(el)?.ok_or_else(|| el.format("a numeric DataArray", el.attr("type").unwrap_or_default()))
}

/// The first DataArray child of `el`.
fn first_array<'d, 'a>(el: El<'d, 'a>) -> Result<El<'d, 'a>, DataError> {
    el.children()
        .find(|c| c.name() == "DataArray")
        .ok_or_else(|| el.format("a <DataArray> element", "none"))
}

/// The DataArray child of `el` named `name`, which must have one component.
fn named_array<'d>(el: El<'d, '_>, name: &str) -> Result<ArrayDesc<'d>, DataError> {
    let a = el
        .children()
        .find(|c| c.name() == "DataArray" && c.attr("Name") == Some(name))
        .ok_or_else(|| el.format(format!("a DataArray named '{name}'"), "none"))?;
    let d = numeric(a)?;
    if d.components != 1 {
        return Err(a.format("NumberOfComponents=\"1\"", d.components.to_string()));
    }
    Ok(d)
}

/// Appends the numeric arrays of `<PointData>` or `<CellData>`, each with `tuples` tuples.
fn attributes(
    dec: &Decoder,
    piece: El,
    location: Location,
    tuples: u64,
    out: &mut Vec<DataArray>,
) -> Result<(), DataError> {
    let tag = match location {
        Location::Point => "PointData",
        Location::Cell => "CellData",
    };
    let Some(section) = piece.child(tag) else {
        return Ok(());
    };
    for el in section.children().filter(|c| c.name() == "DataArray") {
        let Some(d) = desc(el)? else {
            continue;
        };
        let values = dec.scalars(&d, tuples)?;
        out.push(DataArray {
            name: d.name,
            location,
            components: d.components,
            values,
        });
    }
    Ok(())
}

/// The `n` points of `<Points>` in `piece` (which may be absent when `n` is 0).
fn points(dec: &Decoder, piece: El, n: u64) -> Result<Vec<[f64; 3]>, DataError> {
    let el = match piece.child("Points") {
        None if n == 0 => return Ok(Vec::new()),
        None => return Err(piece.format(format!("a <Points> element for {n} points"), "none")),
        Some(el) => el,
    };
    let array = first_array(el)?;
    let d = numeric(array)?;
    if d.components != 3 {
        return Err(array.format("NumberOfComponents=\"3\"", d.components.to_string()));
    }
    let flat = dec.values(&d, Some(n), Keep::All, |v| v)?;
    Ok(flat.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect())
}

/// The only `<Piece>` of a grid file.
fn single_piece<'d, 'a>(body: El<'d, 'a>) -> Result<El<'d, 'a>, DataError> {
    let pieces: Vec<El> = body.children().filter(|c| c.name() == "Piece").collect();
    match pieces.as_slice() {
        [p] => Ok(*p),
        [] => Err(body.format("a <Piece> element", "none")),
        many => Err(body.unsupported(format!(
            "{} pieces in a grid file (grids are read with one piece)",
            many.len()
        ))),
    }
}

/// The piece's extent (else the whole extent) and the point counts per axis it gives.
fn grid_extent(body: El, piece: El) -> Result<([i64; 6], [usize; 3]), DataError> {
    let ext = match piece.numbers::<i64>("Extent", 6)? {
        Some(e) => e,
        None => body
            .numbers::<i64>("WholeExtent", 6)?
            .ok_or_else(|| piece.format("an Extent attribute", "none"))?,
    };
    let mut e = [0i64; 6];
    e.copy_from_slice(&ext);
    let mut dims = [0u64; 3];
    for a in 0..3 {
        let n = i128::from(e[2 * a + 1]) - i128::from(e[2 * a]) + 1;
        dims[a] = u64::try_from(n).ok().filter(|&n| n >= 1).ok_or_else(|| {
            piece.format("an extent with min <= max on each axis", format!("{ext:?}"))
        })?;
    }
    let _ = super::checked_sample_count(piece.doc.path, dims)?;
    Ok((e, dims.map(|d| d as usize)))
}

/// Adds the point and cell arrays of a one-piece grid to its geometry.
fn grid_dataset(dec: &Decoder, piece: El, geometry: Geometry) -> Result<Dataset, DataError> {
    let mut arrays = Vec::new();
    attributes(
        dec,
        piece,
        Location::Point,
        geometry.point_count() as u64,
        &mut arrays,
    )?;
    attributes(
        dec,
        piece,
        Location::Cell,
        geometry.cell_count() as u64,
        &mut arrays,
    )?;
    Ok(Dataset { geometry, arrays })
}

fn image(dec: &Decoder, body: El) -> Result<Dataset, DataError> {
    let piece = single_piece(body)?;
    let (ext, dims) = grid_extent(body, piece)?;
    let origin = body.numbers::<f64>("Origin", 3)?.unwrap_or(vec![0.0; 3]);
    let spacing = body.numbers::<f64>("Spacing", 3)?.unwrap_or(vec![1.0; 3]);
    if origin.iter().any(|v| !v.is_finite()) {
        return Err(body.format("a finite Origin", format!("{origin:?}")));
    }
    if spacing.iter().any(|v| !v.is_finite() || *v == 0.0) {
        return Err(body.format("a finite, non-zero Spacing", format!("{spacing:?}")));
    }
    if spacing.iter().any(|v| *v < 0.0) {
        return Err(body.unsupported(format!("negative Spacing {spacing:?} (a mirrored grid)")));
    }
    if let Some(d) = body.numbers::<f64>("Direction", 9)?
        && d != [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    {
        let what = format!("Direction {d:?} (only the identity: vmls grids are axis-aligned)");
        return Err(body.unsupported(what));
    }
    let geometry = Geometry::Image {
        dims,
        origin: [0, 1, 2].map(|a| origin[a] + ext[2 * a] as f64 * spacing[a]),
        spacing: [spacing[0], spacing[1], spacing[2]],
    };
    grid_dataset(dec, piece, geometry)
}

fn rectilinear(dec: &Decoder, body: El) -> Result<Dataset, DataError> {
    let piece = single_piece(body)?;
    let (_, dims) = grid_extent(body, piece)?;
    let el = piece.need("Coordinates")?;
    let arrays: Vec<El> = el.children().filter(|c| c.name() == "DataArray").collect();
    if arrays.len() != 3 {
        return Err(el.format(
            "3 coordinate DataArrays (x, y, z)",
            arrays.len().to_string(),
        ));
    }
    let mut coords: [Vec<f64>; 3] = Default::default();
    for (a, c) in coords.iter_mut().enumerate() {
        *c = dec.values(
            &numeric(arrays[a])?,
            Some(dims[a] as u64),
            Keep::First,
            |v| v,
        )?;
    }
    grid_dataset(dec, piece, Geometry::Rectilinear { coords })
}

fn structured(dec: &Decoder, body: El) -> Result<Dataset, DataError> {
    let piece = single_piece(body)?;
    let (_, dims) = grid_extent(body, piece)?;
    let n = (dims[0] * dims[1] * dims[2]) as u64;
    let geometry = Geometry::Structured {
        dims,
        points: points(dec, piece, n)?,
    };
    grid_dataset(dec, piece, geometry)
}

/// `.vtu` (`poly` false) or `.vtp` (`poly` true): every piece, merged.
fn unstructured(dec: &Decoder, body: El, poly: bool) -> Result<Dataset, DataError> {
    let pieces: Vec<El> = body.children().filter(|c| c.name() == "Piece").collect();
    if pieces.is_empty() {
        return Err(body.format("a <Piece> element", "none"));
    }
    let mut all_points: Vec<[f64; 3]> = Vec::new();
    let mut cells = Cells::default();
    let mut arrays: Vec<DataArray> = Vec::new();
    for (p, &piece) in pieces.iter().enumerate() {
        let n = piece.count("NumberOfPoints")?;
        let base = all_points.len();
        if base as u64 + n > MAX_SAMPLES {
            let found = format!("{} points", base as u64 + n);
            return Err(piece.format(format!("at most {MAX_SAMPLES} points in all pieces"), found));
        }
        let mut piece_arrays = Vec::new();
        attributes(dec, piece, Location::Point, n, &mut piece_arrays)?;
        if poly {
            check_verts(dec, piece, n)?;
        } else {
            let ncells = piece.count("NumberOfCells")?;
            read_cells(dec, piece, n, base, ncells, &mut cells)?;
            attributes(dec, piece, Location::Cell, ncells, &mut piece_arrays)?;
        }
        all_points.extend(points(dec, piece, n)?);
        if p == 0 {
            arrays = piece_arrays;
            continue;
        }
        let same = arrays.len() == piece_arrays.len()
            && arrays
                .iter()
                .zip(&piece_arrays)
                .all(|(a, b)| a.name == b.name && a.location == b.location);
        if !same {
            let list = |v: &[DataArray]| {
                v.iter()
                    .map(|a| format!("'{}'", a.name))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let expected = format!("the arrays of the first piece ({})", list(&arrays));
            return Err(piece.format(expected, format!("piece {p} with {}", list(&piece_arrays))));
        }
        for (a, b) in arrays.iter_mut().zip(piece_arrays) {
            a.values.append(b.values);
        }
    }
    let geometry = if poly {
        Geometry::Points { points: all_points }
    } else {
        Geometry::Unstructured {
            points: all_points,
            cells,
        }
    };
    Ok(Dataset { geometry, arrays })
}

/// Checks a connectivity entry of cell `cell` against the piece's `points`.
fn point_index(el: El, v: f64, cell: usize, points: u64) -> Result<u32, DataError> {
    if v < 0.0 || v.fract() != 0.0 {
        let expected = format!("whole point indices >= 0 (cell {cell})");
        return Err(el.format(expected, v.to_string()));
    }
    if v >= points as f64 {
        return Err(DataError::IndexOutOfRange {
            path: el.doc.path.to_path_buf(),
            cell,
            index: v as u64,
            points: points as usize,
        });
    }
    // Below MAX_SAMPLES = 2^30, so it fits u32.
    Ok(v as u32)
}

/// Reads `connectivity` and `offsets` of `el` and checks the offsets: increasing, the last one
/// equal to the connectivity length.
fn cell_arrays(dec: &Decoder, el: El, ncells: u64) -> Result<(Vec<f64>, Vec<usize>), DataError> {
    let offsets = dec.values(
        &named_array(el, "offsets")?,
        Some(ncells),
        Keep::First,
        |v| v,
    )?;
    let conn = dec.values(&named_array(el, "connectivity")?, None, Keep::First, |v| v)?;
    let mut ends = Vec::with_capacity(offsets.len());
    let mut prev = 0.0;
    for (c, &end) in offsets.iter().enumerate() {
        if !(end >= prev && end <= conn.len() as f64) {
            let expected = format!(
                "offsets increasing from 0 to {} (connectivity length)",
                conn.len()
            );
            return Err(el.format(expected, format!("{end} for cell {c} after {prev}")));
        }
        ends.push(end as usize);
        prev = end;
    }
    if prev != conn.len() as f64 {
        let expected = format!("a last offset of {} (connectivity length)", conn.len());
        return Err(el.format(expected, prev.to_string()));
    }
    Ok((conn, ends))
}

/// Appends the cells of one `.vtu` piece, its point indices moved by `base`.
fn read_cells(
    dec: &Decoder,
    piece: El,
    points: u64,
    base: usize,
    ncells: u64,
    cells: &mut Cells,
) -> Result<(), DataError> {
    let el = match piece.child("Cells") {
        None if ncells == 0 => return Ok(()),
        None => return Err(piece.format(format!("a <Cells> element for {ncells} cells"), "none")),
        Some(el) => el,
    };
    let (conn, ends) = cell_arrays(dec, el, ncells)?;
    let types = named_array(el, "types")?;
    let types_at = types.at;
    let types = dec.values(&types, Some(ncells), Keep::First, |v| v)?;
    if cells.offsets.is_empty() {
        cells.offsets.push(0);
    }
    let first = cells.len();
    let mut start = 0;
    for (c, (&end, &ty)) in ends.iter().zip(&types).enumerate() {
        let cell = first + c;
        let id = ty as u32;
        let kind = CellType::from_vtk(id).ok_or_else(|| DataError::UnsupportedCell {
            path: dec.path.to_path_buf(),
            location: format!("cell {cell} (types array at byte {types_at})"),
            id,
            name: vtk_cell_name(id),
        })?;
        for &v in &conn[start..end] {
            let index = point_index(el, v, cell, points)?;
            cells.connectivity.push(index + base as u32);
        }
        cells.types.push(kind);
        cells.offsets.push(cells.connectivity.len());
        start = end;
    }
    Ok(())
}

/// Checks the `<Verts>` of one `.vtp` piece; they are not kept (every point is a sample).
fn check_verts(dec: &Decoder, piece: El, points: u64) -> Result<(), DataError> {
    let nverts = match piece.attr("NumberOfVerts") {
        None => 0,
        Some(_) => piece.count("NumberOfVerts")?,
    };
    let el = match piece.child("Verts") {
        None if nverts == 0 => return Ok(()),
        None => return Err(piece.format(format!("a <Verts> element for {nverts} verts"), "none")),
        Some(el) => el,
    };
    let (conn, ends) = cell_arrays(dec, el, nverts)?;
    let mut start = 0;
    for (c, &end) in ends.iter().enumerate() {
        for &v in &conn[start..end] {
            point_index(el, v, c, points)?;
        }
        start = end;
    }
    Ok(())
}
