//! Convergence verification in the manner of Etiene et al., "Verifying volume rendering using
//! discretization error analysis" (IEEE TVCG 2014): refine one discretization parameter, keep
//! the others fine, and compare the observed order of the error with the expected one.
//!
//! - Step of the midpoint (`riemann`) and preintegrated (`fixed`) integrators against the
//!   `reference` integrator: both approximate the scalar linearly between samples (or sample the
//!   midpoint), so the error is O(h²).
//! - Preintegration table resolution at a fixed step, against a fine table: bilinear
//!   interpolation of a C¹ table with bounded second derivatives, O(Δ²).
//! - Sample spacing of scattered samples (a jittered lattice), field error at random points
//!   evaluated by the GPU's `mls_eval`: MLS of degree m reproduces polynomials of degree m, so
//!   O(h^(m+1)): 1 for Shepard (constant), 2 for linear, 3 for quadratic. On a regular lattice
//!   Shepard's first-order term nearly cancels (its weighted centroid sits on the point), so
//!   constant and linear would both measure 2 there and a fallback to the constant basis would
//!   pass; that premise is measured too.
//! - Adaptive ε has no order to expect; the check asserts that the error falls as ε does and
//!   reports the observed order.
//!
//! The observed order p is fitted by least squares to log error = p·log h + c (the negated slope
//! against log 1/h).

use super::{Bound, Case, Env, Outcome, grid_volume, rmse};
use crate::bench::BenchError;
use crate::field::Field;
use crate::probe::Lcg;

pub fn convergence_cases() -> Vec<Case> {
    vec![
        Case {
            name: "converge-step",
            about: "order of the step of riemann and fixed against the reference integrator",
            run: step,
        },
        Case {
            name: "converge-table",
            about: "order of the preintegration table resolution",
            run: table,
        },
        Case {
            name: "converge-spacing",
            about: "order of the spacing of scattered samples, on the GPU: constant, linear, quadratic",
            run: spacing,
        },
        Case {
            name: "converge-epsilon",
            about: "adaptive: error falls at every refinement of ε",
            run: epsilon,
        },
    ]
}

/// The order p of error ≈ C·h^p: the least-squares slope of log(error) against log(h).
pub fn observed_order(h: &[f64], errors: &[f64]) -> f64 {
    let pts: Vec<(f64, f64)> = h
        .iter()
        .zip(errors)
        .map(|(h, e)| (-h.ln(), e.ln()))
        .collect();
    let n = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    -sxy / sxx
}

fn detail(h: &[f64], e: &[f64]) -> String {
    h.iter()
        .zip(e)
        .map(|(h, e)| format!("{h}: {e:.2e}"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn step(env: &Env<'_>) -> Result<Vec<Outcome>, BenchError> {
    let steps: &[f64] = if env.quick {
        &[1.0, 0.5, 0.25]
    } else {
        &[1.0, 0.5, 0.25, 0.125]
    };
    let reference = env.render_scene(&env.scene(&[
        "render.method=\"reference\"",
        "render.reference_step=0.015625",
        "render.min_transmittance=1e-6",
    ])?)?;
    let mut out = Vec::new();
    for method in ["riemann", "fixed"] {
        let mut errors = Vec::new();
        for s in steps {
            let scene = env.scene(&[
                &format!("render.method=\"{method}\""),
                &format!("render.step={s}"),
                "render.min_transmittance=1e-6",
                "render.early_termination=0.999999",
                "render.table_resolution=1024",
            ])?;
            errors.push(rmse(
                &env.render_scene(&scene)?,
                &reference,
                scene.camera.width,
            ));
        }
        out.push(Outcome::new(
            "converge-step",
            &format!("{method}: observed order in the step"),
            observed_order(steps, &errors),
            Bound::Order {
                expected: 2.0,
                tolerance: 0.5,
            },
            detail(steps, &errors),
        ));
    }
    Ok(out)
}

fn table(env: &Env<'_>) -> Result<Vec<Outcome>, BenchError> {
    // The fine table is kept within a 128 MiB storage buffer (six lengths of 16-byte entries).
    let (res, fine): (&[usize], usize) = if env.quick {
        (&[16, 32, 64], 512)
    } else {
        (&[16, 32, 64, 128], 1024)
    };
    let fine = env.render_scene(&env.scene(&[&format!("render.table_resolution={fine}")])?)?;
    let mut errors = Vec::new();
    for r in res {
        let scene = env.scene(&[&format!("render.table_resolution={r}")])?;
        errors.push(rmse(&env.render_scene(&scene)?, &fine, scene.camera.width));
    }
    let cells: Vec<f64> = res.iter().map(|&r| 1.0 / (r - 1) as f64).collect();
    Ok(vec![Outcome::new(
        "converge-table",
        "fixed step 0.5: observed order in the table cell",
        observed_order(&cells, &errors),
        Bound::Order {
            expected: 2.0,
            tolerance: 0.5,
        },
        detail(&cells, &errors),
    )])
}

/// A smooth analytic field on [-1, 1]³.
fn smooth(p: [f64; 3]) -> f64 {
    (1.3 * p[0]).sin() * (0.9 * p[1] + 0.4).cos() + 0.5 * (0.7 * p[2]).sin() * p[0]
}

/// n³ lattice points over [-1, 1]³, each moved by up to a quarter spacing per axis.
fn jittered_lattice(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let h = 2.0 / (n - 1) as f64;
    let mut rng = Lcg::new(seed);
    let mut points = Vec::with_capacity(n * n * n);
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                points
                    .push([i, j, k].map(|c| -1.0 + (c as f64 + 0.5 * (rng.next_f64() - 0.5)) * h));
            }
        }
    }
    points
}

fn spacing(env: &Env<'_>) -> Result<Vec<Outcome>, BenchError> {
    let sizes: &[usize] = if env.quick {
        &[9, 17, 33]
    } else {
        &[9, 13, 17, 25, 33]
    };
    let mut out = Vec::new();
    out.push(shepard_centroid(env, &[17])?);
    let compiler = crate::vk::ShaderCompiler::new()?;
    for (basis, expected) in [("constant", 1.0), ("linear", 2.0), ("quadratic", 3.0)] {
        let mut errors = Vec::new();
        let mut hs = Vec::new();
        for &n in sizes {
            let h = 2.0 / (n - 1) as f64;
            let set = format!("reconstruction.basis=\"{basis}\"");
            let field =
                super::cases::point_field_of(env, jittered_lattice(n, 29), &[&set], smooth)?;
            let mut rng = Lcg::new(17);
            // The inner half of the box: away from one-sided boundary fits.
            let truth: Vec<[f64; 3]> = (0..2000)
                .map(|_| std::array::from_fn(|_| -0.5 + rng.next_f64()))
                .collect();
            let at: Vec<[f64; 3]> = truth
                .iter()
                .map(|p| (glam::DVec3::from(*p) - field.frame_origin).to_array())
                .collect();
            let gpu_field = crate::field::gpu::GpuField::upload(env.ctx, &field)?;
            let (values, _) =
                crate::field::gpu::evaluate(env.ctx, &compiler, &field, &gpu_field, &at, 1)?;
            let sum: f64 = values
                .iter()
                .zip(&truth)
                .map(|(g, p)| {
                    let v = if g.terms > 0 {
                        f64::from(g.value)
                    } else {
                        f64::NAN
                    };
                    (v - smooth(*p)).powi(2)
                })
                .sum();
            errors.push((sum / truth.len() as f64).sqrt());
            hs.push(h);
        }
        out.push(Outcome::new(
            "converge-spacing",
            &format!("{basis} MLS, scattered samples, GPU: observed order in the spacing"),
            observed_order(&hs, &errors),
            Bound::Order {
                expected,
                tolerance: 0.5,
            },
            detail(&hs, &errors),
        ));
    }
    Ok(out)
}

/// Largest offset of Shepard's weighted centroid from the evaluation point, in spacings: the
/// error of reproducing f(x) = x₀ with the constant basis, over h.
fn shepard_centroid(env: &Env<'_>, sizes: &[usize]) -> Result<Outcome, BenchError> {
    let scene = env.scene(&["reconstruction.basis=\"constant\""])?;
    let n = sizes[0];
    let h = 2.0 / (n - 1) as f64;
    let volume = grid_volume(n, |p| p[0]);
    let field = Field::new(volume, scene.reconstruction, &scene.octree, |_| {})?;
    let neighbours = field.evaluator()?;
    let mut rng = Lcg::new(23);
    let mut worst = 0.0f64;
    for _ in 0..2000 {
        let p: [f64; 3] = std::array::from_fn(|_| -0.5 + rng.next_f64());
        let x = (glam::DVec3::from(p) - field.frame_origin).to_array();
        let v = field
            .evaluate(neighbours.as_ref(), x)
            .map_or(f64::NAN, |m| m.value);
        worst = worst.max((v - p[0]).abs() / h);
    }
    Ok(Outcome::new(
        "converge-spacing",
        "constant MLS: Shepard centroid offset on the lattice, in spacings",
        worst,
        Bound::AtMost(0.02),
        format!("support {} spacings", scene.reconstruction.support),
    ))
}

fn epsilon(env: &Env<'_>) -> Result<Vec<Outcome>, BenchError> {
    let eps = [0.1, 0.03, 0.01];
    let reference = env.render_scene(&env.scene(&[
        "render.method=\"reference\"",
        "render.reference_step=0.015625",
    ])?)?;
    let mut errors = Vec::new();
    for e in eps {
        let scene = env.scene(&["render.method=\"adaptive\"", &format!("render.epsilon={e}")])?;
        errors.push(rmse(
            &env.render_scene(&scene)?,
            &reference,
            scene.camera.width,
        ));
    }
    // Every refinement must help: the largest ratio of consecutive errors.
    let worst = errors
        .windows(2)
        .map(|w| w[1] / w[0])
        .fold(f64::NEG_INFINITY, f64::max);
    Ok(vec![Outcome::new(
        "converge-epsilon",
        "adaptive: largest error ratio between consecutive ε (0.1, 0.03, 0.01)",
        worst,
        Bound::AtMost(1.0),
        format!(
            "{}; observed order {:.2}",
            detail(&eps, &errors),
            observed_order(&eps, &errors)
        ),
    )])
}

#[cfg(test)]
mod tests {
    #[test]
    fn observed_order_of_exact_power_laws() {
        let h = [1.0, 0.5, 0.25, 0.125];
        for p in [1.0, 2.0, 3.0] {
            let e: Vec<f64> = h.iter().map(|h: &f64| 0.3 * h.powf(p)).collect();
            assert!((super::observed_order(&h, &e) - p).abs() < 1e-12);
        }
    }
}
