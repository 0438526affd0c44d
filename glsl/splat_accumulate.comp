#version 450
// Stage splat_accumulate (twin: splat_accumulate in src/splat/accumulate.rs), one dispatch per
// sheet, one invocation per binned entry: early splat elimination against the occlusion map
// ([BLUR] §4), then each pixel of the entry's block gets the footprint's share of the sheet.
// Variant macros: SPLAT_POST, SPLAT_OCCLUSION (0 off, 1 on), SPLAT_SURFACES (pre-shaded sheets
// of 9 channels: D, E.rgb, then the surface splats' W, sum q*alpha, C.rgb).
// Sheets are f32 bits in uints added to by compare-and-swap: portable to any Vulkan device
// (no float-atomic feature needed), lock-free (one lane of a contended group always succeeds),
// and on llvmpipe what a native float atomic compiles to anyway.

layout(local_size_x = 64) in;

#include "types.glsl"

layout(push_constant) uniform PushBlock { SlabPush push; };
#include "splat_params.glsl"

#include "splat.glsl"
layout(std430, binding = BINDING_SPLATS) readonly buffer SplatBuf { Splat splats[]; };
layout(std430, binding = BINDING_SLAB_COUNTS) readonly buffer CountBuf { uint slab_counts[]; };
layout(std430, binding = BINDING_SLAB_OFFSETS) readonly buffer OffsetBuf { uint slab_offsets[]; };
layout(std430, binding = BINDING_SPLAT_LIST) readonly buffer ListBuf { uvec2 list[]; };
layout(std430, binding = BINDING_SHEETS) buffer SheetBuf { uint sheets[]; };
layout(std430, binding = BINDING_IMAGE) readonly buffer ImageBuf { vec4 image[]; };
layout(std430, binding = BINDING_OCCLUSION) readonly buffer OcclusionBuf { uint occlusion[]; };
layout(std430, binding = BINDING_SPLAT_STATS) buffer StatsBuf { uint stats[]; };

const uint STAT_SKIPPED = 6u;
const uint STAT_ACCUMULATED = 7u;
// Pixels whose footprint was evaluated, and sheet updates (compare-and-swap adds): the work
// `vmls bench` divides by the FMA and atomic ceilings. 64-bit: the high words sit 2 slots on.
const uint STAT_EVALUATED = 9u;
const uint STAT_UPDATES = 10u;

void stat_add64(uint low, uint v) {
    uint old = atomicAdd(stats[low], v);
    if (old + v < old) {
        atomicAdd(stats[low + 2u], 1u);
    }
}

void sheet_add(uint index, float v) {
    uint old = sheets[index];
    while (true) {
        uint seen = atomicCompSwap(sheets[index], old, floatBitsToUint(uintBitsToFloat(old) + v));
        if (seen == old) {
            break;
        }
        old = seen;
    }
}

// Every occlusion tile under the box is opaque.
bool occluded(ivec4 b) {
    for (int ty = b.y / SPLAT_TILE; ty <= b.w / SPLAT_TILE; ++ty) {
        for (int tx = b.x / SPLAT_TILE; tx <= b.z / SPLAT_TILE; ++tx) {
            if (occlusion[uint(ty) * params.tiles_x + uint(tx)] == 0u) {
                return false;
            }
        }
    }
    return true;
}

void main() {
    load_params();
    uint k = push.slab;
    uint count = slab_counts[k];
    uint first = slab_offsets[k];
    float ta = params.box_min.w + float(k) * params.box_max.w;
    float tb = ta + params.box_max.w;
    float cutoff = params.kernel_filter.x;
    float done = params.background.w;
    uint pixels = params.width * params.height;
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    for (uint e = gl_GlobalInvocationID.x; e < count; e += stride) {
        uvec2 entry = list[first + e];
        Splat s = splats[entry.x];
        ivec4 bb = block_box(s.bbox, s.slabs.z, entry.y);
#if SPLAT_OCCLUSION == 1
#if SPLAT_POST == 1
        // Post-shaded gradients read the neighbours of every pixel: test one pixel wider.
        ivec4 probe = ivec4(max(bb.xy - 1, 0),
                            min(bb.zw + 1, ivec2(params.width, params.height) - 1));
#else
        ivec4 probe = bb;
#endif
        if (occluded(probe)) {
            atomicAdd(stats[STAT_SKIPPED], 1u);
            continue;
        }
#endif
        atomicAdd(stats[STAT_ACCUMULATED], 1u);
        uint evaluated = 0u;
        uint updates = 0u;
        for (int y = bb.y; y <= bb.w; ++y) {
            for (int x = bb.x; x <= bb.z; ++x) {
                uint p = uint(y) * params.width + uint(x);
#if SPLAT_OCCLUSION == 1 && SPLAT_POST == 0
                if (image[p].w > done) {
                    continue;
                }
#endif
                float g = splat_footprint(s, cutoff, vec2(x, y), ta, tb);
                evaluated += 1u;
                if (g != 0.0) {
#if SPLAT_POST == 1
                    updates += 1u;
                    sheet_add((k % 5u) * pixels + p, g);
#elif SPLAT_SURFACES == 1
                    updates += s.color.w > 0.0 ? 5u : 4u;
                    if (s.color.w > 0.0) {
                        sheet_add(9u * p + 4u, g);
                        sheet_add(9u * p + 5u, g * s.color.w);
                        sheet_add(9u * p + 6u, g * s.color.r);
                        sheet_add(9u * p + 7u, g * s.color.g);
                        sheet_add(9u * p + 8u, g * s.color.b);
                    } else {
                        sheet_add(9u * p, g);
                        sheet_add(9u * p + 1u, g * s.color.r);
                        sheet_add(9u * p + 2u, g * s.color.g);
                        sheet_add(9u * p + 3u, g * s.color.b);
                    }
#else
                    updates += 4u;
                    sheet_add(4u * p, g);
                    sheet_add(4u * p + 1u, g * s.color.r);
                    sheet_add(4u * p + 2u, g * s.color.g);
                    sheet_add(4u * p + 3u, g * s.color.b);
#endif
                }
            }
        }
        stat_add64(STAT_EVALUATED, evaluated);
        stat_add64(STAT_UPDATES, updates);
    }
}
