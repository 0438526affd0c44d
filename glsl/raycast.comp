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

// A point on the ray: (t, s, ∇f·d, defined ? 1 : 0).
vec4 knot(vec3 o, vec3 d, float t, inout uint evaluations) {
    MlsResult m = mls_evaluate(o + d * t);
    evaluations += 1u;
    return vec4(t, m.value, dot(m.gradient, d), m.terms > 0u ? 1.0 : 0.0);
}

#if RAY_METHOD == 0
// Midpoint rule (riemann, reference).
void integrate(vec3 o, vec3 d, float t0, float t1, inout vec3 color, inout float transmittance,
               inout uint evaluations) {
    uint steps = uint(ceil((t1 - t0) / params.step));
    for (uint i = 0u; i < steps; ++i) {
        float ta = t0 + float(i) * params.step;
        float dt = min(params.step, t1 - ta);
        if (dt <= 0.0) {
            break;
        }
        MlsResult m = mls_evaluate(o + d * (ta + 0.5 * dt));
        evaluations += 1u;
        if (m.terms == 0u) {
            continue;
        }
        vec4 ct = transfer_lookup(m.value, params.tf_count);
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
        if (prev.w > 0.0 && next.w > 0.0) {
            vec4 c = i + 1u < steps ? preint_lookup(0u, prev.y, next.y)
                                    : preint_segment(prev.y, next.y, tb - ta);
            color += transmittance * c.rgb;
            transmittance *= 1.0 - c.a;
        }
        prev = next;
        if (1.0 - transmittance > params.integrator.y) {
            break;
        }
    }
}
#else
// (C, α) of [a, e] of exactly len: table `level` for full-length intervals, else clipped.
vec4 adaptive_segment(vec4 a, vec4 e, float len, bool full, uint level) {
    if (a.w == 0.0 || e.w == 0.0) {
        return vec4(0.0);
    }
    return full ? preint_lookup(level, a.y, e.y) : preint_segment(a.y, e.y, len);
}

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
            vec4 c = adaptive_segment(a, e, len, full, depth);
            if (int(depth) + 1 < ADAPTIVE_LEVELS && (full || 0.5 * len >= l_min)) {
                vec4 m = knot(o, d, 0.5 * (a.x + e.x), evaluations);
                vec4 cl = adaptive_segment(a, m, 0.5 * len, full, depth + 1u);
                vec4 cr = adaptive_segment(m, e, 0.5 * len, full, depth + 1u);
                vec4 c2 = vec4(cl.rgb + (1.0 - cl.a) * cr.rgb, cl.a + (1.0 - cl.a) * cr.a);
                bool sign_change = a.z * e.z < 0.0;
                if (sign_change || transmittance * length(c.rgb - c2.rgb) > epsilon * length(c.rgb)) {
                    // Both halves are one level deeper; the left one is processed first.
                    float level = float(depth + 2u);
                    stack[sp - 1].w = packed.w > 0.0 ? level : -level;
                    stack[sp] = vec4(m.xyz, m.w > 0.0 ? level : -level);
                    sp += 1;
                    continue;
                }
                c = c2;
            }
            color += transmittance * c.rgb;
            transmittance *= 1.0 - c.a;
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
