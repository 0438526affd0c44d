//! A thousand frames through one persistent renderer keep host and GPU memory flat (issue 12
//! §4): after a warm-up that builds pipelines, tables and frame buffers, host RSS and
//! gpu-allocator's report must not grow with the frame count.
//!
//! Measured here: with core and synchronization validation, GPU memory and buffer counts are
//! flat but host RSS grows by about 2.4 MB per frame inside the validation layer (Debian 12's
//! 1.3.239; without synchronization validation, or without the layer, RSS is flat to the
//! page). So the host-memory bound is asserted with core validation only, and the GPU bounds
//! with both.

mod common;

use vmls::render::renderer::Renderer;
use vmls::scene::Scene;
use vmls::vk::{Context, ContextOptions};

/// Resident set size of this process in bytes (Linux `/proc/self/statm`), or `None`.
fn rss() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096)
}

/// Renders `frames` frames after a 100-frame warm-up; returns (RSS, live buffers, allocator
/// bytes) after the warm-up and at the end.
fn measure(ctx: &Context, frames: u32) -> [(Option<u64>, usize, (u64, u64)); 2] {
    let set = [
        "camera.width=16".to_string(),
        "camera.height=16".to_string(),
    ];
    let scene = Scene::load(None, &set).expect("scene");
    let field = scene.field(|_| {}).expect("field");
    let mut renderer = Renderer::new(ctx, field).expect("renderer");
    let mut run = |from: u32, to: u32| {
        for k in from..to {
            let camera = scene.camera.orbited(f64::from(k % 36) * 10f64.to_radians());
            let (image, _) = renderer
                .render(&scene.view_with(&camera), |_| {})
                .expect("frame");
            assert!(image.pixels.iter().all(|p| p.iter().all(|c| c.is_finite())));
        }
    };
    let state = || (rss(), ctx.live_allocations(), ctx.allocator_bytes());
    run(0, 100);
    let before = state();
    run(100, 100 + frames);
    let after = state();
    eprintln!(
        "after 100 frames: {before:?}; after {}: {after:?}",
        100 + frames
    );
    [before, after]
}

#[test]
fn a_thousand_frames_keep_memory_flat() {
    // Core and synchronization validation: GPU memory flat (500 frames: the layer's own
    // growth would take over 2 GB of host memory at 1000).
    let (ctx, _) = common::gpu();
    let [(_, live0, gpu0), (_, live1, gpu1)] = measure(&ctx, 400);
    assert_eq!(live1, live0, "buffers grew with the frame count");
    assert_eq!(
        gpu1, gpu0,
        "gpu-allocator's bytes grew with the frame count"
    );
    common::finish(ctx);
    // Core validation only: host memory flat too.
    let ctx = Context::new(&ContextOptions {
        validation: Some(true),
        sync_validation: Some(false),
        ..ContextOptions::default()
    })
    .expect("context");
    let [(rss0, live0, gpu0), (rss1, live1, gpu1)] = measure(&ctx, 900);
    assert_eq!((live1, gpu1), (live0, gpu0));
    if let (Some(a), Some(b)) = (rss0, rss1) {
        // 900 frames: a leak of even 5 KiB per frame would show as 4.4 MiB.
        assert!(
            b < a + (4 << 20),
            "host RSS grew from {a} to {b} bytes over 900 frames"
        );
    }
    common::finish(ctx);
}
