//! `--eval-map`: the per-pixel count of MLS evaluations as a heat map (a viridis-like ramp from
//! 0 to the largest count), with a legend strip below the image: the colour bar and its end
//! values, drawn by plotters with the DejaVu Sans font embedded in the binary (no font file on
//! the machine is needed). To a `.exr` file the counts themselves are written instead (R = G = B
//! = count, A = 1, exact below 2^24), for tools that count where evaluations went.

use super::RenderError;
use std::path::Path;

/// Legend strip height in pixels.
const LEGEND: u32 = 22;
/// Colour ramp stops (a viridis approximation): dark violet → blue → teal → green → yellow.
const RAMP: [[f64; 3]; 5] = [
    [68.0, 1.0, 84.0],
    [59.0, 82.0, 139.0],
    [33.0, 145.0, 140.0],
    [94.0, 201.0, 98.0],
    [253.0, 231.0, 37.0],
];
/// Ramp colour at u ∈ [0, 1].
pub fn ramp(u: f64) -> [u8; 3] {
    let x = u.clamp(0.0, 1.0) * (RAMP.len() - 1) as f64;
    let i = (x as usize).min(RAMP.len() - 2);
    let f = x - i as f64;
    [0, 1, 2].map(|k| (RAMP[i][k] + (RAMP[i + 1][k] - RAMP[i][k]) * f).round() as u8)
}

/// Writes the legend's end values into the strip below the image (rows `top..`), in white.
fn draw_legend(img: &mut image::RgbImage, top: u32, max: u32) -> Result<(), String> {
    use plotters::prelude::*;
    super::register_fonts();
    let (w, h) = img.dimensions();
    let buffer: &mut [u8] = img;
    let root = BitMapBackend::with_buffer(buffer, (w, h)).into_drawing_area();
    let style = ("sans-serif", 11).into_font().color(&WHITE);
    let e = |e: DrawingAreaErrorKind<_>| e.to_string();
    root.draw(&Text::new("0".to_string(), (1, top as i32), style.clone()))
        .map_err(e)?;
    let label = max.to_string();
    let (tw, _) = root.estimate_text_size(&label, &style).map_err(e)?;
    root.draw(&Text::new(
        label,
        ((w as i32 - 1 - tw as i32).max(0), top as i32),
        style,
    ))
    .map_err(e)?;
    root.present().map_err(e)
}

/// Checks that `path` names a PNG file (the heat map) or an EXR file (the counts).
pub fn check_path(path: &Path) -> Result<(), RenderError> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png") || e.eq_ignore_ascii_case("exr"))
    {
        Ok(())
    } else {
        Err(RenderError::Output {
            path: path.display().to_string(),
            message: "the evaluation map is a PNG heat map or an EXR of the counts: expected a \
                      .png or .exr file name"
                .into(),
        })
    }
}

/// An evaluation map ready to encode: the heat map (PNG) or the counts (EXR).
pub enum EvalMap {
    Heat(image::RgbImage),
    /// R = G = B = count, A = 1.
    Counts(Vec<[f32; 4]>),
}

/// The map of `counts` that `path` asks for: the counts themselves to a `.exr`, else the heat
/// map ([`eval_map_image`]).
pub fn eval_map(
    path: &Path,
    width: u32,
    height: u32,
    counts: &[u32],
) -> Result<EvalMap, RenderError> {
    check_path(path)?;
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
    {
        let pixels = counts.iter().map(|&c| c as f32).map(|v| [v, v, v, 1.0]);
        return Ok(EvalMap::Counts(pixels.collect()));
    }
    eval_map_image(path, width, height, counts).map(EvalMap::Heat)
}

impl EvalMap {
    /// Encodes the map to `out` (`path` names its format, as [`eval_map`] chose it).
    pub fn encode(
        &self,
        out: &mut (impl std::io::Write + std::io::Seek),
        path: &Path,
        width: u32,
        height: u32,
    ) -> std::io::Result<()> {
        match self {
            EvalMap::Heat(img) => img
                .write_to(out, image::ImageFormat::Png)
                .map_err(std::io::Error::other),
            EvalMap::Counts(pixels) => super::encode_image(out, path, width, height, pixels),
        }
    }
}

/// The heat map of `counts` (row 0 at the top) with its legend below, as an image.
pub fn eval_map_image(
    path: &Path,
    width: u32,
    height: u32,
    counts: &[u32],
) -> Result<image::RgbImage, RenderError> {
    check_path(path)?;
    let max = counts.iter().copied().max().unwrap_or(0).max(1);
    let mut img = image::RgbImage::new(width, height + LEGEND);
    for (i, &c) in counts.iter().enumerate().take((width * height) as usize) {
        let (x, y) = (i as u32 % width, i as u32 / width);
        img.put_pixel(x, y, image::Rgb(ramp(f64::from(c) / f64::from(max))));
    }
    let bar_top = height + 2;
    for x in 0..width {
        let colour = image::Rgb(ramp(f64::from(x) / f64::from(width.max(2) - 1)));
        for y in bar_top..bar_top + 6 {
            img.put_pixel(x, y, colour);
        }
    }
    draw_legend(&mut img, bar_top + 7, max).map_err(|e| RenderError::Output {
        path: path.display().to_string(),
        message: format!("cannot draw the legend: {e}"),
    })?;
    Ok(img)
}

/// Writes the map of `counts` that `path` asks for ([`eval_map`]).
pub fn write_eval_map(
    path: &Path,
    width: u32,
    height: u32,
    counts: &[u32],
) -> Result<(), RenderError> {
    let map = eval_map(path, width, height, counts)?;
    crate::files::write_output("--eval-map", path, &[], |w| {
        map.encode(w, path, width, height)
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_ends_and_monotone_luminance() {
        assert_eq!(ramp(0.0), [68, 1, 84]);
        assert_eq!(ramp(1.0), [253, 231, 37]);
        let lum = |c: [u8; 3]| {
            0.2126 * f64::from(c[0]) + 0.7152 * f64::from(c[1]) + 0.0722 * f64::from(c[2])
        };
        for i in 0..20 {
            assert!(lum(ramp(f64::from(i) / 20.0)) < lum(ramp(f64::from(i + 1) / 20.0)));
        }
    }
}
