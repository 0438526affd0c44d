//! vmls — volume Moving-Least-Squares ray casting and EWA splatting on Vulkan compute.
//!
//! Layers, bottom up:
//! - [`vk`]: the Vulkan layer, the only module that calls Vulkan directly: context, buffers, pipelines,
//!   commands, timestamp queries, run-time GLSL compilation.
//! - [`files`]: reading inputs (regular files only, bounded) and writing outputs all or
//!   nothing through exclusive temporaries.
//! - [`data`]: loaders and generators producing a [`data::Volume`].
//! - [`samples`]: the sample set every input becomes (positions, values, supports, domain).
//! - [`recon`]: MLS reconstruction (f64 CPU reference) and the redundant octree [OCT].
//! - [`render`]: cameras, transfer functions, the ray-casting integrator (CPU reference) and the
//!   GPU renderer that drives the kernels in `glsl/`.
//! - [`splat`]: EWA volume splatting, pre- and post-shaded ([BLUR]'s sheets), drawn as a tile
//!   rasterizer (CPU twins and the GPU driver).
//! - [`scene`]: the TOML scene contract.

// The house rules (issue 28): `unsafe` only in the Vulkan layer, and no unwrap/expect on
// anything a user or a driver can influence (unit tests may).
#![deny(unsafe_code)]
#![deny(clippy::unwrap_used, clippy::expect_used)]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod bench;
pub mod check;
pub mod data;
pub mod files;
pub mod gpu_types;
pub mod info;
pub mod probe;
pub mod recon;
pub mod render;
pub mod samples;
pub mod scene;
pub mod splat;
#[allow(unsafe_code)]
pub mod vk;
