//! The terms' noisy rate, scored against the truth: what its white noise costs B, and two
//! remedies tried on the log.
//!
//! LAG_PROBE_SIMEX="r=sd,v=sd,d=sd,reps=n" (any of them): simulation-extrapolation (SIMEX,
//! Cook and Stefanski 1994) on the navigation's errors in the fit's inputs, which the least
//! squares' bound does not count (errors-in-variables): white noise on the terms' rate (r,
//! rad/s per sample, the gyro's), a random walk on the body velocity (v, m/s per sample: the
//! accelerometer's sd over the rate, as the dead reckoning's) and on the gravity direction
//! (d, rad per sample: the gyro's sd over the rate, the navigated attitude's; the
//! acceleration rows' output moves with it, as `replaced` does). The log is fitted again with
//! lambda times those variances added, lambda = 0.5, 1, 1.5, 2 (reps draws each, averaged),
//! and B's trend in lambda extrapolated back to lambda = -1, where the inputs would be
//! error-free. Printed: the fit as measured, the linear (from 0 and 1) and the quadratic
//! (least squares over the five lambdas) extrapolations, each against the simulator's truth.

use nalgebra::{DMatrix, Vector3};
use thrusterd_core::estimator::dynamic::spin_state::lags_for_fit;
use thrusterd_core::estimator::dynamic::DynamicRun;

use super::{fitted_b, rel_err, Normal};
use crate::estimation::Outcome;

const LAMBDAS: [f64; 4] = [0.5, 1.0, 1.5, 2.0];

pub(super) fn print_simex(
    run: &DynamicRun,
    spec: &str,
    outcome: &Outcome,
    truth_b: &DMatrix<f64>,
    seed: u64,
    gravity: f64,
) {
    let (mut sd_r, mut sd_v, mut sd_d, mut reps) = (0.0, 0.0, 0.0, 4usize);
    for part in spec.split(',') {
        let (k, v) = part
            .split_once('=')
            .expect("LAG_PROBE_SIMEX: key=value pairs");
        let v: f64 = v.parse().expect("LAG_PROBE_SIMEX: a number");
        match k {
            "r" => sd_r = v,
            "v" => sd_v = v,
            "d" => sd_d = v,
            "reps" => reps = v as usize,
            other => panic!("LAG_PROBE_SIMEX: {other} is not r, v, d or reps"),
        }
    }
    let n = run.thrusters();
    let lags = lags_for_fit(
        n,
        outcome.spin_up_s,
        None,
        Some(&outcome.terms.spin_up_per_thruster_s),
    );
    let lags = &lags[..n];
    let Some(b0) = fitted_b(run, lags) else {
        return;
    };
    let mut rng = Normal(0x5171_3e80_d1ce_0001 ^ seed);
    let mut means = Vec::new();
    for &lambda in &LAMBDAS {
        let k = lambda.sqrt();
        let mut sum = DMatrix::zeros(b0.nrows(), b0.ncols());
        let mut got = 0.0;
        for _ in 0..reps {
            let (mut dv, mut dth) = (Vector3::<f64>::zeros(), Vector3::<f64>::zeros());
            let Some(mapped) = run.with_log_mapped(|smp| {
                let mut out = *smp;
                out.rate += Vector3::from_fn(|_, _| k * sd_r * rng.sample());
                dv += Vector3::from_fn(|_, _| k * sd_v * rng.sample());
                dth += Vector3::from_fn(|_, _| k * sd_d * rng.sample());
                out.velocity += dv;
                let down = (smp.down + dth.cross(&smp.down)).normalize();
                out.motion += (down - smp.down) * gravity;
                out.down = down;
                out
            }) else {
                return;
            };
            if let Some(b) = fitted_b(&mapped, lags) {
                sum += b;
                got += 1.0;
            }
        }
        if got == 0.0 {
            return;
        }
        means.push(sum / got);
    }
    // Linear through lambda 0 and 1, evaluated at -1.
    let linear = &b0 * 2.0 - &means[1];
    // Quadratic least squares over lambda = 0 and LAMBDAS, per entry, at -1.
    let xs: Vec<f64> = std::iter::once(0.0).chain(LAMBDAS).collect();
    let ys: Vec<&DMatrix<f64>> = std::iter::once(&b0).chain(means.iter()).collect();
    let design = DMatrix::from_fn(xs.len(), 3, |i, j| xs[i].powi(j as i32));
    let pinv = (design.transpose() * &design)
        .try_inverse()
        .expect("five distinct lambdas")
        * design.transpose();
    // The value at -1 is [1, -1, 1] . coefficients: weights on each lambda's B.
    let at = nalgebra::RowDVector::from_row_slice(&[1.0, -1.0, 1.0]) * &pinv;
    let mut quad = DMatrix::zeros(b0.nrows(), b0.ncols());
    for (w, y) in at.iter().zip(&ys) {
        quad += *y * *w;
    }
    let (r0, a0) = rel_err(&b0, truth_b);
    let (rl, al) = rel_err(&linear, truth_b);
    let (rq, aq) = rel_err(&quad, truth_b);
    let (r2, a2) = rel_err(&means[3], truth_b);
    println!(
        "  simex r {sd_r} v {sd_v} d {sd_d} x{reps}: measured {r0:.4}/{a0:.4} linear {rl:.4}/{al:.4} quadratic {rq:.4}/{aq:.4} (at lambda 2: {r2:.4}/{a2:.4})"
    );
}

/// LAG_PROBE_SMOOTH_FIT="mean|sg,W": the log fitted at the estimation's lags with the terms'
/// rate replaced by the measured gyro smoothed over W samples centred on each, by a moving mean
/// or a Savitzky-Golay cubic (the local cubic's value at the centre, which keeps a pulse's
/// bend that a mean flattens), against the simulator's truth beside the fit as measured.
pub(super) fn print_smoothed_fit(
    run: &DynamicRun,
    spec: &str,
    outcome: &Outcome,
    truth_b: &DMatrix<f64>,
) {
    let mut parts = spec.split(',');
    let kind = parts.next().unwrap_or("mean").to_string();
    let w: usize = parts.next().and_then(|v| v.parse().ok()).unwrap_or(9);
    let half = (w / 2) as i64;
    let Some(log) = run.log() else { return };
    let gyro: Vec<Vector3<f64>> = log.iter().map(|s| s.gyro).collect();
    // Savitzky-Golay cubic weights at the centre of 2 m + 1 samples:
    // (3 (3 m^2 + 3 m - 1) - 15 i^2) / ((2 m + 1)(2 m - 1)(2 m + 3)).
    let sg: Vec<f64> = {
        let m = half as f64;
        let den = (2.0 * m + 1.0) * (2.0 * m - 1.0) * (2.0 * m + 3.0);
        (-half..=half)
            .map(|i| (3.0 * (3.0 * m * m + 3.0 * m - 1.0) - 15.0 * (i * i) as f64) / den)
            .collect()
    };
    let sg_sum: f64 = sg.iter().sum();
    let len = gyro.len() as i64;
    let smooth: Vec<Vector3<f64>> = (0..len)
        .map(|k| {
            if kind == "sg" && k >= half && k + half < len {
                (-half..=half)
                    .zip(&sg)
                    .map(|(i, c)| gyro[(k + i) as usize] * (*c / sg_sum))
                    .sum()
            } else {
                let (a, b) = ((k - half).max(0), (k + half + 1).min(len));
                gyro[a as usize..b as usize].iter().sum::<Vector3<f64>>() / (b - a) as f64
            }
        })
        .collect();
    let n = run.thrusters();
    let lags = lags_for_fit(
        n,
        outcome.spin_up_s,
        None,
        Some(&outcome.terms.spin_up_per_thruster_s),
    );
    let mut k = 0;
    let Some(mapped) = run.with_log_mapped(|smp| {
        let mut out = *smp;
        out.rate = smooth[k];
        k += 1;
        out
    }) else {
        return;
    };
    let (Some(b0), Some(b)) = (fitted_b(run, &lags[..n]), fitted_b(&mapped, &lags[..n])) else {
        return;
    };
    let (r0, a0) = rel_err(&b0, truth_b);
    let (r, a) = rel_err(&b, truth_b);
    println!("  rate {kind} over {w}: {r:.4}/{a:.4} (as measured {r0:.4}/{a0:.4})");
}
