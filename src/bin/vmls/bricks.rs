//! `vmls render --bricks N`: the scene's field divided into N kd bricks, each ray cast alone on
//! this device and composited front to back in f64 (the reference of a distributed render,
//! issue 30), with each brick's cost in the statistics.

use crate::render::{Request, check_validation};
use crate::{CliError, DeviceArgs, check_stop, context, json_to, plan_outputs};
use std::sync::atomic::AtomicBool;
use std::time::Instant;
use vmls::bricks::{BrickError, VirtualBricks};
use vmls::output::{check_finite, encode_image, format_of};
use vmls::scene::Scene;

impl From<BrickError> for CliError {
    fn from(e: BrickError) -> Self {
        match e {
            BrickError::Render(r) => CliError::Render(r),
            other => CliError::Usage(other.to_string()),
        }
    }
}

/// Writes a composited frame (f64 pixels) to `output`, one of `outputs`, unless the context saw
/// a validation error; shared by `--bricks` and `--mpi`.
pub fn write_composite(
    ctx: &vmls::vk::Context,
    outputs: &mut vmls::files::Outputs,
    output: &std::path::Path,
    (w, h): (u32, u32),
    pixels: &[[f64; 4]],
) -> Result<(), CliError> {
    check_validation(ctx, output)?;
    let rgba: Vec<[f32; 4]> = pixels.iter().map(|p| p.map(|c| c as f32)).collect();
    check_finite(&rgba)?;
    outputs.write(output, |out| encode_image(out, output, w, h, &rgba))?;
    Ok(())
}

/// Refuses a scene whose undivided frame passes the work budget (each brick does at most its
/// work): ray casting's evaluations, or the sheets of a splatting frame.
pub fn check_frame_budget(scene: &Scene, field: &vmls::field::Field) -> Result<(), CliError> {
    match scene.render.method.splat_shading() {
        None => scene
            .ray_setup(field)?
            .check_budget(vmls::view::WORK_BUDGET)?,
        Some(shading) => scene
            .splat_setup(shading, field)?
            .check_budget(0, vmls::view::WORK_BUDGET)?,
    }
    Ok(())
}

/// Renders `request`'s scene as `ranks` virtual bricks.
pub fn run_render_bricks(
    request: &Request<'_>,
    ranks: u32,
    device: &DeviceArgs,
    stop: &AtomicBool,
) -> Result<(), CliError> {
    let start = Instant::now();
    if request.eval_map.is_some() || request.frames != 1 {
        return Err(CliError::Usage(
            "--bricks renders one frame without evaluation maps: drop --eval-map and --frames"
                .into(),
        ));
    }
    format_of(request.output)?;
    let scene = Scene::load(request.scene_path, request.set)?;
    let mut outputs = plan_outputs(
        request.scene_path,
        Some(&scene),
        &[("-o", Some(request.output)), ("--stats", request.stats)],
    )?;
    let ctx = context(device)?;
    let field = scene.field_on(Some(ctx.info()), |_| {})?;
    if !request.force {
        check_frame_budget(&scene, &field)?;
    }
    check_stop(stop)?;
    let divide_start = Instant::now();
    let mut bricks = VirtualBricks::new(&ctx, &field, ranks as usize, &scene.view())?;
    let divide_ms = divide_start.elapsed().as_secs_f64() * 1e3;
    check_stop(stop)?;
    let frame = bricks.render(&scene.view())?;
    drop(bricks);
    let (w, h) = (scene.camera.width, scene.camera.height);
    write_composite(&ctx, &mut outputs, request.output, (w, h), &frame.pixels)?;
    if let Some(path) = request.stats {
        let total = field.samples.len();
        let value = serde_json::json!({
            "device": ctx.info().name,
            "method": scene.render.method.name(),
            "width": w,
            "height": h,
            "ranks": ranks,
            "samples": total,
            "order": frame.order,
            "divide_ms": divide_ms,
            "composite_ms": frame.composite_ms,
            "wall_ms": start.elapsed().as_secs_f64() * 1e3,
            "bricks": frame.bricks.iter().map(|b| serde_json::json!({
                "rank": b.rank,
                "box": [b.bounds.0, b.bounds.1],
                "samples_inside": b.samples.own,
                "ghosts": b.samples.ghosts,
                "gpu_ms": b.gpu_ms,
                "evaluations": b.evaluations,
            })).collect::<Vec<_>>(),
        });
        outputs.write(path, json_to(&value))?;
    }
    Ok(outputs.commit()?)
}
