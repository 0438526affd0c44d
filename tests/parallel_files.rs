//! Parallel VTK XML (`.pvti`, `.pvtr`, `.pvts`, `.pvtu`, `.pvtp`; issue 30 §2): a summary and
//! its pieces read as the one dataset the pieces were cut from, shared faces and duplicate
//! ghost cells counted once; pieces that leave a hole, disagree or are missing are errors
//! naming the file. And a `.pvti` read brick by brick (`bricks::parallel`): every rank reads
//! only the pieces that meet its brick and takes exactly the samples the whole field's brick
//! holds; a `.pvtu` or `.pvtp` read by the ranks together (`bricks::parallel_scattered`) gives
//! every rank the whole field's brick.

mod common;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use vmls::bricks::exchange::LocalRanks;
use vmls::bricks::parallel::GridPlan;
use vmls::bricks::parallel_scattered::{ScatteredBrick, read_scattered};
use vmls::bricks::{Ghosts, divide, piece_of};
use vmls::data::dataset::{Dataset, Geometry};
use vmls::data::load_dataset;
use vmls::data::vtk_xml_parallel::Summary;
use vmls::field::Field;
use vmls::recon::OctreeSettings;
use vmls::samples::{SampleSet, SampleSettings};

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vmls-parallel-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

fn f(p: [f64; 3]) -> f64 {
    0.5 + 0.3 * (3.0 * p[0]).sin() * p[1] + 0.2 * p[2] * p[2]
}

fn join<T: std::fmt::Display>(v: impl IntoIterator<Item = T>) -> String {
    let mut s = String::new();
    for x in v {
        let _ = write!(s, "{x} ");
    }
    s
}

fn ext(e: [i64; 6]) -> String {
    join(e)
}

/// The points of extent `e` in x-fastest order.
fn points_of(e: [i64; 6]) -> Vec<[i64; 3]> {
    let mut p = Vec::new();
    for k in e[4]..=e[5] {
        for j in e[2]..=e[3] {
            for i in e[0]..=e[1] {
                p.push([i, j, k]);
            }
        }
    }
    p
}

/// The cells (lower corners) of extent `e`.
fn cells_of(e: [i64; 6]) -> Vec<[i64; 3]> {
    points_of([e[0], e[1] - 1, e[2], e[3] - 1, e[4], e[5] - 1])
}

/// A grid file of kind `kind` over extent `e`: point array "f" and cell array "c" of the
/// positions `at(i, j, k)`.
fn grid_piece(
    kind: &str,
    whole: [i64; 6],
    e: [i64; 6],
    at: &dyn Fn([i64; 3]) -> [f64; 3],
) -> String {
    let pts = points_of(e);
    let centre = |c: [i64; 3]| {
        let (a, b) = (at(c), at([c[0] + 1, c[1] + 1, c[2] + 1]));
        [0, 1, 2].map(|k| 0.5 * (a[k] + b[k]))
    };
    let geometry = match kind {
        "ImageData" => String::new(),
        "RectilinearGrid" => format!(
            "<Coordinates><DataArray type=\"Float64\" format=\"ascii\">{}</DataArray>\
             <DataArray type=\"Float64\" format=\"ascii\">{}</DataArray>\
             <DataArray type=\"Float64\" format=\"ascii\">{}</DataArray></Coordinates>",
            join((e[0]..=e[1]).map(|i| at([i, 0, 0])[0])),
            join((e[2]..=e[3]).map(|j| at([0, j, 0])[1])),
            join((e[4]..=e[5]).map(|k| at([0, 0, k])[2])),
        ),
        _ => format!(
            "<Points><DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">{}\
             </DataArray></Points>",
            join(pts.iter().flat_map(|&p| at(p)))
        ),
    };
    let image = if kind == "ImageData" {
        " Origin=\"-1 -1 -1\" Spacing=\"0.125 0.125 0.125\""
    } else {
        ""
    };
    format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"{kind}\" version=\"1.0\">\
         <{kind} WholeExtent=\"{}\"{image}><Piece Extent=\"{}\">{geometry}\
         <PointData><DataArray type=\"Float32\" Name=\"f\" format=\"ascii\">{}</DataArray>\
         </PointData><CellData><DataArray type=\"Float32\" Name=\"c\" format=\"ascii\">{}\
         </DataArray></CellData></Piece></{kind}></VTKFile>\n",
        ext(whole),
        ext(e),
        join(pts.iter().map(|&p| f(at(p)) as f32)),
        join(cells_of(e).iter().map(|&c| f(centre(c)) as f32)),
    )
}

/// Writes a parallel grid file cut into `cuts` pieces per axis (sharing their faces) and the
/// serial file of the whole; returns both paths.
fn grid_files(
    d: &Path,
    kind: &str,
    whole: [i64; 6],
    cuts: usize,
    at: &dyn Fn([i64; 3]) -> [f64; 3],
) -> (PathBuf, PathBuf) {
    let (ext_name, pkind) = match kind {
        "ImageData" => ("vti", "PImageData"),
        "RectilinearGrid" => ("vtr", "PRectilinearGrid"),
        _ => ("vts", "PStructuredGrid"),
    };
    let serial = d.join(format!("whole.{ext_name}"));
    std::fs::write(&serial, grid_piece(kind, whole, whole, at)).expect("write");
    let bounds = |a: usize| {
        let (lo, hi) = (whole[2 * a], whole[2 * a + 1]);
        (0..=cuts)
            .map(|c| lo + (hi - lo) * c as i64 / cuts as i64)
            .collect::<Vec<_>>()
    };
    let (bx, by, bz) = (bounds(0), bounds(1), bounds(2));
    std::fs::create_dir_all(d.join("pieces")).expect("dir");
    let mut list = String::new();
    let mut n = 0;
    for z in 0..cuts {
        for y in 0..cuts {
            for x in 0..cuts {
                let e = [bx[x], bx[x + 1], by[y], by[y + 1], bz[z], bz[z + 1]];
                let name = format!("pieces/p{n}.{ext_name}");
                std::fs::write(d.join(&name), grid_piece(kind, whole, e, at)).expect("write");
                let _ = write!(list, "<Piece Extent=\"{}\" Source=\"{name}\"/>", ext(e));
                n += 1;
            }
        }
    }
    let placement = if kind == "ImageData" {
        " Origin=\"-1 -1 -1\" Spacing=\"0.125 0.125 0.125\""
    } else {
        ""
    };
    let extra = match kind {
        "ImageData" => "",
        "RectilinearGrid" => {
            "<PCoordinates><PDataArray type=\"Float64\"/><PDataArray type=\"Float64\"/>\
             <PDataArray type=\"Float64\"/></PCoordinates>"
        }
        _ => "<PPoints><PDataArray type=\"Float64\" NumberOfComponents=\"3\"/></PPoints>",
    };
    let parallel = d.join(format!("whole.p{ext_name}"));
    std::fs::write(
        &parallel,
        format!(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"{pkind}\" version=\"1.0\">\
             <{pkind} WholeExtent=\"{}\" GhostLevel=\"0\"{placement}>\
             <PPointData><PDataArray type=\"Float32\" Name=\"f\"/></PPointData>\
             <PCellData><PDataArray type=\"Float32\" Name=\"c\"/></PCellData>{extra}{list}\
             </{pkind}></VTKFile>\n",
            ext(whole)
        ),
    )
    .expect("write");
    (parallel, serial)
}

fn image_at(p: [i64; 3]) -> [f64; 3] {
    p.map(|i| -1.0 + 0.125 * i as f64)
}

fn rectilinear_at(p: [i64; 3]) -> [f64; 3] {
    p.map(|i| -1.0 + 0.02 * (i * i) as f64 + 0.05 * i as f64)
}

fn curved_at(p: [i64; 3]) -> [f64; 3] {
    let [x, y, z] = p.map(|i| 0.1 * i as f64);
    [
        x + 0.05 * y * y,
        y + 0.03 * (2.0 * x).sin(),
        z + 0.02 * x * y,
    ]
}

fn assert_same(a: &Dataset, b: &Dataset, what: &str) {
    assert_eq!(a.geometry, b.geometry, "{what}: geometry");
    assert_eq!(a.arrays.len(), b.arrays.len(), "{what}: arrays");
    for (x, y) in a.arrays.iter().zip(&b.arrays) {
        assert_eq!((&x.name, x.location), (&y.name, y.location), "{what}");
        assert!(
            x.values.iter().eq(y.values.iter()),
            "{what}: {} values",
            x.name
        );
    }
}

#[test]
fn parallel_grids_read_as_the_grid_their_pieces_were_cut_from() {
    let whole = [0, 16, 0, 12, 0, 9];
    for (kind, at) in [
        ("ImageData", &image_at as &dyn Fn([i64; 3]) -> [f64; 3]),
        ("RectilinearGrid", &rectilinear_at),
        ("StructuredGrid", &curved_at),
    ] {
        let d = dir(kind);
        for cuts in [1, 2, 3] {
            let (parallel, serial) = grid_files(&d, kind, whole, cuts, at);
            let a = load_dataset(&parallel).expect("parallel file");
            let b = load_dataset(&serial).expect("serial file");
            assert_same(&a, &b, &format!("{kind}, {cuts}³ pieces"));
        }
        // A non-zero whole extent: the image's first point moves.
        let (parallel, serial) = grid_files(&d, kind, [3, 12, 2, 9, 1, 6], 2, at);
        assert_same(
            &load_dataset(&parallel).expect("parallel"),
            &load_dataset(&serial).expect("serial"),
            &format!("{kind}, offset extent"),
        );
    }
}

/// A tetrahedral mesh cut into pieces: the cells of `cells` (4 point indices each) in pieces of
/// `per` cells, each piece with its own copy of its points; with `ghost`, every piece after the
/// first repeats the previous piece's last cell flagged as a duplicate.
fn vtu_files(
    d: &Path,
    points: &[[f64; 3]],
    cells: &[[usize; 4]],
    per: usize,
    ghost: bool,
) -> PathBuf {
    let mut list = String::new();
    for (n, chunk) in cells.chunks(per).enumerate() {
        let mut own: Vec<([usize; 4], u8)> = chunk.iter().map(|&c| (c, 0)).collect();
        if ghost && n > 0 {
            own.insert(0, (cells[n * per - 1], 1));
        }
        let mut used: Vec<usize> = own.iter().flat_map(|(c, _)| *c).collect();
        used.sort_unstable();
        used.dedup();
        let local = |i: usize| used.binary_search(&i).expect("used");
        let conn = join(own.iter().flat_map(|(c, _)| c.map(local)));
        let offsets = join((1..=own.len()).map(|k| 4 * k));
        let types = join(own.iter().map(|_| 10));
        let flags = join(own.iter().map(|(_, g)| *g));
        let name = format!("m{n}.vtu");
        std::fs::write(
            d.join(&name),
            format!(
                "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\">\
                 <UnstructuredGrid><Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">\
                 <PointData><DataArray type=\"Float32\" Name=\"f\" format=\"ascii\">{}\
                 </DataArray></PointData><CellData><DataArray type=\"UInt8\" \
                 Name=\"vtkGhostType\" format=\"ascii\">{flags}</DataArray></CellData>\
                 <Points><DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">{}\
                 </DataArray></Points><Cells>\
                 <DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">{conn}</DataArray>\
                 <DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">{offsets}</DataArray>\
                 <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">{types}</DataArray>\
                 </Cells></Piece></UnstructuredGrid></VTKFile>\n",
                used.len(),
                own.len(),
                join(used.iter().map(|&i| f(points[i]) as f32)),
                join(used.iter().flat_map(|&i| points[i])),
            ),
        )
        .expect("write");
        let _ = write!(list, "<Piece Source=\"{name}\"/>");
    }
    let path = d.join("mesh.pvtu");
    std::fs::write(
        &path,
        format!(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"PUnstructuredGrid\" version=\"1.0\">\
             <PUnstructuredGrid GhostLevel=\"{}\"><PPointData><PDataArray type=\"Float32\" \
             Name=\"f\"/></PPointData><PPoints><PDataArray type=\"Float64\" \
             NumberOfComponents=\"3\"/></PPoints>{list}</PUnstructuredGrid></VTKFile>\n",
            u8::from(ghost)
        ),
    )
    .expect("write");
    path
}

/// The five-tetrahedra cubes of an n³ lattice of unit cells in [-1, 1]³.
fn lattice(n: usize) -> (Vec<[f64; 3]>, Vec<[usize; 4]>) {
    let m = n + 1;
    let idx = |i: usize, j: usize, k: usize| (k * m + j) * m + i;
    let points = (0..m * m * m)
        .map(|p| [p % m, (p / m) % m, p / (m * m)].map(|i| -1.0 + 2.0 * i as f64 / n as f64))
        .collect();
    let mut cells = Vec::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let v = |a, b, c| idx(i + a, j + b, k + c);
                let (c0, c1, c2, c3) = (v(0, 0, 0), v(1, 0, 0), v(0, 1, 0), v(1, 1, 0));
                let (c4, c5, c6, c7) = (v(0, 0, 1), v(1, 0, 1), v(0, 1, 1), v(1, 1, 1));
                if (i + j + k) % 2 == 0 {
                    cells.extend([
                        [c0, c1, c2, c4],
                        [c1, c3, c2, c7],
                        [c1, c4, c5, c7],
                        [c2, c4, c6, c7],
                        [c1, c2, c4, c7],
                    ]);
                } else {
                    cells.extend([
                        [c0, c1, c3, c5],
                        [c0, c2, c3, c6],
                        [c0, c4, c5, c6],
                        [c3, c5, c6, c7],
                        [c0, c3, c5, c6],
                    ]);
                }
            }
        }
    }
    (points, cells)
}

fn samples(path: &Path) -> SampleSet {
    let d = load_dataset(path).expect("dataset");
    SampleSet::from_dataset(&d, path, Some("f"), &SampleSettings::default()).expect("samples")
}

/// A sample set's (position, value) bits, sorted.
fn sorted(s: &SampleSet) -> Vec<(u64, u64, u64, u32)> {
    let mut v: Vec<_> = (0..s.len())
        .map(|i| {
            let p = s.position(i).map(f64::to_bits);
            (p[0], p[1], p[2], s.values.get(i).to_bits())
        })
        .collect();
    v.sort_unstable();
    v
}

#[test]
fn parallel_meshes_merge_their_shared_points_and_drop_duplicate_ghost_cells() {
    let (points, cells) = lattice(3);
    let d = dir("mesh");
    let one = samples(&vtu_files(&d, &points, &cells, cells.len(), false));
    assert_eq!(one.len(), points.len());
    for (per, ghost) in [(40, false), (17, true)] {
        let path = vtu_files(&d, &points, &cells, per, ghost);
        let dataset = load_dataset(&path).expect("pvtu");
        let Geometry::Unstructured { cells: c, .. } = &dataset.geometry else {
            panic!("not a mesh");
        };
        // Every cell once: the duplicates each piece after the first repeats are dropped.
        assert_eq!(c.len(), cells.len(), "{per} per piece, ghosts {ghost}");
        assert!(dataset.arrays.iter().all(|a| a.name != "vtkGhostType"));
        let s = samples(&path);
        // The points the pieces share coincide and merge into one sample each.
        assert_eq!(s.len(), points.len(), "{per} per piece");
        assert!(s.provenance.merged > 0);
        assert_eq!(sorted(&s), sorted(&one), "{per} per piece: the samples");
    }
}

#[test]
fn an_output_onto_a_piece_is_refused_before_any_work() {
    use common::cli::{assert_fails, s, vmls};
    let d = dir("outputs");
    let (parallel, _) = grid_files(&d, "ImageData", [0, 8, 0, 8, 0, 8], 2, &image_at);
    let piece = d.join("pieces/p3.vti");
    let before = std::fs::read(&piece).expect("piece");
    let png = d.join("x.png");
    let volume = format!("volume.file=\"{}\"", s(&parallel));
    let out = vmls(&[
        "render",
        "-o",
        s(&png),
        "--stats",
        s(&piece),
        "--set",
        &volume,
        "--set",
        "camera.width=8",
        "--set",
        "camera.height=8",
    ]);
    assert_fails(&out, &["p3.vti", "a piece of volume.file"], &png);
    assert_eq!(std::fs::read(&piece).expect("piece"), before);
}

#[test]
fn pieces_that_leave_a_hole_disagree_or_are_missing_are_errors_naming_the_file() {
    let d = dir("faults");
    let whole = [0, 8, 0, 8, 0, 8];
    let (parallel, _) = grid_files(&d, "ImageData", whole, 2, &image_at);
    let text = std::fs::read_to_string(&parallel).expect("read");
    let cases = [
        // A piece left out: its points are a hole.
        (
            text.replacen(
                "<Piece Extent=\"0 4 0 4 0 4 \" Source=\"pieces/p0.vti\"/>",
                "",
                1,
            ),
            vec!["no piece holding point (0, 0, 0)"],
        ),
        // A piece that is not there.
        (
            text.replacen("pieces/p1.vti", "pieces/gone.vti", 1),
            vec!["gone.vti"],
        ),
        // An extent past the whole.
        (
            text.replacen("Extent=\"4 8 4 8 4 8 \"", "Extent=\"4 9 4 8 4 8 \"", 1),
            vec!["inside the WholeExtent"],
        ),
        // A piece whose points the summary places elsewhere.
        (
            text.replacen("Origin=\"-1 -1 -1\"", "Origin=\"-1 -1 -0.5\"", 1),
            vec!["a piece starting at"],
        ),
        // Not a parallel kind.
        (
            text.replacen("type=\"PImageData\"", "type=\"PHyperTreeGrid\"", 1),
            vec!["unsupported", "PHyperTreeGrid"],
        ),
    ];
    for (k, (bad, expect)) in cases.iter().enumerate() {
        assert_ne!(bad, &text, "case {k} changed nothing");
        let path = d.join(format!("bad{k}.pvti"));
        std::fs::write(&path, bad).expect("write");
        let e = load_dataset(&path).expect_err("refused").to_string();
        for x in expect {
            assert!(e.contains(x), "case {k}: {e}");
        }
    }
    // A piece with other arrays than the first.
    let p3 = d.join("pieces/p3.vti");
    let piece = std::fs::read_to_string(&p3).expect("read");
    std::fs::write(&p3, piece.replace("Name=\"c\"", "Name=\"other\"")).expect("write");
    let e = load_dataset(&parallel).expect_err("arrays").to_string();
    assert!(e.contains("p3.vti") && e.contains("arrays"), "{e}");
}

/// The whole field of a parallel image with the default scene settings.
fn whole_field(path: &Path, array: &str) -> Field {
    let d = load_dataset(path).expect("dataset");
    let s = SampleSet::from_dataset(&d, path, Some(array), &SampleSettings::default())
        .expect("samples");
    let scene = common::general_scene(&[]);
    Field::from_samples(s, scene.reconstruction, &OctreeSettings::default(), |_| {}).expect("field")
}

#[test]
fn each_rank_reads_only_its_pieces_and_holds_the_whole_fields_brick() {
    let d = dir("bricks");
    let (parallel, _) = grid_files(&d, "ImageData", [0, 24, 0, 20, 0, 16], 3, &image_at);
    let scene = common::general_scene(&[]);
    for array in ["f", "c"] {
        let field = whole_field(&parallel, array);
        for ranks in [2, 3, 5, 8] {
            let (tree, pieces) = divide(&field, ranks, Ghosts::Mls).expect("divide");
            let summary = Summary::read(&parallel).expect("summary");
            let total = summary.pieces.len();
            let plan = GridPlan::new(summary, Some(array), &SampleSettings::default(), ranks)
                .expect("plan");
            assert_eq!(plan.tree, tree, "{array}, {ranks} ranks: the tree");
            let mut fewest = total;
            for (rank, (piece, count)) in pieces.iter().enumerate() {
                let brick = plan
                    .read_brick(rank, &SampleSettings::default())
                    .expect("brick");
                fewest = fewest.min(brick.pieces_read);
                assert_eq!(brick.count, *count, "{array}, rank {rank} of {ranks}");
                let mine = plan
                    .piece(
                        rank,
                        brick,
                        field.value_range(),
                        scene.reconstruction,
                        scene.octree,
                    )
                    .expect("piece");
                let (a, b) = (&mine.samples, &piece.samples);
                assert_eq!(a.positions, b.positions, "{array}, rank {rank} of {ranks}");
                assert!(
                    a.values.iter().eq(b.values.iter()),
                    "{array}, rank {rank}: values"
                );
                assert_eq!(a.domain, b.domain);
                assert_eq!(mine.frame_origin, piece.frame_origin);
                assert_eq!(mine.support_box(), piece.support_box());
                assert_eq!(mine.clip(), piece.clip());
            }
            if ranks >= 3 {
                assert!(
                    fewest < total,
                    "{array}, {ranks} ranks: a rank read every piece"
                );
            }
        }
    }
}

/// Scattered points cut into `.vtp` pieces of `per` points, with point array "f".
fn vtp_files(d: &Path, points: &[[f64; 3]], per: usize) -> PathBuf {
    let mut list = String::new();
    for (n, chunk) in points.chunks(per).enumerate() {
        let name = format!("q{n}.vtp");
        std::fs::write(
            d.join(&name),
            format!(
                "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"1.0\">\
                 <PolyData><Piece NumberOfPoints=\"{}\"><PointData>\
                 <DataArray type=\"Float32\" Name=\"f\" format=\"ascii\">{}</DataArray>\
                 </PointData><Points><DataArray type=\"Float64\" NumberOfComponents=\"3\" \
                 format=\"ascii\">{}</DataArray></Points></Piece></PolyData></VTKFile>\n",
                chunk.len(),
                join(chunk.iter().map(|&p| f(p) as f32)),
                join(chunk.iter().flatten()),
            ),
        )
        .expect("write");
        let _ = write!(list, "<Piece Source=\"{name}\"/>");
    }
    let path = d.join("points.pvtp");
    std::fs::write(
        &path,
        format!(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"PPolyData\" version=\"1.0\">\
             <PPolyData GhostLevel=\"0\"><PPointData><PDataArray type=\"Float32\" Name=\"f\"/>\
             </PPointData><PPoints><PDataArray type=\"Float64\" NumberOfComponents=\"3\"/>\
             </PPoints>{list}</PPolyData></VTKFile>\n"
        ),
    )
    .expect("write");
    path
}

/// Point i of a Kronecker sequence in [-1, 1)³: scattered, no two alike.
fn kronecker(i: usize) -> [f64; 3] {
    let t = i as f64;
    [
        0.618_033_988_749_894_9,
        0.414_213_562_373_095,
        0.732_050_807_568_877_2,
    ]
    .map(|a| (t * a).fract())
    .map(|x| 2.0 * x - 1.0)
}

/// A brick's own samples and its ghosts as (position, value, metric) bits, in order.
type Bits = Vec<([u64; 3], u32, [u64; 6])>;
fn brick_bits(s: &SampleSet, own: usize) -> (Bits, Bits) {
    let bits = |range: std::ops::Range<usize>| {
        range
            .map(|i| {
                (
                    s.position(i).map(f64::to_bits),
                    s.values.get(i).to_bits(),
                    s.metric(i).map(f64::to_bits),
                )
            })
            .collect::<Bits>()
    };
    (bits(0..own), bits(own..s.len()))
}

/// Kernel volumes of a piece by position.
fn volumes_by_position(field: &Field) -> Vec<([u64; 3], f64)> {
    let s = &field.samples;
    let v = field.kernel_volumes();
    let mut out: Vec<_> = (0..s.len())
        .map(|i| (s.position(i).map(f64::to_bits), v.get(i)))
        .collect();
    out.sort_by_key(|a| a.0);
    out
}

#[test]
fn ranks_reading_a_mesh_points_or_grid_together_hold_the_whole_fields_bricks() {
    let d = dir("scattered");
    let (points, cells) = lattice(4);
    let mesh = vtu_files(&d, &points, &cells, 37, true);
    // Scattered points: a Kronecker sequence, every 7th point written twice (a shared point).
    let mut scattered: Vec<[f64; 3]> = (0..600).map(kronecker).collect();
    let copies: Vec<[f64; 3]> = scattered.iter().step_by(7).copied().collect();
    scattered.extend(copies);
    let cloud = vtp_files(&d, &scattered, 90);
    let whole = [0, 9, 0, 8, 0, 7];
    let (rectilinear, _) = grid_files(&d, "RectilinearGrid", whole, 3, &rectilinear_at);
    let (curved, _) = grid_files(&d, "StructuredGrid", whole, 3, &curved_at);
    for (path, array, method, anisotropic) in [
        (&mesh, "f", "mls", None),
        (&mesh, "f", "mls", Some(true)),
        (&mesh, "f", "gaussian", Some(true)),
        (&cloud, "f", "mls", None),
        (&cloud, "f", "mls", Some(true)),
        (&cloud, "f", "gaussian", None),
        (&mesh, "f", "gaussian", None),
        (&rectilinear, "f", "mls", None),
        (&rectilinear, "c", "mls", None),
        (&rectilinear, "f", "mls", Some(false)),
        (&curved, "f", "mls", None),
        (&curved, "c", "gaussian", None),
        (&curved, "f", "mls", Some(true)),
        (&curved, "c", "mls", Some(true)),
    ] {
        let settings = SampleSettings {
            anisotropic,
            ..SampleSettings::default()
        };
        let scene = common::general_scene(&[format!("reconstruction.method=\"{method}\"")]);
        let dataset = load_dataset(path).expect("dataset");
        let whole = SampleSet::from_dataset(&dataset, path, Some(array), &settings).expect("set");
        let whole =
            Field::from_samples(whole, scene.reconstruction, &scene.octree, |_| {}).expect("field");
        let summary = Summary::read(path).expect("summary");
        for ranks in [1, 2, 3, 5] {
            let what = format!(
                "{}, {array}, {method}, anisotropic {anisotropic:?}, {ranks} ranks",
                path.display()
            );
            let bricks = read_on_ranks(ranks, &summary, array, &settings, &scene, None);
            let bricks: Vec<_> = bricks
                .into_iter()
                .map(|b| b.unwrap_or_else(|e| panic!("{what}: {e}")))
                .collect();
            let tree = vmls::bricks::decompose(&whole, ranks).expect("tree");
            let read: usize = bricks.iter().map(|b| b.pieces_read).sum();
            assert_eq!(read, summary.pieces.len(), "{what}: every piece read once");
            for (rank, brick) in bricks.into_iter().enumerate() {
                assert_eq!(brick.tree, tree, "{what}: the tree");
                if ranks > 1 {
                    assert!(brick.pieces_read < summary.pieces.len(), "{what}");
                }
                let (piece, count) =
                    piece_of(&whole, &tree, rank, Ghosts::Mls).expect("whole piece");
                assert_eq!(brick.count, count, "{what}, rank {rank}: counts");
                let (a, b) = (&brick.samples, &piece.samples);
                assert_eq!(
                    brick_bits(a, count.own),
                    brick_bits(b, count.own),
                    "{what}, rank {rank}: own samples and ghosts, in order"
                );
                assert_eq!(a.domain, b.domain, "{what}: domain");
                assert_eq!(a.spacing, b.spacing, "{what}: spacing");
                assert_eq!(a.provenance, b.provenance, "{what}: provenance");
                let frame = piece.piece_frame();
                assert_eq!(brick.frame.frame_origin, frame.frame_origin, "{what}");
                assert_eq!(brick.frame.range, frame.range, "{what}: range");
                let (e, w) = (brick.frame.extent.as_ref().expect("extent"), frame.extent);
                let w = w.expect("extent");
                assert_eq!(e.support_box, w.support_box, "{what}: support box");
                assert_eq!(e.thinnest, w.thinnest, "{what}: thinnest");
                assert_eq!(e.radii, w.radii, "{what}: radius quantiles");
                let (mine, _, _, _) = brick.piece().expect("piece");
                assert_eq!(mine.clip(), piece.clip(), "{what}: box");
                if method == "gaussian" {
                    // The sums run in another order: rounding only.
                    let (x, y) = (volumes_by_position(&mine), volumes_by_position(&piece));
                    assert_eq!(x.len(), y.len());
                    for ((p, u), (q, v)) in x.iter().zip(&y) {
                        assert_eq!(p, q, "{what}");
                        assert!(
                            (u - v).abs() <= 1e-12 * v.abs(),
                            "{what}: volume {u} vs {v}"
                        );
                    }
                }
            }
        }
    }
}

/// Each of `ranks` ranks' brick of `summary`'s `array` read together with `settings` and the
/// scene's reconstruction, for ray casting or for splatting `view`.
fn read_on_ranks(
    ranks: usize,
    summary: &Summary,
    array: &str,
    settings: &SampleSettings,
    scene: &vmls::scene::Scene,
    view: Option<&vmls::view::View<'_>>,
) -> Vec<Result<ScatteredBrick, vmls::bricks::BrickError>> {
    LocalRanks::run(ranks, |ex| {
        read_scattered(
            ex,
            summary,
            Some(array),
            settings,
            scene.reconstruction,
            scene.octree,
            view,
        )
    })
}

/// What each of `ranks` ranks reading `summary` together with `settings` failed with.
fn failures(summary: &Summary, ranks: usize, settings: &SampleSettings) -> Vec<String> {
    let scene = common::general_scene(&[]);
    read_on_ranks(ranks, summary, "f", settings, &scene, None)
        .into_iter()
        .enumerate()
        .map(|(rank, b)| match b {
            Err(e) => e.to_string(),
            Ok(_) => panic!("rank {rank} went on"),
        })
        .collect()
}

#[test]
fn a_rank_that_cannot_read_its_piece_stops_every_rank_with_its_message() {
    let d = dir("scattered-missing");
    let (points, cells) = lattice(3);
    let mesh = vtu_files(&d, &points, &cells, 20, false);
    let summary = Summary::read(&mesh).expect("summary");
    let last = summary.pieces.len() - 1;
    std::fs::remove_file(&summary.pieces[last].source).expect("remove");
    let name = format!("m{last}.vtu");
    for (rank, e) in failures(&summary, 3, &SampleSettings::default())
        .iter()
        .enumerate()
    {
        assert!(
            e.contains("rank 2 of 3") && e.contains(&name),
            "rank {rank}: {e}"
        );
    }
}

#[test]
fn ranks_reading_together_for_a_splatting_view_hold_the_kernels_its_sheets_need() {
    let d = dir("scattered-splat");
    let (points, cells) = lattice(4);
    let mesh = vtu_files(&d, &points, &cells, 37, true);
    let (curved, _) = grid_files(&d, "StructuredGrid", [0, 9, 0, 8, 0, 7], 3, &curved_at);
    let settings = SampleSettings::default();
    for (path, method) in [(&mesh, "splat"), (&mesh, "splat-post"), (&curved, "splat")] {
        let scene = common::general_scene(&[
            format!("render.method=\"{method}\""),
            "camera.width=48".into(),
            "camera.height=40".into(),
        ]);
        let view = scene.view();
        let dataset = load_dataset(path).expect("dataset");
        let whole = SampleSet::from_dataset(&dataset, path, Some("f"), &settings).expect("set");
        let whole =
            Field::from_samples(whole, scene.reconstruction, &scene.octree, |_| {}).expect("field");
        let reach = vmls::bricks::splat::SplatReach::new(&whole, &view).expect("reach");
        let summary = Summary::read(path).expect("summary");
        for ranks in [2, 3] {
            let what = format!("{}, {method}, {ranks} ranks", path.display());
            let bricks = read_on_ranks(ranks, &summary, "f", &settings, &scene, Some(&view));
            let tree = vmls::bricks::decompose(&whole, ranks).expect("tree");
            let mut ghosts = 0;
            for (rank, brick) in bricks.into_iter().enumerate() {
                let brick = brick.unwrap_or_else(|e| panic!("{what}: {e}"));
                let (piece, count) =
                    piece_of(&whole, &tree, rank, Ghosts::Splat(&reach)).expect("whole piece");
                assert_eq!(brick.count, count, "{what}, rank {rank}: counts");
                ghosts += count.ghosts;
                assert_eq!(
                    brick_bits(&brick.samples, count.own),
                    brick_bits(&piece.samples, count.own),
                    "{what}, rank {rank}: own kernels and the others its sheets need, in order"
                );
                let (x, y) = (volumes_by_position(&piece), {
                    let (mine, _, _, _) = brick.piece().expect("piece");
                    volumes_by_position(&mine)
                });
                for ((p, u), (q, v)) in x.iter().zip(&y) {
                    assert_eq!(p, q, "{what}");
                    assert!(
                        (u - v).abs() <= 1e-12 * u.abs(),
                        "{what}: volume {v} vs {u}"
                    );
                }
            }
            assert!(ghosts > 0, "{what}: no brick took another's kernels");
        }
    }
}

#[test]
fn ranks_splatting_a_parallel_image_read_the_sub_grids_their_sheets_need() {
    let d = dir("bricks-splat");
    let (parallel, _) = grid_files(&d, "ImageData", [0, 32, 0, 28, 0, 24], 3, &image_at);
    for method in ["splat", "splat-post"] {
        let scene = common::general_scene(&[
            format!("render.method=\"{method}\""),
            "camera.width=200".into(),
            "camera.height=160".into(),
        ]);
        let view = scene.view();
        let field = whole_field(&parallel, "f");
        let reach = vmls::bricks::splat::SplatReach::new(&field, &view).expect("reach");
        for ranks in [3, 5, 8] {
            let (_, pieces) = divide(&field, ranks, Ghosts::Splat(&reach)).expect("divide");
            let summary = Summary::read(&parallel).expect("summary");
            let total = summary.pieces.len();
            let plan =
                GridPlan::new(summary, Some("f"), &SampleSettings::default(), ranks).expect("plan");
            let bricks = LocalRanks::run(ranks, |ex| {
                plan.read_splat_brick(
                    ex,
                    &SampleSettings::default(),
                    &view,
                    scene.reconstruction,
                    scene.octree,
                )
            });
            let mut fewest = total;
            for (rank, (brick, (piece, count))) in bricks.into_iter().zip(&pieces).enumerate() {
                let what = format!("{method}, rank {rank} of {ranks}");
                let (mine, mine_count, read) = brick.unwrap_or_else(|e| panic!("{what}: {e}"));
                fewest = fewest.min(read);
                assert_eq!(mine_count, *count, "{what}: counts");
                assert_eq!(mine.samples.positions, piece.samples.positions, "{what}");
                assert!(
                    mine.samples.values.iter().eq(piece.samples.values.iter()),
                    "{what}: values"
                );
                assert_eq!(mine.value_range(), piece.value_range(), "{what}: range");
            }
            eprintln!("{method}, {ranks} ranks: the fewest pieces a rank read {fewest} of {total}");
            assert!(
                fewest < total,
                "{method}, {ranks} ranks: a rank read every piece"
            );
        }
    }
}

#[test]
fn ranks_find_a_hole_that_a_grid_summarys_pieces_leave() {
    let d = dir("scattered-hole");
    let rectilinear: &dyn Fn([i64; 3]) -> [f64; 3] = &rectilinear_at;
    let curved: &dyn Fn([i64; 3]) -> [f64; 3] = &curved_at;
    for (kind, at) in [("RectilinearGrid", rectilinear), ("StructuredGrid", curved)] {
        let (parallel, _) = grid_files(&d, kind, [0, 9, 0, 8, 0, 7], 3, at);
        let text = std::fs::read_to_string(&parallel).expect("summary");
        // Drop the middle piece from the summary: its samples are no piece's.
        let at = text.find("p13.").expect("piece 13");
        let start = text[..at].rfind("<Piece").expect("its element");
        let end = at + text[at..].find("/>").expect("its end") + 2;
        std::fs::write(&parallel, format!("{}{}", &text[..start], &text[end..])).expect("write");
        let summary = Summary::read(&parallel).expect("summary");
        for e in failures(&summary, 3, &SampleSettings::default()) {
            assert!(
                e.contains("leave a hole") && e.contains("whole.pvt"),
                "{kind}: {e}"
            );
        }
    }
}

#[test]
fn ranks_cut_the_whole_fields_tree_past_the_subsample_size() {
    // 70 000 scattered points and 10 000 of them written twice (shared points of the pieces):
    // past SUBSAMPLE, so the tree is cut from one sample in two. The whole file merges the
    // copies before it subsamples and the ranks merge them after reading their shares, so a
    // subsample by index would differ; by coordinates it is the same samples.
    let d = dir("subsample");
    let points: Vec<[f64; 3]> = (0..70_000)
        .flat_map(|i| {
            // Every 7th point twice, the copy right after it: the copies shift the indices of
            // every point after them.
            vec![kronecker(i); 1 + usize::from(i % 7 == 0)]
        })
        .collect();
    let path = vtp_files(&d, &points, 20_000);
    let settings = SampleSettings::default();
    let dataset = load_dataset(&path).expect("dataset");
    let set = SampleSet::from_dataset(&dataset, &path, Some("f"), &settings).expect("set");
    assert_eq!(set.len(), 70_000, "the copies merged");
    let scene = common::general_scene(&["reconstruction.method=\"gaussian\"".to_string()]);
    let whole =
        Field::from_samples_deferred(set, scene.reconstruction, &scene.octree).expect("field");
    let summary = Summary::read(&path).expect("summary");
    for ranks in [2, 3] {
        let tree = vmls::bricks::decompose(&whole, ranks).expect("tree");
        let bricks = read_on_ranks(ranks, &summary, "f", &settings, &scene, None);
        for (rank, brick) in bricks.into_iter().enumerate() {
            let brick = brick.unwrap_or_else(|e| panic!("{ranks} ranks, rank {rank}: {e}"));
            assert_eq!(brick.tree, tree, "{ranks} ranks, rank {rank}: the tree");
        }
    }
}
