#version 450
// Stage splat_raster (twin: splat_raster in src/splat/raster.rs): one workgroup per image
// tile for the whole frame, one invocation per pixel of the tile and of its apron
// (SPLAT_APRON pixels wide: post-shaded isosurfaces read their neighbours' sheets). The tile
// walks its entries, (splat, sheet) pairs sorted by sheet (list[offsets[b] .. offsets[b']]
// with b = tile * sheets, b' = b + sheets), at an index that is the same in every lane, so
// each record is one branch-free gather of one address per 8 lanes on lavapipe. Each lane adds
// its pixel's footprint to its sheet in registers; when the sheet ends it composites in
// registers:
// - pre-shaded: surface splats first (coverage min(W, 1)), then alpha = 1 - e^-D,
//   C += T (E/D) alpha;
// - post-shaded ([BLUR]): one sheet behind; the mean value is classified over the part of the
//   slab inside the domain; isosurfaces crossed since the previous sheet are located by linear
//   interpolation and shaded with central-difference gradients within the sheet (neighbours
//   through shared memory) and across sheets (registers).
// Empty sheets cost nothing: pre-shaded they composite nothing, post-shaded they are skipped
// once the sheets behind them hold no value and value 0 has no extinction. With
// SPLAT_OCCLUSION the tile stops once every pixel of it is opaque. No atomics on pixels, no
// sheet buffers; each pixel is written once. Variant macros: SPLAT_POST, SPLAT_ORTHO,
// SPLAT_EXACT, SPLAT_OCCLUSION, SPLAT_ISOSURFACES, SPLAT_SURFACES, SPLAT_HULL, SPLAT_TILE,
// SPLAT_APRON, SPLAT_GROUP (invocations: EDGE² rounded up to whole subgroups),
// SPLAT_SUBGROUP_OPS (subgroup votes and sums: each subgroup stops by itself, without
// barriers, which cost lavapipe a coroutine switch per subgroup).
#extension GL_EXT_control_flow_attributes : enable
#if SPLAT_SUBGROUP_OPS == 1
#extension GL_KHR_shader_subgroup_basic : enable
#extension GL_KHR_shader_subgroup_vote : enable
#extension GL_KHR_shader_subgroup_arithmetic : enable
#endif

#define EDGE (SPLAT_TILE + 2 * SPLAT_APRON)
layout(local_size_x = SPLAT_GROUP) in;

#include "types.glsl"

layout(push_constant) uniform PushBlock { RasterPush push; };
#include "splat_params.glsl"
layout(rgba32f, binding = BINDING_SPLATS) readonly uniform imageBuffer splat_texels;
layout(rgba32ui, binding = BINDING_SPLAT_WORDS) readonly uniform uimageBuffer splat_words;
#define SPLAT_READ
#include "splat.glsl"
layout(r32ui, binding = BINDING_OFFSET_TEXELS) readonly uniform uimageBuffer offset_texels;
layout(r32ui, binding = BINDING_SPLAT_LIST) readonly uniform uimageBuffer list;
layout(std430, binding = BINDING_IMAGE) writeonly buffer ImageBuf { vec4 image[]; };
layout(std430, binding = BINDING_SPLAT_STATS) buffer StatsBuf { uint stats[]; };

#if SPLAT_POST == 1
#if SPLAT_HULL == 1
layout(std430, binding = BINDING_PIXEL_SEGMENTS) readonly buffer SegBuf { vec2 pixel_segments[]; };
#endif
// Per pixel and sheet: through the texel view (a storage-buffer load is a per-lane loop).
#define TRANSFER_TEXELS_BOUND 1
#include "transfer.glsl"
#include "camera.glsl"
#if SPLAT_ISOSURFACES == 1
#include "shading.glsl"
#endif
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
    return uvec2(imageLoad(list, int(2u * at)).x, imageLoad(list, int(2u * at + 1u)).x);
}

#if SPLAT_POST == 1
// The length of sheet j's slab inside the domain along pixel p's ray: the box's [t_in,
// t_out], or the sum over the pixel's hull segments.
float slab_overlap(int j, float t_in, float t_out, uint p) {
    float a = params.box_min.w + float(j) * params.box_max.w;
    float b = a + params.box_max.w;
#if SPLAT_HULL == 1
    float len = 0.0;
    for (uint i = 0u; i < uint(SPLAT_SEGMENTS); ++i) {
        vec2 s = pixel_segments[p * uint(SPLAT_SEGMENTS) + i];
        len += max(min(b, s.y) - max(a, s.x), 0.0);
    }
    return len;
#else
    return max(min(b, t_out) - max(a, t_in), 0.0);
#endif
}
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
    int lx = int(lane % uint(EDGE)) - SPLAT_APRON;
    int ly = int(lane / uint(EDGE)) - SPLAT_APRON;
    int x = int(gl_WorkGroupID.x) * SPLAT_TILE + lx;
    uint tile_y = gl_WorkGroupID.y + push.tile_row;
    int y = int(tile_y) * SPLAT_TILE + ly;
    int w = int(params.width), h = int(params.height);
    bool inside = lane < uint(EDGE * EDGE) && x >= 0 && y >= 0 && x < w && y < h;
    bool own = inside && lx >= 0 && ly >= 0 && lx < SPLAT_TILE && ly < SPLAT_TILE;
    uint p = inside ? uint(y * w + x) : 0u;
    vec2 pixel = vec2(x, y);
    float done = params.background.w;
    float cutoff = params.kernel_filter.x;
    float slab = params.box_max.w;
    vec4 acc = vec4(0.0);
    // Footprints evaluated and contributing (per invocation); entries walked and entries
    // skipped (per invocation, so that the counters hold them times the invocations).
    uvec4 counts = uvec4(0u);
#if SPLAT_POST == 0
    vec4 ext = vec4(0.0);
#if SPLAT_SURFACES == 1
    float sw = 0.0, sa = 0.0;
    vec3 sc = vec3(0.0);
#endif
#else
    float sheet = 0.0;
    // Mean values of sheets j - 2, j - 1, j = k - 1 (k: the sheet just accumulated).
    float v_2 = 0.0, v0 = 0.0, v = 0.0;
    vec2 lat0 = vec2(0.0), lat1 = vec2(0.0);
    vec3 o = vec3(0.0), d = vec3(0.0);
    float t_in = 0.0, t_out = 0.0;
    bool in_domain = false;
    if (own) {
        camera_ray(uvec2(x, y), o, d);
        in_domain = clip_box(o, d, params.box_min.xyz, params.box_max.xyz, t_in, t_out);
    }
#endif
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
    // The sheet being accumulated, and the next entry: (splat, sheet), past the last the
    // closing sheet.
    uint k = 0u;
    uvec2 entry = next_entry(at, at_end, steps);
    // One iteration per sheet finished; the barrier of post-shaded isosurfaces sits at this
    // loop's level (inside a nested loop it hung lanes on lavapipe).
    while (k < steps) {
#if VOTE == 1
        // This subgroup stops once all its pixels are opaque.
        if (subgroupAll(!own || acc.w > done)) {
            break;
        }
#elif VOTE == 3
        // The workgroup stops once all its pixels are opaque: three slots, so that one
        // barrier per sheet separates each slot's reset, its writes and its reads.
        if (own && !(acc.w > done)) {
            open_slots[k % 3u] = 1u;
        }
        barrier();
        if (open_slots[k % 3u] == 0u) {
            break;
        }
        if (lane == 0u) {
            open_slots[(k + 2u) % 3u] = 0u;
        }
#endif
        while (entry.y == k) {
            // The entry: a splat's share of sheet k.
#if SPLAT_SPLIT == 1
            float ta = params.box_min.w + float(k) * slab;
            float tb = ta + slab;
#else
            float ta = 0.0, tb = 0.0;
#endif
            Splat s = load_splat(entry.x);
            bool in_box = all(greaterThanEqual(ivec2(x, y), s.bbox.xy))
                          && all(lessThanEqual(ivec2(x, y), s.bbox.zw));
#if SPLAT_POST == 0 && SPLAT_OCCLUSION == 1
            in_box = in_box && !(acc.w > done);
#endif
            if (in_box) {
                float g = splat_footprint(s, cutoff, pixel, ta, tb);
                counts.x += 1u;
                if (g != 0.0) {
                    counts.y += 1u;
#if SPLAT_POST == 1
                    sheet += g;
#elif SPLAT_SURFACES == 1
                    if (s.color.w > 0.0) {
                        sw += g;
                        sa += g * s.color.w;
                        sc += g * s.color.rgb;
                    } else {
                        ext += g * vec4(1.0, s.color.rgb);
                    }
#else
                    ext += g * vec4(1.0, s.color.rgb);
#endif
                }
            }
            at += 1u;
            entry = next_entry(at, at_end, steps);
        }
#if SPLAT_POST == 0
        if (own && !(acc.w > done)) {
#if SPLAT_SURFACES == 1
            // Surface splats first: coverage min(W, 1), normalised opacity and colour.
            if (sw > 0.0) {
                float cover = min(sw, 1.0) / sw;
                acc.rgb += (1.0 - acc.w) * sc * cover;
                acc.w += (1.0 - acc.w) * sa * cover;
            }
#endif
            if (!(acc.w > done) && ext.x > 0.0) {
                float alpha = 1.0 - exp_e(-ext.x);
                acc.rgb += (1.0 - acc.w) * ext.yzw / ext.x * alpha;
                acc.w += (1.0 - acc.w) * alpha;
            }
        }
        ext = vec4(0.0);
#if SPLAT_SURFACES == 1
        sw = 0.0;
        sa = 0.0;
        sc = vec3(0.0);
#endif
        k = entry.y;
#else
        float v1 = sheet / slab;
        sheet = 0.0;
        vec2 lat = vec2(0.0);
#if LATERAL == 1
        // Lateral central differences of sheet k from the neighbours' lanes, one-sided at the
        // image border; two buffers, so that one barrier per sheet orders writes and reads.
        sheet_values[k & 1u][lane] = v1;
#if VOTE == 2
        // The workgroup's vote rides on the same barrier (three slots: see VOTE 3).
        if (own && !(acc.w > done)) {
            open_slots[k % 3u] = 1u;
        }
#endif
        barrier();
#if VOTE == 2
        // Every pixel is opaque: sheet k - 1 and later change nothing.
        if (open_slots[k % 3u] == 0u) {
            break;
        }
        if (lane == 0u) {
            open_slots[(k + 2u) % 3u] = 0u;
        }
#endif
        if (own) {
            float a = params.box_min.w + float(k) * slab;
#if SPLAT_ORTHO == 1
            float size = 1.0 / params.forward.w;
#else
            float size = (a + 0.5 * slab) / params.forward.w;
#endif
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
        int j = int(k) - 1;
        if (own && in_domain && j >= 0 && !(acc.w > done)) {
            float len = slab_overlap(j, t_in, t_out, p);
#if SPLAT_ISOSURFACES == 1
            if (j >= 1 && len > 0.0 && slab_overlap(j - 1, t_in, t_out, p) > 0.0) {
                // Crossings in order of their position between the two sheets.
                float pos[4];
                uint order[4];
                uint hits = 0u;
                for (uint i = 0u; i < params.iso_count; ++i) {
                    float iv = isos[i].value;
                    if ((v0 - iv) * (v - iv) < 0.0 || (v == iv && v0 != iv)) {
                        float a = (iv - v0) / (v - v0);
                        uint at = hits;
                        while (at > 0u && pos[at - 1u] > a) {
                            pos[at] = pos[at - 1u];
                            order[at] = order[at - 1u];
                            --at;
                        }
                        pos[at] = a;
                        order[at] = i;
                        ++hits;
                    }
                }
                if (hits > 0u) {
                    float across = 0.5 / slab;
                    vec3 g0 = lat0.x * params.right.xyz + lat0.y * params.up.xyz + (v - v_2) * across * d;
                    vec3 g1 = lat1.x * params.right.xyz + lat1.y * params.up.xyz + (v1 - v0) * across * d;
                    for (uint hi = 0u; hi < hits; ++hi) {
                        IsoSurface iso = isos[order[hi]];
                        vec3 rgb = shade_surface(iso, mix(g0, g1, pos[hi]), d);
                        acc.rgb += (1.0 - acc.w) * rgb;
                        acc.w += (1.0 - acc.w) * iso.color_opacity.a;
                    }
                }
            }
#endif
            if (len > 0.0) {
                vec4 ct = transfer_lookup(v, params.tf_count);
                float alpha = 1.0 - exp_e(-ct.a * len);
                acc.rgb += (1.0 - acc.w) * ct.rgb * alpha;
                acc.w += (1.0 - acc.w) * alpha;
            }
        }
        v_2 = v0;
        v0 = v;
        v = v1;
        lat0 = lat1;
        lat1 = lat;
        k += 1u;
#if LATERAL == 0
        // Past the last sheet with a value, with no extinction at value 0, every sheet
        // before the next entry's composites nothing: skip to it.
#if SPLAT_SUBGROUP_OPS == 1
        if (params.zero_extinction == 0.0 && k < entry.y && subgroupAll(v == 0.0)) {
            v_2 = 0.0;
            v0 = 0.0;
            k = entry.y;
        }
#endif
#endif
#endif
    }
    counts.z = at - offset_at(first_bucket);
    counts.w = at_end - at;
    if (own) {
        image[p] = acc;
    }
    add_counts(counts);
}
