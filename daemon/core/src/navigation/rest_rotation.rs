//! How the vehicle turned during the rest before an excitation, from the accelerometer: so the
//! gyro's bias is not taken for that rotation, and the navigation starts from the attitude at
//! the rest's end, not its mean.
//!
//! Why: the "rest" is only a rest of the thrusters. A vehicle that has just met a current is
//! pitched by it (AMOUR-5 in 0.3 m/s swings +-0.09 rad/s with a 3.5 s period for seconds, as
//! the Munk moment and its restoring moment trade), and one released from a hand or a crane
//! still swings. The mean gyro over such a rest is its bias plus the mean rotation rate: taken
//! whole for the bias (as before), the navigation's attitude drifts by the rotation rate all
//! through the excitation, gravity leaks into the velocity, and the model came out 3-7 % off
//! under a bound of 2 % (issue 32's current; docs/study.md). Its mean attitude is not the one
//! the excitation starts from either.
//!
//! The accelerometer sees every rotation about a horizontal axis: at rest its specific force
//! is gravity turning the other way, df/dt = -omega x f, so the rate across gravity is
//! -(f x df/dt) / |f|^2. Both sensors are reduced alike, by least-squares lines over the rest
//! (the gyro's integrated angle and the specific force against time), so their slopes weigh
//! the rest's moments identically and the difference across gravity is the gyro's bias
//! whatever the motion was. The rotation about gravity (yaw, level) is not seen: there the
//! mean gyro stays the bias. A drag's changing acceleration reads as a tilt rate too (0.03
//! m/s^2 per s: 0.003 rad/s), well below the swing's. Running sums, no allocation.

use nalgebra::Vector3;

/// Fewest samples and shortest span for the slopes to mean anything.
const MIN_SAMPLES: u64 = 10;
const MIN_SPAN_S: f64 = 0.2;

/// A specific force this far from gravity's magnitude, or a rotation this fast, is no rest
/// (a vehicle being carried): nothing is corrected then, as before.
const MAX_FORCE_GAP: f64 = 0.2;
const MAX_RATE_RADPS: f64 = 0.5;

/// The rotation is corrected for only where the specific force's slope stands this many of
/// its standard errors from zero. Why: the slope of a still rest's accelerometer noise is a
/// rotation too (0.03 m/s^2 of noise over a 1 s rest: 0.0008 rad/s), and correcting for it
/// made AMOUR-5 in still water at a realistic IMU 0.0139 -> 0.0162 off (worst 0.0278).
const SIGNIFICANT: f64 = 3.0;

/// Nor below this rate, rad/s (0.006 deg/s, under any MEMS gyro's bias stability): a
/// noise-free rest's slope is rounding, and correcting for it would only move the last digits
/// of every model learned in still water.
const MIN_RATE_RADPS: f64 = 1e-4;

/// Running sums of the specific force and of the gyro's integrated angle against time.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct RestRotation {
    t0: Option<f64>,
    last_t: f64,
    n: u64,
    /// Sums of t and t^2 (t from the first sample).
    st: f64,
    stt: f64,
    /// Sums of f, t f and f^2 (per axis).
    sf: Vector3<f64>,
    stf: Vector3<f64>,
    sff: Vector3<f64>,
    /// The raw gyro integrated since the first sample (small angles), its last reading, and
    /// the sums of that angle and of t times it.
    angle: Vector3<f64>,
    last_gyro: Vector3<f64>,
    sa: Vector3<f64>,
    sta: Vector3<f64>,
}

impl RestRotation {
    pub fn new() -> Self {
        Self::default()
    }

    /// One sample at `t_s`: raw gyro (rad/s) and specific force (m/s^2), body frame. Samples
    /// with a non-finite value or a time that does not advance are skipped: then false.
    pub fn push(&mut self, t_s: f64, gyro: &Vector3<f64>, specific_force: &Vector3<f64>) -> bool {
        let finite = t_s.is_finite()
            && gyro.iter().all(|v| v.is_finite())
            && specific_force.iter().all(|v| v.is_finite());
        if !finite {
            return false;
        }
        let t0 = *self.t0.get_or_insert(t_s);
        let t = t_s - t0;
        if self.n > 0 {
            if t <= self.last_t {
                return false;
            }
            // Trapezoidal: the angle at the sample, not half a step behind it.
            self.angle += (gyro + self.last_gyro) * (0.5 * (t - self.last_t));
        }
        self.last_t = t;
        self.last_gyro = *gyro;
        self.n += 1;
        self.st += t;
        self.stt += t * t;
        self.sf += specific_force;
        self.stf += specific_force * t;
        self.sff += specific_force.component_mul(specific_force);
        self.sa += self.angle;
        self.sta += self.angle * t;
        true
    }

    /// The last sample taken: its time since the first (s) and the gyro's integrated angle
    /// then (rad, small angles).
    pub fn last(&self) -> (f64, Vector3<f64>) {
        (self.last_t, self.angle)
    }

    /// Samples taken.
    pub fn samples(&self) -> u64 {
        self.n
    }

    /// Least-squares slope of a quantity with sums `s` and `st` (of it and of t times it).
    fn slope(&self, s: &Vector3<f64>, st: &Vector3<f64>) -> Option<Vector3<f64>> {
        let n = self.n as f64;
        let det = n * self.stt - self.st * self.st;
        (self.n >= MIN_SAMPLES && self.last_t >= MIN_SPAN_S && det > 0.0)
            .then(|| (st * n - s * self.st) / det)
    }

    /// The mean specific force, m/s^2.
    pub fn mean_force(&self) -> Option<Vector3<f64>> {
        (self.n > 0).then(|| self.sf / self.n as f64)
    }

    /// Whether the rest looks like one (the specific force gravity's size, `gravity` m/s^2,
    /// and the rotation the accelerometer saw slow) and turned: its slope stands out of the
    /// noise on some axis ([`SIGNIFICANT`]). Then the mean specific force and its slope.
    fn turned(&self, gravity: f64) -> Option<(Vector3<f64>, Vector3<f64>)> {
        let f = self.mean_force()?;
        let df = self.slope(&self.sf, &self.stf)?;
        let g2 = f.norm_squared();
        let fits = (f.norm() - gravity).abs() <= MAX_FORCE_GAP * gravity;
        let rate = -f.cross(&df) / g2;
        if !(fits && g2 > 0.0 && rate.norm() <= MAX_RATE_RADPS) {
            return None;
        }
        // Per axis: the slope's part across gravity against its standard error (the residual
        // variance about the line over sum (t - mean t)^2). Along gravity a slope is the
        // vertical acceleration changing (a buoyant vehicle nearing its terminal rise), not
        // a turn.
        let n = self.n as f64;
        let sxx = self.stt - self.st * self.st / n;
        let across = df - f * (f.dot(&df) / g2);
        if across.norm() / g2.sqrt() < MIN_RATE_RADPS {
            return None;
        }
        let stands_out = (0..3).any(|a| {
            let syy = self.sff[a] - self.sf[a] * self.sf[a] / n;
            let sxy = self.stf[a] - self.st * self.sf[a] / n;
            let resid = (syy - df[a] * sxy).max(0.0) / (n - 2.0).max(1.0);
            across[a].abs() > SIGNIFICANT * (resid / sxx).sqrt()
        });
        stands_out.then_some((f, df))
    }

    /// The specific force at the rest's last sample, m/s^2: the attitude the excitation
    /// starts from. The gyro carries the mean attitude to the end: f + phi x f is what the
    /// specific force would read without the rotations the gyro saw (phi its integrated
    /// angle), a straight line in t whose slope is the gyro's bias turning it; that line's
    /// value at the end, turned back by the end's angle. A line through f alone lags a swing
    /// (half a period of it left the pitch 47 mrad off). The mean when the rest did not turn,
    /// or is too short or implausible for a slope.
    pub fn force_at_end(&self, gravity: f64) -> Option<Vector3<f64>> {
        let mean = self.mean_force()?;
        let Some((f, df)) = self.turned(gravity) else {
            return Some(mean);
        };
        let Some(dphi) = self.slope(&self.sa, &self.sta) else {
            return Some(mean);
        };
        let n = self.n as f64;
        let mean_phi = self.sa / n;
        let slope = df + dphi.cross(&f);
        let line_end = f + mean_phi.cross(&f) + slope * (self.last_t - self.st / n);
        Some(line_end - self.angle.cross(&f))
    }

    /// The gyro's bias, rad/s, given the mean gyro over the rest (`mean_gyro`, what was taken
    /// for it): across gravity the gyro's rotation rate minus the accelerometer's, along
    /// gravity the mean. `mean_gyro` itself when the rest did not turn, or is too short or
    /// implausible.
    pub fn gyro_bias(&self, mean_gyro: &Vector3<f64>, gravity: f64) -> Vector3<f64> {
        let Some((f, df)) = self.turned(gravity) else {
            return *mean_gyro;
        };
        let Some(gyro_rate) = self.slope(&self.sa, &self.sta) else {
            return *mean_gyro;
        };
        let g2 = f.norm_squared();
        let seen = -f.cross(&df) / g2;
        let across = |v: &Vector3<f64>| v - f * (f.dot(v) / g2);
        let along = mean_gyro - across(mean_gyro);
        along + across(&(gyro_rate - seen))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const G: f64 = 9.80665;

    /// A vehicle pitching as theta(t) = a sin(w t) with a gyro bias, at rest otherwise.
    fn swinging(bias: Vector3<f64>, seconds: f64) -> (RestRotation, f64) {
        let mut r = RestRotation::new();
        let (a, w) = (0.07, 1.8);
        let mut theta = 0.0;
        for k in 0..=(seconds * 200.0) as usize {
            let t = 100.0 + k as f64 * 0.005;
            theta = a * (w * (t - 100.0)).sin();
            let q = a * w * (w * (t - 100.0)).cos();
            // Gravity in the body pitched up by theta: f = -R^T g.
            let f = Vector3::new(G * theta.sin(), 0.0, -G * theta.cos());
            r.push(t, &(Vector3::new(0.0, q, 0.0) + bias), &f);
        }
        (r, theta)
    }

    #[test]
    fn a_swing_during_the_rest_is_not_taken_for_the_bias() {
        let bias = Vector3::new(0.004, -0.006, 0.003);
        let (r, theta_end) = swinging(bias, 2.0);
        // The mean gyro over 2 s of the swing: the bias plus the mean pitch rate.
        let mean_rate = 0.07 * (1.8f64 * 2.0).sin() / 2.0;
        let mean_gyro = bias + Vector3::new(0.0, mean_rate, 0.0);
        let found = r.gyro_bias(&mean_gyro, G);
        assert!(
            mean_rate.abs() > 0.01,
            "the case tests something: {mean_rate}"
        );
        assert!((found - bias).norm() < 5e-4, "{found} against {bias}");
        // The attitude at the end, not the mean (within a mrad; the mean is 68 mrad off).
        let f = r.force_at_end(G).unwrap();
        let pitch = f.x.atan2(-f.z);
        let mean = r.mean_force().unwrap();
        assert!(
            (pitch - theta_end).abs() < 1e-3,
            "{pitch} against {theta_end}"
        );
        assert!((mean.x.atan2(-mean.z) - theta_end).abs() > 0.05);
    }

    #[test]
    fn a_still_rest_gives_the_mean_gyro_and_force() {
        let bias = Vector3::new(0.01, 0.02, -0.03);
        let mut r = RestRotation::new();
        let f = Vector3::new(0.3, -0.2, -G);
        for k in 0..400 {
            r.push(k as f64 * 0.005, &bias, &f);
        }
        assert!((r.gyro_bias(&bias, G) - bias).norm() < 1e-12);
        assert!((r.force_at_end(G).unwrap() - f).norm() < 1e-9);
    }

    #[test]
    fn no_rest_no_correction() {
        let mean = Vector3::new(0.1, 0.2, 0.3);
        let mut r = RestRotation::new();
        for k in 0..5 {
            r.push(k as f64 * 0.005, &mean, &Vector3::new(0.0, 0.0, -G));
        }
        assert_eq!(r.gyro_bias(&mean, G), mean, "too short");
        // Carried: twice gravity.
        let mut r = RestRotation::new();
        for k in 0..400 {
            let t = k as f64 * 0.005;
            r.push(t, &mean, &Vector3::new(t, 0.0, -2.0 * G));
        }
        assert_eq!(r.gyro_bias(&mean, G), mean, "carried");
        assert!(r.force_at_end(G).unwrap().x < 1.0, "the mean, not the end");
    }
}
