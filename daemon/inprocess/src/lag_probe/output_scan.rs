//! LAG_PROBE_OUTPUTS: each of the six outputs' ln residual variance on the run's log at the
//! common lag learned, at the lags per thruster learned, and at LAG_PROBE_LAGS (the
//! simulator's, one per thruster). Why: a lag per thruster is placed by the sum of those
//! logs (each floored at a share of its group's largest, `thruster_lags::SCORE_FLOOR`);
//! where the learned lags beat the truth this says which outputs pull them there.

use thrusterd_core::estimator::dynamic::lag_search::profile_score_weighted;
use thrusterd_core::estimator::dynamic::DynamicRun;

use crate::estimation::Outcome;

/// The six outputs' ln residual variances of `run`'s log fitted at `lags`.
fn ln_variances(run: &DynamicRun, lags: &[f64]) -> Option<[f64; 6]> {
    let fit = run.refit(lags)?;
    let mut out = [0.0; 6];
    for (a, o) in out.iter_mut().enumerate() {
        let mut w = [0.0; 6];
        w[a] = 1.0;
        *o = profile_score_weighted(&fit, &w)?;
    }
    Some(out)
}

pub(super) fn print_output_scan(run: &DynamicRun, outcome: &Outcome) {
    let n = run.thrusters();
    let mut rows: Vec<(String, Vec<f64>)> = vec![("common".into(), vec![outcome.spin_up_s; n])];
    if outcome.terms.spin_up_per_thruster_s.len() == n {
        rows.push((
            "learned".into(),
            outcome.terms.spin_up_per_thruster_s.clone(),
        ));
    }
    if let Ok(given) = std::env::var("LAG_PROBE_LAGS") {
        let lags: Vec<f64> = given
            .split(',')
            .map(|v| v.parse().expect("LAG_PROBE_LAGS: seconds"))
            .collect();
        rows.push(("given".into(), lags));
    }
    let samples = run.samples() as f64;
    let mut common_sum = None;
    for (name, lags) in rows {
        let Some(v) = ln_variances(run, &lags) else {
            continue;
        };
        let sum: f64 = v.iter().sum();
        let base = *common_sum.get_or_insert(sum);
        println!(
            "  outputs at {name} {:.4?}: ln var {:.2?}, sum {sum:.3}, ln L over common {:.1}",
            lags,
            v,
            samples / 2.0 * (base - sum)
        );
    }
}
