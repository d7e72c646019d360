use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use super::{clamp_count, DaemonState, ThrustMode, MAX_THRUSTERS};
use crate::wire::UnknownEnumValue;

/// What the daemon does, one sample of it (daemon -> all, service `telemetry`): the attitude
/// estimate, the setpoint and the error to it, depth, the commands sent and, while
/// estimating, the estimator's progress. Published after the thrust command of every
/// `telemetry.every_n`-th accepted IMU sample (daemon config), so its time is the IMU's.
///
/// One flat message of fixed size on one topic: a recorder logs it as one channel, and its
/// serde form (arrays of numbers, enums as numbers) is plain JSON. Every float is finite
/// whatever the flags say: what is not known is written as 0 (a quaternion as identity) and
/// its flag is clear, so a plot never meets NaN.
///
/// Angles are radians, like every other message; `thrusterctl watch` shows degrees.
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[type_name("thrusterd.TelemetryMsg.v1")]
pub struct TelemetryMsg {
    /// Sequence number, +1 per telemetry message (gaps: decimation never makes them, a lost
    /// message does).
    pub seq: u64,
    /// `t_ns` of the IMU sample this telemetry describes, ns, sensor monotonic clock (vehicle
    /// time).
    pub t_ns: u64,
    /// `seq` of that IMU sample.
    pub imu_seq: u64,
    /// [`DaemonState`] as `u32`, after the sample was handled.
    pub state: u32,
    /// [`ThrustMode`] of the command sent for the sample, as `u32`.
    pub mode: u32,
    /// Bit set of `TelemetryMsg::*` flags saying which groups of fields hold values.
    pub flags: u64,
    /// Thrusters in `thrust`, at most [`MAX_THRUSTERS`].
    pub count: u32,
    /// Pulses completed in the estimation under way (with [`TelemetryMsg::ESTIMATING`]).
    pub pulse: u32,
    /// Pulses planned for it (may grow until the stopping rule is met).
    pub pulses_planned: u32,
    /// Written as zero, ignored (keeps the `f64`s 8-byte aligned in C).
    pub reserved: u32,
    /// `version` of the model in force (0 = none), as in [`crate::ModelMsg`].
    pub model_version: u64,
    /// Attitude estimate, unit quaternion `[w, x, y, z]`, rotation of the body frame
    /// relative to NED.
    pub attitude: [f64; 4],
    /// The same as roll, pitch, yaw (Z-Y-X Euler angles), rad; roll and yaw in [-pi, pi],
    /// pitch in [-pi/2, pi/2].
    pub euler: [f64; 3],
    /// Body rate, gyro minus the attitude filter's bias estimate, rad/s (x, y, z).
    pub rate: [f64; 3],
    /// Measured depth, m, positive down (with [`TelemetryMsg::HAS_DEPTH`]).
    pub depth: f64,
    /// Attitude the controller tracks, `[w, x, y, z]` body to NED (with
    /// [`TelemetryMsg::HAS_SETPOINT`]; identity otherwise).
    pub setpoint_attitude: [f64; 4],
    /// The same as roll, pitch, yaw, rad.
    pub setpoint_euler: [f64; 3],
    /// Depth the controller holds, m, positive down (with [`TelemetryMsg::HOLD_DEPTH`]).
    pub setpoint_depth: f64,
    /// Rotation from the estimate to the setpoint as a rotation vector in the body frame,
    /// rad (what the attitude controller acts on; x roll, y pitch, z yaw for small errors).
    pub attitude_error: [f64; 3],
    /// Its magnitude: the angle between estimate and setpoint, rad, in [0, pi].
    pub attitude_error_angle: f64,
    /// `setpoint_depth - depth`, m (positive: the vehicle must go deeper); with both
    /// [`TelemetryMsg::HOLD_DEPTH`] and [`TelemetryMsg::HAS_DEPTH`].
    pub depth_error: f64,
    /// Normalised command sent to each thruster in [-1, 1] (after the daemon's last
    /// sanitising, exactly what went out on `thrust`). Entries at and beyond `count` are
    /// ignored.
    pub thrust: [f64; MAX_THRUSTERS],
    /// Excitation power, normalised command magnitude in [0, 1] (with `ESTIMATING`).
    pub power: f64,
    /// Relative error bound (1 sigma, dimensionless) of the estimate so far (with
    /// [`TelemetryMsg::HAS_ERROR_BOUND`]).
    pub error_bound: f64,
    /// Measured rotation-rate noise, one sigma, rad/s (with [`TelemetryMsg::HAS_NOISE`]).
    pub sigma_rot: f64,
    /// Measured acceleration noise, one sigma, m/s^2 (with [`TelemetryMsg::HAS_NOISE`]).
    pub sigma_acc: f64,
}

impl TelemetryMsg {
    /// The controller tracks a setpoint: `setpoint_attitude`, `setpoint_euler`,
    /// `attitude_error` and `attitude_error_angle` hold values.
    pub const HAS_SETPOINT: u64 = 1 << 0;
    /// The setpoint holds a depth: `setpoint_depth` holds a value.
    pub const HOLD_DEPTH: u64 = 1 << 1;
    /// The IMU sample carried a depth: `depth` holds a value.
    pub const HAS_DEPTH: u64 = 1 << 2;
    /// An estimation is under way: `pulse`, `pulses_planned` and `power` hold values.
    pub const ESTIMATING: u64 = 1 << 3;
    /// `error_bound` holds a value (not before every thruster was pulsed).
    pub const HAS_ERROR_BOUND: u64 = 1 << 4;
    /// `sigma_rot` and `sigma_acc` hold values (the noise was measured).
    pub const HAS_NOISE: u64 = 1 << 5;
    /// Every flag this version defines; other bits are rejected.
    pub const KNOWN_FLAGS: u64 = Self::HAS_SETPOINT
        | Self::HOLD_DEPTH
        | Self::HAS_DEPTH
        | Self::ESTIMATING
        | Self::HAS_ERROR_BOUND
        | Self::HAS_NOISE;

    /// Decoded `state`.
    pub fn state(&self) -> Result<DaemonState, UnknownEnumValue> {
        DaemonState::try_from(self.state)
    }

    /// Sets `state`.
    pub fn set_state(&mut self, state: DaemonState) {
        self.state = state.as_u32();
    }

    /// Decoded `mode`.
    pub fn mode(&self) -> Result<ThrustMode, UnknownEnumValue> {
        ThrustMode::try_from(self.mode)
    }

    /// Sets `mode`.
    pub fn set_mode(&mut self, mode: ThrustMode) {
        self.mode = mode.as_u32();
    }

    /// True when every bit of `flag` is set.
    pub fn has(&self, flag: u64) -> bool {
        self.flags & flag == flag
    }

    /// The commands in use (`thrust[..count]`, count clamped to capacity).
    pub fn thrusters(&self) -> &[f64] {
        &self.thrust[..clamp_count(self.count)]
    }
}

impl Default for TelemetryMsg {
    /// Nothing known: identity quaternions, zeros, no flags.
    fn default() -> Self {
        Self {
            seq: 0,
            t_ns: 0,
            imu_seq: 0,
            state: DaemonState::Idle.as_u32(),
            mode: ThrustMode::Neutral.as_u32(),
            flags: 0,
            count: 0,
            pulse: 0,
            pulses_planned: 0,
            reserved: 0,
            model_version: 0,
            attitude: [1.0, 0.0, 0.0, 0.0],
            euler: [0.0; 3],
            rate: [0.0; 3],
            depth: 0.0,
            setpoint_attitude: [1.0, 0.0, 0.0, 0.0],
            setpoint_euler: [0.0; 3],
            setpoint_depth: 0.0,
            attitude_error: [0.0; 3],
            attitude_error_angle: 0.0,
            depth_error: 0.0,
            thrust: [0.0; MAX_THRUSTERS],
            power: 0.0,
            error_bound: 0.0,
            sigma_rot: 0.0,
            sigma_acc: 0.0,
        }
    }
}
