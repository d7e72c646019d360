//! The dynamic-model estimator's research sweeps (docs/study.md), moved from thrusterd-core's
//! tests/dynamic_estimator.rs: each prints a table, knobs from environment variables.

use thruster_sim::disturbance::WaterPreset;
use thruster_sim::{ImuNoise, NoisePreset, SensorConfig};
use thrusterd_core::estimator::{EstimatorConfig, ExcitationPlan};

use thruster_inprocess::estimation::*;

/// The measurement behind docs/study.md's accelerometer-bias table: AMOUR-5, the realistic IMU
/// with turn-on bias 0, 0.05 (the preset) and 0.2 m/s^2, seeds 1-10. Slow; run with
/// `cargo run --release -p thrusterctl -- study sweep bias_sweep`.
pub(super) fn bias_sweep() {
    for state in [0.0, 0.02, 0.05, 0.1] {
        let cfg = EstimatorConfig {
            accel_bias_std: state,
            ..EstimatorConfig::dynamic()
        };
        for bias in [0.0, 0.05, 0.2] {
            let (mut rot, mut acc, mut secs) = (0.0, 0.0, 0.0);
            let seeds = 1..=10u64;
            let n = seeds.clone().count() as f64;
            for seed in seeds {
                let o = estimate_with("amour5", realistic_with_accel_bias(bias), seed, cfg.clone());
                rot += o.err_rot / n;
                acc += o.err_acc / n;
                secs += o.seconds / n;
            }
            println!(
                "bias state prior {state:.2}, accel bias {bias:.2}: err_rot {rot:.4} err_acc {acc:.4} in {secs:.2} s"
            );
        }
    }
}

/// The measurement behind docs/study.md's standard-error table: coverage at the realistic
/// IMU and the paper's noise over seeds 1-10. Slow; run with
/// `cargo run --release -p thrusterctl -- study sweep coverage_sweep`.
pub(super) fn coverage_sweep() {
    for noise in [
        NoisePreset::None,
        NoisePreset::Realistic,
        NoisePreset::Paper,
    ] {
        let sensors = SensorConfig {
            rate_hz: 200.0,
            noise,
            ..SensorConfig::default()
        };
        let (honest, ols, m) = coverage(&sensors, 1..=10);
        println!(
            "{noise:?}: |err|/se < 2 for B, damping, restoring: honest {:.2?}, i.i.d. {:.2?}; err_rot {:.4} err_acc {:.4} in {:.2} s",
            honest, ols, m[0], m[1], m[2]
        );
    }
}

pub(super) fn presets_sweep() {
    for state in [0.0, 0.1] {
        for noise in [
            NoisePreset::None,
            NoisePreset::Realistic,
            NoisePreset::Paper,
        ] {
            let (mut rot, mut acc, mut secs) = (0.0, 0.0, 0.0);
            for seed in 1..=5u64 {
                let sensors = SensorConfig {
                    rate_hz: 200.0,
                    noise,
                    ..SensorConfig::default()
                };
                let cfg = EstimatorConfig {
                    accel_bias_std: state,
                    ..EstimatorConfig::dynamic()
                };
                let o = estimate_with("amour5", sensors, seed, cfg);
                rot += o.err_rot / 5.0;
                acc += o.err_acc / 5.0;
                secs += o.seconds / 5.0;
            }
            println!("prior {state} {noise:?} seeds 1-5: err_rot {rot:.4} err_acc {acc:.4} in {secs:.2} s");
        }
    }
}

/// The stop threshold against the time to model at the paper's noise on AMOUR-5: mean err_rot,
/// err_acc and vehicle seconds over seeds 1-5 (the target's seeds) and 6-10 (held out), for
/// each `target_rel_err`. Run with
/// `cargo run --release -p thrusterctl -- study sweep stop_threshold_sweep`.
pub(super) fn stop_threshold_sweep() {
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise: NoisePreset::Paper,
        ..SensorConfig::default()
    };
    for target in [0.05, 0.055, 0.058, 0.06, 0.065] {
        for seeds in [1..=5u64, 6..=10, 1..=20] {
            let label = format!("{seeds:?}");
            let runs = seeds.clone().count() as f64;
            let (mut rot, mut acc, mut secs, mut worst) = (0.0, 0.0, 0.0, 0.0f64);
            for seed in seeds {
                let cfg = EstimatorConfig {
                    target_rel_err: target,
                    ..EstimatorConfig::dynamic()
                };
                let o = estimate_with("amour5", sensors.clone(), seed, cfg);
                rot += o.err_rot / runs;
                acc += o.err_acc / runs;
                secs += o.seconds / runs;
                worst = worst.max(o.err_rot);
            }
            println!(
                "target {target:.3} seeds {label}: err_rot {rot:.4} (worst {worst:.4}) err_acc {acc:.4} in {secs:.2} s"
            );
        }
    }
}

/// Every vehicle file at every noise preset, seeds 1-5 (the in-process equivalent of
/// `thrusterctl study --methods dynamic --seeds 5`): per vehicle and noise, and the mean over
/// the six. Run with
/// `cargo run --release -p thrusterctl -- study sweep vehicles_sweep`.
pub(super) fn vehicles_sweep() {
    for noise in [
        NoisePreset::None,
        NoisePreset::Realistic,
        NoisePreset::Paper,
    ] {
        let mut all = [0.0; 4];
        for name in VEHICLES {
            let mut m = [0.0; 4];
            for seed in 1..=5u64 {
                let sensors = SensorConfig {
                    rate_hz: 200.0,
                    noise,
                    ..SensorConfig::default()
                };
                let o = estimate_with(name, sensors, seed, EstimatorConfig::dynamic());
                m[0] += o.err_rot / 5.0;
                m[1] += o.err_acc / 5.0;
                m[2] += o.seconds / 5.0;
                m[3] = f64::max(m[3], o.max_tilt_deg);
            }
            println!(
                "{name} {noise:?}: {:.3} / {:.3}, {:.1} s, {:.0} deg",
                m[0], m[1], m[2], m[3]
            );
            for k in 0..3 {
                all[k] += m[k] / VEHICLES.len() as f64;
            }
            all[3] = f64::max(all[3], m[3]);
        }
        println!(
            "all six {noise:?}: {:.3} / {:.3} in {:.1} s, largest tilt {:.0} deg",
            all[0], all[1], all[2], all[3]
        );
    }
}

/// Per vehicle: the learned rotation-row rate damping and roll/pitch restoring against the
/// simulator's, relative, and in honest standard errors; the decisive runs behind
/// docs/study.md ("Where the coefficients' errors come from"). Run with
/// `cargo run --release -p thrusterctl -- study sweep coefficient_error_by_vehicle`;
/// knobs: COEF_NOISE (none, realistic, paper; noisy runs take seeds 1-3), COEF_RATE (IMU Hz),
/// COEF_LAG (the estimator's spin-up time constant, s; the simulator's is 0.1), COEF_BIAS_STATE
/// (`accel_bias_std`), COEF_SYMMETRIC, COEF_DVL and COEF_NEUTRAL (the [`Ideal`] inputs).
pub(super) fn coefficient_error_by_vehicle() {
    let noise = match std::env::var("COEF_NOISE").as_deref() {
        Ok("realistic") => NoisePreset::Realistic,
        Ok("paper") => NoisePreset::Paper,
        _ => NoisePreset::None,
    };
    for name in VEHICLES {
        let (lin, restoring) = true_terms(name);
        for seed in 1..=3u64 {
            let rate_hz = std::env::var("COEF_RATE").map_or(200.0, |r| r.parse().unwrap());
            let sensors = SensorConfig {
                rate_hz,
                noise,
                ..SensorConfig::default()
            };
            let mut cfg = EstimatorConfig::dynamic();
            if let Ok(lag) = std::env::var("COEF_LAG") {
                cfg.spin_up_s = lag.parse().unwrap();
            }
            if let Ok(prior) = std::env::var("COEF_BIAS_STATE") {
                cfg.accel_bias_std = prior.parse().unwrap();
            }
            let ideal = Ideal {
                symmetric_thrusters: std::env::var_os("COEF_SYMMETRIC").is_some(),
                true_velocity: std::env::var_os("COEF_DVL").is_some(),
                neutral: std::env::var_os("COEF_NEUTRAL").is_some(),
                ..Ideal::default()
            };
            let o = estimate_ideal(name, sensors, seed, cfg, ideal);
            let mut line = format!(
                "{name:15} seed {seed}: rot {:.4} acc {:.4}",
                o.err_rot, o.err_acc
            );
            for (row, term, truth) in [
                (0, "p", lin[(0, 3)]),
                (1, "q", lin[(1, 4)]),
                (2, "r", lin[(2, 5)]),
                (0, "down_y", restoring[(0, 1)]),
                (1, "down_x", restoring[(1, 0)]),
            ] {
                let (c, se) = o.terms.get(row, term).unwrap();
                line += &format!(
                    " {term} {:+.3} ({:.1} se)",
                    (c - truth) / truth.abs().max(1e-9),
                    (c - truth).abs() / se
                );
            }
            println!("{line}");
            if noise == NoisePreset::None {
                break;
            }
        }
    }
}

/// The thrusters' lag learned on vehicles whose lag the daemon is not told (docs/study.md,
/// "Learning the thruster lag (issue 29)"): learned lag, err_rot / err_acc and the bounds per
/// vehicle, true lag and seed. Knobs: LAG_NOISE (none|realistic|paper), LAG_VEHICLES,
/// LAG_TAUS, LAG_MIXED (lags a,b,..: thruster i gets the (i mod k)-th, LAG_TAUS then unused),
/// LAG_SEEDS (1..=N), LAG_RATE (the IMU's rate, Hz; 200), LAG_LEARN=0, LAG_CHECK=0 (`check_configured_lag` off), LAG_TOLD (the true lag given), LAG_FORCE (learn
/// whatever the gyro noise: `spin_up_max_gyro_sigma` off), LAG_NOISE_ONLY (gyro|accel|white|bias:
/// that part of the preset alone, `noise_only`), LAG_GYRO_ONLY (<rad/s>|gyro|acc:
/// only that sensor's noise), LAG_MIN_POWER, LAG_BIAS_STD, LAG_TARGET, LAG_REACH
/// (`reach_rel_err`), LAG_FLOOR (`model_error_floor`), LAG_PULSES, LAG_SPANNED (`stop_once_spanned`), LAG_PULSE_S (`machine.pulse_s`), LAG_DVL (a perfect DVL), LAG_SYM (symmetric thrusters), LAG_SPLIT (`split_thrust`), LAG_SHAPED (1|0: `shaped_thrust` on or off; set to anything else: on), LAG_BOUND_PARTS (the bound's lag, lag-floor and IMU-position parts), LAG_NO_IMU (`learn_imu_position` off), LAG_DIST_CONST=1 and LAG_DIST_RAMP=1 (a world-fixed constant force and its ramp as states in the fit), LAG_TILT (the largest tilt), LAG_UNMIX (the one column's gains unmixed from a shared forward/reverse asymmetry k, derived in docs/study.md), LAG_REVERSE_RATIO (`reverse_ratio`: the pulses' forward level is this times the reverse), LAG_EXCITATION (round_robin|pairs|orthogonal|doublet_pairs), LAG_NOISE_S (the rest's length, s), and
/// LAG_PROBE: the lag learned again from the last decision's log with inputs replaced by the
/// simulator's truth ([`thruster_inprocess::lag_probe`]): "1" for the named variants, or
/// comma-separated sets of letters (g the rotation rows' gyro, r the terms' rate, d the
/// attitude, v the velocity, z the velocity zeroed, m the acceleration rows' output, n that
/// output true plus the paper's accelerometer noise; "-" none), with LAG_PROBE_ROWS
/// (rot|acc) the lag's profile scored on that group of rows alone; LAG_PROBE_ERR (the
/// navigation's errors), LAG_PROBE_FIT (each variant's log fitted at the learned lags, its
/// errors against the truth), LAG_PROBE_OUTPUTS (each output's ln residual variance at the
/// common lag, the lags per thruster learned and LAG_PROBE_LAGS), LAG_PROBE_SHIFT (each sample under the command that many
/// samples later), LAG_PROBE_RNOISE (noise on the true rate of r), LAG_PROBE_SMOOTH,
/// LAG_PROBE_LEAK, LAG_PROBE_SIM and LAG_PROBE_DECAY (remedies tried on the log; see the probe's
/// `response` module). LAG_WATER, LAG_WAVE_SCALE, LAG_WAVE_PHASE, LAG_IDLE_S and LAG_TETHER fly
/// it in moving water or on a tether (as imu_and_water_sweep's LA_ knobs).
pub(super) fn lag_sweep() {
    let noise = match std::env::var("LAG_NOISE").as_deref() {
        Ok("realistic") => NoisePreset::Realistic,
        Ok("paper") => NoisePreset::Paper,
        _ => NoisePreset::None,
    };
    let learn = std::env::var("LAG_LEARN").map_or(true, |v| v != "0");
    let names = std::env::var("LAG_VEHICLES").unwrap_or("amour5,eight_vectored".into());
    let n_seeds: u64 = std::env::var("LAG_SEEDS").map_or(1, |s| s.parse().unwrap());
    let seeds = 1..=n_seeds;
    let taus = std::env::var("LAG_TAUS").unwrap_or("0.03,0.05,0.08,0.1,0.15,0.2".into());
    for name in names.split(',') {
        for tau in taus.split(',').map(|t| t.parse::<f64>().unwrap()) {
            for seed in seeds.clone() {
                let mut sensors = SensorConfig {
                    rate_hz: std::env::var("LAG_RATE").map_or(200.0, |r| r.parse().unwrap()),
                    noise,
                    ..SensorConfig::default()
                };
                if let Ok(part) = std::env::var("LAG_NOISE_ONLY") {
                    sensors.custom_noise = Some(noise_only(noise, &part, "LAG_NOISE_ONLY"));
                }
                if let Ok(g) = std::env::var("LAG_GYRO_ONLY") {
                    let mut n = NoisePreset::Paper.params();
                    n.gyro_std_radps = 0.0;
                    n.accel_std_mps2 = 0.0;
                    if let Ok(v) = g.parse::<f64>() {
                        n.gyro_std_radps = v;
                    } else if g == "gyro" {
                        n.gyro_std_radps = 0.25;
                    } else {
                        n.accel_std_mps2 = 0.49;
                    }
                    sensors.custom_noise = Some(n);
                }
                let mut cfg = EstimatorConfig::dynamic();
                cfg.learn_spin_up = learn;
                if let Ok(p) = std::env::var("LAG_MIN_POWER") {
                    cfg.min_power = p.parse().unwrap();
                }
                if std::env::var("LAG_CHECK").is_ok_and(|v| v == "0") {
                    // The configured lag unchecked at a noisy gyro: the model as before.
                    cfg.check_configured_lag = false;
                }
                if std::env::var("LAG_FORCE").is_ok() {
                    // Learn whatever the gyro noise (the decisive runs at the paper's noise).
                    cfg.spin_up_max_gyro_sigma = f64::INFINITY;
                }
                if let Ok(b) = std::env::var("LAG_BIAS_STD") {
                    cfg.accel_bias_std = b.parse().unwrap();
                }
                if let Ok(t) = std::env::var("LAG_TARGET") {
                    cfg.target_rel_err = t.parse().unwrap();
                }
                if let Ok(r) = std::env::var("LAG_REACH") {
                    cfg.reach_rel_err = r.parse().unwrap();
                }
                if let Ok(r) = std::env::var("LAG_LEARNED_REACH") {
                    // `learned_lag_reach_rel_err`.
                    cfg.learned_lag_reach_rel_err = r.parse().unwrap();
                }
                if let Ok(r) = std::env::var("LAG_DRIFT") {
                    // The velocity drift's search (`velocity_drift_search_mps2`), m/s^2.
                    cfg.velocity_drift_search_mps2 = r.parse().unwrap();
                }
                if let Ok(f) = std::env::var("LAG_FLOOR") {
                    cfg.model_error_floor = f.parse().unwrap();
                }
                if let Ok(p) = std::env::var("LAG_PULSES") {
                    cfg.max_pulses = p.parse().unwrap();
                }
                if std::env::var("LAG_SPLIT").is_ok() {
                    cfg.split_thrust = true;
                }
                if let Ok(v) = std::env::var("LAG_SHAPED") {
                    cfg.shaped_thrust = v != "0";
                }
                if let Ok(x) = std::env::var("LAG_EXCITATION") {
                    use thrusterd_core::estimator::Excitation;
                    cfg.excitation = match x.as_str() {
                        "round_robin" => Excitation::RoundRobin,
                        "pairs" => Excitation::Pairs,
                        "orthogonal" => Excitation::Orthogonal,
                        _ => Excitation::DoubletPairs,
                    };
                }
                if std::env::var("LAG_SPANNED").is_ok() {
                    // May stop once the pulses tell every thruster apart (`stop_once_spanned`).
                    cfg.stop_once_spanned = true;
                }
                if let Ok(a) = std::env::var("LAG_SECOND") {
                    // The open loop's second level (docs/study.md, "A second level").
                    cfg.second_amplitude = a.parse().unwrap();
                }
                if let Ok(r) = std::env::var("LAG_REVERSE_RATIO") {
                    cfg.reverse_ratio = r.parse().unwrap();
                }
                // A world-fixed constant and ramp in the fit (`EstimatorConfig::disturbance`):
                // the navigation's velocity drift, taken as states (docs/study.md).
                cfg.disturbance.world_constant = std::env::var("LAG_DIST_CONST").is_ok();
                cfg.disturbance.world_ramp = std::env::var("LAG_DIST_RAMP").is_ok();
                if std::env::var("LAG_NO_IMU").is_ok() {
                    cfg.learn_imu_position = false;
                }
                if std::env::var("LAG_TOLD").is_ok() {
                    // The decisive comparison: the true lag given, nothing learned.
                    cfg.learn_spin_up = false;
                    cfg.spin_up_s = tau;
                }
                let t0 = std::time::Instant::now();
                let ideal = Ideal {
                    true_velocity: std::env::var("LAG_DVL").is_ok(),
                    symmetric_thrusters: std::env::var("LAG_SYM").is_ok(),
                    noise_s: std::env::var("LAG_NOISE_S")
                        .ok()
                        .map(|v| v.parse().unwrap()),
                    pulse_s: std::env::var("LAG_PULSE_S")
                        .ok()
                        .map(|v| v.parse().unwrap()),
                    // A refused model is a result here (the configured lag's check, the
                    // swell's): printed, not a failed run.
                    allow_refusal: true,
                    // LAG_WATER (a preset: the probe in moving water), LAG_WAVE_SCALE,
                    // LAG_WAVE_PHASE (rad or "seed"), LAG_IDLE_S (the water's time to come up).
                    water: super::water_from_env("LAG_WATER").unwrap_or_default(),
                    wave_scale: std::env::var("LAG_WAVE_SCALE")
                        .ok()
                        .map(|v| v.parse().unwrap()),
                    wave_phase_rad: std::env::var("LAG_WAVE_PHASE")
                        .ok()
                        .map(|v| super::wave_phase("LAG_WAVE_PHASE", &v, seed)),
                    idle_s: std::env::var("LAG_IDLE_S").ok().map(|v| v.parse().unwrap()),
                    // LAG_TETHER: a tether's pull, N (the lab's `--tether`).
                    tether_n: std::env::var("LAG_TETHER").ok().map(|v| v.parse().unwrap()),
                    // LAG_BIAS_REST: the long idle window of the gyro's bias, s (0: the rest's).
                    gyro_bias_rest_s: std::env::var("LAG_BIAS_REST")
                        .ok()
                        .map(|v| v.parse().unwrap()),
                    ..Ideal::default()
                };
                let mut v = with_lag(name, tau);
                if let Ok(mixed) = std::env::var("LAG_MIXED") {
                    // Thrusters of two makes: thruster i gets the (i mod k)-th of these lags.
                    let lags: Vec<f64> = mixed.split(',').map(|l| l.parse().unwrap()).collect();
                    for (i, t) in v.thrusters.iter_mut().enumerate() {
                        t.time_constant_s = lags[i % lags.len()];
                    }
                }
                let tau = true_lag(&v);
                if let Ok(p) = std::env::var("LAG_PROBE") {
                    use thruster_inprocess::lag_probe::{probe, Replace};
                    // "1": the named variants; else comma-separated letters (Replace::from_letters).
                    let variants: Vec<(String, Replace)> = if p == "1" {
                        Vec::new()
                    } else {
                        p.split(',')
                            .map(|l| (l.to_string(), Replace::from_letters(l)))
                            .collect()
                    };
                    // LAG_PROBE_ROWS: rot or acc scores that group of rows alone.
                    let weights = match std::env::var("LAG_PROBE_ROWS").as_deref() {
                        Ok("rot") => [1.0, 1.0, 1.0, 0.0, 0.0, 0.0],
                        Ok("acc") => [0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
                        _ => [1.0; 6],
                    };
                    let (o, lags) = probe(v, sensors, seed, cfg, ideal, &variants, &weights);
                    let line: Vec<String> =
                        lags.iter().map(|(n, l)| format!("{n} {l:.4}")).collect();
                    println!(
                        "{name} tau {tau:.3} seed {seed}: learned {:.4} err_rot {:.4} err_acc {:.4} bound {:.4} / {:.4} in {:.2} s{} | {}",
                        o.spin_up_s,
                        o.err_rot,
                        o.err_acc,
                        o.bound[0],
                        o.bound[1],
                        o.seconds,
                        if o.refused { " REFUSED" } else { "" },
                        line.join(", ")
                    );
                    continue;
                }
                let reverse_ratio = cfg.reverse_ratio;
                let o = estimate_on(v, sensors, seed, cfg, ideal);
                let check = o.terms.lag_check.map_or(String::new(), |c| {
                    format!(
                        " [check: learned {:.4} sd_ln {:.4}, consistent {:.4}-{:.4}, lnLR {:.1}{}]",
                        c.learned_s,
                        c.learned_sd_ln,
                        c.consistent_s[0],
                        c.consistent_s[1],
                        c.per_thruster_evidence,
                        if c.contradicted() {
                            ", contradicted"
                        } else {
                            ""
                        }
                    )
                });
                let refused = if o.refused { " REFUSED" } else { "" };
                let mut curve = o
                    .terms
                    .command_exponent
                    .map_or(String::new(), |p| format!(" curve ^{p:.3}"));
                if let Some(r) = o.terms.velocity_drift_ned_mps2 {
                    curve += &format!(" drift [{:.4} {:.4}] m/s^2", r[0], r[1]);
                }
                println!(
                "{name} tau {tau:.3} seed {seed}: learned {:.4} {:?} (sd_ln {:.4}, z {:+.2}, per-thruster lnLR {:.1}) err_rot {:.4} err_acc {:.4} bound {:.4} / {:.4} in {:.2} s (wall {:.1} s){curve}{refused}{check} groups z {:.2} gap {:.4}",
                o.spin_up_s,
                o.terms.spin_up_per_thruster_s.iter().map(|l| (l * 1e4).round() / 1e4).collect::<Vec<_>>(),
                o.terms.spin_up_sd_ln,
                (o.spin_up_s / tau).ln() / o.terms.spin_up_sd_ln,
                o.terms.thruster_lag_evidence,
                o.err_rot,
                o.err_acc,
                o.bound[0],
                o.bound[1],
                o.seconds,
                t0.elapsed().as_secs_f64(),
                o.terms.spin_up_groups.map_or(f64::NAN, |g| g.z),
                o.terms.spin_up_groups.map_or(f64::NAN, |g| g.gap_ln())
            );
                if std::env::var_os("LAG_UNMIX").is_some() {
                    print_unmixed(&o, reverse_ratio);
                }
                if std::env::var_os("LAG_TILT").is_some() {
                    println!("    largest tilt {:.1} deg", o.max_tilt_deg);
                }
                if std::env::var_os("LAG_BOUND_PARTS").is_some() {
                    println!(
                        "    bound parts: lag {:?} lag floor {:?} IMU position {:?}",
                        o.terms.spin_up_rel_err,
                        o.terms.spin_up_floor_rel_err,
                        o.terms
                            .imu_position
                            .map(|p| (p.rel_err_share, p.position_m))
                    );
                }
            }
        }
    }
}

/// One part of `noise`'s preset alone (a sweep's LA_NOISE_ONLY / LAG_NOISE_ONLY, named by
/// `key`): "gyro" / "accel", that sensor's white noise and bias; "white", no biases; "bias",
/// the biases only; "gyro_white" / "accel_white", that sensor's white noise alone. Why: tells
/// which part of a noise moves a figure.
fn noise_only(noise: NoisePreset, part: &str, key: &str) -> ImuNoise {
    let mut n = noise.params();
    let (gyro, accel, white, bias) = match part {
        "gyro" => (true, false, true, true),
        "accel" => (false, true, true, true),
        "white" => (true, true, true, false),
        "bias" => (true, true, false, true),
        "gyro_white" => (true, false, true, false),
        "accel_white" => (false, true, true, false),
        other => {
            panic!("{key}: {other} is not gyro, accel, white, bias, gyro_white or accel_white")
        }
    };
    if !gyro || !white {
        n.gyro_std_radps = 0.0;
    }
    if !gyro || !bias {
        n.gyro_bias_walk = 0.0;
        n.gyro_bias_init_std = 0.0;
    }
    if !accel || !white {
        n.accel_std_mps2 = 0.0;
    }
    if !accel || !bias {
        n.accel_bias_walk = 0.0;
        n.accel_bias_init_std = 0.0;
    }
    n
}

/// The IMU off the centre and the water, over seeds (docs/study.md, "The IMU off the centre"):
/// LA_VEHICLES, LA_SEEDS, LA_NOISE (none|realistic|paper), LA_ARM (x,y,z m), LA_TOLD (the
/// daemon is told LA_ARM), LA_TOLD_AT (x,y,z m: the daemon is told this position instead), LA_TOL (tolerance, m), LA_WATER (current|moderate|rough),
/// LA_NO_CURRENT (the preset's waves alone), LA_WAVE_PART (force|torque|heave|surge: that
/// part of the swell alone), LA_DVL (a perfect DVL), LA_SEG (segment_s), LA_IDLE_S (idle before
/// the request, s), LA_NOISE_S (the noise measurement, s), LA_NOISE_ONLY (gyro|accel|white|bias:
/// that part of the preset's noise alone), LA_TETHER (N aft at the stern, as the lab's
/// `--tether`), LA_REACH (`reach_rel_err`), LA_FLOOR (`model_error_floor`), LA_MIN_CYCLES (`min_cycles`), LA_MAX_PULSES (`max_pulses`), LA_TARGET
/// (`target_rel_err`), LA_TARGET_ACC (`target_rel_err_acc`), LA_NAV_DRAWS
/// (`navigation_error_draws`; 0: the navigation's errors not in the bound), LA_BURST
/// (`identification.burst_rel_err`: the open-loop model refined under control), LA_WAVE_SCALE (every wave's force and moment
/// times this), LA_WAVE_PHASE (every wave's phase at the start: rad, or `seed` for a phase
/// each seed draws, `wave_phase`), LA_LAG_KNOWN (the lag not learned: the configured 0.1 s,
/// the simulator's), LA_ONE_LAG (no lag per thruster), LA_SHAPED (1|0: `shaped_thrust` on or off), LA_LAG_GAP (the machine's
/// `max_lag_gap_over_bound`; 0: the row groups' check off), LA_TERMS_TRUE (sd: the terms'
/// prior centred at the simulator's own, `true_terms.rs`), LA_TERMS_ZERO (sd: every term's
/// prior at 0, `term_prior_sd`), LA_TERMS_VEL (sd: the velocity terms', `velocity_term_prior_sd`; 0 off), LA_TERMS_FROM_STILL (sd: centred at
/// a still-water flight's terms; both through `EstimatorConfig::term_prior_mean`), LA_DIST_HZ
/// (swell states at this frequency, `EstimatorConfig::disturbance`; LA_DIST_WORLD=1 with its
/// force fixed in the world), LA_DIST_CONST=1 (a constant horizontal world-fixed force), LA_DIST_RAMP=1 (the same
/// growing in time), LA_GATE (1: those states in the moving-water refit instead; 0: that
/// refit off), LA_WATER_AFTER_STATES=1 (the water check reads the refit's unexplained
/// rotation), LA_WATER_FROM_RESIDUAL=1 (the unexplained rotation from the fit's residual
/// alone, not the larger of it and the rest's noise: docs/study.md, "What the water check
/// reads"), LA_MAX_UNEXPLAINED (`machine.max_unexplained_rate_radps`), LA_MAX_TILT
/// (`machine.max_moving_water_tilt_deg`), LA_BIAS_REST (`machine.gyro_bias_rest_s`), LA_MAX_SWAY
/// (`machine.max_still_sway`), LA_DRIFT_STATES=0 (`estimator.moving_rest_drift_states` off),
/// LA_TOW (`estimator.start_velocity_search_mps`, m/s: 0 off; on at 1.5 by default),
/// LA_SOLVE_DELAY (s: each solve's result back this late, a starved real-time daemon's),
/// LA_PRINT_LAGS=1 (each thruster's lag, their evidence and the start velocity found).
/// Each flight prints the first
/// cycle's estimate beside the whole run's when the run went beyond it (with LA_TARGET=0.001
/// the first cycle's is the stop decision's, its lag searched; with LA_MIN_CYCLES=2 it is a
/// progress estimate at the lag hint, the configured lag: docs/study.md, "The first cycle
/// against the whole run"). Each flight prints the rest's
/// noise, the unexplained rotation and where the row groups put the lag ("The lag in a swell").
pub(super) fn imu_and_water_sweep() {
    let noise = match std::env::var("LA_NOISE").as_deref() {
        Ok("realistic") => NoisePreset::Realistic,
        Ok("paper") => NoisePreset::Paper,
        _ => NoisePreset::None,
    };
    let arm: Vec<f64> = std::env::var("LA_ARM")
        .unwrap_or("0.15,0.05,-0.10".into())
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    let names = std::env::var("LA_VEHICLES").unwrap_or("amour5,eight_vectored".into());
    let seeds: u64 = std::env::var("LA_SEEDS").map_or(1, |s| s.parse().unwrap());
    for name in names.split(',') {
        for seed in 1..=seeds {
            let mut sensors = SensorConfig {
                rate_hz: 200.0,
                noise,
                lever_arm_m: [arm[0], arm[1], arm[2]],
                ..SensorConfig::default()
            };
            if let Ok(part) = std::env::var("LA_NOISE_ONLY") {
                sensors.custom_noise = Some(noise_only(noise, &part, "LA_NOISE_ONLY"));
            }
            let mut cfg = EstimatorConfig::dynamic();
            if let Ok(v) = std::env::var("LA_SHAPED") {
                cfg.shaped_thrust = v != "0";
            }
            if let Ok(v) = std::env::var("LA_LEARN") {
                cfg.learn_imu_position = v != "0";
            }
            if std::env::var("LA_ONE_LAG").is_ok() {
                cfg.learn_thruster_lags = false;
            }
            if std::env::var("LA_LAG_KNOWN").is_ok() {
                // The decisive run for the lag: configured to the simulator's, not learned.
                cfg.learn_spin_up = false;
            }
            if let Ok(v) = std::env::var("LA_SEG") {
                cfg.segment_s = v.parse().unwrap();
            }
            if let Ok(v) = std::env::var("LA_TOL") {
                cfg.imu_position_tolerance_m = v.parse().unwrap();
            }
            if let Ok(r) = std::env::var("LA_REACH") {
                cfg.reach_rel_err = r.parse().unwrap();
            }
            if let Ok(f) = std::env::var("LA_FLOOR") {
                cfg.model_error_floor = f.parse().unwrap();
            }
            if let Ok(t) = std::env::var("LA_TARGET") {
                cfg.target_rel_err = t.parse().unwrap();
            }
            if let Ok(t) = std::env::var("LA_TARGET_ACC") {
                cfg.target_rel_err_acc = Some(t.parse().unwrap());
            }
            if let Ok(d) = std::env::var("LA_NAV_DRAWS") {
                cfg.navigation_error_draws = d.parse().unwrap();
            }
            if let Ok(c) = std::env::var("LA_MIN_CYCLES") {
                cfg.min_cycles = c.parse().unwrap();
            }
            if let Ok(p) = std::env::var("LA_MAX_PULSES") {
                cfg.max_pulses = p.parse().unwrap();
            }
            if std::env::var("LA_TOLD").is_ok() {
                cfg.imu_position_m = [arm[0], arm[1], arm[2]];
            }
            if let Ok(at) = std::env::var("LA_TOLD_AT") {
                let at: Vec<f64> = at.split(',').map(|s| s.parse().unwrap()).collect();
                cfg.imu_position_m = [at[0], at[1], at[2]];
            }
            let water = match std::env::var("LA_WATER").as_deref() {
                Ok("current") => WaterPreset::Current,
                Ok("moderate") => WaterPreset::Moderate,
                Ok("rough") => WaterPreset::Rough,
                _ => WaterPreset::Still,
            };
            let ideal = Ideal {
                allow_refusal: true,
                water,
                true_velocity: std::env::var("LA_DVL").is_ok(),
                no_current: std::env::var("LA_NO_CURRENT").is_ok(),
                wave_part: std::env::var("LA_WAVE_PART")
                    .ok()
                    .map(|v| &*Box::leak(v.into_boxed_str())),
                idle_s: std::env::var("LA_IDLE_S").ok().map(|v| v.parse().unwrap()),
                gyro_bias_rest_s: std::env::var("LA_BIAS_REST")
                    .ok()
                    .map(|v| v.parse().unwrap()),
                wave_scale: std::env::var("LA_WAVE_SCALE")
                    .ok()
                    .map(|v| v.parse().unwrap()),
                wave_phase_rad: std::env::var("LA_WAVE_PHASE")
                    .ok()
                    .map(|v| super::wave_phase("LA_WAVE_PHASE", &v, seed)),
                tether_n: std::env::var("LA_TETHER").ok().map(|v| v.parse().unwrap()),
                max_lag_gap_over_bound: std::env::var("LA_LAG_GAP")
                    .ok()
                    .map(|v| v.parse().unwrap()),
                max_moving_water_tilt_deg: std::env::var("LA_MAX_TILT")
                    .ok()
                    .map(|v| v.parse().unwrap()),
                max_unexplained_rate_radps: std::env::var("LA_MAX_UNEXPLAINED")
                    .ok()
                    .map(|v| v.parse().unwrap()),
                max_still_sway: std::env::var("LA_MAX_SWAY")
                    .ok()
                    .map(|v| v.parse().unwrap()),
                noise_s: std::env::var("LA_NOISE_S").ok().map(|v| v.parse().unwrap()),
                burst_rel_err: std::env::var("LA_BURST").ok().map(|v| v.parse().unwrap()),
                solve_delay_s: std::env::var("LA_SOLVE_DELAY")
                    .ok()
                    .map(|v| v.parse().unwrap()),
                ..Ideal::default()
            };
            // Where the swell's bias enters B: the terms held (a prior of width sd per unit
            // term) at the simulator's own (LA_TERMS_TRUE=sd, the decisive run) or at what a
            // still-water flight of the same vehicle and seed learned (LA_TERMS_FROM_STILL=sd).
            // The velocity terms' prior (LA_TERMS_VEL) and every term's (LA_TERMS_ZERO), sd.
            if std::env::var("LA_DRIFT_STATES").as_deref() == Ok("0") {
                cfg.moving_rest_drift_states = false;
            }
            if let Ok(v) = std::env::var("LA_TOW") {
                cfg.start_velocity_search_mps = v.parse().unwrap();
            }
            if let Ok(sd) = std::env::var("LA_TERMS_VEL") {
                cfg.velocity_term_prior_sd = sd.parse().unwrap();
            }
            if let Ok(sd) = std::env::var("LA_TERMS_ZERO") {
                cfg.term_prior_sd = sd.parse().unwrap();
            }
            if let Ok(sd) = std::env::var("LA_TERMS_TRUE") {
                let (truth, residual) = super::true_terms::true_terms_38(name);
                cfg.term_prior_sd = sd.parse().unwrap();
                cfg.term_prior_mean = Some(truth);
                println!("  terms held at the simulator's (fit residual {residual:.1e})");
            }
            // Disturbance states at a given frequency (LA_DIST_HZ=f, Hz; the swell's own is
            // the decisive run: docs/study.md, "Disturbance states").
            if let Ok(hz) = std::env::var("LA_DIST_HZ") {
                cfg.disturbance.swell_hz = Some(hz.parse().unwrap());
                cfg.disturbance.swell_in_world = std::env::var("LA_DIST_WORLD").is_ok();
            }
            cfg.disturbance.world_constant = std::env::var("LA_DIST_CONST").is_ok();
            cfg.disturbance.world_ramp = std::env::var("LA_DIST_RAMP").is_ok();
            // The same states in the fit made again when the water moves (LA_GATE=1), or
            // that refit off (LA_GATE=0: `moving_water_swell_hz` 0).
            cfg.water_after_states = std::env::var("LA_WATER_AFTER_STATES").is_ok();
            cfg.water_from_residual = std::env::var("LA_WATER_FROM_RESIDUAL").is_ok();
            match std::env::var("LA_GATE").as_deref() {
                Ok("0") => cfg.moving_water_swell_hz = 0.0,
                Ok(_) => {
                    cfg.moving_water_states = cfg.disturbance;
                    cfg.disturbance = Default::default();
                }
                Err(_) => {}
            }
            if let Ok(sd) = std::env::var("LA_TERMS_FROM_STILL") {
                let still = Ideal {
                    allow_refusal: true,
                    idle_s: ideal.idle_s,
                    ..Ideal::default()
                };
                let calm = estimate_ideal(name, sensors.clone(), seed, cfg.clone(), still);
                cfg.term_prior_sd = sd.parse().unwrap();
                cfg.term_prior_mean = Some(calm.terms.coefficients.clone());
                println!(
                    "  still water first: err {:.4} / {:.4}, refused {}",
                    calm.err_rot, calm.err_acc, calm.refused
                );
            }
            // The first cycle's estimate beside the whole run's: how far apart, relative to B,
            // over the bounds in quadrature (q) and over the nested deviation
            // sqrt(bound1^2 - bound^2 + 0.01^2) (the floor cancels in it): the statistics of a
            // check that was not shipped (docs/study.md, "The first cycle against the whole run").
            let cycle =
                ExcitationPlan::new(cfg.excitation, vehicle(name).thrusters.len()).cycle_len();
            let mut first: Option<(nalgebra::DMatrix<f64>, [f64; 2], usize)> = None;
            let o = estimate_observed(vehicle(name), sensors, seed, cfg, ideal, &mut |m, _| {
                if first.is_none() {
                    if let Some(e) = m.last_estimate().filter(|e| e.pulses >= cycle) {
                        first = Some((
                            e.effectiveness.clone(),
                            [e.rel_err_rot, e.rel_err_acc],
                            e.pulses,
                        ));
                    }
                }
            });
            if let Some((b1, e1, pulses1)) = &first {
                let bf = &o.b_err + &o.truth;
                let part = |k: usize| {
                    let d = (b1.rows(k, 3) - bf.rows(k, 3)).norm() / bf.rows(k, 3).norm();
                    let (e1, ef) = (e1[k / 3], o.bound[k / 3]);
                    let nested = (e1 * e1 - ef * ef).max(0.0) + 0.01 * 0.01;
                    (d, d / e1.hypot(ef), d / nested.sqrt())
                };
                let (r, a) = (part(0), part(3));
                println!(
                    "  first cycle ({pulses1} pulses) bound {:.4}/{:.4}; apart rot {:.4} (q {:.2}, nested {:.2}) acc {:.4} (q {:.2}, nested {:.2}); over bound {:.2}/{:.2}",
                    e1[0], e1[1], r.0, r.1, r.2, a.0, a.1, a.2, o.err_rot / o.bound[0], o.err_acc / o.bound[1]
                );
            }
            let Some((p, l)) = o.terms.imu_position.and_then(|p| Some((p, p.learned?))) else {
                // An identification under control (LA_BURST) does not place the IMU.
                println!(
                    "{name} seed {seed}: tilt {:.0} refused {} lag {:.4} err_rot {:.4} err_acc {:.4} bound {:.4}/{:.4} in {:.2} s (under control)",
                    o.max_tilt_deg, o.refused, o.spin_up_s, o.err_rot, o.err_acc, o.bound[0], o.bound[1], o.seconds
                );
                continue;
            };
            let sd = l.sd_m();
            if std::env::var("LA_PRINT_LAGS").is_ok() {
                // Each thruster's lag and the evidence for them (over one common lag).
                println!(
                    "  lags {:?} evidence {:.1} start velocity {:?}",
                    o.terms
                        .spin_up_per_thruster_s
                        .iter()
                        .map(|v| (v * 1e4).round() / 1e4)
                        .collect::<Vec<_>>(),
                    o.terms.thruster_lag_evidence,
                    o.terms.start_velocity_ned_mps
                );
            }
            println!(
                "  sigma {:?} unexplained {:.4} rad/s lag sd_ln {:.4} rel_err {:.4}/{:.4} groups {:?} gap {:.4} z {:.2}",
                o.sigma.map(|v| (v * 1e4).round() / 1e4),
                o.terms.unexplained_rate_radps,
                o.terms.spin_up_sd_ln,
                o.terms.spin_up_rel_err[0],
                o.terms.spin_up_rel_err[1],
                o.terms
                    .spin_up_groups
                    .map(|g| (g.offset_ln.map(|v| (v * 1e4).round() / 1e4), g.sd_ln.map(|v| (v * 1e4).round() / 1e4))),
                o.terms.spin_up_groups.map_or(0.0, |g| g.gap_ln()),
                o.terms.spin_up_groups.map_or(0.0, |g| g.z)
            );
            if let Some(why) = &o.rejection {
                println!("  rejected: {why}");
            }
            if let Some(v) = o.terms.start_velocity_ned_mps {
                println!("  start velocity found {v:.3?} m/s");
            }
            println!(
                "{name} seed {seed}: tilt {:.0} refused {} lag {:.4} err_rot {:.4} err_acc {:.4} bound {:.4}/{:.4} (share {:.4}) in {:.2} s; used [{:.4} {:.4} {:.4}] learned [{:.4} {:.4} {:.4}] sd [{:.4} {:.4} {:.4}] contradicted {} sway {:.2}",
                o.max_tilt_deg, o.refused, o.spin_up_s, o.err_rot, o.err_acc, o.bound[0], o.bound[1], p.rel_err_share, o.seconds, p.position_m[0], p.position_m[1], p.position_m[2], l.position_m[0], l.position_m[1], l.position_m[2], sd[0], sd[1], sd[2], p.contradicted, o.rest_sway.unwrap_or(f64::NAN)
            );
        }
    }
}

/// `LAG_UNMIX`: the one column's gains unmixed from a forward/reverse asymmetry k shared by
/// the thrusters (docs/study.md, "Where the one column's 1.5-3 % comes from"), the pulses'
/// forward level `reverse_ratio` times the reverse one: per row the mean-|command| term's
/// coefficient m is k times the row's sum of gains G, and each gain b is
/// (g (1 + q k) - q m / N) with q = (a - 1) / (a + 1). k by least squares over the rows,
/// each weighted by its group's norm; R (the weighted norm of the G) near 0 means k is not
/// there to find.
pub(super) fn print_unmixed(o: &thruster_inprocess::estimation::Outcome, reverse_ratio: f64) {
    let b = &o.b_err + &o.truth;
    let n = b.ncols() as f64;
    let q = (reverse_ratio - 1.0) / (reverse_ratio + 1.0);
    let last = o.terms.coefficients.ncols() - 1;
    // Per row: G, its weight, m and m's standard error.
    let rows: Vec<(f64, f64, f64, f64)> = (0..6)
        .map(|r| {
            (
                b.row(r).sum(),
                1.0 / b.rows(3 * (r / 3), 3).norm_squared(),
                o.terms.coefficients[(r, last)],
                o.terms.std_err[(r, last)],
            )
        })
        .collect();
    let den: f64 = rows.iter().map(|(g, w, _, _)| w * g * g).sum();
    let k = rows.iter().map(|(g, w, m, _)| w * m * g).sum::<f64>() / den;
    let se_k = rows
        .iter()
        .map(|(g, w, _, se)| (w * g * se).powi(2))
        .sum::<f64>()
        .sqrt()
        / den;
    let mut c = b.clone();
    for (r, (_, _, m, _)) in rows.iter().enumerate() {
        for i in 0..b.ncols() {
            c[(r, i)] = (b[(r, i)] + q * m / n) / (1.0 + q * k);
        }
    }
    let e = |c: &nalgebra::DMatrix<f64>, r: usize| thruster_inprocess::rel_err(c, &o.truth, r);
    println!("    k {k:.4} se {se_k:.4} R {:.3}", den.sqrt());
    println!(
        "    unmixed: k {k:.4} (m rows {:?}) err {:.4} / {:.4} (as fitted {:.4} / {:.4})",
        rows.iter()
            .map(|(_, _, m, _)| (m * 1e3).round() / 1e3)
            .collect::<Vec<_>>(),
        e(&c, 0),
        e(&c, 3),
        e(&b, 0),
        e(&b, 3)
    );
}
