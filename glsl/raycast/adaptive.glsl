// The adaptive integrator (RAY_METHOD 2) of raycast.comp, included there; twin of
// src/raycast/adaptive.rs.
#ifndef VMLS_ADAPTIVE_GLSL
#define VMLS_ADAPTIVE_GLSL

// Adaptive integration of top intervals first .. last_step (top interval k is
// [t0 + k·l_max, min(t0 + (k+1)·l_max, t1)]); twin of src/raycast/adaptive.rs, whose
// documentation states both criteria: ADAPTIVE_CRITERION 0 = [MLS] §4 (halves compared),
// 1 = the Hermite criterion with its step controller. Intervals are dyadic inside a top; a stack
// entry is a knot closing a pending interval. [MLS]'s kernel keeps it as a vec4 whose w holds
// ±(depth + 1) of that interval, negative when f is undefined there; the Hermite kernel keeps
// (t, f, f') in registers and the rest in three words (integrate_adaptive). `a` is the knot at
// the chunk's start (evaluated here for the first chunk) and `predicted` the Hermite
// controller's depth (unused by [MLS]'s criterion), both carried between chunks. Each loop
// body has few MLS call sites: GLSL inlines every call, and lavapipe's compile time and code
// size grow with the copies.

// Stage `count_error` (twin of Ray::count_error): adds an accepted interval of `len` whose
// criterion estimated `error` per sample spacing, capped by the most that length can add.
void count_error(float error, float len, float transmittance) {
    float h = params.integrator.spacing_world;
    ray_error += min(error, transmittance * params.tables.peak * h) * (len / h);
}

#if ADAPTIVE_CRITERION == 1
float hull_sensitivity(vec3 h) {
    return transfer_sensitivity(h.x, h.y, h.z, params.integrator.tf_count);
}

// The Hermite criterion's error of [a, e] per sample spacing (twin of hermite_error); `mid`
// gets the Hermite's midpoint knot (w = 1) unless the hull holds an isosurface value (w = 0).
float hermite_error(vec4 a, vec4 e, float transmittance, out vec4 mid) {
    mid = vec4(0.0);
    bool da = a.w > 0.0;
    bool de = e.w > 0.0;
    if (!da && !de) {
        return 0.0;
    }
    if (da != de) {
        return 3.0e38;
    }
    float l = e.x - a.x;
    float m0 = l * a.z;
    float m1 = l * e.z;
    float scale = transmittance * params.integrator.spacing_world;
    vec3 whole = bezier_hull(a.y, e.y, m0, m1);
#if MAX_ISO > 0
    for (uint i = 0u; i < params.integrator.iso_count; ++i) {
        float v = isos[i].value;
        if (whole.x <= v && v <= whole.y) {
            bool between = min(a.y, e.y) <= v && v <= max(a.y, e.y);
            return between ? scale * hull_sensitivity(whole) : 3.0e38;
        }
    }
#endif
    float sm = hermite_midpoint(a.y, e.y, m0, m1);
    float mm = 1.5 * (e.y - a.y) - 0.25 * (m0 + m1);
    mid = vec4(0.5 * (a.x + e.x), sm, mm / l, 1.0);
    // One pass over the transfer function for both halves: their hulls' union, widened by the
    // whole interval's departure (the margin of the twin), and the larger departure.
    vec3 h0 = bezier_hull(a.y, sm, 0.5 * m0, 0.5 * mm);
    vec3 h1 = bezier_hull(sm, e.y, 0.5 * mm, 0.5 * m1);
    return scale * hull_sensitivity(vec3(min(h0.x, h1.x) - whole.z, max(h0.y, h1.y) + whole.z,
                                         max(h0.z, h1.z)));
}
#endif

#if ADAPTIVE_CRITERION == 1
// The stack lives in registers: constant-trip loops, unrolled by NIR into selects, stand in for
// dynamic indexing (LAVAPIPE.md: a dynamically indexed local array in divergent code ran at
// one core's speed).
vec3 stack_get(vec3 stack[ADAPTIVE_LEVELS], int i) {
    vec3 v = stack[0];
    [[unroll]] for (int k = 1; k < ADAPTIVE_LEVELS; ++k) {
        v = k == i ? stack[k] : v;
    }
    return v;
}

void stack_set(inout vec3 stack[ADAPTIVE_LEVELS], int i, vec3 v) {
    [[unroll]] for (int k = 0; k < ADAPTIVE_LEVELS; ++k) {
        stack[k] = k == i ? v : stack[k];
    }
}

// Units of the deepest level covered in the top starting at `start`: all of them in a full top,
// ⌊r/u⌋ of the ray's last one (length r); the rest is the tail (twin of top_limit).
uint top_limit(float start, float t1, float l_max, uint units) {
    if (start + l_max <= t1) {
        return units;
    }
    return min(uint(max(floor((t1 - start) / l_max * float(units)), 0.0)), units);
}

// The Hermite criterion with its step controller (twin of integrate_hermite). Every iteration
// of the outer loop evaluates f exactly once, at a new end or at a rejected interval's
// midpoint; the inner loop composites the intervals that pass in between without evaluating.
// So the SIMD lanes of a row meet at the one MLS call site whatever state each ray is in.
// Every interval of the loop has a table length: the ray's last top is covered only up to
// whole units, and the remainder (the tail, shorter than a unit) is composited after the loop,
// so the loop never pays the clipped composite's lookups.
uint integrate_adaptive(vec3 o, vec3 d, float t0, float t1, uint first, uint last_step,
                        inout vec4 a, inout uint predicted, inout vec3 color,
                        inout float transmittance, inout uint evaluations) {
    float l_max = params.tables.longest_world;
    float epsilon = params.integrator.epsilon;
    float termination = params.integrator.early_termination;
    uint units = 1u << uint(ADAPTIVE_LEVELS - 1);
    uint tops = uint(ceil((t1 - t0) / l_max));
    if (first == 0u) {
#if SKIP == 1
        // Pending (counted as saved) unless at a brick's face: the first top's start looks for
        // a run of empty blocks and resumes from a fresh knot (twin of the pending first knot).
        if (CLIP_START(t0) == t0) {
            a = vec4(t0, 0.0, 0.0, PENDING);
            count_skip(0.0, 1u, 0u);
        } else {
            a = knot(o, d, CLIP_START(t0), evaluations);
        }
#else
        a = knot(o, d, CLIP_START(t0), evaluations);
#endif
        predicted = 0u;
    }
    // The stack: entry i's knot (t, f, f'), and bit i of `defined` whether f is defined there.
    // The depths of the intervals the entries close rise strictly from the bottom up to the
    // entry under the top, whose depth the top's equals or exceeds (a split deepens the top and
    // pushes its left half at the same depth; a pop leaves the rest as it was), so bit j of
    // `below` marks the entry under the top that closes an interval of depth j, and
    // `top_depth` is the top's. A vec4 an entry, with the depth in w, kept more values live
    // across the loop (7 more at 7 levels) and measured about a fifth slower on a dense scene
    // (BENCHMARKS.md).
    vec3 stack[ADAPTIVE_LEVELS];
    uint defined = 0u;
    uint below = 0u;
    uint top_depth = 0u;
    uint last = min(last_step, tops);
    uint k = first;
    uint position = 0u;
    int sp = 0;
    bool tail = false;
#if CLIP == 1
    // A brick's face inside the first top: one clipped interval to the first unit of the
    // deepest level past it, from where intervals are the undivided ray's dyadic ones (twin of
    // the head in integrate_hermite). Past the last covered unit the tail takes it all.
    if (first == 0u && g_head > t0) {
        float u = l_max / float(units);
        position = min(uint(ceil((g_head - t0) / u)), top_limit(t0, t1, l_max, units));
        float tb = t0 + float(position) * u;
        if (tb > g_head) {
            vec4 e = knot(o, d, tb, evaluations);
            vec4 unused;
            float len = tb - g_head;
            count_error(hermite_error(a, e, transmittance, unused), len, transmittance);
            emit_interval(o, d, a, e, len, knot_segment(a, e, len, false, 0u), color,
                          transmittance, evaluations);
            a = e;
            if (1.0 - transmittance > termination) {
                return CHUNK_FINISHED;
            }
        }
    }
#endif
    while (k < last) {
        // Composite what passes, until an interval or a new end needs an evaluation.
        float t_eval = 0.0;
        uint depth = 0u;
        bool split = false;
        bool ended = false;
        bool top_start = false;
        // One pass of this loop tests the stack's top interval and, once the stack is empty,
        // places the next end: llvmpipe runs every body of a pass under a mask, so a dense scene,
        // whose every evaluation ends one accepted interval, pays one pass per evaluation (two
        // when the new end had a pass of its own: 20-25% of its frame, BENCHMARKS.md).
        while (true) {
            if (sp > 0) {
                depth = top_depth;
                vec4 e = vec4(stack_get(stack, sp - 1),
                              ((defined >> uint(sp - 1)) & 1u) != 0u ? 1.0 : 0.0);
                float len = l_max * exp2(-float(depth));
                bool can_split = int(depth) + 1 < ADAPTIVE_LEVELS;
                vec4 mid;
                float error = hermite_error(a, e, transmittance, mid);
                if (can_split && error > epsilon) {
                    t_eval = 0.5 * (a.x + e.x);
                    split = true;
                    break;
                }
                predicted = error == 0.0 ? 0u
                    : (depth > 0u && 0.81 * epsilon >= 4.0 * error ? depth - 1u : depth);
                count_error(error, len, transmittance);
                // Accepted: the halves through the predicted midpoint when the hull holds no
                // isosurface value, else the whole interval split at the surfaces it crosses.
                // One emit_interval call site: GLSL inlines every call, and lavapipe's compile
                // time grows with the inlined copies of the root finders. Both halves and the
                // whole interval read a table (adaptive setups build one below the deepest
                // level): no clipped composite here.
                bool halves = mid.w > 0.0;
                vec4 cl = table_segment(halves ? depth + 1u : depth, a, halves ? mid : e);
                vec4 cr = table_segment(depth + 1u, mid, e);
                for (uint piece = 0u; piece < (halves ? 2u : 1u); ++piece) {
                    bool left = piece == 0u;
                    emit_interval(o, d, left ? a : mid, halves && left ? mid : e,
                                  halves ? 0.5 * len : len, left ? cl : cr, color,
                                  transmittance, evaluations);
                }
                sp -= 1;
                position += units >> depth;
                a = e;
                if (1.0 - transmittance > termination) {
                    return CHUNK_FINISHED;
                }
                if (sp > 0) {
                    top_depth = uint(findMSB(below));
                    below &= ~(1u << top_depth);
                    continue;
                }
            }
            // The stack is empty: past a top's covered units, the next top (a last top that
            // covers none goes round again, to its tail).
            float start = t0 + float(k) * l_max;
            uint limit = top_limit(start, t1, l_max, units);
            if (position == limit) {
                if (k + 1u == tops) {
                    tail = true;
                    ended = true;
                    break;
                }
                k += 1u;
                position = 0u;
                if (k == last) {
                    ended = true;
                    break;
                }
                start = t0 + float(k) * l_max;
                limit = top_limit(start, t1, l_max, units);
                if (position == limit) {
                    continue;
                }
            }
            // A new end at the controller's depth, or deeper until the interval is aligned and
            // inside the covered part of the top.
            depth = predicted;
            while (position % (units >> depth) != 0u || position + (units >> depth) > limit) {
                depth += 1u;
            }
            uint to = position + (units >> depth);
            t_eval = start + l_max * (float(to) / float(units));
            top_start = position == 0u;
            break;
        }
        if (ended) {
            break;
        }
#if SKIP == 1
        // At a top's start, outside the inner loop (whose `if` bodies every lane pays): tops
        // inside a run of empty blocks are skipped, and the integration resumes from a fresh
        // knot at the start of the top holding the run's end (twin of the skip in
        // integrate_hermite).
        // A run past this chunk leaves the knot pending (PENDING) instead of evaluating one at
        // the chunk's end: the next chunk's first top looks again and resumes, whether or not
        // the run reaches past that top's start, with the one knot the twin evaluates.
        bool restart = false;
        bool defer = false;
        if (top_start) {
            float start = t0 + float(k) * l_max;
            float run = skip_run(o, d, start, t1, true);
            uint j = resume_interval(t0, l_max, run, k);
            if (j >= tops || skip_reaches_end(run, t1)) {
                count_skip(t1 - start, tops - k, 0u);
                return CHUNK_FINISHED;
            }
            if (j > k || a.w == PENDING) {
                restart = true;
                defer = j >= last;
                // At a top's start the position is already 0, as at the top resumed.
                uint to = min(j, last);
                count_skip(float(to - k) * l_max, to - k, defer ? 0u : 1u);
                k = to;
                t_eval = t0 + float(to) * l_max;
            }
        }
        if (defer) {
            a.w = PENDING;
            break;
        }
#endif
        // The one evaluation of this iteration.
        vec4 m = knot(o, d, t_eval, evaluations);
#if SKIP == 1
        if (restart) {
            a = m;
            continue;
        }
#endif
        // A split's halves are both one level deeper; the left one (closed by m) comes first.
        top_depth = split ? depth + 1u : depth;
        below = split ? below | (1u << top_depth) : 0u;
        stack_set(stack, sp, m.xyz);
        defined = (defined & ~(1u << uint(sp))) | (m.w > 0.0 ? 1u << uint(sp) : 0u);
        sp += 1;
    }
    if (tail) {
#if SKIP == 1
        // A run that passed the chunk before ended in the last top, short of its first unit.
        if (a.w == PENDING) {
            a = knot(o, d, t0 + float(k) * l_max, evaluations);
            count_skip(0.0, 0u, 1u);
        }
#endif
        // From the last covered unit to t1, clipped, without a test: once per chunk.
        float len = t1 - a.x;
        if (len > 0.0) {
            vec4 e = knot(o, d, t1, evaluations);
            vec4 unused;
            count_error(hermite_error(a, e, transmittance, unused), len, transmittance);
            emit_interval(o, d, a, e, len, knot_segment(a, e, len, false, 0u), color,
                          transmittance, evaluations);
        }
        return CHUNK_FINISHED;
    }
    if (k < last) {
        return CHUNK_TRUNCATED;
    }
    return k >= tops ? CHUNK_FINISHED : CHUNK_DONE;
}
#else
uint integrate_adaptive(vec3 o, vec3 d, float t0, float t1, uint first, uint last_step,
                        inout vec4 a, inout uint predicted, inout vec3 color,
                        inout float transmittance, inout uint evaluations) {
    float l_max = params.tables.longest_world;
    float l_min = params.integrator.l_min_world;
    float epsilon = params.integrator.epsilon;
    float termination = params.integrator.early_termination;
    uint tops = uint(ceil((t1 - t0) / l_max));
    if (first == 0u) {
        a = knot(o, d, t0, evaluations);
    }
    vec4 stack[ADAPTIVE_LEVELS];
    uint last = min(last_step, tops);
    uint k = first;
    for (; k < last; ++k) {
        float end = t0 + float(k + 1u) * l_max;
        bool full = end <= t1;
        float top = full ? l_max : t1 - a.x;
        if (top <= 0.0) {
            return CHUNK_FINISHED;
        }
        vec4 top_end = knot(o, d, full ? end : t1, evaluations);
        stack[0] = vec4(top_end.xyz, top_end.w > 0.0 ? 1.0 : -1.0);
        int sp = 1;
        while (sp > 0) {
            vec4 packed = stack[sp - 1];
            uint depth = uint(abs(packed.w)) - 1u;
            vec4 e = vec4(packed.xyz, packed.w > 0.0 ? 1.0 : 0.0);
            float len = top * exp2(-float(depth));
            vec4 c = knot_segment(a, e, len, full, depth);
            bool halves = false;
            vec4 m = e;
            vec4 cl = c;
            vec4 cr = c;
            if (int(depth) + 1 < ADAPTIVE_LEVELS && (full || 0.5 * len >= l_min)) {
                m = knot(o, d, 0.5 * (a.x + e.x), evaluations);
                cl = knot_segment(a, m, 0.5 * len, full, depth + 1u);
                cr = knot_segment(m, e, 0.5 * len, full, depth + 1u);
                vec3 c2 = cl.rgb + (1.0 - cl.a) * cr.rgb;
                bool sign_change = a.z * e.z < 0.0;
                float diff = length(c.rgb - c2);
                // The halves' error, were they composited: a third of their difference from
                // the whole (module documentation of the twin).
                float halves_error = transmittance
                    * max(diff, abs(c.a - (1.0 - (1.0 - cl.a) * (1.0 - cr.a)))) / 3.0;
                if (sign_change || transmittance * diff > epsilon * length(c.rgb)) {
                    // Halves that cannot be split again are composited whole, untested: the
                    // rejected test's estimate stands for them.
                    if (int(depth) + 2 >= ADAPTIVE_LEVELS || !(full || 0.25 * len >= l_min)) {
                        ray_error += halves_error;
                    }
                    // Both halves are one level deeper; the left one is processed first.
                    float level = float(depth + 2u);
                    stack[sp - 1].w = packed.w > 0.0 ? level : -level;
                    stack[sp] = vec4(m.xyz, m.w > 0.0 ? level : -level);
                    sp += 1;
                    continue;
                }
                ray_error += halves_error;
                halves = true;
            }
            // Accepted: the two halves (or the whole interval at the deepest level), each split
            // at any isosurface it crosses. One call site: GLSL inlines every call, and
            // lavapipe's compile time grows with the inlined copies of the root finders.
            for (uint piece = 0u; piece < (halves ? 2u : 1u); ++piece) {
                bool left = piece == 0u;
                emit_interval(o, d, left ? a : m, halves && left ? m : e,
                              halves ? 0.5 * len : len, left ? cl : cr, color, transmittance,
                              evaluations);
            }
            sp -= 1;
            a = e;
            if (1.0 - transmittance > termination) {
                return CHUNK_FINISHED;
            }
        }
        if (sp > 0) {
            return CHUNK_TRUNCATED;
        }
    }
    return k >= tops ? CHUNK_FINISHED : (k == last_step ? CHUNK_DONE : CHUNK_TRUNCATED);
}
#endif

// The chunk state is the knot `a` with the controller's depth folded into w:
// ±(predicted + 1), negative when f is undefined at a, plus PENDING_STATE when the knot is
// pending (PENDING).
#define PENDING_STATE 1024.0
uint integrate(vec3 o, vec3 d, float t0, float t1, uint first, uint last_step, inout vec4 state,
               inout vec3 color, inout float transmittance, inout uint evaluations) {
    bool pending = abs(state.w) > PENDING_STATE;
    uint predicted = uint(abs(state.w) - (pending ? PENDING_STATE : 0.0));
    predicted = predicted > 0u ? predicted - 1u : 0u;
    vec4 a = vec4(state.xyz, pending ? PENDING : (state.w > 0.0 ? 1.0 : 0.0));
    uint outcome = integrate_adaptive(o, d, t0, t1, first, last_step, a, predicted, color,
                                      transmittance, evaluations);
    float packed = float(predicted + 1u) + (a.w == PENDING ? PENDING_STATE : 0.0);
    state = vec4(a.xyz, a.w > 0.0 ? packed : -packed);
    return outcome;
}

#endif
