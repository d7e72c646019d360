//! LAG_PROBE_BOOT="g=sd,a=sd,rest=s,reps=n[,parts=bdwv]": does the acceleration rows' missing
//! bound at the paper's noise come from the navigation's errors, and can the estimator count
//! them? The log is fitted again `reps` times, each with a draw of the errors a dead-reckoning
//! navigation makes from an IMU of that noise (g: the gyro's white noise per sample, rad/s; a:
//! the accelerometer's, m/s^2) after a rest of `rest` s that measured the gyro's bias and
//! "down": the bias's error (b, constant: sd g / sqrt(rest samples)) and the gyro's white noise
//! integrated (w) turn "down"; the navigated gravity moves the acceleration rows' output and,
//! integrated, the velocity, with the accelerometer's white noise integrated besides (v); the
//! starting tilt's error (d: sd a / g / sqrt(rest samples)). The spread of those fits' B is the
//! part of B's error the fit's own (white-noise) bound cannot see. Printed: the fit's
//! statistical bound, the spread, the two in quadrature, and the error against the truth; and
//! the navigation's actual errors against the truth beside the draws', so the error model
//! itself is checked.

use std::collections::HashMap;

use nalgebra::{DMatrix, Vector3};
use thrusterd_core::estimator::dynamic::spin_state::lags_for_fit;
use thrusterd_core::estimator::dynamic::DynamicRun;

use super::{rel_err, truth_at, Normal, Truth};
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
    let mut parts = "bdwv".to_string();
    for part in spec.split(',').filter(|p| !p.is_empty()) {
        let (k, v) = part
            .split_once('=')
            .expect("LAG_PROBE_BOOT: key=value pairs");
        match k {
            "g" => sd_g = v.parse().expect("LAG_PROBE_BOOT g: rad/s"),
            "a" => sd_a = v.parse().expect("LAG_PROBE_BOOT a: m/s^2"),
            "rest" => rest_s = v.parse().expect("LAG_PROBE_BOOT rest: s"),
            "reps" => reps = v.parse().expect("LAG_PROBE_BOOT reps: a count"),
            "parts" => parts = v.to_string(),
            other => panic!("LAG_PROBE_BOOT: {other} is not g, a, rest, reps or parts"),
        }
    }
    let Some(log) = run.log() else { return };
    if log.len() < 10 {
        return;
    }
    let (first, last) = match (log.iter().next(), log.iter().last()) {
        (Some(f), Some(l)) => (f.t_s, l.t_s),
        _ => return,
    };
    let dt: f64 = (last - first) / (log.len() - 1) as f64;
    let n_rest = (rest_s / dt).max(1.0);
    let (use_b, use_d, use_w, use_v) = (
        parts.contains('b'),
        parts.contains('d'),
        parts.contains('w'),
        parts.contains('v'),
    );
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
    let b0 = sol.b.clone();
    let (e_rot, e_acc) = rel_err(&b0, truth_b);
    let mut rng = Normal(0xb007_57a9_0000_0001 ^ seed);
    let mut spread = DMatrix::<f64>::zeros(b0.nrows(), b0.ncols());
    let (mut got, mut att_ms, mut vel_ms, mut cnt) = (0.0, 0.0, 0.0, 0.0);
    for _ in 0..reps {
        let mut draw = |sd: f64| Vector3::from_fn(|_, _| sd * rng.sample());
        let bias = if use_b {
            draw(sd_g / n_rest.sqrt())
        } else {
            Vector3::zeros()
        };
        // The starting tilt's error: about the body's horizontal axes only (the heading does
        // not move gravity).
        let mut theta = if use_d {
            let d = draw(sd_a / gravity / n_rest.sqrt());
            Vector3::new(d.x, d.y, 0.0)
        } else {
            Vector3::zeros()
        };
        let walk: Vec<Vector3<f64>> = (0..log.len())
            .map(|_| {
                if use_w {
                    draw(sd_g * dt)
                } else {
                    Vector3::zeros()
                }
            })
            .collect();
        let kick: Vec<Vector3<f64>> = (0..log.len())
            .map(|_| {
                if use_v {
                    draw(sd_a * dt)
                } else {
                    Vector3::zeros()
                }
            })
            .collect();
        let mut dv = Vector3::zeros();
        let mut k = 0usize;
        let Some(mapped) = run.with_log_mapped(|smp| {
            let mut out = *smp;
            theta += bias * dt + walk[k];
            let down = (smp.down + theta.cross(&smp.down)).normalize();
            let leak = (down - smp.down) * gravity;
            dv += leak * dt + kick[k];
            out.rate += bias;
            out.down = down;
            out.motion += leak;
            out.velocity += dv;
            k += 1;
            att_ms += theta.norm_squared();
            vel_ms += dv.norm_squared();
            cnt += 1.0;
            out
        }) else {
            return;
        };
        if let Some(f) = mapped.refit(lags) {
            let b = f.solve(&[1e-3; 6], 0.0, 0.0, None).b;
            spread += (&b - &b0).map(|x| x * x);
            got += 1.0;
        }
    }
    if got == 0.0 {
        return;
    }
    let spread = spread / got;
    let part = |rows: usize| (spread.rows(rows, 3).sum()).sqrt() / truth_b.rows(rows, 3).norm();
    let (boot_rot, boot_acc) = (part(0), part(3));
    let (s_rot, s_acc) = (sol.rel_err[0], sol.rel_err[1]);
    let (c_rot, c_acc) = (s_rot.hypot(boot_rot), s_acc.hypot(boot_acc));
    // The navigation's actual errors against the truth over the same log.
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
        "  nav bootstrap {parts} x{reps}: err {e_rot:.4}/{e_acc:.4} stat {s_rot:.4}/{s_acc:.4} spread {boot_rot:.4}/{boot_acc:.4} combined {c_rot:.4}/{c_acc:.4}; nav error actual att {:.2} deg vel {:.3} m/s, drawn att {:.2} deg vel {:.3} m/s",
        rms(a_att, a_n).to_degrees(),
        rms(a_vel, a_n),
        rms(att_ms, cnt).to_degrees(),
        rms(vel_ms, cnt),
    );
}
