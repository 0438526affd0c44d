//! Shaded isosurfaces: f64 twin of `shade_surface` in `glsl/common/shading.glsl`.
//!
//! An isosurface is a Dirac spike in the transfer function (DESIGN §4): where a ray crosses
//! f = value it composites `color` with `opacity`, lit by Blinn–Phong with a headlight (light and
//! viewer along the ray, so the half vector is the light vector) and two-sided normals
//! n = ∇f/|∇f|: rgb = color·(ambient + diffuse·|n·l|) + specular·|n·l|^shininess.

use crate::gpu_types::IsoSurface;
use glam::DVec3;

/// At most this many isosurfaces per scene (a fixed loop in the kernel).
pub const MAX_ISOSURFACES: usize = 4;

/// One isosurface of `[transfer] isosurfaces`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Isosurface {
    pub value: f64,
    pub color: [f64; 3],
    pub opacity: f64,
}

/// `[lighting]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lighting {
    pub ambient: f64,
    pub diffuse: f64,
    pub specular: f64,
    pub shininess: f64,
}

impl Default for Lighting {
    fn default() -> Self {
        Self {
            ambient: 0.25,
            diffuse: 0.75,
            specular: 0.35,
            shininess: 32.0,
        }
    }
}

/// Premultiplied colour of a surface hit along unit direction `dir` with gradient `gradient`.
/// A vanishing gradient (a flat critical point) is lit as if facing the viewer.
pub fn shade_surface(
    iso: &Isosurface,
    light: &Lighting,
    gradient: [f64; 3],
    dir: DVec3,
) -> [f64; 3] {
    let g = DVec3::from(gradient);
    let cos = if g.length() > 1e-12 {
        g.normalize().dot(-dir).abs()
    } else {
        1.0
    };
    shade_cos(iso, light, cos)
}

/// The same shading from |n·l| directly (surface splats know it, not the normal).
pub fn shade_cos(iso: &Isosurface, light: &Lighting, cos: f64) -> [f64; 3] {
    let lit = light.ambient + light.diffuse * cos;
    let spec = light.specular * cos.powf(light.shininess);
    [0, 1, 2].map(|k| iso.opacity * (iso.color[k] * lit + spec))
}

/// The isosurfaces as kernels read them; never empty, since a zero-sized binding is invalid
/// (the kernel constants say how many are real).
pub fn iso_buffer_data(isosurfaces: &[Isosurface]) -> Vec<IsoSurface> {
    let mut isos: Vec<IsoSurface> = isosurfaces
        .iter()
        .map(|i| IsoSurface {
            color_opacity: [
                i.color[0] as f32,
                i.color[1] as f32,
                i.color[2] as f32,
                i.opacity as f32,
            ],
            value: i.value as f32,
            _pad: [0.0; 3],
        })
        .collect();
    if isos.is_empty() {
        isos.push(IsoSurface::default());
    }
    isos
}

/// A splatted pixel (premultiplied colour C, opacity α) over the background: (C + (1 − α)·bg,
/// α), in f32 without a fused multiply-add, as `render()` returns it and `target_pack` (twin:
/// `renderer::target`) writes it with `push.composite` = 1.
pub fn composite_background(p: [f32; 4], background: [f32; 3]) -> [f32; 4] {
    let t = 1.0 - p[3];
    [
        p[0] + t * background[0],
        p[1] + t * background[1],
        p[2] + t * background[2],
        p[3],
    ]
}
