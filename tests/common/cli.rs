//! Running the `vmls` binary with validation on, and checking how it fails.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs `vmls` with validation on; fails the test on a validation message or a leak report
/// in its stderr ([`assert_clean`]).
pub fn vmls(args: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_vmls"))
        .args(args)
        .env("VMLS_VALIDATION", "1")
        .env_remove("VMLS_DEVICE")
        .output()
        .expect("run vmls");
    assert_clean(&out);
    out
}

/// What the library prints for a validation error or warning (`vk::context`'s messenger) and
/// for GPU allocations alive at shutdown: a test that reads only the exit status would let
/// them pass.
const UNCLEAN: [&str; 3] = [
    "Vulkan validation error",
    "Vulkan validation warning",
    "leak report",
];

/// Fails on a validation message or a leak report in a run's stderr, whatever its status.
pub fn assert_clean(out: &Output) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    if let Some(found) = UNCLEAN.iter().find(|u| stderr.contains(*u)) {
        panic!("vmls printed a {found}:\n{stderr}");
    }
}

pub fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vmls-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Asserts failure with exactly one stderr line containing every `needle`, and no image.
pub fn assert_fails(out: &Output, needles: &[&str], image: &Path) {
    assert_clean(out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(1),
        "expected exit 1, stderr: {stderr}"
    );
    assert_eq!(
        stderr.trim_end().lines().count(),
        1,
        "expected one error line, got: {stderr}"
    );
    assert!(stderr.starts_with("vmls: error: "), "{stderr}");
    for n in needles {
        assert!(stderr.contains(n), "error line lacks '{n}': {stderr}");
    }
    assert!(!image.exists(), "an image was written despite the error");
}

/// `vmls render -o png` of the built-in scene at 8×8, then `extra`.
pub fn small_render<'a>(png: &'a Path, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "render",
        "-o",
        s(png),
        "--set",
        "camera.width=8",
        "--set",
        "camera.height=8",
    ];
    args.extend_from_slice(extra);
    args
}

/// A quick `vmls bench` of the built-in scene at 8×8 into `out` (the fixed method, one timed
/// frame, no cache, no ceilings), then `extra`.
pub fn quick_bench<'a>(out: &'a Path, extra: &[&'a str]) -> Vec<&'a str> {
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
        s(out),
        "--set",
        "camera.width=8",
        "--set",
        "camera.height=8",
    ];
    args.extend_from_slice(extra);
    args
}
