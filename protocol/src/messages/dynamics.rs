use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use super::{DOF_COUNT, MAX_THRUSTERS};

/// Number of dynamic-model terms per DOF row.
pub const DYNAMIC_TERMS: usize = 38;

/// Name of each term, in the order of [`DynamicsRow::to_terms`]: body rates p, q, r and
/// their |x| x; body velocities u, v, w and their |x| x; gravity's direction in the body
/// frame; the 21 products of [u v w p q r] (upper triangle, row by row); a constant; and the
/// mean |command| through the thrusters' spin-up lag.
pub const DYNAMIC_TERM_NAMES: [&str; DYNAMIC_TERMS] = [
    "p",
    "q",
    "r",
    "|p|p",
    "|q|q",
    "|r|r",
    "u",
    "v",
    "w",
    "|u|u",
    "|v|v",
    "|w|w",
    "down_x",
    "down_y",
    "down_z",
    "uu",
    "uv",
    "uw",
    "up",
    "uq",
    "ur",
    "vv",
    "vw",
    "vp",
    "vq",
    "vr",
    "ww",
    "wp",
    "wq",
    "wr",
    "pp",
    "pq",
    "pr",
    "qq",
    "qr",
    "rr",
    "const",
    "mean_abs_command",
];

/// One DOF row of dynamic-model coefficients: how much each term adds to that DOF's
/// acceleration (rad/s^2 for rotation rows, m/s^2 for translation rows, per unit of the term).
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct DynamicsRow {
    /// p, q, r (linear rate damping and the coupling M^-1 brings between axes).
    pub rate: [f64; 3],
    /// |p|p, |q|q, |r|r (quadratic rate damping).
    pub rate_quadratic: [f64; 3],
    /// u, v, w.
    pub velocity: [f64; 3],
    /// |u|u, |v|v, |w|w.
    pub velocity_quadratic: [f64; 3],
    /// Gravity's direction in the body frame (restoring moment, net buoyancy).
    pub down: [f64; 3],
    /// The products of [u v w p q r] (Coriolis, Munk moment, omega x v).
    pub products: [f64; 21],
    /// A constant acceleration.
    pub constant: f64,
    /// Mean |command| through the spin-up lag (the thrusters' forward/reverse asymmetry).
    pub mean_abs_command: f64,
}

impl DynamicsRow {
    /// From the terms in [`DYNAMIC_TERM_NAMES`] order (missing ones are 0).
    pub fn from_terms(t: &[f64]) -> Self {
        let at = |k: usize| t.get(k).copied().unwrap_or(0.0);
        let arr3 = |k: usize| [at(k), at(k + 1), at(k + 2)];
        DynamicsRow {
            rate: arr3(0),
            rate_quadratic: arr3(3),
            velocity: arr3(6),
            velocity_quadratic: arr3(9),
            down: arr3(12),
            products: std::array::from_fn(|j| at(15 + j)),
            constant: at(36),
            mean_abs_command: at(37),
        }
    }

    /// The terms in [`DYNAMIC_TERM_NAMES`] order.
    pub fn to_terms(&self) -> [f64; DYNAMIC_TERMS] {
        let mut out = [0.0; DYNAMIC_TERMS];
        out[0..3].copy_from_slice(&self.rate);
        out[3..6].copy_from_slice(&self.rate_quadratic);
        out[6..9].copy_from_slice(&self.velocity);
        out[9..12].copy_from_slice(&self.velocity_quadratic);
        out[12..15].copy_from_slice(&self.down);
        out[15..36].copy_from_slice(&self.products);
        out[36] = self.constant;
        out[37] = self.mean_abs_command;
        out
    }
}

/// What the dynamic-model estimator learned besides B (daemon -> all, service `dynamics`,
/// history 1): published with every model the dynamic method made, so operators and the lab
/// can see the vehicle's damping, restoring and Coriolis coefficients and how far the vehicle
/// moved while it was being excited.
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[type_name("thrusterd.DynamicsMsg.v4")]
pub struct DynamicsMsg {
    /// Sequence number, +1 per message.
    pub seq: u64,
    /// The [`super::ModelMsg::version`] these coefficients belong to.
    pub model_version: u64,
    /// Vehicle time the model was made, ns (IMU clock).
    pub t_ns: u64,
    /// Coefficients per DOF row (roll, pitch, yaw, surge, sway, heave); NaN where unknown: a
    /// term the excitation did not determine (the daemon writes a value beyond the validation
    /// bound, or one whose standard error is, as unknown: at the paper's noise a barely
    /// excited quadratic sway term came out at 1293 +- 565 on 3 seeds of 10).
    pub coefficients: [DynamicsRow; DOF_COUNT],
    /// Their one-sigma standard errors, same shape (>= 0; NaN where unknown).
    pub std_err: [DynamicsRow; DOF_COUNT],
    /// Largest tilt during the excitation, rad (the daemon's navigation estimate).
    pub max_tilt_rad: f64,
    /// Largest heading change during the excitation, rad.
    pub max_heading_change_rad: f64,
    /// The thrusters' spin-up time constant the model was fitted with, s; NaN when unknown.
    pub spin_up_s: f64,
    /// 1 when `spin_up_s` was learned from the excitation's data, 0 when configured (v2).
    pub spin_up_learned: u32,
    /// 1 when the data contradicted the configured IMU position, so `imu_position_m` is the
    /// learned one (v3).
    pub imu_position_contradicted: u32,
    /// The IMU's position from the centre the translation rows are referred to, body frame
    /// (x forward, y starboard, z down), m; NaN when unknown (v3).
    pub imu_position_m: [f64; 3],
    /// The IMU's position from the centre of mass as the excitation's data found it, m; NaN
    /// when not learned (v3).
    pub imu_learned_m: [f64; 3],
    /// Its one-sigma standard error per axis, m (>= 0; NaN when not learned) (v3).
    pub imu_learned_sd_m: [f64; 3],
    /// One standard deviation of ln(`spin_up_s`) when learned (>= 0; NaN when configured)
    /// (v4).
    pub spin_up_sd_ln: f64,
    /// Each thruster's own spin-up time constant, s, where the data said their lags differ
    /// (`spin_up_s` is then their mean); NaN for every thruster when one lag serves all, and
    /// beyond the model's thruster count (v4).
    pub spin_up_per_thruster_s: [f64; MAX_THRUSTERS],
    /// ln likelihood ratio of a lag per thruster over one for all, the pre-test's evidence
    /// that the thrusters' lags differ (> 0; NaN when not tested, or when a lag per thruster
    /// explained nothing more) (v4).
    pub thruster_lag_evidence: f64,
    /// 1 when the lag was configured because the gyro was too noisy to learn it, and the
    /// data was searched anyway to check it: `spin_up_consistent_s` is then the range of true
    /// lags the data allows (v4).
    pub spin_up_checked: u32,
    /// The true lags the data allows, s, lower and upper end, when `spin_up_checked`; NaN
    /// otherwise, and at an end the data does not bound (v4).
    pub spin_up_consistent_s: [f64; 2],
}

/// Zeros, but the v4 lag fields unknown: a zero there would read as a lag of 0 s learned.
impl Default for DynamicsMsg {
    fn default() -> Self {
        DynamicsMsg {
            seq: 0,
            model_version: 0,
            t_ns: 0,
            coefficients: Default::default(),
            std_err: Default::default(),
            max_tilt_rad: 0.0,
            max_heading_change_rad: 0.0,
            spin_up_s: 0.0,
            spin_up_learned: 0,
            imu_position_contradicted: 0,
            imu_position_m: [0.0; 3],
            imu_learned_m: [0.0; 3],
            imu_learned_sd_m: [0.0; 3],
            spin_up_sd_ln: f64::NAN,
            spin_up_per_thruster_s: [f64::NAN; MAX_THRUSTERS],
            thruster_lag_evidence: f64::NAN,
            spin_up_checked: 0,
            spin_up_consistent_s: [f64::NAN; 2],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_round_trips_through_the_term_order() {
        let terms: Vec<f64> = (0..DYNAMIC_TERMS).map(|k| k as f64).collect();
        let row = DynamicsRow::from_terms(&terms);
        assert_eq!(row.down, [12.0, 13.0, 14.0]);
        assert_eq!(row.products[0], 15.0);
        assert_eq!(row.mean_abs_command, 37.0);
        assert_eq!(row.to_terms().to_vec(), terms);
    }

    #[test]
    fn validation_names_an_absurd_coefficient_and_accepts_unknown_values_and_errors() {
        use crate::validate::Validate;
        let mut m = DynamicsMsg::default();
        m.std_err[2].products[4] = f64::NAN;
        m.coefficients[2].products[4] = f64::NAN;
        assert!(m.validate().is_ok());
        m.coefficients[2].products[4] = f64::INFINITY;
        assert!(m.validate().is_err());
        m.coefficients[2].products[4] = 0.0;
        m.coefficients[1].down[0] = 1e9;
        let e = m.validate().unwrap_err().to_string();
        assert!(e.contains("coefficients[1][12]"), "{e}");
        m.coefficients[1].down[0] = 0.0;
        m.max_tilt_rad = f64::INFINITY;
        assert!(m.validate().is_err());
    }
}
