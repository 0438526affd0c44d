// MLS reconstruction ([MLS] §3), f32 twin of src/recon/mls.rs (same stage names).
// Variant macros: MLS_TERMS (1 constant, 4 linear, 10 quadratic), MLS_WEIGHT (0 Wendland,
// 1 interpolating), MLS_ANALYTIC_GRADIENT (0 local, 1 analytic).
// Kernels include this after neighbours.glsl's buffers are declared; the kernel enables
// GL_EXT_control_flow_attributes.
#ifndef VMLS_MLS_GLSL
#define VMLS_MLS_GLSL

#define MLS_PACKED (MLS_TERMS * (MLS_TERMS + 1) / 2)
// Index of A[i][j], j <= i, in the packed lower triangle.
#define TRI(i, j) ((i) * ((i) + 1) / 2 + (j))

const float PIVOT_TOLERANCE = 1e-2;
const float QUADRATIC_PIVOT_TOLERANCE = 1e-2;
const float RHO_MIN = 1e-6;

struct MlsSystem {
    float a[MLS_PACKED];
    float r[MLS_TERMS];
    uint neighbours;
    bool exact;
    float exact_value;
    // Scale of the shifted basis, one per evaluation (y = (x_i − x) ⊙ inv_h).
    vec3 inv_h;
};

struct MlsResult {
    float value;
    vec3 gradient;
    uint neighbours;
    uint terms;
};

#if MLS_WEIGHT == 0
// The Wendland weight (1 − ρ²)⁴ and θ'(ρ)/ρ, clamped to 0 outside the support rather than
// branched, for loops over candidates that may lie outside it (mls_accumulate_all). The
// same values inside the support as mls_weight's, which keeps its branch and no clamp: the
// grid's rows measured 2-3% slower with this form there.
vec2 wendland_clamped(float rho2) {
    float q = max(1.0 - rho2, 0.0);
    float q3 = q * q * q;
    return vec2(q3 * q, -8.0 * q3);
}
#endif

// θ(ρ) and θ'(ρ)/ρ from ρ²; zero outside the support.
vec2 mls_weight(float rho2) {
    if (rho2 >= 1.0) {
        return vec2(0.0);
    }
#if MLS_WEIGHT == 0
    float q = 1.0 - rho2;
    float q3 = q * q * q;
    return vec2(q3 * q, -8.0 * q3);
#else
    float rho = sqrt(rho2);
    if (rho < RHO_MIN) {
        float lm = log(RHO_MIN);
        return vec2(lm * lm - RHO_MIN * RHO_MIN + 2.0 * RHO_MIN - 1.0, 0.0);
    }
    float l = log(rho);
    float theta = l * l - rho2 + 2.0 * rho - 1.0;
    float dtheta = 2.0 * l / rho - 2.0 * rho + 2.0;
    return vec2(max(theta, 0.0), dtheta / rho);
#endif
}

void mls_basis(vec3 y, out float b[MLS_TERMS]) {
    b[0] = 1.0;
#if MLS_TERMS >= 4
    b[1] = y.x;
    b[2] = y.y;
    b[3] = y.z;
#endif
#if MLS_TERMS >= 10
    b[4] = y.x * y.x;
    b[5] = y.y * y.y;
    b[6] = y.z * y.z;
    b[7] = y.x * y.y;
    b[8] = y.x * y.z;
    b[9] = y.y * y.z;
#endif
}

// Adds w·b bᵀ and w·f·b to the normal equations.
void mls_add(inout MlsSystem s, vec3 y, float w, float f) {
    float b[MLS_TERMS];
    mls_basis(y, b);
    [[unroll]] for (int i = 0; i < MLS_TERMS; ++i) {
        float wb = w * b[i];
        s.r[i] += wb * f;
        [[unroll]] for (int j = 0; j <= i; ++j) {
            s.a[TRI(i, j)] += wb * b[j];
        }
    }
}

#if MLS_WEIGHT == 0
// mls_accumulate for a loop over candidates that may lie outside the support (the octree's):
// no branch, the Wendland weight is 0 there, so outside candidates add zeros and the sums of
// those inside are mls_accumulate's to the bit. On llvmpipe both sides of a branch run and
// every statement after an early return is a masked write; without them octree frames took
// 6-11% less GPU time (BENCHMARKS.md, "Octree candidates without branches").
void mls_accumulate_all(inout MlsSystem s, vec3 y, float rho2, float f) {
    s.neighbours += rho2 < 1.0 ? 1u : 0u;
    mls_add(s, y, wendland_clamped(rho2).x, f);
}
#endif

void mls_accumulate(inout MlsSystem s, vec3 y, float rho2, float f) {
    float w = mls_weight(rho2).x;
    if (w <= 0.0) {
        return;
    }
#if MLS_WEIGHT == 1
    if (rho2 < RHO_MIN * RHO_MIN) {
        s.exact = true;
        s.exact_value = f;
    }
#endif
    s.neighbours += 1u;
    mls_add(s, y, w, f);
}

#if MLS_TERMS == 4
// The linear basis written out: llvmpipe leaves the generic version's nested loops rolled and
// its arrays in memory, which cost a third of an evaluation. Same arithmetic, same order.
uint mls_factor(inout float a[MLS_PACKED]) {
    float d0 = a[0];
    if (!(d0 > 0.0)) return 0u;
    float l10 = a[1] / d0, l20 = a[3] / d0, l30 = a[6] / d0;
    float d1 = a[2] - l10 * l10 * d0;
    if (!(d1 > PIVOT_TOLERANCE * a[2]) || !(a[2] > 0.0)) return 1u;
    float l21 = (a[4] - l20 * l10 * d0) / d1;
    float l31 = (a[7] - l30 * l10 * d0) / d1;
    float d2 = a[5] - l20 * l20 * d0 - l21 * l21 * d1;
    if (!(d2 > PIVOT_TOLERANCE * a[5]) || !(a[5] > 0.0)) return 1u;
    float l32 = (a[8] - l30 * l20 * d0 - l31 * l21 * d1) / d2;
    float d3 = a[9] - l30 * l30 * d0 - l31 * l31 * d1 - l32 * l32 * d2;
    if (!(d3 > PIVOT_TOLERANCE * a[9]) || !(a[9] > 0.0)) return 1u;
    a[0] = d0; a[1] = l10; a[2] = d1; a[3] = l20; a[4] = l21;
    a[5] = d2; a[6] = l30; a[7] = l31; a[8] = l32; a[9] = d3;
    return 4u;
}

void mls_solve(float l[MLS_PACKED], uint n, inout float c[MLS_TERMS]) {
    if (n < 4u) {
        // Constant fallback: only the first pivot (the original a[0]) is valid.
        c[0] = c[0] / l[0];
        c[1] = 0.0; c[2] = 0.0; c[3] = 0.0;
        return;
    }
    float z0 = c[0];
    float z1 = c[1] - l[1] * z0;
    float z2 = c[2] - l[3] * z0 - l[4] * z1;
    float z3 = c[3] - l[6] * z0 - l[7] * z1 - l[8] * z2;
    z0 /= l[0]; z1 /= l[2]; z2 /= l[5]; z3 /= l[9];
    z2 -= l[8] * z3;
    z1 -= l[4] * z2 + l[7] * z3;
    z0 -= l[1] * z1 + l[3] * z2 + l[6] * z3;
    c[0] = z0; c[1] = z1; c[2] = z2; c[3] = z3;
}
#else
// The quadratic basis's term indices as literals, for the calls below.
#define QUADRATIC_1_TO_9(F) F(1) F(2) F(3) F(4) F(5) F(6) F(7) F(8) F(9)
#define QUADRATIC_9_TO_0(F) F(9) F(8) F(7) F(6) F(5) F(4) F(3) F(2) F(1) F(0)

// Column k of the in-place LDLᵀ (mls_factor), skipped once a pivot failed. The factor and the
// solve call these with literal k, so that after inlining every loop has a constant trip count
// and is unrolled: a loop over k stayed rolled on llvmpipe, its arrays in memory, and a
// quadratic evaluation took twice as long (BENCHMARKS.md, "The quadratic basis's solve
// unrolled"). Same arithmetic in the same order.
void ldl_column(inout float a[MLS_PACKED], const int k, inout bool ok, inout uint sound) {
    if (ok) {
        float diag = a[TRI(k, k)];
        float d = diag;
        [[unroll]] for (int m = 0; m < k; ++m) {
            d -= a[TRI(k, m)] * a[TRI(k, m)] * a[TRI(m, m)];
        }
        float tolerance = k >= 4 ? QUADRATIC_PIVOT_TOLERANCE : PIVOT_TOLERANCE;
        if (!(d > tolerance * diag) || !(diag > 0.0)) {
            ok = false;
        } else {
            a[TRI(k, k)] = d;
            [[unroll]] for (int i = k + 1; i < MLS_TERMS; ++i) {
                float v = a[TRI(i, k)];
                [[unroll]] for (int m = 0; m < k; ++m) {
                    v -= a[TRI(i, m)] * a[TRI(k, m)] * a[TRI(m, m)];
                }
                a[TRI(i, k)] = v / d;
            }
            sound = uint(k + 1);
        }
    }
}

// In-place LDLᵀ without square roots; returns the determined leading terms (10, 4, 1 or 0).
uint mls_factor(inout float a[MLS_PACKED]) {
    uint sound = 0u;
    bool ok = true;
    ldl_column(a, 0, ok, sound);
#if MLS_TERMS >= 10
#define LDL_COLUMN(k) ldl_column(a, k, ok, sound);
    QUADRATIC_1_TO_9(LDL_COLUMN)
#endif
    if (sound >= 10u && MLS_TERMS >= 10) return 10u;
    if (sound >= 4u && MLS_TERMS >= 4) return 4u;
    return sound >= 1u ? 1u : 0u;
}

// Row i of L z = c (mls_solve), in place.
void solve_forward(float l[MLS_PACKED], const int i, inout float c[MLS_TERMS]) {
    [[unroll]] for (int m = 0; m < i; ++m) {
        c[i] -= l[TRI(i, m)] * c[m];
    }
}

// Row i of Lᵀ c = z (mls_solve), in place.
void solve_backward(float l[MLS_PACKED], const int i, inout float c[MLS_TERMS]) {
    [[unroll]] for (int m = i + 1; m < MLS_TERMS; ++m) {
        c[i] -= l[TRI(m, i)] * c[m];
    }
}

// Solves L D Lᵀ c = c for the leading n terms; the others become 0.
void mls_solve(float l[MLS_PACKED], uint n, inout float c[MLS_TERMS]) {
#if MLS_TERMS >= 10
#define SOLVE_FORWARD(i) solve_forward(l, i, c);
    QUADRATIC_1_TO_9(SOLVE_FORWARD)
#endif
    [[unroll]] for (int i = 0; i < MLS_TERMS; ++i) {
        c[i] = uint(i) < n ? c[i] / l[TRI(i, i)] : 0.0;
    }
#if MLS_TERMS >= 10
#define SOLVE_BACKWARD(i) solve_backward(l, i, c);
    QUADRATIC_9_TO_0(SOLVE_BACKWARD)
#endif
}
#endif

#endif
