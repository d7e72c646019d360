//! The best detection time any detector could reach (docs/experiments.md), moved from
//! thrusterd-core's tests/refinement.rs: a generalized-likelihood-ratio test beside the
//! machine on the same flight, knobs from environment variables.

use nalgebra::UnitQuaternion;
use thruster_sim::NoisePreset;
use thrusterd_core::adaptation::refinement::RefinementConfig;
use thrusterd_core::machine::State;

use thruster_inprocess::holding::holding_on_prior;
use thruster_inprocess::Run;

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
/// `cargo run --release -p thrusterctl -- study sweep detection_bound`.
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
pub(super) fn detection_bound() {
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
