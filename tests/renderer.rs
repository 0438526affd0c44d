//! The persistent renderer: a new camera reuses tables, pipeline and buffers and gives exactly
//! the one-shot image; a new transfer function rebuilds only the tables, an isosurface only the
//! pipeline, a new size only the buffers, coarser tables only the tables (in the last ones'
//! buffer), and each of those frames equals a fresh renderer's.
mod common;

use common::*;
use vmls::renderer::Renderer;
use vmls::scene::Scene;
use vmls::{field::gpu::GpuField, renderer::render};

fn scene(extra: &[&str]) -> Scene {
    let mut o: Vec<String> = [
        "volume.resolution=17",
        "camera.width=24",
        "camera.height=16",
        "render.table_resolution=64",
        "render.step=0.5",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    o.extend(extra.iter().map(|s| s.to_string()));
    common::general_scene(&o)
}

#[test]
fn later_frames_rebuild_only_what_changed() {
    let (ctx, compiler) = gpu();
    let base = scene(&[]);
    let field = base.field(|_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    let frame = |r: &mut Renderer, s: &Scene, camera: &vmls::view::camera::Camera| {
        r.render(&s.view_with(camera), |_| {}).expect("frame")
    };
    // The same view from a renderer that has drawn nothing before: what a reused one must equal.
    let fresh = |s: &Scene, camera: &vmls::view::camera::Camera| {
        let mut r = Renderer::new(&ctx, field.clone()).expect("renderer");
        frame(&mut r, s, camera).0
    };
    let (_, first) = frame(&mut renderer, &base, &base.camera);
    assert!(first.tables_built && first.pipeline_built && first.targets_allocated);

    // A new camera: nothing rebuilt, and the image is the one-shot render's, bit for bit.
    let turned = base.camera.orbited(0.4);
    let (image, second) = frame(&mut renderer, &base, &turned);
    assert!(!second.tables_built && !second.pipeline_built && !second.targets_allocated);
    let mut moved = base.clone();
    moved.camera = turned;
    let setup = moved.ray_setup(&field).expect("setup");
    let tables = vmls::raycast::build_tables(&setup, &field, &moved.transfer, 64, |_| {});
    let gf = GpuField::upload(&ctx, &field).expect("upload");
    let once = render(
        &ctx,
        &compiler,
        &field,
        &gf,
        &moved.transfer,
        tables.as_ref(),
        &setup,
        |_| {},
    )
    .expect("render");
    drop(gf);
    assert_eq!(image.pixels, once.pixels);
    assert_eq!(image.counts, once.counts);

    // A new transfer function: tables only.
    let tf = scene(&["transfer.points=[[0.0, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 0.2, 0.1, 5.0]]"]);
    let (image, third) = frame(&mut renderer, &tf, &turned);
    assert!(third.tables_built && !third.pipeline_built && !third.targets_allocated);
    let once = fresh(&tf, &turned);
    assert_eq!((image.pixels, image.counts), (once.pixels, once.counts));

    // An isosurface: a new variant, the same tables.
    let iso = scene(&[
        "transfer.points=[[0.0, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 0.2, 0.1, 5.0]]",
        "transfer.isosurfaces=[{ value = 0.5, color = [1.0, 1.0, 1.0], opacity = 1.0 }]",
    ]);
    let (image, fourth) = frame(&mut renderer, &iso, &turned);
    assert!(!fourth.tables_built && fourth.pipeline_built && !fourth.targets_allocated);
    let once = fresh(&iso, &turned);
    assert_eq!((image.pixels, image.counts), (once.pixels, once.counts));

    // A new image size: buffers only.
    let mut wide = turned;
    wide.width = 32;
    let (image, fifth) = frame(&mut renderer, &iso, &wide);
    assert!(!fifth.tables_built && !fifth.pipeline_built && fifth.targets_allocated);
    assert_eq!(image.pixels.len(), 32 * 16);
    let once = fresh(&iso, &wide);
    assert_eq!((image.pixels, image.counts), (once.pixels, once.counts));

    // Coarser tables: rebuilt, and written into the larger buffer of the last ones (56² of
    // 64² entries), whose tail the kernel must not read.
    let coarse = scene(&[
        "transfer.points=[[0.0, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 0.2, 0.1, 5.0]]",
        "transfer.isosurfaces=[{ value = 0.5, color = [1.0, 1.0, 1.0], opacity = 1.0 }]",
        "render.table_resolution=56",
    ]);
    let (image, sixth) = frame(&mut renderer, &coarse, &wide);
    assert!(sixth.tables_built && !sixth.pipeline_built && !sixth.targets_allocated);
    let once = fresh(&coarse, &wide);
    assert_eq!((image.pixels, image.counts), (once.pixels, once.counts));
    drop(renderer);
    finish(ctx);
}

/// Ctrl-C's path through the library: a set stop flag ends a frame of either method with
/// `Interrupted` and no image; splatting also stops when the flag is raised mid-frame (from
/// its progress callback, after the first group of sheets), reports progress rising to 1, and
/// the same renderer goes on to frames equal to an uninterrupted one's.
#[test]
fn a_stop_request_ends_frames_of_both_methods_and_the_renderer_goes_on() {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use vmls::field::RenderError;
    let (ctx, _compiler) = gpu();
    for (extra, tolerance) in [
        (vec![], 0.0f32),
        // 8² tiles (the default), 5 tile rows in bands of two: four submissions.
        (
            vec![
                "render.method=\"splat\"",
                "splat.tile=8",
                "camera.height=40",
            ],
            1e-5,
        ),
    ] {
        let s = scene(&extra);
        let field = s.field(|_| {}).expect("field");
        let view = s.view_with(&s.camera);
        let stop = Arc::new(AtomicBool::new(false));
        let mut renderer = Renderer::new(&ctx, field).expect("renderer");
        renderer.set_stop(stop.clone());
        let mut seen = Vec::new();
        let (want, _) = renderer
            .render(&view, |f| seen.push(f))
            .expect("uninterrupted frame");
        let splat = !extra.is_empty();
        if splat {
            assert!(seen.len() >= 3, "progress {seen:?}");
            assert!(seen.windows(2).all(|w| w[0] < w[1]), "progress {seen:?}");
            assert_eq!(seen.last().copied(), Some(1.0));
        }

        stop.store(true, Ordering::Relaxed);
        let r = renderer.render(&view, |_| {});
        assert!(matches!(r, Err(RenderError::Interrupted)), "{extra:?}");
        stop.store(false, Ordering::Relaxed);

        if splat {
            let raise = stop.clone();
            let mut calls = 0;
            let r = renderer.render(&view, |_| {
                calls += 1;
                raise.store(true, Ordering::Relaxed);
            });
            assert!(matches!(r, Err(RenderError::Interrupted)));
            assert_eq!(calls, 1, "the frame went on after the stop request");
            stop.store(false, Ordering::Relaxed);
        }

        let (again, _) = renderer.render(&view, |_| {}).expect("frame after a stop");
        let diff = want
            .pixels
            .iter()
            .zip(&again.pixels)
            .flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y).abs()))
            .fold(0.0f32, f32::max);
        assert!(diff <= tolerance, "{extra:?}: {diff}");
        drop(renderer);
    }
    finish(ctx);
}

/// The context's pipeline cache (issue 28 §2): readable after a frame, with a header naming
/// this device; loadable into a new context, whose frame is the same; data of another device
/// (a changed pipelineCacheUUID) or none at all is ignored and says so.
#[test]
fn the_pipeline_cache_reads_back_and_loads_into_a_new_context() {
    let s = scene(&[]);
    let field = s.field(|_| {}).expect("field");
    let frame = |ctx: &vmls::vk::Context| {
        let mut r = Renderer::new(ctx, field.clone()).expect("renderer");
        r.render(&s.view(), |_| {}).expect("frame").0
    };
    let (first, _) = gpu();
    let image = frame(&first);
    let data = first.pipeline_cache_data().expect("cache data");
    let info = first.info().clone();
    finish(first);
    assert!(data.len() >= 32, "{} bytes", data.len());
    assert_eq!(u32::from_le_bytes([data[0], data[1], data[2], data[3]]), 32);
    assert_eq!(
        u32::from_le_bytes([data[8], data[9], data[10], data[11]]),
        info.vendor_id
    );
    assert_eq!(&data[16..32], &info.pipeline_cache_uuid[..]);

    let (second, _) = gpu();
    assert!(second.load_pipeline_cache(&data).expect("load"));
    let mut other = data.clone();
    other[20] ^= 0xFF;
    assert!(
        !second
            .load_pipeline_cache(&other)
            .expect("another device's")
    );
    assert!(!second.load_pipeline_cache(&[]).expect("nothing"));
    assert!(
        !second
            .load_pipeline_cache(&data[..31])
            .expect("a cut header")
    );
    let again = frame(&second);
    assert_eq!(again.pixels, image.pixels);
    finish(second);
}

/// Stage `raycast_next` against its CPU twin: bands whose rays are all done, partly done, not
/// started, or cut short by the driver, at a width that is not a multiple of the workgroup.
#[test]
fn raycast_next_matches_its_cpu_twin() {
    use vmls::gpu_types::{NextPush, RenderParams, binding, binding_defines, params_copies};
    use vmls::renderer::next_groups;
    use vmls::vk::{BindGroup, Buffer, BufferUsage, ComputePipeline, ShaderSource};
    let (ctx, compiler) = gpu();
    let (width, height, rows) = (21u32, 32u32, 8u32);
    let done = vmls::gpu_types::ray_count::DONE;
    let truncated = vmls::gpu_types::ray_count::TRUNCATED;
    // Band 0 done, band 1 one unfinished ray, band 2 nothing done, band 3 unfinished rays and
    // one cut short.
    let counts: Vec<u32> = (0..width * height)
        .map(|i| match i / (width * rows) {
            0 => done | 3,
            1 if i == width * rows + 17 => 9,
            1 => done,
            2 => 0,
            _ if i == 3 * width * rows + 5 => truncated | 4,
            _ => 2,
        })
        .collect();
    let mut params = RenderParams::default();
    params.camera.width = width;
    params.camera.height = height;
    let params = Buffer::from_slice(&ctx, "params", &params_copies(params)).expect("params");
    let counts_buf = Buffer::from_slice(&ctx, "counts", &counts).expect("counts");
    let args = Buffer::new(&ctx, "args", 16 * 4, BufferUsage::Storage).expect("args");
    let spirv = compiler
        .compile(
            ShaderSource::File("raycast/raycast_next.comp"),
            &binding_defines(),
        )
        .expect("compile");
    let kinds =
        [binding::PARAMS, binding::COUNTS, binding::DISPATCH_ARGS].map(|b| (b, binding::kind(b)));
    let pipeline =
        ComputePipeline::with_kinds(&ctx, "raycast_next", &spirv, &kinds, 16).expect("pipeline");
    let group = BindGroup::new(
        &ctx,
        &pipeline,
        &[
            (binding::PARAMS, &params),
            (binding::COUNTS, &counts_buf),
            (binding::DISPATCH_ARGS, &args),
        ],
    )
    .expect("bind");
    ctx.submit(|rec| {
        for band in 0..4 {
            let push = NextPush {
                row_offset: band * rows,
                rows,
                args_slot: band,
                // A brick's window: the third band dispatches half the columns.
                cols: if band == 2 { width / 2 } else { width },
            };
            rec.dispatch(
                &pipeline,
                &group,
                bytemuck::bytes_of(&push),
                [1, 1, 1],
                "raycast_next",
            )?;
        }
        Ok(())
    })
    .expect("submit");
    let got: Vec<[u32; 4]> = args.read(&ctx).expect("read");
    let band_pixels = (width * rows) as usize;
    for (band, (args, counts)) in got.iter().zip(counts.chunks(band_pixels)).enumerate() {
        let cols = if band == 2 { width / 2 } else { width };
        let want = next_groups(counts, cols, rows);
        assert_eq!(args[..3], want, "band {band}");
    }
    assert_eq!(got[0][0], 0, "a finished band dispatches nothing");
    assert_eq!(got[1][..3], [3, 1, 1]);
    assert_eq!(got[2][..3], [2, 1, 1], "a window's columns only");
    assert_eq!(got[3][0], 0, "a band with a truncated ray stops");
    drop(group);
    drop((pipeline, args, counts_buf, params));
    finish(ctx);
}
