//! Instance, device choice, device and allocator, owned or wrapped around a caller's handles.
//!
//! Destruction order is enforced by ownership: resources hold `Arc<Shared>`; when the last one is
//! gone, `Shared::drop` frees the allocator (after checking for leaked allocations), then the
//! device, the debug messenger and the instance — the last three only when vmls created them.
//!
//! The Vulkan loader keeps process-wide lists of instances and devices, and Debian 12's
//! (1.3.239) walks them under one lock, to find the device behind vkGetDeviceProcAddr and
//! vkSetDebugUtilsObjectNameEXT, while vkDestroyDevice unlinks and frees an entry under another
//! (KhronosGroup/Vulkan-Loader#2018): two contexts on two threads, one naming a buffer while the
//! other dropped its device, crashed a test binary in SIGSEGV. So every context makes and
//! destroys its instance and device holding [`LOADER_LISTS`] for writing, and names objects
//! holding it for reading.

use super::commands::SubmitObjects;
use super::{VkError, VkResultExt};
use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use std::ffi::{CStr, CString, c_void};
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicU32, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, RwLock, RwLockReadGuard, RwLockWriteGuard};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// Held for writing while vmls creates or destroys an instance or a device (which changes the
/// loader's lists), for reading while a call walks them (see the module's docs).
static LOADER_LISTS: RwLock<()> = RwLock::new(());

/// The loader's lists, to change them. Not reentrant: nothing that holds it names an object.
fn changing_loader_lists() -> RwLockWriteGuard<'static, ()> {
    LOADER_LISTS.write().unwrap_or_else(|p| p.into_inner())
}

/// The loader's lists, for a call that walks them.
fn reading_loader_lists() -> RwLockReadGuard<'static, ()> {
    LOADER_LISTS.read().unwrap_or_else(|p| p.into_inner())
}

/// How to create a [`Context`].
#[derive(Debug, Clone, Default)]
pub struct ContextOptions {
    /// Enable the Khronos validation layer (and synchronization validation). `None` reads the
    /// environment variable `VMLS_VALIDATION` (`1` = on).
    pub validation: Option<bool>,
    /// With validation: also Khronos synchronization validation. `None` means yes.
    pub sync_validation: Option<bool>,
    /// Device index or case-insensitive name substring. `None` reads `VMLS_DEVICE`, else picks
    /// discrete > integrated > virtual > CPU.
    pub device: Option<String>,
    /// Always go through staging buffers for uploads and readbacks, as on a discrete GPU whose
    /// device-local memory is not mappable (lets lavapipe test that path).
    pub force_staging: bool,
}

/// What we know about the chosen device.
#[derive(Debug, Clone)]
pub struct DeviceInfo {
    pub name: String,
    pub device_type: String,
    pub driver: String,
    pub api_version: String,
    pub max_storage_buffer_range: u64,
    /// Bytes a uniform-buffer binding may span.
    pub max_uniform_buffer_range: u64,
    /// Elements a texel-buffer view may span.
    pub max_texel_buffer_elements: u64,
    pub max_workgroup_count: [u32; 3],
    /// Bytes of the largest device-local memory heap: no single buffer can be larger.
    pub max_heap_bytes: u64,
    /// Nanoseconds per timestamp tick; `None` when the queue has no timestamps.
    pub timestamp_period_ns: Option<f64>,
    /// Invocations per subgroup, and whether compute shaders have the basic, vote and
    /// arithmetic subgroup operations (`splat_raster` stops subgroups by vote, sums its
    /// counters with them and makes a continued walk's position the subgroup's).
    pub subgroup_size: u32,
    pub subgroup_ops: bool,
    /// The texel-view formats vmls binds (`BindingKind::texel`) that this device supports as
    /// storage texel buffers; a view of any other is refused naming its buffer.
    pub storage_texel_formats: Vec<vk::Format>,
    /// What a pipeline cache's header must name to be loaded here (`pipeline_cache`).
    pub vendor_id: u32,
    pub device_id: u32,
    pub pipeline_cache_uuid: [u8; 16],
}

/// Handles of a Vulkan device created by the embedding application.
pub struct RawContext {
    pub entry: ash::Entry,
    pub instance: ash::Instance,
    pub physical_device: vk::PhysicalDevice,
    pub device: ash::Device,
    /// A queue family with COMPUTE support, and a queue of it that vmls may submit to.
    pub queue_family_index: u32,
    pub queue: vk::Queue,
}

/// Counts validation errors and warnings reported through the debug messenger (core and
/// synchronization validation both report through it).
pub(crate) struct ValidationState {
    errors: AtomicU32,
    warnings: AtomicU32,
}

pub(crate) struct Shared {
    pub(crate) instance: ash::Instance,
    pub(crate) device: ash::Device,
    pub(crate) queue: Mutex<vk::Queue>,
    pub(crate) queue_family: u32,
    pub(crate) info: DeviceInfo,
    pub(crate) force_staging: bool,
    pub(crate) debug_names: Option<ash::ext::debug_utils::Device>,
    pub(crate) live_allocations: AtomicUsize,
    /// Bytes written from the host into buffers (`Buffer::write`), for benchmarks.
    pub(crate) bytes_uploaded: std::sync::atomic::AtomicU64,
    allocator: ManuallyDrop<Mutex<Allocator>>,
    /// Buffer allocations that may still succeed before every further one fails as out of
    /// memory (`u64::MAX`: no fault injected); see [`Context::fail_allocations_after`].
    allocations_before_fault: std::sync::atomic::AtomicU64,
    /// Finished submissions' command pools, fences and query pools, reused by the next ones.
    spare_submits: Mutex<Vec<SubmitObjects>>,
    /// Every pipeline's cache (`pipeline_cache`), and the lock its merges take.
    pub(crate) pipeline_cache: vk::PipelineCache,
    pub(crate) pipeline_cache_merge: Mutex<()>,
    messenger: Option<Messenger>,
    validation: Box<ValidationState>,
    owns_device: bool,
    _entry: ash::Entry,
}

/// A Vulkan device with one compute queue and an allocator. Cheap to clone.
#[derive(Clone)]
pub struct Context {
    pub(crate) shared: Arc<Shared>,
}

// SAFETY: the loader calls this with the arguments of PFN_vkDebugUtilsMessengerCallbackEXT;
// the body states what it reads of them.
unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the loader passes a valid callback-data pointer (or null) for the duration of the
    // call; `user` is the `ValidationState` boxed in `Shared`, which outlives the messenger.
    let message = unsafe {
        if data.is_null() || (*data).p_message.is_null() {
            String::from("(no message)")
        } else {
            CStr::from_ptr((*data).p_message)
                .to_string_lossy()
                .into_owned()
        }
    };
    if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) {
        if !user.is_null() {
            // SAFETY: see above; the state is only accessed through atomics.
            let state = unsafe { &*(user as *const ValidationState) };
            state.errors.fetch_add(1, Ordering::SeqCst);
        }
        eprintln!("vmls: Vulkan validation error: {message}");
    } else if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::WARNING) {
        if !user.is_null() {
            // SAFETY: as above.
            let state = unsafe { &*(user as *const ValidationState) };
            state.warnings.fetch_add(1, Ordering::SeqCst);
        }
        eprintln!("vmls: Vulkan validation warning: {message}");
    }
    vk::FALSE
}

fn env_flag(name: &str) -> bool {
    std::env::var(name).is_ok_and(|v| v == "1" || v.eq_ignore_ascii_case("true"))
}

fn type_rank(t: vk::PhysicalDeviceType) -> u32 {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => 0,
        vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
        vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
        vk::PhysicalDeviceType::CPU => 3,
        _ => 4,
    }
}

fn type_name(t: vk::PhysicalDeviceType) -> &'static str {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => "discrete",
        vk::PhysicalDeviceType::INTEGRATED_GPU => "integrated",
        vk::PhysicalDeviceType::VIRTUAL_GPU => "virtual",
        vk::PhysicalDeviceType::CPU => "cpu",
        _ => "other",
    }
}

fn version_string(v: u32) -> String {
    format!(
        "{}.{}.{}",
        vk::api_version_major(v),
        vk::api_version_minor(v),
        vk::api_version_patch(v)
    )
}

/// A physical device as listed by `vmls devices`.
struct Candidate {
    handle: vk::PhysicalDevice,
    name: String,
    kind: vk::PhysicalDeviceType,
    compute_family: Option<u32>,
}

fn messenger_create_info(user_data: *mut c_void) -> vk::DebugUtilsMessengerCreateInfoEXT<'static> {
    vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(
            vk::DebugUtilsMessageSeverityFlagsEXT::ERROR
                | vk::DebugUtilsMessageSeverityFlagsEXT::WARNING,
        )
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
        )
        .pfn_user_callback(Some(debug_callback))
        .user_data(user_data)
}

fn load_entry() -> Result<ash::Entry, VkError> {
    // SAFETY: loading libvulkan runs its initialisers; the loader is designed for this.
    unsafe { ash::Entry::load() }.map_err(|e| VkError::Loading(e.to_string()))
}

/// The debug messenger with the loader that destroys it.
type Messenger = (ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT);

fn create_instance(
    entry: &ash::Entry,
    validation: bool,
    sync_validation: bool,
) -> Result<(ash::Instance, Option<Messenger>, Box<ValidationState>), VkError> {
    let state = Box::new(ValidationState {
        errors: AtomicU32::new(0),
        warnings: AtomicU32::new(0),
    });
    let mut layers: Vec<*const i8> = Vec::new();
    let mut extensions: Vec<*const i8> = Vec::new();
    if validation {
        // SAFETY: plain query of instance layers.
        let available = unsafe { entry.enumerate_instance_layer_properties() }
            .call("vkEnumerateInstanceLayerProperties", || "instance".into())?;
        let found = available
            .iter()
            .any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == VALIDATION_LAYER));
        if !found {
            return Err(VkError::NoValidationLayer);
        }
        layers.push(VALIDATION_LAYER.as_ptr());
        extensions.push(ash::ext::debug_utils::NAME.as_ptr());
    }
    let app = vk::ApplicationInfo::default()
        .application_name(c"vmls")
        .engine_name(c"vmls")
        .api_version(vk::API_VERSION_1_2);
    let enabled_validation = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
    let enabled = if sync_validation {
        &enabled_validation[..]
    } else {
        &[]
    };
    let mut features = vk::ValidationFeaturesEXT::default().enabled_validation_features(enabled);
    let user_data = &*state as *const ValidationState as *mut c_void;
    let mut messenger_info = messenger_create_info(user_data);
    let mut info = vk::InstanceCreateInfo::default()
        .application_info(&app)
        .enabled_layer_names(&layers)
        .enabled_extension_names(&extensions);
    if validation {
        info = info.push_next(&mut features).push_next(&mut messenger_info);
    }
    // SAFETY: every pointer in `info` refers to locals that outlive this call.
    let instance = unsafe { entry.create_instance(&info, None) }
        .call("vkCreateInstance", || "the vmls instance".into())?;
    let messenger = if validation {
        let loader = ash::ext::debug_utils::Instance::new(entry, &instance);
        // A fresh create info: the one above is chained into the instance's pNext list.
        let create = messenger_create_info(user_data);
        // SAFETY: the instance was created with VK_EXT_debug_utils enabled; the callback's user
        // data is the boxed state, which `Shared` keeps alive until after the messenger dies.
        match unsafe { loader.create_debug_utils_messenger(&create, None) } {
            Ok(m) => Some((loader, m)),
            Err(result) => {
                // SAFETY: nothing else was created from this instance yet.
                unsafe { instance.destroy_instance(None) };
                return Err(VkError::Call {
                    call: "vkCreateDebugUtilsMessengerEXT",
                    what: "the validation messenger".into(),
                    result,
                });
            }
        }
    } else {
        None
    };
    Ok((instance, messenger, state))
}

fn candidates(instance: &ash::Instance) -> Result<Vec<Candidate>, VkError> {
    // SAFETY: plain queries on a live instance.
    let devices = unsafe { instance.enumerate_physical_devices() }
        .call("vkEnumeratePhysicalDevices", || "instance".into())?;
    Ok(devices
        .into_iter()
        .map(|handle| {
            // SAFETY: `handle` came from this instance.
            let props = unsafe { instance.get_physical_device_properties(handle) };
            // SAFETY: as above.
            let families = unsafe { instance.get_physical_device_queue_family_properties(handle) };
            let compute_family = families
                .iter()
                .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
                .and_then(|i| u32::try_from(i).ok());
            Candidate {
                handle,
                name: props
                    .device_name_as_c_str()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default(),
                kind: props.device_type,
                compute_family,
            }
        })
        .collect())
}

fn choose(list: &[Candidate], wanted: Option<&str>) -> Result<usize, VkError> {
    let usable: Vec<usize> = (0..list.len())
        .filter(|&i| list[i].compute_family.is_some())
        .collect();
    if usable.is_empty() {
        return Err(VkError::NoDevice(if list.is_empty() {
            " (the loader reports no device: is mesa-vulkan-drivers installed? run tools/setup)"
                .into()
        } else {
            String::new()
        }));
    }
    let Some(wanted) = wanted.filter(|w| !w.is_empty()) else {
        let best = usable
            .iter()
            .copied()
            .min_by_key(|&i| type_rank(list[i].kind));
        return best.ok_or_else(|| VkError::NoDevice(String::new()));
    };
    let found = if let Ok(index) = wanted.parse::<usize>() {
        usable.iter().copied().find(|&i| i == index)
    } else {
        let w = wanted.to_lowercase();
        usable
            .iter()
            .copied()
            .find(|&i| list[i].name.to_lowercase().contains(&w))
    };
    found.ok_or_else(|| VkError::DeviceNotFound {
        wanted: wanted.to_string(),
        available: list
            .iter()
            .enumerate()
            .map(|(i, c)| format!("{i}: {}", c.name))
            .collect::<Vec<_>>()
            .join(", "),
    })
}

/// The `local`-th process's device among the usable ones of the preferred type (round robin),
/// or `None` with at most one of them.
fn spread(list: &[Candidate], local: usize) -> Option<usize> {
    let usable: Vec<usize> = (0..list.len())
        .filter(|&i| list[i].compute_family.is_some())
        .collect();
    let best = usable.iter().map(|&i| type_rank(list[i].kind)).min()?;
    let same: Vec<usize> = usable
        .into_iter()
        .filter(|&i| type_rank(list[i].kind) == best)
        .collect();
    (same.len() > 1).then(|| same[local % same.len()])
}

fn device_info(
    instance: &ash::Instance,
    physical: vk::PhysicalDevice,
    queue_family: u32,
) -> DeviceInfo {
    // SAFETY: plain queries on a device of this instance.
    let props = unsafe { instance.get_physical_device_properties(physical) };
    // SAFETY: as above.
    let families = unsafe { instance.get_physical_device_queue_family_properties(physical) };
    let mut driver = vk::PhysicalDeviceDriverProperties::default();
    let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
    let mut props2 = vk::PhysicalDeviceProperties2::default()
        .push_next(&mut driver)
        .push_next(&mut subgroup);
    // SAFETY: Vulkan 1.1+ query with a valid pNext chain of locals.
    unsafe { instance.get_physical_device_properties2(physical, &mut props2) };
    let driver_name = driver
        .driver_info_as_c_str()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let valid_bits = families
        .get(queue_family as usize)
        .map_or(0, |f| f.timestamp_valid_bits);
    // SAFETY: as above.
    let memory = unsafe { instance.get_physical_device_memory_properties(physical) };
    let max_heap_bytes = memory
        .memory_heaps_as_slice()
        .iter()
        .filter(|h| h.flags.contains(vk::MemoryHeapFlags::DEVICE_LOCAL))
        .map(|h| h.size)
        .max()
        .unwrap_or(u64::MAX);
    let storage_texel_formats = super::TEXEL_FORMATS
        .into_iter()
        .filter(|&f| {
            // SAFETY: a plain query on a device of this instance.
            let p = unsafe { instance.get_physical_device_format_properties(physical, f) };
            p.buffer_features
                .contains(vk::FormatFeatureFlags::STORAGE_TEXEL_BUFFER)
        })
        .collect();
    DeviceInfo {
        storage_texel_formats,
        vendor_id: props.vendor_id,
        device_id: props.device_id,
        pipeline_cache_uuid: props.pipeline_cache_uuid,
        name: props
            .device_name_as_c_str()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        device_type: type_name(props.device_type).into(),
        driver: driver_name,
        api_version: version_string(props.api_version),
        max_storage_buffer_range: u64::from(props.limits.max_storage_buffer_range),
        max_uniform_buffer_range: u64::from(props.limits.max_uniform_buffer_range),
        max_texel_buffer_elements: u64::from(props.limits.max_texel_buffer_elements),
        max_workgroup_count: props.limits.max_compute_work_group_count,
        max_heap_bytes,
        timestamp_period_ns: (valid_bits > 0 && props.limits.timestamp_period > 0.0)
            .then_some(f64::from(props.limits.timestamp_period)),
        subgroup_size: subgroup.subgroup_size.max(1),
        subgroup_ops: subgroup
            .supported_stages
            .contains(vk::ShaderStageFlags::COMPUTE)
            && subgroup.supported_operations.contains(
                vk::SubgroupFeatureFlags::BASIC
                    | vk::SubgroupFeatureFlags::VOTE
                    | vk::SubgroupFeatureFlags::ARITHMETIC,
            ),
    }
}

/// The environment variable that injects an allocation failure into contexts made by
/// [`Context::new`] (see [`Context::fail_allocations_after`]): lets end-to-end tests drive
/// the CLI into out-of-memory at any allocation.
pub const FAIL_ALLOCATIONS_VAR: &str = "VMLS_FAIL_ALLOCATIONS_AFTER";

/// `VMLS_FAIL_ALLOCATIONS_AFTER` as a count, `None` when unset.
fn allocation_fault_from_env() -> Result<Option<u64>, VkError> {
    match std::env::var(FAIL_ALLOCATIONS_VAR) {
        Err(_) => Ok(None),
        Ok(text) => text.trim().parse().map(Some).map_err(|_| {
            VkError::Usage(format!(
                "{FAIL_ALLOCATIONS_VAR}: expected a number of buffer allocations, found {:?}",
                text.chars().take(40).collect::<String>()
            ))
        }),
    }
}

impl Context {
    /// Creates an instance and a device of our own. Reads `VMLS_VALIDATION`, `VMLS_DEVICE`
    /// (where the options leave them open) and [`FAIL_ALLOCATIONS_VAR`].
    pub fn new(options: &ContextOptions) -> Result<Self, VkError> {
        let validation = options
            .validation
            .unwrap_or_else(|| env_flag("VMLS_VALIDATION"));
        let wanted = options
            .device
            .clone()
            .or_else(|| std::env::var("VMLS_DEVICE").ok());
        let fault = allocation_fault_from_env()?;
        let entry = load_entry()?;
        let sync = options.sync_validation.unwrap_or(true);
        // Through `assemble`, which loads the debug-name functions (vkGetDeviceProcAddr).
        let _lists = changing_loader_lists();
        let (instance, messenger, state) = create_instance(&entry, validation, sync)?;
        // From here on, failures must destroy what exists: build a guard-like closure.
        let destroy_instance = |messenger: Option<Messenger>| {
            if let Some((loader, m)) = messenger {
                // SAFETY: the messenger belongs to this instance and nothing uses it any more.
                unsafe { loader.destroy_debug_utils_messenger(m, None) };
            }
            // SAFETY: no child object of the instance is alive at this point.
            unsafe { instance.destroy_instance(None) };
        };
        let list = match candidates(&instance) {
            Ok(l) => l,
            Err(e) => {
                destroy_instance(messenger);
                return Err(e);
            }
        };
        let chosen = match choose(&list, wanted.as_deref()) {
            Ok(c) => &list[c],
            Err(e) => {
                destroy_instance(messenger);
                return Err(e);
            }
        };
        let Some(queue_family) = chosen.compute_family else {
            destroy_instance(messenger);
            return Err(VkError::NoDevice(String::new()));
        };
        let priorities = [1.0f32];
        let queue_info = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(queue_family)
            .queue_priorities(&priorities)];
        let device_info_ci = vk::DeviceCreateInfo::default().queue_create_infos(&queue_info);
        // SAFETY: `chosen.handle` belongs to `instance`; the create info points at locals.
        let device = match unsafe { instance.create_device(chosen.handle, &device_info_ci, None) } {
            Ok(d) => d,
            Err(result) => {
                destroy_instance(messenger);
                return Err(VkError::Call {
                    call: "vkCreateDevice",
                    what: chosen.name.clone(),
                    result,
                });
            }
        };
        // SAFETY: queue 0 of a family we requested one queue from.
        let queue = unsafe { device.get_device_queue(queue_family, 0) };
        Self::assemble(
            entry,
            instance,
            chosen.handle,
            device,
            queue_family,
            queue,
            messenger,
            state,
            true,
            options.force_staging,
            validation,
        )
        .inspect(|ctx| ctx.fail_allocations_after(fault))
    }

    /// Wraps a device created by the embedding application. vmls creates only its allocator and
    /// its own resources on it, and destroys neither the device nor the instance.
    ///
    /// # Safety
    /// The handles must be valid, belong together, and stay alive until every vmls object created
    /// from this context has been dropped. The queue must support COMPUTE and must not be used
    /// by another thread while vmls submits to it.
    pub unsafe fn from_raw(raw: RawContext, force_staging: bool) -> Result<Self, VkError> {
        Self::assemble(
            raw.entry,
            raw.instance,
            raw.physical_device,
            raw.device,
            raw.queue_family_index,
            raw.queue,
            None,
            Box::new(ValidationState {
                errors: AtomicU32::new(0),
                warnings: AtomicU32::new(0),
            }),
            false,
            force_staging,
            false,
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn assemble(
        entry: ash::Entry,
        instance: ash::Instance,
        physical_device: vk::PhysicalDevice,
        device: ash::Device,
        queue_family: u32,
        queue: vk::Queue,
        messenger: Option<Messenger>,
        validation: Box<ValidationState>,
        owns_device: bool,
        force_staging: bool,
        debug_names: bool,
    ) -> Result<Self, VkError> {
        let info = device_info(&instance, physical_device, queue_family);
        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device,
            debug_settings: Default::default(),
            buffer_device_address: false,
            allocation_sizes: Default::default(),
        });
        let allocator = match allocator {
            Ok(a) => a,
            Err(source) => {
                if owns_device {
                    // SAFETY: nothing was created on the device yet.
                    unsafe { device.destroy_device(None) };
                    if let Some((loader, m)) = &messenger {
                        // SAFETY: the messenger belongs to this instance.
                        unsafe { loader.destroy_debug_utils_messenger(*m, None) };
                    }
                    // SAFETY: the device, its only child, is gone.
                    unsafe { instance.destroy_instance(None) };
                }
                return Err(VkError::Allocation {
                    resource: "the allocator".into(),
                    bytes: 0,
                    source,
                });
            }
        };
        let debug_names =
            debug_names.then(|| ash::ext::debug_utils::Device::new(&instance, &device));
        let pipeline_cache = super::pipeline_cache::create(&device);
        Ok(Self {
            shared: Arc::new(Shared {
                instance,
                device,
                queue: Mutex::new(queue),
                queue_family,
                info,
                force_staging,
                debug_names,
                live_allocations: AtomicUsize::new(0),
                bytes_uploaded: std::sync::atomic::AtomicU64::new(0),
                allocator: ManuallyDrop::new(Mutex::new(allocator)),
                allocations_before_fault: std::sync::atomic::AtomicU64::new(u64::MAX),
                spare_submits: Mutex::new(Vec::new()),
                pipeline_cache,
                pipeline_cache_merge: Mutex::new(()),
                messenger,
                validation,
                owns_device,
                _entry: entry,
            }),
        })
    }

    /// The device index the `local`-th process on a node takes when each process drives a
    /// device of its own (MPI ranks): the devices of the type vmls prefers, in the loader's
    /// order, taken round robin ([`spread`]); `None` where the node has at most one of them (the
    /// default choice then serves).
    pub fn device_for_process(local: usize) -> Result<Option<usize>, VkError> {
        let entry = load_entry()?;
        let _lists = changing_loader_lists();
        let (instance, _, _) = create_instance(&entry, false, false)?;
        let result = candidates(&instance).map(|list| spread(&list, local));
        // SAFETY: no child of this instance exists.
        unsafe { instance.destroy_instance(None) };
        result
    }

    /// Lists the devices the loader reports, one line each, marking the one vmls would choose.
    pub fn list_devices() -> Result<Vec<String>, VkError> {
        let entry = load_entry()?;
        let _lists = changing_loader_lists();
        let (instance, _, _) = create_instance(&entry, false, false)?;
        let result = candidates(&instance).map(|list| {
            let best = choose(&list, None).ok();
            list.iter()
                .enumerate()
                .map(|(i, c)| {
                    let info = device_info(&instance, c.handle, c.compute_family.unwrap_or(0));
                    format!(
                        "{}{i}: {} ({}, Vulkan {}, {}){}",
                        if Some(i) == best { "* " } else { "  " },
                        c.name,
                        info.device_type,
                        info.api_version,
                        info.driver,
                        if c.compute_family.is_none() {
                            " [no compute queue]"
                        } else {
                            ""
                        }
                    )
                })
                .collect()
        });
        // SAFETY: no child of this instance exists.
        unsafe { instance.destroy_instance(None) };
        result
    }

    /// The chosen device.
    pub fn info(&self) -> &DeviceInfo {
        &self.shared.info
    }

    /// Validation errors reported so far (always 0 when validation is off).
    pub fn validation_errors(&self) -> u32 {
        self.shared.validation.errors.load(Ordering::SeqCst)
    }

    /// Validation warnings reported so far (always 0 when validation is off); the test suite
    /// requires none, as it requires no error.
    pub fn validation_warnings(&self) -> u32 {
        self.shared.validation.warnings.load(Ordering::SeqCst)
    }

    /// Bytes written from the host into buffers so far (mapped copies and staged uploads alike).
    pub fn bytes_uploaded(&self) -> u64 {
        self.shared.bytes_uploaded.load(Ordering::SeqCst)
    }

    /// Fault injection for tests and audits: after `n` more successful buffer allocations, every
    /// allocation fails as the device's being out of memory (`VkError::OutOfMemory`) until
    /// called with `None`. Lets tests drive each allocation of a render into failure, which
    /// a real device reaches only under memory pressure.
    pub fn fail_allocations_after(&self, n: Option<u64>) {
        self.shared
            .allocations_before_fault
            .store(n.unwrap_or(u64::MAX), Ordering::SeqCst);
    }

    /// Buffers currently allocated from this context.
    pub fn live_allocations(&self) -> usize {
        self.shared.live_allocations.load(Ordering::SeqCst)
    }

    /// gpu-allocator's report: (bytes in live allocations, bytes of the memory blocks it holds
    /// from the driver), to show that repeated frames keep GPU memory flat.
    pub fn allocator_bytes(&self) -> (u64, u64) {
        let report = self.shared.allocator().generate_report();
        (report.total_allocated_bytes, report.total_capacity_bytes)
    }
}

impl Shared {
    pub(crate) fn allocator(&self) -> MutexGuard<'_, Allocator> {
        // A poisoned lock only means another thread panicked mid-allocation; the allocator's
        // state is still consistent for freeing, so keep going.
        self.allocator.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Whether an injected fault fails this buffer allocation (counting it down otherwise).
    pub(crate) fn injected_allocation_failure(&self) -> bool {
        let mut fail = false;
        let _ = self.allocations_before_fault.fetch_update(
            Ordering::SeqCst,
            Ordering::SeqCst,
            |left| match left {
                u64::MAX => None,
                0 => {
                    fail = true;
                    None
                }
                n => Some(n - 1),
            },
        );
        fail
    }

    pub(crate) fn spare_submits(&self) -> MutexGuard<'_, Vec<SubmitObjects>> {
        self.spare_submits.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub(crate) fn queue(&self) -> MutexGuard<'_, vk::Queue> {
        self.queue.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Gives a Vulkan object a debug name (shown by validation messages and GPU debuggers).
    pub(crate) fn set_name<H: vk::Handle>(&self, handle: H, name: &str) {
        if let (Some(loader), Ok(name)) = (&self.debug_names, CString::new(name)) {
            let info = vk::DebugUtilsObjectNameInfoEXT::default()
                .object_handle(handle)
                .object_name(&name);
            let _lists = reading_loader_lists();
            // SAFETY: `handle` is a live object of this device; naming is best-effort, so a
            // failure is ignored on purpose.
            let _ = unsafe { loader.set_debug_utils_object_name(&info) };
        }
    }
}

impl Drop for Shared {
    fn drop(&mut self) {
        let live = self.live_allocations.load(Ordering::SeqCst);
        if live != 0 {
            eprintln!("vmls: leak report: {live} GPU allocation(s) still alive at shutdown");
        }
        // SAFETY: every resource holding this `Shared` is gone (we are in its drop), so no
        // command uses the device; the allocator is dropped exactly once, before the device.
        unsafe {
            // On the application's device only vmls's queue is ours to wait for: a device-wide
            // wait would need every queue of the application externally synchronised.
            if self.owns_device {
                let _ = self.device.device_wait_idle();
            } else {
                let queue = self.queue.get_mut().unwrap_or_else(|p| p.into_inner());
                let _ = self.device.queue_wait_idle(*queue);
            }
            let spares = std::mem::take(
                self.spare_submits
                    .get_mut()
                    .unwrap_or_else(|p| p.into_inner()),
            );
            for objects in spares {
                objects.destroy(&self.device);
            }
            // Ours on any device, the application's too; null is a no-op.
            self.device
                .destroy_pipeline_cache(self.pipeline_cache, None);
            ManuallyDrop::drop(&mut self.allocator);
            if self.owns_device {
                let _lists = changing_loader_lists();
                self.device.destroy_device(None);
                if let Some((loader, m)) = self.messenger.take() {
                    loader.destroy_debug_utils_messenger(m, None);
                }
                self.instance.destroy_instance(None);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{Candidate, spread};
    use ash::vk;

    fn candidate(kind: vk::PhysicalDeviceType, compute: bool) -> Candidate {
        Candidate {
            handle: vk::PhysicalDevice::null(),
            name: String::new(),
            kind,
            compute_family: compute.then_some(0),
        }
    }

    #[test]
    fn processes_take_the_preferred_devices_round_robin() {
        use vk::PhysicalDeviceType as T;
        // A CPU device, two discrete GPUs, one discrete without compute, an integrated one.
        let node = [
            candidate(T::CPU, true),
            candidate(T::DISCRETE_GPU, true),
            candidate(T::DISCRETE_GPU, false),
            candidate(T::INTEGRATED_GPU, true),
            candidate(T::DISCRETE_GPU, true),
        ];
        let taken: Vec<Option<usize>> = (0..5).map(|local| spread(&node, local)).collect();
        assert_eq!(taken, [Some(1), Some(4), Some(1), Some(4), Some(1)]);
        // One device of the preferred kind: the default choice serves.
        let lavapipe = [candidate(T::CPU, true)];
        assert_eq!(spread(&lavapipe, 3), None);
        assert_eq!(spread(&[], 0), None);
    }
}
