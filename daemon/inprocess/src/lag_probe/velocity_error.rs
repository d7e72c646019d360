//! LAG_PROBE_VEL_PARTS=1: which part of the navigated velocity's error the acceleration rows'
//! bound misses. The log fitted again with the velocity's error against the simulator's truth
//! removed in parts: its mean over the run (a constant offset), its mean and linear trend, and
//! whole (the probe's `v`), each against the truth with the fit's own statistical bound. Why:
//! a correction the estimator could make itself (a few sensitivities, the navigation's
//! covariance) needs the error to live in a few such parts.

use std::collections::HashMap;

use nalgebra::{DMatrix, Vector3};
use thrusterd_core::estimator::dynamic::spin_state::lags_for_fit;
use thrusterd_core::estimator::dynamic::DynamicRun;

use super::{rel_err, truth_at, Truth};
use crate::estimation::Outcome;

/// A velocity corrected at time t (s) from the navigated one and the truth there.
type Correction<'a> = &'a dyn Fn(f64, &Vector3<f64>, Option<&Truth>) -> Vector3<f64>;

pub(super) fn print_velocity_parts(
    run: &DynamicRun,
    outcome: &Outcome,
    truth: &HashMap<u64, Truth>,
    truth_b: &DMatrix<f64>,
) {
    let Some(log) = run.log() else { return };
    // The error at each sample (navigated less true) and its time.
    let errs: Vec<(f64, Vector3<f64>)> = log
        .iter()
        .filter_map(|s| truth_at(truth, s.t_s).map(|t| (s.t_s, s.velocity - t.velocity)))
        .collect();
    if errs.len() < 10 {
        return;
    }
    let n = errs.len() as f64;
    let t_mean = errs.iter().map(|e| e.0).sum::<f64>() / n;
    let e_mean = errs.iter().map(|e| e.1).sum::<Vector3<f64>>() / n;
    let stt = errs.iter().map(|e| (e.0 - t_mean).powi(2)).sum::<f64>();
    let slope = errs
        .iter()
        .map(|e| (e.1 - e_mean) * (e.0 - t_mean))
        .sum::<Vector3<f64>>()
        / stt.max(1e-12);
    let rms = (errs.iter().map(|e| e.1.norm_squared()).sum::<f64>() / n).sqrt();
    let detrended = (errs
        .iter()
        .map(|e| (e.1 - e_mean - slope * (e.0 - t_mean)).norm_squared())
        .sum::<f64>()
        / n)
        .sqrt();
    println!(
        "  velocity error: rms {rms:.4} m/s, mean {:.4?}, slope {:.4?} m/s^2, left after mean and trend {detrended:.4}",
        e_mean.as_slice(),
        slope.as_slice()
    );
    let k = run.thrusters();
    let lags = lags_for_fit(
        k,
        outcome.spin_up_s,
        None,
        Some(&outcome.terms.spin_up_per_thruster_s),
    );
    let fit = |part: &str, correct: Correction| {
        let Some(mapped) = run.with_log_mapped(|s| {
            let mut out = *s;
            out.velocity = correct(s.t_s, &s.velocity, truth_at(truth, s.t_s));
            out
        }) else {
            return;
        };
        let Some(f) = mapped.refit(&lags[..k]) else {
            return;
        };
        let sol = f.solve(&[1e-3; 6], 0.0, 0.0, None);
        let (r, a) = rel_err(&sol.b, truth_b);
        println!(
            "  velocity {part}: err_rot {r:.4} err_acc {a:.4} statistical bound {:.4}/{:.4}",
            sol.rel_err[0], sol.rel_err[1]
        );
    };
    fit("as navigated", &|_, v, _| *v);
    fit("less its mean error", &|_, v, _| v - e_mean);
    fit("less its mean and trend", &|t, v, _| {
        v - e_mean - slope * (t - t_mean)
    });
    fit("true", &|_, v, tr| tr.map_or(*v, |tr| tr.velocity));
}
