//! How far the simulated vehicle moved away from where it started: the largest tilt (angle of
//! body z from down) and heading change, from the simulator's true state. The lab reports it
//! for the time the daemon estimates, since an estimation that lets go of the vehicle is only
//! acceptable when it stays small.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use thruster_protocol::VehicleStateMsg;

/// Largest excursion seen over a stretch of vehicle states.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Excursion {
    start_heading: Option<f64>,
    /// Largest tilt, deg.
    pub max_tilt_deg: f64,
    /// Largest heading change from the first state seen, deg.
    pub max_heading_deg: f64,
    /// Vehicle states seen.
    pub samples: u64,
}

impl Excursion {
    /// One true vehicle state.
    pub fn push(&mut self, v: &VehicleStateMsg) {
        let [w, x, y, z] = v.attitude;
        let norm = (w * w + x * x + y * y + z * z).sqrt();
        if !(norm.is_finite() && (norm - 1.0).abs() < 0.1) {
            return;
        }
        self.push_attitude(&UnitQuaternion::from_quaternion(Quaternion::new(
            w, x, y, z,
        )));
    }

    /// One true attitude (body to NED).
    pub fn push_attitude(&mut self, q: &UnitQuaternion<f64>) {
        let down = q.inverse_transform_vector(&Vector3::z());
        let tilt = down.z.clamp(-1.0, 1.0).acos().to_degrees();
        let heading = q.euler_angles().2;
        let start = *self.start_heading.get_or_insert(heading);
        let d = heading - start;
        let change = d.sin().atan2(d.cos()).abs().to_degrees();
        self.max_tilt_deg = self.max_tilt_deg.max(tilt);
        self.max_heading_deg = self.max_heading_deg.max(change);
        self.samples += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(roll: f64, pitch: f64, yaw: f64) -> VehicleStateMsg {
        let q = UnitQuaternion::from_euler_angles(roll, pitch, yaw).into_inner();
        VehicleStateMsg {
            attitude: [q.w, q.i, q.j, q.k],
            ..VehicleStateMsg::default()
        }
    }

    #[test]
    fn tilt_and_heading_are_measured_from_the_first_state() {
        let mut e = Excursion::default();
        e.push(&state(0.0, 0.0, 3.0));
        e.push(&state(0.0, 20f64.to_radians(), 3.0 + 30f64.to_radians()));
        // Across the +-180 deg seam: 3.0 rad -> -3.0 rad is 16.4 deg, not 343.6.
        e.push(&state(0.0, 0.0, -3.0));
        e.push(&VehicleStateMsg::default()); // all-zero quaternion: ignored
        assert!((e.max_tilt_deg - 20.0).abs() < 1e-9);
        assert!((e.max_heading_deg - 30.0).abs() < 1e-9);
        assert_eq!(e.samples, 3);
    }
}
