//! Proves that every struct shared with GLSL has the same layout on both sides: the probe kernel
//! writes field number k into field k of each GLSL struct; each Rust field must hold its number.
mod common;

use bytemuck::{Pod, from_bytes};
use common::*;
use vmls::gpu_types::*;
use vmls::vk::{BindGroup, Buffer, BufferUsage, ComputePipeline, ShaderSource};

fn v(k: f32) -> [f32; 4] {
    [k, k + 0.25, k + 0.5, k + 0.75]
}

fn take<'a, T: Pod>(bytes: &'a [u8], offset: &mut usize) -> &'a T {
    let n = std::mem::size_of::<T>();
    let t = from_bytes(&bytes[*offset..*offset + n]);
    *offset += n;
    t
}

#[test]
fn glsl_and_rust_layouts_agree() {
    let (ctx, compiler) = gpu();
    let spirv = compiler
        .compile(
            ShaderSource::File("probe/layout_probe.comp"),
            &binding_defines(),
        )
        .expect("compile");
    let pipeline =
        ComputePipeline::new(&ctx, "layout_probe", &spirv, &[binding::PROBE], 0).expect("pipeline");
    let out = Buffer::new(&ctx, "layout probe", 4096, BufferUsage::Storage).expect("buffer");
    let group = BindGroup::new(&ctx, &pipeline, &[(binding::PROBE, &out)]).expect("bind");
    ctx.submit(|rec| rec.dispatch(&pipeline, &group, &[], [1, 1, 1], "layout_probe"))
        .expect("submit");
    let words: Vec<u32> = out.read(&ctx).expect("read");
    let bytes: &[u8] = bytemuck::cast_slice(&words);
    let mut at = 0;

    let p: &RenderParams = take(bytes, &mut at);
    // The camera block is the same struct in RenderParams and SplatParams.
    let camera = CameraBlock {
        eye: v(1.0),
        forward: v(2.0),
        right: v(3.0),
        up: v(4.0),
        width: 5,
        height: 6,
        projection: 7,
        tan_half_fov: 8.0,
        ortho_half_height: 9.0,
        _pad: [10.0, 11.0, 12.0],
    };
    let expected = RenderParams {
        camera,
        field: FieldBlock {
            grid_origin: v(13.0),
            grid_inv_spacing: v(14.0),
            inv_support: v(15.0),
            octree_root: v(16.0),
            grid_dims: [17, 18, 19, 20],
            support_cells: 21.0,
            gauss_sigma: 22.0,
            gauss_weight: 23.0,
            _pad: 24.0,
        },
        integrator: IntegratorBlock {
            box_min: v(25.0),
            box_max: v(26.0),
            background: v(27.0),
            step_world: 28.0,
            min_transmittance: 29.0,
            epsilon: 30.0,
            early_termination: 31.0,
            spacing_world: 32.0,
            l_min_world: 33.0,
            tf_count: 34,
            iso_count: 35,
            clip_min: v(101.0),
            clip_max: v(102.0),
        },
        tables: TableBlock {
            s_min: 36.0,
            s_max: 37.0,
            longest_world: 38.0,
            resolution: 39,
            lengths: 40,
            peak: 41.0,
            occupied: [42, 43],
        },
        lighting: v(44.0),
        tf: TfBlock {
            s_tau: std::array::from_fn(|i| v(45.0 + i as f32)),
        },
        sensitivity: SensitivityBlock {
            pieces: std::array::from_fn(|i| v(61.0 + i as f32)),
        },
    };
    assert_eq!(*p, expected, "RenderParams");

    let t: &TfPoint = take(bytes, &mut at);
    assert_eq!(
        *t,
        TfPoint {
            color_tau: v(1.0),
            s: 2.0,
            tau: 3.0,
            _pad: [4.0, 5.0]
        },
        "TfPoint"
    );

    let s: &Sample = take(bytes, &mut at);
    assert_eq!(
        *s,
        Sample {
            pos_value: v(1.0),
            metric: v(2.0),
            metric_off: v(3.0),
        },
        "Sample"
    );

    let m: &MlsOut = take(bytes, &mut at);
    let expected = MlsOut {
        value: 1.0,
        gradient: [2.0, 3.0, 4.0],
        neighbours: 5,
        terms: 6,
        _pad: [7, 8],
    };
    assert_eq!(*m, expected, "MlsOut");

    let r: &RayPush = take(bytes, &mut at);
    assert_eq!(
        *r,
        RayPush {
            row_offset: 1,
            rows: 2,
            first: 3,
            last: 4,
            col_offset: 5,
            cols: 6,
            _pad: [7, 8],
        },
        "RayPush"
    );
    let c: &CountPush = take(bytes, &mut at);
    let i: &IsoSurface = take(bytes, &mut at);
    assert_eq!(
        *i,
        IsoSurface {
            color_opacity: v(1.0),
            value: 2.0,
            _pad: [3.0, 4.0, 5.0]
        },
        "IsoSurface"
    );
    assert_eq!(
        *c,
        CountPush {
            count: 1,
            iterations: 2,
            _pad: [3, 4]
        },
        "CountPush"
    );

    let sp: &SplatParams = take(bytes, &mut at);
    assert_eq!(
        *sp,
        SplatParams {
            camera,
            box_min: v(13.0),
            box_max: v(14.0),
            background: v(15.0),
            lighting: v(16.0),
            near: 17.0,
            focal: 18.0,
            centre_x: 19.0,
            centre_y: 20.0,
            slab0_world: 21.0,
            slab_world: 22.0,
            early_termination: 23.0,
            zero_extinction: 24.0,
            cutoff: 25.0,
            lowpass: 26.0,
            sigma: 27.0,
            lateral_x: 28.0,
            lateral_y: 29.0,
            tf_count: 30,
            iso_count: 31,
            slabs: 32,
            tiles_x: 33,
            kernel_count: 34,
            sheet_first: 35,
            sheet_last: 36,
            cell_min: v(37.0),
            cell_max: v(38.0),
            pixel_window: [39, 40, 41, 42],
            tables: TableBlock {
                s_min: 43.0,
                s_max: 44.0,
                longest_world: 45.0,
                resolution: 46,
                lengths: 47,
                peak: 48.0,
                occupied: [49, 50],
            },
            tf: TfBlock {
                s_tau: std::array::from_fn(|i| v(51.0 + i as f32)),
            },
        },
        "SplatParams"
    );
    let sp: &Splat = take(bytes, &mut at);
    assert_eq!(
        *sp,
        Splat {
            footprint0: v(1.0),
            footprint1: v(2.0),
            footprint2: v(3.0),
            footprint3: v(4.0),
            color: v(5.0),
            bbox: [6, 7, 8, 9],
            slabs: [10, 11, 12, 13],
        },
        "Splat"
    );
    let sp: &ScanPush = take(bytes, &mut at);
    assert_eq!(
        *sp,
        ScanPush {
            buckets: 1,
            blocks: 2,
            _pad: [3, 4]
        },
        "ScanPush"
    );
    let rp: &RasterPush = take(bytes, &mut at);
    assert_eq!(
        *rp,
        RasterPush {
            tile_row: 5,
            pass: 6,
            last_pass: 7,
            chunk: 8,
            sheet_cost: 9,
            band: 10,
            _pad: [11, 12]
        },
        "RasterPush"
    );
    let np: &NextPush = take(bytes, &mut at);
    assert_eq!(
        *np,
        NextPush {
            row_offset: 1,
            rows: 2,
            args_slot: 3,
            cols: 4
        },
        "NextPush"
    );
    let pk: &PackPush = take(bytes, &mut at);
    assert_eq!(
        *pk,
        PackPush {
            count: 1,
            composite: 2,
            _pad: [3, 4],
            background: v(5.0),
        },
        "PackPush"
    );
    let pl: &PlanPush = take(bytes, &mut at);
    assert_eq!(
        *pl,
        PlanPush {
            buckets: 1,
            capacity: 2,
            max_entries: 3,
            bin_groups: 4,
            tiles_x: 5,
            tiles_y: 6,
            segments: 7,
            band_rows: 8,
            chunk: 9,
            sheet_cost: 10,
            steps: 11,
            resumes: 12,
        },
        "PlanPush"
    );
    let wp: &WalkPush = take(bytes, &mut at);
    assert_eq!(
        *wp,
        WalkPush {
            tiles: 1,
            tiles_x: 2,
            slabs: 3,
            band_rows: 4
        },
        "WalkPush"
    );

    drop(group);
    drop((out, pipeline));
    finish(ctx);
}

#[test]
fn binding_numbers_are_unique() {
    let mut numbers: Vec<u32> = binding::ALL.iter().map(|(_, b)| *b).collect();
    numbers.sort_unstable();
    numbers.dedup();
    assert_eq!(numbers.len(), binding::ALL.len());
}

#[test]
fn fma_probe_matches_its_cpu_twin() {
    let (ctx, compiler) = gpu();
    let probe = vmls::probe::fma_probe(&ctx, &compiler, 256, 16, 1).expect("probe");
    for (id, got) in probe.output.iter().enumerate() {
        let want = vmls::probe::fma_reference(id as u32, 16);
        for l in 0..4 {
            // Same f32 FMA sequence on both sides; only the final summation order may differ.
            assert!(
                (got[l] - want[l]).abs() <= 1e-5 * want[l].abs().max(1.0),
                "invocation {id}: {got:?} vs {want:?}"
            );
        }
    }
    assert!(probe.gflops > 0.0);
    finish(ctx);
}

#[test]
fn memory_probes_match_their_cpu_twin() {
    use vmls::probe::{MemoryMode, memory_probe, memory_reference};
    let (ctx, compiler) = gpu();
    for mode in MemoryMode::ALL {
        let (count, iterations) = (300, 17);
        let probe = memory_probe(&ctx, &compiler, mode, count, iterations, 1).expect("probe");
        assert_eq!(probe.output.len(), count as usize);
        for (id, &got) in probe.output.iter().enumerate() {
            // Integer sums: bit-exact.
            assert_eq!(
                got,
                memory_reference(mode, id as u32, count, iterations),
                "{mode:?} {id}"
            );
        }
        assert!(probe.loads_per_s > 0.0 && probe.bytes_per_s > probe.loads_per_s);
        if mode == MemoryMode::Atomic {
            // Two dispatches (a warm-up and one timed): every add counted, none lost.
            let want = vmls::probe::atomic_reference(count, iterations, 2);
            assert_eq!(probe.atomic_words, want);
        }
    }
    finish(ctx);
}
