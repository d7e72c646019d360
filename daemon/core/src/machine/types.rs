//! What goes in and out of the machine: states, inputs (IMU samples, requests, setpoints,
//! reconfigurations), the thrust command, events and the status numbers.

use nalgebra::UnitQuaternion;
use serde::Serialize;
use thruster_protocol::MAX_THRUSTERS;

use crate::model::{geometry_key, Model};

/// Why estimation and control are refused before the first IMU sample: the vehicle cannot be
/// measured, and a run started now would wait at "measuring noise" forever.
pub const NO_IMU_YET: &str =
    "no IMU samples from any driver yet: is thruster-sim or thruster-hw running on this namespace?";

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
#[derive(serde::Deserialize)]
pub enum State {
    Idle,
    MeasureNoise,
    Pulse,
    Settle,
    Solve,
    Active,
    Fault,
    /// Estimating under control: the controller holds the setpoint with the model in force
    /// while a dither excites the thrusters (see `crate::adaptation::identification`).
    Identify,
}

impl State {
    pub fn name(self) -> &'static str {
        match self {
            State::Idle => "idle",
            State::MeasureNoise => "measure_noise",
            State::Pulse => "pulse",
            State::Settle => "settle",
            State::Solve => "solve",
            State::Active => "active",
            State::Fault => "fault",
            State::Identify => "identify",
        }
    }

    pub fn is_estimating(self) -> bool {
        matches!(
            self,
            State::MeasureNoise | State::Pulse | State::Settle | State::Solve | State::Identify
        )
    }
}

/// Declared thruster layout.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Geometry {
    pub positions: Vec<[f64; 3]>,
    pub directions: Vec<[f64; 3]>,
}

impl Geometry {
    pub fn key(&self) -> u64 {
        geometry_key(&self.positions, &self.directions)
    }
}

/// One validated IMU sample: the protocol's one IMU reading (what every driver publishes and
/// the simulator's sensors return), under the name the machine's API has always used.
pub use thruster_protocol::ImuReading as ImuInput;

/// Why the thrusters are doing what they do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Mode {
    Neutral,
    Estimating,
    Controlling,
}

/// The answer to one IMU sample.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Command {
    pub count: usize,
    pub thrust: [f64; MAX_THRUSTERS],
    pub mode: Mode,
}

impl Command {
    /// Every thruster at zero, for `count` thrusters.
    pub fn neutral(count: usize) -> Self {
        Command {
            count,
            thrust: [0.0; MAX_THRUSTERS],
            mode: Mode::Neutral,
        }
    }
}

/// Something the IO layer must publish or persist.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Event {
    /// A new current model (publish it; save it when estimated).
    ModelSwapped(Box<Model>),
    /// The current model was dropped (thruster count changed, no geometry): neutral until a
    /// new one exists.
    ModelDropped(String),
    /// A candidate was refused; the old model stays.
    ModelRejected(String),
    /// While controlling, the thrusters stopped doing what the model says (see `monitor`).
    MismatchDetected(String),
    /// While controlling, the vehicle stayed beyond `machine.lost_hold_deg` of its setpoint
    /// for `machine.lost_hold_s`: the model in force does not hold it (see `hold_watch`).
    HoldLost(String),
    /// The model in force's bound widened in place, B untouched, for what the daemon saw
    /// while holding (the windows' gain at the hold's commands, `gain_gap`); the restated
    /// model comes as a `ModelSwapped` beside it.
    BoundWidened(String),
    StateChanged {
        from: State,
        to: State,
        why: String,
    },
}

/// An operator request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Request {
    Estimate,
    Abort,
    Hold,
    Idle,
    Revert,
    /// Emergency stop: neutral now, and nothing starts the thrusters again until an
    /// estimate or hold request (see `RequestKind::Stop`).
    Stop,
}

/// A request that cannot be carried out now.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct Refused(pub String);

pub use crate::adaptation::identification::carry_over::ThrusterChange;

/// A reconfiguration event, validated.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Reconfig {
    pub count: usize,
    pub geometry: Option<Geometry>,
    /// Which thruster changed and how, when the sender says (the re-estimation then keeps
    /// the rest of the learned model, see `identification::carry_over`).
    pub change: ThrusterChange,
    pub what: String,
}

/// An operator's setpoint: the attitude wanted, which of roll, pitch, yaw keep the value held
/// now instead, and what to do with depth.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SetpointInput {
    pub attitude: UnitQuaternion<f64>,
    pub keep: [bool; 3],
    pub depth: DepthInput,
}

/// The depth part of an operator's setpoint.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum DepthInput {
    /// Keep the depth held now, or stay free if none is held. What a setpoint that does not
    /// mention depth means: an attitude command must never let go of a held depth.
    Keep,
    /// Release the depth hold: heave free.
    Release,
    /// Hold this depth, m, positive down.
    Hold(f64),
}

/// Status numbers for the status message.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct StatusSnapshot {
    pub state: State,
    pub pulse: usize,
    pub pulses_planned: usize,
    pub error_bound: f64,
    pub power: f64,
    pub sigma_rot: f64,
    pub sigma_acc: f64,
    pub samples: u64,
    pub model_version: u64,
    pub imu_rate_hz: f64,
    pub vehicle_time_ns: u64,
    pub thrusters: usize,
    pub text: String,
    /// The supply voltage last reported, V.
    pub supply_voltage_v: Option<f64>,
    /// What is done with the commands for it.
    pub supply: thruster_protocol::SupplyCompensation,
}

/// Last line of defence: nothing non-finite or out of range leaves the machine, and nothing
/// beyond the command's count.
pub(super) fn finish(cmd: &mut Command) {
    for (i, v) in cmd.thrust.iter_mut().enumerate() {
        *v = if i < cmd.count && v.is_finite() {
            v.clamp(-1.0, 1.0)
        } else {
            0.0
        };
    }
}

/// The deadband compensation (which maps [-1, 1] onto itself): a command u != 0 goes out as
/// sign(u) (deadband + (1 - deadband) |u|). Last, after the supply's curve
/// (`Machine::on_imu`): the dead band is the actuator's, before the thrust curve that
/// starts at its edge (thruster-sim's e = (|u| - deadband) / (1 - deadband), thrust ~ e^p).
/// Jumped before the curve was inverted, a learned ^1.5 curve came out 1.25.
pub(super) fn jump_deadband(thrust: &mut [f64], deadband: f64) {
    let db = if deadband.is_finite() {
        deadband.clamp(0.0, 0.5)
    } else {
        0.0
    };
    for v in thrust.iter_mut() {
        let u = if v.is_finite() {
            v.clamp(-1.0, 1.0)
        } else {
            0.0
        };
        // Commands this small are numerical dust: send true neutral, not the deadband edge.
        *v = if u.abs() < 1e-6 {
            0.0
        } else {
            u.signum() * (db + (1.0 - db) * u.abs())
        };
    }
}
