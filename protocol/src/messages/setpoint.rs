use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// Desired attitude and depth (operator -> daemon, service `setpoint`, history 1).
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[type_name("thrusterd.Setpoint.v1")]
pub struct Setpoint {
    /// Sequence number, +1 per setpoint from this sender.
    pub seq: u64,
    /// Desired attitude as a unit quaternion `[w, x, y, z]`, rotation of the body frame
    /// relative to NED (north, east, down).
    pub attitude: [f64; 4],
    /// Desired depth, m, positive down. Used with [`Setpoint::HOLD_DEPTH`].
    pub depth: f64,
    /// Bit set of `Setpoint::*` flags.
    pub flags: u64,
}

impl Setpoint {
    /// Hold `depth`; otherwise heave is left free.
    pub const HOLD_DEPTH: u64 = 1 << 0;
    /// Every flag this protocol version defines; other bits are rejected.
    pub const KNOWN_FLAGS: u64 = Self::HOLD_DEPTH;

    /// True when depth is to be held.
    pub fn hold_depth(&self) -> bool {
        self.flags & Self::HOLD_DEPTH != 0
    }
}

impl Default for Setpoint {
    /// Level attitude (identity quaternion), surface, no depth hold.
    fn default() -> Self {
        Self {
            seq: 0,
            attitude: [1.0, 0.0, 0.0, 0.0],
            depth: 0.0,
            flags: 0,
        }
    }
}
