//! Shared by the driver processes (thruster-sim, thruster-hw): reading TOML configuration
//! with errors that name the file, line and key, and the stop flag set by signals. The
//! logging setup (journald under systemd, else stderr) and systemd's notify protocol
//! (READY, WATCHDOG) are shared by thrusterd as well.

pub mod load;
pub mod logging;
pub mod shutdown;
pub mod systemd;

pub use load::{parse_toml, read_text, LoadError};
pub use shutdown::Shutdown;
pub use systemd::Systemd;
