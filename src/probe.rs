//! Throughput probes (`vmls probe`): the FMA ceiling of the device and the MLS evaluation rate,
//! measured side by side in one run so their ratio is meaningful on a noisy machine.
//!
//! Flop counts: `probe_fma` does 256 flops per invocation and iteration; an MLS evaluation with
//! the linear basis and k weighted neighbours is counted as 39k + 56 flops ([MLS] Table 2).

use crate::gpu_types::{CountPush, binding, binding_defines};
use crate::render::Field;
use crate::render::gpu::{GpuField, evaluate};
use crate::vk::{
    BindGroup, Buffer, BufferUsage, ComputePipeline, Context, ShaderCompiler, ShaderSource, VkError,
};

/// Flops of one `probe_fma` iteration of one invocation.
pub const FMA_FLOPS_PER_ITERATION: f64 = 256.0;

/// f32 CPU twin of `glsl/probe_fma.comp` for invocation `id`.
pub fn fma_reference(id: u32, iterations: u32) -> [f32; 4] {
    let seed = id as f32 * 1e-7;
    let mut acc = [[0.0f32; 4]; 8];
    for (c, a) in acc.iter_mut().enumerate() {
        let cf = c as f32;
        *a = [seed + cf, seed - cf, seed * cf, 1.0];
    }
    let a = [0.999999f32, 0.999998, 0.999997, 0.999996];
    let b = [1e-6f32, 2e-6, 3e-6, 4e-6];
    for _ in 0..iterations * 4 {
        for chain in acc.iter_mut() {
            for l in 0..4 {
                chain[l] = chain[l].mul_add(a[l], b[l]);
            }
        }
    }
    let mut sum = [0.0f32; 4];
    for chain in &acc {
        for l in 0..4 {
            sum[l] += chain[l];
        }
    }
    sum
}

/// Median of a non-empty list (NaN-free); 0 for an empty one.
pub fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => 0.0,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// Result of the FMA probe.
#[derive(Debug, Clone)]
pub struct FmaProbe {
    pub invocations: u32,
    pub iterations: u32,
    /// GPU milliseconds of each timed dispatch (the first, which compiles, is discarded).
    pub gpu_ms: Vec<f64>,
    pub gflops: f64,
    pub output: Vec<[f32; 4]>,
}

/// Runs `probe_fma` `repeats + 1` times and reports the median rate of the last `repeats`.
pub fn fma_probe(
    ctx: &Context,
    compiler: &ShaderCompiler,
    invocations: u32,
    iterations: u32,
    repeats: u32,
) -> Result<FmaProbe, VkError> {
    let spirv = compiler.compile(ShaderSource::File("probe_fma.comp"), &binding_defines())?;
    let pipeline = ComputePipeline::new(
        ctx,
        "probe_fma",
        &spirv,
        &[binding::PROBE],
        std::mem::size_of::<CountPush>() as u32,
    )?;
    let out = Buffer::new(
        ctx,
        "probe output",
        u64::from(invocations) * 16,
        BufferUsage::Storage,
    )?;
    let group = BindGroup::new(ctx, &pipeline, &[(binding::PROBE, &out)])?;
    let push = CountPush {
        count: invocations,
        iterations,
        _pad: [0; 2],
    };
    let mut gpu_ms = Vec::new();
    for i in 0..=repeats {
        let t = ctx.submit(|rec| {
            rec.dispatch(
                &pipeline,
                &group,
                bytemuck::bytes_of(&push),
                [invocations.div_ceil(64), 1, 1],
                "probe_fma",
            )
        })?;
        if i > 0 {
            gpu_ms.extend(t.iter().filter_map(|t| t.gpu_ms));
        }
    }
    let ms = median(&gpu_ms);
    let flops = f64::from(invocations) * f64::from(iterations) * FMA_FLOPS_PER_ITERATION;
    let mut output: Vec<[f32; 4]> = out.read(ctx)?;
    output.truncate(invocations as usize);
    Ok(FmaProbe {
        invocations,
        iterations,
        gflops: if ms > 0.0 { flops / (ms * 1e6) } else { 0.0 },
        gpu_ms,
        output,
    })
}

/// Result of the MLS throughput probe.
#[derive(Debug, Clone)]
pub struct MlsProbe {
    pub variant: String,
    pub points: usize,
    pub gpu_ms: Vec<f64>,
    pub evaluations_per_s: f64,
    pub mean_neighbours: f64,
    /// (39k + 56) flops per evaluation at the measured rate.
    pub gflops: f64,
}

/// A deterministic 64-bit linear congruential generator (Knuth's MMIX constants): reproducible
/// point sets for probes, tests and benchmarks.
#[derive(Debug, Clone)]
pub struct Lcg(u64);

impl Lcg {
    pub fn new(seed: u64) -> Self {
        Self(
            seed.wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407),
        )
    }

    /// Uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Deterministic pseudo-random points inside the field's box (shrunk by `margin` per side).
pub fn random_points(field: &Field, n: usize, margin: f64, seed: u64) -> Vec<[f64; 3]> {
    let (lo, hi) = field.bounds();
    let mut rng = Lcg::new(seed);
    let mut next = || rng.next_f64();
    (0..n)
        .map(|_| {
            let mut p = [0.0; 3];
            for (a, x) in p.iter_mut().enumerate() {
                let l = lo[a] + margin * (hi[a] - lo[a]);
                let h = hi[a] - margin * (hi[a] - lo[a]);
                *x = l + next() * (h - l);
            }
            p
        })
        .collect()
}

/// Reorders points by the cell of a coarse 16³ lattice over the field's box, so that
/// neighbouring invocations evaluate nearby points, as neighbouring rays of a tile do.
pub fn coherent_order(field: &Field, mut points: Vec<[f64; 3]>) -> Vec<[f64; 3]> {
    let (lo, hi) = field.bounds();
    let cell =
        |p: &[f64; 3], a: usize| ((p[a] - lo[a]) / (hi[a] - lo[a]).max(1e-300) * 16.0) as i64;
    points.sort_by_key(|p| (cell(p, 2), cell(p, 1), cell(p, 0)));
    points
}

/// Times `mls_eval` over `points` (`repeats` timed dispatches after one warm-up).
pub fn mls_probe(
    ctx: &Context,
    compiler: &ShaderCompiler,
    field: &Field,
    points: &[[f64; 3]],
    repeats: u32,
) -> Result<MlsProbe, VkError> {
    let gpu_field = GpuField::upload(ctx, field)?;
    let (out, mut times) = evaluate(ctx, compiler, field, &gpu_field, points, repeats + 1)?;
    if !times.is_empty() {
        times.remove(0);
    }
    let ms = median(&times);
    let mean_neighbours =
        out.iter().map(|o| f64::from(o.neighbours)).sum::<f64>() / out.len().max(1) as f64;
    let rate = if ms > 0.0 {
        points.len() as f64 / (ms * 1e-3)
    } else {
        0.0
    };
    Ok(MlsProbe {
        variant: crate::render::gpu::Variant::of(field).name("mls_eval"),
        points: points.len(),
        gpu_ms: times,
        evaluations_per_s: rate,
        mean_neighbours,
        gflops: rate * (39.0 * mean_neighbours + 56.0) * 1e-9,
    })
}
