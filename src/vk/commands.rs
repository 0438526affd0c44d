//! Recording and synchronous submission of compute work, with timestamp queries around every
//! dispatch.
//!
//! Synchronisation is deliberately simple: every command after the first waits for all earlier
//! compute and transfer writes (one global memory barrier), and the submission ends with a
//! barrier that makes all writes visible to the host. Submissions are waited for before
//! [`Context::submit`] returns, which is what lets buffers and bind groups be freed on drop
//! without tracking in-flight work.

use super::buffer::Buffer;
use super::context::{Context, Shared};
use super::pipeline::{BindGroup, ComputePipeline};
use super::{VkError, VkResultExt};
use ash::vk;

/// Timestamp pairs per submission; further dispatches run untimed.
const MAX_TIMED_DISPATCHES: u32 = 8192;

/// GPU time of one dispatch.
#[derive(Debug, Clone)]
pub struct DispatchTiming {
    pub label: String,
    /// Milliseconds between the timestamps around the dispatch; `None` when the device has no
    /// timestamps on this queue or the submission had too many dispatches.
    pub gpu_ms: Option<f64>,
}

/// Records commands into one command buffer; handed out by [`Context::submit`].
pub struct Recorder<'a> {
    pub(super) shared: &'a Shared,
    pub(super) cmd: vk::CommandBuffer,
    queries: Option<vk::QueryPool>,
    labels: Vec<String>,
    commands: u32,
}

impl<'a> Recorder<'a> {
    /// A recorder on the application's command buffer (`Context::record_into`): dispatches
    /// untimed.
    pub(super) fn external(shared: &'a Shared, cmd: vk::CommandBuffer) -> Self {
        Self {
            shared,
            cmd,
            queries: None,
            labels: Vec::new(),
            commands: 0,
        }
    }

    /// The global barrier between vmls's commands (none before the first).
    pub(super) fn barrier(&mut self) {
        if self.commands > 0 {
            let barrier = [vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(
                    vk::AccessFlags::INDIRECT_COMMAND_READ
                        | vk::AccessFlags::UNIFORM_READ
                        | vk::AccessFlags::SHADER_READ
                        | vk::AccessFlags::SHADER_WRITE
                        | vk::AccessFlags::TRANSFER_READ
                        | vk::AccessFlags::TRANSFER_WRITE,
                )];
            let src = vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER;
            let dst = src | vk::PipelineStageFlags::DRAW_INDIRECT;
            // SAFETY: `cmd` is in the recording state.
            unsafe {
                self.shared.device.cmd_pipeline_barrier(
                    self.cmd,
                    src,
                    dst,
                    vk::DependencyFlags::empty(),
                    &barrier,
                    &[],
                    &[],
                )
            };
        }
        self.commands += 1;
    }

    /// Records a dispatch of `groups` workgroups with `push` as push constants.
    pub fn dispatch(
        &mut self,
        pipeline: &ComputePipeline,
        bind_group: &BindGroup<'_>,
        push: &[u8],
        groups: [u32; 3],
        label: &str,
    ) -> Result<(), VkError> {
        let max = self.shared.info.max_workgroup_count;
        if groups.iter().zip(max.iter()).any(|(g, m)| g > m) || groups.contains(&0) {
            return Err(VkError::Usage(format!(
                "dispatch '{label}': {groups:?} workgroups (each must be in 1..={max:?}, maxComputeWorkGroupCount)"
            )));
        }
        self.record_dispatch(pipeline, bind_group, push, label, |device, cmd| {
            // SAFETY: called by `record_dispatch` with the pipeline and set bound on a
            // recording command buffer; the group counts were checked against the limits.
            unsafe { device.cmd_dispatch(cmd, groups[0], groups[1], groups[2]) }
        })
    }

    /// Records an indirect dispatch: the workgroup counts are three `u32` at byte `offset` of
    /// `args`, written before this submission or by an earlier command in it.
    pub fn dispatch_indirect(
        &mut self,
        pipeline: &ComputePipeline,
        bind_group: &BindGroup<'_>,
        push: &[u8],
        args: &Buffer,
        offset: u64,
        label: &str,
    ) -> Result<(), VkError> {
        if !offset.is_multiple_of(4) || offset + 12 > args.size() {
            return Err(VkError::Usage(format!(
                "dispatch '{label}': indirect arguments at byte {offset} of '{}' ({} bytes)",
                args.name(),
                args.size()
            )));
        }
        let handle = args.handle;
        self.record_dispatch(pipeline, bind_group, push, label, |device, cmd| {
            // SAFETY: as for `cmd_dispatch`; `args` is live with INDIRECT_BUFFER usage (every
            // storage buffer has it) and holds 12 bytes at the 4-aligned `offset` (checked
            // above). The global barrier also covers INDIRECT_COMMAND_READ (see `barrier`).
            unsafe { device.cmd_dispatch_indirect(cmd, handle, offset) }
        })
    }

    /// Barrier, timestamps, pipeline, descriptor set and push constants around `dispatch`,
    /// which records the dispatch command itself.
    fn record_dispatch(
        &mut self,
        pipeline: &ComputePipeline,
        bind_group: &BindGroup<'_>,
        push: &[u8],
        label: &str,
        dispatch: impl FnOnce(&ash::Device, vk::CommandBuffer),
    ) -> Result<(), VkError> {
        if push.len() != pipeline.push_size as usize {
            return Err(VkError::Usage(format!(
                "dispatch '{label}': {} bytes of push constants for pipeline '{}' which declares {}",
                push.len(),
                pipeline.name(),
                pipeline.push_size
            )));
        }
        self.barrier();
        let device = &self.shared.device;
        let index = u32::try_from(self.labels.len()).unwrap_or(u32::MAX);
        let timed = self.queries.filter(|_| index < MAX_TIMED_DISPATCHES);
        // SAFETY: `cmd` is recording; pipeline, layout and set are live and compatible (the
        // bind group was made for a pipeline with this set layout); push size was checked.
        unsafe {
            if let Some(pool) = timed {
                // The start is latched once every earlier command has completed (bottom of
                // pipe), not when the command is reached (top of pipe): the barrier above does
                // not order a top-of-pipe write, so on a GPU that runs ahead the interval
                // could include the previous dispatch's tail, and the frame's sum count it
                // twice. The barrier keeps this dispatch from starting before that point (the
                // first of a command buffer has none: it may overlap earlier submissions, and
                // its interval then leaves out the overlap).
                device.cmd_write_timestamp(
                    self.cmd,
                    vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                    pool,
                    2 * index,
                );
            }
            device.cmd_bind_pipeline(self.cmd, vk::PipelineBindPoint::COMPUTE, pipeline.pipeline);
            device.cmd_bind_descriptor_sets(
                self.cmd,
                vk::PipelineBindPoint::COMPUTE,
                pipeline.layout,
                0,
                &[bind_group.set],
                &[],
            );
            if !push.is_empty() {
                device.cmd_push_constants(
                    self.cmd,
                    pipeline.layout,
                    vk::ShaderStageFlags::COMPUTE,
                    0,
                    push,
                );
            }
        }
        dispatch(device, self.cmd);
        if let Some(pool) = timed {
            // SAFETY: as above; the query index is within the pool (index < MAX_TIMED).
            unsafe {
                device.cmd_write_timestamp(
                    self.cmd,
                    vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                    pool,
                    2 * index + 1,
                )
            };
        }
        self.labels.push(label.to_string());
        Ok(())
    }

    /// Copies `size` bytes from the start of `src` to the start of `dst`.
    pub fn copy_buffer(&mut self, src: &Buffer, dst: &Buffer, size: u64) {
        self.copy_buffer_from(src, 0, dst, size);
    }

    /// Copies `size` bytes from `src` at byte `src_offset` to the start of `dst` (clamped to
    /// both buffers).
    pub fn copy_buffer_from(&mut self, src: &Buffer, src_offset: u64, dst: &Buffer, size: u64) {
        self.barrier();
        let src_offset = src_offset.min(src.size());
        let size = size.min(src.size() - src_offset).min(dst.size());
        if size == 0 {
            // A copy region of size 0 is invalid (VUID-VkBufferCopy-size-01988): an empty
            // upload copies nothing.
            return;
        }
        let region = [vk::BufferCopy::default().src_offset(src_offset).size(size)];
        // SAFETY: `cmd` is recording; both buffers are live with TRANSFER usage.
        unsafe {
            self.shared
                .device
                .cmd_copy_buffer(self.cmd, src.handle, dst.handle, &region)
        };
    }

    /// Fills the whole buffer with a 32-bit pattern.
    pub fn fill(&mut self, buffer: &Buffer, value: u32) {
        self.barrier();
        // SAFETY: `cmd` is recording; the buffer is live with TRANSFER_DST usage and its size is a
        // multiple of 4.
        unsafe {
            self.shared
                .device
                .cmd_fill_buffer(self.cmd, buffer.handle, 0, vk::WHOLE_SIZE, value)
        };
    }
}

/// The command pool, command buffer, fence and timestamp pool of one submission. The context
/// keeps finished ones ([`Shared::spare_submits`]) and later submissions reset and reuse them:
/// creating a 16 384-query pool, a pool and a fence per frame costs driver time, and every
/// object created and destroyed per frame is state a validation layer tracks.
pub(crate) struct SubmitObjects {
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    queries: Option<vk::QueryPool>,
}

/// Spare submission objects kept per context; a burst of concurrent submissions beyond this
/// destroys its extras.
const MAX_SPARE_SUBMITS: usize = 4;

impl SubmitObjects {
    fn create(shared: &Shared) -> Result<Self, VkError> {
        let device = &shared.device;
        let what = || "a compute submission".to_string();
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(shared.queue_family)
            .flags(vk::CommandPoolCreateFlags::TRANSIENT);
        // SAFETY: valid create info on a live device.
        let pool = unsafe { device.create_command_pool(&pool_info, None) }
            .call("vkCreateCommandPool", what)?;
        // Every later failure destroys what exists so far through `Drop`.
        let mut made = Lease {
            shared,
            objects: Some(Self {
                pool,
                cmd: vk::CommandBuffer::null(),
                fence: vk::Fence::null(),
                queries: None,
            }),
            reusable: false,
        };
        let objects = made
            .objects
            .as_mut()
            .ok_or_else(|| VkError::Usage("submission objects vanished while being made".into()))?;
        // SAFETY: as above.
        objects.fence = unsafe { device.create_fence(&vk::FenceCreateInfo::default(), None) }
            .call("vkCreateFence", what)?;
        if shared.info.timestamp_period_ns.is_some() {
            let info = vk::QueryPoolCreateInfo::default()
                .query_type(vk::QueryType::TIMESTAMP)
                .query_count(2 * MAX_TIMED_DISPATCHES);
            // SAFETY: valid create info.
            let pool = unsafe { device.create_query_pool(&info, None) };
            objects.queries = Some(pool.call("vkCreateQueryPool", what)?);
        }
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool is live.
        objects.cmd = unsafe { device.allocate_command_buffers(&alloc) }
            .call("vkAllocateCommandBuffers", what)?
            .into_iter()
            .next()
            .ok_or_else(|| VkError::Usage("no command buffer allocated".into()))?;
        made.objects
            .take()
            .ok_or_else(|| VkError::Usage("submission objects vanished while being made".into()))
    }

    /// Destroys the objects (null handles are ignored by Vulkan's destroy calls).
    ///
    /// # Safety
    /// No submission using them may be pending.
    pub(crate) unsafe fn destroy(self, device: &ash::Device) {
        // SAFETY: the caller guarantees nothing pending uses these objects; destroying the
        // pool frees its command buffer.
        unsafe {
            if let Some(q) = self.queries {
                device.destroy_query_pool(q, None);
            }
            device.destroy_fence(self.fence, None);
            device.destroy_command_pool(self.pool, None);
        }
    }
}

/// One submission's hold on its objects: back to the context's spares when the submission
/// finished (`reusable`), destroyed otherwise, on every exit path.
struct Lease<'a> {
    shared: &'a Shared,
    objects: Option<SubmitObjects>,
    reusable: bool,
}

impl Drop for Lease<'_> {
    fn drop(&mut self) {
        let Some(objects) = self.objects.take() else {
            return;
        };
        if self.reusable {
            let mut spares = self.shared.spare_submits();
            if spares.len() < MAX_SPARE_SUBMITS {
                spares.push(objects);
                return;
            }
        }
        // SAFETY: not reusable means the submission failed before or while executing; a
        // failed wait (device lost) leaves nothing the device will still run, and an
        // unsubmitted command buffer is not pending. Reusable extras finished executing.
        unsafe { objects.destroy(&self.shared.device) };
    }
}

impl Context {
    /// Records commands with `record`, submits them to the compute queue and waits. Returns the
    /// GPU time of each dispatch in recording order.
    pub fn submit(
        &self,
        record: impl FnOnce(&mut Recorder<'_>) -> Result<(), VkError>,
    ) -> Result<Vec<DispatchTiming>, VkError> {
        let shared = &*self.shared;
        let device = &shared.device;
        let what = || "a compute submission".to_string();
        let spare = shared.spare_submits().pop();
        let objects = match spare {
            Some(o) => {
                // SAFETY: spares finished executing (their fence was waited for); resetting
                // the pool returns its command buffer to the initial state.
                unsafe {
                    device
                        .reset_command_pool(o.pool, vk::CommandPoolResetFlags::empty())
                        .call("vkResetCommandPool", what)?;
                    device
                        .reset_fences(&[o.fence])
                        .call("vkResetFences", what)?;
                }
                o
            }
            None => SubmitObjects::create(shared)?,
        };
        let (cmd, fence, queries) = (objects.cmd, objects.fence, objects.queries);
        let mut lease = Lease {
            shared,
            objects: Some(objects),
            reusable: false,
        };
        let begin = vk::CommandBufferBeginInfo::default()
            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: fresh command buffer.
        unsafe { device.begin_command_buffer(cmd, &begin) }.call("vkBeginCommandBuffer", what)?;
        if let Some(q) = queries {
            // SAFETY: recording; the pool has this many queries.
            unsafe { device.cmd_reset_query_pool(cmd, q, 0, 2 * MAX_TIMED_DISPATCHES) };
        }
        let mut recorder = Recorder {
            shared,
            cmd,
            queries,
            labels: Vec::new(),
            commands: 0,
        };
        let recorded = record(&mut recorder);
        let labels = std::mem::take(&mut recorder.labels);
        // Make every write visible to the host before the fence signals (readbacks map memory).
        let to_host = [vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ)];
        // SAFETY: recording.
        unsafe {
            device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &to_host,
                &[],
                &[],
            )
        };
        // SAFETY: recording.
        unsafe { device.end_command_buffer(cmd) }.call("vkEndCommandBuffer", what)?;
        if recorded.is_err() {
            // Never submitted: the pool reset on reuse discards the recording.
            lease.reusable = true;
        }
        recorded?;
        let cmds = [cmd];
        let submit = [vk::SubmitInfo::default().command_buffers(&cmds)];
        {
            let queue = shared.queue();
            // SAFETY: the command buffer is executable; the queue is externally synchronised by
            // the mutex guard.
            unsafe { device.queue_submit(*queue, &submit, fence) }.call("vkQueueSubmit", what)?;
        }
        // SAFETY: the fence belongs to this submission.
        unsafe { device.wait_for_fences(&[fence], true, u64::MAX) }
            .call("vkWaitForFences", what)?;
        lease.reusable = true;
        let mut timings: Vec<DispatchTiming> = labels
            .into_iter()
            .map(|label| DispatchTiming {
                label,
                gpu_ms: None,
            })
            .collect();
        if let (Some(q), Some(period)) = (queries, shared.info.timestamp_period_ns) {
            let n = timings.len().min(MAX_TIMED_DISPATCHES as usize);
            if n > 0 {
                let mut stamps = vec![0u64; 2 * n];
                // SAFETY: the submission completed, so these queries are available.
                unsafe {
                    device.get_query_pool_results(
                        q,
                        0,
                        &mut stamps,
                        vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                    )
                }
                .call("vkGetQueryPoolResults", what)?;
                for (i, t) in timings.iter_mut().take(n).enumerate() {
                    let ticks = stamps[2 * i + 1].saturating_sub(stamps[2 * i]);
                    t.gpu_ms = Some(ticks as f64 * period * 1e-6);
                }
            }
        }
        drop(lease);
        Ok(timings)
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Buffer, BufferUsage, ContextOptions};
    use super::*;

    /// Synchronization validation is live in the test suite: two fills of one buffer with the
    /// global barrier between them are clean, the same two fills with the barrier suppressed
    /// (a write-after-write hazard) are reported. A test run whose layer missed hazards would
    /// make every "zero validation messages" assertion meaningless.
    #[test]
    fn synchronization_validation_reports_a_missing_barrier() {
        let ctx = Context::new(&ContextOptions {
            validation: Some(true),
            sync_validation: Some(true),
            ..ContextOptions::default()
        })
        .unwrap_or_else(|e| panic!("no validated Vulkan device (run tools/setup): {e}"));
        let buffer = Buffer::new(&ctx, "hazard", 256, BufferUsage::Storage).expect("buffer");
        let fills = |suppress_barrier: bool| {
            ctx.submit(|r| {
                r.fill(&buffer, 1);
                if suppress_barrier {
                    // The recorder only skips its barrier before the first command.
                    r.commands = 0;
                }
                r.fill(&buffer, 2);
                Ok(())
            })
            .expect("submit");
        };
        fills(false);
        assert_eq!(ctx.validation_errors(), 0, "clean fills reported");
        fills(true);
        assert!(
            ctx.validation_errors() > 0,
            "a write-after-write hazard went unreported: synchronization validation is off"
        );
    }
}
