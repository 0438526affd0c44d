#version 450
// Stage splat_scan (twin: the prefix sum in splat_bin, src/splat/raster.rs): the exclusive
// prefix sum of the (tile, sheet) bucket counts into bucket offsets, on the GPU, in three
// dispatches of this file (SCAN_PASS):
// 0. per block of SPLAT_SCAN_BLOCK buckets (one workgroup, SPLAT_SCAN_BLOCK / 256 contiguous
//    buckets per invocation): the block's sum;
// 1. one workgroup: the exclusive prefix sum of the block sums, in place, and the total into
//    offsets[buckets];
// 2. per block: offsets = the block's prefix + the scan inside the block; cursors = offsets
//    (splat_bin's atomic cursors start at each bucket's first entry).
// No pass reads back to the host; the second level is one workgroup, for at most
// MAX_BUCKETS / SCAN_BLOCK blocks (src/splat/mod.rs).
// Workgroup barriers are what a scan costs on lavapipe (it runs a workgroup's subgroups as
// coroutines and switches all of them at each barrier): with the subgroup operations the
// workgroup scan takes one barrier instead of sixteen, and large blocks make few workgroups
// (BENCHMARKS.md, "The splatting sort's scan").

layout(local_size_x = 256) in;

#if SPLAT_SUBGROUP_OPS == 1
#extension GL_KHR_shader_subgroup_arithmetic : enable
#endif

#include "common/types.glsl"

layout(push_constant) uniform PushBlock { ScanPush push; };
layout(std430, binding = BINDING_BUCKET_COUNTS) readonly buffer CountBuf { uint counts[]; };
layout(std430, binding = BINDING_SCAN_SUMS) buffer SumBuf { uint sums[]; };
#if SCAN_PASS == 1
layout(std430, binding = BINDING_BUCKET_OFFSETS) writeonly buffer OffsetBuf { uint offsets[]; };
#elif SCAN_PASS == 2
layout(std430, binding = BINDING_BUCKET_OFFSETS) writeonly buffer OffsetBuf { uint offsets[]; };
layout(std430, binding = BINDING_BUCKET_CURSORS) writeonly buffer CursorBuf { uint cursors[]; };
#endif

const uint PER_LANE = uint(SPLAT_SCAN_BLOCK) / 256u;

shared uint partial[256];

#if SPLAT_SUBGROUP_OPS == 1
// The invocation's rank in the order group_scan scans: subgroup by subgroup, so that the
// scan is right whichever invocations the device puts in a subgroup (256 is a whole number
// of subgroups of any size a device may have).
uint lane_index() {
    return gl_SubgroupID * gl_SubgroupSize + gl_SubgroupInvocationID;
}

// Inclusive scan of v over the workgroup in lane_index order: within each subgroup, then the
// totals of the subgroups before it from shared memory.
uint group_scan(uint v) {
    uint inclusive = subgroupInclusiveAdd(v);
    if (gl_SubgroupInvocationID == gl_SubgroupSize - 1u) {
        partial[gl_SubgroupID] = inclusive;
    }
    barrier();
    uint before = 0u;
    for (uint s = 0u; s < gl_SubgroupID; ++s) {
        before += partial[s];
    }
    return before + inclusive;
}
#else
uint lane_index() {
    return gl_LocalInvocationIndex;
}

// Inclusive scan of v over the workgroup (Hillis-Steele in shared memory).
uint group_scan(uint v) {
    uint lane = gl_LocalInvocationIndex;
    partial[lane] = v;
    barrier();
    for (uint d = 1u; d < 256u; d *= 2u) {
        uint add = lane >= d ? partial[lane - d] : 0u;
        barrier();
        partial[lane] += add;
        barrier();
    }
    return partial[lane];
}
#endif

uint count_at(uint i) {
    return i < push.buckets ? counts[i] : 0u;
}

void main() {
    uint lane = lane_index();
#if SCAN_PASS == 0
    uint base = gl_WorkGroupID.x * uint(SPLAT_SCAN_BLOCK) + lane * PER_LANE;
    uint total = 0u;
    for (uint i = 0u; i < PER_LANE; ++i) {
        total += count_at(base + i);
    }
    uint all = group_scan(total);
    if (lane == 255u) {
        sums[gl_WorkGroupID.x] = all;
    }
#elif SCAN_PASS == 1
    uint chunk = (push.blocks + 255u) / 256u;
    uint first = min(lane * chunk, push.blocks);
    uint end = min(first + chunk, push.blocks);
    uint total = 0u;
    for (uint b = first; b < end; ++b) {
        total += sums[b];
    }
    uint before = group_scan(total) - total;
    for (uint b = first; b < end; ++b) {
        uint s = sums[b];
        sums[b] = before;
        before += s;
    }
    if (lane == 255u) {
        offsets[push.buckets] = before;
    }
#else
    uint base = gl_WorkGroupID.x * uint(SPLAT_SCAN_BLOCK) + lane * PER_LANE;
    uint c[PER_LANE];
    uint total = 0u;
    for (uint i = 0u; i < PER_LANE; ++i) {
        c[i] = count_at(base + i);
        total += c[i];
    }
    uint at = sums[gl_WorkGroupID.x] + group_scan(total) - total;
    for (uint i = 0u; i < PER_LANE; ++i) {
        if (base + i < push.buckets) {
            offsets[base + i] = at;
            cursors[base + i] = at;
        }
        at += c[i];
    }
#endif
}
