//! thrusterd's pure core: estimator, attitude filter, controller, model and the state machine
//! (the paper's simulation study lives in the lab, `thrusterctl study fig2`). No IPC, no clocks, no files: configuration and model
//! files come in as text (`config::DaemonConfig::from_toml_str`, `model_file::from_json`), and
//! the daemon binary reads and writes them.

pub mod adaptation;
pub mod allocation;
pub mod attitude;
pub mod checkpoint_parts;
pub mod config;
pub mod controller;
pub mod driver_watch;
pub mod estimator;
pub mod machine;
pub mod model;
pub mod model_file;
pub mod navigation;
mod serde_arrays;
pub mod solve;
pub mod supply;
pub mod wire;
