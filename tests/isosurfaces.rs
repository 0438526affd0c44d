//! Shaded isosurfaces and the integrators' hard cases ([MLS] §4), on GPU and CPU, against
//! analytic answers where one exists.
mod common;

use common::*;
use vmls::data::Volume;
use vmls::field::Field;
use vmls::field::gpu::GpuField;
use vmls::raycast::build_tables;
use vmls::raycast::{PixelResult, raycast_image};
use vmls::renderer::{GpuImage, render};
use vmls::scene::Scene;

const METHODS: [&str; 6] = [
    "riemann",
    "fixed",
    "fixed-hermite",
    "adaptive",
    "adaptive-hermite",
    "reference",
];

/// The scene keys of a method name ("adaptive-hermite": the adaptive method, Hermite criterion;
/// "fixed-hermite": fixed steps composited through the Hermite's midpoints).
fn method_keys(method: &str) -> Vec<String> {
    match method {
        "fixed-hermite" => vec![
            "render.method=\"fixed\"".to_string(),
            "render.interval=\"hermite\"".to_string(),
        ],
        "adaptive-hermite" => vec![
            "render.method=\"adaptive\"".to_string(),
            "render.adaptive=\"hermite\"".to_string(),
        ],
        m => vec![format!("render.method=\"{m}\"")],
    }
}

fn scene(overrides: &[String]) -> Scene {
    common::general_scene(overrides)
}

/// GPU and CPU images of a scene over a given volume.
fn both(s: &Scene, volume: Volume) -> (GpuImage, Vec<PixelResult>) {
    let field = Field::new(volume, s.reconstruction, &s.octree, |_| {}).expect("field");
    let setup = s.ray_setup(&field).expect("setup");
    let tables = build_tables(
        &setup,
        &field,
        &s.transfer,
        s.render.table_resolution,
        |_| {},
    );
    let (ctx, compiler) = gpu();
    let gf = GpuField::upload(&ctx, &field).expect("upload");
    let g = render(
        &ctx,
        &compiler,
        &field,
        &gf,
        &s.transfer,
        tables.as_ref(),
        &setup,
        |_| {},
    )
    .expect("render");
    drop(gf);
    finish(ctx);
    let c = raycast_image(&setup, &field, &s.transfer, tables.as_ref()).expect("CPU twin");
    for (p, q) in g.pixels.iter().zip(&c) {
        assert!(p.iter().all(|v| v.is_finite()) && q.rgba.iter().all(|v| v.is_finite()));
    }
    (g, c)
}

/// f = x on [-1, 1]³, viewed along +x with orthographic rays through the middle of the box.
fn ramp() -> Volume {
    volume_from([9, 9, 9], [0.25; 3], [-1.0; 3], |p| p[0])
}

fn along_x(extra: &[&str]) -> Vec<String> {
    let mut o: Vec<String> = [
        "camera.projection=\"orthographic\"",
        "camera.view_height=1.0",
        "camera.eye=[-4.0, 0.0, 0.0]",
        "camera.target=[0.0, 0.0, 0.0]",
        "camera.width=4",
        "camera.height=4",
        "render.table_resolution=128",
        "render.reference_step=0.01",
        "lighting.ambient=0.2",
        "lighting.diffuse=0.8",
        "lighting.specular=0.0",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    o.extend(extra.iter().map(|s| s.to_string()));
    o
}

#[test]
fn isosurface_in_a_constant_medium_matches_the_closed_form() {
    // Constant medium c = (0.2, 0.4, 0.6), τ = 1.5, isosurface at x = 0.3 (opacity 0.6, colour
    // (1, 0.5, 0.25)) facing the viewer: |n·l| = 1, so its colour is lit by 0.2 + 0.8 = 1.
    let (tau, c, a, b) = (1.5f64, [0.2, 0.4, 0.6], 1.3, 0.7);
    let (col, op) = ([1.0, 0.5, 0.25], 0.6);
    let front = 1.0 - (-tau * a).exp();
    let back = 1.0 - (-tau * b).exp();
    let t_front = 1.0 - front;
    let expect: Vec<f64> = (0..3)
        .map(|k| c[k] * front + t_front * (op * col[k] + (1.0 - op) * c[k] * back))
        .collect();
    let alpha = 1.0 - t_front * (1.0 - op) * (1.0 - back);
    for method in METHODS {
        let keys = method_keys(method);
        let o = along_x(&[
            &keys[0],
            keys.get(1).map_or("render.adaptive=\"mls2008\"", |k| k),
            "transfer.points=[[-2.0, 0.2, 0.4, 0.6, 1.5], [2.0, 0.2, 0.4, 0.6, 1.5]]",
            "transfer.isosurfaces=[{ value = 0.3, color = [1.0, 0.5, 0.25], opacity = 0.6 }]",
            "render.early_termination=1.0",
        ]);
        let (g, cpu) = both(&scene(&o), ramp());
        // The midpoint rule places the surface between samples and integrates the medium with
        // steps: it converges, the others are exact up to tables and root finding.
        let bound = if method == "riemann" { 2e-2 } else { 2e-4 };
        for (p, q) in g.pixels.iter().zip(&cpu) {
            for k in 0..3 {
                assert!(
                    (q.rgba[k] - expect[k]).abs() < bound,
                    "{method}: CPU {:?} vs {expect:?}",
                    q.rgba
                );
                assert!(
                    (f64::from(p[k]) - expect[k]).abs() < bound,
                    "{method}: GPU {p:?} vs {expect:?}"
                );
            }
            assert!((q.rgba[3] - alpha).abs() < bound && (f64::from(p[3]) - alpha).abs() < bound);
        }
    }
}

#[test]
fn isosurface_exactly_at_a_knot_is_composited_once() {
    // Fixed step 1 spacing = 0.25: knots at x = -1, -0.75, …, so x = 0.5 is a knot and
    // f(0.5) = 0.5 up to rounding. Transparent medium: α must be the opacity, not 1 − (1 − op)².
    for method in ["fixed", "fixed-hermite", "adaptive", "adaptive-hermite"] {
        let keys = method_keys(method);
        let o = along_x(&[
            &keys[0],
            keys.get(1).map_or("render.adaptive=\"mls2008\"", |k| k),
            "render.step=1.0",
            "render.l_max=4.0",
            "render.l_min=1.0",
            "transfer.points=[[-2.0, 0.0, 0.0, 0.0, 0.0], [2.0, 0.0, 0.0, 0.0, 0.0]]",
            "transfer.isosurfaces=[{ value = 0.5, color = [1.0, 1.0, 1.0], opacity = 0.4 }]",
        ]);
        let (g, c) = both(&scene(&o), ramp());
        for (p, q) in g.pixels.iter().zip(&c) {
            assert!(
                (q.rgba[3] - 0.4).abs() < 1e-9,
                "{method}: CPU α {}",
                q.rgba[3]
            );
            assert!((p[3] - 0.4).abs() < 1e-6, "{method}: GPU α {}", p[3]);
        }
    }
}

#[test]
fn near_tangent_double_crossings_between_two_knots_are_found() {
    // f = |x|² (reproduced exactly by the quadratic basis), isosurface f = 0.81 (radius 0.9),
    // transparent medium. One ray along x at height b: both knots or samples outside the sphere
    // and the chord, 2·√(0.81 − b²), between them. Expected: two surfaces lit by |n·d| =
    // √(0.81 − b²)/0.9, α = 1 − (1 − op)², nothing for b > 0.9.
    let sphere = volume_from([13, 13, 13], [1.0 / 6.0; 3], [-1.0; 3], |p| {
        p[0] * p[0] + p[1] * p[1] + p[2] * p[2]
    });
    let (col, op) = ([1.0, 0.5, 0.25], 0.5);
    for b in [0.6, 0.89, 0.899, 0.9008] {
        let inside = (0.81f64 - b * b).max(0.0);
        let lit = 0.2 + 0.8 * inside.sqrt() / 0.9;
        let (want_rgb, want_alpha) = if b < 0.9 {
            (
                col.map(|c| op * c * lit * (2.0 - op)),
                1.0 - (1.0 - op) * (1.0 - op),
            )
        } else {
            ([0.0; 3], 0.0)
        };
        // Knots at x = ±1 (fixed, adaptive with l_min = l_max) and midpoint samples at ±0.5.
        for (method, step) in [
            ("fixed", 12.0),
            ("fixed-hermite", 12.0),
            ("adaptive", 12.0),
            ("adaptive-hermite", 12.0),
            ("riemann", 6.0),
        ] {
            if method == "riemann" && b * b + 0.25 < 0.81 {
                // Both samples inside: the crossings lie in the half steps outside them.
                continue;
            }
            let keys = method_keys(method);
            let o = along_x(&[
                &keys[0],
                keys.get(1).map_or("render.adaptive=\"mls2008\"", |k| k),
                &format!("render.step={step}"),
                &format!("render.l_max={step}"),
                &format!("render.l_min={step}"),
                &format!("camera.eye=[-4.0, 0.0, {b}]"),
                &format!("camera.target=[0.0, 0.0, {b}]"),
                "camera.width=1",
                "camera.height=1",
                "reconstruction.basis=\"quadratic\"",
                "transfer.points=[[0.0, 0.0, 0.0, 0.0, 0.0], [3.0, 0.0, 0.0, 0.0, 0.0]]",
                "transfer.isosurfaces=[{ value = 0.81, color = [1.0, 0.5, 0.25], opacity = 0.5 }]",
            ]);
            let (g, c) = both(&scene(&o), sphere.clone());
            let (p, q) = (g.pixels[0], c[0].rgba);
            for k in 0..3 {
                assert!(
                    (q[k] - want_rgb[k]).abs() < 2e-3
                        && (f64::from(p[k]) - want_rgb[k]).abs() < 2e-3,
                    "{method} b = {b}: CPU {q:?} GPU {p:?}, want {want_rgb:?} α {want_alpha}"
                );
            }
            assert!(
                (q[3] - want_alpha).abs() < 1e-6 && (f64::from(p[3]) - want_alpha).abs() < 1e-5,
                "{method} b = {b}: α CPU {} GPU {}, want {want_alpha}",
                q[3],
                p[3]
            );
        }
    }
}

#[test]
fn midpoint_rule_sees_surfaces_in_the_half_steps_at_entry_and_exit() {
    // f = x on [-1, 1], step 2 spacings = 0.5: samples at -0.75, -0.25, …, 0.75. Surfaces at
    // x = -0.9 and 0.9 lie between the box faces and the first/last sample; a transparent
    // medium leaves α = 1 − (1 − op)² once both are seen.
    for method in ["riemann", "reference"] {
        let o = along_x(&[
            &format!("render.method=\"{method}\""),
            "render.step=2.0",
            "render.reference_step=2.0",
            "transfer.points=[[-2.0, 0.0, 0.0, 0.0, 0.0], [2.0, 0.0, 0.0, 0.0, 0.0]]",
            "transfer.isosurfaces=[{ value = -0.9, color = [1.0, 1.0, 1.0], opacity = 0.4 }, \
             { value = 0.9, color = [1.0, 1.0, 1.0], opacity = 0.4 }]",
        ]);
        let (g, c) = both(&scene(&o), ramp());
        let want = 1.0 - 0.6 * 0.6;
        for (p, q) in g.pixels.iter().zip(&c) {
            assert!(
                (q.rgba[3] - want).abs() < 1e-9,
                "{method}: CPU α {}",
                q.rgba[3]
            );
            assert!(
                (f64::from(p[3]) - want).abs() < 1e-6,
                "{method}: GPU α {}",
                p[3]
            );
        }
    }
}

#[test]
fn hard_rays_agree_with_the_reference_twin_and_stay_finite() {
    // A sphere-like field (f = |x|²) with an isosurface the rays graze; rays along a face,
    // through a corner, starting inside; an opaque first interval.
    let sphere = || {
        volume_from([13, 13, 13], [1.0 / 6.0; 3], [-1.0; 3], |p| {
            p[0] * p[0] + p[1] * p[1] + p[2] * p[2]
        })
    };
    let iso = "transfer.isosurfaces=[{ value = 0.81, color = [0.9, 0.6, 0.3], opacity = 0.7 }]";
    let tf = "transfer.points=[[0.0, 0.1, 0.2, 0.3, 0.8], [3.0, 0.3, 0.2, 0.1, 0.2]]";
    let cases: Vec<Vec<&str>> = vec![
        // Near-tangent: the top rows graze the 0.9-radius sphere.
        vec![
            "camera.eye=[-4.0, 0.0, 0.0]",
            "camera.projection=\"orthographic\"",
            "camera.view_height=1.84",
        ],
        // Parallel to a face, exactly on it.
        vec![
            "camera.eye=[-4.0, 0.0, 1.0]",
            "camera.target=[0.0, 0.0, 1.0]",
            "camera.projection=\"orthographic\"",
            "camera.view_height=0.5",
        ],
        // Through the corner region.
        vec!["camera.eye=[3.0, 3.0, 3.0]", "camera.fov_y=20.0"],
        // Eye inside the volume.
        vec![
            "camera.eye=[0.2, 0.1, 0.0]",
            "camera.target=[1.0, 1.0, 0.5]",
            "camera.fov_y=90.0",
        ],
    ];
    for method in ["riemann", "fixed", "adaptive"] {
        for case in &cases {
            let m = format!("render.method=\"{method}\"");
            let mut o: Vec<String> = [
                "camera.width=12",
                "camera.height=12",
                "render.table_resolution=128",
                iso,
                tf,
            ]
            .iter()
            .map(|s| s.to_string())
            .collect();
            o.push(m);
            o.extend(case.iter().map(|s| s.to_string()));
            let (g, c) = both(&scene(&o), sphere());
            let worst = g
                .pixels
                .iter()
                .zip(&c)
                .map(|(p, q)| {
                    (0..4)
                        .map(|k| (f64::from(p[k]) - q.rgba[k]).abs())
                        .fold(0.0, f64::max)
                })
                .fold(0.0, f64::max);
            // f32 vs f64 root finding near tangency may land on either side of a grazing hit.
            let loose = g
                .pixels
                .iter()
                .zip(&c)
                .filter(|(p, q)| (0..4).any(|k| (f64::from(p[k]) - q.rgba[k]).abs() > 1e-3))
                .count();
            assert!(
                loose <= 2,
                "{method} {case:?}: {loose} pixels differ by > 1e-3 (worst {worst:.2e})"
            );
        }
    }
    // A fully opaque first interval: the front colour, no NaN.
    for method in ["fixed", "adaptive"] {
        let o: Vec<String> = along_x(&[
            &format!("render.method=\"{method}\""),
            "transfer.points=[[-2.0, 0.3, 0.6, 0.9, 1e9], [2.0, 0.3, 0.6, 0.9, 1e9]]",
        ]);
        let (g, c) = both(&scene(&o), ramp());
        for (p, q) in g.pixels.iter().zip(&c) {
            for (k, want) in [0.3, 0.6, 0.9, 1.0].iter().enumerate() {
                assert!(
                    (q.rgba[k] - want).abs() < 1e-6 && (f64::from(p[k]) - want).abs() < 1e-5,
                    "{method}: {p:?} {:?}",
                    q.rgba
                );
            }
        }
    }
}
