//! Splatting's hard cases and its other inputs: degenerate kernels (at and behind the eye,
//! needle-thin, very long, 179° field of view), the eye inside the volume, irregular data and
//! hull domains, surface splats against the ray caster, refused settings, and what a new camera
//! reuses.
mod common;

use common::splat::*;
use common::*;
use vmls::data::dataset::Geometry;
use vmls::field::{Field, RenderError};
use vmls::probe::Lcg;
use vmls::raycast::raycast_image;
use vmls::recon::OctreeSettings;
use vmls::recon::support_index::SupportIndex;
use vmls::renderer::Renderer;
use vmls::scene::Scene;
use vmls::splat::project::KernelKind;
use vmls::splat::project::{Cull, Kernel, splat_project};
use vmls::splat::raster::splat_image;
use vmls::splat::{Antialias, Shading, SplatSettings, SplatSetup};
use vmls::view::camera::Projection;
use vmls::view::shading::Isosurface;

#[test]
fn degenerate_kernels_are_culled_or_bounded() {
    let base = scene(&["camera.width=64", "camera.height=48"]);
    let field = base.field(|_| {}).expect("field");
    for fov in [30.0, 179.0] {
        let mut s = base.clone();
        s.camera.projection = Projection::Perspective { fov_y_degrees: fov };
        s.camera.eye = [0.2, -0.1, 0.3];
        for shading in [Shading::Pre, Shading::Post] {
            let setup = setup(&s, &field, shading);
            let eye = setup.eye;
            let iso = |h: f64| rotated_metric([h; 3], 0.0);
            let cases = [
                ("at the eye", eye, iso(0.05)),
                ("behind the eye", eye - setup.basis.forward * 0.5, iso(0.05)),
                (
                    "1e-6 thin",
                    eye + setup.basis.forward * 0.6,
                    rotated_metric([0.05, 1e-6, 0.05], 0.4),
                ),
                (
                    "1e6 long",
                    eye + setup.basis.forward * 0.6,
                    rotated_metric([1e6, 0.05, 0.05], 0.4),
                ),
                (
                    "far off-screen",
                    eye + setup.basis.forward * 0.6 + setup.basis.right * 50.0,
                    iso(0.05),
                ),
                (
                    "grazing",
                    eye + setup.basis.forward * 0.01 + setup.basis.right * 0.5,
                    iso(0.005),
                ),
            ];
            for (name, p, metric) in cases {
                let k = Kernel {
                    position: p.to_array(),
                    value: 0.5,
                    metric,
                    volume: 1e-3,
                    kind: KernelKind::Volume,
                };
                match splat_project(&setup, &s.transfer, &k) {
                    Err(_) => {}
                    Ok(sp) => {
                        let finite = sp.amplitude.is_finite()
                            && sp.conic.iter().all(|c| c.is_finite())
                            && sp.depth_sigma.is_finite()
                            && sp.depth_sigma > 0.0;
                        assert!(finite, "{name} (fov {fov}): {sp:?}");
                        let (w, h) = (s.camera.width as i32, s.camera.height as i32);
                        let b = sp.bbox;
                        assert!(
                            b[0] >= 0 && b[1] >= 0 && b[2] < w && b[3] < h,
                            "{name}: box {b:?}"
                        );
                        assert!(sp.slabs[0] <= sp.slabs[1] && sp.slabs[1] < setup.slabs);
                    }
                }
            }
            let at_eye = Kernel {
                position: eye.to_array(),
                value: 0.5,
                metric: iso(0.05),
                volume: 1e-3,
                kind: KernelKind::Volume,
            };
            assert_eq!(splat_project(&setup, &s.transfer, &at_eye), Err(Cull::Near));
        }
    }
}

#[test]
fn the_eye_inside_the_volume_renders_finite_images_on_the_gpu() {
    let (ctx, _) = gpu();
    let field = scene(&[]).field(|_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    for method in ["splat", "splat-post"] {
        let m = format!("render.method=\"{method}\"");
        let s = scene(&[
            m.as_str(),
            "camera.eye=[0.1,0.05,0.02]",
            "camera.fov_y=179.0",
        ]);
        let (gpu, report) = gpu_frame(&mut renderer, &s);
        assert!(
            report.counts.culled_near > 0,
            "{method}: {:?}",
            report.counts
        );
        assert!(gpu.iter().all(|p| p[3] >= 0.0 && p[3] <= 1.0 + 1e-6));
        let shading = s.render.method.splat_shading().expect("splat");
        let cpu = splat_image(&setup(&s, &field, shading), &field, &s.transfer).expect("CPU twin");
        let diff = max_diff(&gpu, &cpu.pixels);
        eprintln!("GPU vs CPU, near {method}: {diff:.2e}");
        assert!(diff < GPU_TOLERANCE, "{method}: GPU vs CPU {diff:.3e}");
    }
    drop(renderer);
    finish(ctx);
}

#[test]
fn irregular_data_splats_on_the_gpu_as_on_the_cpu() {
    let (ctx, _) = gpu();
    let field = field_of(torus_samples(), &scene(&[]));
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    for method in ["splat", "splat-post"] {
        let m = format!("render.method=\"{method}\"");
        let s = scene(&[m.as_str(), "camera.eye=[2.2,-1.8,1.9]"]);
        let (gpu, _) = gpu_frame(&mut renderer, &s);
        let shading = s.render.method.splat_shading().expect("splat");
        let cpu = splat_image(&setup(&s, &field, shading), &field, &s.transfer).expect("CPU twin");
        let diff = max_diff(&gpu, &cpu.pixels);
        eprintln!("GPU vs CPU, torus {method}: {diff:.2e}");
        assert!(diff < GPU_TOLERANCE, "{method}: GPU vs CPU {diff:.3e}");
        let covered = cpu.pixels.iter().filter(|p| p[3] > 0.05).count();
        assert!(covered > 50, "{method}: {covered} pixels show the torus");
    }
    drop(renderer);
    finish(ctx);
}

#[test]
fn splatting_defers_the_octree_and_ray_casting_builds_it() {
    // A splatting field builds no octree: its kernel volumes come from kd-trees over classes
    // of support radii, the same sums as the octree's (up to rounding), and splatting renders
    // without one; the first ray-cast frame builds it. Points clustered towards a corner, so
    // their (anisotropic) supports span several radius classes.
    let mut rng = Lcg::new(5);
    let points: Vec<[f64; 3]> = (0..3000)
        .map(|_| std::array::from_fn(|_| 2.0 * rng.next_f64().powi(2) - 1.0))
        .collect();
    let d = point_data(Geometry::Points { points }, |p| {
        0.5 + 0.4 * (3.0 * p[0]).sin() * p[2].cos()
    });
    let samples = || point_samples(&d, Some(true));
    let s = scene(&["render.method=\"splat-post\"", "camera.eye=[2.2,-1.8,1.9]"]);
    let eager = field_of(samples(), &s);
    let deferred =
        Field::from_samples_deferred(samples(), s.reconstruction, &OctreeSettings::default())
            .expect("field");
    assert!(eager.octree_if_built().is_some() && deferred.octree_if_built().is_none());
    let (a, b) = (eager.kernel_volumes(), deferred.kernel_volumes());
    let worst = (0..eager.samples.len())
        .map(|i| (a.get(i) - b.get(i)).abs() / a.get(i))
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-12,
        "kernel volumes differ by {worst:.3e} (relative)"
    );
    let index = SupportIndex::new(&deferred.samples);
    assert!(index.classes() >= 2, "{} radius classes", index.classes());
    let (ctx, _) = gpu();
    let mut renderer = Renderer::new(&ctx, deferred).expect("renderer");
    let (gpu, _) = gpu_frame(&mut renderer, &s);
    assert!(
        renderer.field().octree_if_built().is_none(),
        "splatting built the octree"
    );
    let cpu =
        splat_image(&setup(&s, &eager, Shading::Post), &eager, &s.transfer).expect("CPU twin");
    let diff = max_diff(&gpu, &cpu.pixels);
    eprintln!("GPU vs CPU, deferred: {diff:.2e}");
    assert!(
        diff < GPU_TOLERANCE,
        "deferred field, GPU vs the eager one's CPU twin {diff:.3e}"
    );
    let ray = scene(&[
        "render.method=\"fixed\"",
        "reconstruction.method=\"gaussian\"",
        "camera.eye=[2.2,-1.8,1.9]",
    ]);
    let (image, _) = renderer
        .render(&ray.view(), |_| {})
        .expect("ray-cast frame");
    assert!(renderer.field().octree_if_built().is_some());
    let covered = image.pixels.iter().filter(|p| p[3] > 0.05).count();
    assert!(covered > 50, "{covered} pixels show the points");
    drop(renderer);
    finish(ctx);
}

#[test]
fn pre_shaded_isosurfaces_and_bad_splat_keys_are_refused_by_name() {
    let s = scene(&[
        "render.method=\"splat\"",
        "transfer.isosurfaces=[{value=0.5, color=[1.0,0.8,0.3], opacity=0.9}]",
    ]);
    let field = s.field(|_| {}).expect("field");
    let err = SplatSetup::new(
        Shading::Pre,
        &s.render.splat,
        &s.camera,
        0.99,
        [0.0; 3],
        &s.isosurfaces,
        &s.lighting,
        &field,
    )
    .expect_err("pre-shaded isosurfaces");
    assert!(matches!(
        err,
        RenderError::Setting {
            key: "transfer.isosurfaces",
            ..
        }
    ));
    for (set, key) in [
        ("splat.cutoff=0.5", "splat.cutoff"),
        ("splat.antialias=\"box\"", "splat.antialias"),
        ("splat.slab=-1.0", "splat.slab"),
        ("splat.occlusion=3", "splat.occlusion"),
        ("splat.footprint=\"ray\"", "splat.footprint"),
        ("splat.surface=1", "splat.surface"),
        ("splat.tile=12", "splat.tile"),
        ("splat.split=\"no\"", "splat.split"),
        ("splat.sheets=3", "sheets"),
        ("reconstruction.sigma=0.5", "reconstruction.sigma"),
    ] {
        let e = Scene::load(None, &[set.to_string()])
            .expect_err(set)
            .to_string();
        assert!(e.contains(key), "{set}: {e}");
    }
    let wide = scene(&["splat.cutoff=5.0"]);
    let err = SplatSetup::new(
        Shading::Pre,
        &wide.render.splat,
        &wide.camera,
        0.99,
        [0.0; 3],
        &[],
        &wide.lighting,
        &field,
    )
    .expect_err("cutoff past the supports");
    assert!(
        matches!(
            err,
            RenderError::Setting {
                key: "splat.cutoff",
                ..
            }
        ),
        "{err}"
    );
    // Post-shaded splatting finds isosurfaces in its sheets (no surface splats), which need
    // split kernels; post-shaded isosurfaces' apron does not fit a workgroup around a 32² tile.
    let iso = [Isosurface {
        value: 0.5,
        color: [1.0, 0.8, 0.3],
        opacity: 0.9,
    }];
    for (extra, isosurfaces, key) in [
        ("splat.surface=true", &[][..], "splat.surface"),
        ("splat.split=false", &[][..], "splat.split"),
        ("splat.tile=32", &iso[..], "splat.tile"),
    ] {
        let post = scene(&["render.method=\"splat-post\"", extra]);
        let err = SplatSetup::new(
            Shading::Post,
            &post.render.splat,
            &post.camera,
            0.99,
            [0.0; 3],
            isosurfaces,
            &post.lighting,
            &field,
        )
        .expect_err(extra);
        assert!(
            matches!(err, RenderError::Setting { key: k, .. } if k == key),
            "{extra}: {err}"
        );
    }
    let tiny = scene(&["render.method=\"splat-post\"", "splat.slab=1e-4"]);
    let err = SplatSetup::new(
        Shading::Post,
        &tiny.render.splat,
        &tiny.camera,
        0.99,
        [0.0; 3],
        &[],
        &tiny.lighting,
        &field,
    )
    .expect_err("too many sheets");
    assert!(err.to_string().contains("splat.slab"), "{err}");
    let d = SplatSettings::default();
    assert_eq!(d.antialias, Antialias::Auto);
}

/// A sphere of radius 0.6 as the isosurface of the distance to the centre, in a 33³ grid.
fn sphere_scene(method: &str) -> (Scene, Field) {
    let m = format!("render.method=\"{method}\"");
    let s = scene(&[
        m.as_str(),
        "splat.surface=true",
        "camera.eye=[0.0,-3.0,0.0]",
        "camera.fov_y=40.0",
        "camera.width=64",
        "camera.height=64",
        "transfer.points=[[0.0,0.0,0.0,0.0,0.0],[2.0,0.0,0.0,0.0,0.0]]",
        "transfer.isosurfaces=[{value=0.6, color=[1.0,0.8,0.3], opacity=1.0}]",
        // Pre-shaded surface splats shade each kernel and average the colours over its
        // footprint, which flattens a shininess-32 highlight (measured: 1.25 against the ray
        // caster's 1.34 at the centre); diffuse shading varies slowly enough to compare.
        "lighting.specular=0.0",
    ]);
    let volume = volume_from([33; 3], [1.0 / 16.0; 3], [-1.0; 3], |p| {
        (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
    });
    let field = grid_field(volume, &s);
    (s, field)
}

#[test]
fn surface_splats_draw_the_isosurface_the_ray_caster_draws() {
    let (rs, field) = sphere_scene("riemann");
    let setup_r = rs.ray_setup(&field).expect("ray setup");
    let ray: Vec<[f64; 4]> = raycast_image(&setup_r, &field, &rs.transfer, None)
        .expect("CPU twin")
        .iter()
        .map(|p| p.rgba)
        .collect();
    let (ss, _) = sphere_scene("splat");
    let splat =
        splat_image(&setup(&ss, &field, Shading::Pre), &field, &ss.transfer).expect("CPU twin");
    let radius = |img: &[[f64; 4]]| {
        let covered = img.iter().map(|p| p[3].clamp(0.0, 1.0)).sum::<f64>();
        (covered / std::f64::consts::PI).sqrt()
    };
    let (r_ray, r_splat) = (radius(&ray), radius(&splat.pixels));
    // The centre pixel faces the viewer: colour·(ambient + diffuse) + specular, opaque.
    let centre = 32 * 64 + 32;
    eprintln!(
        "sphere: radius {r_ray:.2} px ray cast, {r_splat:.2} px surface splats; centre {:?} vs {:?}",
        ray[centre], splat.pixels[centre]
    );
    assert!(
        (r_ray - r_splat).abs() < 0.75,
        "silhouette radius {r_ray:.2} vs {r_splat:.2} px"
    );
    for c in 0..4 {
        assert!(
            (ray[centre][c] - splat.pixels[centre][c]).abs() < 0.03,
            "centre pixel {:?} vs {:?}",
            ray[centre],
            splat.pixels[centre]
        );
    }
}

#[test]
fn post_shaded_sheets_over_a_hull_converge_to_the_ray_cast_gaussian_field() {
    // The transfer function is not transparent at 0, so fog outside the torus but inside its
    // box would show: sheets must integrate inside the hull only, as the ray caster does.
    let common = [
        "render.early_termination=0.99999",
        "splat.antialias=\"none\"",
        "splat.cutoff=4.0",
        "camera.width=32",
        "camera.height=32",
        "camera.eye=[2.2,-1.8,1.9]",
        "transfer.points=[[0.0,0.2,0.2,0.6,1.0],[0.5,0.2,0.5,1.0,2.0],[1.0,1.0,0.5,0.2,5.0]]",
    ];
    let field = field_of(
        torus_samples(),
        &scene(&["reconstruction.method=\"gaussian\""]),
    );
    assert!(field.hull.is_some());
    let errors = sheet_convergence(&field, &common, &[1.0, 0.5, 0.25]);
    eprintln!("post-shaded over a hull, RMSE by sheet thickness: {errors:?}");
    // Measured (Hermite intervals, the default): 1.8e-2, 2.2e-3, 4.3e-4: 8.3× and 5.0× per
    // halving (constant sheets: 1.4e-2, 2.6e-3, 5.4e-4). Thinner sheets converge at about order 2: at
    // least half the error per halving.
    for w in errors.windows(2) {
        assert!(
            w[1].1 <= 0.5 * w[0].1,
            "error must halve as the sheets halve: {errors:?}"
        );
    }
    assert!(errors[2].1 < 3e-3, "finest sheets: {errors:?}");
}

#[test]
fn a_new_camera_reuses_the_splatting_kernels_pipelines_and_buffers() {
    let (ctx, _) = gpu();
    let s = scene(&["render.method=\"splat-post\""]);
    let field = s.field(|_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    let mut frame = |camera: &vmls::view::camera::Camera| {
        renderer
            .render(&s.view_with(camera), |_| {})
            .expect("frame")
    };
    let (_, first) = frame(&s.camera);
    assert!(first.pipeline_built && first.targets_allocated);
    let turned = s.camera.orbited(0.4);
    let (image, second) = frame(&turned);
    assert!(
        !second.pipeline_built && !second.targets_allocated,
        "{second:?}"
    );
    // The same frame from scratch on the CPU twin.
    let mut moved = s.clone();
    moved.camera = turned;
    let cpu = splat_image(
        &setup(&moved, &field, Shading::Post),
        &field,
        &moved.transfer,
    )
    .expect("CPU twin");
    let diff = max_diff(&image.pixels, &cpu.pixels);
    eprintln!("GPU vs CPU, turned: {diff:.2e}");
    assert!(diff < GPU_TOLERANCE, "turned camera: GPU vs CPU {diff:.3e}");
    drop(renderer);
    finish(ctx);
}

/// Pre-shaded frames draw only the kernels their transfer function does not make transparent:
/// a frame of another function uploads them again, classified by it, and each frame equals its
/// CPU twin (which projects every kernel and culls the transparent ones), the first function's
/// frame the same to the bit when it comes back.
#[test]
fn pre_shaded_kernels_are_left_out_by_each_frames_transfer_function() {
    let (ctx, _) = gpu();
    let upper = "transfer.points=[[0.0,0,0,0,0],[0.5,0,0,0,0],[0.6,1,0.5,0.2,8],[1,1,0.5,0.2,8]]";
    let lower = "transfer.points=[[0.0,0.2,0.5,1,8],[0.4,0.2,0.5,1,8],[0.5,0,0,0,0],[1,0,0,0,0]]";
    let scenes = [upper, lower, upper].map(|tf| scene(&["render.method=\"splat\"", tf]));
    let field = scenes[0].field(|_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    let mut frames = Vec::new();
    for s in &scenes {
        let (gpu, report) = gpu_frame(&mut renderer, s);
        let cpu =
            splat_image(&setup(s, &field, Shading::Pre), &field, &s.transfer).expect("CPU twin");
        let diff = max_diff(&gpu, &cpu.pixels);
        let (c, k) = (report.counts, cpu.counts);
        eprintln!(
            "left out {} of {} ({} culled empty by the twin): {diff:.2e}",
            c.left_out, c.projected, k.culled_empty
        );
        assert!(diff < GPU_TOLERANCE, "GPU vs CPU {diff:.3e}");
        assert_eq!(
            (c.projected, c.culled_empty, c.kept()),
            (k.projected, k.culled_empty, k.kept())
        );
        assert!(
            c.left_out > c.projected / 4 && c.left_out <= k.culled_empty,
            "{c:?}"
        );
        frames.push((gpu, c.left_out));
    }
    assert_ne!(
        frames[0].1, frames[1].1,
        "the two functions leave out other kernels"
    );
    assert_eq!(frames[0], frames[2], "the first function's frame again");
    drop(renderer);
    finish(ctx);
}

#[test]
fn negative_data_and_oversized_kernels() {
    // Post-shaded weights carry the data's sign: a field of −0.6 is classified at −0.6, not
    // dropped (a transfer function opaque only for negative values shows it).
    let volume = volume_from([9; 3], [0.25; 3], [-1.0; 3], |_| -0.6);
    let s = scene(&[
        "render.method=\"splat-post\"",
        "transfer.points=[[-1.0,1.0,0.2,0.2,8.0],[0.0,0.0,0.0,0.0,0.0]]",
        "camera.width=16",
        "camera.height=16",
    ]);
    let field = grid_field(volume, &s);
    let image =
        splat_image(&setup(&s, &field, Shading::Post), &field, &s.transfer).expect("CPU twin");
    let centre = image.pixels[8 * 16 + 8];
    assert!(
        centre[3] > 0.5 && centre[0] > 0.3,
        "negative field lost: {centre:?}"
    );

    // A kernel filling a 2048² image across hundreds of sheets would need more entries than
    // one invocation may write: culled as oversized, which fails the frame on the GPU.
    let big = scene(&[
        "camera.width=2048",
        "camera.height=2048",
        "splat.slab=0.05",
        "splat.split=true",
        "camera.eye=[0.0,-1.2,0.0]",
    ]);
    let field = big.field(|_| {}).expect("field");
    let setup = setup(&big, &field, Shading::Pre);
    let k = Kernel {
        position: [0.0, 0.0, 0.0],
        value: 0.5,
        metric: rotated_metric([0.5; 3], 0.0),
        volume: 1e-3,
        kind: KernelKind::Volume,
    };
    assert_eq!(
        splat_project(&setup, &big.transfer, &k),
        Err(Cull::Oversized)
    );
}

/// A 64² post-shaded frame of Marschner–Lobb 41³ in sheets of 1/16 spacing gives each 8² tile
/// of the volume's middle tens of thousands of (tile, sheet) entries and 1223 sheets to walk,
/// past the 65 535 loop iterations llvmpipe allows an invocation in a dispatch: the walk was
/// cut short there and the frame came back wrong by up to 0.75 against its CPU twin (p99 of
/// 0.85), then was refused. Its bands now run in passes, each continuing the walks the one
/// before left (`splat::plan::RasterWalk`). At 128² (still 51 walks past one dispatch, and
/// every bucket in kernel order, so that frames are reproducible to the bit) the frame is the
/// same to the bit in passes of a sixth of the default, and its CPU twin's within 1e-3
/// (measured 3.5e-4: f32 sums over 1223 sheets, where the other tests' frames have tens).
#[test]
fn tile_walks_past_the_loop_limit_continue_in_later_passes() {
    let (ctx, _compiler) = gpu();
    let at = |size: u32| {
        Scene::load(
            None,
            &[
                "render.method=\"splat-post\"".to_string(),
                "splat.slab=0.0625".to_string(),
                // EWA's low-pass widens every footprint by a pixel, which puts enough entries
                // in the middle tiles at 128² (the auto low-pass leaves them under the limit).
                "splat.antialias=\"ewa\"".to_string(),
                format!("camera.width={size}"),
                format!("camera.height={size}"),
                "render.early_termination=0.9999".to_string(),
            ],
        )
        .expect("scene")
    };
    let (small, s) = (at(64), at(128));
    let field = s.field(|_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    let (image, report) = gpu_frame(&mut renderer, &small);
    assert!(report.counts.resumed > 0, "64²: {:?}", report.counts);
    assert!(image.iter().any(|p| p[3] > 0.5));
    let (gpu, report) = gpu_frame(&mut renderer, &s);
    let c = report.counts;
    assert!(c.resumed > 0 && c.unordered == 0, "{c:?}");
    renderer.set_splat_raster_chunk(Some(8_000));
    let (split, more) = gpu_frame(&mut renderer, &s);
    assert!(more.counts.resumed > c.resumed, "{:?}", more.counts);
    let differ = differing(&gpu, &split);
    let cpu = splat_image(&setup(&s, &field, Shading::Post), &field, &s.transfer).expect("CPU");
    let diff = max_diff(&gpu, &cpu.pixels);
    eprintln!(
        "{} and {} walks resumed, {differ} pixels differ; GPU vs CPU {diff:.2e}",
        c.resumed, more.counts.resumed
    );
    assert_eq!(differ, 0, "passes of 8 000 change {differ} pixels");
    assert!(diff < 1e-3, "GPU vs CPU {diff:.3e}");
    assert!(gpu.iter().any(|p| p[3] > 0.5));
    drop(renderer);
    finish(ctx);
}

/// The variants of `splat_raster`'s tile loop: pre-shaded with each subgroup stopping by
/// itself, surface splats, post-shaded with its ring, with isosurfaces and their
/// workgroup-wide exchange, and without occlusion.
const ISO: &str = "transfer.isosurfaces=[{value=0.5, color=[1.0,0.8,0.3], opacity=0.9}]";
const RASTER_VARIANTS: [(&str, &[&str]); 5] = [
    (
        "pre-shaded",
        &["render.method=\"splat\"", "splat.split=true"],
    ),
    (
        "pre-shaded surface splats",
        &["render.method=\"splat\"", "splat.surface=true", ISO],
    ),
    ("post-shaded", &["render.method=\"splat-post\""]),
    (
        "post-shaded isosurface",
        &["render.method=\"splat-post\"", ISO],
    ),
    (
        "post-shaded, erfc, no occlusion",
        &[
            "render.method=\"splat-post\"",
            "splat.sheet_share=\"erfc\"",
            "splat.occlusion=false",
        ],
    ),
];

/// The largest difference of any channel between two images.
fn max_abs_diff(a: &[[f32; 4]], b: &[[f32; 4]]) -> f32 {
    a.iter()
        .zip(b)
        .flat_map(|(p, q)| (0..4).map(move |c| (p[c] - q[c]).abs()))
        .fold(0.0f32, f32::max)
}

/// Pixels of two images that differ (a difference of any size).
fn differing(a: &[[f32; 4]], b: &[[f32; 4]]) -> usize {
    a.iter().zip(b).filter(|(p, q)| p != q).count()
}

/// Splitting the walks among passes changes nothing in the image: the registers a pass leaves
/// are the next one's to the bit, wherever the cut falls (inside a sheet or between sheets).
/// Each variant of the tile loop is rendered whole and in walks of a few hundred loop
/// iterations.
#[test]
fn walks_split_among_passes_give_the_same_image_to_the_bit() {
    let (ctx, _) = gpu();
    let field = scene(&[]).field(|_| {}).expect("field");
    let mut whole = Renderer::new(&ctx, field.clone()).expect("renderer");
    let mut split = Renderer::new(&ctx, field.clone()).expect("renderer");
    for (name, extra) in RASTER_VARIANTS {
        let s = scene(extra);
        let shading = s.render.method.splat_shading().expect("a splat method");
        let frame_setup = setup(&s, &field, shading);
        let walk =
            vmls::splat::plan::RasterWalk::new(&frame_setup, s.transfer.to_gpu().len() as u32)
                .expect("walk");
        split.set_splat_raster_chunk(Some(3 * walk.sheet_cost + 200));
        let (a, ra) = gpu_frame(&mut whole, &s);
        let (b, rb) = gpu_frame(&mut split, &s);
        assert_eq!(ra.counts.resumed, 0, "{name}");
        assert!(rb.counts.resumed > 0, "{name}: nothing was split");
        let differ = differing(&a, &b);
        eprintln!(
            "{name}: {} walks resumed, {differ} pixels differ",
            rb.counts.resumed
        );
        assert_eq!(differ, 0, "{name}: {differ} pixels differ");
        assert_eq!(
            (ra.counts.evaluated, ra.counts.contributions),
            (rb.counts.evaluated, rb.counts.contributions),
            "{name}: footprints"
        );
        assert!(a.iter().any(|p| p[3] > 0.2), "{name}: empty image");
    }
    drop((whole, split));
    finish(ctx);
}

/// The dispatch shape a GPU gets (`SplatSetup::fit_device`: whole-image bands, one pixel per
/// invocation) and any other (`splat.band_rows`, `splat.pixels`) keep the image, as does
/// lavapipe's pre-shaded eight pixels against four. Bands are
/// only dispatches of one compiled kernel: the image is the same to the bit in bands of
/// three of the four tile rows (the last one short) as in lavapipe's two. Pixels per
/// invocation compile another variant, whose arithmetic the compiler may contract into fused
/// multiply-adds differently: within 4e-6 (measured: 1.1e-6 on 774 of the post-shaded
/// quadrature frame's pixels at one pixel an invocation, the other variants equal to the bit).
/// The choice itself: a GPU widens the bands to 4 096 tiles and takes one pixel, a CPU device
/// keeps its shape (eight pixels pre-shaded, four post-shaded), and keys set in the scene win
/// on both.
#[test]
fn the_raster_dispatch_shape_changes_no_pixel() {
    let field = scene(&[]).field(|_| {}).expect("field");
    let shaded = |extra: &[&str], cpu: bool, shading: Shading| {
        let mut st = setup(&scene(extra), &field, shading);
        st.fit_device(cpu);
        (st.band_rows, st.raster_pixels())
    };
    let fitted = |extra: &[&str], cpu: bool| shaded(extra, cpu, Shading::Post);
    assert_eq!(fitted(&[], true), (2, 4));
    assert_eq!(shaded(&[], true, Shading::Pre), (2, 8));
    assert_eq!(shaded(&[], false, Shading::Pre), (4, 2));
    assert_eq!(
        fitted(&[], false),
        (4, 1),
        "40×32: every one of the 4 tile rows"
    );
    let big = ["camera.width=2048", "camera.height=2048"];
    assert_eq!(fitted(&big, false), (16, 1), "256 tiles a row: 4 096 / 256");
    let set = ["splat.band_rows=3", "splat.pixels=2"];
    assert_eq!(fitted(&set, false), (3, 2));
    assert_eq!(fitted(&set, true), (3, 2));

    let (ctx, _) = gpu();
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    for (name, extra) in RASTER_VARIANTS {
        let (a, _) = gpu_frame(&mut renderer, &scene(extra));
        assert!(a.iter().any(|p| p[3] > 0.2), "{name}: empty image");
        let shapes: [(&[&str], f32); 6] = [
            (&["splat.band_rows=3"], 0.0),
            (&["splat.branches=true"], 4e-6),
            (&["splat.band_rows=4", "splat.pixels=1"], 4e-6),
            (&set, 4e-6),
            (&["splat.pixels=4"], 4e-6),
            (&["splat.pixels=8"], 4e-6),
        ];
        for (shape, bound) in shapes {
            let (b, _) = gpu_frame(&mut renderer, &scene(&[extra, shape].concat()));
            let diff = max_abs_diff(&a, &b);
            eprintln!(
                "{name}, {shape:?}: {} pixels differ, by {diff:.2e}",
                differing(&a, &b)
            );
            assert!(diff <= bound, "{name}, {shape:?}: {diff:.3e} > {bound:.0e}");
        }
    }
    drop(renderer);
    finish(ctx);
}

/// Post-shaded branches (a GPU's default, `splat.branches`) skip only exact zeros: a pixel
/// outside a kernel's footprint skips its sheet shares, and an interval half whose table
/// entries are all zero by the table's occupied bins skips its two lookups. With a transfer
/// function transparent below 0.35 and above 0.65 (most halves in this field are clear), every
/// post-shaded variant renders the same image with and without them within f32 rounding, the
/// bound of other compiled variants: on lavapipe the footprint's early return changes how the
/// ring's multiply-adds are fused (471 pixels by up to 1.7e-6 measured; the table skip alone
/// was equal to the bit in all four variants). The lookups' skip fires (its counter) with
/// branches and never without. The fit takes them on a GPU only, post-shaded only, and the
/// table's skip only where some lookup can be clear.
#[test]
fn post_shaded_branches_change_no_pixel() {
    let band = "transfer.points=[[0.0,0.2,0.5,1.0,0.0],[0.35,0.2,0.5,1.0,0.0],[0.5,1.0,0.5,0.2,5.0],\
                [0.65,1.0,0.5,0.2,0.0],[1.0,1.0,1.0,1.0,0.0]]";
    let field = scene(&[]).field(|_| {}).expect("field");
    // (A ring of 16 sheets set: the 13³ grid at 40×32 would take another.)
    let fitted = |extra: &[&str], shading: Shading, cpu: bool| {
        let ring: &[&str] = if shading == Shading::Post {
            &["splat.ring=16"]
        } else {
            &[]
        };
        let s = scene(&[ring, extra].concat());
        let mut st = setup(&s, &field, shading);
        st.fit_device(cpu);
        st.fit_transfer(&field, &s.transfer);
        (st.branches, st.clear_skip)
    };
    assert_eq!(fitted(&[band], Shading::Post, false), (true, true));
    let ring8 = ["splat.ring=8", band];
    assert_eq!(
        fitted(&ring8, Shading::Post, false),
        (false, true),
        "ring 8: no early return"
    );
    assert_eq!(fitted(&[band], Shading::Post, true), (false, false));
    assert_eq!(fitted(&[band], Shading::Pre, false), (false, false));
    let constant = ["splat.interval=\"constant\"", band];
    assert_eq!(
        fitted(&constant, Shading::Post, false),
        (true, false),
        "no table"
    );
    let opaque = "transfer.points=[[0.0,0.1,0.2,0.6,0.5],[1.0,1.0,0.3,0.1,4.0]]";
    assert_eq!(
        fitted(&[opaque], Shading::Post, false),
        (true, false),
        "extinction everywhere: no lookup is ever clear"
    );
    let forced = ["splat.branches=true", "splat.ring=8", band];
    assert_eq!(
        fitted(&forced, Shading::Post, true),
        (true, true),
        "set on lavapipe"
    );

    let (ctx, _) = gpu();
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    let variants: [&[&str]; 4] = [
        &[],
        &["splat.interval=\"linear\""],
        &["splat.sheet_share=\"erfc\"", "splat.occlusion=false"],
        &[ISO],
    ];
    for extra in variants {
        let base = [&["render.method=\"splat-post\"", band][..], extra].concat();
        let (a, ra) = gpu_frame(&mut renderer, &scene(&base));
        assert!(a.iter().any(|p| p[3] > 0.1), "{extra:?}: empty image");
        let (b, rb) = gpu_frame(
            &mut renderer,
            &scene(&[&base[..], &["splat.branches=true"]].concat()),
        );
        // The lookups' skip fired, and only with branches.
        assert_eq!(ra.counts.clear_skipped, 0, "{extra:?}");
        assert!(rb.counts.clear_skipped > 0, "{extra:?}: no half skipped");
        eprintln!("{extra:?}: {} halves skipped", rb.counts.clear_skipped);
        let diff = max_abs_diff(&a, &b);
        eprintln!(
            "{extra:?}: {} pixels differ, by {diff:.2e}",
            differing(&a, &b)
        );
        assert!(
            diff <= 4e-6,
            "{extra:?}: branches changed pixels by {diff:.3e}"
        );
    }
    drop(renderer);
    finish(ctx);
}

/// A post-shaded walk stops where every pixel of its subgroup has left the domain (pixel_live):
/// under a transfer function too faint for any pixel to reach the early termination, the
/// frame with occlusion on (which stops there) equals the one with it off (which walks every
/// sheet) to the bit, and the walks skipped entries past the box's exit, which they did not
/// before; a pixel whose ray misses the box is done from the start.
#[test]
fn post_shaded_walks_stop_past_the_domain_exit() {
    let faint = "transfer.points=[[0.0,0.2,0.5,1.0,0.0],[1.0,1.0,0.5,0.2,0.4]]";
    let field = scene(&[]).field(|_| {}).expect("field");
    let (ctx, _) = gpu();
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    for extra in [&[][..], &["splat.interval=\"constant\""][..]] {
        let base = [&["render.method=\"splat-post\"", faint][..], extra].concat();
        let (on, r_on) = gpu_frame(&mut renderer, &scene(&base));
        let (off, r_off) = gpu_frame(
            &mut renderer,
            &scene(&[&base[..], &["splat.occlusion=false"]].concat()),
        );
        let alpha = on.iter().map(|p| p[3]).fold(0.0f32, f32::max);
        assert!(
            alpha > 0.05 && alpha < 0.9,
            "{extra:?}: the premise, largest alpha {alpha}"
        );
        assert_eq!(
            differing(&on, &off),
            0,
            "{extra:?}: the stop changed pixels"
        );
        assert_eq!(r_off.counts.skipped_occluded, 0, "{extra:?}");
        assert!(
            r_on.counts.skipped_occluded > 0,
            "{extra:?}: no walk stopped past the exit"
        );
        eprintln!(
            "{extra:?}: {} of {} entries skipped past the exit",
            r_on.counts.skipped_occluded, r_on.counts.entries
        );
    }
    drop(renderer);
    finish(ctx);
}

/// Frames of one camera rendered again are the same to the bit: splat_bin's atomic cursors fill
/// a (tile, sheet) bucket in whatever order lavapipe's threads reach it, and splat_order puts
/// each bucket in kernel order (the CPU twin's), so every run sums each sheet in one order.
/// Both scenes differed between runs before splat_order (measured: 42 pixels of the first, about
/// 48 of the second, by up to 1.5e-6); the second's central buckets hold up to 612 entries
/// (heapsorted by the second pass), the others take the first pass's insertion sort.
#[test]
fn splatting_frames_are_the_same_to_the_bit_on_every_run() {
    let (ctx, _) = gpu();
    let pre = [
        "volume.resolution=41",
        "camera.width=96",
        "camera.height=96",
        "render.method=\"splat\"",
    ];
    let post = [
        "volume.resolution=17",
        "camera.width=40",
        "camera.height=24",
        "render.method=\"splat-post\"",
    ];
    // Kernels of 8 spacings' support in sheets of 4: 6.7 M entries, about 20 000 buckets of
    // 65 to a few hundred entries, all for the second pass (whose fixed grid of 1 024
    // invocations, before, ran out of loop iterations and left 13 339 of them unordered).
    let large_kernels = [
        "volume.resolution=17",
        "camera.width=512",
        "camera.height=512",
        "render.method=\"splat\"",
        "reconstruction.support=8",
        "splat.slab=4",
    ];
    let general = |o: &[&str]| general_scene(&o.iter().map(|s| s.to_string()).collect::<Vec<_>>());
    let mut large = Vec::new();
    for (name, s, runs) in [
        ("pre-shaded, Marschner–Lobb 41³ at 96²", scene(&pre), 5),
        ("post-shaded, 17³ at 40 × 24", general(&post), 5),
        (
            "pre-shaded, 17³ of support 8 at 512²",
            general(&large_kernels),
            2,
        ),
    ] {
        let field = s.field(|_| {}).expect("field");
        let mut renderer = Renderer::new(&ctx, field).expect("renderer");
        let (first, report) = gpu_frame(&mut renderer, &s);
        assert_eq!(report.counts.unordered, 0, "{name}: buckets left unordered");
        large.push(report.counts.large_buckets);
        for run in 1..runs {
            let (again, _) = gpu_frame(&mut renderer, &s);
            let differ = first.iter().zip(&again).filter(|(a, b)| a != b).count();
            assert_eq!(
                differ, 0,
                "{name}, run {run}: {differ} pixels differ from run 0"
            );
        }
    }

    // The post-shaded scene's largest buckets went to the second pass, its heapsort, and the
    // third scene's many.
    assert!(large[1] > 0, "no bucket was heapsorted: {large:?}");
    assert!(large[2] > 10_000, "too few buckets heapsorted: {large:?}");

    // One 8 × 8 tile and sheets 400 spacings thick: 4 913 whole kernels in one or two
    // buckets, past what splat_order can sort within llvmpipe's loop limit. Those buckets are
    // left as splat_bin filled them and counted; the image is still the CPU twin's.
    let s = general(&[
        "volume.resolution=17",
        "camera.width=8",
        "camera.height=8",
        "render.method=\"splat\"",
        "splat.slab=400",
    ]);
    let field = s.field(|_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    let (gpu, report) = gpu_frame(&mut renderer, &s);
    let c = report.counts;
    assert!(c.entries > 4000, "{} entries", c.entries);
    assert!(c.unordered >= 1, "no bucket was too large to sort: {c:?}");
    let cpu = splat_image(&setup(&s, &field, Shading::Pre), &field, &s.transfer).expect("CPU twin");
    let diff = max_diff(&gpu, &cpu.pixels);
    assert!(
        diff < GPU_TOLERANCE,
        "unordered buckets: GPU vs CPU {diff:.3e}"
    );
    drop(renderer);
    finish(ctx);
}

/// The kernels for devices without subgroup operations (a workgroup-wide vote through shared
/// memory and barriers, counters summed in shared memory), compiled and run on this device:
/// the same image as the subgroup variant's, whole and in passes. (The vote's slot now follows
/// the sheet loop's trips: by sheet index, a pre-shaded walk that jumps over empty sheets could
/// set a slot that lane 0 was still clearing. That race does not show on lavapipe, whose
/// subgroups run one after another between barriers: this test passes either way.)
#[test]
fn the_variant_without_subgroup_operations_draws_the_same_image() {
    use vmls::raycast::frame::table_buffer;
    use vmls::splat::frame::{FrameControl, splat_frame};
    use vmls::splat::gpu::{GpuKernels, SplatPipelines, SplatTargets, SplatVariant};
    use vmls::view::preintegration::PreintegrationTables;
    let (ctx, compiler) = gpu();
    let field = scene(&[]).field(|_| {}).expect("field");
    let kernels = GpuKernels::upload(&ctx, &field, &[], Vec::new(), None).expect("kernels");
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    for (name, extra) in [
        (
            "pre-shaded",
            &["render.method=\"splat\"", "splat.split=true"][..],
        ),
        ("post-shaded", &["render.method=\"splat-post\""][..]),
    ] {
        let s = scene(extra);
        let shading = s.render.method.splat_shading().expect("a splat method");
        let mut frame_setup = setup(&s, &field, shading);
        let (want, _) = gpu_frame(&mut renderer, &s);
        let mut variant = SplatVariant::of(&frame_setup, ctx.info());
        assert!(variant.subgroup_ops, "lavapipe has subgroup operations");
        variant.subgroup_ops = false;
        let pipelines = SplatPipelines::new(&ctx, &compiler, &variant).expect("pipelines");
        let mut targets = SplatTargets::new(&ctx, &frame_setup, &kernels).expect("targets");
        // Post-shaded intervals read the preintegration table (built as the renderer does).
        let lengths = frame_setup.table_lengths();
        let tables = (!lengths.is_empty()).then(|| {
            PreintegrationTables::build(
                &s.transfer,
                frame_setup.table_range(&field, &s.transfer),
                &lengths,
                frame_setup.table_resolution,
                |_| {},
            )
        });
        let table = tables
            .as_ref()
            .map(|t| table_buffer(&ctx, t).expect("table buffer"));
        for chunk in [None, Some(300)] {
            frame_setup.raster_chunk = chunk;
            let image = splat_frame(
                &ctx,
                &pipelines,
                &kernels,
                &mut targets,
                &frame_setup,
                &s.transfer,
                tables.as_ref().zip(table.as_ref()),
                &[],
                FrameControl {
                    budget: None,
                    stop: None,
                    progress: &mut |_| {},
                },
            )
            .expect("frame");
            assert_eq!(chunk.is_some(), image.counts.resumed > 0, "{name}");
            let differ = want
                .iter()
                .zip(&image.pixels)
                .filter(|(p, q)| p != q)
                .count();
            assert_eq!(differ, 0, "{name}, chunk {chunk:?}: {differ} pixels differ");
        }
    }
    drop((renderer, kernels));
    finish(ctx);
}
