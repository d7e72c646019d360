//! Adapting the model while controlling: everything that judges, refines or replaces the model
//! in force without stopping control. One room, one paragraph per part:
//!
//! - [`monitor`]: a cheap per-sample check that the vehicle still moves as the model says
//!   (innovation of the rate against the model's prediction); a mismatch ends control with
//!   the model and starts a re-estimation, or is only reported (`MonitorConfig`).
//! - [`refinement`]: windows of data taken while holding (with a small dither) are fitted on
//!   the solver; each window's estimate is fused into the model in force (`fusion`), and the
//!   change test (`refinement::change_test`) decides from the same windows whether one
//!   thruster moved or weakened, naming it.
//! - [`identification`]: after an announced or detected change, the estimation runs under
//!   control (the controller's command plus a dither) instead of with free pulses; its
//!   settings, the dither, and what of the old model is carried over (`carry_over`) to the
//!   new one when only some thrusters changed.
//!
//! - [`calibrate_when`]: when the monitor's and the change test's calibrations against the
//!   water apply (in a sea, as the sea-state gauge reads it, or always).
//!
//! The estimator's closed-loop mode (`estimator::run::closed_loop`) and the machine's run
//! under control (`machine::estimation::closed_loop`) are the two ends this room drives: the
//! estimator fits whatever command was sent, the machine feeds it and swaps the result in.

pub mod calibrate_when;
pub mod identification;
pub mod monitor;
pub mod refinement;
