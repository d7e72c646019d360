//! How far the water moved the vehicle while it was held: the running RMS of the attitude
//! error while controlling, on the axes the model actuates (the caller's `err_deg`: four_up's
//! unactuated yaw read 22-30 deg in a current), which an identification under control reads
//! when it concludes.
//!
//! Why: a low dither share alone (the commands mostly the controller's) does not say the
//! controller was answering the water. On `aligned`, its top thruster turned, the nominal
//! model lets the vehicle tumble in still water, the dither fades out (share 0.003) and the
//! fit on the controller's fight is still a usable model (7.6 % / 3.3 %, noise-free); in rough
//! water (share 0.10) it is 57 % off. What tells them apart is the water before the change:
//! held with the model in force, the first vehicle sat near its setpoint, the second swung by
//! tens of degrees.
//!
//! What counts: control ticks from `SETTLE_S` after the machine began controlling (the
//! levelling after an open-loop estimation is no sea: it read 4-5 deg RMS in still water) and
//! `STEP_SETTLE_S` after the setpoint last moved (a commanded step is no sea either: +-20 deg
//! pitch steps every 4 s read as one and made the identification instrument its fit),
//! updated by the control tick only, so an identification's own manoeuvring does not count.
//! A new stretch of control keeps what was measured if the last counted tick is at most
//! `KEEP_S` old (an identification in between: the water did not calm because the vehicle
//! was dithered; forgetting it made a second identification after a refused one fit by
//! least squares, eight_vectored in moderate water 0.22 off under a bound of 0.10), and
//! starts over otherwise. Known only after `MIN_MEASURED_S` of it. Pure: errors, setpoints
//! and sample times in.
//!
//! After a step, ticks count only once its transient is over as well: the smoothed error came
//! within `STEP_REACHED_DEG` or grew back by `STEP_REBOUND_DEG` (the water pushing again).
//! Why: AMOUR-5 under +-20 deg steps every 4 s in still water is still 3-5 deg off, ringing,
//! 3-4 s after each step, and the gauge read 4.3-4.4 deg (aligned 5.6-5.8): a sea, so the
//! identification after a silent change instrumented its fit, which once came out 0.158 off
//! under a bound of 0.052 (least squares 0.019). With the rule, still water through the steps
//! is not known or reads 1.4 deg, moderate water 7.5-12.4, rough 13-18 (every vehicle file).
//!
//! [`InASea`] turns the reading into the answer the detectors' calibrations go by
//! (`adaptation::calibrate_when`): a sea once it has read above the threshold for a while.

use nalgebra::UnitQuaternion;
use serde::{Deserialize, Serialize};

/// The forgetting time constant, s: long enough to span a swell's period (6.7 s for the
/// presets), short enough to forget a manoeuvre a minute old.
pub const SEA_STATE_TAU_S: f64 = 10.0;

/// Control ticks this long after control began are not counted, s.
pub const SETTLE_S: f64 = 5.0;

/// The sea state is known once this much control has been counted, s.
pub const MIN_MEASURED_S: f64 = 5.0;

/// A measurement this old (since its last counted tick) is kept into a new stretch of
/// control, s: longer than an identification (at most `identification.max_s` 20 s and its
/// hold).
pub const KEEP_S: f64 = 60.0;

/// Ticks this long after the setpoint moved are not counted, s.
pub const STEP_SETTLE_S: f64 = 3.0;

/// A setpoint that turned by more than this since the last tick has moved, deg.
pub const STEP_DEG: f64 = 0.5;

/// A step's transient is over once the smoothed error has come within this, deg ...
pub const STEP_REACHED_DEG: f64 = 2.0;

/// ... or once it has grown back by this from its least since the step (the water pushing
/// the vehicle away again), deg. AMOUR-5's own ringing after a 40 deg step in still water
/// grows back by up to 2.0 deg unsmoothed, a swell by several.
pub const STEP_REBOUND_DEG: f64 = 2.0;

/// The smoothing of the error for the two tests above, s: takes out the closed loop's ringing
/// near 1 Hz, keeps a swell (0.15 Hz for the presets; at a vehicle's depth a sea's faster
/// components have died out: a deep-water wave's motion decays as exp(-w^2 z / g), at 1 Hz
/// to 1/e in 0.25 m).
pub const STEP_SMOOTH_S: f64 = 0.5;

/// Running mean square attitude error while held, deg^2.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SeaState {
    mean_sq_deg2: f64,
    measured_s: f64,
    /// When the stretch of control being measured began, ns.
    since_ns: u64,
    /// The setpoint the last tick held, and when it last moved (ns).
    #[serde(default)]
    setpoint: Option<UnitQuaternion<f64>>,
    #[serde(default)]
    moved_ns: u64,
    /// The last counted tick, ns (0: none).
    #[serde(default)]
    counted_ns: u64,
    /// The error has come within `STEP_REACHED_DEG` since the setpoint last moved.
    #[serde(default)]
    reached: bool,
    /// The least error since the setpoint last moved, deg.
    #[serde(default)]
    least_deg: f64,
    /// The error low-passed, deg.
    #[serde(default)]
    smooth_deg: f64,
    /// The smoothing starts over at the next finite error (after [`SeaState::manoeuvre_ended`]).
    #[serde(default)]
    smooth_restart: bool,
}

impl SeaState {
    /// One control tick at `t_ns`, `dt_s` long, holding `setpoint` with the attitude error
    /// `err_deg` from it, in a stretch of control that began at `control_since_ns`.
    pub fn push(
        &mut self,
        t_ns: u64,
        control_since_ns: u64,
        dt_s: f64,
        setpoint: &UnitQuaternion<f64>,
        err_deg: f64,
    ) {
        if control_since_ns != self.since_ns {
            let recent =
                self.counted_ns > 0 && t_ns.saturating_sub(self.counted_ns) as f64 * 1e-9 <= KEEP_S;
            *self = if recent {
                SeaState {
                    since_ns: control_since_ns,
                    ..*self
                }
            } else {
                SeaState {
                    since_ns: control_since_ns,
                    ..SeaState::default()
                }
            };
        }
        let moved = self
            .setpoint
            .is_some_and(|last| last.angle_to(setpoint).to_degrees() > STEP_DEG);
        if moved {
            self.moved_ns = t_ns;
            self.reached = false;
            self.least_deg = f64::INFINITY;
            self.smooth_restart = true;
        }
        if self.smooth_restart && err_deg.is_finite() {
            self.smooth_deg = err_deg;
            self.smooth_restart = false;
        }
        // When the step's own transient is over (see `STEP_REACHED_DEG`).
        if err_deg.is_finite() && dt_s > 0.0 {
            self.smooth_deg += (dt_s / STEP_SMOOTH_S).min(1.0) * (err_deg - self.smooth_deg);
        }
        let e = self.smooth_deg;
        if e <= STEP_REACHED_DEG || e > self.least_deg + STEP_REBOUND_DEG {
            self.reached = true;
        }
        self.least_deg = self.least_deg.min(e);
        self.setpoint = Some(*setpoint);
        let seconds_since = |ns: u64| t_ns.saturating_sub(ns) as f64 * 1e-9;
        let settled = seconds_since(control_since_ns) >= SETTLE_S
            && (self.moved_ns == 0
                || (seconds_since(self.moved_ns) >= STEP_SETTLE_S && self.reached));
        if !(settled && dt_s > 0.0 && err_deg.is_finite()) {
            return;
        }
        self.counted_ns = t_ns;
        self.measured_s += dt_s;
        // The first samples average; then an exponential forgetting.
        let w = (dt_s / self.measured_s)
            .max(dt_s / SEA_STATE_TAU_S)
            .min(1.0);
        self.mean_sq_deg2 += w * (err_deg * err_deg - self.mean_sq_deg2);
    }

    /// The machine's own manoeuvre within the hold (an identification's dither) ended at
    /// `t_ns`: ticks count again once the vehicle has settled from it, as after a setpoint
    /// step (`STEP_SETTLE_S`, then the smoothed error within `STEP_REACHED_DEG` or growing
    /// back). The hold is unbroken, so neither what was measured nor `SETTLE_S` starts over.
    pub fn manoeuvre_ended(&mut self, t_ns: u64) {
        self.moved_ns = t_ns.max(1);
        self.reached = false;
        self.least_deg = f64::INFINITY;
        self.smooth_restart = true;
    }

    /// How much control has been counted, s (telemetry, the sweeps' traces).
    pub fn measured_s(&self) -> f64 {
        self.measured_s
    }

    /// The RMS attitude error while held, deg; None until `MIN_MEASURED_S` of it.
    pub fn rms_deg(&self) -> Option<f64> {
        self.rms_deg_after(MIN_MEASURED_S)
    }

    /// The same, None until `counted_s` of it.
    pub fn rms_deg_after(&self, counted_s: f64) -> Option<f64> {
        (self.measured_s >= counted_s).then(|| self.mean_sq_deg2.max(0.0).sqrt())
    }

    /// The reading whether the vehicle is in a sea goes by ([`InASea`]): known after
    /// `SEA_MIN_COUNTED_S`.
    pub fn sea_reading_deg(&self) -> Option<f64> {
        self.rms_deg_after(SEA_MIN_COUNTED_S)
    }
}

/// The gauge must read above the threshold this long before the vehicle is taken to be in a
/// sea, s. Why: a thruster that moves in still water makes the held vehicle swing too, and
/// entering a sea restarts the detectors' calibrations (30-50 s without a verdict); the change
/// test and the monitor find such a change within 3-8 s of it, while the uncalibrated
/// detectors' first false alarms in a swell came 18-34 s after the water came up.
pub const SEA_CONFIRM_S: f64 = 5.0;

/// For that answer the gauge is read once this much control is counted, s (its own reading
/// waits for `MIN_MEASURED_S`). Why: through +-20 deg pitch steps every 4 s only a step's
/// settled tail counts, in moderate water about 1 s in 10 (AMOUR-5: 1.3 s by 20 s, 4.7 s by
/// 70 s) and in still water nothing at all, while the uncalibrated detectors' false alarms
/// there came after 30-34 s.
pub const SEA_MIN_COUNTED_S: f64 = 1.0;

/// A sea is left when the gauge reads under this share of the threshold (hysteresis: a swell
/// reads 5.5-30 deg held or through steps, still water under 1.5 deg or nothing).
pub const SEA_LEAVE_SHARE: f64 = 0.5;

/// Whether the water moves the held vehicle, from the gauge: in a sea once it has read above
/// the threshold for `SEA_CONFIRM_S`, out of it once it reads under `SEA_LEAVE_SHARE` of the
/// threshold; an unknown reading keeps the last answer. Pure: readings and times in.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct InASea {
    in_sea: bool,
    /// Since when the gauge has read above the threshold, ns.
    above_since_ns: Option<u64>,
}

impl InASea {
    /// One control tick at `t_ns` with the gauge reading `rms_deg` against `threshold_deg`
    /// (`identification.min_sea_state_deg`). Returns whether the vehicle is in a sea now.
    pub fn update(&mut self, t_ns: u64, rms_deg: Option<f64>, threshold_deg: f64) -> bool {
        match rms_deg {
            Some(d) if d > threshold_deg => {
                let since = *self.above_since_ns.get_or_insert(t_ns);
                if t_ns.saturating_sub(since) as f64 * 1e-9 >= SEA_CONFIRM_S {
                    self.in_sea = true;
                }
            }
            Some(d) => {
                self.above_since_ns = None;
                if d < SEA_LEAVE_SHARE * threshold_deg {
                    self.in_sea = false;
                }
            }
            None => {}
        }
        self.in_sea
    }

    /// The last answer.
    pub fn get(&self) -> bool {
        self.in_sea
    }

    /// Taken to be in a sea on other evidence than the gauge: a detector's alarm that the
    /// identification it started did not confirm, while the gauge could not read the water
    /// (the caller's judgement). Left as before: once the gauge reads under
    /// `SEA_LEAVE_SHARE` of the threshold.
    pub fn assume(&mut self) {
        self.in_sea = true;
    }
}

/// An identification the detectors started found no change when, on each row group, its
/// model differs from the one in force by at most this many times its own error bound. A
/// moved thruster changes its column by far more (45 deg: 0.77 of the column, about 0.3 of
/// AMOUR-5's whole B, against bounds of 0.04-0.06); a swell's false alarms at the paper's
/// noise left 0.4-1.4 of the bound (every vehicle file, moderate water, the soak's traces).
pub const UNCONFIRMED_BOUNDS: f64 = 1.5;

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 0.005;

    fn run(s: &mut SeaState, from_s: f64, seconds: f64, since_ns: u64, err: f64) {
        run_at(s, from_s, seconds, since_ns, 0.0, err);
    }

    /// Holding a setpoint pitched `pitch_deg`.
    fn run_at(
        s: &mut SeaState,
        from_s: f64,
        seconds: f64,
        since_ns: u64,
        pitch_deg: f64,
        err: f64,
    ) {
        let sp = UnitQuaternion::from_euler_angles(0.0, pitch_deg.to_radians(), 0.0);
        let n = (seconds / DT).round() as u64;
        for k in 0..n {
            let t = ((from_s + k as f64 * DT) * 1e9) as u64;
            s.push(t, since_ns, DT, &sp, err);
        }
    }

    #[test]
    fn a_commanded_step_is_no_sea() {
        let mut s = SeaState::default();
        run(&mut s, 0.0, 11.0, 0, 1.0);
        assert!((s.rms_deg().unwrap() - 1.0).abs() < 1e-9);
        // Steps of +-20 deg every 4 s: the first 3 s after each (the tracking error, here
        // 15 deg) are not counted, the steady second after each is.
        for k in 0..10 {
            let p = if k % 2 == 0 { 20.0 } else { -20.0 };
            run_at(&mut s, 11.0 + 4.0 * k as f64, 3.0, 0, p, 15.0);
            run_at(&mut s, 14.0 + 4.0 * k as f64, 1.0, 0, p, 1.0);
        }
        assert!(
            (s.rms_deg().unwrap() - 1.0).abs() < 1e-9,
            "{:?}",
            s.rms_deg()
        );
    }

    /// `n` steps of +-20 deg every 4 s from `from_s`, the error `err(t since the step, t)`.
    fn steps(s: &mut SeaState, from_s: f64, n: usize, err: impl Fn(f64, f64) -> f64) {
        for k in 0..n {
            let sp =
                UnitQuaternion::from_euler_angles(0.0, if k % 2 == 0 { 0.35 } else { -0.35 }, 0.0);
            for j in 0..(4.0 / DT) as u64 {
                let (since, t) = (j as f64 * DT, from_s + 4.0 * k as f64 + j as f64 * DT);
                s.push((t * 1e9) as u64, 0, DT, &sp, err(since, t));
            }
        }
    }

    #[test]
    fn a_steps_ringing_tail_is_no_sea_a_swell_through_the_steps_is() {
        let mut s = SeaState::default();
        run(&mut s, 0.0, 11.0, 0, 1.0);
        // AMOUR-5 in still water: 3-5 deg off and ringing near 1 Hz by up to +-1 deg, 3-4 s
        // after each 40 deg step (traced). Nothing of it counts.
        let ringing = |since: f64| {
            36.0 * (-since / 0.4).exp() + 4.5 - 0.3 * since
                + (2.0 * std::f64::consts::PI * since).sin()
        };
        steps(&mut s, 11.0, 20, |since, _| ringing(since));
        assert!(
            (s.rms_deg().unwrap() - 1.0).abs() < 1e-9,
            "{:?}",
            s.rms_deg()
        );
        // The same with a 0.15 Hz swell of 6 deg on it: the water's part counts.
        let swell = |t: f64| 6.0 * (1.0 + (2.0 * std::f64::consts::PI * 0.15 * t).sin());
        steps(&mut s, 91.0, 20, |since, t| ringing(since) + swell(t));
        let rms = s.rms_deg().unwrap();
        assert!(rms > 5.0, "{rms}");
    }

    #[test]
    fn the_settling_is_skipped_a_steady_error_is_its_rms_and_an_old_swing_is_forgotten() {
        let mut s = SeaState::default();
        // Levelling: 5 s at 20 deg, not counted; then 4 s at 3 deg: not known yet.
        run(&mut s, 0.0, 5.0, 0, 20.0);
        run(&mut s, 5.0, 4.0, 0, 3.0);
        assert_eq!(s.rms_deg(), None);
        run(&mut s, 9.0, 2.0, 0, 3.0);
        assert!(
            (s.rms_deg().unwrap() - 3.0).abs() < 1e-9,
            "{:?}",
            s.rms_deg()
        );
        // 30 s at 1 deg: the 3 deg are all but forgotten (at most exp(-3) of their excess
        // left in the mean square: the first seconds average, then it forgets with 10 s).
        run(&mut s, 11.0, 30.0, 0, 1.0);
        let most = (1.0 + 8.0 * (-3.0f64).exp()).sqrt();
        let rms = s.rms_deg().unwrap();
        assert!(rms > 1.0 && rms < most, "{rms}");
        // Nothing non-finite gets in.
        let level = UnitQuaternion::identity();
        s.push(42_000_000_000, 0, DT, &level, f64::NAN);
        s.push(42_000_000_000, 0, f64::INFINITY, &level, 1.0);
        assert!(s.rms_deg().unwrap().is_finite());
        // A new stretch of control right after (an identification between): kept.
        s.push(43_000_000_000, 43_000_000_000, DT, &level, 1.0);
        assert!(s.rms_deg().is_some());
        // One that begins more than a minute after the last counted tick starts over.
        s.push(200_000_000_000, 200_000_000_000, DT, &level, 1.0);
        assert_eq!(s.rms_deg(), None);
    }

    /// An identification under control within the hold: the gauge waits for the vehicle to
    /// settle from its dither, as after a step, but neither forgets what it measured nor waits
    /// `SETTLE_S` again (the hold did not restart: the caller's control start is unchanged).
    #[test]
    fn after_the_machines_own_manoeuvre_the_gauge_waits_for_the_settling_only() {
        let mut s = SeaState::default();
        run(&mut s, 0.0, 11.0, 0, 8.0);
        let counted = s.measured_s();
        assert!((s.rms_deg().unwrap() - 8.0).abs() < 1e-9);
        // The dither ends at 20 s (nothing pushed during it), the vehicle 12 deg off, back
        // within a degree a second later.
        s.manoeuvre_ended(20_000_000_000);
        run(&mut s, 20.0, 1.0, 0, 12.0);
        run(&mut s, 21.0, STEP_SETTLE_S - 1.1, 0, 1.0);
        assert_eq!(
            s.measured_s(),
            counted,
            "counted while settling from the dither"
        );
        // Settled (within STEP_REACHED_DEG) after STEP_SETTLE_S: counted at once.
        run(&mut s, 20.0 + STEP_SETTLE_S, 1.0, 0, 1.0);
        assert!(
            (s.measured_s() - counted - 1.0).abs() < 2.0 * DT,
            "{} s counted after the settling, {counted} before",
            s.measured_s()
        );
        // Not settled but the water pushing it off again (grown back by STEP_REBOUND_DEG
        // from its least): counted too.
        s.manoeuvre_ended(30_000_000_000);
        run(&mut s, 30.0, STEP_SETTLE_S, 0, 6.0);
        let before = s.measured_s();
        run(
            &mut s,
            30.0 + STEP_SETTLE_S,
            2.0,
            0,
            6.0 + STEP_REBOUND_DEG + 1.0,
        );
        assert!(s.measured_s() > before + 1.0, "{}", s.measured_s());
        assert!(s.rms_deg().unwrap() > 5.0);
    }

    #[test]
    fn a_sea_is_entered_after_the_confirmation_and_left_below_half_the_threshold() {
        let mut f = InASea::default();
        let ns = |s: f64| (s * 1e9) as u64;
        // Unknown: not in a sea.
        assert!(!f.update(0, None, 3.0));
        // Above the threshold, but not for long enough; a dip below it starts over.
        assert!(!f.update(ns(1.0), Some(4.0), 3.0));
        assert!(!f.update(ns(1.0 + SEA_CONFIRM_S - 0.1), Some(4.0), 3.0));
        assert!(!f.update(ns(9.5), Some(2.9), 3.0));
        assert!(!f.update(ns(10.0), Some(4.0), 3.0));
        assert!(!f.update(ns(10.0 + SEA_CONFIRM_S - 0.01), Some(4.0), 3.0));
        assert!(f.update(ns(10.0 + SEA_CONFIRM_S), Some(4.0), 3.0));
        // Between half the threshold and it, or unknown: still in a sea.
        assert!(f.update(ns(30.0), Some(2.0), 3.0));
        assert!(f.update(ns(31.0), None, 3.0));
        assert!(f.get());
        // Under half of it: out at once.
        assert!(!f.update(ns(32.0), Some(1.4), 3.0));
        assert!(!f.get());
        // Assumed on other evidence: in a sea while the gauge cannot read or reads above half
        // the threshold, out once it reads under half.
        f.assume();
        assert!(f.update(ns(40.0), None, 3.0));
        assert!(f.update(ns(41.0), Some(2.0), 3.0));
        assert!(!f.update(ns(42.0), Some(1.0), 3.0));
    }
}
