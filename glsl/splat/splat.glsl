// EWA splatting helpers shared by the splat_* kernels: f32 twins of src/splat/footprint.rs
// (erfc_pos, phi_between, splat_profile, splat_column) and the sheet addition. Kernels declare
// `SplatParams params` first.
#ifndef VMLS_SPLAT_GLSL
#define VMLS_SPLAT_GLSL

// SPLAT_TILE (image tile edge), SPLAT_APRON (0, or 1 when post-shaded isosurfaces need
// neighbours) and SPLAT_MAX_KERNEL_ENTRIES come from src/splat/mod.rs as macros.

// e^x through exp2, which is what lavapipe computes either way; written out so that the
// scaling is one multiply the compiler can fold.
float exp_e(float x) {
    return exp2(x * 1.4426950408889634);
}

// erfc(x) for x >= 0, Abramowitz & Stegun 7.1.26 (|error| <= 1.5e-7).
float erfc_pos(float x) {
    float t = 1.0 / (1.0 + 0.3275911 * x);
    float poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741
                 + t * (-1.453152027 + t * 1.061405429))));
    return poly * exp_e(-x * x);
}

// Half the erfc tail at |z| / sqrt(2): the normal distribution's mass beyond |z|.
float normal_tail(float z) {
    return 0.5 * erfc_pos(abs(z) * 0.70710678118654752);
}

// Phi(zb) - Phi(za) for za <= zb from the tails qa, qb at its ends: each branch subtracts
// tails, so that f32 keeps its precision, and a boundary's erfc is computed once where
// consecutive sheets share it.
float phi_from_tails(float za, float qa, float zb, float qb) {
    if (za >= 0.0) {
        return qa - qb;
    } else if (zb <= 0.0) {
        return qb - qa;
    }
    return 1.0 - qa - qb;
}

// Phi(zb) - Phi(za) for za <= zb (twin: phi_between in src/splat/project.rs). Through the two
// tails: llvmpipe runs every branch, and branches of their own erfc pairs cost six erfc where
// two serve (a split pre-shaded splat_raster took about 14% less time).
float phi_between(float za, float zb) {
    return phi_from_tails(za, normal_tail(za), zb, normal_tail(zb));
}

// The pixel's ray through the image plane at unit distance, (dx, dy) with up positive, and
// the length of (dx, dy, 1): the same for every entry of a pixel, so computed once per pixel
// (splat_raster's pixel_at) and passed to splat_profile, not derived per entry.
vec3 pixel_view(vec2 pixel) {
    float f = params.focal;
    float dx = (pixel.x - params.centre_x) / f;
    float dy = (params.centre_y - pixel.y) / f;
    return vec3(dx, dy, sqrt(1.0 + dx * dx + dy * dy));
}

// Q d' for d' = (dx, dy, 1): the exact footprint's precision (footprint0, footprint1.xy) times
// the pixel's ray (twin: precision_times in src/splat/footprint.rs).
vec3 precision_times(Splat s, float dx, float dy) {
    vec4 q0 = s.footprint0, q1 = s.footprint1;
    return vec3(q0.x * dx + q0.y * dy + q0.w,
                q0.y * dx + q0.z * dy + q1.x,
                q0.w * dx + q1.x * dy + q1.y);
}

// The exact footprint's profile from a' = d'^T Q d', b' = d'^T Q r and the Gram form g at a
// pixel whose d' has length `len` (twin: lateral_profile in src/splat/footprint.rs), for a
// kernel of ray amplitude `amplitude`: (0, 0, 1) outside the cutoff.
vec3 lateral_profile(float a, float b, float g, float len, float amplitude, float cutoff) {
    if (!(a > 0.0)) {
        return vec3(0.0, 0.0, 1.0);
    }
    float e = g / a;
    if (e > cutoff * cutoff) {
        return vec3(0.0, 0.0, 1.0);
    }
    float inv_sqrt_a = inversesqrt(a);
    return vec3(amplitude * len * inv_sqrt_a * exp_e(-0.5 * e), -b * len / a,
                1.0 / (len * inv_sqrt_a));
}

// The lateral part of a splat's footprint at a pixel: (A, m, inv) with A the whole line
// integral through the pixel (0 outside the cutoff), m the kernel's mean distance along the
// pixel's ray and inv the inverse of its standard deviation there, so that the share in
// t in [ta, tb] is A * phi_between((ta - m) * inv, (tb - m) * inv). SPLAT_EXACT == 0: the
// affine footprint (exact for orthographic cameras); else the exact integral along the
// pixel's own ray (src/splat/project.rs explains both and the word layout), `view` the
// pixel's pixel_view. Needs SplatParams params.
vec3 splat_profile(Splat s, float cutoff, vec2 pixel, vec3 view) {
#if SPLAT_EXACT == 0
    vec2 d = pixel - s.footprint0.xy;
    vec4 c = s.footprint1;
    float q = c.x * d.x * d.x + 2.0 * c.y * d.x * d.y + c.z * d.y * d.y;
    if (q > cutoff * cutoff) {
        return vec3(0.0, 0.0, 1.0);
    }
    float m = s.footprint0.z + dot(s.footprint2.xy, d);
    return vec3(c.w * exp_e(-0.5 * q), m, 1.0 / s.footprint0.w);
#else
    float dx = view.x;
    float dy = view.y;
    vec4 q0 = s.footprint0, q1 = s.footprint1, j0 = s.footprint2, j1 = s.footprint3;
    // a' = d'^T Q d', b' = d'^T Q r with d' = (dx, dy, 1).
    vec3 qd = precision_times(s, dx, dy);
    float a = dx * qd.x + dy * qd.y + qd.z;
    vec3 r = vec3(q1.z, q1.w, j1.z);
    float b = dot(r, qd);
    // c - b'^2/a' = (r x d')^T adj(P) (r x d') / a', free of cancellation.
    vec3 w = vec3(r.y - r.z * dy, r.z * dx - r.x, r.x * dy - r.y * dx);
    float g = j0.x * w.x * w.x + j0.z * w.y * w.y + j1.y * w.z * w.z
            + 2.0 * (j0.y * w.x * w.y + j0.w * w.x * w.z + j1.x * w.y * w.z);
    return lateral_profile(a, b, g, view.z, j1.w, cutoff);
#endif
}

// The exact profile down one column of pixels, the rays d'(t) = (dx, dy0 + t, 1) of one dx
// (twin: splat_column in src/splat/footprint.rs): a(t) = a0 + t (a1 + t a2), b(t) = b0 + t b1
// and g(t) = g0 + t (g1 + t g2), exact polynomials since d' and w = r x d' are affine in t.
// Taken once per entry at the middle of an invocation's SPLAT_PIXELS rows and shared by them:
// a pixel then pays 5 multiply-adds for a, b and g where splat_profile pays 29 operations.
// The price is f32 rounding: g1 and g2 cancel a little, so e = g/a errs about 3x the direct
// Gram form (tests/splat_footprint.rs: 3.9e-5 against 1.2e-5 at most, the naive c - b^2/a
// 1.0); about the column's first row instead of its middle, 6.6x.
struct Column {
    vec3 a;
    vec2 b;
    vec3 g;
    float dy0;
};

Column splat_column(Splat s, vec2 view0) {
    Column c;
    c.dy0 = view0.y;
#if SPLAT_EXACT == 1
    float dx = view0.x;
    float dy = view0.y;
    vec4 q0 = s.footprint0, q1 = s.footprint1, j0 = s.footprint2, j1 = s.footprint3;
    vec3 qd = precision_times(s, dx, dy);
    vec3 r = vec3(q1.z, q1.w, j1.z);
    vec3 w = vec3(r.y - r.z * dy, r.z * dx - r.x, r.x * dy - r.y * dx);
    // adj(P) w, and adj(P) w1 for w1 = dw/dt = (-r.z, 0, r.x).
    vec3 pw = vec3(j0.x * w.x + j0.y * w.y + j0.w * w.z,
                   j0.y * w.x + j0.z * w.y + j1.x * w.z,
                   j0.w * w.x + j1.x * w.y + j1.y * w.z);
    vec3 pw1 = vec3(j0.w * r.x - j0.x * r.z, j1.x * r.x - j0.y * r.z, j1.y * r.x - j0.w * r.z);
    c.a = vec3(dx * qd.x + dy * qd.y + qd.z, 2.0 * qd.y, q0.z);
    c.b = vec2(dot(r, qd), r.x * q0.y + r.y * q0.z + r.z * q1.x);
    c.g = vec3(dot(w, pw), 2.0 * dot(w, pw1), r.x * pw1.z - r.z * pw1.x);
#else
    c.a = vec3(0.0);
    c.b = vec2(0.0);
    c.g = vec3(0.0);
#endif
    return c;
}

// splat_profile at a pixel of the column `c` was taken for (its pixel_view `view`): through
// the column where an invocation draws several rows, else directly.
vec3 splat_profile_at(Splat s, Column c, float cutoff, vec2 pixel, vec3 view) {
#if SPLAT_EXACT == 1 && SPLAT_PIXELS > 1
    float t = view.y - c.dy0;
    float a = c.a.x + t * (c.a.y + t * c.a.z);
    float b = c.b.x + t * c.b.y;
    float g = c.g.x + t * (c.g.y + t * c.g.z);
    return lateral_profile(a, b, g, view.z, s.footprint3.w, cutoff);
#else
    return splat_profile(s, cutoff, pixel, view);
#endif
}

// The share of a profile `pr` (splat_profile's) that lies in t in [ta, tb] (SPLAT_SPLIT == 0:
// the whole line integral); zero outside the cutoff.
float profile_share(vec3 pr, float ta, float tb) {
#if SPLAT_SPLIT == 1
    if (pr.x == 0.0) {
        return 0.0;
    }
    return pr.x * phi_between((ta - pr.y) * pr.z, (tb - pr.y) * pr.z);
#else
    return pr.x;
#endif
}


// A Splat is seven texels of the SPLATS buffer: footprint0..3 and color as rgba32f, bbox and
// slabs as rgba32ui (SPLAT_WORDS, the same buffer). Kernels that read or write splats declare
// `splat_texels` and `splat_words` (with their access qualifiers) before including this file
// and define SPLAT_READ or SPLAT_WRITE.
#ifdef SPLAT_READ
Splat load_splat(uint i) {
    int b = int(i) * 7;
    Splat s;
    s.footprint0 = imageLoad(splat_texels, b);
    s.footprint1 = imageLoad(splat_texels, b + 1);
    s.footprint2 = imageLoad(splat_texels, b + 2);
    s.footprint3 = imageLoad(splat_texels, b + 3);
    s.color = imageLoad(splat_texels, b + 4);
    s.bbox = ivec4(imageLoad(splat_words, b + 5));
    s.slabs = imageLoad(splat_words, b + 6);
    return s;
}
#endif
#ifdef SPLAT_WRITE
void store_splat(uint i, Splat s) {
    int b = int(i) * 7;
    imageStore(splat_texels, b, s.footprint0);
    imageStore(splat_texels, b + 1, s.footprint1);
    imageStore(splat_texels, b + 2, s.footprint2);
    imageStore(splat_texels, b + 3, s.footprint3);
    imageStore(splat_texels, b + 4, s.color);
    imageStore(splat_words, b + 5, uvec4(s.bbox));
    imageStore(splat_words, b + 6, s.slabs);
}
#endif

// The inclusive tile range (tx0, ty0, tx1, ty1) whose pixels or aprons meet a pixel box
// (twin: SplatSetup::tile_rect).
uvec4 tile_rect(ivec4 bbox) {
    int tiles_y = int((params.camera.height + uint(SPLAT_TILE) - 1u) / uint(SPLAT_TILE));
    return uvec4(uint(max(bbox.x - SPLAT_APRON, 0) / SPLAT_TILE),
                 uint(max(bbox.y - SPLAT_APRON, 0) / SPLAT_TILE),
                 uint(min((bbox.z + SPLAT_APRON) / SPLAT_TILE, int(params.tiles_x) - 1)),
                 uint(min((bbox.w + SPLAT_APRON) / SPLAT_TILE, tiles_y - 1)));
}

#endif
