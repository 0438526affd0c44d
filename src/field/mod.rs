//! The reconstructed field as both renderers see it: the sample set in frame-relative
//! coordinates, the reconstruction (MLS, Gaussian sum, or the generator's analytic field), its
//! neighbour structure (grid or redundant octree [OCT]), the boundary hull, the fast path's fine
//! grid and its skipping blocks, and the field's GPU form ([`gpu::GpuField`]) with the drivers of
//! the kernels that evaluate it (`mls_eval`, `recon_resample`).
//!
//! `raycast` and `splat` read the field only through this module. It imports the layers below
//! it (`vk`, `files`, `data`, `samples`, `recon`) and `view`'s settings, never a renderer.
//!
//! All positions handed to kernels are relative to the *frame origin*, the volume centre, which
//! is subtracted on the host in f64: f32 then keeps its precision for data far from the world
//! origin ([MLS] §3's shifted basis does the same inside each evaluation).

mod error;
pub mod exact;
mod fast_path;
pub mod gpu;
pub mod records;
pub mod resample;
pub mod skip;
pub mod variant;

pub use error::RenderError;

use crate::data::Volume;
use crate::recon::ReconMethod;
use crate::recon::gaussian::{KernelVolumes, gaussian_evaluate};
use crate::recon::mls::{MlsSettings, MlsValue, Neighbours, Visit, mls_evaluate};
use crate::recon::resample::ResampledGrid;
use crate::recon::support_index::SupportIndex;
use crate::recon::{GridNeighbours, Octree, OctreeSettings, ReconError};
use crate::recon::{NeighbourMode, Reconstruction};
use crate::samples::bvh::HullBvh;
use crate::samples::{Domain, Positions, Provenance, SampleSet, Supports};
use glam::DVec3;

/// What a piece of a decomposed field keeps of the whole field ([`Field::piece`]).
#[derive(Debug, Clone, PartialEq)]
pub struct PieceFrame {
    /// The whole field's frame origin (world) and value range.
    pub frame_origin: DVec3,
    pub range: (f64, f64),
    pub reconstruction: Reconstruction,
    pub octree: OctreeSettings,
    /// The whole field's supports (none for a whole field, which reads its own).
    pub extent: Option<SupportExtent>,
}

/// What splatting reads of a whole field's supports: their box (the sheets' depth range), the
/// thinnest (the sheet share's rule) and the radius quantiles (the ring). A piece keeps the
/// whole field's, so that its sheets are the undivided frame's.
#[derive(Debug, Clone, PartialEq)]
pub struct SupportExtent {
    pub support_box: (DVec3, DVec3),
    pub thinnest: f64,
    pub radii: Vec<f64>,
}

/// The scalar field of a scene: its sample set in frame-relative coordinates, its MLS settings,
/// and the redundant octree over its samples (irregular data always; regular grids with
/// `neighbours = "octree"`).
#[derive(Debug, Clone)]
pub struct Field {
    /// World position subtracted from everything (the centre of the domain's box).
    pub frame_origin: DVec3,
    pub samples: SampleSet,
    pub reconstruction: Reconstruction,
    /// The octree over the samples, where kernels read one (`octree_wanted`): built with the
    /// field, or, for a field made by [`Field::from_samples_deferred`] (splatting, which reads
    /// no octree), at the first [`Field::octree`].
    octree: std::sync::OnceLock<Result<Option<Octree>, ReconError>>,
    octree_settings: OctreeSettings,
    octree_wanted: bool,
    /// Ray-clipping hierarchy over the boundary, for a hull domain.
    pub hull: Option<HullBvh>,
    /// Smallest and largest sample value.
    range: (f64, f64),
    /// Whether any support is a rotated ellipsoid.
    full_metric: bool,
    /// Whether every support is a ball (packed inline records).
    isotropic: bool,
    /// Gaussian kernel volumes, computed at first use (Gaussian field, splatting).
    volumes: std::sync::OnceLock<KernelVolumes>,
    /// Set once [`Field::kernel_volumes_where`] computed some volumes alone.
    partial_volumes: std::sync::OnceLock<()>,
    /// Box of every sample's support (frame-relative): where kernels can reach.
    support_box: (DVec3, DVec3),
    /// [`SampleSet::thinnest_support`], computed at first use (post-shaded splatting's
    /// sheet-share rule).
    thinnest: std::sync::OnceLock<f64>,
    /// [`SampleSet::radius_quantiles`] at 64ths, computed at first use (post-shaded
    /// splatting's ring size).
    radii: std::sync::OnceLock<Vec<f64>>,
    /// The fast path's fine grid, built at first CPU use (`reconstruction.resample`; the GPU
    /// builds its own).
    resampled: std::sync::OnceLock<ResampledGrid>,
    /// The fast path's page table, classified at first use ([`Field::fine_pages`]).
    pages: std::sync::OnceLock<Option<crate::recon::pages::Pages>>,
    /// Block ranges of the CPU fine grid, for empty-space skipping.
    blocks: std::sync::OnceLock<skip::Blocks>,
    /// Why `reconstruction.resample = "auto"` chose the general path, where it did.
    fast_path_declined: Option<String>,
    /// What `reconstruction.resample = "auto"` chose beyond the factor, for `--stats`.
    fast_path_note: Option<String>,
    /// Irregular data's fast-path lattice spacing in units of the samples' median spacing
    /// (1 unless "auto" coarsened it to fit its cap, [`Field::lattice`]).
    lattice_scale: f64,
    /// A piece of a decomposed field ([`Field::piece`]): the box rays integrate in
    /// (frame-relative).
    clip: Option<(DVec3, DVec3)>,
}

impl Field {
    /// A regular grid with one support h = support × spacing (see [`Field::from_samples`]).
    pub fn new(
        volume: Volume,
        reconstruction: Reconstruction,
        octree: &OctreeSettings,
        progress: impl FnMut(f64),
    ) -> Result<Self, ReconError> {
        let (lo, hi) = volume.bounds();
        let samples = SampleSet {
            positions: Positions::Grid {
                dims: volume.dims,
                origin: volume.origin,
                spacing: volume.spacing,
            },
            values: volume.values,
            supports: Supports::Uniform(volume.spacing.map(|s| s * reconstruction.support)),
            domain: Domain::Box { lo, hi },
            spacing: volume.spacing.iter().copied().fold(f64::INFINITY, f64::min),
            provenance: Provenance {
                kind: "regular grid",
                array: "scalars".into(),
                location: crate::data::dataset::Location::Point,
                merged: 0,
                inverted_cells: 0,
                support_kind: "uniform",
            },
        };
        Self::from_samples(samples, reconstruction, octree, progress)
    }

    /// Moves the samples into a frame centred on their domain and builds the octree unless the
    /// implicit grid neighbours serve (a regular grid with `neighbours = "grid"`).
    pub fn from_samples(
        samples: SampleSet,
        reconstruction: Reconstruction,
        octree: &OctreeSettings,
        progress: impl FnMut(f64),
    ) -> Result<Self, ReconError> {
        let field = Self::from_samples_deferred(samples, reconstruction, octree)?;
        if field.octree_wanted {
            let built = Octree::from_samples(&field.samples, octree, progress)?;
            // The lock is new and empty: this sets it.
            let _ = field.octree.set(Ok(Some(built)));
        }
        Ok(field)
    }

    /// [`Field::from_samples`] without building the octree: the first [`Field::octree`] builds
    /// it. For splatting, which reads the samples' kernels and no octree: a cloud of 10⁷
    /// points splats although its octree would not fit.
    pub fn from_samples_deferred(
        mut samples: SampleSet,
        reconstruction: Reconstruction,
        octree: &OctreeSettings,
    ) -> Result<Self, ReconError> {
        let (lo, hi) = samples.domain_box();
        let centre = (DVec3::from(lo) + DVec3::from(hi)) * 0.5;
        samples.translate(centre.to_array());
        // Derived once here: every frame's table key and shader variant read them.
        let range = samples
            .values
            .iter()
            .fold((f64::MAX, f64::MIN), |(l, h), v| {
                (l.min(f64::from(v)), h.max(f64::from(v)))
            });
        let frame = PieceFrame {
            frame_origin: centre,
            range,
            reconstruction,
            octree: *octree,
            extent: None,
        };
        let mut field = Self::assemble(samples, frame, None);
        field.resolve_auto_resample();
        if field.reconstruction.resample > 0 {
            field.check_resample()?;
        }
        let always = field.reconstruction.direct_cells == Some(true);
        field.set_resample_direct(always && field.grid().is_none());
        Ok(field)
    }

    /// A field of frame-relative `samples` in `frame`, clipped to `clip` when it is a piece:
    /// what it derives from the samples (the neighbour structure it wants, metrics, the
    /// supports' box, the hull), nothing built yet.
    fn assemble(samples: SampleSet, frame: PieceFrame, clip: Option<(DVec3, DVec3)>) -> Self {
        let grid = matches!(samples.positions, Positions::Grid { .. })
            && matches!(samples.supports, Supports::Uniform(_));
        let full_metric = samples.has_full_metric();
        let isotropic = samples.is_isotropic();
        let support_box = match &frame.extent {
            Some(e) => e.support_box,
            None => {
                let (lo, hi) = samples.support_box();
                (DVec3::from(lo), DVec3::from(hi))
            }
        };
        let hull = match &samples.domain {
            Domain::Hull(h) => Some(HullBvh::build(h)),
            Domain::Box { .. } => None,
        };
        let (thinnest, radii) = (std::sync::OnceLock::new(), std::sync::OnceLock::new());
        if let Some(e) = frame.extent {
            let _ = thinnest.set(e.thinnest);
            let _ = radii.set(e.radii);
        }
        Self {
            frame_origin: frame.frame_origin,
            samples,
            reconstruction: frame.reconstruction,
            octree: std::sync::OnceLock::new(),
            octree_settings: frame.octree,
            octree_wanted: !grid || frame.reconstruction.neighbours == NeighbourMode::Octree,
            hull,
            range: frame.range,
            full_metric,
            isotropic,
            volumes: std::sync::OnceLock::new(),
            partial_volumes: std::sync::OnceLock::new(),
            support_box,
            thinnest,
            radii,
            resampled: std::sync::OnceLock::new(),
            pages: std::sync::OnceLock::new(),
            blocks: std::sync::OnceLock::new(),
            fast_path_declined: None,
            fast_path_note: None,
            lattice_scale: 1.0,
            clip,
        }
    }

    /// What a piece of this field keeps of it ([`Field::piece`]).
    pub fn piece_frame(&self) -> PieceFrame {
        PieceFrame {
            frame_origin: self.frame_origin,
            range: self.range,
            reconstruction: self.reconstruction,
            octree: self.octree_settings,
            extent: Some(self.support_extent()),
        }
    }

    /// What splatting reads of this field's supports (a piece keeps the whole field's).
    pub fn support_extent(&self) -> SupportExtent {
        SupportExtent {
            support_box: self.support_box,
            thinnest: self.thinnest_support(),
            radii: self.radius_quantiles().to_vec(),
        }
    }

    /// A piece of this field for a brick of a decomposition (issue 30): `samples` (the brick's
    /// own and ghost samples, frame-relative, with this field's domain), rendered only inside
    /// `bounds`, with `volumes` as its Gaussian kernels' (the whole field's, selected: a
    /// brick's outermost ghosts lack the neighbours their SPH volumes were estimated from).
    /// See [`Field::from_piece`].
    pub fn piece(
        &self,
        samples: SampleSet,
        bounds: (DVec3, DVec3),
        volumes: Option<KernelVolumes>,
        progress: impl FnMut(f64),
    ) -> Result<Self, ReconError> {
        Self::from_piece(samples, self.piece_frame(), bounds, volumes, progress)
    }

    /// A piece of a field that `frame` describes (the whole field may live in another process):
    /// it keeps the whole field's frame origin, value range (so tables and variants are the
    /// whole field's) and reconstruction, solved directly (the fast path's fine grid would need
    /// the neighbours' fine points too); its hull is rebuilt from the samples' domain. (The
    /// analytic field reads no samples: the caller refuses it.)
    pub fn from_piece(
        samples: SampleSet,
        frame: PieceFrame,
        bounds: (DVec3, DVec3),
        volumes: Option<KernelVolumes>,
        progress: impl FnMut(f64),
    ) -> Result<Self, ReconError> {
        let field = Self::piece_deferred(samples, frame, bounds, volumes);
        if field.octree_wanted {
            let built = Octree::from_samples(&field.samples, &field.octree_settings, progress)?;
            let _ = field.octree.set(Ok(Some(built)));
        }
        Ok(field)
    }

    /// [`Field::from_piece`] with its octree built when first asked for: a piece that is only
    /// projected (a splatting brick's kernels, chosen on the host) never builds it.
    pub fn piece_deferred(
        samples: SampleSet,
        frame: PieceFrame,
        bounds: (DVec3, DVec3),
        volumes: Option<KernelVolumes>,
    ) -> Self {
        let mut reconstruction = frame.reconstruction;
        reconstruction.resample = 0;
        reconstruction.resample_auto = false;
        reconstruction.resample_direct = false;
        let mut field = Self::assemble(
            samples,
            PieceFrame {
                reconstruction,
                ..frame
            },
            Some(bounds),
        );
        field.fast_path_declined = Some("a brick of a decomposed field is solved directly".into());
        if let Some(v) = volumes {
            let _ = field.volumes.set(v);
        }
        field
    }

    /// The box a piece of a decomposed field is rendered in ([`Field::piece`]).
    pub fn clip(&self) -> Option<(DVec3, DVec3)> {
        self.clip
    }

    /// Implicit grid neighbours, for a regular grid with one support.
    pub fn grid(&self) -> Option<GridNeighbours<'_>> {
        match (&self.samples.positions, &self.samples.supports) {
            (
                Positions::Grid {
                    dims,
                    origin,
                    spacing,
                },
                Supports::Uniform(h),
            ) => Some(GridNeighbours {
                dims: *dims,
                origin: *origin,
                spacing: *spacing,
                values: &self.samples.values,
                support: h[0] / spacing[0],
            }),
            _ => None,
        }
    }

    /// The octree, where kernels read one (`None` for a grid's implicit neighbours); a deferred
    /// one is built here, once, and its build error returned on every call.
    pub fn octree(&self) -> Result<Option<&Octree>, ReconError> {
        let built = self.octree.get_or_init(|| {
            if self.octree_wanted {
                Octree::from_samples(&self.samples, &self.octree_settings, |_| {}).map(Some)
            } else {
                Ok(None)
            }
        });
        match built {
            Ok(o) => Ok(o.as_ref()),
            Err(e) => Err(e.clone()),
        }
    }

    /// The octree if it has been built (statistics; never builds one).
    pub fn octree_if_built(&self) -> Option<&Octree> {
        self.octree
            .get()
            .and_then(|o| o.as_ref().ok())
            .and_then(Option::as_ref)
    }

    /// The neighbour structure in use: the octree when kernels read one (built here if it was
    /// deferred), else the grid. Everything else [`Field::evaluate_direct`] reads is built here
    /// too (the Gaussian sum's kernel volumes), so that callers can fan out over rayon after
    /// it: a lazily built value whose builder itself runs on rayon, first asked for inside a
    /// parallel loop, deadlocks when the building worker, waiting for its own jobs, steals an
    /// outer job that waits for the same value (the pilot of a Gaussian field hung that way on
    /// 16 cores).
    pub fn neighbours(&self) -> Result<Box<dyn Neighbours + Sync + '_>, ReconError> {
        let neighbours: Box<dyn Neighbours + Sync + '_> = match (self.octree()?, self.grid()) {
            (Some(o), _) => Box::new(o),
            (None, Some(g)) => Box::new(g),
            // Every field that is not a uniform grid wants an octree.
            (None, None) => Box::new(NoNeighbours),
        };
        if self.reconstruction.method == ReconMethod::Gaussian {
            self.kernel_volumes();
        }
        Ok(neighbours)
    }

    /// [`Field::neighbours`] with everything [`Field::evaluate`] reads built as well (the fast
    /// path's CPU fine grid): what a CPU twin asks for before its parallel loop.
    pub fn evaluator(&self) -> Result<Box<dyn Neighbours + Sync + '_>, ReconError> {
        let neighbours = self.neighbours()?;
        self.resampled();
        Ok(neighbours)
    }

    /// The volume each sample's Gaussian kernel stands for ([`KernelVolumes`]), computed once.
    pub fn kernel_volumes(&self) -> &KernelVolumes {
        self.volumes.get_or_init(|| {
            KernelVolumes::compute(
                &self.samples,
                self.volume_neighbours().as_ref(),
                self.reconstruction.sigma,
            )
        })
    }

    /// The kernel volumes of the samples `keep` accepts, each the value
    /// [`Field::kernel_volumes`] holds (the others may be 0): a pre-shaded frame uploads only
    /// the kernels its transfer function does not make transparent, and its first frame need
    /// not estimate the others' (about a third of a 10⁶-point cloud's first frame). Computed
    /// for those alone the first time, not kept; from the second call on, every volume is
    /// computed once and kept, so that later transfer functions read them.
    pub fn kernel_volumes_where(
        &self,
        keep: &(dyn Fn(usize) -> bool + Sync),
    ) -> std::borrow::Cow<'_, KernelVolumes> {
        if let Some(v) = self.volumes.get() {
            return std::borrow::Cow::Borrowed(v);
        }
        if self.partial_volumes.set(()).is_err() {
            return std::borrow::Cow::Borrowed(self.kernel_volumes());
        }
        std::borrow::Cow::Owned(KernelVolumes::compute_where(
            &self.samples,
            self.volume_neighbours().as_ref(),
            self.reconstruction.sigma,
            keep,
        ))
    }

    /// What the kernel volumes are estimated with: the octree where it was built; a deferred
    /// one is not built for this (a kd-tree per class of support radii finds the same kernels
    /// in O(n) memory).
    fn volume_neighbours(&self) -> Box<dyn Neighbours + Sync + '_> {
        match (self.octree_if_built(), self.grid()) {
            (Some(o), _) => Box::new(o),
            (None, Some(g)) => Box::new(g),
            (None, None) => Box::new(SupportIndex::new(&self.samples)),
        }
    }

    /// The reconstructed field and its gradient at x (frame-relative), by the scene's method;
    /// `None` where it is undefined. With `reconstruction.resample` it is the fast path's
    /// interpolation of the fine grid (stage `resample_evaluate`), or the general path in a
    /// cell with a direct corner (`Reconstruction::resample_direct`).
    pub fn evaluate(&self, neighbours: &dyn Neighbours, x: [f64; 3]) -> Option<MlsValue> {
        if let Some(r) = self.resampled() {
            let v = r.evaluate(x);
            if v.terms == crate::recon::resample::DIRECT_TERMS {
                return self.evaluate_direct(neighbours, x);
            }
            return Some(v).filter(|v| v.terms > 0);
        }
        self.evaluate_direct(neighbours, x)
    }

    /// The general path: the scene's method solved at x.
    pub fn evaluate_direct(&self, neighbours: &dyn Neighbours, x: [f64; 3]) -> Option<MlsValue> {
        match self.reconstruction.method {
            ReconMethod::Mls => mls_evaluate(&self.mls(), neighbours, x),
            ReconMethod::Gaussian => gaussian_evaluate(
                self.reconstruction.sigma,
                self.kernel_volumes(),
                neighbours,
                x,
            ),
            ReconMethod::Exact => Some(exact::exact_evaluate(self.grid()?.origin, x)),
        }
    }

    /// Why `reconstruction.resample = "auto"` chose the general path, where it did.
    pub fn fast_path_declined(&self) -> Option<&str> {
        self.fast_path_declined.as_deref()
    }

    /// Whether kernels read the octree (else the implicit grid).
    pub fn uses_octree(&self) -> bool {
        self.octree_wanted
    }

    /// How kernels read the built octree's leaves ("inline" or "coded") and the bytes that
    /// form takes on the device (nodes, and records or samples and codes), for `--stats`.
    pub fn octree_layout(&self) -> Option<(&'static str, u64)> {
        let o = self.octree_if_built()?;
        let sample_bytes = std::mem::size_of::<crate::gpu_types::Sample>() as u64;
        Some(if self.octree_inline() {
            let stride = self.record_stride();
            let texels = records::record_texel_count(o, stride);
            ("inline", 16 * (texels + o.nodes.len() as u64))
        } else {
            ("coded", o.stats(sample_bytes).bytes)
        })
    }

    /// Whether kernels read the built octree's leaves as inline records
    /// ([`records`]; `octree.records`); false before the octree is built.
    pub fn octree_inline(&self) -> bool {
        self.octree_if_built().is_some_and(|o| {
            records::inline_chosen(
                o,
                self.record_stride(),
                self.octree_settings.records,
                self.octree_settings.max_record_texels,
            )
        })
    }

    /// Texels of an inline record ([`records::record_stride`]).
    pub fn record_stride(&self) -> usize {
        records::record_stride(self.full_metric, self.isotropic)
    }

    /// Compile-time MLS choices.
    pub fn mls(&self) -> MlsSettings {
        MlsSettings {
            basis: self.reconstruction.basis,
            weight: self.reconstruction.weight,
            gradient: self.reconstruction.gradient,
        }
    }

    /// Frame-relative bounding box of the domain (rays are clipped to it).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let (lo, hi) = self.samples.domain_box();
        (DVec3::from(lo), DVec3::from(hi))
    }

    /// Frame-relative box of every sample's support: where kernels can reach (splatting's
    /// depth range).
    pub fn support_box(&self) -> (DVec3, DVec3) {
        self.support_box
    }

    /// A lower bound on the shortest half axis of any support ([`SampleSet::thinnest_support`]).
    pub fn thinnest_support(&self) -> f64 {
        *self
            .thinnest
            .get_or_init(|| self.samples.thinnest_support())
    }

    /// Support radii at the quantiles 0, 1/64, …, 1 ([`SampleSet::radius_quantiles`]).
    pub fn radius_quantiles(&self) -> &[f64] {
        self.radii.get_or_init(|| self.samples.radius_quantiles(64))
    }

    /// The unit of `render.step` ([`SampleSet::spacing`]).
    pub fn min_spacing(&self) -> f64 {
        self.samples.spacing
    }

    /// Smallest and largest sample value.
    pub fn value_range(&self) -> (f64, f64) {
        self.range
    }

    /// Whether any support is a rotated ellipsoid (the full-metric shader variant).
    pub fn has_full_metric(&self) -> bool {
        self.full_metric
    }
}

/// No samples anywhere (never used in practice; keeps `neighbours` total).
struct NoNeighbours;

impl Neighbours for NoNeighbours {
    fn basis_scale(&self, _x: [f64; 3]) -> [f64; 3] {
        [1.0; 3]
    }

    fn for_each(&self, _x: [f64; 3], _visit: &mut Visit<'_>) {}
}

impl Neighbours for &Octree {
    fn basis_scale(&self, x: [f64; 3]) -> [f64; 3] {
        (*self).basis_scale(x)
    }

    fn for_each(&self, x: [f64; 3], visit: &mut Visit<'_>) {
        (*self).for_each(x, visit)
    }
}

/// The tables' scalar range: the data range with a 5% margin each side. The margin is at
/// least 5·10⁻⁶ of the values' magnitude, so that a constant field far from zero (fuzzing found
/// 1e20 everywhere) keeps a range that f32 resolves on the GPU instead of one of zero width,
/// which made the CPU twin divide 0 by 0.
pub fn scalar_range(field: &Field) -> (f64, f64) {
    let (lo, hi) = field.value_range();
    let magnitude = lo.abs().max(hi.abs());
    let margin = 0.05 * (hi - lo).max(1e-6).max(1e-4 * magnitude);
    (lo - margin, hi + margin)
}
