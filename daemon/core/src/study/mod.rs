//! Simulation studies that exercise the estimator without any vehicle dynamics.

pub mod fig2;
pub mod plot;
pub mod report;
