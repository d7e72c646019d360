//! The dynamic response model: thrust and the vehicle's own dynamics regressed together, so
//! drag, restoring moment and added-mass effects no longer bias B.
//!
//! Per rotational axis, in integrated form (no differentiated gyro):
//!   omega(t) = c_segment + B_row . int(u_lag) + theta_row . int(terms)
//! and per translational axis, directly on the gravity-free accelerometer:
//!   f + g down = c_segment + B_row . u_lag + theta_row . terms
//! with u_lag the commands through the thrusters' first-order spin-up and `terms` the ones in
//! [`regressors`], evaluated on the [`crate::navigation::Navigator`]'s attitude and velocity.
//! Both are linear in the unknowns, so the fit stays incremental (normal equations, one
//! intercept per segment) and gives covariances like the static forward model.

pub mod disturbance_states;
mod dynamic_terms;
pub mod imu_position;
pub mod instruments;
pub mod lag_agreement;
pub mod lag_check;
pub mod lag_search;
pub mod navigation_error;
pub mod prior;
pub mod refer_to_centre;
pub mod refit;
pub mod regressors;
pub mod sample_log;
pub mod segment_basis;
pub mod segmented_ls;
pub mod spin_state;
pub mod start_velocity;
pub mod stored_terms;
pub mod thrust_curve;
pub mod thrust_shape;
pub mod thruster_lags;
mod variance;
pub mod velocity_drift;

pub use dynamic_terms::{DynamicTerms, MAX_CURVE_NAMED_REL_ERR};
pub use thrust_shape::MAX_THRUST_ASYMMETRY;

use nalgebra::{DMatrix, Vector3};

use self::disturbance_states::{DisturbanceStates, MAX_COLUMNS as DISTURBANCE_COLUMNS};
use self::prior::{DynamicPrior, PriorEntry};
use self::regressors::{terms, TERMS};
use self::sample_log::{Navigated, SampleLog};
use self::segmented_ls::{SegmentedLs, SegmentedSolution};
use self::spin_state::{lag_step, MAX_LAG_STEP_S};
use crate::navigation::{DepthAid, NavState, Navigator};

use self::variance::{combination_var, group_sigma};

/// The fit of both groups.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct DynamicSolution {
    /// 6 x N effectiveness.
    pub b: DMatrix<f64>,
    /// 6 x N standard errors (infinite for unexcited thrusters): statistical (the larger of
    /// the i.i.d. and the segment-clustered one) and the model-error floor in quadrature.
    pub std_err: DMatrix<f64>,
    /// 1-sigma relative Frobenius error bound of the rotation and translation rows.
    pub rel_err: [f64; 2],
    /// Noise sigma used per DOF row.
    pub sigma: [f64; 6],
    /// Every thruster column identified in both groups.
    pub excited: bool,
    pub terms: DynamicTerms,
    /// With forward and reverse thrust fitted apart (`DynamicRun::split`): the 6 x 2N gains,
    /// forward in columns 0..N, reverse in N..2N, and their standard errors.
    pub split: Option<(DMatrix<f64>, DMatrix<f64>)>,
    /// With disturbance states (`DynamicRun::with_disturbance`, a research hook): their 6 x D
    /// coefficients, which the IMU's lever arm needs as it needs B and the terms.
    #[serde(skip)]
    pub disturbance: Option<DMatrix<f64>>,
    /// The rotation rows' fit residual, rad/s per axis, where well determined (`sigma` is
    /// the larger of it and the rest's noise).
    #[serde(skip)]
    pub residual_rot: Option<[f64; 3]>,
}

/// One dynamic-model fit in progress: navigation, thrust lag, integrals and both regressions.
/// Allocated once; each sample costs two rank-1 updates of a (N + 38)-wide Gram matrix.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct DynamicRun {
    /// The terms' prior mean (`EstimatorConfig::term_prior_mean`, a research hook; None: 0).
    #[serde(skip)]
    term_prior_mean: Option<DMatrix<f64>>,
    /// The velocity terms' own prior width (`EstimatorConfig::velocity_term_prior_sd`; 0:
    /// none). Not in a checkpoint: the estimator's configuration sets it again on restore.
    #[serde(skip)]
    velocity_term_prior_sd: f64,
    /// Disturbance states (`with_disturbance`, a research hook; default: none).
    #[serde(skip)]
    disturbance: DisturbanceStates,
    /// Their regressors at this sample and the one before (for the integrals).
    #[serde(skip)]
    disturbance_now: [f64; DISTURBANCE_COLUMNS],
    #[serde(skip)]
    disturbance_prev: [f64; DISTURBANCE_COLUMNS],
    n: usize,
    /// Forward and reverse command in separate columns (thrust = k_f u+ + k_r u-): needed when
    /// the commands take many levels around zero (under control), where one symmetric column
    /// and the mean-|command| term cannot take each thruster's asymmetry.
    split: bool,
    /// Thrust columns: n, or 2n when split.
    cols: usize,
    /// Split, whether B's bound keeps `model_error_floor` (the open-loop estimation's split,
    /// `EstimatorConfig::split_thrust`: its residue is not only the asymmetry); the
    /// closed-loop identification's split drops it.
    #[serde(default)]
    floor_when_split: bool,
    /// The thrusters' forward/reverse asymmetry k = (f - r) / (f + r) the one thrust column
    /// assumes (`with_asymmetry`; 0: thrust proportional to the command both ways). The
    /// column's regressor is then the command's thrust shape, u (1 + k) forward and u (1 - k)
    /// reverse, so its gain is the mean of the forward and reverse gains. Ignored when split.
    #[serde(default)]
    asymmetry: f64,
    /// Each thruster's spin-up time constant, s (the split columns i and n + i share one).
    lags: Vec<f64>,
    /// Whether `lags` were learned ([`lag_search`]) rather than configured.
    lags_learned: bool,
    segment_s: f64,
    nav: Navigator,
    lag: Vec<f64>,
    lag_prev: Vec<f64>,
    lag_abs: f64,
    /// Each thruster's |command| through its own lag, when the lags differ (`lag_abs` is then
    /// their mean); empty with one lag for all, where one filter of the mean is the same and
    /// cheaper. Sized by `set_lags`.
    #[serde(default)]
    abs_each: Vec<f64>,
    #[serde(with = "crate::serde_arrays::array")]
    terms: [f64; TERMS],
    #[serde(with = "crate::serde_arrays::array")]
    terms_prev: [f64; TERMS],
    integral: Vec<f64>,
    /// Each term's slope over the open segment's previous step and that step's length (None
    /// at a segment's start): for the integrals' curvature correction.
    #[serde(with = "crate::serde_arrays::option_array_f64")]
    slope_prev: Option<([f64; TERMS], f64)>,
    direct: Vec<f64>,
    last_t_s: Option<f64>,
    /// The time the lags were started spun up at (`spin_state`; None: from rest): the first
    /// sample runs them on from there.
    #[serde(default)]
    spun_up_at_s: Option<f64>,
    /// The time the thrusters left rest, the first command applied (open loop: the first
    /// pulse's start; None: the first sample's time): the first sample runs the lags on from
    /// there, and a refit from the log does the same.
    #[serde(default)]
    at_rest_until_s: Option<f64>,
    segment_start_s: f64,
    rot: SegmentedLs,
    acc: SegmentedLs,
    /// The navigated samples, kept when the lag is to be learned (`with_log`).
    log: Option<SampleLog>,
    /// The log's index of the command the last sample was taken under.
    last_command: u32,
    /// Instruments for the thrust columns (`with_instruments`, under control).
    #[serde(default)]
    iv: Option<ThrustInstruments>,
    /// With instruments, the rotation rows fitted by plain least squares too (the
    /// instrumented ones have a ramp per segment, so their sums differ; the acceleration rows'
    /// least-squares sums are the instrumented fit's own): `solve` takes the instrumented fit
    /// only where the two disagree.
    #[serde(default)]
    rot_least_squares: Option<Box<SegmentedLs>>,
    /// The navigation's state at the last sample taken and that sample's time: the
    /// [`thrust_curve`] probes fit on it instead of navigating again.
    #[serde(default)]
    last_nav: Option<(f64, NavState)>,
}

/// The thrust columns' instruments: per sample a value per thruster independent of the water
/// (the dither's signs), through the same lag and integral as the command
/// ([`instruments`]). Split (forward and reverse apart), one sign per thruster cannot tell
/// the two apart (the centred forward and reverse parts of a binary dither are the same
/// series): the forward column gets the dither, the reverse column the forward minus reverse
/// regressor itself (|command|: the asymmetry), so the pair spans (dither, |command|) and the
/// symmetric gain, their mean, is the dither's.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct ThrustInstruments {
    lag: Vec<f64>,
    lag_prev: Vec<f64>,
    integral: Vec<f64>,
    /// This sample's instruments for the rotation rows (integrated) and the acceleration
    /// rows, one per thrust column.
    rot: Vec<f64>,
    acc: Vec<f64>,
}

impl DynamicRun {
    /// A fit for `n` thrusters with spin-up time constant `lag_s`, segments of `segment_s`,
    /// starting from a rest whose mean specific force was `accel_rest`, navigating with `aid`.
    pub fn new(
        n: usize,
        lag_s: f64,
        segment_s: f64,
        accel_rest: &Vector3<f64>,
        aid: DepthAid,
    ) -> Self {
        Self::with_columns(n, false, lag_s, segment_s, accel_rest, aid)
    }

    /// The same with forward and reverse thrust fitted apart (see `split`).
    pub fn split(
        n: usize,
        lag_s: f64,
        segment_s: f64,
        accel_rest: &Vector3<f64>,
        aid: DepthAid,
    ) -> Self {
        Self::with_columns(n, true, lag_s, segment_s, accel_rest, aid)
    }

    fn with_columns(
        n: usize,
        split: bool,
        lag_s: f64,
        segment_s: f64,
        accel_rest: &Vector3<f64>,
        aid: DepthAid,
    ) -> Self {
        let cols = if split { 2 * n } else { n };
        let k = cols + TERMS;
        DynamicRun {
            n,
            split,
            cols,
            floor_when_split: false,
            asymmetry: 0.0,
            lags: vec![lag_s.max(0.0); n],
            lags_learned: false,
            segment_s: segment_s.max(1e-3),
            nav: Navigator::at_rest(accel_rest, 0.0, None, aid),
            lag: vec![0.0; cols],
            lag_prev: vec![0.0; cols],
            lag_abs: 0.0,
            abs_each: Vec::new(),
            terms: [0.0; TERMS],
            terms_prev: [0.0; TERMS],
            integral: vec![0.0; k],
            slope_prev: None,
            direct: vec![0.0; k],
            last_t_s: None,
            spun_up_at_s: None,
            at_rest_until_s: None,
            segment_start_s: 0.0,
            rot: SegmentedLs::new(k),
            acc: SegmentedLs::new(k),
            log: None,
            last_command: u32::MAX,
            iv: None,
            rot_least_squares: None,
            last_nav: None,
            term_prior_mean: None,
            velocity_term_prior_sd: 0.0,
            disturbance: DisturbanceStates::default(),
            disturbance_now: [0.0; DISTURBANCE_COLUMNS],
            disturbance_prev: [0.0; DISTURBANCE_COLUMNS],
        }
    }

    /// The terms' prior centred at `mean` (6 x TERMS) instead of 0, where `term_prior_sd`
    /// sets one (`EstimatorConfig::term_prior_mean`, a research hook).
    pub fn with_term_prior_mean(mut self, mean: Option<DMatrix<f64>>) -> Self {
        self.term_prior_mean = mean.filter(|m| m.shape() == (6, TERMS));
        self
    }

    /// The velocity terms' own prior width (`EstimatorConfig::velocity_term_prior_sd`; 0:
    /// none).
    pub fn with_velocity_term_prior_sd(mut self, sd: f64) -> Self {
        self.velocity_term_prior_sd = sd;
        self
    }

    /// Disturbance states ([`disturbance_states`]) as more columns after the terms, each row
    /// with its own coefficients. `EstimatorConfig::disturbance`, a research hook: not kept
    /// across a checkpoint. Call before `with_instruments` and the first sample.
    pub fn with_disturbance(mut self, states: DisturbanceStates) -> Self {
        if !states.any() || self.disturbance.any() {
            return self;
        }
        self.disturbance = states;
        let k = self.cols + TERMS + states.columns();
        self.rot = SegmentedLs::new(k);
        self.acc = SegmentedLs::new(k);
        self.integral = vec![0.0; k];
        self.direct = vec![0.0; k];
        self
    }

    /// Fit the thrust columns by instrumental variables: every sample then comes with an
    /// instrument per thruster ([`Self::push_instrumented`]). Under control, the dither's
    /// signs: the controller's answer to the water is then not taken for thrust. The rotation
    /// rows' segments also get a ramp each: they regress the integrated rate, so a torque the
    /// model does not have (a swell's) is a ramp in a segment, and the terms, their own
    /// instruments, would take it (moderate water, AMOUR-5, realistic IMU, seeds 1-10: error
    /// / bound 1.22 without the ramp, 1.00 with; noise-free 1.94 and 1.33). Call before the
    /// first sample.
    pub fn with_instruments(mut self) -> Self {
        let c = self.cols;
        // Its own cluster slots (a clone would share them, and the first write to each would
        // copy it on the control thread).
        self.rot_least_squares = Some(Box::new(SegmentedLs::new(self.rot.width())));
        self.rot = self.rot.with_instruments(c).with_ramp();
        self.acc = self.acc.with_instruments(c);
        let n = self.n;
        self.iv = Some(ThrustInstruments {
            lag: vec![0.0; n],
            lag_prev: vec![0.0; n],
            integral: vec![0.0; n],
            rot: vec![0.0; c],
            acc: vec![0.0; c],
        });
        self
    }

    /// Whether the thrust columns are fitted by instrumental variables.
    pub fn instrumented(&self) -> bool {
        self.iv.is_some()
    }

    /// Split, B's bound keeps the model-error floor (see `floor_when_split`).
    pub fn keep_floor(mut self) -> Self {
        self.floor_when_split = true;
        self
    }

    /// Keep every navigated sample (room for `max_commands` distinct commands, one per
    /// pulse), so the fit can be made again with other lags ([`Self::refit`]). Allocates the
    /// whole log now.
    pub fn with_log(mut self, max_commands: usize) -> Self {
        self.log = Some(SampleLog::new(self.n, max_commands));
        self
    }

    /// The samples kept, if logging.
    pub fn log(&self) -> Option<&SampleLog> {
        self.log.as_ref()
    }

    /// Report the lags in use as learned (they came from an earlier run that learned them).
    pub fn mark_lag_learned(&mut self) {
        self.lags_learned = true;
    }

    /// Whether the lags in use were learned.
    pub fn lags_learned(&self) -> bool {
        self.lags_learned
    }

    /// Each thruster's spin-up time constant in use, s.
    pub fn lags(&self) -> &[f64] {
        &self.lags
    }

    pub fn thrusters(&self) -> usize {
        self.n
    }

    /// Rows fitted.
    pub fn samples(&self) -> u64 {
        self.rot.rows()
    }

    pub fn navigator(&self) -> &Navigator {
        &self.nav
    }

    /// The navigation's state at the last sample taken, with that sample's time.
    pub fn last_nav(&self) -> Option<&(f64, NavState)> {
        self.last_nav.as_ref()
    }

    /// The vertical velocity the rest ended with (NED, m/s): the navigation starts from it.
    pub fn start_sinking_at(&mut self, velocity_down: f64) {
        self.nav.start_sinking_at(velocity_down);
    }

    /// A measured body velocity (a DVL, m/s) for the navigation.
    pub fn velocity_fix(&mut self, measured: &Vector3<f64>) {
        self.nav.velocity_fix(measured);
    }

    /// One sample at `t_s`: bias-free gyro (rad/s), specific force (m/s^2), depth (m), and the
    /// command `u` that was applied during the interval this sample ends (None: neutral). A
    /// sample with a non-finite value is dropped whole (the estimate is untouched).
    pub fn push(
        &mut self,
        t_s: f64,
        gyro: &Vector3<f64>,
        specific_force: &Vector3<f64>,
        depth: Option<f64>,
        u: Option<&[f64]>,
    ) {
        self.push_instrumented(t_s, gyro, specific_force, depth, u, None);
    }

    /// [`Self::push`] with the thrust columns' instruments `z` (one per thruster, taken over
    /// the same interval as `u`; None: zero). A sample whose `z` is not finite or of the wrong
    /// length is dropped whole, as one with a bad `u`.
    pub fn push_instrumented(
        &mut self,
        t_s: f64,
        gyro: &Vector3<f64>,
        specific_force: &Vector3<f64>,
        depth: Option<f64>,
        u: Option<&[f64]>,
        z: Option<&[f64]>,
    ) {
        if z.is_some_and(|z| z.len() != self.n || !z.iter().all(|v| v.is_finite())) {
            return;
        }
        let finite = t_s.is_finite()
            && gyro
                .iter()
                .chain(specific_force.iter())
                .all(|v| v.is_finite())
            && u.is_none_or(|u| u.len() == self.n && u.iter().all(|v| v.is_finite()));
        if !finite || self.last_t_s.is_some_and(|t0| t_s <= t0) {
            return;
        }
        let nav = self.nav.update(t_s, gyro, specific_force, depth);
        self.last_nav = Some((t_s, nav));
        if let Some(log) = self.log.as_mut() {
            let command = match u {
                None => u32::MAX,
                Some(u) if log.command(self.last_command) == Some(u) => self.last_command,
                Some(u) => log.add_command(u),
            };
            self.last_command = command;
            log.push(Navigated {
                t_s,
                gyro: *gyro,
                velocity: nav.velocity,
                rate: nav.rate,
                down: nav.down,
                motion: nav.motion,
                command,
                attitude: nav.attitude,
            });
        }
        self.fit(t_s, gyro, &nav, u, z);
    }

    /// The fit's part of a sample: thrust lag, terms, integrals, both regressions. `nav` is
    /// the navigation's state at `t_s` (only velocity, rate, down and motion are read).
    fn fit(
        &mut self,
        t_s: f64,
        gyro: &Vector3<f64>,
        nav: &NavState,
        u: Option<&[f64]>,
        z: Option<&[f64]>,
    ) {
        let dt = self
            .last_t_s
            .map(|t0| (t_s - t0).min(MAX_LAG_STEP_S))
            .unwrap_or(0.0);
        // The lags run from the last sample, or from where they were started spun up.
        let lag_dt = match (self.last_t_s, self.spun_up_at_s.or(self.at_rest_until_s)) {
            (None, Some(t0)) => (t_s - t0).clamp(0.0, MAX_LAG_STEP_S),
            _ => dt,
        };
        self.lag_prev.copy_from_slice(&self.lag);
        if let Some(iv) = self.iv.as_mut() {
            iv.lag_prev.copy_from_slice(&iv.lag);
        }
        let mut abs_target = 0.0;
        let mut a_mean = 0.0;
        let n = self.n;
        let mixed = !self.abs_each.is_empty();
        for i in 0..n {
            let lag_s = self.lags[i];
            let a = lag_step(lag_dt, lag_s);
            a_mean += a / n.max(1) as f64;
            let v = u.map_or(0.0, |u| u[i]);
            abs_target += v.abs();
            if mixed {
                self.abs_each[i] += a * (v.abs() - self.abs_each[i]);
            }
            if self.split {
                self.lag[i] += a * (v.max(0.0) - self.lag[i]);
                self.lag[n + i] += a * (v.min(0.0) - self.lag[n + i]);
            } else {
                let shaped = DynamicTerms::thrust_shape(self.asymmetry, v);
                self.lag[i] += a * (shaped - self.lag[i]);
            }
            if let Some(iv) = self.iv.as_mut() {
                let w = z.map_or(0.0, |z| z[i]);
                iv.lag[i] += a * (w - iv.lag[i]);
            }
        }
        // Split, the mean |command| is a sum of the thrust columns: left out (zero).
        if !self.split {
            if mixed {
                // Each thruster's own lag: one filter at the mean rate left eight_vectored with
                // thrusters of two makes 4-5 % off (docs/study.md, "Thrusters of two makes").
                self.lag_abs = self.abs_each.iter().sum::<f64>() / n.max(1) as f64;
            } else {
                // One lag for all: one filter of the mean is the same.
                self.lag_abs += a_mean * (abs_target / n.max(1) as f64 - self.lag_abs);
            }
        }
        self.terms_prev = self.terms;
        terms(
            &nav.velocity,
            &nav.rate,
            &nav.down,
            self.lag_abs,
            &mut self.terms,
        );
        if self.disturbance.any() {
            self.disturbance_prev = self.disturbance_now;
            self.disturbance
                .fill(t_s, &nav.attitude, &mut self.disturbance_now);
        }
        let first = self.last_t_s.is_none();
        self.last_t_s = Some(t_s);
        if first || t_s - self.segment_start_s >= self.segment_s {
            // A new segment: its own intercept, integrals from zero.
            self.rot.close_segment();
            self.acc.close_segment();
            if let Some(ls) = self.rot_least_squares.as_mut() {
                ls.close_segment();
            }
            self.segment_start_s = t_s;
            self.integral.fill(0.0);
            if let Some(iv) = self.iv.as_mut() {
                iv.integral.fill(0.0);
            }
            self.slope_prev = None;
        } else {
            let c = self.cols;
            for i in 0..c {
                self.integral[i] += 0.5 * (self.lag_prev[i] + self.lag[i]) * dt;
            }
            if let Some(iv) = self.iv.as_mut() {
                for i in 0..n {
                    iv.integral[i] += 0.5 * (iv.lag_prev[i] + iv.lag[i]) * dt;
                }
            }
            // Trapezoids, each corrected by its own curvature: -h^3 f'' / 12, with f'' from
            // the slopes of this step and the one before. Why: the rates, velocities and their
            // products bend within a 5 ms step, and the plain trapezoid's O(h^2) error, tiny in
            // itself, is amplified by the fit's near-collinear terms (smallest eigenvalue of
            // the scaled Gram matrix ~1e-7): noise-free at 200 Hz it moved AMOUR-5's rate
            // damping by 9-26 % (exact at 1 kHz); corrected, 1-2 % (docs/study.md). The
            // thrust columns are left alone: a command step puts a kink in them, and their
            // exponential is integrated to O(h^3) already.
            let slope_prev = self.slope_prev.take();
            let mut slopes = [0.0; TERMS];
            for j in 0..TERMS {
                let (f0, f1) = (self.terms_prev[j], self.terms[j]);
                let mut area = 0.5 * (f0 + f1) * dt;
                if dt > 0.0 {
                    slopes[j] = (f1 - f0) / dt;
                    if let Some((prev, dt_prev)) = &slope_prev {
                        let curvature = (slopes[j] - prev[j]) / (0.5 * (dt + dt_prev));
                        area -= dt * dt * dt / 12.0 * curvature;
                    }
                }
                self.integral[c + j] += area;
            }
            self.slope_prev = (dt > 0.0).then_some((slopes, dt));
            // Trapezoids: the swell and the attitude are slow against a 1-5 ms step.
            let at = c + TERMS;
            for e in 0..self.disturbance.columns() {
                self.integral[at + e] +=
                    0.5 * (self.disturbance_prev[e] + self.disturbance_now[e]) * dt;
            }
        }
        self.direct[..self.cols].copy_from_slice(&self.lag);
        self.direct[self.cols..self.cols + TERMS].copy_from_slice(&self.terms);
        let d = self.disturbance.columns();
        self.direct[self.cols + TERMS..].copy_from_slice(&self.disturbance_now[..d]);

        // Bias removed: what of it the filter found (the rest is the segment's intercept).
        match self.iv.as_mut() {
            Some(iv) => {
                iv.rot[..n].copy_from_slice(&iv.integral);
                iv.acc[..n].copy_from_slice(&iv.lag);
                if self.split {
                    for i in 0..n {
                        iv.rot[n + i] = self.integral[i] - self.integral[n + i];
                        iv.acc[n + i] = self.lag[i] - self.lag[n + i];
                    }
                }
                self.rot.add_instrumented(&self.integral, &iv.rot, gyro);
                self.acc
                    .add_instrumented(&self.direct, &iv.acc, &nav.motion);
                if let Some(ls) = self.rot_least_squares.as_mut() {
                    ls.add(&self.integral, gyro);
                }
            }
            None => {
                self.rot.add(&self.integral, gyro);
                self.acc.add(&self.direct, &nav.motion);
            }
        }
    }

    /// The fit so far. `rest_sigma` is the at-rest noise per DOF row (gyro, accelerometer);
    /// `model_error_floor` the relative error of B that no data removes (added to B's standard
    /// errors and bound; `EstimatorConfig::model_error_floor`); `term_prior_sd` the width of a
    /// zero-mean prior on the damping, restoring and Coriolis terms (0: none;
    /// `EstimatorConfig::term_prior_sd`). With a `prior` (coefficients carried over from the
    /// model in force), the data is weighed against it.
    // Index loops: DOF row 3g + a, thruster i and term j address several matrices at once.
    #[allow(clippy::needless_range_loop)]
    pub fn solve(
        &self,
        rest_sigma: &[f64; 6],
        model_error_floor: f64,
        term_prior_sd: f64,
        prior: Option<&DynamicPrior>,
    ) -> DynamicSolution {
        let fit = |rot: &SegmentedLs, acc: &SegmentedLs| {
            self.solve_on(
                rot,
                acc,
                rest_sigma,
                model_error_floor,
                term_prior_sd,
                prior,
            )
        };
        let instrumented = fit(&self.rot, &self.acc);
        match &self.rot_least_squares {
            Some(rot) => {
                let least_squares = fit(rot, &self.acc.without_instruments());
                instruments::choose(instrumented, least_squares, self.n)
            }
            None => instrumented,
        }
    }

    /// [`Self::solve`] on the regressions `rot` and `acc` (this run's own, or its
    /// least-squares twins).
    #[allow(clippy::needless_range_loop, clippy::too_many_arguments)]
    fn solve_on(
        &self,
        rot_ls: &SegmentedLs,
        acc_ls: &SegmentedLs,
        rest_sigma: &[f64; 6],
        model_error_floor: f64,
        term_prior_sd: f64,
        prior: Option<&DynamicPrior>,
    ) -> DynamicSolution {
        let n = self.n;
        let c = self.cols;
        let base: [SegmentedSolution; 2] = [rot_ls.solve(), acc_ls.solve()];
        let sigmas: [[f64; 3]; 2] =
            std::array::from_fn(|g| group_sigma(&base[g], &rest_sigma[3 * g..3 * g + 3]));
        let prior = prior
            .filter(|p| p.fits(n))
            .map(|p| self.uncontradicted(p, &base, &sigmas));
        // The terms' prior (`term_prior_sd`): the constant and the mean |command| (the last
        // two terms) carry offsets and the thrust asymmetry, not physics that shrinks to 0.
        // The velocity terms' own (`velocity_term_prior_sd`) where it is the narrower.
        let width = |sd: f64| (sd > 0.0 && sd.is_finite()).then_some(sd);
        let (all_sd, velocity_sd) = (width(term_prior_sd), width(self.velocity_term_prior_sd));
        let term_sd = |j: usize| match (all_sd, velocity_sd) {
            (a, Some(v)) if regressors::touches_velocity(j) => Some(a.map_or(v, |a| a.min(v))),
            (a, _) => a,
        };
        let ridge = all_sd.or(velocity_sd);
        let mean = self.term_prior_mean.as_ref();
        let ridge_entries = |out: &mut Vec<PriorEntry>, row: usize| {
            for j in 0..TERMS - 2 {
                if let Some(sd) = term_sd(j) {
                    out.push(PriorEntry {
                        weights: [(c + j, 1.0), (c + j, 0.0)],
                        value: mean.map_or(0.0, |m| m[(row, j)]),
                        std_err: sd,
                    });
                }
            }
        };
        let sols: [SegmentedSolution; 2] = if prior.is_some() || ridge.is_some() {
            let [rot, acc] = base;
            let entries = |g: usize| -> [Vec<PriorEntry>; 3] {
                std::array::from_fn(|a| {
                    let mut e = prior
                        .as_ref()
                        .map(|p| p.entries(3 * g + a, self.split))
                        .unwrap_or_default();
                    ridge_entries(&mut e, 3 * g + a);
                    e
                })
            };
            [
                rot_ls.solve_with_prior(rot, &entries(0), &sigmas[0]),
                acc_ls.solve_with_prior(acc, &entries(1), &sigmas[1]),
            ]
        } else {
            base
        };
        let mut b = DMatrix::zeros(6, n);
        let mut std_err = DMatrix::zeros(6, n);
        let mut split_b = DMatrix::zeros(6, c);
        let mut split_se = DMatrix::zeros(6, c);
        let mut coefficients = DMatrix::zeros(6, TERMS);
        let mut coef_se = DMatrix::zeros(6, TERMS);
        let mut sigma = [0.0; 6];
        let mut rel_err = [f64::INFINITY; 2];
        let mut excited = true;
        let mut coef_ols = DMatrix::zeros(6, TERMS);
        let mut b_ols = DMatrix::zeros(6, n);
        let mut disturbance = self
            .disturbance
            .any()
            .then(|| DMatrix::zeros(6, self.disturbance.columns()));
        for (g, sol) in sols.iter().enumerate() {
            let s = group_sigma(sol, &rest_sigma[3 * g..3 * g + 3]);
            let mut var_sum = 0.0;
            let mut norm2 = 0.0;
            for a in 0..3 {
                let row = 3 * g + a;
                sigma[row] = s[a];
                let var = |w: &[(usize, f64)]| combination_var(sol, s[a], a, w);
                // (Gram diagonal, variance): an unexcited column has no standard error.
                let se = |d: f64, v: f64| if d > 0.0 { v.sqrt() } else { f64::INFINITY };
                for i in 0..c {
                    split_b[(row, i)] = sol.theta[(i, a)];
                    let v = var(&[(i, 1.0)]);
                    split_se[(row, i)] = se(v.0, v.1);
                }
                for i in 0..n {
                    let (theta, w) = self.symmetric_gain(sol, a, i);
                    let v = var(&w);
                    b[(row, i)] = theta;
                    std_err[(row, i)] = se(v.0, v.1);
                    b_ols[(row, i)] = se(v.0, v.2);
                    var_sum += v.1.max(0.0);
                    norm2 += b[(row, i)] * b[(row, i)];
                }
                for j in 0..TERMS {
                    coefficients[(row, j)] = sol.theta[(c + j, a)];
                    let v = var(&[(c + j, 1.0)]);
                    coef_se[(row, j)] = v.1.max(0.0).sqrt();
                    coef_ols[(row, j)] = v.2.max(0.0).sqrt();
                }
                if let Some(d) = disturbance.as_mut() {
                    for e in 0..d.ncols() {
                        d[(row, e)] = sol.theta[(c + TERMS + e, a)];
                    }
                }
            }
            let identified = (0..3).all(|a| (0..c).all(|i| sol.inverse(a)[(i, i)] > 0.0));
            excited &= identified;
            // The model error no amount of data removes (docs/study.md): spread evenly over the
            // block's entries, so the block's bound gains model_error_floor in quadrature. It is
            // the thrusters' asymmetry landing in one symmetric column; split, forward and
            // reverse are fitted apart and there is no such bias.
            let floor = if self.split && !self.floor_when_split {
                0.0
            } else {
                model_error_floor
            };
            let floor2 = floor.powi(2) * norm2 / (3 * n).max(1) as f64;
            for row in 3 * g..3 * g + 3 {
                for i in 0..n {
                    std_err[(row, i)] = (std_err[(row, i)].powi(2) + floor2).sqrt();
                }
                for i in 0..c {
                    split_se[(row, i)] = (split_se[(row, i)].powi(2) + floor2).sqrt();
                }
            }
            var_sum += floor2 * (3 * n) as f64;
            if identified && norm2 > 0.0 {
                rel_err[g] = var_sum.sqrt() / norm2.sqrt();
            }
        }
        let residual_rot = sols[0]
            .residual_var
            .filter(|_| sols[0].residual_dof >= variance::MIN_RESIDUAL_DOF)
            .map(|v| std::array::from_fn(|a| v[a].sqrt()));
        DynamicSolution {
            residual_rot,
            b,
            std_err,
            rel_err,
            sigma,
            excited,
            terms: DynamicTerms {
                coefficients,
                std_err: coef_se,
                ols_std_err: coef_ols,
                b_ols_std_err: b_ols,
                max_tilt_rad: self.nav.max_tilt(),
                max_heading_change_rad: self.nav.max_heading_change(),
                spin_up_s: self.lags.iter().sum::<f64>() / n.max(1) as f64,
                spin_up_learned: self.lags_learned,
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
                imu_position: None,
                unexplained_rate_radps: 0.0,
                lag_gap_without_states: None,
                instrumented: [rot_ls.instrumented(), acc_ls.instrumented()],
                thrust_asymmetry: if self.split { 0.0 } else { self.asymmetry },
                // Reported, not applied: whoever reports the bound widens it by this (the
                // stop rule does not: more data does not remove a bias).
                prior_disagreement: prior::disagreement(
                    prior.as_ref(),
                    [&sols[0].theta, &sols[1].theta],
                    self.split,
                ),
                // Drawn once the run stops (`navigation_error`), not per fit.
                navigation_rel_err: [0.0; 2],
                // Searched by the moving-water refit (`start_velocity`), not per fit.
                start_velocity_ned_mps: None,
                velocity_drift_ned_mps2: None,
            },
            split: self.split.then_some((split_b, split_se)),
            disturbance,
        }
    }
}

/// What is known of the IMU's position before the run (`EstimatorConfig::imu_position_m` and
/// friends).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ImuSetting {
    /// From the vehicle's drawings, body frame, m.
    pub position_m: Vector3<f64>,
    /// Check it against the data ([`ImuPosition::decide`]).
    pub learn: bool,
    /// How far the data's position may differ from `position_m` before it is called wrong, m.
    pub tolerance_m: f64,
}

impl DynamicRun {
    /// Thruster `i`'s gain on output `a` of `sol` and the weights that make it of the
    /// coefficients (the second weight 0 when not split). Split, the symmetric gain is the
    /// mean of forward and reverse (what a linear model of the thruster is, and what the truth
    /// is compared with).
    fn symmetric_gain(
        &self,
        sol: &SegmentedSolution,
        a: usize,
        i: usize,
    ) -> (f64, [(usize, f64); 2]) {
        if self.split {
            let n = self.n;
            let theta = 0.5 * (sol.theta[(i, a)] + sol.theta[(n + i, a)]);
            (theta, [(i, 0.5), (n + i, 0.5)])
        } else {
            (sol.theta[(i, a)], [(i, 1.0), (i, 0.0)])
        }
    }

    /// `prior` without the thruster columns the data alone contradicts (see
    /// [`DynamicPrior::without_contradicted`]): the data-only gains of `base` and their honest
    /// variances, at the noise `sigmas`.
    fn uncontradicted(
        &self,
        prior: &DynamicPrior,
        base: &[SegmentedSolution; 2],
        sigmas: &[[f64; 3]; 2],
    ) -> DynamicPrior {
        let n = self.n;
        let mut b = DMatrix::zeros(6, n);
        let mut var = DMatrix::from_element(6, n, f64::INFINITY);
        for (g, sol) in base.iter().enumerate() {
            for a in 0..3 {
                for i in 0..n {
                    let (theta, w) = self.symmetric_gain(sol, a, i);
                    let (d, honest, _) = combination_var(sol, sigmas[g][a], a, &w);
                    b[(3 * g + a, i)] = theta;
                    if d > 0.0 {
                        var[(3 * g + a, i)] = honest;
                    }
                }
            }
        }
        prior.without_contradicted(&b, &var)
    }
}
