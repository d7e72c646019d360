//! The pure core of the driver: no IPC, no clock, no files. Time is passed in as ns of the
//! driver's monotonic clock.
//!
//! - [`pwm`]: normalised command -> pulse width (deadband, direction, trim, clamping).
//! - [`gate`]: protocol validation, count, and "answers a sample we published".
//! - [`watchdog`]: arming hold, freshness and expiry.
//! - [`controller`]: the three together: commands in, one pulse per thruster out.
//! - [`axes`]: sensor axes to the body frame.

pub mod axes;
pub mod controller;
pub mod gate;
pub mod pwm;
pub mod watchdog;
