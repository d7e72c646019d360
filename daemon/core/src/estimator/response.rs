//! How a thruster pulse shows up in the IMU, as a known time shape per unit effectiveness.
//!
//! A thruster spins up with a first-order lag tau, so a command u stepped at t = 0 gives a force
//! u (1 - e^{-t/tau}). From rest, the vehicle's angular rate then grows like
//! B_rot u (t - tau (1 - e^{-t/tau})) and its linear acceleration like B_acc u (1 - e^{-t/tau}),
//! until drag builds up. Regressing each sample on u times that shape keeps the problem linear
//! in B (still unbiased, still incremental) while using every sample of the pulse, and gives B
//! in physical units: rad/s^2 and m/s^2 per unit command.

use nalgebra::{UnitQuaternion, Vector3};

/// Standard gravity, m/s^2.
pub const GRAVITY: f64 = 9.80665;

/// Shape of the response to a unit step command.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PulseShape {
    /// Thruster spin-up time constant, s (0 = instantaneous).
    pub lag_s: f64,
}

impl PulseShape {
    /// Thrust build-up 1 - e^{-t/tau}: the shape of the linear acceleration.
    pub fn accel(&self, t_s: f64) -> f64 {
        if t_s <= 0.0 {
            0.0
        } else if self.lag_s <= 0.0 {
            1.0
        } else {
            1.0 - (-t_s / self.lag_s).exp()
        }
    }

    /// Integral of the thrust build-up: the shape of the angular rate (rad/s per rad/s^2).
    pub fn rate(&self, t_s: f64) -> f64 {
        if t_s <= 0.0 {
            0.0
        } else {
            t_s - self.lag_s.max(0.0) * self.accel(t_s)
        }
    }
}

/// Gravity as the accelerometer sees it in the body frame at the given attitude (body to NED).
/// An accelerometer reads specific force f = a - g, so the motion acceleration is f + g_body.
pub fn gravity_in_body(attitude: &UnitQuaternion<f64>) -> Vector3<f64> {
    attitude.inverse_transform_vector(&Vector3::new(0.0, 0.0, GRAVITY))
}

/// Linear acceleration of the vehicle (m/s^2, body frame) from a specific-force reading and the
/// current attitude. Without this, a pitch of 0.1 rad during a pulse leaks ~1 m/s^2 of gravity
/// into the "response", as large as the thrust's own effect.
pub fn motion_accel(specific_force: &Vector3<f64>, attitude: &UnitQuaternion<f64>) -> Vector3<f64> {
    specific_force + gravity_in_body(attitude)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_start_at_zero_and_approach_step() {
        let s = PulseShape { lag_s: 0.1 };
        assert_eq!(s.accel(0.0), 0.0);
        assert!((s.accel(1.0) - 1.0).abs() < 1e-4);
        assert!((s.rate(1.0) - 0.9).abs() < 1e-4);
        let ideal = PulseShape { lag_s: 0.0 };
        assert_eq!(ideal.accel(0.01), 1.0);
        assert!((ideal.rate(0.5) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn level_vehicle_at_rest_has_no_motion_accel() {
        let q = UnitQuaternion::identity();
        let f = Vector3::new(0.0, 0.0, -GRAVITY);
        assert!(motion_accel(&f, &q).norm() < 1e-12);
        // Pitched up 10 degrees and at rest: the reading tilts, the motion stays zero.
        let q = UnitQuaternion::from_euler_angles(0.0, 10f64.to_radians(), 0.0);
        let f_tilted = -gravity_in_body(&q);
        assert!(f_tilted.x.abs() > 1.0);
        assert!(motion_accel(&f_tilted, &q).norm() < 1e-12);
    }
}
