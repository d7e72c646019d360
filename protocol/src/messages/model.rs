use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use super::{clamp_count, Dof, Text, DOF_COUNT, MAX_THRUSTERS};
use crate::wire::{wire_enum, UnknownEnumValue};

wire_enum! {
    /// Where the model came from.
    pub enum ModelSource {
        /// Computed from the declared (nominal) geometry.
        #[default]
        Nominal = 0,
        /// Estimated in the water from thruster pulses.
        Estimated = 1,
        /// A model learned earlier for the same configuration, swapped back from cache.
        Cache = 2,
        /// Loaded from a file by the operator.
        Loaded = 3,
    }
}

wire_enum! {
    /// How the model was estimated.
    pub enum ModelMethod {
        /// The paper's regression S * A = T (allocation fitted directly).
        #[default]
        Paper = 0,
        /// Forward model y = B u by least squares, allocation = pseudoinverse of B.
        Forward = 1,
        /// Forward model regressed together with the vehicle's dynamics (damping, restoring,
        /// added mass), allocation = pseudoinverse of B.
        Dynamic = 2,
    }
}

/// The thruster model in use (daemon -> all, service `model`, history 1 so late joiners
/// get the current one).
///
/// DOF order of every 6-row matrix is [`Dof`]: roll, pitch, yaw, surge, sway, heave.
/// Columns at and beyond `count` are ignored and should be zero.
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[type_name("thrusterd.ModelMsg.v2")]
pub struct ModelMsg {
    /// Sequence number, +1 per published model message.
    pub seq: u64,
    /// Model version, +1 each time the model in use changes (hot swap); never reused
    /// while the daemon runs.
    pub version: u64,
    /// Vehicle time at which the model was made (solved, or computed from geometry), ns,
    /// IMU monotonic clock; kept when the model is reverted to, cached or loaded; 0 when
    /// unknown.
    pub t_ns: u64,
    /// Number of thrusters (columns in use), at most [`MAX_THRUSTERS`].
    pub count: u32,
    /// [`ModelSource`] as `u32`.
    pub source: u32,
    /// [`ModelMethod`] as `u32`.
    pub method: u32,
    /// Bit mask of actuated DOFs: bit `Dof as u32` set when the thrusters can move the
    /// vehicle in that DOF. Only the low 6 bits may be set. (A `u32` rather than `u8` so
    /// the layout has no hidden padding.)
    pub actuated: u32,
    /// Effectiveness B: response per unit command of each thruster, rows in DOF order;
    /// rad/s^2 for rotations, m/s^2 for translations.
    pub effectiveness: [[f64; MAX_THRUSTERS]; DOF_COUNT],
    /// Allocation A: thruster command (normalised, [-1, 1] scale) per unit of desired DOF
    /// motion, i.e. per rad/s^2 (rotations) or m/s^2 (translations). Columns of
    /// non-actuated DOFs are zero: they are never commanded.
    pub allocation: [[f64; DOF_COUNT]; MAX_THRUSTERS],
    /// One-sigma standard error of each `effectiveness` entry, same units; NaN where unknown
    /// (nominal models, the paper's method).
    pub std_err: [[f64; MAX_THRUSTERS]; DOF_COUNT],
    /// Relative error bound of the rotational rows (dimensionless, >= 0; NaN if unknown).
    pub rel_err_rot: f64,
    /// Relative error bound of the translational rows (dimensionless, >= 0; NaN if unknown).
    pub rel_err_acc: f64,
    /// Pulses of the estimation that made the model; 0 for a nominal one. (v2)
    pub pulses: u32,
    /// Times the daemon's continuous refinement has updated this model since it was
    /// estimated (0: as solved). A refined model comes with a new `version` like any swap;
    /// this tells it from a new estimation. (This was the padding field `reserved`, always
    /// written as zero: the layout is unchanged, and recordings of an older daemon read 0.)
    #[serde(alias = "reserved")]
    pub refinements: u32,
    /// Where the model came from, in words: "estimated at vehicle time 16.5 s from 16
    /// pulses", "loaded from /var/lib/thrusterd/model.json (...)", "nominal, from the
    /// declared geometry". (v2)
    pub provenance: Text,
}

impl ModelMsg {
    /// Decoded `source`.
    pub fn source(&self) -> Result<ModelSource, UnknownEnumValue> {
        ModelSource::try_from(self.source)
    }

    /// Sets `source`.
    pub fn set_source(&mut self, source: ModelSource) {
        self.source = source.as_u32();
    }

    /// Decoded `method`.
    pub fn method(&self) -> Result<ModelMethod, UnknownEnumValue> {
        ModelMethod::try_from(self.method)
    }

    /// Sets `method`.
    pub fn set_method(&mut self, method: ModelMethod) {
        self.method = method.as_u32();
    }

    /// True when `dof` is actuated.
    pub fn is_actuated(&self, dof: Dof) -> bool {
        self.actuated & dof.mask() != 0
    }

    /// Thruster count clamped to capacity (safe for slicing).
    pub fn thruster_count(&self) -> usize {
        clamp_count(self.count)
    }

    /// Where the model came from, in words.
    pub fn provenance(&self) -> &str {
        self.provenance.as_str()
    }
}
