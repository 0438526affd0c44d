//! The sample set: what every input becomes before either renderer reads it (DESIGN §1).
//!
//! A [`SampleSet`] holds samples `(x_i, f_i)`, a support per sample and a domain:
//! - positions are implicit for a regular grid ([`Positions::Grid`], which keeps the grid
//!   kernel's fast path) and explicit otherwise;
//! - supports ([`Supports`]) are one diagonal radius for a regular grid, or per sample an
//!   ellipsoid given by its metric `M_i = H_iᵀH_i` (`w_i(x) = θ(√((x − x_i)ᵀ M_i (x − x_i)))`),
//!   isotropic when `M_i = h_i⁻² I`; see [`supports`] for how they are derived;
//! - the domain is where rays integrate: the grid's box, the boundary of a mesh, or (scattered
//!   points) the bounding box of the supports, where the field is undefined wherever no sample
//!   has weight (rays skip those stretches; nothing there is integrated, never NaN).
//!
//! Point data are sampled where they live; cell data at cell centroids (MLS needs no data at
//! vertices). Coincident samples would make the MLS system singular, so samples closer than
//! [`DUPLICATE_TOLERANCE`] × the bounding-box diagonal are merged, their values averaged, and
//! the count reported in [`Provenance::merged`].
//!
//! The layer reads `data::Dataset` and never the scene: [`SampleSettings`] is its own
//! configuration type.

pub mod bvh;
pub mod mesh;
pub mod supports;

use crate::data::DataError;
use crate::data::dataset::{Dataset, Geometry, Location, grid_point};
use rayon::prelude::*;
use std::path::Path;

/// Default support factor of kNN-derived supports.
pub const KNN_SUPPORT: f64 = 1.5;

/// Relative distance (of the bounding-box diagonal) under which two samples are one.
pub const DUPLICATE_TOLERANCE: f64 = 1e-9;

/// Errors of the sample-set layer: the dataset is readable but not a valid sample set.
#[derive(Debug, thiserror::Error)]
pub enum SampleError {
    #[error(transparent)]
    Data(#[from] DataError),
    #[error("{source_name}: {message}")]
    Invalid {
        source_name: String,
        message: String,
    },
    #[error("{key} = {value} is out of range ({expected})")]
    Setting {
        key: &'static str,
        value: String,
        expected: &'static str,
    },
}

/// How supports are derived (scene keys `[reconstruction]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleSettings {
    /// Grids (regular, rectilinear, curvilinear with anisotropic supports): h = support ×
    /// spacing.
    pub support: f64,
    /// Scattered samples and meshes: h_i = knn_support × the distance to the `knn`-th nearest
    /// neighbour (or the anisotropic equivalent). The scene's `reconstruction.support` sets
    /// both; left out, this one defaults to [`KNN_SUPPORT`] (about 27 samples in a support in
    /// a uniform cloud, against ~100 with the grid default 2.4).
    pub knn_support: f64,
    /// Neighbour count of the support radius.
    pub knn: usize,
    /// Ellipsoidal supports: `None` = the data kind's default (diagonal for rectilinear grids,
    /// isotropic otherwise).
    pub anisotropic: Option<bool>,
}

impl Default for SampleSettings {
    fn default() -> Self {
        Self {
            support: 2.4,
            knn_support: KNN_SUPPORT,
            knn: 8,
            anisotropic: None,
        }
    }
}

/// Where the samples are.
#[derive(Debug, Clone, PartialEq)]
pub enum Positions {
    /// A regular grid, x fastest: sample (i, j, k) is at `origin + (i, j, k) ⊙ spacing`.
    Grid {
        dims: [usize; 3],
        origin: [f64; 3],
        spacing: [f64; 3],
    },
    /// One position per sample.
    Scattered(Vec<[f64; 3]>),
}

/// A symmetric 3×3 metric `(xx, yy, zz, xy, xz, yz)`: ρ² = yᵀMy.
pub type Metric = [f64; 6];

/// ρ² = yᵀMy for a metric.
pub fn metric_rho2(m: &Metric, y: [f64; 3]) -> f64 {
    m[0] * y[0] * y[0]
        + m[1] * y[1] * y[1]
        + m[2] * y[2] * y[2]
        + 2.0 * (m[3] * y[0] * y[1] + m[4] * y[0] * y[2] + m[5] * y[1] * y[2])
}

/// M·y.
pub fn metric_apply(m: &Metric, y: [f64; 3]) -> [f64; 3] {
    [
        m[0] * y[0] + m[3] * y[1] + m[4] * y[2],
        m[3] * y[0] + m[1] * y[1] + m[5] * y[2],
        m[4] * y[0] + m[5] * y[1] + m[2] * y[2],
    ]
}

/// Supports of the samples.
#[derive(Debug, Clone, PartialEq)]
pub enum Supports {
    /// Every sample: radius per axis (a diagonal H, regular grids).
    Uniform([f64; 3]),
    /// One metric per sample.
    PerSample(Vec<Metric>),
}

/// Where rays integrate.
#[derive(Debug, Clone, PartialEq)]
pub enum Domain {
    /// An axis-aligned box (regular and rectilinear grids; scattered points: the supports' box).
    Box { lo: [f64; 3], hi: [f64; 3] },
    /// The boundary of a mesh or curvilinear grid: triangles over `vertices`.
    Hull(mesh::Hull),
}

/// Where the samples came from, for `--stats` and `vmls info`.
#[derive(Debug, Clone, PartialEq)]
pub struct Provenance {
    /// Data kind (`Geometry::kind`).
    pub kind: &'static str,
    /// The array sampled and where its values live.
    pub array: String,
    pub location: Location,
    /// Samples merged into others because they coincided.
    pub merged: usize,
    /// Cells whose orientation is inverted (accepted: the hull does not use orientation).
    pub inverted_cells: usize,
    /// "uniform" (regular grid), "diagonal" (rectilinear spacings), "anisotropic-edges"
    /// (curvilinear index-direction edges), "anisotropic-one-ring" (mesh point neighbourhoods),
    /// "isotropic" or "anisotropic" (from the k nearest neighbours).
    pub support_kind: &'static str,
}

/// Samples, supports and domain.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleSet {
    pub positions: Positions,
    pub values: crate::data::Values,
    pub supports: Supports,
    pub domain: Domain,
    /// Typical distance between samples, the unit of `render.step`: a grid's smallest spacing,
    /// else the median distance to the nearest other sample.
    pub spacing: f64,
    pub provenance: Provenance,
}

impl SampleSet {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// True when there is no sample.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// Position of sample i.
    pub fn position(&self, i: usize) -> [f64; 3] {
        match &self.positions {
            Positions::Grid {
                dims,
                origin,
                spacing,
            } => grid_point(*dims, *origin, *spacing, i),
            Positions::Scattered(p) => p[i],
        }
    }

    /// Metric of sample i.
    pub fn metric(&self, i: usize) -> Metric {
        match &self.supports {
            Supports::Uniform(h) => supports::diagonal(*h),
            Supports::PerSample(m) => m[i],
        }
    }

    /// Whether any support is a rotated ellipsoid (a metric with off-diagonal terms).
    pub fn has_full_metric(&self) -> bool {
        match &self.supports {
            Supports::Uniform(_) => false,
            Supports::PerSample(m) => m.iter().any(supports::is_rotated),
        }
    }

    /// Whether every support is a ball (`M = I / h²`): packed octree records carry one
    /// metric term (`crate::field::records`).
    pub fn is_isotropic(&self) -> bool {
        let ball = |m: &Metric| !supports::is_rotated(m) && m[0] == m[1] && m[1] == m[2];
        match &self.supports {
            Supports::Uniform(h) => ball(&supports::diagonal(*h)),
            Supports::PerSample(m) => m.iter().all(ball),
        }
    }

    /// A lower bound on the shortest half axis of any sample's support ellipsoid, 1/√λ_max(M)
    /// over all samples: exact for diagonal metrics; for rotated ones λ_max is bounded by the
    /// largest absolute row sum (Gershgorin), which can only shorten the bound.
    pub fn thinnest_support(&self) -> f64 {
        let lambda = match &self.supports {
            Supports::Uniform(h) => supports::largest_eigenvalue_bound(&supports::diagonal(*h)),
            Supports::PerSample(m) => m
                .iter()
                .map(supports::largest_eigenvalue_bound)
                .fold(0.0, f64::max),
        };
        1.0 / lambda.sqrt()
    }

    /// The support radii (geometric means of the half axes) at the quantiles 0, 1/n, …, 1 of
    /// the samples, n = `parts` (one value for a uniform support).
    pub fn radius_quantiles(&self, parts: usize) -> Vec<f64> {
        match &self.supports {
            Supports::Uniform(h) => vec![(h[0] * h[1] * h[2]).cbrt()],
            Supports::PerSample(m) => {
                let mut r: Vec<f64> = m.iter().map(supports::mean_radius).collect();
                r.sort_by(f64::total_cmp);
                let last = r.len().saturating_sub(1);
                (0..=parts)
                    .filter_map(|q| r.get(q * last / parts.max(1)).copied())
                    .collect()
            }
        }
    }

    /// Half extents of sample i's support ellipsoid along the axes (its bounding box).
    pub fn support_extent(&self, i: usize) -> [f64; 3] {
        match &self.supports {
            Supports::Uniform(h) => *h,
            Supports::PerSample(m) => supports::extent(&m[i]),
        }
    }

    /// Bounding box of the domain.
    pub fn domain_box(&self) -> ([f64; 3], [f64; 3]) {
        match &self.domain {
            Domain::Box { lo, hi } => (*lo, *hi),
            Domain::Hull(h) => h.bounds(),
        }
    }

    /// Mean support radius (the geometric mean of the ellipsoid's half axes), the unit of
    /// step lengths for irregular data.
    pub fn mean_radius(&self) -> f64 {
        match &self.supports {
            Supports::Uniform(h) => (h[0] * h[1] * h[2]).cbrt(),
            Supports::PerSample(m) => {
                let n = m.len().max(1) as f64;
                m.iter().map(supports::mean_radius).sum::<f64>() / n
            }
        }
    }

    /// Moves every position by `-by` (into a frame centred near the data).
    pub fn translate(&mut self, by: [f64; 3]) {
        let shift = |p: &mut [f64; 3]| {
            for a in 0..3 {
                p[a] -= by[a];
            }
        };
        match &mut self.positions {
            Positions::Grid { origin, .. } => shift(origin),
            Positions::Scattered(ps) => ps.iter_mut().for_each(shift),
        }
        match &mut self.domain {
            Domain::Box { lo, hi } => {
                shift(lo);
                shift(hi);
            }
            Domain::Hull(h) => h.vertices.iter_mut().for_each(shift),
        }
    }

    /// Builds the sample set of one array of a dataset. `source_name` (the file) names errors.
    pub fn from_dataset(
        dataset: &Dataset,
        path: &Path,
        array: Option<&str>,
        settings: &SampleSettings,
    ) -> Result<Self, SampleError> {
        // Cell indices are used unchecked below: a dataset built by hand must pass the
        // loaders' checks too.
        dataset.validate(path)?;
        Self::build(dataset, path, array, settings)
    }

    fn build(
        dataset: &Dataset,
        path: &Path,
        array: Option<&str>,
        settings: &SampleSettings,
    ) -> Result<Self, SampleError> {
        check_settings(settings)?;
        let source_name = path.display().to_string();
        let data = dataset.array(path, array)?;
        let mut provenance = Provenance {
            kind: dataset.geometry.kind(),
            array: data.name.clone(),
            location: data.location,
            merged: 0,
            inverted_cells: 0,
            support_kind: "isotropic",
        };
        let cell_data = data.location == Location::Cell;
        match &dataset.geometry {
            Geometry::Image {
                dims,
                origin,
                spacing,
            } => {
                // The domain is the grid's box whatever the data's location.
                let lo = *origin;
                let hi = [0, 1, 2].map(|a| origin[a] + (dims[a] - 1) as f64 * spacing[a]);
                // Cell data of an image is an image of the cell centres.
                let (dims, origin) = if cell_data {
                    (
                        dims.map(|n| n.saturating_sub(1).max(1)),
                        [0, 1, 2]
                            .map(|a| origin[a] + if dims[a] > 1 { 0.5 * spacing[a] } else { 0.0 }),
                    )
                } else {
                    (*dims, *origin)
                };
                let h = spacing.map(|s| settings.support * s);
                provenance.support_kind = "uniform";
                Ok(Self {
                    positions: Positions::Grid {
                        dims,
                        origin,
                        spacing: *spacing,
                    },
                    values: data.values.clone(),
                    supports: Supports::Uniform(h),
                    domain: Domain::Box { lo, hi },
                    spacing: spacing.iter().copied().fold(f64::INFINITY, f64::min),
                    provenance,
                })
            }
            Geometry::Rectilinear { coords } => {
                let lo = coords.each_ref().map(|c| c[0]);
                let hi = coords.each_ref().map(|c| c[c.len() - 1]);
                let coords = if cell_data {
                    [0, 1, 2].map(|a| centres(&coords[a]))
                } else {
                    coords.clone()
                };
                let dims = coords.each_ref().map(Vec::len);
                let positions: Vec<[f64; 3]> = (0..dims[0] * dims[1] * dims[2])
                    .map(|i| {
                        let (x, y, z) = (
                            i % dims[0],
                            (i / dims[0]) % dims[1],
                            i / (dims[0] * dims[1]),
                        );
                        [coords[0][x], coords[1][y], coords[2][z]]
                    })
                    .collect();
                let knn = if settings.anisotropic.unwrap_or(true) {
                    provenance.support_kind = "diagonal";
                    supports::SupportsAndSpacing::measured(
                        supports::rectilinear(&coords, settings.support),
                        &positions,
                    )
                } else {
                    supports::knn_supports(&positions, settings.knn_support, settings.knn, false)
                };
                Ok(Self {
                    positions: Positions::Scattered(positions),
                    values: data.values.as_f32().into_owned().into(),
                    supports: Supports::PerSample(knn.metrics),
                    domain: Domain::Box { lo, hi },
                    spacing: knn.spacing,
                    provenance,
                })
            }
            Geometry::Structured { dims, points } => {
                // The grid's own boundary, also for cell data sampled at the centroids.
                let hull = mesh::structured_hull(*dims, points, &source_name)?;
                let (dims, points) = if cell_data {
                    mesh::structured_centroids(*dims, points)
                } else {
                    (*dims, points.clone())
                };
                let knn = if settings.anisotropic.unwrap_or(false) {
                    provenance.support_kind = "anisotropic-edges";
                    supports::SupportsAndSpacing::measured(
                        supports::structured(dims, &points, settings.support),
                        &points,
                    )
                } else {
                    supports::knn_supports(&points, settings.knn_support, settings.knn, false)
                };
                Ok(Self {
                    positions: Positions::Scattered(points),
                    values: data.values.as_f32().into_owned().into(),
                    supports: Supports::PerSample(knn.metrics),
                    domain: hull,
                    spacing: knn.spacing,
                    provenance,
                })
            }
            Geometry::Unstructured { points, cells } => {
                let checked = mesh::check_cells(points, cells, &source_name)?;
                provenance.inverted_cells = checked.inverted;
                let (positions, values) = if cell_data {
                    (checked.centroids.clone(), data.values.as_f32().into_owned())
                } else {
                    (points.clone(), data.values.as_f32().into_owned())
                };
                let merged = merge_duplicates(positions, values);
                provenance.merged = merged.merged;
                let hull = mesh::unstructured_hull(points, cells, &source_name)?;
                let knn = if settings.anisotropic.unwrap_or(false) && !cell_data {
                    provenance.support_kind = "anisotropic-one-ring";
                    let rings = supports::one_rings(cells, &merged.remap, merged.positions.len());
                    supports::SupportsAndSpacing::measured(
                        supports::anisotropic_neighbourhoods(
                            &merged.positions,
                            rings.par_iter().map(Vec::as_slice),
                            settings.knn_support,
                        ),
                        &merged.positions,
                    )
                } else {
                    derive_scattered(&merged.positions, settings, &mut provenance)
                };
                Ok(Self {
                    positions: Positions::Scattered(merged.positions),
                    values: merged.values.into(),
                    supports: Supports::PerSample(knn.metrics),
                    domain: Domain::Hull(hull),
                    spacing: knn.spacing,
                    provenance,
                })
            }
            Geometry::Points { points } => {
                let merged = merge_duplicates(points.clone(), data.values.as_f32().into_owned());
                provenance.merged = merged.merged;
                if merged.positions.len() < 2 {
                    return Err(SampleError::Invalid {
                        source_name,
                        message: format!(
                            "{} distinct point(s): scattered data needs at least 2",
                            merged.positions.len()
                        ),
                    });
                }
                let knn = derive_scattered(&merged.positions, settings, &mut provenance);
                let mut set = Self {
                    positions: Positions::Scattered(merged.positions),
                    values: merged.values.into(),
                    supports: Supports::PerSample(knn.metrics),
                    domain: Domain::Box {
                        lo: [0.0; 3],
                        hi: [0.0; 3],
                    },
                    spacing: knn.spacing,
                    provenance,
                };
                let (lo, hi) = set.support_box();
                set.domain = Domain::Box { lo, hi };
                Ok(set)
            }
        }
    }

    /// Bounding box of every sample's support.
    pub fn support_box(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for i in 0..self.len() {
            let (p, e) = (self.position(i), self.support_extent(i));
            for a in 0..3 {
                lo[a] = lo[a].min(p[a] - e[a]);
                hi[a] = hi[a].max(p[a] + e[a]);
            }
        }
        (lo, hi)
    }
}

/// Rejects sample settings out of range, naming the key.
pub fn check_settings(s: &SampleSettings) -> Result<(), SampleError> {
    for v in [s.support, s.knn_support] {
        if !(v > 0.0 && v.is_finite()) {
            return Err(SampleError::Setting {
                key: "reconstruction.support",
                value: v.to_string(),
                expected: "a positive number",
            });
        }
    }
    if !(1..=64).contains(&s.knn) {
        return Err(SampleError::Setting {
            key: "reconstruction.knn",
            value: s.knn.to_string(),
            expected: "1 to 64",
        });
    }
    Ok(())
}

fn derive_scattered(
    positions: &[[f64; 3]],
    settings: &SampleSettings,
    provenance: &mut Provenance,
) -> supports::SupportsAndSpacing {
    let anisotropic = settings.anisotropic.unwrap_or(false);
    if anisotropic {
        provenance.support_kind = "anisotropic";
    }
    supports::knn_supports(positions, settings.knn_support, settings.knn, anisotropic)
}

/// Midpoints of consecutive coordinates (a single coordinate stays).
pub fn centres(c: &[f64]) -> Vec<f64> {
    if c.len() < 2 {
        return c.to_vec();
    }
    c.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect()
}

/// Samples after merging coincident ones.
pub struct Merged {
    pub positions: Vec<[f64; 3]>,
    pub values: Vec<f32>,
    /// How many samples were folded into others.
    pub merged: usize,
    /// Index of each input sample in the output.
    pub remap: Vec<u32>,
}

/// Merges samples closer than [`DUPLICATE_TOLERANCE`] × the bounding-box diagonal (values
/// averaged). Sorting by a quantised key finds exact and near duplicates in O(n log n); two
/// points that straddle a quantisation cell boundary are found by checking neighbours in sort
/// order within the tolerance.
pub fn merge_duplicates(positions: Vec<[f64; 3]>, values: Vec<f32>) -> Merged {
    let tol = duplicate_tolerance(points_box(&positions));
    merge_duplicates_within(positions, values, tol)
}

/// The bounding box of `points`.
pub fn points_box(points: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (lo, hi)
}

/// The distance within which samples of a set with bounding box `(lo, hi)` merge.
pub fn duplicate_tolerance((lo, hi): ([f64; 3], [f64; 3])) -> f64 {
    let diag = (0..3).map(|a| (hi[a] - lo[a]).powi(2)).sum::<f64>().sqrt();
    DUPLICATE_TOLERANCE * diag.max(f64::MIN_POSITIVE)
}

/// [`merge_duplicates`] with the tolerance given: a part of a sample set merges with the
/// whole set's.
pub fn merge_duplicates_within(positions: Vec<[f64; 3]>, values: Vec<f32>, tol: f64) -> Merged {
    let n = positions.len();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| positions[a][0].total_cmp(&positions[b][0]));
    let mut rep: Vec<usize> = (0..n).collect();
    let mut merged = 0;
    for (k, &i) in order.iter().enumerate() {
        if rep[i] != i {
            continue;
        }
        for &j in &order[k + 1..] {
            if positions[j][0] - positions[i][0] > tol {
                break;
            }
            if rep[j] == j
                && (0..3).all(|a| (positions[j][a] - positions[i][a]).abs() <= tol)
                && j != i
            {
                rep[j] = i;
                merged += 1;
            }
        }
    }
    if merged == 0 {
        return Merged {
            positions,
            values,
            merged,
            remap: (0..n as u32).collect(),
        };
    }
    let mut sum = vec![0.0f64; n];
    let mut count = vec![0u32; n];
    for i in 0..n {
        sum[rep[i]] += f64::from(values[i]);
        count[rep[i]] += 1;
    }
    let mut out_p = Vec::with_capacity(n - merged);
    let mut out_v = Vec::with_capacity(n - merged);
    let mut remap = vec![0u32; n];
    for i in 0..n {
        if rep[i] == i {
            remap[i] = out_p.len() as u32;
            out_p.push(positions[i]);
            out_v.push((sum[i] / f64::from(count[i])) as f32);
        }
    }
    for i in 0..n {
        remap[i] = remap[rep[i]];
    }
    Merged {
        positions: out_p,
        values: out_v,
        merged,
        remap,
    }
}
