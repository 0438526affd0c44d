//! The hull segments cache (issue 27 §1, "cache what the hull BVH gives a ray"): a frame of a
//! camera that the cache does not hold walks the hull's BVH as before (stage `hull_segments`,
//! whose CPU twin is `samples::bvh`), and the chunks that start its rays keep what they found in
//! a buffer of the frame's ([`crate::field::variant::HullCache::Keep`],
//! `glsl/raycast/segments.glsl`); a later frame of
//! the same camera reads it instead, from a variant without the walk (`HullCache::Read`). On
//! the room-fire mesh at 512² the walk was about half of a frame's GPU time, which every frame
//! of an unchanged camera (a transfer-function edit, a tolerance's pilots, a benchmark's
//! repeats) paid again. The walk is not merely skipped at run time in one variant: with it
//! compiled in, reading cost 1.6× the variant without it (lavapipe runs both sides of a branch,
//! and the walk's local arrays cost every invocation).
//!
//! Contract:
//! - the cache holds the segments of one camera (its GPU block, which is what the kernel's rays
//!   are made from), one set of dispatched pixels (a brick's window) and one `HULL_MAX_HITS`
//!   ([`SegmentsKey`]); a frame of the same rays at that bound or a smaller one reads (at the
//!   cache's bound), any other keeps;
//! - per pixel, [`texels_per_pixel`] rgba32f texels: the segment count (−1 past `HULL_MAX_HITS`
//!   crossings, which the ray caster then reports as its walk does) and the segments;
//! - an image is the same whether its segments were walked or read (`tests/hull.rs`,
//!   `tests/embed_example.rs`).

use super::setup::RaySetup;
use crate::gpu_types::CameraBlock;
use crate::vk::{Buffer, BufferUsage, Context, DeviceInfo, VkError};

/// The rgba32f texels a pixel's entry takes for rays of at most `hull_hits` crossings: its
/// count and `hull_hits / 2 + 1` segments (twin of `RAY_SEGMENT_TEXELS`).
pub fn texels_per_pixel(hull_hits: u32) -> u64 {
    let floats = 2 * (u64::from(hull_hits) / 2 + 1) + 1;
    floats.div_ceil(4)
}

/// The most device memory a frame's cache may take: 48 bytes a pixel at the first crossing
/// bound, so images up to about 2 300² cache at it and 1 300² after an overflow.
pub const MAX_CACHE_BYTES: u64 = 256 << 20;

/// Whether a frame of `pixels` can cache its segments for rays of at most `hull_hits`
/// crossings: the entries fit one texel view of the device (with indices a 32-bit int holds)
/// and [`MAX_CACHE_BYTES`]. Where they do not, the ray caster walks the hull in every frame,
/// as without a cache.
pub fn fits(info: &DeviceInfo, pixels: u64, hull_hits: u32) -> bool {
    let texels = pixels * texels_per_pixel(hull_hits);
    texels <= info.max_texel_buffer_elements.min(i32::MAX as u64)
        && 16 * texels <= MAX_CACHE_BYTES.min(info.max_heap_bytes / 4)
}

/// What a cache's segments were found for: the camera's GPU block, the pixels dispatched (a
/// brick's window stores only its own) and the crossing bound.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SegmentsKey {
    camera: CameraBlock,
    window: Option<[u32; 4]>,
    pub(crate) hull_hits: u32,
}

impl SegmentsKey {
    pub(crate) fn of(setup: &RaySetup) -> Self {
        let camera = setup.camera.gpu_block(
            &setup.basis,
            glam::DVec3::from(setup.camera.eye) - setup.frame_origin,
        );
        Self {
            camera,
            window: setup.window,
            hull_hits: setup.hull_hits,
        }
    }

    /// Whether segments kept for `self` serve a frame of `other`: the same rays, and at least
    /// its crossing bound (entries of a larger bound hold every crossing the smaller keeps).
    pub(crate) fn serves(&self, other: &SegmentsKey) -> bool {
        self.camera == other.camera
            && self.window == other.window
            && self.hull_hits >= other.hull_hits
    }
}

/// A frame buffer's cached segments: the texels and what they were found for (`None`: nothing
/// valid yet). A recorded frame that stores sets `pending`; its retire makes that the cache's
/// key, since only a completed submission wrote the texels.
pub(crate) struct SegmentCache {
    pub(crate) texels: Buffer,
    /// The crossing bound whose entries the texels have room for.
    pub(crate) hull_hits: u32,
    pub(crate) valid: Option<SegmentsKey>,
    pub(crate) pending: Option<SegmentsKey>,
}

impl SegmentCache {
    /// Room for `pixels` entries of rays of at most `hull_hits` crossings.
    pub(crate) fn new(ctx: &Context, pixels: u64, hull_hits: u32) -> Result<Self, VkError> {
        let bytes = 16 * pixels.max(1) * texels_per_pixel(hull_hits);
        Ok(Self {
            texels: Buffer::new(ctx, "hull segments", bytes, BufferUsage::Texel)?,
            hull_hits,
            valid: None,
            pending: None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(eye: f32, window: Option<[u32; 4]>, hull_hits: u32) -> SegmentsKey {
        SegmentsKey {
            camera: CameraBlock {
                eye: [eye, 0.0, 0.0, 0.0],
                ..CameraBlock::default()
            },
            window,
            hull_hits,
        }
    }

    /// Kept segments serve only the same rays (camera and dispatched window), at their bound
    /// or a smaller one; and an entry has room for its bound's segments.
    #[test]
    fn kept_segments_serve_the_same_rays_at_no_larger_bound() {
        let kept = key(1.0, None, 8);
        assert!(kept.serves(&key(1.0, None, 8)));
        assert!(!kept.serves(&key(1.5, None, 8)), "another camera");
        assert!(!kept.serves(&key(1.0, Some([0, 0, 4, 4]), 8)), "a window");
        assert!(
            !key(1.0, Some([0, 0, 4, 4]), 8).serves(&kept),
            "only the window's pixels"
        );
        assert!(!kept.serves(&key(1.0, None, 32)), "fewer crossings kept");
        assert!(key(1.0, None, 32).serves(&kept), "every crossing kept");
        assert_eq!(texels_per_pixel(8), 3);
        assert_eq!(texels_per_pixel(32), 9);
    }
}
