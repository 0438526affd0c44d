//! Cameras: f64 twin of `glsl/common/camera.glsl` (stages `camera_ray`, `clip_box`).
//!
//! Convention (the scene contract): forward = normalize(target − eye), right =
//! normalize(forward × up), up′ = right × forward; pixel (px, py), row 0 at the top,
//! dx = (2(px+½)/W − 1)·tan(fov_y/2)·W/H, dy = (1 − 2(py+½)/H)·tan(fov_y/2),
//! direction = normalize(forward + dx·right + dy·up′). Orthographic rays start on the plane
//! through the eye, offset by dx·(view_height/2)·W/H along right and dy·(view_height/2) along up′.

use crate::gpu_types::CameraBlock;
use glam::DVec3;

/// Perspective or orthographic projection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Projection {
    /// Full vertical angle in degrees.
    Perspective { fov_y_degrees: f64 },
    /// Height of the view in world units.
    Orthographic { view_height: f64 },
}

/// A pinhole or orthographic camera with its image size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub eye: [f64; 3],
    pub target: [f64; 3],
    pub up: [f64; 3],
    pub projection: Projection,
    pub width: u32,
    pub height: u32,
}

/// Orthonormal view frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewBasis {
    pub forward: DVec3,
    pub right: DVec3,
    pub up: DVec3,
}

impl Camera {
    /// The camera with its eye turned by `angle` radians about the up axis through the target.
    pub fn orbited(&self, angle: f64) -> Self {
        if angle == 0.0 {
            return *self;
        }
        let up = DVec3::from(self.up).normalize_or_zero();
        let target = DVec3::from(self.target);
        let offset = glam::DQuat::from_axis_angle(up, angle) * (DVec3::from(self.eye) - target);
        Self {
            eye: (target + offset).to_array(),
            ..*self
        }
    }

    /// The view frame, or why it does not exist.
    pub fn basis(&self) -> Result<ViewBasis, String> {
        let eye = DVec3::from(self.eye);
        let f = DVec3::from(self.target) - eye;
        if f.length() <= 1e-12 * (1.0 + eye.length()) {
            return Err("eye and target coincide".into());
        }
        let forward = f.normalize();
        let r = forward.cross(DVec3::from(self.up));
        if r.length() <= 1e-9 * DVec3::from(self.up).length().max(1e-300) {
            return Err("up is zero or parallel to the view direction".into());
        }
        let right = r.normalize();
        Ok(ViewBasis {
            forward,
            right,
            up: right.cross(forward),
        })
    }

    /// Ray through pixel (px, py) relative to `frame_origin`: (origin, unit direction).
    pub fn ray(&self, basis: &ViewBasis, frame_origin: DVec3, px: u32, py: u32) -> (DVec3, DVec3) {
        let w = f64::from(self.width);
        let h = f64::from(self.height);
        let sx = 2.0 * (f64::from(px) + 0.5) / w - 1.0;
        let sy = 1.0 - 2.0 * (f64::from(py) + 0.5) / h;
        let eye = DVec3::from(self.eye) - frame_origin;
        match self.projection {
            Projection::Perspective { fov_y_degrees } => {
                let t = (fov_y_degrees.to_radians() * 0.5).tan();
                let d = basis.forward + sx * t * w / h * basis.right + sy * t * basis.up;
                (eye, d.normalize())
            }
            Projection::Orthographic { view_height } => {
                let hh = 0.5 * view_height;
                let o = eye + sx * hh * w / h * basis.right + sy * hh * basis.up;
                (o, basis.forward)
            }
        }
    }

    /// `n` × `n` of the image's rays, spread evenly (one at the centre of each of n × n equal
    /// parts of the image, rounded to a pixel), relative to `frame_origin`: what the host's
    /// estimates before a frame look through (fast-path pilot and first-frame cost, skipping).
    pub fn sample_rays(
        &self,
        basis: &ViewBasis,
        frame_origin: DVec3,
        n: u32,
    ) -> impl Iterator<Item = (DVec3, DVec3)> + '_ {
        let (w, h) = (self.width.max(1), self.height.max(1));
        let at = move |i: u32, size: u32| {
            (((f64::from(i) + 0.5) * f64::from(size) / f64::from(n)) as u32).min(size - 1)
        };
        let basis = *basis;
        (0..n * n).map(move |k| self.ray(&basis, frame_origin, at(k % n, w), at(k / n, h)))
    }
}

/// Slab test against [lo, hi] with t0 ≥ 0; `None` when the ray misses. Axis-parallel rays are
/// handled explicitly.
pub fn clip_box(o: DVec3, d: DVec3, lo: DVec3, hi: DVec3) -> Option<(f64, f64)> {
    let mut t0: f64 = 0.0;
    let mut t1: f64 = 3.0e38;
    for a in 0..3 {
        if d[a].abs() < 1e-30 {
            if o[a] < lo[a] || o[a] > hi[a] {
                return None;
            }
        } else {
            let inv = 1.0 / d[a];
            let ta = (lo[a] - o[a]) * inv;
            let tb = (hi[a] - o[a]) * inv;
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
    }
    (t1 > t0).then_some((t0, t1))
}

impl Camera {
    /// The camera as the kernels read it ([`CameraBlock`], shared by both renderers), with the
    /// eye at `eye` (frame-relative) and the view frame `basis`.
    pub fn gpu_block(&self, basis: &ViewBasis, eye: DVec3) -> CameraBlock {
        let v = |d: DVec3| [d.x as f32, d.y as f32, d.z as f32, 0.0];
        let (projection, tan_half_fov, ortho_half_height) = match self.projection {
            Projection::Perspective { fov_y_degrees } => {
                (0, (fov_y_degrees.to_radians() * 0.5).tan() as f32, 0.0)
            }
            Projection::Orthographic { view_height } => (1, 0.0, (0.5 * view_height) as f32),
        };
        CameraBlock {
            eye: v(eye),
            forward: v(basis.forward),
            right: v(basis.right),
            up: v(basis.up),
            width: self.width,
            height: self.height,
            projection,
            tan_half_fov,
            ortho_half_height,
            _pad: [0.0; 3],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_pixel_looks_at_target() {
        let cam = Camera {
            eye: [3.0, 2.0, 2.5],
            target: [0.0; 3],
            up: [0.0, 0.0, 1.0],
            projection: Projection::Perspective {
                fov_y_degrees: 30.0,
            },
            width: 3,
            height: 3,
        };
        let b = cam.basis().unwrap();
        let (_, d) = cam.ray(&b, DVec3::ZERO, 1, 1);
        assert!((d - b.forward).length() < 1e-12);
        // Row 0 is the top: its ray points more along up′ than the centre's.
        let (_, top) = cam.ray(&b, DVec3::ZERO, 1, 0);
        assert!(top.dot(b.up) > 0.0);
        let (_, right) = cam.ray(&b, DVec3::ZERO, 2, 1);
        assert!(right.dot(b.right) > 0.0);
    }

    #[test]
    fn clip_parallel_and_miss() {
        let lo = DVec3::splat(-1.0);
        let hi = DVec3::splat(1.0);
        let (t0, t1) = clip_box(DVec3::new(-5.0, 0.0, 0.0), DVec3::X, lo, hi).unwrap();
        assert!((t0 - 4.0).abs() < 1e-12 && (t1 - 6.0).abs() < 1e-12);
        assert!(clip_box(DVec3::new(-5.0, 2.0, 0.0), DVec3::X, lo, hi).is_none());
        // Starting inside: t0 clamps to 0.
        let (t0, t1) = clip_box(DVec3::ZERO, DVec3::Z, lo, hi).unwrap();
        assert!(t0 == 0.0 && (t1 - 1.0).abs() < 1e-12);
    }
}
