//! The C ABI of vmls (issue 28 §2): a context from the application's raw Vulkan handles, a
//! scene (a scene file and `key=value` overrides, which also name a dataset file), a renderer
//! of the scene's field, and frames (ray cast or splatted) recorded into the application's command buffers
//! and retired after the application's fence. The header `include/vmls.h` is generated from
//! this file by cbindgen at every build.
//!
//! Contract for C callers:
//! - Every function returns a `VmlsStatus`; `VMLS_OK` is 0. On any other status,
//!   `vmls_last_error()` returns the message of the calling thread's last failure (valid until
//!   that thread's next vmls call). Output pointers are written only on success.
//! - No Rust panic crosses the boundary: a panic inside vmls is caught and reported as
//!   `VMLS_ERROR_PANIC` with its message.
//! - Objects are destroyed by their `_destroy` function, children before parents: frames (by
//!   `vmls_renderer_retire` or `vmls_frame_destroy`), renderers, then scenes and the context;
//!   vmls never destroys the application's Vulkan objects.
//! - The synchronisation contract of recorded frames is `vmls::renderer`'s (module `record`):
//!   submit on the context's queue, retire after the submission completed.

use ash::vk;
use std::cell::RefCell;
use std::ffi::{CStr, CString, c_char};
use std::panic::{AssertUnwindSafe, catch_unwind};
use vmls::field::RenderError;
use vmls::renderer::{Access, ExternalCommands, FrameInFlight, Renderer, Target, TargetFormat};
use vmls::scene::Scene;
use vmls::view::camera::Camera;
use vmls::vk::{Context, RawContext, VkError};

pub type VkInstance = vk::Instance;
pub type VkPhysicalDevice = vk::PhysicalDevice;
pub type VkDevice = vk::Device;
pub type VkQueue = vk::Queue;
pub type VkCommandBuffer = vk::CommandBuffer;
pub type VkBuffer = vk::Buffer;
pub type VkImage = vk::Image;
pub type VkImageLayout = vk::ImageLayout;
pub type VkPipelineStageFlags = vk::PipelineStageFlags;
pub type VkAccessFlags = vk::AccessFlags;
#[allow(non_camel_case_types)]
pub type PFN_vkVoidFunction = vk::PFN_vkVoidFunction;

/// What a call did.
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VmlsStatus {
    VMLS_OK = 0,
    /// A null pointer, an unknown constant, or text that is not UTF-8.
    VMLS_ERROR_ARGUMENT = 1,
    /// The scene, its dataset or its settings were refused.
    VMLS_ERROR_SCENE = 2,
    /// Vulkan, the device or its memory failed, or a frame could not be rendered.
    VMLS_ERROR_RENDER = 3,
    /// The frame has not completed: retire it again after its submission's fence.
    VMLS_ERROR_NOT_READY = 4,
    /// A panic inside vmls (a bug): the message says where.
    VMLS_ERROR_PANIC = 5,
}
use VmlsStatus::*;

/// `VmlsTarget::kind`: the application's buffer of RGBA32F pixels.
pub const VMLS_TARGET_BUFFER: u32 = 0;
/// `VmlsTarget::kind`: the application's 2D image.
pub const VMLS_TARGET_IMAGE: u32 = 1;
/// `VmlsTarget::format` of an image: `VK_FORMAT_R32G32B32A32_SFLOAT`.
pub const VMLS_FORMAT_RGBA32F: u32 = 0;
/// `VK_FORMAT_R16G16B16A16_SFLOAT`.
pub const VMLS_FORMAT_RGBA16F: u32 = 1;
/// `VK_FORMAT_R8G8B8A8_UNORM`.
pub const VMLS_FORMAT_RGBA8_UNORM: u32 = 2;
/// `VK_FORMAT_R8G8B8A8_SRGB` (colour sRGB-encoded, alpha linear).
pub const VMLS_FORMAT_RGBA8_SRGB: u32 = 3;

/// The application's Vulkan objects that vmls works with. vmls creates only its own
/// resources on this device and destroys none of these.
#[repr(C)]
pub struct VmlsRawContext {
    /// The loader's entry point the instance was created with (`vkGetInstanceProcAddr`).
    pub get_instance_proc_addr:
        Option<unsafe extern "system" fn(VkInstance, *const c_char) -> PFN_vkVoidFunction>,
    pub instance: VkInstance,
    pub physical_device: VkPhysicalDevice,
    pub device: VkDevice,
    /// A queue family with compute support, and the queue of it vmls submits to (and the
    /// application submits recorded frames to).
    pub queue_family_index: u32,
    pub queue: VkQueue,
}

/// Where a recorded frame's pixels go (see `vmls::renderer::Target`): a buffer
/// (`VMLS_TARGET_BUFFER`: `buffer`, `offset`, `size`; RGBA32F, 16 bytes a pixel, row 0 at the
/// top) or an image (`VMLS_TARGET_IMAGE`: `image`, `format`, moved from `old_layout` to
/// `new_layout`), with `TRANSFER_DST` usage. vmls waits for `before_*` and makes its write
/// visible to `after_*`.
#[repr(C)]
pub struct VmlsTarget {
    pub kind: u32,
    pub buffer: VkBuffer,
    pub offset: u64,
    pub size: u64,
    pub image: VkImage,
    pub format: u32,
    pub old_layout: VkImageLayout,
    pub new_layout: VkImageLayout,
    pub before_stages: VkPipelineStageFlags,
    pub before_access: VkAccessFlags,
    pub after_stages: VkPipelineStageFlags,
    pub after_access: VkAccessFlags,
}

/// vmls's context on the application's device.
pub struct VmlsContext {
    ctx: Context,
}

/// A scene: its field's source, reconstruction, camera, transfer function and settings.
pub struct VmlsScene {
    scene: Scene,
    /// The camera frames are drawn from (the scene's, or orbited by `vmls_scene_orbit`).
    camera: Camera,
}

/// The persistent renderer of one scene's field.
pub struct VmlsRenderer {
    renderer: Renderer,
}

/// A recorded frame not yet retired.
pub struct VmlsFrame {
    frame: FrameInFlight,
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

/// A failure: its status and message.
struct Failure(VmlsStatus, String);

impl<E: std::fmt::Display> From<(VmlsStatus, E)> for Failure {
    fn from((status, e): (VmlsStatus, E)) -> Self {
        Failure(status, e.to_string())
    }
}

fn remember(message: &str) {
    let text = CString::new(message.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = text);
}

/// Runs `body`, turning its failure or panic into a status and the thread's last error.
fn guard(body: impl FnOnce() -> Result<(), Failure>) -> VmlsStatus {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => VMLS_OK,
        Ok(Err(Failure(status, message))) => {
            remember(&message);
            status
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown".into());
            remember(&format!("vmls panicked (a bug; please report it): {what}"));
            VMLS_ERROR_PANIC
        }
    }
}

fn argument(message: &str) -> Failure {
    Failure(VMLS_ERROR_ARGUMENT, message.into())
}

/// A reference from a pointer the caller passed, or an argument error naming it.
///
/// # Safety
/// `p` is null or points to a live `T` that nothing else mutates during the call.
unsafe fn get<'a, T>(p: *const T, name: &str) -> Result<&'a T, Failure> {
    // SAFETY: per the contract.
    unsafe { p.as_ref() }
        .ok_or_else(|| argument(&format!("{name}: expected a pointer, found NULL")))
}

/// # Safety
/// As [`get`], and no other reference to `*p` exists during the call.
unsafe fn get_mut<'a, T>(p: *mut T, name: &str) -> Result<&'a mut T, Failure> {
    // SAFETY: per the contract.
    unsafe { p.as_mut() }
        .ok_or_else(|| argument(&format!("{name}: expected a pointer, found NULL")))
}

/// # Safety
/// `p` is null or a NUL-terminated string.
unsafe fn text<'a>(p: *const c_char, name: &str) -> Result<&'a str, Failure> {
    if p.is_null() {
        return Err(argument(&format!("{name}: expected a string, found NULL")));
    }
    // SAFETY: per the contract.
    unsafe { CStr::from_ptr(p) }
        .to_str()
        .map_err(|_| argument(&format!("{name}: expected UTF-8 text")))
}

/// The calling thread's last error message ("" if none). Valid until the thread's next vmls
/// call.
#[unsafe(no_mangle)]
pub extern "C" fn vmls_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}

/// Wraps the application's instance, device and queue (`*out` on success). The handles must
/// outlive the context.
///
/// # Safety
/// `raw` points to a `VmlsRawContext` of live handles; `out` is writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vmls_context_from_raw(
    raw: *const VmlsRawContext,
    out: *mut *mut VmlsContext,
) -> VmlsStatus {
    guard(|| {
        // SAFETY: per this function's contract.
        let raw = unsafe { get(raw, "raw") }?;
        // SAFETY: as above.
        let out = unsafe { get_mut(out, "out") }?;
        let Some(get_instance_proc_addr) = raw.get_instance_proc_addr else {
            return Err(argument(
                "raw.get_instance_proc_addr: expected a function, found NULL",
            ));
        };
        if raw.instance == vk::Instance::null()
            || raw.physical_device == vk::PhysicalDevice::null()
            || raw.device == vk::Device::null()
            || raw.queue == vk::Queue::null()
        {
            return Err(argument(
                "raw: expected an instance, physical device, device and queue, found \
                 VK_NULL_HANDLE",
            ));
        }
        let static_fn = ash::StaticFn {
            get_instance_proc_addr,
        };
        // SAFETY: the application's live handles, loaded through its own entry point.
        let ctx = unsafe {
            let entry = ash::Entry::from_static_fn(static_fn);
            let instance = ash::Instance::load(entry.static_fn(), raw.instance);
            let device = ash::Device::load(instance.fp_v1_0(), raw.device);
            Context::from_raw(
                RawContext {
                    entry,
                    instance,
                    physical_device: raw.physical_device,
                    device,
                    queue_family_index: raw.queue_family_index,
                    queue: raw.queue,
                },
                false,
            )
        }
        .map_err(|e| Failure::from((VMLS_ERROR_RENDER, e)))?;
        *out = Box::into_raw(Box::new(VmlsContext { ctx }));
        Ok(())
    })
}

/// Destroys the context (after every renderer made with it). NULL is ignored.
///
/// # Safety
/// `ctx` is NULL or from `vmls_context_from_raw`, not used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vmls_context_destroy(ctx: *mut VmlsContext) {
    if !ctx.is_null() {
        // SAFETY: per the contract: made by Box::into_raw, destroyed once.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(ctx) })));
    }
}

/// Loads a scene: the TOML file at `path` (NULL: the built-in default scene) with
/// `override_count` overrides `key=value` (`volume.file="data.vti"` names a dataset).
///
/// # Safety
/// `path` is NULL or a NUL-terminated string; `overrides` points to `override_count` of them
/// (or is NULL when the count is 0); `out` is writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vmls_scene_load(
    path: *const c_char,
    overrides: *const *const c_char,
    override_count: usize,
    out: *mut *mut VmlsScene,
) -> VmlsStatus {
    guard(|| {
        // SAFETY: per this function's contract (live objects of this API, writable outputs).
        let out = unsafe { get_mut(out, "out") }?;
        let path = if path.is_null() {
            None
        } else {
            // SAFETY: per the contract.
            Some(std::path::PathBuf::from(unsafe { text(path, "path") }?))
        };
        let mut set = Vec::with_capacity(override_count);
        if override_count > 0 {
            if overrides.is_null() {
                return Err(argument("overrides: expected an array, found NULL"));
            }
            // SAFETY: per the contract, `override_count` readable pointers.
            let list = unsafe { std::slice::from_raw_parts(overrides, override_count) };
            for (i, p) in list.iter().enumerate() {
                // SAFETY: per the contract.
                set.push(unsafe { text(*p, &format!("overrides[{i}]")) }?.to_string());
            }
        }
        let scene =
            Scene::load(path.as_deref(), &set).map_err(|e| Failure::from((VMLS_ERROR_SCENE, e)))?;
        let camera = scene.camera;
        *out = Box::into_raw(Box::new(VmlsScene { scene, camera }));
        Ok(())
    })
}

/// The scene's image size in pixels.
///
/// # Safety
/// `scene` is from `vmls_scene_load`; `width` and `height` are writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vmls_scene_size(
    scene: *const VmlsScene,
    width: *mut u32,
    height: *mut u32,
) -> VmlsStatus {
    guard(|| {
        // SAFETY: per this function's contract (live objects of this API, writable outputs).
        let scene = unsafe { get(scene, "scene") }?;
        if width.is_null() || height.is_null() {
            return Err(argument("width, height: expected pointers, found NULL"));
        }
        // SAFETY: both writable (the contract); written one after the other, so the same
        // pointer twice is fine.
        unsafe {
            width.write(scene.camera.width);
            height.write(scene.camera.height);
        }
        Ok(())
    })
}

/// Turns the scene's camera about its target by `radians` from the scene file's camera (an
/// orbit about the camera's up axis), for the frames recorded after.
///
/// # Safety
/// `scene` is from `vmls_scene_load`, not used by another thread during the call.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vmls_scene_orbit(scene: *mut VmlsScene, radians: f64) -> VmlsStatus {
    guard(|| {
        // SAFETY: per this function's contract (live objects of this API, writable outputs).
        let scene = unsafe { get_mut(scene, "scene") }?;
        if !radians.is_finite() {
            return Err(argument("radians: expected a finite angle"));
        }
        scene.camera = scene.scene.camera.orbited(radians);
        Ok(())
    })
}

/// Destroys a scene. NULL is ignored.
///
/// # Safety
/// `scene` is NULL or from `vmls_scene_load`, not used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vmls_scene_destroy(scene: *mut VmlsScene) {
    if !scene.is_null() {
        // SAFETY: made by Box::into_raw, destroyed once.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(scene) })));
    }
}

/// Builds the scene's field (reading its dataset) and a renderer of it on the context.
///
/// # Safety
/// `ctx` and `scene` are live objects of this API; `out` is writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vmls_renderer_create(
    ctx: *const VmlsContext,
    scene: *const VmlsScene,
    out: *mut *mut VmlsRenderer,
) -> VmlsStatus {
    guard(|| {
        // SAFETY: per this function's contract (live objects of this API, writable outputs).
        let ctx = unsafe { get(ctx, "ctx") }?;
        // SAFETY: as above.
        let scene = unsafe { get(scene, "scene") }?;
        // SAFETY: as above.
        let out = unsafe { get_mut(out, "out") }?;
        let field = scene
            .scene
            .field_on(Some(ctx.ctx.info()), |_| {})
            .map_err(|e| Failure::from((VMLS_ERROR_SCENE, e)))?;
        let renderer =
            Renderer::new(&ctx.ctx, field).map_err(|e| Failure::from((VMLS_ERROR_RENDER, e)))?;
        *out = Box::into_raw(Box::new(VmlsRenderer { renderer }));
        Ok(())
    })
}

/// Builds what frames of the scene need (pipeline, tables, the field on the device), so that
/// recording compiles nothing.
///
/// # Safety
/// `renderer` and `scene` are live objects of this API, not used by another thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vmls_renderer_prepare(
    renderer: *mut VmlsRenderer,
    scene: *const VmlsScene,
) -> VmlsStatus {
    guard(|| {
        // SAFETY: per this function's contract (live objects of this API, writable outputs).
        let r = unsafe { get_mut(renderer, "renderer") }?;
        // SAFETY: as above.
        let s = unsafe { get(scene, "scene") }?;
        r.renderer
            .prepare(&s.scene.view_with(&s.camera))
            .map_err(|e| Failure::from((VMLS_ERROR_RENDER, e)))
    })
}

/// The target a C description names, checked.
///
/// # Safety
/// The description's handles are live until the frame that writes the target completes
/// (`vmls_renderer_record`'s contract).
unsafe fn target_of(t: &VmlsTarget) -> Result<Target, Failure> {
    // An empty stage mask is invalid in a barrier: nothing before means the top of the pipe,
    // nothing after the bottom.
    let or = |stages: VkPipelineStageFlags, none| if stages.is_empty() { none } else { stages };
    let before = Access {
        stages: or(t.before_stages, vk::PipelineStageFlags::TOP_OF_PIPE),
        access: t.before_access,
    };
    let after = Access {
        stages: or(t.after_stages, vk::PipelineStageFlags::BOTTOM_OF_PIPE),
        access: t.after_access,
    };
    match t.kind {
        VMLS_TARGET_BUFFER => {
            // SAFETY: live handles, per this function's contract.
            Ok(unsafe { Target::buffer(t.buffer, t.offset, t.size, before, after) })
        }
        VMLS_TARGET_IMAGE => {
            let format = match t.format {
                VMLS_FORMAT_RGBA32F => TargetFormat::Rgba32f,
                VMLS_FORMAT_RGBA16F => TargetFormat::Rgba16f,
                VMLS_FORMAT_RGBA8_UNORM => TargetFormat::Rgba8Unorm,
                VMLS_FORMAT_RGBA8_SRGB => TargetFormat::Rgba8Srgb,
                other => {
                    return Err(argument(&format!(
                        "target.format: expected one of VMLS_FORMAT_*, found {other}"
                    )));
                }
            };
            // SAFETY: as above.
            let image = unsafe {
                Target::image(t.image, format, t.old_layout, t.new_layout, before, after)
            };
            Ok(image)
        }
        other => Err(argument(&format!(
            "target.kind: expected VMLS_TARGET_BUFFER or VMLS_TARGET_IMAGE, found {other}"
        ))),
    }
}

/// Records one frame (ray cast or splatted) of the scene's current camera into `cmd` (recording, outside a
/// render pass, of the context's queue family) and the write of its pixels into `target`;
/// `*out` is the frame to retire after the submission completes. Nothing is submitted.
///
/// # Safety
/// `renderer`, `scene` and `target` are live; `cmd` is a command buffer of the context's
/// device in the recording state; the target's handles are live until the frame completes;
/// `out` is writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vmls_renderer_record(
    renderer: *mut VmlsRenderer,
    cmd: VkCommandBuffer,
    scene: *const VmlsScene,
    target: *const VmlsTarget,
    out: *mut *mut VmlsFrame,
) -> VmlsStatus {
    guard(|| {
        // SAFETY: per this function's contract (live objects of this API, writable outputs).
        let r = unsafe { get_mut(renderer, "renderer") }?;
        // SAFETY: as above.
        let s = unsafe { get(scene, "scene") }?;
        // SAFETY: per this function's contract (a live target description with live handles).
        let t = unsafe { target_of(get(target, "target")?) }?;
        // SAFETY: per this function's contract (live objects of this API, writable outputs).
        let out = unsafe { get_mut(out, "out") }?;
        if cmd == vk::CommandBuffer::null() {
            return Err(argument(
                "cmd: expected a command buffer, found VK_NULL_HANDLE",
            ));
        }
        // SAFETY: per this function's contract.
        let cmd = unsafe { ExternalCommands::new(cmd) };
        let frame = r
            .renderer
            .record(cmd, &s.scene.view_with(&s.camera), &t)
            .map_err(|e| Failure::from((VMLS_ERROR_RENDER, e)))?;
        *out = Box::into_raw(Box::new(VmlsFrame { frame }));
        Ok(())
    })
}

/// Retires a frame whose submission completed: on `VMLS_OK` the frame is freed and `*gpu_ms`
/// (if not NULL) is its GPU time in milliseconds (negative where the queue has no timestamps).
/// `VMLS_ERROR_NOT_READY`: the frame has not completed and stays valid; retire it later.
///
/// # Safety
/// `renderer` is the renderer that recorded `frame`; `gpu_ms` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vmls_renderer_retire(
    renderer: *mut VmlsRenderer,
    frame: *mut VmlsFrame,
    gpu_ms: *mut f64,
) -> VmlsStatus {
    guard(|| {
        // SAFETY: per this function's contract (live objects of this API, writable outputs).
        let r = unsafe { get_mut(renderer, "renderer") }?;
        // SAFETY: as above.
        let f = unsafe { get(frame, "frame") }?;
        match r.renderer.retire(&f.frame) {
            Ok(done) => {
                if !gpu_ms.is_null() {
                    // SAFETY: per the contract, writable.
                    unsafe { *gpu_ms = done.gpu_ms.unwrap_or(-1.0) };
                }
                // SAFETY: made by Box::into_raw in vmls_renderer_record, freed once here.
                drop(unsafe { Box::from_raw(frame) });
                Ok(())
            }
            // Not run yet: the frame stays valid and in flight.
            Err(e @ RenderError::Vk(VkError::NotReady(_))) => {
                Err(Failure(VMLS_ERROR_NOT_READY, e.to_string()))
            }
            // Another renderer's, or retired: the frame is not this call's to free.
            Err(e @ RenderError::Retired(_)) => Err(Failure(VMLS_ERROR_ARGUMENT, e.to_string())),
            Err(e) => {
                // Retired all the same (a frame that completed wrong, or a failed readback).
                // SAFETY: as above.
                drop(unsafe { Box::from_raw(frame) });
                Err(Failure(VMLS_ERROR_RENDER, e.to_string()))
            }
        }
    })
}

/// Frees a frame without retiring it (its buffers stay reserved until the renderer is
/// destroyed). NULL is ignored.
///
/// # Safety
/// `frame` is NULL or from `vmls_renderer_record`, not used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vmls_frame_destroy(frame: *mut VmlsFrame) {
    if !frame.is_null() {
        // SAFETY: made by Box::into_raw, destroyed once.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(frame) })));
    }
}

/// Destroys a renderer (waiting for its queue first if frames are still in flight). NULL is
/// ignored.
///
/// # Safety
/// `renderer` is NULL or from `vmls_renderer_create`, not used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vmls_renderer_destroy(renderer: *mut VmlsRenderer) {
    if !renderer.is_null() {
        // SAFETY: made by Box::into_raw, destroyed once.
        let _ = catch_unwind(AssertUnwindSafe(|| {
            // SAFETY: made by Box::into_raw, destroyed once.
            drop(unsafe { Box::from_raw(renderer) })
        }));
    }
}
