//! `vmls info FILE`: what a file holds and what vmls would make of it — kind, counts (points,
//! cells by type, boundary faces), bounds, arrays with their ranges, the sample set (where the
//! array is sampled, merged duplicates, inverted cells), support statistics and the octree.

use crate::data::dataset::{Dataset, Geometry};
use crate::field::{Field, RenderError};
use crate::gpu_types::Sample;
use crate::recon::{OctreeSettings, Reconstruction};
use crate::samples::{Domain, SampleSet, SampleSettings, metric_rho2, supports};
use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::Path;

/// Longest name (file or array) the report prints, in characters.
const MAX_NAME_CHARS: usize = 200;

/// A name from a file as the report prints it: escaped and cut, as error lines quote input
/// (a hostile file cannot put terminal escapes or a megabyte line on the screen).
fn shown(name: &str) -> String {
    crate::files::printable(name, MAX_NAME_CHARS)
}

fn v3(p: [f64; 3]) -> String {
    format!("({:.6}, {:.6}, {:.6})", p[0], p[1], p[2])
}

/// The report for one file (a multi-line text). The sample set, its supports and the
/// neighbour structure are built exactly as `render` builds them (the same domain check
/// first, an octree only where the renderer would use one); a file `render` would refuse is
/// still described, with a last line saying why nothing more was built.
pub fn describe(
    path: &Path,
    array: Option<&str>,
    settings: &SampleSettings,
    reconstruction: Reconstruction,
    octree: &OctreeSettings,
) -> Result<String, RenderError> {
    let dataset = crate::data::load_dataset(path)?;
    let mut out = String::new();
    describe_dataset(&mut out, path, &dataset);
    if let Err(e) = dataset.geometry.check_domain(path) {
        let _ = writeln!(out, "render: refused, so nothing more is built: {e}");
        return Ok(out);
    }
    let set = SampleSet::from_dataset(&dataset, path, array, settings).map_err(|e| match e {
        crate::samples::SampleError::Data(d) => RenderError::Data(d),
        other => RenderError::Samples(other),
    })?;
    describe_samples(&mut out, set, settings, reconstruction, octree)?;
    Ok(out)
}

fn describe_dataset(out: &mut String, path: &Path, d: &Dataset) {
    let g = &d.geometry;
    // Writing to a String cannot fail.
    let _ = writeln!(out, "file: {}", shown(&path.display().to_string()));
    let _ = writeln!(out, "kind: {}", g.kind());
    match g {
        Geometry::Image {
            dims,
            origin,
            spacing,
        } => {
            let _ = writeln!(
                out,
                "dimensions: {} × {} × {}, origin {}, spacing {}",
                dims[0],
                dims[1],
                dims[2],
                v3(*origin),
                v3(*spacing)
            );
        }
        Geometry::Rectilinear { coords } => {
            let _ = writeln!(
                out,
                "dimensions: {} × {} × {}",
                coords[0].len(),
                coords[1].len(),
                coords[2].len()
            );
        }
        Geometry::Structured { dims, .. } => {
            let _ = writeln!(out, "dimensions: {} × {} × {}", dims[0], dims[1], dims[2]);
        }
        _ => {}
    }
    let _ = writeln!(out, "points: {}", g.point_count());
    if let Geometry::Unstructured { cells, .. } = g {
        let mut by_type: BTreeMap<&str, usize> = BTreeMap::new();
        for t in &cells.types {
            *by_type.entry(t.name()).or_default() += 1;
        }
        let list: Vec<String> = by_type.iter().map(|(k, v)| format!("{k}: {v}")).collect();
        let _ = writeln!(out, "cells: {} ({})", cells.len(), list.join(", "));
    } else if g.cell_count() > 0 {
        let _ = writeln!(out, "cells: {} (grid cells)", g.cell_count());
    }
    let (lo, hi) = g.bounds();
    let _ = writeln!(out, "bounds: {} .. {}", v3(lo), v3(hi));
    let _ = writeln!(out, "arrays:");
    for a in &d.arrays {
        let (lo, hi) = a.range();
        let _ = writeln!(
            out,
            "  {} ({} data, {} component{}, kept as {}): range [{lo}, {hi}]",
            shown(&a.name),
            a.location.name(),
            a.components,
            if a.components == 1 {
                ""
            } else {
                "s, first used"
            },
            a.values.storage().name()
        );
    }
}

fn quantiles(mut v: Vec<f64>) -> [f64; 3] {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return [0.0; 3];
    }
    [v[0], v[v.len() / 2], v[v.len() - 1]]
}

fn describe_samples(
    out: &mut String,
    set: SampleSet,
    settings: &SampleSettings,
    reconstruction: Reconstruction,
    octree: &OctreeSettings,
) -> Result<(), RenderError> {
    let p = &set.provenance;
    let _ = writeln!(
        out,
        "samples: {} (array '{}' sampled at {}), merged duplicates: {}, inverted cells: {}",
        set.len(),
        shown(&p.array),
        match p.location {
            crate::data::dataset::Location::Point => "points",
            crate::data::dataset::Location::Cell => "cell centroids",
        },
        p.merged,
        p.inverted_cells
    );
    if let Domain::Hull(h) = &set.domain {
        let _ = writeln!(out, "boundary: {} triangles", h.triangles.len());
    }
    let rule = match p.support_kind {
        "uniform" => format!("h = {} × spacing", settings.support),
        "diagonal" => format!(
            "h = {} × the larger neighbouring gap per axis",
            settings.support
        ),
        "anisotropic-edges" => format!(
            "ellipsoids spanned by {} × the local index-direction edges",
            settings.support
        ),
        "anisotropic-one-ring" => format!(
            "ellipsoids from each point's one-ring covariance, scaled to {} × its farthest point",
            settings.knn_support
        ),
        "anisotropic" => format!(
            "ellipsoids from the neighbourhood's covariance, scaled to {} × the {}-th neighbour",
            settings.knn_support, settings.knn
        ),
        _ => format!(
            "h = {} × distance to the {}-th nearest sample",
            settings.knn_support, settings.knn
        ),
    };
    let _ = writeln!(out, "supports: {} ({rule})", p.support_kind);
    let n = set.len();
    let stride = (n / 20_000).max(1);
    let picks: Vec<usize> = (0..n).step_by(stride).collect();
    let radius = quantiles(
        picks
            .iter()
            .map(|&i| supports::mean_radius(&set.metric(i)))
            .collect(),
    );
    let aspect = quantiles(
        picks
            .iter()
            .map(|&i| {
                let (l, _) = supports::eigen_symmetric(&set.metric(i));
                let hi = l.iter().copied().fold(0.0, f64::max);
                let lo = l.iter().copied().fold(f64::INFINITY, f64::min);
                (hi / lo).sqrt()
            })
            .collect(),
    );
    let _ = writeln!(
        out,
        "  radius (geometric mean of the axes): min {:.4e}, median {:.4e}, max {:.4e}",
        radius[0], radius[1], radius[2]
    );
    let _ = writeln!(
        out,
        "  aspect ratio: min {:.2}, median {:.2}, max {:.2}",
        aspect[0], aspect[1], aspect[2]
    );
    let field = Field::from_samples(set, reconstruction, octree, |_| {})?;
    let set = &field.samples;
    let neighbours = field.neighbours()?;
    let weighted = quantiles(
        picks
            .iter()
            .map(|&i| {
                let x = set.position(i);
                let mut count = 0.0;
                neighbours.for_each(x, &mut |_, q, _, m| {
                    if metric_rho2(m, [q[0] - x[0], q[1] - x[1], q[2] - x[2]]) < 1.0 {
                        count += 1.0;
                    }
                });
                count
            })
            .collect(),
    );
    let _ = writeln!(
        out,
        "  samples with weight at a sample: min {}, median {}, max {}",
        weighted[0], weighted[1], weighted[2]
    );
    match field.octree()? {
        Some(tree) => {
            let s = tree.stats(std::mem::size_of::<Sample>() as u64);
            let _ = writeln!(
                out,
                "octree: {} nodes ({} leaves), {} references ({:.2} per sample), depth {}, {:.1} MiB, built in {:.0} ms",
                s.nodes,
                s.leaves,
                s.references,
                s.redundancy,
                s.depth,
                s.bytes as f64 / (1 << 20) as f64,
                s.build_ms
            );
        }
        None => {
            let _ = writeln!(
                out,
                "neighbours: implicit regular grid (no octree needed; octree with reconstruction.neighbours = \"octree\")"
            );
        }
    }
    Ok(())
}
