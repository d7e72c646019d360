//! The dynamic-model estimator against the simulator's truth, in one process: the machine
//! drives the estimation as the daemon does, the simulator's physics answers. Noise-free
//! first (what the model can reach at all), then with the realistic IMU.

use std::path::PathBuf;

use nalgebra::{DMatrix, Matrix3, Matrix6, UnitQuaternion, Vector3};
use thruster_sim::dynamics::{fossen_to_dof_order, RigidBody};
use thruster_sim::{NoisePreset, SensorConfig, Simulator, Vehicle};
use thrusterd_core::estimator::dynamic::DynamicTerms;
use thrusterd_core::estimator::{EstimatorConfig, Method};
use thrusterd_core::machine::{ImuInput, Machine, MachineSetup, Request, State};
use thrusterd_core::navigation::{DepthAid, Navigator};

const VEHICLES: [&str; 6] = [
    "amour5",
    "amour5_top45",
    "six_dof",
    "eight_vectored",
    "four_up",
    "aligned",
];

fn vehicle(name: &str) -> Vehicle {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config/vehicles")
        .join(format!("{name}.toml"));
    Vehicle::load(&path).unwrap()
}

struct Outcome {
    err_rot: f64,
    err_acc: f64,
    seconds: f64,
    max_tilt_deg: f64,
    terms: DynamicTerms,
    rank: usize,
    actuated: usize,
}

fn tick(machine: &mut Machine, sim: &mut Simulator) {
    let r = sim.advance_and_sample();
    let cmd = machine.on_imu(&ImuInput {
        seq: 0,
        t_ns: r.t_ns,
        gyro: r.gyro,
        accel: r.accel,
        mag: Some(r.mag),
        depth: Some(r.depth),
    });
    for v in &cmd.thrust[..cmd.count] {
        assert!(v.is_finite() && v.abs() <= 1.0, "command {v}");
    }
    sim.set_commands(&cmd.thrust[..cmd.count]).unwrap();
}

fn estimate(name: &str, noise: NoisePreset, seed: u64) -> Outcome {
    let v = vehicle(name);
    let n = v.thrusters.len();
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise,
        ..SensorConfig::default()
    };
    let mut sim = Simulator::new(v, sensors, seed).unwrap();
    let mut setup = MachineSetup {
        thrusters: n,
        ..MachineSetup::default()
    };
    setup.estimator = EstimatorConfig::dynamic();
    assert_eq!(setup.estimator.method, Method::Dynamic);
    // No driver in between: the daemon compensates the T200 deadband itself.
    setup.machine.deadband = 0.05;
    let mut machine = Machine::new(setup);
    while sim.time_s() < 1.0 {
        tick(&mut machine, &mut sim);
    }
    machine.on_request(Request::Estimate).unwrap();
    let start = sim.time_s();
    let mut max_tilt = 0.0f64;
    while machine.state() != State::Active && sim.time_s() - start < 60.0 {
        tick(&mut machine, &mut sim);
        let down = sim.attitude().inverse_transform_vector(&Vector3::z());
        max_tilt = max_tilt.max(down.z.clamp(-1.0, 1.0).acos().to_degrees());
    }
    assert_eq!(machine.state(), State::Active, "{name}: no model in 60 s");
    let (f, r) = sim.truth();
    let truth = (f + r) * 0.5;
    let model = machine.model().unwrap();
    let err = |k: usize| {
        (model.effectiveness.rows(k, 3) - truth.rows(k, 3)).norm() / truth.rows(k, 3).norm()
    };
    let est = machine.last_estimate().unwrap();
    Outcome {
        err_rot: err(0),
        err_acc: err(3),
        seconds: sim.time_s() - start,
        max_tilt_deg: max_tilt,
        terms: est.dynamics.clone().expect("dynamic terms"),
        rank: est.rank.rank,
        actuated: est.rank.actuated.count(),
    }
}

/// Noise-free, every vehicle file: B within 2 % of the truth (the static model was 12-23 %
/// off here). Measured 0.014-0.017 / 0.009-0.012: what is left is the linear model of a
/// thruster that is weaker in reverse, fitted on pulses balanced by the nominal ratio.
#[test]
fn noise_free_recovery_on_every_vehicle() {
    for name in VEHICLES {
        let o = estimate(name, NoisePreset::None, 1);
        assert!(
            o.err_rot <= 0.02 && o.err_acc <= 0.02,
            "{name}: err_rot {:.4} err_acc {:.4}",
            o.err_rot,
            o.err_acc
        );
        assert!(o.max_tilt_deg <= 30.0, "{name}: tilt {:.1}", o.max_tilt_deg);
        assert!(o.seconds <= 6.0, "{name}: {:.1} s", o.seconds);
    }
}

/// The aligned vehicle (every thruster along x) actuates fewer DOFs; the dynamic fit must not
/// invent any.
#[test]
fn a_rank_deficient_vehicle_reports_only_its_dofs() {
    let o = estimate("aligned", NoisePreset::Realistic, 1);
    let v = vehicle("aligned");
    let rb = RigidBody::new(&v.body).unwrap();
    let (f, r) = thruster_sim::effectiveness(rb.mass_matrix_inverse(), &v.thrusters);
    let true_rank = thruster_sim::rank(&((f + r) * 0.5), 1e-6);
    assert_eq!(o.rank, true_rank);
    assert_eq!(o.actuated, true_rank);
}

/// Realistic IMU, AMOUR-5, seeds 1-3: within the issue's targets (0.03 / 0.05 in 6 vehicle-s;
/// measured 0.016 / 0.019 in 4.2 s over 5 seeds).
#[test]
fn realistic_imu_amour5_is_accurate_and_quick() {
    for seed in 1..=3 {
        let o = estimate("amour5", NoisePreset::Realistic, seed);
        assert!(
            o.err_rot <= 0.03 && o.err_acc <= 0.05 && o.seconds <= 6.0,
            "seed {seed}: {:.4} / {:.4} in {:.1} s",
            o.err_rot,
            o.err_acc,
            o.seconds
        );
    }
}

/// The simulator's own coefficients in the dynamic model's form (DOF-order rows): how the rate
/// terms p, q, r (linear damping) and gravity's direction (restoring) enter nu_dot.
fn true_terms(name: &str) -> (Matrix6<f64>, nalgebra::Matrix6x3<f64>) {
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

/// What the fit learns besides B is the vehicle's: the roll and pitch restoring coefficients
/// within 10 % of the simulator's (measured roll 1.1 %, pitch 8.5 %), the rate damping within 30 %,
/// noise-free.
#[test]
fn restoring_and_damping_coefficients_match_the_simulator() {
    let name = "amour5";
    let (lin, restoring) = true_terms(name);
    let o = estimate(name, NoisePreset::None, 1);
    for (row, axis, rate) in [(0, "down_y", "p"), (1, "down_x", "q"), (2, "down_x", "r")] {
        let (c, se) = o.terms.get(row, rate).unwrap();
        let col = 3 + ["p", "q", "r"].iter().position(|n| *n == rate).unwrap();
        let t = lin[(row, col)];
        assert!(
            // Damping is only loosely identified: the fit trades the linear term against |p|p,
            // p^2 and the thrusters' asymmetry (measured 9 % off on roll; docs/study.md).
            c.signum() == t.signum() && (c - t).abs() <= 0.3 * t.abs(),
            "row {row} {rate}: learned {c:.4} +- {se:.4}, true {t:.4}"
        );
        if row < 2 {
            let (c, se) = o.terms.get(row, axis).unwrap();
            let k = ["down_x", "down_y", "down_z"]
                .iter()
                .position(|n| *n == axis)
                .unwrap();
            let t = restoring[(row, k)];
            assert!(
                (c - t).abs() <= 0.1 * t.abs(),
                "row {row} {axis}: learned {c:.4} +- {se:.4}, true {t:.4}"
            );
        }
    }
}

/// Drives AMOUR-5 through 4 s of alternating +-,-+ pulses at `power` after a 2 s rest, with
/// the navigation fed the IMU (and the DVL's fixes when `with_dvl`); the worst velocity error
/// against the simulator's truth, the worst attitude error (deg) and the peak true speed.
fn navigation_errors(
    sensors: SensorConfig,
    seed: u64,
    power: f64,
    with_dvl: bool,
) -> (f64, f64, f64) {
    let v = vehicle("amour5");
    let n = v.thrusters.len();
    let mut sim = Simulator::new(v, sensors, seed).unwrap();
    // A rest first, as the daemon's noise measurement: the mean specific force is -g.
    let mut rest = Vector3::zeros();
    let mut r0 = sim.advance_and_sample();
    for _ in 0..400 {
        r0 = sim.advance_and_sample();
        rest += Vector3::from(r0.accel) / 400.0;
    }
    // The filter starts at zero velocity (no DVL at rest); so does the body here (it is not
    // exactly neutrally buoyant and drifts during the rest).
    let mut state = *sim.state();
    state.nu = nalgebra::Vector6::zeros();
    sim.set_state(state);
    let mut nav = Navigator::at_rest(&rest, 0.0, Some(r0.depth), DepthAid::default());
    let (mut worst_v, mut worst_att, mut peak_v) = (0.0f64, 0.0f64, 0.0f64);
    for k in 0..800 {
        let sign = if matches!(k / 20 % 4, 0 | 3) {
            1.0
        } else {
            -1.0
        };
        let u: Vec<f64> = (0..n)
            .map(|i| {
                if (i + k / 80) % 2 == 0 {
                    power * sign
                } else {
                    -power * sign
                }
            })
            .collect();
        sim.set_commands(&u).unwrap();
        let r = sim.advance_and_sample();
        if let Some(d) = sim.dvl_measurement() {
            if with_dvl {
                nav.velocity_fix(&d);
            }
        }
        let s = nav.update(
            r.t_ns as f64 * 1e-9,
            &Vector3::from(r.gyro),
            &Vector3::from(r.accel),
            Some(r.depth),
        );
        worst_v = worst_v.max((s.velocity - sim.linear_velocity()).norm());
        worst_att = worst_att.max(s.attitude.angle_to(&sim.attitude()).to_degrees());
        peak_v = peak_v.max(sim.linear_velocity().norm());
    }
    (worst_v, worst_att, peak_v)
}

/// The navigation filter against the simulator's true velocity and attitude through a
/// doublet-pair excitation (noise-free: the dead reckoning itself).
#[test]
fn navigation_follows_the_true_velocity() {
    let (worst_v, worst_att, peak_v) = navigation_errors(SensorConfig::ideal(200.0), 1, 0.8, false);
    assert!(
        peak_v > 0.1,
        "the excitation moved the vehicle ({peak_v:.3} m/s)"
    );
    assert!(worst_att < 0.5, "attitude off by {worst_att:.3} deg");
    // Measured 0.038 m/s at a 0.76 m/s peak: dead reckoning at 200 Hz through a tumble.
    assert!(
        worst_v < 0.08 * peak_v,
        "velocity off by {worst_v:.4} m/s (peak {peak_v:.3})"
    );
}

/// A non-finite sample in the middle of the excitation is dropped; the model is the one a
/// clean run gives.
#[test]
fn a_non_finite_sample_mid_excitation_changes_nothing() {
    use thrusterd_core::estimator::{Estimator, NoiseLevels};
    let mk = || {
        Estimator::new(
            EstimatorConfig::dynamic(),
            2,
            NoiseLevels::isotropic(0.01, 0.01),
        )
        .with_rest_specific_force(Vector3::new(0.0, 0.0, -9.80665))
    };
    let feed = |e: &mut Estimator, poison: bool| {
        for p in 0..40 {
            let t0 = p as f64 * 0.1;
            e.begin_pulse_at(t0);
            let u = e.current_command().unwrap().to_vec();
            for k in 1..=20 {
                let t = t0 + k as f64 * 0.005;
                let w = Vector3::new(0.3 * u[0] * (t - t0), -0.2 * u[1] * (t - t0), 0.0);
                let f = Vector3::new(0.5 * u[0], 0.0, -9.80665 + 0.1 * u[1]);
                e.push_dynamic_sample(t, &w, &f, Some(5.0));
                if poison && p == 17 && k == 5 {
                    e.push_dynamic_sample(
                        t + 0.001,
                        &Vector3::new(f64::NAN, 0.0, 0.0),
                        &f,
                        Some(5.0),
                    );
                    e.push_dynamic_sample(
                        t + 0.002,
                        &w,
                        &Vector3::new(0.0, f64::INFINITY, 0.0),
                        None,
                    );
                }
            }
            e.end_pulse();
        }
    };
    let (mut a, mut b) = (mk(), mk());
    feed(&mut a, false);
    feed(&mut b, true);
    let (ea, eb) = (a.estimate(), b.estimate());
    assert!(ea.effectiveness.iter().all(|v| v.is_finite()));
    assert_eq!(ea.effectiveness, eb.effectiveness);
    let _: &DMatrix<f64> = &eb.std_err;
}

/// At the paper's IMU noise the dead-reckoned velocity drifts; a DVL (5 Hz, 0.01 m/s), when
/// the vehicle has one, holds it to the truth. Measured against the simulator's true velocity
/// over the same 4 s doublet excitation, with and without the DVL: measured 0.58 m/s worst
/// dead-reckoned, 0.10 m/s with the DVL.
#[test]
fn a_dvl_bounds_the_velocity_drift_at_the_papers_noise() {
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise: NoisePreset::Paper,
        dvl: Some(thruster_sim::DvlConfig::default()),
        ..SensorConfig::default()
    };
    let (without, _, _) = navigation_errors(sensors.clone(), 4, 0.6, false);
    let (with, _, _) = navigation_errors(sensors, 4, 0.6, true);
    println!("worst velocity error: {without:.3} m/s dead-reckoned, {with:.3} m/s with the DVL");
    assert!(with < 0.15, "with the DVL {with:.3} m/s");
    assert!(
        with < 0.3 * without,
        "with {with:.3} vs without {without:.3} m/s"
    );
}
