#version 450
// Stage `recon_resample` (twin: ResampledGrid::build in src/recon/resample.rs): the general path
// (MLS, Gaussian or exact, the variant's MLS_RESAMPLED = 0) at every point of the grid
// RESAMPLE_FACTOR times finer, written as vec4(f, ∇f), x fastest: the fast path's fine grid.
// Undefined points (no neighbour) get the quiet NaN RESAMPLE_UNDEFINED in f and zeros in ∇f,
// as on the CPU (resample::UNDEFINED).
#extension GL_EXT_control_flow_attributes : require

layout(local_size_x = 64) in;

#include "common/types.glsl"

#include "common/params.glsl"
// A texel-buffer view (binding::kind): its size limit is maxTexelBufferElements (128 M texels on
// lavapipe), not maxStorageBufferRange (128 MiB).
layout(binding = BINDING_RESAMPLE_TARGET, rgba32f) uniform writeonly imageBuffer fine;
layout(push_constant) uniform Push { CountPush push; };

#include "field/neighbours.glsl"

void main() {
    load_params();
    uint n = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 64u;
    if (n >= push.count) {
        return;
    }
    uvec3 dims = uvec3(params.field.grid_dims.xyz - 1) * uint(RESAMPLE_FACTOR) + 1u;
    uvec3 idx = uvec3(n % dims.x, (n / dims.x) % dims.y, n / (dims.x * dims.y));
    vec3 spacing = 1.0 / params.field.grid_inv_spacing.xyz;
    vec3 x = params.field.grid_origin.xyz + vec3(idx) * (spacing / float(RESAMPLE_FACTOR));
    MlsResult m = mls_evaluate(x);
    imageStore(fine, int(n), m.terms > 0u ? vec4(m.value, m.gradient)
                                          : vec4(uintBitsToFloat(RESAMPLE_UNDEFINED), vec3(0.0)));
}
