//! The probe's candidate remedies, tried on the log before any is built into the estimator:
//! the terms' rate smoothed, and the rate or velocity replaced by the model's own simulated
//! response (docs/study.md, "Learning the thruster lag").

use std::collections::HashMap;

use nalgebra::Vector3;
use thrusterd_core::estimator::dynamic::lag_search::{learn_common_lag_weighted, LagRange};
use thrusterd_core::estimator::dynamic::DynamicRun;

use super::{truth_at, Truth};

/// The model's own response, simulated from rest through the fit at `lag_s`: (rate, velocity)
/// per log sample. The acceleration rows' intercepts and constant are left out (they carry
/// the navigation's tilt error, not a force), and so is the rotation rows' constant.
fn simulate(
    run: &DynamicRun,
    lag_s: f64,
    linear: bool,
    measured_rate: bool,
) -> Option<Vec<(Vector3<f64>, Vector3<f64>)>> {
    use thrusterd_core::estimator::dynamic::regressors::{self, terms, RATE, TERMS, VELOCITY};
    let fit = run.refit(&[lag_s])?;
    let sol = fit.solve(&[0.01; 6], 0.0, 0.0, None);
    let log = run.log()?;
    let n = run.thrusters();
    let (b, theta) = (&sol.b, &sol.terms.coefficients);
    let constant = TERMS - 2;
    // LAG_PROBE_DECAY: the slowest velocity decay allowed, 1/s (default 0.5: 2 s).
    let slowest: f64 = std::env::var("LAG_PROBE_DECAY")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0.5);
    let mut lag = vec![0.0; n];
    let mut lag_abs = 0.0;
    let (mut w, mut v) = (Vector3::zeros(), Vector3::zeros());
    let mut last_t: Option<f64> = None;
    let mut out = Vec::with_capacity(log.len());
    let mut x = [0.0; TERMS];
    for smp in log.iter() {
        let dt = last_t.map_or(0.0, |t0| (smp.t_s - t0).min(0.1));
        // Advance the state over the step that ends at this sample (explicit Euler with the
        // last sample's derivatives).
        if last_t.is_some() {
            let mut wd = Vector3::zeros();
            let mut md = Vector3::zeros();
            for a in 0..3 {
                for i in 0..n {
                    wd[a] += b[(a, i)] * lag[i];
                    md[a] += b[(3 + a, i)] * lag[i];
                }
                if measured_rate {
                    // The acceleration rows' model with the measured rate and the attitude,
                    // the velocity's own terms replaced by a stable linear damping.
                    for j in 0..TERMS {
                        if j == constant || regressors::touches_velocity(j) {
                            continue;
                        }
                        md[a] += theta[(3 + a, j)] * x[j];
                    }
                    md[a] += theta[(3 + a, VELOCITY + a)].min(-0.5) * v[a];
                    continue;
                }
                if linear {
                    // Thrust and each axis's own linear damping, held stable (at least a 2 s
                    // decay): what of the response the thrust drives.
                    wd[a] += theta[(a, RATE + a)].min(-0.5) * w[a];
                    md[a] += theta[(3 + a, VELOCITY + a)].min(-slowest) * v[a];
                    continue;
                }
                for j in 0..TERMS {
                    if j == constant {
                        continue;
                    }
                    wd[a] += theta[(a, j)] * x[j];
                    md[a] += theta[(3 + a, j)] * x[j];
                }
            }
            let vd = if linear { md } else { md - w.cross(&v) };
            if measured_rate {
                w = smp.rate;
            }
            w += wd * dt;
            v += vd * dt;
        }
        last_t = Some(smp.t_s);
        let u = log.command(smp.command);
        let a = if lag_s > 0.0 {
            1.0 - (-dt / lag_s).exp()
        } else {
            1.0
        };
        let mut abs = 0.0;
        for i in 0..n {
            let c = u.map_or(0.0, |u| u[i]);
            abs += c.abs() / n as f64;
            lag[i] += a * (c - lag[i]);
        }
        lag_abs += a * (abs - lag_abs);
        terms(&v, &w, &smp.down, lag_abs, &mut x);
        out.push((w, v));
    }
    Some(out)
}

/// LAG_PROBE_SIM="RV,3": the lag learned on the log with the rate (R) and/or velocity (V)
/// replaced by the model's simulated response (the fit at the lag learned last), iterated;
/// with L in it the simulation has only the thrust and each axis's linear damping; with A the
/// velocity alone is simulated, by the acceleration rows' model on the measured rate with the
/// velocity's terms replaced by a stable linear damping; with T the terms' rate is the true one.
pub(super) fn print_simulated(
    run: &DynamicRun,
    spec: &str,
    truth: &HashMap<u64, Truth>,
    weights: &[f64; 6],
) {
    let mut parts = spec.split(',');
    let what = parts.next().unwrap_or("RV");
    let linear = what.contains('L');
    let iters: usize = parts.next().and_then(|v| v.parse().ok()).unwrap_or(3);
    let learn = |r: &DynamicRun| {
        learn_common_lag_weighted(r, &LagRange::default(), &Vector3::zeros(), weights)
            .map(|l| l.lag_s)
    };
    let Some(mut lag) = learn(run) else {
        println!("  simulated: no lag learned");
        return;
    };
    let mut line = format!("  simulated {what}: {lag:.4}");
    for _ in 0..iters {
        let Some(sim) = simulate(run, lag, linear, what.contains('A')) else {
            println!("{line}: no simulation");
            return;
        };
        let wmax = sim.iter().map(|(w, _)| w.norm()).fold(0.0, f64::max);
        let vmax = sim.iter().map(|(_, v)| v.norm()).fold(0.0, f64::max);
        line += &format!(" (|w| <= {wmax:.3}, |v| <= {vmax:.3})");
        let mut k = 0;
        let Some(mapped) = run.with_log_mapped(|smp| {
            let mut out = *smp;
            let (w, v) = sim[k];
            k += 1;
            if what.contains('R') {
                out.rate = w;
            }
            if what.contains('V') {
                out.velocity = v;
            }
            if what.contains('T') {
                if let Some(t) = truth_at(truth, smp.t_s) {
                    out.rate = t.rate;
                }
            }
            out
        }) else {
            return;
        };
        let Some(l) = learn(&mapped) else {
            println!("{line}: no lag on the simulated log");
            return;
        };
        lag = l;
        line += &format!(" -> {lag:.4}");
    }
    println!("{line}");
}

/// LAG_PROBE_SMOOTH="W[,v]": the lag learned with the terms' rate replaced by the measured
/// gyro averaged over W samples centred on each (and with ",v" the true velocity as well).
pub(super) fn print_smoothed(
    run: &DynamicRun,
    spec: &str,
    truth: &HashMap<u64, Truth>,
    weights: &[f64; 6],
) {
    let mut parts = spec.split(',');
    let w: usize = parts.next().and_then(|v| v.parse().ok()).unwrap_or(17);
    let true_v = parts.next() == Some("v");
    let Some(log) = run.log() else { return };
    let gyro: Vec<Vector3<f64>> = log.iter().map(|s| s.gyro).collect();
    let half = w / 2;
    let smooth: Vec<Vector3<f64>> = (0..gyro.len())
        .map(|k| {
            let (a, b) = (k.saturating_sub(half), (k + half + 1).min(gyro.len()));
            gyro[a..b].iter().sum::<Vector3<f64>>() / (b - a) as f64
        })
        .collect();
    let mut k = 0;
    let Some(mapped) = run.with_log_mapped(|smp| {
        let mut out = *smp;
        out.rate = smooth[k];
        k += 1;
        if true_v {
            if let Some(t) = truth_at(truth, smp.t_s) {
                out.velocity = t.velocity;
            }
        }
        out
    }) else {
        return;
    };
    let lag = lag_of(&mapped, weights);
    println!(
        "  smoothed over {w}{}: {lag:.4}",
        if true_v { ", true velocity" } else { "" }
    );
}

/// LAG_PROBE_LEAK="tau[,T]": the lag learned with the velocity dead-reckoned again from the
/// log's acceleration with a leak of 1/tau (a first-order high-pass: the tilt's slow drift out,
/// the pulses' response kept), and with T the terms' rate true as well.
pub(super) fn print_leaky(
    run: &DynamicRun,
    spec: &str,
    truth: &HashMap<u64, Truth>,
    weights: &[f64; 6],
) {
    let mut parts = spec.split(',');
    let tau: f64 = parts.next().and_then(|v| v.parse().ok()).unwrap_or(1.0);
    let true_rate = parts.next() == Some("T");
    let mut v = Vector3::zeros();
    let mut last: Option<(f64, Vector3<f64>)> = None;
    let Some(mapped) = run.with_log_mapped(|smp| {
        let accel = smp.motion - smp.rate.cross(&v);
        if let Some((t0, a0)) = last {
            let dt = (smp.t_s - t0).min(0.1);
            v += (0.5 * (accel + a0) - v / tau) * dt;
        }
        last = Some((smp.t_s, accel));
        let mut out = *smp;
        out.velocity = v;
        if true_rate {
            if let Some(t) = truth_at(truth, smp.t_s) {
                out.rate = t.rate;
            }
        }
        out
    }) else {
        return;
    };
    let lag = lag_of(&mapped, weights);
    println!(
        "  leaky velocity tau {tau}{}: {lag:.4}",
        if true_rate { ", true rate" } else { "" }
    );
}

/// The lag learned from `run`'s log scored with `weights` (NaN when it cannot be).
fn lag_of(run: &DynamicRun, weights: &[f64; 6]) -> f64 {
    learn_common_lag_weighted(run, &LagRange::default(), &Vector3::zeros(), weights)
        .map_or(f64::NAN, |l| l.lag_s)
}
