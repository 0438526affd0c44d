//! `vmls render`: one scene to an image on the GPU (or with the f64 CPU twins), with statistics.

use crate::probe::octree_json;
use crate::{CliError, DeviceArgs, check_stop, context, json_to, plan_outputs, progress_bar};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Instant;
use vmls::data::dataset::Location;
use vmls::field::RenderError;
use vmls::field::skip::SkipReport;
use vmls::output::evalmap::{self, check_path};
use vmls::output::{check_finite, encode_image, format_of};
use vmls::renderer::Renderer;
use vmls::renderer::tolerance::p99_of;
use vmls::scene::Scene;

/// What `vmls render` was asked for.
pub struct Request<'a> {
    pub scene_path: Option<&'a Path>,
    pub output: &'a Path,
    pub stats: Option<&'a Path>,
    pub eval_map: Option<&'a Path>,
    pub set: &'a [String],
    pub frames: u32,
    /// Past the work budget.
    pub force: bool,
}

pub fn run_render(
    request: &Request<'_>,
    device: &DeviceArgs,
    stop: &Arc<AtomicBool>,
) -> Result<(), CliError> {
    let &Request {
        scene_path,
        output,
        stats,
        eval_map,
        set,
        frames: frames_wanted,
        force,
    } = request;
    let start = Instant::now();
    format_of(output)?;
    if let Some(map) = eval_map {
        check_path(map)?;
    }
    let scene = Scene::load(scene_path, set)?;
    let mut outputs = plan_outputs(
        scene_path,
        Some(&scene),
        &[
            ("-o", Some(output)),
            ("--stats", stats),
            ("--eval-map", eval_map),
        ],
    )?;
    if eval_map.is_some() && scene.render.method.splat_shading().is_some() {
        return Err(CliError::Usage(format!(
            "--eval-map counts MLS evaluations per ray; render.method = \"{}\" splats and \
             evaluates none (its counts are in --stats)",
            scene.render.method.name()
        )));
    }
    let ctx = context(device)?;
    let bar = progress_bar("octree");
    let field = scene.field_on(Some(ctx.info()), |f| bar.set_position((f * 1000.0) as u64))?;
    bar.finish_and_clear();
    let step_world = match scene.render.method.splat_shading() {
        None => {
            let setup = scene.ray_setup(&field)?;
            if !force {
                setup.check_budget(vmls::view::WORK_BUDGET)?;
            }
            Some(setup.step_world)
        }
        Some(_) => None,
    };
    check_stop(stop)?;
    let upload_start = Instant::now();
    let mut renderer = Renderer::new(&ctx, field)?;
    renderer.set_stop(stop.clone());
    renderer.set_work_budget((!force).then_some(vmls::view::WORK_BUDGET));
    let upload_ms = upload_start.elapsed().as_secs_f64() * 1e3;
    // Frame k turns the camera by 10°·k about its up axis through the target: later frames
    // show what a new camera costs with everything else kept on the GPU.
    let mut frames = Vec::new();
    let mut image = None;
    for k in 0..frames_wanted.max(1) {
        let camera = scene.camera.orbited((10.0 * k as f64).to_radians());
        let view = scene.view_with(&camera);
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
    check_validation(&ctx, output)?;
    check_stop(stop)?;
    let (width, height) = (scene.camera.width, scene.camera.height);
    check_finite(&image.pixels)?;
    outputs.write(output, |w| {
        encode_image(w, output, width, height, &image.pixels)
    })?;
    if let Some(map) = eval_map {
        let m = evalmap::eval_map(map, width, height, &image.counts)?;
        outputs.write(map, |w| m.encode(w, map, width, height))?;
    }
    if let Some(stats) = stats {
        let evaluations: u64 = image.counts.iter().map(|&c| u64::from(c)).sum();
        let rays = image.counts.len() as u64;
        let mut fast_path = field.fast_path();
        if let Some(o) = fast_path
            .as_object_mut()
            .filter(|_| field.reconstruction.resample > 0)
        {
            o.insert("build_gpu_ms".into(), renderer.fast_path_build_ms().into());
        }
        let shaders = vmls::vk::shader_counts();
        let value = serde_json::json!({
            "device": ctx.info().name,
            "device_type": ctx.info().device_type,
            "driver": ctx.info().driver,
            "variant": image.variant,
            // Kernel variants compiled by shaderc and read from the disk cache (shader_cache).
            "shaders": {
                "compiled": shaders.0,
                "from_disk_cache": shaders.1,
            },
            "width": scene.camera.width,
            "height": scene.camera.height,
            "method": scene.render.method.name(),
            "step_world": step_world,
            "neighbours": if field.uses_octree() { "octree" } else { "grid" },
            "fast_path": fast_path,
            "sample_storage": field.samples.values.storage().name(),
            "host_peak_bytes": vmls::files::memory::peak_resident(),
            "gpu_ms": match &image.splat {
                None => serde_json::json!({ "raycast": first.gpu_ms }),
                Some(r) => serde_json::Value::Object(
                    vmls::splat::frame::STAGES
                        .iter()
                        .zip(r.stage_ms)
                        .map(|(n, ms)| (n.to_string(), ms.into()))
                        .collect(),
                ),
            },
            "splat": image.splat.as_ref().map(|r| serde_json::json!({
                "sheets": r.slabs,
                "sheet_thickness_world": r.slab_world,
                "kernels_projected": r.counts.projected,
                "kernels_culled_near": r.counts.culled_near,
                "kernels_culled_outside": r.counts.culled_outside,
                "kernels_culled_degenerate": r.counts.culled_degenerate,
                "kernels_culled_empty": r.counts.culled_empty,
                "kernels_left_out_transparent": r.counts.left_out,
                "kernels_kept": r.counts.kept(),
                "tile": r.tile,
                "raster_invocations_per_tile": r.invocations,
                "raster_band_rows": r.band_rows,
                "footprints_binned": r.counts.entries,
                "footprints_skipped_by_occlusion": r.counts.skipped_occluded,
                "footprints_accumulated": r.counts.accumulated,
                "footprint_pixels_evaluated": r.counts.evaluated,
                "footprint_pixels_contributing": r.counts.contributions,
                "buckets_unordered": r.counts.unordered,
                "buckets_heapsorted": r.counts.large_buckets,
                "tile_walks_resumed": r.counts.resumed,
                "interval_halves_skipped_clear": r.counts.clear_skipped,
                "gpu_ms_per_kernel": {
                    "splat_project": r.stage_ms[0]
                        / (r.counts.projected - r.counts.left_out).max(1) as f64,
                    "splat_sort": r.stage_ms[1] / r.counts.kept().max(1) as f64,
                    "splat_raster": r.stage_ms[2] / r.counts.kept().max(1) as f64,
                },
            })),
            "skip": image.skip.as_ref().map(skip_json),
            "error_estimate": image.error_estimate.as_deref().map(estimate_json),
            "upload_ms": upload_ms,
            "frames": frames.iter().map(|f| serde_json::json!({
                "gpu_ms": f.gpu_ms,
                "wall_ms": f.wall_ms,
                "tables_built": f.tables_built,
                "table_ms": f.table_ms,
                "pipeline_built": f.pipeline_built,
                "buffers_allocated": f.targets_allocated,
                "skip_auto_fraction": f.skip_estimate,
                "hull_segments": f.hull_segments.map(|h| h.name()),
                "tolerance": f.tolerance.as_ref().map(tolerance_json),
            })).collect::<Vec<_>>(),
            "tolerance": first.tolerance.as_ref().map(tolerance_json),
            "bands": image.bands,
            "wall_ms": start.elapsed().as_secs_f64() * 1e3,
            "function_evaluations": evaluations,
            "rays": rays,
            "evaluations_per_ray": evaluations as f64 / rays.max(1) as f64,
            "table_build_ms_cpu": tables.map(|_| table_ms),
            "table_lengths_world": tables.map(|t| t.lengths.clone()),
            "table_resolution": tables.map(|t| t.resolution),
            "exact_opacity": tables.map(|t| t.exact_opacity.is_some()),
            "octree_nodes": field.octree_if_built().map(|o| o.nodes.len()),
            "octree_references": field.octree_if_built().map(|o| o.references),
            "octree": field.octree_if_built().map(|o| octree_json(&o.stats(std::mem::size_of::<vmls::gpu_types::Sample>() as u64))),
            "octree_records": field.octree_layout().map(|(layout, bytes)| serde_json::json!({
                "layout": layout,
                "device_bytes": bytes,
            })),
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
        outputs.write(stats, json_to(&value))?;
    }
    Ok(outputs.commit()?)
}

/// Refuses to write `output` after a validation error: the frame may be garbage.
pub fn check_validation(ctx: &vmls::vk::Context, output: &Path) -> Result<(), CliError> {
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
    Ok(())
}

/// `--stats` "error_estimate": the adaptive integrator's own estimate of the frame's error.
fn estimate_json(pixels: &[f32]) -> serde_json::Value {
    let pixels: Vec<f64> = pixels.iter().map(|&e| f64::from(e)).collect();
    serde_json::json!({
        "measure": "per pixel, the transmittance-weighted sum of the adaptive criterion's local error estimates along the ray, plus the transmittance left where the ray terminated early; the tables' error is not included",
        "p99": p99_of(pixels.clone()),
        "max": pixels.iter().copied().fold(0.0, f64::max),
        "mean": pixels.iter().sum::<f64>() / pixels.len().max(1) as f64,
    })
}

/// What `render.tolerance` chose ([`vmls::renderer::tolerance::ToleranceReport`]).
fn tolerance_json(r: &vmls::renderer::tolerance::ToleranceReport) -> serde_json::Value {
    serde_json::json!({
        "requested": r.tolerance,
        "measure": "99th percentile over pixels of the largest |error| of R, G, B (premultiplied, over the background) and A",
        "chosen": r.chosen.map(|(key, value, estimate)| serde_json::json!({
            "key": key,
            "value": value,
            "estimated_error": estimate,
        })),
        "observed_order": r.order,
        "ladder": r.rungs.iter().map(|(v, d)| serde_json::json!({
            "value": v,
            "difference_to_next": d,
        })).collect::<Vec<_>>(),
        "early_termination": r.early_termination,
        "table_resolution": r.table_resolution,
        "table_errors": r.table_moves.iter().map(|(res, d)| serde_json::json!({
            "resolution": res,
            "estimated_error": d,
        })).collect::<Vec<_>>(),
        "met": r.met,
        "notes": r.notes,
        "pilot_frames": r.pilots,
        "pilot_wall_ms": r.pilot_wall_ms,
        "pilot_gpu_ms": r.pilot_gpu_ms,
        "carried": r.carried,
    })
}

/// `vmls render --cpu`: the f64 CPU twins, rows over all cores.
pub fn run_render_cpu(
    scene_path: Option<&Path>,
    output: &Path,
    stats: Option<&Path>,
    set: &[String],
    force: bool,
    stop: &AtomicBool,
) -> Result<(), CliError> {
    let start = Instant::now();
    format_of(output)?;
    let scene = Scene::load(scene_path, set)?;
    if scene.render.tolerance.is_some() {
        return Err(CliError::Usage(
            "--cpu renders with the scene's parameters: render.tolerance chooses them with \
             pilot frames on the GPU (drop --cpu, or the key)"
                .into(),
        ));
    }
    let mut outputs = plan_outputs(
        scene_path,
        Some(&scene),
        &[("-o", Some(output)), ("--stats", stats)],
    )?;
    let field = scene.field(|_| {})?;
    let mut estimates = None;
    let mut evaluations = None;
    let (pixels, splat, skip): (Vec<[f64; 4]>, _, _) = match scene.render.method.splat_shading() {
        Some(shading) => {
            let setup = scene.splat_setup(shading, &field)?;
            let image = vmls::splat::raster::splat_image(&setup, &field, &scene.transfer)
                .map_err(RenderError::from)?;
            (image.pixels, Some(image.counts), None)
        }
        None => {
            let mut setup = scene.ray_setup(&field)?;
            if !force {
                setup.check_budget(vmls::view::WORK_BUDGET)?;
            }
            check_stop(stop)?;
            setup.resolve_skip(field.blocks(), &scene.transfer, &field);
            let image = vmls::raycast::raycast_frame(
                &setup,
                &field,
                &scene.transfer,
                scene.render.table_resolution,
            )
            .map_err(RenderError::from)?;
            let skip = setup.skip.then(|| vmls::raycast::skip_report(&image));
            evaluations = Some(image.iter().map(|p| u64::from(p.evaluations)).sum::<u64>());
            if scene.render.method == vmls::view::Method::Adaptive {
                estimates = Some(
                    image
                        .iter()
                        .map(|p| p.error_estimate as f32)
                        .collect::<Vec<_>>(),
                );
            }
            (image.iter().map(|p| p.rgba).collect(), None, skip)
        }
    };
    check_stop(stop)?;
    let rgba: Vec<[f32; 4]> = pixels.iter().map(|p| p.map(|c| c as f32)).collect();
    check_finite(&rgba)?;
    outputs.write(output, |w| {
        encode_image(w, output, scene.camera.width, scene.camera.height, &rgba)
    })?;
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
            "function_evaluations": evaluations,
            "skip": skip.as_ref().map(skip_json),
            "error_estimate": estimates.as_deref().map(estimate_json),
        });
        outputs.write(stats, json_to(&value))?;
    }
    Ok(outputs.commit()?)
}

/// `--stats` "skip": what empty-space skipping did in the frame.
fn skip_json(r: &SkipReport) -> serde_json::Value {
    serde_json::json!({
        "ray_length_skipped": r.fraction(),
        "ray_length_skipped_world": r.skipped_length,
        "ray_length_inside_world": r.inside_length,
        "evaluations_saved": r.evaluations_saved,
    })
}
