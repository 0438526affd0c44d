//! Sample sets from irregular data: supports, linear reproduction on every data kind (CPU f64
//! and GPU f32), holes of isotropic supports on anisotropic grids, convergence on scattered
//! points, duplicate merging and the mesh checks.
mod common;

use common::*;
use std::path::Path;
use vmls::data::dataset::{CellType, Cells, DataArray, Dataset, Geometry, Location};
use vmls::field::Field;
use vmls::field::gpu::{GpuField, evaluate};
use vmls::probe::Lcg;
use vmls::recon::mls::{MlsSettings, mls_evaluate};
use vmls::recon::{Basis, GradientMode, OctreeSettings, Weight};
use vmls::samples::{Domain, SampleError, SampleSet, SampleSettings, mesh};
use vmls::scene::NeighbourMode;

const LINEAR: [f64; 4] = [0.3, 1.5, -2.0, 0.75];

/// Linear MLS reproduces the linear field exactly; the samples hold it in f32, so the CPU's f64
/// result is exact to the values' f32 rounding (≤ 3e-7 for |f| < 5).
const CPU_TOLERANCE: f64 = 1e-6;

fn linear(p: [f64; 3]) -> f64 {
    LINEAR[0] + LINEAR[1] * p[0] + LINEAR[2] * p[1] + LINEAR[3] * p[2]
}

fn samples(d: &Dataset, support: f64, knn: usize, anisotropic: Option<bool>) -> SampleSet {
    d.validate(Path::new("test")).expect("valid dataset");
    SampleSet::from_dataset(
        d,
        Path::new("test"),
        None,
        &SampleSettings {
            support,
            knn_support: support,
            knn,
            anisotropic,
        },
    )
    .expect("sample set")
}

fn field(set: SampleSet, basis: Basis) -> Field {
    Field::from_samples(
        set,
        recon(
            basis,
            Weight::Wendland,
            GradientMode::Local,
            NeighbourMode::Octree,
            1.0,
        ),
        &OctreeSettings::default(),
        |_| {},
    )
    .expect("field")
}

/// Uniform random points in [0, 1]³.
fn random_cloud(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = Lcg::new(seed);
    (0..n)
        .map(|_| [rng.next_f64(), rng.next_f64(), rng.next_f64()])
        .collect()
}

/// Frame-relative query points inside `lo..hi` (world), shrunk by `margin`.
fn queries(field: &Field, lo: [f64; 3], hi: [f64; 3], margin: f64, n: usize) -> Vec<[f64; 3]> {
    let mut rng = Lcg::new(99);
    let o = field.frame_origin.to_array();
    (0..n)
        .map(|_| {
            [0, 1, 2]
                .map(|a| lo[a] + margin + (hi[a] - lo[a] - 2.0 * margin) * rng.next_f64() - o[a])
        })
        .collect()
}

/// Max |f − linear| over the queries where the linear basis was solved, on the CPU (f64), and
/// the fraction of queries that were.
fn cpu_linear_error(field: &Field, pts: &[[f64; 3]]) -> (f64, f64) {
    let n = field.neighbours().expect("neighbours");
    let o = field.frame_origin.to_array();
    let mut worst: f64 = 0.0;
    let mut solved = 0;
    for p in pts {
        if let Some(m) = mls_evaluate(&field.mls(), n.as_ref(), *p)
            && m.terms == 4
        {
            solved += 1;
            let world = [p[0] + o[0], p[1] + o[1], p[2] + o[2]];
            worst = worst.max((m.value - linear(world)).abs());
        }
    }
    (worst, solved as f64 / pts.len() as f64)
}

/// The same on the GPU (f32), also checking that the GPU solved the same basis.
fn gpu_linear_error(field: &Field, pts: &[[f64; 3]]) -> f64 {
    let (ctx, compiler) = gpu();
    let gpu_field = GpuField::upload(&ctx, field).expect("upload");
    let (out, _) = evaluate(&ctx, &compiler, field, &gpu_field, pts, 1).expect("mls_eval");
    drop(gpu_field);
    finish(ctx);
    let n = field.neighbours().expect("neighbours");
    let o = field.frame_origin.to_array();
    let mut worst: f64 = 0.0;
    let mut mismatched = 0;
    for (g, p) in out.iter().zip(pts) {
        assert!(g.value.is_finite(), "GPU value not finite at {p:?}");
        let cpu = mls_evaluate(&field.mls(), n.as_ref(), *p);
        if cpu.map(|m| m.terms) != Some(g.terms).filter(|&t| t > 0) {
            mismatched += 1;
            continue;
        }
        if g.terms == 4 {
            let world = [p[0] + o[0], p[1] + o[1], p[2] + o[2]];
            worst = worst.max((f64::from(g.value) - linear(world)).abs());
        }
    }
    assert!(
        mismatched <= pts.len() / 100,
        "{mismatched} of {} points solved a different basis on the GPU",
        pts.len()
    );
    worst
}

#[test]
fn linear_mls_reproduces_linear_fields_on_scattered_points() {
    let cloud = random_cloud(3000, 5);
    for anisotropic in [false, true] {
        let d = point_data(
            Geometry::Points {
                points: cloud.clone(),
            },
            linear,
        );
        let f = field(samples(&d, 1.6, 8, Some(anisotropic)), Basis::Linear);
        let pts = queries(&f, [0.0; 3], [1.0; 3], 0.1, 2000);
        let (err, solved) = cpu_linear_error(&f, &pts);
        assert!(
            err < CPU_TOLERANCE,
            "anisotropic={anisotropic}: CPU error {err}"
        );
        assert!(
            solved > 0.99,
            "anisotropic={anisotropic}: linear solved at {solved}"
        );
        let gpu_err = gpu_linear_error(&f, &pts);
        // f32: values up to ~4, sums of ~30 samples.
        assert!(
            gpu_err < 2e-4,
            "anisotropic={anisotropic}: GPU error {gpu_err}"
        );
    }
}

/// A grid warped by a smooth, invertible map: x' = x + 0.15 sin(πy), y' = y + 0.1 x², z' = z.
fn warped_grid(n: usize) -> Geometry {
    let mut points = Vec::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let (x, y, z) = (
                    i as f64 / (n - 1) as f64,
                    j as f64 / (n - 1) as f64,
                    k as f64 / (n - 1) as f64,
                );
                points.push([
                    x + 0.15 * (std::f64::consts::PI * y).sin(),
                    y + 0.1 * x * x,
                    z,
                ]);
            }
        }
    }
    Geometry::Structured {
        dims: [n; 3],
        points,
    }
}

#[test]
fn linear_mls_reproduces_linear_fields_on_a_warped_curvilinear_grid() {
    let d = point_data(warped_grid(12), linear);
    for anisotropic in [false, true] {
        let set = samples(&d, 2.0, 8, Some(anisotropic));
        assert!(matches!(set.domain, Domain::Hull(_)));
        let f = field(set, Basis::Linear);
        let pts = queries(&f, [0.2, 0.2, 0.1], [0.9, 0.9, 0.9], 0.0, 1500);
        let (err, solved) = cpu_linear_error(&f, &pts);
        assert!(
            err < CPU_TOLERANCE,
            "anisotropic={anisotropic}: CPU error {err}"
        );
        assert!(solved > 0.99, "linear solved at {solved}");
        let gpu_err = gpu_linear_error(&f, &pts);
        assert!(
            gpu_err < 2e-4,
            "anisotropic={anisotropic}: GPU error {gpu_err}"
        );
    }
}

#[test]
fn tetrahedral_torus_hull_is_closed_and_linear_fields_are_reproduced() {
    let d = point_data(tet_torus(24, 3), linear);
    let set = samples(&d, 2.0, 8, Some(false));
    let Domain::Hull(hull) = &set.domain else {
        panic!("a mesh has a hull domain");
    };
    // Boundary of a 24 × 3 × 3 torus: 4 sides × 24 × 3 quads, 2 triangles each.
    assert_eq!(hull.triangles.len(), 4 * 24 * 3 * 2);
    // Closed: every edge is shared by exactly two boundary triangles.
    let mut edges = std::collections::HashMap::new();
    for t in &hull.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    assert!(edges.values().all(|&c| c == 2), "hull is not closed");
    // Facing out: the volume it encloses is the sum of the cells' volumes.
    let Geometry::Unstructured { points, cells } = &d.geometry else {
        unreachable!()
    };
    let cells_volume: f64 = (0..cells.len())
        .map(|c| {
            let p: Vec<[f64; 3]> = cells.cell(c).iter().map(|&i| points[i as usize]).collect();
            mesh::cell_volume(cells.types[c], &p)
        })
        .sum();
    let enclosed = mesh::enclosed_volume(hull);
    assert!(
        (enclosed - cells_volume).abs() < 1e-9 * cells_volume,
        "hull encloses {enclosed}, cells fill {cells_volume}"
    );
    assert_eq!(set.provenance.inverted_cells, 0);
    // Isotropic kNN supports, then ellipsoids from each point's one-ring.
    let one_ring = samples(&d, 2.0, 8, Some(true));
    assert_eq!(one_ring.provenance.support_kind, "anisotropic-one-ring");
    assert!(one_ring.has_full_metric());
    for set in [set, one_ring] {
        let kind = set.provenance.support_kind;
        let f = field(set, Basis::Linear);
        // Queries inside the tube: radius 0.8–1.2, |z| < 0.15.
        let mut rng = Lcg::new(3);
        let o = f.frame_origin.to_array();
        let pts: Vec<[f64; 3]> = (0..1500)
            .map(|_| {
                let phi = 2.0 * std::f64::consts::PI * rng.next_f64();
                let r = 0.8 + 0.4 * rng.next_f64();
                let z = 0.3 * (rng.next_f64() - 0.5);
                [r * phi.cos() - o[0], r * phi.sin() - o[1], z - o[2]]
            })
            .collect();
        let (err, solved) = cpu_linear_error(&f, &pts);
        assert!(err < CPU_TOLERANCE, "{kind}: CPU error {err}");
        assert!(solved > 0.99, "{kind}: linear solved at {solved}");
        let gpu_err = gpu_linear_error(&f, &pts);
        assert!(gpu_err < 2e-4, "{kind}: GPU error {gpu_err}");
    }
}

#[test]
fn cell_data_is_sampled_at_centroids() {
    let mut d = point_data(tet_torus(16, 2), linear);
    let Geometry::Unstructured { points, cells } = &d.geometry else {
        unreachable!()
    };
    let values: Vec<f32> = (0..cells.len())
        .map(|c| {
            let ids = cells.cell(c);
            let mut m = [0.0; 3];
            for &i in ids {
                for a in 0..3 {
                    m[a] += points[i as usize][a] / ids.len() as f64;
                }
            }
            linear(m) as f32
        })
        .collect();
    d.arrays = vec![DataArray {
        name: "cellf".into(),
        location: Location::Cell,
        components: 1,
        values: values.into(),
    }];
    let set = samples(&d, 2.0, 8, None);
    assert_eq!(set.len(), 16 * 2 * 2 * 6);
    assert_eq!(set.provenance.location, Location::Cell);
    let f = field(set, Basis::Linear);
    let o = f.frame_origin.to_array();
    let pts: Vec<[f64; 3]> = (0..200)
        .map(|k| {
            let phi = k as f64 * 0.031;
            [phi.cos() - o[0], phi.sin() - o[1], -o[2]]
        })
        .collect();
    let (err, solved) = cpu_linear_error(&f, &pts);
    assert!(
        err < CPU_TOLERANCE && solved > 0.99,
        "error {err}, solved {solved}"
    );
}

#[test]
fn isotropic_supports_leave_holes_on_a_10_to_1_grid_and_diagonal_ones_do_not() {
    let coords = [
        (0..12).map(|i| i as f64 * 0.1).collect::<Vec<_>>(),
        (0..12).map(|i| i as f64 * 0.1).collect(),
        (0..6).map(|i| i as f64).collect(),
    ];
    let d = point_data(Geometry::Rectilinear { coords }, linear);
    let pts_of = |f: &Field| queries(f, [0.0; 3], [1.1, 1.1, 5.0], 0.0, 2000);
    // Diagonal supports (the rectilinear default): exact everywhere in the box.
    let f = field(samples(&d, 1.6, 8, None), Basis::Linear);
    assert_eq!(f.samples.provenance.support_kind, "diagonal");
    let pts = pts_of(&f);
    let (err, solved) = cpu_linear_error(&f, &pts);
    assert!(
        err < CPU_TOLERANCE && solved == 1.0,
        "diagonal: error {err}, solved {solved}"
    );
    let gpu_err = gpu_linear_error(&f, &pts);
    assert!(gpu_err < 2e-4, "diagonal GPU error {gpu_err}");
    // Isotropic kNN supports: the 8 nearest neighbours lie in the sample's own layer, so the
    // radius (support × 0.2) cannot reach the next layer 1.0 away: holes between layers.
    let f = field(samples(&d, 1.6, 8, Some(false)), Basis::Linear);
    let pts = pts_of(&f);
    let n = f.neighbours().expect("neighbours");
    let undefined = pts
        .iter()
        .filter(|p| mls_evaluate(&f.mls(), n.as_ref(), **p).is_none())
        .count();
    assert!(
        undefined > pts.len() / 4,
        "isotropic: only {undefined} of {} points undefined",
        pts.len()
    );
}

#[test]
fn error_falls_with_density_on_scattered_samples() {
    let g = |p: [f64; 3]| (2.0 * p[0]).sin() * (1.5 * p[1]).cos() + p[2] * p[2];
    let mut errors = Vec::new();
    let sizes = [500, 4000, 32000];
    for &n in &sizes {
        let cloud = random_cloud(n, 11);
        let d = point_data(Geometry::Points { points: cloud }, g);
        let f = field(samples(&d, 1.6, 8, Some(false)), Basis::Linear);
        let pts = queries(&f, [0.0; 3], [1.0; 3], 0.15, 800);
        let nb = f.neighbours().expect("neighbours");
        let o = f.frame_origin.to_array();
        let rms = (pts
            .iter()
            .map(|p| {
                let v = mls_evaluate(&f.mls(), nb.as_ref(), *p).map_or(1.0, |m| m.value);
                (v - g([p[0] + o[0], p[1] + o[1], p[2] + o[2]])).powi(2)
            })
            .sum::<f64>()
            / pts.len() as f64)
            .sqrt();
        errors.push(rms);
    }
    // Spacing falls by 2 per 8× points; the linear basis should converge at about order 2.
    let orders: Vec<f64> = errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
    println!("scattered convergence: rms {errors:?}, observed orders {orders:?}");
    assert!(
        orders.iter().all(|&o| o > 1.2),
        "errors {errors:?} give orders {orders:?}"
    );
}

#[test]
fn octree_finds_every_neighbour_of_anisotropic_supports() {
    let cloud = random_cloud(2000, 21);
    let d = point_data(Geometry::Points { points: cloud }, |p| {
        (3.0 * p[0]).sin() + p[1] * p[2]
    });
    let set = samples(&d, 1.5, 8, Some(true));
    assert!(set.has_full_metric());
    let f = field(set, Basis::Linear);
    // Brute force: every sample, no octree.
    struct All<'a>(&'a Field);
    impl vmls::recon::mls::Neighbours for All<'_> {
        fn basis_scale(&self, x: [f64; 3]) -> [f64; 3] {
            self.0.neighbours().expect("neighbours").basis_scale(x)
        }
        fn for_each(&self, _x: [f64; 3], visit: &mut vmls::recon::mls::Visit<'_>) {
            let s = &self.0.samples;
            for i in 0..s.len() {
                visit(i, s.position(i), f64::from(s.values.get(i)), &s.metric(i));
            }
        }
    }
    let settings = MlsSettings {
        basis: Basis::Linear,
        weight: Weight::Wendland,
        gradient: GradientMode::Local,
    };
    let tree = f.neighbours().expect("neighbours");
    for p in queries(&f, [0.0; 3], [1.0; 3], 0.0, 400) {
        let a = mls_evaluate(&settings, tree.as_ref(), p);
        let b = mls_evaluate(&settings, &All(&f), p);
        match (a, b) {
            (Some(a), Some(b)) => {
                assert_eq!(a.neighbours, b.neighbours, "at {p:?}");
                assert!((a.value - b.value).abs() < 1e-9, "at {p:?}");
            }
            (None, None) => {}
            _ => panic!("octree and brute force disagree on definedness at {p:?}"),
        }
    }
}

#[test]
fn coincident_samples_are_merged_with_averaged_values() {
    let mut points = random_cloud(50, 4);
    points.push(points[7]);
    points.push(points[7]);
    let mut d = point_data(Geometry::Points { points }, |_| 1.0);
    let vmls::data::Values::F32(values) = &mut d.arrays[0].values else {
        panic!("a point array built from f32 values is stored as f32");
    };
    values[7] = 1.0;
    values[50] = 2.0;
    values[51] = 6.0;
    let set = samples(&d, 1.5, 8, None);
    assert_eq!(set.provenance.merged, 2);
    assert_eq!(set.len(), 50);
    assert!(set.values.iter().any(|v| v == 3.0), "average of 1, 2 and 6");
}

fn one_tet(p3: [f64; 3]) -> Dataset {
    let mut cells = Cells::default();
    cells.push(CellType::Tetra, &[0, 1, 2, 3]);
    point_data(
        Geometry::Unstructured {
            points: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], p3],
            cells,
        },
        linear,
    )
}

fn sample_error(d: &Dataset) -> String {
    let e = SampleSet::from_dataset(d, Path::new("mesh.vtu"), None, &SampleSettings::default())
        .expect_err("must fail");
    assert!(matches!(e, SampleError::Invalid { .. }), "{e:?}");
    let text = e.to_string();
    assert!(text.contains("mesh.vtu"), "{text}");
    text
}

#[test]
fn degenerate_cells_are_rejected_and_inverted_ones_counted() {
    let text = sample_error(&one_tet([0.5, 0.5, 0.0]));
    assert!(
        text.contains("cell 0") && text.contains("degenerate"),
        "{text}"
    );
    let set = samples(&one_tet([0.0, 0.0, -1.0]), 2.0, 3, None);
    assert_eq!(set.provenance.inverted_cells, 1);
}

#[test]
fn non_manifold_meshes_are_rejected() {
    // Three tetrahedra sharing the face (0, 1, 2).
    let mut cells = Cells::default();
    cells.push(CellType::Tetra, &[0, 1, 2, 3]);
    cells.push(CellType::Tetra, &[0, 2, 1, 4]);
    cells.push(CellType::Tetra, &[0, 1, 2, 5]);
    let d = point_data(
        Geometry::Unstructured {
            points: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.2, 0.2, 1.0],
                [0.2, 0.2, -1.0],
                [0.3, 0.3, 2.0],
            ],
            cells,
        },
        linear,
    );
    let text = sample_error(&d);
    assert!(text.contains("non-manifold"), "{text}");
}

#[test]
fn cell_data_of_grids_keeps_the_grids_domain() {
    // An image of 5³ points has 4³ cells; their centres form a grid offset by half a cell, but
    // the domain stays the points' box.
    let image = Geometry::Image {
        dims: [5; 3],
        origin: [0.0; 3],
        spacing: [1.0; 3],
    };
    let d = Dataset {
        geometry: image,
        arrays: vec![DataArray {
            name: "c".into(),
            location: Location::Cell,
            components: 1,
            values: vec![1.0; 64].into(),
        }],
    };
    let set = samples(&d, 2.0, 8, None);
    assert_eq!(set.len(), 64);
    assert_eq!(set.position(0), [0.5; 3]);
    assert_eq!(set.domain_box(), ([0.0; 3], [4.0; 3]));
    // A curvilinear grid's hull is its own boundary, not that of its cell centres.
    let mut d = point_data(warped_grid(6), linear);
    d.arrays[0] = DataArray {
        name: "c".into(),
        location: Location::Cell,
        components: 1,
        values: vec![1.0; 125].into(),
    };
    let set = samples(&d, 2.0, 8, None);
    assert_eq!(set.len(), 125);
    assert_eq!(set.domain_box(), d.geometry.bounds());
}
