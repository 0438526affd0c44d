// Part of stage splat_raster (glsl/splat/splat_raster.comp, twin: splat_raster in
// src/splat/raster.rs): what an invocation keeps per pixel in registers (the Pixel, the
// post-shaded ring of sheets ahead), how a pixel starts, and the registers a pass saves for
// the next (save_pixel, load_pixel). Included once, after the bindings it reads.
#ifndef VMLS_RASTER_PIXEL_GLSL
#define VMLS_RASTER_PIXEL_GLSL

#if SPLAT_POST == 1 && SPLAT_RING > 0
// The ring registers, and their shift by one sheet (r<d> <- r<d+1>, the last cleared).
#if SPLAT_RING == 4
#define RING_REGISTERS(F) F(r0) F(r1) F(r2)
#define RING_SHIFT(px) px.r0 = px.r1; px.r1 = px.r2; px.r2 = 0.0;
#elif SPLAT_RING == 8
#define RING_REGISTERS(F) F(r0) F(r1) F(r2) F(r3) F(r4) F(r5) F(r6)
#define RING_SHIFT(px) \
    px.r0 = px.r1; px.r1 = px.r2; px.r2 = px.r3; px.r3 = px.r4; px.r4 = px.r5; px.r5 = px.r6; \
    px.r6 = 0.0;
#elif SPLAT_RING == 16
#define RING_REGISTERS(F) \
    F(r0) F(r1) F(r2) F(r3) F(r4) F(r5) F(r6) F(r7) F(r8) F(r9) F(r10) F(r11) F(r12) F(r13) \
    F(r14)
#define RING_SHIFT(px) \
    px.r0 = px.r1; px.r1 = px.r2; px.r2 = px.r3; px.r3 = px.r4; px.r4 = px.r5; px.r5 = px.r6; \
    px.r6 = px.r7; px.r7 = px.r8; px.r8 = px.r9; px.r9 = px.r10; px.r10 = px.r11; \
    px.r11 = px.r12; px.r12 = px.r13; px.r13 = px.r14; px.r14 = 0.0;
#else
#error "SPLAT_RING is 0, 4, 8 or 16"
#endif
#endif

// Everything a pixel keeps in registers.
struct Pixel {
    int x;
    int y;
    // Inside the image, and a pixel of the tile (not of its apron).
    bool inside;
    bool own;
    uint p;
    // Premultiplied colour and opacity.
    vec4 acc;
    // The pixel's ray for the exact footprint (pixel_view).
    vec3 view;
#if SPLAT_POST == 0
    // The sheet's optical depth and emission (D, E.rgb), and its surface splats' W, sum q*alpha,
    // C.rgb.
    vec4 ext;
#if SPLAT_SURFACES == 1
    float sw;
    float sa;
    vec3 sc;
#endif
#else
    // The integral of sheet k so far.
    float sheet;
#if SPLAT_RING > 0
    // The integrals of sheets k + 1 ... k + SPLAT_RING - 1 (r<d>: sheet k + 1 + d). Named
    // registers, not an array: llvmpipe keeps an array it cannot prove constant-indexed in
    // memory and reads it lane by lane.
#define DECLARE(r) float r;
    RING_REGISTERS(DECLARE)
#undef DECLARE
#endif
    // Mean values of sheets j - 2, j - 1, j = k - 1, and the lateral gradients of j - 1, j.
    float v_2;
    float v0;
    float v;
    vec2 lat0;
    vec2 lat1;
    vec3 d;
    float t_in;
    float t_out;
    bool in_domain;
#if SPLAT_HULL == 1
    // The pixel's hull segments (t_in, t_out) in pairs.
    vec4 s01;
    vec4 s23;
#endif
#endif
#if SPLAT_BRICK == 1
    // The pixel's ray, whose sheet midpoints say which sheets the brick owns.
    vec3 ray_o;
    vec3 ray_d;
#endif
    // Footprints evaluated and contributing.
    uint evaluated;
    uint contributions;
};

Pixel pixel_at(int x, int y, bool valid, bool own_tile) {
    Pixel px;
    int w = int(params.camera.width), h = int(params.camera.height);
    px.x = x;
    px.y = y;
    px.inside = valid && x >= 0 && y >= 0 && x < w && y < h;
    px.own = px.inside && own_tile;
    px.p = px.inside ? uint(y * w + x) : 0u;
    px.acc = vec4(0.0);
#if SPLAT_EXACT == 1
    px.view = pixel_view(vec2(x, y));
#else
    px.view = vec3(0.0);
#endif
#if SPLAT_POST == 0
    px.ext = vec4(0.0);
#if SPLAT_SURFACES == 1
    px.sw = 0.0;
    px.sa = 0.0;
    px.sc = vec3(0.0);
#endif
#else
    px.sheet = 0.0;
#if SPLAT_RING > 0
#define CLEAR(r) px.r = 0.0;
    RING_REGISTERS(CLEAR)
#undef CLEAR
#endif
    px.v_2 = 0.0;
    px.v0 = 0.0;
    px.v = 0.0;
    px.lat0 = vec2(0.0);
    px.lat1 = vec2(0.0);
    px.d = vec3(0.0);
    px.t_in = 0.0;
    px.t_out = 0.0;
    px.in_domain = false;
    if (px.own) {
        vec3 o;
        camera_ray(uvec2(x, y), o, px.d);
        px.in_domain = clip_box(o, px.d, params.box_min.xyz, params.box_max.xyz, px.t_in,
                                px.t_out);
    }
#if SPLAT_HULL == 1
    px.s01 = vec4(0.0);
    px.s23 = vec4(0.0);
    if (px.own) {
        uint at = px.p * uint(SPLAT_SEGMENTS);
        px.s01 = vec4(pixel_segments[at], pixel_segments[at + 1u]);
        px.s23 = vec4(pixel_segments[at + 2u], pixel_segments[at + 3u]);
    }
#endif
#endif
#if SPLAT_BRICK == 1
    px.ray_o = vec3(0.0);
    px.ray_d = vec3(0.0);
    if (px.own) {
        camera_ray(uvec2(x, y), px.ray_o, px.ray_d);
    }
#endif
    px.evaluated = 0u;
    px.contributions = 0u;
    return px;
}

// Whether the frame composites sheet k of the pixel: always, except in a brick's frame, which
// owns the sheets whose midpoint on the ray lies in its cell (lo <= x < hi).
bool sheet_owned(Pixel px, uint k) {
#if SPLAT_BRICK == 1
    float m = params.slab0_world + (float(k) + 0.5) * params.slab_world;
    vec3 x = px.ray_o + m * px.ray_d;
    return all(greaterThanEqual(x, params.cell_min.xyz)) && all(lessThan(x, params.cell_max.xyz));
#else
    return true;
#endif
}

// A pixel that still composites.
bool pixel_open(Pixel px) {
    return px.own && !(px.acc.w > params.early_termination);
}

// A pixel the walk must still serve at sheet k (twin: the lane test of splat_raster's stop in
// src/splat/raster.rs): open, and post-shaded its ray not past the domain's exit (the box's,
// or the end of its last hull segment). Every interval composited from sheet k on starts at
// slab0 + (k - 1.5) slabs or later, so a pixel whose exit lies before slab0 + (k - 2) slabs
// adds nothing more: its composites would be exact zeros. A ray that misses the domain is done
// from the start. Where a tile's rays leave the domain before the sheets end (a torus's hole
// and silhouette), its walk stops there.
bool pixel_live(Pixel px, uint k) {
#if SPLAT_POST == 1
    float exit_t = px.t_out;
#if SPLAT_HULL == 1
    exit_t = max(max(px.s01.y, px.s01.w), max(px.s23.y, px.s23.w));
#endif
    return pixel_open(px) && px.in_domain
           && params.slab0_world + (float(k) - 2.0) * params.slab_world < exit_t;
#else
    return pixel_open(px);
#endif
}

// The registers a pixel carries from one pass to the next, each through F (twin of the word
// count: RASTER_PIXEL_WORDS in src/splat/gpu.rs, which this must not exceed).
#if SPLAT_POST == 0
#if SPLAT_SURFACES == 1
#define PIXEL_REGISTERS(F) \
    F(px.acc.x) F(px.acc.y) F(px.acc.z) F(px.acc.w) F(px.ext.x) F(px.ext.y) F(px.ext.z) \
    F(px.ext.w) F(px.sw) F(px.sa) F(px.sc.x) F(px.sc.y) F(px.sc.z)
#else
#define PIXEL_REGISTERS(F) \
    F(px.acc.x) F(px.acc.y) F(px.acc.z) F(px.acc.w) F(px.ext.x) F(px.ext.y) F(px.ext.z) \
    F(px.ext.w)
#endif
#else
#define PIXEL_REGISTERS(F) \
    F(px.acc.x) F(px.acc.y) F(px.acc.z) F(px.acc.w) F(px.sheet) F(px.v_2) F(px.v0) F(px.v) \
    F(px.lat0.x) F(px.lat0.y) F(px.lat1.x) F(px.lat1.y)
#if SPLAT_RING > 0 && 12 + SPLAT_RING - 1 > SPLAT_PIXEL_WORDS
#error "a pixel's registers exceed SPLAT_PIXEL_WORDS"
#endif
#endif

// Stores the pixel's registers from word w on.
void save_pixel(Pixel px, uint w) {
#define PUT(f) raster_state[w++] = floatBitsToUint(f);
    PIXEL_REGISTERS(PUT)
#if SPLAT_POST == 1 && SPLAT_RING > 0
#define PUT_RING(r) PUT(px.r)
    RING_REGISTERS(PUT_RING)
#undef PUT_RING
#endif
#undef PUT
}

// Restores what save_pixel stored.
void load_pixel(inout Pixel px, uint w) {
#define GET(f) f = uintBitsToFloat(raster_state[w++]);
    PIXEL_REGISTERS(GET)
#if SPLAT_POST == 1 && SPLAT_RING > 0
#define GET_RING(r) GET(px.r)
    RING_REGISTERS(GET_RING)
#undef GET_RING
#endif
#undef GET
}

// The invocation's pixels, one statement each, and the last of them.
#if SPLAT_PIXELS == 1
#define EACH(F) F(px0)
#define LAST_PIXEL px0
#elif SPLAT_PIXELS == 2
#define EACH(F) F(px0) F(px1)
#define LAST_PIXEL px1
#elif SPLAT_PIXELS == 4
#define EACH(F) F(px0) F(px1) F(px2) F(px3)
#define LAST_PIXEL px3
#elif SPLAT_PIXELS == 8
#define EACH(F) F(px0) F(px1) F(px2) F(px3) F(px4) F(px5) F(px6) F(px7)
#define LAST_PIXEL px7
#else
#error "SPLAT_PIXELS is 1, 2, 4 or 8"
#endif
#if SPLAT_APRON > 0 && SPLAT_PIXELS != 1
#error "the apron's lateral exchange takes one pixel per invocation"
#endif
#endif
