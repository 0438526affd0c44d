// Empty-space skipping (issue 11 §2): f32 twin of src/field/skip.rs. Blocks of SKIP_BLOCK³ grid
// cells carry the fast field's value range (exact bounds: the field is trilinear per fine
// cell); the skip table marks the scalar bins with extinction or an isosurface, as prefix
// counts. Needs `params` and the fast path (MLS_RESAMPLED > 0).
#ifndef VMLS_SKIP_GLSL
#define VMLS_SKIP_GLSL

// vec4(min, max, 0, 0) per block, x fastest.
layout(binding = BINDING_SKIP_BLOCKS, rgba32f) uniform readonly imageBuffer skip_blocks;
// lo (f32 bits), 1/width (f32 bits), bins, then bins + 1 prefix counts.
layout(binding = BINDING_SKIP_TABLE, r32ui) uniform readonly uimageBuffer skip_table;

// Bin of a value widened by `widen` bins, clamped (twin of SkipTable::bin); `header` is the
// table's (lo, 1/width, bins), read once per block lookup.
int skip_bin(float v, int widen, vec3 header) {
    float b = clamp(floor((v - header.x) * header.y), -1.0, 1e9);
    return clamp(int(b) + widen, 0, int(header.z) - 1);
}

// What every block lookup of a frame shares, set once per invocation (skip_init): the block's
// edge in world units, the blocks per axis and the skip table's header (lo, 1/width, bins).
// Recomputed per lookup they cost three divisions and three gathers each time.
vec3 skip_size;
ivec3 skip_blocks_per_axis;
vec3 skip_header;

void skip_init() {
    skip_size = float(SKIP_BLOCK) / params.field.grid_inv_spacing.xyz;
    skip_blocks_per_axis =
        max((params.field.grid_dims.xyz - 1 + SKIP_BLOCK - 1) / SKIP_BLOCK, ivec3(1));
    skip_header = vec3(uintBitsToFloat(imageLoad(skip_table, 0).x),
                       uintBitsToFloat(imageLoad(skip_table, 1).x),
                       float(imageLoad(skip_table, 2).x));
}

// Stage `skip_block` (twin of Blocks::lookup): whether the block holding o + t·d (clamped into
// the grid) is empty, and the ray parameter where the ray leaves it. Needs skip_init.
bool skip_block(vec3 o, vec3 d, float t, out float t_exit) {
    vec3 size = skip_size;
    ivec3 blocks = skip_blocks_per_axis;
    vec3 g = (o + d * t - params.field.grid_origin.xyz) / size;
    ivec3 b = min(ivec3(max(floor(g), vec3(0.0))), blocks - 1);
    vec3 lo = params.field.grid_origin.xyz + vec3(b) * size;
    vec3 hi = lo + size;
    t_exit = 3.0e38;
    // The face ahead on each axis the ray moves along: one division where a branch per
    // direction ran two (llvmpipe runs both).
    [[unroll]] for (int a = 0; a < 3; ++a) {
        float along = ((d[a] > 0.0 ? hi[a] : lo[a]) - o[a]) / d[a];
        t_exit = d[a] != 0.0 ? min(t_exit, along) : t_exit;
    }
    vec4 r = imageLoad(skip_blocks, b.x + blocks.x * (b.y + blocks.y * b.z));
    int b0 = skip_bin(r.x, -1, skip_header);
    int b1 = skip_bin(r.y, 1, skip_header);
    // min > max: no defined fine point, the fast field is undefined in the whole block.
    return r.x > r.y || imageLoad(skip_table, 3 + b1 + 1).x == imageLoad(skip_table, 3 + b0).x;
}

// Stage `skip_run` (twin of Blocks::run): from t across consecutive empty blocks, at most
// SKIP_RUN of them and no further once past t_end; where the run stops (t when the block at t
// is occupied). Blocks are looked up RUN_NUDGE of an edge past the point, since a point on a
// face may round into the block just left; a lookup whose exit does not advance ends the run.
// With `empty` false the run crosses occupied blocks instead (see skip_span).
float skip_run(vec3 o, vec3 d, float t, float t_end, bool empty) {
    vec3 size = skip_size;
    float nudge = float(RUN_NUDGE) * min(size.x, min(size.y, size.z));
    for (uint n = 0u; n < uint(SKIP_RUN); ++n) {
        float t_exit;
        if (t >= t_end || skip_block(o, d, t + nudge, t_exit) != empty || t_exit <= t) {
            break;
        }
        t = t_exit;
    }
    return t;
}

// Stages skip_block then skip_run (twin of Skip::span): whether the block at t is empty and, if
// so, where the run of empty blocks from it ends. If not, where the run of occupied blocks from
// it ends: the callers check again there, and no block before it is empty, so every check
// they skip would have found an occupied block (up to an empty block's corner a nudge thin,
// which a run passes over as empty runs already do; the images and counts measured the same).
// Both cases are one loop: llvmpipe would run a branch's run either way, and an integrator
// that left its sample loop at every block's exit paid a round of its own per block (about one
// per interval at the fast path's blocks).
bool skip_span(vec3 o, vec3 d, float t, float t_end, out float t_exit) {
    bool empty = skip_block(o, d, t, t_exit);
    t_exit = skip_run(o, d, t_exit, t_end, empty);
    return empty;
}

// Stage skip_reaches_end (twin of Blocks::reaches_end): whether a run of empty blocks that
// stopped at t_exit covers the ray up to t_end (past it, or at the grid's far face up to a
// nudge): the ray's rest is left out instead of costing a knot to resume and one to close it.
bool skip_reaches_end(float t_exit, float t_end) {
    return t_exit >= t_end - float(RUN_NUDGE) * min(skip_size.x, min(skip_size.y, skip_size.z));
}

// Twin of skip::resume_interval: the first interval of length l from t0 that reaches past
// `t_exit`, no earlier than `next`.
uint resume_interval(float t0, float l, float t_exit, uint next) {
    float j = floor((t_exit - t0) / l);
    return j > float(next) ? uint(min(j, 4.0e9)) : next;
}

#endif
