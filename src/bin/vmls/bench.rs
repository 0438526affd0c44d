//! `vmls bench`: the CLI over `vmls::bench` — a progress bar, a terminal table as rows arrive,
//! and the result files.

use crate::{CliError, DeviceArgs, context};
use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::path::PathBuf;
use vmls::bench::reference::ReferenceMode;
use vmls::bench::results::{Row, csv_bytes, json_bytes, read_csv};
use vmls::bench::{BenchOptions, Event, Sweep, plot, run, run_context, variant_defines};
use vmls::files::Outputs;

#[derive(clap::Args)]
pub struct BenchArgs {
    /// Scene file (TOML); the built-in Marschner–Lobb scene when none is given.
    scene: Option<PathBuf>,
    /// Methods to measure, comma-separated (fixed, adaptive, riemann, reference, splat,
    /// splat-post); default: the scene's.
    #[arg(long, value_delimiter = ',')]
    methods: Vec<String>,
    /// Sweep a scene key over values: section.key=v1,v2,… (repeatable; every combination runs).
    #[arg(long = "sweep", value_name = "SECTION.KEY=V1,V2,…")]
    sweep: Vec<String>,
    /// Override a scene key for every configuration and the reference (repeatable).
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    set: Vec<String>,
    /// Override a scene key for the reference only, e.g. render.reference_step=0.01.
    #[arg(long = "reference-set", value_name = "SECTION.KEY=VALUE")]
    reference_set: Vec<String>,
    /// Render the reference with the f64 CPU twins instead of the GPU (slow, device-independent).
    #[arg(long)]
    reference_cpu: bool,
    /// For a generated volume, measure error against the scene's own reconstruction instead of
    /// the analytic field.
    #[arg(long)]
    own_reference: bool,
    /// Reference cache directory (default: $XDG_CACHE_HOME/vmls/references or
    /// ~/.cache/vmls/references); --no-cache renders it every run.
    #[arg(long)]
    cache: Option<PathBuf>,
    #[arg(long)]
    no_cache: bool,
    /// Timed frames per configuration.
    #[arg(long, default_value_t = 5)]
    repeat: u32,
    /// Frames rendered and discarded after the first one, before timing; where at least one
    /// on a GPU, more until they have lasted a second (its clocks come back up from idle).
    #[arg(long, default_value_t = 1)]
    warmup: u32,
    /// Output directory: results.csv, results.json, speed_error.svg/.png, images/.
    #[arg(long, default_value = "target/bench-out/bench")]
    out: PathBuf,
    /// Merge rows measured elsewhere (another device, a peer) into the table and plot
    /// (repeatable; the CSV columns of results.csv).
    #[arg(long)]
    import: Vec<PathBuf>,
    /// Run a peer renderer on the same scene in the same run and plot it on the same axes
    /// (vtk: tools/peer-vtk, VTK's GPU ray caster; never in CI).
    #[arg(long)]
    peer: Vec<String>,
    /// Print each configuration's shader variant: its kernels and macro definitions.
    #[arg(long)]
    variant: bool,
    /// Write each configuration's SPIR-V (NNN-kernel.spv) to this directory.
    #[arg(long)]
    dump_spirv: Option<PathBuf>,
    /// Skip measuring the device's ceilings (FMA, gathers) and each row's share of them.
    #[arg(long)]
    no_ceilings: bool,
    /// Measure frames past the work budget (4e9 MLS or footprint-pixel evaluations per
    /// frame, reference included); without it such a frame ends the bench before its work.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    device: DeviceArgs,
}

fn cache_dir(args: &BenchArgs) -> Option<PathBuf> {
    if args.no_cache {
        return None;
    }
    if let Some(c) = &args.cache {
        return Some(c.clone());
    }
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))?;
    Some(base.join("vmls").join("references"))
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |x| format!("{x:.digits$}"))
}

fn header() -> String {
    // A row without GPU timestamps (a peer) shows its wall time, marked w.
    format!(
        "{:<3} {:<10} {:<38} {:>10} {:>17} {:>10} {:>11} {:>9} {:>9} {:>9} {:>7}",
        "#",
        "method",
        "settings",
        "gpu ms",
        "[min, max]",
        "first ms",
        "evals",
        "rmse",
        "p99 rgba",
        "max",
        "psnr"
    )
}

fn line(i: usize, r: &Row) -> String {
    // Rows may be imported: every text field is escaped and cut as error lines are.
    let settings = vmls::files::printable(&r.short_settings(), 35);
    let method = vmls::files::printable(&r.method, 10);
    format!(
        "{:<3} {:<10} {:<38} {:>10} {:>17} {:>10.1} {:>11} {:>9} {:>9} {:>9} {:>7}  {}{}",
        i,
        method,
        settings,
        r.gpu_ms
            .map_or(format!("{:.2}w", r.wall_ms), |g| format!("{g:.2}")),
        format!("[{}, {}]", opt(r.gpu_ms_min, 1), opt(r.gpu_ms_max, 1)),
        r.first_frame_wall_ms,
        r.evaluations.map_or("-".into(), |e| e.to_string()),
        opt(r.rmse, 5),
        opt(r.p99, 5),
        opt(r.max_abs, 4),
        opt(r.psnr, 1),
        match (
            r.bound_by.as_str(),
            r.fma_share.zip(r.memory_share).map(|(f, g)| f.max(g))
        ) {
            ("", _) | (_, None) => "-".to_string(),
            (b, Some(x)) => format!("{} {:.0}%", vmls::files::printable(b, 12), 100.0 * x),
        },
        match r.non_finite {
            Some(n) if n > 0 => format!("  {n} NON-FINITE"),
            _ => String::new(),
        }
    )
}

pub fn bench(args: &BenchArgs) -> Result<(), CliError> {
    let sweeps = args
        .sweep
        .iter()
        .map(|s| Sweep::parse(s))
        .collect::<Result<Vec<_>, _>>()?;
    if let Some(bad) = args
        .peer
        .iter()
        .find(|p| !vmls::bench::peer::PEERS.contains(&p.as_str()))
    {
        return Err(CliError::Usage(format!(
            "--peer {bad}: unknown peer (known: {})",
            vmls::bench::peer::PEERS.join(", ")
        )));
    }
    // Imports are read first: a bad file fails before minutes of measurement.
    let mut imported = Vec::new();
    for path in &args.import {
        imported.extend(read_csv(path)?);
    }
    let opts = BenchOptions {
        scene: args.scene.clone(),
        set: args.set.clone(),
        methods: args.methods.clone(),
        sweeps,
        repeat: args.repeat,
        warmup: args.warmup,
        out: args.out.clone(),
        reference: if args.reference_cpu {
            ReferenceMode::Cpu
        } else {
            ReferenceMode::Gpu
        },
        reference_set: args.reference_set.clone(),
        analytic_reference: !args.own_reference,
        cache: cache_dir(args),
        print_variant: args.variant,
        dump_spirv: args.dump_spirv.clone(),
        ceilings: !args.no_ceilings,
        force: args.force,
        imports: args.import.clone(),
    };
    // Every result file is planned before any work: one that is an input (the scene, its
    // data file, an imported CSV) or an unwritable directory fails now, not after minutes.
    std::fs::create_dir_all(&args.out).map_err(|e| {
        CliError::from(vmls::files::FileError::Io {
            path: args.out.clone(),
            action: "create the directory",
            source: e,
        })
    })?;
    let base = vmls::scene::Scene::load(args.scene.as_deref(), &args.set)?;
    let inputs = vmls::bench::inputs(&opts, &base);
    let mut names = vec![
        "results.csv",
        "results.json",
        "speed_error.svg",
        "speed_error.png",
    ];
    // Rendered to a tolerance (the scene, --set or a sweep): the measured-against-requested
    // plot too.
    let tolerance_plot =
        base.render.tolerance.is_some() || opts.sweeps.iter().any(|s| s.key == "render.tolerance");
    if tolerance_plot {
        names.extend(["tolerance.svg", "tolerance.png"]);
    }
    let paths: Vec<std::path::PathBuf> = names.iter().map(|n| args.out.join(n)).collect();
    let planned: Vec<(&str, &std::path::Path)> = names
        .iter()
        .zip(&paths)
        .map(|(n, p)| (*n, p.as_path()))
        .collect();
    let outputs = Outputs::new(&planned, &vmls::bench::outputs::refs(&inputs))?;
    let mut measured_ceilings = None;
    let ctx = context(&args.device)?;
    println!("device: {} ({})", ctx.info().name, ctx.info().driver);
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::new(1)
    } else {
        ProgressBar::hidden()
    };
    if let Ok(style) = ProgressStyle::with_template("{msg:>10} [{bar:30}] {pos}/{len} {elapsed}") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message("reference");
    // A hidden bar drops its println; the table still goes to stdout.
    let say = |text: String| {
        if bar.is_hidden() {
            println!("{text}");
        } else {
            bar.println(text);
        }
    };
    let (mut rows, reference) = run(&ctx, &opts, |event| match event {
        Event::Reference(r) => {
            say(format!(
                "reference: {}{}",
                r.description,
                if r.cached { " (cached)" } else { "" }
            ));
            say(header());
        }
        Event::Ceilings(c) => {
            measured_ceilings = Some(*c);
            say(format!(
                "ceilings: probe_fma {:.1} GFLOP/s; gathers {:.1} M/s random, {:.1} M/s \
                 coherent; texel gathers {:.1} / {:.1} M/s; ray-march texel gathers {:.1} M/s; \
                 atomic adds {:.1} M/s",
                c.fma_gflops,
                c.gathers_per_s * 1e-6,
                c.coherent_gathers_per_s * 1e-6,
                c.texel_gathers_per_s * 1e-6,
                c.coherent_texel_gathers_per_s * 1e-6,
                c.march_texel_gathers_per_s * 1e-6,
                c.atomic_adds_per_s * 1e-6
            ));
        }
        Event::Start { index, total, .. } => {
            bar.set_length(total as u64);
            bar.set_position(index as u64);
            bar.set_message("measuring");
        }
        Event::Variant { name, kernels } => {
            say(format!("    variant {name}"));
            for (k, defines) in kernels {
                let d: Vec<String> = variant_defines(defines)
                    .iter()
                    .map(|(n, v)| format!("{n}={v}"))
                    .collect();
                say(format!("      {k}: {}", d.join(" ")));
            }
        }
        Event::Row(r) => {
            bar.inc(1);
            say(line(bar.position() as usize - 1, r));
        }
    })?;
    bar.finish_and_clear();
    let title = format!(
        "{} on {}",
        args.scene
            .as_ref()
            .map_or("built-in scene".into(), |p| p.display().to_string()),
        ctx.info().name
    );
    let context = run_context(&ctx, &opts, &reference, measured_ceilings.as_ref());
    let write_all = |mut outputs: Outputs, rows: &[Row]| -> Result<(), CliError> {
        let (svg, png) = plot::speed_error_files(rows, &title)?;
        let mut contents = vec![csv_bytes(rows)?, json_bytes(&context, rows)?, svg, png];
        if tolerance_plot {
            let (svg, png) = plot::tolerance_files(rows, &title)?;
            contents.extend([svg, png]);
        }
        for (path, bytes) in paths.iter().zip(&contents) {
            outputs.write(path, |w| std::io::Write::write_all(w, bytes))?;
        }
        Ok(outputs.commit()?)
    };
    for name in &args.peer {
        match vmls::bench::peer::run_peer(name, &opts, &reference) {
            Ok(peer_rows) => {
                for r in peer_rows {
                    println!("{} (peer {name})", line(rows.len(), &r));
                    rows.push(r);
                }
            }
            Err(e) => {
                // Keep what vmls measured: minutes of work.
                write_all(outputs, &rows)?;
                eprintln!(
                    "vmls: wrote {} before the peer failed",
                    args.out.join("results.csv").display()
                );
                return Err(e.into());
            }
        }
    }
    for (i, r) in imported.iter().enumerate() {
        println!(
            "{} (imported from {})",
            line(rows.len() + i, r),
            vmls::files::printable(&r.source, 60)
        );
    }
    rows.extend(imported);
    write_all(outputs, &rows)?;
    let front = vmls::bench::results::pareto_front(&rows);
    println!(
        "Pareto front: {}",
        front
            .iter()
            .map(|&i| format!("#{i}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!(
        "wrote {} (and results.json, speed_error.svg/.png, {}images/)",
        args.out.join("results.csv").display(),
        if tolerance_plot {
            "tolerance.svg/.png, "
        } else {
            ""
        }
    );
    Ok(())
}
