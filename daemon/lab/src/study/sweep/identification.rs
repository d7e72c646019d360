//! The identification under control's research sweeps, moved from thrusterd-core's
//! tests/closed_loop.rs: each prints a table, knobs from environment variables.

use thruster_sim::NoisePreset;
use thrusterd_core::adaptation::identification::IdentificationConfig;
use thrusterd_core::estimator::EstimatorConfig;
use thrusterd_core::machine::Machine;

use thruster_inprocess::{env_list, rotate_while_holding_on, swell_phase, vehicle, Run, VEHICLES};

/// The bounds of the estimates made during one re-estimation (every `estimator.segment_s`).
#[derive(Debug, Default)]
struct Bounds {
    /// The estimate in place at the announcement (the first model's): not this run's.
    stale: Option<(f64, f64)>,
    started: bool,
    fresh: bool,
    /// The last estimate's error bounds, rotation and acceleration rows.
    last: (f64, f64),
    /// Seconds after the announcement when each bound first reached the stop target.
    t_rot: Option<f64>,
    t_acc: Option<f64>,
    /// The last estimate's rotation neither thrust nor the dynamics explain, rad/s.
    unexplained: f64,
    /// The dither's share of the commands' variance in the identification.
    dither_share: f64,
    /// The RMS attitude error while held before it (`Machine::sea_state_deg`), deg.
    sea_deg: f64,
    /// The last estimate's thrust-curve evidence: the best exponent and its ln likelihood
    /// ratio over the linear model.
    curve: Option<(f64, f64)>,
    /// `ID_TRACE`: the machine's state and status text as they change.
    trace: Option<(thrusterd_core::machine::State, String)>,
    /// `ID_STEPS`: every fresh estimate of the run (s after the announcement, its
    /// effectiveness, its bounds rot / acc), judged against the truth after the run.
    steps: Vec<(f64, nalgebra::DMatrix<f64>, f64, f64)>,
}

impl Bounds {
    fn observe(&mut self, m: &Machine, t: f64, target: f64) {
        if std::env::var_os("ID_TRACE").is_some() {
            let now = (m.state(), m.status().text);
            if self.trace.as_ref() != Some(&now) {
                let share = m.last_estimate().map(|e| {
                    let p = e.dynamics.as_ref().and_then(|d| d.imu_position);
                    (e.rel_err_acc, p.map(|p| (p.rel_err_share, p.position_m)))
                });
                println!(
                    "  {t:7.2} s {:?}: {} [acc bound, the IMU position's share of it, the \
                     position: {share:?}]",
                    now.0, now.1
                );
                self.trace = Some(now);
            }
        }
        if let Some(x) = m.identification_excitation() {
            self.dither_share = x.dither_share();
        }
        // While identifying: what the guard reads (the control ticks before it).
        if m.state() == thrusterd_core::machine::State::Identify {
            self.sea_deg = m.sea_state_deg().unwrap_or(f64::NAN);
        }
        let now = m.last_estimate().map(|e| (e.rel_err_rot, e.rel_err_acc));
        if !self.started {
            self.started = true;
            self.stale = now;
        }
        // Not only in Identify: the estimate that stops the run is made on the sample the
        // machine leaves Identify.
        let Some((r, a)) = now else { return };
        if !self.fresh && now == self.stale {
            return;
        }
        self.fresh = true;
        if std::env::var_os("ID_STEPS").is_some() && self.last != (r, a) {
            if let Some(e) = m.last_estimate() {
                self.steps.push((t, e.effectiveness.clone(), r, a));
            }
        }
        self.last = (r, a);
        self.unexplained = m
            .last_estimate()
            .and_then(|e| e.dynamics.as_ref())
            .map_or(0.0, |d| d.unexplained_rate_radps);
        self.curve = m
            .last_estimate()
            .and_then(|e| e.dynamics.as_ref())
            .and_then(|d| d.thrust_curve)
            .map(|c| (c.exponent, c.log_likelihood_ratio));
        if r <= target && self.t_rot.is_none() {
            self.t_rot = Some(t);
        }
        if a <= target && self.t_acc.is_none() {
            self.t_acc = Some(t);
        }
    }
}

/// `ID_STEPS`: each estimate of the identification against the truth and against the estimate
/// before it (relative Frobenius change per row group): what a stop rule that waits for the
/// estimate to settle would see.
fn print_steps(steps: &[(f64, nalgebra::DMatrix<f64>, f64, f64)], truth: &nalgebra::DMatrix<f64>) {
    use thruster_inprocess::rel_err;
    let mut prev: Option<&nalgebra::DMatrix<f64>> = None;
    for (t, b, br, ba) in steps {
        let change = |rows: usize| prev.map_or(f64::NAN, |p| rel_err(b, p, rows));
        println!(
            "    step {t:6.2} s err {:.3} / {:.3} bound {br:.3} / {ba:.3} change {:.3} / {:.3}",
            rel_err(b, truth, 0),
            rel_err(b, truth, 3),
            change(0),
            change(3)
        );
        if std::env::var_os("ID_STEPS_COLUMNS").is_some() {
            println!(
                "      each column's error (of its rows' norm): {}",
                column_errors(b, truth)
            );
        }
        prev = Some(b);
    }
}

/// `ID_FIRST`: the first model as the sweep's run learns it (from a request after 1 s, with
/// `ID_TARGET_ACC` when given), against the truth before the change, column by column (of
/// its rows' norm, as `ID_STEPS_COLUMNS`), beside its bound: what the identification carries
/// over.
fn first_model_probe(name: &str, noise: NoisePreset, seed: u64, target_acc: Option<f64>) {
    use thruster_inprocess::rel_err;
    let mut first = Run::new(name, noise, seed);
    if let Some(t) = target_acc {
        first.with_setup(|s| s.estimator.target_rel_err_acc = Some(t));
    }
    first.run_for(1.0);
    let took = first.estimate();
    let Some(m) = first.machine.model() else {
        println!("    first model: none");
        return;
    };
    let (b, truth) = (&m.effectiveness, first.truth());
    println!(
        "    first model ({took:.2} s): err {:.3} / {:.3} bound {:.3} / {:.3}; each column's error: {}",
        rel_err(b, &truth, 0),
        rel_err(b, &truth, 3),
        m.rel_err_rot,
        m.rel_err_acc,
        column_errors(b, &truth)
    );
}

/// Each column's error against `truth`, rotation / acceleration rows, as a share of those
/// rows' whole norm (so their squares sum to the model's squared relative error).
fn column_errors(b: &nalgebra::DMatrix<f64>, truth: &nalgebra::DMatrix<f64>) -> String {
    let cols: Vec<String> = (0..b.ncols())
        .map(|i| {
            let d = |r: usize| {
                (b.view((r, i), (3, 1)) - truth.view((r, i), (3, 1))).norm()
                    / truth.rows(r, 3).norm()
            };
            format!("{:.3}/{:.3}", d(0), d(3))
        })
        .collect();
    cols.join(" ")
}

/// One row of the sweep: took_s, err_rot, err_acc, max_tilt, mean_err, b_rot, b_acc, t_rot, t_acc.
fn line(label: &str, v: &[f64; 7], t_rot: Option<f64>, t_acc: Option<f64>) -> String {
    let t = |t: Option<f64>| t.map_or("-".to_string(), |t| format!("{t:.1}"));
    format!(
        "{label:>5} {:>6.1} {:>7.3} {:>7.3} {:>8.1} {:>8.1} {:>6.3} {:>6.3} {:>7} {:>7} ",
        v[0],
        v[1],
        v[2],
        v[3],
        v[4],
        v[5],
        v[6],
        t(t_rot),
        t(t_acc)
    )
}

/// A measuring tool, not a check: on every vehicle file, noise-free, thruster K (CO_THRUSTER,
/// default 0) turned 45 degrees about an axis across its direction and announced, with the
/// carry-over on and off. Knobs: CO_NOISE (none|realistic|paper), CO_SEEDS, CO_VEHICLES (a
/// comma list of vehicle files; default all), CO_TRACE (print each run's machine state and
/// status as they change).
pub(super) fn carry_over_on_every_vehicle() {
    use nalgebra::Vector3;
    use thrusterd_core::machine::ThrusterChange;
    let k: usize = std::env::var("CO_THRUSTER").map_or(0, |v| v.parse().unwrap());
    let noise = match std::env::var("CO_NOISE").as_deref() {
        Ok("paper") => NoisePreset::Paper,
        Ok("realistic") => NoisePreset::Realistic,
        _ => NoisePreset::None,
    };
    let seeds = env_list("CO_SEEDS", &[1u64]);
    println!(
        "{noise:?}, thruster {k} turned 45 deg; err_rot / err_acc vs truth, took, largest tilt"
    );
    let only: Option<Vec<String>> = std::env::var("CO_VEHICLES")
        .ok()
        .map(|v| v.split(',').map(|s| s.trim().to_string()).collect());
    let trace = std::env::var_os("CO_TRACE").is_some();
    for name in VEHICLES
        .iter()
        .filter(|n| only.as_ref().is_none_or(|o| o.iter().any(|x| x == *n)))
    {
        for carry in [true, false] {
            let mut sum = [0.0; 4];
            for &seed in &seeds {
                let v = vehicle(name);
                let mut run = Run::with_vehicle(v.clone(), noise, seed, 200.0);
                run.with_identification(IdentificationConfig {
                    carry_over: carry,
                    ..IdentificationConfig::default()
                });
                run.run_for(1.0);
                run.estimate();
                run.run_for(3.0);
                let d = Vector3::from(v.thrusters[k].direction);
                let across = if d.x.abs() < 0.9 {
                    Vector3::x()
                } else {
                    Vector3::y()
                };
                let axis = d.cross(&across).normalize();
                let mut last = None;
                let r = run.announced_turn(
                    &v,
                    k,
                    axis.into(),
                    45.0,
                    ThrusterChange::Moved(k),
                    |m, t| {
                        if trace {
                            let now = (m.state(), m.status().text);
                            if last.as_ref() != Some(&now) {
                                println!("  seed {seed} {t:7.2} s {:?}: {}", now.0, now.1);
                                last = Some(now);
                            }
                        }
                    },
                );
                for (s, x) in sum
                    .iter_mut()
                    .zip([r.err_rot, r.err_acc, r.took_s, r.max_tilt_deg])
                {
                    *s += x / seeds.len() as f64;
                }
            }
            println!(
                "{name:>15} carry {carry:>5}: {:.3} / {:.3} in {:.1} s, {:.1} deg",
                sum[0], sum[1], sum[2], sum[3]
            );
        }
    }
}

/// A measuring tool, not a check: the announced rotation with the identification section
/// overridden from the environment, every combination of the lists given, one row per seed and
/// the mean. Knobs (comma lists; unset: the default): ID_NOISE (none|realistic|paper, default
/// paper), ID_SEEDS (default 1-5), ID_HOLD_S, ID_LEAD_IN, ID_LATE_DECISION, ID_DITHER, ID_DITHER_MAX, ID_BUDGET, ID_MIN_S,
/// ID_MAX_S, ID_SETTLE, ID_SETTLE_FLOOR, ID_SETTLE_WAIT, ID_FOCUS, ID_FOCUS_OTHERS, ID_FOCUS_NOISY, ID_FOCUS_OTHERS_NOISY, ID_SE_SCALE, ID_CARRY (0/1), ID_IV (0 never, 1 in a sea, 2 always: the thrust columns by
/// instrumental variables), ID_MIN_SHARE, ID_WATER (still|current|moderate|rough: the
/// water comes up after the first model, 20 s before the announcement), ID_WAVE_PART
/// (force|torque: that part of the swell alone), ID_WAVE_PHASE (the swell's phase at the
/// start: rad, or `seed` for a phase each seed draws), ID_TRACE (print the machine's state and status as they change), ID_STEPS (every estimate of
/// the identification against the truth and the one before it; ID_STEPS_COLUMNS each column's
/// error too), ID_SEGMENT
/// (`estimator.segment_s`, one value), ID_LINEARIZE (0/1: `[supply] linearize`, one value; default as
/// the operator configures the vehicle, `Run`), ID_SPLIT (0/1: `estimator.split_thrust` for the
/// first model, one value), ID_DEADBAND (`machine.deadband`, one value: a
/// driver that jumps the dead zone, thruster-hw's 25 us is 0.0625), ID_MAX_SWAP
/// (`machine.max_swap_rel_err`, one value), ID_TARGET_ACC (`estimator.target_rel_err_acc`, one
/// value: the first model's and the identification's), ID_VEL_PRIOR
/// (`estimator.velocity_term_prior_sd`, one value), ID_DVL (the true velocity handed to the machine at
/// every sample, a perfect DVL), ID_SYM (thrusters as strong in reverse as forward, the daemon told), ID_FLOOR_PROBE (print the first model's bound, lag floor and lags, from a run of its own), ID_FIRST (the first model against the truth, column by column, `first_model_probe`), ID_VEHICLE (default amour5; its first thruster is turned). The last column is the final estimate's
/// rotation that neither thrust nor the dynamics explain (what refuses an open-loop model in
/// moving water). Besides the outcome it shows the last error bounds of the re-estimation (b_rot,
/// b_acc) and when each first reached the stop target (t_rot, t_acc: s after the announcement,
/// `-` never; the mean row's over the seeds that did, counted after it): which rows hold the
/// stop back.
///   `cargo run --release -p thrusterctl -- study sweep sweep_identification`
pub(super) fn sweep_identification() {
    let d = IdentificationConfig::default();
    let target = EstimatorConfig::default().target_rel_err;
    let noises: Vec<String> = std::env::var("ID_NOISE")
        .unwrap_or_else(|_| "paper".into())
        .split(',')
        .map(|s| s.trim().to_lowercase())
        .collect();
    let seeds: Vec<u64> = env_list("ID_SEEDS", &[1, 2, 3, 4, 5]);
    let mut cfgs = vec![d.clone()];
    let mut vary = |key: &str, default: f64, set: fn(&mut IdentificationConfig, f64)| {
        cfgs = env_list(key, &[default])
            .into_iter()
            .flat_map(|v| {
                cfgs.iter().map(move |c| {
                    let mut c = c.clone();
                    set(&mut c, v);
                    c
                })
            })
            .collect();
    };
    vary("ID_MAX_S", d.max_s, |c, v| c.max_s = v);
    vary("ID_MIN_S", d.min_s, |c, v| c.min_s = v);
    vary("ID_SETTLE", d.settle, |c, v| c.settle = v);
    vary("ID_SETTLE_FLOOR", d.settle_floor, |c, v| c.settle_floor = v);
    vary("ID_SETTLE_WAIT", d.settle_wait_s, |c, v| {
        c.settle_wait_s = v
    });
    vary("ID_BUDGET", d.attitude_budget_deg, |c, v| {
        c.attitude_budget_deg = v
    });
    vary("ID_DITHER", d.dither, |c, v| c.dither = v);
    vary("ID_DITHER_MAX", d.dither_max, |c, v| c.dither_max = v);
    vary("ID_HOLD_S", d.hold_s, |c, v| c.hold_s = v);
    vary("ID_LEAD_IN", d.lead_in_s, |c, v| c.lead_in_s = v);
    vary("ID_SETTLE_DECISION", d.settle_decision_s, |c, v| {
        c.settle_decision_s = v
    });
    vary("ID_LATE_DECISION", d.late_decision_s, |c, v| {
        c.late_decision_s = v
    });
    vary("ID_FOCUS", d.focus_gain, |c, v| c.focus_gain = v);
    vary("ID_FOCUS_OTHERS", d.focus_others, |c, v| c.focus_others = v);
    vary("ID_FOCUS_NOISY", d.focus_gain_noisy, |c, v| {
        c.focus_gain_noisy = v
    });
    vary("ID_FOCUS_OTHERS_NOISY", d.focus_others_noisy, |c, v| {
        c.focus_others_noisy = v
    });
    vary("ID_SE_SCALE", d.carry_over_se_scale, |c, v| {
        c.carry_over_se_scale = v
    });
    vary("ID_CARRY", if d.carry_over { 1.0 } else { 0.0 }, |c, v| {
        c.carry_over = v > 0.0
    });
    // 0 never, 1 in a sea (the default), 2 always.
    vary("ID_IV", 1.0, |c, v| {
        use thrusterd_core::adaptation::identification::Instrument;
        c.instrument = match v as u8 {
            0 => Instrument::Never,
            1 => Instrument::InASea,
            _ => Instrument::Always,
        }
    });
    vary("ID_MIN_SHARE", d.min_dither_share, |c, v| {
        c.min_dither_share = v
    });
    // Still water: no water comes up (and no 20 s hold before the announcement).
    let still = thruster_sim::disturbance::WaterPreset::Still;
    let water = super::water_from_env("ID_WATER")
        .filter(|w| *w != still)
        .map(|w| {
            let mut d = w.disturbance();
            // One part of the swell alone (the current stays): which of the two breaks the fit.
            match std::env::var("ID_WAVE_PART").as_deref() {
                Ok("force") => d.waves.iter_mut().for_each(|w| w.torque_body_nm = [0.0; 3]),
                Ok("torque") => d.waves.iter_mut().for_each(|w| w.force_ned_n = [0.0; 3]),
                Ok(other) => panic!("ID_WAVE_PART: {other} is not force or torque"),
                Err(_) => {}
            }
            d
        });
    for name in &noises {
        let noise = match name.as_str() {
            "none" => NoisePreset::None,
            "realistic" => NoisePreset::Realistic,
            "paper" => NoisePreset::Paper,
            other => panic!("ID_NOISE: {other}"),
        };
        for cfg in &cfgs {
            println!(
                "== noise {name} hold_s {} lead_in_s {} dither {} dither_max {} budget {} min_s {} max_s {} settle {} {} {} every {} late {} \
                 carry_over {} se_scale {} focus {} others {} instrument {:?} min_share {} \
                 (stop target {target})",
                cfg.hold_s,
                cfg.lead_in_s,
                cfg.dither,
                cfg.dither_max,
                cfg.attitude_budget_deg,
                cfg.min_s,
                cfg.max_s,
                cfg.settle,
                cfg.settle_floor,
                cfg.settle_wait_s,
                cfg.settle_decision_s,
                cfg.late_decision_s,
                cfg.carry_over,
                cfg.carry_over_se_scale,
                cfg.focus_gain,
                cfg.focus_others,
                cfg.instrument,
                cfg.min_dither_share,
            );
            println!(
                "{:>5} {:>6} {:>7} {:>7} {:>8} {:>8} {:>6} {:>6} {:>7} {:>7} source",
                "seed",
                "took_s",
                "err_rot",
                "err_acc",
                "max_tilt",
                "mean_err",
                "b_rot",
                "b_acc",
                "t_rot",
                "t_acc"
            );
            let mut sum = [0.0f64; 7];
            let (mut t_rot, mut t_acc) = ((0.0, 0), (0.0, 0));
            for &seed in &seeds {
                let mut b = Bounds::default();
                // The defaults: the machine exactly as Run builds it.
                let vehicle_name =
                    std::env::var("ID_VEHICLE").unwrap_or_else(|_| "amour5".to_string());
                // ID_SYM: thrusters as strong in reverse as forward, and the daemon told so
                // (a decisive run for what the forward/reverse asymmetry costs).
                let sym = std::env::var_os("ID_SYM").is_some();
                let mut run = if sym {
                    let mut v = vehicle(&vehicle_name);
                    v.thrusters
                        .iter_mut()
                        .for_each(|t| t.reverse_max_n = t.forward_max_n);
                    let mut run = Run::with_vehicle(v, noise, seed, 200.0);
                    run.with_setup(|s| s.estimator.reverse_ratio = 1.0);
                    run
                } else {
                    Run::new(&vehicle_name, noise, seed)
                };
                run.perfect_dvl = std::env::var_os("ID_DVL").is_some();
                let segment_s = env_list("ID_SEGMENT", &[]);
                let linearize: Vec<f64> = env_list("ID_LINEARIZE", &[]);
                let deadband: Vec<f64> = env_list("ID_DEADBAND", &[]);
                let split: Vec<f64> = env_list("ID_SPLIT", &[]);
                let max_swap: Vec<f64> = env_list("ID_MAX_SWAP", &[]);
                let target_acc: Vec<f64> = env_list("ID_TARGET_ACC", &[]);
                let velocity_prior: Vec<f64> = env_list("ID_VEL_PRIOR", &[]);
                // ID_SHAPED=0: the first model fitted on the bare command (as the wandering
                // estimate was found, before `estimator.shaped_thrust`).
                let shaped: Vec<f64> = env_list("ID_SHAPED", &[]);
                if *cfg != d
                    || !shaped.is_empty()
                    || !split.is_empty()
                    || !max_swap.is_empty()
                    || !segment_s.is_empty()
                    || !linearize.is_empty()
                    || !deadband.is_empty()
                    || !target_acc.is_empty()
                    || !velocity_prior.is_empty()
                {
                    run.with_setup(|s| {
                        s.identification = cfg.clone();
                        if let Some(v) = segment_s.first() {
                            s.estimator.segment_s = *v;
                        }
                        if let Some(v) = linearize.first() {
                            s.supply.linearize = *v > 0.0;
                        }
                        if let Some(v) = deadband.first() {
                            s.machine.deadband = *v;
                        }
                        if let Some(v) = split.first() {
                            s.estimator.split_thrust = *v > 0.0;
                        }
                        if let Some(v) = max_swap.first() {
                            s.machine.max_swap_rel_err = *v;
                        }
                        if let Some(v) = target_acc.first() {
                            s.estimator.target_rel_err_acc = Some(*v);
                        }
                        if let Some(v) = velocity_prior.first() {
                            s.estimator.velocity_term_prior_sd = *v;
                        }
                        if let Some(v) = shaped.first() {
                            s.estimator.shaped_thrust = *v > 0.0;
                        }
                    });
                }
                if std::env::var_os("ID_FIRST").is_some() {
                    first_model_probe(&vehicle_name, noise, seed, target_acc.first().copied());
                }
                if std::env::var_os("ID_FLOOR_PROBE").is_some() {
                    let mut probe = Run::new(&vehicle_name, noise, seed);
                    probe.run_for(1.0);
                    probe.estimate();
                    let m = probe.machine.model().unwrap();
                    let d = m.dynamics.as_ref();
                    eprintln!(
                        "PROBE first model: bound {:.4} / {:.4} floor {:?} lag {:?} per-thruster {:?}",
                        m.rel_err_rot,
                        m.rel_err_acc,
                        d.map(|d| d.spin_up_floor_rel_err),
                        d.map(|d| d.spin_up_s),
                        d.map(|d| d.spin_up_per_thruster_s.clone())
                    );
                }
                let mut water = water.clone();
                if let (Some(d), Ok(knob)) = (water.as_mut(), std::env::var("ID_WAVE_PHASE")) {
                    swell_phase::set(d, super::wave_phase("ID_WAVE_PHASE", &knob, seed));
                }
                let (run, r) =
                    rotate_while_holding_on(run, &vehicle(&vehicle_name), water, |m, s| {
                        b.observe(m, s, target)
                    });
                print_steps(&b.steps, &run.truth());
                let row = [
                    r.took_s,
                    r.err_rot,
                    r.err_acc,
                    r.max_tilt_deg,
                    r.mean_err_deg,
                    b.last.0,
                    b.last.1,
                ];
                // The bound the daemon reports with the model in force (a fight's or a fit that
                // strayed from its prior widened), beside the identification's own above.
                let reported = run
                    .machine
                    .model()
                    .map_or((f64::NAN, f64::NAN), |m| (m.rel_err_rot, m.rel_err_acc));
                println!(
                    "{}{:?} unexplained {:.4} rad/s dither share {:.2} sea {:.1} deg curve {} model bound {:.3} / {:.3}",
                    line(&seed.to_string(), &row, b.t_rot, b.t_acc),
                    r.source,
                    b.unexplained,
                    b.dither_share,
                    b.sea_deg,
                    b.curve
                        .map_or("-".to_string(), |(p, lr)| format!("p {p:.2} lnLR {lr:.1}")),
                    reported.0,
                    reported.1
                );
                for (s, v) in sum.iter_mut().zip(row) {
                    *s += v;
                }
                for (acc, reached) in [(&mut t_rot, b.t_rot), (&mut t_acc, b.t_acc)] {
                    if let Some(v) = reached {
                        acc.0 += v;
                        acc.1 += 1;
                    }
                }
            }
            let k = seeds.len().max(1) as f64;
            let m = sum.map(|s| s / k);
            let mean_t = |(s, n): (f64, usize)| (n > 0).then(|| s / n as f64);
            println!(
                "{} (t_rot, t_acc: mean over the {} / {} seeds that reached the target)",
                line("mean", &m, mean_t(t_rot), mean_t(t_acc)),
                t_rot.1,
                t_acc.1
            );
        }
    }
}
