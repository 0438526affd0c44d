//! `splat_raster`'s tile walk on the GPU: walks that pass llvmpipe's loop limit and continue
//! in later passes, the walk split among passes, the dispatch shapes and variants (pixels per
//! invocation, bands, a GPU's branches around exact zeros, no subgroup operations), walks that
//! stop past the domain's exit, and frames the same to the bit on every run.
mod common;

use common::splat::*;
use common::*;
use vmls::renderer::Renderer;
use vmls::scene::Scene;
use vmls::splat::raster::splat_image;
use vmls::splat::{Prefetch, Shading};

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
/// iterations, and split again with the walk loading the next entry, and also its record, one
/// step ahead (`splat.prefetch`: the same loads reordered, reloaded where a pass resumes),
/// which changes nothing either.
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
        for prefetch in ["splat.prefetch=\"list\"", "splat.prefetch=\"records\""] {
            let (c, rc) = gpu_frame(&mut split, &scene(&[extra, &[prefetch]].concat()));
            assert!(
                rc.counts.resumed > 0,
                "{name}, {prefetch}: nothing was split"
            );
            let differ = differing(&a, &c);
            assert_eq!(differ, 0, "{name}, {prefetch}: {differ} pixels differ");
        }
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
        let shapes: [(&[&str], f32); 7] = [
            (&["splat.band_rows=3"], 0.0),
            (
                &[
                    "splat.prefetch=\"records\"",
                    "splat.band_rows=4",
                    "splat.pixels=1",
                ],
                4e-6,
            ),
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
/// table's skip only where some lookup can be clear. The skip of lookups outside the domain
/// (a GPU's default where the domain is a hull) is part of the same branches: the box's
/// outside here, equal within the same bound.
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
    // A GPU skips the lookups outside the domain where it is a mesh's hull, and its walk loads
    // the next entry ahead with rings of 16 sheets, the record too otherwise; lavapipe neither,
    // and keys set win.
    let more = |extra: &[&str], shading: Shading, cpu: bool, hull: bool| {
        let mut st = setup(&scene(extra), &field, shading);
        st.hull = hull;
        st.fit_device(cpu);
        (st.outside_skip, st.prefetch)
    };
    let (ring16, ring8) = (["splat.ring=16"], ["splat.ring=8"]);
    assert_eq!(
        more(&ring16, Shading::Post, false, false),
        (false, Prefetch::List)
    );
    assert_eq!(
        more(&ring8, Shading::Post, false, true),
        (true, Prefetch::Records)
    );
    assert_eq!(
        more(&[], Shading::Pre, false, true),
        (false, Prefetch::Records)
    );
    let constant = ["splat.ring=8", "splat.interval=\"constant\""];
    assert_eq!(
        more(&constant, Shading::Post, false, true),
        (false, Prefetch::Records),
        "no halves to skip without intervals"
    );
    assert_eq!(
        more(&ring8, Shading::Post, true, true),
        (false, Prefetch::None)
    );
    let set = [
        "splat.branches=false",
        "splat.prefetch=\"none\"",
        "splat.ring=8",
    ];
    assert_eq!(
        more(&set, Shading::Post, false, true),
        (false, Prefetch::None)
    );
    let set = [
        "splat.branches=true",
        "splat.prefetch=\"records\"",
        "splat.ring=8",
    ];
    assert_eq!(
        more(&set, Shading::Post, true, false),
        (true, Prefetch::Records)
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
