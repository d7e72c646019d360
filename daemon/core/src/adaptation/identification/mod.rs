//! Closed-loop identification: how an estimation runs while a model is in force. The
//! attitude/depth controller keeps holding its setpoint and a designed dither is added to its
//! commands; the dynamic estimator regresses on the total command actually sent.
//!
//! Why: open loop, the controller lets go and the pulses tumble the vehicle (hot-swap
//! experiment: 20-49 deg of tilt during a re-estimation). With the controller on, the vehicle
//! stays near its setpoint and only the dither's share of the motion is spent on learning.
//!
//! Why the dynamic method only: its regression takes any command history (it integrates the
//! command through the thruster lag next to damping, restoring and Coriolis terms), while the
//! static methods need pulses from rest.
//!
//! The dither is a random binary sequence per thruster (independent signs held for `hold_s`),
//! so the thruster columns stay uncorrelated with each other and with the controller's part of
//! the command (which reacts to the motion, a smooth function of the past dither). Pure: the
//! machine calls it with the vehicle time.

pub mod carry_over;
pub mod fight;
pub mod sea_state;

use serde::{Deserialize, Serialize};

use crate::estimator::Settle;
use thruster_driver_kit::Range;
use thruster_protocol::MAX_THRUSTERS;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IdentificationConfig {
    /// Estimate under control whenever a model is in force (learned, nominal from the declared
    /// geometry, cached or loaded) and the daemon is controlling (default true). Without a
    /// model, and with `false`, an estimation runs open loop: level, rest, pulses.
    pub closed_loop: bool,
    /// Dither amplitude for a quiet IMU, a fraction of full command added to the controller's
    /// (default 0.3; forward commands are scaled by `estimator.reverse_ratio` so each
    /// thruster's mean thrust stays zero). Measured in-process on AMOUR-5 after an announced
    /// 45 degree rotation (daemon/core/tests/closed_loop.rs, docs/experiments.md): realistic
    /// IMU, 0.2 / 0.3 of full command gave a model in 6.3 / 5.0 s at 2.9 / 3.8 deg of tilt.
    pub dither: f64,
    /// Sized to the noise: the amplitude is `dither * sqrt(sigma_rot / dither_noise_ref_rad_s)`,
    /// at least `dither` and at most `dither_max` (defaults 0.02 rad/s and 1.0). Why: the
    /// fit's error grows with the gyro noise over the amplitude, and the attitude budget
    /// leaves room at high noise. At the paper's noise (0.25 rad/s) 0.3 / 0.6 / 0.8 gave
    /// 0.081 / 0.048 / 0.045 of the truth within the 20 s limit at 5.1 / 7.9 / 11.4 deg of
    /// largest tilt (seeds 1-5). 1.0 since 2026-12-01 (0.6 before; only a gyro noisier than
    /// 0.08 rad/s reaches either): a thruster turned and announced, paper noise, seeds 1-5,
    /// the new model after 10.4 / 11.8 / 17.8 s mean on AMOUR-5 / six_dof / eight_vectored
    /// instead of 11.6 / 12.4 / 20.2 s, the same errors, the largest tilt 8.4 deg instead of
    /// 8.3 (the budget's fade holds it); docs/study.md, issue 30.
    pub dither_noise_ref_rad_s: f64,
    pub dither_max: f64,
    /// Each half of a thruster's coded dither pair lasts this long, s (default 0.05: the
    /// shorter the pair, the less of it passes the control loop as tilt; 0.1 s doubled the
    /// tilt for the same model quality).
    pub hold_s: f64,
    /// The hold without dither before the dither starts, s, when an earlier run has measured
    /// the noise (default 0.5; otherwise the hold lasts `machine.noise_s` and measures it).
    /// It lets the controller take up the model the change brought, and the navigation starts
    /// from the hold's mean specific force. 1 s until 2026-12-02: the vehicle turns and
    /// accelerates while held on the new geometry's nominal model, so a longer hold's mean
    /// was further from the tilt the dither starts from (eight_vectored noise-free 1.4 deg off
    /// the truth, its acceleration rows 0.029 off; 0.010 with 0.5 s), and it cost a second of
    /// every identification. Shorter was worse at a realistic IMU: with no hold the
    /// acceleration rows came out 0.027 against 0.017 (AMOUR-5, seeds 1-10; docs/study.md,
    /// "Half a second of hold"). A vehicle not held within half `attitude_budget_deg` when the
    /// lead-in ends is held for `machine.noise_s` (or this, if longer): a nominal model that
    /// cannot hold the vehicle (amour5_top45) had its fight cut short by the hold watch with
    /// the lead-in alone.
    pub lead_in_s: f64,
    /// Attitude error budget, deg (default 10): the dither fades out linearly between half
    /// the budget and the budget, so the controller always has the authority to come back.
    pub attitude_budget_deg: f64,
    /// Shortest identification, s of dither (default 3; 4 before 2026-12-02, when a model
    /// wandering with its stop time was taken at 3 s: `settle` waits for those), and longest
    /// (default 20: the best fit so far is then offered, and swapped in only if it passes
    /// `machine.max_swap_rel_err`; at the paper's noise the acceleration rows need longer than
    /// that to reach the 5 % target).
    pub min_s: f64,
    pub max_s: f64,
    /// A bound met at `min_s` is a stop only once the estimate has settled: since the decision
    /// before (one `estimator.segment_s` earlier) each row group moved by at most this times
    /// its own bound, or by `settle_floor` (default 1; 0: off). An estimate that still moves
    /// by more than it claims to be uncertain is not the model its bound describes: a vehicle
    /// whose thrusters are weaker in reverse than the model can say (amour5_reverse60,
    /// noise-free) wanders 0.011-0.023 off with the stop time under bounds of 0.006-0.011,
    /// moving 0.014-0.018 from one decision to the next; a steady one moves 0.002-0.014 under
    /// bounds of 0.015-0.030 (docs/study.md, issue 30). Not while the dither is under
    /// `min_dither_share`: a fight's model has its own confirmation (`fight`).
    pub settle: f64,
    /// How long after `min_s` an unsettled estimate is waited for, s (default 1); after that
    /// the bound alone decides. Longer waits did not pay: an estimate drifting with the
    /// navigation's velocity (eight_vectored noise-free, the acceleration rows 0.029 off at
    /// 5 s, 0.034 at 7 s; with a perfect DVL 0.007-0.019; the cause was the 1 s hold's
    /// starting tilt, `lead_in_s`) only drifts further.
    pub settle_wait_s: f64,
    /// While the stop may wait for a settled estimate (from a segment before `min_s` to the
    /// wait's end), the stop is decided every this many seconds, at most every
    /// `estimator.segment_s` (default 0.1; 1, every segment, until 2026-12-06); each decision
    /// still compares with the estimate a segment earlier, so a wandering estimate, which
    /// moves little between close decisions, is still caught. Why: a steady estimate that
    /// moved just over its bound at `min_s` waited a whole second. Measured in process
    /// (realistic IMU, seeds 1-30): the worst of AMOUR-5 / six_dof / eight_vectored 4.5 s ->
    /// 4.0 / 4.1 / 3.8 s with the same errors; amour5_reverse60 noise-free 4.5 -> 4.0 s and
    /// 1.8x -> 0.9x its bound; the cost, amour5_reverse60 at a realistic IMU: the worst
    /// acceleration rows 0.030 -> 0.034 (1.2x their bound; docs/study.md, "The settle
    /// wait's second").
    pub settle_decision_s: f64,
    /// Once the wait for a settled estimate is over (`min_s` + `settle_wait_s` of dither), the
    /// stop is decided every this many seconds, at most every `estimator.segment_s` (default
    /// 0.1; 1 until 2026-12-02: every segment). Why: a run decided once a segment stops up to a
    /// segment after its bound is met. Measured (AMOUR-5 / six_dof / eight_vectored, the
    /// paper's noise, seeds 1-10, in process): 9.00 / 9.40 / 13.30 s with 1 s, 8.64 / 8.97 /
    /// 12.90 s with 0.1 s, the same errors; through the processes 10.22 -> 9.66 s. The cost:
    /// more looks at a noisy bound stop on a lucky one, so with the detectors uncalibrated in
    /// a swell at the paper's noise more false alarms' models go in (5, the worst 0.090 off,
    /// against 2, 0.060; docs/study.md, "Deciding the stop more often"). A fight (the dither
    /// under `min_dither_share`) keeps one decision a segment.
    pub late_decision_s: f64,
    /// The move always allowed, relative (default 0.01; see `settle`). Noise-free the bounds are 0.1-0.2 %
    /// while a steady estimate still moves 0.2-0.5 % a second (AMOUR-5); 1 % is half the
    /// tightest accuracy asked of a model (0.02), not the stop target (0.06), which let the
    /// wandering 1.5 % moves through.
    pub settle_floor: f64,
    /// From scratch (no model in force), the open-loop pulses stop once both error bounds are
    /// below this (after the minimum cycle, as always), the model is swapped in, and the
    /// estimation goes on under control to `estimator.target_rel_err` (default 0: off, the
    /// open-loop run goes to the target itself; see docs/experiments.md for the trade).
    pub burst_rel_err: f64,
    /// When the change is known (one thruster moved, added or removed, announced or found by
    /// the refinement), the other thrusters' columns of the learned model in force are kept as
    /// the fit's prior ([`carry_over`]), and only the changed thruster is learned from nothing
    /// (default true).
    pub carry_over: bool,
    /// The kept coefficients' standard errors are multiplied by this (default 1, at least 1):
    /// room for what may have drifted since they were learned.
    pub carry_over_se_scale: f64,
    /// With coefficients carried over, the changed thruster is dithered at `focus_gain` times
    /// the amplitude (at most full command; default 1.7) and the others at `focus_others`
    /// times (default 0.1), at a quiet gyro (see `focus_gain_noisy`); `focus_gain` 0: every
    /// thruster keeps the plain dither. Measured in-process, AMOUR-5 top thruster rotated 45
    /// degrees and announced, paper noise, seeds 1-10 (docs/experiments.md): the new model
    /// after 11.8 s (21.0 s without carry-over and focus, the 20 s limit) at 7.8 deg of
    /// largest tilt. Why the others keep a little: with none, their commands are the
    /// controller's reaction to the motion alone, confounded with the damping and restoring
    /// terms, and noise-free the fit ended 0.016 / 0.095 off the truth (0.004 / 0.010 with 0.1).
    pub focus_gain: f64,
    pub focus_others: f64,
    /// The focus at a noisy gyro: as the dither's amplitude goes from `dither` to `dither_max`
    /// (`amplitude`), the gains go linearly from `focus_gain` / `focus_others` to these
    /// (defaults 2.5 / 0.3; `focus_at`). At the paper's noise the identification's stop waits
    /// for the bounds, and a stronger focus reaches them sooner: AMOUR-5 seeds 1-10, 10.2 ->
    /// 9.3 s (docs/study.md, issue 30). At a realistic IMU the amplitude is `dither` and the
    /// focus is as before, where 2.5 / 0.3 had learned a silent rotation 0.076 off (0.016-0.030).
    pub focus_gain_noisy: f64,
    pub focus_others_noisy: f64,
    /// The least share of the commands' variation the dither must have been over an
    /// identification for its model to be swapped in (default 0.5; 0: no check). The rest is
    /// the controller's own answer, and what it answers besides the dither (a swell, a tether)
    /// is then taken for thrust: in rough water (current 0.5 m/s, swell 20 N / 2 Nm) the
    /// dither faded out and made 10 % of the variation, and the fit was 57 % / 65 % off the
    /// truth under bounds of 14 % / 16 %. Still water and current 0.99-1.00, pitch steps
    /// 0.92, moderate water 0.84-0.89 (2x outside its bound, not caught: the steps' share is
    /// too close). docs/study.md, "Under control in moving water".
    pub min_dither_share: f64,
    /// ... and only when the water had moved the vehicle: its RMS attitude error while held
    /// before the identification (`sea_state`) above this, deg (default 3; unknown, as right
    /// after an estimation: no refusal). Why both: on `aligned` in still water a vehicle
    /// tumbling on its nominal model after a change leaves no room for dither either (share
    /// 0.003), but its fit is the model it needs (7.6 % off, noise-free); rough water read
    /// 15-17 deg, moderate 6.3-6.6, still water held 20 s 0.72. docs/study.md, "Under control
    /// in moving water".
    pub min_sea_state_deg: f64,
    /// When the thrust columns are fitted by instrumental variables, the dither's signs as
    /// the instruments (`estimator::dynamic::instruments`), so that the controller's answer
    /// to the water is not taken for thrust: `never`, `in_a_sea` (default: when the water
    /// moved the held vehicle by more than `min_sea_state_deg` before the identification, or,
    /// while the gauge has no reading, when the machine takes the vehicle to be in a sea:
    /// `Instrument::applies`) or `always`. Measured (announced 45 deg turn of the first
    /// thruster, seeds 1-10): in moderate water AMOUR-5's error / bound is 2.1 / 2.7 (noise-free / realistic IMU) by
    /// least squares and 1.33 / 1.24 instrumented. The instrumented fit is taken per row group
    /// only where it and least squares disagree (`dynamic::instruments::choose`). Why not
    /// always: in still water noise-free any difference is significant, and eight_vectored then
    /// took 16 s instead of 5 s (0.047 off instead of 0.027); where the controller's share of
    /// the commands is small it costs accuracy (eight_vectored in moderate water, the dither
    /// 96 % of the commands: err_acc 0.037 against 0.026 mean, error / bound 1.08 against
    /// 1.00). docs/study.md, "The dither as the thrust's instrument".
    pub instrument: Instrument,
    /// What an identification that reached its limit (`max_s`, its bound still above the
    /// target) does with its model when the daemon's own suspicion started it (the
    /// refinement's change test or the monitor's mismatch: nothing announced a change):
    /// `keep_old` (default: the suspected change is not confirmed, its model refused and the
    /// model in force kept) or `swap`. An announced change (a reconfiguration) swaps at the
    /// limit either way: its model in force is only the nominal one. Why: with +-20 deg pitch
    /// steps in a swell the change test's and the monitor's false alarms started
    /// identifications that ended at the limit with fits far off the truth under bounds that
    /// did not show it (AMOUR-5 with its top thruster at 45 deg, moderate water at the
    /// paper's noise: 0.23-0.34 off under 0.05-0.09, by least squares, the sea-state gauge
    /// never having measured between the steps; rough water at a realistic IMU: 0.36 off
    /// under 0.15); swapped in, the vehicle lost its hold 10 s later, 50-59 deg off
    /// (docs/reliability.md, "A suspected change the data cannot confirm"). A change the data
    /// cannot pin down within `max_s` is no change to act on.
    pub at_limit_unannounced: AtLimit,
    /// The model is refused, the old one kept, when commands bent to a power (thrust ~
    /// |u|^2/3 or |u|^1.5) explain the identification's data better than the linear model
    /// by more than this ln likelihood ratio (`estimator::dynamic::thrust_curve`; default 50;
    /// 0: no check): a thrust curve nobody configured, learned at the hold's amplitude. Its
    /// figures: linear thrusters (every vehicle file, still water to rough, noise-free to the
    /// paper's noise) at most 11.4, mostly 0; T200s whose curve is not configured 4000-10000
    /// (their models 50 % off under bounds of 4-6 %); another make's thrust ~ command^1.5
    /// 236-328 at a realistic IMU (1295 noise-free), but 15-32 at the paper's noise
    /// (docs/study.md).
    pub max_curve_evidence: f64,
    /// Above `max_curve_evidence`, learn the curve instead of refusing at once: commands go
    /// out through thrust ~ command^p with p fitted between the probe's exponents, and the
    /// identification starts again on them (three curves in a row at most, then refused as
    /// without).
    /// The model swapped in carries p (`dynamics.command_exponent` in its file) and the
    /// commands follow the model in force. Default true; false: refused, the operator
    /// configures the curve (`[supply]`). Only for thrusters not taken for T200s with their
    /// curve kept (`supply::Supply::takes_t200_curve`: `compensation = "none"`, another
    /// make's, or `linearize`): a T200's curve is its table's, and `linearize` is the
    /// answer there. Measured in docs/study.md ("A thrust curve learned").
    pub learn_thrust_curve: bool,
    /// The identification that starts again on a curve just learned runs at least this
    /// long, s of dither (default 8; `min_s` if shorter). Why: the narrow grid there names
    /// what is left of the exponent, and in the 4 s the bound alone asked for it missed
    /// 8 % (thrust ~ command^1.5 learned as ^1.378, then judged linear; the model's error
    /// grew to 0.17 under a 0.115 bound as the refinement carried it to the hold's gain).
    /// Measured in docs/study.md ("The curve's confirmation, long enough to name what is
    /// left").
    pub curve_confirm_min_s: f64,
}

/// What an identification at its limit does with its model
/// (`IdentificationConfig::at_limit_unannounced`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AtLimit {
    #[default]
    KeepOld,
    Swap,
}

/// When the identification fits the thrust columns by instrumental variables
/// (`IdentificationConfig::instrument`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Instrument {
    Never,
    #[default]
    InASea,
    Always,
}

impl Instrument {
    /// Whether to instrument, the sea state before the identification being `sea_deg` (None:
    /// not known) against `min_sea_state_deg`, and `taken_for_a_sea` whether the machine takes
    /// the vehicle to be in a sea (`sea_state::InASea`), which decides while the gauge has no
    /// reading. Why: at the paper's noise a swell's first false alarm comes within seconds of
    /// the water coming up; its identification is taken for the water, but it leaves the
    /// gauge a few seconds of counted control, and the next identification (an announced
    /// change, AMOUR-5 in moderate water, one swell phase in ten) fitted by least squares to
    /// its limit: 0.222 off under a bound of 0.049, swapped in (docs/study.md, "The swell's
    /// phase").
    pub fn applies(
        self,
        sea_deg: Option<f64>,
        min_sea_state_deg: f64,
        taken_for_a_sea: bool,
    ) -> bool {
        match self {
            Instrument::Never => false,
            Instrument::Always => true,
            Instrument::InASea => sea_deg.map_or(taken_for_a_sea, |d| d > min_sea_state_deg),
        }
    }
}

impl Default for IdentificationConfig {
    fn default() -> Self {
        IdentificationConfig {
            closed_loop: true,
            dither: 0.3,
            dither_noise_ref_rad_s: 0.02,
            dither_max: 1.0,
            hold_s: 0.05,
            lead_in_s: 0.5,
            attitude_budget_deg: 10.0,
            min_s: 3.0,
            max_s: 20.0,
            settle: 1.0,
            settle_floor: 0.01,
            settle_wait_s: 1.0,
            settle_decision_s: 0.1,
            late_decision_s: 0.1,
            burst_rel_err: 0.0,
            carry_over: true,
            carry_over_se_scale: 1.0,
            focus_gain: 1.7,
            focus_others: 0.1,
            focus_gain_noisy: 2.5,
            focus_others_noisy: 0.3,
            min_dither_share: 0.5,
            min_sea_state_deg: 3.0,
            instrument: Instrument::InASea,
            at_limit_unannounced: AtLimit::KeepOld,
            max_curve_evidence: 50.0,
            learn_thrust_curve: true,
            curve_confirm_min_s: 8.0,
        }
    }
}

impl IdentificationConfig {
    /// The stop's wait for a settled estimate, as configured.
    pub fn settle_rule(&self) -> Settle {
        Settle {
            factor: self.settle,
            floor: self.settle_floor,
            wait_s: self.settle_wait_s,
        }
    }

    /// (key, value, allowed range) for the config checker.
    pub fn checks(&self) -> [(&'static str, f64, Range); 23] {
        [
            (
                "identification.settle_decision_s",
                self.settle_decision_s,
                Range::closed(0.05, 60.0),
            ),
            (
                "identification.late_decision_s",
                self.late_decision_s,
                Range::closed(0.05, 60.0),
            ),
            (
                "identification.focus_gain_noisy",
                self.focus_gain_noisy,
                Range::closed(0.0, 10.0),
            ),
            (
                "identification.focus_others_noisy",
                self.focus_others_noisy,
                Range::closed(0.0, 10.0),
            ),
            (
                "identification.settle_wait_s",
                self.settle_wait_s,
                Range::closed(0.0, 600.0),
            ),
            (
                "identification.settle_floor",
                self.settle_floor,
                Range::closed(0.0, 1.0),
            ),
            (
                "identification.settle",
                self.settle,
                Range::closed(0.0, 100.0),
            ),
            (
                "identification.max_curve_evidence",
                self.max_curve_evidence,
                Range::at_least(0.0),
            ),
            (
                "identification.min_sea_state_deg",
                self.min_sea_state_deg,
                Range::closed(0.0, 180.0),
            ),
            (
                "identification.min_dither_share",
                self.min_dither_share,
                Range::closed(0.0, 1.0),
            ),
            (
                "identification.focus_others",
                self.focus_others,
                Range::closed(0.0, 10.0),
            ),
            (
                "identification.focus_gain",
                self.focus_gain,
                Range::closed(0.0, 10.0),
            ),
            (
                "identification.carry_over_se_scale",
                self.carry_over_se_scale,
                Range::closed(1.0, 100.0),
            ),
            (
                "identification.burst_rel_err",
                self.burst_rel_err,
                Range::closed(0.0, 1.0),
            ),
            (
                "identification.dither",
                self.dither,
                Range::closed(0.0, 1.0),
            ),
            (
                "identification.dither_noise_ref_rad_s",
                self.dither_noise_ref_rad_s,
                Range::above(0.0),
            ),
            (
                "identification.dither_max",
                self.dither_max,
                Range::closed(self.dither, 1.0),
            ),
            ("identification.hold_s", self.hold_s, Range::above(0.0)),
            (
                "identification.lead_in_s",
                self.lead_in_s,
                Range::closed(0.0, 60.0),
            ),
            (
                "identification.attitude_budget_deg",
                self.attitude_budget_deg,
                Range::closed(0.0, 180.0),
            ),
            ("identification.min_s", self.min_s, Range::at_least(0.0)),
            (
                "identification.curve_confirm_min_s",
                self.curve_confirm_min_s,
                Range::at_least(0.0),
            ),
            (
                "identification.max_s",
                self.max_s,
                Range::at_least(self.min_s),
            ),
        ]
    }

    /// The dither amplitude for a measured gyro noise `sigma_rot` (rad/s, RMS over the axes).
    pub fn amplitude(&self, sigma_rot: f64) -> f64 {
        let factor = (sigma_rot / self.dither_noise_ref_rad_s).sqrt();
        if !factor.is_finite() {
            return self.dither;
        }
        (self.dither * factor).clamp(self.dither, self.dither_max.max(self.dither))
    }

    /// The focus (gain on the changed thrusters, on the others) for dither amplitude
    /// `amplitude`: `focus_gain` / `focus_others` at `dither`, `focus_gain_noisy` /
    /// `focus_others_noisy` at `dither_max`, linear in between.
    pub fn focus_at(&self, amplitude: f64) -> (f64, f64) {
        let span = self.dither_max - self.dither;
        let t = if span > 0.0 && amplitude.is_finite() {
            ((amplitude - self.dither) / span).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (
            self.focus_gain + t * (self.focus_gain_noisy - self.focus_gain),
            self.focus_others + t * (self.focus_others_noisy - self.focus_others),
        )
    }

    /// Share of the dither applied at attitude error `err_deg`: 1 up to half the budget, then
    /// linearly down to 0 at the budget.
    pub fn fade(&self, err_deg: f64) -> f64 {
        let b = self.attitude_budget_deg;
        if !(err_deg.is_finite() && b > 0.0) {
            return 0.0;
        }
        ((b - err_deg) / (0.5 * b)).clamp(0.0, 1.0)
    }
}

/// A random binary dither for N thrusters, Manchester coded: every `2 hold_s` each thruster
/// draws a sign s and commands +s for `hold_s`, then -s for `hold_s`. Why coded: a plain
/// random binary sequence has most of its power at low frequency, where the controller's loop
/// (about 0.6 Hz) lets it through as tilt (measured 9-12 deg at 0.1 of full command, noise
/// free); each coded pair cancels its own impulse, so the vehicle's angle barely moves while
/// the rate, which the fit uses, still does. The generator is deterministic: the same seed
/// gives the same sequence, and runs are reproducible.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Dither {
    n: usize,
    hold_s: f64,
    state: u64,
    signs: [f64; MAX_THRUSTERS],
    /// Each thruster's share of the amplitude (1 unless `focus` moved it).
    gains: [f64; MAX_THRUSTERS],
    next_switch_s: Option<f64>,
    /// The second half of a coded pair comes next.
    second_half: bool,
}

impl Dither {
    pub fn new(n: usize, hold_s: f64, seed: u64) -> Self {
        Dither {
            n: n.min(MAX_THRUSTERS),
            hold_s: hold_s.max(1e-3),
            // xorshift must not start at zero.
            state: seed ^ 0x9E37_79B9_7F4A_7C15,
            signs: [0.0; MAX_THRUSTERS],
            gains: [1.0; MAX_THRUSTERS],
            next_switch_s: None,
            second_half: false,
        }
    }

    /// The thrusters in `on` are dithered at `gain` times the amplitude (clamped to full
    /// command when added), the others at `others` times. Why: after a known change the other
    /// columns are known ([`carry_over`]), and the attitude budget is better spent on the
    /// unknown one (N independent signs tilt the vehicle about sqrt(N) times as much as one).
    pub fn focus(&mut self, on: &[usize], gain: f64, others: f64) {
        if on.is_empty() {
            return;
        }
        let (gain, others) = (gain.max(0.0), others.max(0.0));
        for (i, g) in self.gains.iter_mut().enumerate() {
            *g = if on.contains(&i) { gain } else { others };
        }
    }

    /// The signs (+-1, zero past N) in force at `t_s`.
    pub fn signs_at(&mut self, t_s: f64) -> &[f64] {
        let due = self.next_switch_s.is_none_or(|t| t_s >= t);
        if due {
            for i in 0..self.n {
                self.signs[i] = if self.second_half {
                    -self.signs[i]
                } else if self.next_bit() {
                    1.0
                } else {
                    -1.0
                };
            }
            self.second_half = !self.second_half;
            let from = self.next_switch_s.unwrap_or(t_s);
            // A late sample (a gap) does not make the next holds shorter.
            self.next_switch_s = Some(from.max(t_s - self.hold_s) + self.hold_s);
        }
        &self.signs[..self.n]
    }

    /// Add the dither in force at `t_s`, `amplitude` of full command, to `command` (clamped
    /// to [-1, 1]). Balanced like the open-loop doublets: the forward half is scaled by
    /// `reverse_ratio`, since propellers push harder forward (a T200's reverse gives ~78 %) and
    /// a symmetric dither would push the vehicle off its setpoint on average, the controller
    /// chasing it.
    pub fn add_to(&mut self, t_s: f64, amplitude: f64, reverse_ratio: f64, command: &mut [f64]) {
        self.signs_at(t_s);
        for ((u, s), g) in command.iter_mut().zip(&self.signs).zip(&self.gains) {
            let d = if *s > 0.0 { reverse_ratio * s } else { *s };
            *u = (*u + (g * amplitude).min(1.0) * d).clamp(-1.0, 1.0);
        }
    }

    /// The dither's shape at unit amplitude, per thruster, as `add_to` last applied it (the
    /// forward half scaled by `reverse_ratio`, each thruster by its focus gain), into `out`:
    /// the fit's instruments for the thrust columns under control. Not faded and not clamped:
    /// the fade follows the attitude error, which the water moves, and only the signs are
    /// independent of the water.
    pub fn instruments(&self, reverse_ratio: f64, out: &mut [f64]) {
        for ((o, s), g) in out.iter_mut().zip(&self.signs[..self.n]).zip(&self.gains) {
            *o = g * if *s > 0.0 { reverse_ratio * s } else { *s };
        }
    }

    fn next_bit(&mut self) -> bool {
        let mut x = self.state;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.state = x;
        x >> 63 == 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn in_a_sea_the_gauge_decides_and_without_a_reading_the_machines_verdict() {
        let i = Instrument::InASea;
        assert!(i.applies(Some(3.5), 3.0, false));
        assert!(!i.applies(Some(2.5), 3.0, true), "a calm reading decides");
        assert!(i.applies(None, 3.0, true), "no reading: taken for a sea");
        assert!(!i.applies(None, 3.0, false));
        assert!(Instrument::Always.applies(None, 3.0, false));
        assert!(!Instrument::Never.applies(Some(10.0), 3.0, true));
    }

    #[test]
    fn signs_are_held_balanced_and_uncorrelated() {
        let mut d = Dither::new(5, 0.25, 7);
        let (mut sum, mut cross, mut switches) = ([0.0; 5], 0.0, 0);
        let mut last = [0.0; 5];
        let steps = 200 * 400; // 400 s at 200 Hz
        for k in 0..steps {
            let s = d.signs_at(k as f64 / 200.0).to_vec();
            assert!(s.iter().all(|v| *v == 1.0 || *v == -1.0));
            if s != last {
                switches += 1;
            }
            last.copy_from_slice(&s);
            for i in 0..5 {
                sum[i] += s[i];
            }
            cross += s[0] * s[1];
        }
        // 1600 holds: the signs change at most once per hold, and always within a pair.
        assert!((1550..=1601).contains(&switches), "{switches}");
        for m in sum {
            assert!((m / steps as f64).abs() < 0.1, "mean {}", m / steps as f64);
        }
        assert!((cross / steps as f64).abs() < 0.1);
    }

    #[test]
    fn the_same_seed_gives_the_same_sequence() {
        let (mut a, mut b) = (Dither::new(3, 0.2, 1), Dither::new(3, 0.2, 1));
        for k in 0..100 {
            assert_eq!(a.signs_at(k as f64 * 0.05), b.signs_at(k as f64 * 0.05));
        }
    }

    #[test]
    fn the_dither_fades_out_towards_the_budget() {
        let c = IdentificationConfig::default();
        assert_eq!(c.fade(0.0), 1.0);
        assert_eq!(c.fade(5.0), 1.0);
        assert!((c.fade(7.5) - 0.5).abs() < 1e-12);
        assert_eq!(c.fade(10.0), 0.0);
        assert_eq!(c.fade(f64::NAN), 0.0);
    }

    #[test]
    fn the_amplitude_grows_with_the_noise_within_its_bounds() {
        let c = IdentificationConfig::default();
        assert_eq!(c.amplitude(0.002), 0.3);
        assert!((c.amplitude(0.045) - 0.45).abs() < 1e-12);
        // 0.3 sqrt(0.25 / 0.02) = 1.06: capped at `dither_max` (1.0; it passes 0.6 at 0.08).
        assert_eq!(c.amplitude(0.25), 1.0);
        assert!((c.amplitude(0.08) - 0.6).abs() < 1e-12);
        assert_eq!(c.amplitude(f64::NAN), 0.3);
        // The focus follows the amplitude: as before at a quiet gyro, the noisy gains at
        // dither_max, halfway between halfway.
        assert_eq!(c.focus_at(c.amplitude(0.002)), (1.7, 0.1));
        assert_eq!(c.focus_at(c.amplitude(0.25)), (2.5, 0.3));
        let (g, o) = c.focus_at(0.65);
        assert!(
            (g - 2.1).abs() < 1e-12 && (o - 0.2).abs() < 1e-12,
            "{g} {o}"
        );
        assert_eq!(c.focus_at(f64::NAN), (1.7, 0.1));
    }
}
