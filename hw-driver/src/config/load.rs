//! Reading TOML with errors that name the file, the line and the key (shared with
//! thruster-sim). Every table uses `#[serde(deny_unknown_fields)]`, so a typo is an error with a
//! position rather than a silently ignored setting (a misspelt `watchdog_ms` must not quietly
//! leave the default in charge of real thrusters).

pub use thruster_driver_kit::load::{parse_toml, read_text, LoadError};
