//! The continuous refinement's research sweeps (docs/experiments.md), moved from
//! thrusterd-core's tests/refinement.rs: each prints a table, knobs from environment
//! variables; the soaks end in a panic naming the false alarms, as they did as tests.

use thruster_sim::disturbance::WaterPreset;
use thruster_sim::NoisePreset;
use thrusterd_core::adaptation::refinement::RefinementConfig;

use thruster_inprocess::holding::*;
use thruster_inprocess::{Run, VEHICLES};

/// [`shipped_change_test`] with the measuring runs' overrides from the environment (the
/// ignored measuring tools only; CT_CAL_WHEN in_a_sea | always for `change_calibrate_when`).
fn with_change_test() -> RefinementConfig {
    let mut c = shipped_change_test();
    if let Ok(v) = std::env::var("CT_UPDATE") {
        c.update = v == "1";
    }
    if let Some(w) = super::calibrate_when_from_env("CT_CAL_WHEN") {
        c.change_calibrate_when = w;
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
        ("CT_MIN_AGE", &mut c.change_min_age_s),
        ("CT_CAL", &mut c.change_calibration_s),
        ("CT_BATCH", &mut c.change_batch_s),
    ] {
        if let Ok(v) = std::env::var(key) {
            *field = v.parse().unwrap_or_else(|_| panic!("{key}: {v}"));
        }
    }
    c
}

/// The 1 kHz hold with knobs, for the change test's runs in docs/experiments.md: KHZ_SEEDS
/// (comma list, default 1,2,3), KHZ_SECONDS (180), KHZ_DEADBAND (0.05), KHZ_CHANGE_TEST=0
/// (turn it off), KHZ_TARGET (the first estimation's `target_rel_err`), RUN_LATENCY_US (`A` or `A-B`: the command takes effect that long after its
/// sample, as through the driver in real time). A measuring tool; run with
/// `cargo run --release -p thrusterctl -- study sweep khz_sweep`.
pub(super) fn khz_sweep() {
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
            target_rel_err: std::env::var("KHZ_TARGET").ok().map(|v| v.parse().unwrap()),
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
/// `cargo run --release -p thrusterctl -- study sweep dither_sweep`.
pub(super) fn dither_sweep() {
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

/// The false-alarm soak for the change test: `CT_MINUTES` (default 10) through pitch steps
/// (+-20 deg every 4 s), then as long again holding level, on an unchanged vehicle at the
/// paper's noise with the shipped settings and the change test on, seeds `CT_SEEDS` (default
/// 1-5; CT_NOISE realistic or none for another IMU; CT_WATER a water preset that comes up
/// after the estimation); no mismatch may be reported. Then the
/// top thruster rotated while holding level: prints the detection time. A measuring tool (minutes of vehicle
/// time per seed): `cargo run --release -p thrusterctl -- study sweep change_test_soak`.
pub(super) fn change_test_soak() {
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
        let (pitch, level) = flight(&mut run, minutes * 60.0);
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

/// Does the refinement's update carry a swell into the model? AMOUR-5 learns in still water,
/// then the water `RW_WATER` (current|moderate|rough, default moderate) comes up and it holds
/// level `RW_MINUTES` (default 10) with the refinement updating and the change test off
/// (`RW_CHANGE_TEST=1`: on), at `RW_NOISE` (none|realistic|paper, default realistic), seeds
/// `RW_SEEDS` (default 1,2,3). Prints, every minute, the model in force's error against the
/// truth, its own bound and its refinement count, and any mismatch (the run stops there).
/// A measuring tool: `cargo run --release -p thrusterctl -- study sweep refinement_in_water`.
pub(super) fn refinement_in_water() {
    let minutes: f64 = std::env::var("RW_MINUTES").map_or(10.0, |v| v.parse().unwrap());
    let seeds: Vec<u64> = thruster_inprocess::env_list("RW_SEEDS", &[1, 2, 3]);
    let noise = match std::env::var("RW_NOISE").as_deref() {
        Ok("none") => NoisePreset::None,
        Ok("paper") => NoisePreset::Paper,
        _ => NoisePreset::Realistic,
    };
    let water = super::water_from_env("RW_WATER").unwrap_or(WaterPreset::Moderate);
    let cfg = RefinementConfig {
        change_test: std::env::var("RW_CHANGE_TEST").is_ok_and(|v| v == "1"),
        ..shipped_change_test()
    };
    for seed in seeds {
        let mut run = holding_with(noise, seed, cfg.clone());
        run.sim.set_disturbance(water.disturbance()).unwrap();
        let show = |run: &Run, t: f64| {
            let m = run.machine.model().expect("holding with a model");
            let truth = run.truth();
            println!(
                "seed {seed} {:>5.0} s: err {:.3} / {:.3}, bound {:.3} / {:.3}, version {} refinements {}",
                t,
                thruster_inprocess::rel_err(&m.effectiveness, &truth, 0),
                thruster_inprocess::rel_err(&m.effectiveness, &truth, 3),
                m.rel_err_rot,
                m.rel_err_acc,
                m.version,
                m.refinements
            );
        };
        show(&run, 0.0);
        for minute in 1..=minutes.ceil() as u64 {
            if let Some((t, why)) = level_with(&mut run, 60.0, |_| {}) {
                println!(
                    "seed {seed}: mismatch after {:.1} s: {why}",
                    (minute - 1) as f64 * 60.0 + t
                );
                break;
            }
            show(&run, minute as f64 * 60.0);
        }
    }
}

/// The change test (`with_change_test`) on every vehicle file: `CT_MINUTES` (default 5) of pitch
/// steps (+-20 deg every 4 s) then as long holding level, unchanged, at each noise of
/// `CT_NOISES` (default none,realistic,paper), seeds `CT_SEEDS` (default 1; CT_VEHICLES a
/// subset, CT_CHANGE_TEST=0 the windows alone, CT_SHAPED=1 the model learned with
/// `estimator.shaped_thrust`, CT_TRACE=1 how much of the flight the test
/// judged and the seconds before an alarm); prints every
/// mismatch reported (a false alarm) and fails on any. A measuring tool: `cargo run --release -p thrusterctl -- study sweep change_test_on_every_vehicle`.
pub(super) fn change_test_on_every_vehicle() {
    let minutes: f64 = std::env::var("CT_MINUTES").map_or(5.0, |v| v.parse().unwrap());
    let list = |key: &str, default: &str| -> Vec<String> {
        std::env::var(key)
            .unwrap_or_else(|_| default.into())
            .split(',')
            .map(|v| v.trim().to_string())
            .collect()
    };
    let mut alarms = Vec::new();
    for vehicle in list("CT_VEHICLES", &VEHICLES.join(",")) {
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
                // CT_SHAPED=1: the model learned with `estimator.shaped_thrust`.
                let shaped = std::env::var("CT_SHAPED").is_ok_and(|v| v == "1");
                let mut run = holding_on_learned_with(&vehicle, preset, seed, cfg, &|e| {
                    e.shaped_thrust = shaped;
                });
                let (pitch, level) = flight(&mut run, minutes * 60.0);
                println!("{vehicle} {noise} seed {seed}: pitch steps {pitch:?}, level {level:?}");
                if pitch.is_some() || level.is_some() {
                    alarms.push((vehicle.clone(), noise.clone(), seed, pitch, level));
                }
            }
        }
    }
    assert!(alarms.is_empty(), "false alarms: {alarms:#?}");
}

/// [`quiet_flight`], traced with CT_TRACE=1 ([`traced_flight`]).
fn flight(run: &mut Run, seconds: f64) -> (Mismatch, Mismatch) {
    if std::env::var("CT_TRACE").is_ok_and(|v| v == "1") {
        traced_flight(run, seconds)
    } else {
        quiet_flight(run, seconds)
    }
}

/// [`quiet_flight`] that prints, on a mismatch, the last 8 s before it every 0.1 s: the
/// change test's largest statistic, the true attitude against the setpoint, the commands
/// (CT_TRACE=1; what decides whether an alarm is the test's or the vehicle's).
fn traced_flight(run: &mut Run, seconds: f64) -> (Mismatch, Mismatch) {
    use std::collections::VecDeque;
    let mut trace: VecDeque<String> = VecDeque::new();
    let threshold = with_change_test().change_chi2;
    // Per minute: the largest chi-square, and the largest share among statistics over the
    // threshold (how close the test runs to an alarm).
    let (mut minute, mut max_chi2, mut max_share) = (0u64, 0.0f64, 0.0f64);
    // Samples, and samples at which the test judged a candidate (it has a statistic).
    let (mut samples, mut judged) = (0u64, 0u64);
    let mut each = |sp: Option<&nalgebra::UnitQuaternion<f64>>, run: &Run| {
        samples += 1;
        let stat = run.machine.change_stat();
        if let Some(s) = stat {
            judged += 1;
            max_chi2 = max_chi2.max(s.chi2);
            if s.chi2 > threshold {
                max_share = max_share.max(s.share);
            }
        }
        let m = (run.sim.time_s() / 60.0) as u64;
        if m != minute {
            println!(
                "  minute {minute}: max chi2 {max_chi2:.0}, max share over chi2 {threshold} {max_share:.2}, model version {:?}, tilt {:.1} deg",
                run.machine.model().map(|m| m.version),
                run.sim.roll_pitch_yaw()[0].hypot(run.sim.roll_pitch_yaw()[1]).to_degrees()
            );
            (minute, max_chi2, max_share) = (m, 0.0, 0.0);
        }
        if !samples.is_multiple_of(20) {
            return;
        }
        let rpy = run.sim.roll_pitch_yaw();
        let sp = sp.map_or([f64::NAN; 3], |q| {
            let (r, p, y) = q.euler_angles();
            [r, p, y]
        });
        let cmd = run.sim.commands();
        trace.push_back(format!(
            "t {:8.2} rpy {:6.1} {:6.1} {:7.1} sp_p {:6.1} stat {} cmd {:?}",
            run.sim.time_s(),
            rpy[0].to_degrees(),
            rpy[1].to_degrees(),
            rpy[2].to_degrees(),
            sp[1].to_degrees(),
            stat.map_or("-".into(), |s| format!(
                "th{} chi2 {:7.1} share {:5.2} since {:4.1}",
                s.thruster, s.chi2, s.share, s.since_s
            )),
            cmd.iter()
                .map(|v| (v * 100.0).round() / 100.0)
                .collect::<Vec<_>>()
        ));
        if trace.len() > 80 {
            trace.pop_front();
        }
    };
    let pitch = pitch_with(run, seconds, |sp, run| each(Some(sp), run));
    let level = if pitch.is_none() {
        level_with(run, seconds, |run| each(None, run))
    } else {
        None
    };
    println!(
        "  judged at {judged} of {samples} samples ({:.1} %)",
        100.0 * judged as f64 / samples.max(1) as f64
    );
    if pitch.is_some() || level.is_some() {
        for line in &trace {
            println!("  {line}");
        }
    }
    (pitch, level)
}
