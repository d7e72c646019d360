//! [`Validate`] for every message type.

use super::limits::*;
use super::{Field, RejectReason, Validate};
use crate::messages::*;
use crate::wire::{FixedText, UnknownEnumValue};

// ---- helpers -------------------------------------------------------------------------

fn finite(field: Field, value: f64) -> Result<(), RejectReason> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(RejectReason::NonFinite { field, value })
    }
}

fn in_range(
    field: Field,
    value: f64,
    min: f64,
    max: f64,
    unit: &'static str,
) -> Result<(), RejectReason> {
    finite(field, value)?;
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(RejectReason::OutOfRange {
            field,
            value,
            min,
            max,
            unit,
        })
    }
}

/// As [`in_range`], but NaN passes: it means "not known yet" in the fields that allow it
/// (status error bound and noise levels, model standard errors, dynamic coefficients).
/// Infinity never does.
fn in_range_or_unknown(
    field: Field,
    value: f64,
    min: f64,
    max: f64,
    unit: &'static str,
) -> Result<(), RejectReason> {
    if value.is_nan() {
        Ok(())
    } else {
        in_range(field, value, min, max, unit)
    }
}

fn all_in_range(
    name: &'static str,
    values: &[f64],
    max_abs: f64,
    unit: &'static str,
) -> Result<(), RejectReason> {
    for (i, &v) in values.iter().enumerate() {
        in_range(Field::at(name, i), v, -max_abs, max_abs, unit)?;
    }
    Ok(())
}

/// Checks rows `[..rows]` x columns `[..cols]` of a matrix: finite and |x| <= max_abs
/// (or 0 <= x <= max_abs when `non_negative`).
fn matrix_in_range<const C: usize>(
    name: &'static str,
    m: &[[f64; C]],
    cols: usize,
    max_abs: f64,
    non_negative: bool,
    unit: &'static str,
) -> Result<(), RejectReason> {
    let min = if non_negative { 0.0 } else { -max_abs };
    for (i, row) in m.iter().enumerate() {
        for (j, &v) in row[..cols].iter().enumerate() {
            in_range(Field::at2(name, i, j), v, min, max_abs, unit)?;
        }
    }
    Ok(())
}

fn unit_norm(field: Field, v: &[f64], tolerance: f64) -> Result<(), RejectReason> {
    let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    if (norm - 1.0).abs() <= tolerance {
        Ok(())
    } else {
        Err(RejectReason::NotUnit {
            field,
            norm,
            tolerance,
        })
    }
}

/// `count <= MAX_THRUSTERS` (and `> 0` unless `allow_zero`); returns it as usize.
fn thruster_count(name: &'static str, count: u32, allow_zero: bool) -> Result<usize, RejectReason> {
    let field = Field::new(name);
    if count as usize > MAX_THRUSTERS {
        return Err(RejectReason::CountTooLarge { field, count });
    }
    if count == 0 && !allow_zero {
        return Err(RejectReason::CountZero { field });
    }
    Ok(count as usize)
}

fn known_enum<T>(
    name: &'static str,
    decoded: Result<T, UnknownEnumValue>,
) -> Result<T, RejectReason> {
    decoded.map_err(|e| RejectReason::UnknownEnum {
        field: Field::new(name),
        value: e.value,
    })
}

fn known_flags(name: &'static str, flags: u64, known: u64) -> Result<(), RejectReason> {
    let bits = flags & !known;
    if bits == 0 {
        Ok(())
    } else {
        Err(RejectReason::UnknownFlags {
            field: Field::new(name),
            bits,
        })
    }
}

fn zero_or_one(name: &'static str, value: u32) -> Result<bool, RejectReason> {
    match value {
        0 => Ok(false),
        1 => Ok(true),
        _ => Err(RejectReason::InvalidBool {
            field: Field::new(name),
            value,
        }),
    }
}

fn utf8_text<const N: usize>(name: &'static str, text: &FixedText<N>) -> Result<(), RejectReason> {
    if text.is_valid_utf8() {
        Ok(())
    } else {
        Err(RejectReason::InvalidText {
            field: Field::new(name),
        })
    }
}

/// Checks that a received thruster count equals the count this reader is configured
/// for (e.g. a driver receiving [`ThrustCommand`]s).
pub fn expect_count(name: &'static str, count: u32, expected: u32) -> Result<(), RejectReason> {
    if count == expected {
        Ok(())
    } else {
        Err(RejectReason::CountMismatch {
            field: Field::new(name),
            count,
            expected,
        })
    }
}

// ---- messages ------------------------------------------------------------------------

impl Validate for ImuSample {
    /// All values finite and in range whether or not their `HAS_*` flag is set (drivers
    /// write zeros for absent sensors), so a validated sample holds no NaN anywhere.
    fn validate(&self) -> Result<(), RejectReason> {
        all_in_range("gyro", &self.gyro, MAX_GYRO_RAD_S, "rad/s")?;
        all_in_range("accel", &self.accel, MAX_ACCEL_M_S2, "m/s^2")?;
        all_in_range("mag", &self.mag, MAX_MAG_UT, "uT")?;
        in_range(
            Field::new("depth"),
            self.depth,
            MIN_DEPTH_M,
            MAX_DEPTH_M,
            "m",
        )?;
        known_flags("flags", self.flags, ImuSample::KNOWN_FLAGS)
    }
}

impl Validate for ThrustCommand {
    /// Count within capacity (0 allowed: no thrusters configured), mode known, commands in
    /// use finite and within [-1, 1]. Entries beyond `count` are not read, so not checked.
    fn validate(&self) -> Result<(), RejectReason> {
        let n = thruster_count("count", self.count, true)?;
        known_enum("mode", self.mode())?;
        all_in_range("thrust", &self.thrust[..n], MAX_THRUST, "")
    }
}

impl Validate for ReconfigEvent {
    /// Kind known, count within capacity, thruster index below the count it refers to,
    /// `has_geometry` 0 or 1, and with geometry: positions finite and within
    /// [`MAX_POSITION_M`], directions unit length.
    fn validate(&self) -> Result<(), RejectReason> {
        let kind = known_enum("kind", self.kind())?;
        let n = thruster_count("count", self.count, true)?;
        let index_limit = match kind {
            ReconfigKind::Unknown => None,
            // The removed thruster is no longer counted: it was at most index `count`.
            ReconfigKind::ThrusterRemoved => Some(self.count + 1),
            ReconfigKind::ThrusterAdded | ReconfigKind::ThrusterMoved => Some(self.count),
        };
        if let Some(limit) = index_limit {
            let limit = limit.min(MAX_THRUSTERS as u32);
            if self.thruster >= limit {
                return Err(RejectReason::IndexOutOfRange {
                    field: Field::new("thruster"),
                    index: self.thruster,
                    count: limit,
                });
            }
        }
        if zero_or_one("has_geometry", self.has_geometry)? {
            matrix_in_range(
                "position",
                &self.position[..n],
                3,
                MAX_POSITION_M,
                false,
                "m",
            )?;
            matrix_in_range(
                "direction",
                &self.direction[..n],
                3,
                1.0 + DIRECTION_NORM_TOLERANCE,
                false,
                "",
            )?;
            for (i, d) in self.direction[..n].iter().enumerate() {
                unit_norm(Field::at("direction", i), d, DIRECTION_NORM_TOLERANCE)?;
            }
        }
        Ok(())
    }
}

impl Validate for ModelMsg {
    /// Count 1..=16, source and method known, only the 6 DOF bits in `actuated`, all
    /// matrix entries in use finite and bounded, standard errors and error bounds
    /// non-negative, and the allocation never commands a non-actuated DOF.
    fn validate(&self) -> Result<(), RejectReason> {
        let n = thruster_count("count", self.count, false)?;
        known_enum("source", self.source())?;
        known_enum("method", self.method())?;
        known_flags(
            "actuated",
            u64::from(self.actuated),
            u64::from(ALL_DOFS_MASK),
        )?;
        matrix_in_range(
            "effectiveness",
            &self.effectiveness,
            n,
            MAX_EFFECTIVENESS,
            false,
            "per unit command",
        )?;
        matrix_in_range(
            "allocation",
            &self.allocation[..n],
            DOF_COUNT,
            MAX_ALLOCATION,
            false,
            "per unit motion",
        )?;
        // NaN = unknown (a nominal model, the paper's method); anything else must be in range.
        for (i, row) in self.std_err.iter().enumerate() {
            for (j, &v) in row[..n].iter().enumerate() {
                in_range_or_unknown(
                    Field::at2("std_err", i, j),
                    v,
                    0.0,
                    MAX_EFFECTIVENESS,
                    "per unit command",
                )?;
            }
        }
        in_range_or_unknown(
            Field::new("rel_err_rot"),
            self.rel_err_rot,
            0.0,
            f64::MAX,
            "",
        )?;
        in_range_or_unknown(
            Field::new("rel_err_acc"),
            self.rel_err_acc,
            0.0,
            f64::MAX,
            "",
        )?;
        utf8_text("provenance", &self.provenance)?;
        for (i, row) in self.allocation[..n].iter().enumerate() {
            for dof in Dof::ALL {
                if !self.is_actuated(*dof) && row[dof.index()] != 0.0 {
                    return Err(RejectReason::Inconsistent {
                        field: Field::at2("allocation", i, dof.index()),
                        detail: "commands a DOF that is not actuated",
                    });
                }
            }
        }
        Ok(())
    }
}

impl Validate for TruthMsg {
    /// Count within capacity, matrices in use finite and bounded.
    fn validate(&self) -> Result<(), RejectReason> {
        let n = thruster_count("count", self.count, true)?;
        matrix_in_range(
            "effectiveness",
            &self.effectiveness,
            n,
            MAX_EFFECTIVENESS,
            false,
            "per unit command",
        )?;
        matrix_in_range(
            "reverse_effectiveness",
            &self.reverse_effectiveness,
            n,
            MAX_EFFECTIVENESS,
            false,
            "per unit command",
        )?;
        in_range(
            Field::new("supply_voltage_v"),
            self.supply_voltage_v,
            0.0,
            MAX_SUPPLY_VOLTAGE_V,
            "V",
        )?;
        zero_or_one("battery", self.battery)?;
        Ok(())
    }
}

impl Validate for StatusMsg {
    /// State known, pulse within plan, floats finite and non-negative, power in [0, 1],
    /// text valid UTF-8.
    fn validate(&self) -> Result<(), RejectReason> {
        known_enum("state", self.state())?;
        in_range_or_unknown(
            Field::new("error_bound"),
            self.error_bound,
            0.0,
            f64::MAX,
            "",
        )?;
        in_range(Field::new("power"), self.power, 0.0, MAX_THRUST, "")?;
        in_range_or_unknown(
            Field::new("sigma_rot"),
            self.sigma_rot,
            0.0,
            MAX_GYRO_RAD_S,
            "rad/s",
        )?;
        in_range_or_unknown(
            Field::new("sigma_acc"),
            self.sigma_acc,
            0.0,
            MAX_ACCEL_M_S2,
            "m/s^2",
        )?;
        in_range(
            Field::new("imu_rate_hz"),
            self.imu_rate_hz,
            0.0,
            f64::MAX,
            "Hz",
        )?;
        in_range_or_unknown(
            Field::new("supply_voltage_v"),
            self.supply_voltage_v,
            0.0,
            MAX_SUPPLY_VOLTAGE_V,
            "V",
        )?;
        known_enum("supply_compensation", self.supply_compensation())?;
        utf8_text("text", &self.text)
    }
}

impl Validate for Setpoint {
    /// Quaternion finite and unit length, depth finite and in range, flags known and not both
    /// HOLD_DEPTH and RELEASE_DEPTH.
    fn validate(&self) -> Result<(), RejectReason> {
        for (i, &q) in self.attitude.iter().enumerate() {
            finite(Field::at("attitude", i), q)?;
        }
        unit_norm(
            Field::new("attitude"),
            &self.attitude,
            QUATERNION_NORM_TOLERANCE,
        )?;
        in_range(
            Field::new("depth"),
            self.depth,
            MIN_DEPTH_M,
            MAX_DEPTH_M,
            "m",
        )?;
        known_flags("flags", self.flags, Setpoint::KNOWN_FLAGS)?;
        if self.hold_depth() && self.release_depth() {
            return Err(RejectReason::Inconsistent {
                field: Field::new("flags"),
                detail: "HOLD_DEPTH and RELEASE_DEPTH together",
            });
        }
        Ok(())
    }
}

impl Validate for ControlRequest {
    /// Kind known, flags zero, value finite (and in [0, 1] for Estimate, where it is a
    /// power), text valid UTF-8.
    fn validate(&self) -> Result<(), RejectReason> {
        let kind = known_enum("kind", self.kind())?;
        known_flags("flags", u64::from(self.flags), 0)?;
        finite(Field::new("value"), self.value)?;
        if kind == RequestKind::Estimate {
            in_range(Field::new("value"), self.value, 0.0, MAX_THRUST, "")?;
        }
        utf8_text("text", &self.text)
    }
}

impl Validate for ControlResponse {
    /// Code known, `ok` 0 or 1 and agreeing with the code, text valid UTF-8.
    fn validate(&self) -> Result<(), RejectReason> {
        let code = known_enum("code", self.code())?;
        let ok = zero_or_one("ok", self.ok)?;
        if ok != (code == ResponseCode::Ok) {
            return Err(RejectReason::Inconsistent {
                field: Field::new("ok"),
                detail: "disagrees with code",
            });
        }
        utf8_text("text", &self.text)
    }
}

impl Validate for crate::VehicleStateMsg {
    /// Every value finite and the attitude a unit quaternion.
    fn validate(&self) -> Result<(), RejectReason> {
        for (name, values) in [
            ("attitude", &self.attitude[..]),
            ("rate", &self.rate[..]),
            ("position_ned", &self.position_ned[..]),
            ("velocity", &self.velocity[..]),
        ] {
            for (i, v) in values.iter().enumerate() {
                if !v.is_finite() {
                    return Err(RejectReason::NonFinite {
                        field: Field::at(name, i),
                        value: *v,
                    });
                }
            }
        }
        let norm = self.attitude.iter().map(|v| v * v).sum::<f64>().sqrt();
        let tolerance = super::limits::QUATERNION_NORM_TOLERANCE;
        if (norm - 1.0).abs() > tolerance {
            return Err(RejectReason::NotUnit {
                field: Field::new("attitude"),
                norm,
                tolerance,
            });
        }
        Ok(())
    }
}

impl Validate for DvlSample {
    /// Velocity finite and within [`MAX_DVL_SPEED`] per axis (no small vehicle goes faster;
    /// beyond it the DVL has lost bottom lock and reports garbage).
    fn validate(&self) -> Result<(), RejectReason> {
        for (a, v) in self.velocity.iter().enumerate() {
            in_range(
                Field::at("velocity", a),
                *v,
                -MAX_DVL_SPEED,
                MAX_DVL_SPEED,
                "m/s",
            )?;
        }
        Ok(())
    }
}

impl Validate for DynamicsMsg {
    /// Coefficients within the physical bound of an effectiveness entry or NaN (unknown),
    /// standard errors non-negative or NaN (unknown), excursions finite and non-negative.
    fn validate(&self) -> Result<(), RejectReason> {
        for (i, row) in self.coefficients.iter().enumerate() {
            for (j, v) in row.to_terms().iter().enumerate() {
                in_range_or_unknown(
                    Field::at2("coefficients", i, j),
                    *v,
                    -MAX_EFFECTIVENESS,
                    MAX_EFFECTIVENESS,
                    "per unit term",
                )?;
            }
        }
        for (i, row) in self.std_err.iter().enumerate() {
            for (j, v) in row.to_terms().iter().enumerate() {
                if !v.is_nan() {
                    in_range(
                        Field::at2("std_err", i, j),
                        *v,
                        0.0,
                        MAX_EFFECTIVENESS,
                        "per unit term",
                    )?;
                }
            }
        }
        in_range(
            Field::new("max_tilt_rad"),
            self.max_tilt_rad,
            0.0,
            std::f64::consts::PI,
            "rad",
        )?;
        in_range(
            Field::new("max_heading_change_rad"),
            self.max_heading_change_rad,
            0.0,
            std::f64::consts::PI,
            "rad",
        )?;
        if !self.spin_up_s.is_nan() {
            in_range(
                Field::new("spin_up_s"),
                self.spin_up_s,
                0.0,
                MAX_SPIN_UP_S,
                "s",
            )?;
        }
        zero_or_one("spin_up_learned", self.spin_up_learned)?;
        zero_or_one("imu_position_contradicted", self.imu_position_contradicted)?;
        // An IMU is on the vehicle: as far from its centre as a thruster may be.
        for (name, v) in [
            ("imu_position_m", &self.imu_position_m),
            ("imu_learned_m", &self.imu_learned_m),
        ] {
            for (i, x) in v.iter().enumerate() {
                if !x.is_nan() {
                    in_range(Field::at(name, i), *x, -MAX_POSITION_M, MAX_POSITION_M, "m")?;
                }
            }
        }
        for (i, x) in self.imu_learned_sd_m.iter().enumerate() {
            if !x.is_nan() {
                in_range(
                    Field::at("imu_learned_sd_m", i),
                    *x,
                    0.0,
                    MAX_POSITION_M,
                    "m",
                )?;
            }
        }
        // ln of a lag: a standard deviation of 10 is a lag unknown to a factor of e^10.
        in_range_or_unknown(
            Field::new("spin_up_sd_ln"),
            self.spin_up_sd_ln,
            0.0,
            10.0,
            "ln s",
        )?;
        in_range_or_unknown(
            Field::new("thruster_lag_evidence"),
            self.thruster_lag_evidence,
            0.0,
            f64::MAX,
            "ln likelihood ratio",
        )?;
        zero_or_one("spin_up_checked", self.spin_up_checked)?;
        for (name, lags) in [
            ("spin_up_per_thruster_s", &self.spin_up_per_thruster_s[..]),
            ("spin_up_consistent_s", &self.spin_up_consistent_s[..]),
        ] {
            for (i, x) in lags.iter().enumerate() {
                in_range_or_unknown(Field::at(name, i), *x, 0.0, MAX_SPIN_UP_S, "s")?;
            }
        }
        Ok(())
    }
}

impl Validate for DriverStatusMsg {
    /// Count within capacity (0 allowed: a driver with no thrusters), output state known,
    /// `link_up` and `armed` 0 or 1, texts valid UTF-8.
    fn validate(&self) -> Result<(), RejectReason> {
        thruster_count("thruster_count", self.thruster_count, true)?;
        known_enum("output_state", self.output_state())?;
        zero_or_one("link_up", self.link_up)?;
        zero_or_one("armed", self.armed)?;
        utf8_text("driver", &self.driver)?;
        utf8_text("text", &self.text)?;
        // NaN is "not measured"; infinity never passes.
        in_range_or_unknown(
            Field::new("supply_voltage_v"),
            self.supply_voltage_v,
            0.0,
            MAX_SUPPLY_VOLTAGE_V,
            "V",
        )?;
        in_range_or_unknown(
            Field::new("supply_current_a"),
            self.supply_current_a,
            -MAX_SUPPLY_CURRENT_A,
            MAX_SUPPLY_CURRENT_A,
            "A",
        )
    }
}

impl Validate for TelemetryMsg {
    /// State, mode and flags known, count within capacity (0 allowed: neutral before a
    /// thruster count is known), and every float finite whatever the flags (unknown values
    /// are written as 0, see the message): quaternions of unit length (the setpoint's only
    /// with `HAS_SETPOINT`, identity being the unset value), angles and rates within their
    /// ranges, commands in use within [-1, 1], power in [0, 1], bound and noise non-negative.
    fn validate(&self) -> Result<(), RejectReason> {
        use std::f64::consts::{FRAC_PI_2, PI};
        // Angles computed in f64 land on +-pi exactly, or a rounding step past it.
        const ANGLE_SLACK: f64 = 1e-9;
        known_enum("state", self.state())?;
        known_enum("mode", self.mode())?;
        known_flags("flags", self.flags, TelemetryMsg::KNOWN_FLAGS)?;
        let n = thruster_count("count", self.count, true)?;
        all_in_range(
            "attitude",
            &self.attitude,
            1.0 + QUATERNION_NORM_TOLERANCE,
            "",
        )?;
        unit_norm(
            Field::new("attitude"),
            &self.attitude,
            QUATERNION_NORM_TOLERANCE,
        )?;
        for (name, e) in [
            ("euler", &self.euler),
            ("setpoint_euler", &self.setpoint_euler),
        ] {
            let limits = [PI, FRAC_PI_2, PI];
            for (i, (&v, lim)) in e.iter().zip(limits).enumerate() {
                let lim = lim + ANGLE_SLACK;
                in_range(Field::at(name, i), v, -lim, lim, "rad")?;
            }
        }
        all_in_range("rate", &self.rate, MAX_GYRO_RAD_S, "rad/s")?;
        in_range(
            Field::new("depth"),
            self.depth,
            MIN_DEPTH_M,
            MAX_DEPTH_M,
            "m",
        )?;
        all_in_range(
            "setpoint_attitude",
            &self.setpoint_attitude,
            1.0 + QUATERNION_NORM_TOLERANCE,
            "",
        )?;
        if self.has(TelemetryMsg::HAS_SETPOINT) {
            unit_norm(
                Field::new("setpoint_attitude"),
                &self.setpoint_attitude,
                QUATERNION_NORM_TOLERANCE,
            )?;
        }
        in_range(
            Field::new("setpoint_depth"),
            self.setpoint_depth,
            MIN_DEPTH_M,
            MAX_DEPTH_M,
            "m",
        )?;
        all_in_range(
            "attitude_error",
            &self.attitude_error,
            PI + ANGLE_SLACK,
            "rad",
        )?;
        in_range(
            Field::new("attitude_error_angle"),
            self.attitude_error_angle,
            0.0,
            PI + ANGLE_SLACK,
            "rad",
        )?;
        let span = MAX_DEPTH_M - MIN_DEPTH_M;
        in_range(
            Field::new("depth_error"),
            self.depth_error,
            -span,
            span,
            "m",
        )?;
        all_in_range("thrust", &self.thrust[..n], MAX_THRUST, "")?;
        in_range(Field::new("power"), self.power, 0.0, MAX_THRUST, "")?;
        in_range(
            Field::new("error_bound"),
            self.error_bound,
            0.0,
            f64::MAX,
            "",
        )?;
        in_range(
            Field::new("sigma_rot"),
            self.sigma_rot,
            0.0,
            MAX_GYRO_RAD_S,
            "rad/s",
        )?;
        in_range(
            Field::new("sigma_acc"),
            self.sigma_acc,
            0.0,
            MAX_ACCEL_M_S2,
            "m/s^2",
        )
    }
}
