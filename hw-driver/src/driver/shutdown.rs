//! The stop flag set by SIGINT, SIGTERM and SIGHUP (shared with thruster-sim). The loop looks
//! at it at least every [`super::MAX_BLOCK`].

pub use thruster_driver_kit::Shutdown;
