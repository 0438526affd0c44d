//! EWA splatting: GPU kernels against their f64 CPU twins, convergence of post-shaded sheets
//! to the ray-cast Gaussian-sum field as the sheets thin and crisp post-shaded edges. One
//! kernel's footprint: tests/splat_footprint.rs; the antialiasing comparison of [EWA]:
//! tests/splat_antialias.rs; hard cases: tests/splat_cases.rs; the tile walk's passes, shapes
//! and variants: tests/splat_raster.rs.
mod common;

use common::splat::*;
use common::*;
use vmls::renderer::Renderer;
use vmls::splat::footprint::{sheet_share, splat_profile};
use vmls::splat::project::KernelKind;
use vmls::splat::project::{Kernel, splat_project};
use vmls::splat::raster::splat_image;
use vmls::splat::{QUADRATURE_MAX_SHEET, RINGS, SCAN_BLOCK, Shading, SheetShare, choose_ring};
use vmls::view::camera::Projection;

#[test]
fn gpu_splatting_matches_its_cpu_twin_on_a_grid() {
    let (ctx, _) = gpu();
    // The default low-pass is auto; at 40×32 the footprints' minor variances span 0.65–2.5 px²
    // (anisotropy up to 1.12), so its three regimes (both axes raised, one, none) all run.
    let cases: [(&str, &[&str]); 19] = [
        (
            "pre-shaded, EWA's resampling filter",
            &["render.method=\"splat\"", "splat.antialias=\"ewa\""],
        ),
        (
            "post-shaded, constant sheets (no table)",
            &[
                "render.method=\"splat-post\"",
                "splat.interval=\"constant\"",
            ],
        ),
        (
            "post-shaded, linear intervals, 4-sheet ring",
            &[
                "render.method=\"splat-post\"",
                "splat.interval=\"linear\"",
                "splat.ring=4",
            ],
        ),
        (
            "pre-shaded, thin sheets (buckets over several scan blocks)",
            &["render.method=\"splat\"", "splat.slab=0.004"],
        ),
        (
            "pre-shaded surface splats",
            &[
                "render.method=\"splat\"",
                "splat.surface=true",
                "transfer.isosurfaces=[{value=0.5, color=[1.0,0.8,0.3], opacity=0.9}]",
            ],
        ),
        ("pre-shaded", &["render.method=\"splat\""]),
        ("post-shaded", &["render.method=\"splat-post\""]),
        (
            "post-shaded, erfc sheet shares",
            &["render.method=\"splat-post\"", "splat.sheet_share=\"erfc\""],
        ),
        (
            "post-shaded, quadrature, 4-sheet ring",
            &[
                "render.method=\"splat-post\"",
                "splat.sheet_share=\"quadrature\"",
                "splat.ring=4",
            ],
        ),
        (
            "post-shaded, quadrature widening kernels thinner than the sheets",
            &[
                "render.method=\"splat-post\"",
                "splat.sheet_share=\"quadrature\"",
                "splat.slab=4.0",
            ],
        ),
        (
            "post-shaded, midpoint, 4-sheet ring",
            &[
                "render.method=\"splat-post\"",
                "splat.sheet_share=\"midpoint\"",
                "splat.ring=4",
            ],
        ),
        (
            "post-shaded, midpoint, 16-sheet ring",
            &[
                "render.method=\"splat-post\"",
                "splat.sheet_share=\"midpoint\"",
                "splat.ring=16",
            ],
        ),
        (
            "post-shaded, midpoint widening kernels thinner than the sheets",
            &[
                "render.method=\"splat-post\"",
                "splat.sheet_share=\"midpoint\"",
                "splat.slab=4.0",
            ],
        ),
        (
            "post-shaded, erfc, 8-sheet ring",
            &[
                "render.method=\"splat-post\"",
                "splat.sheet_share=\"erfc\"",
                "splat.ring=8",
            ],
        ),
        (
            "post-shaded, isosurface, orthographic",
            &[
                "render.method=\"splat-post\"",
                "transfer.isosurfaces=[{value=0.5, color=[1.0,0.8,0.3], opacity=0.9}]",
                "camera.projection=\"orthographic\"",
                "camera.view_height=2.4",
                "splat.antialias=\"ewa\"",
            ],
        ),
        (
            "post-shaded, affine footprints",
            // EWA's low-pass here and in the case above: under auto, footprints narrower than
            // the low-pass become exactly 1 px² and their cutoff boxes end on pixel centres
            // (f32 and f64 disagree on including them), and the orthographic view (where auto
            // leaves the footprints as they are) has a pixel at the early-termination
            // threshold; both measured 2.3-2.6e-5, flips at a threshold, not kernel errors.
            &[
                "render.method=\"splat-post\"",
                "splat.footprint=\"affine\"",
                "splat.antialias=\"ewa\"",
            ],
        ),
        (
            "pre-shaded, kernels split among sheets, 16-pixel tiles",
            &[
                "render.method=\"splat\"",
                "splat.split=true",
                "splat.tile=16",
            ],
        ),
        (
            "post-shaded, 32-pixel tiles, no occlusion",
            &[
                "render.method=\"splat-post\"",
                "splat.tile=32",
                "splat.occlusion=false",
            ],
        ),
        (
            "pre-shaded swan, no occlusion",
            &[
                "render.method=\"splat\"",
                "splat.antialias=\"swan\"",
                "splat.occlusion=false",
            ],
        ),
    ];
    let field = scene(&[]).field(|_| {}).expect("field");
    let mut renderer = Renderer::new(&ctx, field.clone()).expect("renderer");
    for (name, extra) in cases {
        // Early termination is a threshold: a pixel at opacity 0.99 ± 1e-7 stops on one side and
        // not on the other, and then differs by up to 1% of what lies behind. At 0.9999 that
        // jump stays below 1e-4 and the occlusion map still culls.
        let mut extra = extra.to_vec();
        extra.push("render.early_termination=0.9999");
        let s = scene(&extra);
        let shading = s.render.method.splat_shading().expect("a splat method");
        let frame_setup = setup(&s, &field, shading);
        assert_eq!(
            frame_setup.widen,
            name.contains("widening"),
            "{name}: kernels widened"
        );
        if name.starts_with("pre-shaded, thin sheets") {
            // The scan's second level (block sums) only runs with more than one block.
            let blocks = frame_setup.buckets().div_ceil(u64::from(SCAN_BLOCK));
            assert!(blocks >= 3, "{name}: {blocks} scan blocks");
        }
        let cpu = splat_image(&frame_setup, &field, &s.transfer).expect("CPU twin");
        let (gpu, report) = gpu_frame(&mut renderer, &s);
        let diff = max_diff(&gpu, &cpu.pixels);
        eprintln!("GPU vs CPU, {name}: {diff:.2e}");
        assert!(diff < GPU_TOLERANCE, "{name}: GPU vs CPU {diff:.3e}");
        let c = report.counts;
        let k = cpu.counts;
        assert_eq!(
            (c.projected, c.culled_near, c.culled_empty, c.entries),
            (k.projected, k.culled_near, k.culled_empty, k.entries),
            "{name}: counters"
        );
        // Pre-shaded, the GPU leaves transparent volume kernels out before projection: some
        // of those the twin culls as empty, never more (the rest are surface splats, zero
        // volumes or values at the transfer function's edges), and the image stays the twin's.
        assert!(c.left_out <= k.culled_empty, "{name}: {c:?}");
        if shading == Shading::Pre && k.culled_empty > 0 {
            assert!(
                c.left_out > 0,
                "{name}: none left out of {}",
                k.culled_empty
            );
        }
        // The work counters behind `vmls bench`'s ceiling shares: f32 and f64 may disagree on
        // a footprint's zero at its cutoff edge, and on a pixel's opacity at the threshold
        // (surface splats: 1.1% of updates measured).
        for (what, g, c) in [
            ("evaluated", c.evaluated, k.evaluated),
            ("contributions", c.contributions, k.contributions),
        ] {
            let rel = (g as f64 - c as f64).abs() / (c as f64).max(1.0);
            assert!(
                c > 0 && rel < 0.02,
                "{name}: {what} {g} on the GPU, {c} on the CPU"
            );
        }
        let opacity: f64 = cpu.pixels.iter().map(|p| p[3]).sum::<f64>() / cpu.pixels.len() as f64;
        assert!(opacity > 0.05, "{name}: the image is empty ({opacity})");
    }
    drop(renderer);
    finish(ctx);
}

#[test]
fn the_quadrature_sheet_share_keeps_its_bound_and_widens_thinner_kernels() {
    // Against the erfc (1.5e-7) at every sheet position: within 1.5e-4 of the kernel's
    // integral up to QUADRATURE_MAX_SHEET deviations, and far off beyond it.
    let worst = |h: f64| {
        (0..2000)
            .map(|i| {
                let za = -7.0 + 0.007 * f64::from(i);
                (sheet_share(SheetShare::Quadrature, za, za + h)
                    - sheet_share(SheetShare::Erfc, za, za + h))
                .abs()
            })
            .fold(0.0, f64::max)
    };
    for h in [0.25, 0.5, 1.0, QUADRATURE_MAX_SHEET] {
        assert!(
            worst(h) < 1.5e-4,
            "sheets {h} deviations thick: {:.3e}",
            worst(h)
        );
    }
    assert!(worst(3.0) > 1e-3, "{:.3e}", worst(3.0));
    // Unset, post-shaded splatting takes the quadrature where at most WIDEN_MAX_SHARE of the
    // kernels are thinner than it serves (on this grid: none or all), and the erfc where more
    // are; pre-shaded splits always take the erfc. Asked for, the quadrature widens the thinner
    // kernels.
    let field = scene(&[]).field(|_| {}).expect("field");
    let rule = |extra: &[&str], shading| {
        let s = setup(&scene(extra), &field, shading);
        (s.sheet_share, s.widen)
    };
    assert_eq!(rule(&[], Shading::Post), (SheetShare::Midpoint, false));
    assert_eq!(
        rule(&["splat.slab=4.0"], Shading::Post),
        (SheetShare::Erfc, false)
    );
    assert_eq!(
        rule(
            &["splat.sheet_share=\"quadrature\"", "splat.slab=4.0"],
            Shading::Post
        ),
        (SheetShare::Quadrature, true)
    );
    assert_eq!(
        rule(&["splat.split=true"], Shading::Pre),
        (SheetShare::Erfc, false)
    );
    for (extra, shading, key) in [
        (
            &["splat.sheet_share=\"quadrature\"", "splat.split=true"][..],
            Shading::Pre,
            "splat.sheet_share",
        ),
        (&["splat.ring=8"][..], Shading::Pre, "splat.ring"),
    ] {
        let err = scene(extra)
            .splat_setup(shading, &field)
            .expect_err("refused");
        assert!(err.to_string().contains(key), "{err}");
    }
}

#[test]
fn the_midpoint_sheet_share_keeps_each_kernels_integral_and_widens_thinner_kernels() {
    // Summed over every sheet a kernel crosses, the midpoint shares give back its integral
    // within 3.2e-4 for sheets up to QUADRATURE_MAX_SHEET deviations thick, at any offset of
    // the sheets (Poisson summation: 2e^(-2 pi^2 / h^2) is 3.1e-4 at h = 1.5); thicker sheets
    // lose that (h = 3: about 0.09). Each share is the Gaussian at the sheet's middle, so it
    // departs from the sheet's exact share by the midpoint rule's error.
    let sum_error = |h: f64| {
        (0..200)
            .map(|i| {
                let offset = h * f64::from(i) / 200.0;
                let total: f64 = (-40..40)
                    .map(|k| {
                        let za = offset + f64::from(k) * h;
                        sheet_share(SheetShare::Midpoint, za, za + h)
                    })
                    .sum();
                (total - 1.0).abs()
            })
            .fold(0.0, f64::max)
    };
    for h in [0.25, 0.5, 1.0, QUADRATURE_MAX_SHEET] {
        assert!(
            sum_error(h) < 3.2e-4,
            "sheets {h} deviations thick: {:.3e}",
            sum_error(h)
        );
    }
    assert!(sum_error(3.0) > 1e-2, "{:.3e}", sum_error(3.0));
    let h = 0.5;
    let share = sheet_share(SheetShare::Midpoint, -0.25, 0.25);
    let exact = sheet_share(SheetShare::Erfc, -0.25, 0.25);
    assert!(
        (share - h / (2.0 * std::f64::consts::PI).sqrt()).abs() < 1e-15,
        "the central sheet's share {share}"
    );
    // The midpoint rule's bound, h³/24 · max|φ''| with max|φ''| = φ(0); and not exact.
    let bound = h * h * h / 24.0 / (2.0 * std::f64::consts::PI).sqrt();
    assert!(
        (share - exact).abs() < bound && (share - exact).abs() > 0.5 * bound,
        "{share} against {exact}"
    );
    // Asked for, the midpoint rule widens kernels thinner than it serves, like the quadrature,
    // and is refused for pre-shaded splits.
    let field = scene(&[]).field(|_| {}).expect("field");
    let s = setup(
        &scene(&["splat.sheet_share=\"midpoint\"", "splat.slab=4.0"]),
        &field,
        Shading::Post,
    );
    assert_eq!((s.sheet_share, s.widen), (SheetShare::Midpoint, true));
    let err = scene(&["splat.sheet_share=\"midpoint\"", "splat.split=true"])
        .splat_setup(Shading::Pre, &field)
        .expect_err("refused");
    assert!(err.to_string().contains("splat.sheet_share"), "{err}");
}

#[test]
fn the_ring_fits_the_kernels_spans() {
    // Spans of 2·r·sheets_per_radius + 1 sheets: 3 fit one 4-sheet entry; 7 one 8-sheet entry
    // (two 4-sheet ones cost more); 13 one 16-sheet entry (two 8-sheet ones cost more).
    assert_eq!(choose_ring(&[1.0], 1.0), 4);
    assert_eq!(choose_ring(&[1.0], 3.0), 8);
    assert_eq!(choose_ring(&[1.0], 6.0), 16);
    // Mixed supports: a few long spans do not make every entry long.
    let mut radii = vec![1.0; 60];
    radii.extend([8.0; 4]);
    assert_eq!(choose_ring(&radii, 1.0), 4);
    // The scene's default post-shaded setup takes one of them.
    let field = scene(&[]).field(|_| {}).expect("field");
    let ring = setup(&scene(&[]), &field, Shading::Post).ring;
    assert!(RINGS.contains(&ring), "{ring}");
}

/// The view of the sheet-convergence tests: no early termination, no low-pass (the
/// reference samples pixel centres), footprints to 4 deviations, a small image.
const CONVERGENCE_VIEW: [&str; 5] = [
    "render.early_termination=0.99999",
    "splat.antialias=\"none\"",
    "splat.cutoff=4.0",
    "camera.width=32",
    "camera.height=32",
];

#[test]
fn post_shaded_sheets_converge_to_the_ray_cast_gaussian_field() {
    let mut common = CONVERGENCE_VIEW.to_vec();
    common.push("splat.interval=\"constant\"");
    let field = scene(&["reconstruction.method=\"gaussian\""])
        .field(|_| {})
        .expect("field");
    let errors = sheet_convergence(&field, &common, &[1.0, 0.5, 0.25, 0.125]);
    eprintln!(
        "post-shaded RMSE against the ray-cast Gaussian field, by sheet thickness: {errors:?}"
    );
    // Measured on lavapipe: 8.5e-3, 2.2e-3, 6.5e-4, 2.3e-4: 2.9× to 3.9× per halving. Thinner sheets converge at about order 2: at
    // least half the error per halving.
    for w in errors.windows(2) {
        assert!(
            w[1].1 <= 0.5 * w[0].1,
            "error must halve as the sheets halve: {errors:?}"
        );
    }
    assert!(errors[3].1 < 1e-3, "finest sheets: {errors:?}");
}

#[test]
fn intervals_between_sheet_middles_beat_constant_sheets() {
    // A narrow, dense band of the transfer function (what preintegration is for): the
    // constant sheets' midpoint rule misses it between sheets.
    let mut common = CONVERGENCE_VIEW.to_vec();
    common.push(
        "transfer.points=[[0.0,0,0,0,0],[0.45,1.0,0.5,0.2,0.0],[0.5,1.0,0.5,0.2,12.0],[0.55,1.0,0.5,0.2,0.0],[1.0,0,0,0,0]]",
    );
    let field = scene(&["reconstruction.method=\"gaussian\""])
        .field(|_| {})
        .expect("field");
    let slabs = [1.0, 0.5];
    let by = |interval: &str| {
        let key = format!("splat.interval=\"{interval}\"");
        let mut extra = common.to_vec();
        extra.push(key.as_str());
        sheet_convergence(&field, &extra, &slabs)
    };
    let (constant, linear, hermite) = (by("constant"), by("linear"), by("hermite"));
    eprintln!(
        "post-shaded RMSE against the ray-cast Gaussian field at sheets {slabs:?}: constant \
         {constant:?}, linear {linear:?}, hermite {hermite:?}"
    );
    // Measured (CPU twin, f64): constant 7.0e-2, 1.9e-2; linear 4.3e-2, 9.4e-3; Hermite 3.1e-2,
    // 5.2e-3 at sheets of 1 and 0.5 spacings.
    for i in 0..slabs.len() {
        assert!(
            linear[i].1 < constant[i].1,
            "linear intervals must beat constant sheets: {linear:?} vs {constant:?}"
        );
        assert!(
            hermite[i].1 <= 0.5 * constant[i].1,
            "Hermite intervals must halve the constant sheets' error: {hermite:?} vs {constant:?}"
        );
    }
}

#[test]
fn the_intervals_table_covers_the_field_and_puts_zero_on_a_node() {
    let s = scene(&[
        "render.method=\"splat-post\"",
        "render.table_resolution=64",
        "transfer.points=[[-0.5,0,0,0,0],[0.5,1,1,1,2],[1.5,1,1,1,2]]",
    ]);
    let field = s.field(|_| {}).expect("field");
    let post = setup(&s, &field, Shading::Post);
    assert_eq!(post.table_lengths(), vec![0.5 * post.slab_world]);
    let (lo, hi) = post.table_range(&field, &s.transfer);
    let (data_lo, data_hi) = vmls::field::scalar_range(&field);
    assert!(
        lo <= data_lo.min(-0.5) && hi >= data_hi.max(1.5),
        "{lo} {hi}"
    );
    let node = -lo / (hi - lo) * 63.0;
    assert!((node - node.round()).abs() < 1e-9, "0 at node {node}");
    // Constant sheets need no table.
    let constant = scene(&[
        "render.method=\"splat-post\"",
        "splat.interval=\"constant\"",
    ]);
    assert!(
        setup(&constant, &field, Shading::Post)
            .table_lengths()
            .is_empty()
    );
}

/// Width in pixels over which opacity rises from 10% to 90% of its plateau along row `y`,
/// scanning from the left (the first rising edge).
fn edge_width(pixels: &[[f64; 4]], w: usize, y: usize) -> f64 {
    let row: Vec<f64> = (0..w).map(|x| pixels[y * w + x][3]).collect();
    let top = row.iter().copied().fold(0.0, f64::max);
    let cross = |level: f64| {
        let i = row.iter().position(|&a| a >= level * top).expect("edge");
        // Linear interpolation between the two pixels around the crossing.
        if i == 0 {
            return 0.0;
        }
        let (a, b) = (row[i - 1], row[i]);
        (i - 1) as f64 + (level * top - a) / (b - a)
    };
    cross(0.9) - cross(0.1)
}

#[test]
fn post_shaded_edges_are_crisper_than_pre_shaded() {
    // A cube of value 1 in a 21³ grid of zeros, seen face-on; an opaque step at 0.5.
    let volume = volume_from([21; 3], [0.1; 3], [-1.0; 3], |p| {
        if p.iter().all(|c| c.abs() < 0.5 + 1e-9) {
            1.0
        } else {
            0.0
        }
    });
    let s = scene(&[
        "camera.eye=[0.0,-4.0,0.0]",
        "camera.fov_y=40.0",
        "camera.width=64",
        "camera.height=64",
        "transfer.points=[[0.0,0.0,0.0,0.0,0.0],[0.45,0.0,0.0,0.0,0.0],[0.55,1.0,1.0,1.0,400.0],[1.0,1.0,1.0,1.0,400.0]]",
    ]);
    let field = grid_field(volume, &s);
    let mut widths = Vec::new();
    for shading in [Shading::Pre, Shading::Post] {
        let image =
            splat_image(&setup(&s, &field, shading), &field, &s.transfer).expect("CPU twin");
        widths.push(edge_width(&image.pixels, 64, 32));
    }
    eprintln!(
        "edge width 10–90% in pixels: pre-shaded {:.2}, post-shaded {:.2}",
        widths[0], widths[1]
    );
    assert!(
        widths[1] < 0.6 * widths[0],
        "post-shaded edge {:.2} px is not crisper than pre-shaded {:.2} px",
        widths[1],
        widths[0]
    );
}

#[test]
fn widened_kernels_keep_their_line_integrals() {
    // Sheets 3 spacings thick and the quadrature asked for: every kernel here is thinner along
    // the rays than it serves, so each is widened (SplatSetup::share_deviation). The sheets of a
    // kernel's entries must hold its widened profile: its shares through every pixel of its
    // footprint sum to its line integral there but for the tails beyond the cutoff. Entries
    // cut at the unwidened kernel's reach (no reach added in splat_project) kept 0.54 of it.
    let base = scene(&[
        "render.method=\"splat-post\"",
        "splat.sheet_share=\"quadrature\"",
        "splat.slab=3.0",
        "camera.width=128",
        "camera.height=128",
    ]);
    let field = base.field(|_| {}).expect("field");
    let metrics = [
        ("isotropic", rotated_metric([0.04; 3], 0.0)),
        ("flat 16:1", rotated_metric([0.16, 0.01, 0.05], 0.7)),
    ];
    let mut checked = 0;
    for projection in [
        Projection::Perspective {
            fov_y_degrees: 30.0,
        },
        Projection::Orthographic { view_height: 1.6 },
    ] {
        let mut s = base.clone();
        s.camera.projection = projection;
        let setup = setup(&s, &field, Shading::Post);
        let dev = setup.share_deviation().expect("kernels widened");
        // Mass of a normal distribution within the cutoff, and the quadrature's error.
        let kept = 1.0 - 2.0 * sheet_share(SheetShare::Erfc, setup.settings.cutoff, 1e30) - 1e-3;
        for (name, metric) in &metrics {
            let kernel = Kernel {
                position: [0.1, -0.05, 0.02],
                value: 0.7,
                metric: *metric,
                volume: 2e-3,
                kind: KernelKind::Volume,
            };
            let splat = splat_project(&setup, &s.transfer, &kernel).expect("projected");
            let (cx, cy) = (splat.centre[0].round(), splat.centre[1].round());
            let mut worst: f64 = 1.0;
            for y in -6..=6 {
                for x in -6..=6 {
                    let (px, py) = (cx + f64::from(x), cy + f64::from(y));
                    let Some((amplitude, m, inv)) = splat_profile(&splat, &setup, px, py) else {
                        continue;
                    };
                    assert!(inv > 1.0 / dev, "{name}: a kernel the sheets do not widen");
                    let inv = inv.min(1.0 / dev);
                    let shares: f64 = (splat.slabs[0]..=splat.slabs[1])
                        .map(|k| {
                            let (a, b) = setup.slab_bounds(k);
                            sheet_share(SheetShare::Quadrature, (a - m) * inv, (b - m) * inv)
                        })
                        .sum();
                    assert!(amplitude > 0.0);
                    worst = worst.min(shares);
                    checked += 1;
                }
            }
            eprintln!(
                "{name}, {projection:?}: shares sum to at least {worst:.5} of the line integral"
            );
            assert!(
                worst >= kept,
                "{name}, {projection:?}: {worst:.5} < {kept:.5}"
            );
        }
    }
    assert!(checked > 100, "{checked} pixels");
}

/// Stages `splat_walks` and `splat_plan` against their CPU twins (`band_entries`,
/// `plan_groups`): each band's longest tile walk from bucket offsets of 5 × 7 tiles of 3
/// sheets (the last band one tile row), and the workgroups of every indirect dispatch of a
/// recorded frame, its bands' later passes included, with the frame let run or not.
#[test]
fn splat_walks_and_splat_plan_match_their_cpu_twins() {
    use vmls::gpu_types::{PlanPush, WalkPush, binding, binding_defines, splat_stat};
    use vmls::splat::plan::{RasterWalk, args_count, args_slot, band_entries, plan_groups};
    use vmls::vk::{BindGroup, Buffer, BufferUsage, ComputePipeline, ShaderSource};
    let (ctx, compiler) = gpu();
    let walk_push = WalkPush {
        tiles: 35,
        tiles_x: 5,
        slabs: 3,
        band_rows: 2,
    };
    let buckets = walk_push.tiles * walk_push.slabs;
    // Bucket counts up to 400, two tiles (in bands 1 and 2) far longer: offsets are their
    // running sum.
    let mut offsets = vec![0u32];
    for b in 0..buckets {
        let count = (b * 7919 % 401) + if b == 40 || b == 70 { 5000 } else { 0 };
        offsets.push(offsets[b as usize] + count);
    }
    let bands = band_entries(&walk_push, &offsets);
    assert_eq!(bands.len(), 4);
    let pipeline = |file: &str, bindings: &[u32], push: usize| {
        let spirv = compiler
            .compile(ShaderSource::File(file), &binding_defines())
            .expect("compile");
        let kinds: Vec<_> = bindings.iter().map(|&b| (b, binding::kind(b))).collect();
        ComputePipeline::with_kinds(&ctx, file, &spirv, &kinds, push as u32).expect("pipeline")
    };
    let walks = pipeline(
        "splat/splat_walks.comp",
        &[binding::BUCKET_OFFSETS, binding::SPLAT_STATS],
        std::mem::size_of::<WalkPush>(),
    );
    let plan = pipeline(
        "splat/splat_plan.comp",
        &[
            binding::BUCKET_OFFSETS,
            binding::SPLAT_STATS,
            binding::DISPATCH_ARGS,
        ],
        std::mem::size_of::<PlanPush>(),
    );
    let offsets_buf = Buffer::from_slice(&ctx, "offsets", &offsets).expect("offsets");
    let stats = Buffer::new(
        &ctx,
        "stats",
        4 * (splat_stat::BAND_ENTRIES as u64 + 4),
        BufferUsage::Storage,
    )
    .expect("stats");
    let resumes = 3u32;
    let args = Buffer::new(
        &ctx,
        "args",
        16 * args_count(4, resumes) as u64,
        BufferUsage::Storage,
    )
    .expect("args");
    let walk_group = BindGroup::new(
        &ctx,
        &walks,
        &[
            (binding::BUCKET_OFFSETS, &offsets_buf),
            (binding::SPLAT_STATS, &stats),
        ],
    )
    .expect("bind");
    let plan_group = BindGroup::new(
        &ctx,
        &plan,
        &[
            (binding::BUCKET_OFFSETS, &offsets_buf),
            (binding::SPLAT_STATS, &stats),
            (binding::DISPATCH_ARGS, &args),
        ],
    )
    .expect("bind");
    let walk = RasterWalk {
        chunk: 2000,
        sheet_cost: 7,
        steps: 4,
        band_rows: 2,
    };
    for capacity in [u32::MAX, 10] {
        let push = PlanPush {
            buckets,
            capacity,
            max_entries: u32::MAX,
            bin_groups: 3,
            tiles_x: 5,
            tiles_y: 7,
            segments: 0,
            band_rows: 2,
            chunk: walk.chunk,
            sheet_cost: walk.sheet_cost,
            steps: walk.steps,
            resumes,
        };
        ctx.submit(|rec| {
            rec.fill(&stats, 0);
            rec.dispatch(
                &walks,
                &walk_group,
                bytemuck::bytes_of(&walk_push),
                [1, 1, 1],
                "splat_walks",
            )?;
            rec.dispatch(
                &plan,
                &plan_group,
                bytemuck::bytes_of(&push),
                [1, 1, 1],
                "splat_plan",
            )
        })
        .expect("submit");
        let got_stats: Vec<u32> = stats.read(&ctx).expect("read");
        assert_eq!(
            got_stats[splat_stat::BAND_ENTRIES..],
            bands[..],
            "splat_walks"
        );
        let got: Vec<[u32; 4]> = args.read(&ctx).expect("read");
        let want = plan_groups(&push, offsets[buckets as usize], &got_stats);
        let got: Vec<[u32; 3]> = got.iter().map(|a| [a[0], a[1], a[2]]).collect();
        assert_eq!(got, want, "splat_plan, capacity {capacity}");
        let passes: Vec<u32> = bands.iter().map(|&e| walk.passes(e)).collect();
        if capacity == u32::MAX {
            // Some band takes one pass, another more than one.
            assert!(
                passes.contains(&1) && passes.iter().any(|&p| p > 1),
                "{passes:?}"
            );
            let first_band = args_slot(4, resumes, 0, 0);
            assert!(got.iter().skip(first_band).any(|g| g[0] == 0) && got[first_band][0] == 5);
        } else {
            assert!(got.iter().all(|g| g[0] == 0), "nothing runs");
        }
    }
    drop((walk_group, plan_group));
    drop((walks, plan, offsets_buf, stats, args));
    finish(ctx);
}
