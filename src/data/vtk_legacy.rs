//! VTK legacy reader for every dataset type vmls renders ([`load_dataset`]):
//! `STRUCTURED_POINTS`, `RECTILINEAR_GRID`, `STRUCTURED_GRID`,
//! `UNSTRUCTURED_GRID` and `POLYDATA`, ASCII or BINARY (big-endian), file versions 2.0 to 5.1
//! (the version line is not enforced, as in VTK). The tokenizer, number decoding and attribute
//! parsing are `vtk.rs`'s, shared with the volume API (`vtk::load`).
//!
//! Contract and choices:
//! - `STRUCTURED_POINTS`: `DIMENSIONS`, `SPACING` (or `ASPECT_RATIO`, default 1), `ORIGIN`
//!   (default 0) → [`Geometry::Image`];
//! - `RECTILINEAR_GRID`: `DIMENSIONS` and `X_COORDINATES`/`Y_COORDINATES`/`Z_COORDINATES n type`
//!   with n equal to the matching dimension → [`Geometry::Rectilinear`] (coordinates must be
//!   strictly increasing: [`Dataset::validate`] rejects anything else);
//! - `STRUCTURED_GRID`: `DIMENSIONS` and `POINTS n type` with n their product →
//!   [`Geometry::Structured`];
//! - `UNSTRUCTURED_GRID`: `POINTS`, `CELLS` and `CELL_TYPES` → [`Geometry::Unstructured`].
//!   `CELLS` is read in both layouts: the classic `CELLS n size` followed by `npts i0 i1 ...`
//!   per cell (ints), and VTK 5.1's `CELLS nOffsets nConn` followed by `OFFSETS type` and
//!   `CONNECTIVITY type` arrays (offsets start at 0, never decrease and end at nConn). The
//!   layout is recognised by the `OFFSETS` keyword, not by the version line. Types 10 to 14
//!   are read; any other is [`DataError::UnsupportedCell`] naming the cell. A grid without
//!   `CELLS` has no cells (VTK allows it); `CELLS` without `CELL_TYPES` is an error;
//! - `POLYDATA` → [`Geometry::Points`]: every point of `POINTS` is a sample, referenced by a
//!   vertex or not (VTK's glyph and point-cloud filters write one vertex per point, but
//!   other writers leave points unreferenced, and dropping them would renumber the point
//!   data). `VERTICES`, `LINES`, `POLYGONS` and `TRIANGLE_STRIPS` are read in either layout and
//!   their point indices checked, then dropped: vmls renders polydata as scattered points.
//!   Polydata `CELL_DATA` is parsed past, since scattered points have no cells to carry it;
//! - `POINTS`, `CELLS`, `X_COORDINATES` ... may come in any order before the first
//!   `POINT_DATA`/`CELL_DATA`; a keyword that does not belong to the dataset type is an error;
//!   a dataset-level `FIELD` block and VTK 5.1 `METADATA` blocks are skipped;
//! - attributes: `POINT_DATA` and `CELL_DATA` may both appear, in either order, and their
//!   counts must equal the geometry's point and cell counts (cells of a grid are its
//!   hexahedra, cells of polydata all its vertices, lines, polygons and strips). Every
//!   `SCALARS`, `COLOR_SCALARS` and `FIELD` array becomes a [`DataArray`] in file order with
//!   its first component (see `vtk.rs` for COLOR_SCALARS scaling); every such array must hold
//!   one tuple per point or cell. `VECTORS`, `NORMALS`, `TENSORS`, lookup tables etc. are
//!   parsed past. Unlike the volume API, the whole file is read, so trailing garbage fails;
//! - counts in headers are checked against [`MAX_SAMPLES`] before anything is read, and no
//!   buffer is sized from a header before the data behind it has been seen to exist;
//! - coordinates are read as f64 (a `float` coordinate keeps its f32 value exactly); cell
//!   indices, offsets and types must be non-negative whole numbers.
//!
//! Every returned dataset has passed [`Dataset::validate`] (finite coordinates and values,
//! point counts per cell type, indices in range).

use super::dataset::{CellType, Cells, Dataset, Geometry, Location, vtk_cell_name};
use super::encoding::Scalar;
use super::vtk::{Elem, Line, Pick, Reader, Sink, attribute, open};
use super::{DataError, MAX_SAMPLES, checked_sample_count};
use std::path::Path;

#[cfg(doc)]
use super::dataset::DataArray;

/// Reads and parses a legacy `.vtk` file of any supported dataset type.
pub fn load_dataset(path: &Path) -> Result<Dataset, DataError> {
    let bytes = super::read_file(path)?;
    parse_dataset(path, &bytes)
}

#[derive(Clone, Copy, PartialEq)]
enum Kind {
    Image,
    Rectilinear,
    Structured,
    Unstructured,
    PolyData,
}

impl Kind {
    /// The geometry keywords of this dataset type, for error messages.
    fn keywords(self) -> &'static str {
        match self {
            Kind::Image => "DIMENSIONS, SPACING, ORIGIN",
            Kind::Rectilinear => "DIMENSIONS, X_COORDINATES, Y_COORDINATES, Z_COORDINATES",
            Kind::Structured => "DIMENSIONS, POINTS",
            Kind::Unstructured => "POINTS, CELLS, CELL_TYPES",
            Kind::PolyData => "POINTS, VERTICES, LINES, POLYGONS, TRIANGLE_STRIPS",
        }
    }
}

/// A value and the offset of the line that introduced it, for later errors.
type At<T> = Option<(T, usize)>;

/// Cells as read, in either layout: cell c holds `conn[offsets[c]..offsets[c + 1]]`.
struct RawCells {
    offsets: Vec<usize>,
    conn: Vec<u64>,
}

impl RawCells {
    fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }
}

/// Geometry sections read so far.
#[derive(Default)]
struct Parts {
    dims: At<[u64; 3]>,
    spacing: Option<[f64; 3]>,
    origin: Option<[f64; 3]>,
    points: At<Vec<[f64; 3]>>,
    coords: [At<Vec<f64>>; 3],
    cells: Option<RawCells>,
    types: At<Vec<u64>>,
    /// VERTICES, LINES, POLYGONS, TRIANGLE_STRIPS: VTK numbers polydata cells in this order.
    poly: [Option<RawCells>; 4],
}

const POLY_SECTIONS: [&str; 4] = ["VERTICES", "LINES", "POLYGONS", "TRIANGLE_STRIPS"];
const AXES: [&str; 3] = ["X_COORDINATES", "Y_COORDINATES", "Z_COORDINATES"];

/// Parses legacy VTK bytes of any supported dataset type; `path` only names the file in errors.
pub fn parse_dataset(path: &Path, bytes: &[u8]) -> Result<Dataset, DataError> {
    let (mut r, name, at) = open(path, bytes)?;
    let kind = match name.as_str() {
        "STRUCTURED_POINTS" => Kind::Image,
        "RECTILINEAR_GRID" => Kind::Rectilinear,
        "STRUCTURED_GRID" => Kind::Structured,
        "UNSTRUCTURED_GRID" => Kind::Unstructured,
        "POLYDATA" => Kind::PolyData,
        other => return Err(r.unsupported(at, format!("DATASET {other}"))),
    };
    let mut parts = Parts::default();
    let mut geometry: Option<(Geometry, usize)> = None;
    let mut section: Option<(Location, u64)> = None;
    let mut sink = Sink::new(Pick::All {
        cells: kind != Kind::PolyData,
    });
    while let Some(line) = r.line() {
        let kw = line.keyword();
        if kw == "POINT_DATA" || kw == "CELL_DATA" {
            r.expect_tokens(&line, 2, &format!("{kw} count"))?;
            let n: u64 = r.number(&line, 1, "a whole-number count")?;
            if geometry.is_none() {
                geometry = Some(finish(&r, kind, std::mem::take(&mut parts), Some(&line))?);
            }
            let (points, cells) = geometry
                .as_ref()
                .map_or((0, 0), |(g, cells)| (g.point_count(), *cells));
            let (location, count) = match kw.as_str() {
                "POINT_DATA" => (Location::Point, points),
                _ => (Location::Cell, cells),
            };
            if n != count as u64 {
                let expected = format!("{kw} {count} (the {} count)", location.name());
                return Err(r.format(line.start, expected, format!("{kw} {n}")));
            }
            section = Some((location, n));
        } else if section.is_some() || kw == "FIELD" {
            attribute(&mut r, &line, section, &mut sink)?;
        } else {
            geometry_line(&mut r, kind, &line, &mut parts)?;
        }
    }
    let geometry = match geometry {
        Some((g, _)) => g,
        None => finish(&r, kind, parts, None)?.0,
    };
    let dataset = Dataset {
        geometry,
        arrays: sink.kept,
    };
    dataset.validate(path)?;
    Ok(dataset)
}

/// Reads one geometry section (`line` is its keyword line) into `parts`.
fn geometry_line(
    r: &mut Reader,
    kind: Kind,
    line: &Line,
    parts: &mut Parts,
) -> Result<(), DataError> {
    let kw = line.keyword();
    let twice = |r: &Reader| r.unexpected(Some(line), format!("one {kw} section"));
    match (kind, kw.as_str()) {
        (Kind::Image | Kind::Rectilinear | Kind::Structured, "DIMENSIONS") => {
            r.expect_tokens(line, 4, "DIMENSIONS nx ny nz")?;
            let mut d = [0u64; 3];
            for (a, v) in d.iter_mut().enumerate() {
                *v = r.number(line, a + 1, "a whole-number dimension")?;
            }
            checked_sample_count(r.path, d)?;
            parts.dims = Some((d, line.start));
        }
        (Kind::Image, "SPACING" | "ASPECT_RATIO") => {
            let ok = |s: f64| s.is_finite() && s > 0.0;
            parts.spacing = Some(r.vec3(line, "a finite spacing > 0", ok)?);
        }
        (Kind::Image, "ORIGIN") => {
            parts.origin = Some(r.vec3(line, "a finite origin coordinate", f64::is_finite)?);
        }
        (Kind::Structured | Kind::Unstructured | Kind::PolyData, "POINTS") => {
            if parts.points.is_some() {
                return Err(twice(r));
            }
            r.expect_tokens(line, 3, "POINTS n type")?;
            let n = count(r, line, 1, "points")?;
            if n == 0 {
                return Err(r.format(line.start, "at least one point", "POINTS 0"));
            }
            let elem = r.numeric_elem(line, &line.tokens[2])?;
            let v = r.array::<f64>(elem, 1, 3 * n as u64, true)?;
            r.skip_metadata();
            let points = v.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
            parts.points = Some((points, line.start));
        }
        (Kind::Rectilinear, k) if AXES.contains(&k) => {
            let a = AXES.iter().position(|&x| x == k).unwrap_or(0);
            if parts.coords[a].is_some() {
                return Err(twice(r));
            }
            r.expect_tokens(line, 3, &format!("{k} n type"))?;
            let n = count(r, line, 1, "coordinates")?;
            let elem = r.numeric_elem(line, &line.tokens[2])?;
            let v = r.array::<f64>(elem, 1, n as u64, true)?;
            r.skip_metadata();
            parts.coords[a] = Some((v, line.start));
        }
        (Kind::Unstructured, "CELLS") => {
            if parts.cells.is_some() {
                return Err(twice(r));
            }
            parts.cells = Some(cells(r, line)?);
        }
        (Kind::Unstructured, "CELL_TYPES") => {
            if parts.types.is_some() {
                return Err(twice(r));
            }
            r.expect_tokens(line, 2, "CELL_TYPES n")?;
            let n = count(r, line, 1, "cells")?;
            let types = whole(r, line, Elem::Num(Scalar::I32), n)?;
            parts.types = Some((types, line.start));
        }
        (Kind::PolyData, k) if POLY_SECTIONS.contains(&k) => {
            let s = POLY_SECTIONS.iter().position(|&x| x == k).unwrap_or(0);
            if parts.poly[s].is_some() {
                return Err(twice(r));
            }
            parts.poly[s] = Some(cells(r, line)?);
        }
        _ => {
            let expected = format!("{}, FIELD, POINT_DATA or CELL_DATA", kind.keywords());
            return Err(r.unexpected(Some(line), expected));
        }
    }
    Ok(())
}

/// The count in token `i` of `line`, at most [`MAX_SAMPLES`].
fn count(r: &Reader, line: &Line, i: usize, what: &str) -> Result<usize, DataError> {
    let n: u64 = r.number(line, i, &format!("a whole-number count of {what}"))?;
    if n > MAX_SAMPLES {
        return Err(DataError::TooLarge {
            path: r.path.to_path_buf(),
            dims: [n, 1, 1],
            reason: format!(
                "{}: {n} {what} exceed the limit of {MAX_SAMPLES}",
                r.location(line.start)
            ),
        });
    }
    usize::try_from(n).map_err(|_| r.format(line.start, "a smaller count", n.to_string()))
}

/// Reads `n` values that must be non-negative whole numbers (indices, offsets, cell types).
fn whole(r: &mut Reader, line: &Line, elem: Elem, n: usize) -> Result<Vec<u64>, DataError> {
    let values = r.array::<f64>(elem, 1, n as u64, true)?;
    r.skip_metadata();
    // 2^53: past it f64 no longer holds every integer, and no valid index comes near it.
    const EXACT: f64 = 9_007_199_254_740_992.0;
    values
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            if (0.0..EXACT).contains(&v) && v.fract() == 0.0 {
                Ok(v as u64)
            } else {
                let expected = format!("non-negative whole numbers after '{}'", line.keyword());
                Err(r.format(line.start, expected, format!("{v} (value {})", i + 1)))
            }
        })
        .collect()
}

/// Reads a `CELLS`/`VERTICES`/... section (`line` is its keyword line) in either layout.
fn cells(r: &mut Reader, line: &Line) -> Result<RawCells, DataError> {
    let kw = line.keyword();
    r.expect_tokens(line, 3, &format!("{kw} n size"))?;
    let first = count(r, line, 1, "cells")?;
    let size = count(r, line, 2, "connectivity entries")?;
    let modern = if r.binary {
        let rest = r.bytes.get(r.pos..).unwrap_or_default();
        rest.len() >= 7 && rest[..7].eq_ignore_ascii_case(b"OFFSETS")
    } else {
        r.peek_line().is_some_and(|l| l.keyword() == "OFFSETS")
    };
    if modern {
        if first == 0 {
            let expected = format!("at least 1 offset after '{kw}' (one more than the cells)");
            return Err(r.format(line.start, expected, "0"));
        }
        let offsets = typed_array(r, "OFFSETS", first)?;
        let conn = typed_array(r, "CONNECTIVITY", size)?;
        let bad = |expected: String, found: String| r.format(line.start, expected, found);
        if offsets.first().is_some_and(|&o| o != 0) {
            return Err(bad("offsets starting at 0".into(), offsets[0].to_string()));
        }
        if let Some(i) = offsets.windows(2).position(|w| w[1] < w[0]) {
            let found = format!("offset {} = {} after {}", i + 1, offsets[i + 1], offsets[i]);
            return Err(bad("non-decreasing offsets".into(), found));
        }
        let last = offsets.last().copied().unwrap_or(0);
        if last != size as u64 {
            let expected = format!("a last offset equal to the connectivity size {size}");
            return Err(bad(expected, last.to_string()));
        }
        // Every offset is now at most `size`, which fits usize.
        let offsets = offsets.into_iter().map(|o| o as usize).collect();
        return Ok(RawCells { offsets, conn });
    }
    // Classic layout: each cell takes at least its point count, so `first <= size` bounds
    // the allocations below by the data actually read.
    let raw = whole(r, line, Elem::Num(Scalar::I32), size)?;
    if first > size {
        let expected = format!("at least {first} entries for {first} cells");
        return Err(r.format(line.start, expected, size.to_string()));
    }
    let mut offsets = Vec::with_capacity(first + 1);
    let mut conn = Vec::with_capacity(size - first);
    offsets.push(0);
    let mut pos = 0usize;
    for c in 0..first {
        let npts = raw.get(pos).copied().unwrap_or(0);
        let end = usize::try_from(npts)
            .ok()
            .and_then(|n| n.checked_add(pos + 1))
            .filter(|&end| end <= raw.len() && pos < raw.len());
        let Some(end) = end else {
            let expected = format!("cell {c} within the {size} entries of {kw}");
            let found = format!("{npts} points from entry {}", pos + 1);
            return Err(r.format(line.start, expected, found));
        };
        conn.extend_from_slice(&raw[pos + 1..end]);
        offsets.push(conn.len());
        pos = end;
    }
    if pos != size {
        let expected = format!("{size} entries for {first} cells");
        return Err(r.format(line.start, expected, format!("{pos} used")));
    }
    Ok(RawCells { offsets, conn })
}

/// Reads a VTK 5.1 `OFFSETS type` or `CONNECTIVITY type` line and its `n` values.
fn typed_array(r: &mut Reader, kw: &str, n: usize) -> Result<Vec<u64>, DataError> {
    match r.line() {
        Some(line) if line.keyword() == kw && line.tokens.len() == 2 => {
            let elem = r.numeric_elem(&line, &line.tokens[1])?;
            whole(r, &line, elem, n)
        }
        // The error quotes the line that was read, not the one after it.
        other => Err(r.unexpected(other.as_ref(), format!("'{kw} type'"))),
    }
}

/// Builds the geometry from its sections; `at` is the line that ended them (`None`: end of
/// file). Returns the geometry and its cell count as `CELL_DATA` counts cells.
fn finish(
    r: &Reader,
    kind: Kind,
    parts: Parts,
    at: Option<&Line>,
) -> Result<(Geometry, usize), DataError> {
    let missing = |what: &str| r.unexpected(at, format!("{what} before the point and cell data"));
    let dims = || -> Result<([usize; 3], usize), DataError> {
        let (d, line) = parts.dims.ok_or_else(|| missing("DIMENSIONS"))?;
        checked_sample_count(r.path, d)?;
        Ok((d.map(|n| n as usize), line))
    };
    let geometry = match kind {
        Kind::Image => Geometry::Image {
            dims: dims()?.0,
            origin: parts.origin.unwrap_or([0.0; 3]),
            spacing: parts.spacing.unwrap_or([1.0; 3]),
        },
        Kind::Rectilinear => {
            let (d, _) = dims()?;
            let mut coords: [Vec<f64>; 3] = Default::default();
            for (a, slot) in parts.coords.into_iter().enumerate() {
                let (c, line) = slot.ok_or_else(|| missing(AXES[a]))?;
                if c.len() != d[a] {
                    let expected = format!("{} {} (DIMENSIONS)", AXES[a], d[a]);
                    return Err(r.format(line, expected, format!("{} {}", AXES[a], c.len())));
                }
                coords[a] = c;
            }
            Geometry::Rectilinear { coords }
        }
        Kind::Structured => {
            let (d, _) = dims()?;
            let (points, line) = parts.points.ok_or_else(|| missing("POINTS"))?;
            let n = d[0] * d[1] * d[2];
            if points.len() != n {
                let expected = format!("POINTS {n} (the product of DIMENSIONS)");
                return Err(r.format(line, expected, format!("POINTS {}", points.len())));
            }
            Geometry::Structured { dims: d, points }
        }
        Kind::Unstructured => {
            let (points, _) = parts.points.ok_or_else(|| missing("POINTS"))?;
            let cells = unstructured(r, parts.cells, parts.types, points.len(), at)?;
            Geometry::Unstructured { points, cells }
        }
        Kind::PolyData => {
            let (points, _) = parts.points.ok_or_else(|| missing("POINTS"))?;
            let mut first = 0;
            for raw in parts.poly.iter().flatten() {
                check_indices(r, raw, first, points.len())?;
                first += raw.len();
            }
            return Ok((Geometry::Points { points }, first));
        }
    };
    let cells = geometry.cell_count();
    Ok((geometry, cells))
}

/// Every point index of `raw` must be below `points`; cell numbers start at `first`.
fn check_indices(r: &Reader, raw: &RawCells, first: usize, points: usize) -> Result<(), DataError> {
    let Some(bad) = raw.conn.iter().position(|&p| p >= points as u64) else {
        return Ok(());
    };
    // The cell holding entry `bad`: the last one whose offset is at most `bad`.
    let cell = raw.offsets.partition_point(|&o| o <= bad).saturating_sub(1);
    Err(DataError::IndexOutOfRange {
        path: r.path.to_path_buf(),
        cell: first + cell,
        index: raw.conn[bad],
        points,
    })
}

/// Joins `CELLS` and `CELL_TYPES` into [`Cells`], checking types and indices.
fn unstructured(
    r: &Reader,
    raw: Option<RawCells>,
    types: At<Vec<u64>>,
    points: usize,
    at: Option<&Line>,
) -> Result<Cells, DataError> {
    let (raw, (types, types_at)) = match (raw, types) {
        (None, None) => {
            return Ok(Cells {
                offsets: vec![0],
                ..Cells::default()
            });
        }
        (Some(raw), Some(types)) => (raw, types),
        (Some(_), None) => {
            return Err(r.unexpected(at, "CELL_TYPES before the point and cell data"));
        }
        (None, Some((_, line))) => {
            return Err(r.format(line, "CELLS before CELL_TYPES", "CELL_TYPES"));
        }
    };
    if types.len() != raw.len() {
        let expected = format!("CELL_TYPES {} (one per cell of CELLS)", raw.len());
        return Err(r.format(types_at, expected, format!("CELL_TYPES {}", types.len())));
    }
    let kinds = types
        .iter()
        .enumerate()
        .map(|(c, &id)| {
            let id = u32::try_from(id).unwrap_or(u32::MAX);
            CellType::from_vtk(id).ok_or_else(|| DataError::UnsupportedCell {
                path: r.path.to_path_buf(),
                location: format!("cell {c} (CELL_TYPES at {})", r.location(types_at)),
                id,
                name: vtk_cell_name(id),
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    check_indices(r, &raw, 0, points)?;
    Ok(Cells {
        types: kinds,
        offsets: raw.offsets,
        // Indices are below `points`, at most MAX_SAMPLES, so they fit u32.
        connectivity: raw.conn.into_iter().map(|p| p as u32).collect(),
    })
}
