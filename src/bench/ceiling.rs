//! Which ceiling a frame's main kernel is bound by, and how close it came: a cost model per
//! evaluation (or per splat footprint) divided by the rate `vmls probe` measured in the same run.
//!
//! The model counts the work the kernels do, by path (`glsl/field/neighbours.glsl`):
//! - Flops of an MLS evaluation with T basis terms and k weighted neighbours:
//!   k·(2·(T(T+1)/2 + T) + 11) for the normal equations and weights, plus 2T³/3 + 13 for the
//!   solve — 39k + 56 for the linear basis, [MLS] Table 2's count. The Gaussian sum: 25 per
//!   neighbour (a weight, an exp, a gradient); the analytic field: 60 per evaluation. Candidate
//!   tests that find no weight are not counted, so the FMA share is a lower bound.
//! - The fast path (`reconstruction.resample`): 8 rgba32 texel reads and 124 flops per
//!   evaluation, against the ray-march gather ceiling (`probe_memory:march-texel-gather`,
//!   which reads as the fast path does: the 8 corners of each ray's cell, 8×8 tiles of
//!   neighbouring rays). The preintegration lookups are not counted (a lower bound).
//! - Other loads, all through texel-buffer views, against the coherent texel-gather ceiling
//!   (neighbouring rays of a SIMD row read nearby grid rows or one leaf): the grid's row path
//!   (every basis) reads π·s² rows of MLS_GRID_WINDOW vec4s (s = support in spacings); the
//!   Gaussian sum on a grid one texel per weighted neighbour, as an analytic-gradient pass
//!   does; the octree path depth node texels and, per reference of the leaf (references /
//!   leaves on average), its record's 2 or 3 texels inline (`octree.records`), or a code and 2
//!   or 3 sample texels through the coded references.
//! - k is measured, not modelled: the mean weighted neighbours of `mls_eval` at random points
//!   of the domain (`probe::mls_probe`).
//!
//! - Splatting rows are measured on `splat_raster`, the main kernel of a splatting frame: per
//!   pixel whose footprint it evaluates, 110 flops for exact footprints and 65 for affine ones
//!   (the operations of `splat_footprint` evaluated directly, a transcendental function counted
//!   as 10: a nominal count, like the MLS rows' paper count; the kernel shares each entry's
//!   `splat_column` among an invocation's rows, where a pixel's 29 operations for a′, b′ and g
//!   become 5 plus its part of the column's 60; post-shaded entries add their ring's sheet
//!   shares, `entry_flops`), plus per
//!   entry walked 8 per pixel of the tile (the box test and the loop), against `probe_fma`;
//!   and per entry walked and per subgroup of the tile (8 invocations on lavapipe, 32 on an
//!   NVIDIA GPU) one broadcast load of the 120 bytes of its entry and record, against the
//!   streaming bandwidth. Both counts come from the kernel's own counters.

use crate::field::Field;
use crate::probe::Ceilings;
use crate::recon::{GradientMode, ReconMethod};

/// How an evaluation reads memory: which probe is its ceiling.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reads {
    /// Storage-buffer gathers (`probe_memory:coherent-gather`).
    Storage,
    /// Texel-view gathers of nearby words (`probe_memory:coherent-texel-gather`).
    Texel,
    /// A ray march's cell corners (`probe_memory:march-texel-gather`).
    March,
}

impl Reads {
    /// The `bound_by` name of the ceiling.
    pub fn name(self) -> &'static str {
        match self {
            Reads::Storage => "gather",
            Reads::Texel => "texel-gather",
            Reads::March => "march-texel-gather",
        }
    }
}

/// Work of one evaluation, by the model above.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvaluationCost {
    pub flops: f64,
    /// Load instructions, and how they read.
    pub loads: f64,
    pub reads: Reads,
}

/// The model's cost of one evaluation of `field` with `k` weighted neighbours on average.
pub fn evaluation_cost(field: &Field, k: f64) -> EvaluationCost {
    let r = &field.reconstruction;
    if r.resample > 0 {
        // The fast path: 8 vec4 texel reads, 8 weights and the Hermite blend.
        return EvaluationCost {
            flops: 8.0 * 14.0 + 12.0,
            loads: 8.0,
            reads: Reads::March,
        };
    }
    let t = r.basis.terms() as f64;
    let flops = match r.method {
        ReconMethod::Exact => 60.0,
        ReconMethod::Gaussian => 25.0 * k + 10.0,
        ReconMethod::Mls => {
            k * (2.0 * (t * (t + 1.0) / 2.0 + t) + 11.0) + 2.0 * t.powi(3) / 3.0 + 13.0
        }
    };
    let gradient_pass = if r.gradient == GradientMode::Analytic {
        k
    } else {
        0.0
    };
    let (loads, reads) = match (field.octree_if_built(), r.method) {
        (_, ReconMethod::Exact) => (0.0, Reads::Storage),
        (None, ReconMethod::Mls) => {
            let s = r.support;
            let bx = (2.0 * s).floor() + 1.0;
            let window = ((bx + 3.0) / 4.0).ceil();
            (
                std::f64::consts::PI * s * s * window + gradient_pass,
                Reads::Texel,
            )
        }
        (None, _) => (k + gradient_pass, Reads::Texel),
        (Some(o), _) => {
            let stats = o.stats(0);
            let per_leaf = stats.references as f64 / stats.leaves.max(1) as f64;
            let record = if field.has_full_metric() { 3.0 } else { 2.0 };
            // Inline records: one, two or three texels; coded: the sample's and a code.
            let texels = if field.octree_inline() {
                field.record_stride() as f64
            } else {
                record + 1.0
            };
            let depth = f64::from(stats.depth);
            (
                depth + per_leaf * texels * (1.0 + gradient_pass.min(1.0)),
                Reads::Texel,
            )
        }
    };
    EvaluationCost {
        flops,
        loads,
        reads,
    }
}

/// Flops of one `splat_footprint` evaluation, exact or affine.
pub fn footprint_flops(exact: bool) -> f64 {
    if exact { 110.0 } else { 65.0 }
}

/// Flops of one entry at one pixel: a footprint, or with `ring` registers (post-shaded) the
/// lateral profile (the footprint less its erfc share, 30) and `ring` sheet shares, each 30 by
/// the erfc, 14 by the quadrature (4 multiplies of the recurrence, 10 for the rule) or 3 by the
/// midpoint rule (2 multiplies, 1 multiply-add), whose entries also seed the recurrence: 10
/// for e^(-dz²), then per seed (one per 8 sheets) 2 exponentials and a division, 35.
pub fn entry_flops(exact: bool, ring: u32, sheet_share: crate::view::SheetShare) -> f64 {
    let footprint = footprint_flops(exact);
    if ring == 0 {
        return footprint;
    }
    let ring = f64::from(ring);
    let seeds = 10.0 + 35.0 * (ring / 8.0).ceil();
    match sheet_share {
        crate::view::SheetShare::Quadrature => footprint - 30.0 + 14.0 * ring + seeds,
        crate::view::SheetShare::Midpoint => footprint - 30.0 + 3.0 * ring + seeds,
        crate::view::SheetShare::Erfc => footprint - 30.0 + 30.0 * ring,
    }
}

/// (FMA share, broadcast-load share) of a splatting frame's `splat_raster` on a device of
/// `subgroup` invocations a subgroup.
pub fn splat_shares(
    c: &Ceilings,
    report: &crate::renderer::SplatReport,
    exact: bool,
    subgroup: u32,
) -> (f64, f64) {
    let seconds = report.stage_ms[2] * 1e-3;
    let walked = report.counts.accumulated as f64;
    let flops = report.counts.evaluated as f64
        * entry_flops(exact, report.ring, report.sheet_share)
        + walked * 8.0 * f64::from(report.group_size);
    let bytes = walked * 120.0 * f64::from(report.invocations.div_ceil(subgroup.max(1)));
    (
        flops / seconds / (c.fma_gflops * 1e9),
        bytes / seconds / c.stream_bytes_per_s,
    )
}

/// (FMA share, load share) of a frame that made `evaluations` in `gpu_ms`.
pub fn shares(c: &Ceilings, cost: EvaluationCost, evaluations: u64, gpu_ms: f64) -> (f64, f64) {
    let per_s = evaluations as f64 / (gpu_ms * 1e-3);
    // Neighbouring rays read the same leaf or nearby grid rows: the coherent ceilings.
    let load_ceiling = match cost.reads {
        Reads::Storage => c.coherent_gathers_per_s,
        Reads::Texel => c.coherent_texel_gathers_per_s,
        Reads::March => c.march_texel_gathers_per_s,
    };
    (
        per_s * cost.flops / (c.fma_gflops * 1e9),
        per_s * cost.loads / load_ceiling,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_flops_are_the_papers_count() {
        // The general path (the default scene takes the fast path).
        let r = crate::scene::Scene::load(None, &["reconstruction.resample=0".to_string()])
            .expect("scene")
            .reconstruction;
        let field = Field::new(
            crate::data::marschner_lobb::generate(9),
            r,
            &crate::recon::OctreeSettings::default(),
            |_| {},
        )
        .expect("field");
        let k = 56.0;
        let cost = evaluation_cost(&field, k);
        assert!((cost.flops - (39.0 * k + 56.0)).abs() < 0.7, "{cost:?}");
        // Grid rows: π·2.4² rows of two vec4s, through the grid's texel view.
        let rows = std::f64::consts::PI * 2.4 * 2.4 * 2.0;
        assert!(
            (cost.loads - rows).abs() < 1e-9 && cost.reads == Reads::Texel,
            "{cost:?}"
        );
    }

    #[test]
    fn shares_divide_rates_by_ceilings() {
        let c = Ceilings {
            fma_gflops: 100.0,
            gathers_per_s: 1e8,
            texel_gathers_per_s: 1e8,
            coherent_gathers_per_s: 1e8,
            coherent_texel_gathers_per_s: 2e8,
            stream_bytes_per_s: 1e9,
            atomic_adds_per_s: 1e7,
            march_texel_gathers_per_s: 4e8,
        };
        let mut cost = EvaluationCost {
            flops: 2000.0,
            loads: 50.0,
            reads: Reads::Texel,
        };
        // 1e6 evaluations in 1 s: 2 GFLOP/s of 100, 5e7 texel loads/s of 2e8.
        let (f, l) = shares(&c, cost, 1_000_000, 1000.0);
        assert!((f - 0.02).abs() < 1e-12 && (l - 0.25).abs() < 1e-12);
        // The fast path's reads against the ray-march ceiling.
        cost.reads = Reads::March;
        let (_, l) = shares(&c, cost, 1_000_000, 1000.0);
        assert!((l - 0.125).abs() < 1e-12);
    }
}
