//! `vmls check`'s tolerance cases (issue 29 §3): a frame rendered to `render.tolerance = E` on
//! the thinnest transfer-function peak of `tests/scenes/ml-peak-0.002.toml` (half-width 0.002,
//! extinction 100) meets E against the converged image of the same field, or says that it
//! does not (`ToleranceReport::met`), for fixed steps and the adaptive integrator.

use super::{Bound, Case, Env, Outcome};
use crate::bench::BenchError;
use crate::renderer::Renderer;
use crate::renderer::tolerance::p99_error;
use crate::scene::Scene;

const PEAK_SCENE: &str = include_str!("../../tests/scenes/ml-peak-0.002.toml");

pub fn tolerance_cases() -> Vec<Case> {
    vec![Case {
        name: "tolerance-thin-peak",
        about: "render.tolerance met on a transfer-function peak of half-width 0.002",
        run: thin_peak,
    }]
}

fn thin_peak(env: &Env<'_>) -> Result<Vec<Outcome>, BenchError> {
    let size = if env.quick { 40 } else { 96 };
    let scene = |set: &[String]| -> Result<Scene, BenchError> {
        let mut all = vec![
            format!("camera.width={size}"),
            format!("camera.height={size}"),
            // The fine grid for every frame here, the converged one included: one field.
            "reconstruction.resample=2".to_string(),
        ];
        all.extend_from_slice(set);
        Ok(Scene::parse(
            PEAK_SCENE,
            "vmls check thin-peak scene",
            std::path::Path::new("."),
            &all,
        )?)
    };
    let truth_scene = scene(&[
        "render.method=\"reference\"".into(),
        // 1/512 spacing: at 1/64 the midpoint rule itself errs by 5.5e-3 (p99) on this peak,
        // at 1/256 by 3.8e-4 against 1/512.
        "render.reference_step=0.001953125".into(),
        "render.min_transmittance=1e-7".into(),
    ])?;
    let mut renderer = Renderer::new(env.ctx, truth_scene.field(|_| {})?)?;
    let truth = renderer.render(&truth_scene.view(), |_| {})?.0.pixels;
    let tolerances: &[f64] = if env.quick { &[1e-2] } else { &[1e-2, 3e-3] };
    let methods: &[&str] = if env.quick {
        &["fixed"]
    } else {
        &["fixed", "adaptive"]
    };
    let mut out = Vec::new();
    for &method in methods {
        for &e in tolerances {
            let s = scene(&[
                format!("render.method=\"{method}\""),
                format!("render.tolerance={e}"),
            ])?;
            let (image, stats) = renderer.render(&s.view(), |_| {})?;
            let Some(report) = stats.tolerance else {
                return Err(BenchError::Usage("no tolerance report".into()));
            };
            let chosen = report
                .chosen
                .map_or("nothing chosen".into(), |(k, v, est)| {
                    format!("{k} = {v:.4}, estimated {est:.2e}")
                });
            // The tolerance's promise: E met, or said not to be.
            let (bound, detail) = if report.met {
                (Bound::AtMost(e), chosen)
            } else {
                (
                    Bound::AtMost(f64::INFINITY),
                    format!("{chosen}; reported not met: {}", report.notes.join("; ")),
                )
            };
            out.push(Outcome::new(
                "tolerance-thin-peak",
                &format!("{method}, E = {e:.0e}: p99 RGBA error against the converged image"),
                p99_error(&image.pixels, &truth),
                bound,
                detail,
            ));
        }
    }
    Ok(out)
}
