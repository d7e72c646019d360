//! `thrusterctl demo --json`: the README's main command with the real thrusterd and
//! thruster-sim processes (lockstep), scored against the simulator's truth. It runs the default
//! estimator (the dynamic method); the thresholds are issue 11's targets with a margin for a
//! loaded machine, the comments say what the runs measured.

use std::process::Command;

use serde_json::Value;
use system_tests::{bin, workspace};

fn demo(args: &[&str]) -> Value {
    let out = Command::new(bin("thrusterctl"))
        .arg("demo")
        .args(args)
        .args(["--json", "--hold-s", "0"])
        .current_dir(workspace())
        // Under cargo, thrusterctl would build its siblings itself; the test has them already.
        .env_remove("CARGO")
        .env_remove("CARGO_MANIFEST_DIR")
        .output()
        .expect("thrusterctl runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "demo failed\nstdout: {stdout}\nstderr: {stderr}"
    );
    serde_json::from_str(stdout.trim()).expect("one JSON object")
}

/// Realistic IMU (seed 1): a model within 3 % / 5 % of the truth in 6 vehicle-s, measured
/// in-process 0.016 / 0.018 in 4.2 s over seeds 1-5 (docs/study.md); here with margin 2x on
/// the errors. The vehicle stays within 30 deg of level while it is excited (measured 22 deg).
/// The JSON carries the method, the excursion and every learned coefficient.
#[test]
fn the_demo_learns_the_dynamic_model_quickly_and_reports_it() {
    let v = demo(&["--noise", "realistic"]);
    assert_eq!(v["method"], "Dynamic", "{v}");
    let (rot, acc) = (
        v["err_rot"].as_f64().unwrap(),
        v["err_acc"].as_f64().unwrap(),
    );
    assert!(rot <= 0.06 && acc <= 0.10, "errors {rot:.3} / {acc:.3}");
    let secs = v["vehicle_seconds"].as_f64().unwrap();
    assert!(secs <= 8.0, "{secs:.1} vehicle seconds");
    let tilt = v["estimation_max_tilt_deg"]
        .as_f64()
        .expect("tilt measured");
    assert!(tilt > 1.0 && tilt <= 30.0, "tilt {tilt:.1} deg");
    assert!(v["estimation_max_heading_change_deg"].as_f64().is_some());
    let rows = &v["dynamics"]["per_row_term_value_and_std_err"];
    for dof in ["roll", "pitch", "yaw", "surge", "sway", "heave"] {
        let row = rows[dof]
            .as_object()
            .unwrap_or_else(|| panic!("row {dof}: {v}"));
        assert_eq!(row.len(), thruster_protocol::DYNAMIC_TERMS, "{dof}");
    }
    // A bottom-heavy body rights itself: roll acceleration against a positive y component of
    // gravity in the body frame is negative (the simulator's AMOUR-5: -8.06 rad/s^2).
    let restoring = rows["roll"]["down_y"][0].as_f64().unwrap();
    assert!(
        (-12.0..-5.0).contains(&restoring),
        "roll restoring {restoring}"
    );
    assert_eq!(v["clean_exit"], true);
    assert_eq!(v["files_left"], 0);
}
