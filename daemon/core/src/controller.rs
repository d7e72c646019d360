//! Attitude and depth control through the current model's allocation.
//!
//! Attitude (quaternion) and depth errors become a desired body motion: angular acceleration
//! (PID on the attitude error, D on the measured rate) and a heave acceleration expressed in the
//! body frame. The model's allocation turns that into thruster commands. When commands saturate,
//! the translational part is scaled down first, then the rotational part (attitude keeps
//! priority, as PX4's sequential desaturation does), and integrators stop winding up.

use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::allocation::desaturate_within;
use crate::estimator::dynamic::DynamicTerms;
use crate::model::Model;
use thruster_protocol::MAX_THRUSTERS;

/// Depth is controlled only when the actuated translations can push at least this share of a
/// vertical force (0.5: the vertical is within 60 degrees of their span).
const MIN_VERTICAL_AUTHORITY: f64 = 0.5;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControllerConfig {
    /// Attitude proportional gain per axis (roll, pitch, yaw), rad/s^2 per rad (default 16:
    /// a 4 rad/s natural frequency, stiff enough against a BlueROV2-class righting moment).
    pub kp_att: [f64; 3],
    /// Rate damping per axis, rad/s^2 per rad/s (default 6: damping ratio 0.75).
    pub kd_att: [f64; 3],
    /// Attitude integral gain, rad/s^2 per rad s (default 4).
    pub ki_att: [f64; 3],
    /// Depth proportional gain, m/s^2 per m (default 2.0).
    pub kp_depth: f64,
    /// Depth rate damping, m/s^2 per m/s (default 2.5).
    pub kd_depth: f64,
    /// Depth integral gain, m/s^2 per m s (default 0.5): cancels buoyancy.
    pub ki_depth: f64,
    /// Integrator clamp, in units of desired acceleration (default 2.0).
    pub integral_limit: f64,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        ControllerConfig {
            kp_att: [16.0; 3],
            kd_att: [6.0; 3],
            ki_att: [4.0; 3],
            kp_depth: 2.0,
            kd_depth: 2.5,
            ki_depth: 0.5,
            integral_limit: 2.0,
        }
    }
}

/// What the vehicle should hold.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Target {
    pub attitude: UnitQuaternion<f64>,
    /// Depth to hold, m (positive down); None = do not control depth.
    pub depth: Option<f64>,
}

/// One control tick's measurements.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct Measured {
    pub attitude: UnitQuaternion<f64>,
    /// Body rates with the gyro bias removed, rad/s.
    pub rate: Vector3<f64>,
    pub depth: Option<f64>,
}

#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Controller {
    cfg: ControllerConfig,
    att_integral: Vector3<f64>,
    depth_integral: f64,
    last_depth: Option<f64>,
    depth_rate: f64,
}

/// Attitude error as a rotation vector in the body frame (rad): the rotation from the current
/// attitude to the target, shortest way round.
pub fn attitude_error(current: &UnitQuaternion<f64>, target: &UnitQuaternion<f64>) -> Vector3<f64> {
    let e = current.inverse() * target;
    let e = if e.w < 0.0 {
        UnitQuaternion::new_unchecked(-e.into_inner())
    } else {
        e
    };
    e.scaled_axis()
}

impl Controller {
    pub fn new(cfg: ControllerConfig) -> Self {
        Controller {
            cfg,
            ..Controller::default()
        }
    }

    /// Clear integrators and derivative memory (model swap to a different vehicle, fault).
    pub fn reset(&mut self) {
        self.att_integral = Vector3::zeros();
        self.depth_integral = 0.0;
        self.last_depth = None;
        self.depth_rate = 0.0;
    }

    /// Compute thruster commands into `out` (length = the model's thruster count), each in
    /// [-1, 1]. Returns the desired motion that was requested (DOF order).
    pub fn update(
        &mut self,
        m: &Measured,
        target: &Target,
        model: &Model,
        dt: f64,
        out: &mut [f64],
    ) -> [f64; 6] {
        let dt = if dt.is_finite() {
            dt.clamp(0.0, 0.1)
        } else {
            0.0
        };
        let err = attitude_error(&m.attitude, &target.attitude);
        let c = &self.cfg;
        let mut alpha = [0.0; 3];
        for a in 0..3 {
            alpha[a] =
                c.kp_att[a] * err[a] - c.kd_att[a] * m.rate[a] + c.ki_att[a] * self.att_integral[a];
        }
        let mut lin = [0.0; 3];
        let mut depth_err = 0.0;
        // Depth is held only through actuated translations that point mostly up or down now.
        // A vehicle without heave (all thrusters along x) could "fly" to depth by surging while
        // pitched, but a hover controller must not: the surge it would command at every pitch
        // step (from an integrator wound up while level, where depth was out of reach) pitches
        // a moving body further (Munk moment) and wrecks the attitude hold.
        let down_body = m.attitude.inverse_transform_vector(&Vector3::z());
        let vertical_authority = (0..3)
            .filter(|&i| model.actuated.0[3 + i])
            .map(|i| down_body[i] * down_body[i])
            .sum::<f64>()
            .sqrt();
        let depth_controllable = vertical_authority >= MIN_VERTICAL_AUTHORITY;
        if !depth_controllable {
            self.depth_integral = 0.0;
        }
        if let Some(depth) = m.depth {
            // The rate is tracked even while depth is not controlled, so taking over again
            // does not start from a stale sample.
            if let Some(last) = self.last_depth {
                if dt > 0.0 {
                    // Low-passed depth rate: pressure sensors are noisy.
                    let raw = (depth - last) / dt;
                    self.depth_rate += (raw - self.depth_rate) * (dt / 0.2).min(1.0);
                }
            }
            self.last_depth = Some(depth);
        }
        if let (Some(depth), Some(want), true) = (m.depth, target.depth, depth_controllable) {
            depth_err = want - depth;
            let a_down = c.kp_depth * depth_err - c.kd_depth * self.depth_rate
                + c.ki_depth * self.depth_integral;
            let body = m
                .attitude
                .inverse_transform_vector(&Vector3::new(0.0, 0.0, a_down));
            lin = [body.x, body.y, body.z];
        }
        // Unactuated DOFs are dropped by the allocation (zero columns) and their integrators
        // are not run, so they cannot wind up against a motion the vehicle cannot make.
        // Fixed-size scratch: the control tick runs once per IMU sample and must not allocate.
        let n = out.len().min(MAX_THRUSTERS);
        let mut u_rot = [0.0; MAX_THRUSTERS];
        let mut u_lin = [0.0; MAX_THRUSTERS];
        model.allocate(
            &[alpha[0], alpha[1], alpha[2], 0.0, 0.0, 0.0],
            &mut u_rot[..n],
        );
        model.allocate(&[0.0, 0.0, 0.0, lin[0], lin[1], lin[2]], &mut u_lin[..n]);
        // A model whose B multiplies the commands' thrust shape (`estimator.shaped_thrust`)
        // is inverted in that shape: the allocation's output is thrust-shape units, whose range
        // is [-(1 - k), 1 + k], and each command is the one that makes it. Measured
        // (docs/study.md, "The thrust's shape"): through AMOUR-5's pitch step the hold error
        // 6-9 % lower than commanding the shape as the command.
        let k = model.dynamics.as_ref().map_or(0.0, DynamicTerms::asymmetry);
        let (s_rot, s_lin) = desaturate_within(&u_rot[..n], &u_lin[..n], 1.0 - k, 1.0 + k);
        for (i, o) in out.iter_mut().enumerate() {
            let v = DynamicTerms::command_for_shape(k, s_rot * u_rot[i] + s_lin * u_lin[i]);
            *o = if v.is_finite() {
                v.clamp(-1.0, 1.0)
            } else {
                0.0
            };
        }
        if s_rot >= 1.0 && s_lin >= 1.0 {
            for a in 0..3 {
                if model.actuated.0[a] {
                    self.att_integral[a] = (self.att_integral[a] + err[a] * dt)
                        .clamp(-c.integral_limit, c.integral_limit);
                }
            }
            if target.depth.is_some() && depth_controllable {
                self.depth_integral = (self.depth_integral + depth_err * dt)
                    .clamp(-c.integral_limit, c.integral_limit);
            }
        }
        [
            alpha[0] * s_rot,
            alpha[1] * s_rot,
            alpha[2] * s_rot,
            lin[0] * s_lin,
            lin[1] * s_lin,
            lin[2] * s_lin,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{nominal_effectiveness, Model, RigidBody};

    fn model() -> Model {
        // Four thrusters: two forward at +-y (yaw, surge), two vertical at +-y (roll, heave).
        let pos = [
            [0.0, -0.2, 0.0],
            [0.0, 0.2, 0.0],
            [0.0, -0.2, 0.0],
            [0.0, 0.2, 0.0],
        ];
        let dir = [
            [1.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, 1.0],
        ];
        Model::nominal(
            nominal_effectiveness(&RigidBody::default(), &pos, &dir),
            None,
        )
    }

    #[test]
    fn attitude_error_is_body_rotation_vector() {
        let q = UnitQuaternion::identity();
        let t = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3);
        let e = attitude_error(&q, &t);
        assert!((e - Vector3::new(0.0, 0.0, 0.3)).norm() < 1e-12);
    }

    #[test]
    fn yaw_error_commands_differential_thrust_and_nothing_for_unactuated_pitch() {
        let m = model();
        let mut c = Controller::new(ControllerConfig::default());
        let meas = Measured {
            attitude: UnitQuaternion::identity(),
            rate: Vector3::zeros(),
            depth: None,
        };
        let target = Target {
            attitude: UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.1, 0.1)),
            depth: None,
        };
        let mut out = [0.0; 4];
        c.update(&meas, &target, &m, 0.01, &mut out);
        // +yaw: port thruster forward, starboard back; verticals untouched (pitch unactuated).
        assert!(out[0] > 0.0 && out[1] < 0.0, "{out:?}");
        assert!((out[0] + out[1]).abs() < 1e-12, "{out:?}");
        assert!(out[2].abs() < 1e-12 && out[3].abs() < 1e-12, "{out:?}");
    }

    /// A model whose B multiplies the commands' thrust shape (k = 0.1236, a T200's 0.78
    /// reverse ratio): the same yaw asks for the same thrust shapes as from a bare model, so
    /// the forward command is 1 / (1 + k) and the reverse 1 / (1 - k) of the bare one.
    #[test]
    fn a_shaped_model_is_commanded_through_its_thrust_shape() {
        let bare = model();
        let k = (1.0 - 0.78) / (1.0 + 0.78);
        let mut shaped = model();
        shaped.dynamics = Some(DynamicTerms {
            thrust_asymmetry: k,
            ..DynamicTerms::blank(4)
        });
        let meas = Measured {
            attitude: UnitQuaternion::identity(),
            rate: Vector3::zeros(),
            depth: None,
        };
        let target = Target {
            attitude: UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.1)),
            depth: None,
        };
        let (mut a, mut b) = ([0.0; 4], [0.0; 4]);
        Controller::new(ControllerConfig::default()).update(&meas, &target, &bare, 0.01, &mut a);
        Controller::new(ControllerConfig::default()).update(&meas, &target, &shaped, 0.01, &mut b);
        assert!(a[0] > 0.0 && a[1] < 0.0, "{a:?}");
        assert!((b[0] - a[0] / (1.0 + k)).abs() < 1e-12, "{a:?} {b:?}");
        assert!((b[1] - a[1] / (1.0 - k)).abs() < 1e-12, "{a:?} {b:?}");
        // Saturated, the reverse side reaches full command, not beyond it.
        let stiff = ControllerConfig {
            kp_att: [1000.0; 3],
            ..ControllerConfig::default()
        };
        Controller::new(stiff).update(&meas, &target, &shaped, 0.01, &mut b);
        assert!((b[1] + 1.0).abs() < 1e-12, "{b:?}");
        assert!((b[0] - (1.0 - k) / (1.0 + k)).abs() < 1e-12, "{b:?}");
    }

    #[test]
    fn saturation_keeps_attitude_priority_and_bounds() {
        let m = model();
        let mut c = Controller::new(ControllerConfig::default());
        let meas = Measured {
            attitude: UnitQuaternion::identity(),
            rate: Vector3::zeros(),
            depth: Some(0.0),
        };
        // A huge depth error and a roll error: heave saturates, roll must survive.
        let target = Target {
            attitude: UnitQuaternion::from_euler_angles(0.2, 0.0, 0.0),
            depth: Some(100.0),
        };
        let mut out = [0.0; 4];
        let desired = c.update(&meas, &target, &m, 0.01, &mut out);
        assert!(out.iter().all(|v| v.abs() <= 1.0 + 1e-12), "{out:?}");
        // Roll asks for a differential on the verticals, unscaled.
        let roll_alloc = m.allocation.column(0);
        let want = 16.0 * 0.2;
        assert!((desired[0] - want).abs() < 1e-9, "{desired:?}");
        assert!(
            (out[2] - out[3] - 2.0 * roll_alloc[2] * want).abs() < 1e-9,
            "{out:?}"
        );
    }

    #[test]
    fn depth_is_not_held_through_surge_alone() {
        // Two thrusters along x at different heights: pitch and surge, no heave.
        let pos = [[0.0, 0.0, -0.15], [0.0, 0.0, 0.15]];
        let dir = [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
        let m = Model::nominal(
            nominal_effectiveness(&RigidBody::default(), &pos, &dir),
            None,
        );
        assert!(m.actuated.0[3] && !m.actuated.0[5], "surge yes, heave no");
        let mut c = Controller::new(ControllerConfig::default());
        // Pitched 20 degrees, 5 m too shallow: surging would move it down, but must not.
        let pitched = UnitQuaternion::from_euler_angles(0.0, 20f64.to_radians(), 0.0);
        let meas = Measured {
            attitude: pitched,
            rate: Vector3::zeros(),
            depth: Some(0.0),
        };
        let target = Target {
            attitude: pitched,
            depth: Some(5.0),
        };
        let mut out = [0.0; 2];
        for _ in 0..100 {
            let desired = c.update(&meas, &target, &m, 0.01, &mut out);
            assert_eq!(desired[3..], [0.0; 3], "no translation asked for");
        }
        assert!(out.iter().all(|v| v.abs() < 1e-12), "{out:?}");
        assert_eq!(c.depth_integral, 0.0, "nothing wound up");

        // With heave actuated (the four-thruster model) the same error is held.
        let mut c = Controller::new(ControllerConfig::default());
        let mut out = [0.0; 4];
        let desired = c.update(&meas, &target, &model(), 0.01, &mut out);
        assert!(desired[5] > 0.0, "{desired:?}");
    }
}
