//! MLS reconstruction, f64 CPU reference of `glsl/field/mls.glsl` ([MLS] §3).
//!
//! Stage names match the shader: `mls_weight`, `mls_basis`, `mls_accumulate`, `mls_factor`,
//! `mls_solve`, `mls_evaluate`.
//!
//! Contract of [`mls_evaluate`] at a point x:
//! - each sample has its own support, an ellipsoid with metric M_i: w_i = θ(ρ_i),
//!   ρ_i² = (x_i − x)ᵀ M_i (x_i − x) (isotropic: M_i = h_i⁻² I);
//! - local weighted least squares with the shifted basis `y_i = (x_i − x) ⊙ s`, scaled by one
//!   `s` per evaluation point ([`Neighbours::basis_scale`]) (constant: 1 term, linear: 4,
//!   quadratic: 10), so f(x) = c₀ and the local gradient is `(c₁, c₂, c₃) ⊙ s`;
//! - normal equations solved by LDLᵀ without square roots; a pivot `d_k ≤ PIVOT_TOLERANCE·A_kk`
//!   (`QUADRATIC_PIVOT_TOLERANCE` for second-order terms) means the samples do not determine that
//!   many terms, and the solve falls back to the largest
//!   lower-order basis whose pivots are all sound (quadratic → linear → constant). Because the
//!   bases are nested, that is the leading block of the same factorisation;
//! - `None` where no sample has weight (the field is undefined there), never NaN;
//! - the analytic gradient adds `[A⁻¹ Σ_i ∂w_i/∂x (f_i − b_iᵀc) b_i]₀` to the local one: the
//!   derivative of the MLS formula ([MLS] §3) with the basis frame fixed at x;
//! - interpolating weight: θ(ρ) = ln(ρ)² − ρ² + 2ρ − 1 is singular at ρ = 0, so ρ is clamped to
//!   `RHO_MIN` in the weight and its derivative, and a sample closer than `RHO_MIN` (in support
//!   units) is hit exactly: f(x) = f_i there.

// Index loops mirror the shader's packed-matrix code line for line; iterators would hide that.
#![allow(clippy::needless_range_loop)]

use crate::samples::{Metric, metric_apply, metric_rho2};

/// Largest number of basis terms (quadratic).
pub const MAX_TERMS: usize = 10;
/// Relative pivot `d_k / A_kk` below which a constant or linear term counts as undetermined.
/// At 1e-4 (until `vmls check`'s mls-singular case) scattered points with 4–5 neighbours near
/// the domain's edge passed the test with systems whose pivots compound: the f32 solve erred by
/// up to 5× the data range where the f64 twin reproduced the linear data exactly; at 1e-3 the
/// worst error was 3e-3 of the range, at 1e-2 it is 1e-5.
pub const PIVOT_TOLERANCE: f64 = 1e-2;
/// The same for the six second-order terms. A pivot of t amplifies rounding by about 1/t, and
/// f32 rounding (6e-8) at the 1e-4 level gave 7e-4 errors near grid boundaries, where the
/// quadratic system is nearly singular; at 1e-2 those points fall back to the linear basis.
pub const QUADRATIC_PIVOT_TOLERANCE: f64 = 1e-2;
/// Smallest distance (support units) used in the interpolating weight.
pub const RHO_MIN: f64 = 1e-6;

/// Polynomial basis of the local fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Basis {
    Constant,
    Linear,
    Quadratic,
}

impl Basis {
    /// Number of terms.
    pub fn terms(self) -> usize {
        match self {
            Basis::Constant => 1,
            Basis::Linear => 4,
            Basis::Quadratic => 10,
        }
    }
}

/// Weight function θ of the distance in support units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Weight {
    /// θ(ρ) = (1 − ρ²)⁴ (compact, C³).
    Wendland,
    /// θ(ρ) = ln(ρ)² − ρ² + 2ρ − 1 (interpolating, singular at 0).
    Interpolating,
}

/// Which gradient to return.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GradientMode {
    /// (c₁, c₂, c₃) of the local fit (zero for the constant basis).
    Local,
    /// Derivative of the MLS formula.
    Analytic,
}

/// Compile-time choices of an MLS variant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MlsSettings {
    pub basis: Basis,
    pub weight: Weight,
    pub gradient: GradientMode,
}

/// f, ∇f and diagnostics at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MlsValue {
    pub value: f64,
    pub gradient: [f64; 3],
    /// Samples with non-zero weight.
    pub neighbours: u32,
    /// Basis terms actually solved for (after any fallback).
    pub terms: u32,
}

/// The visitor of [`Neighbours::for_each`]: `(index, position, value, metric)`.
pub type Visit<'a> = dyn FnMut(usize, [f64; 3], f64, &Metric) + 'a;

/// Anything that can list the samples whose support may contain x. Samples with zero weight
/// may be listed; they are skipped.
pub trait Neighbours {
    /// Inverse scale per axis of the shifted basis at x: one for every sample of the
    /// evaluation ([MLS] §3 with per-sample supports), so the local gradient is exact whatever
    /// the samples' own supports. Any positive scale gives the same f in exact arithmetic; a
    /// scale near the supports keeps the system well conditioned in f32.
    fn basis_scale(&self, x: [f64; 3]) -> [f64; 3];
    /// `visit(index, position, value, metric)` (index into the sample set): the sample's weight is θ(ρ) with
    /// ρ² = (x_i − x)ᵀ M_i (x_i − x).
    fn for_each(&self, x: [f64; 3], visit: &mut Visit<'_>);
}

/// θ(ρ) and θ'(ρ)/ρ (the factor that turns ∂ρ into ∂w), for ρ < 1; zero outside.
pub fn mls_weight(weight: Weight, rho: f64) -> (f64, f64) {
    if rho >= 1.0 {
        return (0.0, 0.0);
    }
    match weight {
        Weight::Wendland => {
            let q = 1.0 - rho * rho;
            (q * q * q * q, -8.0 * q * q * q)
        }
        Weight::Interpolating => {
            if rho < RHO_MIN {
                // Clamped: the weight is constant inside the RHO_MIN ball.
                let l = RHO_MIN.ln();
                return (l * l - RHO_MIN * RHO_MIN + 2.0 * RHO_MIN - 1.0, 0.0);
            }
            let l = rho.ln();
            let theta = l * l - rho * rho + 2.0 * rho - 1.0;
            // θ'(ρ) = 2 ln ρ / ρ − 2ρ + 2.
            let dtheta = 2.0 * l / rho - 2.0 * rho + 2.0;
            (theta.max(0.0), dtheta / rho)
        }
    }
}

/// The shifted basis b(y) for the first `terms` terms.
pub fn mls_basis(y: [f64; 3], terms: usize) -> [f64; MAX_TERMS] {
    let mut b = [0.0; MAX_TERMS];
    b[0] = 1.0;
    if terms >= 4 {
        b[1] = y[0];
        b[2] = y[1];
        b[3] = y[2];
    }
    if terms >= 10 {
        b[4] = y[0] * y[0];
        b[5] = y[1] * y[1];
        b[6] = y[2] * y[2];
        b[7] = y[0] * y[1];
        b[8] = y[0] * y[2];
        b[9] = y[1] * y[2];
    }
    b
}

/// Normal equations being accumulated.
#[derive(Debug, Clone)]
pub struct MlsSystem {
    pub terms: usize,
    pub a: [[f64; MAX_TERMS]; MAX_TERMS],
    pub r: [f64; MAX_TERMS],
    pub neighbours: u32,
    /// Value of a sample hit exactly (interpolating weight only).
    pub exact: Option<f64>,
}

impl MlsSystem {
    fn new(terms: usize) -> Self {
        Self {
            terms,
            a: [[0.0; MAX_TERMS]; MAX_TERMS],
            r: [0.0; MAX_TERMS],
            neighbours: 0,
            exact: None,
        }
    }
}

/// Offset d = x_i − x, the basis argument y = d ⊙ s and ρ = √(dᵀ M d).
fn offset(x: [f64; 3], p: [f64; 3], scale: [f64; 3], m: &Metric) -> ([f64; 3], [f64; 3], f64) {
    let d = [p[0] - x[0], p[1] - x[1], p[2] - x[2]];
    let y = [d[0] * scale[0], d[1] * scale[1], d[2] * scale[2]];
    (d, y, metric_rho2(m, d).max(0.0).sqrt())
}

/// Adds one sample to the normal equations (lower triangle only, as in the shader).
pub fn mls_accumulate(sys: &mut MlsSystem, weight: Weight, y: [f64; 3], rho: f64, f: f64) {
    let (w, _) = mls_weight(weight, rho);
    if w <= 0.0 {
        return;
    }
    if weight == Weight::Interpolating && rho < RHO_MIN {
        sys.exact = Some(f);
    }
    sys.neighbours += 1;
    let b = mls_basis(y, sys.terms);
    for i in 0..sys.terms {
        let wb = w * b[i];
        sys.r[i] += wb * f;
        for j in 0..=i {
            sys.a[i][j] += wb * b[j];
        }
    }
}

/// In-place LDLᵀ of the lower triangle. Returns how many leading basis terms are determined:
/// 10, 4, 1, or 0 when even the constant term has no weight.
pub fn mls_factor(a: &mut [[f64; MAX_TERMS]; MAX_TERMS], terms: usize) -> usize {
    let mut sound = 0;
    for k in 0..terms {
        let diag = a[k][k];
        let mut d = diag;
        for m in 0..k {
            d -= a[k][m] * a[k][m] * a[m][m];
        }
        // Written so that NaN also fails the test.
        let tolerance = if k >= 4 {
            QUADRATIC_PIVOT_TOLERANCE
        } else {
            PIVOT_TOLERANCE
        };
        let sound_pivot = d > tolerance * diag && diag > 0.0;
        if !sound_pivot {
            break;
        }
        a[k][k] = d;
        for i in k + 1..terms {
            let mut v = a[i][k];
            for m in 0..k {
                v -= a[i][m] * a[k][m] * a[m][m];
            }
            a[i][k] = v / d;
        }
        sound = k + 1;
    }
    // Only whole bases are usable: the leading block of a lower-order basis.
    match sound {
        s if s >= 10 && terms >= 10 => 10,
        s if s >= 4 && terms >= 4 => 4,
        s if s >= 1 => 1,
        _ => 0,
    }
}

/// Solves L D Lᵀ c = rhs for the leading `n` terms of a factorised matrix.
pub fn mls_solve(
    l: &[[f64; MAX_TERMS]; MAX_TERMS],
    n: usize,
    rhs: [f64; MAX_TERMS],
) -> [f64; MAX_TERMS] {
    let mut c = rhs;
    for i in 0..n {
        for m in 0..i {
            c[i] -= l[i][m] * c[m];
        }
    }
    for i in 0..n {
        c[i] /= l[i][i];
    }
    for i in (0..n).rev() {
        for m in i + 1..n {
            c[i] -= l[m][i] * c[m];
        }
    }
    for v in c.iter_mut().skip(n) {
        *v = 0.0;
    }
    c
}

/// Evaluates the MLS reconstruction at x: `None` where no sample has weight.
pub fn mls_evaluate(
    settings: &MlsSettings,
    neighbours: &dyn Neighbours,
    x: [f64; 3],
) -> Option<MlsValue> {
    mls_evaluate_margin(settings, neighbours, x).map(|(v, _)| v)
}

/// [`mls_evaluate`] and the margin of its solve (twin of `g_margin` in
/// `glsl/field/neighbours.glsl`): the smallest pivot `d_k / A_kk` of the basis asked for, k ≥ 1,
/// where every pivot passed; 0 where the solve fell back to fewer terms, 1 for the constant
/// basis. A small margin means the samples barely determine the fit, as where a scattered set's
/// field extrapolates past its samples; the fast path solves such cells directly
/// ([`crate::recon::resample::DIRECT_MARGIN`]).
pub fn mls_evaluate_margin(
    settings: &MlsSettings,
    neighbours: &dyn Neighbours,
    x: [f64; 3],
) -> Option<(MlsValue, f64)> {
    let mut sys = MlsSystem::new(settings.basis.terms());
    let scale = neighbours.basis_scale(x);
    neighbours.for_each(x, &mut |_, p, f, m| {
        let (_, y, rho) = offset(x, p, scale, m);
        mls_accumulate(&mut sys, settings.weight, y, rho, f);
    });
    if sys.neighbours == 0 {
        return None;
    }
    let mut l = sys.a;
    let n = mls_factor(&mut l, sys.terms);
    if n == 0 {
        return None;
    }
    let margin = if n < sys.terms {
        0.0
    } else {
        (1..n).map(|k| l[k][k] / sys.a[k][k]).fold(1.0, f64::min)
    };
    let c = mls_solve(&l, n, sys.r);
    let mut gradient = if n >= 4 {
        [c[1] * scale[0], c[2] * scale[1], c[3] * scale[2]]
    } else {
        [0.0; 3]
    };
    if settings.gradient == GradientMode::Analytic {
        // q_k = Σ ∂w_i/∂x_k (f_i − b_iᵀc) b_i, with ∂ρ/∂x = −M_i d / ρ.
        let mut q = [[0.0; MAX_TERMS]; 3];
        neighbours.for_each(x, &mut |_, p, f, m| {
            let (d, y, rho) = offset(x, p, scale, m);
            let (w, dw_over_rho) = mls_weight(settings.weight, rho);
            if w <= 0.0 {
                return;
            }
            let md = metric_apply(m, d);
            let b = mls_basis(y, n);
            let fit: f64 = (0..n).map(|t| b[t] * c[t]).sum();
            let residual = f - fit;
            for k in 0..3 {
                let dw = -dw_over_rho * md[k];
                for t in 0..n {
                    q[k][t] += dw * residual * b[t];
                }
            }
        });
        for k in 0..3 {
            gradient[k] += mls_solve(&l, n, q[k])[0];
        }
    }
    Some((
        MlsValue {
            value: sys.exact.unwrap_or(c[0]),
            gradient,
            neighbours: sys.neighbours,
            terms: n as u32,
        },
        margin,
    ))
}
