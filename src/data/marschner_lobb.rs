//! The Marschner–Lobb test signal [ML], sampled exactly as the foundation issue specifies:
//! domain [-1,1]³, N samples per axis at x_i = −1 + 2i/(N−1),
//! ρ(x,y,z) = (1 − sin(πz/2) + α(1 + ρ_r(√(x²+y²)))) / (2(1+α)),
//! ρ_r(r) = cos(2π f_M cos(πr/2)), f_M = 6, α = 0.25.

use super::Volume;
use std::f64::consts::PI;

/// Modulation frequency f_M of [ML].
pub const F_M: f64 = 6.0;
/// Amplitude α of [ML].
pub const ALPHA: f64 = 0.25;

/// The analytic signal ρ at a point, in f64 (ground truth for accuracy against the true function).
pub fn rho(x: f64, y: f64, z: f64) -> f64 {
    let r = (x * x + y * y).sqrt();
    let rho_r = (2.0 * PI * F_M * (PI * r / 2.0).cos()).cos();
    (1.0 - (PI * z / 2.0).sin() + ALPHA * (1.0 + rho_r)) / (2.0 * (1.0 + ALPHA))
}

/// The analytic gradient ∇ρ at a point, in f64: ∂ρ/∂x = α/(2(1+α))·ρ_r'(r)·x/r (likewise y), with
/// ρ_r'(r) = 2π f_M · sin(2π f_M cos(πr/2)) · sin(πr/2) · π/2, which vanishes at r = 0; and
/// ∂ρ/∂z = −(π/2)·cos(πz/2)/(2(1+α)).
pub fn rho_gradient(x: f64, y: f64, z: f64) -> [f64; 3] {
    let r = (x * x + y * y).sqrt();
    let scale = 1.0 / (2.0 * (1.0 + ALPHA));
    let (dx, dy) = if r > 1e-12 {
        let d_rho_r = 2.0
            * PI
            * F_M
            * (2.0 * PI * F_M * (PI * r / 2.0).cos()).sin()
            * (PI * r / 2.0).sin()
            * (PI / 2.0);
        let radial = ALPHA * scale * d_rho_r / r;
        (radial * x, radial * y)
    } else {
        (0.0, 0.0)
    };
    [dx, dy, -(PI / 2.0) * (PI * z / 2.0).cos() * scale]
}

/// Samples ρ on an n³ grid over [-1,1]³ (n ≥ 2).
pub fn generate(n: usize) -> Volume {
    let n = n.max(2);
    let h = 2.0 / (n - 1) as f64;
    let mut values = Vec::with_capacity(n * n * n);
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let p = [
                    -1.0 + i as f64 * h,
                    -1.0 + j as f64 * h,
                    -1.0 + k as f64 * h,
                ];
                values.push(rho(p[0], p[1], p[2]) as f32);
            }
        }
    }
    Volume {
        dims: [n; 3],
        origin: [-1.0; 3],
        spacing: [h; 3],
        values: values.into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_and_corners() {
        let v = generate(41);
        let (lo, hi) = v.value_range();
        assert!(lo >= 0.0 && hi <= 1.0, "ML is in [0,1], got [{lo}, {hi}]");
        // At the origin: r = 0, cos(0)=1 → ρ_r = cos(12π) = 1 → (1 + 0.25·2)/2.5 = 0.6.
        let c = v.values.get(v.index(20, 20, 20));
        assert!((c - 0.6).abs() < 1e-6, "centre value {c}");
        assert_eq!(v.bounds(), ([-1.0; 3], [1.0; 3]));
    }

    #[test]
    fn gradient_matches_central_differences() {
        let e = 1e-6;
        for p in [
            [0.3, -0.2, 0.1],
            [0.0, 0.0, 0.5],
            [-0.7, 0.4, -0.9],
            [1e-9, 0.0, 0.0],
        ] {
            let g = rho_gradient(p[0], p[1], p[2]);
            for a in 0..3 {
                let (mut hi, mut lo) = (p, p);
                hi[a] += e;
                lo[a] -= e;
                let fd = (rho(hi[0], hi[1], hi[2]) - rho(lo[0], lo[1], lo[2])) / (2.0 * e);
                assert!(
                    (g[a] - fd).abs() < 1e-6 * (1.0 + fd.abs()),
                    "{p:?} axis {a}: {g:?} vs {fd}"
                );
            }
        }
    }
}
