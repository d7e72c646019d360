//! Estimator settings, as they appear in the `[estimator]` table of thrusterd.toml.

use serde::{Deserialize, Serialize};
use thruster_driver_kit::Range;
use thruster_protocol::validate::limits::MAX_POSITION_M;

use super::dof::Dof;
use super::excitation::Excitation;

/// Most quiet samples `baseline_samples` may ask for: 10 s at 1 kHz.
pub const MAX_BASELINE_SAMPLES: usize = 10_000;

/// Which estimator produces the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Doniec, Detweiler and Rus, Algorithm 1: k-sigma sample selection and S * A = T.
    Paper,
    /// Least squares on y = B u with a fixed pulse shape, SVD allocation, confidence,
    /// automatic stop. Biased in the water by drag, restoring moment and added mass.
    Forward,
    /// The forward model regressed together with the vehicle's dynamics ([`super::dynamic`]):
    /// also learns damping, restoring and Coriolis coefficients, pulses back to back.
    Dynamic,
}

impl Method {
    pub fn name(self) -> &'static str {
        match self {
            Method::Paper => "paper",
            Method::Forward => "forward",
            Method::Dynamic => "dynamic",
        }
    }
}

/// Every key is optional; the defaults are the documented values below.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EstimatorConfig {
    /// "dynamic" (default), "forward" or "paper". The static methods were tuned with the
    /// settings of [`EstimatorConfig::forward`] (config/thrusterd.toml names them).
    pub method: Method,
    /// "doublet_pairs" (default: back-to-back +r,-r,-r,+r Hadamard patterns that return the
    /// vehicle near rest, the dynamic method's), "orthogonal", "pairs" or "round_robin" (the
    /// paper's).
    pub excitation: Excitation,
    /// Sample selection and significance threshold in noise standard deviations (paper: 3).
    pub k_sigma: f64,
    /// First pulse strength as a fraction of full command (default 1.0: at 0.8 the dynamic
    /// method's paper-noise bound did not reach 0.06 within 64 pulses on AMOUR-5, docs/study.md;
    /// forward settings 0.8; the paper: 0.5).
    /// Stronger pulses reach the error bound in fewer pulses; 0.1 s pulses keep the motion small.
    pub initial_power: f64,
    /// With a model in force (declared geometry, or the one being replaced), the first pulse is
    /// only as strong as it needs to be: the model's typical thruster should change the body
    /// rate by `pulse_snr` gyro standard deviations in one pulse (default 20: at the paper's
    /// noise that asks for more than `initial_power`, which then stays the start; 12 lowered
    /// it on AMOUR-5 top45 and doubled the estimation time), but never below `min_power`
    /// (default 0.2). 0 turns this off: every estimation starts at
    /// `initial_power`. See estimator/power.rs for why.
    pub pulse_snr: f64,
    pub min_power: f64,
    /// Increase after a pulse that kept no sample (paper: 0.1).
    pub power_step: f64,
    /// Cap on the pulse strength (paper: 1.0; the paper's max() is meant as min()).
    pub max_power: f64,
    /// Automatic stop: relative error bound (1 sigma, Frobenius) each of the rotation and
    /// acceleration models must reach (forward and dynamic methods; default 0.06, forward
    /// settings 0.1). The dynamic method's bound is honest since it counts the residuals'
    /// autocorrelation and the model-error floor: at the paper's noise on AMOUR-5, seeds 1-20,
    /// stopping at 0.06 gave a true rotation error of 0.056 in 7.5 vehicle-s (docs/study.md).
    pub target_rel_err: f64,
    /// Automatic stop: the dynamic method's acceleration rows' own target (default 0.07;
    /// unset: `target_rel_err`; the static methods stop both at `target_rel_err`). The
    /// rotation rows are what attitude control stands on; the acceleration rows, measured
    /// with an accelerometer ten times noisier relative to their signal at the paper's noise,
    /// hold the slowest part of the run (docs/study.md, "How fast a model can be learned").
    /// Why 0.07, not 0.06: at the paper's noise after a long rest the open loop took 5.46 /
    /// 6.42 s (mean / worst, AMOUR-5) at 0.06 and 4.18 / 5.22 s at 0.07, the identification
    /// under control 8.0-12.9 s against 6.9-8.9 s, with no more models beyond 1.5x their
    /// bound (open loop 5 -> 4 of 50, first models 6 -> 4 of 30); a realistic IMU and
    /// noise-free runs are unchanged (the cycle and the reach rule stop them). docs/study.md,
    /// "The acceleration rows' target at 0.07".
    pub target_rel_err_acc: Option<f64>,
    /// Automatic stop: a bound worth waiting for (default 0.03; 0: off). Once both bounds are
    /// at their targets, the open-loop run goes on while one of them is above this value and
    /// would reach it by `max_pulses` at the rate a bound falls (its statistical part as
    /// 1/sqrt(pulses), `model_error_floor` not at all), or come within 1.2x of it where the
    /// run learns its lag and the IMU is configured at the centre (the rule was a cliff: four_up
    /// stopped 0.037 off where a wait gave 0.015; `run::fits::REACH_SLACK`). At 0.03, eight_vectored with slow
    /// thrusters (0.15 s) at a realistic IMU went from 3 to 9 of 10 seeds within 3 % for 0.8 s
    /// more (issue 29). Only where that premise holds: in still water (a current's drift grows
    /// with the run: AMOUR-5 waited its way from 0.016 to 0.022 off), with the IMU where it was
    /// said to be, and not under control (re-estimations ran 17-21 s instead of 12); elsewhere
    /// the run stops at the targets (docs/study.md).
    pub reach_rel_err: f64,
    /// The bound worth waiting for where the run learns its lag, in the same rule as
    /// `reach_rel_err` and besides it: a run goes on while either reach says so, so no run
    /// stops sooner than under `reach_rel_err` alone (0: off). Why: where the lag is learned
    /// the acceleration rows' bound runs 1.1-1.3x short (the gyro's noise reaches them through
    /// the learned lag and the navigation's velocity), so a 1-sigma stop at 0.03 leaves seeds
    /// over it (docs/study.md, "The slow lags' tail"). Default 0.025: with the velocity's
    /// drift taken out (`velocity_drift_search_mps2`), issue 29's lag table at a realistic IMU
    /// went from 4 to 0 of 120 runs over 0.03 and, over 40 seeds at 0.15-0.2 s, from 15 to 0
    /// of 160 (then only at lags of 0.13 s or more), for 0.4-1.2 vehicle-s more on slow
    /// lags; at every learned lag, eight_vectored at its 0.1 s through the processes went from
    /// 1 to 0 of 30 seeds over 0.03 for about 1.2 vehicle-s more (AMOUR-5 unchanged);
    /// without the drift's search it made AMOUR-5's longer runs drift (1 -> 4 of 40 at 0.2 s;
    /// docs/study.md, "The velocity's drift searched, and a reach for slow thrusters", and
    /// "A second reach at every learned lag").
    pub learned_lag_reach_rel_err: f64,
    /// Full excitation cycles before the automatic stop may fire (>= 1: every thruster seen in
    /// both directions).
    pub min_cycles: usize,
    /// The dynamic method's open loop may stop before its first cycle ends (default false):
    /// at the end of the first doublet pair after which its patterns tell every thruster
    /// apart (`ExcitationPlan::confounded`), when the bounds are at `reach_rel_err` as well
    /// as at the targets. A doublet pair fires every thruster twice each way, so the design
    /// is balanced there though not orthogonal. It gains only with fewer thrusters than the
    /// Hadamard order: AMOUR-5's 5 thrusters are told apart after 5 of its 8 rows, and it
    /// stopped at 20 pulses noise-free and 28 at a realistic IMU instead of 32 (2.83 s
    /// instead of 3.23 through the processes, within 0.011 / 0.025). The cost: the damping
    /// and restoring terms see less of the run (AMOUR-5's roll damping 3 % -> 20 % off
    /// noise-free); B is what the controller uses. In place of `min_cycles`; not with
    /// `second_amplitude` below 1, whose curve needs the whole cycle. See docs/study.md,
    /// "Stopping once the pulses tell the thrusters apart".
    pub stop_once_spanned: bool,
    /// Hard stop, pulses. The paper's method, which has no error bound, stops after
    /// `paper_cycles` full cycles or at this limit.
    pub max_pulses: usize,
    /// Full cycles the paper's method runs (1 cycle of round robin = two pulses per thruster,
    /// what the paper needed).
    pub paper_cycles: usize,
    /// Thruster spin-up time constant, s (default 0.1). The static methods' response shape
    /// assumes it; the dynamic method learns the lag (`learn_spin_up`) and uses this only
    /// when learning is off or the data cannot decide yet.
    pub spin_up_s: f64,
    /// Dynamic method: learn the thrusters' spin-up time constant from the run's data by
    /// profile likelihood (`estimator::dynamic::lag_search`), searched over `spin_up_range_s`
    /// (default true). Why: a lag wrong by 50 ms made the noise-free model 105 % off (issue 29).
    pub learn_spin_up: bool,
    /// Dynamic method: the smallest and largest lag the search considers, s (default
    /// [0.01, 0.5]).
    pub spin_up_range_s: [f64; 2],
    /// Dynamic method: the lag is learned only while the gyro noise measured at rest (RMS of
    /// the axes) is at most this, rad/s (default 0.05); above it `spin_up_s` is used and
    /// reported as configured. Why: on AMOUR-5 the learned lag is within 1 % of the truth
    /// up to 0.04 rad/s of gyro noise, but 6-14 % short at 0.0625-0.25 rad/s (the paper's
    /// level), and a lag 10 % short makes B 10 % off: there it does worse than a configured
    /// lag that is right (docs/study.md, "Learning the thruster lag").
    pub spin_up_max_gyro_sigma: f64,
    /// Dynamic method, with the lag learned: a lag per thruster is kept when it explains the
    /// run's data better than one lag for all by more than this ln likelihood ratio
    /// (`estimator::dynamic::thruster_lags`; default 100). Why: a
    /// vehicle with thrusters of two makes (0.05 and 0.15 s) got one lag and a model 40 % off
    /// under a 3 % bound; the ratio there is in the thousands, on a vehicle of one make at a
    /// realistic IMU under 30 (docs/study.md, "Thrusters of two makes").
    pub thruster_lag_evidence: f64,
    /// Dynamic method, with the lag learned: look for a lag per thruster at all (default
    /// true; false: one lag for all, as before issue 29 item 4, and the search's cost saved).
    pub learn_thruster_lags: bool,
    /// Standard deviation in ln(lag) each thruster's own lag gets beyond the data's, when
    /// the lags are kept apart (default 0.05). Why: with thrusters of two makes the lags came
    /// out 1-7 % short of the truth at a realistic IMU (eight_vectored, seeds 1-3: the model
    /// error the fit puts in them), several times their statistical spread, and the model
    /// 0.036-0.049 off under bounds of 0.021-0.023; the data removes none of it, so the stop
    /// rule leaves it out of the bound it waits on (docs/study.md, "Thrusters of two makes").
    pub thruster_lag_floor: f64,
    /// Dynamic method, with the gyro too noisy to learn the lag (`spin_up_max_gyro_sigma`):
    /// search it anyway and refuse a model whose configured lag the data contradicts
    /// (`estimator::dynamic::lag_check`; default true). Why: at the paper's noise a vehicle
    /// whose thrusters lag 0.05 s got a model 95-109 % off under a 3-13 % bound, swapped in.
    pub check_configured_lag: bool,
    /// Dynamic method, with the gyro too noisy to learn the lag: the learned lag over the
    /// true one is taken to lie in this range (default [0.6, 1.05]), give or take
    /// `lag_check_z` of its standard deviations; a configured lag outside learned / it is
    /// contradicted. Why: at the paper's noise the learned lag is short by a bounded factor:
    /// 0.63-1.08 over every vehicle file and AMOUR-5 / eight_vectored at 0.03-0.2 s, 200 Hz
    /// and 1 kHz, seeds 1-10 (docs/study.md, "The configured lag, checked at a noisy gyro").
    pub lag_check_ratio: [f64; 2],
    /// The learned lag's standard deviations (of ln lag) that widen `lag_check_ratio`
    /// (default 2). Why: at 1 kHz the learned lag scatters up to 8 % long (aligned, seed 6:
    /// 0.1075 s of 0.1, sd 0.027), which no bias explains.
    pub lag_check_z: f64,
    /// Quiet samples just before each pulse that anchor its intercept (default 20, at most
    /// [`MAX_BASELINE_SAMPLES`]).
    pub baseline_samples: usize,
    /// Remove a per-pulse linear drift as well as the intercept (default false). Meant to let
    /// pauses be short while the vehicle still swings back; measured on AMOUR-5 at the paper's
    /// noise it costs so much information that the bound no longer converges within 64 pulses
    /// and the error does not improve (docs/simulation.md), so it is off.
    pub detrend: bool,
    /// A singular value counts when it exceeds this factor times the largest singular value a
    /// pure-noise matrix of the same size would have (sqrt(6) + sqrt(N) in standard errors).
    pub rank_threshold: f64,
    /// Which DOFs the actuated motions are assigned to, most wanted first. When the thrusters
    /// make fewer independent motions than DOFs they touch (a tilted thruster couples pitch and
    /// sway, say), each DOF in this order is taken if its row is independent of those already
    /// taken, above the noise, until the rank is reached. The default keeps what the attitude
    /// and depth controller holds (attitude, then depth) ahead of surge and sway, which then
    /// move as a side effect. Must name each of the six once.
    pub dof_priority: [Dof; 6],
    /// A thruster "responds" when its column's chi-square (6 dof) exceeds this value
    /// (22.46 = the 99.9 % quantile).
    pub response_chi2: f64,
    /// A thruster that does not respond after a pulse at least this strong is reported dead.
    pub dead_min_command: f64,
    /// Forward/reverse gains (and a declared direction) differ when the difference exceeds
    /// this many standard errors.
    pub diagnosis_z: f64,
    /// Dynamic method: positive pulse commands are scaled by this (default 0.78, a T200's
    /// reverse/forward thrust ratio) so forward and reverse impulses balance and the vehicle
    /// does not drift into a tumble (measured: 70 -> 16 deg largest tilt on AMOUR-5); 1 turns
    /// it off.
    pub reverse_ratio: f64,
    /// Dynamic method: length of a regression segment (own intercept, integrals restarted), s
    /// (default 1.0).
    pub segment_s: f64,
    /// Dynamic method: prior 1-sigma of each axis of the accelerometer's bias in the
    /// navigation's bias state, m/s^2 (> 0 also switches the depth aid to the Kalman filter;
    /// 0 turns the state off and leaves the bias folded into the starting attitude). Default
    /// 0.02. It used to lose noise-free (err_acc 0.012 -> 0.020): it was absorbing the body's
    /// rise during the rest, which the navigation now starts from (`navigation::rest_drift`).
    /// Since then (AMOUR-5, seeds 1-5 or 1-10, docs/study.md): noise-free 0.0152 / 0.0115 ->
    /// 0.0148 / 0.0116; 0.2 m/s^2 of bias 0.0181 / 0.0270 -> 0.0151 / 0.0216; and the damping
    /// and restoring coefficients' standard errors cover their error at a realistic IMU (2
    /// sigma: 0.83 / 0.65 of cases -> 0.93 / 0.90). Not in the refinement's windows, which
    /// start mid-manoeuvre (`refinement::open_window`).
    pub accel_bias_std: f64,
    /// Dynamic method: relative error of B that no amount of data removes, added in quadrature
    /// to the standard errors (spread evenly over a block's entries) and so to the bound
    /// (default 0.02: noise-free the fit is 1.4-1.7 % off the simulator's symmetric truth on
    /// every vehicle, the linear model of a thruster weaker in reverse; docs/study.md). Not
    /// applied under control, where forward and reverse thrust are fitted apart.
    pub model_error_floor: f64,
    /// Dynamic method: standard deviation of a zero-mean Gaussian prior on every damping,
    /// restoring and Coriolis coefficient (all terms but the constant and the mean |command|),
    /// per unit term; 0 turns it off (the default). Why it exists: an estimation near level
    /// leaves collinear pairs (down_z with the constant, |v|v with v^2) free to cancel at
    /// hundreds per unit, which predict nonsense away from level; a prior of 3 brings the
    /// roll and yaw rows' innovation through +-20 deg pitch steps from 0.32-0.67 to
    /// 0.25-0.48 rad/s (the oracle's 0.25) but the pitch row's from 0.32-0.44 to 0.58-0.67:
    /// one width for all terms is wrong for the large real ones (the Munk moment's 33).
    /// Measured in docs/experiments.md ("Why the learned model is blind through manoeuvres").
    pub term_prior_sd: f64,
    /// Research hook, not a configuration key (never read from or written to a file): the
    /// terms' prior centred here instead of at 0 (6 x TERMS, the layout of
    /// `DynamicTerms::coefficients`), with `term_prior_sd` its width. Why: the decisive run
    /// for where a swell's bias enters B, the terms held at the simulator's own (the lab's
    /// `study/sweep/true_terms.rs`; docs/study.md, "The first cycle against the whole run").
    #[serde(skip)]
    pub term_prior_mean: Option<nalgebra::DMatrix<f64>>,
    /// Dynamic method: standard deviation of a zero-mean Gaussian prior on the coefficients of
    /// the terms with the body velocity in them (linear and quadratic damping in v, the
    /// products nu_i nu_j with a velocity), per unit term, where `term_prior_sd` is wider or
    /// off; default 0.1, 0 turns it off. Applied in the open loop only, and only where a long
    /// idle rest saw still water (`Estimator::with_rest_water`, which the machine gives from
    /// `machine.max_still_sway`); otherwise off. Why: at the paper's noise the dead-reckoned
    /// velocity is 0.6-2.5 m/s off where the vehicle moves a few tenths, and the velocity
    /// terms' nuisance was most of the bound; at 0.1, still water after a long rest took 5.60 s
    /// instead of 6.52 s (five vehicles x 10 seeds) with errors 0.038 / 0.062 against
    /// 0.045 / 0.065 and the bound as honest on the RMS. Under control, where the vehicle
    /// hardly moves, it changed the identification (16 core tests moved); in a swell at the
    /// paper's noise it doubled the models over 1.5x their bound (14 -> 31 of 141), a swell
    /// only a long rest sees there (docs/study.md, "The velocity terms held where a long rest
    /// saw still water").
    pub velocity_term_prior_sd: f64,
    /// Research hook, not a configuration key: disturbance states in the dynamic fit
    /// (`estimator::dynamic::disturbance_states`: a swell at a given frequency, a constant
    /// force fixed in the world), columns with a free coefficient per DOF row. Why: the
    /// decisive run for issue 32 item 3, whether forcing states in the model remove a swell's
    /// bias and make the bound honest (docs/study.md, "Disturbance states").
    #[serde(skip)]
    pub disturbance: crate::estimator::dynamic::disturbance_states::DisturbanceStates,
    /// Dynamic method, open loop: in moving water (the fit leaves rotation unexplained
    /// beyond the gyro's noise by `estimator::MOVING_WATER_REFIT_RADPS`) the log is
    /// fitted again with a swell at this frequency as disturbance states (sin and cos per
    /// DOF row, `estimator::dynamic::disturbance_states`), the lag searched again with them,
    /// and that fit is the estimate. Hz, default 0.15; 0: off; at most 1. Why: the swell's
    /// moment went into the rotation rows; over 300 swell flights the kept models' mean
    /// error 0.037 / 0.049 -> 0.014 / 0.029, over 1.5x their bound 34 of 125 -> 6 of 122
    /// (the refit's bound kept no tighter than the fit's without states, whose row groups'
    /// lag gap the machine reads); still water is never refitted (identical to the digit),
    /// and any frequency from 0.05 to 0.3 Hz does alike over a run of seconds
    /// (docs/study.md, "Disturbance states").
    pub moving_water_swell_hz: f64,
    /// Where a long idle rest saw the water move (`machine.max_still_sway`) and the gyro is
    /// quiet enough to learn the lag (`spin_up_max_gyro_sigma`), the open-loop fit is made
    /// again with the moving-water states and a world-fixed constant force and ramp
    /// (`dynamic::disturbance_states`), whatever rotation it leaves unexplained; its bound no
    /// tighter than the fit's without them (default true). Why: a 10 N tether met after two
    /// minutes' idle left 10 of 30 models over 1.5x their bound noise-free and 19 at a
    /// realistic IMU (up to 4.5x), with too little rotation unexplained to open the refit;
    /// with this 0 and 2 (2.1x), and of 300 swell flights after the same idle 2 over against
    /// 4. Not at the paper's noise: there the 30 more columns took the rotation rows from
    /// 0.047 to 0.059 off in a swell. Not after a short rest: from a 1-2 s rest the constant
    /// and ramp put 6 swell models over against 3 (docs/study.md, "The water a long rest
    /// saw").
    pub moving_rest_drift_states: bool,
    /// Research hook, not a configuration key: other states for that refit than the swell's
    /// (`moving_water_swell_hz` then ignored), for the lab's decisive runs.
    #[serde(skip)]
    pub moving_water_states: crate::estimator::dynamic::disturbance_states::DisturbanceStates,
    /// Research hook, not a configuration key: the moving-water refit reports the rotation
    /// its own fit leaves unexplained (what the machine's water check reads) instead of the
    /// fit's without states.
    #[serde(skip)]
    pub water_after_states: bool,
    /// Research hook: the unexplained rotation from the fit's residual alone, not from the
    /// larger of it and the rest's noise.
    #[serde(skip)]
    pub water_from_residual: bool,
    /// Dynamic method: the IMU's position from the vehicle's centre (its centre of mass, what
    /// the rates pivot about), body frame (x forward, y starboard, z down), m, from the
    /// vehicle's drawings (default [0, 0, 0]). The acceleration rows are referred from the
    /// IMU to the centre with it. Why: an IMU 10 cm forward made them 144 % off while the
    /// bound said 2 % (issue 32; `estimator::dynamic::imu_position`).
    pub imu_position_m: [f64; 3],
    /// Dynamic method: check `imu_position_m` against the data, which finds the IMU's position
    /// from the vehicle's centre of mass (default true). When an axis differs by more than
    /// `imu_position_tolerance_m` (plus 3 of the data's standard deviations), the learned
    /// position is used, the estimate says so, and the bound counts the tolerance;
    /// otherwise the configured one is used and the bound counts the gap.
    pub learn_imu_position: bool,
    /// Dynamic method, open loop: fit each thruster's forward and reverse gain apart (2N
    /// thrust columns, as the closed-loop identification does) instead of one gain and a
    /// shared mean-|command| term; the model's B is their mean. Default false. Measured
    /// (docs/study.md, "T200 thrusters on a sagging pack", the split columns): thrusters weak
    /// in reverse and curved ones come inside 0.02 noise-free where one column is 0.03; what
    /// it costs at the paper's noise is in the same section.
    pub split_thrust: bool,
    /// Dynamic method, open loop, one column: fit each thruster's gain to the thrust its
    /// command makes under `reverse_ratio` (u (1 + k) forward, u (1 - k) reverse, k = (1 -
    /// r) / (1 + r)) rather than to the bare command, so B is the mean of the forward and
    /// reverse gains; the model carries k, the change test predicts with it and the
    /// controller commands through it (a forward command 1 / (1 + k) of the bare one). Default
    /// true (since 2026-12-03). Why: the pulses' forward level is `reverse_ratio` times the
    /// reverse one, which mixes each thruster's asymmetry into its one gain, 1.5 % low on
    /// T200-like thrusters (docs/study.md, "The thrust's shape in the one column": noise-free
    /// 0.016 -> 0.002 on AMOUR-5). Issue 29's lag table at a realistic IMU, seeds 1-10: 4 of
    /// 120 runs over 0.03 against 9 bare; every untold reverse ratio and dead band within 0.02
    /// noise-free (bare: 0.030 at a ratio of 0.6). The cost: a ratio the daemon is told wrong
    /// the other way (0.95) 0.013 instead of 0.003, and eight_vectored's acceleration rows
    /// with an offset IMU 13 % worse on the mean (docs/study.md, "The shape on by default").
    pub shaped_thrust: bool,
    /// Dynamic method: how far, m, the centre of mass may sit from the point
    /// `imu_position_m` is measured from (default 0.03): a gap within it is the drawings'
    /// origin, not a wrong position.
    pub imu_position_tolerance_m: f64,
    /// Dynamic method, doublet pairs: the level, as a fraction of the pulse's, of half of
    /// each thruster's entries (thruster i in Hadamard row k fires at it when i + k is odd, a
    /// checkerboard that keeps the design orthogonal); 1 fires every entry at the pulse's
    /// level. Why: with one level per direction a thrust curve (thrust ~ command^p) and a
    /// reverse ratio look alike and the open-loop model is right at the pulses' level only
    /// (eight_vectored_lag80ms_curve 8 % off under a 2 % bound); two levels let the fit see
    /// the curve: the open-loop estimate learns its exponent and carries it
    /// (`Estimator::with_learned_curve`; that file at 0.6, seeds 1-5: the exponent 1.487-1.500
    /// for 1.5, the model 0.026-0.043 off under 0.062-0.065, where one level gave 0.083-0.089
    /// under 0.020). Default 1 (off): at a realistic IMU the second level costs linear
    /// vehicles accuracy (four_up 0.028 -> 0.041, amour5_lag200ms 0.027 -> 0.048, seeds 1-5)
    /// and eight_vectored 0.55 s (docs/study.md, "A second level: the open loop sees the
    /// curve").
    pub second_amplitude: f64,
    /// Dynamic method, open loop, with the gyro too noisy to learn the lag
    /// (`spin_up_max_gyro_sigma`): once the run stops, its log is fitted again this many
    /// times with draws of the navigation's own errors for the noise the rest measured, and
    /// the acceleration rows' bound and standard errors take B's spread over them in
    /// quadrature (`estimator::dynamic::navigation_error`); the stop rule does not wait on
    /// it. Default 16; 0: off; at most 256. Why: at the paper's noise the acceleration rows
    /// were 1.25x their bound on the RMS (AMOUR-5, six_dof, eight_vectored, seeds 1-10), 1.01
    /// with the spread; the rotation rows were covered without it (0.96). Below that gyro
    /// noise the spread is a fifth of the 0.02 model-error floor and is not drawn
    /// (docs/study.md, "The navigation's errors in the bound").
    pub navigation_error_draws: usize,
    /// Dynamic method, open loop, where a long rest saw the vehicle move and the moving-water
    /// refit is made with the drift states (`moving_rest_drift_states`): that refit also
    /// searches a steady horizontal velocity through the water at the run's start, fixed in
    /// the world, up to this speed (m/s), and keeps it where the log supports it
    /// ([`START_VELOCITY_EVIDENCE`](crate::estimator::START_VELOCITY_EVIDENCE)); 0: off; at
    /// most 5. Why: the navigation starts from zero at the rest, and a vehicle a tether tows
    /// at a steady speed is at rest to an accelerometer (docs/study.md, "A tether's tow at
    /// the start"). Default 1.5: on a 10 N tether it took the realistic models over 1.5x their
    /// bound from 2 of 30 to 0, noise-free every vehicle file as close to the truth or closer
    /// (eight_vectored_lag100_120ms, thrusters of two lags, once 2.35x its bound with it: the
    /// lags searched again on the moved log now start from those found before the move too,
    /// "The lags searched again after the tow"), the swell's flights and still water as
    /// before or better.
    pub start_velocity_search_mps: f64,
    /// The stopping open loop's model, in still water at a gyro quiet enough to learn the lag,
    /// made again with the dead-reckoned velocity's drift taken out: a horizontal ramp fixed
    /// in the world from the run's start, its rate searched up to this (m/s^2) and kept where
    /// the log supports it ([`VELOCITY_DRIFT_EVIDENCE`](crate::estimator::VELOCITY_DRIFT_EVIDENCE));
    /// 0: off; at most 1. Why: a tilt of a milliradian left after the rest leaks gravity into
    /// the velocity the damping acts on, and on AMOUR-5's slow thrusters it moved the lag
    /// learned by 4 ms and the model to 0.038 off (docs/study.md, "The velocity's drift
    /// searched, and a reach for slow thrusters"). Default 0.04 (four times the largest true
    /// drift measured at a realistic IMU): that seed 0.016 / 0.021 off; noise-free every
    /// vehicle file within 0.0001 of before.
    pub velocity_drift_search_mps2: f64,
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        EstimatorConfig {
            method: Method::Dynamic,
            excitation: Excitation::DoubletPairs,
            k_sigma: 3.0,
            initial_power: 1.0,
            pulse_snr: 20.0,
            min_power: 0.2,
            power_step: 0.1,
            max_power: 1.0,
            target_rel_err: 0.06,
            target_rel_err_acc: Some(0.07),
            reach_rel_err: 0.03,
            learned_lag_reach_rel_err: 0.025,
            min_cycles: 1,
            stop_once_spanned: false,
            max_pulses: 80,
            paper_cycles: 1,
            spin_up_s: 0.1,
            learn_spin_up: true,
            spin_up_range_s: [0.01, 0.5],
            spin_up_max_gyro_sigma: 0.05,
            thruster_lag_evidence: 100.0,
            learn_thruster_lags: true,
            thruster_lag_floor: 0.05,
            check_configured_lag: true,
            lag_check_ratio: [0.6, 1.05],
            lag_check_z: 2.0,
            baseline_samples: 20,
            detrend: false,
            rank_threshold: 1.5,
            dof_priority: [
                Dof::Roll,
                Dof::Pitch,
                Dof::Yaw,
                Dof::Heave,
                Dof::Surge,
                Dof::Sway,
            ],
            response_chi2: 22.46,
            dead_min_command: 0.95,
            diagnosis_z: 4.0,
            reverse_ratio: 0.78,
            segment_s: 1.0,
            accel_bias_std: 0.02,
            model_error_floor: 0.02,
            term_prior_sd: 0.0,
            term_prior_mean: None,
            velocity_term_prior_sd: 0.1,
            disturbance: Default::default(),
            moving_water_swell_hz: 0.15,
            moving_rest_drift_states: true,
            moving_water_states: Default::default(),
            water_after_states: false,
            water_from_residual: false,
            imu_position_m: [0.0; 3],
            learn_imu_position: true,
            split_thrust: false,
            shaped_thrust: true,
            imu_position_tolerance_m: 0.03,
            second_amplitude: 1.0,
            navigation_error_draws: 16,
            start_velocity_search_mps: 1.5,
            velocity_drift_search_mps2: 0.04,
        }
    }
}

/// A setting outside its meaningful range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("estimator.{key}: {why}")]
pub struct ConfigError {
    pub key: &'static str,
    pub why: String,
}

impl EstimatorConfig {
    /// The dynamic method with the settings measured best on the simulator (docs/study.md):
    /// doublet pairs at full power, stop at a 0.06 bound or 80 pulses (8 s). The default.
    pub fn dynamic() -> Self {
        EstimatorConfig::default()
    }

    /// The static forward method with the settings it was tuned with (orthogonal pulses with
    /// settles, power 0.8, stop at a 0.1 bound, 64 pulses): the idealised study, the paper's
    /// comparisons and its own tests use these.
    pub fn forward() -> Self {
        EstimatorConfig {
            method: Method::Forward,
            excitation: Excitation::Orthogonal,
            initial_power: 0.8,
            target_rel_err: 0.1,
            max_pulses: 64,
            ..EstimatorConfig::default()
        }
    }

    /// The acceleration rows' stop target: the dynamic method's `target_rel_err_acc`, else
    /// `target_rel_err` (the static methods were tuned with one target for both).
    pub fn acc_target(&self) -> f64 {
        match (self.method, self.target_rel_err_acc) {
            (Method::Dynamic, Some(t)) => t,
            _ => self.target_rel_err,
        }
    }

    /// The disturbance states of the moving-water refit: the research hook's when it names
    /// any, else the swell at `moving_water_swell_hz` (none at 0).
    pub fn moving_water_states(
        &self,
    ) -> crate::estimator::dynamic::disturbance_states::DisturbanceStates {
        if self.moving_water_states.any() {
            return self.moving_water_states;
        }
        crate::estimator::dynamic::disturbance_states::DisturbanceStates {
            swell_hz: (self.moving_water_swell_hz > 0.0).then_some(self.moving_water_swell_hz),
            ..Default::default()
        }
    }

    /// (key under `[estimator]`, value, allowed range) of every number; the config file's
    /// checker locates a failing one in the file.
    pub fn checks(&self) -> [(&'static str, f64, Range); 42] {
        [
            ("k_sigma", self.k_sigma, Range::above(0.0)),
            (
                "initial_power",
                self.initial_power,
                Range::above_to(0.0, 1.0),
            ),
            (
                "max_power",
                self.max_power,
                Range::closed(self.initial_power, 1.0),
            ),
            ("pulse_snr", self.pulse_snr, Range::at_least(0.0)),
            ("min_power", self.min_power, Range::above_to(0.0, 1.0)),
            ("power_step", self.power_step, Range::at_least(0.0)),
            ("target_rel_err", self.target_rel_err, Range::above(0.0)),
            ("target_rel_err_acc", self.acc_target(), Range::above(0.0)),
            ("reach_rel_err", self.reach_rel_err, Range::at_least(0.0)),
            (
                "learned_lag_reach_rel_err",
                self.learned_lag_reach_rel_err,
                Range::at_least(0.0),
            ),
            ("min_cycles", self.min_cycles as f64, Range::at_least(1.0)),
            ("max_pulses", self.max_pulses as f64, Range::at_least(1.0)),
            (
                "paper_cycles",
                self.paper_cycles as f64,
                Range::at_least(1.0),
            ),
            ("spin_up_s", self.spin_up_s, Range::closed(0.0, 2.0)),
            (
                "spin_up_range_s",
                self.spin_up_range_s[0],
                Range::closed(1e-3, 2.0),
            ),
            (
                "spin_up_range_s",
                self.spin_up_range_s[1],
                Range::closed(1e-3, 2.0),
            ),
            (
                "spin_up_max_gyro_sigma",
                self.spin_up_max_gyro_sigma,
                Range::at_least(0.0),
            ),
            (
                "thruster_lag_floor",
                self.thruster_lag_floor,
                Range::closed(0.0, 1.0),
            ),
            (
                "thruster_lag_evidence",
                self.thruster_lag_evidence,
                Range::at_least(0.0),
            ),
            (
                "lag_check_ratio",
                self.lag_check_ratio[0],
                Range::above_to(0.0, 1.0),
            ),
            (
                "lag_check_ratio",
                self.lag_check_ratio[1],
                Range::closed(self.lag_check_ratio[0], 2.0),
            ),
            ("lag_check_z", self.lag_check_z, Range::closed(0.0, 10.0)),
            ("rank_threshold", self.rank_threshold, Range::above(0.0)),
            ("response_chi2", self.response_chi2, Range::above(0.0)),
            (
                "dead_min_command",
                self.dead_min_command,
                Range::above_to(0.0, 1.0),
            ),
            ("diagnosis_z", self.diagnosis_z, Range::above(0.0)),
            (
                "reverse_ratio",
                self.reverse_ratio,
                Range::above_to(0.0, 1.0),
            ),
            ("segment_s", self.segment_s, Range::closed(0.05, 60.0)),
            (
                "moving_water_swell_hz",
                self.moving_water_swell_hz,
                Range::closed(0.0, 1.0),
            ),
            (
                "navigation_error_draws",
                self.navigation_error_draws as f64,
                Range::closed(0.0, 256.0),
            ),
            (
                "start_velocity_search_mps",
                self.start_velocity_search_mps,
                Range::closed(0.0, 5.0),
            ),
            (
                "velocity_drift_search_mps2",
                self.velocity_drift_search_mps2,
                Range::closed(0.0, 1.0),
            ),
            (
                "second_amplitude",
                self.second_amplitude,
                Range::above_to(0.0, 1.0),
            ),
            (
                "accel_bias_std",
                self.accel_bias_std,
                Range::closed(0.0, 2.0),
            ),
            (
                "model_error_floor",
                self.model_error_floor,
                Range::closed(0.0, 1.0),
            ),
            ("term_prior_sd", self.term_prior_sd, Range::closed(0.0, 1e6)),
            (
                "velocity_term_prior_sd",
                self.velocity_term_prior_sd,
                Range::closed(0.0, 1e6),
            ),
            // The protocol's bound on a thruster's distance from the centre holds the IMU too.
            (
                "imu_position_m",
                self.imu_position_m[0],
                Range::closed(-MAX_POSITION_M, MAX_POSITION_M),
            ),
            (
                "imu_position_m",
                self.imu_position_m[1],
                Range::closed(-MAX_POSITION_M, MAX_POSITION_M),
            ),
            (
                "imu_position_m",
                self.imu_position_m[2],
                Range::closed(-MAX_POSITION_M, MAX_POSITION_M),
            ),
            (
                "imu_position_tolerance_m",
                self.imu_position_tolerance_m,
                Range::closed(0.0, MAX_POSITION_M),
            ),
            // At most 10 s of quiet at 1 kHz: the window is allocated when a run starts, and
            // an unbounded count (1e11 passed the check) aborted the daemon there.
            (
                "baseline_samples",
                self.baseline_samples as f64,
                Range::closed(0.0, MAX_BASELINE_SAMPLES as f64),
            ),
        ]
    }

    /// Check ranges that serde cannot express.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (key, v, range) in self.checks() {
            if !range.contains(v) {
                return Err(ConfigError {
                    key,
                    why: format!("must be in {range}, got {v}"),
                });
            }
        }
        let [lo, hi] = self.spin_up_range_s;
        if lo * 1.1 > hi {
            return Err(ConfigError {
                key: "spin_up_range_s",
                why: format!(
                    "the first value must be below the second by 10 % or more, got [{lo}, {hi}]"
                ),
            });
        }
        self.check_dof_priority()
    }

    /// `dof_priority` names each DOF once.
    pub fn check_dof_priority(&self) -> Result<(), ConfigError> {
        if Dof::ALL.iter().any(|d| !self.dof_priority.contains(d)) {
            return Err(ConfigError {
                key: "dof_priority",
                why: format!(
                    "must name each of roll, pitch, yaw, surge, sway, heave once, got {:?}",
                    self.dof_priority
                ),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_parse_from_empty_toml() {
        let c: EstimatorConfig = toml::from_str("").unwrap();
        assert_eq!(c, EstimatorConfig::default());
        c.validate().unwrap();
    }

    #[test]
    fn unknown_key_and_bad_value_are_named() {
        let e = toml::from_str::<EstimatorConfig>("k_sigmaa = 3.0").unwrap_err();
        assert!(e.to_string().contains("k_sigmaa"), "{e}");
        let c: EstimatorConfig = toml::from_str("method = \"paper\"\ninitial_power = 1.5").unwrap();
        let e = c.validate().unwrap_err();
        assert_eq!(e.key, "initial_power");
        assert_eq!(
            e.to_string(),
            "estimator.initial_power: must be in (0, 1], got 1.5"
        );
        // A count allocated when a run starts: refused here, not as an abort there.
        let c: EstimatorConfig = toml::from_str("baseline_samples = 100000000000").unwrap();
        let e = c.validate().unwrap_err();
        assert_eq!(e.key, "baseline_samples");
        assert!(e.to_string().contains("[0, 10000]"), "{e}");
    }
}
