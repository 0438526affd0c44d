//! How a field is looked at, the vocabulary both renderers share: the camera, the transfer
//! function, isosurfaces and their shading, the renderer's settings, and [`View`], everything a
//! frame is made of besides the field.
//!
//! Pure description: this module imports only `gpu_types` (the layouts its twins share with the
//! kernels) and `data`'s value types, never a field or a renderer.

pub mod camera;
pub mod settings;
pub mod shading;
pub mod transfer;

pub use settings::{
    AdaptiveCriterion, Antialias, GivenKeys, IntervalModel, Method, RenderSettings, Shading,
    SheetShare, SkipMode, SplatSettings,
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
