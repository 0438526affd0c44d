//! Hostile and degenerate input end to end (issue 12): outputs that could clobber a file,
//! inputs that are not regular files, hostile text in error messages, images holding NaN,
//! values that would set unbounded work. Each test asserts the exit code, the one error line
//! and the files left on disk.

mod common;

use common::cli::{assert_fails, dir, s, vmls};
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn data(rel: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(rel)
}

/// A small render of the built-in scene: 8×8 pixels.
const SMALL: [&str; 4] = ["--set", "camera.width=8", "--set", "camera.height=8"];

fn render(args: &[&str]) -> Output {
    let mut all = vec!["render"];
    all.extend_from_slice(args);
    all.extend_from_slice(&SMALL);
    vmls(&all)
}

/// Runs vmls, killing it after `limit`: a hang fails the test instead of stalling the suite.
fn vmls_within(args: &[&str], limit: Duration) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_vmls"))
        .args(args)
        .env("VMLS_VALIDATION", "1")
        .env_remove("VMLS_DEVICE")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run vmls");
    let start = Instant::now();
    while child.try_wait().expect("wait").is_none() {
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("vmls {args:?} still ran after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = child.wait_with_output().expect("output");
    common::cli::assert_clean(&out);
    out
}

/// The names in `d`, sorted (hidden temporaries included).
fn listing(d: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(d)
        .expect("read_dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[cfg(unix)]
#[test]
fn planted_symlinks_redirect_no_output() {
    use std::os::unix::fs::symlink;
    let d = dir("symlinks");
    let victim = d.join("victim.txt");
    std::fs::write(&victim, "keep").expect("write");
    // Links at every fixed name a writer might pick: the targets' old `.NAME.partial`
    // temporaries, and `NAME.tmp`/`NAME~` for good measure.
    for name in ["out.png", "stats.json", "map.png"] {
        for planted in [
            format!(".{name}.partial"),
            format!("{name}.tmp"),
            format!("{name}~"),
        ] {
            symlink(&victim, d.join(planted)).expect("symlink");
        }
    }
    let (png, stats, map) = (d.join("out.png"), d.join("stats.json"), d.join("map.png"));
    let out = render(&["-o", s(&png), "--stats", s(&stats), "--eval-map", s(&map)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(std::fs::read_to_string(&victim).expect("victim"), "keep");
    // An output path that is itself a link is replaced, never written through.
    let link = d.join("link.png");
    symlink(&victim, &link).expect("symlink");
    assert!(render(&["-o", s(&link)]).status.success());
    assert_eq!(std::fs::read_to_string(&victim).expect("victim"), "keep");
    assert!(!std::fs::symlink_metadata(&link).expect("meta").is_symlink());
    assert!(image::open(&link).is_ok());
    // No temporary is left behind.
    assert!(
        listing(&d).iter().all(|n| !n.starts_with(".tmp")),
        "{:?}",
        listing(&d)
    );
}

#[test]
fn a_252_character_output_name_is_written() {
    let d = dir("long-name");
    let png = d.join(format!("{}.png", "n".repeat(248)));
    let out = render(&["-o", s(&png)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(image::open(&png).is_ok());
    assert_eq!(listing(&d).len(), 1, "{:?}", listing(&d));
}

#[test]
fn outputs_equal_to_inputs_or_each_other_are_refused_before_any_work() {
    let d = dir("same-file");
    let scene = d.join("scene.toml");
    let text = "[camera]\nwidth = 8\nheight = 8\n";
    std::fs::write(&scene, text).expect("write");
    let png = d.join("x.png");
    // --stats onto the scene, spelled another way.
    let other = format!("{}/./scene.toml", s(&d));
    assert_fails(
        &vmls(&["render", s(&scene), "-o", s(&png), "--stats", &other]),
        &["scene.toml (--stats)", "(scene)", "same file"],
        &png,
    );
    assert_eq!(std::fs::read_to_string(&scene).expect("scene"), text);
    // Two outputs naming one file.
    let again = format!(
        "{}/../{}/x.png",
        s(&d),
        d.file_name().and_then(|n| n.to_str()).expect("name")
    );
    assert_fails(
        &vmls(&["render", s(&scene), "-o", s(&png), "--eval-map", &again]),
        &["(--eval-map)", "(-o)", "another output"],
        &png,
    );
    // An image output that is a hard link to the volume file.
    let volume = d.join("v.vtk");
    std::fs::copy(data("legacy/image-42-binary.vtk"), &volume).expect("copy");
    let before = std::fs::read(&volume).expect("volume");
    let hard = d.join("hard.png");
    std::fs::hard_link(&volume, &hard).expect("hard link");
    let set = format!("volume.file={}", s(&volume));
    let out = vmls(&["render", "-o", s(&hard), "--set", &set]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("hard.png (-o)") && stderr.contains("(volume.file)"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(&volume).expect("volume"), before);
    #[cfg(unix)]
    {
        // A symlink to the scene as --stats.
        let link = d.join("stats.json");
        std::os::unix::fs::symlink(&scene, &link).expect("symlink");
        assert_fails(
            &vmls(&["render", s(&scene), "-o", s(&png), "--stats", s(&link)]),
            &["stats.json (--stats)", "(scene)"],
            &png,
        );
        assert_eq!(std::fs::read_to_string(&scene).expect("scene"), text);
    }
    // compare --diff onto one of its inputs.
    assert!(render(&["-o", s(&png)]).status.success());
    let out = vmls(&["compare", s(&png), s(&png), "--diff", s(&png)]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("(--diff)"));
    assert!(image::open(&png).is_ok());
}

#[test]
fn outputs_are_all_or_nothing() {
    let d = dir("all-or-nothing");
    let png = d.join("x.png");
    for stats in [d.join("missing/stats.json"), d.clone()] {
        let out = render(&["-o", s(&png), "--stats", s(&stats)]);
        assert_fails(&out, &["stats"], &png);
    }
    #[cfg(unix)]
    {
        // A directory where the eval map should go cannot take a temporary: nothing lands.
        use std::os::unix::fs::PermissionsExt;
        let ro = d.join("ro");
        std::fs::create_dir(&ro).expect("mkdir");
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).expect("chmod");
        let probe = ro.join("probe");
        // Root ignores directory permissions, so as root this case is said to be skipped; the
        // next one stops root too.
        if std::fs::write(&probe, b"").is_err() {
            let map = ro.join("map.png");
            assert_fails(
                &render(&["-o", s(&png), "--eval-map", s(&map)]),
                &["map.png"],
                &png,
            );
        } else {
            eprintln!("outputs_are_all_or_nothing: running as root, the read-only case is skipped");
        }
        let _ = std::fs::remove_file(&probe);
    }
    // A regular file where the eval map's directory should be: no temporary can be made there,
    // for any user.
    let blocker = d.join("blocker");
    std::fs::write(&blocker, b"not a directory").expect("write");
    let map = blocker.join("map.png");
    assert_fails(
        &render(&["-o", s(&png), "--eval-map", s(&map)]),
        &["map.png"],
        &png,
    );
    std::fs::remove_file(&blocker).expect("rm");
    assert_eq!(listing(&d), ["ro"], "{:?}", listing(&d));
}

#[cfg(unix)]
#[test]
fn inputs_that_are_not_regular_files_are_refused() {
    let d = dir("not-regular");
    let png = d.join("x.png");
    let fifo = d.join("pipe.toml");
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .expect("mkfifo")
            .success()
    );
    let fifo_volume = d.join("pipe.nrrd");
    assert!(
        Command::new("mkfifo")
            .arg(&fifo_volume)
            .status()
            .expect("mkfifo")
            .success()
    );
    let zero = d.join("zero.vtk");
    std::os::unix::fs::symlink("/dev/zero", &zero).expect("symlink");
    let folder = d.join("folder.nrrd");
    std::fs::create_dir(&folder).expect("mkdir");
    let limit = Duration::from_secs(60);
    let with_volume = |p: &Path| -> Vec<String> {
        let set = format!("volume.file={}", s(p));
        ["render", "-o", s(&png), "--set", &set]
            .map(String::from)
            .to_vec()
    };
    let cases: [(Vec<String>, &str); 4] = [
        (
            ["render", s(&fifo), "-o", s(&png)]
                .map(String::from)
                .to_vec(),
            "FIFO",
        ),
        (with_volume(&fifo_volume), "FIFO"),
        (with_volume(&zero), "character device"),
        (vec!["info".into(), s(&folder).into()], "directory"),
    ];
    for (args, what) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = vmls_within(&args, limit);
        assert_fails(&out, &[what, "expected a regular file"], &png);
    }
    // `compare` judges the extension first (tests/paraview_files.rs), then what the file is.
    let zero_png = d.join("zero.png");
    std::os::unix::fs::symlink("/dev/zero", &zero_png).expect("symlink");
    let out = vmls_within(&["compare", s(&zero_png), s(&zero_png)], limit);
    assert_fails(&out, &["character device"], &png);
}

#[test]
fn error_messages_quote_short_escaped_excerpts() {
    let d = dir("excerpts");
    let png = d.join("x.png");
    let check = |out: &Output| {
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(
            !stderr.trim_end().chars().any(|c| c.is_control()),
            "{stderr:?}"
        );
        assert!(stderr.len() < 2100, "{} bytes of error", stderr.len());
        assert!(!png.exists());
    };
    let escape = "\u{1b}[2J\u{1b}]0;pwned\u{7}";
    // A scene key, a scene value and a --set argument carrying terminal escapes.
    let scene = d.join("s.toml");
    std::fs::write(&scene, format!("[camera]\n\"{escape}\" = 1\n")).expect("write");
    check(&vmls(&["render", s(&scene), "-o", s(&png)]));
    std::fs::write(
        &scene,
        format!("[render]\nmethod = \"{escape}{}\"\n", "m".repeat(3_000_000)),
    )
    .expect("write");
    check(&vmls(&["render", s(&scene), "-o", s(&png)]));
    check(&vmls(&[
        "render",
        "-o",
        s(&png),
        "--set",
        &format!("{escape}{}", "k".repeat(100_000)),
    ]));
    // A VTK header line of megabytes with escapes in it.
    let vtk = d.join("v.vtk");
    let mut bytes = b"# vtk DataFile Version 3.0\ntitle\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 2 2\nSPACING 1 1 1\nORIGIN 0 0 0\nPOINT_DATA 8\nSCALARS f float\n".to_vec();
    bytes.extend_from_slice(escape.as_bytes());
    bytes.extend(std::iter::repeat_n(b'x', 4_000_000));
    bytes.push(b'\n');
    std::fs::write(&vtk, &bytes).expect("write");
    check(&vmls(&[
        "render",
        "-o",
        s(&png),
        "--set",
        &format!("volume.file={}", s(&vtk)),
    ]));
    // A CSV with a hostile header and field.
    let csv = d.join("p.csv");
    std::fs::write(
        &csv,
        format!("x,y,z,{escape}\n0,0,0,{escape}{}\n", "1".repeat(1_000_000)),
    )
    .expect("write");
    check(&vmls(&[
        "render",
        "-o",
        s(&png),
        "--set",
        &format!("volume.file={}", s(&csv)),
    ]));
}

#[test]
fn set_volume_file_without_a_scene_replaces_the_generator() {
    let d = dir("set-file");
    let png = d.join("x.png");
    let stats = d.join("stats.json");
    let set = format!("volume.file={}", s(&data("legacy/image-42-binary.vtk")));
    let out = render(&["-o", s(&png), "--stats", s(&stats), "--set", &set]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(image::open(&png).is_ok());
    // The file's 3 × 4 × 2 points were rendered, not the generator's 41³.
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
    assert_eq!(json["data"]["kind"], "regular grid", "{json}");
    assert_eq!(json["data"]["samples"], 24, "{json}");
}

#[test]
fn compare_counts_non_finite_pixels_and_fails() {
    let d = dir("compare-nan");
    let (a, b, diff) = (d.join("a.exr"), d.join("b.exr"), d.join("diff.png"));
    let mut pixels = vec![0.5f32; 4 * 4 * 4];
    image::Rgba32FImage::from_raw(4, 4, pixels.clone())
        .expect("image")
        .save(&b)
        .expect("save");
    pixels[5] = f32::NAN;
    pixels[20] = f32::INFINITY;
    image::Rgba32FImage::from_raw(4, 4, pixels)
        .expect("image")
        .save(&a)
        .expect("save");
    let out = vmls(&["compare", s(&a), s(&b), "--diff", s(&diff)]);
    assert_fails(
        &out,
        &["2 pixel(s) with a non-finite channel", "a.exr"],
        &diff,
    );
    assert!(!String::from_utf8_lossy(&out.stdout).contains("NaN"));
}

/// Asserts a quick failure naming every needle, with nothing written.
fn refused_quickly(args: &[&str], needles: &[&str], png: &Path) {
    let out = vmls_within(args, Duration::from_secs(120));
    assert_fails(&out, needles, png);
}

#[test]
fn keys_that_set_work_or_memory_are_range_checked_by_name() {
    let d = dir("ranges");
    let png = d.join("x.png");
    let cases: &[(&str, &[&str])] = &[
        ("render.step=1e-5", &["render.step", "[0.001, 1000]"]),
        ("render.step=1e-9", &["render.step"]),
        ("render.reference_step=0", &["render.reference_step"]),
        ("render.l_min=1e-9", &["render.l_min"]),
        ("render.l_max=1e9", &["render.l_max"]),
        ("render.epsilon=-1", &["render.epsilon"]),
        ("render.table_resolution=1", &["render.table_resolution"]),
        (
            "render.table_resolution=100000",
            &["render.table_resolution"],
        ),
        ("camera.width=100000", &["camera.width"]),
        ("splat.band_rows=0", &["splat.band_rows", "1 to 4096"]),
        ("splat.pixels=3", &["splat.pixels", "1, 2, 4 or 8"]),
        ("camera.eye=[1e308, 0, 0]", &["camera.eye", "1e15"]),
        ("camera.target=[0, 0, -1e300]", &["camera.target"]),
        (
            "render.background=[1e308, 0, 0]",
            &["render.background", "1e6"],
        ),
        ("render.background=[nan, 0, 0]", &["render.background"]),
        (
            "transfer.points=[[0, 0, 0, 0, 0], [1e38, 1, 1, 1, 1]]",
            &["transfer.points", "1e30"],
        ),
        (
            "transfer.points=[[0, 0, 0, 0, 1e300]]",
            &["transfer.points"],
        ),
        (
            "transfer.isosurfaces=[{ value = 1e35 }]",
            &["transfer.isosurfaces"],
        ),
    ];
    for (set, needles) in cases {
        refused_quickly(&["render", "-o", s(&png), "--set", set], needles, &png);
    }
    // The image's pixel count, beyond each side's own range.
    refused_quickly(
        &[
            "render",
            "-o",
            s(&png),
            "--set",
            "camera.width=16384",
            "--set",
            "camera.height=16384",
        ],
        &["camera.width × camera.height", "67108864"],
        &png,
    );
    // A transfer function of 10 000 points (it took over a minute).
    let points: Vec<String> = (0..10_000)
        .map(|i| format!("[{}, 1, 1, 1, 1]", f64::from(i) / 1e4))
        .collect();
    let scene = d.join("tf.toml");
    std::fs::write(
        &scene,
        format!("[transfer]\npoints = [{}]\n", points.join(", ")),
    )
    .expect("write");
    refused_quickly(
        &["render", s(&scene), "-o", s(&png)],
        &["transfer.points", "at most 1024 points (found 10000)"],
        &png,
    );
    // Table resolutions the scene allows but the device cannot bind name the key and the
    // largest this device takes.
    refused_quickly(
        &[
            "render",
            "-o",
            s(&png),
            "--set",
            "render.table_resolution=4096",
        ],
        &[
            "render.table_resolution",
            "expected at most",
            "maxTexelBufferElements",
        ],
        &png,
    );
    // A step the f32 ray parameter cannot resolve at the eye's distance.
    refused_quickly(
        &["render", "-o", s(&png), "--set", "camera.eye=[1e14, 0, 0]"],
        &["render.step", "f32 resolution", "camera.eye"],
        &png,
    );
    // probe's counts.
    for arg in ["--points=0", "--repeats=0", "--resolution=1"] {
        let out = vmls(&["probe", arg]);
        assert_eq!(out.status.code(), Some(2), "probe {arg}");
    }
}

/// `vmls render -o png --set a --set b …`.
fn render_with<'a>(png: &'a Path, sets: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec!["render", "-o", s(png)];
    for set in sets {
        args.extend(["--set", set]);
    }
    args
}

#[test]
fn the_work_budget_refuses_and_force_lifts_it() {
    let d = dir("budget");
    let png = d.join("x.png");
    // 1024² rays at a step of 0.01 spacings plan 7e9 evaluations; the camera looks away
    // from the volume, so that the forced render is quick although the bound is not.
    let args = render_with(
        &png,
        &[
            "render.step=0.01",
            "camera.width=1024",
            "camera.height=1024",
            "camera.target=[60, 40, 50]",
        ],
    );
    refused_quickly(&args, &["work budget", "render.step", "--force"], &png);
    let mut forced = args.clone();
    forced.push("--force");
    let out = vmls_within(&forced, Duration::from_secs(300));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(png.exists());
}

#[test]
fn splatting_checks_its_budget_before_accumulating() {
    let d = dir("splat-budget");
    let png = d.join("x.png");
    // 764 sheets over 4096² pixels in 8² tiles: 2·10⁸ (tile, sheet) buckets, past the
    // counting sort's limit; refused by the key at fault before any work.
    let buckets = [
        "render.method=\"splat\"",
        "camera.width=4096",
        "camera.height=4096",
        "splat.slab=0.1",
        "splat.tile=8",
    ];
    refused_quickly(
        &render_with(&png, &buckets),
        &["splat.slab", "(tile, sheet) buckets", "splat.tile"],
        &png,
    );
    // Left to choose, the tile grows to 32² where the buckets fit, and the sheets alone are
    // past the work budget.
    let sheets = [
        "render.method=\"splat\"",
        "camera.width=4096",
        "camera.height=4096",
        "splat.slab=0.1",
    ];
    refused_quickly(
        &render_with(&png, &sheets),
        &[
            "work budget",
            "footprint-pixel evaluations",
            "sheets of 4096 × 4096",
            "splat.slab",
            "--force",
        ],
        &png,
    );
    // 100³ kernels over thin sheets bin some 10⁸ (tile, sheet) footprints into a 64² image:
    // known only after the projection, refused before the rasterization.
    let blocks = [
        "render.method=\"splat\"",
        "volume.resolution=100",
        "splat.slab=0.05",
        "splat.split=true",
        "camera.width=64",
        "camera.height=64",
    ];
    refused_quickly(
        &render_with(&png, &blocks),
        &["work budget", "binned (tile, sheet) footprints", "--force"],
        &png,
    );
}

#[test]
fn the_bench_checks_the_budget_of_the_reference_and_each_configuration() {
    let d = dir("bench-budget");
    let out = d.join("out");
    let results = out.join("results.csv");
    let bench = |extra: &[&'static str]| {
        let mut args = vec![
            "bench",
            "--methods",
            "fixed",
            "--repeat",
            "1",
            "--warmup",
            "0",
            "--no-cache",
            "--no-ceilings",
            "--out",
            s(&out),
            // Looking away from the volume: a forced run is quick although the bound is not.
            "--set",
            "camera.width=1024",
            "--set",
            "camera.height=1024",
            "--set",
            "camera.target=[60, 40, 50]",
        ];
        args.extend(extra);
        args
    };
    let reference = bench(&["--reference-set", "render.reference_step=0.01"]);
    refused_quickly(
        &reference,
        &[
            "the reference",
            "work budget",
            "render.reference_step",
            "--force",
        ],
        &results,
    );
    let config = bench(&[
        "--reference-set",
        "render.reference_step=2",
        "--set",
        "render.step=0.01",
    ]);
    refused_quickly(
        &config,
        &["configuration 0", "work budget", "render.step", "--force"],
        &results,
    );
    let mut forced = config.clone();
    forced.push("--force");
    let run = vmls_within(&forced, Duration::from_secs(300));
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(results.exists());
}

#[test]
fn out_of_memory_at_any_allocation_fails_cleanly_and_writes_nothing() {
    let d = dir("oom");
    let (png, stats) = (d.join("x.png"), d.join("stats.json"));
    let run = |env: &str, method: &str| {
        let out = Command::new(env!("CARGO_BIN_EXE_vmls"))
            .args(["render", "-o", s(&png), "--stats", s(&stats), "--set"])
            .arg(format!("render.method=\"{method}\""))
            .args(SMALL)
            // Ray casting with the fast path's buffers too ("auto" declines it at 8×8).
            .args(if method == "fixed" {
                &["--set", "reconstruction.resample=2"][..]
            } else {
                &[]
            })
            .env("VMLS_VALIDATION", "1")
            .env_remove("VMLS_DEVICE")
            .env(vmls::vk::FAIL_ALLOCATIONS_VAR, env)
            .output()
            .expect("run vmls");
        common::cli::assert_clean(&out);
        out
    };
    // The first allocation (the upload), early and late ones of the first frame.
    for method in ["fixed", "splat"] {
        for n in ["0", "2", "5", "9"] {
            let out = run(n, method);
            assert_fails(&out, &["out of GPU memory", "buffer '"], &png);
            assert_eq!(
                listing(&d),
                Vec::<String>::new(),
                "{method}, {n}: files left"
            );
        }
    }
    let out = run("many", "fixed");
    assert_fails(&out, &["VMLS_FAIL_ALLOCATIONS_AFTER", "\"many\""], &png);
    // Far enough: every allocation succeeds.
    let out = run("1000", "fixed");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(png.exists() && stats.exists());
}

/// Writes a little-endian float NRRD of `dims` with `values`, or extra header lines.
fn nrrd(path: &Path, dims: [usize; 3], extra: &str, values: &[f32]) {
    let mut bytes = format!(
        "NRRD0004\ntype: float\ndimension: 3\nsizes: {} {} {}\n{extra}endian: little\nencoding: raw\n\n",
        dims[0], dims[1], dims[2]
    )
    .into_bytes();
    for v in values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(path, bytes).expect("write");
}

#[test]
fn geometry_and_values_beyond_f32_or_without_volume_are_refused_by_name() {
    let d = dir("geometry");
    let png = d.join("x.png");
    let ramp: Vec<f32> = (0..64).map(|i| i as f32 / 63.0).collect();
    let file = |name: &str| d.join(name);
    let set = |p: &Path| format!("volume.file={}", s(p));
    let cases: Vec<(std::path::PathBuf, Vec<&str>)> = vec![
        {
            let p = file("spacing.nrrd");
            nrrd(&p, [4, 4, 4], "spacings: 1e308 1 1\n", &ramp);
            (p, vec!["spacing.nrrd", "extent along x", "1e15"])
        },
        {
            let p = file("flat.nrrd");
            nrrd(&p, [8, 8, 1], "", &ramp);
            (
                p,
                vec!["flat.nrrd", "grid dimensions [8, 8, 1]", "1 along z"],
            )
        },
        {
            let p = file("huge.nrrd");
            let mut v = ramp.clone();
            v[9] = 1e38;
            nrrd(&p, [4, 4, 4], "", &v);
            (
                p,
                vec!["huge.nrrd", "sample 9 (x=1, y=2, z=0)", "1e38", "±1e30"],
            )
        },
        {
            let p = file("negative.nrrd");
            let v: Vec<f32> = ramp.iter().map(|x| -1e38 * x).collect();
            nrrd(&p, [4, 4, 4], "", &v);
            (p, vec!["negative.nrrd", "sample 1", "±1e30"])
        },
        {
            let p = file("spacing.vtk");
            let mut text = String::from(
                "# vtk DataFile Version 3.0\nt\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 2 2\nSPACING 1e308 1 1\nORIGIN 0 0 0\nPOINT_DATA 8\nSCALARS f float\nLOOKUP_TABLE default\n",
            );
            text.push_str("0 1 2 3 4 5 6 7\n");
            std::fs::write(&p, text).expect("write");
            (p, vec!["spacing.vtk", "extent along x"])
        },
        {
            let p = file("origin.vtk");
            let text = "# vtk DataFile Version 3.0\nt\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 2 2\nSPACING 1 1 1\nORIGIN 0 0 1e300\nPOINT_DATA 8\nSCALARS f float\nLOOKUP_TABLE default\n0 1 2 3 4 5 6 7\n";
            std::fs::write(&p, text).expect("write");
            (p, vec!["origin.vtk", "extent along z"])
        },
        {
            let p = file("plane.csv");
            std::fs::write(&p, "x,y,z,v\n0,0,0,1\n1,0,0,2\n0,1,0,3\n1,1,0,4\n").expect("write");
            (p, vec!["plane.csv", "extent along z"])
        },
    ];
    for (p, needles) in &cases {
        refused_quickly(&["render", "-o", s(&png), "--set", &set(p)], needles, &png);
    }
}

/// Regression from fuzzing (`nifti_fields`): a constant field of 1e20 or beyond, within the
/// accepted ±1e30, gave the preintegration tables a scalar range of zero width (a margin below
/// f64's resolution at that magnitude) and the CPU twin rendered NaN. Now both renderers give
/// finite images that agree, and show the field where the transfer function makes it opaque.
#[test]
fn constant_fields_far_from_zero_render_finite_on_both_renderers() {
    use vmls::renderer::Renderer;
    use vmls::scene::Scene;
    let d = dir("constant");
    let (ctx, _) = common::gpu();
    for v in [1.0f32, 1e20, 1e30, -1e30] {
        let file = d.join("c.nrrd");
        nrrd(&file, [4, 4, 4], "", &[v; 64]);
        for covering in [false, true] {
            let mut set = vec![
                format!("volume.file={:?}", s(&file)),
                "camera.width=8".into(),
                "camera.height=8".into(),
            ];
            if covering {
                set.push("transfer.points=[[-1e30,0.2,0.4,0.6,0.5],[1e30,0.2,0.4,0.6,0.5]]".into());
            }
            let scene = Scene::load(None, &set).expect("scene");
            let field = scene.field(|_| {}).expect("field");
            let setup = scene.ray_setup(&field).expect("setup");
            let cpu = vmls::raycast::raycast_frame(
                &setup,
                &field,
                &scene.transfer,
                scene.render.table_resolution,
            )
            .expect("CPU twin");
            let mut renderer = Renderer::new(&ctx, field).expect("renderer");
            let (gpu, _) = renderer.render(&scene.view(), |_| {}).expect("frame");
            let mut worst: f64 = 0.0;
            for (c, g) in cpu.iter().zip(&gpu.pixels) {
                for (&x, &y) in c.rgba.iter().zip(g) {
                    assert!(x.is_finite(), "{v}, covering {covering}: CPU {:?}", c.rgba);
                    worst = worst.max((x - f64::from(y)).abs());
                }
            }
            assert!(
                worst <= 1e-4,
                "{v}, covering {covering}: GPU and CPU differ by {worst}"
            );
            // The default transfer function clamps: transparent below 0, τ = 3 above 1.
            let centre = cpu[4 * 8 + 4].rgba[3];
            let visible = covering || v > 0.0;
            assert_eq!(
                centre > 0.1,
                visible,
                "{v}, covering {covering}: centre opacity {centre}"
            );
        }
    }
    common::finish(ctx);
}
