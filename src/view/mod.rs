//! How a field is looked at, the vocabulary both renderers share: the camera, the transfer
//! function, isosurfaces and their shading, the renderer's settings, and [`View`], everything a
//! frame is made of besides the field.
//!
//! Pure description: this module imports only `gpu_types` (the layouts its twins share with the
//! kernels) and `data`'s value types, never a field or a renderer.

pub mod camera;
pub mod preintegration;
pub mod settings;
pub mod shading;
pub mod table_cache;
pub mod table_occupancy;
pub mod transfer;

pub use settings::{
    AdaptiveCriterion, Antialias, ExactOpacity, GivenKeys, IntervalModel, Method, RenderSettings,
    Shading, SheetInterval, SheetShare, SkipMode, SplatSettings,
};

use camera::Camera;
use shading::{Isosurface, Lighting};
use transfer::TransferFunction;

/// The work budget of a frame in MLS evaluations (see `raycast::RaySetup::check_budget`) or
/// footprint-pixel evaluations (`SplatSetup::check_budget`): about 2.5 minutes of the
/// general path on lavapipe at 30 M evaluations/s, seconds on a GPU; the CLI's `--force`
/// lifts it.
pub const WORK_BUDGET: f64 = 4.0e9;

/// What a frame is made of besides the field.
#[derive(Debug, Clone, Copy)]
pub struct View<'a> {
    pub camera: &'a Camera,
    pub settings: &'a RenderSettings,
    pub transfer: &'a TransferFunction,
    pub isosurfaces: &'a [Isosurface],
    pub lighting: &'a Lighting,
}

/// An owned copy of everything a [`View`] holds: the key of what was computed for one view (a
/// tolerance's resolution, the kernels of a splatting decomposition).
#[derive(Debug, Clone, PartialEq)]
pub struct ViewKey {
    camera: Camera,
    settings: RenderSettings,
    transfer: TransferFunction,
    isosurfaces: Vec<Isosurface>,
    lighting: Lighting,
}

impl ViewKey {
    pub fn of(view: &View<'_>) -> Self {
        Self {
            camera: *view.camera,
            settings: view.settings.clone(),
            transfer: view.transfer.clone(),
            isosurfaces: view.isosurfaces.to_vec(),
            lighting: *view.lighting,
        }
    }

    /// Whether `other` is the same view through another camera (a turning camera, a resized
    /// image): what does not depend on the camera can be carried over.
    pub fn same_but_camera(&self, other: &ViewKey) -> bool {
        self.settings == other.settings
            && self.transfer == other.transfer
            && self.isosurfaces == other.isosurfaces
            && self.lighting == other.lighting
    }
}
