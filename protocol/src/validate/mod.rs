//! Validation of every message a process receives.
//!
//! Readers call [`Validate::validate`] on each message (and a [`StreamValidator`] for
//! streams with time and sequence) and drop what fails, counting the rejection in
//! [`RejectCounters`], which map one to one onto the `rejected_*` fields of
//! [`crate::StatusMsg`]. [`sanitize_thrust`] is the last line of defence just before
//! commands reach a thruster.

mod messages;
mod reason;
mod sanitize;
mod sequence;

pub use messages::expect_count;
pub use reason::{Field, RejectCategory, RejectCounters, RejectReason};
pub use sanitize::sanitize_thrust;
pub use sequence::{Accepted, SequenceChecker, SequenceConfig, Sequenced, Stamp, StreamValidator};

/// Stream validator for IMU samples (content, time and sequence).
pub type ImuSampleValidator = StreamValidator<crate::ImuSample>;

/// Stream validator for thrust commands, for drivers (content, time and sequence).
pub type ThrustCommandValidator = StreamValidator<crate::ThrustCommand>;

/// Stateless content check of one message: finite values, physical ranges, known enum
/// and flag values, counts within capacity, unit vectors and quaternions of unit length.
pub trait Validate {
    /// `Ok` when the message may be used; otherwise the first problem found.
    fn validate(&self) -> Result<(), RejectReason>;
}

/// Physical and sanity limits applied by validation. Values beyond them are not
/// physically plausible for a small underwater vehicle and indicate a broken sensor,
/// a units mistake or memory corruption.
pub mod limits {
    /// Largest accepted angular rate per axis, rad/s (about 2900 deg/s; MEMS gyros
    /// saturate near 35-70 rad/s).
    pub const MAX_GYRO_RAD_S: f64 = 50.0;
    /// Largest accepted specific force per axis, m/s^2 (about 20 g).
    pub const MAX_ACCEL_M_S2: f64 = 200.0;
    /// Largest accepted magnetic field per axis, uT (Earth's field is 25-65 uT; this
    /// leaves room for nearby motors without accepting garbage).
    pub const MAX_MAG_UT: f64 = 5000.0;
    /// Shallowest accepted depth, m (negative = above the surface; allows for sensor
    /// offset and out-of-water tests).
    pub const MIN_DEPTH_M: f64 = -10.0;
    /// Deepest accepted depth, m (the deepest ocean trench).
    pub const MAX_DEPTH_M: f64 = 11000.0;
    /// Largest normalised thruster command magnitude.
    pub const MAX_THRUST: f64 = 1.0;
    /// Largest accepted thruster distance from the centre of mass per axis, m.
    pub const MAX_POSITION_M: f64 = 10.0;
    /// Accepted deviation of a declared thrust direction's norm from 1 (loose enough for
    /// hand-entered values such as 0.707).
    pub const DIRECTION_NORM_TOLERANCE: f64 = 1e-2;
    /// Accepted deviation of a setpoint quaternion's norm from 1.
    pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;
    /// Largest accepted DVL velocity per axis, m/s (small vehicles do 1-2 m/s).
    pub const MAX_DVL_SPEED: f64 = 10.0;
    /// Largest accepted effectiveness entry (and its standard error), rad/s^2 or m/s^2
    /// per unit command. A small ROV reaches about 1-20.
    pub const MAX_EFFECTIVENESS: f64 = 1e3;
    /// Largest accepted allocation entry, command per rad/s^2 or per m/s^2.
    pub const MAX_ALLOCATION: f64 = 1e6;
    /// Largest accepted thruster spin-up time constant, s (an ESC and propeller spin up in
    /// 0.03-0.3 s).
    pub const MAX_SPIN_UP_S: f64 = 2.0;
    /// Largest plausible supply voltage, V (a 12S pack is ~50 V).
    pub const MAX_SUPPLY_VOLTAGE_V: f64 = 100.0;
    /// Largest plausible supply current magnitude, A (16 T200s at full are ~500 A).
    pub const MAX_SUPPLY_CURRENT_A: f64 = 1000.0;
}
