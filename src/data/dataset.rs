//! What a file holds before it becomes samples: geometry (regular, rectilinear, curvilinear,
//! unstructured cells or bare points) and every scalar array with where it lives.
//!
//! Contract shared by all loaders that produce a [`Dataset`]:
//! - coordinates are f64 and finite (a NaN/Inf coordinate is [`DataError::NonFiniteCoordinate`]);
//! - arrays keep their first component as f32 (`components` says how many the file had); a
//!   NaN/Inf value is [`DataError::NonFinite`] naming the array element;
//! - a point array has one value per point, a cell array one per cell;
//! - cells are checked by [`Dataset::validate`]: indices in range, supported type, the right
//!   number of points per type. Geometric checks (degenerate or inverted cells, duplicate points,
//!   non-manifold boundaries) belong to the sample-set layer, which knows the tolerances.
//!
//! Cell type numbers are VTK's (`vtkCellType.h`), which every VTK format writes.

use super::{DataError, Volume};
use std::path::Path;

/// Where an array's values live.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    /// One value per point.
    Point,
    /// One value per cell (sampled at the cell centroid by the sample-set layer).
    Cell,
}

impl Location {
    /// "point" or "cell".
    pub fn name(self) -> &'static str {
        match self {
            Location::Point => "point",
            Location::Cell => "cell",
        }
    }
}

/// One named scalar array (first component).
#[derive(Debug, Clone, PartialEq)]
pub struct DataArray {
    pub name: String,
    pub location: Location,
    /// Components per tuple in the file (only the first is kept).
    pub components: usize,
    pub values: super::Values,
}

impl DataArray {
    /// Smallest and largest value.
    pub fn range(&self) -> (f32, f32) {
        self.values.range()
    }
}

/// The volumetric cell types vmls reads, with VTK's type numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum CellType {
    Tetra,
    Voxel,
    Hexahedron,
    Wedge,
    Pyramid,
}

impl CellType {
    /// The type for a VTK cell type number; `None` for types vmls does not read.
    pub fn from_vtk(id: u32) -> Option<Self> {
        Some(match id {
            10 => CellType::Tetra,
            11 => CellType::Voxel,
            12 => CellType::Hexahedron,
            13 => CellType::Wedge,
            14 => CellType::Pyramid,
            _ => return None,
        })
    }

    /// VTK's type number.
    pub fn vtk_id(self) -> u32 {
        match self {
            CellType::Tetra => 10,
            CellType::Voxel => 11,
            CellType::Hexahedron => 12,
            CellType::Wedge => 13,
            CellType::Pyramid => 14,
        }
    }

    /// Points per cell.
    pub fn points(self) -> usize {
        match self {
            CellType::Tetra => 4,
            CellType::Voxel | CellType::Hexahedron => 8,
            CellType::Wedge => 6,
            CellType::Pyramid => 5,
        }
    }

    /// Lower-case name ("tetra", "hexahedron", ...).
    pub fn name(self) -> &'static str {
        match self {
            CellType::Tetra => "tetra",
            CellType::Voxel => "voxel",
            CellType::Hexahedron => "hexahedron",
            CellType::Wedge => "wedge",
            CellType::Pyramid => "pyramid",
        }
    }
}

/// VTK's name of a cell type number, for error messages about types vmls does not read.
pub fn vtk_cell_name(id: u32) -> &'static str {
    match id {
        1 => "VTK_VERTEX",
        2 => "VTK_POLY_VERTEX",
        3 => "VTK_LINE",
        4 => "VTK_POLY_LINE",
        5 => "VTK_TRIANGLE",
        6 => "VTK_TRIANGLE_STRIP",
        7 => "VTK_POLYGON",
        8 => "VTK_PIXEL",
        9 => "VTK_QUAD",
        10 => "VTK_TETRA",
        11 => "VTK_VOXEL",
        12 => "VTK_HEXAHEDRON",
        13 => "VTK_WEDGE",
        14 => "VTK_PYRAMID",
        15 => "VTK_PENTAGONAL_PRISM",
        16 => "VTK_HEXAGONAL_PRISM",
        21..=34 => "a quadratic cell",
        42 => "VTK_POLYHEDRON",
        _ => "an unknown cell type",
    }
}

/// Unstructured cells: cell c has type `types[c]` and points
/// `connectivity[offsets[c]..offsets[c + 1]]` (`offsets.len() == types.len() + 1`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Cells {
    pub types: Vec<CellType>,
    pub offsets: Vec<usize>,
    pub connectivity: Vec<u32>,
}

impl Cells {
    /// Number of cells.
    pub fn len(&self) -> usize {
        self.types.len()
    }

    /// True when there is no cell.
    pub fn is_empty(&self) -> bool {
        self.types.is_empty()
    }

    /// Point indices of cell c.
    pub fn cell(&self, c: usize) -> &[u32] {
        &self.connectivity[self.offsets[c]..self.offsets[c + 1]]
    }

    /// Appends a cell.
    pub fn push(&mut self, kind: CellType, points: &[u32]) {
        if self.offsets.is_empty() {
            self.offsets.push(0);
        }
        self.types.push(kind);
        self.connectivity.extend_from_slice(points);
        self.offsets.push(self.connectivity.len());
    }
}

/// The geometry of a dataset.
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// A regular grid (`Volume` without its values): dims, origin, spacing.
    Image {
        dims: [usize; 3],
        origin: [f64; 3],
        spacing: [f64; 3],
    },
    /// Axis-aligned grid with per-axis coordinates (each strictly increasing).
    Rectilinear { coords: [Vec<f64>; 3] },
    /// Curvilinear grid: `dims` points, x fastest, each with its own position.
    Structured {
        dims: [usize; 3],
        points: Vec<[f64; 3]>,
    },
    /// Points joined by volumetric cells.
    Unstructured { points: Vec<[f64; 3]>, cells: Cells },
    /// Scattered points, no connectivity (VTK `POLYDATA` vertices, CSV, PLY).
    Points { points: Vec<[f64; 3]> },
}

impl Geometry {
    /// The kind's name as `vmls info` prints it.
    pub fn kind(&self) -> &'static str {
        match self {
            Geometry::Image { .. } => "regular grid",
            Geometry::Rectilinear { .. } => "rectilinear grid",
            Geometry::Structured { .. } => "curvilinear grid",
            Geometry::Unstructured { .. } => "unstructured mesh",
            Geometry::Points { .. } => "scattered points",
        }
    }

    /// Number of points.
    pub fn point_count(&self) -> usize {
        match self {
            Geometry::Image { dims, .. } | Geometry::Structured { dims, .. } => {
                dims[0] * dims[1] * dims[2]
            }
            Geometry::Rectilinear { coords } => coords[0].len() * coords[1].len() * coords[2].len(),
            Geometry::Unstructured { points, .. } | Geometry::Points { points } => points.len(),
        }
    }

    /// Number of cells (grids: hexahedral cells between grid points; points: 0).
    pub fn cell_count(&self) -> usize {
        let grid = |d: [usize; 3]| d.iter().map(|&n| n.saturating_sub(1).max(1)).product();
        match self {
            Geometry::Image { dims, .. } | Geometry::Structured { dims, .. } => grid(*dims),
            Geometry::Rectilinear { coords } => {
                grid([coords[0].len(), coords[1].len(), coords[2].len()])
            }
            Geometry::Unstructured { cells, .. } => cells.len(),
            Geometry::Points { .. } => 0,
        }
    }

    /// Position of point i.
    pub fn point(&self, i: usize) -> [f64; 3] {
        match self {
            Geometry::Image {
                dims,
                origin,
                spacing,
            } => grid_point(*dims, *origin, *spacing, i),
            Geometry::Rectilinear { coords } => {
                let (nx, ny) = (coords[0].len(), coords[1].len());
                [
                    coords[0][i % nx],
                    coords[1][(i / nx) % ny],
                    coords[2][i / (nx * ny)],
                ]
            }
            Geometry::Structured { points, .. }
            | Geometry::Unstructured { points, .. }
            | Geometry::Points { points } => points[i],
        }
    }

    /// Axis-aligned bounds of the points: (min, max).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for i in 0..self.point_count() {
            let p = self.point(i);
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        (lo, hi)
    }

    /// Refuses geometry the renderer cannot resolve or that encloses no volume, naming the
    /// axis: a regular grid's spacing must be finite and positive; every coordinate within
    /// ±[`super::MAX_COORDINATE`]; every axis at least [`super::MIN_EXTENT`] long and
    /// [`super::MIN_RELATIVE_EXTENT`] of its coordinates' magnitude; a grid needs two samples
    /// along every axis (one layer, 8×8×1, is a plane with no thickness to integrate over:
    /// vmls rejects it rather than render a transparent image).
    pub fn check_domain(&self, path: &Path) -> Result<(), DataError> {
        let err = |what: String, expected: &str, found: String| DataError::Geometry {
            path: path.to_path_buf(),
            what,
            expected: expected.to_string(),
            found,
        };
        const AXES: [&str; 3] = ["x", "y", "z"];
        if let Geometry::Image {
            origin, spacing, ..
        } = self
        {
            for a in 0..3 {
                if !origin[a].is_finite() {
                    return Err(err(
                        format!("origin along {}", AXES[a]),
                        "a finite number",
                        origin[a].to_string(),
                    ));
                }
                if !(spacing[a].is_finite() && spacing[a] > 0.0) {
                    return Err(err(
                        format!("spacing along {}", AXES[a]),
                        "a finite number > 0",
                        spacing[a].to_string(),
                    ));
                }
            }
        }
        let grid_dims = match self {
            Geometry::Image { dims, .. } | Geometry::Structured { dims, .. } => Some(*dims),
            Geometry::Rectilinear { coords } => Some(coords.each_ref().map(Vec::len)),
            _ => None,
        };
        if let Some(dims) = grid_dims
            && let Some(a) = (0..3).find(|&a| dims[a] < 2)
        {
            return Err(err(
                format!("grid dimensions {dims:?}"),
                "at least 2 samples along every axis (a single layer has no thickness to render)",
                format!("{} along {}", dims[a], AXES[a]),
            ));
        }
        if self.point_count() == 0 {
            return Ok(());
        }
        let (lo, hi) = match self {
            // Grids have their corners without a walk over every point.
            Geometry::Image {
                dims,
                origin,
                spacing,
            } => (
                *origin,
                std::array::from_fn(|a| origin[a] + (dims[a] - 1) as f64 * spacing[a]),
            ),
            Geometry::Rectilinear { coords } => (
                coords.each_ref().map(|c| c[0]),
                coords.each_ref().map(|c| c[c.len() - 1]),
            ),
            _ => self.bounds(),
        };
        for a in 0..3 {
            let magnitude = lo[a].abs().max(hi[a].abs());
            if magnitude > super::MAX_COORDINATE {
                return Err(err(
                    format!("extent along {} (origin, spacing, points)", AXES[a]),
                    "coordinates within ±1e15 (the kernels square distances in f32)",
                    format!("[{:e}, {:e}]", lo[a], hi[a]),
                ));
            }
            let extent = hi[a] - lo[a];
            if extent < super::MIN_EXTENT || extent < super::MIN_RELATIVE_EXTENT * magnitude {
                return Err(err(
                    format!("extent along {}", AXES[a]),
                    "a domain at least 1e-12 and 1e-9 of its coordinates' magnitude long along \
                     every axis (flat or sub-resolution data encloses no volume)",
                    format!("[{:e}, {:e}]", lo[a], hi[a]),
                ));
            }
        }
        Ok(())
    }
}

/// Position of point i of a regular grid stored x fastest.
pub fn grid_point(dims: [usize; 3], origin: [f64; 3], spacing: [f64; 3], i: usize) -> [f64; 3] {
    let index = [
        i % dims[0],
        (i / dims[0]) % dims[1],
        i / (dims[0] * dims[1]),
    ];
    [0, 1, 2].map(|a| origin[a] + index[a] as f64 * spacing[a])
}

/// A loaded file: geometry and its scalar arrays (point and cell data).
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    pub geometry: Geometry,
    pub arrays: Vec<DataArray>,
}

impl Dataset {
    /// A regular grid with one point array.
    pub fn from_volume(volume: Volume, name: &str) -> Self {
        Self {
            geometry: Geometry::Image {
                dims: volume.dims,
                origin: volume.origin,
                spacing: volume.spacing,
            },
            arrays: vec![DataArray {
                name: name.to_string(),
                location: Location::Point,
                components: 1,
                values: volume.values,
            }],
        }
    }

    /// The array named `name`, or the first point array (else the first array) for `None`.
    pub fn array(&self, path: &Path, name: Option<&str>) -> Result<&DataArray, DataError> {
        let found = match name {
            Some(n) => self.arrays.iter().find(|a| a.name == n),
            None => self
                .arrays
                .iter()
                .find(|a| a.location == Location::Point)
                .or_else(|| self.arrays.first()),
        };
        if name.is_none() && self.arrays.is_empty() {
            return Err(DataError::NoArray {
                path: path.to_path_buf(),
            });
        }
        found.ok_or_else(|| DataError::NoSuchArray {
            path: path.to_path_buf(),
            name: name.unwrap_or_default().to_string(),
            available: if self.arrays.is_empty() {
                "none".into()
            } else {
                self.arrays
                    .iter()
                    .map(|a| format!("{} ({} data)", a.name, a.location.name()))
                    .collect::<Vec<_>>()
                    .join(", ")
            },
        })
    }

    /// Checks what every loader must guarantee: finite coordinates, renderable values
    /// ([`super::renderable_value`]), array lengths, cell
    /// indices in range and point counts per cell type. Errors name `path`.
    pub fn validate(&self, path: &Path) -> Result<(), DataError> {
        let n = self.geometry.point_count();
        if let Geometry::Structured { points, .. }
        | Geometry::Unstructured { points, .. }
        | Geometry::Points { points } = &self.geometry
        {
            if points.len() != n {
                return Err(format_error(
                    path,
                    "points",
                    &format!("{n} points"),
                    &points.len().to_string(),
                ));
            }
            if let Some((i, p)) = points
                .iter()
                .enumerate()
                .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
            {
                return Err(DataError::NonFiniteCoordinate {
                    path: path.to_path_buf(),
                    index: i,
                    point: *p,
                });
            }
        }
        if let Geometry::Rectilinear { coords } = &self.geometry {
            for (a, c) in coords.iter().enumerate() {
                let axis = ["x", "y", "z"][a];
                if c.is_empty() || c.iter().any(|v| !v.is_finite()) {
                    return Err(format_error(
                        path,
                        &format!("{axis} coordinates"),
                        "at least one finite coordinate",
                        &format!("{c:?}"),
                    ));
                }
                if let Some(i) = c.windows(2).position(|w| w[1] <= w[0]) {
                    return Err(format_error(
                        path,
                        &format!("{axis} coordinates {i} and {}", i + 1),
                        "strictly increasing coordinates",
                        &format!("{} then {}", c[i], c[i + 1]),
                    ));
                }
            }
        }
        if let Geometry::Unstructured { cells, .. } = &self.geometry {
            if cells.offsets.len() != cells.types.len() + 1 && !cells.is_empty() {
                return Err(format_error(
                    path,
                    "cells",
                    &format!("{} offsets", cells.types.len() + 1),
                    &cells.offsets.len().to_string(),
                ));
            }
            for c in 0..cells.len() {
                let pts = cells.cell(c);
                let kind = cells.types[c];
                if pts.len() != kind.points() {
                    return Err(format_error(
                        path,
                        &format!("cell {c}"),
                        &format!("{} points for a {}", kind.points(), kind.name()),
                        &pts.len().to_string(),
                    ));
                }
                if let Some(&bad) = pts.iter().find(|&&p| p as usize >= n) {
                    return Err(DataError::IndexOutOfRange {
                        path: path.to_path_buf(),
                        cell: c,
                        index: u64::from(bad),
                        points: n,
                    });
                }
            }
        }
        let cells = self.geometry.cell_count();
        for a in &self.arrays {
            let expected = match a.location {
                Location::Point => n,
                Location::Cell => cells,
            };
            if a.values.len() != expected {
                return Err(format_error(
                    path,
                    &format!("array '{}'", a.name),
                    &format!("{expected} values ({} data)", a.location.name()),
                    &a.values.len().to_string(),
                ));
            }
            if let Some(i) = a.values.iter().position(|v| !super::renderable_value(v)) {
                return Err(DataError::NonFiniteValue {
                    path: path.to_path_buf(),
                    array: a.name.clone(),
                    index: i,
                    value: a.values.get(i),
                });
            }
        }
        Ok(())
    }
}

fn format_error(path: &Path, location: &str, expected: &str, found: &str) -> DataError {
    DataError::Format {
        path: path.to_path_buf(),
        location: location.to_string(),
        expected: expected.to_string(),
        found: found.to_string(),
    }
}
