//! Navigation during an excitation: attitude, body velocity and the accelerometer's bias from
//! the IMU and depth sensor.
//!
//! The dynamic-model estimator needs the vehicle's attitude (restoring moment, gravity in the
//! accelerometer) and body velocity (drag, Munk moment, omega x v) while the thrusters pulse.
//! The attitude filter that the controller uses leans on the accelerometer for tilt, which is
//! wrong exactly then: the accelerometer sees the thrust. So this filter starts from the rest
//! that precedes the excitation (vehicle still, attitude from gravity, velocity zero) and then
//! dead-reckons a few seconds:
//! - attitude: the bias-free gyro integrated (exact rotation vector step per sample);
//! - velocity: strapdown, v_dot = f - b + g_body - omega x v;
//! - depth and accelerometer bias: an error-state Kalman filter ([`bias_filter`]) on the
//!   pressure sensor. At rest a bias across gravity looks like tilt and is folded into the
//!   starting attitude; once the vehicle turns, the depth sees what that fold costs, and the
//!   filter corrects bias, attitude and velocity together.
//!
//! Pure: time only from the samples. Horizontal velocity is observed only through the bias's
//! cross-covariances (no DVL), so it drifts with the attitude error; over the excitation's few
//! seconds that drift is well below the velocities the thrusters cause at a realistic IMU
//! (docs/study.md).

pub mod bias_filter;
pub mod long_rest_bias;
pub mod long_rest_down;
pub mod long_rest_sway;
pub mod rest_drift;
pub mod rest_rotation;
pub mod rest_shape;

use nalgebra::{UnitQuaternion, Vector3};

use self::bias_filter::{BiasFilter, FilterNoise};
use crate::estimator::response::GRAVITY;

/// Share of the difference to a DVL measurement taken per measurement. High, since a DVL is
/// far better than the dead-reckoned velocity (0.01 m/s noise against drift of tenths), but
/// below 1 so one bad ping does not replace the state.
pub const DVL_GAIN: f64 = 0.8;

/// Settings of the depth-aided navigation (1-sigma values).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DepthAid {
    /// Depth sensor noise per sample, m. Default 0.005 (a Bar30 is 0.003; a little more for
    /// waves and the lever arm).
    pub depth_std_m: f64,
    /// Accelerometer white noise per sample, m/s^2. Default 0.03 (the realistic IMU); the
    /// estimator passes the noise measured at rest.
    pub accel_std_mps2: f64,
    /// Unmodelled acceleration, m/s^2/sqrt(Hz). Default 0.02: the attitude error that gyro
    /// noise leaves puts a little gravity into the vertical channel.
    pub accel_floor: f64,
    /// Prior of each accelerometer-bias axis, m/s^2. Default 0.1 (MEMS turn-on bias is
    /// 0.05-0.2); 0 turns the bias state off (bias folded into the starting attitude). Only
    /// with `kalman`. The estimator passes `EstimatorConfig::accel_bias_std`, 0.02 by default
    /// (0 in the refinement's windows; docs/study.md).
    pub bias_std_mps2: f64,
    /// Bias random walk, m/s^2/sqrt(s). Default 0.001.
    pub bias_walk: f64,
    /// Depth aiding by the Kalman filter (true: whenever the bias state is on, which the
    /// estimator's default is) or by the complementary gains below (false, this struct's
    /// default). The filter is needed for the bias state; without it, it was better in
    /// open loop (err_acc 0.018 -> 0.015 at the realistic IMU) but under control it made the
    /// refinement blame the wrong thruster and raise a false alarm (tests/refinement.rs), so
    /// it is not the default (docs/study.md).
    pub kalman: bool,
    /// Complementary aid: share of the depth innovation added to the depth estimate per
    /// sample. Default 0.05.
    pub depth_gain: f64,
    /// Complementary aid: vertical velocity correction per metre of depth innovation, 1/s.
    /// Default 0.5. Stiff enough to hold the vertical velocity within a few cm/s at paper
    /// noise, soft enough not to pass the depth noise through (measured on the simulator).
    pub velocity_gain: f64,
    /// Prior of each velocity axis at the rest, m/s. Default 0.02: a body that is not exactly
    /// neutrally buoyant drifts during the rest.
    pub velocity_std_mps: f64,
}

impl Default for DepthAid {
    fn default() -> Self {
        DepthAid {
            depth_std_m: 0.005,
            accel_std_mps2: 0.03,
            accel_floor: 0.02,
            bias_std_mps2: 0.1,
            bias_walk: 0.001,
            velocity_std_mps: 0.02,
            kalman: false,
            depth_gain: 0.05,
            velocity_gain: 0.5,
        }
    }
}

impl DepthAid {
    fn filter_noise(&self) -> FilterNoise {
        FilterNoise {
            depth_std_m: self.depth_std_m,
            accel_std_mps2: self.accel_std_mps2,
            accel_floor: self.accel_floor,
            bias_std_mps2: self.bias_std_mps2,
            bias_walk: self.bias_walk,
            velocity_std_mps: self.velocity_std_mps,
        }
    }
}

/// The navigation state at one sample.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NavState {
    /// Body to NED.
    pub attitude: UnitQuaternion<f64>,
    /// Body velocity over ground, m/s.
    pub velocity: Vector3<f64>,
    /// Body angular rate (bias removed), rad/s.
    pub rate: Vector3<f64>,
    /// Unit gravity direction in the body frame (NED down seen from the body).
    pub down: Vector3<f64>,
    /// The body's acceleration, body frame, m/s^2: specific force minus the estimated bias,
    /// plus gravity.
    pub motion: Vector3<f64>,
}

/// Dead reckoning from a rest, aided by depth.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Navigator {
    aid: DepthAid,
    /// Gravity, m/s^2.
    gravity: f64,
    attitude: UnitQuaternion<f64>,
    /// Body velocity, m/s.
    velocity: Vector3<f64>,
    depth: Option<f64>,
    /// Estimated accelerometer bias, body frame, m/s^2.
    bias: Vector3<f64>,
    filter: BiasFilter,
    last_t_s: Option<f64>,
    /// The previous sample's rate and body acceleration (trapezoidal integration).
    last_rate: Vector3<f64>,
    last_accel: Vector3<f64>,
    /// Largest tilt (angle of body z from down) and heading change seen, rad.
    max_tilt: f64,
    max_heading: f64,
    heading0: f64,
}

impl Navigator {
    /// Starts at rest: `accel_rest` is the mean specific force at rest (m/s^2), `heading` the
    /// heading then (rad, from the attitude filter; it does not enter the dynamics), `depth`
    /// the depth then if a sensor gives one.
    pub fn at_rest(
        accel_rest: &Vector3<f64>,
        heading: f64,
        depth: Option<f64>,
        aid: DepthAid,
    ) -> Self {
        // The accelerometer's reading at rest is -g in the body frame plus its bias; starting
        // the attitude from that reading makes f + g_body zero at rest, bias included. The
        // bias filter later takes back what of that was bias.
        let down = if accel_rest.norm() > 1e-6 {
            -accel_rest.normalize()
        } else {
            Vector3::z()
        };
        let roll = down.y.atan2(down.z);
        let pitch = (-down.x).atan2((down.y * down.y + down.z * down.z).sqrt());
        let attitude = UnitQuaternion::from_euler_angles(roll, pitch, heading);
        // Standard gravity: the rest's magnitude is no better, since a body that is not
        // exactly neutrally buoyant is still accelerating then (measured: 5x the velocity error).
        let gravity = GRAVITY;
        let mut nav = Navigator {
            aid,
            gravity,
            attitude,
            velocity: Vector3::zeros(),
            depth: depth.filter(|d| d.is_finite()),
            bias: Vector3::zeros(),
            filter: BiasFilter::at_rest(aid.filter_noise(), &attitude, gravity),
            last_t_s: None,
            last_rate: Vector3::zeros(),
            last_accel: Vector3::zeros(),
            max_tilt: 0.0,
            max_heading: 0.0,
            heading0: heading,
        };
        nav.max_tilt = nav.tilt();
        nav
    }

    /// One sample at `t_s`: bias-free gyro (rad/s), specific force (m/s^2), depth (m).
    /// Non-finite inputs are skipped (the state is kept).
    pub fn update(
        &mut self,
        t_s: f64,
        rate: &Vector3<f64>,
        specific_force: &Vector3<f64>,
        depth: Option<f64>,
    ) -> NavState {
        let finite = t_s.is_finite()
            && rate
                .iter()
                .chain(specific_force.iter())
                .all(|v| v.is_finite());
        if finite {
            let dt = self
                .last_t_s
                .map(|t0| (t_s - t0).clamp(0.0, 0.1))
                .unwrap_or(0.0);
            let first = self.last_t_s.is_none();
            self.last_t_s = Some(t_s);
            let mean_rate = if first {
                *rate
            } else {
                0.5 * (rate + self.last_rate)
            };
            self.attitude *= UnitQuaternion::from_scaled_axis(mean_rate * dt);
            self.last_rate = *rate;
            let f = specific_force - self.bias;
            // Body-frame strapdown (the NED form is the same equation, but its discretisation
            // moved the noise-free pitch restoring coefficient from 8.5 % to 12 % off).
            let g_body = self.down() * self.gravity;
            let drive = f + g_body;
            // Implicit trapezoid: the transport term -omega x v at the step's end uses the
            // step's end velocity, (I + dt/2 [omega]x) v_k = v_(k-1) + dt/2 (a_(k-1) +
            // drive_k). The explicit form took omega_k x v_(k-1), an error of dt^2/2 omega x a
            // per step that does not cancel: ~1 cm/s over a 4 s excitation at 200 Hz, which
            // moved the noise-free pitch damping by ~10 % (docs/study.md).
            // (The first sample has dt = 0: the velocity stays, and a_(k-1) starts there.)
            let rhs = self.velocity + 0.5 * dt * (self.last_accel + drive);
            let m = nalgebra::Matrix3::identity() + rate.cross_matrix() * (0.5 * dt);
            if let Some(v) = m.lu().solve(&rhs) {
                self.velocity = v;
            }
            self.last_accel = drive - rate.cross(&self.velocity);
            if self.aid.kalman {
                let c = self.attitude.to_rotation_matrix().into_inner();
                self.filter.predict(dt, &c, &f);
            }
            let measured = depth.filter(|d| d.is_finite());
            if self.depth.is_none() {
                // The first depth reading anchors the depth channel.
                self.depth = measured;
            }
            if let (Some(z), Some(measured)) = (self.depth.as_mut(), measured) {
                let vz = self.attitude.transform_vector(&self.velocity).z;
                *z += vz * dt;
                let innovation = measured - *z;
                let velocity_ned = if self.aid.kalman {
                    let k = self.filter.update_depth(innovation);
                    *z += k.depth;
                    self.bias += k.bias;
                    self.attitude = UnitQuaternion::from_scaled_axis(k.attitude) * self.attitude;
                    k.velocity_ned
                } else {
                    *z += self.aid.depth_gain * innovation;
                    Vector3::new(0.0, 0.0, self.aid.velocity_gain * innovation * dt)
                };
                self.velocity += self.attitude.inverse_transform_vector(&velocity_ned);
            }
            self.max_tilt = self.max_tilt.max(self.tilt());
            let heading = self.attitude.euler_angles().2 - self.heading0;
            let heading = heading.sin().atan2(heading.cos());
            self.max_heading = self.max_heading.max(heading.abs());
        }
        let down = self.down();
        NavState {
            attitude: self.attitude,
            velocity: self.velocity(),
            rate: if finite { *rate } else { Vector3::zeros() },
            down,
            motion: if finite {
                specific_force - self.bias + down * self.gravity
            } else {
                Vector3::zeros()
            },
        }
    }

    /// The vertical velocity (NED, m/s, positive sinking) the rest ended with
    /// ([`rest_drift::RestDrift`]): the body velocity starts from it instead of zero.
    pub fn start_sinking_at(&mut self, velocity_down: f64) {
        if velocity_down.is_finite() {
            self.velocity =
                self.attitude
                    .inverse_transform_vector(&Vector3::new(0.0, 0.0, velocity_down));
        }
    }

    /// A measured body velocity (a DVL, m/s): the estimate moves `DVL_GAIN` of the way to it.
    /// Horizontal velocity is otherwise not observed at all; a DVL at 5 Hz bounds its drift.
    /// Non-finite measurements are ignored.
    pub fn velocity_fix(&mut self, measured: &Vector3<f64>) {
        if measured.iter().all(|v| v.is_finite()) {
            self.velocity += DVL_GAIN * (measured - self.velocity);
        }
    }

    /// Body velocity, m/s.
    pub fn velocity(&self) -> Vector3<f64> {
        self.velocity
    }

    /// Estimated accelerometer bias, body frame, m/s^2.
    pub fn accel_bias(&self) -> Vector3<f64> {
        self.bias
    }

    /// 1-sigma of the bias estimate per axis, m/s^2.
    pub fn accel_bias_std(&self) -> Vector3<f64> {
        self.filter.bias_std()
    }

    /// Gravity used, m/s^2 (standard gravity).
    pub fn gravity(&self) -> f64 {
        self.gravity
    }

    /// Unit gravity direction in the body frame.
    pub fn down(&self) -> Vector3<f64> {
        self.attitude.inverse_transform_vector(&Vector3::z())
    }

    /// Angle between body z and down, rad.
    pub fn tilt(&self) -> f64 {
        self.down().z.clamp(-1.0, 1.0).acos()
    }

    /// Largest tilt since the rest, rad.
    pub fn max_tilt(&self) -> f64 {
        self.max_tilt
    }

    /// Largest heading change since the rest, rad.
    pub fn max_heading_change(&self) -> f64 {
        self.max_heading
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_still_tilted_vehicle_stays_put() {
        // A bias across gravity is indistinguishable from tilt at rest and is absorbed with it.
        let q = UnitQuaternion::from_euler_angles(0.2, -0.1, 0.0);
        let f = -q.inverse_transform_vector(&Vector3::z()) * GRAVITY;
        let mut nav = Navigator::at_rest(&f, 0.0, Some(10.0), DepthAid::default());
        let mut s = nav.update(0.0, &Vector3::zeros(), &f, Some(10.0));
        for k in 1..=1000 {
            s = nav.update(k as f64 * 0.005, &Vector3::zeros(), &f, Some(10.0));
        }
        assert!(s.velocity.norm() < 1e-9, "{}", s.velocity);
        assert!((nav.max_tilt() - f.normalize().z.abs().acos()).abs() < 1e-9);
    }

    /// A vehicle that rolls in place with a biased accelerometer: the bias along gravity shows
    /// at once, the one across it (folded into the rest's roll) once the roll turns it toward
    /// the vertical; the one along the roll axis stays unobservable and nearly untouched. The
    /// velocity stays near zero, where without the state it drifts.
    #[test]
    fn a_roll_in_place_reveals_the_accelerometer_bias() {
        let bias = Vector3::new(0.08, 0.1, 0.05);
        let truth_q = |t: f64| UnitQuaternion::from_euler_angles(0.5 * t.min(1.0), 0.0, 0.0);
        let f = |t: f64| -truth_q(t).inverse_transform_vector(&Vector3::z()) * GRAVITY + bias;
        // Exact samples: little unmodelled acceleration to hide the bias behind.
        let aid = DepthAid {
            depth_std_m: 0.001,
            accel_floor: 0.002,
            kalman: true,
            ..DepthAid::default()
        };
        let run = |aid: DepthAid| {
            let mut nav = Navigator::at_rest(&f(0.0), 0.0, Some(10.0), aid);
            let mut s = nav.update(0.0, &Vector3::zeros(), &f(0.0), Some(10.0));
            for k in 1..=1000 {
                let t = k as f64 * 0.005;
                let w = Vector3::new(if t <= 1.0 { 0.5 } else { 0.0 }, 0.0, 0.0);
                s = nav.update(t, &w, &f(t), Some(10.0));
            }
            (nav, s)
        };
        let (nav, s) = run(aid);
        let (_, without) = run(DepthAid {
            bias_std_mps2: 0.0,
            ..aid
        });
        let b = nav.accel_bias();
        assert!((b.y - bias.y).abs() < 0.01, "{b}");
        assert!((b.z - bias.z).abs() < 0.01, "{b}");
        assert!(b.x.abs() < 0.005, "{b}");
        println!(
            "velocity {:.4} m/s, without the state {:.4}",
            s.velocity.norm(),
            without.velocity.norm()
        );
        assert!(
            s.velocity.norm() < 0.02 && s.velocity.norm() < 0.25 * without.velocity.norm(),
            "{} vs {} without the state",
            s.velocity,
            without.velocity
        );
        // The roll that the y bias had folded in is taken back out.
        let roll_err = s.attitude.angle_to(&truth_q(5.0)).to_degrees();
        let unobservable = (bias.x / GRAVITY).to_degrees();
        assert!(roll_err < unobservable + 0.05, "{roll_err} deg");
    }

    #[test]
    fn a_constant_rate_turns_the_attitude_by_rate_times_time() {
        let f = Vector3::new(0.0, 0.0, -GRAVITY);
        let mut nav = Navigator::at_rest(&f, 0.0, None, DepthAid::default());
        let w = Vector3::new(0.0, 0.0, 0.5);
        for k in 0..=200 {
            // A yaw turn leaves gravity where it is.
            nav.update(k as f64 * 0.005, &w, &f, None);
        }
        assert!((nav.max_heading_change() - 0.5).abs() < 1e-9);
        assert!(nav.tilt() < 1e-9);
    }

    #[test]
    fn a_dvl_measurement_pulls_the_velocity_and_a_bad_one_is_ignored() {
        let f = Vector3::new(0.0, 0.0, -GRAVITY);
        let mut nav = Navigator::at_rest(&f, 0.0, None, DepthAid::default());
        nav.update(0.0, &Vector3::zeros(), &f, None);
        nav.velocity_fix(&Vector3::new(1.0, 0.0, 0.0));
        nav.velocity_fix(&Vector3::new(f64::NAN, 0.0, 0.0));
        let s = nav.update(0.005, &Vector3::zeros(), &f, None);
        assert!((s.velocity.x - DVL_GAIN).abs() < 1e-12, "{}", s.velocity);
    }

    #[test]
    fn non_finite_samples_leave_the_state_alone() {
        let f = Vector3::new(0.0, 0.0, -GRAVITY);
        let mut nav = Navigator::at_rest(&f, 0.0, None, DepthAid::default());
        nav.update(0.0, &Vector3::zeros(), &f, None);
        let s = nav.update(0.01, &Vector3::new(f64::NAN, 0.0, 0.0), &f, None);
        assert_eq!(s.velocity, Vector3::zeros());
        assert_eq!(s.attitude, UnitQuaternion::identity());
    }
}
