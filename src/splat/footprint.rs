//! Stages `splat_profile`, `splat_column`, `splat_footprint` and `sheet_share`: f64 twins of
//! the footprint functions of `glsl/splat/splat.glsl`, which `splat_raster` evaluates per pixel
//! (the projection that prepares their words is `super::project`, whose module doc derives the
//! exact footprint).
//!
//! The exact footprint at pixel ray d′ = (dx, dy, 1) is made of three forms of d′: a′ = d′ᵀQd′,
//! b′ = d′ᵀQr and g = (r × d′)ᵀ adj(P) (r × d′), the Gram determinant that gives c − b′²/a′
//! without its cancellation. Down one column of pixels (dx fixed, dy = dy₀ + t) d′ and r × d′
//! are affine in t: `splat_column` takes what the rows share once per entry, and the kernel
//! evaluates each of an invocation's rows from it.

use super::SheetShare;
use super::SplatSetup;
use super::project::Splat;

/// erfc(x) for x ≥ 0 (Abramowitz & Stegun 7.1.26, |error| ≤ 1.5·10⁻⁷), the same polynomial as
/// the kernel's.
pub fn erfc_pos(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    poly * (-x * x).exp()
}

/// The normal distribution's mass beyond |z|: ½·erfc(|z|/√2).
pub fn normal_tail(z: f64) -> f64 {
    0.5 * erfc_pos(z.abs() * std::f64::consts::FRAC_1_SQRT_2)
}

/// Φ(zb) − Φ(za) for za ≤ zb from the tails qa, qb at its ends ([`normal_tail`]): each branch
/// subtracts tails, so that both keep their precision in f32.
pub fn phi_from_tails(za: f64, qa: f64, zb: f64, qb: f64) -> f64 {
    if za >= 0.0 {
        qa - qb
    } else if zb <= 0.0 {
        qb - qa
    } else {
        1.0 - qa - qb
    }
}

/// Φ(zb) − Φ(za) for za ≤ zb, through its two tails as the kernel computes it.
pub fn phi_between(za: f64, zb: f64) -> f64 {
    phi_from_tails(za, normal_tail(za), zb, normal_tail(zb))
}

/// (dx, dy) of pixel (x, y)'s ray d′ = (dx, dy, 1) in the camera frame (the kernel's
/// `pixel_view`).
pub fn pixel_ray(setup: &SplatSetup, x: f64, y: f64) -> (f64, f64) {
    (
        (x - setup.centre[0]) / setup.focal,
        (setup.centre[1] - y) / setup.focal,
    )
}

/// Q·d′ for d′ = (dx, dy, 1), Q's six entries in `Splat::precision`'s order.
fn precision_times(q: &[f64; 6], dx: f64, dy: f64) -> [f64; 3] {
    [
        q[0] * dx + q[1] * dy + q[3],
        q[1] * dx + q[2] * dy + q[4],
        q[3] * dx + q[4] * dy + q[5],
    ]
}

/// Stage `splat_profile`: the lateral part of a splat's footprint at pixel (x, y), `(A, m,
/// inv)` with A the whole line integral through the pixel, m the kernel's mean distance along
/// the pixel's ray and inv the inverse of its standard deviation there, so that the share in
/// t ∈ [ta, tb] is A·(Φ((tb − m)·inv) − Φ((ta − m)·inv)); `None` outside the cutoff. The affine
/// footprint (orthographic, where it is exact, or `splat.footprint = "affine"`), else the
/// integral along the pixel's own ray.
pub fn splat_profile(splat: &Splat, setup: &SplatSetup, x: f64, y: f64) -> Option<(f64, f64, f64)> {
    let cutoff = setup.settings.cutoff;
    if !setup.exact_footprints() {
        let dx = x - splat.centre[0];
        let dy = y - splat.centre[1];
        let q =
            splat.conic[0] * dx * dx + 2.0 * splat.conic[1] * dx * dy + splat.conic[2] * dy * dy;
        if q > cutoff * cutoff {
            return None;
        }
        let m = splat.depth + splat.slope[0] * dx + splat.slope[1] * dy;
        return Some((
            splat.amplitude * (-0.5 * q).exp(),
            m,
            1.0 / splat.depth_sigma,
        ));
    }
    let (dx, dy) = pixel_ray(setup, x, y);
    // a′ = d′ᵀQd′, b′ = d′ᵀQr with d′ = (dx, dy, 1).
    let qd = precision_times(&splat.precision, dx, dy);
    let a = dx * qd[0] + dy * qd[1] + qd[2];
    let r = &splat.eye_offset;
    let b = r[0] * qd[0] + r[1] * qd[1] + r[2] * qd[2];
    // c − b′²/a′ = (r × d′)ᵀ adj(P) (r × d′) / a′: the Gram determinant of r and d′ in the metric
    // P, free of the cancellation of c − b′²/a′ (both ≈ |r|²·|P| ≫ their difference).
    let w = [r[1] - r[2] * dy, r[2] * dx - r[0], r[0] * dy - r[1] * dx];
    let j = &splat.adjugate;
    let g = j[0] * w[0] * w[0]
        + j[2] * w[1] * w[1]
        + j[5] * w[2] * w[2]
        + 2.0 * (j[1] * w[0] * w[1] + j[3] * w[0] * w[2] + j[4] * w[1] * w[2]);
    lateral_profile(splat, setup, a, b, g, (1.0 + dx * dx + dy * dy).sqrt())
}

/// Stage `splat_footprint`: the share of a splat's line integral through pixel (x, y) that lies
/// in t ∈ [ta, tb] ([`splat_profile`] and the erfc); zero outside the cutoff.
pub fn splat_footprint(splat: &Splat, setup: &SplatSetup, x: f64, y: f64, ta: f64, tb: f64) -> f64 {
    splat_profile(splat, setup, x, y).map_or(0.0, |(a, m, inv)| {
        a * phi_between((ta - m) * inv, (tb - m) * inv)
    })
}

/// Stage `splat_column`: the exact footprint down the pixel column x, about the row whose
/// dy is `dy0` (twin of `splat_column` in `glsl/splat/splat.glsl`, which takes it at the middle
/// of an invocation's rows): with t = dy − dy₀, a′(t) = a₀ + t(a₁ + t·a₂), b′(t) = b₀ + t·b₁
/// and g(t) = g₀ + t(g₁ + t·g₂). Exact polynomials, not a Taylor approximation: d′ = (dx, dy₀ +
/// t, 1) and w = r × d′ = w₀ + t·(−r_z, 0, r_x) are affine in t. In f32 the coefficients g₁,
/// g₂ cancel a little, so e = g/a errs about three times the direct Gram form
/// (tests/splat_footprint.rs measures both, and the naive c − b′²/a′ the Gram form replaces).
/// Only for exact footprints.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Column {
    /// a₀, a₁, a₂.
    pub a: [f64; 3],
    /// b₀, b₁.
    pub b: [f64; 2],
    /// g₀, g₁, g₂.
    pub g: [f64; 3],
    /// dy about which the column is taken.
    pub dy0: f64,
}

/// [`Column`] of `splat` down pixel column `x`, about the (possibly fractional) row `y0`.
pub fn splat_column(splat: &Splat, setup: &SplatSetup, x: f64, y0: f64) -> Column {
    let (dx, dy) = pixel_ray(setup, x, y0);
    let q = &splat.precision;
    let qd = precision_times(q, dx, dy);
    let r = &splat.eye_offset;
    let j = &splat.adjugate;
    let w = [r[1] - r[2] * dy, r[2] * dx - r[0], r[0] * dy - r[1] * dx];
    // adj(P)·w, and adj(P)·w₁ for w₁ = dw/dt = (−r_z, 0, r_x).
    let pw = [
        j[0] * w[0] + j[1] * w[1] + j[3] * w[2],
        j[1] * w[0] + j[2] * w[1] + j[4] * w[2],
        j[3] * w[0] + j[4] * w[1] + j[5] * w[2],
    ];
    let pw1 = [
        j[3] * r[0] - j[0] * r[2],
        j[4] * r[0] - j[1] * r[2],
        j[5] * r[0] - j[3] * r[2],
    ];
    let dot = |u: &[f64; 3], v: &[f64; 3]| u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    Column {
        a: [dx * qd[0] + dy * qd[1] + qd[2], 2.0 * qd[1], q[2]],
        b: [dot(r, &qd), r[0] * q[1] + r[1] * q[2] + r[2] * q[4]],
        g: [
            dot(&w, &pw),
            2.0 * dot(&w, &pw1),
            r[0] * pw1[2] - r[2] * pw1[0],
        ],
        dy0: dy,
    }
}

/// [`splat_profile`] at pixel (x, y) of the column `column` was taken for, through it (the
/// kernel's `splat_profile_at` where an invocation draws several rows).
pub fn splat_profile_column(
    splat: &Splat,
    setup: &SplatSetup,
    column: &Column,
    x: f64,
    y: f64,
) -> Option<(f64, f64, f64)> {
    let (dx, dy) = pixel_ray(setup, x, y);
    let t = dy - column.dy0;
    let [a0, a1, a2] = column.a;
    let [g0, g1, g2] = column.g;
    let a = a0 + t * (a1 + t * a2);
    let b = column.b[0] + t * column.b[1];
    let g = g0 + t * (g1 + t * g2);
    lateral_profile(splat, setup, a, b, g, (1.0 + dx * dx + dy * dy).sqrt())
}

/// The profile from the three forms at a pixel whose d′ has length `len` (twin of the kernel's
/// `lateral_profile`).
fn lateral_profile(
    splat: &Splat,
    setup: &SplatSetup,
    a: f64,
    b: f64,
    g: f64,
    len: f64,
) -> Option<(f64, f64, f64)> {
    let cutoff = setup.settings.cutoff;
    if a <= 0.0 || a.is_nan() {
        return None;
    }
    let e = g / a;
    if e > cutoff * cutoff {
        return None;
    }
    let inv_sqrt_a = 1.0 / a.sqrt();
    Some((
        splat.ray_amplitude * len * inv_sqrt_a * (-0.5 * e).exp(),
        -b * len / a,
        1.0 / (len * inv_sqrt_a),
    ))
}

/// Stage `sheet_share`: Φ(zb) − Φ(za), the share of a kernel's line integral between two sheet
/// boundaries in units of its deviation along the ray, by `rule`. The quadrature is the
/// Hermite–Simpson rule with φ′ = −zφ: for h = zb − za,
/// h/30·(7φ(za) + 16φ(zm) + 7φ(zb)) + h²/60·(zb·φ(zb) − za·φ(za)), exact for quintics; its
/// error is at most 1.5·10⁻⁴ for h ≤ 1.5 ([`super::QUADRATURE_MAX_SHEET`]). The midpoint rule is
/// h·φ(zm). The kernel computes the φ by a recurrence; here each is direct.
pub fn sheet_share(rule: SheetShare, za: f64, zb: f64) -> f64 {
    match rule {
        SheetShare::Erfc => phi_between(za, zb),
        SheetShare::Quadrature => {
            let phi = |z: f64| (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt();
            let h = zb - za;
            let (pa, pm, pb) = (phi(za), phi(0.5 * (za + zb)), phi(zb));
            h / 30.0 * (7.0 * (pa + pb) + 16.0 * pm) + h * h / 60.0 * (zb * pb - za * pa)
        }
        SheetShare::Midpoint => {
            (zb - za) * (-0.125 * (za + zb) * (za + zb)).exp() / (2.0 * std::f64::consts::PI).sqrt()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{erfc_pos, phi_between};

    /// erfc(x) = 2/√π ∫ₓ^∞ e^{−t²} dt by composite Simpson on [x, x + 9] (the rest is below
    /// e^{−81}), 20 000 intervals: about 1e-13, independent of the A&S polynomial.
    fn erfc_simpson(x: f64) -> f64 {
        let (n, span) = (20_000, 9.0);
        let h = span / n as f64;
        let f = |t: f64| (-t * t).exp();
        let inner: f64 = (1..n)
            .map(|i| f(x + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 })
            .sum();
        (f(x) + inner + f(x + span)) * h / 3.0 * 2.0 / std::f64::consts::PI.sqrt()
    }

    #[test]
    fn erfc_pos_stays_within_its_published_bound_of_an_independent_integral() {
        // Abramowitz & Stegun 7.1.26: |ε(x)| ≤ 1.5e-7 for x ≥ 0.
        let mut worst = 0.0f64;
        for i in 0..=600 {
            let x = i as f64 * 0.01;
            worst = worst.max((erfc_pos(x) - erfc_simpson(x)).abs());
        }
        assert!(worst <= 1.5e-7, "largest error {worst:.2e}");
        assert!(worst > 1e-9, "the polynomial is not exact: {worst:.2e}");
    }

    #[test]
    fn phi_between_is_the_normal_mass_between_its_bounds() {
        // Φ(b) − Φ(a) = (erfc(−b/√2) − erfc(−a/√2)) / 2, with erfc(−y) = 2 − erfc(y).
        let erfc = |y: f64| {
            if y >= 0.0 {
                erfc_simpson(y)
            } else {
                2.0 - erfc_simpson(-y)
            }
        };
        let k = std::f64::consts::FRAC_1_SQRT_2;
        for (a, b) in [
            (-3.0, -1.0),
            (-0.5, 0.7),
            (0.2, 2.5),
            (-6.0, 6.0),
            (1.0, 1.0),
        ] {
            let exact = 0.5 * (erfc(-b * k) - erfc(-a * k));
            let got = phi_between(a, b);
            assert!(
                (got - exact).abs() <= 1.5e-7,
                "[{a}, {b}]: {got} vs {exact}"
            );
        }
    }
}
