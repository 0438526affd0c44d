//! vmls inside an application's own Vulkan code: the application creates the instance, the
//! device, an image and its command buffers; vmls records frames (ray cast, or splatted with
//! `--set 'render.method="splat"'`) into those command buffers, writing the application's image, with two frames in flight while the camera turns.
//! The application copies each frame to a host buffer in the same command buffer and writes the
//! last one to a file.
//!
//! ```text
//! cargo run --release --example embed -- [out.pam] [--format rgba8|rgba8-srgb|rgba16f|rgba32f]
//!     [--size N] [--frames N] [--set key=value]...
//! ```
//!
//! `VMLS_VALIDATION=1` enables the Khronos validation layer with synchronization validation and
//! counts what it reports (`tests/embed_example.rs` runs this file that way). Everything here
//! that touches a raw Vulkan handle is the application's part and `unsafe` by nature; the vmls
//! calls are safe Rust once the handles are wrapped.

use ash::vk;
use std::error::Error;
use std::ffi::{CStr, c_void};
use std::sync::atomic::{AtomicU32, Ordering};
use vmls::renderer::{Access, ExternalCommands, FrameInFlight, Renderer, Target, TargetFormat};
use vmls::scene::Scene;
use vmls::vk::{Context, RawContext};

/// Validation messages (errors and warnings) the application's messenger saw.
pub static MESSAGES: AtomicU32 = AtomicU32::new(0);

unsafe extern "system" fn on_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    _: *mut c_void,
) -> vk::Bool32 {
    if severity.intersects(
        vk::DebugUtilsMessageSeverityFlagsEXT::ERROR
            | vk::DebugUtilsMessageSeverityFlagsEXT::WARNING,
    ) {
        MESSAGES.fetch_add(1, Ordering::SeqCst);
        // SAFETY: the loader passes a valid message for the duration of the call.
        let text = unsafe { CStr::from_ptr((*data).p_message) };
        eprintln!("validation: {}", text.to_string_lossy());
    }
    vk::FALSE
}

/// What one run of the example produced.
pub struct Frames {
    /// Each frame's target contents as read back by the application (width × height pixels
    /// of the format's size, row 0 at the top).
    pub frames: Vec<Vec<u8>>,
    /// vmls's own image of each frame's camera from `Renderer::render`, on the same device:
    /// what the recorded frames must equal.
    pub rendered: Vec<Vec<[f32; 4]>>,
    /// GPU milliseconds of each recorded frame (its timestamps, from `Renderer::retire`) and
    /// of each `render()` frame (the sum of its submissions), where the queue has timestamps.
    pub recorded_ms: Vec<f64>,
    pub rendered_ms: Vec<f64>,
    /// Dispatches of the last recorded frame, and submissions of the last `render()` frame.
    pub dispatches: u32,
    /// A mesh, ray cast or splatted post-shaded: per recorded frame (in retire order), whether
    /// it found its rays' hull segments or read those its slot kept for the same camera.
    pub hull_segments: Vec<Option<vmls::renderer::HullSegments>>,
    pub submissions: u32,
    pub width: u32,
    pub height: u32,
}

/// A buffer or image with its memory, made by the application.
struct Memory {
    memory: vk::DeviceMemory,
}

/// Finds a memory type with `flags` among `bits`.
fn memory_type(
    props: &vk::PhysicalDeviceMemoryProperties,
    bits: u32,
    flags: vk::MemoryPropertyFlags,
) -> Option<u32> {
    (0..props.memory_type_count).find(|&i| {
        bits & (1 << i) != 0
            && props.memory_types[i as usize]
                .property_flags
                .contains(flags)
    })
}

/// The application's Vulkan objects: instance (with the validation layer and
/// synchronization validation when `VMLS_VALIDATION=1`), device and one compute queue.
pub struct App {
    pub entry: ash::Entry,
    pub instance: ash::Instance,
    pub physical: vk::PhysicalDevice,
    pub device: ash::Device,
    pub family: u32,
    pub queue: vk::Queue,
    pub props: vk::PhysicalDeviceMemoryProperties,
    debug: ash::ext::debug_utils::Instance,
    messenger: Option<vk::DebugUtilsMessengerEXT>,
}

impl App {
    /// Creates the instance, device and queue.
    ///
    /// # Safety
    /// The caller destroys the app with [`App::destroy`] after everything made from it.
    pub unsafe fn new() -> Result<Self, Box<dyn Error>> {
        let validation = std::env::var("VMLS_VALIDATION").is_ok_and(|v| v == "1");
        // SAFETY: plain object creation; the handles are returned to the caller.
        unsafe {
            let entry = ash::Entry::load()?;
            let layers = [c"VK_LAYER_KHRONOS_validation".as_ptr()];
            let extensions = [ash::ext::debug_utils::NAME.as_ptr()];
            let enables = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
            let mut features =
                vk::ValidationFeaturesEXT::default().enabled_validation_features(&enables);
            let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_2);
            let mut info = vk::InstanceCreateInfo::default().application_info(&app);
            if validation {
                info = info
                    .enabled_layer_names(&layers)
                    .enabled_extension_names(&extensions)
                    .push_next(&mut features);
            }
            let instance = entry.create_instance(&info, None)?;
            let debug = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let messenger = if validation {
                Some(
                    debug.create_debug_utils_messenger(
                        &vk::DebugUtilsMessengerCreateInfoEXT::default()
                            .message_severity(
                                vk::DebugUtilsMessageSeverityFlagsEXT::ERROR
                                    | vk::DebugUtilsMessageSeverityFlagsEXT::WARNING,
                            )
                            .message_type(vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION)
                            .pfn_user_callback(Some(on_message)),
                        None,
                    )?,
                )
            } else {
                None
            };
            let physical = *instance
                .enumerate_physical_devices()?
                .first()
                .ok_or("no Vulkan device")?;
            let family = instance
                .get_physical_device_queue_family_properties(physical)
                .iter()
                .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
                .ok_or("no compute queue")? as u32;
            let priorities = [1.0];
            let queues = [vk::DeviceQueueCreateInfo::default()
                .queue_family_index(family)
                .queue_priorities(&priorities)];
            let device = instance.create_device(
                physical,
                &vk::DeviceCreateInfo::default().queue_create_infos(&queues),
                None,
            )?;
            let queue = device.get_device_queue(family, 0);
            let props = instance.get_physical_device_memory_properties(physical);

            Ok(Self {
                entry,
                instance,
                physical,
                device,
                family,
                queue,
                props,
                debug,
                messenger,
            })
        }
    }

    /// vmls's context on the application's device.
    pub fn context(&self) -> Result<Context, Box<dyn Error>> {
        // SAFETY: the handles are live and outlive the context (App::destroy comes after).
        Ok(unsafe {
            Context::from_raw(
                RawContext {
                    entry: self.entry.clone(),
                    instance: self.instance.clone(),
                    physical_device: self.physical,
                    device: self.device.clone(),
                    queue_family_index: self.family,
                    queue: self.queue,
                },
                false,
            )
        }?)
    }

    /// Destroys the device and instance.
    ///
    /// # Safety
    /// Everything made from them is destroyed, vmls's context included.
    pub unsafe fn destroy(self) -> Result<(), Box<dyn Error>> {
        // SAFETY: per the contract.
        unsafe {
            self.device.device_wait_idle()?;
            self.device.destroy_device(None);
            if let Some(m) = self.messenger {
                self.debug.destroy_debug_utils_messenger(m, None);
            }
            self.instance.destroy_instance(None);
        }
        Ok(())
    }
}

/// Renders `count` frames of the scene given by `overrides` (camera orbiting by `turn` radians
/// per frame), two in flight, into an image of `format`.
pub fn run(
    overrides: &[String],
    count: usize,
    turn: f64,
    format: TargetFormat,
) -> Result<Frames, Box<dyn Error>> {
    // SAFETY: this function is the application: it creates its Vulkan objects, hands vmls
    // only wrapped handles, waits for its fences before reusing or reading anything, and
    // destroys its objects after vmls's renderer and context are dropped.
    unsafe {
        let app = App::new()?;
        let (device, queue, family, props) = (&app.device, app.queue, app.family, &app.props);
        let scene = Scene::load(None, overrides)?;
        let (width, height) = (scene.camera.width, scene.camera.height);
        let bytes = u64::from(width) * u64::from(height) * format.bytes();
        // The application's image (what it would sample or present), and a host buffer it
        // copies each frame into.
        let image = device.create_image(
            &vk::ImageCreateInfo::default()
                .image_type(vk::ImageType::TYPE_2D)
                .format(format.vk_format())
                .extent(vk::Extent3D {
                    width,
                    height,
                    depth: 1,
                })
                .mip_levels(1)
                .array_layers(1)
                .samples(vk::SampleCountFlags::TYPE_1)
                .tiling(vk::ImageTiling::OPTIMAL)
                .usage(vk::ImageUsageFlags::TRANSFER_DST | vk::ImageUsageFlags::TRANSFER_SRC)
                .initial_layout(vk::ImageLayout::UNDEFINED),
            None,
        )?;
        let req = device.get_image_memory_requirements(image);
        let image_memory = Memory {
            memory: device.allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(req.size)
                    .memory_type_index(
                        memory_type(
                            props,
                            req.memory_type_bits,
                            vk::MemoryPropertyFlags::DEVICE_LOCAL,
                        )
                        .or_else(|| {
                            memory_type(
                                props,
                                req.memory_type_bits,
                                vk::MemoryPropertyFlags::empty(),
                            )
                        })
                        .ok_or("no memory for the image")?,
                    ),
                None,
            )?,
        };
        device.bind_image_memory(image, image_memory.memory, 0)?;
        // One host buffer per frame in flight.
        let mut readbacks = Vec::new();
        for _ in 0..2 {
            let buffer = device.create_buffer(
                &vk::BufferCreateInfo::default()
                    .size(bytes)
                    .usage(vk::BufferUsageFlags::TRANSFER_DST),
                None,
            )?;
            let req = device.get_buffer_memory_requirements(buffer);
            let host =
                vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
            let memory = device.allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(req.size)
                    .memory_type_index(
                        memory_type(props, req.memory_type_bits, host).ok_or("no host memory")?,
                    ),
                None,
            )?;
            device.bind_buffer_memory(buffer, memory, 0)?;
            readbacks.push((buffer, Memory { memory }));
        }
        let pool = device.create_command_pool(
            &vk::CommandPoolCreateInfo::default()
                .queue_family_index(family)
                .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
            None,
        )?;
        let cmds = device.allocate_command_buffers(
            &vk::CommandBufferAllocateInfo::default()
                .command_pool(pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(2),
        )?;
        let fences = [
            device.create_fence(&vk::FenceCreateInfo::default(), None)?,
            device.create_fence(&vk::FenceCreateInfo::default(), None)?,
        ];

        let mut out = Frames {
            frames: Vec::new(),
            rendered: Vec::new(),
            recorded_ms: Vec::new(),
            rendered_ms: Vec::new(),
            dispatches: 0,
            hull_segments: Vec::new(),
            submissions: 0,
            width,
            height,
        };
        {
            let ctx = app.context()?;
            let field = scene.field_on(Some(ctx.info()), |_| {})?;
            let mut renderer = Renderer::new(&ctx, field.clone())?;
            let mut reference = Renderer::new(&ctx, field)?;
            // Everything built before the first frame: no frame compiles a shader.
            renderer.prepare(&scene.view())?;
            let cameras: Vec<_> = (0..count)
                .map(|i| scene.camera.orbited(turn * i as f64))
                .collect();
            let mut in_flight: [Option<(usize, FrameInFlight)>; 2] = [None, None];
            let mut layout = vk::ImageLayout::UNDEFINED;
            let finish = |k: usize,
                          slot: &mut Option<(usize, FrameInFlight)>,
                          renderer: &mut Renderer,
                          out: &mut Frames|
             -> Result<(), Box<dyn Error>> {
                if let Some((i, frame)) = slot.take() {
                    device.wait_for_fences(&[fences[k]], true, u64::MAX)?;
                    let done = renderer.retire(&frame)?;
                    out.recorded_ms.extend(done.gpu_ms);
                    out.dispatches = done.dispatches;
                    out.hull_segments.push(done.hull_segments);
                    let ptr = device.map_memory(
                        readbacks[k].1.memory,
                        0,
                        bytes,
                        vk::MemoryMapFlags::empty(),
                    )?;
                    let data =
                        std::slice::from_raw_parts(ptr.cast::<u8>(), bytes as usize).to_vec();
                    device.unmap_memory(readbacks[k].1.memory);
                    out.frames.resize(out.frames.len().max(i + 1), Vec::new());
                    out.frames[i] = data;
                }
                Ok(())
            };
            for (i, camera) in cameras.iter().enumerate() {
                let k = i % 2;
                // The frame recorded two frames ago used this command buffer: wait for it.
                finish(k, &mut in_flight[k], &mut renderer, &mut out)?;
                device.reset_fences(&[fences[k]])?;
                let cmd = cmds[k];
                device.begin_command_buffer(
                    cmd,
                    &vk::CommandBufferBeginInfo::default()
                        .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                )?;
                // The image was last read by the previous frame's copy (in another submission,
                // which the queue orders before this one).
                let target = Target::image(
                    image,
                    format,
                    layout,
                    vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                    if layout == vk::ImageLayout::UNDEFINED {
                        Access::NONE
                    } else {
                        Access::TRANSFER_READ
                    },
                    Access::TRANSFER_READ,
                );
                layout = vk::ImageLayout::TRANSFER_SRC_OPTIMAL;
                let frame = renderer.record(
                    ExternalCommands::new(cmd),
                    &scene.view_with(camera),
                    &target,
                )?;
                device.cmd_copy_image_to_buffer(
                    cmd,
                    image,
                    vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                    readbacks[k].0,
                    &[vk::BufferImageCopy::default()
                        .image_subresource(
                            vk::ImageSubresourceLayers::default()
                                .aspect_mask(vk::ImageAspectFlags::COLOR)
                                .layer_count(1),
                        )
                        .image_extent(vk::Extent3D {
                            width,
                            height,
                            depth: 1,
                        })],
                );
                let to_host = [vk::MemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                    .dst_access_mask(vk::AccessFlags::HOST_READ)];
                device.cmd_pipeline_barrier(
                    cmd,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::PipelineStageFlags::HOST,
                    vk::DependencyFlags::empty(),
                    &to_host,
                    &[],
                    &[],
                );
                device.end_command_buffer(cmd)?;
                let submit_cmds = [cmd];
                device.queue_submit(
                    queue,
                    &[vk::SubmitInfo::default().command_buffers(&submit_cmds)],
                    fences[k],
                )?;
                in_flight[k] = Some((i, frame));
            }
            for k in [count % 2, (count + 1) % 2] {
                finish(k, &mut in_flight[k], &mut renderer, &mut out)?;
            }
            for camera in &cameras {
                let (image, _) = reference.render(&scene.view_with(camera), |_| {})?;
                out.rendered.push(image.pixels);
                out.rendered_ms.push(image.gpu_ms);
                out.submissions = image.bands;
            }
        }
        device.device_wait_idle()?;
        for f in fences {
            device.destroy_fence(f, None);
        }
        device.destroy_command_pool(pool, None);
        for (b, m) in readbacks {
            device.destroy_buffer(b, None);
            device.free_memory(m.memory, None);
        }
        device.destroy_image(image, None);
        device.free_memory(image_memory.memory, None);
        app.destroy()?;
        Ok(out)
    }
}

/// Writes RGBA8 pixels as a PAM file (netpbm's RGB_ALPHA), which needs no image crate.
fn write_pam(path: &str, width: u32, height: u32, rgba8: &[u8]) -> std::io::Result<()> {
    let mut data = format!(
        "P7\nWIDTH {width}\nHEIGHT {height}\nDEPTH 4\nMAXVAL 255\nTUPLTYPE RGB_ALPHA\nENDHDR\n"
    )
    .into_bytes();
    data.extend_from_slice(rgba8);
    std::fs::write(path, data)
}

#[allow(dead_code)]
fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let format = match args
        .iter()
        .position(|a| a == "--format")
        .map(|i| args.get(i + 1))
    {
        None => TargetFormat::Rgba8Unorm,
        Some(Some(f)) if f == "rgba8" => TargetFormat::Rgba8Unorm,
        Some(Some(f)) if f == "rgba8-srgb" => TargetFormat::Rgba8Srgb,
        Some(Some(f)) if f == "rgba16f" => TargetFormat::Rgba16f,
        Some(Some(f)) if f == "rgba32f" => TargetFormat::Rgba32f,
        Some(other) => {
            return Err(format!(
                "--format: expected rgba8, rgba8-srgb, rgba16f or rgba32f, found {other:?}"
            )
            .into());
        }
    };
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
    };
    let number = |flag: &str, default: u32| -> Result<u32, Box<dyn Error>> {
        value(flag).map_or(Ok(default), |v| {
            v.parse()
                .map_err(|_| format!("{flag}: expected a positive integer, found {v:?}").into())
        })
    };
    let path = args
        .first()
        .filter(|a| !a.starts_with("--"))
        .cloned()
        .unwrap_or_else(|| "embed.pam".into());
    let size = number("--size", 256)?;
    let count = number("--frames", 8)?.max(2) as usize;
    let mut overrides = vec![
        format!("camera.width={size}"),
        format!("camera.height={size}"),
    ];
    overrides.extend(
        args.windows(2)
            .filter(|w| w[0] == "--set")
            .map(|w| w[1].clone()),
    );
    let frames = run(&overrides, count, 0.2, format)?;
    let last = frames.frames.last().ok_or("no frame")?;
    let rgba8: Vec<u8> = match format {
        TargetFormat::Rgba8Unorm | TargetFormat::Rgba8Srgb => last.clone(),
        _ => {
            let pixels = frames.rendered.last().ok_or("no frame")?;
            pixels
                .iter()
                .flat_map(|p| p.map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8))
                .collect()
        }
    };
    write_pam(&path, frames.width, frames.height, &rgba8)?;
    let median = |v: &[f64]| {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
    };
    println!(
        "GPU time per frame, median: recorded {:.2} ms ({} dispatches), render() {:.2} ms ({} \
         submissions)",
        median(&frames.recorded_ms),
        frames.dispatches,
        median(&frames.rendered_ms),
        frames.submissions
    );
    println!(
        "{} frames of {}×{} recorded into the application's {format:?} image; the last is in {path}; {} validation messages",
        frames.frames.len(),
        frames.width,
        frames.height,
        MESSAGES.load(Ordering::SeqCst)
    );
    Ok(())
}
