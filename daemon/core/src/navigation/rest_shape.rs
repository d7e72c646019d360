//! Whether the accelerometer saw the vehicle turn during a rest, or saw it pushed.
//!
//! Why: the rest's rotation (`rest_rotation`) takes the specific force turning across gravity
//! for a turn, df/dt = -omega x f, and the gyro's bias for the difference between that and
//! the gyro's rate. A force that changes while the vehicle does not turn reads the same: a
//! current's drag accelerating a vehicle that has just met it, by an amount falling fast
//! (eight_vectored at 0.3 m/s: 0.46 m/s^2 per s in the first second, read as 0.047 rad/s of
//! pitch where the gyro's bias is 0), and the model from that rest came out 6-7 % off in its
//! acceleration rows under a bound of 3.5 %. Over one rest nothing tells the two apart by their
//! rates. Their *shapes* do: a turn is seen by both sensors, so the gyro's integrated angle
//! minus the angle the accelerometer saw is the bias times t, a straight line, whatever the
//! turn did; a changing push bends it. The test: a parabola through that difference, per axis,
//! and its curvature against its standard error (`PUSHED_Z`). Measured on the first second of
//! a rest at a realistic IMU (seeds 1-3): eight_vectored meeting a 0.3 m/s current z 20-22;
//! AMOUR-5 meeting it (a real swing, the Munk moment) at most 1.7; either after 3 s in the
//! current at most 5.1; still water at most 2.6.
//!
//! Running sums of x = (the gyro's integrated angle, from `RestRotation`, and the specific
//! force less the first sample's) and their products with 1, t, t^2 and each other; the
//! difference is linear in x once the mean force is known, at the end. No allocation.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

type V6 = SVector<f64, 6>;

/// A curvature this many standard errors from zero is a push, not noise ...
pub const PUSHED_Z: f64 = 10.0;

/// ... when the two sensors' rates also part by this much over the rest, rad/s (noise-free
/// the standard error is rounding).
pub const PUSHED_RATE_RADPS: f64 = 0.01;

/// Fewest samples for the parabola to mean anything.
const MIN_SAMPLES: u64 = 20;

#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct RestShape {
    last_t: f64,
    n: u64,
    /// The first sample's specific force, subtracted from every sample (small sums).
    f0: Vector3<f64>,
    /// Sums of t^k, k = 1..4.
    st: [f64; 4],
    /// Sums of x, t x, t^2 x and x x^T.
    sx: [V6; 3],
    sxx: SMatrix<f64, 6, 6>,
}

impl RestShape {
    /// One sample the rest's rotation took (`RestRotation::push`, which skips the unusable
    /// ones): `t` s after its first, the gyro's integrated `angle` (rad) and the specific
    /// force (m/s^2).
    pub fn push(&mut self, t: f64, angle: &Vector3<f64>, specific_force: &Vector3<f64>) {
        if self.n == 0 {
            self.f0 = *specific_force;
        }
        self.last_t = t;
        self.n += 1;
        let df = specific_force - self.f0;
        let x = V6::new(angle.x, angle.y, angle.z, df.x, df.y, df.z);
        let mut tk = 1.0;
        for k in 0..4 {
            tk *= t;
            self.st[k] += tk;
        }
        self.sx[0] += x;
        self.sx[1] += x * t;
        self.sx[2] += x * (t * t);
        self.sxx += x * x.transpose();
    }

    /// Per axis, the curvature of the gyro's angle less the accelerometer's against its
    /// standard error, and the two rates' parting over the rest (rad/s). None when too short
    /// or the specific force is not gravity-like (no rest to judge).
    pub fn bend(&self, gravity: f64) -> Option<[(f64, f64); 3]> {
        if self.n < MIN_SAMPLES || self.last_t <= 0.0 {
            return None;
        }
        let n = self.n as f64;
        let mean_dx = self.sx[0] / n;
        let f = self.f0 + Vector3::new(mean_dx[3], mean_dx[4], mean_dx[5]);
        let g2 = f.norm_squared();
        if !((f.norm() - gravity).abs() <= 0.2 * gravity && g2 > 0.0) {
            return None;
        }
        // The difference, per axis a: (across-gravity part of the angle) + (f x (f_k - f0)) / g2:
        // the accelerometer's angle is -f x f_k / g2 up to a constant.
        let across = Matrix3::identity() - f * f.transpose() / g2;
        let cross = f.cross_matrix() / g2;
        let [s1, s2, s3, s4] = self.st;
        let gram = Matrix3::new(n, s1, s2, s1, s2, s3, s2, s3, s4);
        let inv = gram.try_inverse()?;
        let mut out = [(0.0, 0.0); 3];
        for (a, o) in out.iter_mut().enumerate() {
            let mut m = V6::zeros();
            for j in 0..3 {
                m[j] = across[(a, j)];
                m[3 + j] = cross[(a, j)];
            }
            let r = Vector3::new(m.dot(&self.sx[0]), m.dot(&self.sx[1]), m.dot(&self.sx[2]));
            let b = inv * r;
            let rss = ((m.transpose() * self.sxx * m)[(0, 0)] - b.dot(&r)).max(0.0);
            let s2 = rss / (n - 3.0);
            let se = (s2 * inv[(2, 2)]).sqrt();
            let z = if se > 0.0 { b[2] / se } else { 0.0 };
            // The rates part by d/dt of the curvature's term over the rest: 2 b2 T.
            *o = (z, 2.0 * b[2] * self.last_t);
        }
        Some(out)
    }

    /// The rest saw a push, not a turn: on some axis its curvature stands `PUSHED_Z` standard
    /// errors out and the rates part by `PUSHED_RATE_RADPS`.
    pub fn pushed(&self, gravity: f64) -> bool {
        self.bend(gravity).is_some_and(|axes| {
            axes.iter()
                .any(|(z, parting)| z.abs() > PUSHED_Z && parting.abs() > PUSHED_RATE_RADPS)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::rest_rotation::RestRotation;
    use super::*;

    const G: f64 = 9.80665;

    /// A second at 200 Hz: pitching as `theta(t)`, pushed forward by `accel(t)` (m/s^2), a
    /// gyro bias and white noise of `sd` on both sensors.
    fn rest(
        theta: impl Fn(f64) -> (f64, f64),
        accel: impl Fn(f64) -> f64,
        bias: f64,
        sd: f64,
        seed: u64,
    ) -> RestShape {
        let mut state = seed;
        let mut noise = move || {
            let mut s = 0.0;
            for _ in 0..12 {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                s += (state >> 11) as f64 / (1u64 << 53) as f64;
            }
            (s - 6.0) * sd
        };
        let (mut rotation, mut r) = (RestRotation::new(), RestShape::default());
        for k in 0..=200 {
            let t = 5.0 + k as f64 * 0.005;
            let (th, q) = theta(t - 5.0);
            let f = Vector3::new(G * th.sin() + accel(t - 5.0), 0.0, -G * th.cos());
            let f = f + Vector3::new(noise(), noise(), noise());
            let gyro = Vector3::new(noise(), q + bias + noise() * 0.1, noise() * 0.1);
            if rotation.push(t, &gyro, &f) {
                let (t, angle) = rotation.last();
                r.push(t, &angle, &f);
            }
        }
        r
    }

    #[test]
    fn a_swing_is_a_turn_a_falling_push_is_not() {
        let swing = |t: f64| (0.07 * (1.8 * t).sin(), 0.07 * 1.8 * (1.8 * t).cos());
        let level = |_: f64| (0.0, 0.0);
        // A drag falling from 0.5 m/s^2 with a 0.5 s time constant (eight_vectored meeting
        // a current reads 0.46 m/s^2 per s).
        let drag = |t: f64| 0.5 * (-t / 0.5).exp();
        for seed in 1..=5 {
            let swung = rest(swing, |_| 0.0, 0.02, 0.02, seed);
            assert!(!swung.pushed(G), "seed {seed}: {:?}", swung.bend(G));
            let still = rest(level, |_| 0.0, 0.02, 0.02, seed);
            assert!(!still.pushed(G), "seed {seed}: {:?}", still.bend(G));
            let pushed = rest(level, drag, 0.0, 0.02, seed);
            assert!(pushed.pushed(G), "seed {seed}: {:?}", pushed.bend(G));
            let swung_and_pushed = rest(swing, drag, 0.0, 0.02, seed);
            assert!(swung_and_pushed.pushed(G), "seed {seed}");
        }
        // Noise-free: a swing with a bias is a line to rounding, not a push.
        assert!(!rest(swing, |_| 0.0, 0.02, 0.0, 1).pushed(G));
        assert!(rest(level, drag, 0.0, 0.0, 1).pushed(G));
        // Too short or not gravity: no verdict.
        assert_eq!(RestShape::default().bend(G), None);
    }
}
