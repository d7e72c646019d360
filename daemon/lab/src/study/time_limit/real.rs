//! The real estimator on a designed excitation: the daemon's dynamic fit
//! (`thrusterd_core::estimator::dynamic::DynamicRun`, its lag search, its solve and its
//! referral to the centre, as `Estimator::dynamic_estimate` does them) fed by the simulator
//! in one process, the commands coming from an [`Excitation`] instead of the machine's plan.
//! The machine's part is reproduced: a 1 s rest that measures the noise, the gyro's baseline
//! and the starting attitude and vertical velocity, then the excitation back to back, the
//! dead band compensated. Not the machine itself: the machine can only pulse its own plan.

use nalgebra::{DMatrix, Vector3};
use thruster_sim::{NoisePreset, SensorConfig, Simulator, Vehicle};
use thrusterd_core::estimator::dynamic::lag_search::{learn_common_lag, LagRange};
use thrusterd_core::estimator::dynamic::{DynamicRun, ImuSetting};
use thrusterd_core::estimator::noise::NoiseMeter;
use thrusterd_core::estimator::EstimatorConfig;
use thrusterd_core::navigation::rest_drift::RestDrift;
use thrusterd_core::navigation::DepthAid;

use super::design::Excitation;
use super::fisher::{compensate, RATE_HZ};

/// The real estimator's result at one instant of the excitation.
#[derive(Debug, Clone, Copy)]
pub struct RealPoint {
    /// Excitation time, s.
    pub t_s: f64,
    pub err_rot: f64,
    pub err_acc: f64,
    /// The estimator's own bounds.
    pub bound: [f64; 2],
    /// The lag it fitted at, s, and whether learned.
    pub lag_s: f64,
    pub lag_learned: bool,
    /// Largest true tilt so far, deg.
    pub max_tilt_deg: f64,
}

/// One run of `excitation` on `v` with the IMU's `noise` (`seed`), solved at every time of
/// `at_s` (ascending, excitation seconds).
pub fn run(
    v: &Vehicle,
    excitation: &Excitation,
    noise: NoisePreset,
    seed: u64,
    at_s: &[f64],
) -> Vec<RealPoint> {
    let cfg = EstimatorConfig::dynamic();
    let n = v.thrusters.len();
    let sensors = SensorConfig {
        rate_hz: RATE_HZ,
        noise,
        ..SensorConfig::default()
    };
    let mut sim = Simulator::new(v.clone(), sensors, seed).expect("vehicle");
    let (f, r) = sim.truth();
    let truth = (f + r) * 0.5;
    // The rest: noise levels, baseline, starting attitude and vertical velocity.
    let mut meter = NoiseMeter::new();
    let mut drift = RestDrift::new();
    let mut force = Vector3::zeros();
    let mut rest_n = 0.0;
    while sim.time_s() < 1.0 - 1e-9 {
        let m = sim.advance_and_sample();
        meter.push(&m.gyro, &m.accel);
        if let Some(d) = m.depth {
            drift.push(sim.time_s(), d);
        }
        force += Vector3::from(m.accel);
        rest_n += 1.0;
    }
    let levels = meter.levels();
    let aid = DepthAid {
        accel_std_mps2: levels.sigma_acc(),
        bias_std_mps2: cfg.accel_bias_std,
        kalman: cfg.accel_bias_std > 0.0,
        ..DepthAid::default()
    };
    let t_end = at_s.last().copied().unwrap_or(0.0);
    let capacity = (t_end * RATE_HZ) as usize + 16;
    let mut fit =
        DynamicRun::new(n, cfg.spin_up_s, cfg.segment_s, &(force / rest_n), aid).with_log(capacity);
    // The one column fitted to the thrust's shape, as the machine's open loop does
    // (`Estimator::dynamic_run`); without it the fit's noise-free floor is 1.5 %.
    if cfg.shaped_thrust {
        fit = fit.with_asymmetry(cfg.reverse_ratio);
    }
    if let Some(w) = drift.velocity_down() {
        fit.start_sinking_at(w);
    }
    let learns_lag = cfg.learn_spin_up && levels.sigma_rot() <= cfg.spin_up_max_gyro_sigma;
    let rest_sigma = {
        let (g, a) = (levels.gyro_sigma, levels.accel_sigma);
        [g[0], g[1], g[2], a[0], a[1], a[2]]
    };
    let setting = ImuSetting {
        position_m: Vector3::from(cfg.imu_position_m),
        learn: cfg.learn_imu_position,
        tolerance_m: cfg.imu_position_tolerance_m,
    };
    let t0 = sim.time_s();
    let mut u = vec![0.0; n];
    let mut sent = vec![0.0; n];
    let mut out = Vec::with_capacity(at_s.len());
    let mut next = 0;
    let mut max_tilt = 0.0_f64;
    let dt = 1.0 / RATE_HZ;
    let mut k = 0usize;
    while next < at_s.len() {
        let t = k as f64 * dt;
        excitation.command(t, &mut u);
        for (s, x) in sent.iter_mut().zip(&u) {
            *s = compensate(*x);
        }
        sim.set_commands(&sent).expect("commands");
        let m = sim.advance_and_sample();
        k += 1;
        let down = sim.attitude().inverse_transform_vector(&Vector3::z());
        max_tilt = max_tilt.max(down.z.clamp(-1.0, 1.0).acos().to_degrees());
        let gyro = levels.gyro_delta(&m.gyro);
        fit.push(
            m.t_ns as f64 * 1e-9,
            &gyro,
            &Vector3::from(m.accel),
            m.depth,
            Some(&u),
        );
        let t_now = sim.time_s() - t0;
        while next < at_s.len() && t_now >= at_s[next] - 1e-9 {
            let learned = learns_lag
                .then(|| {
                    let range = LagRange {
                        min_s: cfg.spin_up_range_s[0],
                        max_s: cfg.spin_up_range_s[1],
                        ..LagRange::default()
                    };
                    learn_common_lag(&fit, &range)
                })
                .flatten();
            let solve = |run: &DynamicRun| {
                run.solve(&rest_sigma, cfg.model_error_floor, cfg.term_prior_sd, None)
            };
            let mut sol = match &learned {
                Some(l) => {
                    let mut s = solve(&l.run);
                    l.widen(&mut s, solve);
                    s
                }
                None => solve(&fit),
            };
            let used = learned.as_ref().map_or(&fit, |l| &l.run);
            used.refer_to_centre(&mut sol, &setting);
            let err = |g: usize| rel_err(&sol.b, &truth, g);
            out.push(RealPoint {
                t_s: t_now,
                err_rot: err(0),
                err_acc: err(1),
                bound: sol.rel_err,
                lag_s: sol.terms.spin_up_s,
                lag_learned: sol.terms.spin_up_learned,
                max_tilt_deg: max_tilt,
            });
            next += 1;
        }
    }
    out
}

/// Relative Frobenius error of group `g` (0 rotation, 1 acceleration rows).
pub fn rel_err(b: &DMatrix<f64>, truth: &DMatrix<f64>, g: usize) -> f64 {
    (b.rows(3 * g, 3) - truth.rows(3 * g, 3)).norm() / truth.rows(3 * g, 3).norm()
}
