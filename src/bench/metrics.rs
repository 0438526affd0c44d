//! Image error against a reference, as `vmls bench` and `vmls compare` report it.
//!
//! Errors are over the RGB channels of the composited image (C + T·background), the values a
//! viewer sees; alpha is not compared. Pixels with a non-finite channel in either image are
//! counted and left out of the RMSE and maximum, so one NaN cannot hide the rest of the error.
//! PSNR assumes a peak of 1 (images are linear radiance in [0, 1] for in-range transfer
//! functions).

use serde::{Deserialize, Serialize};

/// Error of an image against a reference of the same size.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImageError {
    /// Root mean square of the RGB differences over the finite pixels.
    pub rmse: f64,
    /// Largest |difference| of any RGB channel, and the pixel (column, row from the top).
    pub max_abs: f64,
    pub max_x: u32,
    pub max_y: u32,
    /// 20·log10(1 / rmse); infinite for identical images.
    pub psnr: f64,
    /// Pixels with a non-finite channel in the image or in the reference.
    pub non_finite: u64,
    /// The measure `render.tolerance` bounds: the 99th percentile over pixels of the largest
    /// |difference| of the four channels, alpha included
    /// (`crate::renderer::tolerance::p99_error`; a non-finite pixel counts as infinite).
    pub p99: f64,
}

/// The error of `image` against `reference`, both RGBA rows from the top, `width` wide.
/// `None` when the pixel counts differ (callers compare the dimensions too).
pub fn image_error(image: &[[f32; 4]], reference: &[[f32; 4]], width: u32) -> Option<ImageError> {
    if image.len() != reference.len() || width == 0 {
        return None;
    }
    let mut sum = 0.0f64;
    let mut channels = 0u64;
    let mut non_finite = 0u64;
    let (mut max_abs, mut at) = (0.0f64, 0usize);
    for (i, (a, b)) in image.iter().zip(reference).enumerate() {
        if a[..3].iter().chain(&b[..3]).any(|v| !v.is_finite()) {
            non_finite += 1;
            continue;
        }
        for c in 0..3 {
            let d = f64::from(a[c]) - f64::from(b[c]);
            sum += d * d;
            if d.abs() > max_abs {
                max_abs = d.abs();
                at = i;
            }
        }
        channels += 3;
    }
    // No finite pixel: no error to speak of (NaN), not a perfect match.
    let rmse = if channels == 0 {
        f64::NAN
    } else {
        (sum / channels as f64).sqrt()
    };
    let w = width as usize;
    Some(ImageError {
        rmse,
        max_abs,
        max_x: (at % w) as u32,
        max_y: (at / w) as u32,
        psnr: -20.0 * rmse.log10(),
        non_finite,
        p99: crate::renderer::tolerance::p99_error(image, reference),
    })
}

/// Median, smallest and largest of a sample (NaN for an empty one).
pub fn spread(values: &[f64]) -> (f64, f64, f64) {
    if values.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let median = if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    };
    (median, v[0], v[n - 1])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_of_a_known_difference() {
        let reference = vec![[0.5f32, 0.5, 0.5, 1.0]; 6];
        let mut image = reference.clone();
        image[4] = [0.5, 0.8, 0.5, 1.0];
        image[1] = [f32::NAN, 0.5, 0.5, 1.0];
        let e = image_error(&image, &reference, 3).expect("same size");
        // One channel off by 0.3 among 5 finite pixels × 3 channels.
        let rmse = (0.3f64 * 0.3 / 15.0).sqrt();
        assert!((e.rmse - rmse).abs() < 1e-7, "{e:?}");
        assert!((e.max_abs - 0.3).abs() < 1e-6);
        assert_eq!((e.max_x, e.max_y, e.non_finite), (1, 1, 1));
        assert!((e.psnr - (-20.0 * rmse.log10())).abs() < 1e-6);
        assert!(image_error(&image, &reference[..5], 3).is_none());
    }

    #[test]
    fn spread_of_odd_and_even_samples() {
        assert_eq!(spread(&[3.0, 1.0, 2.0]), (2.0, 1.0, 3.0));
        assert_eq!(spread(&[4.0, 1.0, 2.0, 3.0]), (2.5, 1.0, 4.0));
        assert!(spread(&[]).0.is_nan());
    }
}
