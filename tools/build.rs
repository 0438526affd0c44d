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
    if std::env::var_os("CARGO_FEATURE_MPI").is_some() {
        link_icet(&dir);
    }
}

/// The `mpi` feature's IceT: Debian ships it inside ParaView as `libvtkIceTCore-pvX.Y.so` and
/// `libvtkIceTMPI-pvX.Y.so` (package paraview-dev; `tools/setup --mpi`), linked against the
/// OpenMPI that the `mpi` crate links. `ICET_LIB_DIR` points elsewhere.
fn link_icet(default_dir: &str) {
    println!("cargo:rerun-if-env-changed=ICET_LIB_DIR");
    let dir = std::env::var("ICET_LIB_DIR").unwrap_or_else(|_| default_dir.to_string());
    let core = std::fs::read_dir(&dir).ok().and_then(|entries| {
        entries
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter_map(|n| {
                Some(
                    n.strip_prefix("libvtkIceTCore")?
                        .strip_suffix(".so")?
                        .to_string(),
                )
            })
            .next()
    });
    let Some(suffix) = core else {
        println!(
            "cargo:warning=feature mpi: no libvtkIceTCore*.so in {dir} (run tools/setup --mpi, \
             or set ICET_LIB_DIR)"
        );
        return;
    };
    println!("cargo:rustc-link-search=native={dir}");
    println!("cargo:rustc-link-lib=dylib=vtkIceTMPI{suffix}");
    println!("cargo:rustc-link-lib=dylib=vtkIceTCore{suffix}");
}
