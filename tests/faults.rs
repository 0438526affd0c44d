//! Allocation failures at every buffer allocation of a persistent renderer's life (issue 12
//! §4): the upload, the first frame, a frame at a new image size (new frame buffers) and a
//! frame with a new transfer function (new tables). `Context::fail_allocations_after(n)`
//! makes the (n+1)-th allocation and every later one fail as out of memory; the test sweeps n
//! from 0 until a whole run passes without reaching the fault, and requires at each n:
//! an `OutOfMemory` error naming the buffer (no panic, no other error), no leaked buffer, no
//! validation message, and a renderer that, once memory is back, renders frames identical to
//! those of a run that never failed.

mod common;

use vmls::field::RenderError;
use vmls::renderer::Renderer;
use vmls::scene::Scene;
use vmls::vk::{Context, VkError};

/// Frames: (width, height, transfer function) per frame, rendered in order.
const FRAMES: [(u32, u32, &str); 3] = [
    (12, 10, ""),
    (20, 14, ""),
    (20, 14, "[[0.0,0,0,0,0],[0.4,1,0.5,0.2,3],[1.0,1,1,1,9]]"),
];

fn scenes(extra: &[&str]) -> Vec<Scene> {
    FRAMES
        .iter()
        .map(|(w, h, tf)| {
            let mut set: Vec<String> = vec![
                "volume.resolution=13".into(),
                format!("camera.width={w}"),
                format!("camera.height={h}"),
            ];
            if !tf.is_empty() {
                set.push(format!("transfer.points={tf}"));
            }
            set.extend(extra.iter().map(|s| s.to_string()));
            Scene::load(None, &set).expect("scene")
        })
        .collect()
}

/// Builds a renderer and renders every frame; the first error ends the run. Returns the
/// renderer (when its upload succeeded), the frames rendered and the error.
fn run(
    ctx: &Context,
    scenes: &[Scene],
) -> (Option<Renderer>, Vec<Vec<[f32; 4]>>, Option<RenderError>) {
    let field = scenes[0].field(|_| {}).expect("field");
    let mut renderer = match Renderer::new(ctx, field) {
        Ok(r) => r,
        Err(e) => return (None, Vec::new(), Some(e)),
    };
    let mut frames = Vec::new();
    for s in scenes {
        match renderer.render(&s.view(), |_| {}) {
            Ok((image, _)) => frames.push(image.pixels),
            Err(e) => return (Some(renderer), frames, Some(e)),
        }
    }
    (Some(renderer), frames, None)
}

/// Largest difference of any channel of any pixel between two frame sequences.
fn max_diff(a: &[Vec<[f32; 4]>], b: &[Vec<[f32; 4]>]) -> f32 {
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| x.iter().zip(y))
        .flat_map(|(p, q)| p.iter().zip(q).map(|(u, v)| (u - v).abs()))
        .fold(0.0, f32::max)
}

/// `tolerance`: how far frames of two runs may differ (0: ray casting and splatting are both
/// the same to the bit on every run; splatting's buckets are put in kernel order).
fn sweep(extra: &[&str], tolerance: f32) {
    let (ctx, _) = common::gpu();
    let scenes = scenes(extra);
    let (_, reference, error) = run(&ctx, &scenes);
    assert!(error.is_none(), "the unfaulted run failed: {error:?}");
    assert_eq!(ctx.live_allocations(), 0);
    assert!(
        reference.iter().all(|f| f.iter().any(|p| p[3] > 0.01)),
        "a reference frame shows nothing"
    );
    for n in 0..400u64 {
        ctx.fail_allocations_after(Some(n));
        let (renderer, frames, error) = run(&ctx, &scenes);
        ctx.fail_allocations_after(None);
        let Some(error) = error else {
            // Every n before this one failed (the loop ends at the first clean run).
            assert!(n > 0, "no allocation was ever faulted");
            assert_eq!(frames.len(), reference.len());
            assert!(max_diff(&frames, &reference) <= tolerance);
            eprintln!("{extra:?}: {n} allocation points failed cleanly");
            drop(renderer);
            assert_eq!(ctx.live_allocations(), 0, "buffers leaked");
            common::finish(ctx);
            return;
        };
        let message = error.to_string();
        assert!(
            matches!(error, RenderError::Vk(VkError::OutOfMemory { .. })),
            "allocation {n}: expected out of memory, got {error:?}"
        );
        assert!(
            message.contains("out of GPU memory") && message.contains("buffer '"),
            "allocation {n}: {message}"
        );
        let d = max_diff(&frames, &reference);
        assert!(
            d <= tolerance,
            "allocation {n}: frames before the fault differ by {d}"
        );
        // Memory is back: the same renderer finishes the sequence as if nothing happened.
        if let Some(mut renderer) = renderer {
            for (s, want) in scenes.iter().zip(&reference).skip(frames.len()) {
                let (image, _) = renderer
                    .render(&s.view(), |_| {})
                    .unwrap_or_else(|e| panic!("allocation {n}: no recovery: {e}"));
                let d = max_diff(&[image.pixels], std::slice::from_ref(want));
                assert!(
                    d <= tolerance,
                    "allocation {n}: the recovered frame differs by {d}"
                );
            }
        }
        assert_eq!(ctx.live_allocations(), 0, "allocation {n}: buffers leaked");
        assert_eq!(ctx.validation_errors(), 0, "allocation {n}: validation");
    }
    panic!("400 allocations and the run still reaches the fault");
}

#[test]
fn ray_casting_fails_cleanly_at_every_allocation() {
    sweep(&[], 0.0);
}

#[test]
fn splatting_fails_cleanly_at_every_allocation() {
    sweep(&["render.method=\"splat\""], 0.0);
}

#[test]
fn ray_casting_a_cell_mesh_fails_cleanly_at_every_allocation() {
    // Unstructured cells: the hull, the cell octree and the samples are uploaded too.
    let file = format!(
        "volume.file={:?}",
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/legacy/unstructured-42-binary.vtk"
        )
    );
    sweep(&[&file, "volume.scalars=\"f\""], 0.0);
}
