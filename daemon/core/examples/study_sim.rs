//! The estimation methods against the simulator's truth, in one process: the machine drives the
//! simulator's physics as the daemon does (1 s at rest, then `estimate`), for every vehicle file
//! x noise preset x method x seed. CSV rows on stdout, means on stderr (docs/study.md).
//!
//! `cargo run --release -p thrusterd-core --example study_sim -- NOISES METHODS SEEDS [VEHICLES]`
//! with comma lists, e.g. `none,realistic,paper dynamic,forward,paper 5`. Dynamic runs with the
//! default settings, forward and paper with `EstimatorConfig::forward()` (paper: round robin).
//! TARGET, POWER and MAXP in the environment override the bound, power and pulse limit.
use nalgebra::DMatrix;
use thruster_sim::{NoisePreset, SensorConfig, Simulator, Vehicle};
use thrusterd_core::estimator::Method;
use thrusterd_core::machine::{ImuInput, Machine, MachineSetup, Request, State};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let noises: Vec<&str> = args
        .get(1)
        .map(|s| s.split(',').collect())
        .unwrap_or(vec!["none"]);
    let methods: Vec<&str> = args
        .get(2)
        .map(|s| s.split(',').collect())
        .unwrap_or(vec!["dynamic"]);
    let seeds: u64 = args.get(3).map(|s| s.parse().unwrap()).unwrap_or(1);
    let vehicles: Vec<&str> = args.get(4).map(|s| s.split(',').collect()).unwrap_or(vec![
        "amour5",
        "amour5_top45",
        "six_dof",
        "eight_vectored",
        "four_up",
        "aligned",
    ]);
    let target: Option<f64> = std::env::var("TARGET").ok().map(|s| s.parse().unwrap());
    println!("vehicle,noise,method,seed,err_rot,err_acc,seconds,pulses,tilt_deg,heading_deg,bound_rot,bound_acc");
    for v in &vehicles {
        for nz in &noises {
            for m in &methods {
                let (mut a, mut b, mut c, mut d) = (0.0, 0.0, 0.0, 0.0f64);
                for seed in 1..=seeds {
                    let r = run(v, nz, m, seed, target);
                    println!(
                        "{v},{nz},{m},{seed},{:.4},{:.4},{:.2},{},{:.1},{:.1},{:.4},{:.4}",
                        r.0, r.1, r.2, r.3, r.4, r.5, r.6, r.7
                    );
                    a += r.0;
                    b += r.1;
                    c += r.2;
                    d = d.max(r.4);
                }
                let k = seeds as f64;
                eprintln!("MEAN {v:15} {nz:9} {m:8} err_rot {:.4} err_acc {:.4} secs {:.1} max_tilt {:.1}", a / k, b / k, c / k, d);
            }
        }
    }
}

fn run(
    name: &str,
    noise: &str,
    method: &str,
    seed: u64,
    target: Option<f64>,
) -> (f64, f64, f64, usize, f64, f64, f64, f64) {
    let path = format!(
        "{}/../../config/vehicles/{name}.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let v = Vehicle::load(std::path::Path::new(&path)).unwrap();
    let n = v.thrusters.len();
    let noise = match noise {
        "paper" => NoisePreset::Paper,
        "realistic" => NoisePreset::Realistic,
        _ => NoisePreset::None,
    };
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
    setup.machine.deadband = 0.05;
    setup.estimator = if method == "dynamic" {
        thrusterd_core::estimator::EstimatorConfig::dynamic()
    } else {
        thrusterd_core::estimator::EstimatorConfig::forward()
    };
    setup.estimator.method = match method {
        "paper" => Method::Paper,
        "forward" => Method::Forward,
        _ => Method::Dynamic,
    };
    if method != "dynamic" {
        setup.estimator.excitation = match method {
            "paper" => thrusterd_core::estimator::Excitation::RoundRobin,
            _ => thrusterd_core::estimator::Excitation::Orthogonal,
        };
    }
    if let Some(t) = target {
        setup.estimator.target_rel_err = t;
    }
    if let Ok(p) = std::env::var("POWER") {
        setup.estimator.initial_power = p.parse().unwrap();
    }
    if let Ok(p) = std::env::var("MAXP") {
        setup.estimator.max_pulses = p.parse().unwrap();
    }
    let mut machine = Machine::new(setup);
    let tick = |machine: &mut Machine, sim: &mut Simulator| {
        let r = sim.advance_and_sample();
        let cmd = machine.on_imu(&ImuInput {
            seq: 0,
            t_ns: r.t_ns,
            gyro: r.gyro,
            accel: r.accel,
            mag: Some(r.mag),
            depth: Some(r.depth),
        });
        sim.set_commands(&cmd.thrust[..cmd.count]).unwrap();
    };
    while sim.time_s() < 1.0 {
        tick(&mut machine, &mut sim);
    }
    machine.on_request(Request::Estimate).unwrap();
    let start = sim.time_s();
    let mut tilt = 0.0f64;
    let mut heading = 0.0f64;
    let yaw0 = sim.roll_pitch_yaw()[2];
    while sim.time_s() - start < 120.0 {
        tick(&mut machine, &mut sim);
        let rpy = sim.roll_pitch_yaw();
        let down = sim
            .attitude()
            .inverse_transform_vector(&nalgebra::Vector3::z());
        tilt = tilt.max(down.z.clamp(-1.0, 1.0).acos().to_degrees());
        let dy = rpy[2] - yaw0;
        heading = heading.max(dy.sin().atan2(dy.cos()).abs().to_degrees());
        if machine.state() == State::Active || machine.state() == State::Idle {
            break;
        }
    }
    let secs = sim.time_s() - start;
    let (f, r) = sim.truth();
    let truth: DMatrix<f64> = (f + r) * 0.5;
    let model = machine.model().expect("model");
    let e = |k: usize| {
        (model.effectiveness.rows(k, 3) - truth.rows(k, 3)).norm() / truth.rows(k, 3).norm()
    };
    let est = machine.last_estimate().unwrap();
    (
        e(0),
        e(3),
        secs,
        est.pulses,
        tilt,
        heading,
        est.rel_err_rot,
        est.rel_err_acc,
    )
}
