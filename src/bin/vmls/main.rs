//! The `vmls` command line: `render`, `info`, `devices`, `probe`, `compare`, `bench`, `check`.
//!
//! Errors print one line (`vmls: error: …`, with the cause chain) and exit with status 1; usage
//! errors exit with clap's status 2. Progress bars appear only when stderr is a terminal.

#![deny(unsafe_code)]
#![deny(clippy::unwrap_used, clippy::expect_used)]

mod bench;
mod bricks;
mod check;
mod compare;
#[cfg(feature = "mpi")]
mod distributed;
mod probe;
mod render;
mod signals;

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use vmls::field::RenderError;
use vmls::files::Outputs;
use vmls::scene::{Scene, SceneError};
use vmls::vk::{Context, ContextOptions};

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

#[derive(clap::Args, Clone)]
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
        /// Write the per-pixel count of MLS evaluations as a heat map with a legend (.png), or
        /// the counts themselves (.exr: R = G = B = count).
        #[arg(long)]
        eval_map: Option<PathBuf>,
        /// Override a scene key: section.key=value (repeatable).
        #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
        set: Vec<String>,
        /// Render this many frames with one persistent renderer, turning the camera 10° about
        /// its up axis each frame; the last is written, `--stats` lists every frame's cost.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
        frames: u32,
        /// Render with the f64 CPU twins of the kernels instead of the GPU: slow, for ground
        /// truth (e.g. reconstruction.method = "gaussian" with render.method = "reference", the
        /// exact image splatting approximates).
        #[arg(long)]
        cpu: bool,
        /// Render even when the frame plans more evaluations (MLS, or splatted footprint
        /// pixels) than the work budget (4e9, minutes on lavapipe): the budget keeps a
        /// mistyped step or sheet from occupying the device for hours.
        #[arg(long)]
        force: bool,
        /// Render to this accepted error instead of a step: the 99th percentile of the
        /// per-pixel RGBA error against the converged image (`render.tolerance`; README,
        /// "Rendering to a tolerance").
        #[arg(long, value_name = "E")]
        tolerance: Option<f64>,
        /// Divide the field into N kd bricks with ghosts, render each alone (ray casting: rays
        /// clipped to its box, steps where the undivided frame's are; splatting: the sheets
        /// whose midpoints lie in its cell) and composite them front to back in f64 on this
        /// device: the reference of a distributed render (README, "Bricks").
        #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=4096))]
        bricks: Option<u32>,
        /// Render across MPI ranks (`mpirun -np N vmls render … --mpi`; a build with the `mpi`
        /// feature): each rank renders its kd brick, IceT composites them in visibility
        /// order, rank 0 writes the image (README, "Bricks").
        #[arg(long)]
        mpi: bool,
        /// With --mpi: IceT's single-image compositing strategy (radixk, bswap, tree).
        #[arg(long, value_name = "NAME", default_value = "radixk")]
        icet_strategy: String,
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
    /// Sweep methods and settings over a scene: GPU time, error against a cached reference,
    /// `results.csv`/`.json` and the speed–error plot `speed_error.svg`/`.png`.
    Bench(bench::BenchArgs),
    /// Run the numerical hard cases and convergence orders, each against a stated bound;
    /// exits non-zero when any fails.
    Check(check::CheckArgs),
    /// Measure the FMA ceiling and MLS evaluation throughput side by side.
    Probe {
        /// Marschner–Lobb resolution of the probe field (2–1024).
        #[arg(long, default_value_t = 41, value_parser = clap::value_parser!(u32).range(2..=1024))]
        resolution: u32,
        /// Evaluation points per dispatch (1–16 777 216).
        #[arg(long, default_value_t = 65536, value_parser = clap::value_parser!(u32).range(1..=1 << 24))]
        points: u32,
        /// Timed repetitions after one warm-up (1–1000).
        #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=1000))]
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
    #[error(transparent)]
    Bench(#[from] vmls::bench::BenchError),
    #[error("{0}")]
    Usage(String),
    /// Failed where another process reports why (an MPI rank other than 0): exit 1 silently.
    #[cfg(feature = "mpi")]
    #[error("failed; another rank reports why")]
    Quiet,
    /// Failed and already reported ([`report_failure`]): exit with this status.
    #[cfg(feature = "mpi")]
    #[error("failed (reported)")]
    Reported(i32),
}

impl From<vmls::files::FileError> for CliError {
    fn from(e: vmls::files::FileError) -> Self {
        CliError::Render(e.into())
    }
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
        sync_validation: None,
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

/// Plans a command's outputs (see [`vmls::files::Outputs`]): the scene file and the data files
/// it names are inputs no output may be.
fn plan_outputs(
    scene_path: Option<&Path>,
    scene: Option<&Scene>,
    outputs: &[(&str, Option<&Path>)],
) -> Result<Outputs, CliError> {
    let mut inputs: Vec<(&str, &Path)> = scene_path.map(|p| ("scene", p)).into_iter().collect();
    if let Some(scene) = scene {
        inputs.extend(scene.input_files());
    }
    // A parallel VTK XML file's pieces are inputs too (an unreadable summary is the load's
    // error to report).
    let pieces: Vec<std::path::PathBuf> = inputs
        .iter()
        .filter(|(_, p)| vmls::data::vtk_xml_parallel::is_parallel(p))
        .filter_map(|(_, p)| vmls::data::vtk_xml_parallel::Summary::read(p).ok())
        .flat_map(|s| s.pieces.into_iter().map(|p| p.source))
        .collect();
    inputs.extend(
        pieces
            .iter()
            .map(|p| ("a piece of volume.file", p.as_path())),
    );
    let outputs: Vec<(&str, &Path)> = outputs
        .iter()
        .filter_map(|&(role, p)| p.map(|p| (role, p)))
        .collect();
    Ok(Outputs::new(&outputs, &inputs)?)
}

/// Writes `value` as pretty JSON to `path`, one of the planned `outputs`, and commits them.
fn write_json(
    mut outputs: Outputs,
    path: &Path,
    value: &serde_json::Value,
) -> Result<(), CliError> {
    outputs.write(path, json_to(value))?;
    Ok(outputs.commit()?)
}

/// Writes `value` as pretty JSON and a newline.
fn json_to(
    value: &serde_json::Value,
) -> impl FnOnce(&mut std::io::BufWriter<&std::fs::File>) -> std::io::Result<()> + '_ {
    move |w| {
        serde_json::to_writer_pretty(&mut *w, value)?;
        w.write_all(b"\n")
    }
}

/// Fails with [`RenderError::Interrupted`] once a stop was requested.
fn check_stop(stop: &AtomicBool) -> Result<(), CliError> {
    if stop.load(Ordering::SeqCst) {
        return Err(RenderError::Interrupted.into());
    }
    Ok(())
}

/// Longest error line the CLI prints, in characters.
const MAX_REPORT_CHARS: usize = 2000;

/// The error and its causes on one line. Every quote of input is already a short escaped
/// excerpt; as a last guard the line is escaped again (no control character reaches the
/// terminal) and cut to [`MAX_REPORT_CHARS`], whatever a lower layer or crate put in it.
/// `vmls render --mpi` in a build with the `mpi` feature.
#[cfg(feature = "mpi")]
fn run_render_mpi(
    request: &render::Request<'_>,
    strategy: &str,
    device: &DeviceArgs,
    stop: &AtomicBool,
) -> Result<(), CliError> {
    distributed::run_render_mpi(request, strategy, device, stop)
}

/// `vmls render --mpi` in a build without it: refused.
#[cfg(not(feature = "mpi"))]
fn run_render_mpi(
    _: &render::Request<'_>,
    _: &str,
    _: &DeviceArgs,
    _: &AtomicBool,
) -> Result<(), CliError> {
    Err(CliError::Usage(
        "--mpi: this vmls was built without the mpi feature; build it with `cargo build \
         --release --features mpi` (tools/setup --mpi installs OpenMPI, IceT and libclang)"
            .into(),
    ))
}

fn report(error: &dyn std::error::Error) -> String {
    vmls::files::printable(&chain(error), MAX_REPORT_CHARS)
}

fn chain(error: &dyn std::error::Error) -> String {
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

/// Where compiled kernels are kept between runs (vmls::vk::use_disk_cache): `VMLS_SHADER_CACHE`
/// (a directory, or `off`), else `$XDG_CACHE_HOME/vmls/shaders` or `~/.cache/vmls/shaders`.
fn shader_cache_dir() -> Option<PathBuf> {
    match std::env::var_os("VMLS_SHADER_CACHE") {
        Some(v) if v == "off" || v == "0" || v.is_empty() => None,
        Some(v) => Some(PathBuf::from(v)),
        None => std::env::var_os("XDG_CACHE_HOME")
            .map(PathBuf::from)
            .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
            .map(|base| base.join("vmls").join("shaders")),
    }
}

fn main() {
    let cli = Cli::parse();
    vmls::vk::use_disk_cache(shader_cache_dir());
    let stop = signals::install(matches!(cli.command, Command::Render { .. }));
    let result = match &cli.command {
        Command::Render {
            scene,
            output,
            stats,
            eval_map,
            set,
            frames,
            cpu,
            force,
            tolerance,
            bricks,
            mpi,
            icet_strategy,
            device,
        } => {
            // --tolerance E is `--set render.tolerance=E`, after the other overrides.
            let set: &Vec<String> = &set
                .iter()
                .cloned()
                .chain(tolerance.map(|e| format!("render.tolerance={e:e}")))
                .collect();
            if *cpu && (bricks.is_some() || *mpi) {
                Err(CliError::Usage(
                    "--bricks and --mpi render on the GPU; drop --cpu".into(),
                ))
            } else if *mpi && bricks.is_some() {
                Err(CliError::Usage(
                    "--mpi divides the field into one brick per rank: drop --bricks".into(),
                ))
            } else if *cpu {
                if tolerance.is_some() {
                    Err(CliError::Usage(
                        "--cpu renders with the scene's parameters: --tolerance chooses them \
                         with pilot frames on the GPU"
                            .into(),
                    ))
                } else if eval_map.is_some() || *frames != 1 {
                    Err(CliError::Usage(
                        "--cpu renders one frame without evaluation counts: drop --eval-map and \
                     --frames"
                            .into(),
                    ))
                } else {
                    render::run_render_cpu(
                        scene.as_deref(),
                        output,
                        stats.as_deref(),
                        set,
                        *force,
                        &stop,
                    )
                }
            } else {
                let request = render::Request {
                    scene_path: scene.as_deref(),
                    output,
                    stats: stats.as_deref(),
                    eval_map: eval_map.as_deref(),
                    set,
                    frames: *frames,
                    force: *force,
                };
                match bricks {
                    _ if *mpi => run_render_mpi(&request, icet_strategy, device, &stop),
                    Some(n) => bricks::run_render_bricks(&request, *n, device, &stop),
                    None => render::run_render(&request, device, &stop),
                }
            }
        }
        Command::Bench(args) => bench::bench(args),
        Command::Check(args) => check::check(args),
        Command::Compare {
            image,
            reference,
            diff,
        } => compare::compare(image, reference, diff.as_deref()),
        Command::Info { file, array, set } => Scene::load(None, set)
            .map_err(CliError::from)
            .and_then(|scene| {
                Ok(vmls::info::describe(
                    file,
                    array.as_deref(),
                    &scene.samples,
                    scene.reconstruction,
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
            Some(f) => {
                probe::run_file_probe(f, set, *points as usize, *repeats, json.as_deref(), device)
            }
            None => probe::run_probe(
                *resolution as usize,
                *points as usize,
                *repeats,
                json.as_deref(),
                device,
            ),
        },
    };
    if let Err(e) = result {
        std::process::exit(report_failure(&e));
    }
}

/// Prints `e` (unless another process reports it, or it was reported already) and returns the
/// exit status it ends with.
fn report_failure(e: &CliError) -> i32 {
    #[cfg(feature = "mpi")]
    match e {
        CliError::Quiet => return 1,
        CliError::Reported(status) => return *status,
        _ => {}
    }
    eprintln!("vmls: error: {}", report(e));
    if matches!(e, CliError::Render(RenderError::Interrupted)) {
        signals::exit_status()
    } else {
        1
    }
}
