//! The `vmls` binary end to end, with validation on: the contract of `render`, `--stats`,
//! `--set`, and one clear error line plus a non-zero exit (and no image) for every bad input.

mod common;

use common::cli::{assert_fails, dir, s, vmls};

#[test]
fn default_scene_renders_png_with_stats() {
    let d = dir("default");
    let png = d.join("ml.png");
    let stats = d.join("stats.json");
    let out = vmls(&["render", "-o", s(&png), "--stats", s(&stats)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.stderr.is_empty(),
        "unexpected stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&png).expect("png").to_rgba8();
    assert_eq!(img.dimensions(), (256, 256));
    // The default scene shows the volume: a good share of pixels is covered, some are not.
    let covered = img.pixels().filter(|p| p[3] > 128).count();
    assert!(
        covered > 256 * 256 / 4 && covered < 256 * 256,
        "{covered} covered pixels"
    );
    let st: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
    for key in [
        "device",
        "variant",
        "width",
        "height",
        "method",
        "gpu_ms",
        "wall_ms",
        "function_evaluations",
        "rays",
    ] {
        assert!(st.get(key).is_some(), "stats lack '{key}': {st}");
    }
    assert_eq!(st["rays"], 65536);
    assert_eq!(st["method"], "fixed");
    assert!(st["function_evaluations"].as_u64().expect("count") > 65536);
    assert!(st["gpu_ms"]["raycast"].as_f64().expect("ms") > 0.0);
    // The default scene takes the fast path (resample = "auto") with Hermite intervals.
    assert_eq!(
        st["variant"],
        "raycast:linear-wendland-local-grid-fixed-hermite-resample2"
    );
    assert!(
        st["table_lengths_world"]
            .as_array()
            .is_some_and(|l| !l.is_empty())
    );
}

#[test]
fn exr_output_is_linear_float_rgba_and_set_overrides_apply() {
    let d = dir("exr");
    let exr = d.join("ml.exr");
    let out = vmls(&[
        "render",
        "-o",
        s(&exr),
        "--set",
        "camera.width=40",
        "--set",
        "camera.height=30",
        "--set",
        "render.background=[0.0, 0.0, 1.0]",
        "--set",
        "reconstruction.neighbours=octree",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&exr).expect("exr").to_rgba32f();
    assert_eq!(img.dimensions(), (40, 30));
    // A corner ray misses the volume: pure background, alpha 0.
    let corner = img.get_pixel(0, 0);
    assert_eq!(corner.0, [0.0, 0.0, 1.0, 0.0]);
    assert!(
        img.pixels()
            .all(|p| p.0.iter().all(|v| v.is_finite()) && (0.0..=1.0).contains(&p[3]))
    );
}

#[test]
fn scene_file_with_relative_volume_path() {
    let d = dir("scene");
    let n = 6;
    let mut vtk = format!(
        "# vtk DataFile Version 3.0\nramp\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS {n} {n} {n}\nSPACING 0.4 0.4 0.4\nORIGIN -1 -1 -1\nPOINT_DATA {}\nSCALARS density float 1\nLOOKUP_TABLE default\n",
        n * n * n
    );
    for k in 0..n {
        for _ in 0..n * n {
            vtk.push_str(&format!("{}\n", k as f32 / (n - 1) as f32));
        }
    }
    std::fs::create_dir_all(d.join("data")).expect("dir");
    std::fs::write(d.join("data/ramp.vtk"), vtk).expect("write");
    std::fs::write(
        d.join("scene.toml"),
        "[volume]\nfile = \"data/ramp.vtk\"\nscalars = \"density\"\n[camera]\nwidth = 16\nheight = 16\n",
    )
    .expect("write");
    let png = d.join("out.png");
    let out = vmls(&["render", s(&d.join("scene.toml")), "-o", s(&png)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(png.exists());
}

#[test]
fn bad_inputs_fail_with_one_clear_line() {
    let d = dir("bad");
    let png = d.join("never.png");
    let write = |name: &str, text: &str| {
        let p = d.join(name);
        std::fs::write(&p, text).expect("write");
        p
    };
    // Missing scene file.
    let missing = d.join("nope.toml");
    assert_fails(
        &vmls(&["render", s(&missing), "-o", s(&png)]),
        &["nope.toml", "cannot read"],
        &png,
    );
    // Malformed TOML.
    let p = write("broken.toml", "[camera\nwidth = 3\n");
    assert_fails(
        &vmls(&["render", s(&p), "-o", s(&png)]),
        &["broken.toml", "TOML"],
        &png,
    );
    // Unknown key and unknown section.
    let p = write("key.toml", "[camera]\ncolour = 3\n");
    assert_fails(
        &vmls(&["render", s(&p), "-o", s(&png)]),
        &["camera.colour", "fov_y"],
        &png,
    );
    let p = write("section.toml", "[lights]\non = true\n");
    assert_fails(&vmls(&["render", s(&p), "-o", s(&png)]), &["lights"], &png);
    // Out-of-range value and wrong type.
    let p = write("range.toml", "[camera]\nfov_y = 200.0\n");
    assert_fails(
        &vmls(&["render", s(&p), "-o", s(&png)]),
        &["camera.fov_y", "200"],
        &png,
    );
    let p = write("type.toml", "[render]\nstep = \"small\"\n");
    assert_fails(
        &vmls(&["render", s(&p), "-o", s(&png)]),
        &["render.step", "a number"],
        &png,
    );
    let p = write("choice.toml", "[reconstruction]\nbasis = \"cubic\"\n");
    assert_fails(
        &vmls(&["render", s(&p), "-o", s(&png)]),
        &["reconstruction.basis", "\"linear\""],
        &png,
    );
    let p = write(
        "tf.toml",
        "[transfer]\npoints = [[0.5, 1, 1, 1, 1], [0.2, 1, 1, 1, 1]]\n",
    );
    assert_fails(
        &vmls(&["render", s(&p), "-o", s(&png)]),
        &["transfer.points", "point 1"],
        &png,
    );
    let p = write(
        "cam.toml",
        "[camera]\neye = [0, 0, 1]\ntarget = [0, 0, 0]\nup = [0, 0, 1]\n",
    );
    assert_fails(
        &vmls(&["render", s(&p), "-o", s(&png)]),
        &["camera", "parallel"],
        &png,
    );
    // Bad --set arguments.
    assert_fails(
        &vmls(&["render", "-o", s(&png), "--set", "camera.width"]),
        &["--set camera.width"],
        &png,
    );
    assert_fails(
        &vmls(&["render", "-o", s(&png), "--set", "camera.width=0"]),
        &["camera.width"],
        &png,
    );
    assert_fails(
        &vmls(&["render", "-o", s(&png), "--set", "camera.zoom=2"]),
        &["camera.zoom"],
        &png,
    );
    // The keys that take true, false or "auto".
    for key in ["render.skip", "render.exact_opacity"] {
        assert_fails(
            &vmls(&[
                "render",
                "-o",
                s(&png),
                "--set",
                &format!("{key}=\"maybe\""),
            ]),
            &[key, "true, false or \"auto\"", "\"maybe\""],
            &png,
        );
    }
    // Unsupported output format.
    let jpg = d.join("out.jpg");
    assert_fails(
        &vmls(&["render", "-o", s(&jpg)]),
        &["out.jpg", ".png or .exr"],
        &jpg,
    );
    // Missing volume file, and a volume with a NaN.
    let p = write("vol.toml", "[volume]\nfile = \"absent.vtk\"\n");
    assert_fails(
        &vmls(&["render", s(&p), "-o", s(&png)]),
        &["absent.vtk"],
        &png,
    );
    write(
        "nan.vtk",
        "# vtk DataFile Version 3.0\nx\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 2 2\nSPACING 1 1 1\nORIGIN 0 0 0\nPOINT_DATA 8\nSCALARS v float 1\nLOOKUP_TABLE default\n0 1 2 nan 4 5 6 7\n",
    );
    let p = write("nan.toml", "[volume]\nfile = \"nan.vtk\"\n");
    assert_fails(
        &vmls(&["render", s(&p), "-o", s(&png)]),
        &["nan.vtk", "NaN"],
        &png,
    );
    // No such device.
    assert_fails(
        &vmls(&["render", "-o", s(&png), "--device", "no-such-gpu"]),
        &["no-such-gpu", "llvmpipe"],
        &png,
    );
}

#[test]
fn devices_lists_lavapipe() {
    let out = vmls(&["devices"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("* 0:"), "{text}");
}

#[test]
fn compare_reports_rmse_and_rejects_size_mismatch() {
    let d = dir("compare");
    let (a, b, c) = (d.join("a.exr"), d.join("b.exr"), d.join("c.exr"));
    let small = ["--set", "camera.width=12", "--set", "camera.height=10"];
    let mut args = vec!["render", "-o", s(&a)];
    args.extend(small);
    assert!(vmls(&args).status.success());
    let mut args = vec![
        "render",
        "-o",
        s(&b),
        "--set",
        "render.background=[1.0, 0.0, 0.0]",
    ];
    args.extend(small);
    assert!(vmls(&args).status.success());
    let same = vmls(&["compare", s(&a), s(&a)]);
    assert_eq!(
        String::from_utf8_lossy(&same.stdout).trim(),
        "rmse 0.0000e0 max 0.0000e0 at (0, 0) psnr inf dB p99-rgba 0.0000e0"
    );
    // The red background shows through transmittance T in the red channel only.
    let heat = d.join("diff.png");
    let out = vmls(&["compare", s(&a), s(&b), "--diff", s(&heat)]);
    let img = image::open(&heat).expect("diff heat map");
    assert_eq!((img.width(), img.height()), (12, 10));
    let text = String::from_utf8_lossy(&out.stdout);
    let max: f64 = text
        .split_whitespace()
        .nth(3)
        .and_then(|v| v.parse().ok())
        .expect("max");
    assert!(max > 0.9 && max <= 1.0, "{text}");
    assert!(
        vmls(&[
            "render",
            "-o",
            s(&c),
            "--set",
            "camera.width=5",
            "--set",
            "camera.height=5"
        ])
        .status
        .success()
    );
    let bad = vmls(&["compare", s(&a), s(&c)]);
    assert_fails(&bad, &["a.exr", "differs"], &d.join("none.png"));
}

#[test]
fn eval_map_is_a_heat_map_with_a_legend() {
    let d = dir("evalmap");
    let (img, map, st) = (d.join("i.png"), d.join("evals.png"), d.join("s.json"));
    let render = |map: &std::path::Path| {
        let out = vmls(&[
            "render",
            "-o",
            s(&img),
            "--eval-map",
            s(map),
            "--stats",
            s(&st),
            "--set",
            "camera.width=32",
            "--set",
            "camera.height=24",
            "--set",
            "render.method=\"adaptive\"",
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let stats: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&st).expect("stats")).expect("json");
        stats
    };
    let stats = render(&map);
    let m = image::open(&map).expect("map").to_rgb8();
    // The image plus a 22-pixel legend strip.
    assert_eq!(m.dimensions(), (32, 24 + 22));
    // Rays that miss the volume cost nothing: the darkest ramp colour in the corner.
    assert_eq!(m.get_pixel(0, 0).0, [68, 1, 84]);
    assert!(stats["evaluations_per_ray"].as_f64().expect("mean") > 0.0);
    // The counts themselves to an EXR: they sum to the frame's evaluations, and a ray that
    // misses the volume counts 0.
    let counts = d.join("evals.exr");
    let stats = render(&counts);
    let c = image::open(&counts).expect("counts").to_rgba32f();
    assert_eq!(c.dimensions(), (32, 24));
    assert_eq!(c.get_pixel(0, 0).0, [0.0, 0.0, 0.0, 1.0]);
    let sum: f64 = c.pixels().map(|p| f64::from(p.0[0])).sum();
    assert_eq!(
        sum,
        stats["function_evaluations"].as_f64().expect("evaluations")
    );
    assert!(sum > 0.0 && c.pixels().all(|p| p.0[0].fract() == 0.0));
    let bad = d.join("evals.jpg");
    assert_fails(
        &vmls(&["render", "-o", s(&img), "--eval-map", s(&bad)]),
        &["evals.jpg", ".png", ".exr"],
        &bad,
    );
}

#[test]
fn irregular_files_render_and_info_describes_them() {
    let fixture = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/xml/vtu_binary_zlib.vtu"
    );
    let out = vmls(&["info", fixture]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for needle in [
        "kind: unstructured mesh",
        "points: 21",
        "cells: 5 (hexahedron: 1, pyramid: 1, tetra: 1, voxel: 1, wedge: 1)",
        "cell_id (cell data",
        "boundary: ",
        "supports: isotropic",
        "octree: ",
    ] {
        assert!(text.contains(needle), "info lacks '{needle}':\n{text}");
    }
    // Cell data is sampled at the centroids, and says so.
    let out = vmls(&["info", fixture, "--array", "cell_id"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("samples: 5 (array 'cell_id' sampled at cell centroids)"),
        "{text}"
    );

    let d = dir("irregular");
    let png = d.join("mesh.png");
    let stats = d.join("stats.json");
    let file_key = format!("volume.file=\"{fixture}\"");
    let out = vmls(&[
        "render",
        "-o",
        s(&png),
        "--stats",
        s(&stats),
        "--set",
        &file_key,
        "--set",
        "camera.width=32",
        "--set",
        "camera.height=24",
        "--frames",
        "2",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(png.exists());
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
    assert_eq!(json["data"]["kind"], "unstructured mesh");
    assert_eq!(json["data"]["sampled_at"], "points");
    assert_eq!(json["neighbours"], "octree");
    assert!(
        json["variant"]
            .as_str()
            .is_some_and(|v| v.contains("-hull")),
        "{json}"
    );
    // "auto" takes the fast path on a mesh (a lattice over its box): 135 fine points here,
    // fewer than the first frame's solves.
    assert_eq!(json["fast_path"]["factor"], 2, "{json}");
    let frames = json["frames"].as_array().expect("frames");
    assert_eq!(frames.len(), 2);
    assert_eq!(frames[1]["tables_built"], false);
    assert_eq!(frames[1]["pipeline_built"], false);
    assert!(json["octree"]["references"].as_u64().is_some_and(|r| r > 0));

    // A malformed mesh: one clear line naming the file, no image.
    let bad = d.join("bad.vtk");
    std::fs::write(
        &bad,
        "# vtk DataFile Version 4.2\nbad\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n\
         0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 1 5\n4 0 1 2 7\nCELL_TYPES 1\n10\n",
    )
    .expect("write");
    let png = d.join("bad.png");
    let bad_key = format!("volume.file=\"{}\"", s(&bad));
    let out = vmls(&["render", "-o", s(&png), "--set", &bad_key]);
    assert_fails(&out, &["bad.vtk", "cell 0", "point 7"], &png);
    let out = vmls(&["info", s(&bad)]);
    assert_eq!(out.status.code(), Some(1));
}

#[test]
fn splatting_from_the_command_line() {
    let d = dir("splat");
    let (img, st, map) = (d.join("s.png"), d.join("s.json"), d.join("m.png"));
    let size = ["--set", "camera.width=24", "--set", "camera.height=16"];
    let mut args = vec![
        "render",
        "-o",
        s(&img),
        "--stats",
        s(&st),
        "--set",
        "render.method=\"splat-post\"",
        "--set",
        "volume.resolution=9",
    ];
    args.extend(size);
    let out = vmls(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&st).expect("stats")).expect("json");
    assert_eq!(stats["method"], "splat-post");
    assert_eq!(stats["splat"]["kernels_projected"], 729);
    assert!(stats["gpu_ms"]["splat_raster"].as_f64().expect("ms") > 0.0);
    // Every bucket put in kernel order: the frame is reproducible to the bit.
    assert_eq!(stats["splat"]["buckets_unordered"], 0);
    assert!(stats["splat"]["buckets_heapsorted"].as_u64().is_some());
    assert!(stats["gpu_ms"]["splat_order"].as_f64().expect("ms") > 0.0);
    assert!(
        stats["variant"]
            .as_str()
            .expect("variant")
            .contains("post-shaded")
    );

    // No evaluation map for splats, and nothing written.
    let mut bad = vec!["render", "-o", s(&img), "--eval-map", s(&map)];
    bad.extend(["--set", "render.method=\"splat\""]);
    assert_fails(&vmls(&bad), &["--eval-map", "splat"], &map);

    // The f64 CPU twins: the Gaussian field's reference image, and the twin's evaluations in
    // --stats, which the midpoint rule makes equal to the kernel's.
    let cpu = d.join("ref.png");
    let cpu_stats = d.join("ref.json");
    let twin = [
        "--set",
        "reconstruction.method=\"gaussian\"",
        "--set",
        "render.method=\"reference\"",
        "--set",
        "volume.resolution=9",
    ];
    let mut args = vec!["render", "--cpu", "-o", s(&cpu), "--stats", s(&cpu_stats)];
    args.extend(twin);
    args.extend(size);
    let out = vmls(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        image::open(&cpu).expect("png").to_rgba8().dimensions(),
        (24, 16)
    );
    let gpu_stats = d.join("gpu.json");
    let mut args = vec!["render", "-o", s(&img), "--stats", s(&gpu_stats)];
    args.extend(twin);
    args.extend(size);
    assert!(vmls(&args).status.success());
    let read = |p: &std::path::Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p).expect("stats")).expect("json")
    };
    let (c, g) = (read(&cpu_stats), read(&gpu_stats));
    assert_eq!(c["device"], "cpu (f64 reference twins)");
    let twin_evaluations = c["function_evaluations"]
        .as_u64()
        .expect("twin's evaluations");
    assert!(twin_evaluations > 0);
    assert_eq!(Some(twin_evaluations), g["function_evaluations"].as_u64());
}

#[cfg(unix)]
#[test]
fn the_cli_helper_fails_on_validation_messages_and_leak_reports() {
    // What the library prints (vk::context): each must fail a CLI test whatever the status.
    use std::os::unix::process::ExitStatusExt;
    let run = |stderr: &str| {
        let out = std::process::Output {
            status: std::process::ExitStatus::from_raw(0),
            stdout: Vec::new(),
            stderr: stderr.as_bytes().to_vec(),
        };
        std::panic::catch_unwind(|| common::cli::assert_clean(&out)).is_err()
    };
    assert!(!run("vmls: wrote x.png\n"));
    for line in [
        "vmls: Vulkan validation error: VUID-vkCmdDispatch-None-02699\n",
        "vmls: Vulkan validation warning: UNASSIGNED-BestPractices\n",
        "vmls: leak report: 2 GPU allocation(s) still alive at shutdown\n",
    ] {
        assert!(run(line), "passed: {line}");
    }
}
