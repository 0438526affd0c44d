//! `vmls compare`: the error of one image against another, as `vmls bench` measures it.

use crate::CliError;
use std::path::Path;
use vmls::bench::metrics::image_error;
use vmls::field::RenderError;
use vmls::files::Outputs;
use vmls::output::{encode_image, format_for, format_of, read_image};

pub fn compare(image: &Path, reference: &Path, diff: Option<&Path>) -> Result<(), CliError> {
    // Every name is checked before a byte is read: a wrong extension fails at once.
    format_for(image, "input")?;
    format_for(reference, "input")?;
    if let Some(d) = diff {
        format_of(d)?;
    }
    let mut outputs = Outputs::new(
        &diff.map(|d| ("--diff", d)).into_iter().collect::<Vec<_>>(),
        &[("image", image), ("reference", reference)],
    )?;
    let (w, h, a) = read_image(image)?;
    let (rw, rh, b) = read_image(reference)?;
    let Some(e) = image_error(&a, &b, w).filter(|_| (w, h) == (rw, rh)) else {
        return Err(RenderError::Output {
            path: image.display().to_string(),
            message: format!("size ({w}, {h}) differs from the reference's ({rw}, {rh})"),
        }
        .into());
    };
    println!(
        // Scientific notation: the bounds the scripts check these against reach 1e-6 and below.
        "rmse {:.4e} max {:.4e} at ({}, {}) psnr {:.2} dB p99-rgba {:.4e}",
        e.rmse, e.max_abs, e.max_x, e.max_y, e.psnr, e.p99
    );
    if e.non_finite > 0 {
        return Err(CliError::Usage(format!(
            "{} pixel(s) with a non-finite channel in {} or {} (left out of the error above)",
            e.non_finite,
            image.display(),
            reference.display()
        )));
    }
    if let Some(path) = diff {
        let per_pixel: Vec<f64> = a
            .iter()
            .zip(&b)
            .map(|(x, y)| {
                (0..3)
                    .map(|c| f64::from((x[c] - y[c]).abs()))
                    .fold(0.0, f64::max)
            })
            .collect();
        let scale = if e.max_abs > 0.0 {
            1.0 / e.max_abs
        } else {
            0.0
        };
        let heat: Vec<[f32; 4]> = per_pixel
            .iter()
            .map(|&d| {
                let [r, g, b] =
                    vmls::output::evalmap::ramp(d * scale).map(|v| f32::from(v) / 255.0);
                [r, g, b, 1.0]
            })
            .collect();
        outputs.write(path, |out| encode_image(out, path, w, h, &heat))?;
    }
    Ok(outputs.commit()?)
}
