//! The pure core of the driver: no IPC, no clock, no files. Time is passed in as ns of the
//! driver's monotonic clock.
//!
//! - [`pwm`]: normalised command -> pulse width (deadband, direction, trim, clamping).
//! - the command gate (protocol validation, count, and "answers a sample we published") is
//!   the protocol's [`thruster_protocol::gate`], shared with the simulator.
//! - [`watchdog`]: arming hold, freshness and expiry.
//! - [`controller`]: the three together: commands in, one pulse per thruster out.
//! - [`axes`]: sensor axes to the body frame.

pub mod axes;
pub mod controller;
pub mod pwm;
pub mod watchdog;
