//! No runaway (issue 25 §2): settings that would make every evaluation loop over a whole
//! dataset are refused by name; host memory and device limits are checked before the host
//! builds; "auto" weighs the fast path's fine grid. (Tables for the allowed 1024 transfer-function
//! points: `preintegration::tests`, times in BENCHMARKS.md.)

mod common;

use common::cli::{assert_fails, dir, s, small_render, vmls};

#[test]
fn degenerate_octrees_are_refused_by_name() {
    let d = dir("octree-degenerate");
    let png = d.join("x.png");
    let octree = "reconstruction.neighbours=\"octree\"";
    for setting in ["octree.max_depth=0", "octree.leaf_budget=1000000"] {
        let out = vmls(&small_render(&png, &["--set", octree, "--set", setting]));
        assert_fails(&out, &["octree: a leaf holds", "octree.max_depth"], &png);
    }
    // The default octree renders.
    let out = vmls(&small_render(&png, &["--set", octree]));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn stats_of(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("stats")).expect("json")
}

#[test]
fn auto_takes_the_fast_path_only_where_its_fine_grid_stays_moderate() {
    let d = dir("auto-fast-path");
    let (png, stats) = (d.join("x.png"), d.join("s.json"));
    let render = |extra: &[&str]| {
        let mut args = vec!["--stats", s(&stats)];
        args.extend_from_slice(extra);
        vmls(&small_render(&png, &args))
    };
    // The built-in 41³ scene at 128²: 81³ fine points, fewer than the first frame's solves.
    let big = ["--set", "camera.width=128", "--set", "camera.height=128"];
    let out = render(&big);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let fast = &stats_of(&stats)["fast_path"];
    assert_eq!(fast["factor"], 2, "{fast}");
    assert_eq!(fast["fine_points"], 81 * 81 * 81, "{fast}");
    // At 8×8 the first frame solves far fewer than 81³ times: the general path, and why.
    let out = render(&[]);
    assert!(out.status.success());
    let fast = &stats_of(&stats)["fast_path"];
    assert_eq!(fast["factor"], 0, "{fast}");
    let why = fast["declined"].as_str().unwrap_or_default();
    assert!(
        why.contains("531441 solved points") && why.contains("first frame"),
        "{why}"
    );
    // 130³: 259³ = 17.4 M fine points, past auto's 2^24: the general path, and --stats says why.
    let out = render(&["--set", "volume.resolution=130"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let fast = &stats_of(&stats)["fast_path"];
    assert_eq!(fast["factor"], 0, "{fast}");
    let why = fast["declined"].as_str().unwrap_or_default();
    assert!(
        why.contains("17373979 points") && why.contains("resample = 2"),
        "{why}"
    );
}

#[test]
fn loads_past_the_free_host_memory_are_refused_before_allocating() {
    let d = dir("host-memory");
    let png = d.join("x.png");
    let run = |memory: &str, extra: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_vmls"))
            .args(small_render(&png, extra))
            .env("VMLS_VALIDATION", "1")
            .env("VMLS_HOST_MEMORY", memory)
            .env_remove("VMLS_DEVICE")
            .output()
            .expect("run vmls")
    };
    // The generator: 41³ samples at 16 bytes need 1.1 MB.
    let out = run("1000000", &[]);
    assert_fails(
        &out,
        &[
            "volume.resolution",
            "1102736 bytes of host memory",
            "1000000 available",
        ],
        &png,
    );
    // A file: a 30×30×30 uint8 NRRD needs 108 000 bytes (per sample its byte in the file and
    // three copies kept at 8 bits: data::grid_host_bytes).
    let nrrd = d.join("v.nrrd");
    let mut bytes =
        b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 30 30 30\nencoding: raw\n\n".to_vec();
    bytes.extend((0..27_000).map(|i| (i % 251) as u8));
    std::fs::write(&nrrd, bytes).expect("write");
    let key = format!("volume.file=\"{}\"", s(&nrrd));
    let out = run("100000", &["--set", &key]);
    assert_fails(&out, &["v.nrrd", "30×30×30 grid", "108000 bytes"], &png);
    // A sparse file is not read into memory that is not there.
    let sparse = d.join("sparse.nrrd");
    let f = std::fs::File::create(&sparse).expect("create");
    f.set_len(4 << 30).expect("sparse");
    let key_sparse = format!("volume.file=\"{}\"", s(&sparse));
    let out = run("1000000000", &["--set", &key_sparse]);
    assert_fails(
        &out,
        &["sparse.nrrd", "4294967296 bytes of host memory"],
        &png,
    );
    // Enough memory: both render; a bad value is named.
    assert!(run("2000000", &["--set", &key]).status.success());
    std::fs::remove_file(&png).expect("rendered");
    let out = run("lots", &[]);
    assert_fails(&out, &["VMLS_HOST_MEMORY", "byte count"], &png);
}

#[test]
fn a_grid_the_device_cannot_bind_is_refused_before_it_is_built() {
    let d = dir("device-grid");
    let png = d.join("x.png");
    // 820³ float samples: 2.2 GB, past lavapipe's 2 GiB heap and the 2 GiB its texel views span
    // (the grid is a texel view since issue 25 §4, so 330³, past one 128 MiB storage binding,
    // now renders: capacity.rs). Refused before generation, naming the buffer and the limit; the
    // host limit is set high so that the device's is the one met on any machine.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_vmls"))
        .args(small_render(&png, &["--set", "volume.resolution=820"]))
        .env("VMLS_VALIDATION", "1")
        .env("VMLS_HOST_MEMORY", "1000000000000")
        .env_remove("VMLS_DEVICE")
        .output()
        .expect("run vmls");
    assert_fails(&out, &["buffer 'grid'", "2205472192 bytes"], &png);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("heap") || stderr.contains("maxTexelBufferElements"),
        "{stderr}"
    );
}
