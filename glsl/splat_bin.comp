#version 450
// Stage splat_bin (twin: splat_bin in src/splat/accumulate.rs): the scatter of a counting sort
// by sheet. Each kept splat writes one entry (splat, block) per sheet of its range and per pixel
// block of its box, at the sheet's offset (prefix sum from the host) plus an atomic cursor.
// The order inside a sheet does not matter: sheets are sums.

layout(local_size_x = 64) in;

#include "types.glsl"

#include "splat_params.glsl"
layout(std430, binding = BINDING_SPLATS) readonly buffer SplatBuf { Splat splats[]; };
layout(std430, binding = BINDING_SLAB_OFFSETS) readonly buffer OffsetBuf { uint slab_offsets[]; };
layout(std430, binding = BINDING_SLAB_CURSORS) buffer CursorBuf { uint slab_cursors[]; };
layout(std430, binding = BINDING_SPLAT_LIST) writeonly buffer ListBuf { uvec2 list[]; };

void main() {
    load_params();
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    for (uint i = gl_GlobalInvocationID.x; i < params.kernel_count; i += stride) {
        uvec4 r = splats[i].slabs;
        for (uint k = r.x; k <= r.y; ++k) {
            uint at = slab_offsets[k] + atomicAdd(slab_cursors[k], r.w);
            for (uint b = 0u; b < r.w; ++b) {
                list[at + b] = uvec2(i, b);
            }
        }
    }
}
