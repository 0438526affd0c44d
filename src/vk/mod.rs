//! The Vulkan layer: the only module of vmls that contains `unsafe`.
//!
//! Contract:
//! - [`Context`] owns (or wraps) an instance, a device with one compute queue and a gpu-allocator
//!   allocator; every resource ([`Buffer`], [`ComputePipeline`], [`BindGroup`]) holds an `Arc` to
//!   the context's shared state, so the device is destroyed only after the last resource.
//! - Every Vulkan or allocator failure is a [`VkError`] naming the call and the resource; no
//!   function here panics on a driver result.
//! - With validation on, the Khronos layer's error messages are counted
//!   ([`Context::validation_errors`]); tests fail when the count is non-zero.
//! - Work is recorded through [`Recorder`] and submitted synchronously by [`Context::submit`],
//!   which returns the GPU time of every dispatch from timestamp queries, or recorded into the
//!   application's command buffer by [`Context::record_into`], which submits nothing.

mod buffer;
mod commands;
mod context;
mod external;
mod pipeline;
mod pipeline_cache;
mod shader;
mod shader_cache;

pub use buffer::{Buffer, BufferUsage, check_size, check_texel_view};
pub use commands::{DispatchTiming, Recorder};
pub use context::{Context, ContextOptions, DeviceInfo, FAIL_ALLOCATIONS_VAR, RawContext};
pub use external::{Access, ExternalCommands, FrameTimer, Target, TargetFormat};
pub(crate) use pipeline::TEXEL_FORMATS;
pub use pipeline::{BindGroup, BindingKind, ComputePipeline};
pub use shader::{ShaderCompiler, ShaderSource, shader_counts, shader_names, source_texts};
pub use shader_cache::use_disk_cache;

use ash::vk;

/// Errors of the Vulkan layer.
#[derive(Debug, thiserror::Error)]
pub enum VkError {
    #[error("cannot load the Vulkan loader (libvulkan.so.1): {0}; run tools/setup")]
    Loading(String),
    #[error(
        "the Vulkan device was lost in {call} for {what} (a driver reset, a GPU fault, or a \
         dispatch that ran past the system's GPU watchdog); the render stopped and wrote nothing"
    )]
    DeviceLost { call: &'static str, what: String },
    #[error("{call} failed for {what}: {result}")]
    Call {
        call: &'static str,
        what: String,
        result: vk::Result,
    },
    #[error("no Vulkan device with a compute queue was found{0}")]
    NoDevice(String),
    #[error("no Vulkan device matches '{wanted}'; available: {available}")]
    DeviceNotFound { wanted: String, available: String },
    #[error(
        "the Khronos validation layer was requested but is not installed (package vulkan-validationlayers; run tools/setup)"
    )]
    NoValidationLayer,
    #[error("out of GPU memory allocating {bytes} bytes for {resource}: {source}")]
    OutOfMemory {
        resource: String,
        bytes: u64,
        #[source]
        source: gpu_allocator::AllocationError,
    },
    #[error("cannot allocate {bytes} bytes for {resource}: {source}")]
    Allocation {
        resource: String,
        bytes: u64,
        #[source]
        source: gpu_allocator::AllocationError,
    },
    #[error("{resource} needs {bytes} bytes but the device allows at most {limit} ({limit_name})")]
    Limit {
        resource: String,
        bytes: u64,
        limit: u64,
        limit_name: &'static str,
    },
    #[error("shader {name}: {message}")]
    Shader { name: String, message: String },
    #[error("{0}")]
    Usage(String),
    /// Work recorded into the application's command buffer has not completed yet.
    #[error("{0}")]
    NotReady(String),
}

/// Attaches the call name and the resource to a raw `vk::Result`.
pub(crate) trait VkResultExt<T> {
    fn call(self, call: &'static str, what: impl FnOnce() -> String) -> Result<T, VkError>;
}

impl<T> VkResultExt<T> for Result<T, vk::Result> {
    fn call(self, call: &'static str, what: impl FnOnce() -> String) -> Result<T, VkError> {
        self.map_err(|result| match result {
            vk::Result::ERROR_DEVICE_LOST => VkError::DeviceLost { call, what: what() },
            result => VkError::Call {
                call,
                what: what(),
                result,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn device_loss_is_named_and_other_results_keep_their_code() {
        let lost: Result<(), vk::Result> = Err(vk::Result::ERROR_DEVICE_LOST);
        let e = lost
            .call("vkWaitForFences", || "the raycast dispatch".into())
            .expect_err("lost");
        assert!(matches!(e, VkError::DeviceLost { .. }), "{e:?}");
        let text = e.to_string();
        assert!(
            text.contains("device was lost") && text.contains("raycast"),
            "{text}"
        );
        let oom: Result<(), vk::Result> = Err(vk::Result::ERROR_OUT_OF_DEVICE_MEMORY);
        let e = oom
            .call("vkAllocateMemory", || "x".into())
            .expect_err("oom");
        assert!(matches!(e, VkError::Call { .. }), "{e:?}");
        assert!(
            e.to_string().contains("vkAllocateMemory failed for x"),
            "{e}"
        );
    }
}
