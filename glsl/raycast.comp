#version 450
// One ray per invocation: emission–absorption ray casting of the MLS field, twin of
// src/render/raycast.rs (stage `raycast`).
// Method: fixed-step midpoint rule with the transfer function applied directly; per step of
// length δ: a = 1 − exp(−τ(s)δ), C += T·a·c(s), T *= 1 − a. The last step of a segment uses
// its own length; the ray stops at T < min_transmittance or at the box exit.
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
        float len = t1 - t0;
        uint steps = uint(ceil(len / params.step));
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
    uint index = pixel.y * params.width + pixel.x;
    image[index] = vec4(color + transmittance * params.background.rgb, 1.0 - transmittance);
    counts[index] = evaluations;
}
