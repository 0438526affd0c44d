//! The C ABI (tools/capi) from C: `examples/embed.c` is compiled against the generated header
//! and the library, and run under the validation layer with synchronization validation. Its
//! last frame must equal `Renderer::render`'s image of the same camera (through
//! `target_pack`'s twin, within one 8-bit step), and a refused scene must come back as a
//! status with the message `vmls_last_error` gives.

use std::path::{Path, PathBuf};
use std::process::Command;
use vmls::renderer::target::pack_pixel;
use vmls::renderer::{Renderer, TargetFormat};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The directory holding `libvmls_capi.so`: the test's own profile directory when
/// `tools/test` built the library there first, else a build of it in a target directory of
/// its own (the test's cargo may hold the lock of the shared one).
fn library_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable");
    // target/<profile>/deps/capi-<hash>
    let profile_dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("profile directory")
        .to_path_buf();
    if profile_dir.join("libvmls_capi.so").is_file() {
        return profile_dir;
    }
    let own = root().join("target").join("capi");
    let status = Command::new(env!("CARGO"))
        .args(["build", "--quiet", "-p", "vmls-capi"])
        .env("CARGO_TARGET_DIR", &own)
        .current_dir(root())
        .status()
        .expect("cargo runs");
    assert!(status.success(), "cargo build -p vmls-capi failed");
    own.join("debug")
}

/// Compiles examples/embed.c into `dir`.
fn compile(dir: &Path) -> PathBuf {
    let lib = library_dir();
    let exe = dir.join("embed-c");
    let out = Command::new("cc")
        .arg(root().join("examples/embed.c"))
        .arg("-std=c11")
        .arg("-Wall")
        .arg("-Werror")
        .arg("-I")
        .arg(root().join("tools/capi/include"))
        .arg("-L")
        .arg(&lib)
        .args(["-lvmls_capi", "-lvulkan"])
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .arg("-o")
        .arg(&exe)
        .output()
        .expect("cc runs (tools/setup installs gcc and libvulkan-dev)");
    assert!(
        out.status.success(),
        "examples/embed.c does not compile:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    exe
}

/// Parses a PAM file of RGBA8 pixels.
fn read_pam(path: &Path) -> (u32, u32, Vec<u8>) {
    let bytes = std::fs::read(path).expect("output written");
    let end = bytes
        .windows(7)
        .position(|w| w == b"ENDHDR\n")
        .expect("PAM header")
        + 7;
    let header = String::from_utf8_lossy(&bytes[..end]).to_string();
    let field = |name: &str| -> u32 {
        header
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|v| v.trim().parse().ok())
            .unwrap_or_else(|| panic!("PAM {name} in {header:?}"))
    };
    (field("WIDTH"), field("HEIGHT"), bytes[end..].to_vec())
}

#[test]
fn a_c_program_embeds_vmls_and_renders_into_its_own_image() {
    let dir = tempfile::tempdir().expect("tempdir");
    let exe = compile(dir.path());
    let image = dir.path().join("frame.pam");
    let out = Command::new(&exe)
        .arg(&image)
        .env("VMLS_VALIDATION", "1")
        .output()
        .expect("the C program runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "exit {:?}\nstdout:\n{stdout}\nstderr:\n{stderr}",
        out.status.code()
    );
    assert!(stdout.contains("0 validation messages"), "{stdout}");
    assert_eq!(stdout.matches("ms of GPU time").count(), 3, "{stdout}");

    // The same frame from the Rust API: the C program's defaults, its last camera.
    let (w, h, got) = read_pam(&image);
    let scene = vmls::scene::Scene::load(
        None,
        &[
            "camera.width=96".to_string(),
            "camera.height=64".to_string(),
        ],
    )
    .expect("scene");
    assert_eq!((w, h), (96, 64));
    let ctx = vmls_gpu();
    let field = scene.field_on(Some(ctx.info()), |_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field).expect("renderer");
    let camera = scene.camera.orbited(0.6);
    let (want, _) = renderer
        .render(&scene.view_with(&camera), |_| {})
        .expect("render");
    let twin: Vec<u8> = want
        .pixels
        .iter()
        .flat_map(|p| pack_pixel(TargetFormat::Rgba8Unorm, *p))
        .collect();
    assert_eq!(got.len(), twin.len());
    // At most one 8-bit step where the GPU rounds a half step the other way (measured: 0).
    let worst = got.iter().zip(&twin).map(|(a, b)| a.abs_diff(*b)).max();
    assert!(worst.unwrap_or(0) <= 1, "off by {worst:?} from render()");
    assert!(got.iter().any(|&b| b != got[0]), "a blank image");
}

#[test]
fn a_refused_scene_comes_back_as_a_status_and_a_message() {
    let dir = tempfile::tempdir().expect("tempdir");
    let exe = compile(dir.path());
    let out = Command::new(&exe)
        .arg(dir.path().join("never.pam"))
        .arg("camera.width=0")
        .output()
        .expect("the C program runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("vmls_scene_load") && stderr.contains("camera.width"),
        "{stderr}"
    );
    assert!(!dir.path().join("never.pam").exists());
}

/// A validated context on the default device.
fn vmls_gpu() -> vmls::vk::Context {
    vmls::vk::Context::new(&vmls::vk::ContextOptions {
        validation: Some(true),
        ..vmls::vk::ContextOptions::default()
    })
    .unwrap_or_else(|e| panic!("no validated Vulkan device (run tools/setup): {e}"))
}
