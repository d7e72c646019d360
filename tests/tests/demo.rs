//! `thrusterctl demo --json`: the README's main command with the real thrusterd and
//! thruster-sim processes (lockstep), scored against the simulator's truth. It runs the default
//! estimator (the dynamic method); the thresholds are issue 11's targets with a margin for a
//! loaded machine, the comments say what the runs measured.

use serde_json::Value;

fn demo(args: &[&str]) -> Value {
    let (ok, v, log) = demo_outcome(args);
    assert!(ok, "demo failed\n{log}");
    v
}

/// The demo's JSON whether it succeeded or not (a refused model is a failure with a JSON
/// that says why), and its output for messages.
fn demo_outcome(args: &[&str]) -> (bool, Value, String) {
    let out = system_tests::cli::lab(&[&["demo"], args, &["--json", "--hold-s", "0"]].concat());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let log = format!("stdout: {stdout}\nstderr: {stderr}");
    let v = serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("not one JSON object ({e})\n{log}"));
    (out.status.success(), v, log)
}

/// The demo with `args` ends in the daemon refusing its model: the demo fails with a JSON
/// whose `refused` says "model rejected" and each of `says`, both processes gone cleanly.
fn refused_demo(args: &[&str], says: &[&str]) -> Value {
    let (ok, v, log) = demo_outcome(args);
    assert!(!ok, "a refused model fails the demo\n{log}");
    let refused = v["refused"].as_str().unwrap_or_else(|| panic!("{log}"));
    for part in says.iter().chain(&["model rejected"]) {
        assert!(refused.contains(part), "{part:?} not in {refused:?}");
    }
    assert_eq!(v["clean_exit"], true);
    assert_eq!(v["files_left"], 0);
    v
}

/// Realistic IMU (seed 1): over seeds 1-10 the model is 0.006-0.019 / 0.011-0.017 off the
/// truth after 4.24 vehicle-s (32 pulses) on every seed (docs/experiments.md#over-ten-seeds-
/// issue-27); bounds at 1.5x the worst seed. The vehicle stays within 30 deg of level while it
/// is excited (measured 22.3 deg). The JSON carries the method, the excursion and every
/// learned coefficient.
#[test]
fn the_demo_learns_the_dynamic_model_quickly_and_reports_it() {
    let v = demo(&["--noise", "realistic"]);
    assert_eq!(v["method"], "Dynamic", "{v}");
    let (rot, acc) = (
        v["err_rot"].as_f64().unwrap(),
        v["err_acc"].as_f64().unwrap(),
    );
    assert!(rot <= 0.028 && acc <= 0.026, "errors {rot:.3} / {acc:.3}");
    let secs = v["vehicle_seconds"].as_f64().unwrap();
    assert!(secs <= 6.4, "{secs:.1} vehicle seconds");
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

/// Issue 32 through the processes: the simulator's IMU 18 cm off the centre of eight_vectored
/// (noise-free, the daemon told nothing). The daemon finds it (measured in-process
/// (0.150, 0.048, -0.101) m), refuses the model with the position in its status and keeps
/// the vehicle neutral; told the position from the drawings (a config file, as an operator
/// would), the translation rows come out 1.6 % off (measured in-process), where the model
/// referred to the IMU was 84-144 % off.
#[test]
fn an_imu_off_the_centre_is_found_refused_and_then_used_from_the_drawings() {
    let base = [
        "--noise",
        "none",
        "--vehicle",
        "config/vehicles/eight_vectored.toml",
        "--imu-position",
        "0.15,0.05,-0.10",
    ];
    let v = refused_demo(&base, &["IMU found at (0.1"]);
    assert_eq!(v["vehicle_as_is"]["imu_position_true_m"][0], 0.15, "{v}");

    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("thrusterd.toml");
    std::fs::write(&cfg, "[estimator]\nimu_position_m = [0.15, 0.05, -0.10]\n").unwrap();
    let mut told: Vec<&str> = base.to_vec();
    let cfg_arg = cfg.display().to_string();
    told.extend(["--daemon-config", &cfg_arg]);
    let v = demo(&told);
    let (rot, acc) = (
        v["err_rot"].as_f64().unwrap(),
        v["err_acc"].as_f64().unwrap(),
    );
    assert!(
        rot <= 0.03 && acc <= 0.03,
        "errors {rot:.4} / {acc:.4}: {v}"
    );
    assert_eq!(v["imu_position_m"][0], 0.15, "{v}");
    assert_eq!(v["imu_position_contradicted"], false, "{v}");
    let learned = v["imu_learned_m"][0].as_f64().unwrap();
    assert!((learned - 0.15).abs() <= 0.01, "learned x {learned}");
}

/// Issue 31 item 1 through the processes: AMOUR-5 whose thrusters give 0.6 of forward thrust
/// in reverse where the daemon assumes 0.78 (`config/vehicles/amour5_reverse60.toml`; the
/// daemon is not told). Realistic IMU, seed 1: with the bare one column, err 0.0267 / 0.0200
/// under bounds of 0.0208 / 0.0258, the rotation rows outside their bound on every seed of
/// 1-10 (docs/study.md, "Vehicles the estimator was not told about"). With the column fitted
/// to the thrust's shape (`estimator.shaped_thrust`, the default since 2026-12-03): seed 1
/// 0.0105 / 0.0136 under 0.0207 / 0.0259; seeds 1-10 0.0070-0.0242 / 0.0076-0.0201, the
/// rotation rows within their bound on 7 of 10 (seeds 2, 5, 8 at 1.05-1.16x), the acceleration
/// rows on all (docs/study.md, "The shape on by default, test by test"). The excitation still
/// tilts the vehicle 63.6 deg (the budget is 30). Since the learned lag's reach
/// (`estimator.learned_lag_reach_rel_err`, 2026-12-07) four of the ten seeds wait a doublet
/// pair more (4.24 -> 4.64 s): seeds 1-10 0.0070-0.0235 / 0.0099-0.0201, RMS 0.0168 / 0.0160 ->
/// 0.0152 / 0.0146, outside their bound 3 -> 1 of 10; seed 1 itself 0.0105 / 0.0136 -> 0.0161 /
/// 0.0129 under 0.0204 / 0.0231. Errors and tilt bounded at 1.5x the figures, and seed 1
/// within its bounds.
#[test]
fn thrusters_weak_in_reverse_the_daemon_was_not_told_about() {
    let v = demo(&[
        "--noise",
        "realistic",
        "--seed",
        "1",
        "--vehicle",
        "config/vehicles/amour5_reverse60.toml",
    ]);
    let f = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k}: {v}"));
    let (rot, acc, tilt) = (f("err_rot"), f("err_acc"), f("estimation_max_tilt_deg"));
    println!(
        "reverse 0.6: err {rot:.4} / {acc:.4}, bounds {:.4} / {:.4}, tilt {tilt:.1} deg",
        f("bound_rot"),
        f("bound_acc")
    );
    assert!(rot < 0.024 && acc < 0.02, "errors {rot:.4} / {acc:.4}: {v}");
    assert!(tilt < 95.0, "tilted {tilt:.1} deg while excited");
    assert!(
        rot <= f("bound_rot") && acc <= f("bound_acc"),
        "outside the bounds ({rot:.4} / {acc:.4} against {:.4} / {:.4})",
        f("bound_rot"),
        f("bound_acc")
    );
}

/// Issue 32, moving water through the processes: in the `rough` preset (a 0.5 m/s current
/// and a 0.15 Hz swell of 20 N / 2 N m) the swell swings AMOUR-5 118-151 deg while it is excited
/// and its models were 14-41 % off against bounds of 6-15 %; the daemon refuses them, saying how
/// much rotation was unexplained (measured 0.038-0.220 rad/s over seeds 1-5; seed 1, this
/// test's, 0.097-0.158 over two runs against the limit of 0.05).
#[test]
fn a_model_the_water_made_is_refused() {
    let v = refused_demo(
        &["--noise", "realistic", "--water", "rough"],
        &["rad/s of rotation unexplained"],
    );
    assert_eq!(v["vehicle_as_is"]["water"], "rough", "{v}");
}

/// Issue 32 through the processes, a swell the unexplained rotation lets through: the
/// moderate preset's water with its swell at the phase of seed 1 (2 pi x 0.618, as
/// `thruster_inprocess::swell_phase`), AMOUR-5 at a realistic IMU.
/// - As shipped the daemon refuses the model, saying so within its 128-byte status (a first,
///   longer wording was cut before "model rejected" and the demo took the refusal for a
///   fault): the fit without the swell's states puts the lag 8 % apart by its row groups
///   (6.1-7.5 sd), 2.2x B's bound. docs/study.md, "The lag in a swell".
/// - With that check off, the fit made again with the swell's disturbance states
///   (`estimator.moving_water_swell_hz`) is swapped in: 0.023 / 0.024 off under 0.032 / 0.025
///   (0.96x; this refusal is a cautious one). docs/study.md, "Disturbance states".
/// - With the check and the states both off, the model is 0.059 / 0.072 off under a bound
///   of 0.057 / 0.055 (1.31x) and swapped in.
#[test]
fn a_swell_that_pulls_the_lag_apart_is_refused_and_fitted_as_states_is_within_its_bound() {
    let dir = tempfile::tempdir().unwrap();
    let water = dir.path().join("moderate_at_seed_1.toml");
    // The simulator's own preset, its swell started at seed 1's phase.
    let mut moderate = thruster_sim::disturbance::WaterPreset::Moderate.disturbance();
    let phase = std::f64::consts::TAU * (0.5 * (5f64.sqrt() - 1.0)).fract();
    moderate.waves.iter_mut().for_each(|w| w.phase_rad = phase);
    let mut file = toml::Table::new();
    file.insert(
        "disturbance".into(),
        toml::Value::try_from(&moderate).unwrap(),
    );
    std::fs::write(&water, toml::to_string(&file).unwrap()).unwrap();
    let flight = [
        "--noise",
        "realistic",
        "--seed",
        "1",
        "--water-file",
        water.to_str().unwrap(),
    ];
    refused_demo(&flight, &["row groups put the lag"]);
    let config = |name: &str, text: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let with_config = |path: &std::path::Path| {
        demo_outcome(&[&flight[..], &["--daemon-config", path.to_str().unwrap()]].concat())
    };
    let ratio = |v: &Value, log: &str| {
        let f = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k}: {log}"));
        (f("err_rot") / f("bound_rot")).max(f("err_acc") / f("bound_acc"))
    };
    let check_off = config(
        "check_off.toml",
        "[machine]\nmax_lag_gap_over_bound = 0.0\n",
    );
    let (ok, v, log) = with_config(&check_off);
    assert!(ok, "the swell's states: {log}");
    assert!(
        v["err_rot"].as_f64().unwrap() <= 0.035
            && v["err_acc"].as_f64().unwrap() <= 0.036
            && ratio(&v, &log) <= 1.2,
        "the swell's states: {log}"
    );
    let neither = config(
        "neither.toml",
        "[estimator]\nmoving_water_swell_hz = 0.0\n[machine]\nmax_lag_gap_over_bound = 0.0\n",
    );
    let (ok, v, log) = with_config(&neither);
    assert!(ok && ratio(&v, &log) > 1.2, "neither: {log}");
}

/// Issue 29 through the processes: eight_vectored with T200 thrusters from the measured table
/// on the shipped 4S pack (20 mOhm; it sags from 16.8 to 13.7-14.8 V under the pulses, read
/// every 100 ms), noise-free, the daemon configured for T200 thrusters by the demo (`[supply]
/// linearize`) and told nothing of the pack. Scored against the truth at the 16 V the model
/// is referred to (`truth_voltage_v`). Measured 0.0170 / 0.0173 (on a fixed 16 V supply
/// 0.0137 / 0.0142, the power-law eight_vectored 0.013 / 0.014); before the sag was predicted
/// and the pulses capped under it 0.089 / 0.089 (every pulse at full power saturated), and
/// 0.112 / 0.113 without `linearize` (a linear model of the T200's curve).
#[test]
fn t200_thrusters_on_a_sagging_pack_are_learned_at_the_reference_voltage() {
    let v = demo(&[
        "--noise",
        "none",
        "--vehicle",
        "config/vehicles/eight_vectored_t200.toml",
    ]);
    let f = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k}: {v}"));
    let (rot, acc) = (f("err_rot"), f("err_acc"));
    println!(
        "eight_vectored_t200: err {rot:.4} / {acc:.4} at {:.2} V, truth at {:.2} V",
        f("supply_voltage_v"),
        f("truth_voltage_v")
    );
    assert_eq!(v["linearize"], true, "{v}");
    assert_eq!(v["compensation"], "t200", "{v}");
    assert_eq!(f("truth_voltage_v"), 16.0);
    assert!(
        f("supply_voltage_v") < 15.5,
        "the pack sagged and drained: {v}"
    );
    assert!(rot < 0.02 && acc < 0.02, "errors {rot:.4} / {acc:.4}: {v}");
    assert_eq!(v["clean_exit"], true);
    assert_eq!(v["files_left"], 0);
}

/// The demo on eight_vectored_lag80ms_curve (another make's thrust ~ command^1.5) at a
/// realistic IMU with a hold of `hold_s`, its daemon configured by `daemon_toml` (None: the
/// demo's own, as the make's operator has it); the model after the hold within its bound.
/// Returns the JSON.
fn curve_demo(daemon_toml: Option<&str>, hold_s: &str, noise: &str) -> Value {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("thrusterd.toml");
    let mut args = vec![
        "demo",
        "--json",
        "--noise",
        noise,
        "--hold-s",
        hold_s,
        "--vehicle",
        "config/vehicles/eight_vectored_lag80ms_curve.toml",
    ];
    if let Some(text) = daemon_toml {
        std::fs::write(&file, text).unwrap();
        args.extend(["--daemon-config", file.to_str().unwrap()]);
    }
    let out = system_tests::cli::lab(&args);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_str(stdout.trim()).expect("one JSON object");
    let f = |v: &Value, k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k}: {v}"));
    let after = &v["model_after_hold"];
    println!(
        "{}: open loop {:.3} / {:.3} under {:.3} / {:.3}; after the hold (v{}, curve {}) {:.3} / {:.3} under {:.3} / {:.3}",
        v["compensation"],
        f(&v, "err_rot"),
        f(&v, "err_acc"),
        f(&v, "bound_rot"),
        f(&v, "bound_acc"),
        after["version"],
        after["thrust_exponent_learned"],
        f(after, "err_rot"),
        f(after, "err_acc"),
        f(after, "bound_rot"),
        f(after, "bound_acc")
    );
    // The open-loop model is a line through the pulses' amplitude, its learned bound short of
    // it: what is checked after the hold could fail.
    assert!(f(&v, "err_rot") > 2.0 * f(&v, "bound_rot"), "{v}");
    assert!(
        after["version"].as_u64() > v["dynamics"]["model_version"].as_u64(),
        "{after}"
    );
    for g in ["rot", "acc"] {
        assert!(
            f(after, &format!("err_{g}")) <= f(after, &format!("bound_{g}")),
            "{g}: {after}"
        );
    }
    assert_eq!(v["clean_exit"], true);
    assert_eq!(v["files_left"], 0);
    v
}

/// Issues 29 and 32 item 4 through the processes: another make's thrusters under the daemon's
/// defaults, which take them for T200s. Under control the identification names the curve and
/// is refused (the daemon says to configure it); the model in force stays, and the daemon
/// publishes it again with its bound restated to cover it: 0.081 / 0.083 off under 0.69 /
/// 0.97 (it had kept 0.021 / 0.028, a confident wrong model).
#[test]
fn a_curve_named_and_refused_restates_the_model_in_force_bound() {
    let v = curve_demo(Some("[vehicle]\nthrusters = 8\n"), "40", "realistic");
    assert_eq!(v["compensation"], "t200", "{v}");
    let after = &v["model_after_hold"];
    assert!(after["thrust_exponent_learned"].is_null(), "{after}");
    // The same B, restated.
    assert_eq!(after["err_rot"], v["err_rot"], "{after}");
}

/// The same thrusters as their operator configures them (`compensation = "none"`, the demo's
/// own): the curve named is learned, the commands go out through it, and after a 60 s hold
/// the model carries it: ^1.519 (true 1.5), 0.022 / 0.042 off under 0.121 / 0.130 (seeds
/// 1-10: 0.002-0.056, within 0.52x, since the confirmation on the curve runs 8 s), where the
/// line was 0.081. Not at 40 s: the identifications on the curve are then still running
/// and the line is in force, its bound restated (0.081 / 0.083 under 0.77 / 0.97).
#[test]
fn the_demo_learns_another_makes_curve() {
    let v = curve_demo(None, "60", "realistic");
    assert_eq!(v["compensation"], "none", "{v}");
    let after = &v["model_after_hold"];
    let p = after["thrust_exponent_learned"]
        .as_f64()
        .unwrap_or_else(|| panic!("a curve learned: {after}"));
    assert!((p - 1.5).abs() < 0.05, "{p}");
    // Better than the line through the pulses' amplitude.
    let after_err = after["err_rot"].as_f64().unwrap();
    assert!(after_err < 0.5 * v["err_rot"].as_f64().unwrap(), "{after}");
}

/// The same thrusters at the paper's noise, where no identification names the curve: the
/// refinement's windows, pooled, find the line giving about 55 % of its gain at the hold's
/// commands (`refinement.gain_gap_min`), and the daemon publishes it again with its bound
/// restated, B untouched: seed 1 after a 100 s hold 0.114 / 0.129 off under 0.361 / 0.370
/// (off: under its learned 0.043 / 0.093, 2.64x).
#[test]
fn the_hold_gain_restates_the_line_at_the_paper_noise() {
    let v = curve_demo(None, "100", "paper");
    let after = &v["model_after_hold"];
    assert!(after["thrust_exponent_learned"].is_null(), "{after}");
    assert_eq!(after["err_rot"], v["err_rot"], "the same B: {after}");
}

/// Issue 29 through the processes: AMOUR-5 with three thrusters lagging 0.15 s and two 0.05 s
/// (`amour5_two_makes`), a realistic IMU, the daemon told nothing. The lags differ, so each
/// thruster's is learned, and the dynamics topic carries them with the evidence (DynamicsMsg
/// v4). Seed 1 measured: 0.153, 0.151, 0.153, 0.050, 0.050 s (ln LR 2953), the model 0.009 /
/// 0.025 off under bounds of 0.055 / 0.054 in 4.24 vehicle-s.
#[test]
fn thrusters_of_two_makes_are_each_given_their_own_lag() {
    let v = demo(&[
        "--noise",
        "realistic",
        "--vehicle",
        "config/vehicles/amour5_two_makes.toml",
    ]);
    let lags = |k: &str| -> Vec<f64> {
        v[k].as_array()
            .unwrap_or_else(|| panic!("{k}: {v}"))
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let (learned, truth) = (
        lags("spin_up_per_thruster_s"),
        lags("spin_up_true_per_thruster_s"),
    );
    assert_eq!(truth, [0.15, 0.15, 0.15, 0.05, 0.05]);
    assert_eq!(learned.len(), truth.len(), "{v}");
    for (i, (l, t)) in learned.iter().zip(&truth).enumerate() {
        assert!((l - t).abs() <= 0.01, "thruster {i}: {l:.4} s, true {t} s");
    }
    assert!(v["dynamics"]["thruster_lag_evidence"].as_f64().unwrap() > 100.0);
    assert_eq!(v["spin_up_learned"], true);
    assert!(v["spin_up_consistent_s"].is_null(), "learned, not checked");
    let (rot, acc) = (
        v["err_rot"].as_f64().unwrap(),
        v["err_acc"].as_f64().unwrap(),
    );
    assert!(rot <= 0.03 && acc <= 0.04, "errors {rot:.4} / {acc:.4}");
    assert_eq!(v["clean_exit"], true);
    assert_eq!(v["files_left"], 0);
}

/// Issues 29 and 32 through the processes: at the paper's noise the lag is not learned (biased
/// short there) but the data is searched to check the configured 0.1 s. On AMOUR-5, whose
/// thrusters lag 0.1 s, the check allows it and says what the data allows (seed 1 measured
/// 0.083-0.164 s; the model 0.050 / 0.063 off in 7.04 vehicle-s); on AMOUR-5 whose thrusters
/// lag 0.2 s (`amour5_lag200ms`) the model is refused, naming the range, where unchecked it was
/// swapped in 0.48 off under a bound of a few percent.
#[test]
fn at_the_papers_noise_the_configured_lag_is_checked_against_the_data() {
    let v = demo(&["--noise", "paper"]);
    assert_eq!(v["spin_up_learned"], false, "{v}");
    assert_eq!(v["dynamics"]["spin_up_checked"], true, "{v}");
    let range: Vec<f64> = v["spin_up_consistent_s"]
        .as_array()
        .unwrap_or_else(|| panic!("{v}"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert!(
        range[0] < 0.1 && 0.1 < range[1] && range[1] < 0.3,
        "the range the data allows: {range:?}"
    );
    assert!(v["spin_up_per_thruster_s"].is_null(), "{v}");

    refused_demo(
        &[
            "--noise",
            "paper",
            "--vehicle",
            "config/vehicles/amour5_lag200ms.toml",
        ],
        &["s by the data, not spin_up_s 0.100"],
    );
}

/// Issues 29 item 5 and 32 item 4 through the processes: thrusters of another make whose
/// thrust goes as command^1.5 (`config/vehicles/eight_vectored_lag80ms_curve.toml`, 0.58 in
/// reverse, 80 ms; the daemon told none of it). With one pulse level per direction the model
/// came out 0.081 / 0.083 off under bounds of 0.022 / 0.028 and was swapped in. With
/// `estimator.second_amplitude = 0.6` (and `[supply] compensation = "none"`, another make's)
/// the estimate learns the curve and carries it: seed 1 realistic, ^1.508 learned, 0.024 /
/// 0.029 under 0.062 / 0.066, the lag 0.0799 s. Thrusters taken for T200s (the shipped
/// compensation) refuse it, naming the curve and what to configure (docs/study.md, "A second
/// level: the open loop sees the curve"). Errors bounded at 1.5x the figures, the exponent
/// within 3 %.
#[test]
fn an_untold_thrust_curve_is_learned_at_two_pulse_levels_and_refused_for_t200s() {
    let dir = tempfile::tempdir().unwrap();
    let base = [
        "--noise",
        "realistic",
        "--vehicle",
        "config/vehicles/eight_vectored_lag80ms_curve.toml",
    ];
    let other_make = dir.path().join("other_make.toml");
    std::fs::write(
        &other_make,
        "[estimator]\nsecond_amplitude = 0.6\n\n[supply]\ncompensation = \"none\"\n",
    )
    .unwrap();
    let arg = other_make.display().to_string();
    let v = demo(&[&base[..], &["--daemon-config", &arg]].concat());
    let p = v["thrust_exponent_learned"]
        .as_f64()
        .unwrap_or_else(|| panic!("no curve learned: {v}"));
    assert!((p / 1.5 - 1.0).abs() <= 0.03, "exponent {p}");
    let (rot, acc) = (
        v["err_rot"].as_f64().unwrap(),
        v["err_acc"].as_f64().unwrap(),
    );
    assert!(
        rot <= 0.036 && acc <= 0.044,
        "errors {rot:.4} / {acc:.4}: {v}"
    );
    assert!(
        rot <= v["bound_rot"].as_f64().unwrap() && acc <= v["bound_acc"].as_f64().unwrap(),
        "errors {rot:.4} / {acc:.4} beyond the bounds: {v}"
    );
    let lag = v["spin_up_s"].as_f64().unwrap();
    assert!((lag - 0.08).abs() <= 0.005, "lag {lag}");
    assert_eq!(v["clean_exit"], true);
    assert_eq!(v["files_left"], 0);

    let t200 = dir.path().join("t200.toml");
    std::fs::write(&t200, "[estimator]\nsecond_amplitude = 0.6\n").unwrap();
    let arg = t200.display().to_string();
    refused_demo(
        &[&base[..], &["--daemon-config", &arg]].concat(),
        &[
            "thrust ~ command^1.5",
            "not linear",
            "set [supply] linearize (T200) or power_law_exponent",
        ],
    );
}
