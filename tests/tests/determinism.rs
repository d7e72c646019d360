//! One seed, one result (issue 27): `thrusterctl demo` and an experiment run twice with the
//! same seed give the same JSON, bit for bit, once the wall-clock fields are dropped; the
//! second run is made while the machine is loaded (two busy threads), which before the lab
//! stepped the simulator's vehicle time moved err_rot from 0.065 to 0.045 and the experiments'
//! yaw errors by 30 %. A different seed gives different numbers (the comparison can fail).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use serde_json::Value;

/// `thrusterctl <args> --json`, which must succeed, as JSON.
fn run(args: &[&str]) -> Value {
    let out = system_tests::cli::lab(&[args, &["--json"]].concat());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "thrusterctl {args:?} failed\nstdout: {stdout}\nstderr: {stderr}"
    );
    serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("not one JSON object ({e}): {stdout}"))
}

/// The same run with two threads spinning on this machine's two cores meanwhile.
fn run_loaded(args: &[&str]) -> Value {
    let stop = Arc::new(AtomicBool::new(false));
    let hogs: Vec<_> = (0..2)
        .map(|_| {
            let stop = stop.clone();
            std::thread::spawn(move || {
                let mut x = 0u64;
                while !stop.load(Ordering::Relaxed) {
                    x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
                }
            })
        })
        .collect();
    let v = run(args);
    stop.store(true, Ordering::Relaxed);
    for h in hogs {
        h.join().expect("load thread");
    }
    v
}

/// `v` without the fields that measure the wall clock (`wall_s`, `wall_seconds`).
fn vehicle_time_only(v: &Value) -> Value {
    match v {
        Value::Object(map) => Value::Object(
            map.iter()
                .filter(|(k, _)| !k.starts_with("wall_"))
                .map(|(k, x)| (k.clone(), vehicle_time_only(x)))
                .collect(),
        ),
        Value::Array(a) => Value::Array(a.iter().map(vehicle_time_only).collect()),
        x => x.clone(),
    }
}

/// Paths where `a` and `b` differ (for the failure message).
fn differences(a: &Value, b: &Value, path: &str, out: &mut Vec<String>) {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            for k in x.keys().chain(y.keys().filter(|k| !x.contains_key(*k))) {
                differences(
                    x.get(k).unwrap_or(&Value::Null),
                    y.get(k).unwrap_or(&Value::Null),
                    &format!("{path}.{k}"),
                    out,
                );
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => {
            for (i, (p, q)) in x.iter().zip(y).enumerate() {
                differences(p, q, &format!("{path}[{i}]"), out);
            }
        }
        _ if a != b => out.push(format!("{path}: {a} vs {b}")),
        _ => {}
    }
}

fn assert_same(a: &Value, b: &Value, what: &str) {
    let (a, b) = (vehicle_time_only(a), vehicle_time_only(b));
    let mut diff = Vec::new();
    differences(&a, &b, "", &mut diff);
    assert!(
        diff.is_empty(),
        "{what}: {} fields differ between two runs of one seed:\n{}",
        diff.len(),
        diff.iter().take(20).cloned().collect::<Vec<_>>().join("\n")
    );
}

/// The demo with its hold (the level and pitch setpoints are sent at vehicle times the lab
/// decides), paper noise, seed 3: the run the issue saw give 0.065 then 0.045.
#[test]
fn the_demo_gives_the_same_json_for_a_seed_under_load() {
    let args = ["demo", "--seed", "3", "--hold-s", "4", "--noise", "paper"];
    let first = run(&args);
    let second = run_loaded(&args);
    assert!(first["err_rot"].as_f64().is_some(), "{first}");
    assert!(first["attitude_err_deg"].as_f64().is_some(), "{first}");
    assert_same(&first, &second, "demo --seed 3");
    let other = run(&["demo", "--seed", "4", "--hold-s", "4", "--noise", "paper"]);
    assert_ne!(
        vehicle_time_only(&first),
        vehicle_time_only(&other),
        "seeds 3 and 4 gave the same JSON: the comparison sees nothing"
    );
}

/// An experiment of three runs (manual, learned, oracle: an estimation, a model file
/// loaded, pitch steps sent at vehicle times), seed 2: the issue saw its yaw errors move by
/// 30 % between two passes.
#[test]
fn an_experiment_gives_the_same_json_for_a_seed_under_load() {
    let args = ["experiment", "misaligned", "--seed", "2"];
    let first = run(&args);
    let second = run_loaded(&args);
    assert!(first["runs"]["learned"].is_object(), "{first}");
    assert_same(&first, &second, "experiment misaligned --seed 2");
}

/// `--seeds A-B` runs exactly the runs `--seed S` gives, and its spread is theirs: seed 2's
/// headline inside a two-seed sweep equals the single run's, and each figure's mean, sd and
/// range are those of the per-seed values.
#[test]
fn a_seed_sweep_is_the_single_seed_runs_and_their_spread() {
    let sweep = run(&["experiment", "misaligned", "--seeds", "1-2"]);
    assert_eq!(sweep["seeds"], serde_json::json!([1, 2]), "{sweep}");
    let per_seed = sweep["headline_per_seed"].as_array().expect("per seed");
    assert_eq!(per_seed.len(), 2);
    let single = run(&["experiment", "misaligned", "--seed", "2"]);
    assert_eq!(
        per_seed[1], single["headline"],
        "seed 2 in the sweep and alone"
    );
    let stats = &sweep["headline_over_seeds"]["manual_over_learned"];
    let xs: Vec<f64> = per_seed
        .iter()
        .map(|h| h["manual_over_learned"].as_f64().unwrap())
        .collect();
    let mean = (xs[0] + xs[1]) / 2.0;
    let sd = (xs[0] - xs[1]).abs() / 2f64.sqrt();
    assert_eq!(stats["n"], 2, "{stats}");
    assert!(
        (stats["mean"].as_f64().unwrap() - mean).abs() < 1e-12,
        "{stats}"
    );
    assert!(
        (stats["sd"].as_f64().unwrap() - sd).abs() < 1e-12,
        "{stats}"
    );
    assert_eq!(stats["min"].as_f64().unwrap(), xs[0].min(xs[1]));
    assert_eq!(stats["max"].as_f64().unwrap(), xs[0].max(xs[1]));
}

/// A folder of the lab's binaries in which `late` (thrusterd or thruster-sim) starts `run`
/// half a second after the lab spawned it: the lab finds its binaries next to itself, so
/// thrusterctl and the other binary are hard links (same inode: the real programs), and
/// `late` a script that sleeps and then `exec`s the real one (same process, so the lab's
/// signals reach it).
fn binaries_with_a_late(late: &str) -> tempfile::TempDir {
    let real_ctl = system_tests::bin("thrusterctl");
    let target = real_ctl.parent().expect("thrusterctl has a folder");
    // Beside the real binaries: the same file system, so hard links work.
    let dir = tempfile::Builder::new()
        .prefix("late-start-")
        .tempdir_in(target)
        .expect("temp folder beside the binaries");
    for name in ["thrusterctl", "thrusterd", "thruster-sim"] {
        let real = system_tests::bin(name);
        let here = dir.path().join(name);
        if name == late {
            let script = format!(
                "#!/bin/sh\nif [ \"$1\" = run ] && [ \"$2\" != --help ]; then sleep 0.5; fi\nexec '{}' \"$@\"\n",
                real.display()
            );
            std::fs::write(&here, script).expect("write the late starter");
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&here, std::fs::Permissions::from_mode(0o755))
                .expect("make it executable");
        } else {
            std::fs::hard_link(&real, &here).expect("hard link a binary");
        }
    }
    dir
}

/// `thrusterctl <args> --json` from `bins`, which must succeed, as JSON.
fn run_from(bins: &std::path::Path, args: &[&str]) -> Value {
    let out = std::process::Command::new(bins.join("thrusterctl"))
        .args(args)
        .arg("--json")
        .current_dir(system_tests::workspace())
        .output()
        .expect("thrusterctl runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "thrusterctl {args:?} failed\nstdout: {stdout}\nstderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("not one JSON object ({e}): {stdout}"))
}

/// Which process the machine starts first does not change the run: the daemon half a second
/// after the simulator, and the simulator half a second after the daemon, give the same JSON
/// on a battery vehicle. Before the simulator waited for the daemon's thrust publisher, the
/// driver's first report (the pack's voltage at vehicle time 0) went out before a late daemon
/// subscribed, the daemon's first reading came 0.1 s later, its sag line weighed its readings
/// differently, and eight_vectored_t200's learned model moved by 2e-8 (err_rot
/// 0.0162895395 or 0.0162895217, whichever process won).
#[test]
fn which_process_starts_first_does_not_change_the_run() {
    let args = [
        "demo",
        "--vehicle",
        "config/vehicles/eight_vectored_t200.toml",
        "--noise",
        "realistic",
        "--seed",
        "3",
        "--hold-s",
        "0",
    ];
    let late_daemon = binaries_with_a_late("thrusterd");
    let late_sim = binaries_with_a_late("thruster-sim");
    let a = run_from(late_daemon.path(), &args);
    let b = run_from(late_sim.path(), &args);
    assert!(a["err_rot"].as_f64().is_some(), "{a}");
    // A battery vehicle: the daemon read the pack (the reading the race lost).
    assert!(
        a["supply_voltage_v"].as_f64().is_some_and(|v| v > 10.0),
        "{a}"
    );
    assert_same(
        &a,
        &b,
        "demo on eight_vectored_t200, daemon late vs simulator late",
    );
}
