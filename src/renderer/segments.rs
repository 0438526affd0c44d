//! The renderer's half of the hull segments cache ([`crate::raycast::segments`]): a ray-cast
//! frame of a mesh stores its rays' hull segments where the cache of its frame buffers does not
//! serve it (another camera, window or a smaller crossing bound), and reads them otherwise. A
//! tolerance's pilot frames only store: at their size a walk costs less than building the
//! variant that reads.
//!
//! [`Renderer::render`] marks the cache invalid before a frame that stores and valid once the
//! frame's bands all completed (a stopped frame leaves it invalid). A recorded frame that stores
//! marks it pending: [`Renderer::retire`] makes it valid, since only a completed submission wrote
//! the texels (a recorded command buffer that is discarded leaves the cache invalid, and the
//! slot's next frame stores again). Each slot's buffers have their own cache, so a frame in
//! flight never reads texels that another frame rewrites.

use super::Renderer;
use crate::field::RenderError;
use crate::field::variant::HullCache;
use crate::raycast::RaySetup;
use crate::raycast::frame::FrameTargets;
use crate::raycast::segments::{SegmentCache, SegmentsKey, fits};
use crate::vk::{Context, DeviceInfo, VkError};

/// Whether a frame found its rays' hull segments (ray casting: the walk; post-shaded
/// splatting: `splat_segments`) or read those of an earlier frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HullSegments {
    /// Found for this frame's camera, and kept for the next frames of it.
    Found,
    /// Read from the cache an earlier frame of the same camera filled.
    Reused,
}

impl HullSegments {
    /// Reused where `reused`, else found.
    pub(super) fn of(reused: bool) -> Self {
        if reused {
            HullSegments::Reused
        } else {
            HullSegments::Found
        }
    }

    /// The name `--stats` gives it.
    pub fn name(self) -> &'static str {
        match self {
            HullSegments::Found => "found",
            HullSegments::Reused => "reused",
        }
    }
}

impl Renderer {
    /// `setup.hull_cache` where the field has a hull ([`decide`] then says whether the frame
    /// keeps or reads, or turns it off where the cache would not fit).
    pub(super) fn choose_hull_cache(&self, setup: &mut RaySetup) {
        setup.hull_cache = if self.gpu_field.has_hull() {
            HullCache::Keep
        } else {
            HullCache::Off
        };
    }

    /// Before a [`Renderer::render`] frame (its buffers allocated): whether it keeps or reads
    /// the segments (`setup.hull_cache`, which picks the variant), the cache allocated and,
    /// where the frame keeps, invalid until [`Renderer::segments_stored`]. `None` where the
    /// frame does not cache.
    pub(super) fn render_segments(
        &mut self,
        setup: &mut RaySetup,
    ) -> Result<Option<HullSegments>, RenderError> {
        let held = self.targets.as_ref().filter(|_| !self.segments_keep_only);
        let found = decide(self.ctx.info(), held, setup);
        if let Some(targets) = self.targets.as_mut() {
            mark(&self.ctx, targets, setup, false)?;
        }
        Ok(found)
    }

    /// After a [`Renderer::render`] frame's bands all completed: what it kept is valid.
    pub(super) fn segments_stored(&mut self, setup: &RaySetup) {
        if let Some(cache) = self.targets.as_mut().and_then(|t| t.segments.as_mut())
            && setup.hull_cache != HullCache::Off
        {
            cache.valid = Some(SegmentsKey::of(setup));
        }
    }
}

/// Whether a frame of `setup` whose buffers are `targets` keeps its segments (its rays' are
/// not in the cache: another camera's or window's, none, or buffers of another size) or reads
/// them (`setup.hull_cache`), raising `setup.hull_hits` to the bound of segments it reads (kept
/// after an overflow, they hold every crossing). Turns the cache off and returns `None` where
/// it would not fit the device ([`fits`]), or without a hull.
pub(super) fn decide(
    info: &DeviceInfo,
    targets: Option<&FrameTargets>,
    setup: &mut RaySetup,
) -> Option<HullSegments> {
    let pixels = u64::from(setup.camera.width) * u64::from(setup.camera.height);
    if setup.hull_cache == HullCache::Off || !fits(info, pixels, setup.hull_hits) {
        setup.hull_cache = HullCache::Off;
        return None;
    }
    let held = targets
        .filter(|t| t.pixels == pixels)
        .and_then(|t| t.segments.as_ref())
        .and_then(|c| c.valid);
    if let Some(held) = held.filter(|h| h.serves(&SegmentsKey::of(setup))) {
        setup.hull_hits = held.hull_hits;
        setup.hull_cache = HullCache::Read;
        return Some(HullSegments::Reused);
    }
    setup.hull_cache = HullCache::Keep;
    Some(HullSegments::Found)
}

/// Once the frame's buffers are allocated: the cache allocated at the first frame that caches,
/// and, where the frame keeps, invalid (and pending for its own camera when it is `recorded`).
pub(super) fn mark(
    ctx: &Context,
    targets: &mut FrameTargets,
    setup: &RaySetup,
    recorded: bool,
) -> Result<(), VkError> {
    if setup.hull_cache == HullCache::Off {
        return Ok(());
    }
    // Room for this frame's bound (an overflow's frame again needs more).
    if targets
        .segments
        .as_ref()
        .is_none_or(|c| c.hull_hits < setup.hull_hits)
    {
        targets.segments = None;
        targets.segments = Some(SegmentCache::new(ctx, targets.pixels, setup.hull_hits)?);
    }
    if let Some(cache) = targets.segments.as_mut() {
        cache.pending = None;
        if setup.hull_cache == HullCache::Keep {
            cache.valid = None;
            cache.pending = recorded.then(|| SegmentsKey::of(setup));
        }
    }
    Ok(())
}

/// At a recorded frame's retire: the segments it stored are now in the texels.
pub(super) fn retire_segments(targets: &mut FrameTargets) {
    if let Some(cache) = targets.segments.as_mut()
        && let Some(key) = cache.pending.take()
    {
        cache.valid = Some(key);
    }
}
