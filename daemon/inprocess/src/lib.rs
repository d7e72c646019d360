//! The state machine closed around the simulator's physics in one process (no IPC), scored
//! against the simulator's truth: the harness thrusterd-core's asserting tests and the lab's
//! research sweeps (`thrusterctl study sweep NAME`) share, so a sweep measures exactly what a
//! test asserts on. Not a product crate: nothing of a vehicle build depends on it.
//!
//! - [`run`]: the machine and the simulator stepped together (`Run`), re-estimations and their
//!   measurements, the vehicle files.
//! - [`estimation`]: one estimation from rest on a vehicle, its outcome against the truth, and
//!   the vehicles with hidden constants changed (lag, reverse ratio, dead band).
//! - [`holding`]: holding attitude with the refinement and the change test on, through pitch
//!   steps or level, until a mismatch; the 1 kHz hold.
//! - [`lag_probe`]: the thruster lag learned again from one estimation's log with inputs
//!   replaced by the simulator's truth (issue 29's bias at the paper's gyro noise).
//! - [`model_update`]: the refinement's updates followed while a thruster degrades.
//! - [`swell_phase`]: where the swell is when a run begins, varied by seed.

pub mod estimation;
pub mod holding;
pub mod lag_probe;
pub mod model_update;
pub mod run;
pub mod swell_phase;

pub use run::*;
