#version 450
// Stage splat_segments (twin: splat_segments in src/splat/raster.rs): post-shaded splatting
// over a hull, once per frame and pixel, the inside segments of the pixel's ray (hull.glsl, as
// the ray caster clips), at most SPLAT_SEGMENTS of them; more counts as an overflow, which the
// host reports as an error.
#extension GL_EXT_control_flow_attributes : enable

layout(local_size_x = 8, local_size_y = 8) in;

#include "common/types.glsl"

#include "splat/splat_params.glsl"
layout(std430, binding = BINDING_PIXEL_SEGMENTS) writeonly buffer SegBuf { vec2 pixel_segments[]; };
layout(std430, binding = BINDING_SPLAT_STATS) buffer StatsBuf { uint stats[]; };

#include "common/camera.glsl"
#include "field/hull.glsl"

// SplatCounts slot 5 (entries) is filled by the host; the GPU counts overflows there.
const uint STAT_SEGMENT_OVERFLOW = 5u;

void main() {
    load_params();
    uvec2 px = gl_GlobalInvocationID.xy;
    if (px.x >= params.camera.width || px.y >= params.camera.height) {
        return;
    }
    vec3 o, d;
    camera_ray(px, o, d);
    vec2 seg[HULL_SEGMENTS];
    int n = hull_segments(o, d, seg);
    uint base = (px.y * params.camera.width + px.x) * uint(SPLAT_SEGMENTS);
    if (n < 0 || n > SPLAT_SEGMENTS) {
        atomicAdd(stats[STAT_SEGMENT_OVERFLOW], 1u);
        n = 0;
    }
    for (int i = 0; i < SPLAT_SEGMENTS; ++i) {
        pixel_segments[base + uint(i)] = i < n ? seg[i] : vec2(0.0);
    }
}
