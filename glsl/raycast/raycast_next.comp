#version 450
// Stage `raycast_next` (twin: next_groups in src/renderer/record.rs): after a chunk of a
// recorded frame, whether any ray of a band is unfinished, written as the workgroup counts of
// the band's next chunk (x = 0 when every ray is done), which the next chunk dispatches
// indirectly. A frame recorded whole (Renderer::record) then costs no raycast dispatch for a
// band whose rays all ended, as render() stops a band by reading its rays back. A band with a
// ray that the driver cut short (RAY_TRUNCATED) stops too: the host renders it again with
// smaller chunks, so its later chunks would be work thrown away. One workgroup per band.

layout(local_size_x = 64) in;

#include "common/types.glsl"

#include "common/params.glsl"
layout(std430, binding = BINDING_COUNTS) readonly buffer CountsBuf { uint counts[]; };
layout(std430, binding = BINDING_DISPATCH_ARGS) writeonly buffer ArgsBuf { uvec4 args[]; };
layout(push_constant) uniform Push { NextPush push; };

// Bit 0: a ray of the band is unfinished; bit 1: a ray was cut short.
shared uint band_state;

void main() {
    load_params();
    if (gl_LocalInvocationIndex == 0u) {
        band_state = 0u;
    }
    barrier();
    uint width = params.camera.width;
    uint first = push.row_offset * width;
    uint n = push.rows * width;
    uint mine = 0u;
    for (uint i = gl_LocalInvocationIndex; i < n; i += 64u) {
        uint count = counts[first + i];
        mine |= ((count & RAY_DONE) == 0u ? 1u : 0u) | ((count & RAY_TRUNCATED) != 0u ? 2u : 0u);
    }
    if (mine != 0u) {
        atomicOr(band_state, mine);
    }
    barrier();
    if (gl_LocalInvocationIndex == 0u) {
        args[push.args_slot] = band_state == 1u
                                   ? uvec4((push.cols + 7u) / 8u, (push.rows + 7u) / 8u, 1u, 0u)
                                   : uvec4(0u, 1u, 1u, 0u);
    }
}
