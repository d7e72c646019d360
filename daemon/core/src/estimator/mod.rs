//! The thruster-configuration estimator: pure, fed samples and thrust, no IPC, clocks or files.
//!
//! - [`noise`]: at-rest baselines and noise levels.
//! - [`excitation`]: which thrusters fire on each pulse (round robin, pairs, orthogonal).
//! - [`response`]: the time shape of a pulse's response, and gravity compensation.
//! - [`forward`]: the unbiased regression y = B u (normal equations, incremental).
//! - [`dynamic`]: the response regressed with the vehicle's dynamics (drag, restoring, Coriolis).
//! - [`paper`]: Doniec, Detweiler and Rus's S * A = T.
//! - [`analysis`]: rank, actuated DOFs, allocation, thruster diagnosis.
//! - [`power`]: the first pulse's strength from a model in force and the measured noise.
//! - [`run`]: one estimation run tying these together, with power escalation and the stop.

pub mod analysis;
pub mod config;
pub mod dof;
pub mod dynamic;
pub mod excitation;
pub mod forward;
pub mod linalg;
pub mod noise;
pub mod paper;
pub mod power;
pub mod response;
pub mod run;

pub use analysis::{RankReport, ThrusterDiagnosis};
pub use config::{EstimatorConfig, Method};
pub use dof::{Dof, DofMask};
pub use excitation::{Excitation, ExcitationPlan};
pub use noise::{NoiseLevels, NoiseMeter};
pub use response::PulseShape;
pub use run::{Estimate, Estimator, PulseSummary, Settle, StopDecision};
