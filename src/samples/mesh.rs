//! Meshes and curvilinear grids: cell checks, centroids (where cell data is sampled) and the
//! boundary hull that rays are clipped against ([MLS] §4 "clipped intervals"; DESIGN §4).
//!
//! Choices, each tested in `tests/samples.rs`:
//! - a cell whose volume is below `DEGENERATE_VOLUME` × (its bounding-box diagonal)³ is an
//!   error naming the cell: it has no interior, so its faces would make a hull with no inside;
//! - an inverted cell (negative volume in VTK's point order) is accepted and counted: MLS does
//!   not use cells, and the hull is built from face incidence, not orientation;
//! - the boundary is the set of faces used by exactly one cell (faces are matched by their
//!   point indices after coincident points are merged); a face used by three or more cells is a
//!   non-manifold mesh and an error naming the face's points;
//! - quadrilateral faces are split into two triangles along their 0–2 diagonal.

use super::{SampleError, merge_duplicates};
use crate::data::dataset::{CellType, Cells};
use std::collections::HashMap;

/// Relative volume below which a cell counts as degenerate.
pub const DEGENERATE_VOLUME: f64 = 1e-10;

/// Boundary triangles of a domain.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Hull {
    pub vertices: Vec<[f64; 3]>,
    pub triangles: Vec<[u32; 3]>,
}

impl Hull {
    /// Bounding box of the vertices.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for v in &self.vertices {
            for a in 0..3 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
        }
        (lo, hi)
    }
}

/// Faces of a cell in VTK's point order, each listed counter-clockwise seen from outside
/// (for a positively oriented cell).
pub fn cell_faces(kind: CellType) -> &'static [&'static [usize]] {
    match kind {
        CellType::Tetra => &[&[0, 1, 3], &[1, 2, 3], &[2, 0, 3], &[0, 2, 1]],
        CellType::Hexahedron => &[
            &[0, 4, 7, 3],
            &[1, 2, 6, 5],
            &[0, 1, 5, 4],
            &[3, 7, 6, 2],
            &[0, 3, 2, 1],
            &[4, 5, 6, 7],
        ],
        CellType::Voxel => &[
            &[0, 4, 6, 2],
            &[1, 3, 7, 5],
            &[0, 1, 5, 4],
            &[2, 6, 7, 3],
            &[0, 2, 3, 1],
            &[4, 5, 7, 6],
        ],
        CellType::Wedge => &[
            &[0, 1, 2],
            &[3, 5, 4],
            &[0, 3, 4, 1],
            &[1, 4, 5, 2],
            &[2, 5, 3, 0],
        ],
        CellType::Pyramid => &[
            &[0, 3, 2, 1],
            &[0, 1, 4],
            &[1, 2, 4],
            &[2, 3, 4],
            &[3, 0, 4],
        ],
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Signed volume of a cell: the tetrahedra from its centroid to its (fan-triangulated)
/// faces, positive for VTK's orientation.
pub fn cell_volume(kind: CellType, p: &[[f64; 3]]) -> f64 {
    let n = p.len() as f64;
    let c = p.iter().fold([0.0; 3], |s, q| {
        [s[0] + q[0] / n, s[1] + q[1] / n, s[2] + q[2] / n]
    });
    let mut v = 0.0;
    for face in cell_faces(kind) {
        for t in 1..face.len() - 1 {
            let (a, b, d) = (p[face[0]], p[face[t]], p[face[t + 1]]);
            v += dot(sub(a, c), cross(sub(b, a), sub(d, a))) / 6.0;
        }
    }
    v
}

/// What the cell checks found.
#[derive(Debug, Clone)]
pub struct CheckedCells {
    pub centroids: Vec<[f64; 3]>,
    pub inverted: usize,
}

/// Rejects degenerate cells, counts inverted ones and computes centroids.
pub fn check_cells(
    points: &[[f64; 3]],
    cells: &Cells,
    source: &str,
) -> Result<CheckedCells, SampleError> {
    let mut out = CheckedCells {
        centroids: Vec::with_capacity(cells.len()),
        inverted: 0,
    };
    let mut p = Vec::with_capacity(8);
    for c in 0..cells.len() {
        p.clear();
        p.extend(cells.cell(c).iter().map(|&i| points[i as usize]));
        let kind = cells.types[c];
        let n = p.len() as f64;
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut centroid = [0.0; 3];
        for q in &p {
            for a in 0..3 {
                lo[a] = lo[a].min(q[a]);
                hi[a] = hi[a].max(q[a]);
                centroid[a] += q[a] / n;
            }
        }
        let diag = dot(sub(hi, lo), sub(hi, lo)).sqrt();
        let v = cell_volume(kind, &p);
        // Written so that a NaN volume also counts as degenerate.
        let sound = v.abs() > DEGENERATE_VOLUME * diag * diag * diag;
        if !sound {
            return Err(SampleError::Invalid {
                source_name: source.to_string(),
                message: format!(
                    "cell {c} ({}, points {:?}) is degenerate: volume {v:e} for a cell of size {diag:e}",
                    kind.name(),
                    cells.cell(c)
                ),
            });
        }
        if v < 0.0 {
            out.inverted += 1;
        }
        out.centroids.push(centroid);
    }
    Ok(out)
}

/// A face of a cell: its corners (3 or 4), in the order that faces out of the cell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Face {
    pub corners: usize,
    pub points: [[f64; 3]; 4],
}

impl Face {
    /// The corners' coordinates as bits, sorted (unused corners last): two faces with the same
    /// key are the same face seen from its two cells.
    fn key(&self) -> [[u64; 3]; 4] {
        let mut key = [[u64::MAX; 3]; 4];
        for (k, p) in self.points[..self.corners].iter().enumerate() {
            key[k] = p.map(f64::to_bits);
        }
        key.sort_unstable();
        key
    }
}

/// Boundary faces of an unstructured mesh as triangles (module docs).
pub fn unstructured_hull(
    points: &[[f64; 3]],
    cells: &Cells,
    source: &str,
) -> Result<Hull, SampleError> {
    hull_of_faces(boundary_faces(points, cells, source)?, source)
}

/// The faces of `cells` that no other of them shares (module docs), at the coordinates of
/// their merged points: a mesh's boundary, or, for a piece of a mesh, its boundary and the
/// faces it shares with other pieces ([`hull_of_faces`] matches those).
pub fn boundary_faces(
    points: &[[f64; 3]],
    cells: &Cells,
    source: &str,
) -> Result<Vec<Face>, SampleError> {
    // Coincident points are one point for face matching.
    let merged = merge_duplicates(points.to_vec(), vec![0.0; points.len()]);
    let remap = &merged.remap;
    // key: sorted point indices (u32::MAX pads triangles) → (uses, the face as written).
    let mut faces: HashMap<[u32; 4], (u32, [u32; 4], usize)> = HashMap::new();
    let mut corners = Vec::with_capacity(8);
    for c in 0..cells.len() {
        let ids = cells.cell(c);
        corners.clear();
        corners.extend(ids.iter().map(|&i| points[i as usize]));
        // Faces of an inverted cell are listed inside out: reverse them so the hull faces out.
        let inverted = cell_volume(cells.types[c], &corners) < 0.0;
        for face in cell_faces(cells.types[c]) {
            let mut written = [u32::MAX; 4];
            for (k, &f) in face.iter().enumerate() {
                let f = if inverted {
                    face[face.len() - 1 - k]
                } else {
                    f
                };
                written[k] = remap[ids[f] as usize];
            }
            let mut key = written;
            key.sort_unstable();
            let entry = faces.entry(key).or_insert((0, written, face.len()));
            entry.0 += 1;
            if entry.0 > 2 {
                return Err(SampleError::Invalid {
                    source_name: source.to_string(),
                    message: format!(
                        "non-manifold mesh: the face with points {:?} is shared by 3 or more cells (the last is cell {c})",
                        &written[..face.len()]
                    ),
                });
            }
        }
    }
    Ok(faces
        .into_values()
        .filter(|(uses, _, _)| *uses == 1)
        .map(|(_, f, n)| {
            let mut points = [[0.0; 3]; 4];
            for k in 0..n {
                points[k] = merged.positions[f[k] as usize];
            }
            Face { corners: n, points }
        })
        .collect())
}

/// The hull of faces gathered from a mesh's cells, or from pieces of one
/// ([`boundary_faces`] of each): a face listed twice (by coordinates) lies between two cells
/// and is dropped, one listed three or more times is a non-manifold mesh; the rest are fanned
/// into triangles ([`hull_of_triangles`], which sorts them, so that the hull, and every image,
/// is the same whichever pieces they came from and in which order).
pub fn hull_of_faces(faces: Vec<Face>, source: &str) -> Result<Hull, SampleError> {
    let mut keyed: Vec<([[u64; 3]; 4], Face)> = faces.into_iter().map(|f| (f.key(), f)).collect();
    keyed.sort_unstable_by_key(|a| a.0);
    let mut triangles = Vec::new();
    for same in keyed.chunk_by(|a, b| a.0 == b.0) {
        let face = same[0].1;
        if same.len() > 2 {
            return Err(SampleError::Invalid {
                source_name: source.to_string(),
                message: format!(
                    "non-manifold mesh: the face with corners {:?} is shared by 3 or more cells",
                    &face.points[..face.corners]
                ),
            });
        }
        if same.len() == 1 {
            let p = &face.points;
            triangles.extend((1..face.corners - 1).map(|t| [p[0], p[t], p[t + 1]]));
        }
    }
    Ok(hull_of_triangles(triangles))
}

/// Signed volume enclosed by a closed triangle surface (positive when it faces out).
pub fn enclosed_volume(hull: &Hull) -> f64 {
    hull.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| hull.vertices[i as usize]);
            dot(a, cross(b, c)) / 6.0
        })
        .sum()
}

/// Centroids of the hexahedral cells of a curvilinear grid, as a grid of dims − 1.
pub fn structured_centroids(dims: [usize; 3], points: &[[f64; 3]]) -> ([usize; 3], Vec<[f64; 3]>) {
    let cd = dims.map(|n| n.saturating_sub(1).max(1));
    let index = |i: usize, j: usize, k: usize| i + dims[0] * (j + dims[1] * k);
    let mut out = Vec::with_capacity(cd[0] * cd[1] * cd[2]);
    for k in 0..cd[2] {
        for j in 0..cd[1] {
            for i in 0..cd[0] {
                let mut c = [0.0; 3];
                let mut n = 0.0;
                for dk in 0..2.min(dims[2]) {
                    for dj in 0..2.min(dims[1]) {
                        for di in 0..2.min(dims[0]) {
                            let p = points[index(i + di, j + dj, k + dk)];
                            for a in 0..3 {
                                c[a] += p[a];
                            }
                            n += 1.0;
                        }
                    }
                }
                out.push(c.map(|v| v / n));
            }
        }
    }
    (cd, out)
}

/// A triangle as its corners' coordinates.
pub type Triangle = [[f64; 3]; 3];

/// The six sides of a curvilinear grid as triangles. A grid that is flat in some index
/// direction has no interior and is rejected.
pub fn structured_hull(
    dims: [usize; 3],
    points: &[[f64; 3]],
    source: &str,
) -> Result<super::Domain, SampleError> {
    if dims.iter().any(|&n| n < 2) {
        return Err(SampleError::Invalid {
            source_name: source.to_string(),
            message: format!(
                "curvilinear grid of dimensions {dims:?} has no interior (every dimension must be at least 2)"
            ),
        });
    }
    let mut triangles = structured_sides(dims, points, [[true; 2]; 3]);
    // A left-handed index frame turns every side inwards.
    if signed_volume(&triangles) < 0.0 {
        turn(&mut triangles);
    }
    Ok(super::Domain::Hull(hull_of_triangles(triangles)))
}

/// The sides of a curvilinear grid (`dims` points, x fastest) that `sides[axis][low, high]`
/// chooses, each cell face split along its (0,0)–(1,1) diagonal, opposite sides wound
/// oppositely (so that all face the same way, out or in). For a piece of a grid, the sides it
/// shares with the whole grid's boundary: the whole grid's triangles there.
pub fn structured_sides(
    dims: [usize; 3],
    points: &[[f64; 3]],
    sides: [[bool; 2]; 3],
) -> Vec<Triangle> {
    let index = |q: [usize; 3]| q[0] + dims[0] * (q[1] + dims[1] * q[2]);
    let mut triangles = Vec::new();
    if dims.iter().any(|&n| n < 2) {
        return triangles;
    }
    for a in 0..3 {
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        for (high, side) in [(false, 0), (true, dims[a] - 1)] {
            if !sides[a][usize::from(high)] {
                continue;
            }
            for v in 0..dims[c] - 1 {
                for u in 0..dims[b] - 1 {
                    let corner = |du: usize, dv: usize| {
                        let mut q = [0; 3];
                        q[a] = side;
                        q[b] = u + du;
                        q[c] = v + dv;
                        points[index(q)]
                    };
                    let (p0, p1, p2, p3) = (corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1));
                    if high {
                        triangles.push([p0, p1, p2]);
                        triangles.push([p0, p2, p3]);
                    } else {
                        triangles.push([p0, p2, p1]);
                        triangles.push([p0, p3, p2]);
                    }
                }
            }
        }
    }
    triangles
}

/// Signed volume enclosed by triangles (positive when they face out of a closed surface).
pub fn signed_volume(triangles: &[Triangle]) -> f64 {
    triangles
        .iter()
        .map(|[a, b, c]| dot(*a, cross(*b, *c)) / 6.0)
        .sum()
}

/// Turns every triangle the other way.
pub fn turn(triangles: &mut [Triangle]) {
    for t in triangles {
        t.swap(1, 2);
    }
}

/// A hull of triangles given by their corners, sorted by them (so that the hull, and every
/// image, is the same whichever pieces of a grid they came from and in which order), each
/// vertex once.
pub fn hull_of_triangles(mut triangles: Vec<Triangle>) -> Hull {
    triangles.sort_unstable_by_key(|t| t.map(|p| p.map(f64::to_bits)));
    let mut hull = Hull::default();
    let mut used: HashMap<[u64; 3], u32> = HashMap::new();
    for t in &triangles {
        let v = t.map(|p| {
            *used.entry(p.map(f64::to_bits)).or_insert_with(|| {
                hull.vertices.push(p);
                hull.vertices.len() as u32 - 1
            })
        });
        hull.triangles.push(v);
    }
    hull
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(kind: CellType) -> Vec<[f64; 3]> {
        match kind {
            CellType::Tetra => vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
            CellType::Hexahedron => vec![
                [0., 0., 0.],
                [1., 0., 0.],
                [1., 1., 0.],
                [0., 1., 0.],
                [0., 0., 1.],
                [1., 0., 1.],
                [1., 1., 1.],
                [0., 1., 1.],
            ],
            CellType::Voxel => (0..8)
                .map(|i| [(i & 1) as f64, (i >> 1 & 1) as f64, (i >> 2 & 1) as f64])
                .collect(),
            // VTK: the base (0, 1, 2) faces away from the top triangle (3, 4, 5).
            CellType::Wedge => vec![
                [0., 0., 0.],
                [0., 1., 0.],
                [1., 0., 0.],
                [0., 0., 1.],
                [0., 1., 1.],
                [1., 0., 1.],
            ],
            CellType::Pyramid => vec![
                [0., 0., 0.],
                [1., 0., 0.],
                [1., 1., 0.],
                [0., 1., 0.],
                [0.5, 0.5, 1.],
            ],
        }
    }

    #[test]
    fn unit_cells_have_their_volume_and_vtk_orientation() {
        for (kind, volume) in [
            (CellType::Tetra, 1.0 / 6.0),
            (CellType::Hexahedron, 1.0),
            (CellType::Voxel, 1.0),
            (CellType::Wedge, 0.5),
            (CellType::Pyramid, 1.0 / 3.0),
        ] {
            let v = cell_volume(kind, &unit(kind));
            assert!((v - volume).abs() < 1e-12, "{kind:?}: {v}");
            // Every face's normal points away from the centroid.
            let p = unit(kind);
            let n = p.len() as f64;
            let c = p.iter().fold([0.0; 3], |s, q| {
                [s[0] + q[0] / n, s[1] + q[1] / n, s[2] + q[2] / n]
            });
            for face in cell_faces(kind) {
                let (a, b, d) = (p[face[0]], p[face[1]], p[face[2]]);
                assert!(
                    dot(sub(a, c), cross(sub(b, a), sub(d, a))) > 0.0,
                    "{kind:?} {face:?}"
                );
            }
        }
    }
}
