//! The persistent renderer: a new camera reuses tables, pipeline and buffers and gives exactly
//! the one-shot image; a new transfer function rebuilds only the tables, an isosurface only the
//! pipeline, a new size only the buffers.
mod common;

use common::*;
use vmls::render::gpu::{GpuField, render};
use vmls::render::renderer::Renderer;
use vmls::scene::Scene;

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
    let frame = |r: &mut Renderer, s: &Scene, camera: &vmls::render::camera::Camera| {
        r.render(&s.view_with(camera), |_| {}).expect("frame")
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
    let tables = vmls::render::build_tables(&setup, &field, &moved.transfer, 64, |_| {});
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
    let (_, third) = frame(&mut renderer, &tf, &turned);
    assert!(third.tables_built && !third.pipeline_built && !third.targets_allocated);

    // An isosurface: a new variant, the same tables.
    let iso = scene(&[
        "transfer.points=[[0.0, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 0.2, 0.1, 5.0]]",
        "transfer.isosurfaces=[{ value = 0.5, color = [1.0, 1.0, 1.0], opacity = 1.0 }]",
    ]);
    let (_, fourth) = frame(&mut renderer, &iso, &turned);
    assert!(!fourth.tables_built && fourth.pipeline_built && !fourth.targets_allocated);

    // A new image size: buffers only.
    let mut wide = turned;
    wide.width = 32;
    let (image, fifth) = frame(&mut renderer, &iso, &wide);
    assert!(!fifth.tables_built && !fifth.pipeline_built && fifth.targets_allocated);
    assert_eq!(image.pixels.len(), 32 * 16);
    drop(renderer);
    finish(ctx);
}
