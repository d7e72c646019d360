//! The dynamic-model estimation in one process, scored against the simulator's truth: what
//! thrusterd-core's estimator tests assert on and the lab's estimation sweeps print.

use nalgebra::{DMatrix, Matrix3, Matrix6, UnitQuaternion, Vector3};
use thruster_sim::disturbance::WaterPreset;
use thruster_sim::dynamics::{fossen_to_dof_order, RigidBody};
use thruster_sim::sim::SimOptions;
use thruster_sim::{NoisePreset, SensorConfig, Simulator, Vehicle};
use thrusterd_core::estimator::dynamic::DynamicTerms;
use thrusterd_core::estimator::{EstimatorConfig, Method};
use thrusterd_core::machine::{
    Event, Machine, MachineSetup, Request, SolveResult, SolverMode, State,
};

pub use crate::run::vehicle;

/// Every vehicle file but `eight_vectored_lag80ms_curve`, whose thrust curve (~ command^1.5,
/// 30 N reverse) a linear model per thruster misses by 9-10 % against a bound of 2 %
/// (docs/study.md, "Learning the thruster lag"; issue 29 item 5 is open).
pub const VEHICLES: [&str; 8] = [
    "amour5",
    "amour5_top45",
    "six_dof",
    "eight_vectored",
    "four_up",
    "aligned",
    "amour5_lag30ms",
    "amour5_lag200ms",
];

pub struct Outcome {
    pub err_rot: f64,
    pub err_acc: f64,
    pub seconds: f64,
    pub max_tilt_deg: f64,
    /// The lag the model was fitted with, s (learned unless learning is off).
    pub spin_up_s: f64,
    /// Whether `spin_up_s` was learned (false: the configured one).
    pub spin_up_learned: bool,
    /// The daemon's own error bounds, rotation and acceleration rows.
    pub bound: [f64; 2],
    pub terms: DynamicTerms,
    /// Learned B minus the symmetric truth, its honest and its i.i.d. standard errors.
    pub b_err: DMatrix<f64>,
    pub b_se: DMatrix<f64>,
    /// The symmetric truth B is scored against (the mean of forward and reverse).
    pub truth: DMatrix<f64>,
    /// The rank the estimate found and how many DOFs it actuates.
    pub rank: usize,
    pub actuated: usize,
    /// The machine refused the model (only with `Ideal::allow_refusal`).
    pub refused: bool,
    /// The noise the fit used per DOF row (the larger of the rest's and the residuals').
    pub sigma: [f64; 6],
    /// Why the machine refused the model, when it did.
    pub rejection: Option<String>,
    /// How much the long idle rest swayed beyond the IMU's white noise (None: no long rest).
    pub rest_sway: Option<f64>,
}

/// Solves run as the daemon's worker would on a starved machine: each job computed when it
/// goes out, its result handed back `delay_s` of vehicle time later.
struct LateSolver {
    delay_s: f64,
    out: std::collections::VecDeque<(f64, SolveResult)>,
}

impl LateSolver {
    fn new(machine: &mut Machine, delay_s: f64) -> Self {
        machine.set_solver_mode(SolverMode::External);
        Self {
            delay_s,
            out: Default::default(),
        }
    }

    fn tick(&mut self, machine: &mut Machine, sim: &mut Simulator) {
        let now = sim.time_s();
        while self.out.front().is_some_and(|(at, _)| *at <= now) {
            let (_, r) = self.out.pop_front().unwrap();
            machine.deliver(r);
        }
        tick(machine, sim);
        while let Some(job) = machine.take_job() {
            self.out.push_back((now + self.delay_s, job.run()));
        }
    }
}

pub fn tick(machine: &mut Machine, sim: &mut Simulator) {
    let r = sim.advance_and_sample();
    let cmd = machine.on_imu(&r);
    for v in &cmd.thrust[..cmd.count] {
        assert!(v.is_finite() && v.abs() <= 1.0, "command {v}");
    }
    sim.set_commands(&cmd.thrust[..cmd.count]).unwrap();
}

/// One estimation from rest on the vehicle file `name`, the IMU at 200 Hz with `noise`, the
/// default dynamic method.
pub fn estimate(name: &str, noise: NoisePreset, seed: u64) -> Outcome {
    estimate_configured(name, noise, seed, EstimatorConfig::dynamic())
}

/// [`estimate`] with the estimator configured by the caller.
pub fn estimate_configured(
    name: &str,
    noise: NoisePreset,
    seed: u64,
    estimator: EstimatorConfig,
) -> Outcome {
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise,
        ..SensorConfig::default()
    };
    estimate_with(name, sensors, seed, estimator)
}

/// What the decisive runs take away from the estimator's inputs, so that what is left of a
/// coefficient's error against the truth can be attributed (docs/study.md).
#[derive(Debug, Clone, Copy, Default)]
pub struct Ideal {
    /// Thrusters as strong in reverse as forward (and `reverse_ratio` 1): no asymmetry for
    /// the one symmetric column per thruster to miss.
    pub symmetric_thrusters: bool,
    /// A perfect DVL: the simulator's true body velocity at every sample.
    pub true_velocity: bool,
    /// Buoyancy equal to weight: the body does not rise during the rest before the pulses.
    pub neutral: bool,
    /// The machine may refuse the model (the outcome is then the refused estimate's).
    pub allow_refusal: bool,
    /// Current, waves, a tether (default: still water).
    pub water: WaterPreset,
    /// Without the preset's current (its waves alone).
    pub no_current: bool,
    /// The dead band the machine compensates (default 0.05, the simulator's default).
    pub deadband: Option<f64>,
    /// Only this part of the waves: "force", "torque", "heave" or "surge" (a sweep's
    /// LA_WAVE_PART; default all of them).
    pub wave_part: Option<&'static str>,
    /// Every wave's force and moment times this (a sweep's LA_WAVE_SCALE; default 1).
    pub wave_scale: Option<f64>,
    /// Every wave's phase at the simulator's start, rad (a sweep's LA_WAVE_PHASE; default
    /// the preset's 0). Why: the presets' swell starts at the same phase on every seed, so
    /// seeds vary only the sensors' noise, never where the swell is when the pulses begin.
    pub wave_phase_rad: Option<f64>,
    /// The noise measurement's length, s (a sweep's LAG_NOISE_S; default the shipped one).
    pub noise_s: Option<f64>,
    /// One excitation pulse's length, s (default the shipped `machine.pulse_s`).
    pub pulse_s: Option<f64>,
    /// Whether the rest while idle counts towards the noise measurement (default the
    /// shipped `machine.rest_from_idle`).
    pub rest_from_idle: Option<bool>,
    /// The long idle window of the gyro's bias, s (default the shipped
    /// `machine.gyro_bias_rest_s`; 0 = the noise rest's).
    pub gyro_bias_rest_s: Option<f64>,
    /// How long the machine idles before the request, s (default `IDLE_BEFORE_REQUEST_S`).
    pub idle_s: Option<f64>,
    /// A tether pulling this many newtons aft at the stern, varying 30 % over 20 s (the lab's
    /// `--tether`), from the simulator's start.
    pub tether_n: Option<f64>,
    /// The machine's `max_lag_gap_over_bound` (default the shipped one; 0: the check off).
    pub max_lag_gap_over_bound: Option<f64>,
    /// `machine.max_moving_water_tilt_deg` (None: the default).
    pub max_moving_water_tilt_deg: Option<f64>,
    /// `machine.max_still_sway` (None: the default).
    pub max_still_sway: Option<f64>,
    /// `machine.max_unexplained_rate_radps` (None: the default).
    pub max_unexplained_rate_radps: Option<f64>,
    /// `identification.burst_rel_err` (default the shipped 0: off): the open-loop run stops
    /// at this bound, its model goes in and the estimation goes on under control; the
    /// outcome is then the identification's.
    pub burst_rel_err: Option<f64>,
    /// Each solve's result handed back this long after its job went out, vehicle s (None:
    /// inline, at its due sample): the daemon in real time on a machine too loaded for
    /// `machine.solve_budget_s`, whose late results are applied when they come.
    pub solve_delay_s: Option<f64>,
}

/// How long the machine idles, reading the IMU, before the estimation is asked for, s: so the
/// shipped `machine.rest_from_idle` has its rest ready (1-2 s of it), and that rest starts a
/// second after the simulator does, as a daemon's would that has run for a while. Why not 2:
/// the rest would then begin with the simulated body's first second, released from rest,
/// which no vehicle in the water shows; it moved AMOUR-5's noise-free pitch damping from
/// 16.9 to 20.3 % off (with the rest from 1 to 3 s: 17.1 %).
pub const IDLE_BEFORE_REQUEST_S: f64 = 3.0;

/// The dynamic method with its one column fitted to the bare command (`shaped_thrust` off, the
/// default until 2026-12-03): the arm the thrust's shape is compared with, and the fit the
/// flights found before it were measured on.
pub fn bare_dynamic() -> EstimatorConfig {
    EstimatorConfig {
        shaped_thrust: false,
        ..EstimatorConfig::dynamic()
    }
}

pub fn estimate_with(
    name: &str,
    sensors: SensorConfig,
    seed: u64,
    estimator: EstimatorConfig,
) -> Outcome {
    estimate_ideal(name, sensors, seed, estimator, Ideal::default())
}

pub fn estimate_ideal(
    name: &str,
    sensors: SensorConfig,
    seed: u64,
    estimator: EstimatorConfig,
    ideal: Ideal,
) -> Outcome {
    estimate_on(vehicle(name), sensors, seed, estimator, ideal)
}

/// The same on a vehicle given whole (its hidden constants changed by the caller).
pub fn estimate_on(
    v: Vehicle,
    sensors: SensorConfig,
    seed: u64,
    estimator: EstimatorConfig,
    ideal: Ideal,
) -> Outcome {
    estimate_observed(v, sensors, seed, estimator, ideal, &mut |_, _| {})
}

/// [`estimate_on`] with `observe` called after every sample of the estimation (the machine
/// and the simulator at that sample): for decisive runs that need the truth beside what the
/// estimator saw ([`crate::lag_probe`]).
pub fn estimate_observed(
    mut v: Vehicle,
    sensors: SensorConfig,
    seed: u64,
    estimator: EstimatorConfig,
    ideal: Ideal,
    observe: &mut dyn FnMut(&Machine, &Simulator),
) -> Outcome {
    let name = v.name.clone();
    let mut estimator = estimator;
    if ideal.symmetric_thrusters {
        for t in &mut v.thrusters {
            t.reverse_max_n = t.forward_max_n;
        }
        estimator.reverse_ratio = 1.0;
    }
    if ideal.neutral {
        v.body.buoyancy_n = v.body.mass_kg * v.body.gravity_mps2;
    }
    let n = v.thrusters.len();
    let mut disturbance = ideal.water.disturbance();
    if ideal.no_current {
        disturbance.current_ned_mps = [0.0; 3];
    }
    if let Some(pull) = ideal.tether_n {
        disturbance.tether = Some(thruster_sim::disturbance::TetherConfig {
            attach_m: [-0.3, 0.0, 0.0],
            pull_ned_n: [-pull, 0.0, 0.0],
            vary_ned_n: [-0.3 * pull, 0.0, 0.0],
            period_s: 20.0,
        });
    }
    if let Some(phase) = ideal.wave_phase_rad {
        crate::swell_phase::set(&mut disturbance, phase);
    }
    if let Some(k) = ideal.wave_scale {
        for w in disturbance.waves.iter_mut() {
            w.force_ned_n = w.force_ned_n.map(|f| f * k);
            w.torque_body_nm = w.torque_body_nm.map(|m| m * k);
        }
    }
    match ideal.wave_part {
        Some("force") => disturbance
            .waves
            .iter_mut()
            .for_each(|w| w.torque_body_nm = [0.0; 3]),
        Some("torque") => disturbance
            .waves
            .iter_mut()
            .for_each(|w| w.force_ned_n = [0.0; 3]),
        Some("heave") => disturbance.waves.iter_mut().for_each(|w| {
            w.torque_body_nm = [0.0; 3];
            w.force_ned_n[0] = 0.0;
        }),
        Some("surge") => disturbance.waves.iter_mut().for_each(|w| {
            w.torque_body_nm = [0.0; 3];
            w.force_ned_n[2] = 0.0;
        }),
        _ => {}
    }
    let options = SimOptions {
        disturbance,
        ..SimOptions::default()
    };
    let mut sim = Simulator::with_options(v, sensors, seed, options).unwrap();
    let mut setup = MachineSetup {
        thrusters: n,
        ..MachineSetup::default()
    };
    setup.estimator = estimator;
    assert_eq!(setup.estimator.method, Method::Dynamic);
    // No driver in between: the daemon compensates the T200 deadband itself.
    setup.machine.deadband = ideal.deadband.unwrap_or(0.05);
    // Another make's thrusters as their operator configures them (`run::operator_setup`): a
    // curve the estimate names is learned, not taken for a T200's.
    if !sim.vehicle().all_t200() {
        setup.supply.compensation = thrusterd_core::supply::CompensationModel::None;
    }
    if let Some(v) = ideal.noise_s {
        setup.machine.noise_s = v;
    }
    if let Some(v) = ideal.pulse_s {
        setup.machine.pulse_s = v;
    }
    if let Some(v) = ideal.rest_from_idle {
        setup.machine.rest_from_idle = v;
    }
    if let Some(v) = ideal.gyro_bias_rest_s {
        setup.machine.gyro_bias_rest_s = v;
    }
    if let Some(v) = ideal.max_still_sway {
        setup.machine.max_still_sway = v;
    }
    if let Some(v) = ideal.max_unexplained_rate_radps {
        setup.machine.max_unexplained_rate_radps = v;
    }
    if let Some(v) = ideal.max_moving_water_tilt_deg {
        setup.machine.max_moving_water_tilt_deg = v;
    }
    if let Some(v) = ideal.max_lag_gap_over_bound {
        setup.machine.max_lag_gap_over_bound = v;
    }
    if let Some(v) = ideal.burst_rel_err {
        setup.identification.burst_rel_err = v;
    }
    let mut machine = Machine::new(setup);
    let mut late = ideal
        .solve_delay_s
        .map(|d| LateSolver::new(&mut machine, d));
    // One sample, its solves inline or (`solve_delay_s`) handed back late.
    let mut step = |machine: &mut Machine, sim: &mut Simulator| match late.as_mut() {
        Some(l) => l.tick(machine, sim),
        None => tick(machine, sim),
    };
    while sim.time_s() < ideal.idle_s.unwrap_or(IDLE_BEFORE_REQUEST_S) {
        step(&mut machine, &mut sim);
        observe(&machine, &sim);
    }
    machine.on_request(Request::Estimate).unwrap();
    let start = sim.time_s();
    let mut max_tilt = 0.0f64;
    let concluded = |m: &Machine| {
        m.state() == State::Active || (ideal.allow_refusal && m.state() == State::Idle)
    };
    while !concluded(&machine) && sim.time_s() - start < 60.0 {
        if ideal.true_velocity {
            let v = sim.linear_velocity();
            machine.on_dvl([v.x, v.y, v.z]);
        }
        step(&mut machine, &mut sim);
        observe(&machine, &sim);
        let down = sim.attitude().inverse_transform_vector(&Vector3::z());
        max_tilt = max_tilt.max(down.z.clamp(-1.0, 1.0).acos().to_degrees());
    }
    if !ideal.allow_refusal {
        assert_eq!(
            machine.state(),
            State::Active,
            "{name}: no model in 60 s (unexplained rotation {:?} rad/s)",
            machine
                .last_estimate()
                .and_then(|e| e.dynamics.as_ref())
                .map(|d| d.unexplained_rate_radps)
        );
    }
    let rejection = machine
        .take_events()
        .into_iter()
        .rev()
        .find_map(|e| match e {
            Event::ModelRejected(why) => Some(why),
            _ => None,
        });
    let (f, r) = sim.truth();
    let truth = (f + r) * 0.5;
    let est = machine.last_estimate().unwrap();
    let learned = machine
        .model()
        .map_or(&est.effectiveness, |m| &m.effectiveness);
    let err = |k: usize| (learned.rows(k, 3) - truth.rows(k, 3)).norm() / truth.rows(k, 3).norm();
    Outcome {
        err_rot: err(0),
        err_acc: err(3),
        seconds: sim.time_s() - start,
        max_tilt_deg: max_tilt,
        spin_up_s: est.dynamics.as_ref().map_or(f64::NAN, |d| d.spin_up_s),
        spin_up_learned: est.dynamics.as_ref().is_some_and(|d| d.spin_up_learned),
        bound: [est.rel_err_rot, est.rel_err_acc],
        terms: est.dynamics.clone().expect("dynamic terms"),
        b_err: &est.effectiveness - &truth,
        b_se: est.std_err.clone(),
        truth: truth.clone(),
        refused: machine.model().is_none(),
        rejection,
        rank: est.rank.rank,
        actuated: est.rank.actuated.count(),
        sigma: est.sigma,
        rest_sway: machine.last_rest_sway(),
    }
}

/// The simulator's own coefficients in the dynamic model's form (DOF-order rows): how the rate
/// terms p, q, r (linear damping) and gravity's direction (restoring) enter nu_dot.
pub fn true_terms(name: &str) -> (Matrix6<f64>, nalgebra::Matrix6x3<f64>) {
    let v = vehicle(name);
    let rb = RigidBody::new(&v.body).unwrap();
    let p = rb.mass_matrix_inverse();
    let d = Matrix6::from_diagonal(&v.body.linear_damping.to_fossen());
    let lin = -(p * d);
    // g(q) is linear in the body-frame down vector: sample it at three attitudes.
    let atts = [
        UnitQuaternion::identity(),
        UnitQuaternion::from_euler_angles(0.5, 0.0, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.5, 0.0),
    ];
    let downs = Matrix3::from_columns(&atts.map(|q| q.inverse_transform_vector(&Vector3::z())));
    let gs = nalgebra::Matrix6x3::from_columns(&atts.map(|q| rb.restoring_force(&q)));
    let g_map = gs * downs.try_inverse().unwrap();
    let restoring = -(p * g_map);
    // Reorder rows to DOF order (and the linear map's columns to p, q, r).
    let mut lin_dof = Matrix6::zeros();
    for j in 0..6 {
        lin_dof.set_column(j, &fossen_to_dof_order(&lin.column(j).into_owned()));
    }
    let mut rest_dof = nalgebra::Matrix6x3::zeros();
    for j in 0..3 {
        rest_dof.set_column(j, &fossen_to_dof_order(&restoring.column(j).into_owned()));
    }
    (lin_dof, rest_dof)
}

/// The realistic IMU with the accelerometer's turn-on bias set to `bias_std` (m/s^2 per axis).
pub fn realistic_with_accel_bias(bias_std: f64) -> SensorConfig {
    let mut noise = NoisePreset::Realistic.params();
    noise.accel_bias_init_std = bias_std;
    SensorConfig {
        rate_hz: 200.0,
        noise: NoisePreset::Realistic,
        custom_noise: Some(noise),
        ..SensorConfig::default()
    }
}

/// Fractions of |error| / standard error below 2 over `seeds` on AMOUR-5 with `sensors`, for
/// (B entries, rotation-row rate damping, roll/pitch restoring), with the honest standard
/// errors and with the i.i.d. ones; and the mean err_rot, err_acc, vehicle seconds.
pub fn coverage(
    sensors: &SensorConfig,
    seeds: std::ops::RangeInclusive<u64>,
) -> ([f64; 3], [f64; 3], [f64; 3]) {
    // COV_DVL: the true body velocity (a perfect DVL), for the navigation's share.
    coverage_and_worst(sensors, seeds, std::env::var_os("COV_DVL").is_some()).0
}

/// [`coverage`] and the largest |error| / honest standard error per group.
#[allow(clippy::type_complexity)]
pub fn coverage_and_worst(
    sensors: &SensorConfig,
    seeds: std::ops::RangeInclusive<u64>,
    true_velocity: bool,
) -> (([f64; 3], [f64; 3], [f64; 3]), [f64; 3]) {
    let name = "amour5";
    let (lin, restoring) = true_terms(name);
    let mut hits = [[0usize; 3]; 2];
    let mut count = [0usize; 3];
    let mut zs: [Vec<f64>; 3] = Default::default();
    let mut means = [0.0; 3];
    let runs = seeds.clone().count() as f64;
    for seed in seeds {
        let ideal = Ideal {
            true_velocity,
            ..Ideal::default()
        };
        let o = estimate_ideal(
            name,
            sensors.clone(),
            seed,
            EstimatorConfig::dynamic(),
            ideal,
        );
        means[0] += o.err_rot / runs;
        means[1] += o.err_acc / runs;
        means[2] += o.seconds / runs;
        let t = &o.terms;
        let ols_b = t.b_ols_std_err.clone();
        let mut tally = |group: usize, err: f64, se: [f64; 2]| {
            count[group] += 1;
            zs[group].push(err.abs() / se[0]);
            for (k, se) in se.iter().enumerate() {
                if err.abs() < 2.0 * se {
                    hits[k][group] += 1;
                }
            }
        };
        for (i, e) in o.b_err.iter().enumerate() {
            tally(0, *e, [o.b_se[i], ols_b[i]]);
        }
        let coef = |row: usize, term: &str| {
            let j = thrusterd_core::estimator::dynamic::regressors::TERM_NAMES
                .iter()
                .position(|n| *n == term)
                .unwrap();
            (
                t.coefficients[(row, j)],
                t.std_err[(row, j)],
                t.ols_std_err[(row, j)],
            )
        };
        for (row, rate) in [(0, "p"), (1, "q"), (2, "r")] {
            let (c, se, ols) = coef(row, rate);
            if std::env::var("COV_VERBOSE").is_ok() {
                println!(
                    "    seed {seed} {rate}: est {c:.4} true {:.4} se {se:.4} ols {ols:.4}",
                    lin[(row, 3 + row)]
                );
            }
            tally(1, c - lin[(row, 3 + row)], [se, ols]);
        }
        for (row, axis, k) in [(0, "down_y", 1), (1, "down_x", 0)] {
            let (c, se, ols) = coef(row, axis);
            if std::env::var("COV_VERBOSE").is_ok() {
                println!(
                    "    seed {seed} {axis}: est {c:.4} true {:.4} se {se:.4} ols {ols:.4}",
                    restoring[(row, k)]
                );
            }
            tally(2, c - restoring[(row, k)], [se, ols]);
        }
    }
    for (g, z) in zs.iter_mut().enumerate() {
        z.sort_by(|a, b| a.total_cmp(b));
        let q = |p: f64| z[((z.len() - 1) as f64 * p).round() as usize];
        println!(
            "  group {g}: |err|/se median {:.2}, 90 % {:.2}, 95 % {:.2}, max {:.2}",
            q(0.5),
            q(0.9),
            q(0.95),
            q(1.0)
        );
    }
    let frac = |k: usize| std::array::from_fn(|g| hits[k][g] as f64 / count[g] as f64);
    let worst = std::array::from_fn(|g| zs[g].last().copied().unwrap_or(0.0));
    ((frac(0), frac(1), means), worst)
}

/// A vehicle whose every thruster spins up with time constant `tau_s` (the daemon is not
/// told); 0 keeps the file's.
pub fn with_lag(name: &str, tau_s: f64) -> Vehicle {
    let mut v = vehicle(name);
    for t in &mut v.thrusters {
        if tau_s > 0.0 {
            t.time_constant_s = tau_s;
        }
    }
    v
}

/// The mean spin-up time constant of a vehicle's thrusters, s.
pub fn true_lag(v: &Vehicle) -> f64 {
    v.thrusters.iter().map(|t| t.time_constant_s).sum::<f64>() / v.thrusters.len() as f64
}

/// Issue 31: how a vehicle's thrusters differ from what the daemon assumes. The daemon (and
/// these tests' machine) assumes a reverse/forward thrust ratio of 0.78 (`reverse_ratio`, the
/// simulator's T200 40.2 / 51.5 N), compensates a dead band of 0.05 (`machine.deadband` here:
/// the simulator's default) and starts from a 0.1 s lag (`spin_up_s`, learned since issue
/// 29). `None` keeps the vehicle file's value; the daemon is told none of them.
#[derive(Debug, Clone, Copy, Default)]
pub struct Mismatch {
    /// Every thruster's reverse thrust at full command over its forward thrust.
    pub reverse_ratio: Option<f64>,
    /// Every thruster's dead band (fraction of full command); the machine still compensates 0.05.
    pub deadband: Option<f64>,
    /// Every thruster's spin-up time constant, s.
    pub lag_s: Option<f64>,
}

/// The thrusters as the daemon assumes them (each vehicle file's own).
pub const MATCHED: Mismatch = Mismatch {
    reverse_ratio: None,
    deadband: None,
    lag_s: None,
};

/// The cases of issue 31 item 1, with the matched vehicle first.
pub const MISMATCHES: [(&str, Mismatch); 7] = [
    ("matched", MATCHED),
    (
        "reverse 0.6",
        Mismatch {
            reverse_ratio: Some(0.6),
            ..MATCHED
        },
    ),
    (
        "reverse 0.95",
        Mismatch {
            reverse_ratio: Some(0.95),
            ..MATCHED
        },
    ),
    (
        "dead band 0",
        Mismatch {
            deadband: Some(0.0),
            ..MATCHED
        },
    ),
    (
        "dead band 0.1",
        Mismatch {
            deadband: Some(0.1),
            ..MATCHED
        },
    ),
    (
        "lag 0.05 s",
        Mismatch {
            lag_s: Some(0.05),
            ..MATCHED
        },
    ),
    (
        "lag 0.15 s",
        Mismatch {
            lag_s: Some(0.15),
            ..MATCHED
        },
    ),
];

/// The vehicle file `name` with every thruster changed as `m` says (the daemon not told).
pub fn mismatched(name: &str, m: Mismatch) -> Vehicle {
    let mut v = vehicle(name);
    for t in &mut v.thrusters {
        if let Some(r) = m.reverse_ratio {
            t.reverse_max_n = r * t.forward_max_n;
        }
        if let Some(db) = m.deadband {
            t.deadband = db;
        }
        if let Some(tau) = m.lag_s {
            t.time_constant_s = tau;
        }
    }
    v
}

/// The fraction of B's entries whose error against the symmetric truth is within 2 of the
/// model's own standard errors.
pub fn b_within_2se(o: &Outcome) -> f64 {
    let hits = o
        .b_err
        .iter()
        .zip(o.b_se.iter())
        .filter(|(e, s)| e.abs() < 2.0 * **s)
        .count();
    hits as f64 / o.b_err.len().max(1) as f64
}
