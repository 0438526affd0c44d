// Preintegration tables ([MLS] §4): f32 twin of PreintegrationTables::lookup and ::segment in
// src/view/preintegration.rs. Table k (length preint_range.z · 2^−k) holds N² entries
// (C.rgb, α) at index k·N² + f + N·b; the zero-length limits (mean colour, τ̄) follow the last
// table. Needs `params` declared by the kernel.
#ifndef VMLS_PREINT_GLSL
#define VMLS_PREINT_GLSL

// Through an rgba32f texel-buffer view (binding::kind): a lookup's four per-lane gathers are then
// single gathers on llvmpipe instead of loops over the lanes.
layout(binding = BINDING_PREINT, rgba32f) uniform readonly imageBuffer preint;
#define preint_at(i) imageLoad(preint, int(i))

// 1 − e^{−x} without cancellation for small x.
float one_minus_exp(float x) {
    return x < 1e-3 ? x * (1.0 - 0.5 * x) : 1.0 - exp(-x);
}

// Bilinear lookup of table k at (s_f, s_b), clamped to the table's scalar range.
vec4 preint_lookup(uint k, float s_f, float s_b) {
    uint n = params.tables.resolution;
    float n1 = float(n - 1u);
    float scale = n1 / (params.tables.s_max - params.tables.s_min);
    float x = clamp((s_f - params.tables.s_min) * scale, 0.0, n1);
    float y = clamp((s_b - params.tables.s_min) * scale, 0.0, n1);
    uint x0 = min(uint(x), n - 2u);
    uint y0 = min(uint(y), n - 2u);
    float fx = x - float(x0);
    float fy = y - float(y0);
    uint base = k * n * n + x0 + n * y0;
    vec4 a = mix(preint_at(base), preint_at(base + 1u), fx);
    vec4 b = mix(preint_at(base + n), preint_at(base + n + 1u), fx);
    vec4 e = mix(a, b, fy);
#if defined(PREINT_EXACT_OPACITY) && PREINT_EXACT_OPACITY == 1
    // A length table's α from the transfer function's integral, its colour scaled to keep
    // C/α (twin: PreintegrationTables::entry, stage preint_lookup; [LUM], DESIGN §4). The
    // zero-length limits (k == lengths) are returned as read. Needs TF_COUNT from the kernel.
    float lo = params.tables.s_min;
    float hi = params.tables.s_max;
    vec2 mean = transfer_mean_tau(clamp(s_f, lo, hi), clamp(s_b, lo, hi),
                                  (hi - lo) * PREINT_MIN_WIDTH, TF_COUNT);
    float len = params.tables.longest_world * exp2(-float(k));
    float alpha = one_minus_exp(len * mean.x);
    vec3 fallback = imageLoad(tf_texels, 2 * int(mean.y)).rgb;
    vec3 colour = e.a > PREINT_MIN_ALPHA ? e.rgb / e.a : fallback;
    return k < params.tables.lengths ? vec4(colour * alpha, alpha) : e;
#else
    return e;
#endif
}

// Bits lo .. hi (inclusive, 0 <= lo, hi < 64) of word w (bits 32 w .. 32 w + 31) of a mask.
uint bin_bits(uint lo, uint hi, uint w) {
    int a = max(int(lo) - int(32u * w), 0);
    int b = min(int(hi) - int(32u * w), 31);
    return a > b ? 0u : (0xffffffffu >> uint(31 - b)) & (0xffffffffu << uint(a));
}

// Whether every entry preint_lookup(0, s_f, s_b) interpolates is zero (twin:
// PreintegrationTables::clear): the bins of table 0's nodes from one below the lower
// lookup's to one above the higher's upper node hold no nonzero entry
// (params.tables.occupied0/1, bins of OCCUPANCY_BINS = 64 nodes' shares).
bool preint_clear(float s_f, float s_b) {
    uint n = params.tables.resolution;
    float n1 = float(n - 1u);
    float scale = n1 / (params.tables.s_max - params.tables.s_min);
    uint x = uint(clamp((s_f - params.tables.s_min) * scale, 0.0, n1));
    uint y = uint(clamp((s_b - params.tables.s_min) * scale, 0.0, n1));
    uint lo = min(min(x, y), n - 2u);
    lo = lo > 0u ? lo - 1u : 0u;
    uint hi = min(min(max(x, y), n - 2u) + 2u, n - 1u);
    uint b0 = lo * 64u / n;
    uint b1 = hi * 64u / n;
    return (params.tables.occupied0 & bin_bits(b0, b1, 0u)) == 0u
           && (params.tables.occupied1 & bin_bits(b0, b1, 1u)) == 0u;
}

// (C, α) of a segment of any length r in (0, longest table]: binary decomposition over the
// table lengths, then the remainder from the zero-length limits (stage preintegrate_clipped).
// One loop of one lookup per iteration, its arguments selected: iterations 0 .. levels − 1 the
// tables, `levels` the zero-length limits, `levels` + 1 the last table for the remainder's
// colour. With `wanted` false the loop has no iterations to run: llvmpipe then pays one masked
// iteration instead of every lookup (it runs every loop's first iteration and both sides of
// every branch, whatever the lanes decide), so callers that need the clipped composite only
// for some intervals pass the condition instead of branching around the call.
vec4 preint_segment_if(bool wanted, float s_f, float s_b, float r) {
    vec3 color = vec3(0.0);
    float alpha = 0.0;
    float done = 0.0;
    uint levels = params.tables.lengths;
    float l = params.tables.longest_world;
    vec4 zero = vec4(0.0);
    float s0 = s_f;
    uint n = wanted ? levels + 2u : 0u;
    for (uint k = 0u; k < n; ++k) {
        bool table = k < levels;
        if (k == levels) {
            s0 = s_f + (s_b - s_f) * (done / r);
        }
        float end = min(done + l, r);
        uint at = table ? k : (k == levels ? levels : levels - 1u);
        vec4 e = preint_lookup(at, table ? s_f + (s_b - s_f) * (done / r) : s0,
                               table ? s_f + (s_b - s_f) * (end / r) : s_b);
        if (table) {
            if (r - done >= l * (1.0 - 1e-6)) {
                color += (1.0 - alpha) * e.rgb;
                alpha += (1.0 - alpha) * e.a;
                done = end;
            }
            l *= 0.5;
        } else if (k == levels) {
            zero = e;
        } else {
            float rest = r - done;
            if (rest > 0.0) {
                float tau = zero.a;
                float a = one_minus_exp(rest * tau);
                float t_small = 2.0 * l * tau;
                vec3 c = zero.rgb;
                if (e.a > 0.0 && t_small > 0.0) {
                    c += (e.rgb / e.a - zero.rgb) * min(rest * tau / t_small, 1.0);
                }
                color += (1.0 - alpha) * a * c;
                alpha += (1.0 - alpha) * a;
            }
        }
    }
    return vec4(color, alpha);
}

vec4 preint_segment(float s_f, float s_b, float r) {
    return preint_segment_if(true, s_f, s_b, r);
}

#endif
