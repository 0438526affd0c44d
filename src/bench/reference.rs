//! The reference image a bench run measures error against, rendered once and cached on disk.
//!
//! The reference is the scene as written (with the run's `--set` and `--reference-set`
//! overrides, but none of the swept settings) rendered by the `reference` integrator: midpoint
//! steps of `render.reference_step` with the transfer function applied directly. For a
//! generated volume it integrates the analytic field (`reconstruction.method = "exact"`), the
//! true image; otherwise the scene's own reconstruction (by the direct solve: the bench never
//! renders a reference through the fast path, `reconstruction.resample`), the most exact image
//! vmls can make of it — then swept reconstruction settings are measured against the scene's field, and their
//! error includes the reconstruction change.
//!
//! The cache key is a SHA-256 over everything the image depends on: the validated reference
//! scene, the bytes of its data file, the vmls version, commit and executable, and where it was
//! rendered (the device and driver and the GLSL sources, which `VMLS_GLSL_DIR` can change
//! without changing the executable, or the f64 CPU twins). A changed key renders anew; a cache
//! file that cannot be read, or has another size, is a miss and is rendered over.

use super::BenchError;
use crate::output::{read_image, write_image};
use crate::renderer::Renderer;
use crate::scene::{Scene, VolumeSource};
use crate::vk::Context;
use sha2::{Digest, Sha256};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Where the reference is rendered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReferenceMode {
    /// The `reference` integrator on the bench's Vulkan device (f32).
    Gpu,
    /// The f64 CPU twin of the `reference` integrator (slow; independent of the device).
    Cpu,
}

/// A reference image and how it was made.
#[derive(Debug, Clone)]
pub struct Reference {
    pub pixels: Vec<[f32; 4]>,
    pub width: u32,
    pub height: u32,
    /// One line for the CSV's `reference` column.
    pub description: String,
    /// Whether it came from the cache.
    pub cached: bool,
    /// Where it is stored (when a cache directory was given).
    pub path: Option<PathBuf>,
}

/// The cache key of a reference scene rendered in `mode` on `ctx`'s device.
pub fn reference_key(
    scene: &Scene,
    mode: ReferenceMode,
    ctx: &Context,
    commit: &str,
) -> Result<String, BenchError> {
    let mut h = Sha256::new();
    h.update(b"vmls reference v1\n");
    h.update(env!("CARGO_PKG_VERSION").as_bytes());
    h.update(commit.as_bytes());
    // The binary itself: a dirty tree keeps its `git describe` name across edits, the bytes
    // of the executable do not.
    if let Ok(exe) = std::env::current_exe().and_then(std::fs::read) {
        h.update(Sha256::digest(&exe));
    }
    h.update(format!("{scene:?}").as_bytes());
    if let VolumeSource::File { path, .. } = &scene.volume {
        let bytes = std::fs::read(path).map_err(|e| BenchError::Io {
            path: path.display().to_string(),
            message: format!("cannot read the data file to key the reference: {e}"),
        })?;
        h.update(Sha256::digest(&bytes));
    }
    match mode {
        ReferenceMode::Gpu => {
            h.update(b"gpu");
            h.update(crate::vk::source_texts().as_bytes());
            h.update(ctx.info().name.as_bytes());
            h.update(ctx.info().driver.as_bytes());
        }
        ReferenceMode::Cpu => h.update(b"cpu f64"),
    }
    Ok(h.finalize().iter().map(|b| format!("{b:02x}")).collect())
}

fn describe(scene: &Scene, mode: ReferenceMode, ctx: &Context) -> String {
    let field = match scene.reconstruction.method {
        crate::recon::ReconMethod::Exact => "the analytic field".to_string(),
        m => format!("{m:?} {:?} reconstruction", scene.reconstruction.basis),
    };
    format!(
        "reference integrator, step {} spacings, {field}, on {}",
        scene.render.reference_step_spacings,
        match mode {
            ReferenceMode::Gpu => ctx.info().name.clone(),
            ReferenceMode::Cpu => "the CPU (f64 twins)".into(),
        }
    )
}

/// Renders `scene` with the reference integrator (the caller has set `render.method`), after
/// checking its frame against `budget` (MLS evaluations; `None`: `--force`).
fn render(
    scene: &Scene,
    mode: ReferenceMode,
    ctx: &Context,
    budget: Option<f64>,
) -> Result<Vec<[f32; 4]>, BenchError> {
    let field = scene.field(|_| {})?;
    if let Some(budget) = budget {
        scene
            .ray_setup(&field)?
            .check_budget(budget)
            .map_err(|source| BenchError::Budget {
                what: "the reference".into(),
                source: Box::new(source),
            })?;
    }
    match mode {
        ReferenceMode::Gpu => {
            let mut renderer = Renderer::new(ctx, field)?;
            Ok(renderer.render(&scene.view(), |_| {})?.0.pixels)
        }
        ReferenceMode::Cpu => {
            let setup = scene.ray_setup(&field)?;
            let image = crate::raycast::raycast_image(&setup, &field, &scene.transfer, None)
                .map_err(crate::field::RenderError::from)?;
            Ok(image.iter().map(|p| p.rgba.map(|c| c as f32)).collect())
        }
    }
}

/// The reference of `scene` (already set to the `reference` method), from `cache` when a file
/// with its key is there, else rendered (within `budget` MLS evaluations unless `None`) and
/// stored there.
pub fn reference_image(
    scene: &Scene,
    mode: ReferenceMode,
    ctx: &Context,
    commit: &str,
    cache: Option<&Path>,
    budget: Option<f64>,
) -> Result<Reference, BenchError> {
    let (width, height) = (scene.camera.width, scene.camera.height);
    let description = describe(scene, mode, ctx);
    let path = match cache {
        Some(dir) => {
            let key = reference_key(scene, mode, ctx, commit)?;
            Some(dir.join(format!("{key}.exr")))
        }
        None => None,
    };
    if let Some(p) = path.as_ref().filter(|p| p.is_file())
        && let Ok((w, h, pixels)) = read_image(p)
        && (w, h) == (width, height)
    {
        return Ok(Reference {
            pixels,
            width,
            height,
            description,
            cached: true,
            path: path.clone(),
        });
    }
    let pixels = render(scene, mode, ctx, budget)?;
    if let Some(p) = &path {
        if let Some(dir) = p.parent() {
            std::fs::create_dir_all(dir).map_err(|e| BenchError::Io {
                path: dir.display().to_string(),
                message: format!("cannot create the reference cache: {e}"),
            })?;
        }
        write_image(p, width, height, &pixels)?;
        let note = p.with_extension("txt");
        crate::files::write_output("reference note", &note, &[], |out| {
            write!(out, "{description}\n{scene:#?}\n")
        })?;
    }
    Ok(Reference {
        pixels,
        width,
        height,
        description,
        cached: false,
        path,
    })
}
