//! LAG_PROBE_BOOT="g=sd,a=sd,rest=s,reps=n": does the acceleration rows' missing bound at the
//! paper's noise come from the navigation's errors? The log is fitted again `reps` times, each
//! with a draw of the errors a dead-reckoning navigation makes from an IMU of that noise (g: the
//! gyro's white noise per sample, rad/s; a: the accelerometer's, m/s^2) after a rest of `rest`
//! s that measured the gyro's bias and "down", as the estimator draws them itself
//! (`thrusterd_core::estimator::dynamic::navigation_error`). Printed: the fit's statistical
//! bound, B's spread over the draws, the two in quadrature and the error against the truth;
//! and the navigation's actual errors against the truth beside the draws', so the error model
//! itself is checked.

use std::collections::HashMap;

use nalgebra::DMatrix;
use thrusterd_core::estimator::dynamic::navigation_error::{
    navigation_variance, with_drawn_errors, Gaussian, NavigationNoise,
};
use thrusterd_core::estimator::dynamic::spin_state::lags_for_fit;
use thrusterd_core::estimator::dynamic::DynamicRun;

use super::{fitted_b, rel_err, truth_at, Truth};
use crate::estimation::Outcome;

pub(super) fn print_nav_bootstrap(
    run: &DynamicRun,
    spec: &str,
    outcome: &Outcome,
    truth: &HashMap<u64, Truth>,
    truth_b: &DMatrix<f64>,
    seed: u64,
    gravity: f64,
) {
    let (mut sd_g, mut sd_a, mut rest_s, mut reps) = (0.25, 0.49, 1.5, 8usize);
    for part in spec.split(',').filter(|p| !p.is_empty()) {
        let (k, v) = part
            .split_once('=')
            .expect("LAG_PROBE_BOOT: key=value pairs");
        match k {
            "g" => sd_g = v.parse().expect("LAG_PROBE_BOOT g: rad/s"),
            "a" => sd_a = v.parse().expect("LAG_PROBE_BOOT a: m/s^2"),
            "rest" => rest_s = v.parse().expect("LAG_PROBE_BOOT rest: s"),
            "reps" => reps = v.parse().expect("LAG_PROBE_BOOT reps: a count"),
            other => panic!("LAG_PROBE_BOOT: {other} is not g, a, rest or reps"),
        }
    }
    let Some(log) = run.log() else { return };
    let (Some(first), Some(last)) = (log.iter().next(), log.iter().last()) else {
        return;
    };
    if log.len() < 10 {
        return;
    }
    let dt = (last.t_s - first.t_s) / (log.len() - 1) as f64;
    let rest_samples = (rest_s / dt).max(1.0);
    let noise = NavigationNoise {
        gyro_sd: sd_g,
        accel_sd: sd_a,
        bias_sd: sd_g / rest_samples.sqrt(),
        rest_samples,
        gravity,
    };
    let n = run.thrusters();
    let lags = lags_for_fit(
        n,
        outcome.spin_up_s,
        None,
        Some(&outcome.terms.spin_up_per_thruster_s),
    );
    let lags = &lags[..n];
    let Some(fit) = run.refit(lags) else { return };
    let sol = fit.solve(&[1e-3; 6], 0.0, 0.0, None);
    let (e_rot, e_acc) = rel_err(&sol.b, truth_b);
    let seed = 0xb007_57a9_0000_0001 ^ seed;
    let Some(var) = navigation_variance(run, &noise, reps, seed, |r| fitted_b(r, lags)) else {
        return;
    };
    let part = |rows: usize| var.rows(rows, 3).sum().sqrt() / truth_b.rows(rows, 3).norm();
    let (boot_rot, boot_acc) = (part(0), part(3));
    let (s_rot, s_acc) = (sol.rel_err[0], sol.rel_err[1]);
    let (c_rot, c_acc) = (s_rot.hypot(boot_rot), s_acc.hypot(boot_acc));
    // The draws' size, from the drawn logs against the log (other draws of the same model),
    // and the navigation's actual errors against the truth over the same log.
    let (mut d_att, mut d_vel, mut d_n) = (0.0, 0.0, 0.0);
    let mut rng = Gaussian::new(seed ^ 0x5a5a);
    for _ in 0..reps {
        let Some(drawn) = with_drawn_errors(run, &noise, dt, &mut rng) else {
            continue;
        };
        let Some(drawn_log) = drawn.log() else {
            continue;
        };
        for (d, s) in drawn_log.iter().zip(log.iter()) {
            d_att += d.down.cross(&s.down).norm_squared();
            d_vel += (d.velocity - s.velocity).norm_squared();
            d_n += 1.0;
        }
    }
    let (mut a_att, mut a_vel, mut a_n) = (0.0, 0.0, 0.0);
    for s in log.iter() {
        if let Some(t) = truth_at(truth, s.t_s) {
            a_att += s.down.cross(&t.down).norm_squared();
            a_vel += (s.velocity - t.velocity).norm_squared();
            a_n += 1.0;
        }
    }
    let rms = |x: f64, n: f64| (x / n.max(1.0)).sqrt();
    println!(
        "  nav bootstrap x{reps}: err {e_rot:.4}/{e_acc:.4} stat {s_rot:.4}/{s_acc:.4} spread {boot_rot:.4}/{boot_acc:.4} combined {c_rot:.4}/{c_acc:.4}; nav error actual att {:.2} deg vel {:.3} m/s, drawn att {:.2} deg vel {:.3} m/s",
        rms(a_att, a_n).asin().to_degrees(),
        rms(a_vel, a_n),
        rms(d_att, d_n).asin().to_degrees(),
        rms(d_vel, d_n),
    );
}
