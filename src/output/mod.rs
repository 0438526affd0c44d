//! Image files: `.png` is 8-bit RGBA, values clamped to [0,1] with no gamma; `.exr` is 32-bit
//! float RGBA, linear. Files are written through [`crate::files`]: an exclusive temporary beside
//! the target, renamed when complete, so a failure never leaves a partial image behind.
//! [`evalmap`] draws a frame's evaluation counts as a heat map with a scale.

pub mod evalmap;

use crate::field::RenderError;
use std::io::{Seek, Write};
use std::path::Path;

/// Output formats by extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageFormat {
    Png,
    Exr,
}

/// The format of an output path, or an error naming the path and what was expected.
pub fn format_of(path: &Path) -> Result<ImageFormat, RenderError> {
    format_for(path, "output")
}

/// The format of an image `role` ("output", "input") by its extension, checked before a byte
/// is read or written.
pub fn format_for(path: &Path, role: &str) -> Result<ImageFormat, RenderError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("png") => Ok(ImageFormat::Png),
        Some("exr") => Ok(ImageFormat::Exr),
        _ => Err(RenderError::Output {
            path: path.display().to_string(),
            message: format!("unsupported {role} format: expected a .png or .exr file name"),
        }),
    }
}

/// Refuses pixels holding NaN or ±Inf: such an image is garbage, and PNG's clamp would hide it.
pub fn check_finite(pixels: &[[f32; 4]]) -> Result<(), RenderError> {
    let bad = |p: &&[f32; 4]| p.iter().any(|v| !v.is_finite());
    match pixels.iter().position(|p| bad(&p)) {
        None => Ok(()),
        Some(first) => Err(RenderError::NonFinite {
            count: pixels.iter().filter(bad).count(),
            first,
        }),
    }
}

/// Encodes RGBA pixels (row 0 at the top) in the format `path`'s extension names.
pub fn encode_image(
    out: &mut (impl Write + Seek),
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[[f32; 4]],
) -> std::io::Result<()> {
    let format = format_of(path).map_err(std::io::Error::other)?;
    let mismatch = || std::io::Error::other("pixel count does not match the image size");
    let result = match format {
        ImageFormat::Png => {
            let bytes: Vec<u8> = pixels
                .iter()
                .flat_map(|p| p.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8))
                .collect();
            image::RgbaImage::from_raw(width, height, bytes)
                .ok_or_else(mismatch)?
                .write_to(out, image::ImageFormat::Png)
        }
        ImageFormat::Exr => {
            let floats: Vec<f32> = pixels.iter().flat_map(|p| *p).collect();
            image::Rgba32FImage::from_raw(width, height, floats)
                .ok_or_else(mismatch)?
                .write_to(out, image::ImageFormat::OpenExr)
        }
    };
    result.map_err(std::io::Error::other)
}

/// Writes RGBA pixels (row 0 at the top) to `path` through [`crate::files::write_output`]:
/// nothing is written when a pixel is not finite or the encoder fails.
pub fn write_image(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[[f32; 4]],
) -> Result<(), RenderError> {
    format_of(path)?;
    check_finite(pixels)?;
    crate::files::write_output("image", path, &[], |w| {
        encode_image(w, path, width, height, pixels)
    })?;
    Ok(())
}

/// Largest image file [`read_image`] reads: a 16384² RGBA float EXR without compression.
pub const MAX_IMAGE_BYTES: u64 = 16384 * 16384 * 16 + (1 << 20);

/// Reads a `.png` or `.exr` image as linear RGBA floats (PNG bytes / 255, no gamma), row 0 at
/// the top: the inverse of [`write_image`].
pub fn read_image(path: &Path) -> Result<(u32, u32, Vec<[f32; 4]>), RenderError> {
    // The extension first: an unsupported file is refused before it is read.
    let format = match format_for(path, "input")? {
        ImageFormat::Png => image::ImageFormat::Png,
        ImageFormat::Exr => image::ImageFormat::OpenExr,
    };
    let bytes = crate::files::read_input(path, MAX_IMAGE_BYTES)?;
    let img =
        image::load_from_memory_with_format(&bytes, format).map_err(|e| RenderError::Output {
            path: path.display().to_string(),
            message: format!("cannot read image: {e}"),
        })?;
    let rgba = img.to_rgba32f();
    let (w, h) = rgba.dimensions();
    let pixels = rgba
        .as_raw()
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    Ok((w, h, pixels))
}

/// Registers the DejaVu Sans font embedded in the binary as plotters' "sans-serif" (once per
/// process), so that plots and legends draw text on machines without fonts.
pub fn register_fonts() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // A font that fails to parse leaves text undrawn; the picture itself still works.
        let _ = plotters::style::register_font(
            "sans-serif",
            plotters::style::FontStyle::Normal,
            dejavu::sans::regular(),
        );
    });
}
