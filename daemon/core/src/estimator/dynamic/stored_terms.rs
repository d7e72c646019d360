//! A model's dynamic terms from outside (the state directory's model file, an operator's
//! load) checked against the bounds the estimator's own output keeps, before anything uses
//! them: the controller divides by 1 - k, the refinement's windows and the change test fit
//! and predict with the learned lags, the IMU's position and the damping terms.
//!
//! Why they are kept at all: a model loaded without them flew with the configured lag, no
//! thrust shape and no damping until the next estimation. On a vehicle whose lag the daemon
//! was not told, the refinement then dragged a model 0.013 off to 0.45 off within two minutes
//! (amour5_lag200ms, realistic IMU), and on amour5_lag30ms the change test called a moved
//! thruster 6-7 s after the restart (docs/study.md, "A restart kept the lag").
//!
//! Finiteness needs no check here: JSON has no NaN, so a file's numbers are finite, and a
//! model whose terms hold a non-finite value is written without them (`model_file`).

use super::{DynamicTerms, MAX_CURVE_NAMED_REL_ERR, MAX_THRUST_ASYMMETRY, TERMS};
use thruster_protocol::validate::limits::MAX_POSITION_M;

/// The largest spin-up time constant a stored model may carry, s: the configuration's own
/// bound on `estimator.spin_up_s` and `spin_up_range_s`.
pub const MAX_STORED_SPIN_UP_S: f64 = 2.0;

/// What is wrong with stored terms: the key and the allowed range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("dynamics.{key}: {why}")]
pub struct TermsOutOfBounds {
    pub key: &'static str,
    pub why: String,
}

fn out(key: &'static str, why: String) -> TermsOutOfBounds {
    TermsOutOfBounds { key, why }
}

fn within(key: &'static str, v: f64, lo: f64, hi: f64) -> Result<(), TermsOutOfBounds> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(())
    } else {
        Err(out(key, format!("{v} is not in [{lo}, {hi}]")))
    }
}

fn non_negative(key: &'static str, values: &[f64]) -> Result<(), TermsOutOfBounds> {
    match values.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
        None => Ok(()),
        Some(v) => Err(out(key, format!("{v} is not a finite value >= 0"))),
    }
}

fn shape(
    key: &'static str,
    m: &nalgebra::DMatrix<f64>,
    rows: usize,
    cols: usize,
) -> Result<(), TermsOutOfBounds> {
    if m.shape() == (rows, cols) {
        Ok(())
    } else {
        Err(out(
            key,
            format!("{} x {} is not {rows} x {cols}", m.nrows(), m.ncols()),
        ))
    }
}

/// Checks `terms` of a model with `thrusters` columns: every matrix its shape, every value
/// the daemon uses within the range the estimator's own output keeps.
pub fn check(terms: &DynamicTerms, thrusters: usize) -> Result<(), TermsOutOfBounds> {
    shape("coefficients", &terms.coefficients, 6, TERMS)?;
    if let Some(v) = terms.coefficients.iter().find(|v| !v.is_finite()) {
        return Err(out("coefficients", format!("{v} is not finite")));
    }
    shape("std_err", &terms.std_err, 6, TERMS)?;
    non_negative("std_err", terms.std_err.as_slice())?;
    shape("ols_std_err", &terms.ols_std_err, 6, TERMS)?;
    non_negative("ols_std_err", terms.ols_std_err.as_slice())?;
    shape("b_ols_std_err", &terms.b_ols_std_err, 6, thrusters)?;
    non_negative("b_ols_std_err", terms.b_ols_std_err.as_slice())?;
    within(
        "max_tilt_rad",
        terms.max_tilt_rad,
        0.0,
        std::f64::consts::PI,
    )?;
    non_negative("max_heading_change_rad", &[terms.max_heading_change_rad])?;
    within("spin_up_s", terms.spin_up_s, 0.0, MAX_STORED_SPIN_UP_S)?;
    non_negative("spin_up_sd_ln", &[terms.spin_up_sd_ln])?;
    non_negative("spin_up_rel_err", &terms.spin_up_rel_err)?;
    non_negative("spin_up_floor_rel_err", &terms.spin_up_floor_rel_err)?;
    let lags = &terms.spin_up_per_thruster_s;
    if !lags.is_empty() && lags.len() != thrusters {
        return Err(out(
            "spin_up_per_thruster_s",
            format!(
                "{} lags for {thrusters} thrusters (none, or one each)",
                lags.len()
            ),
        ));
    }
    for l in lags {
        within("spin_up_per_thruster_s", *l, 0.0, MAX_STORED_SPIN_UP_S)?;
    }
    if let Some(p) = &terms.imu_position {
        for v in p.position_m.iter() {
            within(
                "imu_position.position_m",
                *v,
                -MAX_POSITION_M,
                MAX_POSITION_M,
            )?;
        }
        non_negative("imu_position.rel_err_share", &[p.rel_err_share])?;
    }
    non_negative("unexplained_rate_radps", &[terms.unexplained_rate_radps])?;
    if let Some(p) = terms.command_exponent {
        // The range `supply.power_law_exponent` takes (`thrust_curve::FITTED_RANGE`).
        let (lo, hi) = super::thrust_curve::FITTED_RANGE;
        within("command_exponent", p, lo, hi)?;
    }
    within(
        "thrust_asymmetry",
        terms.thrust_asymmetry,
        0.0,
        MAX_THRUST_ASYMMETRY,
    )?;
    non_negative("prior_disagreement", &terms.prior_disagreement)?;
    for e in terms.curve_named_rel_err {
        // What the machine writes (`dynamic_terms::MAX_CURVE_NAMED_REL_ERR`): it also opens
        // the swap gate, which a file must not open wider.
        within("curve_named_rel_err", e, 0.0, MAX_CURVE_NAMED_REL_ERR)?;
    }
    Ok(())
}
