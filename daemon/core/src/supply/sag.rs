//! The battery's sag under the thrusters' load, learned from the driver's voltage readings.
//!
//! A pack's voltage falls with the current it gives (`V = E - R I`; a 4S pack of 20 mOhm sags
//! 2-3 V when eight T200s pull 100+ A). The driver reports the voltage about every 100 ms
//! (ArduSub's SYS_STATUS, thruster-sim's report), so a 0.1 s estimation pulse is mostly sent
//! at the voltage read before it started: referred to 16.6 V while the pack gives 13.9 V, the
//! thrusters push 9 % less than the commands ask and the estimator learns thrusters 9 %
//! weaker than they are (eight_vectored_t200, noise-free; 0.3 % with the sag taken out of the
//! simulated pack: docs/study.md, "The battery's sag").
//!
//! So the supply predicts the voltage of the commands it is about to send: each reading is
//! paired with the current the thrusters draw at the commands in force when it came (from the
//! T200's table; the daemon's own commands, so no current sensor is needed, and the hotel load
//! is in the intercept), and a line `V = E - R I` is fitted over the readings with exponential
//! forgetting (the pack drains over minutes; `FORGET_S`). Until the readings spread over enough
//! current to fix the slope (`MIN_SPREAD_A`) nothing is predicted and the last reading is used,
//! as before. Pure: readings and currents in, a voltage out; bounded memory (five sums).

use serde::{Deserialize, Serialize};

/// Readings older than this weigh e^-1 as much as a new one, s of vehicle time: a pack drains
/// over tens of minutes, its resistance changes slower still.
const FORGET_S: f64 = 60.0;
/// The weighted spread of the currents (standard deviation, A) the readings need before their
/// slope is trusted: an idle vehicle's few amperes of hotel load fix no resistance.
const MIN_SPREAD_A: f64 = 5.0;
/// The slopes believed, Ohm: a pack, its wiring and its connectors (a fitted negative slope
/// is noise, a larger one a fault the fit should not act on).
pub(super) const MAX_RESISTANCE_OHM: f64 = 0.5;

/// The fitted line, readings folded in so far.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Sag {
    /// Weighted sums of 1, I, V, I^2, I V.
    sums: [f64; 5],
    /// Vehicle time of the last reading, s.
    last_t_s: Option<f64>,
}

impl Sag {
    /// A reading of `voltage_v` at vehicle time `t_s`, while the thrusters drew `current_a` (A)
    /// by the table. Non-finite input is ignored.
    pub fn on_reading(&mut self, t_s: f64, voltage_v: f64, current_a: f64) {
        if !(t_s.is_finite() && voltage_v.is_finite() && current_a.is_finite()) {
            return;
        }
        let decay = match self.last_t_s {
            Some(last) => (-(t_s - last).max(0.0) / FORGET_S).exp(),
            None => 0.0,
        };
        for s in &mut self.sums {
            *s *= decay;
        }
        let (i, v) = (current_a, voltage_v);
        let add = [1.0, i, v, i * i, i * v];
        for (s, a) in self.sums.iter_mut().zip(add) {
            *s += a;
        }
        self.last_t_s = Some(t_s);
    }

    /// `(E, R)`: the open-circuit voltage (with the hotel load) and the resistance, once the
    /// readings spread over [`MIN_SPREAD_A`] and give a believable slope.
    pub fn line(&self) -> Option<(f64, f64)> {
        let [w, si, sv, sii, siv] = self.sums;
        if w < 2.0 {
            return None;
        }
        let (mi, mv) = (si / w, sv / w);
        let var = sii / w - mi * mi;
        if var < MIN_SPREAD_A * MIN_SPREAD_A {
            return None;
        }
        let r = -(siv / w - mi * mv) / var;
        (0.0..=MAX_RESISTANCE_OHM)
            .contains(&r)
            .then_some((mv + r * mi, r))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pack_seen_under_changing_load_is_predicted_and_an_idle_one_is_not() {
        let mut s = Sag::default();
        // Idle: 1-2 A of hotel load, no line.
        for k in 0..20 {
            s.on_reading(
                0.1 * k as f64,
                16.78 - 0.02 * (k % 2) as f64,
                1.0 + (k % 2) as f64,
            );
        }
        assert_eq!(s.line(), None);
        // Pulses: 1-100 A through 20 mOhm from 16.8 V.
        for k in 20..40 {
            let i = if k % 3 == 0 { 100.0 } else { 1.0 + k as f64 };
            s.on_reading(0.1 * k as f64, 16.8 - 0.02 * i, i);
        }
        let (e, r) = s.line().unwrap();
        assert!(
            (e - 16.8).abs() < 1e-9 && (r - 0.02).abs() < 1e-9,
            "{e} {r}"
        );
        assert!((e - r * 150.0 - 13.8).abs() < 1e-9);
    }

    #[test]
    fn a_draining_pack_is_followed_and_nonsense_is_ignored() {
        let mut s = Sag::default();
        // 30 minutes from 16.8 to 13.8 V open circuit, alternating loads every 0.1 s.
        for k in 0..18_000 {
            let t = 0.1 * k as f64;
            let e = 16.8 - 3.0 * t / 1800.0;
            let i = if k % 2 == 0 { 5.0 } else { 60.0 };
            s.on_reading(t, e - 0.02 * i, i);
        }
        s.on_reading(f64::NAN, 1.0, 1.0);
        s.on_reading(1800.0, f64::INFINITY, 1.0);
        let (e, r) = s.line().unwrap();
        // The forgetting lags the drain by about FORGET_S: 0.1 V at this rate.
        assert!((e - 13.8).abs() < 0.12, "{e}");
        assert!((r - 0.02).abs() < 2e-3, "{r}");
        // A slope of the wrong sign (a charger, a bad reading pattern) predicts nothing.
        let mut up = Sag::default();
        for k in 0..20 {
            let i = 10.0 * (k % 4) as f64;
            up.on_reading(0.1 * k as f64, 16.0 + 0.05 * i, i);
        }
        assert_eq!(up.line(), None);
    }
}
