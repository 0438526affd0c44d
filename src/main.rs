//! The `vmls` command line: `render`, `info`, `devices`, `probe`, `compare`.
//!
//! Errors print one line (`vmls: error: …`, with the cause chain) and exit with status 1; usage
//! errors exit with clap's status 2. Progress bars appear only when stderr is a terminal.

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;
use vmls::data::dataset::Location;
use vmls::probe::{coherent_order, fma_probe, median, mls_probe, random_points};
use vmls::render::evalmap::{check_path, write_eval_map};
use vmls::render::output::{format_of, write_image};
use vmls::render::renderer::{Renderer, View};
use vmls::render::{Field, RenderError};
use vmls::scene::load_volume;
use vmls::scene::{NeighbourMode, Scene, SceneError};
use vmls::vk::{Context, ContextOptions, ShaderCompiler};

#[derive(Parser)]
#[command(
    name = "vmls",
    version,
    about = "Volume MLS ray casting on Vulkan compute"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Args)]
struct DeviceArgs {
    /// Device index or name substring (default: $VMLS_DEVICE, else discrete > integrated > CPU).
    #[arg(long)]
    device: Option<String>,
    /// Enable the Khronos validation layer (also: VMLS_VALIDATION=1).
    #[arg(long)]
    validation: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene (the built-in Marschner–Lobb scene when none is given).
    Render {
        /// Scene file (TOML).
        scene: Option<PathBuf>,
        /// Output image: .png (8-bit RGBA, clamped, no gamma) or .exr (32-bit float RGBA).
        #[arg(short, long)]
        output: PathBuf,
        /// Write statistics as JSON.
        #[arg(long)]
        stats: Option<PathBuf>,
        /// Write the per-pixel count of MLS evaluations as a heat map with a legend (.png).
        #[arg(long)]
        eval_map: Option<PathBuf>,
        /// Override a scene key: section.key=value (repeatable).
        #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
        set: Vec<String>,
        /// Render this many frames with one persistent renderer, turning the camera 10° about
        /// its up axis each frame; the last is written, `--stats` lists every frame's cost.
        #[arg(long, default_value_t = 1)]
        frames: u32,
        /// Render with the f64 CPU twins of the kernels instead of the GPU: slow, for ground
        /// truth (e.g. reconstruction.method = "gaussian" with render.method = "reference", the
        /// exact image splatting approximates).
        #[arg(long)]
        cpu: bool,
        #[command(flatten)]
        device: DeviceArgs,
    },
    /// List Vulkan devices (* marks the default choice).
    Devices,
    /// Describe a data file: kind, counts, bounds, arrays and their ranges, and the supports
    /// and octree vmls would derive.
    Info {
        /// Data file (.vtk, .vti, .vtr, .vts, .vtu, .vtp, .csv, .ply, .nrrd, .nii, .nii.gz).
        file: PathBuf,
        /// Array to sample (default: the first point array).
        #[arg(long)]
        array: Option<String>,
        /// Override a scene key (reconstruction.support, .knn, .anisotropic, octree.*).
        #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
        set: Vec<String>,
    },
    /// RMSE and largest difference of the RGB channels of two images of the same size, and
    /// the pixel where the largest one is.
    Compare {
        /// Image under test (.png or .exr).
        image: PathBuf,
        /// Reference image (.png or .exr).
        reference: PathBuf,
        /// Write the per-pixel largest |difference| as a heat map (.png or .exr), scaled so
        /// that the largest difference is white.
        #[arg(long)]
        diff: Option<PathBuf>,
    },
    /// Measure the FMA ceiling and MLS evaluation throughput side by side.
    Probe {
        /// Marschner–Lobb resolution of the probe field.
        #[arg(long, default_value_t = 41)]
        resolution: usize,
        /// Evaluation points per dispatch.
        #[arg(long, default_value_t = 65536)]
        points: usize,
        /// Timed repetitions (after one warm-up).
        #[arg(long, default_value_t = 5)]
        repeats: u32,
        /// Write the results as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Probe this data file's octree path instead of Marschner–Lobb's grid and octree:
        /// octree statistics, then evaluations at random points of the domain's box.
        #[arg(long)]
        file: Option<PathBuf>,
        /// With --file: override a scene key (reconstruction.*, octree.*, volume.scalars).
        #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
        set: Vec<String>,
        #[command(flatten)]
        device: DeviceArgs,
    },
}

/// Everything a command can fail with: the scene file, or anything below it.
#[derive(Debug, thiserror::Error)]
enum CliError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error("{0}")]
    Usage(String),
}

impl From<vmls::vk::VkError> for CliError {
    fn from(e: vmls::vk::VkError) -> Self {
        CliError::Render(e.into())
    }
}

impl From<vmls::data::DataError> for CliError {
    fn from(e: vmls::data::DataError) -> Self {
        CliError::Render(e.into())
    }
}

impl From<vmls::recon::ReconError> for CliError {
    fn from(e: vmls::recon::ReconError) -> Self {
        CliError::Render(e.into())
    }
}

fn context(args: &DeviceArgs) -> Result<Context, RenderError> {
    Ok(Context::new(&ContextOptions {
        validation: args.validation.then_some(true),
        device: args.device.clone(),
        force_staging: false,
    })?)
}

fn progress_bar(message: &'static str) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(1000);
    if let Ok(style) = ProgressStyle::with_template("{msg:>12} [{bar:40}] {percent:>3}% {elapsed}")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(message);
    bar
}

fn write_json(path: &Path, value: &serde_json::Value) -> Result<(), RenderError> {
    let text = serde_json::to_string_pretty(value).unwrap_or_default();
    std::fs::write(path, text + "\n").map_err(|e| RenderError::Output {
        path: path.display().to_string(),
        message: format!("cannot write: {e}"),
    })
}

fn run_render(
    scene_path: Option<&Path>,
    output: &Path,
    stats: Option<&Path>,
    eval_map: Option<&Path>,
    set: &[String],
    frames_wanted: u32,
    device: &DeviceArgs,
) -> Result<(), CliError> {
    let start = Instant::now();
    format_of(output)?;
    if let Some(map) = eval_map {
        check_path(map)?;
    }
    let scene = Scene::load(scene_path, set)?;
    if eval_map.is_some() && scene.render.method.splat_shading().is_some() {
        return Err(CliError::Usage(format!(
            "--eval-map counts MLS evaluations per ray; render.method = \"{}\" splats and \
             evaluates none (its counts are in --stats)",
            scene.render.method.name()
        )));
    }
    let bar = progress_bar("octree");
    let field = scene.field(|f| bar.set_position((f * 1000.0) as u64))?;
    bar.finish_and_clear();
    let ctx = context(device)?;
    let step_world = match scene.render.method.splat_shading() {
        None => Some(scene.ray_setup(&field)?.step),
        Some(_) => None,
    };
    let upload_start = Instant::now();
    let mut renderer = Renderer::new(&ctx, field)?;
    let upload_ms = upload_start.elapsed().as_secs_f64() * 1e3;
    // Frame k turns the camera by 10°·k about its up axis through the target: later frames
    // show what a new camera costs with everything else kept on the GPU.
    let mut frames = Vec::new();
    let mut image = None;
    for k in 0..frames_wanted.max(1) {
        let camera = scene.camera.orbited((10.0 * k as f64).to_radians());
        let view = View {
            camera: &camera,
            settings: &scene.render,
            transfer: &scene.transfer,
            isosurfaces: &scene.isosurfaces,
            lighting: &scene.lighting,
        };
        let bar = progress_bar("render");
        let (img, frame) = renderer.render(&view, |f| bar.set_position((f * 1000.0) as u64))?;
        bar.finish_and_clear();
        frames.push(frame);
        image = Some(img);
    }
    let (Some(image), Some(first)) = (image, frames.first().cloned()) else {
        return Err(RenderError::Output {
            path: output.display().to_string(),
            message: "no frame rendered".into(),
        }
        .into());
    };
    let field = renderer.field();
    let tables = renderer.tables();
    let table_ms = first.table_ms;
    let errors = ctx.validation_errors();
    if errors > 0 {
        return Err(RenderError::Output {
            path: output.display().to_string(),
            message: format!(
                "{errors} Vulkan validation error(s) during the render; no image written"
            ),
        }
        .into());
    }
    write_image(
        output,
        scene.camera.width,
        scene.camera.height,
        &image.pixels,
    )?;
    if let Some(map) = eval_map {
        write_eval_map(map, scene.camera.width, scene.camera.height, &image.counts)?;
    }
    if let Some(stats) = stats {
        let evaluations: u64 = image.counts.iter().map(|&c| u64::from(c)).sum();
        let rays = image.counts.len() as u64;
        let value = serde_json::json!({
            "device": ctx.info().name,
            "device_type": ctx.info().device_type,
            "driver": ctx.info().driver,
            "variant": image.variant,
            "width": scene.camera.width,
            "height": scene.camera.height,
            "method": scene.render.method.name(),
            "step_world": step_world,
            "neighbours": if field.uses_octree() { "octree" } else { "grid" },
            "gpu_ms": match &image.splat {
                None => serde_json::json!({ "raycast": first.gpu_ms }),
                Some(r) => serde_json::json!({
                    "splat_project": r.stage_ms[0],
                    "splat_bin": r.stage_ms[1],
                    "splat_accumulate": r.stage_ms[2],
                    "splat_composite": r.stage_ms[3],
                }),
            },
            "splat": image.splat.as_ref().map(|r| serde_json::json!({
                "sheets": r.slabs,
                "sheet_thickness_world": r.slab,
                "kernels_projected": r.counts.projected,
                "kernels_culled_near": r.counts.culled_near,
                "kernels_culled_outside": r.counts.culled_outside,
                "kernels_culled_degenerate": r.counts.culled_degenerate,
                "kernels_culled_empty": r.counts.culled_empty,
                "kernels_kept": r.counts.kept(),
                "footprints_binned": r.counts.entries,
                "footprints_skipped_by_occlusion": r.counts.skipped_occluded,
                "footprints_accumulated": r.counts.accumulated,
                "gpu_ms_per_kernel": {
                    "splat_project": r.stage_ms[0] / r.counts.projected.max(1) as f64,
                    "splat_bin": r.stage_ms[1] / r.counts.kept().max(1) as f64,
                    "splat_accumulate": r.stage_ms[2] / r.counts.kept().max(1) as f64,
                    "splat_composite": r.stage_ms[3] / r.counts.kept().max(1) as f64,
                },
            })),
            "upload_ms": upload_ms,
            "frames": frames.iter().map(|f| serde_json::json!({
                "gpu_ms": f.gpu_ms,
                "wall_ms": f.wall_ms,
                "tables_built": f.tables_built,
                "table_ms": f.table_ms,
                "pipeline_built": f.pipeline_built,
                "buffers_allocated": f.targets_allocated,
            })).collect::<Vec<_>>(),
            "bands": image.bands,
            "wall_ms": start.elapsed().as_secs_f64() * 1e3,
            "function_evaluations": evaluations,
            "rays": rays,
            "evaluations_per_ray": evaluations as f64 / rays.max(1) as f64,
            "table_build_ms_cpu": tables.map(|_| table_ms),
            "table_lengths_world": tables.map(|t| t.lengths.clone()),
            "table_resolution": tables.map(|t| t.resolution),
            "octree_nodes": field.octree.as_ref().map(|o| o.nodes.len()),
            "octree_references": field.octree.as_ref().map(|o| o.indices.len()),
            "octree": field.octree.as_ref().map(|o| octree_json(&o.stats(std::mem::size_of::<vmls::gpu_types::Sample>() as u64))),
            "data": {
                "kind": field.samples.provenance.kind,
                "array": field.samples.provenance.array,
                "sampled_at": match field.samples.provenance.location {
                    Location::Point => "points",
                    Location::Cell => "cell centroids",
                },
                "samples": field.samples.len(),
                "merged_duplicates": field.samples.provenance.merged,
                "inverted_cells": field.samples.provenance.inverted_cells,
                "supports": field.samples.provenance.support_kind,
            },
        });
        write_json(stats, &value)?;
    }
    Ok(())
}

/// `vmls render --cpu`: the f64 CPU twins, rows over all cores.
fn run_render_cpu(
    scene_path: Option<&Path>,
    output: &Path,
    stats: Option<&Path>,
    set: &[String],
) -> Result<(), CliError> {
    let start = Instant::now();
    format_of(output)?;
    let scene = Scene::load(scene_path, set)?;
    let field = scene.field(|_| {})?;
    let (pixels, splat): (Vec<[f64; 4]>, _) = match scene.render.method.splat_shading() {
        Some(shading) => {
            let setup = vmls::splat::SplatSetup::new(
                shading,
                &scene.render.splat,
                &scene.camera,
                scene.render.early_termination,
                scene.render.background,
                &scene.isosurfaces,
                &scene.lighting,
                &field,
            )?;
            let image = vmls::splat::accumulate::splat_image(&setup, &field, &scene.transfer);
            (image.pixels, Some(image.counts))
        }
        None => {
            let setup = scene.ray_setup(&field)?;
            let tables = vmls::render::build_tables(
                &setup,
                &field,
                &scene.transfer,
                scene.render.table_resolution,
                |_| {},
            );
            let image = vmls::render::raycast::raycast_image(
                &setup,
                &field,
                &scene.transfer,
                tables.as_ref(),
            );
            (image.iter().map(|p| p.rgba).collect(), None)
        }
    };
    let rgba: Vec<[f32; 4]> = pixels.iter().map(|p| p.map(|c| c as f32)).collect();
    write_image(output, scene.camera.width, scene.camera.height, &rgba)?;
    if let Some(stats) = stats {
        let value = serde_json::json!({
            "device": "cpu (f64 reference twins)",
            "method": scene.render.method.name(),
            "width": scene.camera.width,
            "height": scene.camera.height,
            "wall_ms": start.elapsed().as_secs_f64() * 1e3,
            "splat": splat.map(|c| serde_json::json!({
                "kernels_projected": c.projected,
                "kernels_kept": c.kept(),
                "footprints_binned": c.entries,
                "footprints_skipped_by_occlusion": c.skipped_occluded,
                "footprints_accumulated": c.accumulated,
            })),
        });
        write_json(stats, &value)?;
    }
    Ok(())
}

fn octree_json(s: &vmls::recon::OctreeStats) -> serde_json::Value {
    serde_json::json!({
        "nodes": s.nodes,
        "leaves": s.leaves,
        "references": s.references,
        "redundancy": s.redundancy,
        "depth": s.depth,
        "bytes": s.bytes,
        "build_ms": s.build_ms,
    })
}

fn run_file_probe(
    file: &Path,
    set: &[String],
    points: usize,
    repeats: u32,
    json: Option<&Path>,
    device: &DeviceArgs,
) -> Result<(), CliError> {
    let mut overrides = vec![format!(
        "volume.file={}",
        toml::Value::String(file.display().to_string())
    )];
    overrides.extend(set.iter().cloned());
    // An empty scene, not the built-in one: its generator would conflict with volume.file.
    let scene = Scene::parse("", "vmls probe --file", Path::new("."), &overrides)?;
    let field = scene.field(|_| {})?;
    let stats = field
        .octree
        .as_ref()
        .map(|o| o.stats(std::mem::size_of::<vmls::gpu_types::Sample>() as u64));
    let ctx = context(device)?;
    let compiler = ShaderCompiler::new()?;
    println!("device: {} ({})", ctx.info().name, ctx.info().driver);
    println!(
        "{}: {} samples ({})",
        file.display(),
        field.samples.len(),
        field.samples.provenance.kind
    );
    if let Some(s) = &stats {
        println!(
            "octree: {} nodes, {} references ({:.2} per sample), depth {}, {:.1} MiB, built in {:.0} ms",
            s.nodes,
            s.references,
            s.redundancy,
            s.depth,
            s.bytes as f64 / (1 << 20) as f64,
            s.build_ms
        );
    }
    let random = random_points(&field, points, 0.0, 7);
    let coherent = coherent_order(&field, random.clone());
    let mut rows = Vec::new();
    for (order, pts) in [("random", random), ("coherent", coherent)] {
        let m = mls_probe(&ctx, &compiler, &field, &pts, repeats)?;
        println!(
            "{} ({order} points): {:.3} M evaluations/s median, {:.1} neighbours/evaluation",
            m.variant,
            m.evaluations_per_s * 1e-6,
            m.mean_neighbours
        );
        rows.push(serde_json::json!({
            "variant": m.variant,
            "order": order,
            "gpu_ms": m.gpu_ms,
            "evaluations_per_s": m.evaluations_per_s,
            "mean_neighbours": m.mean_neighbours,
        }));
    }
    if let Some(path) = json {
        write_json(
            path,
            &serde_json::json!({
                "device": ctx.info().name,
                "file": file.display().to_string(),
                "samples": field.samples.len(),
                "octree": stats.as_ref().map(octree_json),
                "mls": rows,
            }),
        )?;
    }
    Ok(())
}

fn run_probe(
    resolution: usize,
    points: usize,
    repeats: u32,
    json: Option<&Path>,
    device: &DeviceArgs,
) -> Result<(), CliError> {
    let ctx = context(device)?;
    let compiler = ShaderCompiler::new()?;
    println!("device: {} ({})", ctx.info().name, ctx.info().driver);
    let fma = fma_probe(&ctx, &compiler, 16384, 4096, repeats)?;
    println!(
        "probe_fma: {:.1} GFLOP/s (median of {} dispatches, {:.2} ms each)",
        fma.gflops,
        fma.gpu_ms.len(),
        median(&fma.gpu_ms)
    );
    let mut rows = Vec::new();
    for mode in [NeighbourMode::Grid, NeighbourMode::Octree] {
        let scene = Scene::load(
            None,
            &[
                format!("volume.resolution={resolution}"),
                format!(
                    "reconstruction.neighbours=\"{}\"",
                    if mode == NeighbourMode::Grid {
                        "grid"
                    } else {
                        "octree"
                    }
                ),
            ],
        )?;
        let field = Field::new(
            load_volume(&scene)?,
            scene.reconstruction,
            &scene.octree,
            |_| {},
        )?;
        let random = random_points(&field, points, 0.0, 7);
        let coherent = coherent_order(&field, random.clone());
        for (order, pts) in [("random", random), ("coherent", coherent)] {
            let m = mls_probe(&ctx, &compiler, &field, &pts, repeats)?;
            let best =
                pts.len() as f64 / (m.gpu_ms.iter().copied().fold(f64::INFINITY, f64::min) * 1e-3);
            println!(
                "{} ({order} points): {:.2} M evaluations/s median ({:.2} best), {:.1} neighbours/evaluation, {:.1} GFLOP/s (39k+56) = {:.1}% of probe_fma",
                m.variant,
                m.evaluations_per_s * 1e-6,
                best * 1e-6,
                m.mean_neighbours,
                m.gflops,
                100.0 * m.gflops / fma.gflops.max(1e-9)
            );
            rows.push(serde_json::json!({
                "variant": m.variant,
                "order": order,
                "points": m.points,
                "gpu_ms": m.gpu_ms,
                "evaluations_per_s": m.evaluations_per_s,
                "mean_neighbours": m.mean_neighbours,
                "gflops": m.gflops,
                "fraction_of_fma": m.gflops / fma.gflops.max(1e-9),
            }));
        }
    }
    if let Some(path) = json {
        write_json(
            path,
            &serde_json::json!({
                "device": ctx.info().name,
                "fma": { "gflops": fma.gflops, "gpu_ms": fma.gpu_ms },
                "mls": rows,
            }),
        )?;
    }
    Ok(())
}

fn read_rgb(path: &Path) -> Result<image::Rgb32FImage, RenderError> {
    image::open(path)
        .map(|i| i.to_rgb32f())
        .map_err(|e| RenderError::Output {
            path: path.display().to_string(),
            message: format!("cannot read image: {e}"),
        })
}

fn compare(image: &Path, reference: &Path, diff: Option<&Path>) -> Result<(), CliError> {
    if let Some(d) = diff {
        vmls::render::output::format_of(d)?;
    }
    let (a, b) = (read_rgb(image)?, read_rgb(reference)?);
    if a.dimensions() != b.dimensions() {
        return Err(RenderError::Output {
            path: image.display().to_string(),
            message: format!(
                "size {:?} differs from the reference's {:?}",
                a.dimensions(),
                b.dimensions()
            ),
        }
        .into());
    }
    let diffs: Vec<f64> = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| f64::from(x - y))
        .collect();
    let rmse = (diffs.iter().map(|d| d * d).sum::<f64>() / diffs.len().max(1) as f64).sqrt();
    let per_pixel: Vec<f64> = diffs
        .chunks(3)
        .map(|c| c.iter().map(|d| d.abs()).fold(0.0, f64::max))
        .collect();
    let (at, max) =
        per_pixel.iter().enumerate().fold(
            (0, 0.0),
            |(i, m), (j, &d)| if d > m { (j, d) } else { (i, m) },
        );
    let w = a.width().max(1) as usize;
    println!("rmse {rmse:.6} max {max:.6} at ({}, {})", at % w, at / w);
    if let Some(path) = diff {
        let scale = if max > 0.0 { 1.0 / max } else { 0.0 };
        let heat: Vec<[f32; 4]> = per_pixel
            .iter()
            .map(|&d| {
                let [r, g, b] =
                    vmls::render::evalmap::ramp(d * scale).map(|v| f32::from(v) / 255.0);
                [r, g, b, 1.0]
            })
            .collect();
        vmls::render::output::write_image(path, a.width(), a.height(), &heat)?;
    }
    Ok(())
}

fn report(error: &dyn std::error::Error) -> String {
    let mut line = error.to_string();
    let mut source = error.source();
    while let Some(s) = source {
        let text = s.to_string();
        if !line.contains(&text) {
            line.push_str(": ");
            line.push_str(&text);
        }
        source = s.source();
    }
    line
}

fn main() {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Render {
            scene,
            output,
            stats,
            eval_map,
            set,
            frames,
            cpu: true,
            device: _,
        } => {
            if eval_map.is_some() || *frames != 1 {
                Err(CliError::Usage(
                    "--cpu renders one frame without evaluation counts: drop --eval-map and \
                     --frames"
                        .into(),
                ))
            } else {
                run_render_cpu(scene.as_deref(), output, stats.as_deref(), set)
            }
        }
        Command::Render {
            scene,
            output,
            stats,
            eval_map,
            set,
            frames,
            cpu: false,
            device,
        } => run_render(
            scene.as_deref(),
            output,
            stats.as_deref(),
            eval_map.as_deref(),
            set,
            *frames,
            device,
        ),
        Command::Compare {
            image,
            reference,
            diff,
        } => compare(image, reference, diff.as_deref()),
        Command::Info { file, array, set } => Scene::load(None, set)
            .map_err(CliError::from)
            .and_then(|scene| {
                Ok(vmls::info::describe(
                    file,
                    array.as_deref(),
                    &scene.samples,
                    &scene.octree,
                )?)
            })
            .map(|text| print!("{text}")),
        Command::Devices => Context::list_devices()
            .map(|lines| lines.iter().for_each(|l| println!("{l}")))
            .map_err(|e| CliError::from(RenderError::from(e))),
        Command::Probe {
            resolution,
            points,
            repeats,
            json,
            file,
            set,
            device,
        } => match file {
            Some(f) => run_file_probe(f, set, *points, *repeats, json.as_deref(), device),
            None => run_probe(*resolution, *points, *repeats, json.as_deref(), device),
        },
    };
    if let Err(e) = result {
        eprintln!("vmls: error: {}", report(&e));
        std::process::exit(1);
    }
}
