//! Shared test helpers: every GPU test runs with the Khronos validation layer on and fails on
//! any validation error or leaked allocation.
#![allow(dead_code)]

pub mod cli;
pub mod splat;

use vmls::data::dataset::{CellType, Cells, Geometry};
use vmls::data::{Volume, marschner_lobb};
use vmls::field::Field;
use vmls::recon::{Basis, GradientMode, OctreeSettings, Weight};
use vmls::scene::{NeighbourMode, Reconstruction, Scene};
use vmls::vk::{Context, ContextOptions, ShaderCompiler};

/// The built-in default scene on the general path with linear intervals (as it stood before it
/// opted into `resample = "auto"` and Hermite intervals), with `overrides` applied after: the
/// tests of the direct solve and its CPU twin start from it.
pub fn general_scene(overrides: &[String]) -> Scene {
    let mut o = vec![
        "reconstruction.resample=0".to_string(),
        "render.interval=\"linear\"".to_string(),
    ];
    o.extend_from_slice(overrides);
    Scene::load(None, &o).expect("scene")
}

/// A validated context on the default device (lavapipe in CI) and a shader compiler.
pub fn gpu() -> (Context, ShaderCompiler) {
    gpu_with(false)
}

/// As [`gpu`], optionally forcing the staging upload/readback path of discrete GPUs.
pub fn gpu_with(force_staging: bool) -> (Context, ShaderCompiler) {
    let ctx = Context::new(&ContextOptions {
        validation: Some(true),
        sync_validation: None,
        device: None,
        force_staging,
    })
    .unwrap_or_else(|e| panic!("no Vulkan device for the tests (run tools/setup): {e}"));
    (ctx, ShaderCompiler::new().expect("shaderc"))
}

/// Asserts the context saw no validation message (core or synchronization validation, error
/// or warning) and holds no allocation.
pub fn finish(ctx: Context) {
    assert_eq!(ctx.validation_errors(), 0, "Vulkan validation errors");
    assert_eq!(ctx.validation_warnings(), 0, "Vulkan validation warnings");
    assert_eq!(ctx.live_allocations(), 0, "GPU allocations leaked");
}

pub fn recon(
    basis: Basis,
    weight: Weight,
    gradient: GradientMode,
    neighbours: NeighbourMode,
    support: f64,
) -> Reconstruction {
    Reconstruction {
        method: vmls::recon::ReconMethod::Mls,
        sigma: vmls::recon::gaussian::DEFAULT_SIGMA,
        basis,
        weight,
        gradient,
        support,
        neighbours,
        resample: 0,
        resample_auto: false,
        resample_direct: false,
        direct_cells: None,
    }
}

/// Marschner–Lobb field of resolution n.
pub fn ml_field(n: usize, r: Reconstruction) -> Field {
    Field::new(
        marschner_lobb::generate(n),
        r,
        &OctreeSettings::default(),
        |_| {},
    )
    .expect("field")
}

/// A grid sampling `f` at its points.
pub fn volume_from(
    dims: [usize; 3],
    spacing: [f64; 3],
    origin: [f64; 3],
    f: impl Fn([f64; 3]) -> f64,
) -> Volume {
    let mut values = Vec::new();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = [
                    origin[0] + i as f64 * spacing[0],
                    origin[1] + j as f64 * spacing[1],
                    origin[2] + k as f64 * spacing[2],
                ];
                values.push(f(p) as f32);
            }
        }
    }
    Volume {
        dims,
        origin,
        spacing,
        values: values.into(),
    }
}

/// A torus of square cross-section (major radius 1, tube half-width 0.35) split into hexahedra,
/// each hexahedron into 6 tetrahedra (Kuhn subdivision, consistent across shared faces).
pub fn tet_torus(around: usize, across: usize) -> Geometry {
    let mut points = Vec::new();
    let n = across + 1;
    let id = |a: usize, i: usize, j: usize| ((a % around) * n * n + j * n + i) as u32;
    for a in 0..around {
        let phi = 2.0 * std::f64::consts::PI * a as f64 / around as f64;
        for j in 0..n {
            for i in 0..n {
                let r = 1.0 + 0.7 * (i as f64 / across as f64 - 0.5);
                let z = 0.7 * (j as f64 / across as f64 - 0.5);
                points.push([r * phi.cos(), r * phi.sin(), z]);
            }
        }
    }
    let mut cells = Cells::default();
    for a in 0..around {
        for j in 0..across {
            for i in 0..across {
                // Corner c = bit0: +i, bit1: +j, bit2: +a.
                let c = |b: usize| id(a + (b >> 2 & 1), i + (b & 1), j + (b >> 1 & 1));
                for path in [[1, 3], [1, 5], [2, 3], [2, 6], [4, 5], [4, 6]] {
                    let mut tet = [c(0), c(path[0]), c(path[1]), c(7)];
                    // Half of the Kuhn tetrahedra are mirrored: swap two points to give every
                    // one VTK's positive orientation.
                    let p = tet.map(|i| points[i as usize]);
                    let e = [1, 2, 3].map(|k| [0, 1, 2].map(|a| p[k][a] - p[0][a]));
                    let det = e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1])
                        - e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0])
                        + e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]);
                    if det < 0.0 {
                        tet.swap(1, 2);
                    }
                    cells.push(CellType::Tetra, &tet);
                }
            }
        }
    }
    Geometry::Unstructured { points, cells }
}

/// Point data "f" = `f` at the points of `geometry`.
pub fn point_data(geometry: Geometry, f: impl Fn([f64; 3]) -> f64) -> vmls::data::dataset::Dataset {
    let values = (0..geometry.point_count())
        .map(|i| f(geometry.point(i)) as f32)
        .collect();
    vmls::data::dataset::Dataset {
        geometry,
        arrays: vec![vmls::data::dataset::DataArray {
            name: "f".into(),
            location: vmls::data::dataset::Location::Point,
            components: 1,
            values,
        }],
    }
}

/// The fast path's values at `points` on the GPU (`mls_eval`) against its CPU twin: the largest
/// difference relative to the value range. Asserts that every GPU evaluation read 8 fine points.
pub fn fast_path_gpu_vs_cpu(field: &Field, points: &[[f64; 3]]) -> f64 {
    let (ctx, compiler) = gpu();
    let gpu_field = vmls::field::gpu::GpuField::upload(&ctx, field).expect("upload");
    let (out, _) =
        vmls::field::gpu::evaluate(&ctx, &compiler, field, &gpu_field, points, 1).expect("eval");
    drop(gpu_field);
    finish(ctx);
    let n = field.neighbours().expect("neighbours");
    let (lo, hi) = field.value_range();
    let mut worst = 0.0f64;
    for (g, p) in out.iter().zip(points) {
        let cpu = field.evaluate(n.as_ref(), *p).expect("defined");
        assert_eq!(g.neighbours, 8, "the fast path reads 8 fine points");
        worst = worst.max((f64::from(g.value) - cpu.value).abs() / (hi - lo));
    }
    worst
}

/// A scene's ray-cast frame of `field` on the GPU (validated) and by the CPU twin, with
/// preintegration tables of 128 entries.
pub fn gpu_and_cpu_frames(
    field: &Field,
    scene: &Scene,
) -> (vmls::renderer::GpuImage, Vec<vmls::raycast::PixelResult>) {
    let (mut images, cpu) = gpu_frames_in_chunks_and_cpu(field, scene, &[None]);
    (images.remove(0), cpu)
}

/// [`gpu_and_cpu_frames`] with the GPU frame rendered once per entry of `chunks` (outer steps
/// per dispatch, `RaySetup::chunk`; None: the default).
pub fn gpu_frames_in_chunks_and_cpu(
    field: &Field,
    scene: &Scene,
    chunks: &[Option<u32>],
) -> (
    Vec<vmls::renderer::GpuImage>,
    Vec<vmls::raycast::PixelResult>,
) {
    let setup = scene.ray_setup(field).expect("setup");
    let tables = vmls::raycast::build_tables(&setup, field, &scene.transfer, 128, |_| {});
    let cpu = vmls::raycast::raycast_image(&setup, field, &scene.transfer, tables.as_ref())
        .expect("CPU twin");
    let (ctx, compiler) = gpu();
    let gf = vmls::field::gpu::GpuField::upload(&ctx, field).expect("upload");
    let images = frames_in_chunks(&ctx, &compiler, scene, field, &gf, tables.as_ref(), chunks);
    drop(gf);
    finish(ctx);
    (images, cpu)
}

/// The scene's frame by the stateless `render`, once per entry of `chunks` (outer steps per
/// dispatch, `RaySetup::chunk`; None: the default).
pub fn frames_in_chunks(
    ctx: &vmls::vk::Context,
    compiler: &vmls::vk::ShaderCompiler,
    scene: &Scene,
    field: &Field,
    gf: &vmls::field::gpu::GpuField,
    tables: Option<&vmls::view::preintegration::PreintegrationTables>,
    chunks: &[Option<u32>],
) -> Vec<vmls::renderer::GpuImage> {
    chunks
        .iter()
        .map(|&chunk| {
            let mut setup = scene.ray_setup(field).expect("setup");
            setup.chunk = chunk;
            vmls::renderer::render(
                ctx,
                compiler,
                field,
                gf,
                &scene.transfer,
                tables,
                &setup,
                |_| {},
            )
            .expect("render")
        })
        .collect()
}

/// The largest channel difference between two GPU images.
pub fn gpu_diff(a: &[[f32; 4]], b: &[[f32; 4]]) -> f32 {
    a.iter()
        .zip(b)
        .flat_map(|(p, q)| (0..4).map(move |k| (p[k] - q[k]).abs()))
        .fold(0.0, f32::max)
}
