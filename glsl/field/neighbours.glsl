// Neighbour loops and the MLS evaluation built on them: twin of GridNeighbours / Octree in
// src/recon/ and of mls_evaluate in src/recon/mls.rs.
// Variant macro MLS_NEIGHBOURS: 0 = implicit regular-grid neighbours, 1 = redundant octree
// ([OCT], [MLS] §5.2). Needs `params` (RenderParams) declared by the kernel.
#ifndef VMLS_NEIGHBOURS_GLSL
#define VMLS_NEIGHBOURS_GLSL

#include "field/mls.glsl"

// Set when an octree leaf's loop ended before its last reference: a device that cuts long
// loops short (llvmpipe after 65 535 iterations, LAVAPIPE.md) would otherwise corrupt an
// evaluation silently; the ray caster reports the ray as truncated instead.
bool g_loop_cut = false;

#if RESAMPLE_DIRECT == 1 && MLS_RESAMPLED == 0
// The margin of the last solve (twin: mls_evaluate_margin's): its smallest pivot d_k / A_kk,
// k >= 1, or 0 where it fell back to fewer terms. recon_resample marks a fine point whose margin
// is below RESAMPLE_DIRECT_MARGIN, and the fast path solves the cells around it directly.
float g_margin = 1.0;
#endif

#if MLS_NEIGHBOURS == 0
// The grid, GRID_PAD zeros first, read through texel-buffer views (binding::kind): on llvmpipe
// an imageLoad is one gather per 8 lanes where a storage-buffer load with a per-lane index is a
// loop over the lanes; the linear ray caster ran 3× faster for it (BENCHMARKS.md). A view is
// bounded by maxTexelBufferElements, not by maxStorageBufferRange (LAVAPIPE.md: 2 GiB of
// rgba32f texels against 128 MiB), which is what lets a 512³ grid in. Row windows read whole
// units of GRID_UNIT values (grid_unit); single values pick theirs (grid_value).
#if GRID_BITS == 32
// f32 samples: a unit is one rgba32f texel.
layout(binding = BINDING_GRID, rgba32f) uniform readonly imageBuffer grid_texels;
#define GRID_UNIT 4
void grid_unit(int q, out float u[GRID_UNIT]) {
    vec4 v = imageLoad(grid_texels, q);
    u[0] = v.x;
    u[1] = v.y;
    u[2] = v.z;
    u[3] = v.w;
}
float grid_value(int i) {
    vec4 v = imageLoad(grid_texels, i >> 2);
    int c = i & 3;
    return c == 0 ? v.x : c == 1 ? v.y : c == 2 ? v.z : v.w;
}
#else
// 8- and 16-bit samples kept at their size (data::values; issue 25 §4), GRID_UNIT to an r32ui
// texel, little end first, converted here: float() of such an integer is exact, so the CPU
// twin's Values::get agrees bit for bit. One 32-bit gather per unit (R16 formats lose the
// gather on llvmpipe, LAVAPIPE.md).
layout(binding = BINDING_GRID_WORDS, r32ui) uniform readonly uimageBuffer grid_words;
#define GRID_UNIT (32 / GRID_BITS)
float grid_decode(uint word, int slot) {
#if GRID_SIGNED
    return float(bitfieldExtract(int(word), slot * GRID_BITS, GRID_BITS));
#else
    return float(bitfieldExtract(word, slot * GRID_BITS, GRID_BITS));
#endif
}
void grid_unit(int q, out float u[GRID_UNIT]) {
    uint w = imageLoad(grid_words, q).x;
    [[unroll]] for (int s = 0; s < GRID_UNIT; ++s) {
        u[s] = grid_decode(w, s);
    }
}
float grid_value(int i) {
    return grid_decode(imageLoad(grid_words, i / GRID_UNIT).x, i % GRID_UNIT);
}
#endif
#else
// Texel-buffer views (binding::kind): imageLoad compiles to one gather per 8 lanes on llvmpipe,
// where a storage-buffer load with a per-lane index is a loop over the lanes. `Sample` i is the
// three texels 3i, 3i + 1, 3i + 2; inline records are RECORD_STRIDE texels. Read as uints (the
// floats' bits), since a packed record's words are not floats.
layout(binding = BINDING_SAMPLES, rgba32ui) uniform readonly uimageBuffer samples;
layout(binding = BINDING_NODES, rgba32ui) uniform readonly uimageBuffer nodes;
layout(binding = BINDING_INDICES, r32ui) uniform readonly uimageBuffer indices;
#endif

// Gradient correction of the analytic gradient: q_k = Σ ∂w_i/∂x_k (f_i − b_iᵀc) b_i, with
// ∂w_i/∂x = −θ'(ρ)/ρ · M_i d (d = x_i − x; `md` = M_i d).
struct MlsGradient {
    float qx[MLS_TERMS];
    float qy[MLS_TERMS];
    float qz[MLS_TERMS];
};

// Adds sample (y, f)'s terms of the gradient correction, dθ = θ'(ρ)/ρ its weight's derivative.
void mls_add_gradient(inout MlsGradient g, vec3 y, float dtheta, float f, vec3 md,
                      float c[MLS_TERMS]) {
    float b[MLS_TERMS];
    mls_basis(y, b);
    float fit = 0.0;
    [[unroll]] for (int t = 0; t < MLS_TERMS; ++t) {
        fit += b[t] * c[t];
    }
    vec3 dw = -dtheta * md * (f - fit);
    [[unroll]] for (int t = 0; t < MLS_TERMS; ++t) {
        g.qx[t] += dw.x * b[t];
        g.qy[t] += dw.y * b[t];
        g.qz[t] += dw.z * b[t];
    }
}

#if MLS_WEIGHT == 0
// mls_visit_gradient without a branch (as mls_accumulate_all): outside the support the
// Wendland weight's derivative is 0 and adds zeros.
void mls_visit_gradient_all(inout MlsGradient g, vec3 y, float rho2, float f, vec3 md,
                            float c[MLS_TERMS]) {
    mls_add_gradient(g, y, wendland_clamped(rho2).y, f, md, c);
}
#endif

void mls_visit_gradient(inout MlsGradient g, vec3 y, float rho2, float f, vec3 md,
                        float c[MLS_TERMS]) {
    vec2 w = mls_weight(rho2);
    if (w.x <= 0.0) {
        return;
    }
    mls_add_gradient(g, y, w.y, f, md, c);
}

#if MLS_NEIGHBOURS == 0
// Specialisation for regular grids (DESIGN §7): the support box of x always fits in
// MLS_GRID_BOX³ grid points (MLS_GRID_BOX = ⌊2·support⌋ + 1, set by the host), so every lane
// runs the same fixed trip counts. Along an x-row, y_y and y_z are constant, so the row only
// needs the moments Σw, Σw·y_x, Σw·y_x², Σw·f, Σw·y_x·f (5 FMAs per sample), and the system is
// updated once per row. The quadratic basis adds Σw·y_x³, Σw·y_x⁴ and Σw·y_x²·f: each of its
// terms is y_x^p times a monomial g in (y_y, y_z) (QP, gyz), so entry (i, j) gains
// g_i g_j Σw·y_x^(p_i+p_j) and r_i gains g_i Σw·y_x^p_i·f; 8 sums a sample instead of 65.
// Same sums as mls_accumulate, reordered (f32 rounding apart).
// Pass 1 (the analytic gradient, Wendland weight θ = (1 − ρ²)⁴) factors the same way: with
// u = −θ'(ρ)/ρ = 8(1 − ρ²)³ and e = f − fit, where the fit along the row is A₀ + A₁y_x + A₂y_x²
// (A_p the sum of c_t g_t over the terms of x-power p), q_x[t] gains h⁻¹_x g_t Σu·e·y_x^(p_t+1)
// and q_y[t], q_z[t] gain h⁻¹_y y_y g_t, h⁻¹_z y_z g_t times Σu·e·y_x^p_t: 4 sums a sample
// instead of the basis, the fit and 3T multiply-adds (mls_visit_gradient_all's terms, reordered).
void mls_gather_rows(uint pass, vec3 x, inout MlsSystem s, inout MlsGradient g, float c[MLS_TERMS]) {
    vec3 gp = (x - params.field.grid_origin.xyz) * params.field.grid_inv_spacing.xyz;
    float inv_sc = 1.0 / params.field.support_cells;
    ivec3 base = ivec3(ceil(gp - params.field.support_cells));
    ivec3 dims = params.field.grid_dims.xyz;
    float xs[MLS_GRID_BOX];
    bool xin[MLS_GRID_BOX];
    [[unroll]] for (int ii = 0; ii < MLS_GRID_BOX; ++ii) {
        int i = base.x + ii;
        xs[ii] = (float(i) - gp.x) * inv_sc;
        xin[ii] = i >= 0 && i < dims.x;
    }
    // A row's MLS_GRID_BOX values sit in a window of MLS_GRID_WINDOW units starting at the
    // unit holding the first one: vector loads instead of per-sample scalar gathers, which were
    // 3/4 of the kernel's time on lavapipe. Out-of-row values in the window have zero weight;
    // the start is clamped into the buffer for points far outside the grid (all weights 0).
    // The last unit a window may start at: the buffer's padded length (padded_grid_len in
    // src/field/gpu.rs) in units, less the window.
    int padded = (dims.x * dims.y * dims.z + 3 * GRID_PAD + 3) / 4 * 4;
    int last_unit = padded / GRID_UNIT - MLS_GRID_WINDOW;
    int x0 = GRID_PAD + clamp(base.x, -GRID_PAD, dims.x);
    uint count = 0u;
    for (int kk = 0; kk < MLS_GRID_BOX; ++kk) {
        int k = base.z + kk;
        float yz = (float(k) - gp.z) * inv_sc;
        if (k < 0 || k >= dims.z || yz * yz >= 1.0) {
            continue;
        }
        for (int jj = 0; jj < MLS_GRID_BOX; ++jj) {
            int j = base.y + jj;
            float yy = (float(j) - gp.y) * inv_sc;
            float r2 = yy * yy + yz * yz;
            if (j < 0 || j >= dims.y || r2 >= 1.0) {
                continue;
            }
            int start = dims.x * (j + dims.y * k) + x0;
            int q = min(start / GRID_UNIT, last_unit);
            int o = start - GRID_UNIT * q;
            float win[GRID_UNIT * MLS_GRID_WINDOW];
            [[unroll]] for (int v = 0; v < MLS_GRID_WINDOW; ++v) {
                float u[GRID_UNIT];
                grid_unit(q + v, u);
                [[unroll]] for (int s = 0; s < GRID_UNIT; ++s) {
                    win[GRID_UNIT * v + s] = u[s];
                }
            }
            // Value ii of the row, win[o + ii], with constant indices only (a dynamic index
            // would spill win).
#if GRID_UNIT == 2
#define ROW_VALUE(ii) (o == 0 ? win[ii] : win[ii + 1])
#else
#define ROW_VALUE(ii) (o == 0 ? win[ii] : o == 1 ? win[ii + 1] : o == 2 ? win[ii + 2] : win[ii + 3])
#endif
            // Each term's x-power and (y_y, y_z) monomial.
#if MLS_TERMS >= 10
            const int QP[10] = int[](0, 1, 0, 0, 2, 0, 0, 1, 1, 0);
            float gyz[10] = float[](1.0, 1.0, yy, yz, 1.0, yy * yy, yz * yz, yy, yz, yy * yz);
#elif MLS_TERMS >= 4
            const int QP[4] = int[](0, 1, 0, 0);
            float gyz[4] = float[](1.0, 1.0, yy, yz);
#else
            const int QP[1] = int[](0);
            float gyz[1] = float[](1.0);
#endif
#if MLS_WEIGHT == 0
            if (pass == 1u) {
                float fit[3] = float[](0.0, 0.0, 0.0);
                [[unroll]] for (int t = 0; t < MLS_TERMS; ++t) {
                    fit[QP[t]] += c[t] * gyz[t];
                }
                float e0 = 0.0, e1 = 0.0, e2 = 0.0, e3 = 0.0;
                [[unroll]] for (int ii = 0; ii < MLS_GRID_BOX; ++ii) {
                    float xv = xs[ii];
                    float u = xin[ii] ? -wendland_clamped(xv * xv + r2).y : 0.0;
                    float ue = u * (ROW_VALUE(ii) - (fit[0] + xv * (fit[1] + xv * fit[2])));
                    e0 += ue;
                    e1 += ue * xv;
                    e2 += ue * xv * xv;
                    e3 += ue * xv * xv * xv;
                }
                float e[4] = float[](e0, e1, e2, e3);
                vec3 inv_h = params.field.inv_support.xyz;
                [[unroll]] for (int t = 0; t < MLS_TERMS; ++t) {
                    g.qx[t] += inv_h.x * gyz[t] * e[QP[t] + 1];
                    g.qy[t] += inv_h.y * yy * gyz[t] * e[QP[t]];
                    g.qz[t] += inv_h.z * yz * gyz[t] * e[QP[t]];
                }
                continue;
            }
#endif
            float s0 = 0.0, sx = 0.0, sxx = 0.0, sf = 0.0, sxf = 0.0;
#if MLS_TERMS >= 10
            float sx3 = 0.0, sx4 = 0.0, sxxf = 0.0;
#endif
            [[unroll]] for (int ii = 0; ii < MLS_GRID_BOX; ++ii) {
                float rho2 = xs[ii] * xs[ii] + r2;
                float w = xin[ii] ? mls_weight(rho2).x : 0.0;
                float f = ROW_VALUE(ii);
#if MLS_WEIGHT == 1
                if (w > 0.0 && rho2 < RHO_MIN * RHO_MIN) {
                    s.exact = true;
                    s.exact_value = f;
                }
#endif
                count += w > 0.0 ? 1u : 0u;
                float wx = w * xs[ii];
                s0 += w;
                sx += wx;
                sxx += wx * xs[ii];
                sf += w * f;
                sxf += wx * f;
#if MLS_TERMS >= 10
                float wxx = wx * xs[ii];
                float wx3 = wxx * xs[ii];
                sx3 += wx3;
                sx4 += wx3 * xs[ii];
                sxxf += wxx * f;
#endif
            }
#if MLS_TERMS >= 10
            float mom[5] = float[](s0, sx, sxx, sx3, sx4);
            float fmom[3] = float[](sf, sxf, sxxf);
            [[unroll]] for (int i = 0; i < 10; ++i) {
                s.r[i] += gyz[i] * fmom[QP[i]];
                [[unroll]] for (int j = 0; j <= i; ++j) {
                    s.a[TRI(i, j)] += gyz[i] * gyz[j] * mom[QP[i] + QP[j]];
                }
            }
#else
            s.a[0] += s0;
            s.r[0] += sf;
#endif
#if MLS_TERMS >= 4 && MLS_TERMS < 10
            s.a[TRI(1, 0)] += sx;
            s.a[TRI(1, 1)] += sxx;
            s.a[TRI(2, 0)] += yy * s0;
            s.a[TRI(2, 1)] += yy * sx;
            s.a[TRI(2, 2)] += yy * yy * s0;
            s.a[TRI(3, 0)] += yz * s0;
            s.a[TRI(3, 1)] += yz * sx;
            s.a[TRI(3, 2)] += yy * yz * s0;
            s.a[TRI(3, 3)] += yz * yz * s0;
            s.r[1] += sxf;
            s.r[2] += yy * sf;
            s.r[3] += yz * sf;
#endif
        }
    }
    if (pass == 0u) {
        s.neighbours = count;
        s.inv_h = params.field.inv_support.xyz;
    }
}
#endif

#if MLS_NEIGHBOURS == 0
// Visits the grid points inside the support box of x; pass 0 accumulates the normal equations,
// pass 1 the analytic-gradient correction. y = (i − g) / support_cells = (x_i − x) ⊙ h⁻¹.
void mls_gather(uint pass, vec3 x, inout MlsSystem s, inout MlsGradient g, float c[MLS_TERMS]) {
    vec3 gp = (x - params.field.grid_origin.xyz) * params.field.grid_inv_spacing.xyz;
    float sc = params.field.support_cells;
    float inv_sc = 1.0 / sc;
    ivec3 lo = max(ivec3(ceil(gp - sc)), ivec3(0));
    ivec3 hi = min(ivec3(floor(gp + sc)), params.field.grid_dims.xyz - 1);
    vec3 inv_h = params.field.inv_support.xyz;
    s.inv_h = inv_h;
    for (int k = lo.z; k <= hi.z; ++k) {
        float yz = (float(k) - gp.z) * inv_sc;
        for (int j = lo.y; j <= hi.y; ++j) {
            float yy = (float(j) - gp.y) * inv_sc;
            int row = params.field.grid_dims.x * (j + params.field.grid_dims.y * k);
            for (int i = lo.x; i <= hi.x; ++i) {
                vec3 y = vec3((float(i) - gp.x) * inv_sc, yy, yz);
                float rho2 = dot(y, y);
#if MLS_WEIGHT == 0
                if (pass == 1u) {
                    mls_visit_gradient_all(g, y, rho2, grid_value(GRID_PAD + row + i), y * inv_h, c);
                    continue;
                }
#endif
                if (rho2 < 1.0) {
                    float f = grid_value(GRID_PAD + row + i);
                    if (pass == 0u) {
                        mls_accumulate(s, y, rho2, f);
                    } else {
                        mls_visit_gradient(g, y, rho2, f, y * inv_h, c);
                    }
                }
            }
        }
    }
}
#else
// Descends to the leaf containing x; returns (first word, count, basis-scale bits) of its coded
// reference list (the scale: 1 / the leaf's mean support radius).
uvec3 octree_leaf(vec3 x) {
    vec3 center = params.field.octree_root.xyz;
    float half_side = params.field.octree_root.w;
    if (any(greaterThan(abs(x - center), vec3(half_side)))) {
        return uvec3(0u);
    }
    uint node = 0u;
    for (int depth = 0; depth < 64; ++depth) {
        uvec4 n = imageLoad(nodes, int(node));
        if (n.x == 0u) {
            return n.yzw;
        }
        half_side *= 0.5;
        bvec3 upper = greaterThanEqual(x, center);
        center += mix(vec3(-half_side), vec3(half_side), upper);
        node = n.x + (upper.x ? 1u : 0u) + (upper.y ? 2u : 0u) + (upper.z ? 4u : 0u);
    }
    return uvec3(0u);
}

// RECORD_STRIDE (the host's define, Variant::defines): texels per sample as the coded layout
// reads it (Sample in src/gpu_types.rs, 3) or per inline record (record_stride in
// src/field/records.rs: 3 with full metrics, 2 with diagonal ones, the Gaussian weight in the
// metric's w; 1 packed, where every support is a ball).

#if OCTREE_INLINE == 1
// Stage `octree_records` (twin: InlineLeaves in src/field/records.rs): a leaf is its first
// record and its record count; candidate r is record first + r (packed: after the leaf's
// frame, first + 1 + r), an address no load precedes.
uint leaf_first(uvec3 leaf) {
    return leaf.x;
}

bool leaf_code(uvec3 leaf, uint r, inout uint prev) {
#if RECORD_STRIDE == 1
    prev = leaf.x + 1u + r;
#else
    prev = leaf.x + r;
#endif
    return true;
}
#else
// Stage `octree_codes` (twin: LeafCodes in src/recon/octree_codes.rs): a leaf is its first
// sample index (word `begin`), then 16-bit codes from half 2 (begin + 1), two to a word: each
// adds itself to the running index, and names a sample unless it is the jump 0xFFFF. Code c's
// address does not depend on the codes before it, so the loads of a loop overlap.
uint leaf_first(uvec3 leaf) {
    return leaf.y > 0u ? imageLoad(indices, int(leaf.x)).x : 0u;
}

// Adds code r of `leaf` to the running index `prev`; false for a jump (no sample).
bool leaf_code(uvec3 leaf, uint r, inout uint prev) {
    uint h = 2u * (leaf.x + 1u) + r;
    uint code = bitfieldExtract(imageLoad(indices, int(h >> 1u)).x, int((h & 1u) << 4u), 16);
    prev += code;
    return code != 0xFFFFu;
}
#endif

vec4 sample_texel(int t) {
    return uintBitsToFloat(imageLoad(samples, t));
}

// The frame a leaf's candidates are offset in from query x: packed records (twin:
// PackedFrame), the leaf's corner relative to x and the step of its records' coordinates,
// read once per leaf; otherwise (−x, 0), so that d = p + (−x) is p − x to the bit.
vec4 leaf_frame(uvec3 leaf, vec3 x) {
#if RECORD_STRIDE == 1
    vec4 f = sample_texel(int(leaf.x));
    return vec4(f.xyz - x, f.w);
#else
    return vec4(-x, 0.0);
#endif
}

// Candidate i in `frame`: its offset d = x_i − x from the query, its value (packed Gaussian
// records: w_i f_i), and M_i d (MLS_FULL_METRIC 0: diagonal metrics only, and a third texel
// is never read).
void candidate(int i, vec4 frame, out vec3 d, out float value, out vec3 md) {
#if RECORD_STRIDE == 1
    uvec4 t = imageLoad(samples, i);
    uvec3 q = uvec3(t.x & 0x1FFFFFu, (t.x >> 21u) | ((t.y << 11u) & 0x1FFFFFu), t.y >> 10u);
    d = frame.xyz + vec3(ivec3(q)) * frame.w;
    value = uintBitsToFloat(t.z);
    md = uintBitsToFloat(t.w) * d;
#else
    vec4 pos_value = sample_texel(RECORD_STRIDE * i);
    d = pos_value.xyz + frame.xyz;
    value = pos_value.w;
    vec4 m = sample_texel(RECORD_STRIDE * i + 1);
    md = m.xyz * d;
#if MLS_FULL_METRIC == 1
    vec4 off = sample_texel(RECORD_STRIDE * i + 2);
    md += vec3(m.w * d.y + off.x * d.z, m.w * d.x + off.y * d.z, off.x * d.x + off.y * d.y);
#endif
#endif
}

// The Gaussian-sum weight v_i·norm_i of sample i (packed records hold it in their value).
float sample_weight(int i) {
#if RECORD_STRIDE == 1
    return 1.0;
#elif RECORD_STRIDE == 2
    return sample_texel(2 * i + 1).w;
#else
    return sample_texel(3 * i + 2).z;
#endif
}

void mls_gather(uint pass, vec3 x, inout MlsSystem s, inout MlsGradient g, float c[MLS_TERMS]) {
    uvec3 leaf = octree_leaf(x);
    vec3 scale = vec3(uintBitsToFloat(leaf.z));
    s.inv_h = scale;
    vec4 frame = leaf_frame(leaf, x);
    uint prev = leaf_first(leaf);
    uint r = 0u;
    for (; r < leaf.y; ++r) {
        if (!leaf_code(leaf, r, prev)) {
            continue;
        }
        vec3 d, md;
        float f;
        candidate(int(prev), frame, d, f, md);
        float rho2 = dot(d, md);
#if MLS_WEIGHT == 0
        if (pass == 0u) {
            mls_accumulate_all(s, d * scale, rho2, f);
        } else {
            mls_visit_gradient_all(g, d * scale, rho2, f, md, c);
        }
        continue;
#endif
        if (rho2 < 1.0) {
            if (pass == 0u) {
                mls_accumulate(s, d * scale, rho2, f);
            } else {
                mls_visit_gradient(g, d * scale, rho2, f, md, c);
            }
        }
    }
    if (r < leaf.y) {
        g_loop_cut = true;
    }
}
#endif

#if MLS_GAUSSIAN == 1
// The Gaussian-sum field (twin: gaussian_evaluate in src/recon/gaussian.rs): f = sum of
// w_i f_i exp(-rho^2 / (2 sigma^2)) over samples with rho < 1, w_i = v_i * norm_i, and its
// gradient sum w_i f_i exp(...) M_i d / sigma^2 (d = x_i - x). terms = 0 where no kernel reaches.
MlsResult gaussian_evaluate(vec3 x) {
    float k = -0.5 / (params.field.gauss_sigma * params.field.gauss_sigma);
    float value = 0.0;
    vec3 grad = vec3(0.0);
    uint count = 0u;
#if MLS_NEIGHBOURS == 0
    vec3 gp = (x - params.field.grid_origin.xyz) * params.field.grid_inv_spacing.xyz;
    float sc = params.field.support_cells;
    float inv_sc = 1.0 / sc;
    ivec3 lo = max(ivec3(ceil(gp - sc)), ivec3(0));
    ivec3 hi = min(ivec3(floor(gp + sc)), params.field.grid_dims.xyz - 1);
    vec3 inv_h = params.field.inv_support.xyz;
    for (int kk = lo.z; kk <= hi.z; ++kk) {
        for (int j = lo.y; j <= hi.y; ++j) {
            int row = params.field.grid_dims.x * (j + params.field.grid_dims.y * kk);
            for (int i = lo.x; i <= hi.x; ++i) {
                vec3 y = (vec3(i, j, kk) - gp) * inv_sc;
                float rho2 = dot(y, y);
                if (rho2 < 1.0) {
                    float wf = params.field.gauss_weight * grid_value(GRID_PAD + row + i) * exp(k * rho2);
                    value += wf;
                    // M d = d / h^2 = y / h.
                    grad += wf * (y * inv_h);
                    ++count;
                }
            }
        }
    }
#else
    uvec3 leaf = octree_leaf(x);
    vec4 frame = leaf_frame(leaf, x);
    uint prev = leaf_first(leaf);
    uint r = 0u;
    for (; r < leaf.y; ++r) {
        if (!leaf_code(leaf, r, prev)) {
            continue;
        }
        int i = int(prev);
        vec3 d, md;
        float f;
        candidate(i, frame, d, f, md);
        float rho2 = dot(d, md);
        // Selects, not a branch (see mls_accumulate_all): outside candidates add zeros.
        float w = sample_weight(i);
        float wf = rho2 < 1.0 ? w * f * exp(k * rho2) : 0.0;
        value += wf;
        grad += wf * md;
        count += rho2 < 1.0 ? 1u : 0u;
    }
    if (r < leaf.y) {
        g_loop_cut = true;
    }
#endif
    return MlsResult(value, grad / (params.field.gauss_sigma * params.field.gauss_sigma), count,
                     count > 0u ? 1u : 0u);
}
#endif

#if MLS_EXACT == 1
// Stage `exact_evaluate` (twin: the Exact arm of Field::evaluate): the Marschner–Lobb function
// and its analytic gradient (data::marschner_lobb::rho, rho_gradient) at x's position relative
// to the generated grid, whose first sample is the function's (-1,-1,-1).
MlsResult exact_evaluate(vec3 x) {
    const float PI = 3.14159265358979;
    vec3 w = x - vec3(1.0) - params.field.grid_origin.xyz;
    float r = length(w.xy);
    float scale = 1.0 / (2.0 * (1.0 + ML_ALPHA));
    float phase = 2.0 * PI * ML_F_M * cos(PI * r / 2.0);
    float value = (1.0 - sin(PI * w.z / 2.0) + ML_ALPHA * (1.0 + cos(phase))) * scale;
    vec2 dxy = vec2(0.0);
    if (r > 1e-12) {
        float d_rho_r = 2.0 * PI * ML_F_M * sin(phase) * sin(PI * r / 2.0) * (PI / 2.0);
        dxy = ML_ALPHA * scale * d_rho_r / r * w.xy;
    }
    vec3 grad = vec3(dxy, -(PI / 2.0) * cos(PI * w.z / 2.0) * scale);
    return MlsResult(value, grad, 1u, 1u);
}
#endif

#if MLS_RESAMPLED > 0
// The fast path's fine grid (recon_resample.comp): (f, ∇f) at MLS_RESAMPLED points per
// spacing, x fastest, or in pages (RESAMPLE_PAGED).
layout(binding = BINDING_RESAMPLED, rgba32f) uniform readonly imageBuffer resampled;
#if RESAMPLE_PAGED == 1
// A paged grid's page table (src/recon/pages.rs): each page's slot in `resampled`.
layout(binding = BINDING_RESAMPLE_PAGES, r32ui) uniform readonly uimageBuffer resample_pages;
#endif

// Stage `resample_evaluate` (twin: ResampledGrid::evaluate in src/recon/resample.rs): x clamped
// into the box; from the fine cell around it (8 texel reads; paged: after its page's slot),
// f = Σ w_c (f_c + ½ ∇f_c·(x − x_c)) with trilinear weights w_c (exact for quadratics) and ∇f interpolated trilinearly; undefined
// (terms 0) where a corner is (f = the quiet NaN RESAMPLE_UNDEFINED, compared as bits: a NaN
// compare could be folded away); terms RESAMPLE_DIRECT_TERMS where a corner is direct
// (RESAMPLE_DIRECT: +inf in its first gradient component), whatever the others.
MlsResult resampled_evaluate(vec3 x) {
    ivec3 dims = (params.field.grid_dims.xyz - 1) * MLS_RESAMPLED + 1;
    vec3 h = 1.0 / (params.field.grid_inv_spacing.xyz * float(MLS_RESAMPLED));
    vec3 g = (x - params.field.grid_origin.xyz) * params.field.grid_inv_spacing.xyz * float(MLS_RESAMPLED);
    g = clamp(g, vec3(0.0), vec3(dims - 1));
    ivec3 cell = min(ivec3(g), max(dims - 2, ivec3(0)));
    vec3 u = g - vec3(cell);
#if RESAMPLE_PAGED == 1
    // The cell's page, its slot (one table read), and the cell's corner in the slot.
    const int edge = RESAMPLE_PAGE + 1;
    ivec3 counts = (max(dims - 1, ivec3(1)) + RESAMPLE_PAGE - 1) / RESAMPLE_PAGE;
    ivec3 page = min(cell / RESAMPLE_PAGE, counts - 1);
    ivec3 local = cell - page * RESAMPLE_PAGE;
    int slot = int(imageLoad(resample_pages, page.x + counts.x * (page.y + counts.y * page.z)).x);
    ivec3 next = ivec3(dims.x > 1 ? 1 : 0, dims.y > 1 ? edge : 0, dims.z > 1 ? edge * edge : 0);
    int base = slot * edge * edge * edge + local.x + edge * (local.y + edge * local.z);
#else
    ivec3 next = ivec3(dims.x > 1 ? 1 : 0, dims.y > 1 ? dims.x : 0, dims.z > 1 ? dims.x * dims.y : 0);
    int base = cell.x + dims.x * (cell.y + dims.y * cell.z);
#endif
    float value = 0.0;
    vec3 gradient = vec3(0.0);
    bool defined = true;
    // A direct corner (resample::DIRECT) holds +inf in its first gradient component.
    bool direct = false;
    [[unroll]] for (int c = 0; c < 8; ++c) {
        vec3 b = vec3(c & 1, (c >> 1) & 1, c >> 2);
        vec3 wa = mix(1.0 - u, u, b);
        float w = wa.x * wa.y * wa.z;
        vec4 v = imageLoad(resampled, base + (c & 1) * next.x + ((c >> 1) & 1) * next.y + (c >> 2) * next.z);
        defined = defined && floatBitsToUint(v.x) != RESAMPLE_UNDEFINED && !isnan(v.x);
        direct = direct || floatBitsToUint(v.y) == 0x7F800000u;
        value += w * (v.x + 0.5 * dot(v.yzw, (u - b) * h));
        gradient += w * v.yzw;
    }
    return direct    ? MlsResult(0.0, vec3(0.0), 8u, RESAMPLE_DIRECT_TERMS)
           : defined ? MlsResult(value, gradient, 8u, 1u)
                     : MlsResult(0.0, vec3(0.0), 8u, 0u);
}
#endif

// f(x), ∇f(x); terms == 0 where no sample has weight (the field is undefined there).
MlsResult mls_evaluate(vec3 x) {
#if MLS_RESAMPLED > 0 && RESAMPLE_DIRECT == 1
    // Cells with a direct corner fall through to the general path below (twin: Field::evaluate).
    MlsResult fast = resampled_evaluate(x);
    if (fast.terms != RESAMPLE_DIRECT_TERMS) {
        return fast;
    }
#elif MLS_RESAMPLED > 0
    return resampled_evaluate(x);
#endif
#if MLS_EXACT == 1
    return exact_evaluate(x);
#endif
#if MLS_GAUSSIAN == 1
    return gaussian_evaluate(x);
#endif
    MlsSystem s;
    [[unroll]] for (int i = 0; i < MLS_PACKED; ++i) s.a[i] = 0.0;
    [[unroll]] for (int i = 0; i < MLS_TERMS; ++i) s.r[i] = 0.0;
    s.neighbours = 0u;
    s.exact = false;
    s.exact_value = 0.0;
    s.inv_h = vec3(0.0);
    MlsGradient g;
    float c[MLS_TERMS];
    [[unroll]] for (int i = 0; i < MLS_TERMS; ++i) {
        g.qx[i] = 0.0;
        g.qy[i] = 0.0;
        g.qz[i] = 0.0;
        c[i] = 0.0;
    }
#if MLS_NEIGHBOURS == 0
    mls_gather_rows(0u, x, s, g, c);
#else
    mls_gather(0u, x, s, g, c);
#endif
    MlsResult res = MlsResult(0.0, vec3(0.0), s.neighbours, 0u);
    if (s.neighbours == 0u) {
        return res;
    }
#if RESAMPLE_DIRECT == 1 && MLS_RESAMPLED == 0
    float diag[MLS_TERMS];
    [[unroll]] for (int k = 0; k < MLS_TERMS; ++k) {
        diag[k] = s.a[TRI(k, k)];
    }
#endif
    uint n = mls_factor(s.a);
    if (n == 0u) {
        return res;
    }
#if RESAMPLE_DIRECT == 1 && MLS_RESAMPLED == 0
    // After the factor, the diagonal holds the pivots d_k.
    g_margin = 1.0;
    [[unroll]] for (int k = 1; k < MLS_TERMS; ++k) {
        g_margin = min(g_margin, s.a[TRI(k, k)] / diag[k]);
    }
    g_margin = n < uint(MLS_TERMS) ? 0.0 : g_margin;
#endif
    c = s.r;
    mls_solve(s.a, n, c);
    res.terms = n;
    res.value = s.exact ? s.exact_value : c[0];
#if MLS_TERMS >= 4
    if (n >= 4u) {
        res.gradient = vec3(c[1], c[2], c[3]) * s.inv_h;
    }
#endif
#if MLS_ANALYTIC_GRADIENT == 1
#if MLS_NEIGHBOURS == 0 && MLS_WEIGHT == 0
    mls_gather_rows(1u, x, s, g, c);
#else
    mls_gather(1u, x, s, g, c);
#endif
    mls_solve(s.a, n, g.qx);
    mls_solve(s.a, n, g.qy);
    mls_solve(s.a, n, g.qz);
    res.gradient += vec3(g.qx[0], g.qy[0], g.qz[0]);
#endif
    return res;
}

#endif
