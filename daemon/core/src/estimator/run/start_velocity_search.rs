//! The stopped open loop's model made again with the vehicle's steady velocity through the
//! water at the run's start searched (`estimator::dynamic::start_velocity`): only where a long
//! rest saw the vehicle move, and only in the solve job that makes the model, since the search
//! refits the log about 120 times and the stop rule does not wait on it.

// The estimator's fields and helpers are the parent's: these are its methods, by job.
use super::*;
use crate::estimator::dynamic::disturbance_states::DisturbanceStates;
use crate::estimator::dynamic::start_velocity;

impl Estimator {
    /// `estimate` (the one a stopping open loop swaps in) made again with the start velocity
    /// searched in the moving-water refit, where the log supports one; otherwise unchanged.
    /// Only the dynamic method's open loop, with `start_velocity_search_mps` set, after a long
    /// rest that saw the water move and with a gyro quiet enough for the drift states
    /// (`moving_rest_drift_states`). Why: a 10 N tether met after 125 s idle towed the
    /// vehicle at 0.77 m/s, which the navigation started from zero, and left AMOUR-5's
    /// rotation rows 2.1x their bound at a realistic IMU through a lag learned 4 % long
    /// (docs/study.md, "A tether's tow at the start").
    pub fn search_start_velocity(&self, estimate: &mut Estimate) {
        if self.cfg.method != Method::Dynamic
            || self.under_control
            || self.cfg.start_velocity_search_mps <= 0.0
            || !self.drift_states_from_rest()
        {
            return;
        }
        let mut searching = self.clone();
        searching.searching_start_velocity = true;
        let mut again = searching.dynamic_estimate();
        if again
            .dynamics
            .as_ref()
            .is_none_or(|d| d.start_velocity_ned_mps.is_none())
        {
            return;
        }
        // Its bound no tighter than the model's without the search: the start velocity is
        // one more thing fitted, and its own uncertainty is not counted. Measured without
        // this: in the faintest swell a start velocity the log liked moved eight_vectored's
        // acceleration rows 0.063 -> 0.068 off and their bound 0.045 -> 0.034 (1.99x).
        again.keep_bound_no_tighter_than(estimate);
        *estimate = again;
    }

    /// `moving` (the log restated with `states`) with the start velocity the log supports
    /// taken into its velocity and restated again, and that velocity; `moving` and None where
    /// the search is off (`start_velocity_search_mps` 0), finds nothing the log supports by
    /// [`START_VELOCITY_EVIDENCE`](crate::estimator::START_VELOCITY_EVIDENCE), or fails. The
    /// search is at the lags `e` (the fit without states) learned; the caller searches the lag
    /// again on the result.
    pub(super) fn with_start_velocity(
        &self,
        moving: DynamicRun,
        e: &Estimate,
        states: DisturbanceStates,
    ) -> (DynamicRun, Option<Vector3<f64>>) {
        let max = self.cfg.start_velocity_search_mps;
        let Some(terms) = e.dynamics.as_ref().filter(|_| max > 0.0) else {
            return (moving, None);
        };
        let n = self.thrusters();
        let found = start_velocity::search_start_velocity(&moving, &terms.fitted_lags(n), max)
            .filter(|f| f.log_likelihood_ratio > crate::estimator::START_VELOCITY_EVIDENCE);
        let Some(found) = found else {
            return (moving, None);
        };
        match start_velocity::with_start_velocity(&moving, &found.velocity_ned_mps)
            .and_then(|m| m.restated(states))
        {
            Some(towed) => (towed, Some(found.velocity_ned_mps)),
            None => (moving, None),
        }
    }
}
