//! The stop flag set by SIGINT, SIGTERM and SIGHUP (shared with thruster-hw). Loops poll it at
//! least every [`super::wait::MAX_BLOCK`].

pub use thruster_driver_kit::Shutdown;
