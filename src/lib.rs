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
//! - [`view`]: how a field is looked at: camera, transfer function, shading, settings, `View`.
//! - [`field`]: the reconstructed field as both renderers see it, and its GPU form.
//! - [`raycast`]: MLS ray casting with preintegration (CPU twins and the GPU driver).
//! - [`splat`]: EWA volume splatting, pre- and post-shaded ([BLUR]'s sheets), drawn as a tile
//!   rasterizer (CPU twins and the GPU driver). `raycast` and `splat` are peers: each imports
//!   `field` and `view`, never the other.
//! - [`renderer`]: the persistent [`renderer::Renderer`], the one place that knows both methods.
//! - [`bricks`]: the field divided into kd bricks with exact ghosts, each rendered alone and
//!   composited in visibility order (sort-last rendering, issue 30).
//! - `distributed` (feature `mpi`): the bricks on MPI ranks, composited by IceT; its IceT calls
//!   are the one other place with `unsafe` (C FFI, `distributed/icet.rs`).
//! - [`scene`]: the TOML scene contract.
//!
//! With the `cli` feature (on by default) also the command-line program's modules: image files
//! and plots (`output`), `bench`, `check`, `probe` and `info`.

// The house rules (issue 28): `unsafe` only in the Vulkan layer, and no unwrap/expect on
// anything a user or a driver can influence (unit tests may).
#![deny(unsafe_code)]
#![deny(clippy::unwrap_used, clippy::expect_used)]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

#[cfg(feature = "cli")]
pub mod bench;
pub mod bricks;
#[cfg(feature = "cli")]
pub mod check;
pub mod data;
#[cfg(feature = "mpi")]
pub mod distributed;
pub mod field;
pub mod files;
pub mod gpu_types;
#[cfg(feature = "cli")]
pub mod info;
#[cfg(feature = "cli")]
pub mod output;
#[cfg(feature = "cli")]
pub mod probe;
pub mod raycast;
pub mod recon;
pub mod renderer;
pub mod samples;
pub mod scene;
pub mod splat;
pub mod view;
#[allow(unsafe_code)]
pub mod vk;
