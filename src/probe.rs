//! Throughput probes (`vmls probe`): the FMA ceiling of the device and the MLS evaluation rate,
//! measured side by side in one run so their ratio is meaningful on a noisy machine.
//!
//! Flop counts: `probe_fma` does 256 flops per invocation and iteration; an MLS evaluation with
//! the linear basis and k weighted neighbours is counted as 39k + 56 flops ([MLS] Table 2).
//! `probe_memory` measures the two other ceilings a kernel may meet: random 32-bit gathers per
//! second (through a storage buffer and through a texel-buffer view) and streaming bandwidth.

pub use crate::data::random::Lcg;
use crate::field::Field;
use crate::field::gpu::{GpuField, evaluate};
use crate::gpu_types::{CountPush, binding, binding_defines};
use crate::recon::Octree;
use crate::vk::{
    BindGroup, Buffer, BufferUsage, ComputePipeline, Context, ShaderCompiler, ShaderSource, VkError,
};

/// Flops of one `probe_fma` iteration of one invocation.
pub const FMA_FLOPS_PER_ITERATION: f64 = 256.0;

/// f32 CPU twin of `glsl/probe/probe_fma.comp` for invocation `id`.
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

/// The output buffer of a probe: one 16-byte result per invocation.
fn probe_output(ctx: &Context, invocations: u32) -> Result<Buffer, VkError> {
    Buffer::new(
        ctx,
        "probe output",
        u64::from(invocations) * 16,
        BufferUsage::Storage,
    )
}

/// Dispatches a probe `repeats + 1` times (64 invocations per group) and returns the GPU
/// milliseconds of all but the first, which pays for compilation and first touches.
fn timed_dispatches(
    ctx: &Context,
    pipeline: &ComputePipeline,
    group: &BindGroup,
    invocations: u32,
    iterations: u32,
    repeats: u32,
) -> Result<Vec<f64>, VkError> {
    let push = CountPush {
        count: invocations,
        iterations,
        _pad: [0; 2],
    };
    let mut gpu_ms = Vec::new();
    for i in 0..=repeats {
        let t = ctx.submit(|rec| {
            rec.dispatch(
                pipeline,
                group,
                bytemuck::bytes_of(&push),
                [invocations.div_ceil(64), 1, 1],
                pipeline.name(),
            )
        })?;
        if i > 0 {
            gpu_ms.extend(t.iter().filter_map(|t| t.gpu_ms));
        }
    }
    Ok(gpu_ms)
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
    let spirv = compiler.compile(
        ShaderSource::File("probe/probe_fma.comp"),
        &binding_defines(),
    )?;
    let pipeline = ComputePipeline::new(
        ctx,
        "probe_fma",
        &spirv,
        &[binding::PROBE],
        std::mem::size_of::<CountPush>() as u32,
    )?;
    let out = probe_output(ctx, invocations)?;
    let group = BindGroup::new(ctx, &pipeline, &[(binding::PROBE, &out)])?;
    let gpu_ms = timed_dispatches(ctx, &pipeline, &group, invocations, iterations, repeats)?;
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

/// Words read by `probe_memory` (64 MiB: beyond any CPU cache, within every storage-buffer
/// limit we know).
pub const PROBE_WORDS: u32 = 1 << 24;

/// Words `probe_memory`'s atomic mode adds to: a 512² image's four channels.
pub const PROBE_ATOMIC_WORDS: u32 = 1 << 20;

/// Points per axis of the periodic grid `probe_memory`'s ray-march mode reads (128³ rgba32ui
/// texels: 32 MiB, the first half of the probe's words).
pub const MARCH_DIM: i32 = 128;

/// What `probe_memory` measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MemoryMode {
    /// 32-bit storage-buffer gathers at a random index per lane.
    Gather,
    /// The same through a texel-buffer view.
    TexelGather,
    /// Gathers where each group of 8 invocations reads 8 consecutive words at a random base
    /// (neighbouring rays reading one octree leaf or nearby grid rows), storage buffer.
    CoherentGather,
    /// The same through a texel-buffer view.
    CoherentTexelGather,
    /// Consecutive vec4 loads.
    Stream,
    /// Float adds by compare-and-swap loops at random words (what the splatter's sheet buffers
    /// paid per footprint pixel before the tile rasterizer).
    Atomic,
    /// A ray march's reads as the fast path makes them: 8×8 tiles of parallel rays, each
    /// reading its cell's 8 corner texels (rgba32) per step.
    MarchTexelGather,
}

impl MemoryMode {
    /// Every mode, in the order `vmls probe` prints them.
    pub const ALL: [MemoryMode; 7] = [
        MemoryMode::Gather,
        MemoryMode::TexelGather,
        MemoryMode::CoherentGather,
        MemoryMode::CoherentTexelGather,
        MemoryMode::Stream,
        MemoryMode::Atomic,
        MemoryMode::MarchTexelGather,
    ];

    pub fn name(self) -> &'static str {
        match self {
            MemoryMode::Gather => "probe_memory:gather",
            MemoryMode::TexelGather => "probe_memory:texel-gather",
            MemoryMode::CoherentGather => "probe_memory:coherent-gather",
            MemoryMode::CoherentTexelGather => "probe_memory:coherent-texel-gather",
            MemoryMode::Stream => "probe_memory:stream",
            MemoryMode::Atomic => "probe_memory:atomic-add",
            MemoryMode::MarchTexelGather => "probe_memory:march-texel-gather",
        }
    }

    fn define(self) -> &'static str {
        match self {
            MemoryMode::Gather | MemoryMode::CoherentGather => "0",
            MemoryMode::TexelGather | MemoryMode::CoherentTexelGather => "1",
            MemoryMode::Stream => "2",
            MemoryMode::Atomic => "3",
            MemoryMode::MarchTexelGather => "4",
        }
    }

    /// Load instructions per iteration of an invocation.
    fn loads_per_iteration(self) -> u32 {
        match self {
            MemoryMode::MarchTexelGather => 8,
            _ => 1,
        }
    }
}

/// The ray-march mode's ray for invocation `id` (twin of march_start): its fixed-point origin
/// and step, 256 units per cell.
pub fn march_start(id: u32) -> ([i32; 3], [i32; 3]) {
    let h = probe_hash(id >> 6);
    let mask = (MARCH_DIM * 256 - 1) as u32;
    let start = [0, 1, 2].map(|k| (probe_hash(h + k) & mask) as i32);
    let step = [
        (probe_hash(h + 3) & 255) as i32 - 128,
        (probe_hash(h + 4) & 255) as i32 - 128,
        128,
    ];
    let lane = [(id & 7) as i32, ((id >> 3) & 7) as i32, 0];
    (std::array::from_fn(|a| start[a] + 77 * lane[a]), step)
}

/// The word `probe_memory` reads at index i.
pub fn probe_word(i: u32) -> u32 {
    i.wrapping_mul(2_654_435_761)
}

/// Wellons' lowbias32 hash, twin of `probe_hash` in `glsl/probe/probe_memory.comp`.
pub fn probe_hash(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// CPU twin of `glsl/probe/probe_memory.comp` for invocation `id`: the wrapping sum of its loads
/// (the atomic mode: its count of adds; [`atomic_reference`] is what they leave behind).
pub fn memory_reference(mode: MemoryMode, id: u32, count: u32, iterations: u32) -> u32 {
    let mut sum = 0u32;
    for it in 0..iterations {
        match mode {
            MemoryMode::Stream => {
                let v = (it.wrapping_mul(count).wrapping_add(id)) & (PROBE_WORDS / 4 - 1);
                for k in 0..4 {
                    sum = sum.wrapping_add(probe_word(4 * v + k));
                }
            }
            MemoryMode::Atomic => sum = sum.wrapping_add(1),
            MemoryMode::MarchTexelGather => {
                let (origin, step) = march_start(id);
                let cell: [i32; 3] =
                    std::array::from_fn(|a| (origin[a] + it as i32 * step[a]) >> 8);
                for c in 0..8 {
                    let corner = [c & 1, (c >> 1) & 1, c >> 2];
                    let k: [i32; 3] =
                        std::array::from_fn(|a| (cell[a] + corner[a]) & (MARCH_DIM - 1));
                    let texel = (k[0] + MARCH_DIM * (k[1] + MARCH_DIM * k[2])) as u32;
                    for w in 0..4 {
                        sum = sum.wrapping_add(probe_word(4 * texel + w));
                    }
                }
            }
            MemoryMode::CoherentGather | MemoryMode::CoherentTexelGather => {
                let base = probe_hash((id >> 3).wrapping_mul(iterations).wrapping_add(it));
                let i = (base & (PROBE_WORDS - 1) & !7) | (id & 7);
                sum = sum.wrapping_add(probe_word(i));
            }
            MemoryMode::Gather | MemoryMode::TexelGather => {
                let i =
                    probe_hash(id.wrapping_mul(iterations).wrapping_add(it)) & (PROBE_WORDS - 1);
                sum = sum.wrapping_add(probe_word(i));
            }
        }
    }
    sum
}

/// CPU twin of the atomic mode's target after `dispatches` dispatches: how many adds each
/// word received.
pub fn atomic_reference(count: u32, iterations: u32, dispatches: u32) -> Vec<f32> {
    let mut words = vec![0.0f32; PROBE_ATOMIC_WORDS as usize];
    for id in 0..count {
        for it in 0..iterations {
            let a =
                probe_hash(id.wrapping_mul(iterations).wrapping_add(it)) & (PROBE_ATOMIC_WORDS - 1);
            words[a as usize] += dispatches as f32;
        }
    }
    words
}

/// Result of a memory probe.
#[derive(Debug, Clone)]
pub struct MemoryProbe {
    pub mode: MemoryMode,
    pub gpu_ms: Vec<f64>,
    /// Load instructions per second (32-bit for gathers, vec4 for the stream), median.
    pub loads_per_s: f64,
    /// Bytes read per second, median.
    pub bytes_per_s: f64,
    /// Each invocation's sum, for comparison with [`memory_reference`].
    pub output: Vec<u32>,
    /// The atomic mode's target words afterwards (empty for the other modes).
    pub atomic_words: Vec<f32>,
}

/// Runs `probe_memory` in `mode` `repeats + 1` times over `invocations` × `iterations` loads and
/// reports the median rate of the last `repeats`.
pub fn memory_probe(
    ctx: &Context,
    compiler: &ShaderCompiler,
    mode: MemoryMode,
    invocations: u32,
    iterations: u32,
    repeats: u32,
) -> Result<MemoryProbe, VkError> {
    let mut defines = binding_defines();
    defines.push(("PROBE_MODE".into(), mode.define().into()));
    let coherent = matches!(
        mode,
        MemoryMode::CoherentGather | MemoryMode::CoherentTexelGather
    );
    defines.push((
        "PROBE_COHERENT".into(),
        if coherent { "1" } else { "0" }.into(),
    ));
    defines.push(("PROBE_WORDS".into(), format!("{PROBE_WORDS}u")));
    defines.push((
        "PROBE_ATOMIC_WORDS".into(),
        format!("{PROBE_ATOMIC_WORDS}u"),
    ));
    defines.push(("MARCH_DIM".into(), MARCH_DIM.to_string()));
    let spirv = compiler.compile(ShaderSource::File("probe/probe_memory.comp"), &defines)?;
    let source_binding = match mode {
        MemoryMode::TexelGather
        | MemoryMode::CoherentTexelGather
        | MemoryMode::MarchTexelGather => binding::PROBE_TEXELS,
        _ => binding::PROBE_SOURCE,
    };
    // The ray-march mode reads the probe's texel binding as rgba32 texels, as the fast path
    // reads its fine grid.
    let source_kind = match mode {
        MemoryMode::MarchTexelGather => crate::vk::BindingKind::TexelRgba32Uint,
        _ => binding::kind(source_binding),
    };
    let kinds = [
        (binding::PROBE, binding::kind(binding::PROBE)),
        (source_binding, source_kind),
    ];
    let pipeline = ComputePipeline::with_kinds(
        ctx,
        mode.name(),
        &spirv,
        &kinds,
        std::mem::size_of::<CountPush>() as u32,
    )?;
    let words: Vec<u32> = if mode == MemoryMode::Atomic {
        vec![0; PROBE_ATOMIC_WORDS as usize]
    } else {
        (0..PROBE_WORDS).map(probe_word).collect()
    };
    let source = Buffer::from_slice(ctx, "probe words", &words)?;
    drop(words);
    let out = probe_output(ctx, invocations)?;
    let group = BindGroup::new(
        ctx,
        &pipeline,
        &[(binding::PROBE, &out), (source_binding, &source)],
    )?;
    let gpu_ms = timed_dispatches(ctx, &pipeline, &group, invocations, iterations, repeats)?;
    let ms = median(&gpu_ms);
    let loads =
        f64::from(invocations) * f64::from(iterations) * f64::from(mode.loads_per_iteration());
    let bytes_per_load = match mode {
        MemoryMode::Stream | MemoryMode::MarchTexelGather => 16.0,
        MemoryMode::Atomic => 8.0,
        _ => 4.0,
    };
    let rate = |n: f64| if ms > 0.0 { n / (ms * 1e-3) } else { 0.0 };
    let output: Vec<[u32; 4]> = out.read(ctx)?;
    Ok(MemoryProbe {
        mode,
        loads_per_s: rate(loads),
        bytes_per_s: rate(loads * bytes_per_load),
        gpu_ms,
        output: output
            .iter()
            .take(invocations as usize)
            .map(|o| o[0])
            .collect(),
        atomic_words: if mode == MemoryMode::Atomic {
            source.read(ctx)?
        } else {
            Vec::new()
        },
    })
}

/// Every ceiling a kernel may be bound by, measured side by side.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Ceilings {
    pub fma_gflops: f64,
    /// 32-bit random gathers per second: storage buffer, texel-buffer view.
    pub gathers_per_s: f64,
    pub texel_gathers_per_s: f64,
    /// The same when each 8 invocations read 8 consecutive words at a random base.
    pub coherent_gathers_per_s: f64,
    pub coherent_texel_gathers_per_s: f64,
    /// Streaming read bandwidth, bytes per second.
    pub stream_bytes_per_s: f64,
    /// Float adds by compare-and-swap per second, at random words of a 4 MiB buffer.
    pub atomic_adds_per_s: f64,
    /// rgba32 texel loads per second in a ray march's pattern (8×8 tiles of parallel rays, the
    /// 8 corners of each ray's cell per step): the fast path's ceiling.
    pub march_texel_gathers_per_s: f64,
}

/// Measures [`Ceilings`]: `probe_fma`, then `probe_memory` in its seven modes, each the median
/// of `repeats` dispatches after a warm-up.
pub fn ceilings(
    ctx: &Context,
    compiler: &ShaderCompiler,
    repeats: u32,
) -> Result<Ceilings, VkError> {
    let fma = fma_probe(ctx, compiler, 16384, 4096, repeats)?;
    let run = |mode| memory_probe(ctx, compiler, mode, 16384, 256, repeats);
    Ok(Ceilings {
        fma_gflops: fma.gflops,
        gathers_per_s: run(MemoryMode::Gather)?.loads_per_s,
        texel_gathers_per_s: run(MemoryMode::TexelGather)?.loads_per_s,
        coherent_gathers_per_s: run(MemoryMode::CoherentGather)?.loads_per_s,
        coherent_texel_gathers_per_s: run(MemoryMode::CoherentTexelGather)?.loads_per_s,
        stream_bytes_per_s: run(MemoryMode::Stream)?.bytes_per_s,
        atomic_adds_per_s: run(MemoryMode::Atomic)?.loads_per_s,
        march_texel_gathers_per_s: run(MemoryMode::MarchTexelGather)?.loads_per_s,
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
        variant: crate::field::variant::Variant::of(field).name("mls_eval"),
        points: points.len(),
        gpu_ms: times,
        evaluations_per_s: rate,
        mean_neighbours,
        gflops: rate * (39.0 * mean_neighbours + 56.0) * 1e-9,
    })
}

/// How often consecutive samples of a ray fall in the same octree leaf: what keeping the leaf
/// between samples (issue 27 §1) could save of the descents.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LeafReuse {
    /// Consecutive sample pairs both in a leaf that lists samples.
    pub pairs: u64,
    /// Those whose two samples share the leaf.
    pub same_leaf: u64,
}

impl LeafReuse {
    /// The hit rate of a kept leaf: same-leaf pairs over pairs (0 without pairs).
    pub fn rate(&self) -> f64 {
        if self.pairs == 0 {
            0.0
        } else {
            self.same_leaf as f64 / self.pairs as f64
        }
    }
}

/// [`LeafReuse`] over `rays` lines through the box `lo`..`hi`, each through a uniform point of
/// it in a uniform direction (deterministic in `seed`), sampled across the box at spacing
/// `step` (samples at the middles of the steps, as a fixed-step ray caster places them).
pub fn leaf_reuse(
    octree: &Octree,
    (lo, hi): ([f64; 3], [f64; 3]),
    rays: usize,
    step: f64,
    seed: u64,
) -> LeafReuse {
    let mut rng = Lcg::new(seed);
    let mut reuse = LeafReuse {
        pairs: 0,
        same_leaf: 0,
    };
    if step.is_nan() || step <= 0.0 {
        return reuse;
    }
    for _ in 0..rays {
        let o: [f64; 3] = std::array::from_fn(|a| lo[a] + rng.next_f64() * (hi[a] - lo[a]));
        // Uniform on the sphere: z uniform in [−1, 1] (Archimedes), the azimuth uniform.
        let z = 2.0 * rng.next_f64() - 1.0;
        let phi = std::f64::consts::TAU * rng.next_f64();
        let r = (1.0 - z * z).max(0.0).sqrt();
        let d = [r * phi.cos(), r * phi.sin(), z];
        // The line's chord of the box (slabs).
        let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
        for a in 0..3 {
            if d[a] != 0.0 {
                let (ta, tb) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        let mut last = None;
        let mut t = t0 + 0.5 * step;
        while t < t1 {
            let x = std::array::from_fn(|a| o[a] + t * d[a]);
            let leaf = octree
                .leaf_cell(x)
                .map(|(node, _, _)| node)
                .filter(|&node| !octree.leaf_is_empty(node));
            if let (Some(a), Some(b)) = (last, leaf) {
                reuse.pairs += 1;
                reuse.same_leaf += u64::from(a == b);
            }
            last = leaf;
            t += step;
        }
    }
    reuse
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    /// On leaves that are cubes of one side L, a sample uniform in a leaf and the next one at
    /// distance h along d share it with probability Π_a (1 − h|d_a|/L) (h ≤ L): averaged over
    /// uniform directions, the rate [`leaf_reuse`] must measure. Its first sample sits h/2
    /// inside the box, whose faces are leaves' faces here: a bias of about one point in these
    /// rates (measured 0.6–1.2), inside the bound.
    #[test]
    fn leaf_reuse_on_uniform_leaves_is_the_analytic_rate() {
        let scene = Scene::load(
            None,
            &[
                "volume.resolution=17".to_string(),
                "reconstruction.neighbours=\"octree\"".to_string(),
            ],
        )
        .expect("scene");
        let field = Field::new(
            crate::scene::load_volume(&scene).expect("volume"),
            scene.reconstruction,
            &scene.octree,
            |_| {},
        )
        .expect("field");
        let octree = field.octree().expect("octree").expect("an octree");
        let (lo, hi) = field.bounds();
        let bounds = (lo.to_array(), hi.to_array());
        // Every leaf a ray meets has one size (the 17³ grid's octree splits uniformly).
        let mut halves: Vec<f64> = random_points(&field, 4000, 0.0, 3)
            .iter()
            .filter_map(|&x| octree.leaf_cell(x).map(|(_, _, h)| h))
            .collect();
        halves.sort_by(f64::total_cmp);
        halves.dedup();
        assert_eq!(halves.len(), 1, "leaf half sizes {halves:?}");
        let side = 2.0 * halves[0];
        for fraction in [0.1, 0.25, 0.5, 1.0] {
            let h = fraction * side;
            // E_d Π_a (1 − h|d_a|/L) on a 400 × 800 (z, azimuth) midpoint grid of the sphere.
            let (nz, nphi) = (400, 800);
            let mut expected = 0.0;
            for i in 0..nz {
                let z = -1.0 + (i as f64 + 0.5) * 2.0 / nz as f64;
                let r = (1.0 - z * z).sqrt();
                for j in 0..nphi {
                    let phi = (j as f64 + 0.5) * std::f64::consts::TAU / nphi as f64;
                    let d = [r * phi.cos(), r * phi.sin(), z];
                    expected += d
                        .iter()
                        .map(|c| (1.0 - h * c.abs() / side).max(0.0))
                        .product::<f64>();
                }
            }
            expected /= (nz * nphi) as f64;
            let measured = leaf_reuse(octree, bounds, 3000, h, 11);
            eprintln!(
                "h = {fraction} L: measured {:.4} over {} pairs, expected {expected:.4}",
                measured.rate(),
                measured.pairs
            );
            assert!(measured.pairs > 10_000);
            assert!(
                (measured.rate() - expected).abs() < 0.015,
                "h = {fraction} L: measured {} expected {expected}",
                measured.rate()
            );
        }
    }
}
