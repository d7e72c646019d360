//! The estimator under control: the dynamic method fed with whatever command was sent (the
//! controller's plus a dither), instead of its own pulses. See `crate::adaptation::identification`.

use std::collections::VecDeque;

use nalgebra::{DMatrix, Vector3};

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

    /// The estimate of a decision interval that did not stop the run, `elapsed_s` into it,
    /// for later decisions' settling check. The machine calls it when it applies the result,
    /// at a sample fixed in vehicle time, so a replay remembers the same ones. Kept while a
    /// later decision may still compare with it (two segments); the oldest's storage is
    /// reused once the shapes agree (the control thread applies results).
    pub fn remember_interval(&mut self, estimate: &Estimate, elapsed_s: f64) {
        let keep_s = 2.0 * self.cfg.segment_s;
        remember(
            &mut self.intervals,
            elapsed_s,
            &estimate.effectiveness,
            keep_s,
        );
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
        if judged && decision.is_stop() && !self.settled(estimate, elapsed_s, settle) {
            return StopDecision::Continue;
        }
        decision
    }

    /// Whether `estimate`, `elapsed_s` into the run, moved from the latest remembered one at
    /// least a segment older by at most `settle.factor` times its reducible bound, or
    /// `settle.floor`, in both row groups. Without such an estimate (or with one of another
    /// shape) it has not settled: nothing says it has. A segment, whatever the decisions'
    /// spacing: a wandering estimate moves little between close decisions.
    fn settled(&self, estimate: &Estimate, elapsed_s: f64, settle: Settle) -> bool {
        let Some(earlier) = a_segment_before(&self.intervals, elapsed_s, self.cfg.segment_s) else {
            return false;
        };
        let change = row_group_change(&estimate.effectiveness, earlier);
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

/// The most decision intervals' estimates kept for the settling check: two segments at the
/// finest spacing the configuration allows (`identification.settle_decision_s` >= 0.05 s of
/// the default 1 s segment) with room. With a longer segment the oldest go first, and a
/// decision that then finds none a segment old takes the estimate as unsettled: the wait
/// goes on, for at most `settle_wait_s`.
const MAX_INTERVALS: usize = 48;

/// `b`, `elapsed_s` into the run, appended to `intervals` (oldest first); the ones older than
/// `keep_s` before it, and the oldest beyond `MAX_INTERVALS`, dropped, the last of them giving
/// its storage when the shapes agree.
fn remember(
    intervals: &mut VecDeque<(f64, DMatrix<f64>)>,
    elapsed_s: f64,
    b: &DMatrix<f64>,
    keep_s: f64,
) {
    let mut spare = None;
    while intervals
        .front()
        .is_some_and(|(t, _)| *t < elapsed_s - keep_s || intervals.len() >= MAX_INTERVALS)
    {
        spare = intervals.pop_front().map(|(_, m)| m);
    }
    let m = match spare {
        Some(mut m) if m.shape() == b.shape() => {
            m.copy_from(b);
            m
        }
        _ => b.clone(),
    };
    intervals.push_back((elapsed_s, m));
}

/// The latest remembered estimate at least `segment_s` older than `elapsed_s`.
fn a_segment_before(
    intervals: &VecDeque<(f64, DMatrix<f64>)>,
    elapsed_s: f64,
    segment_s: f64,
) -> Option<&DMatrix<f64>> {
    intervals
        .iter()
        .rev()
        .find(|(t, _)| *t <= elapsed_s - segment_s + 1e-6)
        .map(|(_, m)| m)
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
    use super::{a_segment_before, remember, row_group_change, within_settle, MAX_INTERVALS};
    use nalgebra::DMatrix;
    use std::collections::VecDeque;

    #[test]
    fn a_decision_compares_with_the_estimate_a_segment_before_it() {
        let at = |v: f64| DMatrix::from_element(6, 5, v);
        let mut kept = VecDeque::new();
        // Decisions every 0.25 s from 2 s (the value stands for the time).
        for i in 0..=8 {
            let t = 2.0 + 0.25 * i as f64;
            remember(&mut kept, t, &at(t), 2.0);
        }
        let before = |t: f64| a_segment_before(&kept, t, 1.0).map(|m| m[(0, 0)]);
        assert_eq!(before(4.25), Some(3.25));
        assert_eq!(before(3.1), Some(2.0));
        // Nothing a segment old: no comparison (the caller reads that as unsettled).
        assert_eq!(before(2.9), None);
        // Decisions a segment apart, as before the finer spacing: the one before.
        let mut sparse = VecDeque::new();
        for t in [1.0, 2.0, 3.0] {
            remember(&mut sparse, t, &at(t), 2.0);
        }
        assert_eq!(
            a_segment_before(&sparse, 4.0, 1.0).map(|m| m[(0, 0)]),
            Some(3.0)
        );
    }

    #[test]
    fn only_two_segments_of_estimates_are_kept_and_never_more_than_the_cap() {
        let mut kept = VecDeque::new();
        for i in 0..=40 {
            let t = 0.1 * i as f64;
            remember(&mut kept, t, &DMatrix::from_element(6, 4, t), 2.0);
        }
        // 2.0 ..= 4.0 s kept (21 of 41), the oldest first.
        assert_eq!(kept.len(), 21);
        assert!(
            (kept.front().unwrap().0 - 2.0).abs() < 1e-9,
            "{:?}",
            kept.front()
        );
        assert_eq!(kept.back().unwrap().1[(0, 0)], 4.0);
        // A thruster added: the new shape is kept as it is.
        remember(&mut kept, 4.1, &DMatrix::from_element(6, 5, 1.0), 2.0);
        assert_eq!(kept.back().unwrap().1.shape(), (6, 5));
        // Decisions finer than the cap allows over two segments: at most the cap.
        let mut dense = VecDeque::new();
        for i in 0..200 {
            remember(&mut dense, 0.01 * i as f64, &DMatrix::zeros(6, 4), 2.0);
        }
        assert_eq!(dense.len(), MAX_INTERVALS);
    }

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
