//! `vmls probe`: the device's ceilings and MLS evaluation throughput, side by side.

use crate::{CliError, DeviceArgs, context, plan_outputs, write_json};
use std::path::Path;
use vmls::field::{Field, RenderError};
use vmls::probe::{
    MemoryMode, coherent_order, fma_probe, leaf_reuse, median, memory_probe, mls_probe,
    random_points,
};
use vmls::scene::{NeighbourMode, Scene, load_volume};
use vmls::vk::ShaderCompiler;

pub fn octree_json(s: &vmls::recon::OctreeStats) -> serde_json::Value {
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

/// Steps, in sample spacings, at which the probe reports [`leaf_reuse`].
const REUSE_STEPS: [f64; 3] = [1.0, 0.25, 0.0625];

/// How often a fixed-step ray's consecutive samples share an octree leaf (printed, and the
/// rows of `--json`): what keeping the leaf between samples could save of the descents.
fn leaf_reuse_rows(field: &Field) -> Result<Vec<serde_json::Value>, CliError> {
    let Some(octree) = field.octree().map_err(RenderError::from)? else {
        return Ok(Vec::new());
    };
    let (lo, hi) = field.bounds();
    let mut rows = Vec::new();
    for steps in REUSE_STEPS {
        let step = steps * field.samples.spacing;
        let r = leaf_reuse(octree, (lo.to_array(), hi.to_array()), 2000, step, 5);
        println!(
            "leaf reuse at a step of {steps} spacings: {:.1}% of {} consecutive sample pairs \
             share a leaf",
            100.0 * r.rate(),
            r.pairs
        );
        rows.push(serde_json::json!({
            "step_spacings": steps,
            "pairs": r.pairs,
            "same_leaf": r.same_leaf,
            "rate": r.rate(),
        }));
    }
    Ok(rows)
}

pub fn run_file_probe(
    file: &Path,
    set: &[String],
    points: usize,
    repeats: u32,
    json: Option<&Path>,
    device: &DeviceArgs,
) -> Result<(), CliError> {
    // The general path, as the probe's name says (a scene file's default is "auto", which
    // would measure the fast path's interpolation); --set reconstruction.resample=N still wins.
    let mut overrides = vec![
        format!(
            "volume.file={}",
            toml::Value::String(file.display().to_string())
        ),
        "reconstruction.resample=0".to_string(),
    ];
    overrides.extend(set.iter().cloned());
    // An empty scene, not the built-in one: its generator would conflict with volume.file.
    let scene = Scene::parse("", "vmls probe --file", Path::new("."), &overrides)?;
    let outputs = plan_outputs(None, Some(&scene), &[("--json", json)])?;
    let field = scene.field(|_| {})?;
    let stats = field
        .octree()
        .map_err(RenderError::from)?
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
    let reuse = leaf_reuse_rows(&field)?;
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
            outputs,
            path,
            &serde_json::json!({
                "device": ctx.info().name,
                "file": file.display().to_string(),
                "samples": field.samples.len(),
                "octree": stats.as_ref().map(octree_json),
                "leaf_reuse": reuse,
                "mls": rows,
            }),
        )?;
    }
    Ok(())
}

pub fn run_probe(
    resolution: usize,
    points: usize,
    repeats: u32,
    json: Option<&Path>,
    device: &DeviceArgs,
) -> Result<(), CliError> {
    let outputs = plan_outputs(None, None, &[("--json", json)])?;
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
    let mut memory = Vec::new();
    for mode in MemoryMode::ALL {
        let m = memory_probe(&ctx, &compiler, mode, 16384, 256, repeats)?;
        println!(
            "{}: {:.3} G operations/s, {:.2} GB/s (median of {} dispatches)",
            mode.name(),
            m.loads_per_s * 1e-9,
            m.bytes_per_s * 1e-9,
            m.gpu_ms.len()
        );
        memory.push(serde_json::json!({
            "kernel": mode.name(),
            "gpu_ms": m.gpu_ms,
            "loads_per_s": m.loads_per_s,
            "bytes_per_s": m.bytes_per_s,
        }));
    }
    let mut rows = Vec::new();
    let mut reuse = Vec::new();
    // The octree twice, its leaves read through coded references and as inline records
    // (`octree.records`), side by side with the grid.
    for (mode, records) in [
        (NeighbourMode::Grid, "auto"),
        (NeighbourMode::Octree, "coded"),
        (NeighbourMode::Octree, "inline"),
    ] {
        let scene = Scene::load(
            None,
            &[
                format!("volume.resolution={resolution}"),
                // The MLS solve itself (the default scene takes the fast path).
                "reconstruction.resample=0".into(),
                format!(
                    "reconstruction.neighbours=\"{}\"",
                    if mode == NeighbourMode::Grid {
                        "grid"
                    } else {
                        "octree"
                    }
                ),
                format!("octree.records=\"{records}\""),
            ],
        )?;
        let field = Field::new(
            load_volume(&scene)?,
            scene.reconstruction,
            &scene.octree,
            |_| {},
        )?;
        if mode == NeighbourMode::Octree && records == "coded" {
            reuse = leaf_reuse_rows(&field)?;
        }
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
            outputs,
            path,
            &serde_json::json!({
                "device": ctx.info().name,
                "fma": { "gflops": fma.gflops, "gpu_ms": fma.gpu_ms },
                "memory": memory,
                "mls": rows,
                "leaf_reuse": reuse,
            }),
        )?;
    }
    Ok(())
}
