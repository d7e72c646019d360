use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// Desired attitude and depth (operator -> daemon, service `setpoint`, history 1).
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[type_name("thrusterd.Setpoint.v1")]
pub struct Setpoint {
    /// Sequence number, +1 per setpoint from this sender.
    pub seq: u64,
    /// Desired attitude as a unit quaternion `[w, x, y, z]`, rotation of the body frame
    /// relative to NED (north, east, down).
    pub attitude: [f64; 4],
    /// Desired depth, m, positive down. Used with [`Setpoint::HOLD_DEPTH`] only.
    pub depth: f64,
    /// Bit set of `Setpoint::*` flags.
    pub flags: u64,
}

impl Setpoint {
    /// Hold `depth`. Without this flag or [`Setpoint::RELEASE_DEPTH`] the daemon keeps the
    /// depth it holds now (none if it holds none): an attitude command never lets go of depth
    /// unless asked to (issue 27: a pitch-only setpoint once let a held vehicle rise 7 m).
    pub const HOLD_DEPTH: u64 = 1 << 0;
    /// Keep the roll the daemon holds now; `attitude`'s roll is ignored.
    pub const KEEP_ROLL: u64 = 1 << 1;
    /// Keep the pitch the daemon holds now; `attitude`'s pitch is ignored.
    pub const KEEP_PITCH: u64 = 1 << 2;
    /// Keep the heading the daemon holds now; `attitude`'s yaw is ignored.
    pub const KEEP_YAW: u64 = 1 << 3;
    /// Release the depth hold: heave is left free. Exclusive with [`Setpoint::HOLD_DEPTH`].
    pub const RELEASE_DEPTH: u64 = 1 << 4;
    /// Every flag this protocol version defines; other bits are rejected (a daemon that
    /// does not know the KEEP_* or RELEASE_DEPTH flags refuses such a setpoint rather than
    /// misreading it).
    pub const KNOWN_FLAGS: u64 = Self::HOLD_DEPTH
        | Self::KEEP_ROLL
        | Self::KEEP_PITCH
        | Self::KEEP_YAW
        | Self::RELEASE_DEPTH;

    /// True when depth is to be held.
    pub fn hold_depth(&self) -> bool {
        self.flags & Self::HOLD_DEPTH != 0
    }

    /// True when the depth hold is to be released (heave free).
    pub fn release_depth(&self) -> bool {
        self.flags & Self::RELEASE_DEPTH != 0
    }

    /// Which of roll, pitch, yaw keep the value the daemon holds now (the operator left
    /// them out).
    pub fn kept_angles(&self) -> [bool; 3] {
        [Self::KEEP_ROLL, Self::KEEP_PITCH, Self::KEEP_YAW].map(|f| self.flags & f != 0)
    }
}

impl Default for Setpoint {
    /// Level attitude (identity quaternion); the depth held now is kept.
    fn default() -> Self {
        Self {
            seq: 0,
            attitude: [1.0, 0.0, 0.0, 0.0],
            depth: 0.0,
            flags: 0,
        }
    }
}
