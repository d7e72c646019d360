//! `thrusterctl experiment NAME --json`: the paper's four pool experiments and `degrade` (a
//! slowly weakening thruster), each run with the real thrusterd and thruster-sim processes
//! (stepped lockstep, paper noise unless the run says otherwise), asserting the headline
//! result. A run is reproducible (one seed, one JSON, under any load: tests/determinism.rs),
//! so the bounds sit near the figures measured over seeds 1-10 (`thrusterctl experiment NAME
//! --seeds 1-10`, docs/experiments.md#over-ten-seeds-issue-27): errors and delays at 1.5x
//! the worst seed, ratios at 1.2x (issue 31); a change that moves a figure beyond them is a
//! regression or a new measurement for the docs.

use std::sync::Mutex;

use serde_json::Value;

/// One experiment at a time: a run's result no longer depends on the machine's load, but
/// several at once on two cores only make each slower.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

fn experiment(name: &str) -> Value {
    experiment_with(name, &[])
}

/// [`experiment`] with more arguments (`--seed S`).
fn experiment_with(name: &str, more: &[&str]) -> Value {
    // A failed experiment poisons the lock; the others still run.
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let mut args = vec!["experiment", name, "--json"];
    args.extend_from_slice(more);
    let out = system_tests::cli::lab(&args);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "experiment {name} failed\nstdout: {stdout}\nstderr: {stderr}"
    );
    let v: Value = serde_json::from_str(&stdout).expect("one JSON object");
    for (label, run) in v["runs"].as_object().expect("runs") {
        assert_eq!(run["clean_exit"], true, "{name}/{label}: {run}");
        assert_eq!(run["files_left"], 0, "{name}/{label}: {run}");
        // Most of the 200 Hz vehicle samples were scored (the inbox keeps up).
        let scored = run["vehicle_samples_scored"].as_f64().unwrap();
        let hold = run["hold_s"].as_f64().unwrap();
        assert!(
            scored > 0.5 * 200.0 * hold,
            "{name}/{label}: {scored} samples"
        );
    }
    v
}

fn f(v: &Value, path: &[&str]) -> f64 {
    let mut x = v;
    for p in path {
        x = &x[*p];
    }
    x.as_f64()
        .unwrap_or_else(|| panic!("{path:?} is not a number in {v}"))
}

fn dofs(v: &Value) -> Vec<String> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|d| d.as_str().unwrap().to_string())
        .collect()
}

#[test]
fn manual_vs_learned_the_learned_model_holds_attitude_as_well_as_the_manual_one() {
    let v = experiment("manual-vs-learned");
    let (l, m) = (
        f(&v, &["runs", "learned", "mean_err_deg"]),
        f(&v, &["runs", "manual", "mean_err_deg"]),
    );
    // The paper's claim is "matches". Seeds 1-10: learned/manual 0.85-1.10, learned 3.96-4.98
    // deg, manual 4.06-5.19 deg.
    assert!(l < 1.3 * m, "learned {l} deg vs manual {m} deg");
    assert!(l < 7.5 && m < 7.8, "learned {l}, manual {m}");
    // The reference: the simulator's true model, loaded: learned/oracle 0.88-1.16, the hold
    // is not limited by the model.
    let o = f(&v, &["runs", "oracle", "mean_err_deg"]);
    assert!(l < 1.4 * o, "learned {l} deg vs the true model {o} deg");
    // The learned model at the paper's noise: 0.040-0.077 / 0.044-0.093 off the truth.
    let h = &v["headline"];
    assert!(f(h, &["learned_model_err_rot"]) < 0.115, "{h}");
    assert!(f(h, &["learned_model_err_acc"]) < 0.14, "{h}");
    assert!(f(&v, &["runs", "oracle", "model", "rel_err_rot_vs_truth"]) < 1e-6);
    assert_eq!(
        dofs(&v["runs"]["learned"]["model"]["actuated"]),
        ["roll", "pitch", "yaw", "surge", "heave"]
    );
}

/// The paper: more than 2x smaller yaw error with the learned model. Measured over seeds 1-10
/// at the paper's noise with the bare one column: manual/learned 0.84-2.22 (mean 1.47; below 1
/// on seeds 2 and 7), and with the simulator's true model (the "oracle" run) 0.86-1.77 (mean
/// 1.35): this setup shows about 1.4x at this noise even with a perfect model. With the column
/// fitted to the thrust's shape (the default since 2026-12-03): manual/learned 0.70-2.46 (mean
/// 1.42; below 1 on seeds 2 and 7 again), manual/oracle 0.87-1.77 (mean 1.35), manual
/// 1.58-3.71 deg, the learned model 0.027-0.054 off. One seed is a draw from that spread (seed
/// 1 went from 1.17 to 1.04 with the shape), so seeds 1-5 are flown and their mean asserted
/// (measured 1.25; the oracle's 1.26).
#[test]
fn misaligned_the_relearned_model_does_not_yaw_more_than_the_manual_one() {
    let (mut over_learned, mut over_oracle) = (0.0, 0.0);
    let seeds = ["1", "2", "3", "4", "5"];
    for seed in seeds {
        let v = experiment_with("misaligned", &["--seed", seed]);
        let h = &v["headline"];
        let (m, l) = (
            f(h, &["manual_yaw_err_mean_deg"]),
            f(h, &["learned_yaw_err_mean_deg"]),
        );
        let o = f(h, &["oracle_yaw_err_mean_deg"]);
        println!("seed {seed}: manual {m:.2} deg, learned {l:.2}, true model {o:.2}");
        over_learned += m / l;
        over_oracle += m / o;
        assert!(m < 5.6, "seed {seed}: manual {m}");
        assert!(f(&v, &["runs", "manual", "model", "rel_err_rot_vs_truth"]) > 0.3);
        // The re-learned model: 0.026-0.062 off the truth over seeds 1-10.
        assert!(f(h, &["learned_model_err_rot"]) < 0.095, "seed {seed}: {h}");
    }
    let n = seeds.len() as f64;
    let (over_learned, over_oracle) = (over_learned / n, over_oracle / n);
    assert!(
        over_learned > 1.12,
        "manual / learned {over_learned:.2} on the mean"
    );
    assert!(
        over_oracle > 1.12,
        "manual / true model {over_oracle:.2} on the mean"
    );
}

#[test]
fn aligned_ours_reports_the_missing_dofs_holds_pitch_and_yaw_and_the_papers_thrust_chatters() {
    let v = experiment("aligned");
    let paper = dofs(&v["headline"]["paper"]["actuated"]);
    let ours = dofs(&v["headline"]["forward"]["actuated"]);
    assert_eq!(ours, ["pitch", "yaw", "surge"]);
    // The paper's estimator "learns" the nonexistent DOFs (its Fig. 5b, blue bars).
    for dof in ["roll", "sway", "heave"] {
        assert!(paper.iter().any(|d| d == dof), "paper {paper:?}");
    }
    // Thrust activity paper/ours 11.2-18.5x over seeds 1-10 (337-540/s against 29-32/s): the
    // paper's model commands the thrusters back and forth for the DOFs they cannot move.
    let ratio = f(&v, &["headline", "paper_over_forward_thrust_activity"]);
    assert!(ratio > 9.0, "thrust activity paper/ours {ratio}");
    // Ours holds yaw (3.7-5.5 deg mean over the 30 deg yaw step and back, seeds 1-10; the
    // paper's model 3.5-9.7 deg over seeds 1-10, so it is not asserted).
    let yaw = f(
        &v,
        &["runs", "forward", "per_maneuver", "yaw", "mean_err_deg"],
    );
    assert!(yaw < 8.3, "ours: yaw maneuver {yaw} deg");
    // And pitch, without rolling away: 4.1-5.4 deg mean over the 20 deg pitch step and back,
    // roll rate 1.29-1.51 deg/s rms over seeds 1-10. Before the controller stopped holding
    // depth by surging (this vehicle has no heave) it was 12.9-14.4 deg and 6.1-6.8 deg/s.
    let pitch = f(
        &v,
        &["runs", "forward", "per_maneuver", "pitch", "mean_err_deg"],
    );
    assert!(pitch < 8.0, "ours: pitch maneuver {pitch} deg");
    let roll_rate = f(
        &v,
        &["runs", "forward", "oscillation", "roll_rate_rms_deg_s"],
    );
    assert!(roll_rate < 2.3, "ours: roll rate {roll_rate} deg/s rms");
}

#[test]
fn hot_swap_the_daemon_reestimates_swaps_and_recovers() {
    let v = experiment("hot-swap");
    let a = &v["runs"]["announced"]["hot_swap"];
    // Announced: the nominal model of the declared geometry at once (0.0 s), the learned one
    // after identifying under control, keeping the other thrusters' columns (10-14 s over
    // seeds 1-10, 0.041-0.064 off the truth; learning every column anew took the 20 s limit,
    // 21.0 s: 18 s fails that), and the error back under 1.5x its worst 2 s window before
    // the change (0.005-1.6 s).
    assert_eq!(a["first_swap_source"], "Nominal", "{a}");
    assert!(f(a, &["first_swap_delay_s"]) < 0.5, "{a}");
    assert!(f(a, &["new_model_delay_s"]) < 18.0, "{a}");
    assert!(f(a, &["new_model_rel_err_rot_vs_truth"]) < 0.1, "{a}");
    assert!(f(a, &["recovered_after_s"]) < 2.5, "{a}");
    // After: as good as before, within 2 deg (measured 4.4 before, 4.6 after).
    let (before, after) = (
        f(a, &["before", "mean_err_deg"]),
        f(a, &["after", "mean_err_deg"]),
    );
    assert!(after < before + 2.0, "before {before}, after {after}");

    // Holding level through the announced change (paper noise), the identification under
    // control tilts the vehicle by 6.5-8.2 deg (seeds 1-10; the bound is its issue's 10 deg)
    // and brings the new model after 10-15 s.
    let h = &v["headline"];
    assert!(f(h, &["announced_level_max_tilt_deg"]) <= 10.0, "{h}");
    assert!(f(h, &["announced_level_new_model_delay_s"]) < 18.0, "{h}");

    let s = &v["runs"]["silent"]["hot_swap"];
    if v["daemon_has_monitor"] == true {
        // Silent: the model-mismatch monitor notices and re-estimates, once: the model it then
        // learns is not mistaken for another change (before the settle gate and the
        // noise-sized pulses, 3 of 8 seeds re-estimated a second time).
        assert_eq!(
            v["runs"]["silent"]["monitor_mismatch_reports"], 1,
            "{}",
            v["runs"]["silent"]
        );
        assert_eq!(v["runs"]["announced"]["monitor_mismatch_reports"], 0);
        // Seeds 1-10 (realistic IMU): detected after 0.60-1.04 s, new model after 5.6-6.0 s,
        // 0.011-0.032 off the truth, recovered after 0.4 s.
        assert!(f(s, &["detection_delay_s"]) < 1.6, "{s}");
        assert!(f(s, &["new_model_delay_s"]) < 9.0, "{s}");
        assert!(f(s, &["new_model_rel_err_rot_vs_truth"]) < 0.05, "{s}");
        assert!(f(s, &["recovered_after_s"]) < 2.5, "{s}");
        let (before, after) = (
            f(s, &["before", "mean_err_deg"]),
            f(s, &["after", "mean_err_deg"]),
        );
        assert!(after < before + 2.0, "before {before}, after {after}");
        // At the paper's noise the refinement's change test finds it through the pitch steps
        // (seeds 1-10: detected after 2.8-6.6 s, the new model 11.5-18.6 s after the change,
        // 0.037-0.068 off the truth, one report each; the windows alone took 42.6-50.6 s).
        let p = &v["runs"]["silent-paper"];
        assert_eq!(p["monitor_mismatch_reports"], 1, "{p}");
        let ph = &p["hot_swap"];
        assert!(f(ph, &["detection_delay_s"]) < 10.0, "{ph}");
        assert!(f(ph, &["new_model_rel_err_rot_vs_truth"]) < 0.1, "{ph}");
        // The oracle (the new true model loaded at the change) holds as the learned one does
        // after re-learning (measured after 4.7-5.0 deg against before 4.6-5.0).
        let o = &v["runs"]["oracle"]["hot_swap"];
        let (before, after) = (
            f(o, &["before", "mean_err_deg"]),
            f(o, &["after", "mean_err_deg"]),
        );
        assert!(
            after < before + 2.0,
            "oracle: before {before}, after {after}"
        );
    } else {
        // A daemon without the monitor keeps the old model: the vehicle stays controlled
        // (measured 5.5 deg after the change vs 4.6 before) but nothing is re-learned.
        assert!(s["new_model_delay_s"].is_null(), "{s}");
        let (before, during) = (
            f(s, &["before", "mean_err_deg"]),
            f(s, &["during", "mean_err_deg"]),
        );
        assert!(
            during < before + 5.0,
            "before {before}, after the change {during}"
        );
    }
}

/// Thruster L loses 30 % over a minute, unannounced, realistic IMU: the refined model follows
/// it without a re-estimation (seeds 1-10: 0.010-0.021 / 0.014-0.025 off the truth at the end,
/// 24 refinements, no new model), the model learned at the start ends 0.12 / 0.17 off; the
/// oracle reloads the truth as it moves. Bounds at 1.5x the worst seed (the issue asked for
/// 0.05).
#[test]
fn degrade_the_refined_model_follows_a_weakening_thruster() {
    let v = experiment("degrade");
    let h = &v["headline"];
    assert!(f(h, &["refined_err_rot"]) <= 0.032, "{h}");
    assert!(f(h, &["refined_err_acc"]) <= 0.038, "{h}");
    assert_eq!(h["refined_new_models"], 0, "{h}");
    assert!(f(h, &["refined_refinements"]) >= 10.0, "{h}");
    // The fixed model is the contrast: the loss is visible in it.
    assert!(f(h, &["fixed_err_rot"]) > 0.08, "{h}");
    assert!(f(h, &["fixed_err_acc"]) > 0.1, "{h}");
    let o = &v["runs"]["oracle"]["degrade"];
    assert!(f(o, &["err_rot_vs_truth_end"]) < 0.02, "{o}");
    assert_eq!(v["runs"]["refined"]["degrade"]["mismatch_reports"], 0);
}

/// The dive drains the battery over 30 vehicle minutes in both runs, and the daemon refers
/// its commands to the reference voltage (and linearizes them) in one of them. The issue's
/// ratio on the whole hold error (compensated last/first <= 1.15) is not asserted: over seeds
/// it scatters from 0.75 to 1.64 in both runs alike, because the heading follows the
/// magnetometer's bias as it wanders. On the tilt alone (roll and pitch, what the thrusters'
/// strength moves) the compensated ratio is 1.03-1.10 and the uncompensated one 1.29-1.33
/// on AMOUR-5, seeds 1-5 (docs/experiments.md); seed 1: 1.09 and 1.32. So the tilt's
/// ratio is asserted: at most 1.15 compensated, at least 1.2 uncompensated. The compensated
/// run ends the dive lower (measured 12.95-12.99 V under load, against 13.0-13.5 V; why is not
/// decided, docs/experiments.md).
#[test]
fn dive_drains_the_battery_from_full_to_nearly_empty_in_both_runs() {
    let v = experiment("dive");
    let h = &v["headline"];
    let start = f(h, &["voltage_start_v"]);
    assert!((16.3..16.8).contains(&start), "{h}");
    for run in ["compensated", "uncompensated"] {
        let end = f(h, &[run, "voltage_end_v"]);
        assert!((12.7..14.2).contains(&end), "{run}: {h}");
        let d = &v["runs"][run]["dive"];
        assert!(f(d, &["hold_s"]) > 1700.0, "{run}: {d}");
        assert_eq!(
            d["new_models"], 0,
            "{run}: one estimation at the start: {d}"
        );
        // Unread, the supply (and the T200's curve, the dead zone only jumped) leaves the
        // model stronger than the thrusters at the hold's commands: the refinement's windows
        // find it and the bound is restated, the same B (`refinement.gain_gap_min`; seed 1:
        // 0.45 after 6 s, 0.53 after 1767 s). Referred to 16 V and linearized, nothing to find.
        let restated = d["bounds_restated"].as_array().expect("bounds_restated");
        assert_eq!(restated.is_empty(), run == "compensated", "{run}: {d}");
        for k in ["hold_err_first_5min_deg", "hold_err_last_5min_deg"] {
            let e = f(d, &[k]);
            assert!(e > 0.0 && e < 15.0, "{run} {k}: {d}");
        }
    }
    let tilt = |run: &str| f(h, &[run, "tilt_last_over_first"]);
    assert!(tilt("compensated") <= 1.15, "{h}");
    assert!(tilt("uncompensated") >= 1.2, "{h}");
    assert_eq!(h["holds_on_tilt"], true, "{h}");
}
