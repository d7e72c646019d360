//! The under-control fit's own floor against the truth: a vehicle held through the pitch steps
//! of the refinement's tests, noise-free, and beside the machine a closed-loop fit fed exactly
//! what a refinement window is fed (the sent command in model units, the gyro, the specific
//! force, the depth), ended every few seconds and compared with the simulator's truth. The
//! simulator's thrusters can be made ideal one property at a time, so the run names which of
//! them the fit's ~1 % floor comes from (issue 29: the refinement dragging an exact model).

use nalgebra::Vector3;
use thruster_inprocess::model_update::pitch_step;
use thruster_inprocess::run::{operator_deadband, rel_err, vehicle, Run};
use thruster_sim::NoisePreset;
use thrusterd_core::estimator::dynamic::spin_state::SpinState;
use thrusterd_core::estimator::response::GRAVITY;
use thrusterd_core::estimator::{Estimator, EstimatorConfig, NoiseLevels};

/// `WF_VEHICLES` (comma-separated file stems; default amour5,eight_vectored,six_dof),
/// `WF_VARIANTS` (comma-separated: `file` as the file has it, `sym` reverse thrust equal to
/// forward, the thrust's shape out of the question; default both), `WF_WINDOW_S`
/// (each fit's length, default 10), `WF_SECONDS` (default 60), `WF_SHAPED=1` the machine's
/// open-loop estimation fits the thrust's shape (`estimator.shaped_thrust`), `WF_NOISE`
/// (none|realistic|paper, default none), `WF_SEED` (default 1), `WF_DVL=1` the fit is given
/// the true body velocity at every sample (a perfect DVL: the decisive run for the
/// navigation's share), `WF_DVL_START=1` the true velocity at the window's start only,
/// `WF_TRUE_THRUST=1` the simulator's thrust at every sample in place of
/// the commands and their lag (the decisive run for the thrust's share), `WF_COLD=1` each
/// window's lags start from rest (as before `SpinState`), `WF_OPEN=a` pseudo-random commands
/// within +-a in place of the controller's, `WF_DITHER` the refinement's dither, `WF_RATE` the
/// IMU's rate (Hz, default 200), `WF_LAG` the windows' lag (s), `WF_DETAIL=1` each window's
/// per-thruster errors and residuals.
pub(super) fn window_floor() {
    let list = |k: &str, d: &str| -> Vec<String> {
        std::env::var(k)
            .unwrap_or_else(|_| d.into())
            .split(',')
            .map(str::to_string)
            .collect()
    };
    let num = |k: &str, d: f64| {
        std::env::var(k).ok().map_or(d, |v| {
            v.parse().unwrap_or_else(|_| panic!("{k} is a number"))
        })
    };
    let shaped = std::env::var_os("WF_SHAPED").is_some();
    let dvl = std::env::var_os("WF_DVL").is_some();
    let window_s = num("WF_WINDOW_S", 10.0);
    let seconds = num("WF_SECONDS", 60.0);
    let seed = num("WF_SEED", 1.0) as u64;
    let noise = match std::env::var("WF_NOISE").as_deref() {
        Ok("realistic") => NoisePreset::Realistic,
        Ok("paper") => NoisePreset::Paper,
        _ => NoisePreset::None,
    };
    for name in list("WF_VEHICLES", "amour5,eight_vectored,six_dof") {
        for variant in list("WF_VARIANTS", "file,sym") {
            let (model, windows) = fly(
                &name,
                &variant,
                (shaped, dvl),
                window_s,
                seconds,
                noise,
                seed,
            );
            let w: Vec<String> = windows
                .iter()
                .map(|(r, a, b)| format!("{r:.4}/{a:.4} ({b:.3})"))
                .collect();
            let mean = |k: usize| {
                windows
                    .iter()
                    .map(|w| if k == 0 { w.0 } else { w.1 })
                    .sum::<f64>()
                    / windows.len().max(1) as f64
            };
            println!(
                "{name} {variant}: model {:.4}/{:.4}; windows mean {:.4}/{:.4}: {}",
                model.0,
                model.1,
                mean(0),
                mean(1),
                w.join(" ")
            );
        }
    }
}

/// The vehicle `name` with `variant`'s thrusters, estimated, then held for `seconds` of +-10
/// deg pitch steps every 5 s. The learned model's error (rot, acc) and each window's
/// (rot, acc, its own rotation bound).
#[allow(clippy::type_complexity)]
fn fly(
    name: &str,
    variant: &str,
    (shaped, dvl): (bool, bool),
    window_s: f64,
    seconds: f64,
    noise: NoisePreset,
    seed: u64,
) -> ((f64, f64), Vec<(f64, f64, f64)>) {
    let mut v = vehicle(name);
    let sym = match variant {
        "file" => false,
        "sym" => true,
        other => panic!("WF_VARIANTS: no variant {other:?} (file, sym)"),
    };
    if sym {
        for t in &mut v.thrusters {
            t.reverse_max_n = t.forward_max_n;
        }
    }
    let rate_hz = std::env::var("WF_RATE")
        .ok()
        .map_or(200.0, |v| v.parse().expect("WF_RATE is a number"));
    let mut run = Run::with_vehicle(v, noise, seed, rate_hz);
    run.with_setup(|s| {
        s.estimator.shaped_thrust = shaped;
        if let Some(d) = std::env::var("WF_DITHER").ok().and_then(|v| v.parse().ok()) {
            s.refinement.dither = d;
        }
        // The model stays as learned: the windows are judged against the truth, not folded in.
        s.refinement.update = false;
    });
    let deadband = operator_deadband(run.sim.vehicle());
    run.run_for(1.0);
    run.estimate();
    run.machine.take_events();
    let Some(m) = run.machine.model().cloned() else {
        println!("{name} {variant}: no model ({:?})", run.machine.state());
        return ((f64::NAN, f64::NAN), Vec::new());
    };
    let truth = run.truth();
    let model_err = (
        rel_err(&m.effectiveness, &truth, 0),
        rel_err(&m.effectiveness, &truth, 3),
    );
    // The window's lag: `WF_LAG` (s), else the model's learned one, else the configured.
    let window_lag = std::env::var("WF_LAG")
        .ok()
        .map(|v| v.parse::<f64>().expect("WF_LAG is a number"))
        .or(m.learned_spin_up_s())
        .unwrap_or(0.1);
    println!(
        "{name} {variant}: learned lag {:?}, window lag {window_lag}, state {:?}",
        m.learned_spin_up_s(),
        run.machine.state()
    );
    let n = run.sim.thruster_count();
    let yaw = run.sim.roll_pitch_yaw()[2];
    let depth = run.sim.position_ned().z;
    let start = run.sim.time_s();
    let mut windows = Vec::new();
    let mut fit: Option<(Estimator, f64)> = None;
    let mut sent = vec![0.0; n];
    let mut step = 0;
    let true_thrust = std::env::var_os("WF_TRUE_THRUST").is_some();
    // The true velocity at the window's first samples only (its start; the decisive run for a
    // window that starts from a known velocity).
    let dvl_start = std::env::var_os("WF_DVL_START").is_some();
    // Each window's lags start from rest, as before the spin state (the counterfactual).
    let cold = std::env::var_os("WF_COLD").is_some();
    let mut spin = SpinState::default();
    let lags = vec![window_lag; n];
    let open_amp: Option<f64> = std::env::var("WF_OPEN")
        .ok()
        .map(|v| v.parse().expect("WF_OPEN"));
    while run.sim.time_s() - start < seconds {
        let t = run.sim.time_s() - start;
        pitch_step(&mut run, t, &mut step, yaw, depth);
        let input = run.next_input();
        let t_s = input.t_ns as f64 * 1e-9;
        spin.advance_to(t_s, &lags);
        let gyro = Vector3::from(input.gyro);
        let accel = Vector3::from(input.accel);
        match fit.as_mut() {
            Some((est, t0)) => {
                let t0 = *t0;
                if true_thrust {
                    // The thrust itself, in command units, at this sample: no lag to model.
                    let f = run.sim.thrusts_n();
                    for (i, s) in sent.iter_mut().enumerate() {
                        let t = &run.sim.vehicle().thrusters[i];
                        let sign = if t.reversed { -1.0 } else { 1.0 };
                        *s = sign * f[i] / t.forward_max_n;
                    }
                }
                if dvl || (dvl_start && t_s - t0 < 0.02) {
                    est.push_velocity_fix(&run.sim.linear_velocity());
                }
                est.push_commanded_sample(t_s, &gyro, &accel, input.depth, &sent, None);
            }
            // The first window after a second of the spin state's tracking, as the refinement's
            // settle gate opens one.
            None if t >= 1.0 => {
                // Opened from the true attitude, as a window opens from the filter's.
                let q = run.sim.attitude();
                let down = q.inverse_transform_vector(&Vector3::z());
                let cfg = EstimatorConfig {
                    accel_bias_std: 0.0,
                    spin_up_s: if true_thrust { 0.0 } else { window_lag },
                    ..EstimatorConfig::default()
                };
                let mut est = Estimator::new(cfg, n, NoiseLevels::isotropic(1e-3, 1e-2))
                    .with_rest_specific_force(-down * GRAVITY)
                    .with_configured_imu_position();
                est.begin_closed_loop();
                if !cold {
                    est.start_spun_up(&spin);
                }
                fit = Some((est, t_s));
            }
            None => {}
        }
        let mut cmd = run.machine.on_imu(&input);
        if let Some(amp) = open_amp {
            // Open loop: piecewise-constant pseudo-random commands, a new level every 0.1 s,
            // jumped over the dead band as the machine would.
            let slot = (t_s / 0.1) as u64;
            for (i, c) in cmd.thrust[..n].iter_mut().enumerate() {
                let h = (slot * 31 + i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11;
                let u = amp * (2.0 * (h as f64 / (1u64 << 53) as f64) - 1.0);
                *c = u.signum() * (deadband + (1.0 - deadband) * u.abs());
            }
        }
        run.sim.set_commands(&cmd.thrust[..cmd.count]).unwrap();
        for (s, c) in sent.iter_mut().zip(&cmd.thrust[..n]) {
            // Back to model units: the machine jumps the dead band on the way out.
            *s = if c.abs() > 0.0 {
                c.signum() * ((c.abs() - deadband) / (1.0 - deadband)).max(0.0)
            } else {
                0.0
            };
        }
        spin.hold(&sent);
        if let Some((est, t0)) = fit.as_ref() {
            if t_s - t0 >= window_s {
                let e = est.estimate();
                if std::env::var_os("WF_DETAIL").is_some() {
                    let d = (&e.effectiveness - &truth).rows(0, 3).into_owned();
                    let norm = truth.rows(0, 3).norm();
                    let cols: Vec<String> = (0..n)
                        .map(|i| format!("{:.4}", d.column(i).norm() / norm))
                        .collect();
                    println!(
                        "  window at {t_s:.1} s: rot column errors {}, residual sigma {:.2e} {:.2e} {:.2e}",
                        cols.join(" "),
                        e.sigma[0],
                        e.sigma[1],
                        e.sigma[2]
                    );
                }
                windows.push((
                    rel_err(&e.effectiveness, &truth, 0),
                    rel_err(&e.effectiveness, &truth, 3),
                    e.rel_err_rot,
                ));
                fit = None;
            }
        }
    }
    (model_err, windows)
}
