//! Bricks of a parallel file whose samples are scattered positions — a mesh, points, a
//! rectilinear or curvilinear grid (`.pvtu`, `.pvtp`, `.pvtr`, `.pvts`; issue 30 §2) — read by
//! the ranks together and redistributed to the kd boxes, so that no rank holds the whole
//! field: each rank's brick equals the one [`super::piece_of`] takes from the whole field read
//! by one process, under the same tree, sample for sample and in the same order.
//!
//! Every rank reads a contiguous share of the pieces ([`super::part`]), then
//! ([`read_scattered`]):
//! 1. The ranks gather their counts, bounding boxes and a subsample of their positions (every
//!    s-th of the whole set, s = [`super::kd::subsample_stride`], by each sample's index in
//!    the whole set: a grid's sample index, else the pieces' order); a first tree cut from it
//!    (only to route: any balanced tree serves) sends every sample to the rank whose box holds
//!    it, where coincident samples merge (with
//!    the whole set's tolerance: coincident samples fall in one box; a grid's shared face
//!    samples are one).
//! 2. Supports from the k nearest neighbours, exactly: a rank's own k-th neighbour distance
//!    r_i bounds the true one from above, so the true neighbours lie in the ball of radius r_i;
//!    each rank asks every other rank whose box that ball meets for its samples inside it, and
//!    takes the k nearest of its own and the answers. A rectilinear grid's diagonal supports
//!    come from its coordinates, which the ranks gather; a curvilinear grid's edge supports
//!    from its samples' index-direction neighbours, asked of their owners. The nearest
//!    distances' median (the step unit) and the radius quantiles are selected over the ranks
//!    exactly ([`super::exchange::select`]).
//! 3. A mesh's hull: each rank's cells' faces that none of its cells shares
//!    ([`crate::samples::mesh::boundary_faces`]) are gathered, and a face that two ranks list
//!    lies between their pieces ([`crate::samples::mesh::hull_of_faces`]); a curvilinear
//!    grid's: the whole grid's sides in each share ([`crate::samples::mesh::structured_sides`]).
//! 4. The frame (the domain's centre), the value range and the supports' extent over the ranks;
//!    the final tree from the merged samples in the frame, subsampled and cut as the whole
//!    field's tree is ([`super::kd::picked`]); every
//!    sample is sent to the rank whose box owns it and, as a ghost, to every rank whose box its
//!    support reaches ([`super::distribute`]); the Gaussian sum's kernel volumes are computed
//!    by each sample's owner and sent on to the ranks that hold it as a ghost.
//!
//! What can differ from the whole field read by one process: sums in another order (kernel
//! volumes, merged values: rounding). The final tree is cut from the merged samples'
//! subsample, picked by their coordinates ([`super::kd::picked`]) as the whole field's is, so
//! it is the whole field's tree at any size.
//! Samples closer than the merge tolerance on two sides of a first-tree plane stay two
//! samples. A curvilinear grid's anisotropic (edge) supports read each sample's
//! index-direction neighbours, asked by grid index of the rank that owns them
//! ([`edge_supports`]); a mesh's one-ring supports join the rings each rank's cells give a
//! point at the point's owner ([`ring_supports`]).

use super::distribute::{distribute, kernel_volumes, route, splat_ghosts};
use super::exchange::{Exchange, all_max, all_min, all_sum, gather_f64, pod_bytes, pods, select};
use super::ghosts::GhostCount;
use super::ghosts::cell_of;
use super::kd::{KdTree, picked_of, subsample_stride};
use super::part::{Part, read_part, sample_dims};
use super::splat::SplatReach;
use super::{Aabb, BrickError};
use crate::data::dataset::Location;
use crate::data::vtk_xml_parallel::Summary;
use crate::field::{Field, PieceFrame, SupportExtent};
use crate::recon::gaussian::KernelVolumes;
use crate::recon::{OctreeSettings, ReconMethod, Reconstruction};
use crate::samples::mesh::{
    Face, Hull, Triangle, hull_of_faces, hull_of_triangles, signed_volume, turn,
};
use crate::samples::{
    Domain, Metric, Positions, Provenance, SampleSet, SampleSettings, Supports, centres,
    duplicate_tolerance, merge_duplicates_within, supports,
};
use crate::view::View;
use glam::DVec3;

/// One rank's brick of a parallel file read by the ranks together: its samples (frame-relative, its own
/// first, then its ghosts), the whole field's frame and tree, and its kernel volumes.
pub struct ScatteredBrick {
    pub samples: SampleSet,
    pub count: GhostCount,
    pub frame: PieceFrame,
    pub tree: KdTree,
    pub volumes: Option<KernelVolumes>,
    pub pieces_read: usize,
    pub rank: usize,
}

impl ScatteredBrick {
    /// The piece of the field this brick renders ([`Field::from_piece`]).
    pub fn piece(self) -> Result<(Field, KdTree, GhostCount, usize), BrickError> {
        let bounds = self.tree.boxes.get(self.rank).copied().ok_or_else(|| {
            BrickError::Message(format!("no box for rank {} in the tree", self.rank))
        })?;
        let field = Field::from_piece(
            self.samples,
            self.frame,
            (DVec3::from(bounds.0), DVec3::from(bounds.1)),
            self.volumes,
            |_| {},
        )?;
        Ok((field, self.tree, self.count, self.pieces_read))
    }
}

/// Squared distance from x to the box.
fn box_distance2(x: [f64; 3], (lo, hi): Aabb) -> f64 {
    (0..3)
        .map(|a| (x[a].clamp(lo[a], hi[a]) - x[a]).powi(2))
        .sum()
}

/// Reads the parallel file `summary` (not an image) on every rank of `ex` together and returns
/// this rank's brick for ray casting, or, with a splatting `view`, for splatting that view
/// (module docs). Collective; every phase is agreed on.
pub fn read_scattered<E: Exchange>(
    ex: &E,
    summary: &Summary,
    array: Option<&str>,
    settings: &SampleSettings,
    reconstruction: Reconstruction,
    octree: OctreeSettings,
    view: Option<&View<'_>>,
) -> Result<ScatteredBrick, E::Error> {
    let (rank, ranks) = (ex.rank(), ex.size());
    let path = summary.path.display().to_string();
    let mut part =
        ex.agree(read_part(summary, rank, ranks, array, settings).map_err(|e| e.to_string()))?;
    let kind = summary.kind;
    let grid = summary.whole.is_some();

    // 1. The whole set's size and box, the subsample, the first partition.
    let whole = gather_heads(ex, &part, summary)?;
    if !grid {
        part.index = (0..part.positions.len())
            .map(|i| (whole.offset + i) as f64)
            .collect();
    }
    let sub = subsample(ex, &part, whole.total);
    let first_tree =
        ex.agree(KdTree::decompose_points(sub, whole.bbox, ranks).map_err(|e| e.to_string()))?;
    let owned = partition(ex, &part, &first_tree, whole.bbox, grid);
    let counts = all_sum(ex, &[owned.positions.len() as f64, owned.merged as f64]);
    let (count, merged) = (counts[0] as u64, counts[1] as usize);
    // A grid's pieces must cover its whole extent, as the whole-file reader requires.
    ex.agree(if !grid || count as usize == whole.total {
        Ok(())
    } else {
        Err(format!(
            "{path}: the pieces hold {count} of the grid's {} samples: they leave a hole in its \
             whole extent",
            whole.total
        ))
    })?;

    // 2. Supports, and what the whole set's supports and spacing are: a rectilinear grid's
    // from its coordinates (with the nearest distances, the spacing, from one neighbour),
    // the others' from their k nearest neighbours.
    let coords = grid_coords(ex, &part, kind);
    let anisotropic = settings.anisotropic.unwrap_or(false);
    let diagonal = kind == "RectilinearGrid" && settings.anisotropic.unwrap_or(true);
    let edges = kind == "StructuredGrid" && anisotropic;
    let rings = kind == "UnstructuredGrid" && whole.array.1 == Location::Point && anisotropic;
    // Supports by a rule of the data where it has one (one-rings, grid edges, rectilinear gaps),
    // else from the k nearest neighbours; the nearest distances (the spacing) from neighbours.
    let ruled: Option<Vec<Metric>> = match &coords {
        _ if rings => Some(ring_supports(
            ex,
            &part,
            &owned,
            &first_tree,
            settings.knn_support,
        )),
        _ if edges => {
            let dims = whole.dims.unwrap_or([1; 3]);
            let metrics = edge_supports(ex, &owned, dims, settings.support);
            Some(ex.agree(metrics.map_err(|e| format!("{path}: {e}")))?)
        }
        Some(c) if diagonal => {
            let sampled = if whole.array.1 == Location::Cell {
                [0, 1, 2].map(|a| centres(&c[a]))
            } else {
                c.clone()
            };
            let dims = sampled.each_ref().map(Vec::len);
            let r = supports::RectilinearSupports::new(&sampled, settings.support);
            Some(
                owned
                    .index
                    .iter()
                    .map(|&g| r.at(supports::grid_index(dims, g as usize)))
                    .collect(),
            )
        }
        _ => None,
    };
    let (metrics, nearest) = match ruled {
        Some(metrics) => {
            let one = SampleSettings {
                knn: 1,
                ..*settings
            };
            let (_, nearest) = knn_supports(ex, &owned.positions, &first_tree, &one);
            (metrics, nearest)
        }
        None => knn_supports(ex, &owned.positions, &first_tree, settings),
    };
    ex.agree(if kind != "PolyData" || count >= 2 {
        Ok(())
    } else {
        Err(format!(
            "{path}: {count} distinct point(s): scattered data needs at least 2"
        ))
    })?;
    let spacing = if count < 2 {
        1.0
    } else {
        select(ex, &nearest, &[count / 2])[0]
    };
    let radii: Vec<f64> = metrics.iter().map(supports::mean_radius).collect();
    let last = count.saturating_sub(1);
    let quantiles: Vec<u64> = (0..=64u64).map(|q| q * last / 64).collect();
    let radii = select(ex, &radii, &quantiles);
    let lambda = metrics
        .iter()
        .map(supports::largest_eigenvalue_bound)
        .fold(0.0, f64::max);
    let thinnest = 1.0 / all_max(ex, &[lambda])[0].sqrt();

    let provenance = Provenance {
        kind: match kind {
            "UnstructuredGrid" => "unstructured mesh",
            "StructuredGrid" => "curvilinear grid",
            "RectilinearGrid" => "rectilinear grid",
            _ => "scattered points",
        },
        array: whole.array.0,
        location: whole.array.1,
        merged,
        inverted_cells: whole.inverted,
        support_kind: match (diagonal, anisotropic) {
            (true, _) => "diagonal",
            (false, true) if edges => "anisotropic-edges",
            (false, true) if rings => "anisotropic-one-ring",
            (false, true) => "anisotropic",
            (false, false) => "isotropic",
        },
    };
    let mut set = SampleSet {
        positions: Positions::Scattered(owned.positions),
        values: owned.values.into(),
        supports: Supports::PerSample(metrics),
        domain: Domain::Box {
            lo: [0.0; 3],
            hi: [0.0; 3],
        },
        spacing,
        provenance,
    };

    // 3. The domain: a mesh's hull, a curvilinear grid's sides, a rectilinear grid's box, the
    // points' supports' box (over the ranks).
    set.domain = match (kind, &coords) {
        ("UnstructuredGrid", _) => Domain::Hull(gathered_hull(ex, &part.faces, &path)?),
        ("StructuredGrid", _) => Domain::Hull(gathered_sides(ex, &part.triangles)),
        (_, Some(c)) => Domain::Box {
            lo: c.each_ref().map(|c| c.first().copied().unwrap_or(0.0)),
            hi: c.each_ref().map(|c| c.last().copied().unwrap_or(0.0)),
        },
        _ => {
            let (lo, hi) = set.support_box();
            Domain::Box {
                lo: all_min(ex, &lo).try_into().unwrap_or(lo),
                hi: all_max(ex, &hi).try_into().unwrap_or(hi),
            }
        }
    };

    // 4. The frame, as the whole field's (Field::from_samples_deferred): the domain's centre;
    // the final tree, cut in the frame as the whole field's is.
    let (lo, hi) = set.domain_box();
    let centre = (DVec3::from(lo) + DVec3::from(hi)) * 0.5;
    let c = centre.to_array();
    set.translate(c);
    let tree = ex.agree(
        KdTree::decompose_points(
            picked_subsample(ex, &set, count as usize),
            set.domain_box(),
            ranks,
        )
        .map_err(|e| e.to_string()),
    )?;
    let range = {
        let (l, h) = set.values.iter().fold((f64::MAX, f64::MIN), |(l, h), v| {
            (l.min(f64::from(v)), h.max(f64::from(v)))
        });
        (all_min(ex, &[l])[0], all_max(ex, &[h])[0])
    };
    let (slo, shi) = set.support_box();
    let support_box = (
        DVec3::from_slice(&all_min(ex, &slo)),
        DVec3::from_slice(&all_max(ex, &shi)),
    );

    // Own samples to their owners, ghosts to every box their supports reach.
    let sent = distribute(ex, &set, &owned.index, &tree);
    let split = sent.split(&tree, rank);
    let count = split.count();
    ex.agree(if count.own == 0 {
        Err(format!(
            "rank {rank}'s brick holds no samples; use fewer ranks"
        ))
    } else {
        Ok(())
    })?;
    let brick = split.brick(&set);
    let splat = view.filter(|v| v.settings.method.splat_shading().is_some());
    let volumes = (reconstruction.method == ReconMethod::Gaussian || splat.is_some())
        .then(|| kernel_volumes(ex, &brick, &split, &sent, &set, &tree, reconstruction.sigma));
    let frame = PieceFrame {
        frame_origin: centre,
        range,
        reconstruction,
        octree,
        extent: Some(SupportExtent {
            support_box,
            thinnest,
            radii,
        }),
    };
    // A splatting brick takes, instead of MLS's ghosts, the kernels that add to the sheets its
    // cell owns in the view, which each kernel's owner finds by projecting its own kernels.
    let (brick, count, volumes) = match (splat, volumes) {
        (Some(view), Some(KernelVolumes::PerSample(v))) => {
            let bounds = tree.boxes[rank];
            let piece = Field::piece_deferred(
                brick,
                frame.clone(),
                (DVec3::from(bounds.0), DVec3::from(bounds.1)),
                Some(KernelVolumes::PerSample(v)),
            );
            let reach =
                ex.agree(SplatReach::of_first(&piece, view, count.own).map_err(|e| e.to_string()))?;
            let cells: Vec<Aabb> = tree
                .boxes
                .iter()
                .map(|&b| cell_of(&piece.samples, b))
                .collect();
            let index = split.own_index();
            let volumes: Vec<f64> = (0..count.own)
                .map(|i| piece.kernel_volumes().get(i))
                .collect();
            let (set, v, count) = splat_ghosts(
                ex,
                &piece.samples,
                (count.own, &index, &volumes),
                &reach,
                &cells,
            );
            (set, count, Some(KernelVolumes::PerSample(v)))
        }
        (_, volumes) => (brick, count, volumes),
    };
    Ok(ScatteredBrick {
        samples: brick,
        count,
        frame,
        tree,
        volumes,
        pieces_read: part.pieces,
        rank,
    })
}

/// What the ranks learn of each other's parts.
struct Whole {
    /// Samples in the whole set (before merging), and the first of this rank's.
    total: usize,
    /// A grid's samples along each axis (its points, or its cells for cell data).
    dims: Option<[usize; 3]>,
    offset: usize,
    inverted: usize,
    /// The samples' bounding box.
    bbox: Aabb,
    /// The array read and where it lives.
    array: (String, Location),
}

fn gather_heads<E: Exchange>(ex: &E, part: &Part, summary: &Summary) -> Result<Whole, E::Error> {
    let path = summary.path.display().to_string();
    let (lo, hi) = crate::samples::points_box(&part.positions);
    let head = [
        part.positions.len() as f64,
        part.inverted as f64,
        lo[0],
        lo[1],
        lo[2],
        hi[0],
        hi[1],
        hi[2],
    ];
    let heads = gather_f64(ex, &head);
    let names = ex.all_gather(match &part.array {
        Some((name, location)) => {
            [&[u8::from(*location == Location::Cell)], name.as_bytes()].concat()
        }
        None => Vec::new(),
    });
    let read: Vec<&Vec<u8>> = names.iter().filter(|n| !n.is_empty()).collect();
    let array = ex.agree(match read.first() {
        None => Err(format!("{path}: no rank read a piece")),
        Some(first) if read.iter().any(|n| n != first) => {
            Err(format!("{path}: the ranks' pieces hold different arrays"))
        }
        Some(first) => Ok((
            String::from_utf8_lossy(&first[1..]).into_owned(),
            if first[0] == 1 {
                Location::Cell
            } else {
                Location::Point
            },
        )),
    })?;
    // A grid's samples are its points or cells, each once (pieces share their faces' points).
    let dims = summary.whole.map(|w| {
        let points = [0, 1, 2].map(|a| (w[2 * a + 1] - w[2 * a] + 1) as usize);
        sample_dims(points, array.1 == Location::Cell)
    });
    let total = match dims {
        Some(d) => d.iter().product(),
        None => heads.iter().map(|h| h[0] as usize).sum(),
    };
    Ok(Whole {
        total,
        dims,
        offset: heads[..ex.rank()].iter().map(|h| h[0] as usize).sum(),
        inverted: heads.iter().map(|h| h[1] as usize).sum(),
        bbox: (
            [2, 3, 4].map(|k| heads.iter().map(|h| h[k]).fold(f64::INFINITY, f64::min)),
            [5, 6, 7].map(|k| heads.iter().map(|h| h[k]).fold(f64::NEG_INFINITY, f64::max)),
        ),
        array,
    })
}

/// The subsample the trees are cut from, on every rank: the samples of `part` whose index in
/// the whole set of `total` is a multiple of the stride, exact copies once (the whole set
/// merges them before it is subsampled; grid pieces share their faces' samples).
fn subsample<E: Exchange>(ex: &E, part: &Part, total: usize) -> Vec<[f64; 3]> {
    let stride = subsample_stride(total);
    let picked: Vec<[f64; 3]> = (0..part.positions.len())
        .filter(|&i| (part.index[i] as usize).is_multiple_of(stride))
        .map(|i| part.positions[i])
        .collect();
    let mut sub: Vec<[f64; 3]> = ex
        .all_gather(pod_bytes(&picked))
        .iter()
        .flat_map(|b| pods::<[f64; 3]>(b))
        .collect();
    sub.sort_unstable_by_key(|p| p.map(f64::to_bits));
    sub.dedup_by_key(|p| p.map(f64::to_bits));
    sub
}

/// The subsample the final tree is cut from, on every rank: the samples each rank owns (the
/// whole merged set, once) that [`super::kd::picked`] takes from a set of `total`, as
/// [`KdTree::decompose`] takes them from the whole field.
fn picked_subsample<E: Exchange>(ex: &E, set: &SampleSet, total: usize) -> Vec<[f64; 3]> {
    let mine = picked_of((0..set.len()).map(|i| set.position(i)), total);
    ex.all_gather(pod_bytes(&mine))
        .iter()
        .flat_map(|b| pods::<[f64; 3]>(b))
        .collect()
}

/// A mesh's one-ring supports of the samples `owned` (on the ranks of `tree`), as
/// [`supports::anisotropic_neighbourhoods`] gives the whole mesh: each rank sends the one-ring
/// of every point of its cells, by the points' indices in the whole set, to the rank that owns
/// the point; there the rings of a point's copies join, each neighbour stands for the sample it
/// merged into, and the neighbours are summed in the whole set's order, as the whole mesh sums
/// them. Copies merge on the rank that owns their position, so a rank resolves its own points
/// and neighbours itself and asks the owner of a neighbour across a kd plane only.
fn ring_supports<E: Exchange>(
    ex: &E,
    part: &Part,
    owned: &Owned,
    tree: &KdTree,
    support: f64,
) -> Vec<Metric> {
    let (rank, ranks) = (ex.rank(), ex.size());
    // Each of this rank's samples by its index in the whole set, and each merged copy's index.
    let mut at: std::collections::HashMap<u64, usize> = owned
        .index
        .iter()
        .enumerate()
        .map(|(j, &g)| (g as u64, j))
        .collect();
    at.extend(owned.copies.iter().map(|&(raw, j)| (raw as u64, j)));
    // The sample a point of index g merged into (its index and position), where it is here.
    let resolve = |g: f64| {
        at.get(&(g as u64))
            .map(|&j| (owned.index[j], owned.positions[j]))
    };
    // (the point's index, a neighbour's index and position) to the point's owner.
    let out = route(
        part.positions.len(),
        ranks,
        |i, v| {
            for &b in part.rings.get(i).into_iter().flatten() {
                let q = part.positions[b as usize];
                v.extend([part.index[i], part.index[b as usize], q[0], q[1], q[2]]);
            }
        },
        |i, send| send(tree.owner(part.positions[i])),
    );
    let got: Vec<Vec<[f64; 5]>> = ex
        .all_to_all(out)
        .iter()
        .map(|b| pods::<[f64; 5]>(b))
        .collect();
    // Neighbours another rank owns: asked of it by index.
    let mut asks: Vec<Vec<f64>> = vec![Vec::new(); ranks];
    for r in got.iter().flatten() {
        let owner = tree.owner([r[2], r[3], r[4]]);
        if owner != rank {
            asks[owner].push(r[1]);
        }
    }
    for a in &mut asks {
        a.sort_by(f64::total_cmp);
        a.dedup();
    }
    let answers: Vec<Vec<u8>> = ex
        .all_to_all(asks.iter().map(|a| pod_bytes(a)).collect())
        .iter()
        .map(|asked| {
            let found: Vec<[f64; 5]> = pods::<f64>(asked)
                .iter()
                .filter_map(|&g| resolve(g).map(|(k, p)| [g, k, p[0], p[1], p[2]]))
                .collect();
            pod_bytes(&found)
        })
        .collect();
    let remote: std::collections::HashMap<u64, (f64, [f64; 3])> = ex
        .all_to_all(answers)
        .iter()
        .flat_map(|b| pods::<[f64; 5]>(b))
        .map(|r| (r[0] as u64, (r[1], [r[2], r[3], r[4]])))
        .collect();
    let mut rings: Vec<Vec<(f64, [f64; 3])>> = vec![Vec::new(); owned.positions.len()];
    for r in got.iter().flatten() {
        let Some(&j) = at.get(&(r[0] as u64)) else {
            continue;
        };
        let b = resolve(r[1])
            .or_else(|| remote.get(&(r[1] as u64)).copied())
            .unwrap_or((r[1], [r[2], r[3], r[4]]));
        if b.0 != owned.index[j] {
            rings[j].push(b);
        }
    }
    rings
        .iter_mut()
        .zip(&owned.positions)
        .map(|(ring, &p)| {
            ring.sort_by(|x, y| x.0.total_cmp(&y.0));
            ring.dedup_by(|x, y| x.0 == y.0);
            supports::anisotropic_neighbourhood(p, ring.iter().map(|x| x.1), support)
        })
        .collect()
}

/// A curvilinear grid's edge supports of the samples `owned` (whole-grid indices of a grid of
/// `dims` samples), as [`supports::structured`] gives the whole grid: each sample's
/// index-direction neighbours that another rank owns (across a kd plane) are asked of every
/// rank and sent back by their owner.
fn edge_supports<E: Exchange>(
    ex: &E,
    owned: &Owned,
    dims: [usize; 3],
    support: f64,
) -> Result<Vec<Metric>, String> {
    let linear = |q: [usize; 3]| (q[0] + dims[0] * (q[1] + dims[1] * q[2])) as u64;
    let mut at: std::collections::HashMap<u64, [f64; 3]> = owned
        .index
        .iter()
        .zip(&owned.positions)
        .map(|(&g, &p)| (g as u64, p))
        .collect();
    let mut missing: Vec<u64> = owned
        .index
        .iter()
        .flat_map(|&g| supports::edge_neighbours(supports::grid_index(dims, g as usize), dims))
        .map(linear)
        .filter(|g| !at.contains_key(g))
        .collect();
    missing.sort_unstable();
    missing.dedup();
    // Every rank sees every rank's questions and answers those about samples it owns.
    let answers: Vec<Vec<u8>> = ex
        .all_gather(pod_bytes(&missing))
        .iter()
        .map(|asked| {
            let found: Vec<[f64; 4]> = pods::<u64>(asked)
                .iter()
                .filter_map(|g| at.get(g).map(|p| [*g as f64, p[0], p[1], p[2]]))
                .collect();
            pod_bytes(&found)
        })
        .collect();
    for got in ex.all_to_all(answers) {
        for r in pods::<[f64; 4]>(&got) {
            at.insert(r[0] as u64, [r[1], r[2], r[3]]);
        }
    }
    if let Some(g) = missing.iter().find(|g| !at.contains_key(g)) {
        return Err(format!(
            "grid sample {g} is on no rank: the pieces leave a hole"
        ));
    }
    Ok(owned
        .index
        .iter()
        .zip(&owned.positions)
        .map(|(&g, &here)| {
            let idx = supports::grid_index(dims, g as usize);
            // Every neighbour is known (checked above); a missing one would count as no edge.
            supports::structured_at(idx, dims, support, |q| {
                at.get(&linear(q)).copied().unwrap_or(here)
            })
        })
        .collect())
}

/// A rectilinear grid's coordinates along each axis, on every rank (its pieces' runs joined).
fn grid_coords<E: Exchange>(ex: &E, part: &Part, kind: &str) -> Option<[Vec<f64>; 3]> {
    if kind != "RectilinearGrid" {
        return None;
    }
    Some([0, 1, 2].map(|a| {
        let mine: Vec<f64> = part.coords[a]
            .iter()
            .flat_map(|&(i, c)| [i as f64, c])
            .collect();
        let mut all: Vec<(usize, f64)> = gather_f64(ex, &mine)
            .iter()
            .flat_map(|v| {
                v.chunks_exact(2)
                    .map(|p| (p[0] as usize, p[1]))
                    .collect::<Vec<_>>()
            })
            .collect();
        all.sort_by_key(|p| p.0);
        all.dedup_by_key(|p| p.0);
        all.into_iter().map(|p| p.1).collect()
    }))
}

/// A curvilinear grid's hull from its sides' triangles in the ranks' shares, facing out (a
/// left-handed index frame turns them all inwards: [`crate::samples::mesh::structured_hull`]).
fn gathered_sides<E: Exchange>(ex: &E, mine: &[Triangle]) -> Hull {
    let flat: Vec<f64> = mine.iter().flatten().flatten().copied().collect();
    let mut triangles: Vec<Triangle> = gather_f64(ex, &flat)
        .iter()
        .flat_map(|v| {
            v.chunks_exact(9)
                .map(|t| [[t[0], t[1], t[2]], [t[3], t[4], t[5]], [t[6], t[7], t[8]]])
                .collect::<Vec<_>>()
        })
        .collect();
    if signed_volume(&triangles) < 0.0 {
        turn(&mut triangles);
    }
    hull_of_triangles(triangles)
}

/// The samples a rank holds after the first partition, merged, with their indices in the
/// whole set.
struct Owned {
    positions: Vec<[f64; 3]>,
    values: Vec<f32>,
    index: Vec<f64>,
    merged: usize,
    /// Samples merged into another (meshes and points): their index in the whole set, and the
    /// sample's they merged into, in `index`.
    copies: Vec<(f64, usize)>,
}

/// Every sample to the rank whose box of `tree` holds it, with its index in the whole set;
/// coincident samples merge there, within the whole set's tolerance (its box `bbox`), or, on
/// a grid, the samples its pieces share are one (the later piece's, as the whole grid reads
/// them).
fn partition<E: Exchange>(ex: &E, part: &Part, tree: &KdTree, bbox: Aabb, grid: bool) -> Owned {
    let out = route(
        part.positions.len(),
        ex.size(),
        |i, v| {
            v.extend(part.positions[i]);
            v.extend([f64::from(part.values[i]), part.index[i]]);
        },
        |i, send| send(tree.owner(part.positions[i])),
    );
    let got: Vec<f64> = ex
        .all_to_all(out)
        .iter()
        .flat_map(|b| pods::<f64>(b))
        .collect();
    let mut records: Vec<&[f64]> = got.chunks_exact(5).collect();
    if grid {
        // Stable: of the copies of one sample, the last piece's comes last.
        records.sort_by(|a, b| a[4].total_cmp(&b[4]));
        let mut kept: Vec<&[f64]> = Vec::with_capacity(records.len());
        for r in records {
            match kept.last_mut() {
                Some(last) if last[4] == r[4] => *last = r,
                _ => kept.push(r),
            }
        }
        return Owned {
            positions: kept.iter().map(|r| [r[0], r[1], r[2]]).collect(),
            values: kept.iter().map(|r| r[3] as f32).collect(),
            index: kept.iter().map(|r| r[4]).collect(),
            merged: 0,
            copies: Vec::new(),
        };
    }
    let merged = merge_duplicates_within(
        records.iter().map(|r| [r[0], r[1], r[2]]).collect(),
        records.iter().map(|r| r[3] as f32).collect(),
        duplicate_tolerance(bbox),
    );
    // A merged sample's index is its first copy's, as where the whole set merges (the records
    // arrive in index order, and a merge keeps the first copy's position).
    let mut index = vec![f64::INFINITY; merged.positions.len()];
    for (r, &j) in records.iter().zip(&merged.remap) {
        index[j as usize] = index[j as usize].min(r[4]);
    }
    let copies = records
        .iter()
        .zip(&merged.remap)
        .filter(|(r, j)| r[4] != index[**j as usize])
        .map(|(r, &j)| (r[4], j as usize))
        .collect();
    Owned {
        positions: merged.positions,
        values: merged.values,
        index,
        merged: merged.merged,
        copies,
    }
}

/// The supports of a rank's samples `own` (partitioned by `tree`) from their k nearest
/// neighbours among all ranks' (module docs, step 2), and each one's nearest distance.
fn knn_supports<E: Exchange>(
    ex: &E,
    own: &[[f64; 3]],
    tree: &KdTree,
    settings: &SampleSettings,
) -> (Vec<Metric>, Vec<f64>) {
    let (rank, ranks, k) = (ex.rank(), ex.size(), settings.knn);
    let local = supports::knn_of_first(own, own.len(), k);
    let reach: Vec<f64> = own
        .iter()
        .zip(local.iter())
        .map(|(p, n)| {
            if n.len() < k {
                return f64::INFINITY;
            }
            let d2 = n
                .iter()
                .map(|&j| {
                    (0..3)
                        .map(|a| (own[j as usize][a] - p[a]).powi(2))
                        .sum::<f64>()
                })
                .fold(0.0, f64::max);
            // A little over: the answering rank's squared distances round differently.
            d2 * (1.0 + 1e-9) + f64::MIN_POSITIVE
        })
        .collect();
    let asks = route(
        own.len(),
        ranks,
        |i, v| v.extend(own[i].iter().copied().chain([reach[i]])),
        |i, send| {
            for s in (0..ranks).filter(|&s| s != rank) {
                if box_distance2(own[i], tree.boxes[s]) <= reach[i] {
                    send(s);
                }
            }
        },
    );
    let answers: Vec<Vec<u8>> = ex
        .all_to_all(asks)
        .iter()
        .map(|b| {
            let balls: Vec<([f64; 3], f64)> = pods::<f64>(b)
                .chunks_exact(4)
                .map(|r| ([r[0], r[1], r[2]], r[3]))
                .collect();
            let near = supports::within_any(own, &balls);
            let points: Vec<[f64; 3]> = near.iter().map(|&j| own[j as usize]).collect();
            pod_bytes(&points)
        })
        .collect();
    let mut around = own.to_vec();
    around.extend(
        ex.all_to_all(answers)
            .iter()
            .flat_map(|b| pods::<[f64; 3]>(b)),
    );
    let neighbours = supports::knn_of_first(&around, own.len(), k);
    let metrics = if settings.anisotropic.unwrap_or(false) {
        supports::anisotropic_neighbourhoods(&around, neighbours.par_iter(), settings.knn_support)
    } else {
        supports::isotropic_neighbourhoods(&around, neighbours.par_iter(), settings.knn_support)
    };
    (metrics, supports::nearest_distances(&around, &neighbours))
}

/// The hull of a mesh whose ranks found `faces` unshared among their own cells.
fn gathered_hull<E: Exchange>(ex: &E, faces: &[Face], path: &str) -> Result<Hull, E::Error> {
    let mine: Vec<f64> = faces
        .iter()
        .flat_map(|f| std::iter::once(f.corners as f64).chain(f.points.iter().flatten().copied()))
        .collect();
    let faces: Vec<Face> = gather_f64(ex, &mine)
        .iter()
        .flat_map(|v| {
            v.chunks_exact(13)
                .map(|r| Face {
                    corners: r[0] as usize,
                    points: [0, 1, 2, 3].map(|c| [r[1 + 3 * c], r[2 + 3 * c], r[3 + 3 * c]]),
                })
                .collect::<Vec<_>>()
        })
        .collect();
    ex.agree(hull_of_faces(faces, path).map_err(|e| e.to_string()))
}
