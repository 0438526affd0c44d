//! Stage `splat_project`: f64 twin of `glsl/splat/splat_project.comp` ([EWA] §4–6).
//!
//! For a kernel at p with object-space covariance V″ = σ²M⁻¹ and weight w:
//! - viewing transform u = W(p − eye), W's rows right, up, forward;
//! - ray space x = (pixel x, pixel y, t) with t the distance along the ray (‖u‖ perspective,
//!   u₂ orthographic); its Jacobian at u (lateral terms at u₀/u₂, u₁/u₂ clamped to
//!   `LATERAL_CLAMP` × the half-angle tangent), A = J·W, V = A V″ Aᵀ ([EWA] §4.2, Eq. 30);
//! - footprint: V̂ = V without its third row and column, so the line integral of the kernel
//!   through pixel x̂ is `w·|det A|·G_V̂(x̂ − x̂_c)` ([EWA] §4.3: the normalisation is
//!   1/(|J⁻¹||W⁻¹|)); the resampling filter adds the low-pass variance ([EWA] §5, Eq. 36);
//! - depth: given x̂, t is Gaussian with mean t_c + bᵀ(x̂ − x̂_c), b = V̂⁻¹V_x̂t, and variance
//!   s² = V_tt − V_x̂tᵀV̂⁻¹V_x̂t (the conditional of the ray-space Gaussian); a sheet's share of
//!   the footprint is Φ((t_b − m)/s) − Φ((t_a − m)/s), which slices the kernel exactly instead
//!   of [BLUR]'s pre-integrated kernel sections;
//! - the bounding box and the sheet range cover the affine cutoff ellipse exactly: the conditional
//!   mean varies by at most cutoff·√(bᵀV̂_f b) over it, plus cutoff·s.
//!
//! Perspective-exact footprints: the affine footprint above errs by up to ~6·10⁻³ of its peak for
//! a 16:1 needle at a few hundred pixels (tests/splat_footprint.rs), so for a perspective camera the
//! footprint is evaluated per pixel as the exact integral of the kernel along that pixel's ray:
//! with unit direction d, a = dᵀPd, b = dᵀP(eye − p), c = (eye − p)ᵀP(eye − p),
//! ∫ w·G(eye + t d − p) dt = w·√det P/(2π)^{3/2} · √(2π/a) · e^{−(c − b²/a)/2}, and t given the
//! ray is Gaussian with mean −b/a and standard deviation 1/√a. With d′ = (dx, dy, 1) the
//! unnormalised camera-frame direction, a′ = d′ᵀQd′ and b′ = d′ᵀQr are a quadratic and a linear
//! polynomial in the pixel, and a = a′/|d′|², b = b′/|d′| — no more work per pixel than the
//! conic. The resampling filter is then applied in object space: the screen low-pass diag(L, L, 0)
//! pulled back through A, V″_f = V″ + A⁻¹diag(L, L, 0)A⁻ᵀ, which is [EWA]'s V̂ + L·I wherever the
//! affine map holds; SWAN scales V″ uniformly. The rays within the cutoff form a cone whose
//! section by the image plane is an exact ellipse ([`cutoff_conic`]): it gives the bounding box;
//! the affine V gives the sheet range, widened by 10% for the difference.
//!
//! Guards where 3D-Gaussian-splatting renderers break: kernels reaching the near plane (or
//! behind the eye) are culled; a footprint variance below `MIN_VARIANCE` px² is raised to it;
//! det ≤ 0 or any non-finite intermediate culls the kernel as degenerate.

use super::{Antialias, MIN_VARIANCE, Shading, SplatCounts, SplatSetup};
use crate::samples::Metric;
use crate::samples::supports::largest_eigenvalue_bound;
use crate::view::shading::shade_cos;
use crate::view::transfer::TransferFunction;
use glam::DVec3;

/// Tangential over normal standard deviation of a surface kernel.
pub const FLATNESS: f64 = 10.0;

/// What a kernel is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum KernelKind {
    /// A sample of the volume.
    Volume,
    /// A surface splat of isosurface `iso`; its metric is `scale`·(I + (R² − 1)nnᵀ).
    Surface { iso: u32, scale: f64 },
}

/// (n·d)² of a surface kernel's metric along unit direction d.
pub fn normal_cos2(metric: &crate::samples::Metric, scale: f64, d: [f64; 3]) -> f64 {
    let rho2 = crate::samples::metric_rho2(metric, d);
    ((rho2 / scale - 1.0) / (FLATNESS * FLATNESS - 1.0)).clamp(0.0, 1.0)
}

/// A kernel as `splat_project` reads it (frame-relative position).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kernel {
    pub position: [f64; 3],
    pub value: f64,
    pub metric: Metric,
    /// The volume it stands for (`KernelVolumes`); a surface splat's area.
    pub volume: f64,
    pub kind: KernelKind,
}

/// A projected kernel (twin of the GLSL `Splat`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Splat {
    /// Pixel coordinates of the centre.
    pub centre: [f64; 2],
    /// Conic (V̂_f⁻¹): xx, xy, yy.
    pub conic: [f64; 3],
    /// w·|det A| / (2π √det V̂_f): the footprint's peak.
    pub amplitude: f64,
    /// t at the centre, and the depth slope b.
    pub depth: f64,
    pub slope: [f64; 2],
    /// Conditional standard deviation s of t.
    pub depth_sigma: f64,
    /// Perspective: the filtered kernel's precision P = V″_f⁻¹ in the camera frame (Q: xx, xy,
    /// yy, xz, yz, zz), its adjugate det(P)·V″_f (same order), the eye relative to the kernel
    /// r (camera frame) and w·√det P / (2π): the per-pixel ray integral
    /// ([`super::footprint::splat_footprint`]).
    pub precision: [f64; 6],
    pub adjugate: [f64; 6],
    pub eye_offset: [f64; 3],
    pub ray_amplitude: f64,
    /// Emitted colour (pre-shaded); a surface splat's shaded, premultiplied colour.
    pub color: [f64; 3],
    /// A surface splat's isosurface opacity; 0 for volume kernels.
    pub opacity: f64,
    /// Inclusive pixel box x0, y0, x1, y1.
    pub bbox: [i32; 4],
    /// Inclusive sheet range.
    pub slabs: [u32; 2],
}

/// Why a kernel was not splatted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cull {
    Near,
    Outside,
    Degenerate,
    Empty,
    /// More binned entries than one invocation may write (`MAX_KERNEL_ENTRIES`): an error.
    Oversized,
}

impl Cull {
    /// Counts the cull in `counts`.
    pub fn count(self, counts: &mut SplatCounts) {
        match self {
            Cull::Near => counts.culled_near += 1,
            Cull::Outside => counts.culled_outside += 1,
            Cull::Degenerate => counts.culled_degenerate += 1,
            Cull::Empty => counts.culled_empty += 1,
            Cull::Oversized => counts.oversized += 1,
        }
    }
}

/// M⁻¹ of a symmetric metric as a row-major 3×3 matrix; `None` unless M is positive definite
/// and finite.
pub fn metric_inverse(m: &Metric) -> Option<[[f64; 3]; 3]> {
    let det = crate::recon::gaussian::metric_det(m);
    if det <= 0.0 || !det.is_finite() || m[0] <= 0.0 || m[0] * m[1] - m[3] * m[3] <= 0.0 {
        return None;
    }
    let v = crate::samples::supports::inverse(m);
    Some([[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]])
}

fn mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut r = [[0.0; 3]; 3];
    for (i, row) in r.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    r
}

fn transpose(a: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = a[j][i];
        }
    }
    r
}

fn add(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut r = *a;
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] += b[i][j];
        }
    }
    r
}

/// Inverse of a 3×3 matrix; `None` when singular or not finite.
fn inverse(a: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let det = det3(a);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    // Cofactors with cyclic indices carry their sign; the inverse is the transposed cofactor
    // matrix over det.
    let c = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]
    };
    let mut r = [[0.0; 3]; 3];
    for (i, row) in r.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = c(j, i) / det;
        }
    }
    Some(r)
}

fn det3(a: &[[f64; 3]; 3]) -> f64 {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

/// The ray-space map at u: the pixel centre, t, and A = J·W.
pub fn ray_space(setup: &SplatSetup, u: DVec3) -> ([f64; 2], f64, [[f64; 3]; 3]) {
    let f = setup.focal;
    let b = &setup.basis;
    let w = [b.right.to_array(), b.up.to_array(), b.forward.to_array()];
    let (centre, t, j) = if setup.orthographic() {
        (
            [setup.centre[0] + f * u.x, setup.centre[1] - f * u.y],
            u.z,
            [[f, 0.0, 0.0], [0.0, -f, 0.0], [0.0, 0.0, 1.0]],
        )
    } else {
        let l = u.length();
        let inv = 1.0 / u.z;
        let cx = (u.x * inv).clamp(-setup.lateral[0], setup.lateral[0]);
        let cy = (u.y * inv).clamp(-setup.lateral[1], setup.lateral[1]);
        (
            [
                setup.centre[0] + f * u.x * inv,
                setup.centre[1] - f * u.y * inv,
            ],
            l,
            [
                [f * inv, 0.0, -f * cx * inv],
                [0.0, -f * inv, f * cy * inv],
                [u.x / l, u.y / l, u.z / l],
            ],
        )
    };
    (centre, t, mul(&j, &w))
}

/// The footprint variance after `splat.antialias`, and the screen low-pass it added: EWA and
/// auto add theirs ([`screen_lowpass`]), SWAN scales the variance uniformly so its smaller
/// eigenvalue reaches the low-pass, none leaves it (both add none).
pub fn filtered(v: [f64; 3], antialias: Antialias, lowpass: f64) -> ([f64; 3], [f64; 3]) {
    let v = [v[0].max(MIN_VARIANCE), v[1], v[2].max(MIN_VARIANCE)];
    let d = screen_lowpass(v, antialias, lowpass);
    let vf = match antialias {
        Antialias::Ewa | Antialias::Auto | Antialias::None => {
            [v[0] + d[0], v[1] + d[1], v[2] + d[2]]
        }
        Antialias::Swan => {
            let (mean, r) = mean_and_radius(v);
            let minor = (mean - r).max(MIN_VARIANCE);
            let k = (lowpass / minor).max(1.0);
            [v[0] * k, v[1] * k, v[2] * k]
        }
    };
    (vf, d)
}

/// The screen-space variance (xx, xy, yy, px²) that `splat.antialias` adds to the 2×2
/// footprint variance `v`: [EWA]'s resampling filter adds the low-pass `lowpass · I`; auto
/// adds `Σ max(lowpass − λ_i, 0) e_i e_iᵀ` over v's eigenpairs, so that v + Δ has the
/// eigenvalues max(λ_i, lowpass). With λ₁ ≥ λ₂, d_i = max(lowpass − λ_i, 0) and the
/// projector P₁ = (v − λ₂ I)/(λ₁ − λ₂): Δ = d₂ I + (d₁ − d₂) P₁, where (d₁ − d₂)/(λ₁ − λ₂)
/// lies in [−1, 0] and the P₁ term vanishes with λ₁ = λ₂. SWAN and none add nothing.
pub fn screen_lowpass(v: [f64; 3], antialias: Antialias, lowpass: f64) -> [f64; 3] {
    match antialias {
        Antialias::Ewa => [lowpass, 0.0, lowpass],
        Antialias::Auto => {
            let (mean, r) = mean_and_radius(v);
            let (l1, l2) = (mean + r, mean - r);
            let (d1, d2) = ((lowpass - l1).max(0.0), (lowpass - l2).max(0.0));
            let g = if r > 0.0 { (d1 - d2) / (2.0 * r) } else { 0.0 };
            [d2 + g * (v[0] - l2), g * v[1], d2 + g * (v[2] - l2)]
        }
        Antialias::Swan | Antialias::None => [0.0; 3],
    }
}

/// The symmetric 2×2 (xx, xy, yy)'s eigenvalues as mean ± radius.
fn mean_and_radius(v: [f64; 3]) -> (f64, f64) {
    let mean = 0.5 * (v[0] + v[2]);
    (
        mean,
        (0.25 * (v[0] - v[2]) * (v[0] - v[2]) + v[1] * v[1]).sqrt(),
    )
}

/// The per-pixel ray integral's constants (`Splat::precision` … `ray_amplitude`) and a
/// rigorous depth reach: the filtered kernel's cutoff ellipsoid lies within
/// cutoff·√λ_max(V″_f) of its centre, λ_max bounded by the largest Gershgorin row sum.
struct Exact {
    precision: [f64; 6],
    adjugate: [f64; 6],
    eye_offset: [f64; 3],
    ray_amplitude: f64,
    reach: f64,
}

fn exact_footprint(
    setup: &SplatSetup,
    a: &[[f64; 3]; 3],
    v_obj: &[[f64; 3]; 3],
    vhat: [f64; 3],
    (vf, d): ([f64; 3], [f64; 3]),
    u: DVec3,
    weight: f64,
) -> Option<Exact> {
    // The object-space filtered covariance: the screen low-pass d ([EWA]'s, or auto's) pulled
    // back through A.
    let v_f = match setup.settings.antialias {
        Antialias::Ewa | Antialias::Auto => {
            let ai = inverse(a)?;
            let mut lp = [[0.0; 3]; 3];
            for (i, row) in lp.iter_mut().enumerate() {
                for (j, x) in row.iter_mut().enumerate() {
                    *x = ai[i][0] * (d[0] * ai[j][0] + d[1] * ai[j][1])
                        + ai[i][1] * (d[1] * ai[j][0] + d[2] * ai[j][1]);
                }
            }
            add(v_obj, &lp)
        }
        Antialias::Swan => {
            let k = vf[0] / vhat[0].max(MIN_VARIANCE);
            v_obj.map(|r| r.map(|x| x * k))
        }
        Antialias::None => *v_obj,
    };
    let p_obj = inverse(&v_f)?;
    let det_p = det3(&p_obj);
    if det_p <= 0.0 || !det_p.is_finite() {
        return None;
    }
    let b = &setup.basis;
    let e = [b.right, b.up, b.forward].map(|v| v.to_array());
    let frame = |m: &[[f64; 3]; 3], i: usize, j: usize| -> f64 {
        (0..3)
            .map(|k| (0..3).map(|l| e[i][k] * m[k][l] * e[j][l]).sum::<f64>())
            .sum()
    };
    let sym = |m: &[[f64; 3]; 3], s: f64| {
        [(0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)].map(|(i, j)| s * frame(m, i, j))
    };
    let gershgorin = v_f
        .iter()
        .map(|r| r.iter().map(|x| x.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let out = Exact {
        precision: sym(&p_obj, 1.0),
        adjugate: sym(&v_f, det_p),
        eye_offset: [-u.x, -u.y, -u.z],
        ray_amplitude: weight * det_p.sqrt() / (2.0 * std::f64::consts::PI),
        reach: setup.settings.cutoff * gershgorin.sqrt(),
    };
    let finite = out
        .precision
        .iter()
        .chain(&out.adjugate)
        .chain(&[out.ray_amplitude, out.reach])
        .all(|x| x.is_finite());
    finite.then_some(out)
}

/// Whether some ray through the kernel may see a deviation below `dev`: the affine footprint's
/// one along every ray (√cond), or, for exact footprints, a lower bound over all directions
/// (the filtered variance is at least σ²/λ_max(M), bounded by Gershgorin).
fn thinner_than(setup: &SplatSetup, kernel: &Kernel, exact: bool, cond: f64, dev: f64) -> bool {
    let variance = if exact {
        setup.sigma * setup.sigma / largest_eigenvalue_bound(&kernel.metric)
    } else {
        cond
    };
    variance < dev * dev
}

/// Projects one kernel; `Err` says why it is culled.
pub fn splat_project(
    setup: &SplatSetup,
    tf: &TransferFunction,
    kernel: &Kernel,
) -> Result<Splat, Cull> {
    let (weight, color, opacity) = match (kernel.kind, setup.shading) {
        (KernelKind::Surface { iso, scale }, _) => {
            let Some(iso) = setup.isosurfaces.get(iso as usize) else {
                return Err(Cull::Empty);
            };
            let view = if setup.orthographic() {
                setup.basis.forward
            } else {
                (DVec3::from(kernel.position) - setup.eye).normalize_or_zero()
            };
            let cos = normal_cos2(&kernel.metric, scale, view.to_array()).sqrt();
            let rgb = shade_cos(iso, &setup.lighting, cos);
            (kernel.volume * cos, rgb, iso.opacity)
        }
        (KernelKind::Volume, Shading::Post) => (kernel.value * kernel.volume, [0.0; 3], 0.0),
        (KernelKind::Volume, Shading::Pre) => {
            let (c, tau) = tf.lookup(kernel.value);
            (tau * kernel.volume, c, 0.0)
        }
    };
    if weight == 0.0 {
        return Err(Cull::Empty);
    }
    let Some(minv) = metric_inverse(&kernel.metric) else {
        return Err(Cull::Degenerate);
    };
    let s2 = setup.sigma * setup.sigma;
    let v_obj = minv.map(|r| r.map(|x| x * s2));
    let b = &setup.basis;
    let d = DVec3::from(kernel.position) - setup.eye;
    let u = DVec3::new(d.dot(b.right), d.dot(b.up), d.dot(b.forward));
    // Depth reach of the kernel along the view axis (camera-space variance of u₂).
    let fwd = b.forward.to_array();
    let var_fwd: f64 = (0..3)
        .map(|i| (0..3).map(|j| fwd[i] * v_obj[i][j] * fwd[j]).sum::<f64>())
        .sum();
    let reach = setup.settings.cutoff * var_fwd.max(0.0).sqrt();
    if u.z - reach <= setup.near {
        return Err(Cull::Near);
    }
    let (centre, t, a) = ray_space(setup, u);
    let v = mul(&mul(&a, &v_obj), &transpose(&a));
    let vhat = [v[0][0], v[0][1], v[1][1]];
    let vxt = [v[0][2], v[1][2]];
    let vtt = v[2][2];
    let det_hat = vhat[0] * vhat[2] - vhat[1] * vhat[1];
    let (vf, lowpass_added) = filtered(vhat, setup.settings.antialias, setup.settings.lowpass);
    let det_f = vf[0] * vf[2] - vf[1] * vf[1];
    if det_hat <= 0.0 || det_f <= 0.0 || !det_f.is_finite() {
        return Err(Cull::Degenerate);
    }
    let slope = [
        (vhat[2] * vxt[0] - vhat[1] * vxt[1]) / det_hat,
        (vhat[0] * vxt[1] - vhat[1] * vxt[0]) / det_hat,
    ];
    let exact = setup.exact_footprints().then(|| {
        exact_footprint(setup, &a, &v_obj, vhat, (vf, lowpass_added), u, weight)
            .ok_or(Cull::Degenerate)
    });
    let exact = exact.transpose()?;
    let cond = (vtt - slope[0] * vxt[0] - slope[1] * vxt[1]).max(1e-12 * vtt);
    let amplitude = weight * det3(&a).abs() / (2.0 * std::f64::consts::PI * det_f.sqrt());
    let conic = [vf[2] / det_f, -vf[1] / det_f, vf[0] / det_f];
    let cut = setup.settings.cutoff;
    let (w, h) = (setup.camera.width as i32, setup.camera.height as i32);
    // The pixel-space box of the cutoff region: the affine ellipse, or the exact conic of rays
    // within `cutoff` of the centre (`cutoff_conic`).
    let (bx, by, rx, ry) = match &exact {
        None => (centre[0], centre[1], cut * vf[0].sqrt(), cut * vf[2].sqrt()),
        Some(x) => cutoff_conic(setup, &x.precision, &x.adjugate, x.eye_offset, cut)
            .ok_or(Cull::Degenerate)?,
    };
    // Within the frame's window (a brick's: the pixels and sheets it can own).
    let ([wx0, wy0, wx1, wy1], [k0, k1]) = setup.window;
    let bbox = [
        (((bx - rx).ceil().max(0.0).min(f64::from(w))) as i32).max(wx0),
        (((by - ry).ceil().max(0.0).min(f64::from(h))) as i32).max(wy0),
        (((bx + rx).floor().min(f64::from(w - 1)).max(-1.0)) as i32).min(wx1),
        (((by + ry).floor().min(f64::from(h - 1)).max(-1.0)) as i32).min(wy1),
    ];
    let spread = slope[0] * (vf[0] * slope[0] + vf[1] * slope[1])
        + slope[1] * (vf[1] * slope[0] + vf[2] * slope[1]);
    let affine_reach = cut * (spread.max(0.0).sqrt() + cond.sqrt());
    // Exact footprints: the affine reach does not bound off-centre rays near the eye; the
    // kernel's cutoff ellipsoid does.
    let depth_reach = exact
        .as_ref()
        .map_or(affine_reach, |x| affine_reach.max(x.reach));
    // A kernel the quadrature widens (SplatSetup::share_deviation) reaches that much further
    // along a ray: where a ray through it may be thinner than the widened deviation (its
    // affine deviation √cond, else at least σ × the support's shortest half axis).
    let depth_reach = match setup.share_deviation() {
        Some(dev) if thinner_than(setup, kernel, exact.is_some(), cond, dev) => {
            depth_reach + cut * dev
        }
        _ => depth_reach,
    };
    let first = ((t - depth_reach - setup.slab0) / setup.slab_world)
        .floor()
        .max(f64::from(k0));
    let last = ((t + depth_reach - setup.slab0) / setup.slab_world)
        .floor()
        .min(f64::from(k1));
    let values = [
        amplitude, conic[0], conic[1], conic[2], slope[0], slope[1], t, cond,
    ];
    if values.iter().any(|x| !x.is_finite()) {
        return Err(Cull::Degenerate);
    }
    if bbox[0] > bbox[2]
        || bbox[1] > bbox[3]
        || last < 0.0
        || first >= f64::from(setup.slabs)
        || first > last
    {
        return Err(Cull::Outside);
    }
    let slabs = if setup.split {
        [
            first.max(0.0) as u32,
            last.min(f64::from(setup.slabs - 1)) as u32,
        ]
    } else {
        // Whole kernels go to the sheet of their centre.
        let k = ((t - setup.slab0) / setup.slab_world)
            .floor()
            .clamp(0.0, f64::from(setup.slabs - 1)) as u32;
        if k < k0 || k > k1 {
            return Err(Cull::Outside);
        }
        [k, k]
    };
    let r = setup.tile_rect(bbox);
    let tiles = u64::from(r[2] - r[0] + 1) * u64::from(r[3] - r[1] + 1);
    let span = slabs[1] - slabs[0] + 1;
    // With ring registers a kernel is one entry per tile and per `ring` sheets.
    let entries = if setup.ring > 0 {
        u64::from(span.div_ceil(setup.ring)) * tiles
    } else {
        u64::from(span) * tiles
    };
    if entries > super::MAX_KERNEL_ENTRIES {
        return Err(Cull::Oversized);
    }
    let x = exact.unwrap_or(Exact {
        precision: [0.0; 6],
        adjugate: [0.0; 6],
        eye_offset: [0.0; 3],
        ray_amplitude: 0.0,
        reach: 0.0,
    });
    Ok(Splat {
        centre,
        conic,
        amplitude,
        depth: t,
        slope,
        depth_sigma: cond.sqrt(),
        precision: x.precision,
        adjugate: x.adjugate,
        eye_offset: x.eye_offset,
        ray_amplitude: x.ray_amplitude,
        color,
        opacity,
        bbox,
        slabs,
    })
}

/// The rays through d′ = (dx, dy, 1) whose Mahalanobis distance to the kernel centre is at most
/// `cut` satisfy d′ᵀ(K − cut²·Q)d′ ≤ 0 with K = [r]ₓᵀ adj(P) [r]ₓ (the numerator of
/// [`super::footprint::splat_footprint`]'s e): an ellipse in the image plane while the kernel
/// lies in front of the eye. Returns its centre and half extents in pixels; `None` when it is
/// not an ellipse.
pub fn cutoff_conic(
    setup: &SplatSetup,
    q: &[f64; 6],
    j: &[f64; 6],
    r: [f64; 3],
    cut: f64,
) -> Option<(f64, f64, f64, f64)> {
    let jm = [[j[0], j[1], j[3]], [j[1], j[2], j[4]], [j[3], j[4], j[5]]];
    // (r × d′) = X d′ with X the cross-product matrix of r.
    let x = [[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]];
    let k = mul(&mul(&transpose(&x), &jm), &x);
    let qm = [[q[0], q[1], q[3]], [q[1], q[2], q[4]], [q[3], q[4], q[5]]];
    let c2 = cut * cut;
    let hm = |a: usize, b: usize| k[a][b] - c2 * qm[a][b];
    let (h00, h01, h11, h02, h12, h22) =
        (hm(0, 0), hm(0, 1), hm(1, 1), hm(0, 2), hm(1, 2), hm(2, 2));
    let det = h00 * h11 - h01 * h01;
    if h00 <= 0.0 || det <= 0.0 || !det.is_finite() {
        return None;
    }
    // Centre −H₂⁻¹(h02, h12), value there, extents √(−F₀·(H₂⁻¹)_aa).
    let cx = -(h11 * h02 - h01 * h12) / det;
    let cy = -(h00 * h12 - h01 * h02) / det;
    let f0 = h22 + h02 * cx + h12 * cy;
    if f0 >= 0.0 {
        return None;
    }
    let ex = (-f0 * h11 / det).sqrt();
    let ey = (-f0 * h00 / det).sqrt();
    let f = setup.focal;
    Some((
        setup.centre[0] + f * cx,
        setup.centre[1] - f * cy,
        f * ex,
        f * ey,
    ))
}

#[cfg(test)]
mod tests {
    use super::{Antialias, screen_lowpass};

    /// The eigenvalues (larger first) of the symmetric 2×2 [[a, b], [b, c]].
    fn eigen(v: [f64; 3]) -> (f64, f64) {
        let mean = 0.5 * (v[0] + v[2]);
        let r = (0.25 * (v[0] - v[2]).powi(2) + v[1] * v[1]).sqrt();
        (mean + r, mean - r)
    }

    #[test]
    fn the_auto_lowpass_raises_each_footprint_axis_to_the_lowpass_and_no_further() {
        // Footprints (xx, xy, yy) from wide to needle-thin, isotropic and rotated, against a
        // low-pass of 1 px²: v + Δ must keep v's eigenvectors (Δ commutes with v), have the
        // eigenvalues max(λ, 1), and Δ must be positive semi-definite.
        let lp = 1.0;
        let mut cases = vec![[3.0, 0.0, 3.0], [0.2, 0.0, 0.2], [1.0, 0.0, 1.0]];
        for (l1, l2) in [
            (25.0, 4.0),
            (25.0, 0.3),
            (0.9, 0.01),
            (1.0 + 1e-9, 1.0),
            (4.0, 1.0),
        ] {
            for angle in [0.0, 0.4, 1.3, 2.9] {
                let (c, s) = (f64::cos(angle), f64::sin(angle));
                cases.push([
                    l1 * c * c + l2 * s * s,
                    (l1 - l2) * c * s,
                    l1 * s * s + l2 * c * c,
                ]);
            }
        }
        for v in cases {
            let d = screen_lowpass(v, Antialias::Auto, lp);
            let f = [v[0] + d[0], v[1] + d[1], v[2] + d[2]];
            let ((a1, a2), (b1, b2)) = (eigen(v), eigen(f));
            let scale = a1.max(lp);
            assert!(
                (b1 - a1.max(lp)).abs() <= 1e-12 * scale,
                "{v:?}: {b1} vs max({a1}, 1)"
            );
            assert!(
                (b2 - a2.max(lp)).abs() <= 1e-12 * scale,
                "{v:?}: {b2} vs max({a2}, 1)"
            );
            let (e1, e2) = eigen(d);
            assert!(e2 >= -1e-12 * scale && e1 <= lp + 1e-12, "{v:?}: Δ {d:?}");
            // Commuting: (vΔ)_xy = (Δv)_xy for symmetric 2×2 matrices.
            let comm = v[0] * d[1] + v[1] * d[2] - (d[0] * v[1] + d[1] * v[2]);
            assert!(
                comm.abs() <= 1e-12 * scale * scale,
                "{v:?}: vΔ ≠ Δv by {comm:e}"
            );
        }
        // EWA adds the whole low-pass whatever the footprint.
        assert_eq!(
            screen_lowpass([25.0, 0.0, 25.0], Antialias::Ewa, lp),
            [1.0, 0.0, 1.0]
        );
        assert_eq!(
            screen_lowpass([25.0, 0.0, 25.0], Antialias::Auto, lp),
            [0.0; 3]
        );
    }
}
