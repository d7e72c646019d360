//! Continuous refinement in one process, against the simulator's truth: while the machine
//! holds AMOUR-5 through pitch manoeuvres, the background fit (`thrusterd_core::adaptation::refinement`)
//! must stay quiet on an unchanged vehicle and find the top thruster rotated 45 degrees, at a
//! realistic IMU and at the paper's (where the older monitor is blind by design). The monitor's
//! own test is off here (infinite threshold), so every mismatch is the refinement's.
//!
//! Measured (in-process runs are deterministic). With one window deciding and a 0.4 share, a
//! 10-minute soak through the processes at the paper's noise (1 kHz, pitch toggled 0/10 deg
//! every 20 s) re-estimated 10 times on an unchanged vehicle, and in process 1.3-4 false alarms
//! per 180 s appeared (1 kHz and 200 Hz, seeds 1-3). Now a change must hold in two windows in a
//! row (or score chi2 > 200 in one) and move the column by 55 %: no false alarm in the same
//! 9 x 180 s; a rotation found after 2.9 s and 7.9 s with a realistic IMU (seeds 1, 4; a window
//! that straddles the change moves the column less, so the next one decides) and after 49.5 s
//! at the paper's noise (seed 4). With the estimator's honest (larger) standard errors since:
//! 8.9 s and 7.9 s, and 79.9 s at the paper's noise (the windows; with the per-sample change
//! test, on by default since, 5.0 s on both seeds and 2.5-5.4 s at the paper's noise, seeds
//! 1-10: the tests below).
mod common;
use thruster_inprocess::holding::*;
use thruster_sim::NoisePreset;
use thrusterd_core::machine::State;

/// A realistic IMU, seeds 1 and 4: a minute of pitch steps on the unchanged vehicle raises
/// nothing, then the rotated top thruster is found and named. Measured (`cargo test -p
/// thrusterd-core --test refinement -- --nocapture with_a_realistic`): 5.0 s on both seeds,
/// by the change test (on by default); bound 7.5 s (1.5x).
#[test]
fn with_a_realistic_imu_a_rotated_thruster_is_found_within_seconds_and_nothing_else() {
    for seed in [1, 4] {
        let mut run = holding(NoisePreset::Realistic, seed);
        let quiet = pitch_until_mismatch(&mut run, 60.0);
        assert!(quiet.is_none(), "seed {seed}: false alarm {quiet:?}");
        assert!(run.machine.refinement().is_some(), "no window ended");
        run.rotate_top();
        let (t, why) = pitch_until_mismatch(&mut run, 30.0).expect("rotation not found");
        println!("seed {seed}: found after {t:.1} s: {why}");
        assert!(t < 7.5, "seed {seed}: {t:.1} s");
        assert!(why.contains("thruster 1"), "{why}");
        // The mismatch starts a re-estimation, under control.
        assert_eq!(run.machine.state(), State::Identify);
    }
}

#[test]
fn at_the_papers_noise_a_rotated_thruster_is_found_and_an_unchanged_one_is_not() {
    let mut run = holding(NoisePreset::Paper, 4);
    let quiet = pitch_until_mismatch(&mut run, 120.0);
    assert!(quiet.is_none(), "false alarm {quiet:?}");
    run.rotate_top();
    // Measured 79.9 s: 30 s windows (the honest standard errors keep the bound above
    // `window_rel_err` until the limit), and the change must show in two of them.
    let (t, why) = pitch_until_mismatch(&mut run, 120.0).expect("rotation not found");
    println!("found after {t:.1} s: {why}");
    assert!(why.contains("thruster 1"), "{why}");
}

/// Holding through the soak's manoeuvres (pitch 0 / 10 deg every 20 s) at 1 kHz and the
/// paper's noise, with the shipped settings (monitor and change test included): nothing
/// changed, so nothing may be reported. This is where one window deciding failed (see the
/// module docs). The knobs of the runs in docs/experiments.md are the lab's `khz_sweep`'s.
#[test]
fn at_1_khz_and_the_papers_noise_an_unchanged_vehicle_raises_no_alarm_in_three_minutes() {
    for seed in [1, 2, 3] {
        let windows = khz_hold(seed, KhzSettings::default());
        // The refinement judged the whole time (a window every 5-30 s), it did not sleep.
        assert!(windows >= 6, "seed {seed}: only {windows} windows in 180 s");
    }
}

/// The same hold on a first model learned to a 4 % target (`estimator.target_rel_err` 0.04, a
/// documented key): the run goes on to 5.4-8.2 vehicle-s, and the model's damping, restoring
/// and Coriolis terms come out with smaller standard errors, though at this noise they are
/// still noise and bias. With `refinement.change_term_z` at 4 enough of them passed into the
/// change test's prediction that seeds 4 and 5 raised false alarms on the unchanged vehicle
/// (thrusters 4 and 3, "moved" 76 % and 40 %, at 50.5 and 96.1 s; 2 of seeds 1-12); at 8
/// none did (`KHZ_TARGET=0.04 KHZ_SEEDS=S ... study sweep khz_sweep`; docs/study.md, "The
/// change test's terms").
#[test]
fn at_1_khz_and_the_papers_noise_a_model_learned_longer_raises_no_alarm() {
    for seed in [4, 5] {
        let windows = khz_hold(
            seed,
            KhzSettings {
                target_rel_err: Some(0.04),
                ..KhzSettings::default()
            },
        );
        assert!(windows >= 6, "seed {seed}: only {windows} windows in 180 s");
    }
}

/// The per-sample change test (`refinement::change_test`, on by default) through the
/// machine, noise-free: quiet while nothing changes (a minute, with the refinement's model
/// updates installed meanwhile), and the rotated top thruster found within seconds.
///
/// Where the rotation falls in the refinement's 5 s windows decides who finds it: a window
/// that ends after it with its move still under `min_change` folds the move in, and the new
/// model version restarts the test's warm-up (5 s), so the next window finds it. Rotated
/// after 60-64 s of quiet, measured: 3.28 (change test), 5.32 (window), 6.30, 5.30, 4.30 s
/// (change test), naming thruster 1 every time; with the first model fitted to the thrust's
/// shape the window after the 60 s rotation folds its move in and finds it at 6.32 s, the
/// others the same. One thruster at a time the test named thruster 2, LB, which takes up the
/// new roll moment in closed loop (the joint fit names 1).
#[test]
fn noise_free_the_change_test_is_quiet_then_finds_a_rotated_thruster_within_seconds() {
    let mut by_the_test = 0;
    for quiet_s in [60.0, 61.0, 62.0, 63.0, 64.0] {
        let mut run = holding_with(NoisePreset::None, 1, shipped_change_test());
        let quiet = level_until_mismatch(&mut run, quiet_s);
        assert!(quiet.is_none(), "false alarm {quiet:?}");
        run.rotate_top();
        let (t, why) = level_until_mismatch(&mut run, 10.0).expect("rotation not found");
        println!("rotated after {quiet_s} s, found after {t:.2} s: {why}");
        assert!(t < 6.5, "{t:.2} s: {why}");
        assert!(why.contains("thruster 1"), "{why}");
        by_the_test += usize::from(why.contains("change test"));
        assert_eq!(run.machine.state(), State::Identify);
    }
    assert!(by_the_test >= 3, "the change test found {by_the_test} of 5");
}

/// The two false alarms the change test raised over every vehicle file (seeds 1-6, 10 minutes
/// each), flown again up to just past the moment each came: on four_up, whose four thrusters
/// the controller commands together, a one-at-a-time move of 50 % was "jointly" 463 columns of
/// another thruster (after 39 s of pitch steps, realistic IMU, seed 4; now capped at 3 columns);
/// on aligned the learned model's terms, counted from 3 standard errors, "moved" thruster 2 by
/// 47 % (after 134 s, seed 1; now from 4). Both unchanged vehicles must stay quiet.
#[test]
fn thrusters_commanded_together_and_weak_terms_are_not_a_change() {
    for (vehicle, seed, seconds) in [("four_up", 4, 50.0), ("aligned", 1, 145.0)] {
        let mut run = holding_on(vehicle, NoisePreset::Realistic, seed, shipped_change_test());
        let alarm = pitch_until_mismatch(&mut run, seconds);
        assert!(
            alarm.is_none(),
            "{vehicle}, seed {seed}, unchanged: {alarm:?}"
        );
    }
}

/// A model learned with `estimator.shaped_thrust` has B as the mean of each thruster's
/// forward and reverse gain, to be multiplied by the commands' thrust shape (u (1 + k)
/// forward, u (1 - k) reverse); the change test predicts with it. Predicted from the bare
/// commands instead, each thruster's forward surplus was a "change": aligned at a realistic
/// IMU, seed 1, "thruster 1 moved 40 %" (chi-square 40) after 40.3 s of pitch steps; AMOUR-5
/// at the paper's noise, seed 3, "thruster 4 moved 66 %" (chi-square 20) while holding level.
/// Measured with the shaping: quiet through both, and AMOUR-5's top thruster rotated after
/// that found in the time and by the name a bare model's test asks. (four_up is not quiet with a shaped model:
/// docs/study.md, "The thrust's shape in the one column".)
#[test]
fn a_shaped_model_is_predicted_from_the_commands_thrust_shape() {
    let shaped = |e: &mut thrusterd_core::estimator::EstimatorConfig| e.shaped_thrust = true;
    let mut run = thruster_inprocess::holding::holding_on_learned_with(
        "aligned",
        NoisePreset::Realistic,
        1,
        shipped_change_test(),
        &shaped,
    );
    let k = run
        .machine
        .model()
        .and_then(|m| m.dynamics.as_ref())
        .map(|d| d.thrust_asymmetry);
    assert!(k.is_some_and(|k| k > 0.1), "the model carries k: {k:?}");
    let alarm = pitch_until_mismatch(&mut run, 60.0);
    assert!(alarm.is_none(), "aligned, shaped: {alarm:?}");
    let mut run = thruster_inprocess::holding::holding_on_learned_with(
        "amour5",
        NoisePreset::Paper,
        3,
        shipped_change_test(),
        &shaped,
    );
    let quiet = level_until_mismatch(&mut run, 120.0);
    assert!(quiet.is_none(), "amour5, shaped: {quiet:?}");
    // And a real change is still found, as with a bare model (`at_the_papers_noise_...`).
    run.rotate_top();
    let found = level_until_mismatch(&mut run, 30.0);
    println!("amour5, shaped, top thruster rotated: found after {found:?}");
    let (t, why) = found.expect("the rotation found");
    assert!(t < 8.0 && why.contains("thruster 1:"), "{t:.2} s: {why}");
}

/// Issue 12's target is a silent hot swap detected at the paper's noise within 5 s. Holding
/// level with the learned model and the shipped settings (0.1 dither), the change test on,
/// after two quiet minutes, seeds 1-10. Measured (`cargo test -p thrusterd-core --test
/// refinement -- --nocapture at_the_papers_noise_the_change_test`): 3.7, 5.4, 4.0, 2.5, 3.9,
/// 4.1, 3.0, 2.7, 5.3, 5.2 s (mean 4.0 s; 3 of 10 seeds miss the 5 s target), all naming
/// thruster 1. Bounds at 1.5x: 8.0 s on every seed, 6.0 s on the mean. (Before the rows, the
/// significant terms and the joint fit, seeds 1-5: 6.4, 6.4, 2.6, 3.7, 6.1 s, mean 5.0 s. The
/// windows alone took 74 s here.)
#[test]
fn at_the_papers_noise_the_change_test_finds_a_rotated_thruster_within_seconds() {
    let seeds: Vec<u64> = (1..=10).collect();
    let mut results = Vec::new();
    for &seed in &seeds {
        let mut run = holding_with(NoisePreset::Paper, seed, shipped_change_test());
        let quiet = level_until_mismatch(&mut run, 120.0);
        assert!(quiet.is_none(), "seed {seed}: false alarm {quiet:?}");
        run.rotate_top();
        let found = level_until_mismatch(&mut run, 30.0);
        println!("seed {seed}: found after {found:?}");
        results.push((seed, found));
    }
    let mut sum = 0.0;
    for (seed, found) in &results {
        let (t, why) = found
            .as_ref()
            .unwrap_or_else(|| panic!("seed {seed}: rotation not found"));
        assert!(*t < 8.0, "seed {seed}: {t:.2} s: {why}");
        assert!(why.contains("change test"), "seed {seed}: {why}");
        // The joint fit names the turned thruster (one thruster at a time, the controller's
        // answer to it made thruster 5 look moved in 4 of 5 seeds of `detection_bound`).
        assert!(why.contains("thruster 1:"), "seed {seed}: {why}");
        sum += t;
    }
    let mean = sum / results.len() as f64;
    assert!(mean < 6.0, "mean {mean:.2} s: {results:?}");
}

/// The false-alarm check CI runs, a short version of the lab's sweeps `change_test_soak` and
/// `change_test_on_every_vehicle` (`thrusterctl study sweep NAME`; config/thrusterd.toml's "no
/// false alarm" rests on the long ones; docs/research-log.md quotes their figures and commands): with the shipped settings
/// (no environment variable read), an unchanged vehicle flown through pitch steps (+-20 deg
/// every 4 s) and then as long holding level raises no mismatch, and the refinement judged
/// meanwhile (a window ended). AMOUR-5 at the paper's noise, seeds 1-5, 2 + 2 minutes each.
/// Measured: quiet; 13 s of a debug build (`time cargo test -p thrusterd-core --test
/// refinement short_soak`).
#[test]
fn change_test_short_soak_raises_no_false_alarm() {
    for seed in 1..=5 {
        let mut run = holding_with(NoisePreset::Paper, seed, shipped_change_test());
        let (pitch, level) = quiet_flight(&mut run, 120.0);
        assert!(
            pitch.is_none() && level.is_none(),
            "seed {seed}: false alarm: pitch steps {pitch:?}, level {level:?}"
        );
        assert!(
            run.machine.refinement().is_some(),
            "seed {seed}: no window ended"
        );
    }
}

/// The same on every vehicle file at every noise preset (none, realistic, paper), seed 1, 1 +
/// 1 minutes each: the short version of [`change_test_on_every_vehicle`]. Measured: quiet;
/// about 20 s of a debug build (`time cargo test -p thrusterd-core --test refinement
/// every_vehicle_short`).
#[test]
fn change_test_on_every_vehicle_short_raises_no_false_alarm() {
    let mut alarms = Vec::new();
    for vehicle in common::VEHICLES {
        for noise in [
            NoisePreset::None,
            NoisePreset::Realistic,
            NoisePreset::Paper,
        ] {
            let mut run = holding_on(vehicle, noise, 1, shipped_change_test());
            let (pitch, level) = quiet_flight(&mut run, 60.0);
            println!("{vehicle} {noise:?}: pitch steps {pitch:?}, level {level:?}");
            if pitch.is_some() || level.is_some() {
                alarms.push((vehicle, noise, pitch, level));
            }
            assert!(
                run.machine.refinement().is_some(),
                "{vehicle} {noise:?}: no window ended"
            );
        }
    }
    assert!(alarms.is_empty(), "false alarms: {alarms:#?}");
}

/// A swell is not a moved thruster (issue 32 item 5). AMOUR-5 learns in still water at a
/// realistic IMU, then the water comes up (moderate: 0.3 m/s current, 10 N / 1 Nm at 0.15 Hz)
/// and it flies +-20 deg pitch steps. Uncalibrated (`change_calibration_s = 0`), the change
/// test takes the controller's answer to the waves for a moved thruster within a minute
/// (measured 29.7-33.7 s on seeds 1-3, 10 of 10 seeds in 10-minute soaks); as shipped,
/// calibrated against the water once the sea-state gauge says the vehicle is in a sea
/// (`change_calibrate_when = "in_a_sea"`), none in 3 minutes, and the rotated top thruster is
/// still found in the swell (by the windows: measured 6.4-7.6 s on seeds 1-10). `cargo test -p
/// thrusterd-core --test refinement -- --nocapture swell`.
#[test]
fn in_a_swell_the_calibrated_change_test_is_quiet_and_still_finds_a_rotated_thruster() {
    use thruster_sim::disturbance::WaterPreset;
    let seed = 1;
    let in_the_swell = |cfg| {
        let mut run = holding_with(NoisePreset::Realistic, seed, cfg);
        run.sim
            .set_disturbance(WaterPreset::Moderate.disturbance())
            .unwrap();
        run
    };
    let calibrated = shipped_change_test();
    assert_eq!(
        calibrated.change_calibration_s, 120.0,
        "the shipped default"
    );
    assert_eq!(
        calibrated.change_calibrate_when,
        thrusterd_core::adaptation::calibrate_when::CalibrateWhen::InASea,
        "the shipped default"
    );
    let uncalibrated = thrusterd_core::adaptation::refinement::RefinementConfig {
        change_calibration_s: 0.0,
        ..shipped_change_test()
    };
    let (t, why) = pitch_until_mismatch(&mut in_the_swell(uncalibrated), 60.0)
        .expect("uncalibrated: no false alarm in the swell (the decisive run is gone)");
    println!("uncalibrated: a false alarm after {t:.1} s: {why}");
    assert!(why.contains("change test"), "{why}");

    let mut run = in_the_swell(calibrated);
    let quiet = pitch_until_mismatch(&mut run, 180.0);
    assert!(quiet.is_none(), "calibrated: false alarm {quiet:?}");
    run.rotate_top();
    let (t, why) = level_until_mismatch(&mut run, 30.0).expect("rotation not found");
    println!("calibrated: the rotated top thruster found after {t:.1} s: {why}");
    assert!(t < 12.0, "{t:.1} s: {why}");
    assert!(why.contains("thruster 1"), "{why}");
}
