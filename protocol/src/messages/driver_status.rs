use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use super::Text;
use crate::wire::{wire_enum, UnknownEnumValue};

wire_enum! {
    /// What a driver's thruster outputs are doing, as the driver itself sees it.
    pub enum OutputState {
        /// The driver cannot tell yet (starting, no first report from the output device).
        #[default]
        Unknown = 0,
        /// Outputs follow the daemon's commands.
        Active = 1,
        /// Outputs held at neutral by the driver (arming, its watchdog expired: no commands).
        Neutral = 2,
        /// The output device refuses to move the thrusters (an autopilot that is disarmed):
        /// commands are accepted by the driver but nothing reaches the water.
        Disarmed = 3,
        /// The driver has no link to the output device (autopilot heartbeat lost, PWM chip
        /// gone): nothing reaches the water.
        LinkDown = 4,
    }
}

impl OutputState {
    /// True when the daemon's commands can move the vehicle (outputs follow them, or are
    /// neutral only because no command came).
    pub const fn can_move_vehicle(self) -> bool {
        matches!(self, OutputState::Active | OutputState::Neutral)
    }
}

/// A driver's own report of its outputs (driver -> daemon and operators, service
/// `driver_status`, history 1). A driver publishes it at start, at least every
/// [`DriverStatusMsg::PERIOD_MS`] ms, and at once when `output_state` or
/// `thruster_count` changes.
///
/// The daemon uses it to see what it cannot see in the IMU alone: a driver configured for
/// another thruster count (it rejects every command), a driver rejecting commands, an
/// autopilot that is disarmed or unreachable.
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[type_name("thrusterd.DriverStatusMsg.v2")]
pub struct DriverStatusMsg {
    /// Sequence number, +1 per message from this driver.
    pub seq: u64,
    /// Time of the report, ns, on the driver's monotonic clock (the IMU's clock).
    pub time_ns: u64,
    /// Thrusters the driver is configured for, at most [`super::MAX_THRUSTERS`]; thrust
    /// commands with another count are rejected by it.
    pub thruster_count: u32,
    /// [`OutputState`] as `u32`.
    pub output_state: u32,
    /// Thrust commands accepted since the driver started.
    pub commands_accepted: u64,
    /// Thrust commands rejected since the driver started (failed validation, wrong count).
    pub commands_rejected: u64,
    /// Times the driver's command watchdog expired and drove the outputs to neutral.
    pub watchdog_expiries: u64,
    /// 1 while the driver's link to its output device is up (always 1 for a simulator),
    /// 0 otherwise.
    pub link_up: u32,
    /// 1 while the output device is armed (always 1 where there is no arming, e.g. a
    /// simulator or direct PWM), 0 otherwise.
    pub armed: u32,
    /// The driver and its backend, e.g. `thruster-sim` or `thruster-hw mavlink`.
    pub driver: Text,
    /// Short human-readable detail: the last rejection reason, why the link is down.
    pub text: Text,
    /// Supply (battery) voltage at the thrusters' ESCs, V, in [0, 100]; NaN when the driver
    /// cannot measure it (the default). (v2 of this message.)
    pub supply_voltage_v: f64,
    /// Current drawn from the supply, A, in [-1000, 1000] (positive: discharging); NaN when
    /// not known (the default). (v2.)
    pub supply_current_a: f64,
}

impl Default for DriverStatusMsg {
    /// Every counter zero, state unknown, supply not known (NaN).
    fn default() -> Self {
        DriverStatusMsg {
            seq: 0,
            time_ns: 0,
            thruster_count: 0,
            output_state: 0,
            commands_accepted: 0,
            commands_rejected: 0,
            watchdog_expiries: 0,
            link_up: 0,
            armed: 0,
            driver: Text::default(),
            text: Text::default(),
            supply_voltage_v: f64::NAN,
            supply_current_a: f64::NAN,
        }
    }
}

impl DriverStatusMsg {
    /// How often a driver publishes at the least, ms.
    pub const PERIOD_MS: u64 = 100;

    /// Decoded `output_state`.
    pub fn output_state(&self) -> Result<OutputState, UnknownEnumValue> {
        OutputState::try_from(self.output_state)
    }

    /// Sets `output_state`.
    pub fn set_output_state(&mut self, state: OutputState) {
        self.output_state = state.as_u32();
    }

    /// The driver's name.
    pub fn driver(&self) -> &str {
        self.driver.as_str()
    }

    /// The detail text.
    pub fn text(&self) -> &str {
        self.text.as_str()
    }

    /// The supply voltage, V, when the driver measures it.
    pub fn supply_voltage(&self) -> Option<f64> {
        self.supply_voltage_v
            .is_finite()
            .then_some(self.supply_voltage_v)
    }

    /// The supply current, A, when the driver measures it.
    pub fn supply_current(&self) -> Option<f64> {
        self.supply_current_a
            .is_finite()
            .then_some(self.supply_current_a)
    }
}
