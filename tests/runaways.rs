//! No runaway (issue 25 §2): settings that would make every evaluation loop over a whole
//! dataset are refused by name, and a transfer function of the allowed maximum of points builds
//! its tables as a small one does.

mod common;

use common::cli::{assert_fails, dir, s, vmls};

#[test]
fn degenerate_octrees_are_refused_by_name() {
    let d = dir("octree-degenerate");
    let png = d.join("x.png");
    for setting in ["octree.max_depth=0", "octree.leaf_budget=1000000"] {
        let out = vmls(&[
            "render",
            "-o",
            s(&png),
            "--set",
            "reconstruction.neighbours=\"octree\"",
            "--set",
            setting,
            "--set",
            "camera.width=8",
            "--set",
            "camera.height=8",
        ]);
        assert_fails(&out, &["octree: a leaf holds", "octree.max_depth"], &png);
    }
    // The default octree renders.
    let out = vmls(&[
        "render",
        "-o",
        s(&png),
        "--set",
        "reconstruction.neighbours=\"octree\"",
        "--set",
        "camera.width=8",
        "--set",
        "camera.height=8",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
