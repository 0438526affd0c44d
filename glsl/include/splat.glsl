// EWA splatting helpers shared by the splat_* kernels: f32 twins of src/splat/project.rs
// (erfc_pos, phi_between, splat_footprint) and the sheet addition. Kernels declare
// `SplatParams params` first.
#ifndef VMLS_SPLAT_GLSL
#define VMLS_SPLAT_GLSL

// Pixel blocks per binned entry and occlusion tiles, in pixels (src/splat/mod.rs).
const int SPLAT_BLOCK = 32;
const int SPLAT_TILE = 8;

// erfc(x) for x >= 0, Abramowitz & Stegun 7.1.26 (|error| <= 1.5e-7).
float erfc_pos(float x) {
    float t = 1.0 / (1.0 + 0.3275911 * x);
    float poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741
                 + t * (-1.453152027 + t * 1.061405429))));
    return poly * exp(-x * x);
}

// Phi(zb) - Phi(za) for za <= zb; each branch subtracts tails so f32 keeps its precision.
float phi_between(float za, float zb) {
    const float k = 0.70710678118654752;
    if (za >= 0.0) {
        return 0.5 * (erfc_pos(za * k) - erfc_pos(zb * k));
    } else if (zb <= 0.0) {
        return 0.5 * (erfc_pos(-zb * k) - erfc_pos(-za * k));
    }
    return 1.0 - 0.5 * (erfc_pos(-za * k) + erfc_pos(zb * k));
}

// The share of a splat's line integral through pixel (x, y) that lies in t in [ta, tb]; zero
// outside the cutoff ellipse.
float splat_footprint(Splat s, float cutoff, vec2 pixel, float ta, float tb) {
    vec2 d = pixel - s.centre_depth.xy;
    vec4 c = s.conic_amplitude;
    float q = c.x * d.x * d.x + 2.0 * c.y * d.x * d.y + c.z * d.y * d.y;
    if (q > cutoff * cutoff) {
        return 0.0;
    }
    float m = s.centre_depth.z + dot(s.slope.xy, d);
    float inv = 1.0 / s.centre_depth.w;
    return c.w * exp(-0.5 * q) * phi_between((ta - m) * inv, (tb - m) * inv);
}

// Inclusive pixel box of block b of a splat's bounding box.
ivec4 block_box(ivec4 bbox, uint blocks_x, uint b) {
    int x0 = bbox.x + int(b % blocks_x) * SPLAT_BLOCK;
    int y0 = bbox.y + int(b / blocks_x) * SPLAT_BLOCK;
    return ivec4(x0, y0, min(x0 + SPLAT_BLOCK - 1, bbox.z), min(y0 + SPLAT_BLOCK - 1, bbox.w));
}

#endif
