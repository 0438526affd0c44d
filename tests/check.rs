//! `vmls check --quick`, the configuration CI runs: every hard case and convergence order within
//! its bound, on lavapipe with validation on; and a clear error for an unknown case.

mod common;

use common::cli::{assert_fails, dir, s, vmls};

#[test]
fn quick_suite_passes_and_reports_json() {
    let d = dir("check");
    let json = d.join("check.json");
    let out = vmls(&["check", "--quick", "--json", s(&json)]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("valid");
    let outcomes = v["outcomes"].as_array().expect("outcomes");
    assert!(outcomes.len() >= 25, "{}", outcomes.len());
    for o in outcomes {
        assert_eq!(o["passed"], true, "{o}");
        assert!(o["measured"].is_number(), "{o}");
    }
    // Every case ran: one line per outcome.
    for case in [
        "far-origin",
        "value-scale",
        "mls-singular",
        "tf-spike",
        "tangent-rays",
        "eye-inside",
        "splat-eye-kernel",
        "converge-step",
        "converge-table",
        "converge-spacing",
        "converge-epsilon",
        "tolerance-thin-peak",
    ] {
        assert!(stdout.contains(case), "{case} missing:\n{stdout}");
    }
}

#[test]
fn unknown_case_is_an_error() {
    let d = dir("check-none");
    let json = d.join("check.json");
    let out = vmls(&[
        "check",
        "--quick",
        "--case",
        "no-such-case",
        "--json",
        s(&json),
    ]);
    // Refused before any work: no JSON either.
    assert_fails(&out, &["no case matches 'no-such-case'", "--list"], &json);
}
