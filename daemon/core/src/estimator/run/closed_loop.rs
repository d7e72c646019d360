//! The estimator under control: the dynamic method fed with whatever command was sent (the
//! controller's plus a dither), instead of its own pulses. See `crate::adaptation::identification`.

use nalgebra::Vector3;

use super::{Estimate, Estimator, StopDecision};
use crate::estimator::config::Method;
use crate::estimator::dynamic::spin_state::SpinState;
use crate::estimator::dynamic::thrust_curve::ThrustCurveProbe;
use crate::estimator::linalg::rel_frobenius_err_per_row_group as row_group_change;

impl Estimator {
    /// Start the dynamic fit now, for samples whose command the caller gives
    /// (`push_commanded_sample`), forward and reverse thrust fitted apart (the controller's
    /// commands take every level around zero; see `DynamicRun::split`). The navigation starts
    /// from the specific force given with `with_rest_specific_force` (the mean while holding)
    /// and the vertical velocity given with `with_rest_velocity_down` (else zero). False, and
    /// nothing started, for the static methods: they need pulses from rest.
    pub fn begin_closed_loop(&mut self) -> bool {
        if self.cfg.method != Method::Dynamic {
            return false;
        }
        self.pulse = None;
        self.under_control = true;
        self.dynamic = Some(self.dynamic_run(true, false));
        self.thrust_curve = None;
        true
    }

    /// Start the fit's thrust lags from the thrusters' state under control, tracked from the
    /// commands sent (`dynamic::spin_state`), instead of from rest. After `begin_closed_loop`,
    /// before the first sample; the state's lags must be this fit's
    /// (`spin_state::lags_for_fit`).
    pub fn start_spun_up(&mut self, state: &SpinState) {
        if let Some(run) = self.dynamic.as_mut() {
            run.start_spun_up(state);
        }
    }

    /// [`Self::begin_closed_loop`] with the thrust columns fitted by instrumental variables:
    /// every sample then brings the dither's signs as their instruments
    /// (`push_commanded_sample`'s `instruments`; see `dynamic::instruments`).
    pub fn begin_instrumented_closed_loop(&mut self) -> bool {
        if !self.begin_closed_loop() {
            return false;
        }
        self.dynamic = self.dynamic.take().map(|run| run.with_instruments());
        true
    }

    /// Fit the samples from now on again with bent commands too, to tell whether the thrust
    /// follows the command linearly (`dynamic::thrust_curve`; the estimate's
    /// `DynamicTerms::thrust_curve`). After `begin_closed_loop`; false, nothing started,
    /// before. Three more fits per sample: for the identification, not every refinement
    /// window.
    pub fn probe_thrust_curve(&mut self, ratio: f64) -> bool {
        self.thrust_curve = self
            .dynamic
            .as_ref()
            .map(|run| ThrustCurveProbe::new(run, ratio));
        self.thrust_curve.is_some()
    }

    /// One sample under control at `t_s`: bias-free gyro (rad/s), the raw specific force
    /// (m/s^2), depth (m) if measured, and `u`, the command sent during the interval this
    /// sample ends (model units, before any deadband compensation). Ignored before
    /// `begin_closed_loop`; a sample with a non-finite value or the wrong length is dropped.
    pub fn push_commanded_sample(
        &mut self,
        t_s: f64,
        gyro: &Vector3<f64>,
        specific_force: &Vector3<f64>,
        depth: Option<f64>,
        u: &[f64],
        instruments: Option<&[f64]>,
    ) {
        let Some(run) = self.dynamic.as_mut() else {
            return;
        };
        if u.len() != self.max_command.len() {
            return;
        }
        for (m, v) in self.max_command.iter_mut().zip(u) {
            if v.is_finite() {
                *m = m.max(v.abs());
            }
        }
        run.push_instrumented(t_s, gyro, specific_force, depth, Some(u), instruments);
        if let (Some(probe), Some((t_nav, nav))) = (self.thrust_curve.as_mut(), run.last_nav()) {
            if *t_nav == t_s {
                probe.push(t_s, gyro, nav, u);
            }
        }
        self.samples += 1;
    }

    /// One decision interval under control is over: counted like a pulse (status shows it).
    pub fn end_interval(&mut self) {
        self.pulses += 1;
    }

    /// The relative error of B that the lags given by `with_learned_lag` /
    /// `with_learned_thruster_lags` carry (`Model::lag_rel_err`): the fits that do not learn
    /// the lag again add it to their bound as a floor, which the stop rule does not wait on.
    pub fn with_inherited_lag_error(mut self, rel_err: [f64; 2]) -> Self {
        if rel_err.iter().all(|e| e.is_finite() && *e >= 0.0) {
            self.inherited_lag_rel_err = rel_err;
        }
        self
    }

    /// The relative error the navigation of the run that learned the prior's columns left in
    /// them (`DynamicPrior::navigation_rel_err`): a fit that keeps those columns keeps it, in
    /// the share of B they are, and adds it to its bound as a floor the stop rule does not
    /// wait on (`run/navigation_bound.rs`).
    pub fn with_inherited_navigation_error(mut self, rel_err: [f64; 2]) -> Self {
        if rel_err.iter().all(|e| e.is_finite() && *e >= 0.0) {
            self.inherited_navigation_rel_err = rel_err;
        }
        self
    }

    /// The estimate of a decision interval that did not stop the run, for the next
    /// decision's settling check. The machine calls it when it applies the result, at a
    /// sample fixed in vehicle time, so a replay remembers the same one. Copied in place once
    /// the shapes agree (the control thread applies results).
    pub fn remember_interval(&mut self, estimate: &Estimate) {
        let b = &estimate.effectiveness;
        match self.last_interval.as_mut() {
            Some(m) if m.shape() == b.shape() => m.copy_from(b),
            _ => self.last_interval = Some(b.clone()),
        }
    }

    /// Stop under control: never before `min_s`, at `max_s` whatever the bound (reported as
    /// the limit), in between once both error bounds reached the target and, for up to
    /// `settle.wait_s` after `min_s`, the estimate has settled (`Settle`).
    pub fn closed_loop_decision(
        &self,
        estimate: &Estimate,
        elapsed_s: f64,
        [min_s, max_s]: [f64; 2],
        settle: Settle,
    ) -> StopDecision {
        if elapsed_s >= max_s {
            return StopDecision::MaxPulses;
        }
        if elapsed_s < min_s {
            return StopDecision::Continue;
        }
        let decision = self.bound_decision(estimate, false);
        let judged = settle.factor > 0.0 && elapsed_s < min_s + settle.wait_s;
        if judged && decision.is_stop() && !self.settled(estimate, settle) {
            return StopDecision::Continue;
        }
        decision
    }

    /// Whether `estimate` moved from the last interval's by at most `settle.factor` times its
    /// reducible bound, or `settle.floor`, in both row groups. Without a last estimate (or one
    /// of another shape) it has not settled: nothing says it has.
    fn settled(&self, estimate: &Estimate, settle: Settle) -> bool {
        let Some(last) = self.last_interval.as_ref() else {
            return false;
        };
        let change = row_group_change(&estimate.effectiveness, last);
        // The part of the bound more data reduces: a floor (the inherited lags') says nothing
        // of how much the estimate may still move.
        within_settle(
            change,
            super::fits::reducible_bounds(estimate),
            settle.factor,
            settle.floor,
        )
    }
}

/// The identification's wait for a settled estimate (`IdentificationConfig::settle`,
/// `settle_floor`, `settle_wait_s`): a bound met at `min_s` stops the run only if the
/// estimate moved since the decision before by at most `factor` times its bound, or `floor`;
/// otherwise the run goes on for at most `wait_s` more, and stops on its bound after that.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Settle {
    /// Times the reducible bound (0: no wait).
    pub factor: f64,
    /// The move always allowed, relative.
    pub floor: f64,
    /// How long after `min_s` the wait lasts at most, s.
    pub wait_s: f64,
}

impl Settle {
    /// No wait: the bound alone decides.
    pub const OFF: Settle = Settle {
        factor: 0.0,
        floor: 0.0,
        wait_s: 0.0,
    };
}

/// Whether each row group's `change` is at most `settle` times its `bound`, or `floor` (a
/// bound that is NaN allows the floor only; an infinite change is never within).
fn within_settle(change: [f64; 2], bound: [f64; 2], settle: f64, floor: f64) -> bool {
    change
        .iter()
        .zip(bound)
        .all(|(c, b)| *c <= (settle * b).max(floor))
}

#[cfg(test)]
mod tests {
    use super::{row_group_change, within_settle};
    use nalgebra::DMatrix;

    #[test]
    fn the_change_is_measured_per_row_group_relative_to_the_last_estimate() {
        let old = DMatrix::from_fn(6, 4, |r, c| 1.0 + (r * 4 + c) as f64 * 0.1);
        let mut new = old.clone();
        // Only the acceleration rows move, by 2 % of their norm.
        let norm_acc = old.rows(3, 3).norm();
        new[(4, 2)] += 0.02 * norm_acc;
        let [rot, acc] = row_group_change(&new, &old);
        assert_eq!(rot, 0.0);
        assert!((acc - 0.02).abs() < 1e-12, "{acc}");
        // A thruster added or removed: nothing to compare with.
        let other = DMatrix::from_element(6, 5, 1.0);
        assert_eq!(row_group_change(&other, &old), [f64::INFINITY; 2]);
        assert_eq!(
            row_group_change(&old, &DMatrix::zeros(6, 4)),
            [f64::INFINITY; 2]
        );
    }

    #[test]
    fn an_estimate_moving_more_than_its_bound_and_the_floor_has_not_settled() {
        // amour5_reverse60 noise-free at 3 s of dither: moved 1.5 % under bounds of 0.6 /
        // 1.5 %: not settled (the rotation rows). A steady AMOUR-5 at a realistic IMU: moved
        // 0.4 / 1.9 % under 1.8 / 2.5 %: settled.
        assert!(!within_settle([0.015, 0.015], [0.006, 0.015], 1.0, 0.01));
        assert!(within_settle([0.004, 0.019], [0.018, 0.025], 1.0, 0.01));
        // Noise-free, bounds of 0.1 %: a move under the floor is settled, one over it not.
        assert!(within_settle([0.005, 0.004], [0.001, 0.010], 1.0, 0.01));
        assert!(!within_settle([0.012, 0.004], [0.001, 0.010], 1.0, 0.01));
        // No bound (NaN) allows the floor only; an infinite move never settles.
        assert!(within_settle([0.009, 0.0], [f64::NAN, 0.0], 1.0, 0.01));
        assert!(!within_settle([f64::INFINITY, 0.0], [1.0, 1.0], 1.0, 0.01));
    }
}
