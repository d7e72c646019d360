//! One estimation run: pulse plan, power escalation, both regressions, and the stop rule.
//!
//! Pure: the caller feeds at-rest noise levels, then for each pulse the baseline-removed IMU
//! samples with their time since the pulse started; it gets back the thrust to apply, a fresh
//! estimate whenever it asks, and a decision to go on or stop. The daemon's state machine, the
//! simulator experiments, the study and the tests all drive this same code.

use std::collections::VecDeque;

use nalgebra::{DMatrix, Vector3};

use super::analysis::{diagnose, rank_report, RankReport, ThrusterDiagnosis};
use super::config::{EstimatorConfig, Method};
use super::dof::DofMask;
use super::dynamic::lag_agreement;
use super::dynamic::lag_check::check_configured_lag;
use super::dynamic::lag_search::{
    fit_at, fit_at_centred, learn_common_lag_centred, LagFit, LagRange, STEP,
};
use super::dynamic::prior::DynamicPrior;
use super::dynamic::thrust_curve::ThrustCurveProbe;
use super::dynamic::thruster_lags::search_thruster_lags;
use super::dynamic::{DynamicRun, DynamicTerms, ImuSetting};
use super::excitation::ExcitationPlan;
use super::forward::{ForwardLs, ForwardSolution};
use super::linalg::singular_right;
use super::noise::NoiseLevels;
use super::paper::PaperLs;
use super::response::PulseShape;
use crate::allocation::pseudo_inverse;
use crate::navigation::long_rest_sway::RestWater;
use crate::navigation::DepthAid;

mod closed_loop;
pub use closed_loop::Settle;
mod fits;
mod navigation_bound;
mod start_velocity_search;
mod stop;
mod velocity_drift_search;

/// A residual-based noise estimate is trusted once it rests on this many degrees of freedom.
const MIN_RESIDUAL_DOF: u64 = 10;

/// Index of the rotation and acceleration sensor groups.
/// RMS over the rotation axes of the fit's noise level beyond sqrt(2) times the gyro's white
/// noise at rest (`DynamicTerms::unexplained_rate_radps`), rad/s. Why that much room: at the
/// paper's noise (0.25 rad/s) in still water the fit's level sat up to 12 % above the rest's
/// white level (AMOUR-5, seeds 1-5), which 10 % of room called 0.047 rad/s unexplained.
fn unexplained(sigma: &[f64; 6], white: &[f64; 3]) -> f64 {
    let sum: f64 = (0..3)
        .map(|a| (sigma[a].powi(2) - 2.0 * white[a].powi(2)).max(0.0))
        .sum();
    (sum / 3.0).sqrt()
}

/// Fits made again with the centre's velocity once the IMU is found off the centre (each
/// moves the position found less: on eight_vectored 8 cm, then under 1 mm).
const IMU_REFITS: usize = 2;

const ROT: usize = 0;
const ACC: usize = 1;

/// What happened during one pulse.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PulseSummary {
    /// 0-based index of the pulse just ended.
    pub index: usize,
    pub samples: u32,
    /// Samples whose rotation response exceeded k * sigma_rot (the paper's selection).
    pub kept_rot: u32,
    /// Samples whose acceleration response exceeded k * sigma_acc.
    pub kept_acc: u32,
    /// Power used by the pulse.
    pub power: f64,
    /// Power for the next pulse (raised when one group kept nothing).
    pub next_power: f64,
}

/// Whether to pulse again.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum StopDecision {
    Continue,
    /// The error bound reached the target (forward method).
    Converged {
        rel_err_rot: f64,
        rel_err_acc: f64,
    },
    /// The planned cycles are done (paper method, which has no bound).
    PlanComplete,
    /// The hard pulse limit.
    MaxPulses,
}

impl StopDecision {
    pub fn is_stop(self) -> bool {
        !matches!(self, StopDecision::Continue)
    }
}

/// A model and everything known about its quality.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Estimate {
    pub method: Method,
    pub thrusters: usize,
    pub pulses: usize,
    pub samples: u64,
    /// 6 x N forward model, DOF rows (rad/s^2 and m/s^2 per unit command for the forward
    /// method; for the paper's method the response units of its samples).
    pub effectiveness: DMatrix<f64>,
    /// 6 x N standard errors (infinite for unexcited columns, NaN for the paper's method).
    pub std_err: DMatrix<f64>,
    /// N x 6 allocation: commands per unit desired motion; zero columns for unactuated DOFs.
    pub allocation: DMatrix<f64>,
    /// 1-sigma relative error bound (Frobenius) of the rotation rows; NaN for the paper's method.
    pub rel_err_rot: f64,
    /// Same for the acceleration rows.
    pub rel_err_acc: f64,
    /// Noise standard deviation used per DOF row.
    pub sigma: [f64; 6],
    pub rank: RankReport,
    pub thruster: Vec<ThrusterDiagnosis>,
    /// Every thruster has been excited (the Gram matrix is full rank).
    pub excited: bool,
    /// The dynamic method's other coefficients (damping, restoring, Coriolis) and the
    /// excursion during the excitation; None for the static methods.
    pub dynamics: Option<DynamicTerms>,
}

/// Running sums of one sensor group over a pulse (and the quiet samples just before it, whose
/// shape value is 0): enough to add the pulse with its own intercept and, optionally, its own
/// linear drift removed (Frisch-Waugh: regress [1, t] out of both shape and response).
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
struct Moments {
    n: u64,
    t: f64,
    tt: f64,
    s: f64,
    ts: f64,
    ss: f64,
    y: Vector3<f64>,
    ty: Vector3<f64>,
    yy: Vector3<f64>,
    sy: Vector3<f64>,
}

impl Moments {
    fn push(&mut self, t: f64, s: f64, y: &Vector3<f64>) {
        self.n += 1;
        self.t += t;
        self.tt += t * t;
        self.s += s;
        self.ts += t * s;
        self.ss += s * s;
        self.y += y;
        self.ty += y * t;
        self.yy += y.component_mul(y);
        self.sy += y * s;
    }

    /// (sxx, sxy, syy) after removing a per-pulse intercept, and a linear drift too when
    /// `detrend` (and the times span enough to fit one).
    fn residual(&self, detrend: bool) -> (f64, Vector3<f64>, Vector3<f64>) {
        let n = self.n.max(1) as f64;
        let det = n * self.tt - self.t * self.t;
        if detrend && self.n >= 3 && det > 1e-12 * n * n {
            // Project onto span{1, t} with M = [[n, St], [St, Stt]], M^-1 = [[Stt, -St], [-St, n]] / det.
            let proj = |a0: f64, a1: f64, b0: f64, b1: f64| {
                (a0 * (self.tt * b0 - self.t * b1) + a1 * (n * b1 - self.t * b0)) / det
            };
            let sxx = self.ss - proj(self.s, self.ts, self.s, self.ts);
            let sxy =
                Vector3::from_fn(|a, _| self.sy[a] - proj(self.s, self.ts, self.y[a], self.ty[a]));
            let syy = Vector3::from_fn(|a, _| {
                self.yy[a] - proj(self.y[a], self.ty[a], self.y[a], self.ty[a])
            });
            (sxx, sxy, syy)
        } else {
            (
                self.ss - self.s * self.s / n,
                self.sy - self.y * (self.s / n),
                self.yy - self.y.component_mul(&self.y) / n,
            )
        }
    }

    /// Degrees of freedom the nuisance terms took.
    fn nuisance(&self, detrend: bool) -> u64 {
        if detrend && self.n >= 3 {
            2
        } else {
            1
        }
    }
}

/// Per-pulse bookkeeping, allocated once per pulse (never per sample).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct ActivePulse {
    u: Vec<f64>,
    split: Vec<f64>,
    moments: [Moments; 2],
    samples: u32,
    kept: [u32; 2],
}

/// The last few quiet samples before a pulse, kept in a fixed ring: they pin each pulse's
/// intercept without costing the pulse's own samples.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct PreWindow {
    ring: Vec<(f64, Vector3<f64>, Vector3<f64>)>,
    next: usize,
    len: usize,
}

impl PreWindow {
    fn new(capacity: usize) -> Self {
        PreWindow {
            ring: vec![(0.0, Vector3::zeros(), Vector3::zeros()); capacity],
            next: 0,
            len: 0,
        }
    }

    fn push(&mut self, t: f64, gyro: &Vector3<f64>, accel: &Vector3<f64>) {
        if self.ring.is_empty() {
            return;
        }
        self.ring[self.next] = (t, *gyro, *accel);
        self.next = (self.next + 1) % self.ring.len();
        self.len = (self.len + 1).min(self.ring.len());
    }

    /// Latest time pushed, if any.
    fn last_time(&self) -> Option<f64> {
        (self.len > 0).then(|| self.ring[(self.next + self.ring.len() - 1) % self.ring.len()].0)
    }

    /// Move the samples into a pulse's moments, times made relative to the pulse start `t0`.
    fn drain_into(&mut self, t0: f64, moments: &mut [Moments; 2]) {
        for k in 0..self.len {
            let (t, g, a) = &self.ring[k];
            moments[ROT].push(t - t0, 0.0, g);
            moments[ACC].push(t - t0, 0.0, a);
        }
        self.len = 0;
        self.next = 0;
    }
}

/// An estimation run for a fixed set of thrusters.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Estimator {
    cfg: EstimatorConfig,
    plan: ExcitationPlan,
    noise: NoiseLevels,
    shape: PulseShape,
    power: f64,
    pulses: usize,
    samples: u64,
    pulse: Option<ActivePulse>,
    pre: PreWindow,
    forward: [ForwardLs; 2],
    split: [ForwardLs; 2],
    paper: [PaperLs; 2],
    max_command: Vec<f64>,
    nominal: Option<DMatrix<f64>>,
    /// Coefficients known before the run (carried over from the model in force when only
    /// part of the vehicle changed): the dynamic fit weighs its data against them.
    prior: Option<DynamicPrior>,
    /// The dynamic method's fit, built at the first pulse.
    dynamic: Option<DynamicRun>,
    /// Mean specific force at rest (m/s^2, body): where the dynamic method's navigation starts.
    rest_force: Option<Vector3<f64>>,
    /// The vertical velocity at the end of that rest (NED, m/s), from the depth.
    rest_velocity_down: Option<f64>,
    /// What a long rest before the run read of the water (`with_rest_water`; None: no long
    /// rest). Still: the open-loop fit holds the velocity terms
    /// (`EstimatorConfig::velocity_term_prior_sd`); moved: the moving-water refit is made
    /// whatever the fit leaves unexplained (`EstimatorConfig::moving_rest_drift_states`).
    #[serde(default)]
    rest_water: Option<RestWater>,
    /// `cfg.spin_up_s` is a lag an earlier run learned (`with_learned_lag`).
    lag_inherited: bool,
    /// Each thruster's own lag an earlier run learned (`with_learned_thruster_lags`), used in
    /// place of `cfg.spin_up_s` (their mean); empty: one lag for all.
    #[serde(default)]
    inherited_lags: Vec<f64>,
    /// The lag this run's last applied estimate learned and its sd in ln(lag)
    /// (`set_lag_hint`): progress estimates fit at it instead of searching.
    lag_hint: Option<(Vec<f64>, f64)>,
    /// Under control, the fit made again with bent commands (`thrust_curve`).
    #[serde(default)]
    thrust_curve: Option<ThrustCurveProbe>,
    /// Under control, the effectiveness of the recent decision intervals' estimates that did
    /// not stop the run, each with its seconds into the run, oldest first
    /// (`remember_interval`): a decision asks whether the estimate has settled since the one
    /// a segment earlier (`closed_loop_decision`).
    #[serde(default)]
    intervals: VecDeque<(f64, DMatrix<f64>)>,
    /// The relative error the lags inherited from an earlier model carry into B
    /// (`with_inherited_lag_error`), rotation and acceleration rows.
    #[serde(default)]
    inherited_lag_rel_err: [f64; 2],
    /// The relative error the prior's navigation left in its columns
    /// (`with_inherited_navigation_error`), rotation and acceleration rows.
    #[serde(default)]
    inherited_navigation_rel_err: [f64; 2],
    /// The moving-water refit searches the start velocity (`search_start_velocity`, only in
    /// the job a stopping open loop makes its model in).
    #[serde(default)]
    searching_start_velocity: bool,
    /// The gyro bias's error where it came from a long idle rest (`with_gyro_bias_sd`), rad/s;
    /// None: the rest's, `gyro_sd / sqrt(samples)`.
    #[serde(default)]
    gyro_bias_sd: Option<f64>,
    /// Fed the commands sent under control (`begin_closed_loop`), not its own plan's pulses.
    #[serde(default)]
    under_control: bool,
}

impl Estimator {
    /// A run for `n` thrusters with the noise levels measured at rest.
    pub fn new(cfg: EstimatorConfig, n: usize, noise: NoiseLevels) -> Self {
        let n = n.max(1);
        Estimator {
            plan: ExcitationPlan::new(cfg.excitation, n),
            shape: PulseShape {
                lag_s: cfg.spin_up_s,
            },
            power: cfg.initial_power.min(cfg.max_power),
            pulses: 0,
            samples: 0,
            pulse: None,
            pre: PreWindow::new(cfg.baseline_samples),
            forward: [ForwardLs::new(n), ForwardLs::new(n)],
            split: [ForwardLs::new(2 * n), ForwardLs::new(2 * n)],
            paper: [PaperLs::new(n), PaperLs::new(n)],
            max_command: vec![0.0; n],
            nominal: None,
            prior: None,
            dynamic: None,
            rest_force: None,
            rest_velocity_down: None,
            rest_water: None,
            lag_inherited: false,
            lag_hint: None,
            inherited_lags: Vec::new(),
            thrust_curve: None,
            intervals: VecDeque::new(),
            inherited_lag_rel_err: [0.0; 2],
            inherited_navigation_rel_err: [0.0; 2],
            searching_start_velocity: false,
            gyro_bias_sd: None,
            under_control: false,
            noise,
            cfg,
        }
    }

    /// The thrusters' lag an earlier run learned (the model in force's), s: used in place of
    /// `spin_up_s` and reported as learned. For runs that cannot learn it themselves (under
    /// control, see `dynamic_run`).
    pub fn with_learned_lag(mut self, lag_s: f64) -> Self {
        if lag_s.is_finite() && lag_s >= 0.0 {
            self.cfg.spin_up_s = lag_s;
            self.shape.lag_s = lag_s;
            self.lag_inherited = true;
        }
        self
    }

    /// Each thruster's own lag an earlier run learned (the model in force's, one per
    /// thruster), s: as [`Self::with_learned_lag`] with their mean, the fit using each.
    /// Ignored unless there is one per thruster. Why: a vehicle with thrusters of two makes
    /// identified under control with their mean lag is as wrong as one estimated open loop
    /// with it (0.40-0.84 off).
    pub fn with_learned_thruster_lags(mut self, lags: &[f64]) -> Self {
        if lags.len() == self.thrusters() && lags.iter().all(|l| l.is_finite() && *l >= 0.0) {
            self = self.with_learned_lag(lags.iter().sum::<f64>() / lags.len() as f64);
            self.inherited_lags = lags.to_vec();
        }
        self
    }

    /// The IMU taken where `estimator.imu_position_m` says, not learned (a fit under control
    /// with no learned position to go by).
    pub fn with_configured_imu_position(mut self) -> Self {
        self.cfg.learn_imu_position = false;
        self
    }

    /// The IMU's position an earlier run found or was told (the model in force's), m: used
    /// as configured, not learned again. For runs under control, whose excitation the
    /// controller shapes and which keep no log to refit the velocity with.
    pub fn with_known_imu_position(mut self, position_m: Vector3<f64>) -> Self {
        if position_m.iter().all(|v| v.is_finite()) {
            self.cfg.imu_position_m = position_m.into();
            self.cfg.learn_imu_position = false;
        }
        self
    }

    /// Declared model (6 x N) to check thruster directions against.
    pub fn with_nominal(mut self, nominal: DMatrix<f64>) -> Self {
        if nominal.nrows() == 6 && nominal.ncols() == self.thrusters() {
            self.nominal = Some(nominal);
        }
        self
    }

    /// Coefficients known before the run, for the dynamic method (see
    /// [`DynamicPrior`]); ignored when its shape does not fit N thrusters.
    pub fn with_prior(mut self, prior: DynamicPrior) -> Self {
        if prior.fits(self.thrusters()) {
            self.prior = Some(prior);
        }
        self
    }

    /// The mean specific force measured at rest just before the run (m/s^2, body frame, the
    /// raw accelerometer): the dynamic method starts its navigation from it. Without it the
    /// vehicle is taken as level.
    pub fn with_rest_specific_force(mut self, f: Vector3<f64>) -> Self {
        if f.iter().all(|v| v.is_finite()) {
            self.rest_force = Some(f);
        }
        self
    }

    /// What a long rest before the run read of the water (`navigation::long_rest_sway`).
    /// Still: the open-loop fit holds the velocity terms at
    /// `EstimatorConfig::velocity_term_prior_sd` (why only then: at the paper's noise that
    /// prior's tighter bound is honest in still water but not in a swell, which nothing
    /// shorter than a long rest sees there). Moved: the open-loop fit is made again with the
    /// moving-water states whatever rotation it leaves unexplained
    /// (`EstimatorConfig::moving_rest_drift_states`).
    pub fn with_rest_water(mut self, water: RestWater) -> Self {
        self.rest_water = Some(water);
        self
    }

    /// The error of the gyro's bias (rad/s per axis) where the machine took it from a long idle
    /// rest (`machine.gyro_bias_rest_s`) instead of the short one the noise levels come from:
    /// the navigation's errors are drawn with it (`count_navigation_error`).
    pub fn with_gyro_bias_sd(mut self, sd: f64) -> Self {
        if sd.is_finite() && sd >= 0.0 {
            self.gyro_bias_sd = Some(sd);
        }
        self
    }

    /// The vertical velocity (NED, m/s) the rest ended with, from the depth sensor
    /// (`navigation::rest_drift`): the dynamic method's navigation starts from it, since a
    /// buoyant vehicle is rising by then. Without it the navigation starts from zero.
    pub fn with_rest_velocity_down(mut self, velocity_down: f64) -> Self {
        if velocity_down.is_finite() {
            self.rest_velocity_down = Some(velocity_down);
        }
        self
    }

    /// A dynamic fit whose navigation starts from the rest measured before the run (level and
    /// still without one); `split` fits forward and reverse thrust apart; `open_loop`: the
    /// pulsed estimation's own run (one command per pulse: a log for the lag search, and a
    /// split bound that keeps its model-error floor), not the identification under control.
    fn dynamic_run(&self, split: bool, open_loop: bool) -> DynamicRun {
        let rest = self
            .rest_force
            .unwrap_or(Vector3::new(0.0, 0.0, -super::response::GRAVITY));
        let (n, lag, segment, aid) = (
            self.thrusters(),
            self.cfg.spin_up_s,
            self.cfg.segment_s,
            self.navigation_aid(),
        );
        let mut run = if split {
            let run = DynamicRun::split(n, lag, segment, &rest, aid);
            if open_loop {
                run.keep_floor()
            } else {
                run
            }
        } else {
            let run = DynamicRun::new(n, lag, segment, &rest, aid);
            if open_loop && self.cfg.shaped_thrust {
                run.with_asymmetry(self.cfg.reverse_ratio)
            } else {
                run
            }
        }
        .with_term_prior_mean(self.cfg.term_prior_mean.clone())
        // The velocity terms' prior in the open loop only, and only where a long rest saw
        // still water: under control the vehicle hardly moves, and there it changed the
        // identification (docs/study.md, "At the paper's noise"); in a swell at the paper's
        // noise its bound was not honest ("The velocity terms held where a long rest saw
        // still water").
        .with_velocity_term_prior_sd(if open_loop && self.rest_water == Some(RestWater::Still) {
            self.cfg.velocity_term_prior_sd
        } else {
            0.0
        })
        .with_disturbance(self.cfg.disturbance);
        // The open-loop estimation only: the log keeps one command per pulse, split or not
        // (under control the command changes every sample; there the lag is the model's,
        // `EstimatorConfig::spin_up_s` set from it by the caller).
        if open_loop
            && (self.learns_lag() || self.checks_configured_lag() || self.cfg.learn_imu_position)
        {
            run = run.with_log(self.cfg.max_pulses + 1);
        }
        if self.lag_inherited {
            run.mark_lag_learned();
        }
        if !self.inherited_lags.is_empty() {
            run.set_lags(&self.inherited_lags);
        }
        if let Some(w) = self.rest_velocity_down {
            run.start_sinking_at(w);
        }
        run
    }

    pub fn thrusters(&self) -> usize {
        self.plan.thrusters()
    }

    /// The lag an estimate of this run learned (`estimate.dynamics`), for the progress
    /// estimates that follow (`estimate_progress`). The machine sets it when it applies a
    /// solve's result, at a sample fixed in vehicle time, so replay sets it at the same one.
    pub fn set_lag_hint(&mut self, estimate: &Estimate) {
        if let Some(d) = estimate.dynamics.as_ref() {
            if d.spin_up_learned && d.spin_up_s.is_finite() && d.spin_up_sd_ln.is_finite() {
                let lags = if d.spin_up_per_thruster_s.is_empty() {
                    vec![d.spin_up_s]
                } else {
                    d.spin_up_per_thruster_s.clone()
                };
                self.lag_hint = Some((lags, d.spin_up_sd_ln));
            }
        }
    }

    /// An estimate for progress only (status, the bound shown between decisions): as
    /// `estimate`, but the lag is not searched: the last learned one (`set_lag_hint`) is
    /// fitted at, or the configured one before any. A search costs ~22 refits of the run's
    /// samples (56-75 ms after 64 pulses); queued after every pulse they delayed the
    /// decisions behind them.
    pub fn estimate_progress(&self) -> Estimate {
        if self.cfg.method != Method::Dynamic || !self.learns_lag() {
            return self.estimate();
        }
        let Some(run) = self.dynamic.as_ref() else {
            return self.estimate();
        };
        let fit = self
            .lag_hint
            .as_ref()
            .and_then(|(lags, sd_ln)| fit_at(run, lags, *sd_ln));
        let e = self.dynamic_estimate_with(run, fit, false);
        self.in_moving_water(run, e, |moving, _| {
            let fit = self
                .lag_hint
                .as_ref()
                .and_then(|(lags, sd_ln)| fit_at(moving, lags, *sd_ln));
            self.dynamic_estimate_with(moving, fit, false)
        })
    }

    /// Whether this run learns the thrusters' lag: asked to, and the gyro quiet enough for
    /// the learned lag to be trusted (`EstimatorConfig::spin_up_max_gyro_sigma`).
    pub fn learns_lag(&self) -> bool {
        self.cfg.method == Method::Dynamic
            && self.cfg.learn_spin_up
            && !self.lag_inherited
            && self.noise.sigma_rot() <= self.cfg.spin_up_max_gyro_sigma
    }

    /// Whether this run checks the configured lag against its data instead of learning it:
    /// the lag would be learned but for the gyro's noise
    /// (`EstimatorConfig::check_configured_lag`, [`super::dynamic::lag_check`]).
    pub fn checks_configured_lag(&self) -> bool {
        self.cfg.method == Method::Dynamic
            && self.cfg.learn_spin_up
            && self.cfg.check_configured_lag
            && !self.lag_inherited
            && !self.learns_lag()
    }

    /// The at-rest noise per DOF row (gyro, then accelerometer).
    fn rest_sigma(&self) -> [f64; 6] {
        let (g, a) = (self.noise.gyro_sigma, self.noise.accel_sigma);
        [g[0], g[1], g[2], a[0], a[1], a[2]]
    }

    /// Where the dynamic method searches the thrusters' lag.
    fn lag_range(&self) -> LagRange {
        let [min_s, max_s] = self.cfg.spin_up_range_s;
        LagRange {
            min_s,
            max_s,
            ..LagRange::default()
        }
    }

    pub fn config(&self) -> &EstimatorConfig {
        &self.cfg
    }

    pub fn noise(&self) -> &NoiseLevels {
        &self.noise
    }

    pub fn plan(&self) -> &ExcitationPlan {
        &self.plan
    }

    /// The dynamic method's fit so far (None before the first pulse or for the static methods).
    pub fn dynamic_fit(&self) -> Option<&DynamicRun> {
        self.dynamic.as_ref()
    }

    /// Pulses completed so far.
    pub fn pulses(&self) -> usize {
        self.pulses
    }

    /// Current pulse strength (fraction of full command).
    pub fn power(&self) -> f64 {
        self.power
    }

    /// Caps the pulse power at `cap` (in (0, 1]) from the next pulse on: what the thrusters
    /// can give now (a sagging pack). A linear model learns from any power; a saturated pulse
    /// would teach it a weaker thruster than it has. The dynamic method's power is otherwise
    /// constant, so it returns to the configured power when the cap allows; the static
    /// methods' raised power is only lowered.
    pub fn cap_power(&mut self, cap: f64) {
        if !cap.is_finite() {
            return;
        }
        let cap = cap.clamp(0.05, 1.0);
        self.power = if self.cfg.method == Method::Dynamic {
            self.cfg.initial_power.min(self.cfg.max_power).min(cap)
        } else {
            self.power.min(cap)
        };
    }

    /// The thrust to apply for the next pulse: power times the plan's sign pattern, in [-1, 1].
    /// Starts the pulse; feed its samples with `push_pulse_sample`, then call `end_pulse`.
    /// The pulse starts just after the last rest sample.
    pub fn begin_pulse(&mut self) -> &[f64] {
        let t0 = self.pre.last_time().unwrap_or(0.0);
        self.begin_pulse_at(t0)
    }

    /// As `begin_pulse`, with the pulse's start on the clock of `push_rest_sample` (s).
    pub fn begin_pulse_at(&mut self, t0_s: f64) -> &[f64] {
        let pattern = self.plan.pattern(self.pulses);
        // The dynamic method balances forward and reverse impulses (see `reverse_ratio`).
        let forward_scale = if self.cfg.method == Method::Dynamic {
            self.cfg.reverse_ratio
        } else {
            1.0
        };
        // The dynamic method's second level (`second_amplitude`, `ExcitationPlan::level`).
        let level = if self.cfg.method == Method::Dynamic {
            self.plan.level(self.pulses, self.cfg.second_amplitude)
        } else {
            1.0
        };
        let u: Vec<f64> = pattern
            .iter()
            .map(|s| {
                let v = s * self.power * level;
                let v = if v > 0.0 { v * forward_scale } else { v };
                v.clamp(-1.0, 1.0)
            })
            .collect();
        if self.cfg.method == Method::Dynamic && self.dynamic.is_none() {
            let mut run = self.dynamic_run(self.cfg.split_thrust, true);
            // The thrusters leave rest now, a sample period before the run's first sample.
            run.start_from_rest_at(t0_s);
            self.dynamic = Some(run);
        }
        let split = split_regressor(&u);
        for (m, v) in self.max_command.iter_mut().zip(&u) {
            *m = m.max(v.abs());
        }
        let mut moments = [Moments::default(); 2];
        self.pre.drain_into(t0_s, &mut moments);
        self.pulse = Some(ActivePulse {
            u,
            split,
            moments,
            samples: 0,
            kept: [0, 0],
        });
        self.pulse.as_ref().map(|p| p.u.as_slice()).unwrap_or(&[])
    }

    /// Command of the pulse in progress, if any.
    pub fn current_command(&self) -> Option<&[f64]> {
        self.pulse.as_ref().map(|p| p.u.as_slice())
    }

    /// A sample between pulses at time `t_s` (any clock in seconds, the one `begin_pulse_at`
    /// uses; same units as `push_pulse_sample`); the last `baseline_samples` of them anchor the
    /// next pulse's intercept and drift.
    pub fn push_rest_sample(&mut self, t_s: f64, gyro: &Vector3<f64>, accel: &Vector3<f64>) {
        if t_s.is_finite() && gyro.iter().chain(accel.iter()).all(|v| v.is_finite()) {
            self.pre.push(t_s, gyro, accel);
        }
    }

    /// One IMU sample during the pulse: `t_s` since the command was applied, responses with the
    /// at-rest baseline removed (gyro rad/s; motion acceleration m/s^2, gravity compensated).
    pub fn push_pulse_sample(&mut self, t_s: f64, gyro: &Vector3<f64>, accel: &Vector3<f64>) {
        let shape = [self.shape.rate(t_s), self.shape.accel(t_s)];
        let k_sigma = [
            self.cfg.k_sigma * self.noise.sigma_rot(),
            self.cfg.k_sigma * self.noise.sigma_acc(),
        ];
        let Some(p) = self.pulse.as_mut() else {
            return;
        };
        p.samples += 1;
        self.samples += 1;
        if !gyro.iter().chain(accel.iter()).all(|v| v.is_finite()) {
            return;
        }
        for (g, y) in [(ROT, gyro), (ACC, accel)] {
            p.moments[g].push(t_s, shape[g], y);
            if y.norm() > k_sigma[g] {
                self.paper[g].add(y, &p.u);
                p.kept[g] += 1;
            }
        }
    }

    /// One IMU sample for the dynamic method at `t_s` (the clock of `begin_pulse_at`), during a
    /// pulse or between pulses: bias-free gyro (rad/s), the raw specific force (m/s^2) and the
    /// depth (m) if measured. The command is the pulse's (zero between pulses). Samples before
    /// the first pulse, and every sample for the static methods, are ignored.
    pub fn push_dynamic_sample(
        &mut self,
        t_s: f64,
        gyro: &Vector3<f64>,
        specific_force: &Vector3<f64>,
        depth: Option<f64>,
    ) {
        let Some(run) = self.dynamic.as_mut() else {
            return;
        };
        // Between pulses the thrusters are at neutral.
        let u = self.pulse.as_mut().map(|p| {
            p.samples += 1;
            p.kept = [p.samples; 2];
            p.u.as_slice()
        });
        run.push(t_s, gyro, specific_force, depth, u);
        self.samples += 1;
    }

    /// A measured body velocity (a DVL, m/s) for the dynamic method's navigation; ignored
    /// by the static methods and before the first pulse.
    pub fn push_velocity_fix(&mut self, measured: &Vector3<f64>) {
        if let Some(run) = self.dynamic.as_mut() {
            run.velocity_fix(measured);
        }
    }

    /// Close the pulse; raises the power when a sensor group kept no sample (Algorithm 1).
    pub fn end_pulse(&mut self) -> Option<PulseSummary> {
        if self.cfg.method == Method::Dynamic {
            // Fitted sample by sample; the power stays (back-to-back pulses need no rescue).
            let p = self.pulse.take()?;
            let summary = PulseSummary {
                index: self.pulses,
                samples: p.samples,
                kept_rot: p.kept[ROT],
                kept_acc: p.kept[ACC],
                power: self.power,
                next_power: self.power,
            };
            self.pulses += 1;
            return Some(summary);
        }
        let p = self.pulse.take()?;
        let detrend = self.cfg.detrend;
        for g in [ROT, ACC] {
            let m = &p.moments[g];
            let (sxx, sxy, syy) = m.residual(detrend);
            // add_centred charges one degree of freedom per pulse; a drift term costs one more.
            let rows = m.n.saturating_sub(m.nuisance(detrend) - 1);
            self.forward[g].add_centred(&p.u, sxx, &sxy, &syy, rows);
            self.split[g].add_centred(&p.split, sxx, &sxy, &syy, rows);
        }
        let used = self.power;
        if p.kept[ROT] == 0 || p.kept[ACC] == 0 {
            self.power = (self.power + self.cfg.power_step).min(self.cfg.max_power);
        }
        let summary = PulseSummary {
            index: self.pulses,
            samples: p.samples,
            kept_rot: p.kept[ROT],
            kept_acc: p.kept[ACC],
            power: used,
            next_power: self.power,
        };
        self.pulses += 1;
        Some(summary)
    }

    /// A whole pulse reduced to one measurement (the paper's simulation study): command `u`,
    /// responses `rot` and `acc`. The same regressions and selection; the power is the caller's.
    pub fn push_observation(&mut self, u: &[f64], rot: &Vector3<f64>, acc: &Vector3<f64>) {
        if u.len() != self.thrusters() {
            return;
        }
        let split = split_regressor(u);
        for (m, v) in self.max_command.iter_mut().zip(u) {
            *m = m.max(v.abs());
        }
        let k_sigma = [
            self.cfg.k_sigma * self.noise.sigma_rot(),
            self.cfg.k_sigma * self.noise.sigma_acc(),
        ];
        for (g, y) in [(ROT, rot), (ACC, acc)] {
            self.forward[g].add(u, y);
            self.split[g].add(&split, y);
            if y.norm() > k_sigma[g] {
                self.paper[g].add(y, u);
            }
        }
        self.samples += 1;
        self.pulses += 1;
    }

    /// Forward-method effectiveness only (6 x N), without the analysis: the study's hot path.
    pub fn forward_effectiveness(&self) -> DMatrix<f64> {
        let [rot, acc] = self.forward_solutions();
        stack(&rot.b, &acc.b)
    }

    /// The raw forward regressions of the rotation and acceleration groups.
    pub fn forward_solutions(&self) -> [ForwardSolution; 2] {
        [self.forward[ROT].solve(), self.forward[ACC].solve()]
    }

    /// Paper-method effectiveness in forward form (6 x N), the study's other hot path.
    pub fn paper_effectiveness(&self) -> DMatrix<f64> {
        stack(
            &self.paper[ROT].forward_model(),
            &self.paper[ACC].forward_model(),
        )
    }

    /// The current model with its quality report, by the configured method.
    pub fn estimate(&self) -> Estimate {
        match self.cfg.method {
            Method::Forward => self.forward_estimate(),
            Method::Paper => self.paper_estimate(),
            Method::Dynamic => self.dynamic_estimate(),
        }
    }
}

/// [u+; u-]: forward and reverse commands as separate regressors (2N), so the fit can tell a
/// thruster's forward gain from its reverse gain.
fn split_regressor(u: &[f64]) -> Vec<f64> {
    let n = u.len();
    let mut s = vec![0.0; 2 * n];
    for (i, &v) in u.iter().enumerate() {
        if v >= 0.0 {
            s[i] = v;
        } else {
            s[n + i] = v;
        }
    }
    s
}

/// Rotation rows on top of acceleration rows.
fn stack(rot: &DMatrix<f64>, acc: &DMatrix<f64>) -> DMatrix<f64> {
    let n = rot.ncols();
    let mut b = DMatrix::zeros(6, n);
    b.view_mut((0, 0), (3, n)).copy_from(rot);
    b.view_mut((3, 0), (3, n)).copy_from(acc);
    b
}
