//! How far the water moved the vehicle while it was held: the running RMS of the attitude
//! error while controlling, which an identification under control reads when it concludes.
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
//! levelling after an open-loop estimation is no sea: it read 4-5 deg RMS in still water),
//! updated by the control tick only, so an identification's own manoeuvring does not count;
//! a new stretch of control starts over. Known only after `MIN_MEASURED_S` of it. Pure:
//! errors and sample times in.

use serde::{Deserialize, Serialize};

/// The forgetting time constant, s: long enough to span a swell's period (6.7 s for the
/// presets), short enough to forget a manoeuvre a minute old.
pub const SEA_STATE_TAU_S: f64 = 10.0;

/// Control ticks this long after control began are not counted, s.
pub const SETTLE_S: f64 = 5.0;

/// The sea state is known once this much control has been counted, s.
pub const MIN_MEASURED_S: f64 = 5.0;

/// Running mean square attitude error while held, deg^2.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SeaState {
    mean_sq_deg2: f64,
    measured_s: f64,
    /// When the stretch of control being measured began, ns.
    since_ns: u64,
}

impl SeaState {
    /// One control tick at `t_ns`, `dt_s` long, with the attitude error `err_deg` from the
    /// setpoint, in a stretch of control that began at `control_since_ns`.
    pub fn push(&mut self, t_ns: u64, control_since_ns: u64, dt_s: f64, err_deg: f64) {
        if control_since_ns != self.since_ns {
            *self = SeaState {
                since_ns: control_since_ns,
                ..SeaState::default()
            };
        }
        let settled = t_ns.saturating_sub(control_since_ns) as f64 * 1e-9 >= SETTLE_S;
        if !(settled && dt_s > 0.0 && err_deg.is_finite()) {
            return;
        }
        self.measured_s += dt_s;
        // The first samples average; then an exponential forgetting.
        let w = (dt_s / self.measured_s)
            .max(dt_s / SEA_STATE_TAU_S)
            .min(1.0);
        self.mean_sq_deg2 += w * (err_deg * err_deg - self.mean_sq_deg2);
    }

    /// The RMS attitude error while held, deg; None until `MIN_MEASURED_S` of it.
    pub fn rms_deg(&self) -> Option<f64> {
        (self.measured_s >= MIN_MEASURED_S).then(|| self.mean_sq_deg2.max(0.0).sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 0.005;

    fn run(s: &mut SeaState, from_s: f64, seconds: f64, since_ns: u64, err: f64) {
        let n = (seconds / DT).round() as u64;
        for k in 0..n {
            let t = ((from_s + k as f64 * DT) * 1e9) as u64;
            s.push(t, since_ns, DT, err);
        }
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
        s.push(42_000_000_000, 0, DT, f64::NAN);
        s.push(42_000_000_000, 0, f64::INFINITY, 1.0);
        assert!(s.rms_deg().unwrap().is_finite());
        // A new stretch of control starts over.
        s.push(43_000_000_000, 43_000_000_000, DT, 1.0);
        assert_eq!(s.rms_deg(), None);
    }
}
