//! Ray casting with MLS reconstruction and preintegration ([MLS] §4): the ray setup, the
//! integrators' f64 CPU twins (`raycast`, `adaptive`, `interval`), the preintegration tables,
//! and the GPU driver of `glsl/raycast/raycast.comp` (`gpu`, `frame`).
//!
//! Imports `field` and `view`, never `splat`; the `Renderer` above both methods drives it.

pub mod adaptive;
pub mod frame;
pub mod gpu;
pub(crate) mod interval;
mod ray;
// The CPU twin of the kernel `raycast` carries the kernel's name, as every stage does.
#[allow(clippy::module_inception)]
pub mod raycast;
pub mod segments;
pub mod setup;
pub mod tables;

pub use raycast::{PixelResult, raycast_frame, raycast_image, skip_report};
pub use setup::{F32_STEP_RESOLUTION, RaySetup};
pub use tables::{build_tables, check_table_size};
