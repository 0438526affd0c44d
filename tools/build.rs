//! Link fix for shaderc on Debian.
//!
//! The `shaderc` crate (feature `prefer-static-linking`) links Debian's `libshaderc_combined.a`,
//! which despite its name does not contain glslang or SPIRV-Tools, and Debian's shared
//! `libshaderc.so.1` is under-linked. So we add the static glslang and SPIRV-Tools archives that
//! the packages `glslang-dev` and `spirv-tools` ship, plus the C++ runtime, after shaderc.

fn main() {
    println!("cargo:rerun-if-changed=tools/build.rs");
    println!("cargo:rerun-if-env-changed=SHADERC_LIB_DIR");
    let target_os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    if target_os != "linux" {
        return;
    }
    let arch = std::env::var("CARGO_CFG_TARGET_ARCH").unwrap_or_default();
    let dir =
        std::env::var("SHADERC_LIB_DIR").unwrap_or_else(|_| format!("/usr/lib/{arch}-linux-gnu"));
    println!("cargo:rustc-link-search=native={dir}");
    // Order matters for static archives: dependants before their dependencies.
    for lib in [
        "glslang",
        "MachineIndependent",
        "OSDependent",
        "GenericCodeGen",
        "OGLCompiler",
        "SPIRV",
        "glslang-default-resource-limits",
        "SPIRV-Tools-opt",
        "SPIRV-Tools",
    ] {
        if std::path::Path::new(&format!("{dir}/lib{lib}.a")).exists() {
            println!("cargo:rustc-link-lib=static={lib}");
        }
    }
    println!("cargo:rustc-link-lib=dylib=stdc++");
}
