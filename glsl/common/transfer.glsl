// Piecewise-linear transfer function, twin of TransferFunction::lookup in src/view/transfer.rs:
// colour and extinction interpolated linearly in s between control points, clamped outside.
#ifndef VMLS_TRANSFER_GLSL
#define VMLS_TRANSFER_GLSL

layout(std430, binding = BINDING_TRANSFER) readonly buffer TransferBuf { TfPoint tf[]; };

#if TRANSFER_TEXELS_BOUND == 1
// The same points as rgba32f texels: 2i = color_tau, 2i + 1 = (s, padding). The ray caster
// binds this view; inside divergent code a storage-buffer load is a per-lane loop even at a
// uniform index, and `if` bodies run whatever the lanes decide (BENCHMARKS.md, "Two lavapipe
// costs").
layout(binding = BINDING_TRANSFER_TEXELS, rgba32f) uniform readonly imageBuffer tf_texels;

// rgb = emitted colour, a = extinction τ per world unit: the same selection and arithmetic as
// the storage-buffer version below. The segment is counted (one comparison per point, at the
// same texel in every lane), then only its two points are read and interpolated: one division
// per lookup, where interpolating every segment and selecting cost one per point.
vec4 transfer_lookup(float s, uint count) {
    uint seg = 0u;
    for (uint i = 1u; i < count; ++i) {
        seg += s >= imageLoad(tf_texels, int(2u * i + 1u)).x ? 1u : 0u;
    }
    int last = int(count) - 1;
    // Beyond the last point (and NaN): the last colour; at or below the first: the first.
    if (!(s == s) || int(seg) >= last) {
        return imageLoad(tf_texels, 2 * last);
    }
    if (s <= imageLoad(tf_texels, 1).x) {
        return imageLoad(tf_texels, 0);
    }
    int a = 2 * int(seg);
    float sa = imageLoad(tf_texels, a + 1).x;
    float sb = imageLoad(tf_texels, a + 3).x;
    return mix(imageLoad(tf_texels, a), imageLoad(tf_texels, a + 2), (s - sa) / (sb - sa));
}
#if defined(PREINT_EXACT_OPACITY) && PREINT_EXACT_OPACITY == 1
#if PREINT_TF_POINTS > 0
// Up to TF_BLOCK_POINTS points: (s, τ) of point i from the parameters' TfBlock, which the kernel
// copied into registers; the scan's trip count is then a constant, NIR unrolls it and every
// read is at a constant offset (no gather).
#define TF_S_TAU(i) (((i) & 1u) == 0u ? params.tf.s_tau[(i) >> 1u].xy : params.tf.s_tau[(i) >> 1u].zw)
#define TF_SCAN_POINTS uint(PREINT_TF_POINTS)
#else
// More points: one texel a point from the view (the same texel in every lane).
#define TF_S_TAU(i) imageLoad(tf_texels, int(2u * (i) + 1u)).xy
#define TF_SCAN_POINTS count
#endif
// x = the mean extinction ∫τ ds / |b − a| over [a, b] (either order) of the clamped
// piecewise-linear function, y = the point nearest the largest share of that integral (twin:
// TransferFunction::mean_tau, stage transfer_mean_tau): per piece its overlap times τ at the
// overlap's middle; below the first point and above the last the end values. A range narrower
// than min_width is widened upwards to it. Every piece is computed and weighted by its overlap
// (0 outside), so no lane branches.
vec2 transfer_mean_tau(float a, float b, float min_width, uint count) {
    float lo = min(a, b);
    float hi = max(max(a, b), lo + min_width);
    vec2 pa = TF_S_TAU(0u);
    float below = max(min(hi, pa.x) - lo, 0.0) * pa.y;
    float sum = below;
    float best = below;
    uint at = 0u;
    for (uint i = 1u; i < TF_SCAN_POINTS; ++i) {
        vec2 pb = TF_S_TAU(i);
        float u = max(lo, pa.x);
        float v = min(hi, pb.x);
        float w = max(v - u, 0.0);
        // Zero overlap (and a step, pb.x == pa.x) weighs 0: the division's result is not used.
        float t = w > 0.0 ? (0.5 * (u + v) - pa.x) / (pb.x - pa.x) : 0.0;
        float d = w * mix(pa.y, pb.y, t);
        sum += d;
        bool more = d > best;
        best = more ? d : best;
        at = more ? (pb.y >= pa.y ? i : i - 1u) : at;
        pa = pb;
    }
    float above = max(hi - max(lo, pa.x), 0.0) * pa.y;
    sum += above;
    at = above > best ? TF_SCAN_POINTS - 1u : at;
    return vec2(sum / (hi - lo), float(at));
}
#endif
#else
#if defined(PREINT_EXACT_OPACITY) && PREINT_EXACT_OPACITY == 1
#error "the exact opacity (PREINT_EXACT_OPACITY) reads the transfer function's texel view"
#endif
// rgb = emitted colour, a = extinction τ per world unit.
vec4 transfer_lookup(float s, uint count) {
    if (s <= tf[0].s) {
        return tf[0].color_tau;
    }
    for (uint i = 1u; i < count; ++i) {
        if (s < tf[i].s) {
            float t = (s - tf[i - 1u].s) / (tf[i].s - tf[i - 1u].s);
            return mix(tf[i - 1u].color_tau, tf[i].color_tau, t);
        }
    }
    return tf[count - 1u].color_tau;
}
#endif

#if defined(ADAPTIVE_CRITERION) && ADAPTIVE_CRITERION == 1

// How far τ and τ·c can move when s departs by at most `deviation` from the line the tables
// assume, somewhere in [lo, hi] (twin of TransferFunction::sensitivity, stage
// transfer_sensitivity).
#if TF_SENSITIVITY_PIECES >= 0
// Over the pieces of change the host computed (SensitivityBlock; flat pieces add nothing and are
// left out), copied into registers with the parameters: a constant trip count, so NIR unrolls
// the scan and no lane gathers. The adaptive kernel runs it for every interval it tests, and
// the scan through the texel view below cost about a fifth of a dense scene's frame.
float transfer_sensitivity(float lo, float hi, float deviation, uint count) {
    float m = 0.0;
    [[unroll]] for (int i = 0; i < TF_SENSITIVITY_PIECES; ++i) {
        vec4 p = params.sensitivity.pieces[i];
        float change = p.z < 0.0 ? p.w : min(p.z * deviation, p.w);
        m = p.y >= lo && p.x <= hi ? max(m, change) : m;
    }
    return m;
}
#else
// Through the texel view: inside divergent code a storage-buffer load is a per-lane loop even
// at a uniform index.
float transfer_sensitivity(float lo, float hi, float deviation, uint count) {
    float m = 0.0;
    vec4 ca = imageLoad(tf_texels, 0);
    float sa = imageLoad(tf_texels, 1).x;
    vec4 wa = vec4(ca.rgb * ca.a, ca.a);
    for (uint i = 1u; i < count; ++i) {
        vec4 cb = imageLoad(tf_texels, int(2u * i));
        float sb = imageLoad(tf_texels, int(2u * i + 1u)).x;
        vec4 wb = vec4(cb.rgb * cb.a, cb.a);
        if (sb >= lo && sa <= hi) {
            vec4 change = abs(wb - wa);
            float jump = max(max(change.x, change.y), max(change.z, change.w));
            float width = sb - sa;
            m = max(m, width > 0.0 ? min(jump / width * deviation, jump) : jump);
        }
        sa = sb;
        wa = wb;
    }
    return m;
}
#endif
#endif

#endif
