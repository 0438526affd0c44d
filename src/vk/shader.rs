//! Run-time GLSL → SPIR-V compilation with shaderc.
//!
//! The kernels in `glsl/` are embedded in the binary, so `vmls` runs from any directory; setting
//! `VMLS_GLSL_DIR` to a directory with the same layout compiles from there instead (for shader
//! work without rebuilding). Includes name files by their path under `glsl/`.
//! Every variant is a set of macro definitions; results are cached per process by a hash of
//! the kernel source and its definitions. `VMLS_SPIRV_DUMP=dir` writes every compiled variant
//! there (for `spirv-dis`) through the output layer like every other writer (a planted symlink
//! redirects nothing); a variable that names no directory, or a dump that cannot be written,
//! fails the compilation with an error naming the variable, since the user asked for the files.
//! Where the process turned it on, compiled variants are also kept on disk between processes
//! ([`super::shader_cache`]).

use super::VkError;
use super::shader_cache;
use std::collections::HashMap;
use std::hash::{Hash, Hasher};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};

macro_rules! embed {
    ($($name:literal),* $(,)?) => {
        &[$(($name, include_str!(concat!("../../glsl/", $name)))),*]
    };
}

/// Every GLSL file of the project, by its path relative to `glsl/`: shared code in `common/`,
/// the field's reconstruction and its kernels in `field/`, each method's kernels and
/// integrators in `raycast/` and `splat/`, the throughput probes in `probe/`. Includes name
/// files by the same paths.
static SOURCES: &[(&str, &str)] = embed![
    "common/types.glsl",
    "common/params.glsl",
    "common/camera.glsl",
    "common/transfer.glsl",
    "common/shading.glsl",
    "common/target_pack.comp",
    "field/mls.glsl",
    "field/neighbours.glsl",
    "field/hull.glsl",
    "field/skip.glsl",
    "field/mls_eval.comp",
    "field/recon_resample.comp",
    "common/preintegration.glsl",
    "raycast/interval.glsl",
    "raycast/adaptive.glsl",
    "raycast/raycast.comp",
    "raycast/raycast_next.comp",
    "raycast/segments.glsl",
    "splat/splat.glsl",
    "splat/splat_params.glsl",
    "splat/walks.glsl",
    "splat/raster_pixel.glsl",
    "splat/raster_post.glsl",
    "splat/splat_project.comp",
    "splat/splat_scan.comp",
    "splat/splat_walks.comp",
    "splat/splat_bin.comp",
    "splat/splat_order.comp",
    "splat/splat_raster.comp",
    "splat/splat_segments.comp",
    "splat/splat_plan.comp",
    "probe/probe_fma.comp",
    "probe/probe_memory.comp",
    "probe/layout_probe.comp",
];

/// Names of the embedded GLSL files.
pub fn shader_names() -> impl Iterator<Item = &'static str> {
    SOURCES.iter().map(|(n, _)| *n)
}

/// The text of every GLSL file as a new compiler would read it (from `VMLS_GLSL_DIR` when it is
/// set; an unreadable file contributes its error): what a cache of rendered images keys on, since
/// shaders compiled from a directory change without the executable changing.
pub fn source_texts() -> String {
    let dir = std::env::var_os("VMLS_GLSL_DIR").map(PathBuf::from);
    let mut all = String::new();
    for name in shader_names() {
        all.push_str(name);
        all.push('\n');
        match lookup(&dir, name) {
            Ok(text) | Err(text) => all.push_str(&text),
        }
        all.push('\n');
    }
    all
}

/// A kernel to compile: an embedded file by name, or literal text (probes, tests).
#[derive(Debug, Clone, Copy)]
pub enum ShaderSource<'a> {
    File(&'a str),
    Text { name: &'a str, text: &'a str },
}

/// shaderc compiler with a per-process cache of compiled variants, and the disk cache of
/// [`super::shader_cache`] where the process turned it on.
pub struct ShaderCompiler {
    compiler: Mutex<shaderc::Compiler>,
    cache: Mutex<HashMap<u64, Arc<Vec<u32>>>>,
    dir: Option<PathBuf>,
    /// The disk cache's directory and the hash of every GLSL file as this compiler reads them.
    disk: Option<(PathBuf, u64)>,
}

/// Variants compiled by shaderc in this process, and variants read from the disk cache.
static COMPILED: AtomicU32 = AtomicU32::new(0);
static FROM_DISK: AtomicU32 = AtomicU32::new(0);

/// Kernel variants this process compiled with shaderc, and those it read from the disk cache
/// (`--stats` reports both).
pub fn shader_counts() -> (u32, u32) {
    (
        COMPILED.load(Ordering::Relaxed),
        FROM_DISK.load(Ordering::Relaxed),
    )
}

fn lookup(dir: &Option<PathBuf>, name: &str) -> Result<String, String> {
    if let Some(dir) = dir {
        let path = dir.join(name);
        return std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()));
    }
    SOURCES
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, t)| (*t).to_string())
        .ok_or_else(|| {
            format!(
                "no GLSL file '{name}' (known: {})",
                shader_names().collect::<Vec<_>>().join(", ")
            )
        })
}

impl ShaderCompiler {
    /// Starts the compiler (glslang initialisation costs ~100 ms once per process).
    pub fn new() -> Result<Self, VkError> {
        let compiler = shaderc::Compiler::new().map_err(|e| VkError::Shader {
            name: "(compiler)".into(),
            message: format!("cannot start shaderc: {e}"),
        })?;
        let disk = shader_cache::disk_cache_dir().map(|d| {
            let sources = shader_cache::Fnv::new().field(source_texts().as_bytes());
            (d, sources.finish())
        });
        Ok(Self {
            compiler: Mutex::new(compiler),
            cache: Mutex::new(HashMap::new()),
            dir: std::env::var_os("VMLS_GLSL_DIR").map(PathBuf::from),
            disk,
        })
    }

    /// Compiles a kernel with the given `#define NAME VALUE` pairs.
    pub fn compile(
        &self,
        source: ShaderSource<'_>,
        defines: &[(String, String)],
    ) -> Result<Arc<Vec<u32>>, VkError> {
        let (name, text) = match source {
            ShaderSource::File(name) => (
                name,
                lookup(&self.dir, name).map_err(|message| VkError::Shader {
                    name: name.into(),
                    message,
                })?,
            ),
            ShaderSource::Text { name, text } => (name, text.to_string()),
        };
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        text.hash(&mut hasher);
        defines.hash(&mut hasher);
        let key = hasher.finish();
        if let Some(hit) = self
            .cache
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .get(&key)
        {
            return Ok(hit.clone());
        }
        let disk = self.disk.as_ref().map(|(dir, sources)| {
            let mut key = shader_cache::Fnv::new()
                .bytes(&sources.to_le_bytes())
                .field(name.as_bytes())
                .field(text.as_bytes());
            for (k, v) in defines {
                key = key.field(k.as_bytes()).field(v.as_bytes());
            }
            (dir, key.finish())
        });
        let cached = disk.and_then(|(dir, key)| shader_cache::load(dir, name, key));
        let words = match cached {
            Some(words) => {
                FROM_DISK.fetch_add(1, Ordering::Relaxed);
                Arc::new(words)
            }
            None => {
                let words = Arc::new(self.shaderc(name, &text, defines)?);
                COMPILED.fetch_add(1, Ordering::Relaxed);
                if let Some((dir, key)) = disk {
                    shader_cache::store(dir, name, key, &words);
                }
                words
            }
        };
        if let Some(dir) = std::env::var_os("VMLS_SPIRV_DUMP") {
            dump_spirv(
                &PathBuf::from(dir),
                &format!("{}-{key:016x}.spv", name.replace('/', "_")),
                bytemuck::cast_slice(&words),
            )?;
        }
        self.cache
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(key, words.clone());
        Ok(words)
    }

    /// Runs shaderc on one variant (the options are part of the disk cache's format: bump
    /// `shader_cache::FORMAT` when they change).
    fn shaderc(
        &self,
        name: &str,
        text: &str,
        defines: &[(String, String)],
    ) -> Result<Vec<u32>, VkError> {
        let shader_err = |message: String| VkError::Shader {
            name: name.to_string(),
            message,
        };
        let mut options = shaderc::CompileOptions::new()
            .map_err(|e| shader_err(format!("cannot create compile options: {e}")))?;
        options.set_target_env(
            shaderc::TargetEnv::Vulkan,
            shaderc::EnvVersion::Vulkan1_2 as u32,
        );
        options.set_optimization_level(shaderc::OptimizationLevel::Performance);
        options.set_generate_debug_info();
        for (k, v) in defines {
            options.add_macro_definition(k, Some(v));
        }
        let dir = self.dir.clone();
        options.set_include_callback(move |requested, _kind, _from, _depth| {
            let content = lookup(&dir, requested)?;
            Ok(shaderc::ResolvedInclude {
                resolved_name: requested.to_string(),
                content,
            })
        });
        let artifact = self
            .compiler
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .compile_into_spirv(
                text,
                shaderc::ShaderKind::Compute,
                name,
                "main",
                Some(&options),
            )
            .map_err(|e| shader_err(e.to_string()))?;
        Ok(artifact.as_binary().to_vec())
    }
}

/// Writes one dump of `VMLS_SPIRV_DUMP` (see the module contract).
fn dump_spirv(dir: &std::path::Path, name: &str, bytes: &[u8]) -> Result<(), VkError> {
    let err = |message: String| {
        VkError::Usage(format!(
            "VMLS_SPIRV_DUMP={}: {message}",
            crate::files::excerpt_text(&dir.to_string_lossy(), 200)
        ))
    };
    match std::fs::metadata(dir) {
        Ok(meta) if meta.is_dir() => {}
        Ok(_) => return Err(err("expected a directory, found something else".into())),
        Err(e) => return Err(err(format!("expected an existing directory: {e}"))),
    }
    crate::files::write_output("VMLS_SPIRV_DUMP", &dir.join(name), &[], |w| {
        std::io::Write::write_all(w, bytes)
    })
    .map_err(|e| err(e.to_string()))
}
