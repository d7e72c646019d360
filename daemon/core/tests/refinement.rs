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
use common::Run;
use nalgebra::UnitQuaternion;
use thruster_sim::disturbance::WaterPreset;
use thruster_sim::NoisePreset;
use thrusterd_core::adaptation::monitor::MismatchAction;
use thrusterd_core::adaptation::refinement::RefinementConfig;
use thrusterd_core::machine::{Event, Machine, MachineSetup, State};

fn holding(noise: NoisePreset, seed: u64) -> Run {
    holding_with(noise, seed, RefinementConfig::default())
}

/// [`holding`] with the refinement's settings replaced.
fn holding_with(noise: NoisePreset, seed: u64, refinement: RefinementConfig) -> Run {
    holding_on("amour5", noise, seed, refinement)
}

/// [`holding_with`] on another vehicle file.
fn holding_on(vehicle: &str, noise: NoisePreset, seed: u64, refinement: RefinementConfig) -> Run {
    holding_on_prior(vehicle, noise, seed, refinement, None)
}

/// [`holding_on`] with the estimator's terms prior (`term_prior_sd`, default off) replaced:
/// for `detection_bound`'s decisive runs (`DB_TERM_PRIOR`); no asserting test sets it.
fn holding_on_prior(
    vehicle: &str,
    noise: NoisePreset,
    seed: u64,
    refinement: RefinementConfig,
    term_prior_sd: Option<f64>,
) -> Run {
    let mut run = Run::new(vehicle, noise, seed);
    let mut setup = MachineSetup {
        thrusters: run.sim.thruster_count(),
        refinement,
        ..MachineSetup::default()
    };
    setup.machine.deadband = 0.05;
    if let Some(v) = term_prior_sd {
        setup.estimator.term_prior_sd = v;
    }
    // The monitor's own test never fires (infinite threshold); its action still decides what
    // a mismatch does: re-estimate.
    setup.monitor.action = MismatchAction::Estimate;
    setup.monitor.z = f64::INFINITY;
    run.machine = Machine::new(setup);
    run.run_for(1.0);
    run.estimate();
    run.machine.take_events();
    run
}

/// Pitch steps of +-20 deg every 4 s for `seconds`; the first mismatch's time, if any.
fn pitch_until_mismatch(run: &mut Run, seconds: f64) -> Option<(f64, String)> {
    pitch_scored(run, seconds).0
}

/// [`pitch_until_mismatch`], and the mean angle between the true attitude and the setpoint
/// over the samples flown, deg.
fn pitch_scored(run: &mut Run, seconds: f64) -> (Option<(f64, String)>, f64) {
    let (mut sum, mut k) = (0.0, 0u64);
    let found = pitch_with(run, seconds, |sp, run| {
        sum += run.sim.attitude().angle_to(sp).to_degrees();
        k += 1;
    });
    (found, sum / k.max(1) as f64)
}

fn pitch_with(
    run: &mut Run,
    seconds: f64,
    mut each: impl FnMut(&UnitQuaternion<f64>, &Run),
) -> Option<(f64, String)> {
    let yaw = run.sim.roll_pitch_yaw()[2];
    let depth = run.sim.position_ned().z;
    let start = run.sim.time_s();
    let mut step = 0;
    let mut sp = UnitQuaternion::identity();
    while run.sim.time_s() - start < seconds {
        let t = run.sim.time_s() - start;
        if t >= 4.0 * step as f64 {
            let p: f64 = [20.0, -20.0][step % 2];
            sp = UnitQuaternion::from_euler_angles(0.0, p.to_radians(), yaw);
            run.machine.on_setpoint(sp, Some(depth));
            step += 1;
        }
        run.tick();
        each(&sp, run);
        for e in run.machine.take_events() {
            if let Event::MismatchDetected(why) = e {
                return Some((t, why));
            }
        }
        assert_eq!(
            run.machine.state(),
            State::Active,
            "left control at {t:.1} s"
        );
    }
    None
}

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
/// module docs). The knobs of the runs in docs/experiments.md are `khz_sweep`'s.
#[test]
fn at_1_khz_and_the_papers_noise_an_unchanged_vehicle_raises_no_alarm_in_three_minutes() {
    for seed in [1, 2, 3] {
        let windows = khz_hold(seed, KhzSettings::default());
        // The refinement judged the whole time (a window every 5-30 s), it did not sleep.
        assert!(windows >= 6, "seed {seed}: only {windows} windows in 180 s");
    }
}

/// What `khz_hold` varies; the default is the shipped setup.
struct KhzSettings {
    seconds: f64,
    /// The deadband the machine compensates (0.05: the T200's, as thruster-sim's driver does
    /// in the daemon's setup). With 0 the model is linear where the thrust is not, and the
    /// change test took that for a yaw thruster's change after 13 s (seed 1).
    deadband: f64,
    change_test: bool,
    latency_us: Option<(u64, u64)>,
}

impl Default for KhzSettings {
    fn default() -> Self {
        KhzSettings {
            seconds: 180.0,
            deadband: 0.05,
            change_test: true,
            latency_us: None,
        }
    }
}

/// Estimates at 1 kHz and the paper's noise, then holds through pitch 0 / 10 deg steps every
/// 20 s for `seconds`; panics on any mismatch reported or on leaving Active. The number of
/// refinement windows judged.
fn khz_hold(seed: u64, k: KhzSettings) -> usize {
    let mut run = Run::with_rate("amour5", NoisePreset::Paper, seed, 1000.0);
    run.latency_us = k.latency_us;
    let mut setup = MachineSetup {
        thrusters: 5,
        ..MachineSetup::default()
    };
    // No driver in between: the machine compensates the deadband itself.
    setup.machine.deadband = k.deadband;
    setup.refinement.change_test = k.change_test;
    run.machine = Machine::new(setup);
    run.run_for(1.0);
    run.estimate();
    run.machine.take_events();
    let yaw = run.sim.roll_pitch_yaw()[2];
    let depth = run.sim.position_ned().z;
    let start = run.sim.time_s();
    let mut step = 0;
    let mut windows = 0;
    while run.sim.time_s() - start < k.seconds {
        let t = run.sim.time_s() - start;
        if t >= 20.0 * step as f64 {
            let p: f64 = [10.0, 0.0][step % 2];
            run.machine.on_setpoint(
                UnitQuaternion::from_euler_angles(0.0, p.to_radians(), yaw),
                Some(depth),
            );
            step += 1;
        }
        let before = run.machine.refinement().copied();
        run.tick();
        if run.machine.refinement().copied() != before {
            windows += 1;
        }
        for e in run.machine.take_events() {
            assert!(
                !matches!(e, Event::MismatchDetected(_)),
                "seed {seed}: false alarm at {t:.1} s: {e:?}"
            );
        }
        assert_eq!(
            run.machine.state(),
            State::Active,
            "seed {seed} at {t:.1} s"
        );
    }
    windows
}

/// The 1 kHz hold with knobs, for the change test's runs in docs/experiments.md: KHZ_SEEDS
/// (comma list, default 1,2,3), KHZ_SECONDS (180), KHZ_DEADBAND (0.05), KHZ_CHANGE_TEST=0
/// (turn it off), RUN_LATENCY_US (`A` or `A-B`: the command takes effect that long after its
/// sample, as through the driver in real time). A measuring tool; run with
/// `cargo test --release -p thrusterd-core --test refinement -- --ignored khz_sweep --nocapture`.
#[test]
#[ignore = "measuring tool driven by KHZ_* and RUN_LATENCY_US variables"]
fn khz_sweep() {
    let seeds: Vec<u64> = std::env::var("KHZ_SEEDS").map_or(vec![1, 2, 3], |v| {
        v.split(',').map(|x| x.trim().parse().unwrap()).collect()
    });
    let latency_us = std::env::var("RUN_LATENCY_US")
        .ok()
        .map(|v| match v.split_once('-') {
            Some((a, b)) => (a.parse().unwrap(), b.parse().unwrap()),
            None => (v.parse().unwrap(), v.parse().unwrap()),
        });
    for seed in seeds {
        let k = KhzSettings {
            seconds: std::env::var("KHZ_SECONDS").map_or(180.0, |v| v.parse().unwrap()),
            deadband: std::env::var("KHZ_DEADBAND").map_or(0.05, |v| v.parse().unwrap()),
            change_test: std::env::var("KHZ_CHANGE_TEST").map_or(true, |v| v != "0"),
            latency_us,
        };
        let windows = khz_hold(seed, k);
        println!("seed {seed}: no alarm, {windows} refinement windows");
    }
}

/// The refinement's dither against detection and hold at a given noise: for each seed, 120 s
/// of pitch steps on the unchanged vehicle (a false alarm ends it), then the top thruster
/// rotated and up to 120 s more. Prints the first alarm, the detection time and the mean
/// angle from the setpoint. A measuring tool; knobs RF_NOISE (paper, realistic), RF_SEEDS
/// (comma list), RF_DITHER (comma list). Run with
/// `cargo test --release -p thrusterd-core --test refinement -- --ignored dither_sweep --nocapture`.
#[test]
#[ignore = "measuring tool driven by RF_* variables"]
fn dither_sweep() {
    let noise = match std::env::var("RF_NOISE").as_deref() {
        Ok("realistic") => NoisePreset::Realistic,
        _ => NoisePreset::Paper,
    };
    let list = |key: &str, default: &str| -> Vec<f64> {
        std::env::var(key)
            .unwrap_or_else(|_| default.into())
            .split(',')
            .map(|v| v.trim().parse().unwrap_or_else(|_| panic!("{key}: {v}")))
            .collect()
    };
    for dither in list("RF_DITHER", "0.1") {
        let (mut found_sum, mut found_n, mut alarms, mut err_sum) = (0.0, 0, 0, 0.0);
        let seeds = list("RF_SEEDS", "1,2,3,4");
        for &seed in &seeds {
            let cfg = RefinementConfig {
                dither,
                ..RefinementConfig::default()
            };
            let term_prior = std::env::var("DB_TERM_PRIOR")
                .ok()
                .map(|v| v.parse().expect("DB_TERM_PRIOR"));
            let mut run = holding_on_prior("amour5", noise, seed as u64, cfg, term_prior);
            let (quiet, err) = pitch_scored(&mut run, 120.0);
            err_sum += err;
            let found = if quiet.is_none() {
                run.rotate_top();
                pitch_until_mismatch(&mut run, 120.0)
            } else {
                alarms += 1;
                None
            };
            if let Some((t, _)) = &found {
                found_sum += t;
                found_n += 1;
            }
            println!(
                "dither {dither} seed {seed}: false alarm {:?}, found after {:?}, mean error {err:.2} deg",
                quiet.map(|q| q.0),
                found.map(|f| f.0)
            );
        }
        println!(
            "dither {dither}: {alarms} false alarms in {} x 120 s, found in {found_n} (mean {:.1} s), mean error {:.2} deg",
            seeds.len(),
            found_sum / found_n.max(1) as f64,
            err_sum / seeds.len() as f64
        );
    }
}

/// Hold level at the current heading and depth for `seconds`; the first mismatch's time (s
/// from the start of this call) and text, if any.
fn level_until_mismatch(run: &mut Run, seconds: f64) -> Option<(f64, String)> {
    level_with(run, seconds, |_| {})
}

/// [`level_until_mismatch`], calling `each` after every sample.
fn level_with(run: &mut Run, seconds: f64, mut each: impl FnMut(&Run)) -> Option<(f64, String)> {
    let yaw = run.sim.roll_pitch_yaw()[2];
    let depth = run.sim.position_ned().z;
    run.machine.on_setpoint(
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
        Some(depth),
    );
    let start = run.sim.time_s();
    while run.sim.time_s() - start < seconds {
        run.tick();
        each(run);
        let t = run.sim.time_s() - start;
        for e in run.machine.take_events() {
            if let Event::MismatchDetected(why) = e {
                return Some((t, why));
            }
        }
        assert_eq!(
            run.machine.state(),
            State::Active,
            "left control at {t:.1} s"
        );
    }
    None
}

/// The false-alarm flight of the soaks: `seconds` of pitch steps, then (if nothing was
/// reported) as long holding level; the mismatch of each part, if any.
type Mismatch = Option<(f64, String)>;
fn quiet_flight(run: &mut Run, seconds: f64) -> (Mismatch, Mismatch) {
    let pitch = pitch_until_mismatch(run, seconds);
    let level = if pitch.is_none() {
        level_until_mismatch(run, seconds)
    } else {
        None
    };
    (pitch, level)
}

/// The shipped refinement settings (the per-sample change test on, as by default: see
/// `RefinementConfig::change_test`). What the asserting tests use: no environment variable
/// changes it.
fn shipped_change_test() -> RefinementConfig {
    let c = RefinementConfig::default();
    assert!(c.change_test, "the change test is on by default");
    c
}

/// [`shipped_change_test`] with the measuring runs' overrides from the environment (the
/// ignored measuring tools only).
fn with_change_test() -> RefinementConfig {
    let mut c = shipped_change_test();
    if let Ok(v) = std::env::var("CT_UPDATE") {
        c.update = v == "1";
    }
    // Overrides for the measuring runs: (variable, the setting it replaces).
    for (key, field) in [
        ("CT_FLOOR", &mut c.change_model_floor),
        ("CT_SHARE", &mut c.change_min_share),
        ("CT_NOISE_S", &mut c.change_noise_s),
        ("CT_TAU", &mut c.change_tau_s),
        ("CT_CHI2", &mut c.change_chi2),
        ("CT_TERM_Z", &mut c.change_term_z),
        ("CT_WARMUP", &mut c.change_warmup_s),
        ("CT_MAX_ERROR", &mut c.change_max_error_deg),
    ] {
        if let Ok(v) = std::env::var(key) {
            *field = v.parse().unwrap_or_else(|_| panic!("{key}: {v}"));
        }
    }
    c
}

/// The per-sample change test (`refinement::change_test`, on by default) through the
/// machine, noise-free: quiet while nothing changes (a minute, with the refinement's model
/// updates installed meanwhile), and the rotated top thruster found within seconds.
#[test]
fn noise_free_the_change_test_is_quiet_then_finds_a_rotated_thruster_within_seconds() {
    let mut run = holding_with(NoisePreset::None, 1, shipped_change_test());
    let quiet = level_until_mismatch(&mut run, 60.0);
    assert!(quiet.is_none(), "false alarm {quiet:?}");
    run.rotate_top();
    let (t, why) = level_until_mismatch(&mut run, 10.0).expect("rotation not found");
    println!("found after {t:.2} s: {why}");
    // Measured 3.78 s, naming thruster 1 (the joint fit; one thruster at a time it named
    // thruster 2, LB, which takes up the new roll moment in closed loop): a candidate is judged
    // once it is `change_min_age_s` (2 s) old; at 1 s it was found after 2.53 s.
    assert!(t < 4.5, "{t:.2} s: {why}");
    assert!(why.contains("thruster 1"), "{why}");
    assert!(why.contains("change test"), "{why}");
    assert_eq!(run.machine.state(), State::Identify);
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

/// The false-alarm check CI runs, a short version of [`change_test_soak`] and
/// [`change_test_on_every_vehicle`] (config/thrusterd.toml's "no false alarm" rests on the long
/// ones; docs/experiments.md quotes their figures and commands): with the shipped settings
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

/// The false-alarm soak for the change test: `CT_MINUTES` (default 10) through pitch steps
/// (+-20 deg every 4 s), then as long again holding level, on an unchanged vehicle at the
/// paper's noise with the shipped settings and the change test on, seeds `CT_SEEDS` (default
/// 1-5; CT_NOISE realistic or none for another IMU; CT_WATER a water preset that comes up
/// after the estimation); no mismatch may be reported. Then the
/// top thruster rotated while holding level: prints the detection time. A measuring tool (minutes of vehicle
/// time per seed): `cargo test --release -p thrusterd-core --test refinement -- --ignored
/// change_test_soak --nocapture`.
#[test]
#[ignore = "measuring tool: 20 vehicle-minutes per seed; CI runs change_test_short_soak_raises_no_false_alarm"]
fn change_test_soak() {
    let minutes: f64 = std::env::var("CT_MINUTES").map_or(10.0, |v| v.parse().unwrap());
    let seeds: Vec<u64> = std::env::var("CT_SEEDS")
        .unwrap_or_else(|_| "1,2,3,4,5".into())
        .split(',')
        .map(|v| v.trim().parse().unwrap())
        .collect();
    let mut alarms = Vec::new();
    for seed in seeds {
        let noise = match std::env::var("CT_NOISE").as_deref() {
            Ok("realistic") => NoisePreset::Realistic,
            Ok("none") => NoisePreset::None,
            _ => NoisePreset::Paper,
        };
        let mut run = holding_with(noise, seed, with_change_test());
        // CT_WATER (current|moderate|rough): the model learned in still water, then the water
        // comes up (issue 32 item 5: a swell is not a moved thruster).
        let water = match std::env::var("CT_WATER").as_deref() {
            Ok("current") => Some(WaterPreset::Current),
            Ok("moderate") => Some(WaterPreset::Moderate),
            Ok("rough") => Some(WaterPreset::Rough),
            _ => None,
        };
        if let Some(w) = water {
            run.sim.set_disturbance(w.disturbance()).unwrap();
        }
        let (pitch, level) = quiet_flight(&mut run, minutes * 60.0);
        println!("seed {seed}: pitch steps {pitch:?}, level {level:?}");
        if level.is_some() || pitch.is_some() {
            alarms.push((seed, level, pitch));
            continue;
        }
        run.rotate_top();
        let mut tilt = 0.0f64;
        let mut track = |run: &Run| {
            let down = run.machine.attitude().inverse() * nalgebra::Vector3::z();
            tilt = tilt.max(down.z.clamp(-1.0, 1.0).acos().to_degrees());
        };
        // CT_AFTER: the flight after the change, pitch steps (the hot-swap experiment's) or
        // level (default).
        let after = std::env::var("CT_AFTER").unwrap_or_else(|_| "level".into());
        let found = if after == "pitch" {
            pitch_with(&mut run, 60.0, |_, run| track(run))
        } else {
            level_with(&mut run, 60.0, &mut track)
        };
        println!(
            "seed {seed}: rotated top thruster found ({after}) after {found:?}; largest tilt (filter) {tilt:.1} deg"
        );
    }
    assert!(alarms.is_empty(), "false alarms: {alarms:?}");
}

/// The change test (`with_change_test`) on every vehicle file: `CT_MINUTES` (default 5) of pitch
/// steps (+-20 deg every 4 s) then as long holding level, unchanged, at each noise of
/// `CT_NOISES` (default none,realistic,paper), seeds `CT_SEEDS` (default 1; CT_VEHICLES a
/// subset, CT_CHANGE_TEST=0 the windows alone); prints every
/// mismatch reported (a false alarm) and fails on any. A measuring tool: `cargo test --release
/// -p thrusterd-core --test refinement -- --ignored change_test_on_every_vehicle --nocapture`.
#[test]
#[ignore = "measuring tool: 10 vehicle-minutes per vehicle and noise; CI runs change_test_on_every_vehicle_short_raises_no_false_alarm"]
fn change_test_on_every_vehicle() {
    let minutes: f64 = std::env::var("CT_MINUTES").map_or(5.0, |v| v.parse().unwrap());
    let list = |key: &str, default: &str| -> Vec<String> {
        std::env::var(key)
            .unwrap_or_else(|_| default.into())
            .split(',')
            .map(|v| v.trim().to_string())
            .collect()
    };
    let mut alarms = Vec::new();
    for vehicle in list("CT_VEHICLES", &common::VEHICLES.join(",")) {
        for noise in list("CT_NOISES", "none,realistic,paper") {
            let preset = match noise.as_str() {
                "none" => NoisePreset::None,
                "realistic" => NoisePreset::Realistic,
                _ => NoisePreset::Paper,
            };
            for seed in list("CT_SEEDS", "1") {
                let seed: u64 = seed.parse().unwrap();
                // CT_CHANGE_TEST=0: the windows alone (is an alarm the change test's?).
                let cfg = RefinementConfig {
                    change_test: std::env::var("CT_CHANGE_TEST").map_or(true, |v| v != "0"),
                    ..with_change_test()
                };
                let mut run = holding_on(&vehicle, preset, seed, cfg);
                let (pitch, level) = quiet_flight(&mut run, minutes * 60.0);
                println!("{vehicle} {noise} seed {seed}: pitch steps {pitch:?}, level {level:?}");
                if pitch.is_some() || level.is_some() {
                    alarms.push((vehicle.clone(), noise.clone(), seed, pitch, level));
                }
            }
        }
    }
    assert!(alarms.is_empty(), "false alarms: {alarms:#?}");
}

/// The best detection time any detector could reach, measured: a generalized-likelihood-ratio
/// (GLR) change test per thruster column on the gyro's innovations (see [`bound`]), run beside
/// the machine on the same flight, with two predictors of the motion from the commands sent:
/// ORACLE (the simulator's true rigid body and thrusters, the geometry before the change) and
/// LEARNED (the model the machine learned and controls with: B and its damping, restoring and
/// Coriolis terms). The machine's own refinement only adds its dither here (its change test
/// and its model updates are off, so the model in force stays the learned one).
///
/// For each seed and dither: `DB_BEFORE` s unchanged (the largest statistic seen is the false
/// alarm figure), the top thruster rotated, `DB_AFTER` s more; the detection time for each
/// threshold of `DB_THRESH` is the first time a thruster's statistic passes it (and whether
/// that thruster is the rotated one). Knobs: DB_NOISE (none, realistic, paper), DB_SEEDS,
/// DB_DITHER (comma lists), DB_MANOEUVRE (level: hold level; pitch: +-20 deg every 4 s),
/// DB_TAU_ORACLE / DB_TAU_LEARNED (observer time constants, s; defaults 0.5 / 0.2),
/// DB_HORIZON (s of candidate change times), DB_SPACING (s between them), DB_THRESH,
/// DB_BEFORE / DB_AFTER (s), DB_SIGMA_FLOOR (least noise assumed, rad/s; 0.01 makes the
/// noise-free run readable), DB_REFERENCE (s: test the window against the recent past
/// instead of against the model), DB_MODEL_FLOOR (the module's `change_model_floor`),
/// DB_TERM_PRIOR (the estimator's `term_prior_sd` for the learned model),
/// DB_LEARNED_TRUE_VEL (the simulator's body velocity in the learned model's terms),
/// DB_LEARNED_B_TRUE (the learned predictor with the simulator's true B instead of the
/// learned one: is it B or the other terms?), DB_LEARNED_SKIP (indices of the learned terms
/// left out, e.g. `14,36`), DB_AXES (the rows the three GLRs judge, e.g. `0,2`), the module's
/// DB_MIN_SHARE / DB_CHI2 / DB_WARMUP / DB_MAX_TILT and DB_MODULE_ALWAYS (judged whatever the error from
/// the setpoint; its first verdicts before and after the change are printed), DB_DEBUG
/// (print the learned and true B and terms; the learned innovation's mean). Run with
/// `cargo test --release -p thrusterd-core --test refinement -- --ignored detection_bound --nocapture`.
///
/// Measured (paper noise, hold level, 10 min unchanged, seeds 1-10; the threshold the next of
/// 30, 40, 50, 60, 70, 80, 100, 120 above the largest unchanged statistic; detection by any
/// thruster, mean / worst): oracle (true state) 0.74 / 0.87, 0.81 / 1.01, 0.72 / 0.92,
/// 0.59 / 0.84 s at dither 0 / 0.1 / 0.2 / 0.3 (largest unchanged 32-33); learned 2.6 / 5.7
/// (2 of 10 never within 30 s), 3.5 / 4.9, 3.5 / 4.5, 2.5 / 3.2 s (largest unchanged 39, 51,
/// 80, 119). The oracle with the attitude filter's attitude and tau 2 s reached 100-400 on
/// the unchanged vehicle: the filter's error, which the controller acts on, correlates with
/// the commands; a short tau removes it. Through pitch steps the learned statistic reaches
/// 800-2100 unchanged.
#[test]
#[ignore = "measuring tool driven by DB_* variables"]
fn detection_bound() {
    use bound::*;
    let env = |key: &str, default: &str| std::env::var(key).unwrap_or_else(|_| default.into());
    let list = |key: &str, default: &str| -> Vec<f64> {
        env(key, default)
            .split(',')
            .map(|v| v.trim().parse().unwrap_or_else(|_| panic!("{key}: {v}")))
            .collect()
    };
    let noise = match env("DB_NOISE", "paper").as_str() {
        "none" => NoisePreset::None,
        "realistic" => NoisePreset::Realistic,
        _ => NoisePreset::Paper,
    };
    let pitch = env("DB_MANOEUVRE", "level") == "pitch";
    let before_s = list("DB_BEFORE", "60")[0];
    let after_s = list("DB_AFTER", "30")[0];
    let tau = [
        list("DB_TAU_ORACLE", "0.5")[0],
        list("DB_TAU_ORACLE", "0.5")[0],
        list("DB_TAU_LEARNED", "0.2")[0],
    ];
    let horizon = list("DB_HORIZON", "10")[0];
    let spacing = list("DB_SPACING", "0.25")[0];
    let thresholds = list("DB_THRESH", "20,30,40,50,60,80");
    println!(
        "noise {noise:?}, manoeuvre {}, before {before_s} s, after {after_s} s, tau {tau:?}, horizon {horizon} s, spacing {spacing} s",
        if pitch { "pitch +-20 deg / 4 s" } else { "hold level" }
    );
    for dither in list("DB_DITHER", "0,0.1,0.2,0.3") {
        for seed in list("DB_SEEDS", "1,2,3,4,5") {
            let cfg = RefinementConfig {
                dither,
                update: false,
                min_change: f64::INFINITY,
                chi2_single_window: f64::INFINITY,
                change_test: false,
                ..RefinementConfig::default()
            };
            let term_prior = std::env::var("DB_TERM_PRIOR")
                .ok()
                .map(|v| v.parse().expect("DB_TERM_PRIOR"));
            let mut run = holding_on_prior("amour5", noise, seed as u64, cfg, term_prior);
            let mut flight = Flight::new(&run, pitch, tau, horizon, spacing);
            if std::env::var("DB_DEBUG").is_ok() {
                let m = run.machine.model().unwrap();
                println!("B learned {:.3}", m.effectiveness.rows(0, 3));
                println!("B true {:.3}", run.truth().rows(0, 3));
                if let Some(d) = &m.dynamics {
                    println!("terms {:.3}", d.coefficients.rows(0, 3));
                }
                println!("cmds {:?}", run.sim.commands());
            }
            // Warm-up: the observers converge, the noise statistics fill.
            flight.fly(&mut run, 10.0, None);
            flight.rms();
            flight.module_found = None;
            let max_before = flight.fly(&mut run, before_s, None);
            let rms_before = flight.rms();
            println!(
                "dither {dither} seed {seed} module verdict on the unchanged vehicle: {:?}",
                flight.module_found.take()
            );
            run.rotate_top();
            let mut trace: Vec<(f64, [Stat; VARIANTS])> = Vec::new();
            flight.fly(&mut run, after_s, Some(&mut trace));
            let rms_after = flight.rms();
            println!(
                "dither {dither} seed {seed} module verdict after the change: {:?}",
                flight.module_found.take()
            );
            println!(
                "dither {dither} seed {seed} learned innovation mean now {:.3?}",
                flight.learned_mean()
            );
            for (v, name) in NAMES.iter().enumerate().take(3) {
                println!(
                    "dither {dither} seed {seed} {name:14}: innovation rms before {:.3?} after {:.3?}",
                    rms_before[v], rms_after[v]
                );
            }
            for (v, name) in NAMES.iter().enumerate() {
                let found: Vec<String> = thresholds
                    .iter()
                    .map(|&h| {
                        let any = trace.iter().find(|(_, s)| s[v].chi2 > h);
                        let top = trace
                            .iter()
                            .find(|(_, s)| s[v].chi2 > h && s[v].thruster == 0);
                        let fmt = |x: Option<&(f64, [Stat; VARIANTS])>| {
                            x.map_or("never".to_string(), |(t, s)| {
                                format!("{t:.2}/T{}", s[v].thruster + 1)
                            })
                        };
                        format!("h{h}: {} {}", fmt(any), fmt(top))
                    })
                    .collect();
                let peak = trace.iter().map(|(_, s)| s[v].chi2).fold(0.0, f64::max);
                println!(
                    "dither {dither} seed {seed} {name:14}: unchanged max {:.1} (T{}), after: peak {peak:.0}; {}",
                    max_before[v].chi2,
                    max_before[v].thruster + 1,
                    found.join(", ")
                );
            }
        }
    }
}

/// The change test of [`detection_bound`].
///
/// An observer predicts the body rates from the commands sent (one step of the model, then
/// corrected towards the gyro by the share `dt / tau`); its innovation `e = gyro - predicted`
/// is white noise while the model holds. A change of thruster i's rotation column by `d`
/// (rad/s^2 per unit thrust) from time t0 adds `phi_i(t) d` to the innovation, where
/// `phi_i(t0) = 0` and `phi_i <- (1 - L) phi_i + dt s_i` (s_i: the thruster's lagged thrust;
/// the observer's correction L bleeds the accumulated effect away). For each candidate t0 (a
/// fresh one every `spacing`, kept for `horizon`) and thruster, the least-squares `d` on each
/// axis is S/F with S = sum phi e, F = sum phi^2, and the GLR statistic is
/// chi2 = sum over the 3 axes of S^2 / (F sigma^2): chi-square with 3 degrees of freedom
/// while nothing changed. O(candidates x thrusters) per sample, no allocation.
///
/// Why the gyro: it measures the rates the torque changes directly, white noise per sample;
/// a torque step shows in it as a ramp (rate) that the observer's prediction does not follow.
/// The attitude (filter or accelerometer tilt) sees the same torque integrated once more
/// with a lower noise at low frequencies, but in closed loop the controller cancels the
/// attitude drift within its bandwidth, and the tilt from the accelerometer is mixed with the
/// thruster's changed force; the dither and the controller's own noise-driven commands are
/// fast (0.05 s holds), where the gyro is the better sensor.
// Per-axis and per-thruster indexing over several fixed arrays at once.
#[allow(clippy::needless_range_loop)]
mod bound {
    use super::*;
    use nalgebra::{Vector3, Vector6};
    use thruster_sim::{RigidBody, Thruster};
    use thrusterd_core::estimator::dynamic::regressors::{terms, TERMS};

    const MAX_N: usize = 8;
    pub const VARIANTS: usize = 4;
    /// ORACLE with the true attitude and velocity in its nuisance terms (model and state
    /// error zero), ORACLE with the attitude filter's attitude, LEARNED (the filter's too),
    /// and MODULE: `thrusterd_core::adaptation::refinement::change_test` with the shipped settings on the
    /// same inputs as in the machine (its statistic whatever the share of the move).
    pub const NAMES: [&str; VARIANTS] = ["oracle", "oracle+filter", "learned", "module"];

    #[derive(Debug, Clone, Copy, Default)]
    pub struct Stat {
        pub chi2: f64,
        pub thruster: usize,
    }

    #[derive(Clone, Copy, Default)]
    struct Cand {
        live: bool,
        phi: [f64; MAX_N],
        s: [[f64; 3]; MAX_N],
        f: [f64; MAX_N],
        /// Samples, sum of the innovations and of each signature: the GLR is centred (an
        /// unknown constant innovation per candidate, the model's bias, is not a change).
        count: f64,
        sz: [f64; 3],
        sp: [f64; MAX_N],
    }

    pub struct Glr {
        n: usize,
        gain: f64,
        spacing: u64,
        cands: Vec<Cand>,
        next: usize,
        k: u64,
        mean: [f64; 3],
        var: [f64; 3],
        /// EW weight of the noise statistics per sample (30 s).
        w: f64,
        /// Samples seen (the statistics are valid after a warm-up).
        pub seen: u64,
        /// Lowest noise standard deviation assumed, rad/s.
        floor: f64,
        pub mean_out: [f64; 3],
        /// The reference: the same regression over the recent past with forgetting (weight
        /// per sample `ref_w`; 0: no reference, the change is measured from the model).
        /// The test is then window against reference: a column error the model has had all
        /// along (its own bias, or an apparent one from the attitude filter's error that the
        /// controller acts on) is not a change.
        refr: Cand,
        phi_ref: [f64; MAX_N],
        ref_w: f64,
        /// The rows judged (DB_AXES, e.g. `0,2`: roll and yaw only; default all three).
        axes: [bool; 3],
    }

    impl Glr {
        pub fn new(n: usize, dt: f64, tau: f64, horizon: f64, spacing: f64) -> Glr {
            let spacing = (spacing / dt).round().max(1.0) as u64;
            let count = ((horizon / dt) as u64 / spacing).max(1) as usize;
            Glr {
                n,
                gain: (dt / tau).min(1.0),
                spacing,
                cands: vec![Cand::default(); count],
                next: 0,
                k: 0,
                mean: [0.0; 3],
                var: [0.0; 3],
                w: dt / 30.0,
                seen: 0,
                floor: std::env::var("DB_SIGMA_FLOOR")
                    .ok()
                    .and_then(|v| v.parse().ok())
                    .unwrap_or(1e-3),
                mean_out: [0.0; 3],
                refr: Cand::default(),
                phi_ref: [0.0; MAX_N],
                ref_w: std::env::var("DB_REFERENCE")
                    .ok()
                    .and_then(|v| v.parse::<f64>().ok())
                    .map_or(0.0, |t| if t > 0.0 { dt / t } else { 0.0 }),
                axes: std::env::var("DB_AXES").map_or([true; 3], |v| {
                    let on: Vec<usize> = v.split(',').filter_map(|a| a.parse().ok()).collect();
                    [0, 1, 2].map(|a| on.contains(&a))
                }),
            }
        }

        /// The innovation of one sample; the largest statistic over candidates and thrusters.
        pub fn observe(&mut self, e: &Vector3<f64>) -> Stat {
            let mut best = Stat::default();
            let warm = self.seen as f64 * self.w > 0.3;
            let mut z = [0.0; 3];
            let mut inv = [0.0; 3];
            for j in 0..3 {
                z[j] = e[j] - self.mean[j];
                inv[j] = 1.0 / self.var[j].max(self.floor * self.floor);
            }
            if warm {
                if self.k.is_multiple_of(self.spacing) {
                    self.cands[self.next] = Cand {
                        live: true,
                        ..Cand::default()
                    };
                    self.next = (self.next + 1) % self.cands.len();
                }
                self.k += 1;
                if self.ref_w > 0.0 {
                    let keep = 1.0 - self.ref_w;
                    let r = &mut self.refr;
                    r.count = keep * r.count + 1.0;
                    for j in 0..3 {
                        r.sz[j] = keep * r.sz[j] + z[j];
                    }
                    for i in 0..self.n {
                        let p = self.phi_ref[i];
                        r.f[i] = keep * r.f[i] + p * p;
                        r.sp[i] = keep * r.sp[i] + p;
                        for j in 0..3 {
                            r.s[i][j] = keep * r.s[i][j] + p * z[j];
                        }
                    }
                }
                let r = self.refr;
                let use_ref = self.ref_w > 0.0;
                for c in self.cands.iter_mut().filter(|c| c.live) {
                    c.count += 1.0;
                    for j in 0..3 {
                        c.sz[j] += z[j];
                    }
                    for i in 0..self.n {
                        let p = c.phi[i];
                        c.f[i] += p * p;
                        c.sp[i] += p;
                        for j in 0..3 {
                            c.s[i][j] += p * z[j];
                        }
                        let f = c.f[i] - c.sp[i] * c.sp[i] / c.count;
                        let mut chi2 = 0.0;
                        if use_ref {
                            // Window minus reference, over both variances.
                            let fr = r.f[i] - r.sp[i] * r.sp[i] / r.count.max(1.0);
                            if f > 1e-12 && fr > 1e-12 && c.count > 2.0 {
                                for j in 0..3 {
                                    let dc = (c.s[i][j] - c.sp[i] * c.sz[j] / c.count) / f;
                                    let dr = (r.s[i][j] - r.sp[i] * r.sz[j] / r.count) / fr;
                                    chi2 += (dc - dr) * (dc - dr) * inv[j];
                                }
                                chi2 /= 1.0 / f + 1.0 / fr;
                                if chi2 > best.chi2 {
                                    best = Stat { chi2, thruster: i };
                                }
                            }
                            continue;
                        }
                        for j in 0..3 {
                            if !self.axes[j] {
                                continue;
                            }
                            let sc = c.s[i][j] - c.sp[i] * c.sz[j] / c.count;
                            chi2 += sc * sc * inv[j];
                        }
                        if f > 1e-12 * c.f[i].max(1e-300) && c.count > 2.0 {
                            chi2 /= f;
                            if chi2 > best.chi2 {
                                best = Stat { chi2, thruster: i };
                            }
                        }
                    }
                }
            }
            let w = if warm {
                self.w
            } else {
                1.0 / (self.seen + 1) as f64
            };
            for j in 0..3 {
                let d = e[j] - self.mean[j];
                self.mean[j] += w * d;
                self.var[j] += w * (d * d - self.var[j]);
            }
            self.seen += 1;
            self.mean_out = self.mean;
            best
        }

        /// The thrusters' (lagged) thrust over the next sample interval.
        pub fn advance(&mut self, s: &[f64], dt: f64) {
            let keep = 1.0 - self.gain;
            for i in 0..self.n {
                self.phi_ref[i] = keep * self.phi_ref[i] + dt * s[i];
            }
            for c in self.cands.iter_mut().filter(|c| c.live) {
                for i in 0..self.n {
                    c.phi[i] = keep * c.phi[i] + dt * s[i];
                }
            }
        }
    }

    /// The simulator's true model before the change.
    pub struct Oracle {
        body: RigidBody,
        thrusters: Vec<Thruster>,
        nu: Vector6<f64>,
        scale: Vec<f64>,
    }

    impl Oracle {
        fn new(run: &Run) -> Oracle {
            let v = run.sim.vehicle();
            let mut thrusters: Vec<Thruster> =
                v.thrusters.iter().cloned().map(Thruster::new).collect();
            for (t, c) in thrusters.iter_mut().zip(run.sim.commands()) {
                t.set_command(c);
                t.settle();
            }
            Oracle {
                body: run.sim.body().clone(),
                thrusters,
                nu: run.sim.state().nu,
                scale: v.thrusters.iter().map(|t| t.forward_max_n).collect(),
            }
        }

        fn predicted(&self) -> Vector3<f64> {
            Vector3::new(self.nu[3], self.nu[4], self.nu[5])
        }

        /// Correct the rates by `gain` of the innovation, then one step with the commands
        /// sent (the raw ones, the thrusters' deadband included) from the attitude `q`.
        fn step(
            &mut self,
            e: &Vector3<f64>,
            gain: f64,
            q: &UnitQuaternion<f64>,
            sent: &[f64],
            dt: f64,
            s: &mut [f64],
        ) {
            for j in 0..3 {
                self.nu[3 + j] += gain * e[j];
            }
            for (t, &c) in self.thrusters.iter_mut().zip(sent) {
                t.set_command(c);
            }
            let state = thruster_sim::State {
                position_ned_m: Vector3::new(0.0, 0.0, 5.0),
                attitude: *q,
                nu: self.nu,
            };
            let ths = &self.thrusters;
            let next = self.body.step_rk4(&state, dt, &Vector3::zeros(), |h, _| {
                let mut tau = Vector6::zeros();
                for t in ths {
                    tau += t.wrench_per_newton() * t.thrust_after(h);
                }
                tau
            });
            self.nu = next.nu;
            for (i, t) in self.thrusters.iter_mut().enumerate() {
                let a = t.thrust_n();
                t.advance(dt);
                s[i] = 0.5 * (a + t.thrust_n()) / self.scale[i];
            }
        }
    }

    /// The learned model in force: B's rotation rows on the lagged commands, and its damping,
    /// restoring and Coriolis terms on the predicted rates (body velocity taken as zero: the
    /// vehicle holds).
    pub struct Learned {
        w: Vector3<f64>,
        lag: Vec<f64>,
        lag_abs: f64,
        terms: [f64; TERMS],
        deadband: f64,
        lag_s: f64,
    }

    impl Learned {
        fn new(run: &Run) -> Learned {
            let n = run.sim.thruster_count();
            Learned {
                w: run.sim.angular_velocity(),
                lag: vec![0.0; n],
                lag_abs: 0.0,
                terms: [0.0; TERMS],
                deadband: 0.05,
                lag_s: 0.1,
            }
        }

        fn step(
            &mut self,
            e: &Vector3<f64>,
            gain: f64,
            run: &Run,
            sent: &[f64],
            dt: f64,
            s: &mut [f64],
        ) {
            self.w += e * gain;
            let model = run.machine.model().expect("a model");
            let n = sent.len();
            let a = 1.0 - (-dt / self.lag_s).exp();
            let mut abs = 0.0;
            for i in 0..n {
                let c = sent[i];
                // Model units: the machine's deadband compensation undone.
                let u = if c.abs() > self.deadband {
                    c.signum() * (c.abs() - self.deadband) / (1.0 - self.deadband)
                } else {
                    0.0
                };
                abs += u.abs();
                self.lag[i] += a * (u - self.lag[i]);
                s[i] = self.lag[i];
            }
            self.lag_abs += a * (abs / n as f64 - self.lag_abs);
            let down = run
                .machine
                .attitude()
                .inverse_transform_vector(&Vector3::z());
            let v = if std::env::var("DB_LEARNED_TRUE_VEL").is_ok() {
                run.sim.linear_velocity()
            } else {
                Vector3::zeros()
            };
            terms(&v, &self.w, &down, self.lag_abs, &mut self.terms);
            let truth = run.truth();
            let b = if std::env::var("DB_LEARNED_B_TRUE").is_ok() {
                &truth
            } else {
                &model.effectiveness
            };
            let skip: Vec<usize> = std::env::var("DB_LEARNED_SKIP")
                .map(|v| v.split(',').filter_map(|k| k.parse().ok()).collect())
                .unwrap_or_default();
            let mut wd = Vector3::zeros();
            for j in 0..3 {
                for i in 0..n {
                    wd[j] += b[(j, i)] * self.lag[i];
                }
                if let Some(d) = &model.dynamics {
                    for (k, t) in self.terms.iter().enumerate() {
                        if !skip.contains(&k) {
                            wd[j] += d.coefficients[(j, k)] * t;
                        }
                    }
                }
            }
            self.w += wd * dt;
        }
    }

    /// The flight: the manoeuvre, the machine, and both detectors beside it.
    pub struct Flight {
        pitch: bool,
        tau: [f64; 3],
        oracle: [Oracle; 2],
        learned: Learned,
        pub glr: [Glr; 3],
        module: thrusterd_core::adaptation::refinement::change_test::ChangeTest,
        model_units: Vec<f64>,
        sp: UnitQuaternion<f64>,
        yaw: f64,
        depth: f64,
        step: usize,
        t0: f64,
        s: Vec<f64>,
        /// Sum of squared innovations per variant and axis, and their count (since `rms`).
        sq: [[f64; 3]; VARIANTS],
        count: u64,
        /// The module's first verdict (seconds into the `fly`, the statistic), if any.
        pub module_found: Option<(
            f64,
            thrusterd_core::adaptation::refinement::change_test::ChangeStat,
        )>,
    }

    impl Flight {
        pub fn new(run: &Run, pitch: bool, tau: [f64; 3], horizon: f64, spacing: f64) -> Flight {
            let n = run.sim.thruster_count();
            let dt = run.sim.sample_period_ns() as f64 * 1e-9;
            Flight {
                pitch,
                tau,
                oracle: [Oracle::new(run), Oracle::new(run)],
                learned: Learned::new(run),
                glr: [0, 1, 2].map(|v| Glr::new(n, dt, tau[v], horizon, spacing)),
                module: thrusterd_core::adaptation::refinement::change_test::ChangeTest::new({
                    let mut c = RefinementConfig::default();
                    if let Ok(v) = std::env::var("DB_MODEL_FLOOR") {
                        c.change_model_floor = v.parse().unwrap();
                    }
                    if let Ok(v) = std::env::var("DB_MIN_SHARE") {
                        c.change_min_share = v.parse().unwrap();
                    }
                    if let Ok(v) = std::env::var("DB_CHI2") {
                        c.change_chi2 = v.parse().unwrap();
                    }
                    if let Ok(v) = std::env::var("DB_WARMUP") {
                        c.change_warmup_s = v.parse().unwrap();
                    }
                    c.change_settings(0.1)
                }),
                model_units: vec![0.0; n],
                sp: UnitQuaternion::identity(),
                yaw: run.sim.roll_pitch_yaw()[2],
                depth: run.sim.position_ned().z,
                step: 0,
                t0: run.sim.time_s(),
                s: vec![0.0; n],
                sq: [[0.0; 3]; VARIANTS],
                count: 0,
                module_found: None,
            }
        }

        /// The learned predictor's innovation mean (the test's slow running estimate), rad/s.
        pub fn learned_mean(&self) -> [f64; 3] {
            self.glr[2].mean_out
        }

        /// RMS innovation per variant and axis since the last call, rad/s.
        pub fn rms(&mut self) -> [[f64; 3]; VARIANTS] {
            let c = self.count.max(1) as f64;
            let r = self.sq.map(|a| a.map(|v| (v / c).sqrt()));
            self.sq = [[0.0; 3]; VARIANTS];
            self.count = 0;
            r
        }

        /// Fly `seconds`; the largest statistic of each variant, and every sample's in `trace`.
        pub fn fly(
            &mut self,
            run: &mut Run,
            seconds: f64,
            mut trace: Option<&mut Vec<(f64, [Stat; VARIANTS])>>,
        ) -> [Stat; VARIANTS] {
            let dt = run.sim.sample_period_ns() as f64 * 1e-9;
            let start = run.sim.time_s();
            let mut max = [Stat::default(); VARIANTS];
            while run.sim.time_s() - start < seconds {
                let t = run.sim.time_s() - self.t0;
                let p: f64 = if self.pitch {
                    [20.0, -20.0][self.step % 2]
                } else {
                    0.0
                };
                if t >= 4.0 * self.step as f64 {
                    let sp = UnitQuaternion::from_euler_angles(0.0, p.to_radians(), self.yaw);
                    run.machine.on_setpoint(sp, Some(self.depth));
                    self.sp = sp;
                    self.step += 1;
                }
                let r = run.sim.advance_and_sample();
                let gyro = Vector3::from(r.gyro);
                let e = [
                    gyro - self.oracle[0].predicted(),
                    gyro - self.oracle[1].predicted(),
                    gyro - self.learned.w,
                ];
                let g = [0, 1, 2].map(|v| self.glr[v].observe(&e[v]));
                let mut stats = [g[0], g[1], g[2], Stat::default()];
                let cmd = run.machine.on_imu(&r);
                let sent = &cmd.thrust[..cmd.count];
                run.sim.set_commands(sent).unwrap();
                for (m, &c) in self.model_units.iter_mut().zip(sent) {
                    *m = if c.abs() > 0.05 {
                        c.signum() * (c.abs() - 0.05) / 0.95
                    } else {
                        0.0
                    };
                }
                let found = self.module.observe(
                    r.t_ns,
                    &gyro,
                    &run.machine.attitude(),
                    run.machine.model().unwrap(),
                    &self.model_units,
                    &[1e-3; 3],
                    {
                        let cfg = RefinementConfig::default();
                        let err = (run.machine.attitude().inverse() * self.sp)
                            .scaled_axis()
                            .map(|v| v.to_degrees().abs());
                        let tilt =
                            run.machine
                                .attitude()
                                .angle_to(&UnitQuaternion::from_euler_angles(
                                    0.0,
                                    0.0,
                                    run.machine.attitude().euler_angles().2,
                                ));
                        let max_tilt = std::env::var("DB_MAX_TILT")
                            .map_or(cfg.change_max_tilt_deg, |v| v.parse().unwrap());
                        let level = tilt.to_degrees() <= max_tilt;
                        let always = std::env::var("DB_MODULE_ALWAYS").is_ok();
                        [0, 1, 2].map(|j| always || (level && err[j] <= cfg.change_max_error_deg))
                    },
                );
                if let (Some(f), None) = (found, self.module_found) {
                    self.module_found = Some((run.sim.time_s() - start, f));
                }
                if let Some(m) = self.module.last_stat() {
                    stats[3] = Stat {
                        chi2: m.chi2,
                        thruster: m.thruster,
                    };
                }
                assert_eq!(
                    run.machine.state(),
                    State::Active,
                    "left control at {t:.1} s"
                );
                for v in 0..3 {
                    for j in 0..3 {
                        self.sq[v][j] += e[v][j] * e[v][j];
                    }
                }
                self.count += 1;
                let nu = run.sim.state().nu;
                self.oracle[0].nu[0] = nu[0];
                self.oracle[0].nu[1] = nu[1];
                self.oracle[0].nu[2] = nu[2];
                let q = run.sim.attitude();
                self.oracle[0].step(&e[0], dt / self.tau[0], &q, sent, dt, &mut self.s);
                self.glr[0].advance(&self.s, dt);
                let q = run.machine.attitude();
                self.oracle[1].step(&e[1], dt / self.tau[1], &q, sent, dt, &mut self.s);
                self.glr[1].advance(&self.s, dt);
                self.learned
                    .step(&e[2], dt / self.tau[2], run, sent, dt, &mut self.s);
                self.glr[2].advance(&self.s, dt);
                for v in 0..VARIANTS {
                    if stats[v].chi2 > max[v].chi2 {
                        max[v] = stats[v];
                    }
                }
                if let Some(tr) = trace.as_mut() {
                    tr.push((run.sim.time_s() - start, stats));
                }
                run.machine.take_events();
            }
            max
        }
    }
}
