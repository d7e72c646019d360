//! How fast the vehicle rises or sinks at the end of the rest before an excitation, from the
//! depth sensor alone.
//!
//! Why: the navigation starts the excitation at zero velocity, but the "rest" is only a rest
//! of the thrusters. A vehicle trimmed positive (as ROVs are, so they surface when they fail:
//! the simulator's BlueROV2 body is 2 N buoyant) is rising by then, at up to its terminal
//! velocity (0.17 m/s for that body). The dead-reckoned velocity then carries that offset
//! through the whole excitation, and the fit's velocity products (p w, q w, ...) turn it into
//! wrong damping and restoring coefficients: noise-free on AMOUR-5 the rate damping 3-11 % and
//! the pitch restoring 8.9 % off, against 3-4 % and 1.6 % for a neutrally buoyant body
//! (docs/study.md, "Where the coefficients' errors come from").
//!
//! A quadratic least-squares fit of depth against time over the rest, differentiated at its
//! last sample: the body is still accelerating towards its terminal velocity, so a straight
//! line (the mean slope) would lag the velocity at the end. Running sums, no allocation.

use nalgebra::{Matrix3, Vector3};

/// Fewest samples and shortest span that make the fit's slope worth more than zero.
const MIN_SAMPLES: u64 = 10;
const MIN_SPAN_S: f64 = 0.2;
/// A drift beyond this is not a body at rest (a depth sensor glitch, a vehicle being lifted):
/// no velocity is claimed then, and the navigation starts from zero as before.
pub const MAX_DRIFT_MPS: f64 = 1.0;

/// Running sums for depth = a + b t + c t^2 over the rest.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct RestDrift {
    t0: Option<f64>,
    last_t: f64,
    n: u64,
    /// Sums of t^k, k = 0..4, and of t^k depth, k = 0..2 (t from the first sample).
    st: [f64; 5],
    sd: [f64; 3],
}

impl RestDrift {
    pub fn new() -> Self {
        Self::default()
    }

    /// One depth reading (m, down positive) at `t_s`. Non-finite values and times that do
    /// not advance are skipped.
    pub fn push(&mut self, t_s: f64, depth_m: f64) {
        if !(t_s.is_finite() && depth_m.is_finite()) {
            return;
        }
        let t0 = *self.t0.get_or_insert(t_s);
        let t = t_s - t0;
        if self.n > 0 && t <= self.last_t {
            return;
        }
        self.last_t = t;
        let mut tk = 1.0;
        for k in 0..5 {
            self.st[k] += tk;
            if k < 3 {
                self.sd[k] += tk * depth_m;
            }
            tk *= t;
        }
        self.n += 1;
    }

    /// Samples taken.
    pub fn samples(&self) -> u64 {
        self.n
    }

    /// The vertical velocity (NED, m/s: positive sinking) at the last sample, when the rest
    /// was long enough and the fit well posed and plausible (below [`MAX_DRIFT_MPS`]).
    pub fn velocity_down(&self) -> Option<f64> {
        if self.n < MIN_SAMPLES || self.last_t < MIN_SPAN_S {
            return None;
        }
        let s = &self.st;
        let normal = Matrix3::new(s[0], s[1], s[2], s[1], s[2], s[3], s[2], s[3], s[4]);
        let coef = normal
            .cholesky()?
            .solve(&Vector3::new(self.sd[0], self.sd[1], self.sd[2]));
        let w = coef[1] + 2.0 * coef[2] * self.last_t;
        (w.is_finite() && w.abs() <= MAX_DRIFT_MPS).then_some(w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_velocity_at_the_end_of_an_accelerating_rise() {
        // Rising from 0.05 m/s, decelerating upwards at 0.08 m/s^2 (depth decreasing).
        let mut d = RestDrift::new();
        for k in 0..=200 {
            let t = 10.0 + k as f64 * 0.005;
            let tau = t - 10.0;
            d.push(t, 5.0 - 0.05 * tau - 0.04 * tau * tau);
        }
        let w = d.velocity_down().unwrap();
        assert!((w - (-0.05 - 0.08 * 1.0)).abs() < 1e-9, "{w}");
    }

    #[test]
    fn too_short_or_implausible_gives_nothing() {
        let mut d = RestDrift::new();
        for k in 0..5 {
            d.push(k as f64 * 0.005, 1.0);
        }
        assert_eq!(d.velocity_down(), None, "5 samples");
        let mut d = RestDrift::new();
        for k in 0..100 {
            let t = k as f64 * 0.01;
            d.push(t, 1.0 + 3.0 * t);
        }
        assert_eq!(d.velocity_down(), None, "3 m/s is no rest");
    }

    #[test]
    fn bad_samples_are_skipped() {
        let mut clean = RestDrift::new();
        let mut dirty = RestDrift::new();
        for k in 0..100 {
            let t = k as f64 * 0.01;
            let z = 2.0 + 0.1 * t;
            clean.push(t, z);
            dirty.push(t, z);
            if k == 50 {
                dirty.push(t + 0.001, f64::NAN);
                dirty.push(t, z + 1.0); // does not advance
                dirty.push(f64::INFINITY, z);
            }
        }
        assert_eq!(clean.velocity_down(), dirty.velocity_down());
        assert!((clean.velocity_down().unwrap() - 0.1).abs() < 1e-9);
    }
}
