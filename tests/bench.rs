//! `vmls bench` end to end on lavapipe with validation on: the result files and their columns,
//! error against the cached reference, imports, and one clear error for bad arguments.

mod common;

use common::cli::{assert_fails, dir, s, vmls};
use vmls::bench::results::{Row, read_csv};

const SMALL: [&str; 4] = ["--set", "camera.width=24", "--set", "camera.height=20"];

fn run_ok(args: &[&str]) -> String {
    let out = vmls(args);
    assert!(
        out.status.success(),
        "bench failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// `vmls bench` of one fixed-step configuration (step 1) at the small size, into `out`, with
/// the reference cache `cache` and `extra` arguments.
fn one_fixed(out: &std::path::Path, cache: &std::path::Path, extra: &[&str]) -> String {
    let mut args = vec![
        "bench",
        "--methods",
        "fixed",
        "--sweep",
        "render.step=1",
        "--repeat",
        "1",
        "--out",
        s(out),
        "--cache",
        s(cache),
    ];
    args.extend(extra);
    args.extend(SMALL);
    run_ok(&args)
}

fn finite(v: Option<f64>) -> f64 {
    let x = v.expect("value present");
    assert!(x.is_finite(), "{x}");
    x
}

#[test]
fn sweep_writes_rows_plot_and_caches_the_reference() {
    let d = dir("bench");
    let (out, cache) = (d.join("out"), d.join("cache"));
    let mut args = vec![
        "bench",
        "--methods",
        "fixed,riemann",
        "--sweep",
        "render.step=1,0.5",
        "--repeat",
        "2",
        "--warmup",
        "0",
        "--out",
        s(&out),
        "--cache",
        s(&cache),
        "--variant",
        // Against the scene's own field, so that the integrators' error is what converges.
        "--own-reference",
        // The fast path whatever the image size ("auto" declines it for a 24×20 first frame).
        "--set",
        "reconstruction.resample=2",
    ];
    args.extend(SMALL);
    let stdout = run_ok(&args);
    assert!(
        stdout.contains("MLS_TERMS="),
        "--variant prints defines: {stdout}"
    );
    assert!(
        !stdout.contains("(cached)"),
        "first run renders the reference"
    );
    let rows = read_csv(&out.join("results.csv")).expect("results.csv");
    let methods: Vec<&str> = rows.iter().map(|r| r.method.as_str()).collect();
    assert_eq!(methods, ["fixed", "fixed", "riemann", "riemann"]);
    for r in &rows {
        assert_eq!(
            (r.source.as_str(), r.width, r.height, r.frames),
            ("vmls", 24, 20, 2)
        );
        assert!(r.device.contains("llvmpipe") || !r.device.is_empty());
        let gpu = finite(r.gpu_ms);
        assert!(gpu > 0.0 && finite(r.gpu_ms_min) <= gpu && gpu <= finite(r.gpu_ms_max));
        assert!(r.kernel_ms.starts_with("raycast="), "{}", r.kernel_ms);
        assert!(r.evaluations.expect("ray casting counts") > 0);
        // The first frame uploads the dataset; later ones only their constants.
        let (first, next) = (
            r.bytes_uploaded_first.expect("bytes"),
            r.bytes_uploaded_next.expect("bytes"),
        );
        assert!(first > next && next > 0, "{first} {next}");
        assert_eq!(r.non_finite, Some(0));
        // The default scene's fast path: both ceiling shares by the stated model, its reads
        // against the ray-march gather ceiling.
        let (fma, gather) = (finite(r.fma_share), finite(r.memory_share));
        assert!(
            fma > 0.0 && gather > 0.0 && fma < 10.0 && gather < 10.0,
            "{r:?}"
        );
        assert_eq!(
            r.bound_by,
            if fma >= gather {
                "fma"
            } else {
                "march-texel-gather"
            }
        );
        assert!(finite(r.rmse) < 0.05, "{r:?}");
        assert!(finite(r.max_abs) >= finite(r.rmse));
    }
    // Halving the step brings both integrators closer to the reference.
    assert!(finite(rows[1].rmse) < finite(rows[0].rmse), "{rows:?}");
    assert!(finite(rows[3].rmse) < finite(rows[2].rmse), "{rows:?}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).expect("json"))
            .expect("valid JSON");
    assert_eq!(json["rows"].as_array().map(Vec::len), Some(4));
    assert!(json["run"]["commit"].is_string() && json["run"]["device"].is_string());
    let png = image::open(out.join("speed_error.png")).expect("plot png");
    assert_eq!((png.width(), png.height()), (1100, 750));
    let svg = std::fs::read_to_string(out.join("speed_error.svg")).expect("plot svg");
    assert!(svg.contains("<svg") && svg.contains("Pareto front"));
    assert!(out.join("images/003.exr").is_file());

    // Second run: the reference comes from the cache, and imported rows join the table.
    let out2 = d.join("out2");
    let first_csv = out.join("results.csv");
    let stdout = one_fixed(
        &out2,
        &cache,
        &[
            "--no-ceilings",
            "--own-reference",
            "--set",
            "reconstruction.resample=2",
            "--import",
            s(&first_csv),
        ],
    );
    assert!(stdout.contains("(cached)"), "{stdout}");
    assert!(
        !stdout.contains("ceilings:"),
        "--no-ceilings skips the probes"
    );
    let merged: Vec<Row> = read_csv(&out2.join("results.csv")).expect("merged");
    assert_eq!(merged.len(), 5);
    assert_eq!(merged[1..], rows[..]);
    // The same configuration against the same reference: the same error.
    assert_eq!(merged[0].settings, rows[0].settings);
    assert!((finite(merged[0].rmse) - finite(rows[0].rmse)).abs() < 1e-6);

    // By default a generated volume is measured against its analytic field: a new reference,
    // and the error now includes the reconstruction's.
    let out3 = d.join("out3");
    let stdout = one_fixed(&out3, &cache, &["--no-ceilings"]);
    assert!(
        stdout.contains("the analytic field") && !stdout.contains("(cached)"),
        "{stdout}"
    );
    let truth: Vec<Row> = read_csv(&out3.join("results.csv")).expect("rows");
    assert!(truth[0].reference.contains("analytic"), "{:?}", truth[0]);
    assert!(finite(truth[0].rmse) > finite(rows[0].rmse), "{truth:?}");

    // Splatting rows are measured on splat_raster against the FMA and streaming ceilings.
    let out4 = d.join("out4");
    let mut args = vec![
        "bench",
        "--methods",
        "splat",
        "--repeat",
        "1",
        "--warmup",
        "0",
        "--out",
        s(&out4),
        "--cache",
        s(&cache),
    ];
    args.extend(SMALL);
    run_ok(&args);
    let splat: Vec<Row> = read_csv(&out4.join("results.csv")).expect("rows");
    let r = &splat[0];
    assert!(
        r.kernel_ms.contains("splat_raster=") && r.evaluations.is_none(),
        "{r:?}"
    );
    let (fma, stream) = (finite(r.fma_share), finite(r.memory_share));
    assert!(
        fma > 0.0 && stream > 0.0 && fma < 10.0 && stream < 10.0,
        "{r:?}"
    );
    assert_eq!(r.bound_by, if fma >= stream { "fma" } else { "stream" });
}

#[test]
fn bad_bench_arguments_fail_before_any_work() {
    let d = dir("bench-bad");
    let out = d.join("out");
    let csv = out.join("results.csv");
    let bad_csv = d.join("bad.csv");
    std::fs::write(&bad_csv, "source,method\nvmls,fixed\n").expect("write");
    let cases: [(&[&str], &[&str]); 6] = [
        (
            &["--sweep", "render.step"],
            &["--sweep render.step", "section.key=value1"],
        ),
        (&["--sweep", "render.step=1,-2"], &["render.step"]),
        (&["--methods", "fast"], &["render.method", "fast"]),
        (&["--repeat", "0"], &["--repeat"]),
        (
            &["--sweep", "camera.width=10,20"],
            &["--sweep camera.width=10,20", "one reference"],
        ),
        (&["--import", s(&bad_csv)], &["bad.csv", "line 2"]),
    ];
    for (extra, needles) in cases {
        let mut args = vec!["bench", "--out", s(&out), "--no-cache"];
        args.extend(extra);
        args.extend(SMALL);
        assert_fails(&vmls(&args), needles, &csv);
    }
}
