//! Splatting's bricks (issue 30 §2): which kernels a brick needs so that its sheets are the
//! undivided frame's.
//!
//! A brick's splatting frame composites a pixel's sheet k only where the sheet's midpoint on the
//! pixel's ray lies in the brick's kd cell ([`crate::splat::SplatSetup::owns`]), and then
//! composites the whole sheet: every kernel's share of it, the exact split between sheets that
//! the undivided frame uses. Every (pixel, sheet) is owned by one brick, so no kernel's share is
//! counted twice, and the bricks composited in visibility order composite the undivided frame's
//! sheets in its order: the images agree to f32 rounding (and within a brick early
//! termination acts alone, as for ray casting).
//!
//! A brick therefore needs every kernel that adds to a sheet it owns, which depends on the
//! view: kernel i adds to the sheets s0..=s1 of the pixels in its footprint box (`splat_project`),
//! and post-shaded isosurfaces read the sheets either side and the neighbouring pixels too.
//! [`SplatReach`] projects every kernel on the host (f64, for the frame's view, on an image
//! two pixels wider on every side so that a kernel f32 keeps at the image's border is not
//! lost) and bounds the points x(p, k) = o_p + m_k·d_p (m_k the midpoint of sheet k) over those
//! pixels and sheets, widened by a pixel and a sheet for f32's rounding of the box and range:
//! the brick takes every kernel whose bound meets its cell. For a perspective camera the
//! points lie in the hull of the corner rays' points at the first and last midpoint, but for
//! a bulge of at most m·(1 − cos θ) (θ the widest angle between a corner ray and the central
//! one), which the bound adds.
//!
//! A brick's frame draws its kernels only where it can own sheets: on the pixels whose rays
//! meet its cell and the sheets whose midpoints can lie in it (`SplatSetup::window`, with the
//! apron post-shaded isosurfaces read): a ghost kernel's entries elsewhere would add only to
//! sheets other bricks own.

use super::Aabb;
use crate::field::Field;
use crate::splat::SplatSetup;
use crate::splat::project::splat_project;
use crate::splat::raster::kernel;
use crate::view::View;
use crate::view::camera::{Camera, Projection};
use glam::DVec3;
use rayon::prelude::*;

/// Pixels the host's projection adds on each side of the image.
const BORDER: u32 = 2;

/// Per kernel of a field, the box of the points whose sheets it can add to in one view (none
/// for a kernel the view culls).
#[derive(Debug, Clone)]
pub struct SplatReach {
    boxes: Vec<Option<Aabb>>,
}

impl SplatReach {
    /// Projects every kernel of `field` for `view` (a splatting view; `field` the whole field).
    pub fn new(field: &Field, view: &View<'_>) -> Result<Self, crate::field::RenderError> {
        Self::of_first(field, view, field.samples.len())
    }

    /// Projects the first `n` kernels of `field` for `view`: `field` a piece that keeps the
    /// whole field's frame (its sheets), and those kernels its own.
    pub fn of_first(
        field: &Field,
        view: &View<'_>,
        n: usize,
    ) -> Result<Self, crate::field::RenderError> {
        let Some(shading) = view.settings.method.splat_shading() else {
            return Err(crate::field::RenderError::Setting {
                key: "render.method",
                message: "a splatting brick's kernels are chosen for a splatting view".into(),
            });
        };
        let wide = widened(view.camera);
        let setup = SplatSetup::new(
            shading,
            &view.settings.splat,
            &wide,
            view.settings.early_termination,
            [0.0; 3],
            view.isosurfaces,
            view.lighting,
            field,
        )?;
        // What compositing a sheet reads around it (SplatSetup::reach).
        let (pixels, sheets) = setup.reach();
        let boxes = (0..n.min(field.samples.len()))
            .into_par_iter()
            .map(|i| {
                let splat = splat_project(&setup, view.transfer, &kernel(field, i)).ok()?;
                let b = BORDER as i32;
                let [x0, y0, x1, y1] = splat.bbox;
                let first = i64::from(splat.slabs[0]) - sheets[0];
                let last = i64::from(splat.slabs[1]) + sheets[1];
                reach_box(
                    view.camera,
                    &setup,
                    [
                        x0 - b - pixels,
                        y0 - b - pixels,
                        x1 - b + pixels,
                        y1 - b + pixels,
                    ],
                    (first, last),
                )
            })
            .collect();
        Ok(Self { boxes })
    }

    /// Whether kernel i adds to a sheet whose midpoint can lie in `cell` (closed).
    pub fn meets(&self, i: usize, (lo, hi): Aabb) -> bool {
        self.boxes[i].is_some_and(|(a, b)| (0..3).all(|k| b[k] >= lo[k] && a[k] <= hi[k]))
    }
}

/// `camera` with [`BORDER`] more pixels on every side and the same pixels per unit: pixel
/// (x, y) of `camera` is (x + BORDER, y + BORDER) of the result.
fn widened(camera: &Camera) -> Camera {
    let (w, h) = (camera.width + 2 * BORDER, camera.height + 2 * BORDER);
    let scale = f64::from(h) / f64::from(camera.height);
    let projection = match camera.projection {
        Projection::Perspective { fov_y_degrees } => Projection::Perspective {
            fov_y_degrees: 2.0
                * ((fov_y_degrees.to_radians() * 0.5).tan() * scale)
                    .atan()
                    .to_degrees(),
        },
        Projection::Orthographic { view_height } => Projection::Orthographic {
            view_height: view_height * scale,
        },
    };
    Camera {
        width: w,
        height: h,
        projection,
        ..*camera
    }
}

/// The box of o_p + m_k·d_p over the pixels of `bbox` and the sheets `first ..= last` (both
/// clamped to the frame's), `camera` the frame's camera; none where they are empty.
fn reach_box(
    camera: &Camera,
    setup: &SplatSetup,
    bbox: [i32; 4],
    (first, last): (i64, i64),
) -> Option<Aabb> {
    let (w, h) = (camera.width as i32, camera.height as i32);
    let [x0, y0] = [bbox[0].max(0), bbox[1].max(0)];
    let [x1, y1] = [bbox[2].min(w - 1), bbox[3].min(h - 1)];
    let (k0, k1) = (first.max(0), last.min(i64::from(setup.slabs) - 1));
    if x0 > x1 || y0 > y1 || k0 > k1 {
        return None;
    }
    let mid = |k: i64| setup.slab0 + (k as f64 + 0.5) * setup.slab_world;
    let (m0, m1) = (mid(k0), mid(k1));
    let rays = [(x0, y0), (x1, y0), (x0, y1), (x1, y1)]
        .map(|(x, y)| camera.ray(&setup.basis, setup.frame_origin, x as u32, y as u32));
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for (o, d) in rays {
        for m in [m0, m1] {
            lo = lo.min(o + m * d);
            hi = hi.max(o + m * d);
        }
    }
    // Perspective rays fan out from the eye: the midpoints between the corner rays bulge past
    // the corners' hull by at most m1·(1 − cos θ).
    let centre = rays.iter().map(|r| r.1).sum::<DVec3>().normalize_or_zero();
    let cos = rays.iter().map(|r| r.1.dot(centre)).fold(1.0, f64::min);
    let bulge = m1.abs() * (1.0 - cos).max(0.0);
    Some(((lo - bulge).to_array(), (hi + bulge).to_array()))
}
