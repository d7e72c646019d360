//! The in-process harness the tests share: thruster-inprocess's (the lab's sweeps drive the
//! same one).
#![allow(unused_imports)]

pub use thruster_inprocess::*;

/// The open-loop fit's one column on the bare command (`estimator.shaped_thrust` off), for
/// the flights found and measured with it: a tumble's branch, a swell's false alarm and an
/// identification at its limit follow from the first model, and a model fitted to the
/// thrust's shape (0.1-0.2 % off noise-free instead of 1.5 %) flies them differently
/// (docs/study.md, "The shape on by default, test by test"). Each use says what the shape
/// makes of its flight.
#[allow(dead_code)] // each test binary compiles this module; some fly only shipped models
pub fn bare_first_model(s: &mut thrusterd_core::machine::MachineSetup) {
    s.estimator.shaped_thrust = false;
}

/// The acceleration rows' stop target as the flight was found: the rotation rows' (0.06),
/// before `estimator.target_rel_err_acc` became 0.07 (2026-12-05). A first model or an
/// identification that stops sooner flies the scenario after it differently (docs/study.md,
/// "The acceleration rows' target at 0.07"). Each use says what 0.07 makes of its flight.
#[allow(dead_code)] // each test binary compiles this module
pub fn acc_target_as_found(s: &mut thrusterd_core::machine::MachineSetup) {
    s.estimator.target_rel_err_acc = None;
}
