//! Bricks read piece by piece from a parallel VTK XML image (`.pvti`, issue 30 §2), so that no
//! rank holds the whole grid: every rank reads the summary, builds the kd tree from it alone
//! (a grid's tree needs only its planes: [`KdTree::decompose_grid`]) and reads only the
//! pieces that meet its brick and its ghost planes ([`GridPlan::read_brick`]). The brick's
//! samples equal those that [`super::piece_of`] takes from the whole field: the same grid
//! positions in the same frame (the domain's centre), the same values; what a rank cannot know
//! alone, the value range, the caller agrees on across the ranks (a minimum and maximum).
//!
//! For splatting, a grid brick is the sub-grid holding every kernel that reaches its sheets
//! in the view ([`super::splat`]): each rank projects its own planes' kernels and the ranks
//! reduce, per brick, the index box of those that reach it ([`GridPlan::read_splat_brick`]).
//! The other kinds (`.pvtr`, `.pvts`, `.pvtu`, `.pvtp`), whose samples vmls holds as scattered
//! positions, are read by the ranks in shares and redistributed
//! ([`super::parallel_scattered`]); what neither reads is read whole by one rank
//! ([`crate::data::vtk_xml_parallel::load`]) and divided as any field ([`ranks_read`]).

use super::exchange::{Exchange, all_max, all_min};
use super::ghosts::{GhostCount, cell_of, grid_window, mls_layers};
use super::kd::KdTree;
use super::splat::SplatReach;
use super::{Aabb, BrickError};
use crate::data::dataset::Location;
use crate::data::dataset::grid_point;
use crate::data::vtk_xml_parallel::Summary;
use crate::field::{Field, PieceFrame, SupportExtent};
use crate::recon::{OctreeSettings, Reconstruction};
use crate::samples::{Domain, Positions, SampleSet, SampleSettings, Supports};
use crate::view::View;
use glam::DVec3;

/// Whether the ranks read the file at `path` themselves ([`GridPlan`],
/// [`super::parallel_scattered`]); otherwise rank 0 reads it whole and sends each rank its
/// piece: every parallel kind, ray cast or splatted, with any supports (the neighbours that
/// pieces split, a mesh's one-rings and a curvilinear grid's edges, are asked of the ranks
/// that hold them).
pub fn ranks_read(path: &std::path::Path) -> bool {
    let name = path.to_string_lossy().to_ascii_lowercase();
    [".pvti", ".pvtr", ".pvts", ".pvtu", ".pvtp"]
        .iter()
        .any(|e| name.ends_with(e))
}

/// A `.pvti`'s grid as the whole field would hold it, and its decomposition.
#[derive(Debug, Clone)]
pub struct GridPlan {
    pub summary: Summary,
    pub tree: KdTree,
    /// The samples' grid, frame-relative (cell data: the cells' centres).
    dims: [usize; 3],
    origin: [f64; 3],
    spacing: [f64; 3],
    /// The domain (the points' box), frame-relative, and the frame's origin (its centre).
    domain: Aabb,
    frame_origin: DVec3,
    /// The scene's array (`volume.array`), whether it is cell data, its support radii.
    array: Option<String>,
    cell_data: bool,
    support: [f64; 3],
}

/// One rank's brick of a [`GridPlan`]: its samples (frame-relative, the whole field's
/// domain), counts, and the range of the values it read.
pub struct GridBrick {
    pub samples: SampleSet,
    pub count: GhostCount,
    pub range: (f64, f64),
    /// Pieces read, of the summary's.
    pub pieces_read: usize,
    /// Its first sample's grid index along each axis, and its samples along each axis.
    pub first: [usize; 3],
    pub dims: [usize; 3],
}

impl GridPlan {
    /// The plan of `summary` (a `.pvti`) for `ranks` ranks, with the scene's `array` and
    /// sample `settings`.
    pub fn new(
        summary: Summary,
        array: Option<&str>,
        settings: &SampleSettings,
        ranks: usize,
    ) -> Result<Self, BrickError> {
        let whole = match (summary.kind, summary.whole) {
            ("ImageData", Some(w)) => w,
            _ => {
                return Err(BrickError::Setting {
                    key: "volume.file",
                    message: format!(
                        "{}: ranks read their own pieces of a parallel image (.pvti); a {} is \
                         read by rank 0",
                        summary.path.display(),
                        summary.kind
                    ),
                });
            }
        };
        // The scene's array by the rule of Dataset::array: named, else the first point array,
        // else the first.
        let arrays = &summary.arrays;
        let chosen = match array {
            Some(n) => arrays.iter().find(|a| a.0 == n),
            None => arrays
                .iter()
                .find(|a| a.1 == Location::Point)
                .or_else(|| arrays.first()),
        };
        let Some((_, location)) = chosen else {
            return Err(BrickError::Setting {
                key: "volume.array",
                message: format!(
                    "{}: no array {} among the summary's {:?}",
                    summary.path.display(),
                    array.unwrap_or("at all"),
                    arrays.iter().map(|a| &a.0).collect::<Vec<_>>()
                ),
            });
        };
        let cell_data = *location == Location::Cell;
        let points = [0, 1, 2].map(|a| (whole[2 * a + 1] - whole[2 * a] + 1) as usize);
        let (s, o) = (summary.spacing, summary.origin);
        // As the loader and SampleSet::from_dataset place them.
        let origin = [0, 1, 2].map(|a| o[a] + whole[2 * a] as f64 * s[a]);
        let lo = origin;
        let hi = [0, 1, 2].map(|a| origin[a] + (points[a] - 1) as f64 * s[a]);
        let (dims, origin) = if cell_data {
            (
                points.map(|n| n.saturating_sub(1).max(1)),
                [0, 1, 2].map(|a| origin[a] + if points[a] > 1 { 0.5 * s[a] } else { 0.0 }),
            )
        } else {
            (points, origin)
        };
        // Field::from_samples_deferred's frame: the domain's centre.
        let centre = (DVec3::from(lo) + DVec3::from(hi)) * 0.5;
        let c = centre.to_array();
        let shift = |p: [f64; 3]| [0, 1, 2].map(|a| p[a] - c[a]);
        let (origin, domain) = (shift(origin), (shift(lo), shift(hi)));
        let tree = KdTree::decompose_grid(dims, origin, s, domain, ranks)?;
        Ok(Self {
            summary,
            tree,
            dims,
            origin,
            spacing: s,
            domain,
            frame_origin: centre,
            array: array.map(str::to_string),
            cell_data,
            support: s.map(|x| settings.support * x),
        })
    }

    /// Reads the pieces that meet `rank`'s brick and its ghost planes, and takes the brick's
    /// samples from them.
    pub fn read_brick(
        &self,
        rank: usize,
        settings: &SampleSettings,
    ) -> Result<GridBrick, BrickError> {
        let layers = mls_layers(self.support, self.spacing);
        self.read_window(rank, settings, layers, None)
    }

    /// Reads the sub-grid of `rank`'s brick with `layers` more planes on each side, widened to
    /// the index box `needed` ([`grid_window`]).
    fn read_window(
        &self,
        rank: usize,
        settings: &SampleSettings,
        layers: [i64; 3],
        needed: Option<([i64; 3], [i64; 3])>,
    ) -> Result<GridBrick, BrickError> {
        let (first, count, own) = grid_window(
            self.dims,
            self.origin,
            self.spacing,
            self.tree.boxes[rank],
            layers,
            needed,
        );
        // The sample index box in the whole extent's point indices (a cell's samples need the
        // point after it).
        let whole = self.summary.whole.unwrap_or_default();
        let extra = i64::from(self.cell_data);
        let lo = [0, 1, 2].map(|a| whole[2 * a] + first[a] as i64);
        let hi = [0, 1, 2].map(|a| whole[2 * a] + (first[a] + count[a]) as i64 - 1 + extra);
        let which = self.summary.pieces_meeting(lo, hi);
        let dataset = self.summary.assemble(&which)?;
        let path = &self.summary.path;
        let read = SampleSet::from_dataset(&dataset, path, self.array.as_deref(), settings)
            .map_err(|e| BrickError::Message(e.to_string()))?;
        let Positions::Grid { dims: rd, .. } = read.positions else {
            return Err(BrickError::Message(
                "a parallel image read as no grid".into(),
            ));
        };
        // Where the pieces read start, in sample indices of the whole grid.
        let crate::data::dataset::Geometry::Image { origin: ro, .. } = dataset.geometry else {
            return Err(BrickError::Message(
                "a parallel image read as no grid".into(),
            ));
        };
        let start = [0, 1, 2].map(|a| {
            ((ro[a] - self.summary.origin[a]) / self.spacing[a]).round() as i64 - whole[2 * a]
        });
        let mut indices = Vec::with_capacity(count.iter().product());
        for k in 0..count[2] {
            for j in 0..count[1] {
                let at = |a: usize, i: usize| (first[a] + i) as i64 - start[a];
                let (y, z) = (at(1, j), at(2, k));
                let x = at(0, 0);
                if [x, y, z]
                    .iter()
                    .zip(&rd)
                    .any(|(&v, &n)| v < 0 || v as usize >= n)
                    || x as usize + count[0] > rd[0]
                {
                    return Err(BrickError::Message(format!(
                        "{}: the pieces meeting rank {rank}'s brick do not hold its samples",
                        path.display()
                    )));
                }
                let row = ((z as usize * rd[1]) + y as usize) * rd[0] + x as usize;
                indices.extend(row..row + count[0]);
            }
        }
        let values = read.values.select(&indices);
        let range = values.iter().fold((f64::MAX, f64::MIN), |(l, h), v| {
            (l.min(f64::from(v)), h.max(f64::from(v)))
        });
        let total = indices.len();
        let samples = SampleSet {
            positions: Positions::Grid {
                dims: count,
                origin: [0, 1, 2].map(|a| self.origin[a] + first[a] as f64 * self.spacing[a]),
                spacing: self.spacing,
            },
            values,
            supports: Supports::Uniform(self.support),
            domain: Domain::Box {
                lo: self.domain.0,
                hi: self.domain.1,
            },
            spacing: read.spacing,
            provenance: read.provenance,
        };
        Ok(GridBrick {
            samples,
            count: GhostCount {
                own,
                ghosts: total - own,
            },
            range,
            pieces_read: which.len(),
            first,
            dims: count,
        })
    }

    /// The piece of `rank` from its [`GridBrick`] and the whole field's value `range`.
    pub fn piece(
        &self,
        rank: usize,
        brick: GridBrick,
        range: (f64, f64),
        reconstruction: Reconstruction,
        octree: OctreeSettings,
    ) -> Result<Field, BrickError> {
        let last = self.dims.map(|n| n - 1);
        let corner = grid_point(
            self.dims,
            self.origin,
            self.spacing,
            (last[2] * self.dims[1] + last[1]) * self.dims[0] + last[0],
        );
        let h = self.support;
        let extent = SupportExtent {
            support_box: (
                DVec3::from([0, 1, 2].map(|a| self.origin[a] - h[a])),
                DVec3::from([0, 1, 2].map(|a| corner[a] + h[a])),
            ),
            thinnest: brick.samples.thinnest_support(),
            radii: brick.samples.radius_quantiles(64),
        };
        let frame = PieceFrame {
            frame_origin: self.frame_origin,
            range,
            reconstruction,
            octree,
            extent: Some(extent),
        };
        let bounds = self.tree.boxes[rank];
        Ok(Field::from_piece(
            brick.samples,
            frame,
            (DVec3::from(bounds.0), DVec3::from(bounds.1)),
            None,
            |_| {},
        )?)
    }

    /// `rank`'s brick for splatting `view` (collective over `ex`): the sub-grid holding every
    /// kernel that adds to a sheet its cell owns, as [`super::piece_of`] takes it with
    /// [`super::Ghosts::Splat`]. Each rank reads its brick's planes, projects those kernels
    /// for the view ([`SplatReach`], on a piece that keeps the whole field's frame) and marks,
    /// for every rank whose cell a kernel reaches, the kernel's grid index; the index boxes
    /// are reduced over the ranks, and each rank reads the pieces its box meets. Returns the
    /// piece, its counts and the pieces it read.
    pub fn read_splat_brick<E: Exchange>(
        &self,
        ex: &E,
        settings: &SampleSettings,
        view: &View<'_>,
        reconstruction: Reconstruction,
        octree: OctreeSettings,
    ) -> Result<(Field, GhostCount, usize), E::Error> {
        let rank = ex.rank();
        let planes = ex.agree(
            self.read_window(rank, settings, [0; 3], None)
                .map_err(|e| e.to_string()),
        )?;
        let range = (
            all_min(ex, &[planes.range.0])[0],
            all_max(ex, &[planes.range.1])[0],
        );
        let (first, dims, own_pieces) = (planes.first, planes.dims, planes.pieces_read);
        let piece = ex.agree(
            self.piece(rank, planes, range, reconstruction, octree)
                .map_err(|e| e.to_string()),
        )?;
        let reach = ex.agree(SplatReach::new(&piece, view).map_err(|e| e.to_string()))?;
        let cells: Vec<Aabb> = self
            .tree
            .boxes
            .iter()
            .map(|&b| cell_of(&piece.samples, b))
            .collect();
        let ranks = cells.len();
        let (mut lo, mut hi) = (
            vec![f64::INFINITY; 3 * ranks],
            vec![f64::NEG_INFINITY; 3 * ranks],
        );
        for j in 0..piece.samples.len() {
            let local = [
                j % dims[0],
                (j / dims[0]) % dims[1],
                j / (dims[0] * dims[1]),
            ];
            for (s, &cell) in cells.iter().enumerate() {
                if reach.meets(j, cell) {
                    for a in 0..3 {
                        let g = (first[a] + local[a]) as f64;
                        lo[3 * s + a] = lo[3 * s + a].min(g);
                        hi[3 * s + a] = hi[3 * s + a].max(g);
                    }
                }
            }
        }
        let (lo, hi) = (all_min(ex, &lo), all_max(ex, &hi));
        let bound = |v: f64, empty: i64| if v.is_finite() { v as i64 } else { empty };
        let needed = (
            [0, 1, 2].map(|a| bound(lo[3 * rank + a], i64::MAX)),
            [0, 1, 2].map(|a| bound(hi[3 * rank + a], i64::MIN)),
        );
        let brick = ex.agree(
            self.read_window(rank, settings, [0; 3], Some(needed))
                .map_err(|e| e.to_string()),
        )?;
        let (count, pieces) = (brick.count, own_pieces.max(brick.pieces_read));
        let piece = ex.agree(
            self.piece(rank, brick, range, reconstruction, octree)
                .map_err(|e| e.to_string()),
        )?;
        Ok((piece, count, pieces))
    }
}
