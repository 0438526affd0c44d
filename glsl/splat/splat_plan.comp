#version 450
// Stage splat_plan (twin: plan_groups in src/splat/plan.rs): in a recorded frame, the one
// decision render() makes on the host between the projection and the accumulation. From the
// scan's total of binned entries and the projection's counters it writes the workgroup counts
// of splat_bin, of splat_order's two passes (an invocation per bucket, rows of at most 65 535
// workgroups; the second's per bucket the first can hand over), of each band of
// push.band_rows tile rows of splat_raster, then of each band's push.resumes later passes,
// which all dispatch indirectly: the whole frame where its entries fit the list, the work
// budget allows them and no kernel or pixel overflowed, each band's passes as many as its
// longest walk takes (splat_walks; twin RasterWalk::passes); none (x = 0) otherwise, so that
// nothing writes past the list, and Renderer::retire reads the same numbers back and names
// what stopped the frame.

layout(local_size_x = 1) in;

#include "common/types.glsl"
#include "splat/walks.glsl"

layout(std430, binding = BINDING_BUCKET_OFFSETS) readonly buffer OffsetBuf { uint offsets[]; };
layout(std430, binding = BINDING_SPLAT_STATS) readonly buffer StatsBuf { uint stats[]; };
layout(std430, binding = BINDING_DISPATCH_ARGS) writeonly buffer ArgsBuf { uvec4 args[]; };
layout(push_constant) uniform Push { PlanPush push; };

// Workgroups of 64 (splat_order's local size, GROUP in src/splat/plan.rs) for one invocation
// per item, in rows of at most 65 535 (twin: order_groups); none where the frame does not run.
uvec4 order_args(uint items, bool run) {
    uint groups = max((items + 63u) / 64u, 1u);
    uint x = min(groups, 65535u);
    return run ? uvec4(x, (groups + x - 1u) / x, 1u, 0u) : uvec4(0u, 1u, 1u, 0u);
}

void main() {
    uint total = offsets[push.buckets];
    bool run = total <= push.capacity && total <= push.max_entries
               && stats[SPLAT_STAT_OVERSIZED] == 0u
               && (push.segments == 0u || stats[SPLAT_STAT_SEGMENT_OVERFLOW] == 0u);
    args[0] = run ? uvec4(push.bin_groups, 1u, 1u, 0u) : uvec4(0u, 1u, 1u, 0u);
    // splat_order's first pass: one invocation per bucket; its second: one for every bucket
    // the first can hand over, at most one per SPLAT_ORDER_INSERTION_MAX + 1 entries.
    args[1] = order_args(push.buckets, run);
    args[2] = order_args(min(push.buckets, total / (SPLAT_ORDER_INSERTION_MAX + 1u)), run);
    uint rows = max(push.band_rows, 1u);
    uint bands = (push.tiles_y + rows - 1u) / rows;
    for (uint b = 0u; b < bands; ++b) {
        uint n = min(rows, push.tiles_y - b * rows);
        args[3u + b] = run ? uvec4(push.tiles_x, n, 1u, 0u) : uvec4(0u, 1u, 1u, 0u);
        uint passes = raster_passes(stats[SPLAT_STAT_BAND_ENTRIES + b], push.steps, push.chunk,
                                    push.sheet_cost);
        for (uint pass = 1u; pass <= push.resumes; ++pass) {
            args[3u + bands + b * push.resumes + pass - 1u] =
                run && pass < passes ? uvec4(push.tiles_x, n, 1u, 0u) : uvec4(0u, 1u, 1u, 0u);
        }
    }
}
