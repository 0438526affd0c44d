//! What one rank reads of a parallel file's pieces when the ranks read it together
//! ([`super::parallel_scattered`]): a contiguous share of the pieces, as samples (positions,
//! values, and for grids each sample's index in the whole grid) with what the whole field's
//! domain and supports need from them — a mesh's unshared cell faces (and, for one-ring
//! supports, its points' one-rings in the share), a curvilinear grid's boundary triangles in
//! the share, a rectilinear grid's coordinates.

use super::BrickError;
use crate::data::dataset::{Geometry, Location};
use crate::data::vtk_xml_parallel::Summary;
use crate::samples::mesh::{
    Face, Triangle, boundary_faces, check_cells, structured_centroids, structured_sides,
};
use crate::samples::supports::one_rings;
use crate::samples::{SampleSettings, centres, check_settings};

/// What a rank read of its share of the pieces.
#[derive(Default)]
pub struct Part {
    pub positions: Vec<[f64; 3]>,
    pub values: Vec<f32>,
    /// Each sample's index in the whole set: a grid's sample index (x fastest); meshes and
    /// points are numbered once the ranks know each other's counts.
    pub index: Vec<f64>,
    /// A mesh: the faces none of this share's cells shares.
    pub faces: Vec<Face>,
    /// A mesh's point data with one-ring supports: each point's one-ring in this share's cells
    /// (indices into `positions`); empty otherwise.
    pub rings: Vec<Vec<u32>>,
    /// A curvilinear grid: the whole grid's sides in this share.
    pub triangles: Vec<Triangle>,
    /// A rectilinear grid: (point index along the axis, coordinate) per axis.
    pub coords: [Vec<(usize, f64)>; 3],
    /// The array read and where it lives (none: this rank read no piece).
    pub array: Option<(String, Location)>,
    pub inverted: usize,
    pub pieces: usize,
}

/// The pieces rank `rank` of `ranks` reads: a contiguous share.
fn share(pieces: usize, rank: usize, ranks: usize) -> std::ops::Range<usize> {
    pieces * rank / ranks..pieces * (rank + 1) / ranks
}

/// The samples along each axis of a grid of `points` points (cell data: its cells).
pub fn sample_dims(points: [usize; 3], cell_data: bool) -> [usize; 3] {
    if cell_data {
        points.map(|n| n.saturating_sub(1).max(1))
    } else {
        points
    }
}

/// Reads rank `rank`'s share of `summary`'s pieces.
pub fn read_part(
    summary: &Summary,
    rank: usize,
    ranks: usize,
    array: Option<&str>,
    settings: &SampleSettings,
) -> Result<Part, BrickError> {
    check_settings(settings).map_err(|e| BrickError::Message(e.to_string()))?;
    let mine: Vec<usize> = share(summary.pieces.len(), rank, ranks).collect();
    let mut part = Part {
        pieces: mine.len(),
        ..Part::default()
    };
    if mine.is_empty() {
        return Ok(part);
    }
    if summary.whole.is_some() {
        for &p in &mine {
            read_grid_piece(summary, p, array, &mut part)?;
        }
        return Ok(part);
    }
    let dataset = summary.assemble(&mine)?;
    let path = &summary.path;
    let source = path.display().to_string();
    let sample = |e: crate::samples::SampleError| BrickError::Message(e.to_string());
    let data = dataset.array(path, array)?;
    let cell_data = data.location == Location::Cell;
    part.array = Some((data.name.clone(), data.location));
    part.values = data.values.as_f32().into_owned();
    match &dataset.geometry {
        Geometry::Unstructured { points, cells } => {
            let checked = check_cells(points, cells, &source).map_err(sample)?;
            part.inverted = checked.inverted;
            if !cell_data && settings.anisotropic == Some(true) {
                let identity: Vec<u32> = (0..points.len() as u32).collect();
                part.rings = one_rings(cells, &identity, points.len());
            }
            part.positions = if cell_data {
                checked.centroids
            } else {
                points.clone()
            };
            part.faces = boundary_faces(points, cells, &source).map_err(sample)?;
        }
        Geometry::Points { points } => part.positions = points.clone(),
        other => {
            return Err(BrickError::Message(format!(
                "{source}: a {} among the pieces of a {}",
                other.kind(),
                summary.kind
            )));
        }
    }
    Ok(part)
}

/// Adds piece `p` of a curvilinear or rectilinear grid to `part`.
fn read_grid_piece(
    summary: &Summary,
    p: usize,
    array: Option<&str>,
    part: &mut Part,
) -> Result<(), BrickError> {
    let source = summary.pieces[p].source.display().to_string();
    let (Some(whole), Some(e)) = (summary.whole, summary.pieces[p].extent) else {
        return Err(BrickError::Message(format!(
            "{source}: a grid piece without its extent"
        )));
    };
    if summary.kind == "StructuredGrid" && (0..3).any(|a| whole[2 * a + 1] <= whole[2 * a]) {
        return Err(BrickError::Message(format!(
            "{}: a curvilinear grid flat along an axis has no interior",
            summary.path.display()
        )));
    }
    let dataset = summary.assemble(&[p])?;
    let data = dataset.array(&summary.path, array)?;
    let cell_data = data.location == Location::Cell;
    let points_of = |e: [i64; 6]| [0, 1, 2].map(|a| (e[2 * a + 1] - e[2 * a] + 1) as usize);
    let ws = sample_dims(points_of(whole), cell_data);
    let ps = sample_dims(points_of(e), cell_data);
    let start = [0, 1, 2].map(|a| (e[2 * a] - whole[2 * a]) as usize);
    // The piece's samples in its own x-fastest order, numbered in the whole grid's.
    for k in 0..ps[2] {
        for j in 0..ps[1] {
            for i in 0..ps[0] {
                let q = [start[0] + i, start[1] + j, start[2] + k];
                part.index
                    .push((q[0] + ws[0] * (q[1] + ws[1] * q[2])) as f64);
            }
        }
    }
    part.values.extend(data.values.as_f32().iter());
    match &dataset.geometry {
        Geometry::Structured { dims, points } => {
            if cell_data {
                part.positions.extend(structured_centroids(*dims, points).1);
            } else {
                part.positions.extend(points);
            }
            // The whole grid's sides that this piece lies on.
            let sides =
                [0, 1, 2].map(|a| [e[2 * a] == whole[2 * a], e[2 * a + 1] == whole[2 * a + 1]]);
            part.triangles
                .extend(structured_sides(*dims, points, sides));
        }
        Geometry::Rectilinear { coords } => {
            let sampled = if cell_data {
                [0, 1, 2].map(|a| centres(&coords[a]))
            } else {
                coords.clone()
            };
            for k in 0..ps[2] {
                for j in 0..ps[1] {
                    for i in 0..ps[0] {
                        part.positions
                            .push([sampled[0][i], sampled[1][j], sampled[2][k]]);
                    }
                }
            }
            for a in 0..3 {
                part.coords[a].extend(
                    coords[a]
                        .iter()
                        .enumerate()
                        .map(|(i, &c)| (start[a] + i, c)),
                );
            }
        }
        other => {
            return Err(BrickError::Message(format!(
                "{source}: a {} among the pieces of a {}",
                other.kind(),
                summary.kind
            )));
        }
    }
    let name = (data.name.clone(), data.location);
    match &part.array {
        Some(a) if *a != name => {
            return Err(BrickError::Message(format!(
                "{source}: holds array {} where the share's first piece holds {}",
                name.0, a.0
            )));
        }
        _ => part.array = Some(name),
    }
    Ok(())
}
