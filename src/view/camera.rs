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

    /// The pixels [x0, y0, x1, y1] (inclusive) whose rays can meet the box `(lo, hi)`
    /// (frame-relative): the bounding box of its corners' projections, a pixel wider on every
    /// side; the whole image where a corner lies on or behind a perspective eye's plane (the
    /// projection of a box in front of the eye is the hull of its corners' projections, and
    /// rays start at the eye).
    pub fn pixel_box(
        &self,
        basis: &ViewBasis,
        frame_origin: DVec3,
        (lo, hi): (DVec3, DVec3),
    ) -> [u32; 4] {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        let whole = [
            0,
            0,
            self.width.saturating_sub(1),
            self.height.saturating_sub(1),
        ];
        let eye = DVec3::from(self.eye) - frame_origin;
        let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for c in 0..8 {
            let corner = DVec3::new(
                if c & 1 == 0 { lo.x } else { hi.x },
                if c & 2 == 0 { lo.y } else { hi.y },
                if c & 4 == 0 { lo.z } else { hi.z },
            );
            let d = corner - eye;
            // The screen coordinates sx, sy in [-1, 1] of `ray`'s convention.
            let (sx, sy) = match self.projection {
                Projection::Perspective { fov_y_degrees } => {
                    let depth = d.dot(basis.forward);
                    if depth <= 0.0 {
                        return whole;
                    }
                    let t = (fov_y_degrees.to_radians() * 0.5).tan();
                    (
                        d.dot(basis.right) / depth / (t * w / h),
                        d.dot(basis.up) / depth / t,
                    )
                }
                Projection::Orthographic { view_height } => {
                    let hh = 0.5 * view_height;
                    (d.dot(basis.right) / (hh * w / h), d.dot(basis.up) / hh)
                }
            };
            let (px, py) = ((sx + 1.0) * 0.5 * w - 0.5, (1.0 - sy) * 0.5 * h - 0.5);
            (x0, y0, x1, y1) = (x0.min(px), y0.min(py), x1.max(px), y1.max(py));
        }
        let clamp = |v: f64, n: u32| v.clamp(0.0, f64::from(n.saturating_sub(1))) as u32;
        let (x0, x1) = ((x0 - 1.0).floor(), (x1 + 1.0).ceil());
        let (y0, y1) = ((y0 - 1.0).floor(), (y1 + 1.0).ceil());
        if !(x0.is_finite() && y0.is_finite() && x1.is_finite() && y1.is_finite()) {
            return whole;
        }
        [
            clamp(x0, self.width),
            clamp(y0, self.height),
            clamp(x1, self.width),
            clamp(y1, self.height),
        ]
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
    fn a_boxs_pixel_box_holds_every_pixel_whose_ray_meets_it() {
        let boxes = [
            (DVec3::new(-0.3, -0.2, -0.1), DVec3::new(0.1, 0.4, 0.3)),
            (DVec3::new(0.2, -0.9, -0.9), DVec3::new(0.9, -0.5, 0.0)),
            (DVec3::new(-1.0, -1.0, -1.0), DVec3::new(-0.6, 1.0, -0.7)),
        ];
        let perspective = Projection::Perspective {
            fov_y_degrees: 40.0,
        };
        let orthographic = Projection::Orthographic { view_height: 2.6 };
        for (projection, eye) in [
            (perspective, [2.5, 1.5, 2.0]),
            (orthographic, [2.5, 1.5, 2.0]),
            (perspective, [0.0, 0.0, 4.0]),
        ] {
            let cam = Camera {
                eye,
                target: [0.0; 3],
                up: [0.0, 1.0, 0.0],
                projection,
                width: 61,
                height: 47,
            };
            let basis = cam.basis().expect("basis");
            for b in boxes {
                let [x0, y0, x1, y1] = cam.pixel_box(&basis, DVec3::ZERO, b);
                let mut hits = 0;
                for y in 0..cam.height {
                    for x in 0..cam.width {
                        let (o, d) = cam.ray(&basis, DVec3::ZERO, x, y);
                        if clip_box(o, d, b.0, b.1).is_some() {
                            hits += 1;
                            assert!(
                                (x0..=x1).contains(&x) && (y0..=y1).contains(&y),
                                "{projection:?}: pixel ({x}, {y}) outside {:?}",
                                [x0, y0, x1, y1]
                            );
                        }
                    }
                }
                assert!(hits > 0, "{b:?} is seen");
                // Tight: at most the hits' own box and its one-pixel margin, far from all.
                let area = (x1 - x0 + 1) * (y1 - y0 + 1);
                assert!(area < cam.width * cam.height / 2, "{b:?}: {area} pixels");
            }
        }
        // A box around the eye: every pixel.
        let cam = Camera {
            eye: [0.0, 0.0, 0.0],
            target: [0.0, 0.0, -1.0],
            up: [0.0, 1.0, 0.0],
            projection: Projection::Perspective {
                fov_y_degrees: 40.0,
            },
            width: 10,
            height: 8,
        };
        let basis = cam.basis().expect("basis");
        let around = (DVec3::splat(-1.0), DVec3::splat(1.0));
        assert_eq!(cam.pixel_box(&basis, DVec3::ZERO, around), [0, 0, 9, 7]);
    }

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
