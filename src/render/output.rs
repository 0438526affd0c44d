//! Image files: `.png` is 8-bit RGBA, values clamped to [0,1] with no gamma; `.exr` is 32-bit
//! float RGBA, linear. Files are written to a temporary name beside the target and renamed, so
//! a failure never leaves a partial image behind.

use super::RenderError;
use std::path::Path;

/// Output formats by extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageFormat {
    Png,
    Exr,
}

/// The format of an output path, or an error naming the path and what was expected.
pub fn format_of(path: &Path) -> Result<ImageFormat, RenderError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("png") => Ok(ImageFormat::Png),
        Some("exr") => Ok(ImageFormat::Exr),
        _ => Err(RenderError::Output {
            path: path.display().to_string(),
            message: "unsupported output format: expected a .png or .exr file name".into(),
        }),
    }
}

/// Writes RGBA pixels (row 0 at the top) to `path`.
pub fn write_image(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[[f32; 4]],
) -> Result<(), RenderError> {
    let format = format_of(path)?;
    if let Some(first) = pixels.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
        return Err(RenderError::NonFinite {
            count: pixels
                .iter()
                .filter(|p| p.iter().any(|v| !v.is_finite()))
                .count(),
            first,
        });
    }
    let err = |message: String| RenderError::Output {
        path: path.display().to_string(),
        message,
    };
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".{file_name}.partial"));
    let result = match format {
        ImageFormat::Png => {
            let bytes: Vec<u8> = pixels
                .iter()
                .flat_map(|p| p.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8))
                .collect();
            image::RgbaImage::from_raw(width, height, bytes)
                .ok_or_else(|| err("pixel count does not match the image size".into()))?
                .save_with_format(&tmp, image::ImageFormat::Png)
        }
        ImageFormat::Exr => {
            let floats: Vec<f32> = pixels.iter().flat_map(|p| *p).collect();
            image::Rgba32FImage::from_raw(width, height, floats)
                .ok_or_else(|| err("pixel count does not match the image size".into()))?
                .save_with_format(&tmp, image::ImageFormat::OpenExr)
        }
    };
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(err(format!("cannot write image: {e}")));
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        err(format!("cannot write image: {e}"))
    })
}

/// Reads a `.png` or `.exr` image as linear RGBA floats (PNG bytes / 255, no gamma), row 0 at
/// the top: the inverse of [`write_image`].
pub fn read_image(path: &Path) -> Result<(u32, u32, Vec<[f32; 4]>), RenderError> {
    let img = image::open(path).map_err(|e| RenderError::Output {
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
