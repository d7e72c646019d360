//! Shared by the driver processes (thruster-sim, thruster-hw): reading TOML configuration
//! with errors that name the file, line and key, and the stop flag set by signals. The
//! logging setup (journald under systemd, else stderr), systemd's notify protocol (READY,
//! WATCHDOG) and the quiet exit on a closed stdout pipe ([`pipe`]) are shared by thrusterd and
//! thrusterctl as well.

pub mod load;
pub mod logging;
pub mod pipe;
pub mod shutdown;
pub mod systemd;

pub use load::{locate, parse_toml, read_text, LoadError, Range};
pub use shutdown::Shutdown;
pub use systemd::Systemd;
