//! Storage buffers allocated through gpu-allocator, with upload and readback that work on
//! unified memory (lavapipe: every allocation is mapped) and on discrete GPUs (staging copies).

use super::context::{Context, Shared};
use super::{VkError, VkResultExt};
use ash::vk;
use gpu_allocator::MemoryLocation;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// What a buffer is for; decides where gpu-allocator places it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BufferUsage {
    /// Read or written by kernels; filled by uploads, read by readbacks.
    Storage,
    /// Host-visible staging memory for transfers.
    Staging,
    /// Read and written by kernels through texel-buffer views only (`BindingKind::Texel*`):
    /// bounded by maxTexelBufferElements when a view is made, not by maxStorageBufferRange.
    Texel,
}

/// Refuses a buffer of `size` bytes that `info`'s device cannot hold or bind, naming it, the
/// size and the limit: [`Buffer::new`] checks every buffer, and callers check the large ones
/// before the host builds their contents.
pub fn check_size(
    info: &super::DeviceInfo,
    name: &str,
    size: u64,
    usage: BufferUsage,
) -> Result<(), VkError> {
    if usage == BufferUsage::Storage && size > info.max_storage_buffer_range {
        return Err(VkError::Limit {
            resource: format!("buffer '{name}'"),
            bytes: size,
            limit: info.max_storage_buffer_range,
            limit_name: "maxStorageBufferRange",
        });
    }
    if size > info.max_heap_bytes {
        return Err(VkError::Limit {
            resource: format!("buffer '{name}'"),
            bytes: size,
            limit: info.max_heap_bytes,
            limit_name: "the largest device-local memory heap",
        });
    }
    Ok(())
}

/// Refuses a texel-buffer view of `bytes` bytes read as `kind` that `info`'s device cannot make
/// (a format it does not support as a storage texel buffer, or past maxTexelBufferElements),
/// naming the buffer: bind groups check every view, and callers check the large ones before
/// the host builds their contents.
pub fn check_texel_view(
    info: &super::DeviceInfo,
    name: &str,
    bytes: u64,
    kind: super::BindingKind,
) -> Result<(), VkError> {
    let Some((format, texel_bytes)) = kind.texel() else {
        return Ok(());
    };
    if !info.storage_texel_formats.contains(&format) {
        return Err(VkError::Usage(format!(
            "buffer '{name}' is read through a {format:?} storage texel buffer, which device \
             '{}' does not support",
            info.name
        )));
    }
    if bytes / texel_bytes > info.max_texel_buffer_elements {
        return Err(VkError::Limit {
            resource: format!("texel view of buffer '{name}'"),
            bytes,
            limit: info.max_texel_buffer_elements * texel_bytes,
            limit_name: "maxTexelBufferElements",
        });
    }
    Ok(())
}

/// A Vulkan buffer with its memory. Freed on drop.
pub struct Buffer {
    shared: Arc<Shared>,
    pub(crate) handle: vk::Buffer,
    allocation: Option<Allocation>,
    size: u64,
    name: String,
}

impl Buffer {
    /// Allocates `size` bytes (at least 4) named `name` for debugging and error messages.
    pub fn new(ctx: &Context, name: &str, size: u64, usage: BufferUsage) -> Result<Self, VkError> {
        let shared = ctx.shared.clone();
        let size = size.max(4).next_multiple_of(4);
        check_size(&shared.info, name, size, usage)?;
        let vk_usage = match usage {
            // Every storage buffer may also be read through a texel-buffer view or as a uniform
            // buffer (BindingKind).
            BufferUsage::Storage => {
                vk::BufferUsageFlags::STORAGE_BUFFER
                    | vk::BufferUsageFlags::UNIFORM_BUFFER
                    | vk::BufferUsageFlags::STORAGE_TEXEL_BUFFER
                    | vk::BufferUsageFlags::INDIRECT_BUFFER
                    | vk::BufferUsageFlags::TRANSFER_DST
                    | vk::BufferUsageFlags::TRANSFER_SRC
            }
            BufferUsage::Staging => {
                vk::BufferUsageFlags::TRANSFER_SRC | vk::BufferUsageFlags::TRANSFER_DST
            }
            BufferUsage::Texel => {
                vk::BufferUsageFlags::STORAGE_TEXEL_BUFFER
                    | vk::BufferUsageFlags::TRANSFER_DST
                    | vk::BufferUsageFlags::TRANSFER_SRC
            }
        };
        let location = match usage {
            BufferUsage::Storage | BufferUsage::Texel => MemoryLocation::GpuOnly,
            BufferUsage::Staging => MemoryLocation::GpuToCpu,
        };
        let info = vk::BufferCreateInfo::default()
            .size(size)
            .usage(vk_usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid create info on a live device.
        let handle = unsafe { shared.device.create_buffer(&info, None) }
            .call("vkCreateBuffer", || {
                format!("buffer '{name}' ({size} bytes)")
            })?;
        // SAFETY: `handle` was just created on this device.
        let requirements = unsafe { shared.device.get_buffer_memory_requirements(handle) };
        let allocation = if shared.injected_allocation_failure() {
            Err(gpu_allocator::AllocationError::OutOfMemory)
        } else {
            shared.allocator().allocate(&AllocationCreateDesc {
                name,
                requirements,
                location,
                linear: true,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            })
        };
        let allocation = match allocation {
            Ok(a) => a,
            Err(source) => {
                // SAFETY: the buffer is unused and has no memory bound.
                unsafe { shared.device.destroy_buffer(handle, None) };
                let resource = format!("buffer '{name}'");
                return Err(match source {
                    gpu_allocator::AllocationError::OutOfMemory => VkError::OutOfMemory {
                        resource,
                        bytes: size,
                        source,
                    },
                    _ => VkError::Allocation {
                        resource,
                        bytes: size,
                        source,
                    },
                });
            }
        };
        // SAFETY: the allocation satisfies the buffer's requirements and is not bound elsewhere.
        let bound = unsafe {
            shared
                .device
                .bind_buffer_memory(handle, allocation.memory(), allocation.offset())
        };
        if let Err(result) = bound {
            // SAFETY: the buffer is unused.
            unsafe { shared.device.destroy_buffer(handle, None) };
            let _ = shared.allocator().free(allocation);
            return Err(VkError::Call {
                call: "vkBindBufferMemory",
                what: format!("buffer '{name}'"),
                result,
            });
        }
        shared.set_name(handle, name);
        shared.live_allocations.fetch_add(1, Ordering::SeqCst);
        Ok(Self {
            shared,
            handle,
            allocation: Some(allocation),
            size,
            name: name.to_string(),
        })
    }

    /// Allocates a storage buffer holding `data`.
    pub fn from_slice<T: bytemuck::Pod>(
        ctx: &Context,
        name: &str,
        data: &[T],
    ) -> Result<Self, VkError> {
        Self::from_slice_as(ctx, name, data, BufferUsage::Storage)
    }

    /// Allocates a buffer of `usage` holding `data` (`Texel`: read through texel views only,
    /// bounded by maxTexelBufferElements rather than maxStorageBufferRange).
    pub fn from_slice_as<T: bytemuck::Pod>(
        ctx: &Context,
        name: &str,
        data: &[T],
        usage: BufferUsage,
    ) -> Result<Self, VkError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let buffer = Self::new(ctx, name, bytes.len() as u64, usage)?;
        buffer.write(ctx, bytes)?;
        Ok(buffer)
    }

    /// Size in bytes (rounded up to a multiple of 4).
    pub fn size(&self) -> u64 {
        self.size
    }

    /// Debug name.
    pub fn name(&self) -> &str {
        &self.name
    }

    fn mapped(&self) -> bool {
        !self.shared.force_staging
            && self
                .allocation
                .as_ref()
                .is_some_and(|a| a.mapped_ptr().is_some())
    }

    /// Copies `bytes` to the start of the buffer, directly when mapped, else through staging.
    pub fn write(&self, ctx: &Context, bytes: &[u8]) -> Result<(), VkError> {
        self.write_parts(ctx, &[bytes])
    }

    /// Copies `parts`, one after the other, to the start of the buffer: what [`Buffer::write`]
    /// of their concatenation does, without that concatenation on the host (a padded grid of
    /// hundreds of MiB).
    pub fn write_parts(&self, ctx: &Context, parts: &[&[u8]]) -> Result<(), VkError> {
        let len: usize = parts.iter().map(|p| p.len()).sum();
        self.fill(ctx, len, |out: &mut [u8]| {
            let mut at = 0;
            for part in parts {
                out[at..at + part.len()].copy_from_slice(part);
                at += part.len();
            }
        })
    }

    /// Lets `fill` write the first `len` `T`s of the buffer in place, and returns what it
    /// returns: into the buffer's own mapping where it is host-visible, so that contents of
    /// hundreds of MiB (an octree's inline records) need no host copy beside the buffer
    /// (lavapipe: every allocation is mapped), else into a staging buffer copied after. The
    /// memory `fill` gets is not cleared: it must write all `len` elements.
    pub fn fill<T: bytemuck::Pod, R>(
        &self,
        ctx: &Context,
        len: usize,
        fill: impl FnOnce(&mut [T]) -> R,
    ) -> Result<R, VkError> {
        let bytes = len
            .checked_mul(std::mem::size_of::<T>())
            .filter(|&b| b as u64 <= self.size)
            .ok_or_else(|| {
                VkError::Usage(format!(
                    "upload of {len} elements of {} bytes into buffer '{}' of {} bytes",
                    std::mem::size_of::<T>(),
                    self.name,
                    self.size
                ))
            })?;
        self.shared
            .bytes_uploaded
            .fetch_add(bytes as u64, Ordering::Relaxed);
        let staging = if self.mapped() {
            None
        } else {
            let name = format!("{} (upload)", self.name);
            Some(Buffer::new(ctx, &name, bytes as u64, BufferUsage::Staging)?)
        };
        let target = staging.as_ref().unwrap_or(self);
        let ptr = target.mapped_ptr()?;
        // SAFETY: the mapping (this buffer's, of `size` >= bytes, or the staging buffer's, of
        // bytes) covers `bytes` bytes; no GPU work uses it now (every submission is waited for
        // before returning) and no other reference into it lives during this call.
        let mapping = unsafe { std::slice::from_raw_parts_mut(ptr, bytes) };
        let elements = bytemuck::try_cast_slice_mut::<u8, T>(mapping).map_err(|e| {
            VkError::Usage(format!(
                "buffer '{}' cannot hold its type: {e}",
                target.name
            ))
        })?;
        let result = fill(elements);
        if let Some(staging) = &staging {
            ctx.submit(|rec| {
                rec.copy_buffer(staging, self, bytes as u64);
                Ok(())
            })?;
        }
        Ok(result)
    }

    /// Lends the whole buffer's contents as `T`s to `view`, and returns what it returns: its
    /// own mapping where the buffer is host-visible (lavapipe: no host copy of a fine grid of
    /// hundreds of MiB), else a copy read back through staging.
    pub fn view<T: bytemuck::Pod, R>(
        &self,
        ctx: &Context,
        view: impl FnOnce(&[T]) -> R,
    ) -> Result<R, VkError> {
        if !self.mapped() {
            return Ok(view(&self.read::<T>(ctx)?));
        }
        let size_of = std::mem::size_of::<T>().max(1);
        let len = self.size as usize / size_of * size_of;
        let mapping = self
            .allocation
            .as_ref()
            .and_then(|a| a.mapped_slice())
            .ok_or_else(|| VkError::Usage(format!("buffer '{}' is not mapped", self.name)))?;
        let elements = bytemuck::try_cast_slice::<u8, T>(&mapping[..len]).map_err(|e| {
            VkError::Usage(format!(
                "buffer '{}' cannot be read as its type: {e}",
                self.name
            ))
        })?;
        Ok(view(elements))
    }

    /// Reads the whole buffer back as `T`s.
    pub fn read<T: bytemuck::Pod>(&self, ctx: &Context) -> Result<Vec<T>, VkError> {
        self.read_range(ctx, 0, self.size as usize / std::mem::size_of::<T>().max(1))
    }

    /// Reads `count` `T`s starting at element `first` (clamped to the buffer), copying only
    /// that range through staging where the buffer is not host-visible.
    pub fn read_range<T: bytemuck::Pod>(
        &self,
        ctx: &Context,
        first: usize,
        count: usize,
    ) -> Result<Vec<T>, VkError> {
        let size_of = std::mem::size_of::<T>().max(1);
        let total = self.size as usize / size_of;
        let first = first.min(total);
        let n = count.min(total - first);
        let offset = first * size_of;
        let mut out = vec![T::zeroed(); n];
        let dst: &mut [u8] = bytemuck::cast_slice_mut(&mut out);
        if dst.is_empty() {
            return Ok(out);
        }
        if self.mapped() {
            let ptr = self.mapped_ptr()?;
            // SAFETY: offset + dst.len() ≤ size, which the mapping covers; all GPU work has
            // completed.
            unsafe { std::ptr::copy_nonoverlapping(ptr.add(offset), dst.as_mut_ptr(), dst.len()) };
            return Ok(out);
        }
        let staging = Buffer::new(
            ctx,
            &format!("{} (readback)", self.name),
            dst.len() as u64,
            BufferUsage::Staging,
        )?;
        ctx.submit(|rec| {
            rec.copy_buffer_from(self, offset as u64, &staging, dst.len() as u64);
            Ok(())
        })?;
        let ptr = staging.mapped_ptr()?;
        // SAFETY: the staging mapping holds dst.len() bytes and the copy has completed.
        unsafe { std::ptr::copy_nonoverlapping(ptr, dst.as_mut_ptr(), dst.len()) };
        Ok(out)
    }

    fn mapped_ptr(&self) -> Result<*mut u8, VkError> {
        let allocation = self.allocation.as_ref();
        allocation
            .and_then(|a| a.mapped_ptr())
            .map(|p| p.as_ptr().cast::<u8>())
            .ok_or_else(|| {
                VkError::Usage(format!(
                    "buffer '{}' is not host-visible on this device",
                    self.name
                ))
            })
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        // SAFETY: submissions are synchronous, so no pending GPU work references the buffer.
        unsafe { self.shared.device.destroy_buffer(self.handle, None) };
        if let Some(Err(e)) = self
            .allocation
            .take()
            .map(|a| self.shared.allocator().free(a))
        {
            eprintln!("vmls: freeing buffer '{}' failed: {e}", self.name);
        }
        self.shared.live_allocations.fetch_sub(1, Ordering::SeqCst);
    }
}
