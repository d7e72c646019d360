//! LAG_PROBE_TOW=k1,k2,...: whether a run's own fit can find the steady velocity it started
//! with (a vehicle towed through the water, which the navigation starts from zero). The log
//! is fitted again with the navigation's velocity moved by k times its error at the start
//! (held fixed in the world, the probe's `o` at k = 1), the lag searched each time; printed:
//! the lag, the profile's score (ln residual variance summed over the outputs: lower fits
//! better) and B's error against the truth. A score lowest near k = 1 would make the start
//! velocity an unknown the estimator could search, as it searches the lag.

use std::collections::HashMap;

use nalgebra::DMatrix;
use thrusterd_core::estimator::dynamic::lag_search::{
    learn_common_lag_weighted, profile_score_weighted, LagRange,
};
use thrusterd_core::estimator::dynamic::{start_velocity, DynamicRun};

use super::{fitted_b, rel_err, start_offset_in_world, Truth};

pub(super) fn print_tow_scan(
    run: &DynamicRun,
    spec: &str,
    truth: &HashMap<u64, Truth>,
    truth_b: &DMatrix<f64>,
    weights: &[f64; 6],
) {
    let offset = start_offset_in_world(run, truth);
    println!(
        "  tow scan: start error in the world {:.3?} m/s",
        offset.as_slice()
    );
    // LAG_PROBE_TOW_LAGS=l1,l2,...: also fitted at these lags, one per thruster (the
    // vehicle file's true ones), with the moving-water refit's drift states (a world-fixed
    // constant force and ramp) as the estimator restates the moved log: where the lag
    // search's profile and the truth part.
    let at: Vec<f64> = std::env::var("LAG_PROBE_TOW_LAGS")
        .map(|v| v.split(',').filter_map(|l| l.parse().ok()).collect())
        .unwrap_or_default();
    let states = thrusterd_core::estimator::dynamic::disturbance_states::DisturbanceStates {
        world_constant: true,
        world_ramp: true,
        ..Default::default()
    };
    for k in spec.split(',').filter_map(|k| k.parse::<f64>().ok()) {
        let Some(moved) = start_velocity::with_start_velocity(run, &(offset * k)) else {
            continue;
        };
        if !at.is_empty() {
            let drift = moved.restated(states);
            for (name, log) in [("plain", Some(&moved)), ("drift states", drift.as_ref())] {
                let Some(fit) = log.and_then(|l| l.refit(&at)) else {
                    continue;
                };
                let score = profile_score_weighted(&fit, weights).unwrap_or(f64::NAN);
                let (rot, acc) = fitted_b(log.unwrap(), &at)
                    .map_or((f64::NAN, f64::NAN), |b| rel_err(&b, truth_b));
                println!(
                    "    k {k:+.2} at the given lags, {name}: score {score:.4} err_rot {rot:.4} err_acc {acc:.4}"
                );
            }
        }
        let Some(fit) =
            learn_common_lag_weighted(&moved, &LagRange::default(), &Default::default(), weights)
        else {
            continue;
        };
        let score = profile_score_weighted(&fit.run, weights).unwrap_or(f64::NAN);
        let (rot, acc) =
            fitted_b(&moved, &[fit.lag_s]).map_or((f64::NAN, f64::NAN), |b| rel_err(&b, truth_b));
        println!(
            "    k {k:+.2}: lag {:.4} (sd_ln {:.4}) score {score:.4} err_rot {rot:.4} err_acc {acc:.4}",
            fit.lag_s, fit.sd_ln
        );
    }
}
