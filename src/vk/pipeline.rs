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
/// How a kernel reads a binding. Texel-buffer views compile to gathers on llvmpipe, where a
/// storage-buffer load with a per-lane index is a loop over the lanes (LAVAPIPE.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BindingKind {
    /// A storage buffer (`buffer` block).
    Storage,
    /// A uniform buffer (`uniform` block, std140) of at most maxUniformBufferRange bytes: for
    /// parameters every invocation reads at the same address, cheaper to read on llvmpipe than
    /// a storage buffer, whose reads are loops over the lanes (BENCHMARKS.md).
    Uniform,
    /// A storage texel buffer of `uint`s (`r32ui uimageBuffer`).
    TexelR32Uint,
    /// A storage texel buffer of `uvec2`s (`rg32ui uimageBuffer`).
    TexelRg32Uint,
    /// A storage texel buffer of `vec4`s (`rgba32f imageBuffer`).
    TexelRgba32Float,
    /// A storage texel buffer of `uvec4`s (`rgba32ui uimageBuffer`).
    TexelRgba32Uint,
}

/// Every texel-view format of [`BindingKind::texel`]: `r32ui`, `rgba32f` and `rgba32ui` are
/// required of every Vulkan device as storage texel buffers, `rg32ui` is not; the device's
/// support is queried once (`DeviceInfo::storage_texel_formats`).
pub(crate) const TEXEL_FORMATS: [vk::Format; 4] = [
    vk::Format::R32_UINT,
    vk::Format::R32G32_UINT,
    vk::Format::R32G32B32A32_SFLOAT,
    vk::Format::R32G32B32A32_UINT,
];

impl BindingKind {
    fn descriptor_type(self) -> vk::DescriptorType {
        match self {
            BindingKind::Storage => vk::DescriptorType::STORAGE_BUFFER,
            BindingKind::Uniform => vk::DescriptorType::UNIFORM_BUFFER,
            _ => vk::DescriptorType::STORAGE_TEXEL_BUFFER,
        }
    }

    /// The view's format and its element size in bytes.
    pub(crate) fn texel(self) -> Option<(vk::Format, u64)> {
        match self {
            BindingKind::Storage | BindingKind::Uniform => None,
            BindingKind::TexelR32Uint => Some((vk::Format::R32_UINT, 4)),
            BindingKind::TexelRg32Uint => Some((vk::Format::R32G32_UINT, 8)),
            BindingKind::TexelRgba32Float => Some((vk::Format::R32G32B32A32_SFLOAT, 16)),
            BindingKind::TexelRgba32Uint => Some((vk::Format::R32G32B32A32_UINT, 16)),
        }
    }
}

pub struct ComputePipeline {
    shared: Arc<Shared>,
    pub(crate) pipeline: vk::Pipeline,
    pub(crate) layout: vk::PipelineLayout,
    set_layout: vk::DescriptorSetLayout,
    bindings: Vec<u32>,
    kinds: Vec<BindingKind>,
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
        let kinds: Vec<(u32, BindingKind)> = bindings
            .iter()
            .map(|&b| (b, BindingKind::Storage))
            .collect();
        Self::with_kinds(ctx, name, spirv, &kinds, push_size)
    }

    /// As [`ComputePipeline::new`], with the kind of each binding.
    pub fn with_kinds(
        ctx: &Context,
        name: &str,
        spirv: &[u32],
        kinds: &[(u32, BindingKind)],
        push_size: u32,
    ) -> Result<Self, VkError> {
        let bindings: Vec<u32> = kinds.iter().map(|(b, _)| *b).collect();
        if push_size > MAX_PUSH_CONSTANTS || !push_size.is_multiple_of(4) {
            return Err(VkError::Usage(format!(
                "pipeline '{name}': push constants of {push_size} bytes (must be a multiple of 4, at most {MAX_PUSH_CONSTANTS})"
            )));
        }
        let shared = ctx.shared.clone();
        let device = &shared.device;
        let what = || format!("pipeline '{name}'");
        let layout_bindings: Vec<_> = kinds
            .iter()
            .map(|&(b, kind)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(kind.descriptor_type())
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
        let cache = ctx.shared.pipeline_cache;
        // SAFETY: the module and layout are live; the module may be destroyed after creation.
        // The cache is this device's (or null), created without external synchronisation.
        let created = unsafe { device.create_compute_pipelines(cache, &info, None) };
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
            bindings,
            kinds: kinds.iter().map(|(_, k)| *k).collect(),
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
    /// Texel-buffer views of this group's texel bindings.
    views: Vec<vk::BufferView>,
    _buffers: PhantomData<&'a Buffer>,
}

impl<'a> BindGroup<'a> {
    /// Binds `buffers[i]` at `(binding, buffer)` pairs; every binding of the pipeline must be
    /// given exactly once. Texel bindings get a view over the whole buffer, owned by the group.
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
        let kind_of = |binding: u32| {
            pipeline
                .bindings
                .iter()
                .position(|&b| b == binding)
                .map_or(BindingKind::Storage, |i| pipeline.kinds[i])
        };
        let mut group = Self {
            shared: shared.clone(),
            pool: vk::DescriptorPool::null(),
            set: vk::DescriptorSet::null(),
            views: Vec::new(),
            _buffers: PhantomData,
        };
        let device = &shared.device;
        let what = || format!("descriptors of pipeline '{}'", pipeline.name);
        // One view per texel binding (None for storage buffers), made before anything that
        // needs them; `group` destroys whatever was made if a later step fails.
        let mut views = Vec::with_capacity(buffers.len());
        for (binding, buffer) in buffers {
            if kind_of(*binding) == BindingKind::Uniform
                && buffer.size() > shared.info.max_uniform_buffer_range
            {
                return Err(VkError::Limit {
                    resource: format!("uniform buffer '{}'", buffer.name()),
                    bytes: buffer.size(),
                    limit: shared.info.max_uniform_buffer_range,
                    limit_name: "maxUniformBufferRange",
                });
            }
            let Some((format, _)) = kind_of(*binding).texel() else {
                views.push(None);
                continue;
            };
            super::buffer::check_texel_view(
                &shared.info,
                buffer.name(),
                buffer.size(),
                kind_of(*binding),
            )?;
            let info = vk::BufferViewCreateInfo::default()
                .buffer(buffer.handle)
                .format(format)
                .offset(0)
                .range(vk::WHOLE_SIZE);
            // SAFETY: the buffer is live and was created with STORAGE_TEXEL_BUFFER usage; its
            // size in texels was checked against maxTexelBufferElements above.
            let view = unsafe { device.create_buffer_view(&info, None) }
                .call("vkCreateBufferView", || {
                    format!("texel view of buffer '{}'", buffer.name())
                })?;
            group.views.push(view);
            views.push(Some(view));
        }
        let mut sizes: Vec<vk::DescriptorPoolSize> = Vec::new();
        for ty in [
            vk::DescriptorType::STORAGE_BUFFER,
            vk::DescriptorType::UNIFORM_BUFFER,
            vk::DescriptorType::STORAGE_TEXEL_BUFFER,
        ] {
            let n = buffers
                .iter()
                .filter(|(b, _)| kind_of(*b).descriptor_type() == ty)
                .count();
            if n > 0 {
                sizes.push(
                    vk::DescriptorPoolSize::default()
                        .ty(ty)
                        .descriptor_count(u32::try_from(n).unwrap_or(u32::MAX)),
                );
            }
        }
        if sizes.is_empty() {
            sizes.push(
                vk::DescriptorPoolSize::default()
                    .ty(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1),
            );
        }
        let pool_info = vk::DescriptorPoolCreateInfo::default()
            .max_sets(1)
            .pool_sizes(&sizes);
        // SAFETY: valid create info on a live device.
        group.pool = unsafe { device.create_descriptor_pool(&pool_info, None) }
            .call("vkCreateDescriptorPool", what)?;
        let layouts = [pipeline.set_layout];
        let alloc = vk::DescriptorSetAllocateInfo::default()
            .descriptor_pool(group.pool)
            .set_layouts(&layouts);
        // SAFETY: the pool has room for exactly this set.
        let set = unsafe { device.allocate_descriptor_sets(&alloc) }
            .call("vkAllocateDescriptorSets", what)?
            .into_iter()
            .next();
        let Some(set) = set else {
            return Err(VkError::Usage(format!("{}: no set allocated", what())));
        };
        group.set = set;
        let infos: Vec<[vk::DescriptorBufferInfo; 1]> = buffers
            .iter()
            .map(|(_, b)| {
                [vk::DescriptorBufferInfo::default()
                    .buffer(b.handle)
                    .offset(0)
                    .range(vk::WHOLE_SIZE)]
            })
            .collect();
        let view_lists: Vec<[vk::BufferView; 1]> = views
            .iter()
            .map(|v| [v.unwrap_or(vk::BufferView::null())])
            .collect();
        let writes: Vec<_> = buffers
            .iter()
            .zip(infos.iter().zip(&view_lists))
            .zip(&views)
            .map(|(((binding, _), (info, view)), made)| {
                let write = vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(*binding)
                    .descriptor_type(kind_of(*binding).descriptor_type());
                if made.is_some() {
                    write.texel_buffer_view(view)
                } else {
                    write.buffer_info(info)
                }
            })
            .collect();
        // SAFETY: the set, buffers and views are live; the infos outlive the call.
        unsafe { device.update_descriptor_sets(&writes, &[]) };
        Ok(group)
    }
}

impl BindGroup<'_> {
    /// The group without the borrow of its buffers, for a recorded frame that outlives the
    /// call that made it: its owner keeps every buffer alive, and the group too, until the
    /// application reports the frame's submission complete.
    pub(crate) fn detach(mut self) -> BindGroup<'static> {
        BindGroup {
            shared: self.shared.clone(),
            pool: std::mem::replace(&mut self.pool, vk::DescriptorPool::null()),
            set: self.set,
            views: std::mem::take(&mut self.views),
            _buffers: PhantomData,
        }
    }
}

impl Drop for BindGroup<'_> {
    fn drop(&mut self) {
        // SAFETY: submissions are synchronous, and a detached group's owner drops it only after
        // its frame completed: no pending command buffer uses the set or the views. Destroying
        // a null pool is a no-op (a group that failed before creating it, or was detached).
        unsafe {
            self.shared.device.destroy_descriptor_pool(self.pool, None);
            for &view in &self.views {
                self.shared.device.destroy_buffer_view(view, None);
            }
        }
    }
}
