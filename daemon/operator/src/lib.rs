//! thrusterctl's operator verbs: the client that talks to a running thrusterd and the verbs
//! that use it (status, model, estimate, watch with live telemetry, save/load/revert, reconfigure,
//! setpoint).
//!
//! It talks to the daemon only through `thruster_protocol` (control requests, published
//! status and model, reconfiguration events and setpoints). Exit codes are in [`exit`].
//! The lab (demo, experiments) builds on this library, never the other way round.

pub mod attitude;
pub mod chart;
pub mod checks;
pub mod cli;
pub mod client;
pub mod commands;
pub mod console;
pub mod dynamics;
pub mod estimate;
pub mod exit;
pub mod geometry;
pub mod json;
pub mod number;
pub mod publish;
pub mod record;
pub mod render;
pub mod telemetry;
pub mod watch;
