//! Splatting's low-pass filters on a minified zebra ([EWA]'s comparison): EWA against no
//! low-pass and [SWAN], and the auto low-pass (aliasing as little as EWA, wide footprints left
//! as they are). CPU twin only: the GPU's agreement with it is tests/splat.rs's.
mod common;

use common::splat::*;
use common::*;
use vmls::splat::Shading;
use vmls::splat::raster::splat_image;

/// A one-layer sheet of flat kernels seen at 10° elevation through an orthographic camera: along
/// image x one sample spacing is 2 pixels, along image y 0.35 pixels (strong anisotropic
/// minification). The field is x-stripes of period 16 px (amplitude `stripes.0`) plus y-stripes
/// of period 0.7 px (`stripes.1`); the band-limited image keeps the first and removes the second.
fn zebra(antialias: &str, scale: u32, stripes: (f64, f64)) -> (Vec<[f64; 4]>, u32, u32) {
    let n = 128;
    // Kernels flat in z (a sheet of voxels one 512th thick): isotropic kernels would project to
    // circles at any elevation, and no filter would need to be anisotropic.
    let volume = volume_from(
        [n, n, 1],
        [1.0 / 64.0, 1.0 / 64.0, 1.0 / 512.0],
        [-1.0, -1.0, 0.0],
        |p| {
            let i = ((p[0] + 1.0) * 64.0).round() as i64;
            let j = ((p[1] + 1.0) * 64.0).round() as i64;
            let sx = if (i / 4) % 2 == 0 { 1.0 } else { -1.0 };
            let sy = if j % 2 == 0 { 1.0 } else { -1.0 };
            0.5 + stripes.0 * sx + stripes.1 * sy
        },
    );
    let e = 10f64.to_radians();
    let eye = format!("camera.eye=[0.0,{},{}]", -3.0 * e.cos(), 3.0 * e.sin());
    let (w, h) = (64 * scale, 32 * scale);
    let size = [format!("camera.width={w}"), format!("camera.height={h}")];
    let aa = format!("splat.antialias=\"{antialias}\"");
    let s = scene(&[
        "render.method=\"splat\"",
        "camera.projection=\"orthographic\"",
        "camera.view_height=0.25",
        eye.as_str(),
        size[0].as_str(),
        size[1].as_str(),
        aa.as_str(),
        "splat.occlusion=false",
        "splat.slab=32.0",
        "transfer.points=[[0.0,0.0,0.0,0.0,50.0],[1.0,1.0,1.0,1.0,50.0]]",
    ]);
    let field = grid_field(volume, &s);
    let image =
        splat_image(&setup(&s, &field, Shading::Pre), &field, &s.transfer).expect("CPU twin");
    (image.pixels, w, h)
}

/// Each filter's RGB RMSE over the zebra's interior against the band-limited image: the
/// zebra 4×4 supersampled without any filter, then the same Gaussian low-pass (variance
/// 1 px², 16 in supersampled pixels) as the resampling filter, sampled at the pixel centres.
fn zebra_errors<'a>(filters: &[&'a str], stripes: (f64, f64)) -> Vec<(&'a str, f64)> {
    let (fine, fw, fh) = zebra("none", 4, stripes);
    let (w, h) = (64usize, 32usize);
    let mut reference = vec![[0.0; 4]; w * h];
    for (p, out) in reference.iter_mut().enumerate() {
        let (cx, cy) = (4.0 * (p % w) as f64 + 1.5, 4.0 * (p / w) as f64 + 1.5);
        let mut sum = [0.0; 4];
        let mut weight = 0.0;
        for y in 0..fh as usize {
            for x in 0..fw as usize {
                let d2 = (x as f64 - cx).powi(2) + (y as f64 - cy).powi(2);
                if d2 > 200.0 {
                    continue;
                }
                let g = (-0.5 * d2 / 16.0).exp();
                weight += g;
                for c in 0..4 {
                    sum[c] += g * fine[y * fw as usize + x][c];
                }
            }
        }
        *out = sum.map(|v| v / weight);
    }
    // Interior only: the reference's filter is cut at the image border.
    let err = |img: &[[f64; 4]]| {
        let mut s = 0.0;
        let mut n = 0.0;
        for y in 4..h - 4 {
            for x in 4..w - 4 {
                for c in 0..3 {
                    s += (img[y * w + x][c] - reference[y * w + x][c]).powi(2);
                    n += 1.0;
                }
            }
        }
        (s / n).sqrt()
    };
    filters
        .iter()
        .map(|a| (*a, err(&zebra(a, 1, stripes).0)))
        .collect()
}

#[test]
fn ewa_beats_no_lowpass_and_swan_on_a_minified_zebra() {
    let errors = zebra_errors(&["ewa", "none", "swan"], (0.3, 0.2));
    eprintln!("zebra RMSE against the band-limited supersampled image: {errors:?}");
    // Measured: EWA 9.6e-4, none 1.5e-2 (aliasing of the y-stripes), SWAN 7.8e-2 (the x-stripes
    // blurred away). A factor 4 keeps the orderings meaningful.
    assert!(
        4.0 * errors[0].1 < errors[1].1,
        "EWA must alias less than no low-pass: {errors:?}"
    );
    assert!(
        4.0 * errors[0].1 < errors[2].1,
        "EWA must blur less than SWAN: {errors:?}"
    );
}

#[test]
fn the_auto_lowpass_removes_the_zebras_aliasing_and_keeps_wide_footprints_sharp() {
    // The y-stripes alone: the band-limited image is flat, so what differs from it is aliasing
    // (and the x-blur of the reference's filter does not count). The auto low-pass raises the
    // 0.35 px y-spacing's footprints to the low-pass, as EWA does: it must alias as little.
    let aliasing = zebra_errors(&["auto", "ewa", "none"], (0.0, 0.2));
    eprintln!("y-stripes only, RMSE against the band-limited image: {aliasing:?}");
    assert!(
        4.0 * aliasing[0].1 < aliasing[2].1 && aliasing[0].1 < 2.0 * aliasing[1].1 + 1e-4,
        "auto must alias as little as EWA and less than no low-pass: {aliasing:?}"
    );
    // Wide footprints: the 13³ test grid at 64², where every footprint's minor variance is
    // 2.6–10 px². Auto leaves them as they are (the image of no low-pass, to rounding); EWA
    // blurs them by its full low-pass.
    let wide = |aa: &str| {
        let s = scene(&[
            "render.method=\"splat-post\"",
            "camera.width=64",
            "camera.height=64",
            &format!("splat.antialias=\"{aa}\""),
        ]);
        let field = s.field(|_| {}).expect("field");
        splat_image(&setup(&s, &field, Shading::Post), &field, &s.transfer)
            .expect("CPU twin")
            .pixels
    };
    let (auto, ewa, none) = (wide("auto"), wide("ewa"), wide("none"));
    let (to_none, ewa_to_none) = (rmse(&auto, &none), rmse(&ewa, &none));
    eprintln!("wide footprints: auto to none {to_none:.2e}, EWA to none {ewa_to_none:.2e}");
    assert!(
        to_none < 1e-3 * ewa_to_none,
        "auto changed wide footprints: {to_none:.2e} against EWA's {ewa_to_none:.2e}"
    );
}
