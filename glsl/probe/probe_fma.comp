#version 450
// FMA ceiling probe (stage `probe_fma`): 8 independent vec4 FMA chains, unrolled x4, so the
// result measures arithmetic throughput rather than latency or loop overhead. Each iteration
// is 4 x 8 vec4 FMAs = 256 flops per invocation. Twin: probe::fma_reference.
#extension GL_EXT_control_flow_attributes : require

layout(local_size_x = 64) in;

#include "common/types.glsl"

layout(std430, binding = BINDING_PROBE) writeonly buffer ProbeBuf { vec4 probe_out[]; };
layout(push_constant) uniform Push { CountPush push; };

void main() {
    uint id = gl_GlobalInvocationID.x;
    if (id >= push.count) {
        return;
    }
    float seed = float(id) * 1e-7;
    vec4 acc[8];
    [[unroll]] for (int c = 0; c < 8; ++c) {
        acc[c] = vec4(seed + float(c), seed - float(c), seed * float(c), 1.0);
    }
    const vec4 a = vec4(0.999999, 0.999998, 0.999997, 0.999996);
    const vec4 b = vec4(1e-6, 2e-6, 3e-6, 4e-6);
    for (uint it = 0u; it < push.iterations; ++it) {
        [[unroll]] for (int u = 0; u < 4; ++u) {
            [[unroll]] for (int c = 0; c < 8; ++c) {
                acc[c] = fma(acc[c], a, b);
            }
        }
    }
    vec4 sum = vec4(0.0);
    [[unroll]] for (int c = 0; c < 8; ++c) {
        sum += acc[c];
    }
    probe_out[id] = sum;
}
