#version 450
// Stage splat_walks (twin: band_entries in src/splat/plan.rs): after splat_scan, the most
// entries any tile of each band of push.band_rows tile rows walks, one invocation per tile,
// into the band's counter word (stats[SPLAT_STAT_BAND_ENTRIES + band], zeroed with the
// counters). From it the host, or splat_plan in a recorded frame, knows how many passes of
// splat_raster the band takes before it records them: llvmpipe ends an invocation's loops
// after 65 535 iterations in a dispatch (LAVAPIPE.md), and a tile of a dense point cloud can
// walk more entries than that.

layout(local_size_x = 64) in;

#include "common/types.glsl"

layout(push_constant) uniform Push { WalkPush push; };
layout(std430, binding = BINDING_BUCKET_OFFSETS) readonly buffer OffsetBuf { uint offsets[]; };
layout(std430, binding = BINDING_SPLAT_STATS) buffer StatsBuf { uint stats[]; };

void main() {
    uint tile = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 64u;
    if (tile >= push.tiles) {
        return;
    }
    uint entries = offsets[(tile + 1u) * push.slabs] - offsets[tile * push.slabs];
    uint band = tile / push.tiles_x / max(push.band_rows, 1u);
    if (entries > 0u) {
        atomicMax(stats[SPLAT_STAT_BAND_ENTRIES + band], entries);
    }
}
