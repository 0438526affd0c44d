#version 450
// Stage `recon_resample` (twin: ResampledGrid::build in src/recon/resample.rs): the general path
// (MLS, Gaussian or exact, the variant's MLS_RESAMPLED = 0) at every point of the grid
// RESAMPLE_FACTOR times finer, written as vec4(f, ∇f), x fastest: the fast path's fine grid.
// Undefined points (no neighbour) get the quiet NaN RESAMPLE_UNDEFINED in f and zeros in ∇f,
// as on the CPU (resample::UNDEFINED). RESAMPLE_PAGED: the points of a paged grid's pool
// (twin: ResampledGrid::build_paged), slot after slot, RESAMPLE_PAGE + 1 points per slot edge:
// a solved slot's from its page's corner, a shared slot filled with its value.
#extension GL_EXT_control_flow_attributes : require

layout(local_size_x = 64) in;

#include "common/types.glsl"

#include "common/params.glsl"
// A texel-buffer view (binding::kind): its size limit is maxTexelBufferElements (128 M texels on
// lavapipe), not maxStorageBufferRange (128 MiB).
layout(binding = BINDING_RESAMPLE_TARGET, rgba32f) uniform writeonly imageBuffer fine;
layout(push_constant) uniform Push { CountPush push; };
#if RESAMPLE_PAGED == 1
layout(std430, binding = BINDING_RESAMPLE_SLOTS) readonly buffer Slots { uvec2 slots[]; };
#endif

#include "field/neighbours.glsl"

void main() {
    load_params();
    uint n = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 64u;
    if (n >= push.count) {
        return;
    }
    uvec3 dims = uvec3(params.field.grid_dims.xyz - 1) * uint(RESAMPLE_FACTOR) + 1u;
#if RESAMPLE_PAGED == 1
    const uint edge = uint(RESAMPLE_PAGE) + 1u;
    uvec2 slot = slots[n / (edge * edge * edge)];
    if (slot.x == RESAMPLE_SLOT_CONSTANT) {
        imageStore(fine, int(n), vec4(uintBitsToFloat(slot.y), vec3(0.0)));
        return;
    }
    uvec3 counts = (max(dims - 1u, uvec3(1u)) + uint(RESAMPLE_PAGE) - 1u) / uint(RESAMPLE_PAGE);
    uvec3 page = uvec3(slot.x % counts.x, (slot.x / counts.x) % counts.y,
                       slot.x / (counts.x * counts.y));
    uint local = n % (edge * edge * edge);
    uvec3 idx = min(page * uint(RESAMPLE_PAGE)
                    + uvec3(local % edge, (local / edge) % edge, local / (edge * edge)),
                    dims - 1u);
#else
    uvec3 idx = uvec3(n % dims.x, (n / dims.x) % dims.y, n / (dims.x * dims.y));
#endif
    vec3 spacing = 1.0 / params.field.grid_inv_spacing.xyz;
    vec3 x = params.field.grid_origin.xyz + vec3(idx) * (spacing / float(RESAMPLE_FACTOR));
    MlsResult m = mls_evaluate(x);
#if RESAMPLE_DIRECT == 1
    // A fit the samples barely determine: the cells around this point are solved directly
    // (twin: resample::DIRECT, f the bits RESAMPLE_DIRECT_BITS, +inf in the first gradient).
    if (m.terms > 0u && g_margin < RESAMPLE_DIRECT_MARGIN) {
        imageStore(fine, int(n), vec4(uintBitsToFloat(RESAMPLE_DIRECT_BITS),
                                      uintBitsToFloat(0x7F800000u), 0.0, 0.0));
        return;
    }
#endif
    imageStore(fine, int(n), m.terms > 0u ? vec4(m.value, m.gradient)
                                          : vec4(uintBitsToFloat(RESAMPLE_UNDEFINED), vec3(0.0)));
}
