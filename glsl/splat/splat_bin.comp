#version 450
// Stage splat_bin (twin: splat_bin in src/splat/raster.rs): the scatter of the counting sort
// by (tile, sheet) bucket. Each kept splat writes (its index, the sheet) once per tile its box
// (with the apron) meets and per sheet of its range, at its bucket's atomic cursor (which splat_scan
// set to the bucket's first entry). The cursors hand out slots in whatever order the workgroups
// reach them; splat_order then puts each bucket in kernel order, so that a sheet's sum is the
// same on every run.

layout(local_size_x = 64) in;

#include "common/types.glsl"

#include "splat/splat_params.glsl"
layout(rgba32ui, binding = BINDING_SPLAT_WORDS) readonly uniform uimageBuffer splat_words;
layout(std430, binding = BINDING_BUCKET_CURSORS) buffer CursorBuf { uint cursors[]; };
layout(rg32ui, binding = BINDING_SPLAT_LIST) writeonly uniform uimageBuffer list;

#include "splat/splat.glsl"

void main() {
    load_params();
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    for (uint i = gl_GlobalInvocationID.x; i < params.kernel_count; i += stride) {
        uvec4 slabs = imageLoad(splat_words, int(7u * i + 6u));
        if (slabs.x > slabs.y) {
            continue;
        }
        uvec4 r = tile_rect(ivec4(imageLoad(splat_words, int(7u * i + 5u))));
        for (uint ty = r.y; ty <= r.w; ++ty) {
            for (uint tx = r.x; tx <= r.z; ++tx) {
                uint first = (ty * params.tiles_x + tx) * params.slabs;
                // Ring registers: one entry per SPLAT_RING sheets, at the first of them.
                for (uint k = slabs.x; k <= slabs.y; k += uint(max(SPLAT_RING, 1))) {
                    int at = int(atomicAdd(cursors[first + k], 1u));
                    imageStore(list, at, uvec4(i, k, 0u, 0u));
                }
            }
        }
    }
}
