#version 450
// Stage splat_composite (twin: splat_composite in src/splat/accumulate.rs), one dispatch per
// sheet, one workgroup per occlusion tile, one invocation per pixel.
// - Pre-shaded: the sheet's optical depth D and emission E: alpha = 1 - e^-D, C += T (E/D) alpha.
// - Post-shaded ([BLUR]): one sheet behind; its mean value is classified over the part of the
//   slab inside the domain box; isosurfaces crossed since the previous sheet are located by
//   linear interpolation and shaded with central-difference gradients within and across sheets.
// Then the tile's occlusion flag: 1 when every pixel in it is opaque.
// image[p] = (premultiplied colour, opacity). Variant macros: SPLAT_POST, SPLAT_ORTHO,
// SPLAT_ISOSURFACES, SPLAT_SURFACES, SPLAT_HULL (post-shaded: the pixels' hull segments bound the
// domain instead of the box).
#extension GL_EXT_control_flow_attributes : enable

layout(local_size_x = 8, local_size_y = 8) in;

#include "types.glsl"

layout(push_constant) uniform PushBlock { SlabPush push; };
#include "splat_params.glsl"

#include "splat.glsl"
layout(std430, binding = BINDING_SHEETS) buffer SheetBuf { uint sheets[]; };
layout(std430, binding = BINDING_IMAGE) buffer ImageBuf { vec4 image[]; };
layout(std430, binding = BINDING_OCCLUSION) writeonly buffer OcclusionBuf { uint occlusion[]; };

#if SPLAT_POST == 1
#if SPLAT_HULL == 1
layout(std430, binding = BINDING_PIXEL_SEGMENTS) readonly buffer SegBuf { vec2 pixel_segments[]; };
#endif
#include "transfer.glsl"
#include "camera.glsl"
#if SPLAT_ISOSURFACES == 1
#include "shading.glsl"
#endif

const uint RING = 5u;

// Mean field value of sheet k (k < 0: nothing splatted yet) at a clamped pixel.
float sheet_value(int k, int x, int y) {
    if (k < 0) {
        return 0.0;
    }
    x = clamp(x, 0, int(params.width) - 1);
    y = clamp(y, 0, int(params.height) - 1);
    uint p = uint(y) * params.width + uint(x);
    return uintBitsToFloat(sheets[(uint(k) % RING) * params.width * params.height + p])
           / params.box_max.w;
}

// Central difference along one image axis, one-sided at the border, per world unit.
float sheet_diff(int k, int x, int y, bool horizontal, float pixel) {
    int c = horizontal ? x : y;
    int n = horizontal ? int(params.width) : int(params.height);
    int m = max(c - 1, 0);
    int p = min(c + 1, n - 1);
    if (p == m) {
        return 0.0;
    }
    float vm = horizontal ? sheet_value(k, m, y) : sheet_value(k, x, m);
    float vp = horizontal ? sheet_value(k, p, y) : sheet_value(k, x, p);
    return (vp - vm) / (float(p - m) * pixel);
}

vec3 sheet_gradient(int k, int x, int y, vec3 d) {
    float a = params.box_min.w + float(k) * params.box_max.w;
#if SPLAT_ORTHO == 1
    float pixel = 1.0 / params.forward.w;
#else
    float pixel = (a + 0.5 * params.box_max.w) / params.forward.w;
#endif
    float gx = sheet_diff(k, x, y, true, pixel);
    float gy = -sheet_diff(k, x, y, false, pixel);
    float gt = (sheet_value(k + 1, x, y) - sheet_value(k - 1, x, y)) / (2.0 * params.box_max.w);
    return gx * params.right.xyz + gy * params.up.xyz + gt * d;
}

// The length of sheet j's slab inside the domain along this pixel's ray: the box's [t_in,
// t_out], or the sum over the pixel's hull segments.
float slab_overlap(int j, float t_in, float t_out, uint p) {
    float a = params.box_min.w + float(j) * params.box_max.w;
    float b = a + params.box_max.w;
#if SPLAT_HULL == 1
    float len = 0.0;
    for (uint i = 0u; i < uint(SPLAT_SEGMENTS); ++i) {
        vec2 s = pixel_segments[p * uint(SPLAT_SEGMENTS) + i];
        len += max(min(b, s.y) - max(a, s.x), 0.0);
    }
    return len;
#else
    return max(min(b, t_out) - max(a, t_in), 0.0);
#endif
}
#endif

shared uint tile_open;

void main() {
    load_params();
    uvec2 px = gl_GlobalInvocationID.xy;
    bool inside = px.x < params.width && px.y < params.height;
    uint p = px.y * params.width + px.x;
    float done = params.background.w;
    if (gl_LocalInvocationIndex == 0u) {
        tile_open = 0u;
    }
    barrier();
    if (inside) {
        vec4 acc = image[p];
#if SPLAT_POST == 0
#if SPLAT_SURFACES == 1
        const uint STRIDE = 9u;
        float sw = uintBitsToFloat(sheets[9u * p + 4u]);
        float sa = uintBitsToFloat(sheets[9u * p + 5u]);
        vec3 sc = vec3(uintBitsToFloat(sheets[9u * p + 6u]), uintBitsToFloat(sheets[9u * p + 7u]),
                       uintBitsToFloat(sheets[9u * p + 8u]));
        for (uint c = 4u; c < 9u; ++c) {
            sheets[9u * p + c] = 0u;
        }
        // Surface splats first: coverage min(W, 1), normalised opacity and colour.
        if (!(acc.w > done) && sw > 0.0) {
            float cover = min(sw, 1.0) / sw;
            acc.rgb += (1.0 - acc.w) * sc * cover;
            acc.w += (1.0 - acc.w) * sa * cover;
        }
#else
        const uint STRIDE = 4u;
#endif
        vec4 e = vec4(uintBitsToFloat(sheets[STRIDE * p]), uintBitsToFloat(sheets[STRIDE * p + 1u]),
                      uintBitsToFloat(sheets[STRIDE * p + 2u]), uintBitsToFloat(sheets[STRIDE * p + 3u]));
        sheets[STRIDE * p] = 0u;
        sheets[STRIDE * p + 1u] = 0u;
        sheets[STRIDE * p + 2u] = 0u;
        sheets[STRIDE * p + 3u] = 0u;
        if (!(acc.w > done) && e.x > 0.0) {
            float alpha = 1.0 - exp(-e.x);
            acc.rgb += (1.0 - acc.w) * e.yzw / e.x * alpha;
            acc.w += (1.0 - acc.w) * alpha;
        }
#else
        int j = int(push.slab) - 1;
        vec3 o, d;
        float t_in, t_out;
        if (j >= 0 && !(acc.w > done)) {
            camera_ray(px, o, d);
            if (clip_box(o, d, params.box_min.xyz, params.box_max.xyz, t_in, t_out)) {
                int x = int(px.x), y = int(px.y);
                float len = slab_overlap(j, t_in, t_out, p);
                float v = sheet_value(j, x, y);
#if SPLAT_ISOSURFACES == 1
                if (j >= 1 && len > 0.0 && slab_overlap(j - 1, t_in, t_out, p) > 0.0) {
                    float v0 = sheet_value(j - 1, x, y);
                    // Crossings in order of their position between the two sheets.
                    float pos[4];
                    uint order[4];
                    uint hits = 0u;
                    for (uint i = 0u; i < params.iso_count; ++i) {
                        float iv = isos[i].value;
                        if ((v0 - iv) * (v - iv) < 0.0 || (v == iv && v0 != iv)) {
                            float a = (iv - v0) / (v - v0);
                            uint at = hits;
                            while (at > 0u && pos[at - 1u] > a) {
                                pos[at] = pos[at - 1u];
                                order[at] = order[at - 1u];
                                --at;
                            }
                            pos[at] = a;
                            order[at] = i;
                            ++hits;
                        }
                    }
                    if (hits > 0u) {
                        vec3 g0 = sheet_gradient(j - 1, x, y, d);
                        vec3 g1 = sheet_gradient(j, x, y, d);
                        for (uint h = 0u; h < hits; ++h) {
                            IsoSurface iso = isos[order[h]];
                            vec3 rgb = shade_surface(iso, mix(g0, g1, pos[h]), d);
                            acc.rgb += (1.0 - acc.w) * rgb;
                            acc.w += (1.0 - acc.w) * iso.color_opacity.a;
                        }
                    }
                }
#endif
                if (len > 0.0) {
                    vec4 ct = transfer_lookup(v, params.tf_count);
                    float alpha = 1.0 - exp(-ct.a * len);
                    acc.rgb += (1.0 - acc.w) * ct.rgb * alpha;
                    acc.w += (1.0 - acc.w) * alpha;
                }
            }
        }
        // Sheet k + 1 is accumulated next; its ring slot held sheet k - 4, read by nobody now.
        sheets[((push.slab + 1u) % RING) * params.width * params.height + p] = 0u;
#endif
        image[p] = acc;
        if (!(acc.w > done)) {
            atomicOr(tile_open, 1u);
        }
    }
    barrier();
    if (gl_LocalInvocationIndex == 0u) {
        occlusion[gl_WorkGroupID.y * params.tiles_x + gl_WorkGroupID.x] = tile_open == 0u ? 1u : 0u;
    }
}
