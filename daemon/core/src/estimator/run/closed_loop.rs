//! The estimator under control: the dynamic method fed with whatever command was sent (the
//! controller's plus a dither), instead of its own pulses. See `crate::adaptation::identification`.

use nalgebra::Vector3;

use super::{Estimate, Estimator, StopDecision};
use crate::estimator::config::Method;
use crate::estimator::dynamic::spin_state::SpinState;
use crate::estimator::dynamic::thrust_curve::ThrustCurveProbe;

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
    pub fn probe_thrust_curve(&mut self) -> bool {
        self.thrust_curve = self.dynamic.as_ref().map(ThrustCurveProbe::new);
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

    /// Stop under control: never before `min_s`, at `max_s` whatever the bound (reported as
    /// the limit), in between once both error bounds reached the target.
    pub fn closed_loop_decision(
        &self,
        estimate: &Estimate,
        elapsed_s: f64,
        min_s: f64,
        max_s: f64,
    ) -> StopDecision {
        if elapsed_s >= max_s {
            return StopDecision::MaxPulses;
        }
        if elapsed_s < min_s {
            return StopDecision::Continue;
        }
        self.bound_decision(estimate, false)
    }
}
