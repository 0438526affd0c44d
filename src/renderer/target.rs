//! Stage `target_pack`'s CPU twin: a frame's RGBA32F pixel, over its background where the
//! frame splatted ([`crate::view::shading::composite_background`]), in the format of the application's image
//! ([`TargetFormat`]), as the bytes `vkCmdCopyBufferToImage` copies, and the kernel's driver
//! (pipelines per format, bind group, dispatch and the write into the application's target).
//! The GPU kernel is `glsl/common/target_pack.comp`; tests compare the two over every pixel of
//! a frame.

use super::Renderer;
use super::record::RecordState;
use crate::field::RenderError;
use crate::field::variant::groups_2d;
use crate::gpu_types::{PackPush, binding};
use crate::vk::{
    BindGroup, Buffer, ComputePipeline, Context, Recorder, Target, TargetFormat, VkError,
};

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

/// Stage `target_pack`'s driver: its pipelines, bind groups and dispatch.
impl RecordState {
    /// The bind group of `target_pack` pipeline `pack` from `image` into `packed`.
    pub(super) fn pack_group<'a>(
        &self,
        ctx: &Context,
        pack: usize,
        image: &'a Buffer,
        packed: &'a Option<Buffer>,
    ) -> Result<BindGroup<'a>, VkError> {
        let (Some((_, p)), Some(out)) = (self.pack.get(pack), packed.as_ref()) else {
            return Err(VkError::Usage(
                "target_pack pipeline or buffer missing".into(),
            ));
        };
        BindGroup::new(
            ctx,
            p,
            &[(binding::IMAGE, image), (binding::TARGET_PACKED, out)],
        )
    }

    /// The write of a frame's pixels into the target ([`RecordState::record_finish`]).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn record_write(
        &self,
        rec: &mut Recorder<'_>,
        pack: Option<(usize, &BindGroup<'_>)>,
        background: [f32; 3],
        image: &Buffer,
        packed: Option<&Buffer>,
        target: &Target,
        size: (u32, u32),
    ) -> Result<u32, VkError> {
        let (w, h) = size;
        match (pack, packed) {
            (Some((p, g)), Some(out)) => {
                let Some((_, pipeline)) = self.pack.get(p) else {
                    return Err(VkError::Usage("target_pack pipeline missing".into()));
                };
                let count = u32::try_from(u64::from(w) * u64::from(h)).unwrap_or(u32::MAX);
                let push = PackPush {
                    count,
                    composite: u32::from(background != [0.0; 3]),
                    _pad: [0; 2],
                    background: [background[0], background[1], background[2], 0.0],
                };
                rec.dispatch(
                    pipeline,
                    g,
                    bytemuck::bytes_of(&push),
                    groups_2d(count, 64),
                    "target_pack",
                )?;
                rec.write_target(out, target, w, h)?;
                Ok(1)
            }
            _ => {
                rec.write_target(image, target, w, h)?;
                Ok(0)
            }
        }
    }
}

impl Renderer {
    /// The `target_pack` pipeline for `format` (compiled at its first use).
    pub(super) fn pack_pipeline(&mut self, format: TargetFormat) -> Result<usize, RenderError> {
        if let Some(i) = self.record.pack.iter().position(|(f, _)| *f == format) {
            return Ok(i);
        }
        let code = match format {
            TargetFormat::Rgba16f => 1,
            TargetFormat::Rgba8Unorm => 2,
            TargetFormat::Rgba8Srgb => 3,
            // Splatting frames over a background composite it while copying.
            TargetFormat::Rgba32f => 0,
        };
        let mut defines = crate::gpu_types::binding_defines();
        defines.push(("TARGET_FORMAT".into(), code.to_string()));
        let spirv = self.compiler.compile(
            crate::vk::ShaderSource::File("common/target_pack.comp"),
            &defines,
        )?;
        let kinds = [binding::IMAGE, binding::TARGET_PACKED].map(|b| (b, binding::kind(b)));
        let p = ComputePipeline::with_kinds(
            &self.ctx,
            &format!("target_pack:{format:?}"),
            &spirv,
            &kinds,
            std::mem::size_of::<PackPush>() as u32,
        )?;
        self.record.pack.push((format, p));
        Ok(self.record.pack.len() - 1)
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
