//! `--eval-map`: the per-pixel count of MLS evaluations as a heat map (a viridis-like ramp from
//! 0 to the largest count), with a legend strip below the image: the colour bar and its end
//! values, drawn with a built-in 3×5 digit font (there is no font file to rely on).

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
/// 3×5 glyphs of the digits 0–9, one row per 3 bits (most significant = left).
const DIGITS: [[u8; 5]; 10] = [
    [7, 5, 5, 5, 7],
    [2, 6, 2, 2, 7],
    [7, 1, 7, 4, 7],
    [7, 1, 7, 1, 7],
    [5, 5, 7, 1, 1],
    [7, 4, 7, 1, 7],
    [7, 4, 7, 5, 7],
    [7, 1, 1, 1, 1],
    [7, 5, 7, 5, 7],
    [7, 5, 7, 1, 7],
];

/// Ramp colour at u ∈ [0, 1].
pub fn ramp(u: f64) -> [u8; 3] {
    let x = u.clamp(0.0, 1.0) * (RAMP.len() - 1) as f64;
    let i = (x as usize).min(RAMP.len() - 2);
    let f = x - i as f64;
    [0, 1, 2].map(|k| (RAMP[i][k] + (RAMP[i + 1][k] - RAMP[i][k]) * f).round() as u8)
}

fn draw_number(img: &mut image::RgbImage, value: u32, x0: u32, y0: u32, right_aligned: bool) {
    let text = value.to_string();
    let scale = 2;
    let width = text.len() as u32 * 4 * scale;
    let x0 = if right_aligned {
        x0.saturating_sub(width)
    } else {
        x0
    };
    for (n, ch) in text.bytes().enumerate() {
        let glyph = DIGITS[(ch - b'0') as usize];
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..3 {
                if bits >> (2 - col) & 1 == 1 {
                    for dy in 0..scale {
                        for dx in 0..scale {
                            let x = x0 + (n as u32 * 4 + col) * scale + dx;
                            let y = y0 + row as u32 * scale + dy;
                            if x < img.width() && y < img.height() {
                                img.put_pixel(x, y, image::Rgb([255, 255, 255]));
                            }
                        }
                    }
                }
            }
        }
    }
}

/// Checks that `path` names a PNG file (the only format of the map).
pub fn check_path(path: &Path) -> Result<(), RenderError> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        Ok(())
    } else {
        Err(RenderError::Output {
            path: path.display().to_string(),
            message: "the evaluation map is a PNG: expected a .png file name".into(),
        })
    }
}

/// Writes the heat map of `counts` (row 0 at the top) to a PNG file.
pub fn write_eval_map(
    path: &Path,
    width: u32,
    height: u32,
    counts: &[u32],
) -> Result<(), RenderError> {
    let err = |message: String| RenderError::Output {
        path: path.display().to_string(),
        message,
    };
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
    draw_number(&mut img, 0, 1, bar_top + 8, false);
    draw_number(&mut img, max, width.saturating_sub(1), bar_top + 8, true);
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".{file_name}.partial"));
    img.save_with_format(&tmp, image::ImageFormat::Png)
        .map_err(|e| err(format!("cannot write the evaluation map: {e}")))?;
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        err(format!("cannot write the evaluation map: {e}"))
    })
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
