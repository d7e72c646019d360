//! Message types exchanged over iceoryx2 shared memory.
//!
//! Conventions shared by every message:
//! - `#[repr(C)]`, only `u8`/`u32`/`u64`/`f64` fields and arrays of them, so any bit
//!   pattern is a valid value (see [`crate::wire`]). Enums are `u32` fields decoded with
//!   `TryFrom<u32>`; flags are `u64` bit sets.
//! - SI units, documented on every field. Body frame: x forward, y starboard, z down.
//! - Fixed capacity [`MAX_THRUSTERS`] with an explicit `count`; entries at or beyond
//!   `count` are ignored by readers and should be zero.
//! - Every message carries `seq: u64`, incremented by one per message by its sender.
//! - Fields named `reserved` make padding explicit so the layout is the same in C; they
//!   are written as zero and ignored.
//! - The iceoryx2 type name carries a version (`thrusterd.<Type>.v1`): a process built
//!   with an incompatible layout fails to open the service instead of misreading it.

mod checkpoint;
mod config;
mod control;
mod driver_status;
mod dvl;
mod dynamics;
mod imu;
mod input;
mod model;
mod reconfig;
mod setpoint;
mod status;
mod telemetry;
mod thrust;
mod truth;

pub use checkpoint::{CheckpointMsg, CHECKPOINT_MAX_PARTS, CHECKPOINT_PART_CAPACITY};
pub use config::{ConfigMsg, CONFIG_TEXT_CAPACITY};
pub use control::{ControlRequest, ControlResponse, RequestKind, ResponseCode};
pub use driver_status::{DriverStatusMsg, OutputState};
pub use dvl::DvlSample;
pub use dynamics::{DynamicsMsg, DynamicsRow, DYNAMIC_TERMS, DYNAMIC_TERM_NAMES};
pub use imu::ImuSample;
pub use input::{InputKind, InputMsg};
pub use model::{ModelMethod, ModelMsg, ModelSource};
pub use reconfig::{ReconfigEvent, ReconfigKind};
pub use setpoint::Setpoint;
pub use status::{DaemonState, StatusMsg, SupplyCompensation};
pub use telemetry::TelemetryMsg;
pub use thrust::{ThrustCommand, ThrustMode};
pub use truth::{TruthMsg, VehicleStateMsg};

use crate::wire::wire_enum;

/// Most thrusters any message can describe. Arrays are sized for it; `count` says how
/// many entries are in use.
pub const MAX_THRUSTERS: usize = 16;

/// Number of rigid-body degrees of freedom (rows of an effectiveness matrix).
pub const DOF_COUNT: usize = 6;

/// Capacity in bytes of the human-readable text fields.
pub const TEXT_CAPACITY: usize = 128;

/// Human-readable text field of [`TEXT_CAPACITY`] bytes.
pub type Text = crate::wire::FixedText<TEXT_CAPACITY>;

/// Bit mask with one bit per DOF, all six set.
pub const ALL_DOFS_MASK: u32 = (1 << DOF_COUNT) - 1;

wire_enum! {
    /// A rigid-body degree of freedom, in the row order used by every matrix in the
    /// protocol: rotations first (roll, pitch, yaw about body x, y, z), then translations
    /// (surge, sway, heave along body x, y, z). Bit `d as u32` of an `actuated` mask refers
    /// to DOF `d`.
    pub enum Dof {
        /// Rotation about body x; effectiveness unit rad/s^2 per unit command.
        #[default]
        Roll = 0,
        /// Rotation about body y; rad/s^2 per unit command.
        Pitch = 1,
        /// Rotation about body z; rad/s^2 per unit command.
        Yaw = 2,
        /// Translation along body x; m/s^2 per unit command.
        Surge = 3,
        /// Translation along body y; m/s^2 per unit command.
        Sway = 4,
        /// Translation along body z (down); m/s^2 per unit command.
        Heave = 5,
    }
}

impl Dof {
    /// Row index in effectiveness matrices.
    pub const fn index(self) -> usize {
        self as usize
    }

    /// True for roll, pitch and yaw.
    pub const fn is_rotation(self) -> bool {
        (self as u32) < 3
    }

    /// Bit of this DOF in an `actuated` mask.
    pub const fn mask(self) -> u32 {
        1 << (self as u32)
    }
}

/// Clamps a wire `count` to the array capacity, so slicing with it can never panic even
/// for an unvalidated message.
pub(crate) fn clamp_count(count: u32) -> usize {
    (count as usize).min(MAX_THRUSTERS)
}
