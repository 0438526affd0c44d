//! Rendering to a tolerance (issue 29 §1): with `render.tolerance = E` the renderer chooses
//! the parameters that bound a frame's error, so that the frame meets E without tuning.
//!
//! # What E bounds
//! The error of a pixel is the largest absolute difference over its four channels — colour
//! premultiplied and composited over the background, as [`Renderer::render`] returns it, and
//! opacity — from the converged image of the same field (the same reconstruction, integrated
//! with a vanishing step and no early termination). E bounds its 99th percentile over the
//! frame's pixels ([`p99_error`]).
//!
//! # How the parameters follow from E
//! E is shared out: E/2 to the discretization of the integral along a ray, E/4 to early ray
//! termination, E/4 to the preintegration tables' resolution.
//! - **Early termination**: a ray that stops at transmittance T would have gained at most T
//!   in any channel from the rest of the ray (colours, opacities and background lie in [0, 1]),
//!   so the threshold is opacity 1 − E/4 (`render.early_termination`; the reference and
//!   midpoint integrators stop at transmittance E/4, `render.min_transmittance`).
//! - **Discretization**: a ladder of pilot frames ([`PILOT_EDGE`] pixels on the longer side,
//!   the same camera; splatting at the frame's size) at refinement levels k = 0, 1, 2, …: the fixed step (`render.step`) or
//!   the sheet thickness (`splat.slab`) halves from level to level; the adaptive integrator's
//!   ε quarters, its shortest interval halves and its longest shrinks by 2^(2/3) (from √2 times
//!   the scene's `render.l_max` at level 0). The difference of consecutive levels,
//!   d_k = p99(I_k − I_{k+1}), estimates the error left in I_{k+1} by Richardson extrapolation,
//!   e_{k+1} ≈ d_k / (2^p − 1), with the order p fitted from consecutive differences (clamped
//!   to [1, 4]; the method's expected order until two differences exist). The ladder stops
//!   once that estimate is below [`SAFETY`] · E/2; the level is then the power law's from the
//!   last rung (within the rungs rendered, below). Where the first difference already puts
//!   level 0 itself inside that budget, the ladder climbs instead (levels −1, −2: coarser
//!   steps, sheets and ε), measuring each rung from its difference to the one below while the
//!   power law predicts it inside, and the level is the power law's between the coarsest rung
//!   measured inside and the one above it. The power law may coarsen up to two levels past the last rung, never past the
//!   coarsest rung rendered: where a ladder resolves a feature between two rungs, its last
//!   difference falls far below the trend and one level left frames at E/21 (BENCHMARKS.md,
//!   "The power law two rungs back").
//! - **Tables** (preintegrated methods, post-shaded splatting's intervals): a level rendered
//!   once more with tables of twice the resolution (half again where twice does not fit the
//!   device); the move, extrapolated at the tables' order 2 in the cell, is the tables' error,
//!   and while it exceeds E/4 the finer tables are taken (up to 4096). This runs before the
//!   ladder, at its level 0, so that the rungs differ by their step and not by their tables'
//!   error, and again at the level chosen.
//!
//! - **A turning camera**: the next view of the same settings (another camera only: an
//!   orbit, a resized image) starts from the last one's choice instead of from scratch. Its
//!   ladder starts one level below the level chosen, with the order measured there, and runs
//!   as above (so an easier view coarsens by up to a level, a harder one refines until the
//!   estimate holds); its tables are the last view's, checked again at the level chosen unless
//!   their last measured error was within E/16. An orbit's frames at 128² paid 8 pilots and
//!   1.2-3.4 s of wall time each for a 20 ms frame, most of it the table check's uploads
//!   (BENCHMARKS.md, "A tolerance carried across a turning camera").
//!
//! - **The adaptive criterion**: Hermite's (`render.adaptive = "hermite"`) unless the scene
//!   names one or gives ε: it met E with 4-9× fewer evaluations than [MLS]'s.
//!
//! The adaptive integrator also estimates each frame's error itself, per ray, from its
//! criterion's local estimates ([`super::GpuImage::error_estimate`]; `--stats` "error_estimate", `vmls bench`
//! `error_estimate`). That estimate is reported beside the measured error but does not choose
//! ε: the Hermite criterion's is a bound, which sums the largest departure of every interval
//! as if none cancelled, and measured 10-25× the frame's actual 99th percentile on
//! Marschner–Lobb (never below it in 99.9% of pixels); keeping it under E/2 on the ladder's
//! rungs took 4× the evaluations of the pilots' choice at E = 1e-2 and 10× at 1e-3 on the
//! built-in scene, for an image 10-20× better than asked (BENCHMARKS.md). The pilots measure
//! the error instead.
//!
//! Assumptions, each of which a scene can break: the error behaves as C·2^(−p·k) over the
//! ladder's last rungs (it is in its asymptotic regime there); the pilot's 99th percentile
//! stands for the frame's (features narrower than a pilot pixel are weighed by their area,
//! which a resolution change keeps, but sampled more coarsely); and the three shares add. An
//! explicit key (`render.step`, `render.epsilon`, `render.l_min`, `splat.slab`,
//! `render.early_termination`, `render.min_transmittance`, `render.table_resolution`) wins over
//! the tolerance, and the report says so.

use super::Renderer;
use crate::field::RenderError;
use crate::view::camera::Camera;
use crate::view::settings::SheetInterval;
use crate::view::{AdaptiveCriterion, Method, RenderSettings, View, ViewKey};
use std::time::Instant;

/// Pixels on the longer side of a pilot frame.
pub const PILOT_EDGE: u32 = 96;
/// The share of the discretization budget the ladder aims at (the rest absorbs the
/// extrapolation's error).
pub const SAFETY: f64 = 0.5;
/// Refinements of the ladder at most.
const MAX_LEVELS: i32 = 9;
/// The coarsest level the ladder may climb to where its first rungs are far inside the
/// budget ([`coarsen`]): steps and sheets of 4 spacings, ε 16× level 0's with the longest
/// interval twice as long. Coarser, a feature narrower than a step could lie unseen between
/// both rungs of a difference that then reads as converged.
const MIN_LEVEL: i32 = -2;

/// How many levels the power law may take the choice above the last rung (within the rungs
/// rendered). One level left the 0.005 peak's even views at E/21 where its ladder resolved the
/// peak between two rungs; two kept every eight-view case within [E/10, E] (BENCHMARKS.md).
const MAX_COARSENING: i32 = 2;
/// The largest table resolution the tolerance chooses.
const MAX_TABLE: usize = 4096;

/// Per pixel, the largest absolute difference over the four channels; a non-finite pixel in
/// either image counts as infinitely wrong.
pub fn pixel_errors(image: &[[f32; 4]], reference: &[[f32; 4]]) -> Vec<f64> {
    image
        .iter()
        .zip(reference)
        .map(|(a, b)| {
            a.iter()
                .zip(b)
                .map(|(x, y)| {
                    let d = (f64::from(*x) - f64::from(*y)).abs();
                    if d.is_nan() { f64::INFINITY } else { d }
                })
                .fold(0.0, f64::max)
        })
        .collect()
}

/// The 99th percentile of [`pixel_errors`], the error that `render.tolerance` bounds: the
/// ⌈0.99·n⌉-th smallest of the n pixels' errors, so that at most 1% of the pixels are worse.
/// 0 for empty images.
pub fn p99_error(image: &[[f32; 4]], reference: &[[f32; 4]]) -> f64 {
    p99_of(pixel_errors(image, reference))
}

/// The 99th percentile of per-pixel errors (as [`p99_error`] ranks them).
pub fn p99_of(mut errors: Vec<f64>) -> f64 {
    if errors.is_empty() {
        return 0.0;
    }
    errors.sort_by(f64::total_cmp);
    let rank = (0.99 * errors.len() as f64).ceil() as usize;
    errors[rank.clamp(1, errors.len()) - 1]
}

/// What a tolerance chose for a frame, for `--stats`.
#[derive(Debug, Clone, PartialEq)]
pub struct ToleranceReport {
    /// E.
    pub tolerance: f64,
    /// The key the ladder chose (`render.step`, `render.epsilon`, `splat.slab`), its value in
    /// the key's units, and the error the pilots estimate for the frame at that value; `None`
    /// where an explicit key won.
    pub chosen: Option<(&'static str, f64, f64)>,
    /// The observed order in the level (the last fit).
    pub order: f64,
    /// Each rung: the level's value of the chosen key and d_k, the difference to the next.
    pub rungs: Vec<(f64, f64)>,
    pub early_termination: f64,
    pub table_resolution: usize,
    /// Each table resolution tried, and its error extrapolated from the move to a finer
    /// table.
    pub table_moves: Vec<(usize, f64)>,
    /// Whether every share of E was shown to hold (`notes` says which did not: a ladder
    /// that ran out of levels, tables the device cannot hold finer).
    pub met: bool,
    /// Explicit keys that won over the tolerance, and other remarks.
    pub notes: Vec<String>,
    /// Wall and GPU milliseconds of the pilot frames.
    pub pilot_wall_ms: f64,
    pub pilot_gpu_ms: f64,
    pub pilots: u32,
    /// Whether the pilots started from the last view's choice (the same settings through
    /// another camera) rather than from the ladder's first level.
    pub carried: bool,
}

/// The renderer's last resolution: the view it was for and what it chose.
pub(super) struct Resolved {
    key: ViewKey,
    settings: RenderSettings,
    report: ToleranceReport,
    carry: Carry,
}

/// What a resolution leaves to the next view of the same settings through another camera
/// (module documentation, "A turning camera").
#[derive(Debug, Clone, Copy)]
struct Carry {
    /// The ladder's level chosen (continuous; 0 where the scene gave the ladder's key).
    level: f64,
    /// The order fitted at that level.
    order: f64,
    table_resolution: usize,
    /// The tables' error where it was last measured.
    table_error: Option<f64>,
}

/// The order in the level assumed until two differences measure one: every ladder's
/// parameter enters its method's error to the second order ([`fitted_order`] takes over).
const EXPECTED_ORDER: f64 = 2.0;

/// The key a method's ladder refines, and whether the scene gave it (then it is not refined).
fn ladder_key(settings: &RenderSettings) -> (&'static str, bool) {
    let g = &settings.given;
    match settings.method {
        Method::Fixed | Method::Riemann => ("render.step", g.step),
        Method::Reference => ("render.reference_step", g.reference_step),
        Method::Adaptive => ("render.epsilon", g.epsilon),
        Method::Splat | Method::SplatPost => ("splat.slab", g.slab),
    }
}

/// The settings at refinement level `k` (continuous): the ladder's parameter refined from its
/// starting value, everything else as `base`. Returns the settings and the parameter's value.
fn at_level(base: &RenderSettings, k: f64) -> (RenderSettings, f64) {
    let mut s = base.clone();
    let halve = 0.5f64.powf(k);
    let value = match s.method {
        Method::Fixed | Method::Riemann => {
            s.step_spacings = START_STEP * halve;
            s.step_spacings
        }
        Method::Reference => {
            s.reference_step_spacings = START_STEP * halve;
            s.reference_step_spacings
        }
        Method::Adaptive => {
            s.epsilon = base.adaptive.default_epsilon() * START_EPSILON * halve * halve;
            // The longest interval shrinks too: a feature between an interval's knots that
            // none of its evaluations sees is never subdivided, whatever ε (DESIGN.md §4), so
            // with l_max fixed the ladder converged to a biased limit (before the hull's
            // margin: 1.2e-3 on ml-emission at 128² while consecutive levels differed by
            // 1.7e-4; with the margin, the graded torus at l_max = 2.6 spacings still stopped
            // at 6e-4). Halving it every level, as before the margin, cost the torus and the
            // thin peaks 20-40% more evaluations at equal error (BENCHMARKS.md, "A margin on
            // the Hermite hull"). Where it starts and how fast it shrinks: START_L_MAX and
            // L_MAX_SHRINK_EXPONENT.
            if !base.given.l_max {
                s.l_max_spacings =
                    base.l_max_spacings * START_L_MAX * halve.powf(L_MAX_SHRINK_EXPONENT);
            }
            if !base.given.l_min {
                s.l_min_spacings = base.l_min_spacings * halve;
            }
            s.l_min_spacings = s.l_min_spacings.min(s.l_max_spacings);
            s.epsilon
        }
        Method::Splat | Method::SplatPost => {
            s.splat.slab_spacings = START_STEP * halve;
            s.splat.slab_spacings
        }
    };
    (s, value)
}

/// A pilot frame's pixels for a frame of `camera` (module documentation). Splatting pilots at
/// the frame's size: a smaller image costs it little less (its projection and sort are per
/// kernel) and would pack more entries into each tile.
pub fn pilot_size(camera: &Camera, method: Method) -> (u32, u32) {
    let scale = f64::from(PILOT_EDGE) / f64::from(camera.width.max(camera.height));
    if scale < 1.0 && method.splat_shading().is_none() {
        let shrink = |n: u32| ((f64::from(n) * scale).round() as u32).max(1);
        (shrink(camera.width), shrink(camera.height))
    } else {
        (camera.width, camera.height)
    }
}

/// The fewest pilot frames a tolerance renders before its frame for these settings (none
/// without one), each costing about the ladder's first level ([`first_level`]; a climb's
/// coarser rungs and a level chosen above it cost less): two there
/// to check the tables, that level and the next, and two at the level chosen to check the
/// tables again; fewer where the scene gives the ladder's key or the tables' resolution. What
/// the first frame of a scene under a tolerance costs beyond its own (`reconstruction.resample
/// = "auto"` counts them, `Scene::frame_evaluations`).
pub fn fewest_pilots(settings: &RenderSettings) -> u32 {
    if settings.tolerance.is_none() {
        return 0;
    }
    let (_, key_given) = ladder_key(settings);
    let tables = reads_tables(settings) && !settings.given.table_resolution;
    let ladder = if key_given { 0 } else { 2 };
    let table_checks = match (tables, key_given) {
        (false, _) => 0,
        (true, true) => 2,
        (true, false) => 4,
    };
    ladder + table_checks
}

/// Whether frames of these settings read preintegration tables, whose share of E the
/// tolerance checks: the preintegrated ray casters, and post-shaded splatting's intervals
/// between sheet middles (all but constant sheets). Splatting's were left unchecked before: on
/// a peak of half-width 0.002 its 512² tables erred by 5e-2 (p99) unreported (BENCHMARKS.md).
fn reads_tables(settings: &RenderSettings) -> bool {
    settings.method.preintegrated()
        || (settings.method == Method::SplatPost
            && settings.splat.interval != Some(SheetInterval::Constant))
}

/// The settings of a tolerance's first level, the coarsest it renders (`settings` themselves
/// without a tolerance or where the scene gives the ladder's key).
pub fn first_level(settings: &RenderSettings) -> RenderSettings {
    if settings.tolerance.is_none() || ladder_key(settings).1 {
        return settings.clone();
    }
    at_level(settings, 0.0).0
}

/// Level 0's step or sheet thickness, in sample spacings.
const START_STEP: f64 = 1.0;
/// Level 0's ε, in multiples of the criterion's default.
const START_EPSILON: f64 = 8.0;
/// Level 0's l_max, in multiples of the scene's (`render.l_max`, 2.6 spacings by default), so
/// that level k's is 2.6 · √2 · 2^(−2k/3) with [`L_MAX_SHRINK_EXPONENT`]. Most evaluations of a
/// thin scene's adaptive frame are the ends of its longest intervals (BENCHMARKS.md "(ix)":
/// 16 876 of 24 292 on the graded torus). At eight views of the six tolerance scenes this
/// ladder kept every tolerance and met E with at most a third of the oracle's evaluations in 8
/// of the 12 thin cases (6 with l_max from 1× shrinking by √2); √2 shrinking by √2 did too but
/// took ml-emission at E = 1e-3 to 2.4× the oracle's time, and 2× took more evaluations on the
/// 0.01 peak (BENCHMARKS.md "(x)").
const START_L_MAX: f64 = std::f64::consts::SQRT_2;
/// l_max shrinks by 2^this a level. The error its floor leaves falls 1.9–3.9× a halving (the
/// graded torus's floor: 1.1e-3, 5.9e-4, 1.5e-4 at 5.2, 2.6, 1.3 spacings), so 1.5–2.5× a level
/// here, nearer ε's 4× than at √2 a level, where the ladder's one fitted order chose a finer ε
/// for ml-emission at E = 1e-3 (1.8e-4 against 2.7e-4, BENCHMARKS.md "(x)").
const L_MAX_SHRINK_EXPONENT: f64 = 2.0 / 3.0;

/// The order fitted from the last two differences, clamped to [1, 4]; `expected` with fewer.
fn fitted_order(d: &[f64], expected: f64) -> f64 {
    match d {
        [.., a, b] if *a > 0.0 && *b > 0.0 => (a / b).log2().clamp(1.0, 4.0),
        _ => expected,
    }
}

impl Renderer {
    /// The settings a view's tolerance chooses (cached while the view stays the same), or
    /// `None` without a tolerance. A view that differs from the last one only by its camera
    /// starts from the last one's choice ([`Carry`]).
    pub(super) fn tolerance_settings(
        &mut self,
        view: &View<'_>,
    ) -> Result<Option<(RenderSettings, ToleranceReport)>, RenderError> {
        let Some(tolerance) = view.settings.tolerance else {
            return Ok(None);
        };
        let key = ViewKey::of(view);
        if let Some(r) = self.tolerance.as_ref().filter(|r| r.key == key) {
            return Ok(Some((r.settings.clone(), r.report.clone())));
        }
        let carry = self
            .tolerance
            .as_ref()
            .filter(|r| r.key.same_but_camera(&key))
            .map(|r| r.carry);
        // Pilots keep hull segments but never read them: at their size a walk costs less than
        // compiling the variant that reads (the frame after the pilots has another size, and
        // walks anyway).
        self.segments_keep_only = true;
        let resolved = self.resolve(view, tolerance, carry);
        self.segments_keep_only = false;
        let (settings, report, carry) = resolved?;
        self.tolerance = Some(Resolved {
            key,
            settings: settings.clone(),
            report: report.clone(),
            carry,
        });
        Ok(Some((settings, report)))
    }

    /// Runs the pilots of `view` for tolerance `e` (module documentation), from the last
    /// view's choice where `carry` holds it.
    fn resolve(
        &mut self,
        view: &View<'_>,
        e: f64,
        carry: Option<Carry>,
    ) -> Result<(RenderSettings, ToleranceReport, Carry), RenderError> {
        let start = Instant::now();
        let given = view.settings.given;
        let mut base = view.settings.clone();
        base.tolerance = None;
        let mut notes = Vec::new();
        // Cleared where a share of E cannot be shown to hold.
        let mut met = true;
        // Early termination: E/4 of the budget.
        if given.early_termination {
            notes.push(format!(
                "render.early_termination = {} given: kept",
                base.early_termination
            ));
        } else {
            base.early_termination = 1.0 - e / 4.0;
        }
        if given.min_transmittance {
            notes.push(format!(
                "render.min_transmittance = {} given: kept",
                base.min_transmittance
            ));
        } else {
            base.min_transmittance = e / 4.0;
        }
        // The adaptive criterion: Hermite's, one evaluation per accepted interval, met E with
        // 4-9× fewer evaluations and 4-13× less GPU time than [MLS]'s on Marschner–Lobb
        // (BENCHMARKS.md, "The adaptive integrator's own error estimate").
        if base.method == Method::Adaptive && base.adaptive != AdaptiveCriterion::Hermite {
            if given.adaptive || given.epsilon {
                notes.push(format!(
                    "render.adaptive = \"{}\" given: kept",
                    base.adaptive.name()
                ));
            } else {
                base.adaptive = AdaptiveCriterion::Hermite;
                base.epsilon = base.adaptive.default_epsilon();
            }
        }
        let mut camera = *view.camera;
        (camera.width, camera.height) = pilot_size(&camera, view.settings.method);
        let mut pilots = 0u32;
        let mut pilot_gpu_ms = 0.0;
        let mut pilot = |r: &mut Renderer, s: &RenderSettings| -> Result<Image, RenderError> {
            let v = View {
                camera: &camera,
                settings: s,
                ..*view
            };
            let (image, stats) = r.render(&v, |_| {})?;
            pilots += 1;
            pilot_gpu_ms += stats.gpu_ms;
            Ok(image.pixels)
        };
        let (key, key_given) = ladder_key(&base);
        let tables_chosen = reads_tables(&base) && !given.table_resolution;
        let mut table_moves = Vec::new();
        // The tables' error last measured, where they were.
        let mut table_error = None;
        if let Some(c) = carry {
            base.table_resolution = c.table_resolution;
            table_error = c.table_error;
            notes.push(format!(
                "carried from the last view (the same settings through another camera): \
                 its tables, and the ladder from its level {:.2} less one",
                c.level
            ));
        } else if tables_chosen && !key_given {
            // Tables first, at the ladder's first level: their error changes with the step
            // (the segment length), and with coarse tables that change entered the ladder's
            // differences and made it refine the step for the tables' sake (a transfer-function
            // peak of half-width 0.01 took a step 4.6× finer than the oracle's at E = 3e-3,
            // BENCHMARKS.md). The tables are checked again at the level chosen.
            let (mut first, _) = at_level(&base, 0.0);
            let refined = refine_tables(self, &mut first, e, &mut pilot)?;
            table_moves = refined.moves;
            table_error = refined.error;
            base.table_resolution = first.table_resolution;
        }
        let budget = SAFETY * e / 2.0;
        let mut rungs: Vec<(f64, f64)> = Vec::new();
        let mut order = carry.map_or(EXPECTED_ORDER, |c| c.order);
        let mut chosen_level = 0.0;
        let (mut settings, chosen) = if key_given {
            notes.push(format!("{} given: kept, not chosen by the tolerance", key));
            (base.clone(), None)
        } else {
            // A carried ladder starts a level below the last view's choice, so that an easier
            // view can coarsen by up to one level and a harder one refines from there, with
            // the order the last view measured until two differences measure this one's.
            let first = carry.map_or(0, |c| (c.level.floor() as i32 - 1).max(MIN_LEVEL));
            let expected = order;
            let (s0, v0) = at_level(&base, f64::from(first));
            let mut previous = pilot(self, &s0)?;
            // The first rung's image, kept once the second is rendered for a climb above it.
            let mut first_image = None;
            let mut last_value = v0;
            let mut d = Vec::new();
            let mut level = first;
            // The estimate at the last rung rendered, and the level.
            let mut estimate = f64::INFINITY;
            loop {
                let (s, v) = at_level(&base, f64::from(level + 1));
                // A rung the scene cannot render (too many sheets, past the work budget) ends
                // the ladder at the last one rendered.
                let image = match pilot(self, &s) {
                    Err(e @ (RenderError::Setting { .. } | RenderError::Budget { .. })) => {
                        notes.push(format!("{} = {v:.4} refused: {e}", key));
                        break;
                    }
                    r => r?,
                };
                level += 1;
                let dk = p99_error(&previous, &image);
                rungs.push((last_value, dk));
                d.push(dk);
                order = fitted_order(&d, expected);
                estimate = dk / (2f64.powf(order) - 1.0);
                let coarser = std::mem::replace(&mut previous, image);
                if level == first + 1 {
                    first_image = Some(coarser);
                }
                last_value = v;
                if estimate <= budget || level - first >= MAX_LEVELS {
                    break;
                }
            }
            // The coarsest rung rendered: the power law interpolates, never extrapolates, to it.
            let mut coarsest = first;
            if let Some(image) = first_image.filter(|_| level == first + 1 && estimate.is_finite())
            {
                let up = coarsen(
                    self,
                    &base,
                    budget,
                    (first, image),
                    (estimate, order),
                    &mut pilot,
                )?;
                coarsest -= up.rungs.len() as i32;
                rungs.splice(0..0, up.rungs);
                (level, estimate, order) = up.level;
            }
            if estimate > e / 2.0 {
                met = false;
                notes.push(format!(
                    "{} = {last_value:.4} after {} refinements still estimates \
                     {estimate:.2e}, more than its share E/2 = {:.2e}: the tolerance is not met",
                    key,
                    level - first,
                    e / 2.0
                ));
            }
            chosen_level = power_law_level(level, coarsest, estimate / budget, order);
            let (s, v) = at_level(&base, chosen_level);
            let at_k = estimate * 2f64.powf(order * (f64::from(level) - chosen_level));
            (s, Some((key, v, at_k)))
        };
        if reads_tables(&settings) {
            if given.table_resolution {
                notes.push(format!(
                    "render.table_resolution = {} given: kept",
                    settings.table_resolution
                ));
            } else if let Some(t) = table_error.filter(|&t| carry.is_some() && t <= e / 16.0) {
                // Far inside their share where last measured: the tables' error depends on
                // the transfer function and the segment lengths, which a new camera changes
                // little, and checking them costs the pilots' largest uploads.
                notes.push(format!(
                    "tables of {} carried unchecked: their error was {t:.2e} at the last view, \
                     within E/16",
                    settings.table_resolution
                ));
            } else {
                let refined = refine_tables(self, &mut settings, e, &mut pilot)?;
                table_moves.extend(refined.moves);
                table_error = refined.error;
                if let Some(note) = refined.miss {
                    met = false;
                    notes.push(note);
                }
            }
        }
        let report = ToleranceReport {
            tolerance: e,
            chosen,
            order,
            rungs,
            early_termination: settings.early_termination,
            table_resolution: settings.table_resolution,
            table_moves,
            met,
            notes,
            pilot_wall_ms: start.elapsed().as_secs_f64() * 1e3,
            pilot_gpu_ms,
            pilots,
            carried: carry.is_some(),
        };
        let carry = Carry {
            level: chosen_level,
            order,
            table_resolution: settings.table_resolution,
            table_error,
        };
        Ok((settings, report, carry))
    }
}

/// A frame's pixels.
type Image = Vec<[f32; 4]>;

/// A pilot frame of the view being resolved at these settings (counted in the report).
type Pilot<'a> = dyn FnMut(&mut Renderer, &RenderSettings) -> Result<Image, RenderError> + 'a;

/// What [`coarsen`] found: the level the choice extrapolates from, its estimated error and
/// the order to extrapolate with; and the rungs it rendered above the ladder's first, coarsest
/// first (each rung's value and its difference to the next finer one).
struct Coarsened {
    level: (i32, f64, f64),
    rungs: Vec<(f64, f64)>,
}

/// The ladder upward: where its first difference puts the first rung itself inside the budget
/// by the power law (the estimate at the second times 2^p), the rung above is rendered and
/// the first's error measured from their difference, and so on up to [`MIN_LEVEL`] while each
/// new rung is predicted inside the budget. `first` is the ladder's first level and its image,
/// `(estimate, order)` the second rung's estimate and the order it assumed. Returns the
/// coarsest level measured inside the budget with its estimate and order; where a measured
/// error came out above the budget, the order between it and the level below, so that the
/// power law interpolates between two measured rungs. Without it the shell's 0.002 peak kept ε
/// at level 0 and measured E/29 at E = 1e-2, and the graded torus stopped at step 1 with E/7
/// (BENCHMARKS.md): level 0 was the coarsest the ladder could reach.
fn coarsen(
    renderer: &mut Renderer,
    base: &RenderSettings,
    budget: f64,
    (first, image): (i32, Image),
    (estimate, order): (f64, f64),
    pilot: &mut Pilot<'_>,
) -> Result<Coarsened, RenderError> {
    let (mut level, mut estimate, mut order) = (first + 1, estimate, order);
    let (mut top, mut top_image) = (first, image);
    // The difference between `top` and the rung below it.
    let mut below = estimate * (2f64.powf(order) - 1.0);
    let mut rungs = Vec::new();
    while top > MIN_LEVEL && estimate * 2f64.powf(order) <= budget {
        let (s, v) = at_level(base, f64::from(top - 1));
        let image = match pilot(renderer, &s) {
            Err(RenderError::Setting { .. } | RenderError::Budget { .. }) => break,
            r => r?,
        };
        let d = p99_error(&image, &top_image);
        rungs.push((v, d));
        // The order between the two coarsest differences (they grow upward).
        let p = fitted_order(&[d, below], order);
        let at_top = d / (2f64.powf(p) - 1.0);
        if at_top > budget {
            // `top` measured outside the budget and `level` inside: the local law between them.
            order = (at_top / estimate).log2();
            break;
        }
        (level, estimate, order) = (top, at_top, p);
        (top, top_image, below) = (top - 1, image, d);
    }
    rungs.reverse();
    Ok(Coarsened {
        level: (level, estimate, order),
        rungs,
    })
}

/// What [`refine_tables`] found: each resolution tried with its extrapolated error, and why
/// the tables' share could not be shown where it could not.
struct TableRefinement {
    moves: Vec<(usize, f64)>,
    /// The error of the tables taken, extrapolated from the last move to them (`None`: not
    /// measured).
    error: Option<f64>,
    miss: Option<String>,
}

/// The tables' share (module documentation): their error, extrapolated from the move to a
/// finer table at their order 2 in the cell (`vmls check`'s converge-table), must stay within
/// E/4, else the finer ones are taken.
fn refine_tables(
    renderer: &mut Renderer,
    settings: &mut RenderSettings,
    e: f64,
    pilot: &mut Pilot<'_>,
) -> Result<TableRefinement, RenderError> {
    let mut moves = Vec::new();
    let mut image = pilot(renderer, settings)?;
    let mut current: Option<f64> = None;
    while settings.table_resolution < MAX_TABLE {
        let r = settings.table_resolution;
        let Some((finer, fine)) = finer_tables(renderer, settings, pilot)? else {
            break;
        };
        let ratio = r as f64 / finer.table_resolution as f64;
        let error = p99_error(&image, &fine) / (1.0 - ratio * ratio);
        moves.push((r, error));
        if error <= e / 4.0 {
            current = Some(error);
            break;
        }
        // The finer table's error at the tables' order 2.
        current = Some(error * ratio * ratio);
        *settings = finer;
        image = fine;
    }
    let miss = match current {
        Some(c) if c <= e / 4.0 => None,
        Some(c) => Some(format!(
            "tables of {} estimate {c:.2e}, more than their share E/4, and finer ones do not \
             fit this device: the tolerance is not met",
            settings.table_resolution
        )),
        None => Some(format!(
            "tables finer than {} do not fit this device: their share E/4 of the tolerance is \
             not verified, so it is not met",
            settings.table_resolution
        )),
    };
    Ok(TableRefinement {
        moves,
        error: current,
        miss,
    })
}

/// The pilot with tables twice as fine, or half again as fine where twice does not fit the
/// device (`None`: neither does).
fn finer_tables(
    renderer: &mut Renderer,
    settings: &RenderSettings,
    pilot: &mut Pilot<'_>,
) -> Result<Option<(RenderSettings, Image)>, RenderError> {
    let r = settings.table_resolution;
    for finer_r in [2 * r, r + r / 2] {
        let mut finer = settings.clone();
        finer.table_resolution = finer_r.min(MAX_TABLE);
        match pilot(renderer, &finer) {
            Err(RenderError::Setting {
                key: "render.table_resolution",
                ..
            }) => continue,
            result => return Ok(Some((finer, result?))),
        }
    }
    Ok(None)
}

/// The level whose error the power law from the last rung `level` (its estimate `ratio` times
/// the budget, at `order`) puts at the budget: no finer than `level`, at most
/// [`MAX_COARSENING`] levels coarser and never past `coarsest`, the coarsest rung rendered, so
/// that the law interpolates between measured rungs. An estimate of zero coarsens one level.
fn power_law_level(level: i32, coarsest: i32, ratio: f64, order: f64) -> f64 {
    let extra = if ratio > 0.0 {
        ratio.log2() / order
    } else {
        -1.0
    };
    let reach = (coarsest - level).max(-MAX_COARSENING);
    f64::from(level) + extra.clamp(f64::from(reach.min(0)), 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_power_law_coarsens_within_the_rungs_rendered() {
        // Inside the budget by 2^4 at order 2: two levels coarser, where two rungs above exist.
        assert_eq!(power_law_level(3, 0, 1.0 / 16.0, 2.0), 1.0);
        // Only one rung above the last: no further than it.
        assert_eq!(power_law_level(3, 2, 1.0 / 16.0, 2.0), 2.0);
        // Far inside: never more than two levels.
        assert_eq!(power_law_level(5, -2, 1e-9, 1.0), 3.0);
        // Between rungs: the law's own level.
        assert!((power_law_level(2, 0, 0.5, 2.0) - 1.5).abs() < 1e-12);
        // Outside the budget (the ladder ran out): the last rung, never finer.
        assert_eq!(power_law_level(4, 0, 3.0, 2.0), 4.0);
        assert_eq!(power_law_level(4, 0, 0.0, 2.0), 3.0);
    }

    #[test]
    fn p99_is_the_rank_of_the_99th_percentile() {
        let zero = [[0.0f32; 4]; 200];
        let mut img = zero;
        // Two pixels of 200 wrong: 1% of them may be, so the 99th percentile is 0.
        img[3] = [0.0, 0.5, 0.0, 0.0];
        img[7] = [0.0, 0.0, 0.0, -0.25];
        assert_eq!(p99_error(&img, &zero), 0.0);
        // A third: the smallest of the three is the 198th smallest error.
        img[9] = [0.125, 0.0, 0.0, 0.0];
        assert_eq!(p99_error(&img, &zero), 0.125);
        assert_eq!(p99_error(&zero, &zero), 0.0);
        let mut nan = zero;
        nan[0][0] = f32::NAN;
        nan[1][0] = f32::NAN;
        nan[2][0] = f32::NAN;
        assert!(p99_error(&nan, &zero).is_infinite());
    }

    #[test]
    fn the_order_comes_from_the_last_two_differences() {
        assert_eq!(fitted_order(&[0.1], 2.0), 2.0);
        assert!((fitted_order(&[0.4, 0.1, 0.0125], 2.0) - 3.0).abs() < 1e-12);
        assert_eq!(fitted_order(&[0.1, 0.2], 2.0), 1.0, "clamped below");
        assert_eq!(fitted_order(&[1.0, 1e-6], 2.0), 4.0, "clamped above");
    }
}
