#version 450
// Evaluates the MLS field at a list of points (stage `mls_eval`): the kernel the GPU-vs-CPU
// tests and the throughput benchmark run. Twin: recon::mls_evaluate.
#extension GL_EXT_control_flow_attributes : require

layout(local_size_x = 64) in;

#include "common/types.glsl"

#include "common/params.glsl"
layout(std430, binding = BINDING_POINTS) readonly buffer PointsBuf { vec4 points[]; };
layout(std430, binding = BINDING_RESULTS) writeonly buffer ResultsBuf { MlsOut results[]; };
layout(push_constant) uniform Push { CountPush push; };

#include "field/neighbours.glsl"

void main() {
    load_params();
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 64u;
    if (i >= push.count) {
        return;
    }
    MlsResult m = mls_evaluate(points[i].xyz);
    results[i] = MlsOut(m.value, m.gradient.x, m.gradient.y, m.gradient.z, m.neighbours, m.terms, 0u, 0u);
}
