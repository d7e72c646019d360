//! The refinement's settings (`[refinement]`): the windows, the dither, the fusion and the
//! change test, each with its documented default and allowed range.

use serde::{Deserialize, Serialize};
use thruster_driver_kit::Range;

use super::change_test::ChangeSettings;
use crate::adaptation::calibrate_when::CalibrateWhen;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RefinementConfig {
    /// Refine in the background while controlling (default true; the dynamic method only).
    pub enabled: bool,
    /// Dither added while controlling, a fraction of full command (default 0.1; 0: the
    /// controller's own commands during manoeuvres are the only excitation, and a thruster
    /// they do not move cannot be judged, and is not).
    pub dither: f64,
    /// Each half of the coded dither pair, s (default 0.05).
    pub hold_s: f64,
    /// A window lasts at least this long, s (default 5) ...
    pub window_min_s: f64,
    /// ... and ends once the rotation rows' error bound is below this (default 0.1) ...
    pub window_rel_err: f64,
    /// ... or at this length, s (default 30).
    pub window_max_s: f64,
    /// A thruster changed when its rotation column moved by more than this share of the
    /// model's column (default 0.55: AMOUR's top thruster rotated 45 degrees moves its column
    /// by 0.77, a rotation of 32 degrees by 0.55; at the paper's noise an unchanged thruster's
    /// window fit moved 40-64 %, 0.4 gave a false alarm every 1-3 minutes) ...
    pub min_change: f64,
    /// ... and significantly: chi-square of the move over the window's standard errors, three
    /// rows (default 40, about 6 sigma).
    pub chi2: f64,
    /// ... in this many windows in a row, for the same thruster (default 2). One window at the
    /// paper's noise judged an unchanged thruster "moved" about once a minute (its standard
    /// errors are too small for the fit's real error); two windows in a row make that rare
    /// and cost one window (at least `window_min_s`) of detection time.
    pub confirm_windows: u32,
    /// A window whose chi-square is above this needs no second one (default 200): a rotated
    /// thruster seen with a realistic IMU scores in the thousands, the paper's-noise false
    /// alarms 25-57, so a clear case is reported at once.
    pub chi2_single_window: f64,
    /// Fold each window that finds no change into the model in force, so it follows slow
    /// changes (default true). It was off while the updates took each window at its own
    /// standard error: noise-free those say 0.001 while the windows are 0.02-0.06 off, and the
    /// model of eight_vectored followed them from 0.015 to 0.065 off the truth in 60 s. With
    /// `window_floor`, the slower drift and the two-window rule it stays (0.015 -> 0.017).
    pub update: bool,
    /// How fast a thruster may drift unseen: each entry's standard deviation grows by this
    /// share of its column's norm per sqrt(s) (default 0.003: 3 % in 100 s). Faster changes
    /// are followed through `inflate_above`; 0.01 made the model follow every window.
    pub drift_per_sqrt_s: f64,
    /// A window's standard errors are multiplied by this before it is weighed against the
    /// model, in the fusion and in the judgement of a change (default 2: the window fits' own
    /// errors understate their real error, the same reason the change test needs two windows).
    /// In the judgement since 2026-11-29: four_up's model, learned tighter once the stop waits
    /// for a bound within reach, met a window that "moved" thruster 4 by 185 % with chi2 306
    /// over the window's unscaled errors, and a single window above `chi2_single_window` was
    /// reported at once (realistic IMU, seed 4, 46 s of pitch steps; docs/study.md).
    pub window_se_scale: f64,
    /// ... and only a window whose rotation bound is at most this updates it (default 0.1:
    /// with a realistic IMU windows end at 0.01-0.06, at the paper's noise at 0.15).
    pub update_rel_err: f64,
    /// A window's entries are never trusted to better than this share of their column's norm
    /// (default 0.04): noise-free, closed-loop windows are 0.02-0.06 off the truth while their
    /// standard errors say 0.001, and weighed by those alone the model followed each window.
    pub window_floor: f64,
    /// A column whose window-minus-model chi-square (three rows of a block) exceeds this in
    /// two windows in a row has its prior widened to match (default 7.8, the 95 % point of
    /// chi-square with 3 degrees of freedom): a thruster losing strength is followed within a
    /// window or two, while an unchanged one is averaged at the slow `drift_per_sqrt_s`. At the 99 % point (11.3)
    /// the acceleration rows of a thruster losing 30 % in a minute lagged to 0.044-0.049.
    pub inflate_above: f64,
    /// The per-sample change test on the gyro's innovations ([`change_test`]; default true).
    /// Measured in process at the paper's noise, AMOUR-5 with the learned model and the 0.1
    /// dither, top thruster rotated 45 degrees (tests/refinement.rs, `change_test_soak`):
    /// found after 4.2-4.4 s through +-20 deg pitch steps (seeds 1-10, thruster 1 named every
    /// time) and 2.6-7.2 s holding level (seeds 1-5), where the windows take 45-80 s; no false
    /// alarm in 10 x 20 minutes at the paper's noise, 5 x 20 with a realistic IMU or none, nor
    /// at 1 kHz (6 x 10 minutes). Through the processes at 200 Hz (`thrusterctl experiment
    /// hot-swap`, which turns it on, seeds 1-5) the silent change at the paper's noise was
    /// found after 3.1-5.1 s (mean 4.1 s; the windows alone: 42.6-50.6 s), and a 3-minute soak
    /// raised no alarm; at 1 kHz in real time, the 10-minute soak none either (it raised 17
    /// while the real-time simulator published its samples in bursts of eight, see
    /// docs/experiments.md). Off, the windows alone judge (43-51 s at the paper's noise).
    pub change_test: bool,
    /// A change: its chi-square (the rows judged, one thruster at a time) passes this
    /// (default 60: the largest an unchanged vehicle holding level reached in 10 x 10 minutes
    /// at the paper's noise was 51 with the 0.1 dither, 80 with 0.2 and 120 with 0.3 (the
    /// learned model's error under the dither grows with it); raise it with the dither) ...
    pub change_chi2: f64,
    /// ... and the estimated move of the column is at least this share of the model's
    /// rotation column, one thruster at a time and with every thruster fitted jointly
    /// (default 0.4: AMOUR's top thruster rotated 45 degrees moves by 0.77 and was estimated
    /// at 0.6-1.3 when found at the paper's noise; one at a time, through pitch steps with a
    /// realistic IMU, unchanged thrusters "moved" 40-69 %, jointly 6-33 %).
    pub change_min_share: f64,
    /// The observer's time constant, s (default 0.2): the gyro corrects the predicted rates
    /// by `dt / change_tau_s` of the innovation each sample, so slow errors of the model and
    /// of the attitude filter fade within it while the dither's fast changes stay. At 2 s the
    /// attitude filter's error, which the controller acts on, gave an unchanged vehicle
    /// chi-squares of 100-400 at the paper's noise; at 0.5 s the learned model 38-146.
    pub change_tau_s: f64,
    /// Candidate change times are kept this long, s (default 10) ...
    pub change_horizon_s: f64,
    /// ... one every this many seconds (default 0.25; cost per sample: candidates x
    /// thrusters).
    pub change_spacing_s: f64,
    /// The innovation's mean and variance forget with this time constant, s (default 30).
    pub change_noise_s: f64,
    /// After a new model or a restart of control the test waits this long before it judges,
    /// and a row is judged only once its axis has been held this long, s (default 5: the
    /// observer and the noise statistics settle; after a 20 deg pitch step the vehicle swings
    /// for a while, and at 1 s the pitch row's unmodelled restoring and damping were
    /// "changes" within 4-150 s with a realistic IMU or none).
    pub change_warmup_s: f64,
    /// An axis counts as held while its error from the setpoint (the rotation vector's
    /// component, body frame) is within this (default 10 deg) and its setpoint has not
    /// stepped by 5 deg or more ...
    pub change_max_error_deg: f64,
    /// ... and the vehicle is within this tilt from level (default 90: off). Why off now: the
    /// test used to judge only near level (8 deg), where the learned model with all its
    /// terms holds; with the insignificant terms left out and the rows of a manoeuvring axis
    /// not judged, the roll and yaw rows stay quiet at 20 deg of pitch (see `change_test`).
    pub change_max_tilt_deg: f64,
    /// The model in force may be taken to be this wrong in every entry, a share of its
    /// column's norm (default 0: off): the move is then judged against the regression's
    /// variance plus this, as the windows are (`window_floor`). 0.03 did not remove the
    /// noise-free false alarm it was meant for (a model update mid-flight was, now handled
    /// by starting over on every new model version) and cost 1.3 s of detection at the
    /// paper's noise (seed 1).
    pub change_model_floor: f64,
    /// How significant a damping, restoring or Coriolis term of the model must be to take
    /// part in the change test's prediction, in standard errors (default 4): a coefficient c
    /// with standard error se counts as `c (1 - (change_term_z se / c)^2)` when positive, else
    /// not at all; 0 uses every term as fitted. Why: at the paper's noise most of those terms,
    /// learned near level under feedback, are noise (a roll damping of -6.2 where the truth is
    /// -0.24, pairs cancelling at +-85), and through pitch steps they made "changes" of an
    /// unchanged vehicle (false alarms after 5-9 s in 5 of 5 seeds), while B alone was quiet;
    /// with a realistic IMU or none the terms are right and B alone, missing the damping and
    /// restoring, was not (one false alarm in 5 x 20 noise-free minutes). 4, not 3: over every
    /// vehicle file, three noise levels and seeds 1-6 (10 minutes each, `change_test_on_every_vehicle`),
    /// 3 let one false alarm through (aligned, realistic IMU, seed 1, after 134 s) and 4 none,
    /// with the same detection times on AMOUR-5 (paper's noise, seeds 1-10: 4.24-4.33 s
    /// through pitch steps; seeds 1-5 holding level: 2.8-5.9 s against 2.8-7.2 s). 8, not 4
    /// (since 2026-12-04): a first model learned longer at the paper's noise (a 4 % target,
    /// 1 kHz) has those terms' standard errors small enough that noise passed 4, and 2 of 12
    /// seeds raised false alarms on an unchanged vehicle; at 8 none, with the detection times
    /// as at 4 (holding level, seeds 1-5: 2.5-6.8 s against 2.6-6.5 s) and the six flight
    /// vehicles quiet at three noise levels, 12 vehicle-hours (docs/study.md, "The change
    /// test's terms").
    pub change_term_z: f64,
    /// A candidate change time is judged only once this old, s (default 2): younger, the
    /// thrusters' signatures have barely risen (the observer's time constant is 0.2 s) and
    /// cannot be told apart. With a realistic IMU, 0.1-0.2 s candidates "found" moves of
    /// 160-650 % of the wrong thruster, and through the processes 1 s candidates moves of
    /// 48-92 % after the new model was in; at the paper's noise the rotated thruster is found
    /// on candidates 3-5 s old.
    pub change_min_age_s: f64,
    /// The thruster named must lead the others by this much (default 20; 0: the largest is
    /// named): every thruster's move is fitted jointly, and the named one's chi-square must
    /// pass the next one's by this; by less the test names nobody yet and waits for more
    /// evidence. Why: holding AMOUR-5 level at the paper's noise with its top thruster rotated
    /// (seeds 1-300), the largest was the wrong thruster on 25 seeds, and on 60 with a model
    /// fitted to the thrust's shape (`estimator.shaped_thrust`), each time by a lead of 0.1-7;
    /// the re-estimation then carries the moved thruster's old column over. Margin 9.21: 11 and
    /// 26 wrong; 13.8: 7 and 14; 20: 2 and 1, found after 4.65 s and 4.36 s on average
    /// instead of 4.22 s and 3.42 s (docs/study.md, "The change test's name"). In a swell
    /// the uncalibrated test's false alarms come later and stronger at 20
    /// (`tests/unconfirmed_change.rs`).
    pub change_name_margin: f64,
    /// The change test calibrated against the water (default 120; 0: off; applied as
    /// `change_calibrate_when` says, by default only in a sea): every thruster's
    /// apparent move is fitted on consecutive `change_batch_s` batches of the rows held, and
    /// their mean square over this recent past (forgetting time constant, s), against what
    /// the innovation's variance alone gives, is the factor on a candidate's variance. Why: in
    /// a swell the controller's answer to the waves is in the commands, so the regression
    /// "finds" moves of 40-200 % of a column; uncalibrated, AMOUR-5 flying pitch steps in
    /// moderate water (0.3 m/s, 10 N / 1 Nm at 0.15 Hz) had a false alarm on 10 of 10 seeds
    /// within 10 minutes at every noise preset, and rough water at the paper's noise on 6 of
    /// 10; calibrated, none from the change test (`change_test_soak`, docs/study.md). In still
    /// water the soak's detection times are unchanged (paper's noise through pitch steps
    /// 4.2-4.5 s). Its costs: in a swell at the paper's noise a moved thruster is no longer
    /// found within 60 s (the windows find it in moderate water at a realistic IMU); and, why
    /// it applies only in a sea by default, in still water with a realistic IMU
    /// the model's own few-percent errors under manoeuvres inflate the factor too, so in
    /// `machine_sim`'s silent rotation the change test (5.8 s, thruster named, its column
    /// learned anew and the others carried over: 0.016-0.030 off) gave way to the monitor
    /// (6.4-6.9 s, nothing named, nothing carried over: 0.022-0.065 off) ...
    pub change_calibration_s: f64,
    /// ... on batches this long, s (default 10, the candidates' horizon: a swell's apparent
    /// move is coloured, so shorter batches understate it for the older candidates; with 2 s
    /// batches the 10 s candidates alarmed in moderate water after 115 s, and 2 s batches over
    /// 30 s cost the realistic IMU's change-test detection in still water, 3.9 s -> 7.0 s).
    pub change_batch_s: f64,
    /// ... when: "in_a_sea" (the default: while the sea-state gauge says the water moves the
    /// held vehicle, `identification.min_sea_state_deg`; uncalibrated otherwise, as before
    /// 2026-12-01) or "always".
    #[serde(default)]
    pub change_calibrate_when: CalibrateWhen,
    /// The model in force's gain at the hold's commands (`common_gain`: one factor over
    /// every column, pooled over the windows judged against its B) off 1 by more than this
    /// beyond `gain_gap_z` standard errors: its bound is restated to cover that much (default
    /// 0.2; 0: off). Why: thrusters whose thrust is not linear in the command (^1.5, the
    /// daemon not told) leave the open-loop line 60 % too strong at the hold's small
    /// commands, and at the paper's noise no identification names the curve: the line stayed
    /// in force 0.10-0.13 off the truth under a bound of 0.043-0.058. There the pooled gain
    /// read 0.52-0.64; on linear vehicles in still water, a current and moderate water
    /// 0.85-1.23, at most 0.08 beyond its two standard errors. In rough water AMOUR-5 read 0.52
    /// (the controller's answer to the swell), so it is not judged in a sea (docs/study.md,
    /// "The hold's gain").
    pub gain_gap_min: f64,
    /// ... in standard errors (default 2).
    pub gain_gap_z: f64,
}

impl Default for RefinementConfig {
    fn default() -> Self {
        RefinementConfig {
            enabled: true,
            dither: 0.1,
            hold_s: 0.05,
            window_min_s: 5.0,
            window_rel_err: 0.15,
            window_max_s: 30.0,
            min_change: 0.55,
            chi2: 25.0,
            confirm_windows: 2,
            chi2_single_window: 200.0,
            update: true,
            drift_per_sqrt_s: 0.003,
            window_se_scale: 2.0,
            update_rel_err: 0.1,
            window_floor: 0.04,
            inflate_above: 7.8,
            change_test: true,
            change_chi2: 60.0,
            change_min_share: 0.4,
            change_tau_s: 0.2,
            change_horizon_s: 10.0,
            change_spacing_s: 0.25,
            change_noise_s: 30.0,
            change_warmup_s: 5.0,
            change_max_error_deg: 10.0,
            change_max_tilt_deg: 90.0,
            change_model_floor: 0.0,
            change_term_z: 8.0,
            change_min_age_s: 2.0,
            change_name_margin: 20.0,
            change_calibration_s: 120.0,
            change_batch_s: 10.0,
            change_calibrate_when: CalibrateWhen::InASea,
            gain_gap_min: 0.2,
            gain_gap_z: 2.0,
        }
    }
}

impl RefinementConfig {
    /// (key, value, allowed range) for the config checker.
    pub fn checks(&self) -> [(&'static str, f64, Range); 31] {
        [
            (
                "refinement.gain_gap_min",
                self.gain_gap_min,
                Range::closed(0.0, 10.0),
            ),
            (
                "refinement.gain_gap_z",
                self.gain_gap_z,
                Range::closed(0.0, 100.0),
            ),
            ("refinement.dither", self.dither, Range::closed(0.0, 1.0)),
            ("refinement.hold_s", self.hold_s, Range::above(0.0)),
            (
                "refinement.window_min_s",
                self.window_min_s,
                Range::above(0.0),
            ),
            (
                "refinement.window_rel_err",
                self.window_rel_err,
                Range::above(0.0),
            ),
            (
                "refinement.window_max_s",
                self.window_max_s,
                Range::at_least(self.window_min_s),
            ),
            ("refinement.min_change", self.min_change, Range::above(0.0)),
            ("refinement.chi2", self.chi2, Range::above(0.0)),
            (
                "refinement.chi2_single_window",
                self.chi2_single_window,
                Range::at_least(self.chi2),
            ),
            (
                "refinement.confirm_windows",
                f64::from(self.confirm_windows),
                Range::closed(1.0, 10.0),
            ),
            (
                "refinement.drift_per_sqrt_s",
                self.drift_per_sqrt_s,
                Range::closed(0.0, 1.0),
            ),
            (
                "refinement.window_se_scale",
                self.window_se_scale,
                Range::closed(1.0, 100.0),
            ),
            (
                "refinement.update_rel_err",
                self.update_rel_err,
                Range::closed(0.0, 1.0),
            ),
            (
                "refinement.window_floor",
                self.window_floor,
                Range::closed(0.0, 1.0),
            ),
            (
                "refinement.inflate_above",
                self.inflate_above,
                Range::at_least(1.0),
            ),
            (
                "refinement.change_chi2",
                self.change_chi2,
                Range::above(0.0),
            ),
            (
                "refinement.change_min_share",
                self.change_min_share,
                Range::closed(0.0, 10.0),
            ),
            (
                "refinement.change_tau_s",
                self.change_tau_s,
                Range::closed(0.001, 100.0),
            ),
            (
                "refinement.change_horizon_s",
                self.change_horizon_s,
                Range::closed(0.1, 120.0),
            ),
            (
                "refinement.change_spacing_s",
                self.change_spacing_s,
                Range::closed(self.change_horizon_s / 1000.0, self.change_horizon_s),
            ),
            (
                "refinement.change_noise_s",
                self.change_noise_s,
                Range::closed(0.1, 3600.0),
            ),
            (
                "refinement.change_warmup_s",
                self.change_warmup_s,
                Range::closed(0.0, 600.0),
            ),
            (
                "refinement.change_max_error_deg",
                self.change_max_error_deg,
                Range::closed(0.0, 180.0),
            ),
            (
                "refinement.change_max_tilt_deg",
                self.change_max_tilt_deg,
                Range::closed(0.0, 180.0),
            ),
            (
                "refinement.change_model_floor",
                self.change_model_floor,
                Range::closed(0.0, 10.0),
            ),
            (
                "refinement.change_term_z",
                self.change_term_z,
                Range::closed(0.0, 1000.0),
            ),
            (
                "refinement.change_min_age_s",
                self.change_min_age_s,
                Range::closed(0.0, self.change_horizon_s),
            ),
            (
                "refinement.change_name_margin",
                self.change_name_margin,
                Range::closed(0.0, 1000.0),
            ),
            (
                "refinement.change_calibration_s",
                self.change_calibration_s,
                Range::closed(0.0, 3600.0),
            ),
            (
                "refinement.change_batch_s",
                self.change_batch_s,
                Range::closed(0.1, 60.0),
            ),
        ]
    }

    /// The change test's settings; `lag_s` the thrusters' spin-up the model was fitted with.
    pub fn change_settings(&self, lag_s: f64) -> ChangeSettings {
        ChangeSettings {
            tau_s: self.change_tau_s,
            horizon_s: self.change_horizon_s,
            spacing_s: self.change_spacing_s,
            chi2: self.change_chi2,
            min_share: self.change_min_share,
            noise_s: self.change_noise_s,
            warmup_s: self.change_warmup_s,
            model_floor: self.change_model_floor,
            lag_s,
            term_z: self.change_term_z,
            min_age_s: self.change_min_age_s,
            calibration_s: self.change_calibration_s,
            batch_s: self.change_batch_s,
            calibrate_when: self.change_calibrate_when,
            name_margin: self.change_name_margin,
        }
    }
}
