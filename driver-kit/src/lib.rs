//! Shared by the driver processes (thruster-sim, thruster-hw): reading TOML configuration
//! with errors that name the file, line and key, and the stop flag set by signals. The
//! logging setup (journald under systemd, else stderr), systemd's notify protocol (READY,
//! WATCHDOG) and the quiet exit on a closed stdout pipe ([`pipe`]) are shared by thrusterd and
//! thrusterctl as well, and so is raising the control thread to real-time priority ([`realtime`]).
//! Every driver limits its repeated warnings with one [`LogLimiter`]. Behind feature
//! `conformance` (tests only): the driver contract's conformance suite ([`conformance`]), run
//! by the simulator's and every hardware backend's own test file.

#[cfg(feature = "conformance")]
pub mod conformance;
pub mod load;
pub mod log_limit;
#[cfg(feature = "process")]
pub mod logging;
#[cfg(feature = "process")]
pub mod pipe;
#[cfg(feature = "process")]
pub mod realtime;
#[cfg(feature = "process")]
pub mod shutdown;
#[cfg(feature = "process")]
pub mod systemd;
#[cfg(any(feature = "test-process", test))]
pub mod test_process;

pub use load::{locate, parse_toml, read_text, LoadError, Range, SettingsError};
pub use log_limit::LogLimiter;
#[cfg(feature = "process")]
pub use shutdown::Shutdown;
#[cfg(feature = "process")]
pub use systemd::Systemd;
