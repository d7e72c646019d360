//! Message types, validation and iceoryx2 services shared by every thrusterd process.
//!
//! - [`messages`]: `#[repr(C)]` zero-copy payloads in SI units (re-exported at the root).
//! - [`validate`]: what a reader checks before using a message, and rejection counters.
//! - [`services`]: namespaced service names, QoS, typed ports, control request/response
//!   and cleanup of iceoryx2 resources.
//! - [`gate`]: the one command gate every driver runs (which thrust commands may reach the
//!   thrusters), its differences between drivers as [`gate::GateSettings`].
//! - [`reading`]: the one IMU reading in SI units ([`ImuReading`]) every source and the core
//!   share, and its one conversion to and from the wire's [`ImuSample`].
//! - [`wire`]: enums as `u32` fields and fixed-size text, safe for any bit pattern.

#![warn(missing_docs)]

pub mod gate;
pub mod messages;
pub mod reading;
pub mod services;
pub mod validate;
pub mod wire;

pub use messages::*;
pub use reading::ImuReading;
pub use validate::{sanitize_thrust, RejectReason, Validate};
