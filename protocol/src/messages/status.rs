use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use super::Text;
use crate::wire::{wire_enum, UnknownEnumValue};

wire_enum! {
    /// The daemon's state machine state.
    pub enum DaemonState {
        /// Zero thrust, waiting for a command.
        #[default]
        Idle = 0,
        /// Vehicle at rest; measuring baseline and noise per axis.
        MeasureNoise = 1,
        /// Applying excitation pulse `pulse`.
        Pulse = 2,
        /// Zero thrust until the vehicle is quiet after pulse `pulse`.
        Settle = 3,
        /// Computing the model and checking its quality.
        Solve = 4,
        /// Controlling the vehicle with the model.
        Active = 5,
        /// Zero thrust after a fault (stale IMU, bad input); `text` says why.
        Fault = 6,
        /// Estimating while controlling: the model in force holds the setpoint and a dither
        /// excites the thrusters; `pulse` counts the seconds of excitation so far.
        Identify = 7,
    }
}

wire_enum! {
    /// Whether the daemon scales its commands for the measured supply voltage.
    pub enum SupplyCompensation {
        /// Not configured (`[supply] compensation = "none"`): commands go out as computed.
        #[default]
        Off = 0,
        /// Configured, but no driver reports a voltage: commands go out as computed, as if
        /// the supply were at the reference voltage.
        NoReading = 1,
        /// Commands are referred to the reference voltage through the thruster table.
        Active = 2,
    }
}

/// Daemon progress and health (daemon -> all, service `status`, history 1).
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[type_name("thrusterd.StatusMsg.v3")]
pub struct StatusMsg {
    /// Sequence number, +1 per status message.
    pub seq: u64,
    /// [`DaemonState`] as `u32`.
    pub state: u32,
    /// Pulses completed in the current (or the last) estimation.
    pub pulse: u32,
    /// Pulses planned for this estimation (may grow until the stopping rule is met).
    pub pulses_planned: u32,
    /// Operator requests refused: failed validation (answered `InvalidRequest`), not allowed
    /// in the current state (`Rejected`), or failed (`Failed`, e.g. an unreadable model
    /// file); a saved model file refused at start counts too. Saturates. (This was the
    /// padding field `reserved`, always written as zero: the layout is unchanged, and an
    /// older daemon simply reports 0.)
    pub requests_refused: u32,
    /// Relative error bound (1 sigma) of the model being estimated, or of the last estimate
    /// (dimensionless, >= 0); NaN while not known (before every thruster has been pulsed, or
    /// for a method without a bound).
    pub error_bound: f64,
    /// Current excitation power, normalised command magnitude in [0, 1].
    pub power: f64,
    /// Measured rotation-rate noise, one sigma, rad/s; NaN before it was measured.
    pub sigma_rot: f64,
    /// Measured acceleration noise, one sigma, m/s^2; NaN before it was measured.
    pub sigma_acc: f64,
    /// IMU samples accepted since start.
    pub samples: u64,
    /// IMU samples that never arrived: gaps in the sequence numbers of accepted samples (a
    /// driver's samples lost on the way, e.g. a burst longer than the subscriber's buffer).
    /// With `samples` and the `rejected_*` counters every sample a driver published is
    /// accounted for. (v2 of this message.)
    pub samples_missed: u64,
    /// Messages rejected because a value was NaN or infinite.
    pub rejected_nonfinite: u64,
    /// Messages rejected because a value was outside its physical range (or a vector or
    /// quaternion was not unit length).
    pub rejected_range: u64,
    /// Messages rejected for time or sequence (time backwards, duplicate, jump).
    pub rejected_time: u64,
    /// Messages rejected for a bad thruster count or index.
    pub rejected_count: u64,
    /// Messages rejected for any other reason (unknown enum or flag value, ...).
    pub rejected_other: u64,
    /// `version` of the model in use (0 = none).
    pub model_version: u64,
    /// Measured IMU sample rate, Hz.
    pub imu_rate_hz: f64,
    /// Time of the latest accepted IMU sample, ns, IMU monotonic clock.
    pub vehicle_time_ns: u64,
    /// Short human-readable reason or message (why a fault, why a model was refused).
    pub text: Text,
    /// The supply voltage the daemon last heard from the driver, V; NaN when it has none.
    /// (v3 of this message.)
    pub supply_voltage_v: f64,
    /// [`SupplyCompensation`] as `u32`: whether commands are referred to the reference
    /// voltage. (v3.)
    pub supply_compensation: u32,
    /// Written as zero, ignored.
    pub reserved: u32,
}

impl StatusMsg {
    /// The text of the last status a daemon publishes as it exits (state: the one it left).
    /// Operators show it as stopped rather than as that state.
    pub const STOPPED_TEXT: &'static str = "thrusterd stopped";

    /// True for the last status of a daemon that exited.
    pub fn is_stopped(&self) -> bool {
        self.text() == Self::STOPPED_TEXT
    }

    /// Decoded `state`.
    pub fn state(&self) -> Result<DaemonState, UnknownEnumValue> {
        DaemonState::try_from(self.state)
    }

    /// Sets `state`.
    pub fn set_state(&mut self, state: DaemonState) {
        self.state = state.as_u32();
    }

    /// Sets the human-readable text, truncated at a character boundary to fit.
    pub fn set_text(&mut self, s: &str) {
        self.text.set(s);
    }

    /// The human-readable text.
    pub fn text(&self) -> &str {
        self.text.as_str()
    }

    /// Decoded `supply_compensation`.
    pub fn supply_compensation(&self) -> Result<SupplyCompensation, UnknownEnumValue> {
        SupplyCompensation::try_from(self.supply_compensation)
    }
}
