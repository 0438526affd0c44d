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
    child.wait_with_output().expect("output")
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
        // Root ignores directory permissions; the check means nothing then.
        if std::fs::write(&probe, b"").is_err() {
            let map = ro.join("map.png");
            assert_fails(
                &render(&["-o", s(&png), "--eval-map", s(&map)]),
                &["map.png"],
                &png,
            );
        }
        let _ = std::fs::remove_file(&probe);
    }
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
    let cases: [(Vec<String>, &str); 4] = [
        (
            vec![
                "render".into(),
                s(&fifo).into(),
                "-o".into(),
                s(&png).into(),
            ],
            "FIFO",
        ),
        (
            vec![
                "render".into(),
                "-o".into(),
                s(&png).into(),
                "--set".into(),
                format!("volume.file={}", s(&fifo_volume)),
            ],
            "FIFO",
        ),
        (
            vec![
                "render".into(),
                "-o".into(),
                s(&png).into(),
                "--set".into(),
                format!("volume.file={}", s(&zero)),
            ],
            "character device",
        ),
        (vec!["info".into(), s(&folder).into()], "directory"),
    ];
    for (args, what) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = vmls_within(&args, limit);
        assert_fails(&out, &[what, "expected a regular file"], &png);
    }
    let out = vmls_within(&["compare", s(&zero), s(&zero)], limit);
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
    let set = format!("volume.file={}", s(&data("legacy/image-42-binary.vtk")));
    let out = render(&["-o", s(&png), "--set", &set]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(image::open(&png).is_ok());
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
