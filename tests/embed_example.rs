//! `examples/embed.rs` run as a test: an application's own instance, device, image and command
//! buffers, frames recorded by `Renderer::record` with two in flight while the camera turns,
//! under the validation layer with synchronization validation. Each recorded frame must equal
//! `Renderer::render`'s image of the same camera: bit for bit in RGBA32F, and through
//! `target_pack`'s CPU twin in the packed formats; ray casting and both splatting methods.

#[path = "../examples/embed.rs"]
mod embed;

use std::sync::atomic::Ordering;
use vmls::renderer::TargetFormat;
use vmls::renderer::target::pack_pixel;

fn overrides(extra: &[&str]) -> Vec<String> {
    let mut o: Vec<String> = [
        "volume.resolution=17",
        "camera.width=40",
        "camera.height=24",
        "render.table_resolution=64",
        "render.step=0.5",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    o.extend(extra.iter().map(|s| s.to_string()));
    o
}

/// The tests of this binary one at a time, with the application's validation on: they share
/// the message count and the environment variable that `App::new` reads.
fn validated() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let guard = LOCK.lock().unwrap_or_else(|p| p.into_inner());
    // SAFETY: every test of this binary holds the lock while it reads or writes the variable.
    unsafe { std::env::set_var("VMLS_VALIDATION", "1") };
    guard
}

/// Runs the example with validation on and checks what it must.
fn check(extra: &[&str], format: TargetFormat, frames: usize) -> embed::Frames {
    check_turning(extra, format, frames, 0.35)
}

/// [`check`] with the camera turning `turn` radians a frame.
fn check_turning(extra: &[&str], format: TargetFormat, frames: usize, turn: f64) -> embed::Frames {
    let _guard = validated();
    let before = embed::MESSAGES.load(Ordering::SeqCst);
    let out = embed::run(&overrides(extra), frames, turn, format).expect("example runs");
    assert_eq!(
        embed::MESSAGES.load(Ordering::SeqCst),
        before,
        "validation (synchronization included) reported messages"
    );
    assert_eq!(out.frames.len(), frames);
    assert_eq!(out.rendered.len(), frames);
    out
}

#[test]
fn recorded_frames_equal_render_bit_for_bit() {
    let out = check(&[], TargetFormat::Rgba32f, 4);
    for (i, (got, want)) in out.frames.iter().zip(&out.rendered).enumerate() {
        let want: &[u8] = bytemuck::cast_slice(want);
        assert_eq!(got.len(), want.len());
        let differ = got
            .chunks(4)
            .zip(want.chunks(4))
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(
            differ, 0,
            "frame {i}: {differ} channels differ from render()"
        );
    }
    // The camera turned: consecutive frames differ.
    assert_ne!(out.frames[0], out.frames[1]);
}

/// Ray casting a tetrahedral mesh: each slot finds its hull segments at its first frame of a
/// camera and reuses them while the camera stays, and every recorded frame still equals
/// `render()`'s to the bit, turning or not.
#[test]
fn recorded_mesh_frames_reuse_hull_segments_and_equal_render() {
    use vmls::renderer::HullSegments::{Found, Reused};
    let mesh = "volume.file=\"tests/data/legacy/unstructured-42-ascii.vtk\"";
    for (turn, expect) in [
        (0.35, [Found, Found, Found, Found]),
        // Two slots, each with its own cache: each walks at its first frame.
        (0.0, [Found, Found, Reused, Reused]),
    ] {
        let out = check_turning(&[mesh], TargetFormat::Rgba32f, 4, turn);
        for (i, (got, want)) in out.frames.iter().zip(&out.rendered).enumerate() {
            let want: &[u8] = bytemuck::cast_slice(want);
            assert!(got == want, "turn {turn}, frame {i}: differs from render()");
        }
        if turn == 0.0 {
            assert_eq!(
                out.frames[0], out.frames[3],
                "the same camera, the same image"
            );
        }
        assert_eq!(out.hull_segments, expect.map(Some), "turn {turn}");
    }
}

/// Recorded splatting frames equal `render()`'s to the bit: the same stages on the same
/// buffers, and `splat_order` puts each bucket in kernel order, so every sheet sums its entries
/// in one order whoever filled the bucket (before it, they differed by up to 3.0e-6). The
/// background composite in `target_pack` is exact.
#[test]
fn recorded_splatting_frames_equal_render() {
    // Post-shaded over a tetrahedral mesh's hull: `splat_segments` runs first.
    let mesh = "volume.file=\"tests/data/legacy/unstructured-42-ascii.vtk\"";
    for (method, data, turn) in [
        ("splat", "", 0.35),
        ("splat-post", "", 0.35),
        ("splat-post", mesh, 0.35),
        // A still camera: each slot's second frame reuses its hull segments.
        ("splat-post", mesh, 0.0),
    ] {
        let m = format!("render.method=\"{method}\"");
        // A background, which recorded splatting frames composite in `target_pack`.
        let mut extra = vec![m.as_str(), "render.background=[0.2, 0.3, 0.4]"];
        extra.extend([data].into_iter().filter(|d| !d.is_empty()));
        let out = check_turning(&extra, TargetFormat::Rgba32f, 4, turn);
        for (i, (got, want)) in out.frames.iter().zip(&out.rendered).enumerate() {
            let got: &[f32] = bytemuck::cast_slice(got);
            let want: &[f32] = bytemuck::cast_slice(want);
            assert_eq!(got.len(), want.len());
            let worst = got
                .iter()
                .zip(want)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(worst == 0.0, "{method} frame {i}: off by {worst:e}");
        }
        use vmls::renderer::HullSegments::{Found, Reused};
        let segments = match (data.is_empty(), turn == 0.0) {
            (true, _) => [None; 4],
            (false, false) => [Some(Found); 4],
            (false, true) => [Some(Found), Some(Found), Some(Reused), Some(Reused)],
        };
        assert_eq!(out.hull_segments, segments, "{method}, turn {turn}");
        if turn == 0.0 {
            assert_eq!(out.frames[0], out.frames[3]);
            continue;
        }
        assert_ne!(out.frames[0], out.frames[1]);
        // The background is in the recorded frames: a corner pixel, outside the volume.
        let corner: &[f32] = bytemuck::cast_slice(&out.frames[0][..16]);
        assert_eq!(corner, [0.2, 0.3, 0.4, 0.0], "{method}: background");
    }
}

#[test]
fn packed_formats_match_the_cpu_twin() {
    for format in [
        TargetFormat::Rgba16f,
        TargetFormat::Rgba8Unorm,
        TargetFormat::Rgba8Srgb,
    ] {
        // A splatting frame over a background too: `target_pack` composites, then converts.
        let splat = [
            "render.method=\"splat-post\"",
            "render.background=[0.2, 0.3, 0.4]",
        ];
        for extra in [&["render.method=\"adaptive\""][..], &splat[..]] {
            let out = check(extra, format, 3);
            for (i, (got, want)) in out.frames.iter().zip(&out.rendered).enumerate() {
                let twin: Vec<u8> = want.iter().flat_map(|p| pack_pixel(format, *p)).collect();
                assert_eq!(got.len(), twin.len());
                // 8-bit: at most one step where the GPU's rounding of a value on a half step
                // differs; half floats: at most one unit in the last place (measured: 0 and 0).
                let worst = match format {
                    TargetFormat::Rgba16f => got
                        .chunks(2)
                        .zip(twin.chunks(2))
                        .map(|(a, b)| {
                            u16::from_le_bytes([a[0], a[1]])
                                .abs_diff(u16::from_le_bytes([b[0], b[1]]))
                        })
                        .max(),
                    _ => got
                        .iter()
                        .zip(&twin)
                        .map(|(a, b)| u16::from(a.abs_diff(*b)))
                        .max(),
                };
                assert!(
                    worst.unwrap_or(0) <= 1,
                    "{format:?} {extra:?} frame {i}: off by {worst:?} units from the twin"
                );
            }
        }
    }
}

/// A command buffer of the application's, begun, and the pool it came from.
///
/// # Safety
/// `app` outlives the pool; the caller destroys the pool.
unsafe fn begun(app: &embed::App) -> (ash::vk::CommandPool, ash::vk::CommandBuffer) {
    use ash::vk;
    // SAFETY: live device; the pool is destroyed by the caller.
    unsafe {
        let pool = app
            .device
            .create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(app.family)
                    .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
                None,
            )
            .expect("pool");
        let cmd = app
            .device
            .allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .command_buffer_count(1),
            )
            .expect("command buffer")[0];
        app.device
            .begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default())
            .expect("begin");
        (pool, cmd)
    }
}

/// A host-visible buffer of the application's that transfers can write, and its memory.
///
/// # Safety
/// `app` outlives both; the caller destroys them.
unsafe fn host_buffer(app: &embed::App, bytes: u64) -> (ash::vk::Buffer, ash::vk::DeviceMemory) {
    use ash::vk;
    let d = &app.device;
    // SAFETY: live device; the caller destroys the buffer and frees the memory.
    unsafe {
        let buffer = d
            .create_buffer(
                &vk::BufferCreateInfo::default()
                    .size(bytes)
                    .usage(vk::BufferUsageFlags::TRANSFER_DST),
                None,
            )
            .expect("buffer");
        let req = d.get_buffer_memory_requirements(buffer);
        let host = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
        let index = (0..app.props.memory_type_count)
            .find(|&i| {
                req.memory_type_bits & (1 << i) != 0
                    && app.props.memory_types[i as usize]
                        .property_flags
                        .contains(host)
            })
            .expect("host memory");
        let memory = d
            .allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(req.size)
                    .memory_type_index(index),
                None,
            )
            .expect("memory");
        d.bind_buffer_memory(buffer, memory, 0).expect("bind");
        (buffer, memory)
    }
}

/// Destroys what a test made on the application's device, then the application, and checks
/// that validation reported nothing since `before`.
///
/// # Safety
/// The device is idle; nothing else uses these objects.
unsafe fn teardown(
    app: embed::App,
    pool: ash::vk::CommandPool,
    (buffer, memory): (ash::vk::Buffer, ash::vk::DeviceMemory),
    before: u32,
) {
    // SAFETY: per this function's contract.
    unsafe {
        app.device.destroy_command_pool(pool, None);
        app.device.destroy_buffer(buffer, None);
        app.device.free_memory(memory, None);
        app.destroy().expect("destroy");
    }
    assert_eq!(
        embed::MESSAGES.load(Ordering::SeqCst),
        before,
        "validation reported messages"
    );
}

/// A buffer target, and what the API refuses: a frame retired before its submission ran,
/// retired twice or by another renderer, a buffer too small, a splatting method.
#[test]
fn buffer_targets_and_misuse() {
    use ash::vk;
    use vmls::renderer::{Access, ExternalCommands, Renderer, Target};
    let _guard = validated();
    let before = embed::MESSAGES.load(Ordering::SeqCst);
    let scene = vmls::scene::Scene::load(None, &overrides(&[])).expect("scene");
    let (w, h) = (scene.camera.width, scene.camera.height);
    let bytes = u64::from(w) * u64::from(h) * 16;
    // SAFETY: the test is the application; it waits for the queue before reading or destroying.
    unsafe {
        let app = embed::App::new().expect("app");
        let d = &app.device;
        let (buffer, memory) = host_buffer(&app, bytes);
        let (pool, cmd) = begun(&app);
        {
            let ctx = app.context().expect("context");
            let field = scene.field_on(Some(ctx.info()), |_| {}).expect("field");
            let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
            let mut other = Renderer::new(&ctx, field).expect("renderer");
            let target = Target::buffer(buffer, 0, bytes, Access::NONE, Access::HOST_READ);
            let small = Target::buffer(buffer, 0, bytes - 16, Access::NONE, Access::HOST_READ);
            let view = scene.view();
            let err = renderer
                .record(ExternalCommands::new(cmd), &view, &small)
                .expect_err("a buffer one pixel short");
            assert!(err.to_string().contains("target buffer"), "{err}");
            let left_undefined = Target::image(
                vk::Image::null(),
                TargetFormat::Rgba8Unorm,
                vk::ImageLayout::UNDEFINED,
                vk::ImageLayout::UNDEFINED,
                Access::NONE,
                Access::NONE,
            );
            let err = renderer
                .record(ExternalCommands::new(cmd), &view, &left_undefined)
                .expect_err("an image cannot be left in UNDEFINED");
            assert!(err.to_string().contains("target image"), "{err}");
            // Records into `cmd`, retires too early (the frame has not run: it stays in
            // flight), submits, waits and retires.
            let frame_cycle = |renderer: &mut Renderer| {
                let frame = renderer
                    .record(ExternalCommands::new(cmd), &view, &target)
                    .expect("record");
                assert_eq!(renderer.frames_in_flight(), 1);
                let err = renderer.retire(&frame).expect_err("retired early");
                assert!(
                    err.to_string().contains("before the GPU completed"),
                    "{err}"
                );
                assert_eq!(renderer.frames_in_flight(), 1);
                d.end_command_buffer(cmd).expect("end");
                let cmds = [cmd];
                d.queue_submit(
                    app.queue,
                    &[vk::SubmitInfo::default().command_buffers(&cmds)],
                    vk::Fence::null(),
                )
                .expect("submit");
                d.queue_wait_idle(app.queue).expect("wait");
                let done = renderer.retire(&frame).expect("retire");
                assert_eq!(renderer.frames_in_flight(), 0);
                assert!(done.evaluations > 0 && done.dispatches > 0);
                frame
            };
            let frame = frame_cycle(&mut renderer);
            assert!(other.retire(&frame).is_err(), "another renderer's frame");
            assert!(renderer.retire(&frame).is_err(), "retired twice");
            // The same slot again: its earlier frame completed, this one has not yet run.
            d.reset_command_buffer(cmd, vk::CommandBufferResetFlags::empty())
                .expect("reset");
            d.begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default())
                .expect("begin");
            let again = frame_cycle(&mut renderer);
            assert!(renderer.retire(&again).is_err(), "retired twice");
            let ptr = d
                .map_memory(memory, 0, bytes, vk::MemoryMapFlags::empty())
                .expect("map");
            let got = std::slice::from_raw_parts(ptr.cast::<u8>(), bytes as usize).to_vec();
            d.unmap_memory(memory);
            let (image, _) = renderer.render(&view, |_| {}).expect("render");
            let want: &[u8] = bytemuck::cast_slice(&image.pixels);
            assert!(got == want, "the buffer target differs from render()");
            assert_eq!(ctx.validation_errors(), 0);
        }
        teardown(app, pool, (buffer, memory), before);
    }
}

/// A recorded splatting frame sizes its entry list before it runs: from `prepare`'s count of
/// a view with thick sheets (93 504 entries at 40 × 24), a view with thinner ones (323 430)
/// bins more entries than the list holds.
/// That frame accumulates nothing and `retire` says so; the next frame of the view reserves
/// what the first one counted and equals `render()`'s. A work budget that the binned entries
/// exceed stops a recorded frame as it stops `render()`.
#[test]
fn recorded_splatting_learns_its_entry_count() {
    use ash::vk;
    use vmls::field::RenderError;
    use vmls::renderer::{Access, ExternalCommands, RecordedFrame, Renderer, Target};
    let _guard = validated();
    let before = embed::MESSAGES.load(Ordering::SeqCst);
    let thick = vmls::scene::Scene::load(
        None,
        &overrides(&[
            "render.method=\"splat\"",
            "splat.split=true",
            "splat.slab=2.0",
        ]),
    )
    .expect("scene");
    let thin = vmls::scene::Scene::load(
        None,
        &overrides(&[
            "render.method=\"splat\"",
            "splat.split=true",
            "splat.slab=0.5",
        ]),
    )
    .expect("scene");
    let (w, h) = (thin.camera.width, thin.camera.height);
    let bytes = u64::from(w) * u64::from(h) * 16;
    // SAFETY: the test is the application; it waits for the queue before reading or destroying.
    unsafe {
        let app = embed::App::new().expect("app");
        let d = &app.device;
        let (buffer, memory) = host_buffer(&app, bytes);
        let (pool, cmd) = begun(&app);
        d.end_command_buffer(cmd).expect("end");
        {
            let ctx = app.context().expect("context");
            let field = thin.field_on(Some(ctx.info()), |_| {}).expect("field");
            let mut renderer = Renderer::new(&ctx, field).expect("renderer");
            let target = Target::buffer(buffer, 0, bytes, Access::NONE, Access::HOST_READ);
            // The target's pixels, through a mapping (after a frame, the queue idle).
            let read_target = || -> Vec<f32> {
                let ptr = d
                    .map_memory(memory, 0, bytes, vk::MemoryMapFlags::empty())
                    .expect("map");
                let pixels = bytemuck::cast_slice(std::slice::from_raw_parts(
                    ptr.cast::<u8>(),
                    bytes as usize,
                ))
                .to_vec();
                d.unmap_memory(memory);
                pixels
            };
            // Records one frame of `view` into `cmd`, submits it, waits and retires it.
            let run = |renderer: &mut Renderer,
                       view: &vmls::view::View<'_>|
             -> Result<RecordedFrame, RenderError> {
                d.reset_command_buffer(cmd, vk::CommandBufferResetFlags::empty())
                    .expect("reset");
                d.begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default())
                    .expect("begin");
                let frame = renderer.record(ExternalCommands::new(cmd), view, &target);
                d.end_command_buffer(cmd).expect("end");
                let frame = frame?;
                let cmds = [cmd];
                d.queue_submit(
                    app.queue,
                    &[vk::SubmitInfo::default().command_buffers(&cmds)],
                    vk::Fence::null(),
                )
                .expect("submit");
                d.queue_wait_idle(app.queue).expect("wait");
                renderer.retire(&frame)
            };
            let (rendered, _) = renderer.render(&thin.view(), |_| {}).expect("render");
            let Some(report) = rendered.splat.as_ref() else {
                panic!("a splatting frame reports its counts");
            };
            let entries = report.counts.entries;
            renderer.prepare(&thick.view()).expect("prepare");
            let err = run(&mut renderer, &thin.view()).expect_err("the list is too small");
            assert!(
                matches!(err, RenderError::Recorded(_)) && err.to_string().contains("entry list"),
                "{err}"
            );
            assert!(err.to_string().contains(&entries.to_string()), "{err}");
            let done = run(&mut renderer, &thin.view()).expect("the next frame fits");
            let counts = done.splat.expect("splatting counts");
            assert_eq!(counts.entries, entries);
            assert_eq!(done.evaluations, counts.evaluated);
            assert!(done.dispatches >= 8, "{} dispatches", done.dispatches);
            let got = read_target();
            let want: &[f32] = bytemuck::cast_slice(&rendered.pixels);
            let worst = got
                .iter()
                .zip(want)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            // To the bit, as in recorded_splatting_frames_equal_render.
            assert!(worst == 0.0, "off by {worst:e} from render()");

            // A budget that the sheets meet and the binned entries exceed by half of theirs.
            let pixels = f64::from(w * h);
            let sheets = f64::from(report.slabs) * pixels;
            let budget = sheets + 0.5 * entries as f64 * f64::from(report.group_size);
            renderer.set_work_budget(Some(budget));
            let err = renderer
                .render(&thin.view(), |_| {})
                .expect_err("render() refuses it");
            assert!(matches!(err, RenderError::Budget { .. }), "{err}");
            let err = run(&mut renderer, &thin.view()).expect_err("so does retire");
            assert!(matches!(err, RenderError::Budget { .. }), "{err}");
            renderer.set_work_budget(None);
            run(&mut renderer, &thin.view()).expect("without the budget it runs");

            // Walks of a few hundred loop iterations a pass: the frames recorded so far took
            // one pass a band, so the next records one, its walks do not finish, and retire
            // says so; the one after records the passes it counted and equals render()'s,
            // which the split leaves the same to the bit.
            renderer.set_splat_raster_chunk(Some(300));
            let err = run(&mut renderer, &thin.view()).expect_err("one pass a band is too few");
            assert!(
                matches!(err, RenderError::Recorded(_)) && err.to_string().contains("passes"),
                "{err}"
            );
            let done = run(&mut renderer, &thin.view()).expect("the next records enough");
            assert!(done.splat.expect("counts").resumed > 0);
            let split = read_target();
            assert!(split == want, "split walks differ from render()'s frame");
            assert_eq!(ctx.validation_errors(), 0);
        }
        teardown(app, pool, (buffer, memory), before);
    }
}
