//! thrusterd's pure core: the estimator, (later) the controller and the state machine.
//! No IPC, no clocks, no files in here: those live in the binaries.
