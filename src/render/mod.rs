//! Rendering: the reconstructed field as both renderers see it, the ray-casting integrator
//! (f64 CPU reference in [`raycast`], GPU driver in [`gpu`]) and image output.
//!
//! All positions handed to kernels are relative to the *frame origin*, the volume centre, which
//! is subtracted on the host in f64: f32 then keeps its precision for data far from the world
//! origin ([MLS] §3's shifted basis does the same inside each evaluation).

pub mod camera;
pub mod gpu;
pub mod output;
pub mod preintegration;
pub mod raycast;
pub mod transfer;

use crate::data::{DataError, Volume};
use crate::recon::mls::{MlsSettings, Neighbours};
use crate::recon::{GridNeighbours, Octree, OctreeSettings, ReconError, SamplePoint};
use crate::scene::{Method, NeighbourMode, Reconstruction, Scene, SceneError};
use crate::vk::VkError;
use camera::{Camera, ViewBasis};
use glam::DVec3;

/// Errors of the render layer (and everything below it).
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(transparent)]
    Vk(#[from] VkError),
    #[error(transparent)]
    Recon(#[from] ReconError),
    #[error(transparent)]
    Data(#[from] DataError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("{path}: {message}")]
    Output { path: String, message: String },
    #[error(
        "the render produced {count} non-finite pixel values (first at pixel {first}); no image written"
    )]
    NonFinite { count: usize, first: usize },
}

/// The scalar field of a scene: a regular grid in frame-relative coordinates, its MLS settings,
/// and (for `neighbours = "octree"`) the redundant octree over its samples.
#[derive(Debug, Clone)]
pub struct Field {
    /// World position subtracted from everything (the volume centre).
    pub frame_origin: DVec3,
    pub dims: [usize; 3],
    /// Frame-relative position of grid point (0,0,0).
    pub origin: [f64; 3],
    pub spacing: [f64; 3],
    pub values: Vec<f32>,
    pub reconstruction: Reconstruction,
    pub octree: Option<Octree>,
}

impl Field {
    /// Moves the volume into its frame and builds the octree when the scene asks for one.
    pub fn new(
        volume: Volume,
        reconstruction: Reconstruction,
        octree: &OctreeSettings,
        progress: impl FnMut(f64),
    ) -> Result<Self, ReconError> {
        let (lo, hi) = volume.bounds();
        let centre = (DVec3::from(lo) + DVec3::from(hi)) * 0.5;
        let origin = (DVec3::from(volume.origin) - centre).to_array();
        let mut field = Self {
            frame_origin: centre,
            dims: volume.dims,
            origin,
            spacing: volume.spacing,
            values: volume.values,
            reconstruction,
            octree: None,
        };
        if reconstruction.neighbours == NeighbourMode::Octree {
            let inv_h = field.grid().inv_support();
            let mut samples = Vec::with_capacity(field.values.len());
            for k in 0..field.dims[2] {
                for j in 0..field.dims[1] {
                    for i in 0..field.dims[0] {
                        samples.push(SamplePoint {
                            position: field.position(i, j, k),
                            value: f64::from(field.values[field.index(i, j, k)]),
                            inv_support: inv_h,
                        });
                    }
                }
            }
            field.octree = Some(Octree::build(samples, octree, progress)?);
        }
        Ok(field)
    }

    fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// Frame-relative position of grid point (i, j, k).
    pub fn position(&self, i: usize, j: usize, k: usize) -> [f64; 3] {
        [
            self.origin[0] + i as f64 * self.spacing[0],
            self.origin[1] + j as f64 * self.spacing[1],
            self.origin[2] + k as f64 * self.spacing[2],
        ]
    }

    /// Implicit grid neighbours.
    pub fn grid(&self) -> GridNeighbours<'_> {
        GridNeighbours {
            dims: self.dims,
            origin: self.origin,
            spacing: self.spacing,
            values: &self.values,
            support: self.reconstruction.support,
        }
    }

    /// The neighbour structure the scene chose.
    pub fn neighbours(&self) -> Box<dyn Neighbours + '_> {
        match &self.octree {
            Some(o) => Box::new(o),
            None => Box::new(self.grid()),
        }
    }

    /// Compile-time MLS choices.
    pub fn mls(&self) -> MlsSettings {
        MlsSettings {
            basis: self.reconstruction.basis,
            weight: self.reconstruction.weight,
            gradient: self.reconstruction.gradient,
        }
    }

    /// Frame-relative bounding box of the samples (the domain rays are clipped to).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let lo = DVec3::from(self.origin);
        let n = DVec3::new(
            self.dims[0] as f64 - 1.0,
            self.dims[1] as f64 - 1.0,
            self.dims[2] as f64 - 1.0,
        );
        (lo, lo + n * DVec3::from(self.spacing))
    }

    /// Smallest sample spacing: the unit of `render.step`.
    pub fn min_spacing(&self) -> f64 {
        self.spacing.iter().copied().fold(f64::INFINITY, f64::min)
    }
}

impl Neighbours for &Octree {
    fn for_each(&self, x: [f64; 3], visit: &mut dyn FnMut([f64; 3], f64, [f64; 3])) {
        (*self).for_each(x, visit)
    }
}

/// Everything a ray needs besides the field: camera frame, clip box, step and compositing.
#[derive(Debug, Clone, Copy)]
pub struct RaySetup {
    pub camera: Camera,
    pub basis: ViewBasis,
    pub frame_origin: DVec3,
    pub box_lo: DVec3,
    pub box_hi: DVec3,
    /// Step length in world units.
    pub step: f64,
    pub background: [f64; 3],
    pub min_transmittance: f64,
}

impl RaySetup {
    /// Derives the ray setup of a scene for a field.
    pub fn new(scene: &Scene, field: &Field) -> Result<Self, SceneError> {
        let basis = scene.camera.basis().map_err(|found| SceneError::Key {
            origin: "scene".into(),
            key: "camera".into(),
            expected: "a valid view frame".into(),
            found,
        })?;
        let (box_lo, box_hi) = field.bounds();
        let spacings = match scene.render.method {
            Method::Fixed => scene.render.step,
            Method::Reference => scene.render.reference_step,
        };
        Ok(Self {
            camera: scene.camera,
            basis,
            frame_origin: field.frame_origin,
            box_lo,
            box_hi,
            step: spacings * field.min_spacing(),
            background: scene.render.background,
            min_transmittance: scene.render.min_transmittance,
        })
    }
}

/// Loads or generates the scene's volume.
pub fn load_volume(scene: &Scene) -> Result<Volume, DataError> {
    match &scene.volume {
        crate::scene::VolumeSource::MarschnerLobb { resolution } => {
            Ok(crate::data::marschner_lobb::generate(*resolution))
        }
        crate::scene::VolumeSource::File { path, array } => {
            crate::data::load(path, array.as_deref())
        }
    }
}
