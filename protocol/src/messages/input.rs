use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use super::{ReconfigEvent, Setpoint, Text};
use crate::wire::{wire_enum, UnknownEnumValue};

wire_enum! {
    /// What an [`InputMsg`] handed to the daemon's state machine.
    pub enum InputKind {
        /// The daemon started serving: `code` is 1 when it loaded a saved model at start
        /// (replay cannot reproduce that model), 0 otherwise. Always the journal's first entry.
        #[default]
        Start = 0,
        /// An operator request the machine acted on: `code` is the
        /// [`crate::RequestKind`] (estimate, abort, hold, idle, revert), `value` the
        /// estimation power an estimate request carried (0: the configured one).
        Request = 1,
        /// A validated setpoint, in `setpoint`.
        Setpoint = 2,
        /// A validated reconfiguration event, in `reconfig`.
        Reconfig = 3,
        /// The driver's outputs became unusable (`code` 1, `text` why) or usable again (0).
        Outputs = 4,
        /// No IMU sample within the deadline after samples had come: `text` why.
        ImuStale = 5,
        /// No IMU sample yet since the start: `text` why.
        NoImuYet = 6,
        /// A validated DVL velocity, in `dvl`.
        Dvl = 7,
        /// A model loaded from a file (`text` the path) by an operator request: its content
        /// is not in the journal, so replay refuses a recording that has one.
        Load = 8,
        /// The driver's supply voltage as the machine took it: `code` 1 with the volts in
        /// `value`, or `code` 0 when the reading was lost (`value` 0; never NaN, so the
        /// journal's JSON stays numbers).
        Supply = 9,
        /// A solve job's result reached the state machine (`code`: the job's id). Journaled
        /// for every result, so a replay hands each result over between the same two samples
        /// as the daemon did: one that came back after its due sample (a long solve, a
        /// loaded machine) is applied late in both (thrusterd_core::solve; issue 29).
        SolveDelivered = 10,
    }
}

/// One input the daemon handed its state machine besides an IMU sample (daemon -> anyone,
/// service `input`, no history): the daemon's input journal.
///
/// The daemon handles other inputs only between IMU samples, so "after the `imu_count`-th
/// accepted sample" places each one exactly; `seq` orders the inputs that fall between the
/// same two samples. With the recorded IMU stream and the daemon's configuration
/// ([`crate::ConfigMsg`]) it is everything the machine saw, so `thrusterd replay` can run the
/// same machine offline and reach the same models (docs/recording.md).
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[type_name("thrusterd.InputMsg.v1")]
pub struct InputMsg {
    /// Sequence number, +1 per input; the daemon's first (a [`InputKind::Start`]) is 0.
    pub seq: u64,
    /// Accepted IMU samples the machine had been given before this input.
    pub imu_count: u64,
    /// `seq` of the last of them (0 when none).
    pub imu_seq: u64,
    /// `t_ns` of the last of them (0 when none): the vehicle time of the input.
    pub t_ns: u64,
    /// [`InputKind`] as `u32`.
    pub kind: u32,
    /// Kind-specific code (see [`InputKind`]).
    pub code: u32,
    /// 1 when the machine refused the input (a request in the wrong state, a model
    /// rejected), 0 when it took it.
    pub refused: u32,
    /// Written as zero.
    pub reserved: u32,
    /// Kind-specific number (see [`InputKind`]).
    pub value: f64,
    /// The DVL velocity, m/s, body frame, for [`InputKind::Dvl`].
    pub dvl: [f64; 3],
    /// The setpoint, for [`InputKind::Setpoint`].
    pub setpoint: Setpoint,
    /// The reconfiguration event, for [`InputKind::Reconfig`].
    pub reconfig: ReconfigEvent,
    /// Kind-specific text (why, a path).
    pub text: Text,
}

impl InputMsg {
    /// The kind, or the unknown value.
    pub fn kind(&self) -> Result<InputKind, UnknownEnumValue> {
        InputKind::try_from(self.kind)
    }

    /// Sets the kind.
    pub fn set_kind(&mut self, kind: InputKind) {
        self.kind = kind.as_u32();
    }
}
