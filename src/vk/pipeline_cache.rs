//! The context's `VkPipelineCache` (issue 28 §2): every compute pipeline vmls creates goes
//! through it, and an application may read it back ([`Context::pipeline_cache_data`]) and hand
//! it to the next run ([`Context::load_pipeline_cache`]), as it does for its own pipelines, so a
//! driver that compiles SPIR-V to machine code at pipeline creation does it once.
//!
//! Contract:
//! - The cache is vmls's own object, created empty with the context and destroyed with it,
//!   also on a device the application made (`Context::from_raw`). A device that cannot create
//!   one leaves it null: pipelines are then created uncached, which is still correct.
//! - Loaded data is used only when its header (Vulkan's `VkPipelineCacheHeaderVersionOne`) names
//!   this device: length ≥ 32, version 1, vendor and device ID and `pipelineCacheUUID` equal to
//!   the device's; anything else is ignored and `load_pipeline_cache` says so by returning
//!   `false`. Usable data is merged into the cache (the merge is serialised by a lock, as
//!   Vulkan requires of the destination).

use super::{Context, DeviceInfo, VkError};
use ash::vk;

/// An empty cache on `device`, or null where the device cannot make one.
pub(crate) fn create(device: &ash::Device) -> vk::PipelineCache {
    let info = vk::PipelineCacheCreateInfo::default();
    // SAFETY: a plain object creation on a live device; failure is handled as "no cache".
    unsafe { device.create_pipeline_cache(&info, None) }.unwrap_or(vk::PipelineCache::null())
}

/// Whether `data` starts with a pipeline-cache header for this device.
pub(crate) fn compatible(data: &[u8], info: &DeviceInfo) -> bool {
    let word = |i: usize| {
        data.get(4 * i..4 * i + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let header = word(0).is_some_and(|len| len >= 32 && data.len() >= len as usize);
    header
        && word(1) == Some(vk::PipelineCacheHeaderVersion::ONE.as_raw() as u32)
        && word(2) == Some(info.vendor_id)
        && word(3) == Some(info.device_id)
        && data.get(16..32) == Some(&info.pipeline_cache_uuid[..])
}

impl Context {
    /// The pipeline cache's contents (empty where the device made none), for
    /// [`Context::load_pipeline_cache`] in a later run.
    pub fn pipeline_cache_data(&self) -> Result<Vec<u8>, VkError> {
        let cache = self.shared.pipeline_cache;
        if cache == vk::PipelineCache::null() {
            return Ok(Vec::new());
        }
        // SAFETY: the cache belongs to this live device; reading needs no external lock.
        unsafe { self.shared.device.get_pipeline_cache_data(cache) }.map_err(|result| {
            VkError::Call {
                call: "vkGetPipelineCacheData",
                what: "the pipeline cache".into(),
                result,
            }
        })
    }

    /// Merges `data` from [`Context::pipeline_cache_data`] of an earlier run into this
    /// context's cache; `Ok(false)` when it was not made by this device (and is ignored).
    pub fn load_pipeline_cache(&self, data: &[u8]) -> Result<bool, VkError> {
        let dst = self.shared.pipeline_cache;
        if dst == vk::PipelineCache::null() || !compatible(data, &self.shared.info) {
            return Ok(false);
        }
        let device = &self.shared.device;
        let call = |call: &'static str| {
            move |result| VkError::Call {
                call,
                what: "the pipeline cache".into(),
                result,
            }
        };
        let info = vk::PipelineCacheCreateInfo::default().initial_data(data);
        // SAFETY: `data` outlives the call and its header was checked against this device.
        let src = unsafe { device.create_pipeline_cache(&info, None) }
            .map_err(call("vkCreatePipelineCache"))?;
        let merged = {
            let _merge = self
                .shared
                .pipeline_cache_merge
                .lock()
                .unwrap_or_else(|p| p.into_inner());
            // SAFETY: both caches belong to this device; the lock is the destination's
            // external synchronisation, and `src` is used by nothing else.
            unsafe { device.merge_pipeline_caches(dst, &[src]) }
        };
        // SAFETY: `src` was only used by the merge above, which has returned.
        unsafe { device.destroy_pipeline_cache(src, None) };
        merged.map_err(call("vkMergePipelineCaches"))?;
        Ok(true)
    }
}
