//! Reconstruction: the MLS method ([MLS] §3) as an f64 CPU reference, and the neighbour
//! structures it reads — implicit grid neighbours and the redundant octree ([OCT], [MLS] §5.2).
//!
//! The GPU twins are `glsl/field/mls.glsl` and `glsl/field/neighbours.glsl`.

pub mod gaussian;
pub mod mls;
pub mod octree;
pub mod octree_codes;
pub mod pages;
pub mod resample;
pub mod support_index;

pub use mls::{Basis, GradientMode, MlsSettings, MlsValue, Neighbours, Weight, mls_evaluate};
pub use octree::{Octree, OctreeSettings, OctreeStats, SamplePoint};

use mls::Visit;

/// How neighbours are found (scene key `reconstruction.neighbours`). Only a regular grid has
/// implicit neighbours; every other sample set always uses the octree.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NeighbourMode {
    Grid,
    Octree,
}

/// Which field is reconstructed from the samples (scene key `reconstruction.method`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReconMethod {
    /// Moving least squares ([MLS] §3).
    Mls,
    /// The Gaussian sum that splatting integrates ([`gaussian`]).
    Gaussian,
    /// The analytic function a generated volume samples, with its analytic gradient (ground
    /// truth; the scene accepts it only for `volume.generator`).
    Exact,
}

/// Reconstruction settings (scene section `[reconstruction]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reconstruction {
    pub method: ReconMethod,
    /// Gaussian kernels: σ as a fraction of the support radius ([`gaussian`]).
    pub sigma: f64,
    pub basis: Basis,
    pub weight: Weight,
    pub gradient: GradientMode,
    /// h = support × sample spacing, per axis.
    pub support: f64,
    pub neighbours: NeighbourMode,
    /// The fast path: the field resampled `resample` times finer than its lattice (a grid's
    /// points, or a lattice over irregular data) and interpolated ([`resample`]); 0 evaluates
    /// the general path everywhere.
    pub resample: u32,
    /// `reconstruction.resample = "auto"` (the default): the field picks the factor when it
    /// sees the data ([`resample::AUTO_FACTOR`] where the fast path serves and its fine grid
    /// stays under [`resample::AUTO_MAX_POINTS`], else 0), sets `resample` to it and clears
    /// this flag, so a built field never holds it set; a scene then also weighs the first
    /// frame and, on irregular data, a pilot of the fast path's error
    /// (`Scene::fit_fast_path`).
    pub resample_auto: bool,
    /// The fast path's cells with a corner whose fit the samples barely determine are solved
    /// by the general path ([`resample::DIRECT`]): MLS on irregular data only. Resolved from
    /// `direct_cells` when the field is built; with "auto", a scene sets it where the fast
    /// path's pilot fails without it and passes with it (`Scene::fit_fast_path`).
    pub resample_direct: bool,
    /// `reconstruction.direct_cells`: `Some(true)` solves those cells directly wherever the
    /// fast path serves irregular MLS data, `Some(false)` never, `None` ("auto", the default)
    /// where "auto"'s pilot needs it.
    pub direct_cells: Option<bool>,
}

/// Errors of the reconstruction layer.
#[derive(Debug, Clone, thiserror::Error)]
pub enum ReconError {
    #[error("octree: no samples to index")]
    Empty,
    #[error(
        "octree: {refs} sample references ({words} words of codes) exceed the limit of {limit} \
         words (octree.max_references, at most the device's maxTexelBufferElements); raise \
         octree.leaf_size or octree.leaf_budget, or lower reconstruction.support"
    )]
    TooManyReferences { refs: u64, words: u64, limit: u64 },
    #[error(
        "octree: a leaf holds {refs} sample references (or codes), more than {limit} (every MLS evaluation \
         loops over its leaf; devices such as lavapipe cut loops past 65 535 iterations): raise \
         octree.max_depth, or lower octree.leaf_budget or octree.leaf_size"
    )]
    LeafTooLarge { refs: usize, limit: usize },
    #[error("octree: {key} = {value} is out of range ({expected})")]
    Setting {
        key: &'static str,
        value: String,
        expected: &'static str,
    },
}

/// Implicit neighbours of a regular grid: the grid points inside the support box of x.
///
/// Positions are relative to the frame origin the caller chose (see `field::Field::frame_origin`), exactly
/// as on the GPU.
#[derive(Debug, Clone, Copy)]
pub struct GridNeighbours<'a> {
    pub dims: [usize; 3],
    pub origin: [f64; 3],
    pub spacing: [f64; 3],
    pub values: &'a crate::data::Values,
    /// Support radius in sample spacings (h = support × spacing per axis).
    pub support: f64,
}

impl GridNeighbours<'_> {
    /// 1 / h per axis.
    pub fn inv_support(&self) -> [f64; 3] {
        [
            1.0 / (self.support * self.spacing[0]),
            1.0 / (self.support * self.spacing[1]),
            1.0 / (self.support * self.spacing[2]),
        ]
    }
}

impl Neighbours for GridNeighbours<'_> {
    fn basis_scale(&self, _x: [f64; 3]) -> [f64; 3] {
        self.inv_support()
    }

    fn for_each(&self, x: [f64; 3], visit: &mut Visit<'_>) {
        let inv_h = self.inv_support();
        let metric = crate::samples::supports::diagonal(inv_h.map(|v| 1.0 / v));
        let mut lo = [0usize; 3];
        let mut hi = [0usize; 3];
        for a in 0..3 {
            let g = (x[a] - self.origin[a]) / self.spacing[a];
            let l = (g - self.support).ceil().max(0.0);
            let h = (g + self.support).floor().min(self.dims[a] as f64 - 1.0);
            if l.is_nan() || h.is_nan() || l > h {
                return;
            }
            lo[a] = l as usize;
            hi[a] = h as usize;
        }
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                for i in lo[0]..=hi[0] {
                    let p = [
                        self.origin[0] + i as f64 * self.spacing[0],
                        self.origin[1] + j as f64 * self.spacing[1],
                        self.origin[2] + k as f64 * self.spacing[2],
                    ];
                    let index = i + self.dims[0] * (j + self.dims[1] * k);
                    visit(index, p, f64::from(self.values.get(index)), &metric);
                }
            }
        }
    }
}
