//! Surface splats for isosurfaces in pre-shaded splatting (`splat.surface = true`, [EWA] §6:
//! a kernel flattened along the normal becomes Heckbert's EWA texture filter).
//!
//! For every isosurface value v and every sample within half a sample spacing of the surface
//! (|f_i − v| < ½·Δ·|∇f_i|, the gradient from the scene's reconstruction at the sample), one
//! surface kernel is made:
//! - at the first-order surface point x_i + (v − f_i)∇f/|∇f|² (one Newton step);
//! - with metric M_s = a·(I + (R² − 1)·nnᵀ), n = ∇f/|∇f|: the sample's own Gaussian
//!   (a = its mean metric eigenvalue) in the tangent plane, R = `FLATNESS` times thinner along n;
//! - standing for the area A = v_i/Δ (the band of thickness Δ around the surface holds one
//!   sample per volume v_i, so Δ/v_i per unit area), so that on a fully covered surface the footprints add up to W = Σ A·|n·d|·q ≈ 1 (a
//!   ray crosses a layer of unit areal density over a length 1/|n·d|; `splat_project` multiplies
//!   the weight by |n·d|).
//!
//! `splat_raster` then composites each sheet's surface before its volume: coverage
//! c = min(W, 1), opacity (Σ q·α_iso / W)·c and premultiplied colour (Σ q·rgb / W)·c, where rgb is
//! the ray caster's Blinn–Phong shading with |n·d| from the flattened metric
//! ((n·d)² = (dᵀM_s d / a − 1)/(R² − 1)), so no normal needs storing.

use super::project::{FLATNESS, Kernel, KernelKind};
use crate::field::Field;
use crate::view::shading::Isosurface;
use rayon::prelude::*;

/// The surface kernels of a field's isosurfaces (frame-relative), in isosurface order.
pub fn surface_kernels(
    field: &Field,
    isosurfaces: &[Isosurface],
) -> Result<Vec<Kernel>, crate::recon::ReconError> {
    if isosurfaces.is_empty() {
        return Ok(Vec::new());
    }
    let volumes = field.kernel_volumes();
    let band = field.min_spacing();
    let s = &field.samples;
    let neighbours = field.evaluator()?;
    let gradients: Vec<Option<[f64; 3]>> = (0..s.len())
        .into_par_iter()
        .map(|i| {
            field
                .evaluate(neighbours.as_ref(), s.position(i))
                .map(|v| v.gradient)
        })
        .collect();
    let mut out = Vec::new();
    for (iso_index, iso) in isosurfaces.iter().enumerate() {
        for (i, g) in gradients.iter().enumerate() {
            let Some(g) = g else { continue };
            let len2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
            let f = f64::from(s.values.get(i));
            if len2 <= 0.0 || !len2.is_finite() || (f - iso.value).abs() >= 0.5 * band * len2.sqrt()
            {
                continue;
            }
            let len = len2.sqrt();
            let n = g.map(|c| c / len);
            let step = (iso.value - f) / len2;
            let x = s.position(i);
            let m = s.metric(i);
            // The mean eigenvalue of the sample's metric: its Gaussian's tangential size.
            let a = (m[0] + m[1] + m[2]) / 3.0;
            let b = a * (FLATNESS * FLATNESS - 1.0);
            out.push(Kernel {
                position: [x[0] + step * g[0], x[1] + step * g[1], x[2] + step * g[2]],
                value: iso.value,
                metric: [
                    a + b * n[0] * n[0],
                    a + b * n[1] * n[1],
                    a + b * n[2] * n[2],
                    b * n[0] * n[1],
                    b * n[0] * n[2],
                    b * n[1] * n[2],
                ],
                volume: volumes.get(i) / band,
                kind: KernelKind::Surface {
                    iso: iso_index as u32,
                    scale: a,
                },
            });
        }
    }
    Ok(out)
}
