//! Issue 30 §2–3 on one device: a field divided into kd bricks with ghosts reconstructs, inside
//! every brick, exactly the undivided field (and does not without the ghosts), and the bricks'
//! frames, each clipped to its box with steps anchored to the undivided ray and composited in
//! the kd tree's visibility order, add up to the one-device frame.

mod common;

use common::{finish, general_scene, gpu, ml_field, point_data, recon, splat};
use vmls::bricks::{Ghosts, VirtualBricks, divide};
use vmls::data::dataset::Geometry;
use vmls::data::random::Lcg;
use vmls::field::Field;
use vmls::recon::{Basis, GradientMode, Weight};
use vmls::renderer::Renderer;
use vmls::scene::NeighbourMode;

/// A grid (support 2.4 spacings: two ghost planes), a tetrahedral mesh (per-point supports
/// from the one-ring), scattered points with rotated ellipsoidal supports, and the Gaussian sum
/// over the same points.
fn fields() -> Vec<(&'static str, Field)> {
    let grid = ml_field(
        17,
        recon(
            Basis::Linear,
            Weight::Wendland,
            GradientMode::Local,
            NeighbourMode::Grid,
            2.4,
        ),
    );
    let scene = general_scene(&[]);
    let mesh = splat::field_of(splat::torus_samples(), &scene);
    let mut rng = Lcg::new(5);
    let points: Vec<[f64; 3]> = (0..2000)
        .map(|_| [rng.next_f64(), rng.next_f64(), rng.next_f64()])
        .collect();
    let d = point_data(Geometry::Points { points }, |p| {
        0.5 + 0.3 * (4.0 * p[0]).sin() * p[1] + 0.2 * p[2] * p[2]
    });
    let cloud = splat::field_of(splat::point_samples(&d, Some(true)), &scene);
    // The Gaussian sum, whose SPH volumes a brick keeps from the whole field.
    let gaussian = general_scene(&["reconstruction.method=\"gaussian\"".into()]);
    let sum = splat::field_of(splat::point_samples(&d, Some(true)), &gaussian);
    vec![
        ("grid", grid),
        ("mesh", mesh),
        ("points", cloud),
        ("gaussian points", sum),
    ]
}

/// The largest |difference| between a piece and the whole at random points of the piece's box
/// (relative to the value range), and how many points one defines and the other does not.
fn piece_difference(whole: &Field, piece: &Field, rng: &mut Lcg) -> (f64, usize) {
    let (lo, hi) = piece.clip().expect("a piece has a box");
    let nw = whole.neighbours().expect("neighbours");
    let np = piece.neighbours().expect("neighbours");
    let (vlo, vhi) = whole.value_range();
    let (mut worst, mut undefined) = (0.0f64, 0usize);
    for _ in 0..400 {
        let x = [0, 1, 2].map(|a| lo[a] + rng.next_f64() * (hi[a] - lo[a]));
        match (
            whole.evaluate_direct(nw.as_ref(), x),
            piece.evaluate_direct(np.as_ref(), x),
        ) {
            (Some(a), Some(b)) => worst = worst.max((a.value - b.value).abs() / (vhi - vlo)),
            (None, None) => {}
            _ => undefined += 1,
        }
    }
    (worst, undefined)
}

#[test]
fn every_brick_reconstructs_the_undivided_field_and_only_with_its_ghosts() {
    let mut rng = Lcg::new(17);
    for (name, field) in fields() {
        for ranks in [2, 3, 5] {
            let (_, pieces) = divide(&field, ranks, Ghosts::Mls).expect("divide");
            let (_, bare) = divide(&field, ranks, Ghosts::Off).expect("divide without ghosts");
            let (mut exact, mut without) = (0.0f64, 0.0f64);
            for ((piece, count), (alone, alone_count)) in pieces.iter().zip(&bare) {
                assert!(
                    count.ghosts > 0,
                    "{name}, {ranks} ranks: a brick without ghosts"
                );
                assert_eq!(alone_count.ghosts, 0);
                let (d, undefined) = piece_difference(&field, piece, &mut rng);
                assert_eq!(undefined, 0, "{name}, {ranks} ranks: definedness differs");
                exact = exact.max(d);
                let (d, undefined) = piece_difference(&field, alone, &mut rng);
                without = without.max(if undefined > 0 { 1.0 } else { d });
            }
            // The same samples in another order: f64 rounding only.
            assert!(
                exact <= 1e-9,
                "{name}, {ranks} ranks: {exact:.3e} with ghosts"
            );
            assert!(
                without > 1e-3,
                "{name}, {ranks} ranks: {without:.3e} without ghosts"
            );
        }
    }
}

/// The one-device frame of `scene`'s view of `field` and the same at a quarter of the step (ε
/// a sixteenth, l_min and l_max a quarter): the frame and its own discretisation error's
/// reference.
fn one_device(
    ctx: &vmls::vk::Context,
    field: &Field,
    scene: &vmls::scene::Scene,
) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let mut fine_settings = scene.render.clone();
    fine_settings.step_spacings *= 0.25;
    fine_settings.reference_step_spacings *= 0.25;
    fine_settings.epsilon /= 16.0;
    fine_settings.l_min_spacings *= 0.25;
    fine_settings.l_max_spacings *= 0.25;
    let frame = |settings: &vmls::view::RenderSettings| {
        let mut r = Renderer::new(ctx, field.clone()).expect("renderer");
        let view = vmls::view::View {
            settings,
            ..scene.view()
        };
        r.render(&view, |_| {}).expect("frame").0.pixels
    };
    (frame(&scene.render), frame(&fine_settings))
}

/// The one-device frame, the bricks' composite of the same view (and their order) and the
/// one-device frame at a quarter of the step (its own discretisation error, the scale the face
/// splits are measured against).
struct Frames {
    whole: Vec<[f32; 4]>,
    bricked: Vec<[f64; 4]>,
    fine: Vec<[f32; 4]>,
    order: Vec<usize>,
}

fn frames(extra: &[&str], ranks: usize) -> Frames {
    let mut o: Vec<String> = [
        "camera.width=40",
        "camera.height=40",
        "render.method=\"fixed\"",
        "render.interval=\"hermite\"",
        "render.step=0.5",
        "render.background=[0.1,0.2,0.3]",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    o.extend(extra.iter().map(|s| s.to_string()));
    let scene = general_scene(&o);
    let field = scene.field(|_| {}).expect("field");
    let (ctx, _) = gpu();
    let (whole, fine) = one_device(&ctx, &field, &scene);
    let (bricked, order) = {
        let mut b = VirtualBricks::new(&ctx, &field, ranks, &scene.view()).expect("bricks");
        let frame = b.render(&scene.view()).expect("bricked frame");
        assert_eq!(frame.bricks.len(), ranks);
        (frame.pixels, frame.order)
    };
    finish(ctx);
    Frames {
        whole,
        bricked,
        fine,
        order,
    }
}

fn largest(a: &[[f32; 4]], b: impl Fn(usize) -> [f64; 4]) -> f64 {
    a.iter()
        .enumerate()
        .flat_map(|(i, p)| {
            let q = b(i);
            (0..4).map(move |k| (f64::from(p[k]) - q[k]).abs())
        })
        .fold(0.0, f64::max)
}

#[test]
fn bricks_composite_to_the_one_device_frame() {
    // Early termination off: it acts within a brick only (module documentation of bricks).
    for (extra, name) in [
        (&["render.early_termination=1"][..], "fixed"),
        (
            &["render.method=\"riemann\"", "render.min_transmittance=0"][..],
            "riemann",
        ),
        (
            &[
                "render.method=\"adaptive\"",
                "render.adaptive=\"hermite\"",
                "render.early_termination=1",
            ][..],
            "adaptive",
        ),
    ] {
        for ranks in [2, 5] {
            let Frames {
                whole,
                bricked,
                fine,
                order,
            } = frames(extra, ranks);
            let split = largest(&whole, |i| bricked[i]);
            let own = largest(&whole, |i| fine[i].map(f64::from));
            let pixel = |i: usize| {
                (0..4)
                    .map(|k| (f64::from(whole[i][k]) - bricked[i][k]).abs())
                    .fold(0.0, f64::max)
            };
            let touched = (0..whole.len()).filter(|&i| pixel(i) > 0.1 * own).count();
            eprintln!(
                "{name}, {ranks} bricks (order {order:?}): split {split:.3e} ({touched} pixels \
                 over a tenth of the step's {own:.3e})"
            );
            // Only the interval a face splits differs, two clipped intervals with a knot on
            // the face standing for one: at most that interval's own discretisation error, so
            // at most the frame's (step against a quarter step), and in few pixels.
            assert!(split <= own, "{name}, {ranks}: {split:.3e} vs {own:.3e}");
            assert!(
                touched * 20 <= whole.len(),
                "{name}, {ranks}: {touched} pixels"
            );
            assert!(split > 0.0, "{name}, {ranks}: bricks changed nothing?");
        }
    }
}

#[test]
fn a_bricks_kernel_equals_its_cpu_twin() {
    for method in ["fixed", "riemann", "adaptive"] {
        let scene = general_scene(&[
            "camera.width=24".into(),
            "camera.height=24".into(),
            format!("render.method=\"{method}\""),
            "render.adaptive=\"hermite\"".into(),
            "render.step=0.5".into(),
        ]);
        let field = scene.field(|_| {}).expect("field");
        let (_, pieces) = divide(&field, 3, Ghosts::Mls).expect("divide");
        let mut narrowed = 0;
        for (piece, _) in &pieces {
            let mut setup = scene.ray_setup(piece).expect("setup");
            // A brick over black dispatches only the rows its box can project to.
            let [_, y0, _, y1] = setup.window.expect("a brick's window");
            narrowed += usize::from(y1 - y0 + 1 < setup.camera.height);
            let tables = vmls::raycast::build_tables(&setup, piece, &scene.transfer, 128, |_| {});
            let cpu = vmls::raycast::raycast_image(&setup, piece, &scene.transfer, tables.as_ref())
                .expect("CPU twin");
            let (ctx, compiler) = gpu();
            let gf = vmls::field::gpu::GpuField::upload(&ctx, piece).expect("upload");
            // Whole frames, and frames of two steps a chunk (the face's interval is only the
            // first chunk's).
            let mut frames = Vec::new();
            for chunk in [None, Some(2)] {
                setup.chunk = chunk;
                let image = vmls::renderer::render(
                    &ctx,
                    &compiler,
                    piece,
                    &gf,
                    &scene.transfer,
                    tables.as_ref(),
                    &setup,
                    |_| {},
                )
                .expect("render");
                frames.push(image.pixels);
            }
            drop(gf);
            finish(ctx);
            for pixels in &frames {
                let pixel = |i: usize| {
                    (0..4)
                        .map(|k| (f64::from(pixels[i][k]) - cpu[i].rgba[k]).abs())
                        .fold(0.0, f64::max)
                };
                let worst = (0..cpu.len()).map(pixel).fold(0.0, f64::max);
                // As every ray-cast frame's bound (3e-5), with room for the clipped first
                // interval at the face in f32 (measured 4.2e-5); adaptive rays whose f32 and
                // f64 choices differ, as in the other adaptive GPU-vs-CPU tests, on at most 1%
                // of the pixels and within 2e-3.
                let apart = (0..cpu.len()).filter(|&i| pixel(i) >= 1e-4).count();
                match method {
                    "adaptive" => assert!(
                        apart * 100 <= cpu.len() && worst < 2e-3,
                        "adaptive GPU vs CPU on a brick: {apart} pixels apart, {worst:.3e}"
                    ),
                    _ => assert!(worst < 1e-4, "{method} GPU vs CPU on a brick: {worst:.3e}"),
                }
            }
            assert!(
                cpu.iter().any(|p| p.rgba[3] > 0.05),
                "the brick rendered nothing"
            );
        }
        assert!(narrowed > 0, "{method}: no brick's window left rows out");
    }
}

#[test]
fn axis_aligned_orthographic_views_composite_like_one_device() {
    // Rays along an axis: a whole row lies in the plane between two bricks (odd image size,
    // eye on the plane), and faces fall on step positions; parallel rays also need the
    // visibility order of their direction, not of the eye. Tilted too, so that rays cross the
    // planes from the side away from the eye.
    for (eye, up) in [
        ("[-3.0,0.0,0.0]", "[0.0,0.0,1.0]"),
        ("[0.0,0.0,3.0]", "[0.0,1.0,0.0]"),
        ("[0.3,0.2,-3.0]", "[1.0,0.0,0.0]"),
        // The eye above the x and y planes while the rays travel towards +x and +y: a rule
        // from the eye's side would composite the rays that start below them backwards.
        ("[0.5,0.4,3.0]|[1.2,0.9,0.0]", "[0.0,1.0,0.0]"),
    ] {
        let (eye, target) = eye.split_once('|').unwrap_or((eye, "[0.0,0.0,0.0]"));
        let scene = general_scene(&[
            "camera.width=41".into(),
            "camera.height=41".into(),
            "camera.projection=\"orthographic\"".into(),
            "camera.view_height=2.4".into(),
            format!("camera.eye={eye}"),
            format!("camera.target={target}"),
            format!("camera.up={up}"),
            "render.method=\"fixed\"".into(),
            "render.step=0.25".into(),
            "render.early_termination=1".into(),
        ]);
        let field = scene.field(|_| {}).expect("field");
        let (ctx, _) = gpu();
        let (whole, fine) = one_device(&ctx, &field, &scene);
        let own = largest(&whole, |i| fine[i].map(f64::from));
        for ranks in [2, 4, 8] {
            let mut b = VirtualBricks::new(&ctx, &field, ranks, &scene.view()).expect("bricks");
            let bricked = b.render(&scene.view()).expect("bricked frame").pixels;
            let split = largest(&whole, |i| bricked[i]);
            eprintln!("orthographic from {eye}, {ranks} bricks: {split:.3e} (own {own:.3e})");
            assert!(
                split <= own,
                "from {eye}, {ranks} bricks: {split:.3e} vs {own:.3e}"
            );
        }
        finish(ctx);
    }
}

#[test]
fn what_bricks_cannot_render_is_refused_by_name() {
    let scene = general_scene(&[
        "camera.width=8".into(),
        "camera.height=8".into(),
        "render.method=\"adaptive\"".into(),
        "render.adaptive=\"mls2008\"".into(),
    ]);
    let field = scene.field(|_| {}).expect("field");
    let (ctx, _) = gpu();
    {
        let mut b = VirtualBricks::new(&ctx, &field, 2, &scene.view()).expect("bricks");
        let e = b.render(&scene.view()).expect_err("mls2008").to_string();
        assert!(
            e.contains("render.adaptive") && e.contains("mls2008"),
            "{e}"
        );
        let mut settings = scene.render.clone();
        settings.method = vmls::view::Method::Fixed;
        settings.tolerance = Some(1e-2);
        let view = vmls::view::View {
            settings: &settings,
            ..scene.view()
        };
        let e = b.render(&view).expect_err("tolerance").to_string();
        assert!(e.contains("render.tolerance"), "{e}");
    }
    finish(ctx);
    let exact = general_scene(&["reconstruction.method=\"exact\"".into()]);
    let field = exact.field(|_| {}).expect("field");
    let e = divide(&field, 2, Ghosts::Mls)
        .expect_err("exact refused")
        .to_string();
    assert!(e.contains("reconstruction.method"), "{e}");
}

#[test]
fn the_command_line_renders_bricks_and_reports_each() {
    use common::cli::{assert_fails, dir, s, small_render, vmls};
    let d = dir("bricks");
    // Splatting at 32² with thick sheets (at 8² one tile's walk would pass llvmpipe's loop
    // limit, bricks or not).
    let splat = ["camera.width=32", "camera.height=32", "splat.slab=4.0"];
    for (method, extra) in [
        ("fixed", &[][..]),
        ("splat", &splat),
        ("splat-post", &splat),
    ] {
        let png = d.join(format!("{method}.png"));
        let stats = d.join(format!("{method}.json"));
        let set = format!("render.method=\"{method}\"");
        let mut args = vec!["--bricks", "3", "--stats", s(&stats), "--set", &set];
        for e in extra {
            args.extend(["--set", e]);
        }
        let out = vmls(&small_render(&png, &args));
        assert!(
            out.status.success(),
            "{method}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(png.exists());
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
        let bricks = v["bricks"].as_array().expect("bricks");
        assert_eq!(bricks.len(), 3);
        assert_eq!(v["order"].as_array().map(|o| o.len()), Some(3));
        for b in bricks {
            assert!(b["ghosts"].as_u64() > Some(0) && b["samples_inside"].as_u64() > Some(0));
            assert!(b["gpu_ms"].as_f64() > Some(0.0), "{method}");
        }
    }
    let refused = d.join("r.png");
    let out = vmls(&small_render(
        &refused,
        &["--bricks", "2", "--set", "render.method=\"adaptive\""],
    ));
    assert_fails(&out, &["render.adaptive", "mls2008"], &refused);
    let out = vmls(&small_render(&refused, &["--bricks", "2", "--cpu"]));
    assert_fails(&out, &["--bricks"], &refused);
    let out = vmls(&small_render(&refused, &["--bricks", "100000"]));
    assert!(!out.status.success() && !refused.exists());
}
