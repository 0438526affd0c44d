/* vmls from C: the application creates its Vulkan instance, device, an RGBA8 image and a
 * command buffer; vmls (through the C ABI, tools/capi) records frames of a scene into
 * that command buffer, writing the image, while the camera turns; the application copies the
 * last frame to a host buffer and writes it as a PAM file.
 *
 *   cargo build -p vmls-capi            # target/debug/libvmls_capi.so, tools/capi/include/vmls.h
 *   cc examples/embed.c -I tools/capi/include -L target/debug -lvmls_capi -lvulkan \
 *      -Wl,-rpath,$PWD/target/debug -o embed-c && ./embed-c out.pam [key=value ...]
 *
 * With VMLS_VALIDATION=1 the Khronos validation layer runs with synchronization validation, and
 * the program exits with status 3 if it reported anything (tests/capi.rs runs it that way). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <vulkan/vulkan.h>

#include "vmls.h"

static unsigned messages = 0;

static VKAPI_ATTR VkBool32 VKAPI_CALL on_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                                 VkDebugUtilsMessageTypeFlagsEXT type,
                                                 const VkDebugUtilsMessengerCallbackDataEXT *data,
                                                 void *user) {
    (void)type;
    (void)user;
    if (severity & (VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT |
                    VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT)) {
        messages++;
        fprintf(stderr, "validation: %s\n", data->pMessage);
    }
    return VK_FALSE;
}

#define VK_CHECK(call)                                                                   \
    do {                                                                                 \
        VkResult r_ = (call);                                                            \
        if (r_ != VK_SUCCESS) {                                                          \
            fprintf(stderr, "%s failed: %d (line %d)\n", #call, (int)r_, __LINE__);      \
            exit(1);                                                                     \
        }                                                                                \
    } while (0)

#define VMLS_CHECK(call)                                                                 \
    do {                                                                                 \
        VmlsStatus s_ = (call);                                                          \
        if (s_ != VMLS_OK) {                                                             \
            fprintf(stderr, "%s failed (%d): %s\n", #call, (int)s_, vmls_last_error());  \
            exit(2);                                                                     \
        }                                                                                \
    } while (0)

static uint32_t memory_type(const VkPhysicalDeviceMemoryProperties *props, uint32_t bits,
                            VkMemoryPropertyFlags flags) {
    for (uint32_t i = 0; i < props->memoryTypeCount; i++) {
        if ((bits & (1u << i)) && (props->memoryTypes[i].propertyFlags & flags) == flags) {
            return i;
        }
    }
    fprintf(stderr, "no memory type with flags %u\n", (unsigned)flags);
    exit(1);
}

int main(int argc, char **argv) {
    const char *path = argc > 1 ? argv[1] : "embed-c.pam";
    const char *validation_env = getenv("VMLS_VALIDATION");
    int validation = validation_env && strcmp(validation_env, "1") == 0;

    /* The application's instance and device. */
    VkApplicationInfo app = {.sType = VK_STRUCTURE_TYPE_APPLICATION_INFO,
                             .apiVersion = VK_API_VERSION_1_2};
    const char *layers[] = {"VK_LAYER_KHRONOS_validation"};
    const char *extensions[] = {VK_EXT_DEBUG_UTILS_EXTENSION_NAME};
    VkValidationFeatureEnableEXT enables[] = {VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT};
    VkValidationFeaturesEXT features = {.sType = VK_STRUCTURE_TYPE_VALIDATION_FEATURES_EXT,
                                        .enabledValidationFeatureCount = 1,
                                        .pEnabledValidationFeatures = enables};
    VkInstanceCreateInfo instance_info = {.sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO,
                                          .pApplicationInfo = &app};
    if (validation) {
        instance_info.pNext = &features;
        instance_info.enabledLayerCount = 1;
        instance_info.ppEnabledLayerNames = layers;
        instance_info.enabledExtensionCount = 1;
        instance_info.ppEnabledExtensionNames = extensions;
    }
    VkInstance instance;
    VK_CHECK(vkCreateInstance(&instance_info, NULL, &instance));
    VkDebugUtilsMessengerEXT messenger = VK_NULL_HANDLE;
    PFN_vkCreateDebugUtilsMessengerEXT create_messenger =
        (PFN_vkCreateDebugUtilsMessengerEXT)vkGetInstanceProcAddr(instance, "vkCreateDebugUtilsMessengerEXT");
    PFN_vkDestroyDebugUtilsMessengerEXT destroy_messenger =
        (PFN_vkDestroyDebugUtilsMessengerEXT)vkGetInstanceProcAddr(instance, "vkDestroyDebugUtilsMessengerEXT");
    if (validation && create_messenger) {
        VkDebugUtilsMessengerCreateInfoEXT info = {
            .sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT,
            .messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT |
                               VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT,
            .messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT,
            .pfnUserCallback = on_message};
        VK_CHECK(create_messenger(instance, &info, NULL, &messenger));
    }
    uint32_t count = 1;
    VkPhysicalDevice physical;
    VkResult listed = vkEnumeratePhysicalDevices(instance, &count, &physical);
    if ((listed != VK_SUCCESS && listed != VK_INCOMPLETE) || count == 0) {
        fprintf(stderr, "no Vulkan device\n");
        return 1;
    }
    uint32_t families = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(physical, &families, NULL);
    VkQueueFamilyProperties *family_props = calloc(families, sizeof *family_props);
    vkGetPhysicalDeviceQueueFamilyProperties(physical, &families, family_props);
    uint32_t family = families;
    for (uint32_t i = 0; i < families; i++) {
        if (family_props[i].queueFlags & VK_QUEUE_COMPUTE_BIT) {
            family = i;
            break;
        }
    }
    free(family_props);
    if (family == families) {
        fprintf(stderr, "no compute queue\n");
        return 1;
    }
    float priority = 1.0f;
    VkDeviceQueueCreateInfo queue_info = {.sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO,
                                          .queueFamilyIndex = family,
                                          .queueCount = 1,
                                          .pQueuePriorities = &priority};
    VkDeviceCreateInfo device_info = {.sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO,
                                      .queueCreateInfoCount = 1,
                                      .pQueueCreateInfos = &queue_info};
    VkDevice device;
    VK_CHECK(vkCreateDevice(physical, &device_info, NULL, &device));
    VkQueue queue;
    vkGetDeviceQueue(device, family, 0, &queue);
    VkPhysicalDeviceMemoryProperties props;
    vkGetPhysicalDeviceMemoryProperties(physical, &props);

    /* vmls on that device, and a scene: the built-in one at 96 × 64 unless the command line
     * overrides keys (volume.file="data.vti" renders a dataset). */
    VmlsRawContext raw = {.get_instance_proc_addr = vkGetInstanceProcAddr,
                          .instance = instance,
                          .physical_device = physical,
                          .device = device,
                          .queue_family_index = family,
                          .queue = queue};
    VmlsContext *ctx = NULL;
    VMLS_CHECK(vmls_context_from_raw(&raw, &ctx));
    const char *defaults[] = {"camera.width=96", "camera.height=64"};
    const char **overrides = argc > 2 ? (const char **)&argv[2] : defaults;
    size_t override_count = argc > 2 ? (size_t)(argc - 2) : 2;
    VmlsScene *scene = NULL;
    VMLS_CHECK(vmls_scene_load(NULL, overrides, override_count, &scene));
    uint32_t width, height;
    VMLS_CHECK(vmls_scene_size(scene, &width, &height));
    VmlsRenderer *renderer = NULL;
    VMLS_CHECK(vmls_renderer_create(ctx, scene, &renderer));
    VMLS_CHECK(vmls_renderer_prepare(renderer, scene));

    /* The application's image and a host buffer for the last frame. */
    VkImageCreateInfo image_info = {.sType = VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO,
                                    .imageType = VK_IMAGE_TYPE_2D,
                                    .format = VK_FORMAT_R8G8B8A8_UNORM,
                                    .extent = {width, height, 1},
                                    .mipLevels = 1,
                                    .arrayLayers = 1,
                                    .samples = VK_SAMPLE_COUNT_1_BIT,
                                    .tiling = VK_IMAGE_TILING_OPTIMAL,
                                    .usage = VK_IMAGE_USAGE_TRANSFER_DST_BIT |
                                             VK_IMAGE_USAGE_TRANSFER_SRC_BIT,
                                    .initialLayout = VK_IMAGE_LAYOUT_UNDEFINED};
    VkImage image;
    VK_CHECK(vkCreateImage(device, &image_info, NULL, &image));
    VkMemoryRequirements req;
    vkGetImageMemoryRequirements(device, image, &req);
    VkMemoryAllocateInfo alloc = {.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO,
                                  .allocationSize = req.size,
                                  .memoryTypeIndex = memory_type(&props, req.memoryTypeBits, 0)};
    VkDeviceMemory image_memory;
    VK_CHECK(vkAllocateMemory(device, &alloc, NULL, &image_memory));
    VK_CHECK(vkBindImageMemory(device, image, image_memory, 0));
    VkDeviceSize bytes = (VkDeviceSize)width * height * 4;
    VkBufferCreateInfo buffer_info = {.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO,
                                      .size = bytes,
                                      .usage = VK_BUFFER_USAGE_TRANSFER_DST_BIT};
    VkBuffer host;
    VK_CHECK(vkCreateBuffer(device, &buffer_info, NULL, &host));
    vkGetBufferMemoryRequirements(device, host, &req);
    alloc.allocationSize = req.size;
    alloc.memoryTypeIndex = memory_type(&props, req.memoryTypeBits,
                                        VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT |
                                            VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
    VkDeviceMemory host_memory;
    VK_CHECK(vkAllocateMemory(device, &alloc, NULL, &host_memory));
    VK_CHECK(vkBindBufferMemory(device, host, host_memory, 0));

    VkCommandPoolCreateInfo pool_info = {.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO,
                                         .flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT,
                                         .queueFamilyIndex = family};
    VkCommandPool pool;
    VK_CHECK(vkCreateCommandPool(device, &pool_info, NULL, &pool));
    VkCommandBufferAllocateInfo cmd_info = {.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO,
                                            .commandPool = pool,
                                            .level = VK_COMMAND_BUFFER_LEVEL_PRIMARY,
                                            .commandBufferCount = 1};
    VkCommandBuffer cmd;
    VK_CHECK(vkAllocateCommandBuffers(device, &cmd_info, &cmd));
    VkFenceCreateInfo fence_info = {.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
    VkFence fence;
    VK_CHECK(vkCreateFence(device, &fence_info, NULL, &fence));

    /* Three frames while the camera turns; each waits for the previous one's fence. */
    VkImageLayout layout = VK_IMAGE_LAYOUT_UNDEFINED;
    const int frames = 3;
    for (int i = 0; i < frames; i++) {
        VMLS_CHECK(vmls_scene_orbit(scene, 0.3 * i));
        VkCommandBufferBeginInfo begin = {.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO,
                                          .flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT};
        VK_CHECK(vkBeginCommandBuffer(cmd, &begin));
        VmlsTarget target = {.kind = VMLS_TARGET_IMAGE,
                             .image = image,
                             .format = VMLS_FORMAT_RGBA8_UNORM,
                             .old_layout = layout,
                             .new_layout = VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL,
                             .before_stages = layout == VK_IMAGE_LAYOUT_UNDEFINED
                                                  ? VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT
                                                  : VK_PIPELINE_STAGE_TRANSFER_BIT,
                             .before_access = layout == VK_IMAGE_LAYOUT_UNDEFINED
                                                  ? 0
                                                  : VK_ACCESS_TRANSFER_READ_BIT,
                             .after_stages = VK_PIPELINE_STAGE_TRANSFER_BIT,
                             .after_access = VK_ACCESS_TRANSFER_READ_BIT};
        layout = VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL;
        VmlsFrame *frame = NULL;
        VMLS_CHECK(vmls_renderer_record(renderer, cmd, scene, &target, &frame));
        VkBufferImageCopy region = {.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1},
                                    .imageExtent = {width, height, 1}};
        vkCmdCopyImageToBuffer(cmd, image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, host, 1, &region);
        VkMemoryBarrier to_host = {.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER,
                                   .srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT,
                                   .dstAccessMask = VK_ACCESS_HOST_READ_BIT};
        vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1,
                             &to_host, 0, NULL, 0, NULL);
        VK_CHECK(vkEndCommandBuffer(cmd));
        VkSubmitInfo submit = {.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO,
                               .commandBufferCount = 1,
                               .pCommandBuffers = &cmd};
        VK_CHECK(vkQueueSubmit(queue, 1, &submit, fence));
        VK_CHECK(vkWaitForFences(device, 1, &fence, VK_TRUE, UINT64_MAX));
        VK_CHECK(vkResetFences(device, 1, &fence));
        double gpu_ms = 0.0;
        VMLS_CHECK(vmls_renderer_retire(renderer, frame, &gpu_ms));
        printf("frame %d: %u x %u, %.2f ms of GPU time\n", i, width, height, gpu_ms);
    }

    /* The last frame as a PAM file (netpbm RGB_ALPHA). */
    void *pixels;
    VK_CHECK(vkMapMemory(device, host_memory, 0, bytes, 0, &pixels));
    FILE *out = fopen(path, "wb");
    if (!out) {
        fprintf(stderr, "%s: cannot open for writing\n", path);
        return 1;
    }
    fprintf(out, "P7\nWIDTH %u\nHEIGHT %u\nDEPTH 4\nMAXVAL 255\nTUPLTYPE RGB_ALPHA\nENDHDR\n", width,
            height);
    int written = fwrite(pixels, 1, (size_t)bytes, out) == (size_t)bytes;
    written = fclose(out) == 0 && written;
    vkUnmapMemory(device, host_memory);
    if (!written) {
        fprintf(stderr, "%s: write failed\n", path);
        return 1;
    }

    /* vmls first, then the application's objects. */
    vmls_renderer_destroy(renderer);
    vmls_scene_destroy(scene);
    vmls_context_destroy(ctx);
    vkDestroyFence(device, fence, NULL);
    vkDestroyCommandPool(device, pool, NULL);
    vkDestroyBuffer(device, host, NULL);
    vkFreeMemory(device, host_memory, NULL);
    vkDestroyImage(device, image, NULL);
    vkFreeMemory(device, image_memory, NULL);
    vkDestroyDevice(device, NULL);
    if (messenger) {
        destroy_messenger(instance, messenger, NULL);
    }
    vkDestroyInstance(instance, NULL);
    printf("wrote %s; %u validation messages\n", path, messages);
    return messages == 0 ? 0 : 3;
}
