#version 450
// Stage splat_raster (twin: splat_raster in src/splat/raster.rs): one workgroup per image
// tile for the whole frame, one invocation per column of SPLAT_PIXELS pixels of the tile and
// of its apron (SPLAT_APRON pixels wide: post-shaded isosurfaces read their neighbours'
// sheets; then one pixel per invocation). The tile
// walks its entries, (splat, sheet) pairs sorted by sheet (list[offsets[b] .. offsets[b']]
// with b = tile * sheets, b' = b + sheets), at an index that is the same in every lane, so
// each record is branch-free gathers of one address per 8 lanes on lavapipe, shared by the
// invocation's SPLAT_PIXELS pixels (the gathers cost more than a footprint). Each pixel adds
// its footprint to its sheet in registers; when the sheet ends it composites in registers:
// - pre-shaded: surface splats first (coverage min(W, 1)), then alpha = 1 - e^-D,
//   C += T (E/D) alpha;
// - post-shaded ([BLUR]): one sheet behind; the mean value is classified over the part of the
//   slab inside the domain; isosurfaces crossed since the previous sheet are located by linear
//   interpolation and shaded with central-difference gradients within the sheet (neighbours
//   through shared memory) and across sheets (registers).
// Empty sheets cost nothing: pre-shaded they composite nothing, post-shaded they are skipped
// once the sheets behind them hold no value and value 0 has no extinction. With
// SPLAT_OCCLUSION the tile stops once every pixel of it is opaque or, post-shaded, past its
// ray's exit from the domain (pixel_live). No atomics on pixels, no
// sheet buffers; each pixel is written once. A band runs in passes (push.pass): a walk whose
// cost would pass push.chunk loop iterations stops and saves its position and registers,
// and the next pass goes on from there (llvmpipe ends an invocation's loops after 65 535
// iterations in a dispatch; src/splat/plan.rs counts the passes). The split changes nothing
// in the image, so the CPU twin walks in one go. Variant macros: SPLAT_POST, SPLAT_ORTHO,
// SPLAT_EXACT, SPLAT_RING (0, or post-shaded: one entry per SPLAT_RING sheets, the sheets ahead
// in ring registers), SPLAT_QUADRATURE (its sheet shares: 1 the quadrature, 2 the midpoint
// rule, 0 the erfc; SPLAT_WIDEN: kernels thinner than they serve shared as if that thick),
// SPLAT_INTERVAL (post-shaded: 0 each sheet's value over its slab, 1 linear and 2 Hermite
// intervals between sheet middles, preintegrated), SPLAT_OCCLUSION, SPLAT_ISOSURFACES,
// SPLAT_SURFACES, SPLAT_HULL, SPLAT_BRICK (a brick's frame: a pixel composites only the sheets whose midpoint on its ray lies in the brick's kd cell,
// twin SplatSetup::owns), SPLAT_TILE,
// SPLAT_APRON, SPLAT_GROUP (invocations: EDGE² rounded up to whole subgroups),
// SPLAT_SUBGROUP_OPS (subgroup votes and sums: each subgroup stops by itself, without
// barriers, which cost lavapipe a coroutine switch per subgroup), SPLAT_BRANCHES and
// SPLAT_CLEAR_SKIP (post-shaded: branch around the shares of pixels outside a footprint, and
// around lookups of all-zero table entries, which add exact zeros; on a GPU only: lavapipe
// runs both sides of a branch), SPLAT_OUTSIDE_SKIP (post-shaded, the same on a GPU: around
// lookups of halves outside the domain), SPLAT_PREFETCH (the walk loads the next entry, 1, or
// also its record, 2, one step ahead: the same loads earlier, and at most two entries and one
// record past a pass's last, never used). A pixel's registers and their saving between passes are in splat/raster_pixel.glsl, post-shaded compositing in
// splat/raster_post.glsl.
#extension GL_EXT_control_flow_attributes : enable
#if SPLAT_SUBGROUP_OPS == 1
#extension GL_KHR_shader_subgroup_basic : enable
#extension GL_KHR_shader_subgroup_vote : enable
#extension GL_KHR_shader_subgroup_arithmetic : enable
#endif

#define EDGE (SPLAT_TILE + 2 * SPLAT_APRON)
// Rows of invocations: each covers SPLAT_PIXELS pixel rows.
#define ROWS (EDGE / SPLAT_PIXELS)
layout(local_size_x = SPLAT_GROUP) in;

#include "common/types.glsl"

layout(push_constant) uniform PushBlock { RasterPush push; };
#include "splat/splat_params.glsl"
layout(rgba32f, binding = BINDING_SPLATS) readonly uniform imageBuffer splat_texels;
layout(rgba32ui, binding = BINDING_SPLAT_WORDS) readonly uniform uimageBuffer splat_words;
#define SPLAT_READ
#include "splat/splat.glsl"
#include "splat/walks.glsl"
layout(r32ui, binding = BINDING_OFFSET_TEXELS) readonly uniform uimageBuffer offset_texels;
layout(rg32ui, binding = BINDING_SPLAT_LIST) readonly uniform uimageBuffer list;
layout(std430, binding = BINDING_IMAGE) writeonly buffer ImageBuf { vec4 image[]; };
layout(std430, binding = BINDING_SPLAT_STATS) buffer StatsBuf { uint stats[]; };
// Walks a pass leaves unfinished, per tile of the band and invocation: a tag (the pass that
// continues it), the walk's position (at, k, live) and its pixels' registers. The position is
// the same in every lane of a subgroup, but not always in every subgroup of a workgroup: with
// subgroup votes each subgroup skips empty sheets by itself.
layout(std430, binding = BINDING_SPLAT_RASTER_STATE) buffer StateBuf { uint raster_state[]; };
#define INVOCATION_WORDS (4 + SPLAT_PIXELS * SPLAT_PIXEL_WORDS)
#define TILE_WORDS (SPLAT_GROUP * INVOCATION_WORDS)

#if SPLAT_POST == 1
#if SPLAT_HULL == 1
layout(std430, binding = BINDING_PIXEL_SEGMENTS) readonly buffer SegBuf { vec2 pixel_segments[]; };
#endif
// Per pixel and sheet: through the texel view (a storage-buffer load is a per-lane loop).
#define TRANSFER_TEXELS_BOUND 1
#define TF_COUNT params.tf_count
#include "common/transfer.glsl"
#if SPLAT_INTERVAL > 0
// Intervals between sheet middles: one table, half a sheet long (SplatSetup::table_lengths).
#include "common/preintegration.glsl"
#endif
#include "common/camera.glsl"
#if SPLAT_ISOSURFACES == 1
#include "common/shading.glsl"
#endif
#elif SPLAT_BRICK == 1
#include "common/camera.glsl"
#endif

// SplatCounts slots (64-bit counters keep their high word in the slot named second).
const uint STAT_SKIPPED = 6u;
const uint STAT_SKIPPED_HIGH = 13u;
const uint STAT_ACCUMULATED = 7u;
const uint STAT_ACCUMULATED_HIGH = 14u;
const uint STAT_EVALUATED = 9u;
const uint STAT_EVALUATED_HIGH = 11u;
const uint STAT_CONTRIBUTIONS = 10u;
const uint STAT_CONTRIBUTIONS_HIGH = 12u;

// Post-shaded isosurfaces exchange sheet values between lanes once per sheet.
#if SPLAT_POST == 1 && SPLAT_ISOSURFACES == 1
#define LATERAL 1
shared float sheet_values[2][SPLAT_GROUP];
#else
#define LATERAL 0
#endif
// How a tile stops once its pixels are opaque: 0 never (occlusion off), 1 each subgroup by
// itself (a vote, no barrier), 2 the whole workgroup at the lateral exchange's barrier, 3 the
// whole workgroup at a barrier of its own (devices without subgroup votes).
#if SPLAT_OCCLUSION == 0
#define VOTE 0
#elif LATERAL == 1
#define VOTE 2
#elif SPLAT_SUBGROUP_OPS == 1
#define VOTE 1
#else
#define VOTE 3
#endif
#if VOTE >= 2
shared uint open_slots[3];
#endif
#if SPLAT_SUBGROUP_OPS == 0
shared uint group_counts[4];
#endif

void stat_add64(uint low, uint high, uint v) {
    uint old = atomicAdd(stats[low], v);
    if (old + v < old) {
        atomicAdd(stats[high], 1u);
    }
}


uint offset_at(uint b) {
    return imageLoad(offset_texels, int(b)).x;
}

// Entry `at` of the sorted list as (splat, sheet); at the end, the closing sheet.
uvec2 next_entry(uint at, uint at_end, uint steps) {
    if (at >= at_end) {
        return uvec2(0u, steps);
    }
    return imageLoad(list, int(at)).xy;
}

#include "splat/raster_pixel.glsl"

// Adds entry (s, covering sheets k .. k + span - 1 of the splat's) to the pixel. Branch-free:
// a pixel outside the entry's box, or outside its cutoff, adds exact zeros (its footprint is
// 0 and every share a finite multiple of it). On lavapipe an early `return` here cost about
// 30% of a post-shaded splat_raster: every statement after it, the ring's registers
// included, became a masked write (BENCHMARKS.md, "Branch-free accumulation").
void accumulate(inout Pixel px, Splat s, Column col, uint k, uint span, float ta, float tb) {
    // (Padding invocations past the tile's rows have no pixel.)
    bool in_box = px.inside && all(greaterThanEqual(ivec2(px.x, px.y), s.bbox.xy))
                  && all(lessThanEqual(ivec2(px.x, px.y), s.bbox.zw));
#if SPLAT_POST == 0 && SPLAT_OCCLUSION == 1
    in_box = in_box && !(px.acc.w > params.early_termination);
#endif
    float cutoff = params.cutoff;
    vec2 pixel = vec2(px.x, px.y);
    px.evaluated += in_box ? 1u : 0u;
#if SPLAT_RING > 0
    // The lateral footprint once, then its share of each sheet k + d (d < span).
    vec3 pr = splat_profile_at(s, col, cutoff, pixel, px.view);
    pr.x = in_box ? pr.x : 0.0;
    px.contributions += pr.x != 0.0 ? 1u : 0u;
#if SPLAT_BRANCHES == 1
    // Outside the footprint every share below adds an exact zero: on a GPU the lanes skip
    // them (a warp runs the steps only while some lane's pixel is inside).
    if (pr.x == 0.0) {
        return;
    }
#endif
    float slab = params.slab_world;
#if SPLAT_QUADRATURE == 1
    // The Hermite-Simpson rule on each sheet (twin: sheet_share), h deviations thick: with
    // w = A/sqrt(2 pi), w h/30 (7 g_a + 16 g_m + 7 g_b) + w h^2/60 (z_b g_b - z_a g_a) for
    // g = e^(-z^2/2) at its boundaries a, b and middle m. The g at steps of dz = h/2 by the
    // recurrence g(z + dz) = g(z) rf, rf <- rf e^(-dz^2) (backwards: rb), from seeds at
    // boundaries 4 and 12 (ring 4: boundary 2), each serving up to 4 sheets either side:
    // h <= QUADRATURE_MAX_SHEET keeps every sheet that matters within 13 deviations of its
    // seed, where f32's e^(-z^2/2) has not underflowed. Seeds further out are clamped (their
    // sheets are all ~0, and an unclamped rf could reach infinity against a zero g).
#if SPLAT_WIDEN == 1
    // A kernel thinner along this ray than the rule serves is shared out as if it were that
    // thick (twin: SplatSetup::share_deviation); its entries reach as far (splat_project).
    pr.z = min(pr.z, float(QUADRATURE_MAX_SHEET) / slab);
#endif
    float h = slab * pr.z;
    float dz = 0.5 * h;
    float c = exp_e(-dz * dz);
    float w = pr.x * 0.3989422804014327;
    float wa = w * h * (7.0 / 30.0);
    float wm = w * h * (16.0 / 30.0);
    float wd = w * h * h * (1.0 / 60.0);
    float z0, g0, p0, p1, g1, gm, rho, zs, gs, rf, rb;
#define SEED(j) \
    zs = clamp((ta + float(j) * slab - pr.y) * pr.z, -20.0, 20.0); \
    gs = exp_e(-0.5 * zs * zs); \
    rf = exp_e(-(zs * dz + 0.5 * dz * dz)); \
    rb = c / rf;
#define FROM_SEED(ratio) \
    z0 = zs; \
    g0 = gs; \
    p0 = zs * gs; \
    rho = ratio;
    // Sheet d between z0 and z0 + dir h (dir = 1 forwards, -1 backwards); p = z g carried.
#define SHEET_STEP(d, dir, r) \
    gm = g0 * rho; \
    rho *= c; \
    g1 = gm * rho; \
    rho *= c; \
    z0 += dir * h; \
    p1 = z0 * g1; \
    r += d < span ? wa * (g0 + g1) + wm * gm + dir * wd * (p1 - p0) : 0.0; \
    p0 = p1; \
    g0 = g1;
#if SPLAT_RING == 4
    SEED(2u)
    FROM_SEED(rb)
    SHEET_STEP(1u, -1.0, px.r0) SHEET_STEP(0u, -1.0, px.sheet)
    FROM_SEED(rf)
    SHEET_STEP(2u, 1.0, px.r1) SHEET_STEP(3u, 1.0, px.r2)
#else
    SEED(4u)
    FROM_SEED(rb)
    SHEET_STEP(3u, -1.0, px.r2) SHEET_STEP(2u, -1.0, px.r1) SHEET_STEP(1u, -1.0, px.r0)
    SHEET_STEP(0u, -1.0, px.sheet)
    FROM_SEED(rf)
    SHEET_STEP(4u, 1.0, px.r3) SHEET_STEP(5u, 1.0, px.r4) SHEET_STEP(6u, 1.0, px.r5)
    SHEET_STEP(7u, 1.0, px.r6)
#endif
#if SPLAT_RING == 16
    SEED(12u)
    FROM_SEED(rb)
    SHEET_STEP(11u, -1.0, px.r10) SHEET_STEP(10u, -1.0, px.r9) SHEET_STEP(9u, -1.0, px.r8)
    SHEET_STEP(8u, -1.0, px.r7)
    FROM_SEED(rf)
    SHEET_STEP(12u, 1.0, px.r11) SHEET_STEP(13u, 1.0, px.r12) SHEET_STEP(14u, 1.0, px.r13)
    SHEET_STEP(15u, 1.0, px.r14)
#endif
#undef SHEET_STEP
#undef FROM_SEED
#undef SEED
#elif SPLAT_QUADRATURE == 2
    // The midpoint rule (twin: sheet_share): sheet d gets w h g(z_d), z_d its middle in
    // deviations, h its thickness. The g by the recurrence above at steps of h,
    // g(z + h) = g(z) rf, rf <- rf e^(-h^2), from seeds at the middles of sheets 4 and 12
    // (ring 4: sheet 2), each serving up to 4 sheets either side, clamped as above.
#if SPLAT_WIDEN == 1
    pr.z = min(pr.z, float(QUADRATURE_MAX_SHEET) / slab);
#endif
    float h = slab * pr.z;
    float c = exp_e(-h * h);
    float wm = pr.x * 0.3989422804014327 * h;
    float g, rho, zs, gs, rf, rb;
#define SEED(j) \
    zs = clamp((ta + (float(j) + 0.5) * slab - pr.y) * pr.z, -20.0, 20.0); \
    gs = exp_e(-0.5 * zs * zs); \
    rf = exp_e(-(zs * h + 0.5 * h * h)); \
    rb = c / rf;
#define MID(d, r) r += d < span ? wm * g : 0.0;
#define STEP(d, r) \
    g *= rho; \
    rho *= c; \
    MID(d, r)
#if SPLAT_RING == 4
    SEED(2u)
    g = gs;
    MID(2u, px.r1)
    rho = rb;
    STEP(1u, px.r0) STEP(0u, px.sheet)
    g = gs;
    rho = rf;
    STEP(3u, px.r2)
#else
    SEED(4u)
    g = gs;
    MID(4u, px.r3)
    rho = rb;
    STEP(3u, px.r2) STEP(2u, px.r1) STEP(1u, px.r0) STEP(0u, px.sheet)
    g = gs;
    rho = rf;
    STEP(5u, px.r4) STEP(6u, px.r5) STEP(7u, px.r6)
#endif
#if SPLAT_RING == 16
    SEED(12u)
    g = gs;
    MID(12u, px.r11)
    rho = rb;
    STEP(11u, px.r10) STEP(10u, px.r9) STEP(9u, px.r8) STEP(8u, px.r7)
    g = gs;
    rho = rf;
    STEP(13u, px.r12) STEP(14u, px.r13) STEP(15u, px.r14)
#endif
#undef STEP
#undef MID
#undef SEED
#else
    // The erfc tails at the sheet boundaries, each boundary's once.
    float za = (ta - pr.y) * pr.z;
    float qa = normal_tail(za);
    float zb = (tb - pr.y) * pr.z;
    float qb = normal_tail(zb);
    px.sheet += pr.x * phi_from_tails(za, qa, zb, qb);
    // Every step runs (as lavapipe would run it under a mask anyway); past the entry's span
    // it adds zero.
#define RING_STEP(d, r) \
    za = zb; \
    qa = qb; \
    zb = (params.slab0_world + float(k + d + 2u) * slab - pr.y) * pr.z; \
    qb = normal_tail(zb); \
    px.r += d + 1u < span ? pr.x * phi_from_tails(za, qa, zb, qb) : 0.0;
    RING_STEP(0u, r0) RING_STEP(1u, r1) RING_STEP(2u, r2)
#if SPLAT_RING >= 8
    RING_STEP(3u, r3) RING_STEP(4u, r4) RING_STEP(5u, r5) RING_STEP(6u, r6)
#endif
#if SPLAT_RING == 16
    RING_STEP(7u, r7) RING_STEP(8u, r8) RING_STEP(9u, r9) RING_STEP(10u, r10)
    RING_STEP(11u, r11) RING_STEP(12u, r12) RING_STEP(13u, r13) RING_STEP(14u, r14)
#endif
#undef RING_STEP
#endif
#else
    float g = profile_share(splat_profile_at(s, col, cutoff, pixel, px.view), ta, tb);
    g = in_box ? g : 0.0;
    px.contributions += g != 0.0 ? 1u : 0u;
#if SPLAT_POST == 1
    px.sheet += g;
#elif SPLAT_SURFACES == 1
    // A surface splat's g goes to the coverage sums, a volume splat's to the extinction.
    float gs = s.color.w > 0.0 ? g : 0.0;
    float gv = g - gs;
    px.sw += gs;
    px.sa += gs * s.color.w;
    px.sc += gs * s.color.rgb;
    px.ext += gv * vec4(1.0, s.color.rgb);
#else
    px.ext += g * vec4(1.0, s.color.rgb);
#endif
#endif
}

#if SPLAT_POST == 0
// Composites the pixel's sheet k (where the frame owns it) and clears it.
// Branch-free, like accumulate: a pixel that does not composite adds exact zeros.
void finish_pre(inout Pixel px, uint k) {
    float done = params.early_termination;
    bool on = px.own && !(px.acc.w > done) && sheet_owned(px, k);
#if SPLAT_SURFACES == 1
    // Surface splats first: coverage min(W, 1), normalised opacity and colour.
    float cover = on && px.sw > 0.0 ? min(px.sw, 1.0) / px.sw : 0.0;
    px.acc.rgb += (1.0 - px.acc.w) * px.sc * cover;
    px.acc.w += (1.0 - px.acc.w) * px.sa * cover;
#endif
    bool volume = on && !(px.acc.w > done) && px.ext.x > 0.0;
    float alpha = volume ? 1.0 - exp_e(-px.ext.x) : 0.0;
    px.acc.rgb += volume ? (1.0 - px.acc.w) * px.ext.yzw / px.ext.x * alpha : vec3(0.0);
    px.acc.w += (1.0 - px.acc.w) * alpha;
    px.ext = vec4(0.0);
#if SPLAT_SURFACES == 1
    px.sw = 0.0;
    px.sa = 0.0;
    px.sc = vec3(0.0);
#endif
}
#else
#include "splat/raster_post.glsl"
#endif

// Adds per-invocation counts to the frame's counters: summed over each subgroup first where
// subgroup operations exist, else over the workgroup in shared memory (group_counts, zeroed
// before the frame's loop).
void add_counts(uvec4 c) {
#if SPLAT_SUBGROUP_OPS == 1
    c = uvec4(subgroupAdd(c.x), subgroupAdd(c.y), subgroupAdd(c.z), subgroupAdd(c.w));
    if (subgroupElect()) {
#else
    atomicAdd(group_counts[0], c.x);
    atomicAdd(group_counts[1], c.y);
    atomicAdd(group_counts[2], c.z);
    atomicAdd(group_counts[3], c.w);
    barrier();
    c = uvec4(group_counts[0], group_counts[1], group_counts[2], group_counts[3]);
    if (gl_LocalInvocationIndex == 0u) {
#endif
        stat_add64(STAT_EVALUATED, STAT_EVALUATED_HIGH, c.x);
        stat_add64(STAT_CONTRIBUTIONS, STAT_CONTRIBUTIONS_HIGH, c.y);
        stat_add64(STAT_ACCUMULATED, STAT_ACCUMULATED_HIGH, c.z);
        stat_add64(STAT_SKIPPED, STAT_SKIPPED_HIGH, c.w);
    }
}

void main() {
    load_params();
    uint lane = gl_LocalInvocationIndex;
    bool valid = lane < uint(EDGE * ROWS);
    int lx = int(lane % uint(EDGE)) - SPLAT_APRON;
    int ly = int(lane / uint(EDGE)) * SPLAT_PIXELS - SPLAT_APRON;
    int x = int(gl_WorkGroupID.x) * SPLAT_TILE + lx;
    uint tile_y = gl_WorkGroupID.y + push.tile_row;
    int y = int(tile_y) * SPLAT_TILE + ly;
    bool own_x = lx >= 0 && lx < SPLAT_TILE;
#define OWN(r) (own_x && ly + r >= 0 && ly + r < SPLAT_TILE)
    Pixel px0 = pixel_at(x, y, valid, OWN(0));
#if SPLAT_PIXELS >= 2
    Pixel px1 = pixel_at(x, y + 1, valid, OWN(1));
#endif
#if SPLAT_PIXELS >= 4
    Pixel px2 = pixel_at(x, y + 2, valid, OWN(2));
    Pixel px3 = pixel_at(x, y + 3, valid, OWN(3));
#endif
#if SPLAT_PIXELS == 8
    Pixel px4 = pixel_at(x, y + 4, valid, OWN(4));
    Pixel px5 = pixel_at(x, y + 5, valid, OWN(5));
    Pixel px6 = pixel_at(x, y + 6, valid, OWN(6));
    Pixel px7 = pixel_at(x, y + 7, valid, OWN(7));
#endif
#undef OWN
    float slab = params.slab_world;
    // Entries walked and entries skipped by this invocation (the counters hold them times
    // the invocations of a workgroup).
    uvec2 walked = uvec2(0u);
#if VOTE >= 2 || SPLAT_SUBGROUP_OPS == 0
    if (lane == 0u) {
#if VOTE >= 2
        open_slots[0] = 0u;
        open_slots[1] = 0u;
        open_slots[2] = 0u;
#endif
#if SPLAT_SUBGROUP_OPS == 0
        group_counts[0] = 0u;
        group_counts[1] = 0u;
        group_counts[2] = 0u;
        group_counts[3] = 0u;
#endif
    }
    barrier();
#endif

    uint tile = tile_y * params.tiles_x + gl_WorkGroupID.x;
    uint first_bucket = tile * params.slabs;
    // The tile's entries, sheet after sheet; every index below is the same in all lanes.
    uint at = offset_at(first_bucket);
    uint at_end = offset_at(first_bucket + params.slabs);
    uint steps = params.slabs + uint(SPLAT_POST);
    // Ring registers holding something (the same in every lane: it follows the entries).
    uint live = 0u;
    // The sheet being accumulated.
    uint k = 0u;
    // Where this tile's walk and this invocation's registers wait between passes.
    uint tile_words = (gl_WorkGroupID.y * params.tiles_x + gl_WorkGroupID.x) * uint(TILE_WORDS);
    uint own_words = tile_words + lane * uint(INVOCATION_WORDS);
    if (push.pass > 0u) {
        // A later pass continues the walks the pass before left unfinished, with this
        // invocation's registers; an invocation that had finished, its pixels written, has
        // nothing to do (with subgroup votes, a whole subgroup: the tag is the same in all its
        // lanes).
        if (raster_state[own_words] != push.pass) {
            return;
        }
        uvec3 position = uvec3(raster_state[own_words + 1u], raster_state[own_words + 2u],
                               raster_state[own_words + 3u]);
#if SPLAT_SUBGROUP_OPS == 1
        // The same in every lane, and so known to the compiler as a subgroup's minimum: the
        // list is then read once per subgroup and broadcast, not gathered lane by lane.
        position = subgroupMin(position);
#endif
        at = position.x;
        k = position.y;
        live = position.z;
        uint w = own_words + 4u;
#define LOAD(px) load_pixel(px, w); w += uint(SPLAT_PIXEL_WORDS);
        EACH(LOAD)
#undef LOAD
    }
    uint at_start = at;
    // The next entry: (splat, sheet), past the last the closing sheet.
    uvec2 entry = next_entry(at, at_end, steps);
    // SPLAT_PREFETCH 1 loads the entry after `entry` one step ahead, so that a step's record
    // load has its address at hand; 2 also the record of `entry`, so that on a GPU a step
    // waits on no load of its own (they overlap the step before's arithmetic) at the price of
    // the record's registers. Past the list's end the record read is splat 0's (the buffer
    // holds at least one), never accumulated.
#if SPLAT_PREFETCH == 2
    Splat ahead = load_splat(entry.x);
#endif
#if SPLAT_PREFETCH >= 1
    uvec2 entry1 = next_entry(at + 1u, at_end, steps);
#endif
    // Where splat_column takes each entry's forms: the middle of the invocation's rows.
    vec2 column_view = vec2(px0.view.x, 0.5 * (px0.view.y + LAST_PIXEL.view.y));
    // The walk's cost in this pass, in loop iterations (one per entry, push.sheet_cost per
    // sheet, which counts the loops of compositing it): a pass stops before it would pass
    // push.chunk, below llvmpipe's limit, and leaves the walk to the next (`cut`).
    uint cost = 0u;
    bool cut = false;
    // Sheet-loop trips, which pick the workgroup vote's slot (k may jump by any count).
    uint trip = 0u;
    // One iteration per sheet finished; the barrier of post-shaded isosurfaces sits at this
    // loop's level (inside a nested loop it hung lanes on lavapipe).
    while (k < steps) {
        if (cost + push.sheet_cost > push.chunk) {
            cut = true;
            break;
        }
        cost += push.sheet_cost;
        uint slot = trip % 3u;
        trip += 1u;
        bool open = false;
#define OPEN(px) open = open || pixel_live(px, k);
        EACH(OPEN)
#undef OPEN
#if VOTE == 1
        // This subgroup stops once all its pixels are opaque or past the domain's exit.
        if (subgroupAll(!open)) {
            break;
        }
#elif VOTE == 3
        // The workgroup stops once all its pixels are done (pixel_live): three slots, one per trip in
        // turn, so that one barrier per trip separates each slot's reset, its writes and its
        // reads.
        if (open) {
            open_slots[slot] = 1u;
        }
        barrier();
        if (open_slots[slot] == 0u) {
            break;
        }
        if (lane == 0u) {
            open_slots[(slot + 2u) % 3u] = 0u;
        }
#endif
#if SPLAT_SPLIT == 1
        float ta = params.slab0_world + float(k) * slab;
        float tb = ta + slab;
#else
        float ta = 0.0, tb = 0.0;
#endif
        // Each entry costs one: the pass walks at most chunk - cost more.
        uint at_sheet = at;
        uint at_limit = at + (push.chunk - cost);
        while (entry.y == k && at < at_limit) {
#if SPLAT_PREFETCH == 2
            Splat s = ahead;
            ahead = load_splat(entry1.x);
#else
            Splat s = load_splat(entry.x);
#endif
#if SPLAT_PREFETCH >= 1
            uvec2 entry2 = next_entry(at + 2u, at_end, steps);
#endif
#if SPLAT_RING > 0
            // The entry covers sheets k .. k + span - 1 of the splat's.
            uint span = min(s.slabs.y - k + 1u, uint(SPLAT_RING));
            live = max(live, span - 1u);
#else
            uint span = 1u;
#endif
            // The exact footprint down this invocation's column (splat_column).
            Column col = splat_column(s, column_view);
#define ACCUMULATE(px) accumulate(px, s, col, k, span, ta, tb);
            EACH(ACCUMULATE)
#undef ACCUMULATE
            at += 1u;
#if SPLAT_PREFETCH >= 1
            entry = entry1;
            entry1 = entry2;
#else
            entry = next_entry(at, at_end, steps);
#endif
        }
        cost += at - at_sheet;
        if (entry.y == k) {
            // Sheet k is incomplete: the next pass goes on accumulating it.
            cut = true;
            break;
        }
#if SPLAT_POST == 0
#define FINISH(px) finish_pre(px, k);
        EACH(FINISH)
#undef FINISH
        k = entry.y;
#else
#define TAKE(px) float v1_##px = take_sheet(px);
        EACH(TAKE)
#undef TAKE
        live = live > 0u ? live - 1u : 0u;
        vec2 lat = vec2(0.0);
#if LATERAL == 1
        // Lateral central differences of sheet k from the neighbours' lanes, one-sided at the
        // image border; two buffers, so that one barrier per sheet orders writes and reads.
        sheet_values[k & 1u][lane] = v1_px0;
#if VOTE == 2
        // The workgroup's vote rides on the same barrier (three slots: see VOTE 3).
        if (open) {
            open_slots[slot] = 1u;
        }
#endif
        barrier();
#if VOTE == 2
        // Every pixel is done: sheet k - 1 and later change nothing.
        if (open_slots[slot] == 0u) {
            break;
        }
        if (lane == 0u) {
            open_slots[(slot + 2u) % 3u] = 0u;
        }
#endif
        if (px0.own) {
            float a = params.slab0_world + float(k) * slab;
#if SPLAT_ORTHO == 1
            float size = 1.0 / params.focal;
#else
            float size = (a + 0.5 * slab) / params.focal;
#endif
            int w = int(params.camera.width), h = int(params.camera.height);
            int mx = max(x - 1, 0) - x, px = min(x + 1, w - 1) - x;
            int my = max(y - 1, 0) - y, py = min(y + 1, h - 1) - y;
            if (px != mx) {
                lat.x = (sheet_values[k & 1u][int(lane) + px] - sheet_values[k & 1u][int(lane) + mx])
                        / (float(px - mx) * size);
            }
            if (py != my) {
                // Pixel rows grow downwards, against `up`.
                lat.y = -(sheet_values[k & 1u][int(lane) + py * EDGE]
                          - sheet_values[k & 1u][int(lane) + my * EDGE])
                        / (float(py - my) * size);
            }
        }
#endif
#define COMPOSITE(px) composite_post(px, k, v1_##px, lat);
        EACH(COMPOSITE)
#undef COMPOSITE
        k += 1u;
#if LATERAL == 0 && SPLAT_SUBGROUP_OPS == 1
        // Past the last sheet with a value, with no extinction at value 0 and nothing ahead
        // in the ring, every sheet before the next entry's composites nothing: skip to it.
        if (params.zero_extinction == 0.0 && k < entry.y && live == 0u) {
            bool empty = true;
// Intervals between sheet middles also read the sheets before: linear ones v0, Hermite ones
// v_2 as well (the skipped composites would have read them).
#if SPLAT_INTERVAL == 2
#define BEFORE(px) px.v0 == 0.0 && px.v_2 == 0.0
#elif SPLAT_INTERVAL == 1
#define BEFORE(px) px.v0 == 0.0
#else
#define BEFORE(px) true
#endif
#define EMPTY(px) empty = empty && px.v == 0.0 && px.sheet == 0.0 && BEFORE(px);
            EACH(EMPTY)
#undef EMPTY
#undef BEFORE
            if (subgroupAll(empty)) {
#define CLEAR(px) px.v_2 = 0.0; px.v0 = 0.0;
                EACH(CLEAR)
#undef CLEAR
                k = entry.y;
            }
        }
#endif
#endif
    }
    // llvmpipe ends an invocation's loops after 65 535 iterations in a dispatch (LAVAPIPE.md),
    // silently: a walk that stopped before the last sheet with a pixel still open was cut
    // short, and the host refuses the frame rather than show it.
    bool open_at_end = false;
#define OPEN(px) open_at_end = open_at_end || pixel_live(px, k);
    EACH(OPEN)
#undef OPEN
    // A walk the chunk cut is left to the band's next pass, if there is one: the band's last
    // is the one its longest walk needs (a recorded frame may have recorded more, which
    // dispatch nothing). One that stops with a pixel open and no pass to go on was cut short,
    // by the chunk or by llvmpipe's limit.
    uint last_pass = min(push.last_pass, raster_passes(stats[SPLAT_STAT_BAND_ENTRIES + push.band],
                                                       steps, push.chunk, push.sheet_cost) - 1u);
    bool resume = cut && push.pass < last_pass;
    if (k < steps && open_at_end && !resume) {
        atomicAdd(stats[SPLAT_STAT_RASTER_TRUNCATED], 1u);
    }
    if (resume) {
        raster_state[own_words] = push.pass + 1u;
        raster_state[own_words + 1u] = at;
        raster_state[own_words + 2u] = k;
        raster_state[own_words + 3u] = live;
        uint w = own_words + 4u;
#define SAVE(px) save_pixel(px, w); w += uint(SPLAT_PIXEL_WORDS);
        EACH(SAVE)
#undef SAVE
        atomicAdd(stats[SPLAT_STAT_RESUMED], 1u);
    } else if (push.pass < last_pass) {
        // Finished: no later pass of the band continues it (in the first pass this also
        // clears what an earlier band left in these words).
        raster_state[own_words] = 0u;
    }
    walked.x = at - at_start;
    walked.y = cut ? 0u : at_end - at;
    uvec2 footprints = uvec2(0u);
#define WRITE(px) \
    if (px.own && !resume) { \
        image[px.p] = px.acc; \
    } \
    footprints += uvec2(px.evaluated, px.contributions);
    EACH(WRITE)
#undef WRITE
    add_counts(uvec4(footprints, walked));
#if SPLAT_POST == 1 && SPLAT_INTERVAL > 0 && SPLAT_CLEAR_SKIP == 1
#if SPLAT_SUBGROUP_OPS == 1
    uint skipped = subgroupAdd(clear_halves);
    if (subgroupElect()) {
        stat_add64(SPLAT_STAT_CLEAR_SKIPPED, SPLAT_STAT_CLEAR_SKIPPED_HIGH, skipped);
    }
#else
    stat_add64(SPLAT_STAT_CLEAR_SKIPPED, SPLAT_STAT_CLEAR_SKIPPED_HIGH, clear_halves);
#endif
#endif
}
