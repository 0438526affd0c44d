//! `vmls render --mpi`: one scene across MPI ranks (run under `mpirun`), each rank ray casting
//! its kd brick, IceT compositing them in visibility order, rank 0 writing the image and the
//! statistics (issue 30). Built with the cargo feature `mpi`.

use crate::bricks::{check_frame_budget, write_composite};
use crate::render::Request;
use crate::{
    CliError, DeviceArgs, check_stop, context, json_to, plan_outputs, report, report_failure,
};
use mpi::Threading;
use mpi::topology::SimpleCommunicator;
use mpi::traits::{Communicator, CommunicatorCollectives};
use std::sync::atomic::AtomicBool;
use std::time::Instant;
use vmls::distributed::{DistributedError, RankBrick, Strategy, agree};
use vmls::field::RenderError;
use vmls::output::format_of;
use vmls::scene::Scene;

impl From<DistributedError> for CliError {
    fn from(e: DistributedError) -> Self {
        match e {
            // Rank 0 says what failed; the other ranks exit non-zero without a word.
            DistributedError::Elsewhere { .. } => CliError::Quiet,
            other => CliError::Usage(other.to_string()),
        }
    }
}

/// The scene's volume file and array where the ranks read their own pieces
/// (`vmls::bricks::parallel::ranks_read`).
fn parallel_image(scene: &Scene) -> Option<(&std::path::Path, Option<&str>)> {
    match &scene.volume {
        vmls::scene::VolumeSource::File { path, array }
            if vmls::bricks::parallel::ranks_read(path) =>
        {
            Some((path.as_path(), array.as_deref()))
        }
        _ => None,
    }
}

/// Renders `request`'s scene across the ranks of MPI_COMM_WORLD.
pub fn run_render_mpi(
    request: &Request<'_>,
    strategy: &str,
    device: &DeviceArgs,
    stop: &AtomicBool,
) -> Result<(), CliError> {
    let strategy = Strategy::ALL
        .iter()
        .find(|(n, _)| *n == strategy)
        .map(|&(_, s)| s)
        .ok_or_else(|| {
            CliError::Usage(format!(
                "--icet-strategy {strategy}: expected radixk, bswap or tree"
            ))
        })?;
    // Only the main thread calls MPI (rayon's and the signal thread never do).
    let Some((universe, _)) = mpi::initialize_with_threading(Threading::Funneled) else {
        return Err(CliError::Usage("MPI was initialised twice".into()));
    };
    let world = universe.world();
    let result = run(&world, request, strategy, device, stop);
    // mpirun ends the job as soon as one rank exits non-zero, which could cut off rank 0's
    // report of a failure: rank 0 prints it before any rank leaves this barrier (every rank
    // reaches it, since failures are agreed on and only rank 0 works after the last collective).
    let result = result.map_err(|e| CliError::Reported(report_failure(&e)));
    world.barrier();
    result
}

/// The device this rank opens: the one named (`--device`, `VMLS_DEVICE`), else, where the node
/// has several of the preferred kind, the one its local rank takes round robin (one process per
/// device; OpenMPI's, MPICH's and Slurm's local-rank variables).
fn rank_device(device: &DeviceArgs) -> Result<DeviceArgs, CliError> {
    let named = device.device.is_some() || std::env::var_os("VMLS_DEVICE").is_some();
    let local = [
        "OMPI_COMM_WORLD_LOCAL_RANK",
        "MPI_LOCALRANKID",
        "SLURM_LOCALID",
    ]
    .iter()
    .find_map(|v| std::env::var(v).ok()?.parse::<usize>().ok());
    let mut chosen = device.clone();
    if let (false, Some(local)) = (named, local) {
        let index = vmls::vk::Context::device_for_process(local).map_err(RenderError::from)?;
        chosen.device = index.map(|i| i.to_string());
    }
    Ok(chosen)
}

fn run(
    world: &SimpleCommunicator,
    request: &Request<'_>,
    strategy: Strategy,
    device: &DeviceArgs,
    stop: &AtomicBool,
) -> Result<(), CliError> {
    let start = Instant::now();
    let root = world.rank() == 0;
    let loaded = (|| -> Result<_, CliError> {
        if request.eval_map.is_some() || request.frames != 1 {
            return Err(CliError::Usage(
                "--mpi renders one frame without evaluation maps: drop --eval-map and --frames"
                    .into(),
            ));
        }
        format_of(request.output)?;
        let scene = Scene::load(request.scene_path, request.set)?;
        // Rank 0 writes; its outputs are checked before any rank renders.
        let outputs = if root {
            Some(plan_outputs(
                request.scene_path,
                Some(&scene),
                &[("-o", Some(request.output)), ("--stats", request.stats)],
            )?)
        } else {
            None
        };
        let ctx = context(&rank_device(device)?)?;
        // Rank 0 reads the data and sends each rank its piece, unless the ranks read their own
        // pieces of a parallel file.
        let field = if root && parallel_image(&scene).is_none() {
            let field = scene.field_on(Some(ctx.info()), |_| {})?;
            if !request.force {
                check_frame_budget(&scene, &field)?;
            }
            Some(field)
        } else {
            None
        };
        check_stop(stop)?;
        Ok((scene, outputs, ctx, field))
    })();
    let (scene, outputs, ctx, field) = agree(world, loaded.map_err(|e| report(&e)))?;
    let mut brick = match parallel_image(&scene) {
        Some((path, array)) => {
            let brick = RankBrick::read_parallel(
                world,
                &ctx,
                path,
                array,
                &scene.samples,
                &scene.view(),
                scene.reconstruction,
                scene.octree,
            )?;
            // The frame's budget, judged on each rank's piece (it keeps the whole domain).
            let checked = match request.force {
                true => Ok(()),
                false => check_frame_budget(&scene, brick.field()).map_err(|e| report(&e)),
            };
            agree(world, checked)?;
            brick
        }
        None => RankBrick::scatter(
            world,
            &ctx,
            field.as_ref(),
            &scene.view(),
            scene.reconstruction,
            scene.octree,
        )?,
    };
    drop(field);
    let frame = brick.render(world, &scene.view(), strategy)?;
    drop(brick);
    let (Some(frame), Some(mut outputs)) = (frame, outputs) else {
        return Ok(());
    };
    let (w, h) = (scene.camera.width, scene.camera.height);
    write_composite(&ctx, &mut outputs, request.output, (w, h), &frame.pixels)?;
    if let Some(path) = request.stats {
        let ranks = &frame.ranks;
        let mean = |f: fn(&vmls::distributed::RankReport) -> f64| {
            ranks.iter().map(f).sum::<f64>() / ranks.len().max(1) as f64
        };
        let max =
            |f: fn(&vmls::distributed::RankReport) -> f64| ranks.iter().map(f).fold(0.0, f64::max);
        let value = serde_json::json!({
            "device": ctx.info().name,
            "method": scene.render.method.name(),
            "width": w,
            "height": h,
            "ranks": world.size(),
            "icet_strategy": format!("{strategy:?}"),
            "order": frame.order,
            "render_gpu_ms": { "max": max(|r| r.render_gpu_ms), "mean": mean(|r| r.render_gpu_ms) },
            "render_wall_ms": { "max": max(|r| r.render_wall_ms), "mean": mean(|r| r.render_wall_ms) },
            "composite_ms": { "max": max(|r| r.composite_ms), "mean": mean(|r| r.composite_ms) },
            "composite_wall_ms_rank0": frame.composite_wall_ms,
            "bytes_sent": { "max": max(|r| r.bytes_sent), "mean": mean(|r| r.bytes_sent) },
            "wall_ms": start.elapsed().as_secs_f64() * 1e3,
            "per_rank": ranks.iter().map(|r| serde_json::json!({
                "rank": r.rank,
                "samples_inside": r.samples,
                "ghosts": r.ghosts,
                "divide_ms": r.divide_ms,
                "pieces_read": r.pieces_read,
                "render_gpu_ms": r.render_gpu_ms,
                "render_wall_ms": r.render_wall_ms,
                "composite_ms": r.composite_ms,
                "bytes_sent": r.bytes_sent,
            })).collect::<Vec<_>>(),
        });
        outputs.write(path, json_to(&value))?;
    }
    Ok(outputs.commit()?)
}
