//! Peers in the same run: `vmls bench --peer vtk` runs `tools/peer-vtk` on the same scene file
//! and overrides, reads the rows it writes (the columns of `results.csv`), and measures each
//! peer image against the run's reference exactly as vmls's own rows are measured.
//!
//! For a grid the VTK peer ray casts (`vtkGPUVolumeRayCastMapper`), its sample distances
//! following the run's `render.step` sweep when there is one (the same steps in spacings), else
//! 1, 0.5 and 0.25 spacings. A scattered point cloud it draws as point Gaussians
//! (`vtkPointGaussianMapper`, the same kernels sorted back to front), where steps do not apply.

use super::{BenchError, BenchOptions, metrics, reference::Reference, results::read_csv};
use crate::bench::results::Row;
use std::path::{Path, PathBuf};

/// The peers `--peer` accepts.
pub const PEERS: &[&str] = &["vtk"];

/// The peer's command: `$VMLS_PEER_VTK`, else `tools/peer-vtk` of the source tree.
fn command(name: &str) -> PathBuf {
    std::env::var_os(format!("VMLS_PEER_{}", name.to_ascii_uppercase()))
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("tools/peer-{name}")))
}

/// Runs peer `name` on the run's scene and returns its rows with their error filled in.
pub fn run_peer(
    name: &str,
    opts: &BenchOptions,
    reference: &Reference,
) -> Result<Vec<Row>, BenchError> {
    if !PEERS.contains(&name) {
        return Err(BenchError::Usage(format!(
            "--peer {name}: unknown peer (known: {})",
            PEERS.join(", ")
        )));
    }
    let dir = opts.out.join(format!("peer-{name}"));
    std::fs::create_dir_all(&dir).map_err(|e| BenchError::Io {
        path: dir.display().to_string(),
        message: e.to_string(),
    })?;
    // The built-in scene has no file: the peer gets its text.
    let scene = match &opts.scene {
        Some(p) => p.clone(),
        None => {
            let p = dir.join("scene.toml");
            crate::files::write_output("peer scene", &p, &[], |out| {
                std::io::Write::write_all(out, crate::scene::DEFAULT_SCENE.as_bytes())
            })?;
            p
        }
    };
    let steps = opts
        .sweeps
        .iter()
        .find(|s| s.key == "render.step")
        .map_or("1,0.5,0.25".to_string(), |s| s.values.join(","));
    let cmd = command(name);
    let mut c = std::process::Command::new(&cmd);
    c.arg(&scene);
    for s in &opts.set {
        c.arg("--set").arg(s);
    }
    c.args([
        "--steps",
        &steps,
        "--repeat",
        &opts.repeat.to_string(),
        "--out",
    ])
    .arg(&dir);
    let output = c.output().map_err(|e| BenchError::Io {
        path: cmd.display().to_string(),
        message: format!("cannot run the {name} peer: {e}"),
    })?;
    if !output.status.success() {
        let stderr = String::from_utf8_lossy(&output.stderr);
        return Err(BenchError::Io {
            path: cmd.display().to_string(),
            message: format!(
                "the {name} peer failed ({}): {}",
                output.status,
                stderr.lines().last().unwrap_or("")
            ),
        });
    }
    let mut rows = read_csv(&dir.join("results.csv"))?;
    for r in &mut rows {
        let Some(image) = r.variant.strip_prefix("image=") else {
            continue;
        };
        let (w, h, pixels) = crate::output::read_image(Path::new(image))?;
        if (w, h) != (reference.width, reference.height) {
            return Err(BenchError::Io {
                path: image.into(),
                message: format!(
                    "the peer's image is {w}×{h}, the reference {}×{}",
                    reference.width, reference.height
                ),
            });
        }
        let e = metrics::image_error(&pixels, &reference.pixels, w);
        r.rmse = e.map(|e| e.rmse);
        r.max_abs = e.map(|e| e.max_abs);
        r.max_x = e.map(|e| e.max_x);
        r.max_y = e.map(|e| e.max_y);
        r.psnr = e.map(|e| e.psnr);
        r.non_finite = e.map(|e| e.non_finite);
        r.p99 = e.map(|e| e.p99);
        r.reference = reference.description.clone();
    }
    Ok(rows)
}
