//! Compute pipelines whose interface is a list of storage-buffer bindings plus push constants,
//! and bind groups (one descriptor set each) that attach buffers to those bindings.

use super::buffer::Buffer;
use super::context::{Context, Shared};
use super::{VkError, VkResultExt};
use ash::vk;
use std::marker::PhantomData;
use std::sync::Arc;

/// Push constants are limited to 128 bytes on lavapipe (and guaranteed minimum everywhere).
pub const MAX_PUSH_CONSTANTS: u32 = 128;

/// A compute pipeline with its descriptor-set and pipeline layouts.
pub struct ComputePipeline {
    shared: Arc<Shared>,
    pub(crate) pipeline: vk::Pipeline,
    pub(crate) layout: vk::PipelineLayout,
    set_layout: vk::DescriptorSetLayout,
    bindings: Vec<u32>,
    pub(crate) push_size: u32,
    name: String,
}

impl ComputePipeline {
    /// Creates a pipeline from SPIR-V whose descriptor set 0 holds a storage buffer at each of
    /// `bindings`, with `push_size` bytes of push constants.
    pub fn new(
        ctx: &Context,
        name: &str,
        spirv: &[u32],
        bindings: &[u32],
        push_size: u32,
    ) -> Result<Self, VkError> {
        if push_size > MAX_PUSH_CONSTANTS || !push_size.is_multiple_of(4) {
            return Err(VkError::Usage(format!(
                "pipeline '{name}': push constants of {push_size} bytes (must be a multiple of 4, at most {MAX_PUSH_CONSTANTS})"
            )));
        }
        let shared = ctx.shared.clone();
        let device = &shared.device;
        let what = || format!("pipeline '{name}'");
        let layout_bindings: Vec<_> = bindings
            .iter()
            .map(|&b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let set_info = vk::DescriptorSetLayoutCreateInfo::default().bindings(&layout_bindings);
        // SAFETY: valid create info on a live device.
        let set_layout = unsafe { device.create_descriptor_set_layout(&set_info, None) }
            .call("vkCreateDescriptorSetLayout", what)?;
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
            .offset(0)
            .size(push_size)];
        let set_layouts = [set_layout];
        let mut layout_info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
        if push_size > 0 {
            layout_info = layout_info.push_constant_ranges(&ranges);
        }
        // SAFETY: as above; `set_layout` is live.
        let layout = match unsafe { device.create_pipeline_layout(&layout_info, None) } {
            Ok(l) => l,
            Err(result) => {
                // SAFETY: unused layout.
                unsafe { device.destroy_descriptor_set_layout(set_layout, None) };
                return Err(VkError::Call {
                    call: "vkCreatePipelineLayout",
                    what: what(),
                    result,
                });
            }
        };
        let module_info = vk::ShaderModuleCreateInfo::default().code(spirv);
        // SAFETY: `spirv` is a complete module produced by shaderc.
        let module = match unsafe { device.create_shader_module(&module_info, None) } {
            Ok(m) => m,
            Err(result) => {
                // SAFETY: unused layouts.
                unsafe {
                    device.destroy_pipeline_layout(layout, None);
                    device.destroy_descriptor_set_layout(set_layout, None);
                }
                return Err(VkError::Call {
                    call: "vkCreateShaderModule",
                    what: what(),
                    result,
                });
            }
        };
        let stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module)
            .name(c"main");
        let info = [vk::ComputePipelineCreateInfo::default()
            .stage(stage)
            .layout(layout)];
        // SAFETY: the module and layout are live; the module may be destroyed after creation.
        let created =
            unsafe { device.create_compute_pipelines(vk::PipelineCache::null(), &info, None) };
        // SAFETY: pipelines keep no reference to their shader module.
        unsafe { device.destroy_shader_module(module, None) };
        let pipeline = match created {
            Ok(p) => p.into_iter().next(),
            Err((_, result)) => {
                // SAFETY: unused layouts.
                unsafe {
                    device.destroy_pipeline_layout(layout, None);
                    device.destroy_descriptor_set_layout(set_layout, None);
                }
                return Err(VkError::Call {
                    call: "vkCreateComputePipelines",
                    what: what(),
                    result,
                });
            }
        };
        let Some(pipeline) = pipeline else {
            // SAFETY: unused layouts.
            unsafe {
                device.destroy_pipeline_layout(layout, None);
                device.destroy_descriptor_set_layout(set_layout, None);
            }
            return Err(VkError::Usage(format!(
                "{}: the driver returned no pipeline",
                what()
            )));
        };
        shared.set_name(pipeline, name);
        Ok(Self {
            shared: shared.clone(),
            pipeline,
            layout,
            set_layout,
            bindings: bindings.to_vec(),
            push_size,
            name: name.to_string(),
        })
    }

    /// Debug name.
    pub fn name(&self) -> &str {
        &self.name
    }
}

impl Drop for ComputePipeline {
    fn drop(&mut self) {
        // SAFETY: submissions are synchronous; no command buffer using these objects is pending.
        unsafe {
            self.shared.device.destroy_pipeline(self.pipeline, None);
            self.shared
                .device
                .destroy_pipeline_layout(self.layout, None);
            self.shared
                .device
                .destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

/// One descriptor set attaching buffers to a pipeline's bindings. Borrows the buffers, so they
/// cannot be dropped while the set may still be used.
pub struct BindGroup<'a> {
    shared: Arc<Shared>,
    pool: vk::DescriptorPool,
    pub(crate) set: vk::DescriptorSet,
    _buffers: PhantomData<&'a Buffer>,
}

impl<'a> BindGroup<'a> {
    /// Binds `buffers[i]` at `(binding, buffer)` pairs; every binding of the pipeline must be
    /// given exactly once.
    pub fn new(
        ctx: &Context,
        pipeline: &ComputePipeline,
        buffers: &[(u32, &'a Buffer)],
    ) -> Result<Self, VkError> {
        let mut given: Vec<u32> = buffers.iter().map(|(b, _)| *b).collect();
        given.sort_unstable();
        let mut wanted = pipeline.bindings.clone();
        wanted.sort_unstable();
        if given != wanted {
            return Err(VkError::Usage(format!(
                "pipeline '{}' has bindings {wanted:?}, got {given:?}",
                pipeline.name
            )));
        }
        let shared = ctx.shared.clone();
        let device = &shared.device;
        let what = || format!("descriptors of pipeline '{}'", pipeline.name);
        let count = u32::try_from(buffers.len().max(1)).unwrap_or(u32::MAX);
        let sizes = [vk::DescriptorPoolSize::default()
            .ty(vk::DescriptorType::STORAGE_BUFFER)
            .descriptor_count(count)];
        let pool_info = vk::DescriptorPoolCreateInfo::default()
            .max_sets(1)
            .pool_sizes(&sizes);
        // SAFETY: valid create info on a live device.
        let pool = unsafe { device.create_descriptor_pool(&pool_info, None) }
            .call("vkCreateDescriptorPool", what)?;
        let layouts = [pipeline.set_layout];
        let alloc = vk::DescriptorSetAllocateInfo::default()
            .descriptor_pool(pool)
            .set_layouts(&layouts);
        // SAFETY: the pool has room for exactly this set.
        let set = match unsafe { device.allocate_descriptor_sets(&alloc) } {
            Ok(s) => s.into_iter().next(),
            Err(result) => {
                // SAFETY: the pool is unused.
                unsafe { device.destroy_descriptor_pool(pool, None) };
                return Err(VkError::Call {
                    call: "vkAllocateDescriptorSets",
                    what: what(),
                    result,
                });
            }
        };
        let Some(set) = set else {
            // SAFETY: the pool is unused.
            unsafe { device.destroy_descriptor_pool(pool, None) };
            return Err(VkError::Usage(format!("{}: no set allocated", what())));
        };
        let infos: Vec<[vk::DescriptorBufferInfo; 1]> = buffers
            .iter()
            .map(|(_, b)| {
                [vk::DescriptorBufferInfo::default()
                    .buffer(b.handle)
                    .offset(0)
                    .range(vk::WHOLE_SIZE)]
            })
            .collect();
        let writes: Vec<_> = buffers
            .iter()
            .zip(&infos)
            .map(|((binding, _), info)| {
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(*binding)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .buffer_info(info)
            })
            .collect();
        // SAFETY: the set and buffers are live; the infos outlive the call.
        unsafe { device.update_descriptor_sets(&writes, &[]) };
        Ok(Self {
            shared,
            pool,
            set,
            _buffers: PhantomData,
        })
    }
}

impl Drop for BindGroup<'_> {
    fn drop(&mut self) {
        // SAFETY: submissions are synchronous; no pending command buffer uses the set.
        unsafe { self.shared.device.destroy_descriptor_pool(self.pool, None) };
    }
}
