use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use super::{clamp_count, MAX_THRUSTERS};
use crate::wire::{wire_enum, UnknownEnumValue};

wire_enum! {
    /// What the daemon is doing with the thrusters; tells a driver why it gets the
    /// command (e.g. a hardware driver may log estimation pulses differently).
    pub enum ThrustMode {
        /// All thrust zero (idle, settle, abort, fault).
        #[default]
        Neutral = 0,
        /// Excitation pulses for estimation.
        Estimating = 1,
        /// Closed-loop control with the current model.
        Controlling = 2,
    }
}

/// Thruster commands answering one [`crate::ImuSample`] (daemon -> driver, service
/// `thrust`).
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[type_name("thrusterd.ThrustCommand.v1")]
pub struct ThrustCommand {
    /// Sequence number, +1 per command.
    pub seq: u64,
    /// `seq` of the IMU sample this command answers (lets the driver measure latency and
    /// detect skipped ticks).
    pub imu_seq: u64,
    /// `t_ns` of that IMU sample, ns, sensor monotonic clock.
    pub t_ns: u64,
    /// Number of thrusters in use, at most [`MAX_THRUSTERS`].
    pub count: u32,
    /// [`ThrustMode`] as `u32`.
    pub mode: u32,
    /// Normalised command per thruster in [-1, 1] (1 = full forward thrust; the paper's
    /// -100..+100 is this times 100). Entries at and beyond `count` are ignored.
    pub thrust: [f64; MAX_THRUSTERS],
}

impl ThrustCommand {
    /// A neutral (all zero) command for `count` thrusters answering sample `imu_seq`
    /// taken at `t_ns`.
    pub fn neutral(seq: u64, imu_seq: u64, t_ns: u64, count: u32) -> Self {
        Self {
            seq,
            imu_seq,
            t_ns,
            count,
            mode: ThrustMode::Neutral.as_u32(),
            thrust: [0.0; MAX_THRUSTERS],
        }
    }

    /// Decoded `mode`.
    pub fn mode(&self) -> Result<ThrustMode, UnknownEnumValue> {
        ThrustMode::try_from(self.mode)
    }

    /// Sets `mode`.
    pub fn set_mode(&mut self, mode: ThrustMode) {
        self.mode = mode.as_u32();
    }

    /// The commands in use (`thrust[..count]`, count clamped to capacity).
    pub fn thrusters(&self) -> &[f64] {
        &self.thrust[..clamp_count(self.count)]
    }

    /// Mutable access to the commands in use.
    pub fn thrusters_mut(&mut self) -> &mut [f64] {
        let n = clamp_count(self.count);
        &mut self.thrust[..n]
    }
}
