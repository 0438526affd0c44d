#version 450
// One ray per invocation: emission–absorption ray casting of the MLS field, twin of
// src/render/raycast.rs (stage `raycast`). Variant macro RAY_METHOD: 0 = midpoint rule
// (riemann, reference), 1 = preintegration with a fixed step, 2 = [MLS] adaptive subdivision
// (ADAPTIVE_LEVELS = stack entries = ⌊log2(l_max/l_min)⌋ + 1).
#extension GL_EXT_control_flow_attributes : require

layout(local_size_x = 8, local_size_y = 8) in;

#include "types.glsl"

layout(std430, binding = BINDING_PARAMS) readonly buffer ParamsBuf { RenderParams params; };
layout(std430, binding = BINDING_IMAGE) writeonly buffer ImageBuf { vec4 image[]; };
layout(std430, binding = BINDING_COUNTS) writeonly buffer CountsBuf { uint counts[]; };
layout(push_constant) uniform Push { RayPush band; };

#include "neighbours.glsl"
#include "transfer.glsl"
#include "camera.glsl"

#if RAY_METHOD != 0
#include "preint.glsl"
#endif

#if MAX_ISO > 0
#include "shading.glsl"
#endif

// A point on the ray: (t, s, ∇f·d, defined ? 1 : 0); its gradient is returned separately.
vec4 knot_gradient(vec3 o, vec3 d, float t, inout uint evaluations, out vec3 gradient) {
    MlsResult m = mls_evaluate(o + d * t);
    evaluations += 1u;
    gradient = m.gradient;
    return vec4(t, m.value, dot(m.gradient, d), m.terms > 0u ? 1.0 : 0.0);
}

vec4 knot(vec3 o, vec3 d, float t, inout uint evaluations) {
    vec3 unused;
    return knot_gradient(o, d, t, evaluations, unused);
}

#if MAX_ISO > 0
// Whether f crosses v in (a, e] (twin of interval::crosses).
bool crosses(float sa, float se, float v) {
    return (sa - v) * (se - v) < 0.0 || (se == v && sa != v);
}

const uint LOCATE_ITERATIONS = 12u;

// Regula falsi (Illinois) for f = v between knots a and e; returns t, the gradient there.
// A knot exactly at v is re-evaluated for its gradient (knots do not carry one).
float locate_crossing(vec3 o, vec3 d, vec4 a, vec4 e, float v, inout uint evaluations,
                      out vec3 gradient) {
    if (e.y == v) {
        knot_gradient(o, d, e.x, evaluations, gradient);
        return e.x;
    }
    gradient = vec3(0.0);
    vec2 lo = vec2(a.x, a.y - v);
    vec2 hi = vec2(e.x, e.y - v);
    float width = e.x - a.x;
    float best = e.x;
    for (uint it = 0u; it < LOCATE_ITERATIONS; ++it) {
        float t = clamp(lo.x - lo.y * (hi.x - lo.x) / (hi.y - lo.y), lo.x, hi.x);
        vec3 g;
        vec4 k = knot_gradient(o, d, t, evaluations, g);
        if (k.w == 0.0) {
            return best;
        }
        best = t;
        gradient = g;
        float fk = k.y - v;
        if (abs(fk) <= 1e-6 || hi.x - lo.x <= 1e-6 * width) {
            break;
        }
        if ((fk < 0.0) == (lo.y < 0.0)) {
            lo = vec2(t, fk);
            hi.y *= 0.5;
        } else {
            hi = vec2(t, fk);
            lo.y *= 0.5;
        }
    }
    return best;
}

// Crossings of [a, e], sorted by t: up to MAX_ISO (t, iso index) pairs; returns their count.
uint find_crossings(vec3 o, vec3 d, vec4 a, vec4 e, inout uint evaluations,
                    out vec4 hit_t, out vec3 hit_g[MAX_ISO], out uvec4 hit_i) {
    uint n = 0u;
    hit_t = vec4(0.0);
    hit_i = uvec4(0u);
    [[unroll]] for (int i = 0; i < MAX_ISO; ++i) {
        hit_g[i] = vec3(0.0);
        if (uint(i) < params.iso_count.x && crosses(a.y, e.y, isos[i].value)) {
            vec3 g;
            float t = locate_crossing(o, d, a, e, isos[i].value, evaluations, g);
            // Sorted insertion with constant indices only: find the slot, shift, store.
            uint slot = n;
            [[unroll]] for (int j = 0; j < MAX_ISO; ++j) {
                if (uint(j) < n && hit_t[j] > t && uint(j) < slot) {
                    slot = uint(j);
                }
            }
            [[unroll]] for (int j = MAX_ISO - 1; j > 0; --j) {
                if (uint(j) > slot && uint(j) <= n) {
                    hit_t[j] = hit_t[j - 1];
                    hit_g[j] = hit_g[j - 1];
                    hit_i[j] = hit_i[j - 1];
                }
            }
            [[unroll]] for (int j = 0; j < MAX_ISO; ++j) {
                if (uint(j) == slot) {
                    hit_t[j] = t;
                    hit_g[j] = g;
                    hit_i[j] = uint(i);
                }
            }
            n += 1u;
        }
    }
    return n;
}

#endif

// Composites the shaded isosurfaces crossed between two knots (midpoint samples).
void emit_crossings(vec3 o, vec3 d, vec4 a, vec4 e, inout vec3 color, inout float transmittance,
                    inout uint evaluations) {
#if MAX_ISO > 0
    if (params.iso_count.x == 0u || a.w == 0.0 || e.w == 0.0) {
        return;
    }
    vec4 hit_t;
    vec3 hit_g[MAX_ISO];
    uvec4 hit_i;
    uint n = find_crossings(o, d, a, e, evaluations, hit_t, hit_g, hit_i);
    [[unroll]] for (int j = 0; j < MAX_ISO; ++j) {
        if (uint(j) < n) {
            IsoSurface iso = isos[hit_i[j]];
            color += transmittance * shade_surface(iso, hit_g[j], d);
            transmittance *= 1.0 - iso.color_opacity.a;
        }
    }
#endif
}

#if RAY_METHOD != 0
// (C, α) of [a, e] of exactly len: table `level` for full-length intervals, else the clipped
// composite; undefined ends contribute nothing (twin of interval::knot_segment).
vec4 knot_segment(vec4 a, vec4 e, float len, bool full, uint level) {
    if (a.w == 0.0 || e.w == 0.0) {
        return vec4(0.0);
    }
    return full ? preint_lookup(level, a.y, e.y) : preint_segment(a.y, e.y, len);
}

// Composites [a, e] of exactly len, split at isosurface crossings (twin of
// interval::emit_interval). `plain` is the interval's knot_segment, already looked up by the
// caller, used as it is when no isosurface is crossed.
void emit_interval(vec3 o, vec3 d, vec4 a, vec4 e, float len, vec4 plain,
                   inout vec3 color, inout float transmittance, inout uint evaluations) {
    if (a.w == 0.0 || e.w == 0.0) {
        return;
    }
#if MAX_ISO > 0
    vec4 hit_t;
    vec3 hit_g[MAX_ISO];
    uvec4 hit_i;
    uint n = find_crossings(o, d, a, e, evaluations, hit_t, hit_g, hit_i);
#else
    uint n = 0u;
#endif
    if (n == 0u) {
        color += transmittance * plain.rgb;
        transmittance *= 1.0 - plain.a;
        return;
    }
#if MAX_ISO > 0
    float scale = len / (e.x - a.x);
    float t = a.x;
    float s = a.y;
    [[unroll]] for (int j = 0; j < MAX_ISO; ++j) {
        if (uint(j) < n) {
            IsoSurface iso = isos[hit_i[j]];
            float piece = (hit_t[j] - t) * scale;
            if (piece > 0.0) {
                vec4 c = preint_segment(s, iso.value, piece);
                color += transmittance * c.rgb;
                transmittance *= 1.0 - c.a;
            }
            color += transmittance * shade_surface(iso, hit_g[j], d);
            transmittance *= 1.0 - iso.color_opacity.a;
            t = hit_t[j];
            s = iso.value;
        }
    }
    float piece = (e.x - t) * scale;
    if (piece > 0.0) {
        vec4 c = preint_segment(s, e.y, piece);
        color += transmittance * c.rgb;
        transmittance *= 1.0 - c.a;
    }
#endif
}
#endif

#if RAY_METHOD == 0
// Midpoint rule (riemann, reference); isosurfaces crossed between consecutive samples are
// composited before the later sample's step.
void integrate(vec3 o, vec3 d, float t0, float t1, inout vec3 color, inout float transmittance,
               inout uint evaluations) {
    uint steps = uint(ceil((t1 - t0) / params.step));
    vec4 prev = vec4(0.0);
    for (uint i = 0u; i < steps; ++i) {
        float ta = t0 + float(i) * params.step;
        float dt = min(params.step, t1 - ta);
        if (dt <= 0.0) {
            break;
        }
        vec4 k = knot(o, d, ta + 0.5 * dt, evaluations);
        emit_crossings(o, d, prev, k, color, transmittance, evaluations);
        prev = k;
        if (k.w == 0.0) {
            continue;
        }
        vec4 ct = transfer_lookup(k.y, params.tf_count);
        float a = 1.0 - exp(-ct.a * dt);
        color += transmittance * a * ct.rgb;
        transmittance *= 1.0 - a;
        if (transmittance < params.min_transmittance) {
            break;
        }
    }
}
#elif RAY_METHOD == 1
// Preintegration with a constant step: one lookup of table 0 per interval, the clipped
// composite for the last one.
void integrate(vec3 o, vec3 d, float t0, float t1, inout vec3 color, inout float transmittance,
               inout uint evaluations) {
    float l = params.step;
    uint steps = uint(ceil((t1 - t0) / l));
    vec4 prev = knot(o, d, t0, evaluations);
    for (uint i = 0u; i < steps; ++i) {
        float ta = t0 + float(i) * l;
        float tb = min(ta + l, t1);
        if (tb <= ta) {
            break;
        }
        vec4 next = knot(o, d, tb, evaluations);
        vec4 plain = knot_segment(prev, next, tb - ta, i + 1u < steps, 0u);
        emit_interval(o, d, prev, next, tb - ta, plain, color, transmittance, evaluations);
        prev = next;
        if (1.0 - transmittance > params.integrator.y) {
            break;
        }
    }
}
#else
// [MLS] §4 adaptive subdivision on a local stack of pending interval ends; twin of
// src/render/raycast/adaptive.rs. A stack entry is a knot whose w holds ±(depth + 1) of the
// interval it closes, negative when f is undefined there (one vec4 per entry keeps the
// dynamically indexed stack small, which matters on lavapipe).
void integrate(vec3 o, vec3 d, float t0, float t1, inout vec3 color, inout float transmittance,
               inout uint evaluations) {
    float l_max = params.preint_range.z;
    float l_min = params.preint_range.w;
    float epsilon = params.integrator.x;
    float termination = params.integrator.y;
    vec4 stack[ADAPTIVE_LEVELS];
    int sp = 0;
    vec4 a = knot(o, d, t0, evaluations);
    while (a.x < t1 && 1.0 - transmittance <= termination) {
        bool full = a.x + l_max <= t1;
        float top = full ? l_max : t1 - a.x;
        vec4 first = knot(o, d, full ? a.x + l_max : t1, evaluations);
        stack[0] = vec4(first.xyz, first.w > 0.0 ? 1.0 : -1.0);
        sp = 1;
        while (sp > 0) {
            vec4 packed = stack[sp - 1];
            uint depth = uint(abs(packed.w)) - 1u;
            vec4 e = vec4(packed.xyz, packed.w > 0.0 ? 1.0 : 0.0);
            float len = top * exp2(-float(depth));
            vec4 c = knot_segment(a, e, len, full, depth);
            if (int(depth) + 1 < ADAPTIVE_LEVELS && (full || 0.5 * len >= l_min)) {
                vec4 m = knot(o, d, 0.5 * (a.x + e.x), evaluations);
                vec4 cl = knot_segment(a, m, 0.5 * len, full, depth + 1u);
                vec4 cr = knot_segment(m, e, 0.5 * len, full, depth + 1u);
                vec3 c2 = cl.rgb + (1.0 - cl.a) * cr.rgb;
                bool sign_change = a.z * e.z < 0.0;
                if (sign_change || transmittance * length(c.rgb - c2) > epsilon * length(c.rgb)) {
                    // Both halves are one level deeper; the left one is processed first.
                    float level = float(depth + 2u);
                    stack[sp - 1].w = packed.w > 0.0 ? level : -level;
                    stack[sp] = vec4(m.xyz, m.w > 0.0 ? level : -level);
                    sp += 1;
                    continue;
                }
                // Accepted: the two halves, each split at any isosurface it crosses.
                emit_interval(o, d, a, m, 0.5 * len, cl, color, transmittance, evaluations);
                emit_interval(o, d, m, e, 0.5 * len, cr, color, transmittance, evaluations);
            } else {
                emit_interval(o, d, a, e, len, c, color, transmittance, evaluations);
            }
            sp -= 1;
            a = e;
            if (1.0 - transmittance > termination) {
                return;
            }
        }
    }
}
#endif

void main() {
    uvec2 pixel = uvec2(gl_GlobalInvocationID.x, gl_GlobalInvocationID.y + band.row_offset);
    if (pixel.x >= params.width || gl_GlobalInvocationID.y >= band.rows || pixel.y >= params.height) {
        return;
    }
    vec3 o, d;
    camera_ray(pixel, o, d);
    vec3 color = vec3(0.0);
    float transmittance = 1.0;
    uint evaluations = 0u;
    float t0, t1;
    if (clip_box(o, d, params.box_min.xyz, params.box_max.xyz, t0, t1)) {
        integrate(o, d, t0, t1, color, transmittance, evaluations);
    }
    uint index = pixel.y * params.width + pixel.x;
    image[index] = vec4(color + transmittance * params.background.rgb, 1.0 - transmittance);
    counts[index] = evaluations;
}
