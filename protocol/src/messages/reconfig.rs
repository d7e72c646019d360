use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use super::MAX_THRUSTERS;
use crate::wire::{wire_enum, UnknownEnumValue};

wire_enum! {
    /// What changed in the thruster configuration.
    pub enum ReconfigKind {
        /// Something changed but the sender cannot say what (re-estimate everything).
        #[default]
        Unknown = 0,
        /// Thruster `thruster` was added; `count` includes it.
        ThrusterAdded = 1,
        /// Thruster `thruster` was removed; thrusters after it shift down by one.
        ThrusterRemoved = 2,
        /// Thruster `thruster` was moved or re-oriented.
        ThrusterMoved = 3,
    }
}

/// A change of the thruster configuration (driver or operator -> daemon, service
/// `reconfig`). It starts re-estimation; when it declares the new geometry the daemon
/// swaps in the nominal model for it at once.
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[type_name("thrusterd.ReconfigEvent.v1")]
pub struct ReconfigEvent {
    /// Sequence number, +1 per event from this sender.
    pub seq: u64,
    /// [`ReconfigKind`] as `u32`.
    pub kind: u32,
    /// Index of the thruster concerned (0-based); ignored for `Unknown`.
    pub thruster: u32,
    /// Thruster count after the change, at most [`MAX_THRUSTERS`].
    pub count: u32,
    /// 1 when `position` and `direction` declare the new geometry of all `count`
    /// thrusters, 0 otherwise (a `u32`, not `bool`, so any bit pattern is valid).
    pub has_geometry: u32,
    /// Thruster positions, m, body frame (x forward, y starboard, z down), measured from
    /// the centre of mass. Valid when `has_geometry == 1`.
    pub position: [[f64; 3]; MAX_THRUSTERS],
    /// Unit vector of the force each thruster produces for a positive command, body
    /// frame, dimensionless. Valid when `has_geometry == 1`.
    pub direction: [[f64; 3]; MAX_THRUSTERS],
}

impl ReconfigEvent {
    /// Decoded `kind`.
    pub fn kind(&self) -> Result<ReconfigKind, UnknownEnumValue> {
        ReconfigKind::try_from(self.kind)
    }

    /// Sets `kind`.
    pub fn set_kind(&mut self, kind: ReconfigKind) {
        self.kind = kind.as_u32();
    }

    /// True when the event declares the new geometry (`has_geometry == 1`).
    pub fn geometry_declared(&self) -> bool {
        self.has_geometry == 1
    }
}
