//! The stopped open loop's model made again with the dead-reckoned velocity's drift taken
//! out (`estimator::dynamic::velocity_drift`): only in the solve job that makes the model,
//! since the search refits the log about 120 times and the lag is searched again after it.

// The estimator's fields and helpers are the parent's: these are its methods, by job.
use super::*;
use crate::estimator::dynamic::velocity_drift;

impl Estimator {
    /// `estimate` (the one a stopping open loop swaps in) made again from the log with the
    /// velocity's drift the log supports taken out, its lag searched again; otherwise
    /// unchanged. Only the dynamic method's open loop in still water (where a long rest saw
    /// the water move, the moving-water refit's world-fixed ramp takes a drift already; where
    /// the fit leaves rotation unexplained, its states do), with
    /// `velocity_drift_search_mps2` set and a gyro quiet enough to learn the lag (the lag is
    /// what the drift biases; at a noisier gyro the dead-reckoned velocity is mostly error,
    /// and taking a ramp out of it changed nothing: docs/study.md).
    /// Whether the drift was searched (kept or not).
    pub fn search_velocity_drift(&self, estimate: &mut Estimate) -> bool {
        let max = self.cfg.velocity_drift_search_mps2;
        if self.cfg.method != Method::Dynamic
            || self.under_control
            || max <= 0.0
            || self.rest_water == Some(RestWater::Moved)
            || !self.learns_lag()
        {
            return false;
        }
        let (Some(run), Some(terms)) = (self.dynamic.as_ref(), estimate.dynamics.as_ref()) else {
            return false;
        };
        // Still water only (the reach rule's premise too): where the fit leaves rotation
        // unexplained, the moving-water refit's states are at work on the same log.
        if terms.command_exponent.is_some()
            || terms.unexplained_rate_radps > crate::estimator::STILL_WATER_UNEXPLAINED_RADPS
        {
            return false;
        }
        let n = self.thrusters();
        let found = velocity_drift::search_velocity_drift(run, &terms.fitted_lags(n), max)
            .filter(|f| f.log_likelihood_ratio > crate::estimator::VELOCITY_DRIFT_EVIDENCE);
        let Some(found) = found else {
            return true;
        };
        // Not refitted here: the lag is learned again on it, which refits from the log (a
        // refit keeps no log to learn from).
        let Some(corrected) = velocity_drift::without_drift(run, &found.rate_ned_mps2) else {
            return true;
        };
        let mut searching = self.clone();
        searching.dynamic = Some(corrected);
        let mut again = searching.dynamic_estimate();
        // Its bound no tighter than the model's without the search: the drift is one more
        // thing fitted, and its own uncertainty is not counted.
        again.keep_bound_no_tighter_than(estimate);
        if let Some(d) = again.dynamics.as_mut() {
            d.velocity_drift_ned_mps2 = Some(found.rate_ned_mps2.into());
        }
        *estimate = again;
        true
    }
}
