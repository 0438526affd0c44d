#version 450
// Stage splat_order (twin: splat_bin in src/splat/raster.rs, whose buckets list their entries in
// kernel order): puts each (tile, sheet) bucket's entries in kernel order. splat_bin's atomic
// cursors hand out a bucket's slots in whatever order its workgroups reach them (lavapipe runs
// them on several threads), and a sheet sums its entries in list order, so without this pass
// two frames of one camera differ by f32 rounding. With it a frame is the same to the bit on
// every run, recorded or not, and a brick's frame on an MPI rank equals the virtual brick's.
// The kernel indices are sorted in place (every entry of a bucket has the same sheet), in two
// dispatches of this file (ORDER_PASS):
// 1. one invocation per bucket: insertion sort where the subgroup's largest bucket has at most
//    SPLAT_ORDER_INSERTION_MAX entries; a larger bucket's index goes to the bucket cursors
//    (free once splat_bin is done), counted in stats[SPLAT_STAT_LARGE_BUCKETS];
// 2. one invocation per bucket the first pass can hand over (order_large_groups in
//    src/splat/plan.rs: one per SPLAT_ORDER_INSERTION_MAX + 1 entries at most): heapsort.
// Two passes, because llvmpipe runs every instruction of a kernel whatever its lanes decide:
// heapsort's code beside the insertion sort made every one of a frame's million buckets pay
// for what a few need (BENCHMARKS.md). llvmpipe also ends an invocation's loops after 65 535
// iterations of all its loops together, counted per subgroup (LAVAPIPE.md), silently: so the
// lanes' loops are bounded by the subgroup's largest bucket before they start, and a bucket
// whose sort could pass SORT_ITERATIONS is left as splat_bin filled it and counted in
// SPLAT_STAT_UNORDERED (`--stats`): correct sheets, summed in an order that may change.

#if SPLAT_SUBGROUP_OPS == 1
#extension GL_KHR_shader_subgroup_arithmetic : enable
#endif

layout(local_size_x = 64) in;

#include "common/types.glsl"

layout(push_constant) uniform PushBlock { ScanPush push; };
layout(r32ui, binding = BINDING_OFFSET_TEXELS) readonly uniform uimageBuffer offset_texels;
layout(rg32ui, binding = BINDING_SPLAT_LIST) uniform uimageBuffer list;
layout(std430, binding = BINDING_SPLAT_STATS) buffer StatsBuf { uint stats[]; };
layout(std430, binding = BINDING_BUCKET_CURSORS) buffer LargeBuf { uint large[]; };

// Below llvmpipe's 65 535, with room for the loops' last passes.
const uint SORT_ITERATIONS = 60000u;
// The first pass sorts buckets of up to SPLAT_ORDER_INSERTION_MAX = 64 entries, within
// 64 * 63 / 2 + 2 * 64 + 1 = 2 145 loop iterations (see insertion_sort): far below the limit,
// so it needs no count.

uint lo;
uint sheet;

uint key(uint i) {
    return imageLoad(list, int(lo + i)).x;
}

void put(uint i, uint kernel) {
    imageStore(list, int(lo + i), uvec4(kernel, sheet, 0u, 0u));
}

#if ORDER_PASS == 1
// Loop iterations of insertion sorts of buckets of at most n entries (one shift per pair at
// most, and a pass that ends each loop): n (n - 1) / 2 + 2 n + 1.
void insertion_sort(uint n) {
    for (uint i = 1u; i < n; ++i) {
        uint e = key(i);
        uint j = i;
        uint before = key(j - 1u);
        while (before > e) {
            put(j, before);
            j -= 1u;
            // (Both sides run: the address stays inside the bucket.)
            before = j > 0u ? key(max(j, 1u) - 1u) : 0u;
        }
        if (j != i) {
            put(j, e);
        }
    }
}

void main() {
    uint b = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * gl_WorkGroupSize.x
             + gl_LocalInvocationID.x;
    bool valid = b < push.buckets;
    lo = valid ? imageLoad(offset_texels, int(b)).x : 0u;
    uint n = valid ? imageLoad(offset_texels, int(b + 1u)).x - lo : 0u;
    if (n > SPLAT_ORDER_INSERTION_MAX) {
        large[atomicAdd(stats[SPLAT_STAT_LARGE_BUCKETS], 1u)] = b;
        n = 0u;
    }
    if (n < 2u) {
        return;
    }
    sheet = imageLoad(list, int(lo)).y;
    insertion_sort(n);
}
#else
// The subgroup's largest of n: its lanes loop as long as that lane.
uint largest_of(uint n) {
#if SPLAT_SUBGROUP_OPS == 1
    return subgroupMax(n);
#else
    return n;
#endif
}

// Loop iterations of heapsorts of buckets of at most n entries: n/2 + n - 1 sift-downs of at
// most floor(log2 n) + 1 steps, and a pass that ends each loop.
uint heap_bound(uint n) {
    return (n / 2u + n) * (uint(findMSB(max(n, 1u))) + 3u) + 2u;
}

// Moves the key at `root` down the max-heap of the first `end` entries.
void sift_down(uint root, uint end) {
    uint v = key(root);
    bool going = true;
    while (going) {
        uint child = 2u * root + 1u;
        going = child < end;
        if (going) {
            uint c = key(child);
            // (Both sides run: the address stays inside the heap.)
            uint right = child + 1u < end ? key(min(child + 1u, end - 1u)) : 0u;
            if (child + 1u < end && right > c) {
                child += 1u;
                c = right;
            }
            going = c > v;
            if (going) {
                put(root, c);
                root = child;
            }
        }
    }
    put(root, v);
}

void heap_sort(uint n) {
    for (uint s = n / 2u; s > 0u; --s) {
        sift_down(s - 1u, n);
    }
    for (uint end = n - 1u; end > 0u; --end) {
        uint top = key(0u);
        put(0u, key(end));
        put(end, top);
        sift_down(0u, end);
    }
}

void main() {
    uint count = stats[SPLAT_STAT_LARGE_BUCKETS];
    uint stride = gl_NumWorkGroups.x * gl_NumWorkGroups.y * gl_WorkGroupSize.x;
    uint first = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * gl_WorkGroupSize.x
                 + gl_LocalInvocationID.x;
    // One round where the grid has an invocation per bucket (it is sized so); the same in
    // every lane, so that the subgroup can count its iterations.
    uint rounds = (count + stride - 1u) / stride;
    uint spent = 0u;
    for (uint r = 0u; r < rounds; ++r) {
        uint k = first + r * stride;
        uint b = k < count ? large[k] : 0u;
        lo = k < count ? imageLoad(offset_texels, int(b)).x : 0u;
        uint n = k < count ? imageLoad(offset_texels, int(b + 1u)).x - lo : 0u;
        uint bound = heap_bound(largest_of(n)) + 1u;
        if (spent + bound > SORT_ITERATIONS) {
            if (n > 0u) {
                atomicAdd(stats[SPLAT_STAT_UNORDERED], 1u);
            }
        } else {
            spent += bound;
            if (n > 0u) {
                sheet = imageLoad(list, int(lo)).y;
                heap_sort(n);
            }
        }
    }
}
#endif
