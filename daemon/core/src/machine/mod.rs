//! The daemon's state machine: Idle -> MeasureNoise -> Pulse -> Settle -> ... -> Solve ->
//! Active, plus Fault. Pure: IMU samples (with their own timestamps), operator requests,
//! setpoints and reconfiguration events in; a thrust command for every sample, model swaps and
//! status out. Time comes only from sample timestamps, so real time and a faster-than-real-time
//! simulator run the same code.
//!
//! One file per part, split by the state each part owns (imports point one way, down this
//! list):
//! - `types`: what goes in and out (states, inputs, the command, events, status);
//! - `config`: the machine's settings and setup;
//! - `models`: the model slot (the model in force, the previous one, the per-geometry cache);
//! - `estimation`: one estimation run (noise at rest, pulses and pauses, the candidate), its
//!   solves handed out as jobs with a due time (`crate::solve`);
//! - `hold_watch`: whether the model in force holds the vehicle at all (the error beyond a
//!   limit for too long);
//! - `state_machine`: the machine itself (routing, state changes, faults, levelling, control);
//! - `telemetry`: what the machine is doing, one snapshot per sample, for the `telemetry` topic;
//! - `checkpoint`: the whole state as bytes and back (a late recording's replay starts there).

mod checkpoint;
mod config;
mod depth_watch;
mod estimation;
mod hold_watch;
mod models;
mod state_machine;
mod telemetry;
mod types;

pub use crate::solve::{SolveJob, SolveResult, SolverMode, MAX_OUTSTANDING};
pub use checkpoint::{CheckpointError, FORMAT as CHECKPOINT_FORMAT};
pub use config::{MachineConfig, MachineSetup, ReconfigPolicy};
pub use estimation::Excitation;
pub use hold_watch::actuated_error_deg;
pub use state_machine::Machine;
pub use telemetry::{Progress, TelemetrySnapshot};
pub use types::{
    Command, DepthInput, Event, Geometry, ImuInput, Mode, Reconfig, Refused, Request,
    SetpointInput, State, StatusSnapshot, ThrusterChange, NO_IMU_YET,
};
