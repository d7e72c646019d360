use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use super::{clamp_count, DOF_COUNT, MAX_THRUSTERS};

/// The simulator's true thruster model (simulator -> anyone, service `truth`, history 1),
/// so tests and the study can score estimates. Never used for control.
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[type_name("thrusterd.TruthMsg.v2")]
pub struct TruthMsg {
    /// Sequence number, +1 per message.
    pub seq: u64,
    /// Simulation time at which this truth became valid, ns, same clock as the IMU.
    pub t_ns: u64,
    /// Number of thrusters, at most [`MAX_THRUSTERS`].
    pub count: u32,
    /// Written as zero, ignored.
    pub reserved: u32,
    /// True effectiveness for positive commands, rows in [`crate::Dof`] order; rad/s^2
    /// (rotations) or m/s^2 (translations) per unit command, linearised about rest.
    pub effectiveness: [[f64; MAX_THRUSTERS]; DOF_COUNT],
    /// True effectiveness for negative commands (thrusters are weaker in reverse), same
    /// shape and units: response = reverse_effectiveness * u for u < 0.
    pub reverse_effectiveness: [[f64; MAX_THRUSTERS]; DOF_COUNT],
    /// Supply voltage the effectiveness holds at, V, in [0, 100]: a simulator with a battery
    /// republishes the truth as the voltage moves (thrusters with a measured table follow it);
    /// without one the fixed supply's. (v2 of this message.)
    pub supply_voltage_v: f64,
    /// 1 when the simulator models a battery (the voltage sags and falls), 0 for a fixed
    /// supply. (v2.)
    pub battery: u32,
    /// Written as zero, ignored.
    pub reserved2: u32,
}

impl TruthMsg {
    /// Thruster count clamped to capacity (safe for slicing).
    pub fn thruster_count(&self) -> usize {
        clamp_count(self.count)
    }

    /// The symmetric truth: the mean of forward and reverse effectiveness, which is what a
    /// linear model (one gain per thruster) learns from balanced pulses.
    pub fn symmetric(&self, dof: usize, thruster: usize) -> f64 {
        0.5 * (self.effectiveness[dof][thruster] + self.reverse_effectiveness[dof][thruster])
    }

    /// Relative Frobenius error of `model`'s rows `first..first + 3` (0: rotation, 3:
    /// translation) against the symmetric truth, over the model's thrusters.
    pub fn relative_error(&self, model: &super::ModelMsg, first: usize) -> f64 {
        let n = model.thruster_count().min(self.thruster_count());
        let (mut num, mut den) = (0.0, 0.0);
        for j in first..(first + 3).min(DOF_COUNT) {
            for i in 0..n {
                let t = self.symmetric(j, i);
                num += (model.effectiveness[j][i] - t).powi(2);
                den += t * t;
            }
        }
        (num / den.max(f64::MIN_POSITIVE)).sqrt()
    }
}

/// The simulated vehicle's true state (simulator -> anyone, service `vehicle`), one per IMU
/// sample, so experiments can score attitude control against the truth rather than against the
/// daemon's own estimate. Never used for control.
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[type_name("thrusterd.VehicleStateMsg.v1")]
pub struct VehicleStateMsg {
    /// Sequence number: the IMU sample's.
    pub seq: u64,
    /// Simulation time, ns, same clock as the IMU.
    pub t_ns: u64,
    /// Attitude, unit quaternion w, x, y, z, body to NED.
    pub attitude: [f64; 4],
    /// Body angular rate, rad/s.
    pub rate: [f64; 3],
    /// Position in NED, m (z = depth, positive down).
    pub position_ned: [f64; 3],
    /// Body linear velocity, m/s.
    pub velocity: [f64; 3],
}
