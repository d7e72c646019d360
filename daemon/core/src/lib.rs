//! thrusterd's pure core: estimator, attitude filter, controller, model and the state machine,
//! plus the paper's simulation study. No IPC, no clocks, no files in here except `store`, the
//! one module that reads and writes the state directory.

pub mod attitude;
pub mod config;
pub mod controller;
pub mod driver_watch;
pub mod estimator;
pub mod identification;
pub mod machine;
pub mod model;
pub mod monitor;
pub mod navigation;
pub mod refinement;
pub mod store;
pub mod study;
pub mod wire;
