//! Where "down" is at the end of a long rest, from the accelerometer averaged over the last
//! tens of seconds, each reading carried to the present by the gyro.
//!
//! Why: the navigation starts from the attitude the rest ended with. Over a 1-2 s rest that
//! is the accelerometer's reading then (`rest_rotation::force_at_end`), and in a swell the
//! reading carries the swell's acceleration: eight_vectored in the moderate preset's full
//! swell started 0.35 rad off on three seeds of ten with its gyro's bias right, and the
//! tilted gravity went into its acceleration rows (0.10-0.11 against 0.03-0.04 on the others).
//! The swell's acceleration has no mean in the world; a world-fixed direction carried by the
//! gyro does. So: an average with exponential forgetting (time constant `tau_s`, several
//! swell periods), kept in the present body frame by turning it with the gyro net of its bias
//! at every sample. A bias error e turns it by about e tau_s (1 mrad/s over 20 s: 0.02 rad);
//! the swell's acceleration is left at about its tilt over (2 pi tau_s / period).

use nalgebra::{UnitQuaternion, Vector3};

/// The running average of "down", in the body frame of the last sample.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct LongRestDown {
    /// The forgetting's time constant, s.
    tau_s: f64,
    last_t_s: Option<f64>,
    /// The average (not normalised), and the weight it carries (its approach to 1).
    sum: Vector3<f64>,
    weight: f64,
}

impl LongRestDown {
    /// An empty average forgetting over `tau_s`.
    pub fn new(tau_s: f64) -> Self {
        LongRestDown {
            tau_s,
            ..Self::default()
        }
    }

    /// One sample at `t_s`: the gyro net of its bias (rad/s) and the specific force (m/s^2),
    /// body frame. A non-finite or degenerate sample, or a time that does not advance, is
    /// skipped.
    pub fn push(&mut self, t_s: f64, rate: &Vector3<f64>, specific_force: &Vector3<f64>) {
        let tau_s = self.tau_s;
        let Some(down) = specific_force.try_normalize(1e-9).map(|f| -f) else {
            return;
        };
        if !(t_s.is_finite() && rate.iter().all(|v| v.is_finite()) && tau_s > 0.0) {
            return;
        }
        let dt = match self.last_t_s {
            Some(t) if t_s <= t => return,
            Some(t) => t_s - t,
            None => 0.0,
        };
        // A direction fixed in the world turns the other way in the body: d' = -w x d.
        let turn = UnitQuaternion::from_scaled_axis(-rate * dt);
        let keep = (-dt / tau_s).exp();
        let take = if self.last_t_s.is_none() {
            1.0
        } else {
            1.0 - keep
        };
        self.sum = turn * self.sum * keep + down * take;
        self.weight = self.weight * keep + take;
        self.last_t_s = Some(t_s);
    }

    /// "Down" now (unit, body frame), once anything was taken.
    pub fn down(&self) -> Option<Vector3<f64>> {
        (self.weight > 0.0)
            .then(|| self.sum.try_normalize(1e-12))
            .flatten()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const G: f64 = 9.80665;

    /// A vehicle rocking 0.3 / 0.2 rad at a 6.7 s period, turning about the vertical, whose
    /// accelerometer reads a horizontal swell acceleration of 1.2 m/s^2 besides gravity: the
    /// average's "down" at the end is within 0.02 rad of the truth, the last reading's is not.
    #[test]
    fn the_swell_averages_out_of_down() {
        let w = std::f64::consts::TAU / 6.7;
        let attitude = |t: f64| {
            UnitQuaternion::from_euler_angles(
                0.3 * (w * t).sin(),
                0.2 * (w * t + 1.0).cos(),
                0.13 * t,
            )
        };
        let mut r = LongRestDown::new(20.0);
        let (h, mut last_f, mut truth) = (1e-5, Vector3::zeros(), Vector3::zeros());
        for k in 0..=(90.0 * 200.0) as usize {
            let t = k as f64 * 0.005;
            let (q0, q1, q) = (attitude(t - h), attitude(t + h), attitude(t));
            let rate = (q0.inverse() * q1).scaled_axis() / (2.0 * h);
            // The specific force: the swell's acceleration (world) minus gravity, in the body.
            let swell = Vector3::new(1.2 * (w * t + 0.4).sin(), 0.8 * (w * t).cos(), 0.0);
            let f = q.inverse_transform_vector(&(swell - Vector3::new(0.0, 0.0, G)));
            r.push(t, &rate, &f);
            last_f = f;
            truth = q.inverse_transform_vector(&Vector3::z());
        }
        let found = r.down().unwrap();
        let angle = |a: &Vector3<f64>| a.angle(&truth);
        assert!(angle(&found) < 0.02, "{:.4} rad off", angle(&found));
        assert!(
            angle(&-last_f) > 0.05,
            "the case tests something: {:.4}",
            angle(&-last_f)
        );
    }
}
