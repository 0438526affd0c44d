#version 450
// Stage `target_pack` (twin: renderer::target::pack_pixel, after composite_background where
// push.composite is 1): a recorded frame's RGBA32F pixels converted to the format of the
// application's image, as u32 words that vkCmdCopyBufferToImage copies unchanged. Splatting
// frames composite their background here (render() does it on the host with the twin), ray
// casting composites in raycast.comp. TARGET_FORMAT: 0 rgba32f (four words), 1 rgba16f (two
// words: packHalf2x16 of rg, of ba), 2 rgba8 unorm (one word: packUnorm4x8), 3 rgba8 srgb
// (colour sRGB-encoded first, alpha linear).

layout(local_size_x = 64) in;

#include "common/types.glsl"

layout(std430, binding = BINDING_IMAGE) readonly buffer ImageBuf { vec4 image[]; };
layout(std430, binding = BINDING_TARGET_PACKED) writeonly buffer PackedBuf { uint packed[]; };
layout(push_constant) uniform Push { PackPush push; };

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
    if (push.composite == 1u) {
        // `precise`: no fused multiply-add, so that the result is the host twin's to the bit.
        precise float t = 1.0 - p.a;
        precise vec3 c = p.rgb + t * push.background.rgb;
        p.rgb = c;
    }
#if TARGET_FORMAT == 0
    packed[4u * i] = floatBitsToUint(p.r);
    packed[4u * i + 1u] = floatBitsToUint(p.g);
    packed[4u * i + 2u] = floatBitsToUint(p.b);
    packed[4u * i + 3u] = floatBitsToUint(p.a);
#elif TARGET_FORMAT == 1
    packed[2u * i] = packHalf2x16(p.rg);
    packed[2u * i + 1u] = packHalf2x16(p.ba);
#elif TARGET_FORMAT == 2
    packed[i] = packUnorm4x8(p);
#else
    packed[i] = packUnorm4x8(vec4(srgb_encode(p.r), srgb_encode(p.g), srgb_encode(p.b), p.a));
#endif
}
