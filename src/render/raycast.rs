//! Emission–absorption ray casting, f64 CPU twin of `glsl/raycast.comp` (stage `raycast`).
//!
//! Per ray: clip to the sample box, then n = ⌈L/δ⌉ midpoint steps of length δ (the last one
//! shortened to end at the exit); per step a = 1 − exp(−τ(s)·δ), C += T·a·c(s), T *= 1 − a;
//! stop when T < min_transmittance. Where no sample has weight the field is undefined and the
//! step adds nothing. Pixel = (C + T·background, 1 − T).

use super::camera::clip_box;
use super::transfer::TransferFunction;
use super::{Field, RaySetup};
use crate::recon::mls::{Neighbours, mls_evaluate};

/// One pixel of the reference integrator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelResult {
    pub rgba: [f64; 4],
    /// MLS evaluations spent on this ray.
    pub evaluations: u32,
}

/// Integrates the ray through pixel (px, py).
pub fn raycast(
    setup: &RaySetup,
    field: &Field,
    neighbours: &dyn Neighbours,
    tf: &TransferFunction,
    px: u32,
    py: u32,
) -> PixelResult {
    let (o, d) = setup.camera.ray(&setup.basis, setup.frame_origin, px, py);
    let mls = field.mls();
    let mut color = [0.0f64; 3];
    let mut transmittance = 1.0f64;
    let mut evaluations = 0u32;
    if let Some((t0, t1)) = clip_box(o, d, setup.box_lo, setup.box_hi) {
        let steps = ((t1 - t0) / setup.step).ceil() as u64;
        for i in 0..steps {
            let ta = t0 + i as f64 * setup.step;
            let dt = setup.step.min(t1 - ta);
            if dt <= 0.0 {
                break;
            }
            let x = o + d * (ta + 0.5 * dt);
            evaluations += 1;
            let Some(m) = mls_evaluate(&mls, neighbours, x.to_array()) else {
                continue;
            };
            let (c, tau) = tf.lookup(m.value);
            let a = 1.0 - (-tau * dt).exp();
            for (acc, ci) in color.iter_mut().zip(c) {
                *acc += transmittance * a * ci;
            }
            transmittance *= 1.0 - a;
            if transmittance < setup.min_transmittance {
                break;
            }
        }
    }
    let bg = setup.background;
    PixelResult {
        rgba: [
            color[0] + transmittance * bg[0],
            color[1] + transmittance * bg[1],
            color[2] + transmittance * bg[2],
            1.0 - transmittance,
        ],
        evaluations,
    }
}

/// Renders the whole image on the CPU (rows split over the available cores).
pub fn raycast_image(setup: &RaySetup, field: &Field, tf: &TransferFunction) -> Vec<PixelResult> {
    let w = setup.camera.width as usize;
    let h = setup.camera.height as usize;
    let mut out = vec![
        PixelResult {
            rgba: [0.0; 4],
            evaluations: 0
        };
        w * h
    ];
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let rows_per = h.div_ceil(threads).max(1);
    std::thread::scope(|scope| {
        for (chunk_index, chunk) in out.chunks_mut(rows_per * w).enumerate() {
            scope.spawn(move || {
                let neighbours = field.neighbours();
                for (k, px) in chunk.iter_mut().enumerate() {
                    let index = chunk_index * rows_per * w + k;
                    *px = raycast(
                        setup,
                        field,
                        neighbours.as_ref(),
                        tf,
                        (index % w) as u32,
                        (index / w) as u32,
                    );
                }
            });
        }
    });
    out
}
