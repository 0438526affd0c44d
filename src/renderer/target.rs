//! Stage `target_pack`'s CPU twin: a frame's RGBA32F pixel, over its background where the
//! frame splatted ([`crate::view::shading::composite_background`]), in the format of the application's image
//! ([`TargetFormat`]), as the bytes `vkCmdCopyBufferToImage` copies. The GPU kernel is
//! `glsl/common/target_pack.comp`; tests compare the two over every pixel of a frame.

use crate::vk::TargetFormat;

/// The sRGB transfer function (IEC 61966-2-1) of a linear value clamped to [0, 1].
pub fn srgb_encode(c: f64) -> f64 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.0031308 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// GLSL's `packUnorm4x8` of one channel: clamped to [0, 1], ×255, rounded to nearest.
fn unorm8(c: f64) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Stage `target_pack`: one pixel's bytes in `format`, little-endian as the image stores them.
pub fn pack_pixel(format: TargetFormat, p: [f32; 4]) -> Vec<u8> {
    match format {
        TargetFormat::Rgba32f => bytemuck::cast_slice(&p).to_vec(),
        TargetFormat::Rgba16f => p
            .iter()
            .flat_map(|c| half::f16::from_f32(*c).to_le_bytes())
            .collect(),
        TargetFormat::Rgba8Unorm => p.iter().map(|c| unorm8(f64::from(*c))).collect(),
        TargetFormat::Rgba8Srgb => {
            let [r, g, b, a] = p.map(f64::from);
            vec![
                unorm8(srgb_encode(r)),
                unorm8(srgb_encode(g)),
                unorm8(srgb_encode(b)),
                unorm8(a),
            ]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_round_trip_what_they_can_hold() {
        let p = [0.25f32, 1.5, -0.5, 1.0];
        assert_eq!(pack_pixel(TargetFormat::Rgba32f, p).len(), 16);
        let h = pack_pixel(TargetFormat::Rgba16f, p);
        let back: Vec<f32> = h
            .chunks(2)
            .map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32())
            .collect();
        assert_eq!(back, vec![0.25, 1.5, -0.5, 1.0]);
        assert_eq!(
            pack_pixel(TargetFormat::Rgba8Unorm, p),
            vec![64, 255, 0, 255]
        );
        // sRGB: 0.25 linear is 137.0 of 255 encoded (0.5371 × 255); alpha stays linear.
        assert_eq!(
            pack_pixel(TargetFormat::Rgba8Srgb, [0.25, 0.0, 1.0, 0.25]),
            vec![137, 0, 255, 64]
        );
    }

    #[test]
    fn srgb_meets_its_linear_segment_continuously() {
        let knee = 0.0031308;
        assert!((srgb_encode(knee) - (1.055 * knee.powf(1.0 / 2.4) - 0.055)).abs() < 1e-6);
        assert!((srgb_encode(0.5) - 0.735_356_6).abs() < 1e-6);
    }
}
