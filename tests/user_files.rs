//! Nothing of the user's is touched (issue 25 §1): `vmls bench` removes only the images it
//! recorded and refuses outputs that are its inputs, `VMLS_SPIRV_DUMP` writes through the
//! output layer and fails loudly, and SIGTERM and SIGHUP leave no temporary behind, as SIGINT.

mod common;

use common::cli::{dir, quick_bench, s, small_render, vmls};
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The names in `d`, sorted (hidden temporaries included).
fn listing(d: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(d)
        .expect("read_dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// A quick bench of the built-in scene at 8×8 into `out`, with `extra` arguments.
fn bench(out: &Path, extra: &[&str]) -> Output {
    vmls(&quick_bench(out, extra))
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn bench_removes_only_the_images_it_recorded() {
    let d = dir("bench-keeps");
    let images = d.join("images");
    std::fs::create_dir_all(images.join("holiday")).expect("mkdir");
    std::fs::write(images.join("holiday/photo.jpg"), b"sunset").expect("write");
    let out = bench(&d, &[]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let e = stderr(&out);
    assert!(
        e.contains("holiday") && e.contains("not written by vmls bench"),
        "{e}"
    );
    assert_eq!(
        std::fs::read(images.join("holiday/photo.jpg")).expect("kept"),
        b"sunset"
    );
    assert!(!d.join("results.csv").exists());
    // Without the user's folder the bench runs, records its image, and a second run replaces
    // exactly that image.
    std::fs::remove_dir_all(images.join("holiday")).expect("rm");
    for _ in 0..2 {
        let out = bench(&d, &[]);
        assert!(out.status.success(), "{}", stderr(&out));
        assert_eq!(listing(&images), [".vmls-bench", "000.exr"]);
    }
    // An image file of the user's named like the bench's own is not removed either.
    std::fs::write(images.join("001.exr"), b"mine").expect("write");
    let out = bench(&d, &[]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert_eq!(
        std::fs::read(images.join("001.exr")).expect("kept"),
        b"mine"
    );
}

#[test]
fn bench_refuses_outputs_that_are_its_inputs() {
    let d = dir("bench-same");
    let scene = d.join("results.csv");
    let text = "[camera]\nwidth = 8\nheight = 8\n";
    std::fs::write(&scene, text).expect("write");
    let out = bench(&d, &[s(&scene)]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("same file"), "{}", stderr(&out));
    assert_eq!(std::fs::read_to_string(&scene).expect("kept"), text);
    assert!(!d.join("images").exists(), "{:?}", listing(&d));
    // An imported CSV is an input too.
    let imported = d.join("sub");
    std::fs::create_dir_all(&imported).expect("mkdir");
    let csv = imported.join("results.json");
    std::fs::write(&csv, "source,method\n").expect("write");
    let out = bench(&imported, &["--import", s(&csv)]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert_eq!(std::fs::read(&csv).expect("kept"), b"source,method\n");
}

fn render_with_dump(dump: &Path, png: &Path) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_vmls"))
        .args(small_render(png, &[]))
        .env("VMLS_VALIDATION", "1")
        .env("VMLS_SPIRV_DUMP", dump)
        .env_remove("VMLS_DEVICE")
        .output()
        .expect("run vmls");
    common::cli::assert_clean(&out);
    out
}

#[cfg(unix)]
#[test]
fn spirv_dumps_go_through_the_output_layer() {
    let d = dir("spirv-dump");
    let first = d.join("first");
    std::fs::create_dir_all(&first).expect("mkdir");
    let png = d.join("x.png");
    let out = render_with_dump(&first, &png);
    assert!(out.status.success(), "{}", stderr(&out));
    let names = listing(&first);
    assert!(!names.is_empty() && names.iter().all(|n| n.ends_with(".spv")));
    // Symlinks planted at every dump's name redirect nothing.
    let second = d.join("second");
    std::fs::create_dir_all(&second).expect("mkdir");
    let victim = d.join("victim.txt");
    std::fs::write(&victim, b"keep").expect("write");
    for n in &names {
        std::os::unix::fs::symlink(&victim, second.join(n)).expect("symlink");
    }
    let out = render_with_dump(&second, &png);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(std::fs::read(&victim).expect("kept"), b"keep");
    for n in &names {
        let meta = std::fs::symlink_metadata(second.join(n)).expect("dump");
        assert!(meta.is_file(), "{n} is still a link");
        assert_eq!(
            std::fs::read(second.join(n)).expect("dump"),
            std::fs::read(first.join(n)).expect("dump")
        );
    }
    // A variable naming a regular file, a missing directory or a full device fails the
    // render with the variable's name, and writes no image.
    let _ = std::fs::remove_file(&png);
    for bad in [victim.clone(), d.join("missing"), "/dev/full".into()] {
        let out = render_with_dump(&bad, &png);
        assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
        assert!(stderr(&out).contains("VMLS_SPIRV_DUMP"), "{}", stderr(&out));
        assert!(!png.exists());
    }
    assert_eq!(std::fs::read(&victim).expect("kept"), b"keep");
}

/// Starts a render that takes minutes (the reference integrator at 1024², on lavapipe, plus
/// `extra` arguments), waits until its outputs are planned, sends `signal` and returns how it
/// ended.
#[cfg(unix)]
fn signal_a_long_render(d: &Path, signal: i32, extra: &[&str]) -> Output {
    let (png, stats) = (d.join("x.png"), d.join("stats.json"));
    let mut child = Command::new(env!("CARGO_BIN_EXE_vmls"))
        .args([
            "render",
            "-o",
            s(&png),
            "--stats",
            s(&stats),
            "--set",
            "render.method=\"reference\"",
            "--set",
            "camera.width=1024",
            "--set",
            "camera.height=1024",
        ])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run vmls");
    // Wait until the temporaries exist (the outputs are planned), then a little more.
    let start = Instant::now();
    while listing(d).is_empty() && start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(3));
    assert!(
        child.try_wait().expect("wait").is_none(),
        "the render ended too early to test"
    );
    let pid = i32::try_from(child.id()).expect("pid");
    // SAFETY: `pid` is our own child, still running (checked above, never reaped).
    assert_eq!(unsafe { libc::kill(pid, signal) }, 0);
    let start = Instant::now();
    while child.try_wait().expect("wait").is_none() {
        if start.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            panic!("no stop after signal {signal}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = child.wait_with_output().expect("output");
    common::cli::assert_clean(&out);
    out
}

#[cfg(unix)]
#[test]
fn sigint_sigterm_and_sighup_stop_a_render_and_leave_nothing() {
    for (signal, status, word) in [
        (libc::SIGINT, 130, "SIGINT"),
        (libc::SIGTERM, 143, "SIGTERM"),
        (libc::SIGHUP, 129, "SIGHUP"),
    ] {
        let d = dir(&format!("signal-{signal}"));
        let out = signal_a_long_render(&d, signal, &[]);
        let e = stderr(&out);
        assert_eq!(out.status.code(), Some(status), "{e}");
        assert!(e.contains(word) && e.contains("wrote nothing"), "{e}");
        assert!(listing(&d).is_empty(), "left behind: {:?}", listing(&d));
    }
}

#[cfg(unix)]
#[test]
fn a_render_that_cannot_stop_in_time_quits_after_the_grace_period() {
    // The CPU twin reads no stop flag within a frame, which takes far longer than the grace
    // period at 1024²: the process quits by itself after it, leaving nothing behind.
    let d = dir("signal-grace");
    let start = Instant::now();
    let out = signal_a_long_render(&d, libc::SIGTERM, &["--cpu"]);
    let e = stderr(&out);
    assert_eq!(out.status.code(), Some(143), "{e}");
    assert!(e.contains("did not stop within 10 s"), "{e}");
    assert!(listing(&d).is_empty(), "left behind: {:?}", listing(&d));
    assert!(
        start.elapsed() < Duration::from_secs(110),
        "{:?}",
        start.elapsed()
    );
}
