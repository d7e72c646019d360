//! Pulse power study (docs/study.md, "Pulse power"): the first estimation of each vehicle with
//! its declared geometry as the model in force, the first pulse's power fixed at
//! `initial_power` (pulse_snr = 0, the old behaviour) or chosen from the measured noise
//! (pulse_snr = 20, the default), at the paper's and a realistic IMU noise, seeds 1-3. Prints
//! the power used, the largest roll/pitch tilt during the estimation, the rotation model's
//! error against the simulator's truth and the estimation time.
//!
//! cargo run --release -p thrusterctl -- study pulse-power

use anyhow::{Context, Result};
use nalgebra::DMatrix;
use thruster_sim::{NoisePreset, SensorConfig, Simulator, Vehicle};
use thrusterd_core::machine::{Geometry, Machine, MachineSetup, Request, State};

use crate::session::config_file;

struct Outcome {
    power: f64,
    tilt_deg: f64,
    err_rot: f64,
    seconds: f64,
}

fn rel_err_rot(est: &DMatrix<f64>, truth: &DMatrix<f64>) -> f64 {
    (est.rows(0, 3) - truth.rows(0, 3)).norm() / truth.rows(0, 3).norm()
}

fn estimate_once(name: &str, noise: NoisePreset, snr: f64, seed: u64) -> Result<Outcome> {
    let path = config_file(&format!("vehicles/{name}.toml"));
    let v = Vehicle::load(&path).with_context(|| format!("loading {}", path.display()))?;
    let mut setup = MachineSetup {
        thrusters: v.thrusters.len(),
        geometry: Some(Geometry {
            positions: v.thrusters.iter().map(|t| t.position_m).collect(),
            directions: v.thrusters.iter().map(|t| t.direction).collect(),
        }),
        ..MachineSetup::default()
    };
    // No driver in between: the daemon compensates the T200 deadband itself.
    setup.machine.deadband = 0.05;
    setup.estimator.pulse_snr = snr;
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise,
        ..SensorConfig::default()
    };
    let mut sim = Simulator::new(v, sensors, seed)?;
    let mut m = Machine::new(setup);
    let tick = |m: &mut Machine, sim: &mut Simulator| -> Result<()> {
        let r = sim.advance_and_sample();
        let cmd = m.on_imu(&r);
        sim.set_commands(&cmd.thrust[..cmd.count])?;
        Ok(())
    };
    for _ in 0..200 {
        tick(&mut m, &mut sim)?;
    }
    m.on_request(Request::Estimate)
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let t0 = sim.time_s();
    let (mut tilt, mut power) = (0.0f64, 0.0f64);
    while m.state() != State::Active && sim.time_s() - t0 < 120.0 {
        tick(&mut m, &mut sim)?;
        let [r, p, _] = sim.roll_pitch_yaw();
        tilt = tilt.max(r.abs().max(p.abs()).to_degrees());
        if m.state() == State::Pulse && power == 0.0 {
            power = m.status().power;
        }
    }
    let (fwd, rev) = sim.truth();
    let truth = (fwd + rev) * 0.5;
    let err_rot = m
        .model()
        .map_or(f64::NAN, |md| rel_err_rot(&md.effectiveness, &truth));
    Ok(Outcome {
        power,
        tilt_deg: tilt,
        err_rot,
        seconds: sim.time_s() - t0,
    })
}

/// `thrusterctl study pulse-power`: the table of docs/study.md, "Pulse power".
pub fn run() -> Result<()> {
    println!("vehicle       noise      pulse_snr  power  tilt max deg  err rot  time s   (seeds 1-3, mean)");
    for name in ["amour5", "amour5_top45", "six_dof", "four_up"] {
        for noise in [NoisePreset::Paper, NoisePreset::Realistic] {
            for snr in [0.0, 20.0] {
                let runs = (1..=3)
                    .map(|seed| estimate_once(name, noise, snr, seed))
                    .collect::<Result<Vec<_>>>()?;
                let mean = |f: &dyn Fn(&Outcome) -> f64| runs.iter().map(f).sum::<f64>() / 3.0;
                println!(
                    "{name:13} {:10} {snr:9.0}  {:5.2}  {:12.0}  {:7.3}  {:6.1}",
                    format!("{noise:?}"),
                    mean(&|o| o.power),
                    mean(&|o| o.tilt_deg),
                    mean(&|o| o.err_rot),
                    mean(&|o| o.seconds),
                );
            }
        }
    }
    Ok(())
}
