//! Compiled kernels kept on disk between runs (`vk::shader_cache`): a second run compiles
//! nothing and renders the same image, a damaged file is compiled again, `VMLS_SHADER_CACHE`
//! moves or turns the cache off, and the default follows `XDG_CACHE_HOME`.

mod common;

use common::cli::{assert_clean, dir, s, small_render};
use std::path::Path;
use std::process::Command;

/// Renders the built-in scene at 8×8 with `env` set; returns (compiled, from disk, PNG bytes).
fn render(d: &Path, env: &[(&str, &Path)], off: bool) -> (u64, u64, Vec<u8>) {
    let (png, stats) = (d.join("x.png"), d.join("stats.json"));
    let mut args = small_render(&png, &[]);
    args.extend(["--stats", s(&stats)]);
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_vmls"));
    cmd.args(&args)
        .env("VMLS_VALIDATION", "1")
        .env_remove("VMLS_DEVICE")
        .env_remove("VMLS_SHADER_CACHE")
        .env_remove("VMLS_GLSL_DIR");
    for (k, v) in env {
        cmd.env(k, v);
    }
    if off {
        cmd.env("VMLS_SHADER_CACHE", "off");
    }
    let out = cmd.output().expect("run vmls");
    assert_clean(&out);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&stats).expect("stats")).expect("json");
    let count = |k: &str| json["shaders"][k].as_u64().expect("a count");
    (
        count("compiled"),
        count("from_disk_cache"),
        std::fs::read(&png).expect("png"),
    )
}

fn files(d: &Path) -> Vec<std::path::PathBuf> {
    let mut v: Vec<_> = std::fs::read_dir(d)
        .map(|r| r.map(|e| e.expect("entry").path()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn a_second_run_compiles_nothing_and_a_damaged_file_is_compiled_again() {
    let d = dir("shader-cache");
    let cache = d.join("kernels");
    let env = [("VMLS_SHADER_CACHE", cache.as_path())];
    let (compiled, from_disk, first) = render(&d, &env, false);
    assert!(compiled >= 1, "{compiled}");
    assert_eq!(from_disk, 0);
    let stored = files(&cache);
    assert_eq!(stored.len() as u64, compiled, "{stored:?}");
    assert!(
        stored
            .iter()
            .all(|p| p.extension().is_some_and(|e| e == "spv"))
    );

    let (again, from_disk, second) = render(&d, &env, false);
    assert_eq!((again, from_disk), (0, compiled));
    assert_eq!(first, second, "the cached kernels render another image");

    // One flipped byte in the middle of one file: that kernel is compiled and stored again.
    let victim = &stored[0];
    let mut bytes = std::fs::read(victim).expect("read");
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0x40;
    std::fs::write(victim, &bytes).expect("write");
    let (again, from_disk, third) = render(&d, &env, false);
    assert_eq!((again, from_disk), (1, compiled - 1));
    assert_eq!(first, third);
    assert_eq!(
        files(&cache),
        stored,
        "rewritten in place, nothing else left"
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn the_default_place_follows_xdg_cache_home_and_off_writes_nothing() {
    let d = dir("shader-cache-default");
    let xdg = d.join("xdg");
    let env = [("XDG_CACHE_HOME", xdg.as_path())];
    let (compiled, _, _) = render(&d, &env, true);
    assert!(compiled >= 1);
    // (Mesa and the validation layer keep caches of their own there.)
    assert!(!xdg.join("vmls").exists(), "off wrote {:?}", files(&xdg));
    let (compiled, from_disk, _) = render(&d, &env, false);
    assert_eq!(from_disk, 0);
    assert_eq!(files(&xdg.join("vmls/shaders")).len() as u64, compiled);
    let _ = std::fs::remove_dir_all(&d);
}
