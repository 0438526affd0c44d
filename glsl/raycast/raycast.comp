#version 450
// One ray per invocation: emission–absorption ray casting of the MLS field, twin of
// src/raycast/raycast.rs (stage `raycast`). Variant macro RAY_METHOD: 0 = midpoint rule
// (riemann, reference), 1 = preintegration with a fixed step, 2 = [MLS] adaptive subdivision
// (ADAPTIVE_LEVELS = stack entries = ⌊log2(l_max/l_min)⌋ + 1).
//
// Rays are integrated in chunks, one dispatch per chunk: outer steps (midpoint steps, fixed
// intervals or adaptive top intervals) band.first .. band.last, numbered across the ray's inside
// segments (one for a box domain; a mesh hull may give several). llvmpipe silently ends every
// loop once an invocation has run 65 535 loop iterations in one dispatch (nested ones
// included); chunks keep typical rays below that (default_chunk). Between chunks a ray's
// state lives in the image ((C, T) while running), the counts (evaluations | RAY_DONE) and the
// ray-state buffer (the last knot). A loop that ends before its chunk does marks
// RAY_TRUNCATED, and the host renders the band again with smaller chunks.
#extension GL_EXT_control_flow_attributes : require

layout(local_size_x = 8, local_size_y = 8) in;

#include "common/types.glsl"

#include "common/params.glsl"
layout(std430, binding = BINDING_IMAGE) buffer ImageBuf { vec4 image[]; };
layout(std430, binding = BINDING_COUNTS) buffer CountsBuf { uint counts[]; };
layout(std430, binding = BINDING_RAY_STATE) buffer RayStateBuf { vec4 ray_state[]; };
layout(push_constant) uniform Push { RayPush band; };

#include "field/neighbours.glsl"
// The ray caster binds the transfer function's texel view too (frame_bindings).
#define TRANSFER_TEXELS_BOUND 1
// The transfer function's point count, for the exact opacity's scan (preintegration.glsl).
#define TF_COUNT params.integrator.tf_count
#include "common/transfer.glsl"
#include "common/camera.glsl"

#if RAY_METHOD != 0
#include "common/preintegration.glsl"
#endif

#if MAX_ISO > 0
#include "common/shading.glsl"
#endif

#include "raycast/interval.glsl"

#if SKIP == 1 || RAY_METHOD == 2
// The ray report: skipping's lengths and counts (xyz), the adaptive error estimate (w).
#define RAY_STATS 1
layout(std430, binding = BINDING_RAY_STATS) buffer RayStatsBuf { vec4 ray_stats[]; };
#endif

#if RAY_METHOD == 2
// The adaptive criterion's error estimate of this ray so far, carried between chunks (twin of
// Ray::error_estimate).
float ray_error = 0.0;
#endif

#if SKIP == 1
#include "field/skip.glsl"
// This ray's skipping so far (carried between chunks): x = ray length skipped, y = evaluations
// saved (twin of Ray::skipped and Ray::saved).
vec2 skipped = vec2(0.0);

// Outer steps skipped over `len` of the ray, of which `restart` knots are evaluated anyway.
void count_skip(float len, uint steps, uint restart) {
    skipped += vec2(len, float(steps) - float(restart));
}
#endif

#if HULL == 1 && HULL_CACHED == 1
// The hull segments an earlier frame of this camera kept (raycast::segments): no walk.
layout(binding = BINDING_RAY_SEGMENTS, rgba32f) uniform readonly imageBuffer ray_segments;
#include "raycast/segments.glsl"
#elif HULL == 1
#include "field/hull.glsl"
#if HULL_CACHED == 2
// Where this frame keeps the segments it walks, for the next frames of its camera.
layout(binding = BINDING_RAY_SEGMENTS, rgba32f) uniform writeonly imageBuffer ray_segments;
#define RAY_SEGMENTS_WRITE 1
#include "raycast/segments.glsl"
#endif
#endif

// Outcome of integrating one chunk of a ray.
const uint CHUNK_DONE = 0u;      // reached last_step, more to do in this segment
const uint CHUNK_FINISHED = 1u;  // the segment is complete (t_exit or termination)
const uint CHUNK_TRUNCATED = 2u; // a loop ended early: the driver's loop limit

// Whether the ray has stopped: opacity for the preintegrated methods, transmittance for the
// midpoint rule.
bool terminated(float transmittance) {
#if RAY_METHOD == 0
    return transmittance < params.integrator.min_transmittance;
#else
    return 1.0 - transmittance > params.integrator.early_termination;
#endif
}

#if CLIP == 1
// Where the current segment's part inside a brick starts (main()): the integrators start there
// instead of at their first anchored step.
float g_head = 0.0;

// clip_box for a brick (twin of clip_brick): a ray parallel to a face that lies exactly on a
// face shared with the next brick up belongs to that brick only (as a sample on a plane does),
// so that no ray is integrated by two bricks.
bool clip_brick(vec3 o, vec3 d, out float t0, out float t1) {
    vec3 lo = params.integrator.clip_min.xyz;
    vec3 hi = params.integrator.clip_max.xyz;
    for (int a = 0; a < 3; ++a) {
        if (abs(d[a]) < 1e-30 && o[a] == hi[a] && hi[a] < params.integrator.box_max[a]) {
            return false;
        }
    }
    return clip_box(o, d, lo, hi, t0, t1);
}
#define CLIP_START(t) max((t), g_head)
#else
#define CLIP_START(t) (t)
#endif

#if RAY_METHOD == 0
// Midpoint rule (riemann, reference): steps first .. last_step of n = ⌈L/δ⌉; isosurfaces
// crossed between consecutive samples are composited before the later sample's step. `prev`
// is the previous sample (w = 0 before the first). With isosurfaces, f is also evaluated at the
// entry and the t_exit, so that a surface in the half step before the first sample or after the
// last is not missed.
// The midpoint step of sample k (length dt) composited (nothing where f is undefined); true
// once the ray has stopped.
bool midpoint_step(vec4 k, float dt, inout vec3 color, inout float transmittance) {
    if (k.w == 0.0) {
        return false;
    }
    vec4 ct = transfer_lookup(k.y, params.integrator.tf_count);
    float a = 1.0 - exp(-ct.a * dt);
    color += transmittance * a * ct.rgb;
    transmittance *= 1.0 - a;
    return terminated(transmittance);
}

uint integrate(vec3 o, vec3 d, float t0, float t1, uint first, uint last_step, inout vec4 prev,
               inout vec3 color, inout float transmittance, inout uint evaluations) {
    uint steps = uint(ceil((t1 - t0) / params.integrator.step_world));
    // A compile-time false without isosurfaces: llvmpipe would run the extra evaluations under
    // a runtime condition anyway.
    bool isos = MAX_ISO > 0 && params.integrator.iso_count > 0u;
    if (first == 0u && isos) {
        prev = knot(o, d, CLIP_START(t0), evaluations);
    }
    uint last = min(last_step, steps);
    uint i = first;
    bool exited = false;
#if SKIP == 1
    float occupied_until = -3.0e38;
#endif
    // As in the fixed-step kernel, the hot loop leaves a sample whose step crosses or may touch
    // an isosurface (needs_surfaces) to the round around it, so that the root finders, which
    // llvmpipe would otherwise run on every step, run once per round: sample i, `k`, awaits
    // emit_crossings and its own step.
    bool pending = false;
    vec4 k = prev;
    float pending_dt = 0.0;
    while (i < last && !exited) {
        if (pending) {
            emit_crossings(o, d, prev, k, color, transmittance, evaluations);
            prev = k;
            pending = false;
            if (midpoint_step(k, pending_dt, color, transmittance)) {
                return CHUNK_FINISHED;
            }
            i += 1u;
        }
        for (; i < last; ++i) {
#if CLIP == 1
            // A brick's first step starts at its face (anchored steps, main()).
            float ta = max(t0 + float(i) * params.integrator.step_world, g_head);
            float dt = min(t0 + float(i + 1u) * params.integrator.step_world, t1) - ta;
#else
            float ta = t0 + float(i) * params.integrator.step_world;
            float dt = min(params.integrator.step_world, t1 - ta);
#endif
            if (dt <= 0.0) {
                exited = true;
                break;
            }
#if SKIP == 1
            // A midpoint in an empty block adds nothing: resume at the first midpoint past the
            // run of empty blocks (twin of skip in integrate_riemann). With isosurfaces, the
            // knot at its end stands in for the skipped samples (no crossing inside).
            float tm = ta + 0.5 * dt;
            if (tm >= occupied_until) {
                float t_exit;
                if (skip_span(o, d, tm, t1, t_exit)) {
                    uint j = min(resume_interval(t0 - 0.5 * params.integrator.step_world, params.integrator.step_world, t_exit, i + 1u), last);
                    count_skip(min(t0 + float(j) * params.integrator.step_world, t1) - ta, j - i, isos ? 1u : 0u);
                    if (isos) {
                        prev = knot(o, d, min(t_exit, t1), evaluations);
                    }
                    i = j - 1u;
                    continue;
                } else {
                    occupied_until = t_exit;
                }
            }
#endif
            vec4 next = knot(o, d, ta + 0.5 * dt, evaluations);
            if (needs_surfaces(prev, next)) {
                k = next;
                pending_dt = dt;
                pending = true;
                break;
            }
            prev = next;
            if (midpoint_step(next, dt, color, transmittance)) {
                return CHUNK_FINISHED;
            }
        }
    }
    if (!exited && i < steps) {
        return i == last_step ? CHUNK_DONE : CHUNK_TRUNCATED;
    }
    if (isos) {
        emit_crossings(o, d, prev, knot(o, d, t1, evaluations), color, transmittance,
                       evaluations);
    }
    return CHUNK_FINISHED;
}
#elif RAY_METHOD == 1
// Preintegration with a constant step: intervals first .. last_step, one lookup of
// table 0 per interval, the clipped composite for the ray's last one (twin of integrate_fixed).
// `prev` is the knot at the chunk's start (evaluated here for the first chunk).
//
// llvmpipe runs the body of every `if`, and the first iteration of every loop, whatever its
// lanes decide (gallivm masks lanes and never branches around a block). Rare work behind a
// condition in the loop would therefore cost every interval: the clipped composite (three
// lookups and an exp), the isosurface root finders (an MLS evaluation each) and the skip lookup.
// So the hot loop composites plain full-length intervals only and stops at an interval that
// needs more: one crossing an isosurface or possibly touching one (needs_surfaces), or one
// past the last skip lookup. The round around it does that work, once per round for the lanes
// that stopped, and the ray's last interval follows, once per chunk.
//
// With skipping, a knot that starts the ray or resumes it after a run of empty blocks is left
// pending (w = PENDING) until an interval needs it: a ray that starts in an empty run, or whose
// run is cut at SKIP_RUN blocks or at a chunk's end, does not evaluate where it would only
// skip again (twin of the pending knot in integrate_fixed). Every pending knot counts as saved
// until it is evaluated.
uint integrate(vec3 o, vec3 d, float t0, float t1, uint first, uint last_step, inout vec4 prev,
               inout vec3 color, inout float transmittance, inout uint evaluations) {
    float l = params.integrator.step_world;
    uint steps = uint(ceil((t1 - t0) / l));
    if (first == 0u) {
#if SKIP == 1
        if (CLIP_START(t0) == t0) {
            prev = vec4(t0, 0.0, 0.0, PENDING);
            count_skip(0.0, 1u, 0u);
        } else {
            prev = knot(o, d, CLIP_START(t0), evaluations);
        }
#else
        prev = knot(o, d, CLIP_START(t0), evaluations);
#endif
    }
    uint last = min(last_step, steps);
    uint full_end = min(last, steps - 1u);
    uint i = first;
#if CLIP == 1
    // A brick's first interval, from its face to the first anchored step, clipped (the last
    // interval's code below takes it when it is also the last).
    if (first == 0u && g_head > t0 && steps > 1u) {
        float tb = t0 + l;
        vec4 e = knot(o, d, tb, evaluations);
        emit_interval(o, d, prev, e, tb - g_head, knot_segment(prev, e, tb - g_head, false, 0u),
                      color, transmittance, evaluations);
        prev = e;
        if (terminated(transmittance)) {
            return CHUNK_FINISHED;
        }
        i = 1u;
    }
#endif
    // Interval i awaits emit_interval, `next` its end knot.
    bool pending = false;
    vec4 next = prev;
#if SKIP == 1
    float occupied_until = -3.0e38;
    uint checked = 0xffffffffu;
#endif
    while (i < full_end) {
        if (pending) {
            float ta = t0 + float(i) * l;
            float len = min(ta + l, t1) - ta;
            emit_interval(o, d, prev, next, len, full_segment(prev, next), color,
                          transmittance, evaluations);
            prev = next;
            pending = false;
            if (terminated(transmittance)) {
                return CHUNK_FINISHED;
            }
            i += 1u;
        }
#if SKIP == 1
        // Intervals inside a run of empty blocks are skipped; the first one reaching past it
        // starts from a fresh knot (twin of skip in integrate_fixed).
        float ts = t0 + float(i) * l;
        if (i < full_end && ts >= occupied_until && i != checked) {
            float t_exit;
            checked = i;
            if (skip_span(o, d, ts, t1, t_exit)) {
                uint j = min(resume_interval(t0, l, t_exit, i), last);
                if (j >= steps || skip_reaches_end(t_exit, t1)) {
                    count_skip(t1 - ts, steps - i, 0u);
                    return CHUNK_FINISHED;
                }
                if (j > i) {
                    count_skip(float(j - i) * l, j - i, 0u);
                    prev.w = PENDING;
                    i = j;
                    continue;
                }
            } else {
                occupied_until = t_exit;
            }
        }
        if (prev.w == PENDING && i < full_end) {
            prev = knot(o, d, CLIP_START(t0 + float(i) * l), evaluations);
            count_skip(0.0, 0u, 1u);
        }
#endif
        for (; i < full_end; ++i) {
            float ta = t0 + float(i) * l;
            float tb = min(ta + l, t1);
            if (tb <= ta) {
                return CHUNK_FINISHED;
            }
#if SKIP == 1
            if (ta >= occupied_until && i != checked) {
                break;
            }
#endif
            next = knot(o, d, tb, evaluations);
            if (needs_surfaces(prev, next)) {
                pending = true;
                break;
            }
            vec4 c = full_segment(prev, next);
            color += transmittance * c.rgb;
            transmittance *= 1.0 - c.a;
            prev = next;
            if (terminated(transmittance)) {
                return CHUNK_FINISHED;
            }
        }
    }
    // The ray's last interval, clipped at t1, with everything it may need.
    if (i + 1u == steps && i < last) {
        float ta = CLIP_START(t0 + float(i) * l);
        float tb = min(ta + l, t1);
        if (tb <= ta) {
            return CHUNK_FINISHED;
        }
#if SKIP == 1
        if (ta >= occupied_until) {
            float t_exit;
            if (skip_span(o, d, ta, t1, t_exit)
                && (resume_interval(t0, l, t_exit, i) >= steps || skip_reaches_end(t_exit, t1))) {
                count_skip(t1 - ta, 1u, 0u);
                return CHUNK_FINISHED;
            }
        }
        if (prev.w == PENDING) {
            prev = knot(o, d, ta, evaluations);
            count_skip(0.0, 0u, 1u);
        }
#endif
        next = knot(o, d, tb, evaluations);
        emit_interval(o, d, prev, next, tb - ta, knot_segment(prev, next, tb - ta, false, 0u),
                      color, transmittance, evaluations);
        prev = next;
        if (terminated(transmittance)) {
            return CHUNK_FINISHED;
        }
        i += 1u;
    }
    return i >= steps ? CHUNK_FINISHED : (i == last_step ? CHUNK_DONE : CHUNK_TRUNCATED);
}
#else
#include "raycast/adaptive.glsl"
#endif

// The length of an outer step: the adaptive integrator's top interval, else the step.
float outer_step() {
#if RAY_METHOD == 2
    return params.tables.longest_world;
#else
    return params.integrator.step_world;
#endif
}

// Outer steps of a segment [t0, t1]: midpoint steps, fixed intervals or adaptive top intervals,
// exactly as integrate() counts them.
uint segment_steps(float t0, float t1) {
    return uint(ceil((t1 - t0) / outer_step()));
}

void main() {
    load_params();
#if SKIP == 1
    skip_init();
#endif
#if MAX_ISO > 0
    load_isos();
#endif
    // The band's rows, and its columns: a brick's window, else the whole width.
    uvec2 pixel = uvec2(gl_GlobalInvocationID.x + band.col_offset,
                        gl_GlobalInvocationID.y + band.row_offset);
    if (gl_GlobalInvocationID.x >= band.cols || pixel.x >= params.camera.width
        || gl_GlobalInvocationID.y >= band.rows || pixel.y >= params.camera.height) {
        return;
    }
    uint index = pixel.y * params.camera.width + pixel.x;
    vec3 color = vec3(0.0);
    float transmittance = 1.0;
    uint evaluations = 0u;
    vec4 state = vec4(0.0);
    // A truncated chunk stays marked through later chunks of the same dispatch sequence, so
    // that a frame recorded whole (Renderer::record) still shows it when read after the fence.
    uint truncated = 0u;
    if (band.first > 0u) {
        uint count = counts[index];
        if ((count & RAY_DONE) != 0u) {
            return;
        }
        truncated = count & RAY_TRUNCATED;
        color = image[index].rgb;
        transmittance = image[index].a;
        evaluations = count & RAY_EVALUATIONS;
        state = ray_state[index];
#if SKIP == 1
        skipped = ray_stats[index].xy;
#endif
#if RAY_METHOD == 2
        ray_error = ray_stats[index].w;
#endif
    }
    vec3 o, d;
    camera_ray(pixel, o, d);
#if HULL == 1
    vec2 segs[HULL_SEGMENTS];
#if HULL_CACHED == 1
    int segments = segments_load(index, segs);
#else
    int segments = hull_segments(o, d, segs);
#if HULL_CACHED == 2
    if (band.first == 0u) {
        segments_store(index, segments, segs);
    }
#endif
#endif
    if (segments < 0) {
        image[index] = vec4(0.0);
        counts[index] = RAY_DONE | RAY_HULL_OVERFLOW;
        return;
    }
#else
    vec2 segs[1];
    int segments = 0;
    float b0, b1;
    if (clip_box(o, d, params.integrator.box_min.xyz, params.integrator.box_max.xyz, b0, b1)) {
        segs[0] = vec2(b0, b1);
        segments = 1;
    }
#endif
#if CLIP == 1
    // A brick: each segment's part inside the brick's box, its steps where the undivided
    // field's would be (from the segment's start), the first one starting at the face.
    float c0, c1;
    bool in_brick = clip_brick(o, d, c0, c1);
#endif
    // Outer steps are numbered across segments: segment s owns [base, base + its steps).
    uint outcome = CHUNK_FINISHED;
    uint base = 0u;
    for (int s = 0; s < segments; ++s) {
#if CLIP == 1
        float w0 = max(segs[s].x, c0);
        float w1 = min(segs[s].y, c1);
        if (!in_brick || w1 <= w0) {
            continue;
        }
        float anchor_step = outer_step();
        float t_start = segs[s].x + floor((w0 - segs[s].x) / anchor_step) * anchor_step;
        // The floor may land a step short when the face is on a step (twin of anchored).
        if (t_start + anchor_step <= w0) {
            t_start += anchor_step;
        }
        g_head = w0;
        vec2 seg = vec2(t_start, w1);
#else
        vec2 seg = segs[s];
#endif
        uint n = segment_steps(seg.x, seg.y);
        if (band.first < base + n && band.last > base) {
            uint first = band.first > base ? band.first - base : 0u;
            outcome = integrate(o, d, seg.x, seg.y, first, min(band.last - base, n),
                                state, color, transmittance, evaluations);
            if (outcome != CHUNK_FINISHED || terminated(transmittance)) {
                break;
            }
        }
        base += n;
        if (base >= band.last) {
            // The chunk ends at this segment's end; later segments belong to later chunks.
            outcome = s + 1 < segments ? CHUNK_DONE : CHUNK_FINISHED;
            break;
        }
    }
    // A neighbour loop cut short corrupted some evaluation, whatever the outer loop saw.
    if (g_loop_cut) {
        outcome = CHUNK_TRUNCATED;
    }
#ifdef RAY_STATS
    vec4 report = vec4(0.0);
#if SKIP == 1
    // z: the ray's length inside the domain, the denominator of the skipped fraction.
    float inside = 0.0;
    for (int s = 0; s < segments; ++s) {
        inside += segs[s].y - segs[s].x;
    }
    report.xyz = vec3(skipped, inside);
#endif
#if RAY_METHOD == 2
    report.w = ray_error;
#endif
    ray_stats[index] = report;
#endif
    if (outcome == CHUNK_FINISHED) {
        image[index] = vec4(color + transmittance * params.integrator.background.rgb, 1.0 - transmittance);
        counts[index] = evaluations | RAY_DONE | truncated;
    } else {
        image[index] = vec4(color, transmittance);
        counts[index] = evaluations | truncated | (outcome == CHUNK_TRUNCATED ? RAY_TRUNCATED : 0u);
        ray_state[index] = state;
    }
}
