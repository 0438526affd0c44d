//! vmls inside an application that already has Vulkan: the test creates its own instance
//! (with validation and its own messenger) and device, wraps them, runs vmls work, drops vmls,
//! and then destroys its own objects — which must still be valid.
//!
//! This is the one place outside the Vulkan layer with `unsafe`: it plays the embedding
//! application, whose raw Vulkan calls are unsafe by nature.

use ash::vk;
use std::ffi::{CStr, c_void};
use std::sync::atomic::{AtomicU32, Ordering};
use vmls::field::Field;
use vmls::field::gpu::{GpuField, evaluate};
use vmls::recon::{Basis, GradientMode, OctreeSettings, Weight};
use vmls::scene::{NeighbourMode, Reconstruction};
use vmls::vk::{Context, RawContext, ShaderCompiler};

static ERRORS: AtomicU32 = AtomicU32::new(0);

unsafe extern "system" fn count_errors(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    _: *mut c_void,
) -> vk::Bool32 {
    if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) {
        ERRORS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: the loader passes a valid message for the duration of the call.
        let msg = unsafe { CStr::from_ptr((*data).p_message) };
        eprintln!("validation error: {}", msg.to_string_lossy());
    }
    vk::FALSE
}

#[test]
fn wraps_an_application_device() {
    // SAFETY: the test is the application: it creates, uses and destroys its objects in order.
    unsafe {
        let entry = ash::Entry::load().expect("libvulkan");
        let layers = [c"VK_LAYER_KHRONOS_validation".as_ptr()];
        let extensions = [ash::ext::debug_utils::NAME.as_ptr()];
        let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_2);
        let instance = entry
            .create_instance(
                &vk::InstanceCreateInfo::default()
                    .application_info(&app)
                    .enabled_layer_names(&layers)
                    .enabled_extension_names(&extensions),
                None,
            )
            .expect("instance");
        let debug = ash::ext::debug_utils::Instance::new(&entry, &instance);
        let messenger = debug
            .create_debug_utils_messenger(
                &vk::DebugUtilsMessengerCreateInfoEXT::default()
                    .message_severity(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR)
                    .message_type(vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION)
                    .pfn_user_callback(Some(count_errors)),
                None,
            )
            .expect("messenger");
        let physical = instance.enumerate_physical_devices().expect("devices")[0];
        let family = instance
            .get_physical_device_queue_family_properties(physical)
            .iter()
            .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
            .expect("compute queue") as u32;
        let priorities = [1.0];
        let queues = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(family)
            .queue_priorities(&priorities)];
        let device = instance
            .create_device(
                physical,
                &vk::DeviceCreateInfo::default().queue_create_infos(&queues),
                None,
            )
            .expect("device");
        let queue = device.get_device_queue(family, 0);

        {
            let ctx = Context::from_raw(
                RawContext {
                    entry: entry.clone(),
                    instance: instance.clone(),
                    physical_device: physical,
                    device: device.clone(),
                    queue_family_index: family,
                    queue,
                },
                false,
            )
            .expect("wrap");
            let compiler = ShaderCompiler::new().expect("shaderc");
            let field = Field::new(
                vmls::data::marschner_lobb::generate(9),
                Reconstruction {
                    method: vmls::recon::ReconMethod::Mls,
                    sigma: vmls::recon::gaussian::DEFAULT_SIGMA,
                    basis: Basis::Linear,
                    weight: Weight::Wendland,
                    gradient: GradientMode::Local,
                    support: 2.4,
                    neighbours: NeighbourMode::Grid,
                    resample: 0,
                    resample_auto: false,
                    resample_direct: false,
                    direct_cells: None,
                },
                &OctreeSettings::default(),
                |_| {},
            )
            .expect("field");
            let gf = GpuField::upload(&ctx, &field).expect("upload");
            let (out, _) =
                evaluate(&ctx, &compiler, &field, &gf, &[[0.0, 0.0, 0.0]], 1).expect("eval");
            assert_eq!(out[0].terms, 4);
            let cpu = vmls::recon::mls_evaluate(
                &field.mls(),
                field.neighbours().expect("neighbours").as_ref(),
                [0.0; 3],
            )
            .expect("defined");
            assert!(
                (f64::from(out[0].value) - cpu.value).abs() < 1e-5,
                "GPU {} vs CPU {}",
                out[0].value,
                cpu.value
            );
            drop(gf);
            assert_eq!(ctx.live_allocations(), 0);
        }
        // vmls is gone; the application's device must still be alive and usable.
        device
            .device_wait_idle()
            .expect("device still valid after vmls dropped");
        device.destroy_device(None);
        debug.destroy_debug_utils_messenger(messenger, None);
        instance.destroy_instance(None);
    }
    assert_eq!(ERRORS.load(Ordering::SeqCst), 0, "validation errors");
}
