#version 450
// Stage `target_pack` (twin: renderer::target::pack_pixel): a recorded frame's RGBA32F pixels
// converted to the format of the application's image, as u32 words that vkCmdCopyBufferToImage
// copies unchanged. TARGET_FORMAT: 1 rgba16f (two words: packHalf2x16 of rg, of ba), 2 rgba8
// unorm (one word: packUnorm4x8), 3 rgba8 srgb (colour sRGB-encoded first, alpha linear).

layout(local_size_x = 64) in;

#include "common/types.glsl"

layout(std430, binding = BINDING_IMAGE) readonly buffer ImageBuf { vec4 image[]; };
layout(std430, binding = BINDING_TARGET_PACKED) writeonly buffer PackedBuf { uint packed[]; };
layout(push_constant) uniform Push { CountPush push; };

// The sRGB transfer function (IEC 61966-2-1) on [0, 1].
float srgb_encode(float c) {
    c = clamp(c, 0.0, 1.0);
    return c <= 0.0031308 ? 12.92 * c : 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 64u;
    if (i >= push.count) {
        return;
    }
    vec4 p = image[i];
#if TARGET_FORMAT == 1
    packed[2u * i] = packHalf2x16(p.rg);
    packed[2u * i + 1u] = packHalf2x16(p.ba);
#elif TARGET_FORMAT == 2
    packed[i] = packUnorm4x8(p);
#else
    packed[i] = packUnorm4x8(vec4(srgb_encode(p.r), srgb_encode(p.g), srgb_encode(p.b), p.a));
#endif
}
