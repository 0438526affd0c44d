//! The errors of the rendering layers: `field`, `view`, `raycast`, `splat` and the `Renderer`
//! (and everything below them), one type so that a frame reports any of them the same way.

use crate::data::DataError;
use crate::recon::ReconError;
use crate::vk::VkError;

/// Errors of the render layer (and everything below it).
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(transparent)]
    Vk(#[from] VkError),
    #[error(transparent)]
    Recon(#[from] ReconError),
    #[error(transparent)]
    Data(#[from] DataError),
    #[error("camera: expected a valid view frame, found {0}")]
    Camera(String),
    #[error(transparent)]
    Samples(#[from] crate::samples::SampleError),
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    #[error("{key}: {message}")]
    Setting { key: &'static str, message: String },
    #[error("{path}: {message}")]
    Output { path: String, message: String },
    #[error(
        "the render plans up to {planned:.3e} {unit}, more than the work budget of \
         {budget:.1e} ({hint}); pass --force to render anyway"
    )]
    Budget {
        planned: f64,
        /// What is counted: MLS evaluations (ray casting) or footprint-pixel evaluations
        /// (splatting), which cost about the same on lavapipe.
        unit: &'static str,
        budget: f64,
        hint: String,
    },
    /// A recorded frame that completed wrong (`Renderer::retire`): what cut it short, and
    /// what the next recordings do instead.
    #[error("the recorded frame is not right: {0}")]
    Recorded(String),
    /// `Renderer::retire` of a frame it does not hold (another renderer's, or retired).
    #[error("retire: {0}")]
    Retired(String),
    #[error("interrupted: the render stopped and wrote nothing")]
    Interrupted,
    #[error(
        "the render produced {count} non-finite pixel values (first at pixel {first}); no image written"
    )]
    NonFinite { count: usize, first: usize },
}
