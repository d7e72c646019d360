//! Physics checks of the simulator: passive stability, energy, thrust response, sensors.

use std::path::PathBuf;

use nalgebra::{UnitQuaternion, Vector3, Vector6};
use thruster_sim::dynamics::fossen_to_dof_order;
use thruster_sim::{
    Body, Dof6, InitialState, NoisePreset, SensorConfig, SimOptions, Simulator, ThrusterSpec,
    Vehicle,
};

fn vehicles_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../config/vehicles")
}

fn load(name: &str) -> Vehicle {
    let path = vehicles_dir().join(format!("{name}.toml"));
    Vehicle::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

fn options_with(initial: InitialState) -> SimOptions {
    SimOptions {
        initial,
        ..SimOptions::default()
    }
}

fn tilted(roll_deg: f64, pitch_deg: f64) -> InitialState {
    InitialState {
        attitude_rpy_deg: [roll_deg, pitch_deg, 30.0],
        ..InitialState::default()
    }
}

fn no_damping(mut body: Body) -> Body {
    let zero = Dof6 {
        surge: 0.0,
        sway: 0.0,
        heave: 0.0,
        roll: 0.0,
        pitch: 0.0,
        yaw: 0.0,
    };
    body.linear_damping = zero;
    body.quadratic_damping = zero;
    body
}

/// Terminal heave speed (m/s, negative = rising) of a body with net buoyancy, from
/// d_l w + d_q w^2 = B - W.
fn terminal_rise_speed(body: &Body) -> f64 {
    let net = body.buoyancy_n - body.weight_n();
    let (a, b) = (body.quadratic_damping.heave, body.linear_damping.heave);
    -(-b + (b * b + 4.0 * a * net).sqrt()) / (2.0 * a)
}

#[test]
fn tilted_free_vehicle_rights_itself_and_comes_to_rest() {
    let vehicle = load("four_up");
    let body = vehicle.body.clone();
    let mut sim = Simulator::with_options(
        vehicle,
        SensorConfig::ideal(100.0),
        1,
        options_with(tilted(20.0, 0.0)),
    )
    .expect("valid");
    sim.step_secs(60.0);
    let [roll, pitch, _] = sim.roll_pitch_yaw();
    assert!(roll.to_degrees().abs() < 0.5, "roll {}", roll.to_degrees());
    assert!(
        pitch.to_degrees().abs() < 0.5,
        "pitch {}",
        pitch.to_degrees()
    );
    assert!(
        sim.angular_velocity().norm() < 1e-3,
        "{}",
        sim.angular_velocity()
    );
    let v = sim.linear_velocity();
    assert!(v.x.abs() < 1e-3 && v.y.abs() < 1e-3, "{v}");
    // The vehicle is 2 N buoyant (there is no free surface): it rises at its terminal speed.
    let w_term = terminal_rise_speed(&body);
    assert!(
        (v.z - w_term).abs() < 1e-3 * w_term.abs(),
        "w {} vs {w_term}",
        v.z
    );
    assert!(sim.acceleration().norm() < 1e-4);
}

#[test]
fn tilted_in_roll_and_pitch_neutral_body_comes_to_rest() {
    let mut vehicle = load("amour5");
    vehicle.body.buoyancy_n = vehicle.body.weight_n();
    let mut sim = Simulator::with_options(
        vehicle,
        SensorConfig::ideal(100.0),
        1,
        options_with(tilted(14.0, -14.0)),
    )
    .expect("valid");
    sim.step_secs(60.0);
    let [roll, pitch, _] = sim.roll_pitch_yaw();
    assert!(roll.to_degrees().abs() < 0.5 && pitch.to_degrees().abs() < 0.5);
    let nu = sim.state().nu;
    assert!(nu.norm() < 1e-3, "{nu}");
}

#[test]
fn energy_never_increases_with_damping() {
    let vehicle = load("amour5");
    let initial = InitialState {
        attitude_rpy_deg: [25.0, -15.0, 0.0],
        linear_mps: [0.3, -0.2, 0.1],
        angular_radps: [0.5, -0.4, 0.8],
        ..InitialState::default()
    };
    let mut sim = Simulator::with_options(
        vehicle,
        SensorConfig::ideal(100.0),
        1,
        options_with(initial),
    )
    .expect("valid");
    let e0 = sim.energy();
    let mut prev = e0;
    for _ in 0..20_000 {
        sim.step(1_000_000);
        let e = sim.energy();
        // RK4 at 1 kHz: per-step error far below a microjoule.
        assert!(
            e <= prev + 1e-9,
            "energy rose by {} at t = {}",
            e - prev,
            sim.time_s()
        );
        prev = e;
    }
    assert!(prev < e0 - 0.1, "damping should dissipate: {e0} -> {prev}");
}

fn assert_energy_conserved(body: Body, initial: InitialState) {
    let mut vehicle = load("six_dof");
    vehicle.body = body;
    let mut sim = Simulator::with_options(
        vehicle,
        SensorConfig::ideal(100.0),
        1,
        options_with(initial),
    )
    .expect("valid");
    let e0 = sim.energy();
    let kinetic0 = 0.5
        * sim
            .state()
            .nu
            .dot(&(sim.body().mass_matrix() * sim.state().nu));
    let mut worst: f64 = 0.0;
    for _ in 0..100 {
        sim.step_secs(0.1);
        worst = worst.max((sim.energy() - e0).abs());
    }
    assert!(
        worst < 1e-7 * kinetic0.max(1.0),
        "energy drift {worst} J (kinetic {kinetic0} J)"
    );
}

#[test]
fn energy_is_conserved_without_damping() {
    let moving = InitialState {
        attitude_rpy_deg: [10.0, 5.0, 0.0],
        linear_mps: [0.4, -0.3, 0.2],
        angular_radps: [1.0, -0.7, 1.5],
        ..InitialState::default()
    };
    // Neutral, CB at the CG: only the inertial (Coriolis/Munk) terms act.
    let mut neutral = no_damping(Body::bluerov2());
    neutral.buoyancy_n = neutral.weight_n();
    neutral.cb_m = neutral.cg_m;
    assert_energy_conserved(neutral, moving.clone());
    // With the restoring pendulum and net buoyancy: still conservative.
    assert_energy_conserved(no_damping(Body::bluerov2()), moving);
}

#[test]
fn known_thrust_gives_the_predicted_acceleration() {
    for (name, index) in [
        ("amour5", 0),
        ("amour5", 3),
        ("six_dof", 5),
        ("eight_vectored", 0),
    ] {
        let vehicle = load(name);
        let n = vehicle.thrusters.len();
        let mut commands = vec![0.0; n];
        for (u, col_of) in [(1.0, 0usize), (-1.0, 1)] {
            let mut sim =
                Simulator::new(vehicle.clone(), SensorConfig::ideal(100.0), 1).expect("valid");
            let mut idle =
                Simulator::new(vehicle.clone(), SensorConfig::ideal(100.0), 1).expect("valid");
            commands[index] = u;
            sim.set_commands(&commands).expect("count");
            sim.settle_thrusters();
            let truth = sim.truth();
            let b = if col_of == 0 { &truth.0 } else { &truth.1 };
            let column = Vector6::from_iterator(b.column(index).iter().map(|x| x * u));
            // Exact model acceleration at rest, minus what buoyancy alone does.
            let a = fossen_to_dof_order(&(sim.acceleration() - idle.acceleration()));
            let err = (a - column).norm();
            assert!(
                err < 1e-9 * column.norm(),
                "{name}[{index}] u={u}: {a} vs {column}"
            );
            // Integrated: the mean acceleration over the first millisecond.
            sim.step(1_000_000);
            idle.step(1_000_000);
            let dv = fossen_to_dof_order(&((sim.state().nu - idle.state().nu) / 1e-3));
            let err = (dv - column).norm();
            assert!(
                err < 2e-3 * column.norm(),
                "{name}[{index}] u={u}: {dv} vs {column}"
            );
        }
    }
}

#[test]
fn thrust_builds_up_with_the_spin_up_lag() {
    let vehicle = load("four_up");
    let mut sim = Simulator::new(vehicle, SensorConfig::ideal(100.0), 1).expect("valid");
    sim.set_commands(&[1.0, 1.0, 1.0, 1.0]).expect("count");
    assert_eq!(sim.thrusts_n(), vec![0.0; 4]);
    sim.step_secs(0.1);
    let expected = 51.485 * (1.0 - (-1.0f64).exp());
    for f in sim.thrusts_n() {
        assert!((f - expected).abs() < 0.01, "{f} vs {expected}");
    }
    // Commands are sanitised: a NaN stops the thruster, overdrive saturates.
    sim.set_commands(&[f64::NAN, 7.0, -7.0, 0.02])
        .expect("count");
    assert_eq!(sim.commands(), vec![0.0, 1.0, -1.0, 0.02]);
    assert!(sim.set_commands(&[0.0; 3]).is_err());
    assert_eq!(sim.commands(), vec![0.0, 1.0, -1.0, 0.02]);
}

#[test]
fn accelerometer_at_rest_reads_gravity_as_specific_force() {
    // Neutral, with CG and CB at the CO: no restoring force or moment, so a still vehicle
    // stays still in any attitude.
    let mut vehicle = load("amour5");
    vehicle.body.buoyancy_n = vehicle.body.weight_n();
    vehicle.body.cg_m = [0.0; 3];
    vehicle.body.cb_m = [0.0; 3];
    let mut sim = Simulator::new(vehicle.clone(), SensorConfig::ideal(200.0), 1).expect("valid");
    let r = sim.advance_and_sample();
    assert_eq!(r.t_ns, 5_000_000);
    let g = vehicle.body.gravity_mps2;
    assert!(
        (Vector3::from(r.accel) - Vector3::new(0.0, 0.0, -g)).norm() < 1e-9,
        "{:?}",
        r.accel
    );
    assert!(Vector3::from(r.gyro).norm() < 1e-12);
    assert!((r.depth.unwrap() - 30.0).abs() < 1e-9);
    assert!((Vector3::from(r.mag.unwrap()) - Vector3::new(20.0, 0.0, 45.0)).norm() < 1e-9);
    // Tilted and still, it reads -R^T g.
    let q = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0);
    let mut state = *sim.state();
    state.attitude = q;
    state.nu = Vector6::zeros();
    sim.set_state(state);
    let r = sim.ideal_sample();
    let expect = -(q.inverse_transform_vector(&Vector3::new(0.0, 0.0, g)));
    assert!((Vector3::from(r.accel) - expect).norm() < 1e-9);
}

fn sample_std(values: &[f64]) -> f64 {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
}

#[test]
fn noise_presets_have_their_stated_std() {
    for preset in [NoisePreset::Realistic, NoisePreset::Paper] {
        let mut vehicle = load("amour5");
        vehicle.body.buoyancy_n = vehicle.body.weight_n();
        let sensors = SensorConfig {
            rate_hz: 1000.0,
            noise: preset,
            ..SensorConfig::default()
        };
        let params = sensors.noise_params();
        let mut sim = Simulator::new(vehicle, sensors, 11).expect("valid");
        let mut gyro = vec![Vec::new(); 3];
        let mut accel = vec![Vec::new(); 3];
        let mut mag = Vec::new();
        let mut depth = Vec::new();
        for _ in 0..20_000 {
            let r = sim.advance_and_sample();
            let ideal = sim.ideal_sample();
            let b = *sim.sensor_biases();
            for i in 0..3 {
                gyro[i].push(r.gyro[i] - ideal.gyro[i] - b.gyro[i]);
                accel[i].push(r.accel[i] - ideal.accel[i] - b.accel[i]);
            }
            mag.push(r.mag.unwrap()[0] - ideal.mag.unwrap()[0] - b.mag[0]);
            depth.push(r.depth.unwrap() - ideal.depth.unwrap());
        }
        // 20 000 samples: the std estimate has a relative sd of 0.5 %; allow 3 %.
        let close = |est: f64, want: f64, what: &str| {
            assert!(
                (est / want - 1.0).abs() < 0.03,
                "{preset:?} {what}: {est} vs {want}"
            );
        };
        for i in 0..3 {
            close(sample_std(&gyro[i]), params.gyro_std_radps, "gyro");
            close(sample_std(&accel[i]), params.accel_std_mps2, "accel");
        }
        close(sample_std(&mag), params.mag_std_ut, "mag");
        close(sample_std(&depth), params.depth_std_m, "depth");
    }
    assert_eq!(NoisePreset::Paper.params().gyro_std_radps, 0.25);
    assert!((NoisePreset::Paper.params().accel_std_mps2 - 0.05 * 9.80665).abs() < 1e-12);
}

#[test]
fn no_noise_preset_is_exact() {
    let vehicle = load("four_up");
    let mut sim = Simulator::new(vehicle, SensorConfig::ideal(100.0), 3).expect("valid");
    sim.set_commands(&[0.5, -0.5, 0.2, 0.0]).expect("count");
    for _ in 0..50 {
        let r = sim.advance_and_sample();
        assert_eq!(r, sim.ideal_sample());
    }
}

fn run(seed: u64) -> Vec<thruster_protocol::ImuReading> {
    let vehicle = load("amour5_top45");
    let sensors = SensorConfig {
        noise: NoisePreset::Realistic,
        ..SensorConfig::default()
    };
    let mut sim = Simulator::new(vehicle, sensors, seed).expect("valid");
    (0..300)
        .map(|k| {
            let u = if (k / 50) % 2 == 0 { 0.6 } else { -0.6 };
            sim.set_commands(&[u, 0.0, 0.0, -u, 0.3]).expect("count");
            sim.advance_and_sample()
        })
        .collect()
}

#[test]
fn same_seed_same_run() {
    let a = run(5);
    let b = run(5);
    let c = run(6);
    assert_eq!(a, b);
    assert_ne!(a, c);
}

#[test]
fn inner_rate_is_configurable_and_converges() {
    let vehicle = load("six_dof");
    let go = |rate: f64| {
        let opts = SimOptions {
            integration_rate_hz: rate,
            ..SimOptions::default()
        };
        let mut sim = Simulator::with_options(vehicle.clone(), SensorConfig::ideal(100.0), 1, opts)
            .expect("valid");
        sim.set_commands(&[0.8, -0.3, 0.5, 1.0, -1.0, 0.7])
            .expect("count");
        sim.step_secs(3.0);
        sim.state().nu
    };
    let a = go(1000.0);
    let b = go(4000.0);
    assert!((a - b).norm() < 1e-6 * a.norm(), "{a} vs {b}");
    let low = SimOptions {
        integration_rate_hz: 500.0,
        ..SimOptions::default()
    };
    assert!(Simulator::with_options(vehicle, SensorConfig::default(), 1, low).is_err());
}

/// The bounds of `[sim.initial]` and `[sim.disturbance]` are safe for the physics: every
/// shipped vehicle started at their corners, in the strongest current and forcing, at full
/// thrust, stays finite.
#[test]
fn every_vehicle_stays_finite_at_the_limits_of_the_start_and_the_water() {
    use thruster_sim::disturbance::{TetherConfig, MAX_CURRENT_MPS, MAX_FORCING};
    use thruster_sim::WaveComponent;
    let limits = |sign: f64| SimOptions {
        initial: InitialState {
            position_ned_m: [1e6 * sign, -1e6 * sign, 11_000.0],
            attitude_rpy_deg: [360.0 * sign, -360.0, 360.0],
            linear_mps: [10.0 * sign, -10.0, 10.0],
            angular_radps: [50.0 * sign, -50.0, 50.0],
        },
        disturbance: thruster_sim::DisturbanceConfig {
            current_ned_mps: [MAX_CURRENT_MPS * sign, -MAX_CURRENT_MPS, MAX_CURRENT_MPS],
            waves: vec![WaveComponent {
                frequency_hz: 10.0,
                phase_rad: 0.0,
                force_ned_n: [MAX_FORCING * sign, MAX_FORCING, -MAX_FORCING],
                torque_body_nm: [MAX_FORCING, -MAX_FORCING * sign, MAX_FORCING],
            }],
            tether: Some(TetherConfig {
                attach_m: [10.0 * sign, -10.0, 10.0],
                pull_ned_n: [MAX_FORCING, MAX_FORCING * sign, -MAX_FORCING],
                vary_ned_n: [MAX_FORCING; 3],
                period_s: 0.1,
            }),
        },
        ..SimOptions::default()
    };
    for entry in std::fs::read_dir(vehicles_dir()).expect("config/vehicles") {
        let path = entry.expect("entry").path();
        let vehicle = Vehicle::load(&path).unwrap_or_else(|e| panic!("{e}"));
        let n = vehicle.thrusters.len();
        for (sign, u) in [(1.0, 1.0), (-1.0, -1.0)] {
            let mut sim =
                Simulator::with_options(vehicle.clone(), SensorConfig::default(), 1, limits(sign))
                    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            sim.set_commands(&vec![u; n]).expect("count");
            for _ in 0..200 {
                assert!(
                    sim.advance_and_sample().is_finite(),
                    "{} diverged at t = {} s",
                    path.display(),
                    sim.time_s()
                );
            }
        }
    }
}

#[test]
fn current_carries_the_vehicle_along() {
    let mut vehicle = load("four_up");
    vehicle.body.buoyancy_n = vehicle.body.weight_n();
    let mut opts = SimOptions::default();
    opts.disturbance.current_ned_mps = [0.2, 0.0, 0.0];
    // Heading east, so the current is on the vehicle's port side.
    opts.initial.attitude_rpy_deg = [0.0, 0.0, 90.0];
    let mut sim =
        Simulator::with_options(vehicle, SensorConfig::ideal(100.0), 1, opts).expect("valid");
    sim.step_secs(60.0);
    let v_ned = sim.attitude() * sim.linear_velocity();
    assert!(
        (v_ned - Vector3::new(0.2, 0.0, 0.0)).norm() < 2e-3,
        "{v_ned}"
    );
}

#[test]
fn dead_reversed_and_added_thrusters_in_truth() {
    let mut vehicle = load("aligned");
    vehicle
        .thrusters
        .push(ThrusterSpec::new("X", [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]));
    vehicle.thrusters[5].dead = true;
    let sim = Simulator::new(vehicle, SensorConfig::ideal(100.0), 1).expect("valid");
    let (f, _) = sim.truth();
    assert_eq!(f.column(5).norm(), 0.0);
    // L (reversed) surges backwards for a positive command, R forwards.
    assert!(f[(3, 3)] < 0.0 && f[(3, 4)] > 0.0);
}
