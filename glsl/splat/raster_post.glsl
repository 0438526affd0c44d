// Part of stage splat_raster (glsl/splat/splat_raster.comp, twin: splat_raster in
// src/splat/raster.rs): post-shaded compositing ([BLUR]). A sheet complete, its mean value is
// classified over the part of its slab inside the domain, and the isosurfaces crossed since
// the sheet before are shaded. Included once, post-shaded only, after accumulate.
#ifndef VMLS_RASTER_POST_GLSL
#define VMLS_RASTER_POST_GLSL

#if SPLAT_HULL == 1 && SPLAT_SEGMENTS != 4
#error "the pixel's hull segments are two vec4 registers"
#endif
// The length of [a, b] inside the domain along a pixel's ray: the box's [t_in,
// t_out], or the sum over the pixel's hull segments (s01, s23: two each, read once per pixel
// into registers; a storage-buffer read per sheet is a loop over the lanes on lavapipe).
float span_overlap(float a, float b, float t_in, float t_out, vec4 s01, vec4 s23) {
#if SPLAT_HULL == 1
    return max(min(b, s01.y) - max(a, s01.x), 0.0) + max(min(b, s01.w) - max(a, s01.z), 0.0)
           + max(min(b, s23.y) - max(a, s23.x), 0.0) + max(min(b, s23.w) - max(a, s23.z), 0.0);
#else
    return max(min(b, t_out) - max(a, t_in), 0.0);
#endif
}

// The length of sheet j's slab inside the domain.
float slab_overlap(int j, float t_in, float t_out, vec4 s01, vec4 s23) {
    float a = params.slab0_world + float(j) * params.slab_world;
    return span_overlap(a, a + params.slab_world, t_in, t_out, s01, s23);
}

#if SPLAT_HULL == 1
#define SEGMENTS(px) px.s01, px.s23
#else
#define SEGMENTS(px) vec4(0.0), vec4(0.0)
#endif

// Sheet k is complete: its mean value, and the next sheet's integral from the ring. The ring
// shifts whether or not it holds something: registers past the walk's `live` are zero, so
// shifting them changes nothing, and on lavapipe a shift under `if (live > 0u)` cost a masked
// blend per register and sheet (about 9% of a post-shaded splat_raster).
float take_sheet(inout Pixel px) {
    float v1 = px.sheet / params.slab_world;
#if SPLAT_RING > 0
    px.sheet = px.r0;
    RING_SHIFT(px)
#else
    px.sheet = 0.0;
#endif
    return v1;
}

#if SPLAT_INTERVAL > 0
#if SPLAT_CLEAR_SKIP == 1
// Halves this invocation's pixels skipped (splat_stat::CLEAR_SKIPPED, added once per pass).
uint clear_halves = 0u;
#endif
// Intervals between sheet middles (twin: composite_half): the field from s_f to s_b over
// [lo, hi], half a sheet (table 0's length), composited over its part inside the domain. A
// part keeps the half's colour per opacity, its opacity from the half's optical depth scaled
// by the part's share (exact for a constant field; only halves a boundary clips are scaled).
// Branch-free (but for SPLAT_CLEAR_SKIP's skip of all-zero entries and SPLAT_OUTSIDE_SKIP's of
// halves outside the domain): outside the domain (or with `on` 0) the share is 0 and so are
// its opacity and colour.
void composite_half(inout Pixel px, float lo, float hi, float on, float s_f, float s_b) {
#if SPLAT_CLEAR_SKIP == 1
    // A half whose table entries are all zero composites nothing (alpha 0, colour 0): on a
    // GPU the lanes that find it so skip both lookups (compiled where the transfer function
    // has a transparent run: SplatSetup::fit_transfer).
    if (preint_clear(s_f, s_b)) {
        clear_halves += 1u;
        return;
    }
#endif
    float r = on * span_overlap(lo, hi, px.t_in, px.t_out, SEGMENTS(px));
#if SPLAT_OUTSIDE_SKIP == 1
    // Outside the pixel's part of the domain the share is 0: on a GPU the lanes whose half lies
    // there skip its lookups (a mesh's hole and silhouette; SplatSetup::fit_device).
    if (r == 0.0) {
        return;
    }
#endif
    vec4 e = preint_lookup(0u, s_f, s_b);
    float f = r / (hi - lo);
    float alpha = f >= 1.0 ? e.a : 1.0 - exp2(f * log2(max(1.0 - e.a, 1e-30)));
    float scale = e.a > 0.0 ? alpha / e.a : 0.0;
    px.acc.rgb += (1.0 - px.acc.w) * e.rgb * scale;
    px.acc.w += (1.0 - px.acc.w) * alpha;
}
#endif

// Composites sheet j = k - 1 (value px.v) given sheet k's value v1 and lateral gradient,
// then shifts the pixel's sheet values. With intervals between sheet middles, the interval
// from sheet j - 1's middle to sheet j's instead, in two halves split at the sheet boundary,
// the isosurfaces between them; the field at the boundary is the Catmull-Rom cubic's through
// sheets j - 2 .. j + 1 (Hermite, [MLS] section 4's intervals with central-difference slopes)
// or the straight line's.
void composite_post(inout Pixel px, uint k, float v1, vec2 lat) {
    float slab = params.slab_world;
    int j = int(k) - 1;
    if (pixel_open(px) && px.in_domain && j >= 0 && sheet_owned(px, uint(j))) {
        float len = slab_overlap(j, px.t_in, px.t_out, SEGMENTS(px));
#if SPLAT_INTERVAL > 0
        float a_j = params.slab0_world + float(j) * slab;
        float half_sheet = 0.5 * slab;
        // Before the first sheet nothing is composited, and its value extends backwards (the
        // sheets may start at the near plane inside the field).
        float p0 = j == 0 ? px.v : px.v0;
        float p_2 = j <= 1 ? p0 : px.v_2;
#if SPLAT_INTERVAL == 2
        float mid = (9.0 * (p0 + px.v) - p_2 - v1) * (1.0 / 16.0);
#else
        float mid = 0.5 * (p0 + px.v);
#endif
        composite_half(px, a_j - half_sheet, a_j, j == 0 ? 0.0 : 1.0, p0, mid);
#endif
#if SPLAT_ISOSURFACES == 1
        if (j >= 1 && len > 0.0 && slab_overlap(j - 1, px.t_in, px.t_out, SEGMENTS(px)) > 0.0) {
            float v0 = px.v0, v = px.v;
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
                float across = 0.5 / slab;
                vec3 g0 = px.lat0.x * params.camera.right.xyz + px.lat0.y * params.camera.up.xyz
                          + (v - px.v_2) * across * px.d;
                vec3 g1 = px.lat1.x * params.camera.right.xyz + px.lat1.y * params.camera.up.xyz
                          + (v1 - v0) * across * px.d;
                for (uint hi = 0u; hi < hits; ++hi) {
                    IsoSurface iso = isos[order[hi]];
                    vec3 rgb = shade_surface(iso, mix(g0, g1, pos[hi]), px.d);
                    px.acc.rgb += (1.0 - px.acc.w) * rgb;
                    px.acc.w += (1.0 - px.acc.w) * iso.color_opacity.a;
                }
            }
        }
#endif
#if SPLAT_INTERVAL > 0
        composite_half(px, a_j, a_j + half_sheet, 1.0, mid, px.v);
#else
        if (len > 0.0) {
            vec4 ct = transfer_lookup(px.v, params.tf_count);
            float alpha = 1.0 - exp_e(-ct.a * len);
            px.acc.rgb += (1.0 - px.acc.w) * ct.rgb * alpha;
            px.acc.w += (1.0 - px.acc.w) * alpha;
        }
#endif
    }
    px.v_2 = px.v0;
    px.v0 = px.v;
    px.v = v1;
    px.lat0 = px.lat1;
    px.lat1 = lat;
}
#endif
