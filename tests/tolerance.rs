//! `render.tolerance` (issue 29): a frame rendered to a tolerance E meets it against the
//! converged image of the same field (the reference integrator at a step of 1/64 spacing with
//! no early termination), and is not wastefully better; explicit keys win and are reported.
mod common;

use common::*;
use vmls::field::Field;
use vmls::renderer::Renderer;
use vmls::renderer::tolerance::{p99_error, p99_of, pixel_errors};
use vmls::scene::Scene;

/// Marschner–Lobb 17³ on the fast path's fine grid (as a scene's default chooses it), 48², with
/// `extra` after.
fn scene(extra: &[&str]) -> Scene {
    let mut o: Vec<String> = [
        "volume.resolution=17",
        "camera.width=48",
        "camera.height=48",
        "reconstruction.resample=2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    o.extend(extra.iter().map(|s| s.to_string()));
    Scene::load(None, &o).expect("scene")
}

/// The converged image of the scene's field.
fn converged(renderer: &mut Renderer, field_scene: &Scene) -> Vec<[f32; 4]> {
    converged_at(renderer, field_scene, 1.0 / 64.0)
}

/// The reference integrator's image of the scene's field at `step` spacings.
fn converged_at(renderer: &mut Renderer, field_scene: &Scene, step: f64) -> Vec<[f32; 4]> {
    converged_through(renderer, field_scene, &field_scene.camera, step)
}

#[test]
fn fixed_steps_and_the_adaptive_integrator_meet_the_tolerance() {
    let (ctx, _compiler) = gpu();
    let base = scene(&[]);
    let field: Field = base.field(|_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field).expect("renderer");
    let truth = converged(&mut renderer, &base);
    for method in ["fixed", "adaptive"] {
        let mut chosen = Vec::new();
        for e in [1e-2, 3e-3] {
            let m = format!("render.method=\"{method}\"");
            let t = format!("render.tolerance={e}");
            let s = scene(&[&m, &t]);
            let (image, stats) = renderer.render(&s.view(), |_| {}).expect("render");
            let report = stats.tolerance.expect("a tolerance report");
            let (key, value, estimate) = report.chosen.expect("the tolerance chose");
            let measured = p99_error(&image.pixels, &truth);
            eprintln!(
                "{method} E = {e}: {key} = {value:.4}, estimated {estimate:.2e}, measured \
                 {measured:.2e}, early termination {}, tables {}, {} pilots, notes {:?}",
                report.early_termination, report.table_resolution, report.pilots, report.notes
            );
            assert!(report.met, "{method}: E = {e}: {:?}", report.notes);
            assert!(measured <= e, "{method}: E = {e}, measured {measured:e}");
            // Not wastefully accurate. Measured on lavapipe: fixed 3.05e-3 at E = 1e-2 and
            // 1.05e-3 at 3e-3 (0.31 E, 0.35 E), adaptive 2.74e-3 and 1.30e-3 (0.27 E, 0.43 E);
            // issue 29 asks ≥ E/10 of most cases, one scene here bounds it at E/30.
            assert!(
                measured >= e / 30.0,
                "{method}: E = {e}, measured {measured:e}"
            );
            assert!((report.early_termination - (1.0 - e / 4.0)).abs() < 1e-12);
            chosen.push(value);
            // The same view again reuses the choice: no pilots.
            let (_, again) = renderer.render(&s.view(), |_| {}).expect("render");
            assert_eq!(again.tolerance.map(|r| r.chosen), Some(report.chosen));
        }
        assert!(
            chosen[1] < chosen[0],
            "{method}: a smaller E refines: {chosen:?}"
        );
    }
    drop(renderer);
    finish(ctx);
}

/// A loose tolerance climbs above the ladder's first level where its first rungs are far
/// inside the budget (`coarsen`): before, ε stayed at level 0's, the coarsest the ladder could
/// reach, and frames came out many times better than asked (the shell's 0.002 peak at E/29).
/// The scene gives `render.l_max` (2.6 spacings, the default), so that the rungs differ by ε
/// alone: with the ladder's own l_max (from √2 × 2.6 at level 0) this scene's level 0 is no
/// longer far inside E = 0.1 (its first difference 2.3e-2, where 1.6e-2 with 2.6) and the
/// ladder refines from it instead.
#[test]
fn a_loose_tolerance_coarsens_past_the_first_level_and_still_meets_it() {
    let (ctx, _compiler) = gpu();
    let base = scene(&[]);
    let field: Field = base.field(|_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field).expect("renderer");
    let truth = converged(&mut renderer, &base);
    let e = 0.1;
    let s = scene(&[
        "render.method=\"adaptive\"",
        "render.adaptive=\"hermite\"",
        "render.l_max=2.6",
        "render.tolerance=0.1",
    ]);
    let level0 = vmls::renderer::tolerance::first_level(&s.render).epsilon;
    let (image, stats) = renderer.render(&s.view(), |_| {}).expect("render");
    let report = stats.tolerance.expect("a tolerance report");
    let measured = p99_error(&image.pixels, &truth);
    eprintln!(
        "E = {e}: chosen {:?}, rungs {:?}, measured {measured:.2e}, level 0's ε {level0}",
        report.chosen, report.rungs
    );
    assert!(report.met, "{:?}", report.notes);
    assert!(
        report.rungs[0].0 > 3.0 * level0,
        "the ladder climbed above level 0 (ε {level0}): {:?}",
        report.rungs
    );
    assert!(measured <= e, "measured {measured:e}");
    // Measured on lavapipe: 2.35e-2, at ε 0.054 against level 0's 0.024.
    assert!(measured >= e / 10.0, "measured {measured:e}");
    drop(renderer);
    finish(ctx);
}

/// The reference integrator's image of the scene's field through `camera` at `step` spacings.
fn converged_through(
    renderer: &mut Renderer,
    field_scene: &Scene,
    camera: &vmls::view::camera::Camera,
    step: f64,
) -> Vec<[f32; 4]> {
    let mut s = field_scene.render.clone();
    s.method = vmls::view::Method::Reference;
    s.reference_step_spacings = step;
    s.min_transmittance = 1e-7;
    s.tolerance = None;
    let view = vmls::view::View {
        settings: &s,
        ..field_scene.view_with(camera)
    };
    renderer.render(&view, |_| {}).expect("reference").0.pixels
}

/// A turning camera: the next view of the same settings starts its pilots from the last
/// view's choice, renders fewer of them, and still meets E against its own converged image,
/// with a choice within a level of what that view's pilots choose from scratch (one level: the
/// step halves, ε quarters). Any other change (here E) resolves from scratch.
#[test]
fn a_turning_camera_carries_the_choice_and_still_meets_the_tolerance() {
    let (ctx, _compiler) = gpu();
    let e = 1e-2;
    for (method, per_level) in [("fixed", 2.0f64), ("adaptive", 4.0)] {
        let m = format!("render.method=\"{method}\"");
        let t = format!("render.tolerance={e}");
        let s = scene(&[&m, &t]);
        let field: Field = s.field(|_| {}).expect("field");
        let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
        let mut first_pilots = 0;
        for k in 0..4 {
            let camera = s.camera.orbited((25.0 * f64::from(k)).to_radians());
            let (image, stats) = renderer
                .render(&s.view_with(&camera), |_| {})
                .expect("render");
            let report = stats.tolerance.expect("a tolerance report");
            let (_, value, _) = report.chosen.expect("the tolerance chose");
            let truth = converged_through(&mut renderer, &s, &camera, 1.0 / 64.0);
            let measured = p99_error(&image.pixels, &truth);
            // A fresh renderer resolves this view from scratch.
            let mut fresh = Renderer::new(&ctx, field.clone()).expect("renderer");
            let (_, fresh_stats) = fresh.render(&s.view_with(&camera), |_| {}).expect("render");
            drop(fresh);
            let fresh_report = fresh_stats.tolerance.expect("a tolerance report");
            let (_, fresh_value, _) = fresh_report.chosen.expect("the tolerance chose");
            eprintln!(
                "{method} view {k}: value {value:.4} (fresh {fresh_value:.4}), measured \
                 {measured:.2e}, {} pilots (fresh {}), carried {}, notes {:?}",
                report.pilots, fresh_report.pilots, report.carried, report.notes
            );
            assert_eq!(report.carried, k > 0, "{method} view {k}");
            assert!(!fresh_report.carried);
            assert!(report.met, "{method} view {k}: {:?}", report.notes);
            assert!(measured <= e, "{method} view {k}: measured {measured:e}");
            let levels = (value / fresh_value).ln().abs() / per_level.ln();
            assert!(
                levels <= 1.0 + 1e-9,
                "{method} view {k}: {value} against {fresh_value} fresh"
            );
            if k == 0 {
                first_pilots = report.pilots;
            } else {
                assert!(
                    report.pilots < first_pilots,
                    "{method} view {k}: {} pilots, the first view {first_pilots}",
                    report.pilots
                );
            }
        }
        // Another E through the last camera: not carried.
        let finer = scene(&[&m, "render.tolerance=0.003"]);
        let camera = finer.camera.orbited((75.0f64).to_radians());
        let (_, stats) = renderer
            .render(&finer.view_with(&camera), |_| {})
            .expect("render");
        let report = stats.tolerance.expect("a tolerance report");
        assert!(
            !report.carried,
            "{method}: a new E is resolved from scratch"
        );
        drop(renderer);
    }
    finish(ctx);
}

#[test]
fn explicit_keys_win_over_the_tolerance_and_are_reported() {
    let (ctx, _compiler) = gpu();
    let s = scene(&[
        "render.tolerance=0.01",
        "render.step=0.5",
        "render.early_termination=0.9",
    ]);
    let field = s.field(|_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field).expect("renderer");
    let (_, stats) = renderer.render(&s.view(), |_| {}).expect("render");
    let report = stats.tolerance.expect("report");
    assert_eq!(report.chosen, None);
    assert_eq!(report.early_termination, 0.9);
    let notes = report.notes.join("; ");
    assert!(notes.contains("render.step given"), "{notes}");
    assert!(
        notes.contains("render.early_termination = 0.9 given"),
        "{notes}"
    );
    // The built-in scene spells render.step out, but that is not the user's choice.
    let default = Scene::load(None, &["render.tolerance=0.01".to_string()]).expect("scene");
    assert!(!default.render.given.step);
    assert_eq!(default.render.tolerance, Some(0.01));
    for bad in ["0", "0.7", "-1e-3", "\"small\""] {
        let err =
            Scene::load(None, &[format!("render.tolerance={bad}")]).expect_err("out of range");
        assert!(err.to_string().contains("render.tolerance"), "{err}");
    }
    drop(renderer);
    finish(ctx);
}

/// Runs `vmls` (which must succeed) and reads the `--stats` file it wrote.
fn render_stats(args: &[&str], stats: &std::path::Path) -> serde_json::Value {
    let out = common::cli::vmls(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&std::fs::read(stats).expect("stats")).expect("json")
}

/// `vmls render --tolerance E` writes what it chose into `--stats`; `--cpu` refuses it (its
/// pilots run on the GPU) and leaves no image.
#[test]
fn the_command_line_takes_a_tolerance() {
    use common::cli::*;
    let d = dir("tolerance");
    let (png, stats) = (d.join("t.png"), d.join("t.json"));
    let small = [
        "--set",
        "volume.resolution=17",
        "--set",
        "camera.width=32",
        "--set",
        "camera.height=24",
    ];
    let mut args = vec![
        "render",
        "-o",
        s(&png),
        "--stats",
        s(&stats),
        "--tolerance",
        "0.01",
    ];
    args.extend(small);
    let json = render_stats(&args, &stats);
    let t = &json["tolerance"];
    assert_eq!(t["requested"], 0.01);
    assert_eq!(t["chosen"]["key"], "render.step");
    assert!(
        t["chosen"]["value"]
            .as_f64()
            .is_some_and(|v| v > 0.0 && v < 1.0)
    );
    assert!(t["pilot_frames"].as_u64().is_some_and(|n| n >= 3));
    assert_eq!(json["frames"][0]["tolerance"], *t);

    let cpu_png = d.join("cpu.png");
    let mut args = vec!["render", "--cpu", "-o", s(&cpu_png), "--tolerance", "0.01"];
    args.extend(small);
    assert_fails(&vmls(&args), &["--tolerance"], &cpu_png);

    // Adaptive frames report their own error estimate, on the GPU and on the CPU twin alike.
    for cpu in [false, true] {
        let mut args = vec!["render", "-o", s(&png), "--stats", s(&stats), "--force"];
        if cpu {
            args.push("--cpu");
        }
        args.extend(small);
        args.extend(["--set", "render.method=\"adaptive\""]);
        let json = render_stats(&args, &stats);
        let e = &json["error_estimate"];
        let (p99, max) = (e["p99"].as_f64(), e["max"].as_f64());
        assert!(
            p99.zip(max)
                .is_some_and(|(p, m)| 0.0 < p && p <= m && m < 1.0),
            "cpu {cpu}: {e}"
        );
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// `vmls bench` with a swept tolerance: its rows carry E, the estimate and `met`, and it draws
/// the measured-against-requested plot.
#[test]
fn the_bench_plots_measured_against_requested_error() {
    use common::cli::*;
    let d = dir("tolerance-bench");
    let out = vmls(&quick_bench(&d, &["--sweep", "render.tolerance=1e-2,3e-3"]));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for plot in ["tolerance.svg", "tolerance.png"] {
        let bytes = std::fs::read(d.join(plot)).expect("the tolerance plot");
        assert!(bytes.len() > 1000, "{plot}: {} bytes", bytes.len());
    }
    let svg = std::fs::read_to_string(d.join("tolerance.svg")).expect("svg");
    assert!(svg.contains("requested E"), "axis label missing");
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("results.json")).expect("json"))
            .expect("valid");
    let rows = json["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 2);
    for r in rows {
        let e = r["tolerance"].as_f64().expect("E");
        assert!(e == 0.01 || e == 0.003, "{r}");
        assert!(
            r["tolerance_estimate"].as_f64().is_some_and(|v| v > 0.0),
            "{r}"
        );
        assert!(r["tolerance_met"].is_boolean(), "{r}");
        assert!(r["p99"].as_f64().is_some_and(f64::is_finite), "{r}");
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// The adaptive integrator's own estimate of each pixel's error (its criterion's local
/// estimates along the ray, weighted by the transmittance, plus what early termination left)
/// is honest: on the analytic field rendered to E = 1e-3, it is at least the measured error in
/// 99% of the pixels (with the tables' estimated share added), and not vacuous.
#[test]
fn the_adaptive_error_estimate_covers_the_measured_error() {
    let (ctx, _compiler) = gpu();
    let base = scene(&["reconstruction.method=\"exact\""]);
    let field: Field = base.field(|_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field).expect("renderer");
    let truth = converged(&mut renderer, &base);
    let e = 1e-3;
    let s = scene(&[
        "reconstruction.method=\"exact\"",
        "render.method=\"adaptive\"",
        "render.tolerance=1e-3",
    ]);
    let (image, stats) = renderer.render(&s.view(), |_| {}).expect("render");
    let report = stats.tolerance.expect("report");
    let ray = image
        .error_estimate
        .as_ref()
        .expect("adaptive frames estimate their error");
    let estimated: Vec<f64> = ray.iter().map(|&e| f64::from(e)).collect();
    let tables = report.table_moves.last().map_or(0.0, |m| m.1);
    let measured = pixel_errors(&image.pixels, &truth);
    let covered = measured
        .iter()
        .zip(&estimated)
        .filter(|(m, est)| **est + tables >= **m)
        .count();
    let (p99_measured, p99_estimated) = (p99_of(measured.clone()), p99_of(estimated.clone()));
    eprintln!(
        "E = {e}: measured p99 {p99_measured:.2e}, estimated {p99_estimated:.2e} (+ tables \
         {tables:.1e}), covered {covered} of {} pixels",
        measured.len()
    );
    assert!(
        covered as f64 >= 0.99 * measured.len() as f64,
        "the estimate is below the measured error in {} of {} pixels",
        measured.len() - covered,
        measured.len()
    );
    // Measured on lavapipe at 96²: 13× the measured 99th percentile (a bound: no cancellation
    // between intervals is assumed).
    assert!(
        p99_estimated <= 40.0 * p99_measured.max(e / 10.0),
        "estimate {p99_estimated:e} against measured {p99_measured:e}"
    );
    drop(renderer);
    finish(ctx);
}

/// The GPU's per-ray error estimate is its f64 twin's, for both criteria, up to the f32
/// decisions that flip an acceptance.
#[test]
fn the_error_estimate_matches_its_cpu_twin() {
    let (ctx, _compiler) = gpu();
    for criterion in ["hermite", "mls2008"] {
        let c = format!("render.adaptive=\"{criterion}\"");
        let s = scene(&[
            "render.method=\"adaptive\"",
            &c,
            "render.table_resolution=256",
            "render.early_termination=0.999",
        ]);
        let field: Field = s.field(|_| {}).expect("field");
        let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
        let (image, _) = renderer.render(&s.view(), |_| {}).expect("render");
        let gpu = image.error_estimate.expect("estimate");
        let setup = s.ray_setup(&field).expect("setup");
        let cpu = vmls::raycast::raycast_frame(&setup, &field, &s.transfer, 256).expect("cpu");
        let largest = cpu.iter().map(|p| p.error_estimate).fold(0.0, f64::max);
        let diffs: Vec<f64> = cpu
            .iter()
            .zip(&gpu)
            .map(|(p, g)| (p.error_estimate - f64::from(*g)).abs())
            .collect();
        let mean = |v: &mut dyn Iterator<Item = f64>| v.sum::<f64>() / diffs.len() as f64;
        let (mean_cpu, mean_gpu) = (
            mean(&mut cpu.iter().map(|p| p.error_estimate)),
            mean(&mut gpu.iter().map(|g| f64::from(*g))),
        );
        let p99 = p99_of(diffs);
        eprintln!(
            "{criterion}: largest {largest:.2e}, p99 |GPU − CPU| {p99:.2e}, means {mean_cpu:.3e} \
             {mean_gpu:.3e}"
        );
        assert!(largest > 0.0, "{criterion}: no estimate");
        assert!(p99 <= 1e-3 * largest, "{criterion}: p99 difference {p99:e}");
        assert!(
            (mean_cpu - mean_gpu).abs() <= 5e-3 * mean_cpu,
            "{criterion}: means {mean_cpu:e} and {mean_gpu:e}"
        );
        drop(renderer);
    }
    finish(ctx);
}

/// `reconstruction.resample = "auto"` counts a tolerance's pilot frames in the first frame's
/// cost: the built-in 41³ scene at 64², adaptive, declines the fast path alone (81³ = 531 441
/// fine points, each a solve, against about 1.2e5 solves in the frame) and takes it under a
/// tolerance (six pilots and the frame, each at least the ladder's first level: about 8.3e5).
/// An explicit `render.table_resolution` leaves two of the pilots (3.6e5), and the general
/// path.
#[test]
fn auto_counts_a_tolerance_s_pilots_in_the_first_frame() {
    let factor = |extra: &[&str]| {
        let mut o: Vec<String> = [
            "camera.width=64",
            "camera.height=64",
            "render.method=\"adaptive\"",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        o.extend(extra.iter().map(|s| s.to_string()));
        let scene = Scene::load(None, &o).expect("scene");
        let field = scene.field(|_| {}).expect("field");
        field.fast_path()["factor"].as_u64().expect("factor")
    };
    assert_eq!(factor(&[]), 0, "no tolerance: one frame");
    assert_eq!(
        factor(&["render.tolerance=3e-3"]),
        2,
        "a tolerance's pilots"
    );
    assert_eq!(
        factor(&["render.tolerance=3e-3", "render.table_resolution=1024"]),
        0,
        "two pilots"
    );
}

/// Post-shaded splatting's intervals read a table as well, and the tolerance now checks its
/// share as it does the ray casters': it did not, and on issue 29's thinnest peak splatting's
/// 512² table erred by 5e-2 (p99) unreported (BENCHMARKS.md). With the tables' opacity the
/// tolerance measures their move and refines them; with "auto"'s exact opacity the move is
/// f32 rounding and the coarse table stays.
#[test]
fn splatting_tolerances_check_the_table_of_their_intervals() {
    let peak = "transfer.points=[[0.0,1.0,0.6,0.2,0.0],[0.498,1.0,0.6,0.2,0.0],\
                [0.5,1.0,0.6,0.2,100],[0.502,1.0,0.6,0.2,0.0],[1.0,1.0,0.6,0.2,0.0]]";
    let (ctx, _compiler) = gpu();
    let splat = ["render.method=\"splat-post\"", "reconstruction.resample=0"];
    let base = scene(&[&[peak][..], &splat].concat());
    let field: Field = base.field(|_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field).expect("renderer");
    let mut report = |exact: &str| {
        let s = scene(&[&[peak, "render.tolerance=1e-2", exact][..], &splat].concat());
        let (_, stats) = renderer.render(&s.view(), |_| {}).expect("render");
        let r = stats.tolerance.expect("a tolerance report");
        eprintln!(
            "{exact}: tables {}, moves {:?}, notes {:?}",
            r.table_resolution, r.table_moves, r.notes
        );
        r
    };
    let plain = report("render.exact_opacity=false");
    let first = plain.table_moves.first().expect("the tables were checked");
    assert!(first.1 > 1e-2, "the premise: 512² errs by {:.2e}", first.1);
    assert!(plain.table_resolution > 512, "{}", plain.table_resolution);
    let exact = report("render.exact_opacity=\"auto\"");
    assert!(!exact.table_moves.is_empty(), "the tables were not checked");
    for (resolution, error) in &exact.table_moves {
        assert!(
            *error < 1e-5,
            "exact opacity: tables of {resolution} err by {error:.2e}"
        );
    }
    assert_eq!(exact.table_resolution, 512);
    drop(renderer);
    finish(ctx);
}

#[test]
fn a_peak_thinner_than_the_tables_resolve_meets_its_tolerance_by_the_exact_opacity() {
    // Issue 29's thinnest peak (half-width 0.002, 1/550 of the tables' range, τ up to 100),
    // against a reference at 1/512 spacing (1/64 errs by ~6e-3 on it). Bilinear tables of a
    // resolution that fits lavapipe miss E = 3e-3 there and report it (BENCHMARKS.md, "The
    // thinnest Marschner–Lobb peak"); "auto" takes the exact opacity for such a function, and
    // then coarse tables suffice.
    let peak = "transfer.points=[[0.0,1.0,0.6,0.2,0.0],[0.498,1.0,0.6,0.2,0.0],\
                [0.5,1.0,0.6,0.2,100],[0.502,1.0,0.6,0.2,0.0],[1.0,1.0,0.6,0.2,0.0]]";
    let (ctx, _compiler) = gpu();
    let base = scene(&[peak]);
    let field: Field = base.field(|_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field).expect("renderer");
    let truth = converged_at(&mut renderer, &base, 1.0 / 512.0);
    let e = 3e-3;
    for method in ["fixed", "adaptive"] {
        let m = format!("render.method=\"{method}\"");
        let s = scene(&[peak, &m, "render.tolerance=3e-3"]);
        let (image, stats) = renderer.render(&s.view(), |_| {}).expect("render");
        let report = stats.tolerance.expect("a tolerance report");
        let measured = p99_error(&image.pixels, &truth);
        eprintln!(
            "{method}: {:?}, measured {measured:.2e}, tables {}, notes {:?}",
            report.chosen, report.table_resolution, report.notes
        );
        let tables = renderer.tables().expect("tables");
        assert!(tables.exact_opacity.is_some(), "{method}: auto took it");
        assert!(report.met, "{method}: {:?}", report.notes);
        assert!(measured <= e, "{method}: measured {measured:e}");
        assert!(
            report.table_resolution <= 1024,
            "{method}: tables of {}",
            report.table_resolution
        );
    }
    // The built-in transfer function has no piece that narrow: "auto" keeps the tables'.
    let plain = scene(&["render.method=\"fixed\""]);
    renderer.render(&plain.view(), |_| {}).expect("render");
    let tables = renderer.tables().expect("tables");
    assert!(tables.exact_opacity.is_none());
    drop(renderer);
    finish(ctx);
}
