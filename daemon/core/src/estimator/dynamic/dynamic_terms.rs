//! What the dynamic fit reports besides B ([`DynamicTerms`]): every term's coefficient and
//! standard error per DOF row, and what the run learned of the lag, the IMU, the water and the
//! thrust's shape on the way.

use nalgebra::DMatrix;

use super::{imu_position::ImuPosition, lag_agreement, lag_check, regressors, thrust_curve};

/// What the dynamic fit learned besides B: the coefficients of every term, per DOF row.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DynamicTerms {
    /// 6 x TERMS coefficients, rows in DOF order (rotation rows per rad/s^2, translation rows
    /// per m/s^2), columns as [`regressors::TERM_NAMES`].
    pub coefficients: DMatrix<f64>,
    /// Their standard errors, same shape: the larger of the i.i.d. and the segment-clustered
    /// (autocorrelation-robust) one, see [`segmented_ls`].
    pub std_err: DMatrix<f64>,
    /// The i.i.d. least-squares standard errors sigma sqrt((X'X)^-1) of the same coefficients,
    /// kept for comparison: they do not cover the error (docs/study.md).
    pub ols_std_err: DMatrix<f64>,
    /// The same for B (6 x N).
    pub b_ols_std_err: DMatrix<f64>,
    /// Largest tilt during the excitation, rad (navigation estimate).
    pub max_tilt_rad: f64,
    /// Largest heading change during the excitation, rad.
    pub max_heading_change_rad: f64,
    /// The thrusters' spin-up time constant the fit used, s: learned
    /// ([`lag_search`]) or the configured `estimator.spin_up_s`.
    pub spin_up_s: f64,
    /// Whether `spin_up_s` was learned from this run's data.
    pub spin_up_learned: bool,
    /// One standard deviation of ln(`spin_up_s`) when learned (0 when configured).
    pub spin_up_sd_ln: f64,
    /// What that uncertainty adds to the rotation and acceleration rows' relative bounds (in
    /// quadrature, [`lag_search::LagFit::widen`]; 0 when configured): the stop rule projects
    /// this share apart, since a lag's profile sharpens faster than 1/sqrt(pulses).
    #[serde(default)]
    pub spin_up_rel_err: [f64; 2],
    /// Each thruster's own lag, s, where the data said they differ
    /// ([`thruster_lags`]; `spin_up_s` is then their mean). Empty: one lag for all.
    #[serde(default)]
    pub spin_up_per_thruster_s: Vec<f64>,
    /// ln likelihood ratio of a lag per thruster over one for all (0 when not searched).
    #[serde(default)]
    pub thruster_lag_evidence: f64,
    /// Where the rotation rows alone and the acceleration rows alone put the learned lag
    /// ([`lag_agreement`]); None when the lag was configured or a group's profile is flat.
    #[serde(default)]
    pub spin_up_groups: Option<lag_agreement::LagAgreement>,
    /// With a lag per thruster: what their floor (`EstimatorConfig::thruster_lag_floor`)
    /// adds to the rotation and acceleration rows' bounds (in quadrature; inside
    /// `spin_up_rel_err`'s bound but not in it): no more data removes it, so the stop rule
    /// leaves it out of the bound it waits on.
    #[serde(default)]
    pub spin_up_floor_rel_err: [f64; 2],
    /// With the lag configured because the gyro is too noisy to learn it: what the data says
    /// of it ([`lag_check`]); None otherwise. A contradicted lag refuses the model.
    #[serde(default)]
    pub lag_check: Option<lag_check::LagCheck>,
    /// The IMU's position from the centre the acceleration rows are referred to
    /// ([`imu_position`]), learned or configured; None before [`DynamicRun::refer_to_centre`].
    pub imu_position: Option<ImuPosition>,
    /// The rotation rows' noise level beyond the gyro's white noise at rest (RMS over the axes
    /// of sqrt(max(0, sigma^2 - 2 white^2))), rad/s, where sigma is the larger of the fit's
    /// residual and the gyro's level over the rest: rotation neither thrust nor the vehicle's
    /// dynamics explain, such as a swell's torque, during the pulses or the rest before them
    /// (set by the estimation run, which knows the rest's noise; 0 until then). Why the rest
    /// counts: in a swell the fit's terms soak up a slow moment, so its residual alone is
    /// small where B is off (docs/study.md, "What the water check reads").
    pub unexplained_rate_radps: f64,
    /// With the moving-water refit (`EstimatorConfig::moving_water_swell_hz`): how far the
    /// fit without states put the lag apart by its row groups, over its bound
    /// ([`super::lag_agreement::gap_over_bound`]), which the machine's lag-gap check then
    /// reads instead of the kept fit's own; None without the refit. Why: the states can take
    /// the swell's pull on the lag out of the groups' disagreement without taking it out of
    /// the lag (AMOUR-5 at a realistic IMU, the moderate preset at seed 5's swell phase: kept
    /// 0.133 / 0.121 off under 0.053 / 0.056, where without the states the gap refused it),
    /// and where a model error leaves the rotation unexplained (a T200 fitted as a line, in
    /// still water) the states' own groups moved apart (13 sd) on a model the fit without them
    /// let through.
    #[serde(default)]
    pub lag_gap_without_states: Option<f64>,
    /// Per row group (rotation, acceleration): whether B came from the fit by instrumental
    /// variables (`DynamicRun::with_instruments`, chosen where it and least squares disagree)
    /// rather than least squares.
    #[serde(default)]
    pub instrumented: [bool; 2],
    /// Under control: whether commands bent to a power explain the data better than the
    /// linear model ([`thrust_curve`]); None open loop.
    #[serde(default)]
    pub thrust_curve: Option<thrust_curve::ThrustCurveEvidence>,
    /// The forward/reverse asymmetry k = (f - r) / (f + r) B's columns assume: a thruster's
    /// thrust is its column times u (1 + k) forward and u (1 - k) reverse, so B is the mean
    /// of the forward and reverse gains ([`DynamicRun::with_asymmetry`]). 0: thrust taken as
    /// proportional to the command, as B's split fits and older models have it. Whoever
    /// predicts motion from B and the commands shapes the commands with it.
    #[serde(default)]
    pub thrust_asymmetry: f64,
    /// Per row group (rotation, acceleration): how far the fit strayed from the prior it was
    /// given, the mean over the prior's entries of ((fitted - prior) / prior's standard
    /// error)^2 ([`prior::disagreement`]); 0 without a prior. Above 1 the data and the prior
    /// disagree beyond their errors, and the fit's bound is too small by about its square root.
    #[serde(default)]
    pub prior_disagreement: [f64; 2],
    /// Per row group (rotation, acceleration): the relative error the navigation's own errors
    /// leave in B, which the fit's statistical bound does not count
    /// ([`navigation_error`](super::navigation_error)); in the bound and the standard errors
    /// once the run stops, never in what the stop rule waits on. 0 where not drawn.
    #[serde(default)]
    pub navigation_rel_err: [f64; 2],
    /// The steady velocity through the water at the run's start that the navigation missed
    /// and the fit found (NED, m/s; [`start_velocity`](super::start_velocity)): where a long
    /// rest saw the vehicle move, the moving-water refit searches it
    /// (`EstimatorConfig::start_velocity_search_mps`) and keeps it when the log supports it.
    /// None where not searched or not kept.
    #[serde(default)]
    pub start_velocity_ned_mps: Option<[f64; 3]>,
    /// The rate the navigation's velocity ran away from the truth over the run (NED, m/s^2;
    /// [`velocity_drift`](super::velocity_drift)): the stopping open loop's model is made
    /// again with it taken out where the log supports it
    /// (`EstimatorConfig::velocity_drift_search_mps2`). None where not searched or not kept.
    #[serde(default)]
    pub velocity_drift_ned_mps2: Option<[f64; 3]>,
    /// The thrust curve the commands went out through when the model was learned (thrust ~
    /// command^p, learned under control: `supply::Supply::set_learned_exponent`), so B is per
    /// unit of the linearized command; None: the commands as the machine computed them.
    /// The machine puts it in force with the model, from a file too. Set by the machine,
    /// not the fit.
    #[serde(default)]
    pub command_exponent: Option<f64>,
    /// Per row group (rotation, acceleration): how far an identification under control put
    /// this model off at the hold's commands when it named a thrust curve that was not
    /// learned (`machine::state_machine::curve_named`): the model is a line through its
    /// pulses' amplitude; or how far the refinement's windows, pooled, found its gain off at
    /// the hold's commands where nothing named a curve (`machine::state_machine::gain_gap`).
    /// In the bound from then on, the refinement's too; 0 otherwise. Set by the machine, not
    /// the fit.
    #[serde(default)]
    pub curve_named_rel_err: [f64; 2],
}

/// The most `DynamicTerms::curve_named_rel_err` says: a line twice off at the hold's commands.
/// It opens the swap gate as far (`machine::state_machine::swaps::swap_gate`), so it is capped
/// where it is set and checked where it is loaded (`stored_terms`).
pub const MAX_CURVE_NAMED_REL_ERR: f64 = 2.0;

impl DynamicTerms {
    /// Coefficient and standard error of term `name` on DOF row `row`.
    pub fn get(&self, row: usize, name: &str) -> Option<(f64, f64)> {
        let j = regressors::TERM_NAMES.iter().position(|n| *n == name)?;
        Some((self.coefficients[(row, j)], self.std_err[(row, j)]))
    }

    /// The `n` thrusters' lags this fit was made at (one per thruster where it learned them,
    /// else the common lag), s: what a refit of the same log takes to be the same fit.
    pub fn fitted_lags(&self, n: usize) -> Vec<f64> {
        let lags = super::spin_state::lags_for_fit(
            n,
            self.spin_up_s,
            None,
            Some(&self.spin_up_per_thruster_s),
        );
        lags[..n].to_vec()
    }
}

#[cfg(test)]
impl DynamicTerms {
    /// Terms of `n` thrusters with nothing learned (zeros, the configured lag): for the tests
    /// of what reads a field or two of them.
    pub(crate) fn blank(n: usize) -> DynamicTerms {
        let zeros = DMatrix::zeros(6, regressors::TERMS);
        DynamicTerms {
            coefficients: zeros.clone(),
            std_err: zeros.clone(),
            ols_std_err: zeros,
            b_ols_std_err: DMatrix::zeros(6, n),
            max_tilt_rad: 0.0,
            max_heading_change_rad: 0.0,
            spin_up_s: 0.1,
            spin_up_learned: false,
            spin_up_sd_ln: 0.0,
            spin_up_rel_err: [0.0; 2],
            spin_up_per_thruster_s: Vec::new(),
            thruster_lag_evidence: 0.0,
            spin_up_groups: None,
            spin_up_floor_rel_err: [0.0; 2],
            lag_check: None,
            thrust_curve: None,
            command_exponent: None,
            curve_named_rel_err: [0.0; 2],
            thrust_asymmetry: 0.0,
            prior_disagreement: [0.0; 2],
            navigation_rel_err: [0.0; 2],
            start_velocity_ned_mps: None,
            velocity_drift_ned_mps2: None,
            imu_position: None,
            unexplained_rate_radps: 0.0,
            lag_gap_without_states: None,
            instrumented: [false; 2],
        }
    }
}
