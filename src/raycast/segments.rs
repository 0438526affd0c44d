//! The hull segments cache (issue 27 §1, "cache what the hull BVH gives a ray"): a frame of a
//! camera that the cache does not hold walks the hull's BVH as before (stage `hull_segments`,
//! whose CPU twin is `samples::bvh`), and the chunks that start its rays keep what they found in
//! a buffer of the frame's ([`HullCache::Keep`], `glsl/raycast/segments.glsl`); a later frame of
//! the same camera reads it instead, from a variant without the walk ([`HullCache::Read`]). On
//! the room-fire mesh at 512² the walk was about half of a frame's GPU time, which every frame
//! of an unchanged camera (a transfer-function edit, a tolerance's pilots, a benchmark's
//! repeats) paid again. The walk is not merely skipped at run time in one variant: with it
//! compiled in, reading cost 1.6× the variant without it (lavapipe runs both sides of a branch,
//! and the walk's local arrays cost every invocation).
//!
//! Contract:
//! - the cache holds the segments of one camera (its GPU block, which is what the kernel's rays
//!   are made from) at one `HULL_MAX_HITS` ([`SegmentsKey`]); a frame of another camera or
//!   bound keeps, a frame of the same one reads;
//! - per pixel, [`texels_per_pixel`] rgba32f texels: the segment count (−1 past `HULL_MAX_HITS`
//!   crossings, which the ray caster then reports as its walk does) and the segments;
//! - an image is the same whether its segments were walked or read (`tests/hull.rs`,
//!   `tests/embed_example.rs`).

use super::setup::RaySetup;
use crate::field::variant::HullCache;
use crate::gpu_types::CameraBlock;
use crate::samples::bvh::MAX_HITS;
use crate::vk::{Buffer, BufferUsage, Context, DeviceInfo, VkError};

/// The rgba32f texels a pixel's entry takes for rays of at most `hull_hits` crossings: its
/// count and `hull_hits / 2 + 1` segments (twin of `RAY_SEGMENT_TEXELS`).
pub fn texels_per_pixel(hull_hits: u32) -> u64 {
    let floats = 2 * (u64::from(hull_hits) / 2 + 1) + 1;
    floats.div_ceil(4)
}

/// Whether a frame of `pixels` can cache its segments: the entries of the largest bound a frame
/// may need ([`MAX_HITS`], after an overflow) fit one texel view of the device. Where they do
/// not, the ray caster walks the hull in every chunk, uncached.
pub fn fits(info: &DeviceInfo, pixels: u64) -> bool {
    pixels * texels_per_pixel(MAX_HITS as u32) <= info.max_texel_buffer_elements
}

/// How a frame of `setup` comes by its segments, for a field with or without a hull.
pub fn hull_cache(setup: &RaySetup, has_hull: bool) -> HullCache {
    match (has_hull && setup.hull_cache, setup.hull_store) {
        (false, _) => HullCache::Off,
        (true, true) => HullCache::Keep,
        (true, false) => HullCache::Read,
    }
}

/// What a cache's segments were found for: the camera's GPU block and the crossing bound.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SegmentsKey {
    camera: CameraBlock,
    hull_hits: u32,
}

impl SegmentsKey {
    pub(crate) fn of(setup: &RaySetup) -> Self {
        let camera = setup.camera.gpu_block(
            &setup.basis,
            glam::DVec3::from(setup.camera.eye) - setup.frame_origin,
        );
        Self {
            camera,
            hull_hits: setup.hull_hits,
        }
    }
}

/// A frame buffer's cached segments: the texels and what they were found for (`None`: nothing
/// valid yet). A recorded frame that stores sets `pending`; its retire makes that the cache's
/// key, since only a completed submission wrote the texels.
pub(crate) struct SegmentCache {
    pub(crate) texels: Buffer,
    pub(crate) valid: Option<SegmentsKey>,
    pub(crate) pending: Option<SegmentsKey>,
}

impl SegmentCache {
    /// Room for `pixels` entries at the largest crossing bound.
    pub(crate) fn new(ctx: &Context, pixels: u64) -> Result<Self, VkError> {
        let bytes = 16 * pixels.max(1) * texels_per_pixel(MAX_HITS as u32);
        Ok(Self {
            texels: Buffer::new(ctx, "hull segments", bytes, BufferUsage::Texel)?,
            valid: None,
            pending: None,
        })
    }
}
