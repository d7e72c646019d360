//! thrusterd's pure core: the estimator, (later) the controller and the state machine, and the
//! paper's simulation study. No IPC, no clocks, no files in here: those live in the binaries.

pub mod estimator;
pub mod study;
