//! The fast path as a field holds it (DESIGN §7, issue 11 §4, issue 27 §1): its lattice (a
//! regular grid's points, or a lattice over irregular data), the fine grid built on it
//! ([`ResampledGrid`], computed here in f64 for the CPU twins; the GPU builds its own in
//! `super::resample`), what "auto" chose and why, and the skipping blocks read from it.

use super::{Field, skip};
use crate::recon::ReconError;
use crate::recon::ReconMethod;
use crate::recon::mls::{MlsSettings, MlsValue, Neighbours, mls_evaluate_margin};
use crate::recon::pages::{Constants, Pages, grid_reach, scattered_reach};
use crate::recon::resample::{
    AUTO_FACTOR, AUTO_MAX_POINTS, DIRECT_MARGIN, DIRECT_TERMS, FINE_POINT_DEVICE_BYTES, Lattice,
    MAX_LATTICE_POINTS, MAX_POINTS, PilotError, ResampledGrid, fine_dims,
};
use crate::samples::{Positions, Supports};

impl Field {
    /// `reconstruction.resample = "auto"` as the field sees it: [`AUTO_FACTOR`] where the
    /// fast path serves and its fine grid stores at most [`AUTO_MAX_POINTS`] points (device
    /// memory and a first-frame build both grow with them); on irregular data where that grid
    /// does not fit, [`AUTO_FACTOR`] over a coarser lattice, as fine as the cap admits (fine
    /// points between half the median nearest-sample spacing and that spacing), and failing
    /// that the lattice itself (factor 1: fine points at the samples' spacing); the scene's
    /// pilot then judges either as it judges factor 2's; else 0 with the reason kept for
    /// `--stats`. The scene weighs the first frame and a pilot after this
    /// (`Scene::fit_fast_path`).
    pub(super) fn resolve_auto_resample(&mut self) {
        if !self.reconstruction.resample_auto {
            return;
        }
        self.reconstruction.resample_auto = false;
        let irregular = self.grid().is_none();
        let dense = self.lattice().fine_points(AUTO_FACTOR);
        let scale = cap_scale(dense, AUTO_MAX_POINTS);
        match auto_factor(irregular, scale, |f, c| {
            self.set_lattice_scale(c);
            self.auto_fits(f)
        }) {
            Ok((AUTO_FACTOR, _, None)) => {}
            Ok((factor, c, why)) => self.note_fast_path(format!(
                "factor {factor} over a lattice at {c:.3}× the samples' median spacing: at \
                 factor {AUTO_FACTOR} over their spacing, {}",
                why.unwrap_or_default()
            )),
            Err(why) => {
                self.set_lattice_scale(1.0);
                self.decline_fast_path(format!(
                    "\"auto\" declined the fast path: {why}; set reconstruction.resample = \
                     {AUTO_FACTOR} to take it anyway"
                ))
            }
        }
    }

    /// Sets the fast path's factor and says why "auto" cannot take it, if it cannot: its
    /// lattice or stored fine points past auto's bounds, or a refusal of `check_resample`.
    fn auto_fits(&mut self, factor: u32) -> Result<(), String> {
        self.reconstruction.resample = factor;
        self.pages = std::sync::OnceLock::new();
        // Past this many lattice points even a paged grid would have to store under a sixteenth
        // of them to fit; auto declines without reading every sample to classify its pages.
        let dense = self.lattice().fine_points(factor);
        if dense > 16 * AUTO_MAX_POINTS {
            return Err(format!(
                "its lattice has {dense} fine points, more than 16 times auto's \
                 {AUTO_MAX_POINTS} stored points"
            ));
        }
        self.check_resample().map_err(|e| e.to_string())?;
        let points = self.stored_fine_points();
        if points > AUTO_MAX_POINTS {
            let bytes = self.fine_device_bytes();
            return Err(format!(
                "its fine grid would hold {points} points ({bytes} bytes on the device, built in \
                 the first frame), more than auto's {AUTO_MAX_POINTS}"
            ));
        }
        Ok(())
    }

    /// Irregular data's fast-path lattice at `scale` times the samples' median spacing (what
    /// "auto" sets past its cap; 1 otherwise), before anything used the fine grid. A regular
    /// grid's lattice is its own points whatever the scale.
    pub fn set_lattice_scale(&mut self, scale: f64) {
        self.lattice_scale = scale;
        self.pages = std::sync::OnceLock::new();
        self.resampled = std::sync::OnceLock::new();
        self.blocks = std::sync::OnceLock::new();
    }

    /// Solves the fast path's cells around barely determined fits directly, or not
    /// (`Reconstruction::resample_direct`), before anything used the fine grid: MLS only (the
    /// other methods have no pivots).
    pub fn set_resample_direct(&mut self, on: bool) {
        self.reconstruction.resample_direct = on && self.reconstruction.method == ReconMethod::Mls;
        self.resampled = std::sync::OnceLock::new();
        self.blocks = std::sync::OnceLock::new();
    }

    /// Records what "auto" chose beyond the default factor, for `--stats` (after any note
    /// before it).
    pub fn note_fast_path(&mut self, note: String) {
        self.fast_path_note = Some(match self.fast_path_note.take() {
            Some(before) => format!("{before}; {note}"),
            None => note,
        });
    }

    /// Turns the fast path off before anything used it, recording why for `--stats` (the
    /// scene's "auto" rule for the first frame, [`crate::scene::Scene::frame_evaluations`]).
    pub fn decline_fast_path(&mut self, why: String) {
        self.reconstruction.resample = 0;
        self.reconstruction.resample_direct = false;
        self.fast_path_declined = Some(why);
        self.resampled = std::sync::OnceLock::new();
        self.pages = std::sync::OnceLock::new();
        self.blocks = std::sync::OnceLock::new();
    }

    /// The fast path as `--stats` states it: its factor, the lattice's fine points, the points
    /// it stores (fewer where it is paged, with its pages) and their device bytes, or why
    /// `"auto"` declined it.
    pub fn fast_path(&self) -> serde_json::Value {
        let factor = self.reconstruction.resample;
        match Some(self.lattice()).filter(|_| factor > 0) {
            Some(l) => {
                let mut v = serde_json::json!({
                    "factor": factor,
                    "fine_points": l.fine_points(factor),
                    "stored_points": self.stored_fine_points(),
                    "device_bytes": self.fine_device_bytes(),
                    "direct_cells": self.reconstruction.resample_direct,
                });
                if let Some(n) = &self.fast_path_note {
                    v["note"] = serde_json::json!(n);
                }
                if let Some(p) = self.fine_pages() {
                    v["pages"] = serde_json::json!({
                        "pages": p.table.len(),
                        "slots": p.slots.len(),
                        "solved_points": p.solved_points(),
                    });
                }
                v
            }
            None => serde_json::json!({
                "factor": 0,
                "declined": self.fast_path_declined,
            }),
        }
    }

    /// The fast path's page table ([`crate::recon::pages`]), classified once: `None` without
    /// the fast path, for the generator's exact field, and where the dense fine grid is kept.
    pub fn fine_pages(&self) -> Option<&Pages> {
        let factor = self.reconstruction.resample;
        if factor == 0 {
            return None;
        }
        self.pages
            .get_or_init(|| self.classify_pages(factor))
            .as_ref()
    }

    /// Stage `resample_pages`: each page's slot from the samples whose supports reach it.
    fn classify_pages(&self, factor: u32) -> Option<Pages> {
        let constants = match self.reconstruction.method {
            ReconMethod::Mls => Constants::Any,
            ReconMethod::Gaussian => Constants::Zero,
            ReconMethod::Exact => return None,
        };
        let l = self.lattice();
        let fine = fine_dims(l.dims, factor);
        let value = |i: usize| f64::from(self.samples.values.get(i));
        let (reach, constants) = match (&self.samples.positions, &self.samples.supports) {
            (Positions::Grid { dims, spacing, .. }, Supports::Uniform(h)) => {
                let r: [f64; 3] = std::array::from_fn(|a| h[a] / spacing[a]);
                // A cell's centre is the point furthest from its corners: inside their supports
                // (ρ < 1) the whole box is defined, else a page reached by one value may still
                // hold undefined points.
                let centre: f64 = (0..3)
                    .filter(|&a| dims[a] > 1)
                    .map(|a| (0.5 / r[a]).powi(2))
                    .sum();
                let constants = if centre < 1.0 {
                    constants
                } else {
                    Constants::Never
                };
                (grid_reach(*dims, fine, factor, r, value), constants)
            }
            _ => {
                // Each support's box, widened a millionth: the kernels' f32 positions may fall
                // inside a support whose f64 box just misses a page.
                let step = l.spacing.map(|s| s / f64::from(factor));
                let samples = (0..self.samples.len()).map(|i| {
                    let e = self.samples.support_extent(i).map(|e| e * (1.0 + 1e-6));
                    (self.samples.position(i), e, value(i))
                });
                let reach = scattered_reach(fine, l.origin, step, samples);
                (reach, Constants::Never)
            }
        };
        Pages::classify(fine, &reach, constants)
    }

    /// Points the fast path's fine grid stores (0 without it): the lattice's, or the pool's
    /// where it is paged.
    pub fn stored_fine_points(&self) -> u64 {
        let factor = self.reconstruction.resample;
        match self.fine_pages() {
            Some(p) => p.points(),
            None if factor > 0 => self.lattice().fine_points(factor),
            None => 0,
        }
    }

    /// Points `recon_resample` solves (0 without the fast path): a paged grid's shared slots are
    /// filled, not solved.
    pub fn solved_fine_points(&self) -> u64 {
        match self.fine_pages() {
            Some(p) => p.solved_points(),
            None => self.stored_fine_points(),
        }
    }

    /// Device bytes of the fine grid and its page table.
    pub fn fine_device_bytes(&self) -> u64 {
        let table = self.fine_pages().map_or(0, |p| p.table.len() as u64 * 4);
        self.stored_fine_points() * FINE_POINT_DEVICE_BYTES + table
    }

    /// The coarse grid the fast path refines: a regular grid's points, or for irregular data a
    /// lattice over the domain's box at the median nearest-sample spacing (the unit of
    /// `render.step`, [`crate::samples::SampleSet::spacing`]).
    pub fn lattice(&self) -> Lattice {
        match &self.samples.positions {
            Positions::Grid {
                dims,
                origin,
                spacing,
            } => Lattice {
                dims: *dims,
                origin: *origin,
                spacing: *spacing,
            },
            Positions::Scattered(_) => {
                let (lo, hi) = self.samples.domain_box();
                let spacing = self.lattice_scale * self.samples.spacing;
                Lattice::covering(lo, hi, spacing.max(f64::MIN_POSITIVE))
            }
        }
    }

    /// The fast path needs a lattice of at most [`MAX_LATTICE_POINTS`] fine points, and a fine
    /// grid (dense, or paged where that stores fewer) of at most [`MAX_POINTS`].
    pub(super) fn check_resample(&self) -> Result<(), ReconError> {
        let factor = self.reconstruction.resample;
        let lattice = self.lattice();
        let [x, y, z] = lattice.dims;
        let points = lattice.fine_points(factor);
        if points > MAX_LATTICE_POINTS {
            return Err(ReconError::Setting {
                key: "reconstruction.resample",
                value: format!("{factor} ({points} fine points for a {x}x{y}x{z} lattice)"),
                expected: "a factor giving at most 2^33 fine points over the lattice",
            });
        }
        let stored = self.stored_fine_points();
        if stored > MAX_POINTS {
            return Err(ReconError::Setting {
                key: "reconstruction.resample",
                value: format!("{factor} ({stored} fine points stored for a {x}x{y}x{z} lattice)"),
                expected: "a factor giving at most 2^27 stored fine points (2 GiB)",
            });
        }
        Ok(())
    }

    /// The fast path's fine grid (`None` unless `reconstruction.resample` > 0): the general
    /// path at every fine point of the lattice, computed here in f64 at first use (stage
    /// `recon_resample`). For irregular data it reads the octree, built here if it was
    /// deferred; `None` where that build fails (every CPU twin asks [`Field::evaluator`]
    /// first, which returns its error).
    pub fn resampled(&self) -> Option<&ResampledGrid> {
        let factor = self.reconstruction.resample;
        if factor == 0 {
            return None;
        }
        let neighbours = self.neighbours().ok()?;
        let l = self.lattice();
        Some(self.resampled.get_or_init(|| {
            let pages = self.fine_pages().cloned();
            ResampledGrid::build_paged(l.dims, l.origin, l.spacing, factor, pages, |x| {
                self.fine_point(neighbours.as_ref(), x)
            })
        }))
    }

    /// What the fine grid stores at x: the general path with the field's own derivative (the
    /// analytic gradient for MLS), since the fast path's interpolation needs ∇f, not the local
    /// fit's slope (twin of `recon_resample`'s variant).
    /// With `resample_direct`, a point whose margin is below [`DIRECT_MARGIN`] is marked
    /// [`DIRECT_TERMS`] (stored as [`crate::recon::resample::DIRECT`]).
    fn fine_point(&self, neighbours: &dyn Neighbours, x: [f64; 3]) -> Option<MlsValue> {
        match self.reconstruction.method {
            ReconMethod::Mls => {
                let analytic = MlsSettings {
                    gradient: crate::recon::GradientMode::Analytic,
                    ..self.mls()
                };
                let (v, margin) = mls_evaluate_margin(&analytic, neighbours, x)?;
                Some(
                    if self.reconstruction.resample_direct && margin < DIRECT_MARGIN {
                        MlsValue {
                            terms: DIRECT_TERMS,
                            ..v
                        }
                    } else {
                        v
                    },
                )
            }
            _ => self.evaluate_direct(neighbours, x),
        }
    }

    /// [`crate::recon::resample::pilot_error`] at `points` (frame-relative); `None` without
    /// the fast path, where its octree cannot be built, or where no point is defined.
    pub fn fast_path_pilot(&self, points: &[[f64; 3]]) -> Option<PilotError> {
        let factor = self.reconstruction.resample;
        if factor == 0 {
            return None;
        }
        let neighbours = self.neighbours().ok()?;
        let (lo, hi) = self.value_range();
        crate::recon::resample::pilot_error(
            &self.lattice(),
            factor,
            points,
            |x| self.fine_point(neighbours.as_ref(), x),
            |x| self.evaluate_direct(neighbours.as_ref(), x),
            hi - lo,
        )
    }

    /// Value ranges of the fast field per skipping block (`None` without the fast path).
    pub fn blocks(&self) -> Option<&skip::Blocks> {
        let grid = self.resampled()?;
        Some(
            self.blocks
                .get_or_init(|| skip::Blocks::from_resampled(grid)),
        )
    }
}

/// The lattice scale at which `dense` fine points (factor [`AUTO_FACTOR`] over the samples'
/// spacing) shrink to at most `cap`: 1 where they fit, else their cube root's ratio with a
/// margin for the lattice's rounding up (whether it fits is still `auto_fits`'s to say).
fn cap_scale(dense: u64, cap: u64) -> f64 {
    if dense <= cap {
        1.0
    } else {
        (dense as f64 / cap as f64).cbrt() * 1.01
    }
}

/// The (factor, lattice scale) "auto" takes: ([`AUTO_FACTOR`], 1) where `fits` accepts it,
/// else on irregular data ([`AUTO_FACTOR`], `scale`) where `scale` stays below
/// [`AUTO_FACTOR`] (past it the fine points would be sparser than the samples) and `fits`
/// accepts it, else (1, 1) where `fits` accepts that (with the reason the first failed), else
/// the first reason. `fits` sets the factor and scale it is asked about; where one is
/// returned, the last call left it set.
fn auto_factor(
    irregular: bool,
    scale: f64,
    mut fits: impl FnMut(u32, f64) -> Result<(), String>,
) -> Result<(u32, f64, Option<String>), String> {
    let why = match fits(AUTO_FACTOR, 1.0) {
        Ok(()) => return Ok((AUTO_FACTOR, 1.0, None)),
        Err(why) => why,
    };
    if irregular {
        if scale > 1.0 && scale < AUTO_FACTOR as f64 && fits(AUTO_FACTOR, scale).is_ok() {
            return Ok((AUTO_FACTOR, scale, Some(why)));
        }
        if fits(1, 1.0).is_ok() {
            return Ok((1, 1.0, Some(why)));
        }
    }
    Err(why)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_coarsens_the_lattice_then_falls_back_to_it_on_irregular_data_only() {
        // Fits at factor 1, or at factor 2 over a lattice at least `min_scale` coarse.
        let fits_from = |min_scale: f64| {
            move |f: u32, c: f64| {
                if f == 1 || c >= min_scale {
                    Ok(())
                } else {
                    Err(format!("factor {f} at {c} too big"))
                }
            }
        };
        let refused = Some("factor 2 at 1 too big".to_string());
        assert_eq!(
            auto_factor(true, 1.0, |_, _| Ok(())),
            Ok((AUTO_FACTOR, 1.0, None))
        );
        assert_eq!(
            auto_factor(true, 1.3, fits_from(1.2)),
            Ok((AUTO_FACTOR, 1.3, refused.clone()))
        );
        // A scale that does not fit, or one at which the fine points would be sparser than
        // the samples, gives the lattice itself.
        assert_eq!(
            auto_factor(true, 1.3, fits_from(1.5)),
            Ok((1, 1.0, refused.clone()))
        );
        assert_eq!(
            auto_factor(true, 2.5, fits_from(1.5)),
            Ok((1, 1.0, refused.clone()))
        );
        assert_eq!(
            auto_factor(false, 1.3, fits_from(1.2)),
            Err("factor 2 at 1 too big".into())
        );
        assert_eq!(
            auto_factor(true, 1.3, |f, c| Err(format!("factor {f} at {c} too big"))),
            Err("factor 2 at 1 too big".into())
        );
        // Whatever it returns, the last factor and scale asked about are the ones returned.
        for (scale, min_scale) in [(1.3, 1.2), (1.3, 1.5), (1.0, 0.5)] {
            let mut last = (0, 0.0);
            let got = auto_factor(true, scale, |f, c| {
                last = (f, c);
                fits_from(min_scale)(f, c)
            });
            assert_eq!(got.map(|(f, c, _)| (f, c)), Ok(last));
        }
    }

    #[test]
    fn the_cap_scale_shrinks_the_fine_points_under_the_cap() {
        assert_eq!(cap_scale(1000, 1000), 1.0);
        let c = cap_scale(27_000, 1000);
        assert!(c > 3.0 && c < 3.1, "{c}");
        // A lattice whose spacing grows by c holds 1/c³ of the points, under the cap.
        assert!(27_000.0 / (c * c * c) <= 1000.0);
    }
}
