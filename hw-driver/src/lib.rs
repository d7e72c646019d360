//! `thruster-hw`: the hardware driver process of thrusterd.
//!
//! To the daemon it is indistinguishable from the simulator driver: it publishes
//! [`thruster_protocol::ImuSample`]s on `<ns>/imu` and applies the
//! [`thruster_protocol::ThrustCommand`]s it receives on `<ns>/thrust` to real thrusters.
//!
//! Layers, from pure to IO:
//! - [`core`]: command -> PWM mapping (deadband, direction, trim, clamping), the command
//!   gate (protocol validation, count, freshness) and the watchdog. No clock, no IO: time is
//!   passed in, so every rule is unit-tested exactly.
//! - [`backend`]: the [`backend::Backend`] trait and its implementations: ArduSub over
//!   MAVLink ([`backend::mavlink`]) and Linux sysfs PWM + IIO ([`backend::linux`]). One
//!   conformance suite (`tests/conformance.rs`) runs against every backend.
//! - [`driver`]: the process loop (iceoryx2 ports, wait set, monotonic clock, signals).
//! - [`config`] and [`cli`]: `config/thruster-hw.toml` and the command line.
//!
//! See `docs/hardware.md` for wiring, parameters and measured latencies.

pub mod backend;
pub mod cli;
pub mod clock;
pub mod config;
pub mod core;
pub mod driver;
