//! Recording into a command buffer the application owns, and writing into its buffer or image:
//! what `Renderer::record` is built on.
//!
//! Contract: the application promises, once, when it wraps a raw handle ([`ExternalCommands`],
//! [`Target`]) that the handle belongs to the context's device and is in the state the wrapper
//! names; from then on recording is safe Rust. Commands recorded here follow the same simple
//! synchronisation as [`Context::submit`] (one global barrier between vmls's own commands) and
//! add, around the application's resource, exactly the barriers its [`Access`] values ask for.
//! Nothing here submits, waits or frees: the application submits the command buffer, and the
//! frame's owner keeps every buffer it recorded alive until the application reports the
//! submission complete.

use super::buffer::Buffer;
use super::commands::Recorder;
use super::context::{Context, Shared};
use super::{VkError, VkResultExt};
use ash::vk;
use std::sync::Arc;

/// Pipeline stages and memory accesses of a resource on one side of vmls's commands: what the
/// application did before them (vmls waits for it) or will do after them (vmls's writes are made
/// available and visible to it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Access {
    pub stages: vk::PipelineStageFlags,
    pub access: vk::AccessFlags,
}

impl Access {
    /// Nothing to wait for (a resource not used before, or whose last use the application
    /// already waited for with a fence).
    pub const NONE: Self = Self {
        stages: vk::PipelineStageFlags::TOP_OF_PIPE,
        access: vk::AccessFlags::empty(),
    };
    /// Read by a compute shader.
    pub const COMPUTE_READ: Self = Self {
        stages: vk::PipelineStageFlags::COMPUTE_SHADER,
        access: vk::AccessFlags::SHADER_READ,
    };
    /// Sampled or read by a fragment shader.
    pub const FRAGMENT_READ: Self = Self {
        stages: vk::PipelineStageFlags::FRAGMENT_SHADER,
        access: vk::AccessFlags::SHADER_READ,
    };
    /// The source of a transfer (a copy or blit out of the resource).
    pub const TRANSFER_READ: Self = Self {
        stages: vk::PipelineStageFlags::TRANSFER,
        access: vk::AccessFlags::TRANSFER_READ,
    };
    /// Read by the host after the submission's fence (a readback).
    pub const HOST_READ: Self = Self {
        stages: vk::PipelineStageFlags::HOST,
        access: vk::AccessFlags::HOST_READ,
    };
}

/// A command buffer of the application, in the recording state, outside a render pass,
/// allocated from a pool of the context's queue family.
#[derive(Debug, Clone, Copy)]
pub struct ExternalCommands {
    handle: vk::CommandBuffer,
}

impl ExternalCommands {
    /// Wraps `handle`.
    ///
    /// # Safety
    /// `handle` is a command buffer of the context's device, allocated from a pool of the
    /// context's queue family, in the recording state and outside a render pass, and no other
    /// thread records into it while vmls does. What vmls records into it must complete before
    /// the renderer that recorded it is dropped (or the command buffer must be discarded
    /// unsubmitted), and a command buffer into which a `record` failed must not be submitted:
    /// the descriptor sets it names are gone.
    pub unsafe fn new(handle: vk::CommandBuffer) -> Self {
        Self { handle }
    }

    pub fn handle(&self) -> vk::CommandBuffer {
        self.handle
    }
}

/// The pixel formats an image target may have. Pixels are converted on the GPU where the
/// format is not the frame's own RGBA32F (see `glsl/common/target_pack.comp`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TargetFormat {
    /// `R32G32B32A32_SFLOAT`: the frame as rendered.
    Rgba32f,
    /// `R16G16B16A16_SFLOAT`: each channel rounded to the nearest half.
    Rgba16f,
    /// `R8G8B8A8_UNORM`: each channel clamped to [0, 1], ×255, rounded.
    Rgba8Unorm,
    /// `R8G8B8A8_SRGB`: colour channels sRGB-encoded before the 8-bit rounding, alpha linear.
    Rgba8Srgb,
}

impl TargetFormat {
    /// Bytes per pixel.
    pub fn bytes(self) -> u64 {
        match self {
            Self::Rgba32f => 16,
            Self::Rgba16f => 8,
            Self::Rgba8Unorm | Self::Rgba8Srgb => 4,
        }
    }

    /// The matching Vulkan format.
    pub fn vk_format(self) -> vk::Format {
        match self {
            Self::Rgba32f => vk::Format::R32G32B32A32_SFLOAT,
            Self::Rgba16f => vk::Format::R16G16B16A16_SFLOAT,
            Self::Rgba8Unorm => vk::Format::R8G8B8A8_UNORM,
            Self::Rgba8Srgb => vk::Format::R8G8B8A8_SRGB,
        }
    }
}

#[derive(Debug, Clone, Copy)]
enum TargetKind {
    Buffer {
        buffer: vk::Buffer,
        offset: u64,
        size: u64,
    },
    Image {
        image: vk::Image,
        format: TargetFormat,
        old_layout: vk::ImageLayout,
        new_layout: vk::ImageLayout,
    },
}

/// Where a recorded frame's pixels go: a buffer or an image that the application owns.
///
/// vmls writes the target once per frame, with a transfer (`vkCmdCopyBuffer` or
/// `vkCmdCopyBufferToImage`): a buffer needs `TRANSFER_DST` usage, an image `TRANSFER_DST`
/// usage, mip level 0 and array layer 0 of the colour aspect, and an extent of at least the
/// frame's width × height. Before the copy vmls waits for `before` (and moves an image from
/// `old_layout` to `TRANSFER_DST_OPTIMAL`); after it, the write is made available and visible
/// to `after` (and the image moved to `new_layout`).
#[derive(Debug, Clone, Copy)]
pub struct Target {
    kind: TargetKind,
    before: Access,
    after: Access,
}

impl Target {
    /// A buffer of RGBA32F pixels, 16 bytes each, row 0 at the top, starting at byte `offset`
    /// (a multiple of 4); `size` is the bytes the application made room for from there.
    ///
    /// # Safety
    /// `buffer` is a live buffer of the context's device with `TRANSFER_DST` usage and at
    /// least `offset + size` bytes, and stays alive until the frame that writes it completes.
    pub unsafe fn buffer(
        buffer: vk::Buffer,
        offset: u64,
        size: u64,
        before: Access,
        after: Access,
    ) -> Self {
        Self {
            kind: TargetKind::Buffer {
                buffer,
                offset,
                size,
            },
            before,
            after,
        }
    }

    /// A 2D image of `format`, in `old_layout` when vmls's commands start (`UNDEFINED`
    /// discards its contents) and left in `new_layout`.
    ///
    /// # Safety
    /// `image` is a live image of the context's device with `TRANSFER_DST` usage, `format`,
    /// an extent of at least the frame's size, and (unless `old_layout` is `UNDEFINED`) in
    /// `old_layout` when the frame's commands execute; it stays alive until the frame
    /// completes.
    pub unsafe fn image(
        image: vk::Image,
        format: TargetFormat,
        old_layout: vk::ImageLayout,
        new_layout: vk::ImageLayout,
        before: Access,
        after: Access,
    ) -> Self {
        Self {
            kind: TargetKind::Image {
                image,
                format,
                old_layout,
                new_layout,
            },
            before,
            after,
        }
    }

    /// The format vmls must deliver: RGBA32F for a buffer.
    pub fn format(&self) -> TargetFormat {
        match self.kind {
            TargetKind::Buffer { .. } => TargetFormat::Rgba32f,
            TargetKind::Image { format, .. } => format,
        }
    }

    /// Refuses a buffer too small for `pixels` pixels or misaligned, and a layout an image
    /// cannot be left in.
    pub fn check(&self, pixels: u64) -> Result<(), VkError> {
        match self.kind {
            TargetKind::Buffer { offset, size, .. } => {
                if !offset.is_multiple_of(4) || pixels.checked_mul(16).is_none_or(|b| size < b) {
                    return Err(VkError::Usage(format!(
                        "target buffer: expected at least {} bytes at a 4-aligned offset for \
                         {pixels} RGBA32F pixels, found {size} bytes at offset {offset}",
                        pixels.saturating_mul(16)
                    )));
                }
            }
            TargetKind::Image { new_layout, .. } => {
                if matches!(
                    new_layout,
                    vk::ImageLayout::UNDEFINED | vk::ImageLayout::PREINITIALIZED
                ) {
                    return Err(VkError::Usage(format!(
                        "target image: expected a layout to leave the image in, found \
                         {new_layout:?}"
                    )));
                }
            }
        }
        Ok(())
    }
}

/// Two timestamps around a recorded frame, in a query pool of its own (none where the queue
/// has no timestamps).
pub struct FrameTimer {
    shared: Arc<Shared>,
    pool: Option<vk::QueryPool>,
}

impl FrameTimer {
    pub fn new(ctx: &Context) -> Result<Self, VkError> {
        let shared = ctx.shared.clone();
        let pool = match shared.info.timestamp_period_ns {
            None => None,
            Some(_) => {
                let info = vk::QueryPoolCreateInfo::default()
                    .query_type(vk::QueryType::TIMESTAMP)
                    .query_count(2);
                // SAFETY: valid create info on a live device.
                let pool = unsafe { shared.device.create_query_pool(&info, None) };
                Some(pool.call("vkCreateQueryPool", || "a frame's timestamps".into())?)
            }
        };
        Ok(Self { shared, pool })
    }

    /// The frame's GPU milliseconds once it has completed (the owner knows it has): `Ok(None)`
    /// without timestamps, or if they are not available.
    pub fn gpu_ms(&self) -> Result<Option<f64>, VkError> {
        let (Some(pool), Some(period)) = (self.pool, self.shared.info.timestamp_period_ns) else {
            return Ok(None);
        };
        let mut stamps = [0u64; 2];
        // SAFETY: the pool has two queries; without WAIT the call returns NOT_READY instead
        // of blocking when the frame has not completed.
        let result = unsafe {
            self.shared.device.get_query_pool_results(
                pool,
                0,
                &mut stamps,
                vk::QueryResultFlags::TYPE_64,
            )
        };
        match result {
            Ok(()) => Ok(Some(
                stamps[1].saturating_sub(stamps[0]) as f64 * period * 1e-6,
            )),
            Err(vk::Result::NOT_READY) => Ok(None),
            Err(result) => Err(VkError::Call {
                call: "vkGetQueryPoolResults",
                what: "a frame's timestamps".into(),
                result,
            }),
        }
    }
}

impl Drop for FrameTimer {
    fn drop(&mut self) {
        if let Some(pool) = self.pool {
            // SAFETY: the owner drops the timer only after the frame that used it completed.
            unsafe { self.shared.device.destroy_query_pool(pool, None) };
        }
    }
}

impl Context {
    /// Waits until the context's queue is idle: what an owner of recorded frames that were
    /// never retired does before freeing their buffers.
    pub fn wait_queue_idle(&self) -> Result<(), VkError> {
        let queue = self.shared.queue();
        // SAFETY: the queue is externally synchronised by the mutex guard.
        unsafe { self.shared.device.queue_wait_idle(*queue) }
            .call("vkQueueWaitIdle", || "the context's queue".into())
    }

    /// Records vmls's commands into the application's command buffer: `record` gets a
    /// [`Recorder`] on it (its dispatches untimed; `timer`, if given, takes the frame's start and
    /// end). The recording ends with a barrier that makes vmls's writes visible to the host,
    /// for the readback after the application's fence. Nothing is submitted.
    pub fn record_into(
        &self,
        cmd: ExternalCommands,
        timer: Option<&FrameTimer>,
        record: impl FnOnce(&mut Recorder<'_>) -> Result<(), VkError>,
    ) -> Result<(), VkError> {
        let shared = &*self.shared;
        let device = &shared.device;
        let pool = timer.and_then(|t| t.pool);
        if let Some(pool) = pool {
            // SAFETY: `cmd` is recording outside a render pass (ExternalCommands::new); the
            // pool has two queries.
            unsafe {
                device.cmd_reset_query_pool(cmd.handle, pool, 0, 2);
                device.cmd_write_timestamp(
                    cmd.handle,
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    pool,
                    0,
                );
            }
        }
        let mut recorder = Recorder::external(shared, cmd.handle);
        record(&mut recorder)?;
        let to_host = [vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ)];
        // SAFETY: recording (as above).
        unsafe {
            device.cmd_pipeline_barrier(
                cmd.handle,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &to_host,
                &[],
                &[],
            );
            if let Some(pool) = pool {
                device.cmd_write_timestamp(
                    cmd.handle,
                    vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                    pool,
                    1,
                );
            }
        }
        Ok(())
    }
}

impl Recorder<'_> {
    /// Writes `bytes` to the start of `buffer` from the command buffer (`vkCmdUpdateBuffer`,
    /// 64 KiB at a time): per-frame constants of a recorded frame, with no host wait.
    pub fn update(&mut self, buffer: &Buffer, bytes: &[u8]) -> Result<(), VkError> {
        if bytes.len() as u64 > buffer.size() || !bytes.len().is_multiple_of(4) {
            return Err(VkError::Usage(format!(
                "update of {} bytes into buffer '{}' of {} bytes (a multiple of 4 that fits)",
                bytes.len(),
                buffer.name(),
                buffer.size()
            )));
        }
        // One barrier against earlier commands; the parts write disjoint ranges.
        self.barrier();
        for (i, part) in bytes.chunks(65536).enumerate() {
            // SAFETY: recording; the buffer is live with TRANSFER_DST usage; the part is at
            // most 65536 bytes, a multiple of 4, at a 4-aligned offset inside the buffer.
            unsafe {
                self.shared.device.cmd_update_buffer(
                    self.cmd,
                    buffer.handle,
                    (i * 65536) as u64,
                    part,
                )
            };
        }
        Ok(())
    }

    /// Copies `pixels` pixels of `src` (`format.bytes()` each, row-major, `width` wide) into
    /// the application's target, with the barriers its accesses and layouts ask for.
    pub fn write_target(
        &mut self,
        src: &Buffer,
        target: &Target,
        width: u32,
        height: u32,
    ) -> Result<(), VkError> {
        let pixels = u64::from(width) * u64::from(height);
        target.check(pixels)?;
        let bytes = pixels * target.format().bytes();
        if bytes > src.size() {
            return Err(VkError::Usage(format!(
                "target copy of {bytes} bytes from buffer '{}' of {} bytes",
                src.name(),
                src.size()
            )));
        }
        // vmls's own writes to `src` before the copy.
        self.barrier();
        let (before, after) = (target.before, target.after);
        let write = vk::AccessFlags::TRANSFER_WRITE;
        match target.kind {
            TargetKind::Buffer { buffer, offset, .. } => {
                let barrier = |src, dst| {
                    [vk::BufferMemoryBarrier::default()
                        .src_access_mask(src)
                        .dst_access_mask(dst)
                        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .buffer(buffer)
                        .offset(offset)
                        .size(bytes)]
                };
                let (wait, release) = (barrier(before.access, write), barrier(write, after.access));
                let region = [vk::BufferCopy::default().dst_offset(offset).size(bytes)];
                self.around_copy(
                    before,
                    after,
                    (&wait, &[]),
                    (&release, &[]),
                    |device, cmd| {
                        // SAFETY: recording; `buffer` is the application's live buffer with
                        // TRANSFER_DST usage and offset + bytes within it (Target::buffer, checked
                        // above); `src` is live with TRANSFER_SRC usage and holds `bytes`.
                        unsafe { device.cmd_copy_buffer(cmd, src.handle, buffer, &region) }
                    },
                );
            }
            TargetKind::Image {
                image,
                old_layout,
                new_layout,
                ..
            } => {
                let range = vk::ImageSubresourceRange::default()
                    .aspect_mask(vk::ImageAspectFlags::COLOR)
                    .level_count(1)
                    .layer_count(1);
                let barrier = |src, dst, old, new| {
                    [vk::ImageMemoryBarrier::default()
                        .src_access_mask(src)
                        .dst_access_mask(dst)
                        .old_layout(old)
                        .new_layout(new)
                        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .image(image)
                        .subresource_range(range)]
                };
                let dst_layout = vk::ImageLayout::TRANSFER_DST_OPTIMAL;
                let wait = barrier(before.access, write, old_layout, dst_layout);
                let release = barrier(write, after.access, dst_layout, new_layout);
                let region = [vk::BufferImageCopy::default()
                    .image_subresource(
                        vk::ImageSubresourceLayers::default()
                            .aspect_mask(vk::ImageAspectFlags::COLOR)
                            .layer_count(1),
                    )
                    .image_extent(vk::Extent3D {
                        width,
                        height,
                        depth: 1,
                    })];
                self.around_copy(
                    before,
                    after,
                    (&[], &wait),
                    (&[], &release),
                    |device, cmd| {
                        // SAFETY: recording; `image` is the application's live TRANSFER_DST
                        // image of the target's format, ≥ width × height texels (Target::image),
                        // TRANSFER_DST_OPTIMAL after the wait; `src`: those pixels, packed.
                        unsafe {
                            device.cmd_copy_buffer_to_image(
                                cmd, src.handle, image, dst_layout, &region,
                            )
                        }
                    },
                );
            }
        }
        Ok(())
    }

    /// `copy` (a transfer into the application's target) between the barriers that wait for
    /// the target's `before` access and release it to its `after` access.
    fn around_copy(
        &mut self,
        before: Access,
        after: Access,
        wait: (
            &[vk::BufferMemoryBarrier<'_>],
            &[vk::ImageMemoryBarrier<'_>],
        ),
        release: (
            &[vk::BufferMemoryBarrier<'_>],
            &[vk::ImageMemoryBarrier<'_>],
        ),
        copy: impl FnOnce(&ash::Device, vk::CommandBuffer),
    ) {
        let device = &self.shared.device;
        let transfer = vk::PipelineStageFlags::TRANSFER;
        let none = vk::DependencyFlags::empty();
        // SAFETY: recording; the barriers name the application's live target (Target's
        // constructors) and stages its queue family supports (the record contract).
        unsafe {
            device.cmd_pipeline_barrier(
                self.cmd,
                before.stages,
                transfer,
                none,
                &[],
                wait.0,
                wait.1,
            )
        };
        copy(device, self.cmd);
        // SAFETY: as above.
        unsafe {
            device.cmd_pipeline_barrier(
                self.cmd,
                transfer,
                after.stages,
                none,
                &[],
                release.0,
                release.1,
            )
        };
    }
}
