//! Attitude from gyro, accelerometer and magnetometer: a Mahony complementary filter.
//!
//! The gyro is integrated; the accelerometer's gravity direction corrects roll and pitch and the
//! magnetometer's horizontal field corrects yaw, through a proportional and an integral (gyro
//! bias) term. Body frame x forward, y starboard, z down; the quaternion maps body to NED.

use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AttitudeConfig {
    /// Proportional correction gain, 1/s (default 1.0: tilt errors decay in about a second).
    pub kp: f64,
    /// Integral (gyro bias) gain, 1/s^2 (default 0.05).
    pub ki: f64,
    /// Accelerometer readings further than this from 1 g (m/s^2) are not trusted for tilt:
    /// the vehicle is accelerating (default 2.0).
    pub accel_trust_m_s2: f64,
}

impl Default for AttitudeConfig {
    fn default() -> Self {
        AttitudeConfig {
            kp: 1.0,
            ki: 0.05,
            accel_trust_m_s2: 2.0,
        }
    }
}

const G: f64 = crate::estimator::response::GRAVITY;

/// The gyro bias is integrated only below this rotation rate, rad/s. Why: turning fast, the
/// vehicle is tumbling or swinging, and the accelerometer's "up" carries its accelerations
/// across gravity (their magnitude barely moves the norm the trust test reads: 2 m/s^2 across
/// g changes it by 0.2 m/s^2 and tilts "up" by 11 deg). The proportional term forgets them in
/// a second; the integral kept them as a bias: after `aligned` tumbled to 75 deg (noise-free)
/// the filter's tilt was still 0.9 deg off 6 s later and 0.5 deg at 17 s (kp / ki = 20 s),
/// and the fits made then took the tilt's gravity for thrust (docs/study.md, "A model fitted
/// on the controller's fight").
pub const BIAS_LEARNING_MAX_RADPS: f64 = 0.5;

/// The time constant of the rate the bias gate reads, s (40 samples at 200 Hz: the paper's
/// white gyro noise averages to about 0.05 rad/s in norm).
pub const RATE_SMOOTHING_S: f64 = 0.2;

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct AttitudeFilter {
    cfg: AttitudeConfig,
    q: UnitQuaternion<f64>,
    bias: Vector3<f64>,
    initialised: bool,
    /// The bias-corrected rate, low-passed over `RATE_SMOOTHING_S`: what the bias gate
    /// reads (one sample's white gyro noise is 0.43 rad/s in norm at the paper's noise).
    #[serde(default)]
    rate_lp: Vector3<f64>,
}

impl AttitudeFilter {
    pub fn new(cfg: AttitudeConfig) -> Self {
        AttitudeFilter {
            cfg,
            q: UnitQuaternion::identity(),
            bias: Vector3::zeros(),
            initialised: false,
            rate_lp: Vector3::zeros(),
        }
    }

    /// Body-to-NED attitude.
    pub fn attitude(&self) -> UnitQuaternion<f64> {
        self.q
    }

    /// Estimated gyro bias, rad/s.
    pub fn gyro_bias(&self) -> Vector3<f64> {
        self.bias
    }

    pub fn is_initialised(&self) -> bool {
        self.initialised
    }

    /// Forget everything (after a fault the old attitude may be far off).
    pub fn reset(&mut self) {
        self.initialised = false;
        self.bias = Vector3::zeros();
        self.rate_lp = Vector3::zeros();
        self.q = UnitQuaternion::identity();
    }

    /// One sample: gyro rad/s, specific force m/s^2, optional magnetometer (any unit), `dt` s.
    pub fn update(
        &mut self,
        gyro: &Vector3<f64>,
        accel: &Vector3<f64>,
        mag: Option<&Vector3<f64>>,
        dt: f64,
    ) {
        self.update_with(gyro, accel, mag, dt, true);
    }

    /// As `update`, but with `correct = false` the gyro is only integrated: during a thruster
    /// pulse the accelerometer sees the pulse's own acceleration, and letting it "correct" the
    /// tilt would leak that acceleration into the gravity compensation.
    pub fn update_with(
        &mut self,
        gyro: &Vector3<f64>,
        accel: &Vector3<f64>,
        mag: Option<&Vector3<f64>>,
        dt: f64,
        correct: bool,
    ) {
        if !self.initialised {
            if let Some(q) = attitude_from_vectors(accel, mag) {
                self.q = q;
                self.initialised = true;
            }
            return;
        }
        let dt = if dt.is_finite() {
            dt.clamp(0.0, 0.1)
        } else {
            0.0
        };
        let mut err = Vector3::zeros();
        let norm = accel.norm();
        if correct && norm > 0.0 && (norm - G).abs() < self.cfg.accel_trust_m_s2 {
            // Measured and predicted "up" (specific force at rest points up: -z in NED).
            let measured = accel / norm;
            let predicted = self
                .q
                .inverse_transform_vector(&Vector3::new(0.0, 0.0, -1.0));
            err += measured.cross(&predicted);
        }
        if let Some(m) = mag.filter(|m| correct && m.norm() > 0.0) {
            // Only the horizontal field direction: the magnetometer must not fight the tilt.
            let m = m.normalize();
            let h = self.q.transform_vector(&m);
            let reference = Vector3::new((h.x * h.x + h.y * h.y).sqrt(), 0.0, h.z);
            let predicted = self.q.inverse_transform_vector(&reference);
            let e = m.cross(&predicted);
            // Project onto the NED down axis in body: heading only.
            let down = self.q.inverse_transform_vector(&Vector3::z());
            err += down * down.dot(&e);
        }
        // The bias is learned only while the vehicle turns slowly (`BIAS_LEARNING_MAX_RADPS`).
        let smoothing = (dt / RATE_SMOOTHING_S).min(1.0);
        self.rate_lp += (gyro - self.bias - self.rate_lp) * smoothing;
        if self.rate_lp.norm() < BIAS_LEARNING_MAX_RADPS {
            self.bias -= err * self.cfg.ki * dt;
        }
        let omega = gyro - self.bias + err * self.cfg.kp;
        self.q *= UnitQuaternion::from_scaled_axis(omega * dt);
        self.q.renormalize();
    }
}

/// Attitude from one accelerometer (roll, pitch) and magnetometer (yaw) reading.
pub fn attitude_from_vectors(
    accel: &Vector3<f64>,
    mag: Option<&Vector3<f64>>,
) -> Option<UnitQuaternion<f64>> {
    if accel.norm() < 1e-6 || !accel.iter().all(|v| v.is_finite()) {
        return None;
    }
    // At rest the specific force is -g in body: f = R^T (0, 0, -g).
    let f = -accel.normalize();
    let roll = f.y.atan2(f.z);
    let pitch = (-f.x).atan2((f.y * f.y + f.z * f.z).sqrt());
    let tilt = UnitQuaternion::from_euler_angles(roll, pitch, 0.0);
    let yaw = match mag {
        Some(m) if m.norm() > 0.0 => {
            let h = tilt.transform_vector(m);
            // North is +x in NED: heading is the angle that rotates the field onto north.
            -h.y.atan2(h.x)
        }
        _ => 0.0,
    };
    Some(UnitQuaternion::from_euler_angles(roll, pitch, yaw))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(q: &UnitQuaternion<f64>) -> (Vector3<f64>, Vector3<f64>) {
        let accel = q.inverse_transform_vector(&Vector3::new(0.0, 0.0, -G));
        let mag = q.inverse_transform_vector(&Vector3::new(20.0, 0.0, 45.0));
        (accel, mag)
    }

    #[test]
    fn initial_attitude_from_vectors() {
        let truth = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0);
        let (a, m) = reading(&truth);
        let q = attitude_from_vectors(&a, Some(&m)).unwrap();
        assert!(
            q.angle_to(&truth) < 1e-9,
            "{:?} vs {:?}",
            q.euler_angles(),
            truth.euler_angles()
        );
    }

    #[test]
    fn converges_and_learns_gyro_bias() {
        let truth = UnitQuaternion::from_euler_angles(0.1, 0.2, -0.5);
        let (a, m) = reading(&truth);
        let mut f = AttitudeFilter::new(AttitudeConfig::default());
        f.update(&Vector3::zeros(), &a, Some(&m), 0.01);
        assert!(f.is_initialised());
        // A biased gyro at rest: the filter must learn the bias and hold the attitude.
        let bias = Vector3::new(0.02, -0.01, 0.015);
        for _ in 0..20_000 {
            f.update(&bias, &a, Some(&m), 0.01);
        }
        assert!(
            f.attitude().angle_to(&truth) < 0.01,
            "angle {}",
            f.attitude().angle_to(&truth)
        );
        assert!((f.gyro_bias() - bias).norm() < 2e-3, "{:?}", f.gyro_bias());
    }

    #[test]
    fn tracks_a_rotation_from_the_gyro() {
        let mut f = AttitudeFilter::new(AttitudeConfig {
            kp: 0.0,
            ki: 0.0,
            ..AttitudeConfig::default()
        });
        let (a, m) = reading(&UnitQuaternion::identity());
        f.update(&Vector3::zeros(), &a, Some(&m), 0.01);
        for _ in 0..100 {
            f.update(&Vector3::new(0.0, 0.0, 0.5), &a, Some(&m), 0.01);
        }
        let (_, _, yaw) = f.attitude().euler_angles();
        assert!((yaw - 0.5).abs() < 1e-6, "{yaw}");
    }

    /// A fast turn with the accelerometer pulled across gravity (a tumble's accelerations)
    /// leaves the bias alone but for the rate filter's first moments; the same misleading
    /// accelerometer while turning slowly is learned as bias (the counterfactual: the gate is
    /// what keeps it out).
    #[test]
    fn a_fast_turn_does_not_teach_the_bias() {
        let bias_after = |rate: f64| {
            let mut f = AttitudeFilter::new(AttitudeConfig::default());
            let level = Vector3::new(0.0, 0.0, -G);
            f.update(&Vector3::zeros(), &level, None, 0.005);
            // 2 m/s^2 across gravity along the body's x axis, turning about its z axis.
            let pulled = Vector3::new(2.0, 0.0, -G);
            for _ in 0..1000 {
                f.update(&Vector3::new(0.0, 0.0, rate), &pulled, None, 0.005);
            }
            f.gyro_bias().norm()
        };
        let fast = bias_after(1.0);
        let slow = bias_after(0.1);
        println!("bias learned: fast turn {fast:.5}, slow turn {slow:.5} rad/s");
        assert!(
            fast < 0.2 * slow,
            "fast turn: bias {fast}, slow turn {slow}"
        );
    }
}
