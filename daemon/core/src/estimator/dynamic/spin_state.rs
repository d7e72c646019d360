//! The thrusters' spin-up state when a fit starts under control.
//!
//! The fit models each thruster's thrust as its command through a first-order lag. A run
//! from rest starts that lag at zero, which is right: the thrusters are stopped. A refinement
//! window or an identification under control starts while the controller drives them, and a
//! lag started at zero then describes thrust that is not there for the first few time
//! constants. That alone was the under-control fit's whole noise-free floor: AMOUR-5 held
//! through pitch steps, its windows' rotation rows 1-2 % off the simulator's truth with the
//! commands, 0.1 % with the thrusters' true state at the window's start (`thrusterctl study
//! sweep window_floor`, docs/study.md, "The under-control fit's floor"). So whoever feeds a
//! fit under control tracks the commands it sent through the same lags ([`SpinState`]) and
//! starts the fit from there ([`DynamicRun::start_spun_up`]).

use serde::{Deserialize, Serialize};
use thruster_protocol::MAX_THRUSTERS;

use super::{DynamicRun, DynamicTerms};

/// The commands sent, forward and reverse parts apart, each through its thruster's lag (model
/// units): the lag states a fit would have reached had it run all along. Pure and
/// allocation-free: a control tick advances it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SpinState {
    #[serde(with = "crate::serde_arrays::array")]
    forward: [f64; MAX_THRUSTERS],
    #[serde(with = "crate::serde_arrays::array")]
    reverse: [f64; MAX_THRUSTERS],
    /// The command held since `at_s`, which the next advance runs the lags on.
    #[serde(with = "crate::serde_arrays::array")]
    held: [f64; MAX_THRUSTERS],
    /// The time the state is at, s (None: nothing sent yet; the thrusters at rest).
    at_s: Option<f64>,
}

impl SpinState {
    /// Runs the lags to `t_s` on the command held since the last call; `lags` are the
    /// thrusters' time constants, s (one per thruster). A gap counts as at most 0.1 s, as in
    /// the fit itself; a step back in time moves nothing.
    pub fn advance_to(&mut self, t_s: f64, lags: &[f64]) {
        if let Some(t0) = self.at_s {
            let dt = (t_s - t0).min(MAX_LAG_STEP_S);
            if dt > 0.0 {
                let n = lags.len().min(MAX_THRUSTERS);
                for (i, &lag_s) in lags[..n].iter().enumerate() {
                    let a = lag_step(dt, lag_s);
                    let u = self.held[i];
                    self.forward[i] += a * (u.max(0.0) - self.forward[i]);
                    self.reverse[i] += a * (u.min(0.0) - self.reverse[i]);
                }
            }
        }
        if t_s.is_finite() && self.at_s.is_none_or(|t0| t_s > t0) {
            self.at_s = Some(t_s);
        }
    }

    /// The command sent from now on (model units), as the thrusters get it: within [-1, 1],
    /// a non-finite one as 0 (the machine's last line of defence).
    pub fn hold(&mut self, sent: &[f64]) {
        let n = sent.len().min(MAX_THRUSTERS);
        for (h, u) in self.held[..n].iter_mut().zip(sent) {
            *h = if u.is_finite() {
                u.clamp(-1.0, 1.0)
            } else {
                0.0
            };
        }
        self.held[n..].fill(0.0);
    }

    /// The time the state is at, s (None before the first advance).
    pub fn at_s(&self) -> Option<f64> {
        self.at_s
    }
}

/// The longest step a lag is run over at once, s: a longer gap between samples counts as this.
pub(crate) const MAX_LAG_STEP_S: f64 = 0.1;

/// The share of the way to its target a first-order lag of `lag_s` covers in `dt` (exact for
/// a command held over the step; 1 without a lag). The fit and [`SpinState`] both step with
/// it, so a fit started spun up holds the lag states of one that ran all along.
pub(crate) fn lag_step(dt: f64, lag_s: f64) -> f64 {
    if lag_s > 0.0 {
        1.0 - (-dt / lag_s).exp()
    } else {
        1.0
    }
}

/// Each thruster's lag, s, as a fit under control takes them (`Estimator::with_learned_lag`
/// and `with_learned_thruster_lags`): `per_thruster` when there is one per thruster, each
/// finite and non-negative; else `learned` when finite and non-negative; else `configured_s`.
/// What a [`SpinState`] for that fit must advance with.
pub fn lags_for_fit(
    n: usize,
    configured_s: f64,
    learned: Option<f64>,
    per_thruster: Option<&[f64]>,
) -> [f64; MAX_THRUSTERS] {
    let n = n.min(MAX_THRUSTERS);
    let mut out = [0.0; MAX_THRUSTERS];
    match per_thruster.filter(|l| l.len() == n && l.iter().all(|v| v.is_finite() && *v >= 0.0)) {
        Some(l) => out[..n].copy_from_slice(l),
        None => {
            let one = learned
                .filter(|l| l.is_finite() && *l >= 0.0)
                .unwrap_or(configured_s);
            out[..n].fill(one);
        }
    }
    out
}

impl DynamicRun {
    /// The thrusters were at rest until `t_s`, when the first command was applied: the first
    /// sample, taken after it, runs the lags on from `t_s` (its refits from the log too).
    /// Why: the open-loop run's first sample comes one sample period after the first pulse
    /// began, and its lags started there from rest trailed the thrust by that period all
    /// through the first pulse: noise-free with every thruster at 0.03 s (amour5_lag30ms) the
    /// lag states were 1.4 % rms off the simulator's thrust at 200 Hz (0.3 % at 1 kHz), and the
    /// model 0.004 / 0.013 off (docs/study.md, "The first sample's lag"). Before the first
    /// sample only; ignored after it, or for a time that is not finite.
    pub fn start_from_rest_at(&mut self, t_s: f64) {
        if self.last_t_s.is_none() && t_s.is_finite() {
            self.at_rest_until_s = Some(t_s);
        }
    }

    /// Start the lags from `state` (at its time) instead of from rest: the run's first sample,
    /// however long after, runs them on to it with that sample's command. Before the first
    /// sample only; ignored after it, or for a state with no time.
    pub fn start_spun_up(&mut self, state: &SpinState) {
        let Some(t_s) = state.at_s else {
            return;
        };
        if self.last_t_s.is_some() {
            return;
        }
        let n = self.n.min(MAX_THRUSTERS);
        for i in 0..n {
            let (f, r) = (state.forward[i], state.reverse[i]);
            if self.split {
                self.lag[i] = f;
                self.lag[self.n + i] = r;
            } else {
                // The shape is linear on each side, so its lag state is the sides' shaped.
                self.lag[i] = DynamicTerms::thrust_shape(self.asymmetry, f)
                    + DynamicTerms::thrust_shape(self.asymmetry, r);
            }
            if let Some(a) = self.abs_each.get_mut(i) {
                *a = f - r;
            }
        }
        if !self.split {
            let abs: f64 = (0..n).map(|i| state.forward[i] - state.reverse[i]).sum();
            self.lag_abs = abs / self.n.max(1) as f64;
        }
        self.lag_prev.copy_from_slice(&self.lag);
        self.spun_up_at_s = Some(t_s);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::navigation::DepthAid;
    use nalgebra::Vector3;

    /// The tracked state is the fit's own lag run all along: a run started from it at any
    /// time holds, sample by sample, the lag states of a run that saw every command.
    #[test]
    fn a_run_started_spun_up_has_the_lag_states_of_one_that_ran_all_along() {
        let lags = [0.1, 0.05, 0.2];
        let rest = Vector3::new(0.0, 0.0, -9.81);
        let command = |k: usize| {
            let t = k as f64 * 0.005;
            [
                (3.0 * t).sin(),
                0.6 * (7.0 * t).cos(),
                if k % 40 < 20 { 0.8 } else { -0.5 },
            ]
        };
        for split in [false, true] {
            let make = || {
                let mut run = if split {
                    DynamicRun::split(3, 0.1, 0.5, &rest, DepthAid::default())
                } else {
                    DynamicRun::new(3, 0.1, 0.5, &rest, DepthAid::default()).with_asymmetry(0.78)
                };
                run.set_lags(&lags);
                run
            };
            let mut all_along = make();
            let mut state = SpinState::default();
            let (mut late, mut cold) = (make(), make());
            let zero = Vector3::zeros();
            for k in 0..400 {
                let t = k as f64 * 0.005;
                state.advance_to(t, &lags);
                // The sample at t ends the interval the last command was held over.
                let u = if k == 0 { [0.0; 3] } else { command(k - 1) };
                all_along.push(t, &zero, &-rest, None, Some(&u));
                if k == 250 {
                    late.start_spun_up(&state);
                }
                if k > 250 {
                    late.push(t, &zero, &-rest, None, Some(&u));
                    cold.push(t, &zero, &-rest, None, Some(&u));
                    for (a, b) in all_along.lag.iter().zip(&late.lag) {
                        assert!((a - b).abs() < 1e-12, "split {split}, sample {k}: {a} {b}");
                    }
                    assert!((all_along.lag_abs - late.lag_abs).abs() < 1e-12);
                }
                if k == 251 {
                    // Started from rest instead, the same run is far off at first.
                    let off = all_along
                        .lag
                        .iter()
                        .zip(&cold.lag)
                        .map(|(a, b)| (a - b).abs());
                    assert!(off.fold(0.0, f64::max) > 0.1, "split {split}");
                }
                state.hold(&command(k));
            }
        }
    }

    /// A run whose thrusters left rest at t0, its first sample one period later, holds at that
    /// sample the thrust the first command has spun up to over the period (not zero: started
    /// at the first sample it trailed the thrust by a period all through the first pulse), and
    /// so do its refits from the log, at any lag.
    #[test]
    fn a_run_started_from_rest_runs_its_lags_from_the_first_command() {
        let rest = Vector3::new(0.0, 0.0, -9.81);
        let zero = Vector3::zeros();
        let (t0, dt, lag) = (3.005, 0.005, 0.03);
        let u = [0.78, -1.0];
        let mut run = DynamicRun::new(2, lag, 0.5, &rest, DepthAid::default()).with_log(64);
        run.start_from_rest_at(t0);
        run.push(t0 + dt, &zero, &-rest, None, Some(&u));
        let a = 1.0 - (-dt / lag).exp();
        for (x, v) in run.lag.iter().zip(&u) {
            assert!((x - a * v).abs() < 1e-12, "{x} against {}", a * v);
        }
        // Ignored once a sample is in: the lags go on from the last sample.
        run.start_from_rest_at(t0 + dt);
        run.push(t0 + 2.0 * dt, &zero, &-rest, None, Some(&u));
        let a2 = 1.0 - (-2.0 * dt / lag).exp();
        for (x, v) in run.lag.iter().zip(&u) {
            assert!((x - a2 * v).abs() < 1e-12);
        }
        let refit = run.refit(&[0.06]).expect("a log");
        let a2 = 1.0 - (-2.0 * dt / 0.06f64).exp();
        for (x, v) in refit.lag.iter().zip(&u) {
            assert!((x - a2 * v).abs() < 1e-12, "refit: {x} against {}", a2 * v);
        }
        // Without it, the first sample starts the lags at rest.
        let mut cold = DynamicRun::new(2, lag, 0.5, &rest, DepthAid::default());
        cold.push(t0 + dt, &zero, &-rest, None, Some(&u));
        assert!(cold.lag.iter().all(|x| *x == 0.0));
    }

    #[test]
    fn a_state_moves_only_forward_in_time_and_holds_what_the_machine_would_send() {
        let mut s = SpinState::default();
        s.advance_to(1.0, &[0.1]);
        s.hold(&[f64::NAN]);
        s.advance_to(2.0, &[0.1]);
        assert_eq!(s.forward[0], 0.0);
        s.hold(&[3.0]);
        s.advance_to(2.05, &[0.1]);
        assert!((s.forward[0] - (1.0 - (-0.5f64).exp())).abs() < 1e-12);
        s.advance_to(1.5, &[0.1]);
        assert_eq!(s.at_s(), Some(2.05));
    }
}
