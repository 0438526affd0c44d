//! A thousand frames through one persistent renderer keep host and GPU memory flat (issue 12
//! §4): after a warm-up that builds pipelines, tables and frame buffers, host RSS and
//! gpu-allocator's report must not grow with the frame count.
//!
//! History: while every submission created and destroyed its own command pool, fence and
//! 16 384-query timestamp pool, host RSS grew by about 2.4 MB per frame inside the validation
//! layer with synchronization validation on (Debian 12's 1.3.239; flat without it). Since the
//! context reuses those objects (`vk::commands::SubmitObjects`) RSS is flat to the page with
//! core and synchronization validation, which is what this test asserts.

mod common;

use vmls::render::renderer::Renderer;
use vmls::scene::Scene;
use vmls::vk::Context;

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
    // Core and synchronization validation, as every GPU test.
    let (ctx, _) = common::gpu();
    let [(rss0, live0, gpu0), (rss1, live1, gpu1)] = measure(&ctx, 900);
    assert_eq!(live1, live0, "buffers grew with the frame count");
    assert_eq!(
        gpu1, gpu0,
        "gpu-allocator's bytes grew with the frame count"
    );
    if let (Some(a), Some(b)) = (rss0, rss1) {
        // 900 frames: a leak of even 5 KiB per frame would show as 4.4 MiB.
        assert!(
            b < a + (4 << 20),
            "host RSS grew from {a} to {b} bytes over 900 frames"
        );
    }
    common::finish(ctx);
}
