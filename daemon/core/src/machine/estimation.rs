//! One estimation run, as the machine drives it: the noise at rest, then the pulses and the
//! pauses between them, then the candidate model. It owns the noise meter, the noise levels,
//! the estimator and the last estimate; the machine owns the states and when they change.

use nalgebra::Vector3;
use thruster_protocol::MAX_THRUSTERS;

use super::config::MachineSetup;
use crate::adaptation::identification::IdentificationConfig;
use crate::estimator::dynamic::prior::DynamicPrior;
use crate::estimator::power::pulse_power;
use crate::estimator::response::GRAVITY;
use crate::estimator::{
    Estimate, Estimator, EstimatorConfig, Method, NoiseLevels, NoiseMeter, Settle, StopDecision,
};
use crate::model::{Model, ModelSource};
use crate::navigation::long_rest_bias::RestBias;
use crate::navigation::long_rest_down::LongRestDown;
use crate::navigation::long_rest_sway::RestWater;
use crate::navigation::rest_drift::RestDrift;
use crate::navigation::rest_rotation::RestRotation;
use crate::navigation::rest_shape::RestShape;

mod closed_loop;
mod idle_rest;
pub use closed_loop::Excitation;
pub(super) use closed_loop::{ClosedLoop, ClosedStep};
pub(super) use idle_rest::{IdleRest, TakenRest};

use crate::solve::{Purpose, SolveResult, Solver};

/// The fewest samples a noise measurement is made of, however short `noise_s` is.
pub(super) const MIN_REST_SAMPLES: u64 = 10;

/// A rest that saw the vehicle pushed starts over until the noise measurement is this old, s;
/// then the excitation begins anyway. eight_vectored meeting a 0.3 m/s current is seen pushed
/// over its first second in it and not over the second after (`navigation::rest_shape`): one
/// restart.
pub(super) const MAX_PUSHED_WAIT_S: f64 = 10.0;

/// A rest that swings from the thrusters' last push (`machine.max_rest_swing_radps`) starts
/// over until the thrusters have been neutral this long, s; then the rest is taken as it is.
/// Why 10: AMOUR-5, six_dof and four_up swing down to the default limit in 4-7 s after an
/// emergency stop in their pulses (docs/reliability.md); a swing that outlasts 10 s is the
/// water's, which waiting does not end.
pub(super) const MAX_SWING_WAIT_S: f64 = 10.0;

/// The estimation run's owner number for its solver (see `solve::owner_of`).
pub(super) const ESTIMATION: u64 = 0;

/// One IMU sample as the run uses it: the body rate and the gravity-compensated acceleration.
#[derive(serde::Serialize, serde::Deserialize)]
pub(super) struct Motion {
    pub(super) gyro: Vector3<f64>,
    pub(super) accel: Vector3<f64>,
    /// The raw accelerometer reading (specific force), m/s^2.
    pub(super) specific_force: Vector3<f64>,
    pub(super) depth: Option<f64>,
    /// The magnetometer (any unit), when the IMU has one.
    pub(super) mag: Option<Vector3<f64>>,
}

/// What one sample during a pulse led to.
#[derive(serde::Serialize, serde::Deserialize)]
pub(super) enum PulseStep {
    /// No estimator or no noise levels: there is no run to pulse.
    NoRun,
    /// The pulse goes on (its thrust was written).
    Pulsing,
    /// The pulse ended. `gate`: the stop decision when the counts alone make it (see
    /// `Estimator::stop_gate`); None when the estimate's error bound decides, which takes a
    /// solve (a job, `crate::solve`).
    Ended {
        gate: Option<StopDecision>,
        pulses: usize,
    },
}

#[derive(Clone, serde::Serialize, serde::Deserialize)]
pub(super) struct EstimationRun {
    noise: NoiseMeter,
    levels: Option<NoiseLevels>,
    est: Option<Estimator>,
    last_estimate: Option<Estimate>,
    quiet_since_ns: Option<u64>,
    /// What the noise measurement (or the hold before an identification) saw.
    rest: Rest,
    /// Rest taken before the run began (while idle, `IdleRest`), s: counted towards
    /// `machine.noise_s`.
    rested_s: f64,
    /// When the rest being measured began, s into the noise measurement: later than 0 once a
    /// rest that saw the vehicle pushed was started over (`MAX_PUSHED_WAIT_S`).
    #[serde(default)]
    rest_from_s: f64,
    /// How often the rest was started over for a push.
    #[serde(default)]
    rest_restarts: u32,
    /// How often the rest was started over for a swing the thrusters left
    /// (`MAX_SWING_WAIT_S`).
    #[serde(default)]
    swing_restarts: u32,
    /// The gyro's bias over a long idle spell before the run (`machine.gyro_bias_rest_s`):
    /// stands for the rest's when there is one.
    idle_gyro_bias: Option<RestBias>,
    /// With it, the long idle rest's average of "down", carried on through the noise
    /// measurement: where the navigation starts.
    idle_down: Option<LongRestDown>,
    /// With it, how much the vehicle swayed over that long rest beyond the IMU's white noise
    /// (`navigation::long_rest_sway`; 1: still).
    idle_sway: Option<f64>,
    /// Under control (state Identify): the dither and its clock.
    closed: Option<ClosedLoop>,
    /// This open-loop run is a burst: its model is refined under control next.
    burst: bool,
    /// What the run keeps from the model before a known change (`identification::carry_over`).
    prior: Option<DynamicPrior>,
    /// The run's solves, out as jobs and back as results applied at their due sample.
    solver: Solver,
}

impl EstimationRun {
    pub(super) fn new(solve_budget_s: f64) -> Self {
        EstimationRun {
            solver: Solver::new(solve_budget_s, ESTIMATION),
            noise: NoiseMeter::new(),
            levels: None,
            est: None,
            last_estimate: None,
            quiet_since_ns: None,
            rest: Rest::default(),
            rested_s: 0.0,
            rest_from_s: 0.0,
            rest_restarts: 0,
            swing_restarts: 0,
            idle_gyro_bias: None,
            idle_down: None,
            idle_sway: None,
            closed: None,
            burst: false,
            prior: None,
        }
    }

    /// The run about to start keeps these coefficients as its prior (None: learns everything).
    /// Under control, the dither then goes to the thrusters the prior knows nothing about, at
    /// `identification.focus_gain` times the amplitude and the others' at `focus_others` times.
    pub(super) fn carry(&mut self, prior: Option<DynamicPrior>, cfg: &IdentificationConfig) {
        if let (Some(p), Some(c)) = (&prior, self.closed.as_mut()) {
            if cfg.focus_gain > 0.0 {
                c.dither
                    .focus(&p.unknown_thrusters(), cfg.focus_gain, cfg.focus_others);
            }
        }
        self.prior = prior;
    }

    /// The prior the run under way keeps (`carry`).
    pub(super) fn prior(&self) -> Option<&DynamicPrior> {
        self.prior.as_ref()
    }

    /// The estimator for this run, with the nominal model of a declared geometry (to check
    /// directions against) and the carried-over prior.
    fn new_estimator(
        &self,
        cfg: EstimatorConfig,
        n: usize,
        levels: NoiseLevels,
        model: Option<&Model>,
    ) -> Estimator {
        let mut est = self.rest.start(Estimator::new(cfg, n, levels));
        if let Some(down) = self.idle_down.as_ref().and_then(LongRestDown::down) {
            // The long idle rest's "down" (`navigation::long_rest_down`), not the short one's
            // last reading: in a swell that carries the swell's acceleration.
            est = est.with_rest_specific_force(-down * GRAVITY);
        }
        if let Some(nominal) = model.filter(|m| m.source == ModelSource::Nominal) {
            est = est.with_nominal(nominal.effectiveness.clone());
        }
        if let Some(p) = &self.prior {
            est = est.with_prior(p.clone());
        }
        est
    }

    /// The rest measured so far is dropped; the noise measurement goes on from `elapsed_s`.
    fn start_rest_over(&mut self, elapsed_s: f64) {
        self.noise = NoiseMeter::new();
        self.rest = Rest::default();
        self.rested_s = 0.0;
        self.rest_from_s = elapsed_s;
    }

    /// A new run begins: the noise is measured afresh.
    pub(super) fn restart(&mut self) {
        self.solver.cancel();
        self.noise = NoiseMeter::new();
        self.rest = Rest::default();
        self.rested_s = 0.0;
        self.rest_from_s = 0.0;
        self.rest_restarts = 0;
        self.swing_restarts = 0;
        self.idle_gyro_bias = None;
        self.idle_down = None;
        self.idle_sway = None;
        self.est = None;
        self.closed = None;
        self.burst = false;
        self.prior = None;
    }

    /// The run just begun starts from the rest the vehicle took while idle: its noise and
    /// rest stand for (the first part of) the noise measurement.
    pub(super) fn adopt_rest(&mut self, taken: TakenRest) {
        self.noise = taken.noise;
        self.rest = taken.rest;
        self.rested_s = taken.span_s;
        self.idle_gyro_bias = taken.gyro_bias;
        self.idle_down = taken.down;
        self.idle_sway = taken.sway;
    }

    /// How much the vehicle swayed over the long idle rest this run started from, beyond the
    /// IMU's white noise (1: still; None: no long rest).
    pub(super) fn idle_sway(&self) -> Option<f64> {
        self.idle_sway
    }

    /// What that long rest read of the water against `max_still` (`machine.max_still_sway`;
    /// None: no long rest, or the limit 0). What hangs on it: the velocity terms' prior where
    /// still (its tighter bound honest in still water at the paper's noise but not in a swell
    /// there, which nothing shorter than a long rest sees), the drift states where moved
    /// (docs/study.md, "The velocity terms held where a long rest saw still water", "The water
    /// a long rest saw").
    pub(super) fn idle_water(&self, max_still: f64) -> Option<RestWater> {
        RestWater::read(self.idle_sway?, max_still)
    }

    /// Whether the run that just concluded was an open-loop burst to be refined under control.
    pub(super) fn was_burst(&self) -> bool {
        self.burst
    }

    /// The run ends without a candidate (abort, fault, idle, hold, reconfiguration).
    pub(super) fn stop(&mut self) {
        self.solver.cancel();
        self.est = None;
        self.closed = None;
    }

    /// The run's solves (jobs out, results in).
    pub(super) fn solver(&mut self) -> &mut Solver {
        &mut self.solver
    }

    /// The job a sample at `t_ns` needs and whose result is not back.
    pub(super) fn awaiting(&self, t_ns: u64) -> Option<u64> {
        self.solver.awaiting(t_ns)
    }

    /// Jobs out with the caller, result not back (see `Solver::out_with_caller`).
    pub(super) fn jobs_out(&self) -> usize {
        self.solver.out_with_caller()
    }

    pub(super) fn late_solves(&self) -> u64 {
        self.solver.late()
    }

    /// Whether the run waits for a result of this kind.
    pub(super) fn waiting_for(&self, purpose: Purpose) -> bool {
        self.solver.waiting_for(purpose)
    }

    /// Submit a solve of the run as it stands at `t_ns` (after a pulse, `purpose` saying what
    /// the result is for). False when there is no run, or (a progress estimate only) when the
    /// queue is full: a progress estimate is skipped then, status shows the previous one.
    pub(super) fn submit_pulse(&mut self, t_ns: u64, purpose: Purpose, key: Option<u64>) -> bool {
        let Some(est) = self.est.as_ref() else {
            return false;
        };
        if purpose == Purpose::Progress && !self.solver.has_room() {
            return false;
        }
        self.solver.submit_pulse(est, t_ns, purpose, key);
        true
    }

    /// Submit a decision interval's solve under control (see `closed_loop_sample`).
    pub(super) fn submit_interval(
        &mut self,
        t_ns: u64,
        elapsed_s: f64,
        setup: &MachineSetup,
        key: Option<u64>,
    ) -> bool {
        let Some(est) = self.est.as_ref() else {
            return false;
        };
        let cfg = &setup.identification;
        // A fight (the dither under its share) has its own confirmation: waiting for it to
        // settle would only prolong the fight (`IdentificationConfig::settle`).
        let fighting = self
            .excitation()
            .is_some_and(|x| x.dither_share() < cfg.min_dither_share);
        let settle = if fighting {
            Settle::OFF
        } else {
            cfg.settle_rule()
        };
        let min_s = self.shortest_s(cfg);
        self.solver
            .submit_interval(est, t_ns, (elapsed_s, min_s, cfg.max_s, settle), key);
        true
    }

    /// A result applied: its estimate is the run's latest.
    /// The lag an applied estimate learned, for the run's next progress estimates.
    pub(super) fn hint_lag(&mut self, estimate: &Estimate) {
        if let Some(est) = self.est.as_mut() {
            est.set_lag_hint(estimate);
        }
    }

    /// A decision interval's estimate that did not stop the run: the next decision judges
    /// whether the estimate has settled against it (`IdentificationConfig::settle`).
    pub(super) fn remember_interval(&mut self, estimate: &Estimate, elapsed_s: f64) {
        if let Some(est) = self.est.as_mut() {
            est.remember_interval(estimate, elapsed_s);
        }
    }

    pub(super) fn keep_estimate(&mut self, estimate: Estimate) {
        self.last_estimate = Some(estimate);
    }

    /// The run pulses back to back (the dynamic method fits through the motion, no settles).
    pub(super) fn back_to_back(&self) -> bool {
        self.est
            .as_ref()
            .is_some_and(|e| e.config().method == Method::Dynamic)
    }

    /// A measured body velocity (a DVL) for the estimation under way.
    pub(super) fn velocity_fix(&mut self, measured: &Vector3<f64>) {
        if let Some(est) = self.est.as_mut() {
            est.push_velocity_fix(measured);
        }
    }

    /// The estimator of the run under way.
    pub(super) fn estimator(&self) -> Option<&Estimator> {
        self.est.as_ref()
    }

    pub(super) fn last_estimate(&self) -> Option<&Estimate> {
        self.last_estimate.as_ref()
    }

    /// How often this run's rest started over for a swing the thrusters left
    /// (`MAX_SWING_WAIT_S`).
    pub(super) fn swing_restarts(&self) -> u32 {
        self.swing_restarts
    }

    /// How often this run's rest started over for a push (`MAX_PUSHED_WAIT_S`).
    pub(super) fn rest_restarts(&self) -> u32 {
        self.rest_restarts
    }

    /// The last noise levels measured.
    pub(super) fn levels(&self) -> Option<NoiseLevels> {
        self.levels
    }

    /// One sample at rest, at `t_ns`, into the noise measurement.
    pub(super) fn rest_sample(&mut self, m: &Motion, t_ns: u64) {
        self.noise.push(&m.gyro.into(), &m.accel.into());
        // On the sample clock, so a rest taken while idle (`adopt_rest`) goes on seamlessly.
        self.rest.push(m, t_ns as f64 * 1e-9);
        if let (Some(down), Some(bias)) = (&mut self.idle_down, &self.idle_gyro_bias) {
            down.push(t_ns as f64 * 1e-9, &(m.gyro - bias.bias), &m.specific_force);
        }
    }

    /// The noise measurement, `elapsed_s` into it (its rest samples given to `rest_sample`).
    /// Once it is long enough, the levels are kept and the estimator is built, its first power
    /// sized to the noise with the model in force: then true (pulse now). `power_cap` (in
    /// (0, 1]) bounds every pulse's power: the largest the thrusters can give at the present
    /// supply voltage, so a pulse the estimator believes it applied is the one applied
    /// (`crate::supply`).
    /// `neutral_s`: how long the thrusters have been neutral (None: they never drove the
    /// vehicle).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn measure_noise(
        &mut self,
        elapsed_s: f64,
        neutral_s: Option<f64>,
        setup: &MachineSetup,
        model: Option<&Model>,
        n: usize,
        power_cap: f64,
    ) -> bool {
        let rested_s = elapsed_s - self.rest_from_s + self.rested_s;
        if !(rested_s >= setup.machine.noise_s && self.noise.samples() >= MIN_REST_SAMPLES) {
            return false;
        }
        // A rest that saw the vehicle pushed (a current's drag still taking it) would put the
        // push into the gyro's bias: it starts over, until `MAX_PUSHED_WAIT_S`.
        if self.rest.pushed() && elapsed_s < MAX_PUSHED_WAIT_S {
            self.start_rest_over(elapsed_s);
            self.rest_restarts += 1;
            return false;
        }
        // A rest the thrusters' last push still swings would take the swing for the gyro's
        // noise: it starts over, until they have been neutral `MAX_SWING_WAIT_S`.
        let swing_limit = setup.machine.max_rest_swing_radps;
        if neutral_s.is_some_and(|s| s < MAX_SWING_WAIT_S)
            && swing_limit > 0.0
            && swinging(&self.noise.levels(), swing_limit)
        {
            self.start_rest_over(elapsed_s);
            self.swing_restarts += 1;
            return false;
        }
        let mut levels = self.rest.correct(self.noise.levels());
        let mut bias_sd = None;
        match self
            .idle_gyro_bias
            .map(|long| (long, long_rest_bias(&levels, &long)))
        {
            // The rest moved (a swell): the long idle spell's bias and "down"
            // (`machine.gyro_bias_rest_s`), and that bias's error for the bound.
            Some((long, Some(bias))) => {
                levels.gyro_baseline = bias.into();
                let rate_hz = levels.samples as f64 / rested_s.max(1e-3);
                bias_sd = Some(long_rest_bias_sd(&levels, &long, rate_hz));
            }
            // Still: the short rest's, as fresh as can be (a long one's bias is a minute old).
            _ => self.idle_down = None,
        }
        self.levels = Some(levels);
        let mut cfg = setup.estimator.clone();
        let cap = if power_cap.is_finite() {
            power_cap.clamp(0.05, 1.0)
        } else {
            1.0
        };
        cfg.max_power = cfg.max_power.min(cap);
        cfg.initial_power = cfg.initial_power.min(cap);
        cfg.min_power = cfg.min_power.min(cap);
        // The dynamic method pulses back to back at a fixed strength: its information grows
        // with the motion it fits, not with one pulse's SNR (pulse_power's model).
        let sized = cfg.pulse_snr > 0.0 && cfg.method != Method::Dynamic;
        if let Some(p) = model.filter(|_| sized).and_then(|m| {
            pulse_power(
                &m.effectiveness,
                n,
                &levels,
                setup.machine.pulse_s,
                cfg.pulse_snr,
                cfg.min_power,
                cfg.initial_power,
            )
        }) {
            cfg.initial_power = p;
        }
        // From scratch with closed-loop identification: only a burst, good enough to hold.
        self.burst = model.is_none()
            && Self::closed_loop_possible(setup)
            && setup.identification.burst_rel_err > cfg.target_rel_err;
        if self.burst {
            // Both row groups at the burst's target (the acceleration rows' own target no
            // tighter than it: with it at 0.07 the burst at 0.15 ran to 5.8 s, not 4.6).
            let burst = setup.identification.burst_rel_err;
            cfg.target_rel_err = burst;
            cfg.target_rel_err_acc = cfg.target_rel_err_acc.map(|t| t.max(burst));
        }
        let mut est = self.new_estimator(cfg, n, levels, model);
        if let Some(sd) = bias_sd {
            est = est.with_gyro_bias_sd(sd);
        }
        self.est = Some(match self.idle_water(setup.machine.max_still_sway) {
            Some(water) => est.with_rest_water(water),
            None => est,
        });
        true
    }

    /// Begin the next pulse at `t_ns`, its thrust written into `thrust`, its power no more
    /// than `power_cap`: the pulse's number (None without an estimator).
    pub(super) fn begin_pulse(
        &mut self,
        t_ns: u64,
        power_cap: Option<f64>,
        thrust: &mut [f64; MAX_THRUSTERS],
    ) -> Option<usize> {
        let est = self.est.as_mut()?;
        if let Some(cap) = power_cap {
            est.cap_power(cap);
        }
        let u = est.begin_pulse_at(t_ns as f64 * 1e-9);
        for (o, v) in thrust.iter_mut().zip(u) {
            *o = *v;
        }
        Some(est.pulses() + 1)
    }

    /// One sample `elapsed_s` into a pulse. While the pulse lasts its thrust is written into
    /// `thrust`; at its end the estimate is updated.
    pub(super) fn pulse_sample(
        &mut self,
        t_ns: u64,
        elapsed_s: f64,
        m: &Motion,
        pulse_s: f64,
        thrust: &mut [f64; MAX_THRUSTERS],
    ) -> PulseStep {
        let (Some(est), Some(levels)) = (self.est.as_mut(), self.levels) else {
            return PulseStep::NoRun;
        };
        let gyro_d = levels.gyro_delta(&m.gyro.into());
        let acc_d = levels.accel_delta(&m.accel.into());
        if est.config().method == Method::Dynamic {
            est.push_dynamic_sample(t_ns as f64 * 1e-9, &gyro_d, &m.specific_force, m.depth);
        } else {
            est.push_pulse_sample(elapsed_s, &gyro_d, &acc_d);
        }
        if elapsed_s < pulse_s {
            if let Some(u) = est.current_command() {
                for (o, v) in thrust.iter_mut().zip(u) {
                    *o = *v;
                }
            }
            return PulseStep::Pulsing;
        }
        est.end_pulse();
        // The estimate and the decision it makes are a solve: the machine submits it as a job.
        self.quiet_since_ns = None;
        PulseStep::Ended {
            gate: est.stop_gate(),
            pulses: est.pulses(),
        }
    }

    /// One sample of the pause after a pulse: fed to the estimator as rest. How long every
    /// gyro axis has stayed within k sigma of rest, s (None without noise levels).
    pub(super) fn settle_sample(&mut self, t_ns: u64, m: &Motion, k_sigma: f64) -> Option<f64> {
        let levels = self.levels?;
        let d = levels.gyro_delta(&m.gyro.into());
        if let Some(est) = self.est.as_mut() {
            est.push_rest_sample(t_ns as f64 * 1e-9, &d, &levels.accel_delta(&m.accel.into()));
            est.push_dynamic_sample(t_ns as f64 * 1e-9, &d, &m.specific_force, m.depth);
        }
        let quiet = (0..3).all(|a| d[a].abs() <= k_sigma * levels.gyro_sigma[a].max(1e-6));
        if quiet {
            self.quiet_since_ns.get_or_insert(t_ns);
        } else {
            self.quiet_since_ns = None;
        }
        Some(
            self.quiet_since_ns
                .map(|q| (t_ns - q) as f64 * 1e-9)
                .unwrap_or(0.0),
        )
    }

    /// The run ends with the result that stopped it: its candidate model (made by the job)
    /// and how many pulses it took. None when the result has no candidate.
    pub(super) fn conclude(&mut self, result: SolveResult) -> Option<(Model, usize)> {
        self.solver.cancel();
        self.est = None;
        self.closed = None;
        let SolveResult {
            estimate,
            candidate,
            pulses,
            ..
        } = result;
        self.last_estimate = Some(estimate);
        Some((candidate?, pulses))
    }
}

/// How fast a MEMS gyro's bias walks, rad/s per sqrt(s), for the long rest's test: the
/// simulator's realistic IMU has 5e-5; twice that for a cheaper part.
const GYRO_BIAS_WALK: f64 = 1e-4;

/// The long rest's bias and the short one's further apart than this many of their combined
/// standard deviations say the short rest moved.
const REST_MOVED_SIGMAS: f64 = 4.0;

/// Whether a rest with `levels` swung more than `limit` rad/s on some gyro axis: the part of
/// its spread beyond the white noise (`NoiseLevels::gyro_white_sigma`, from successive
/// differences, which a slow swing hardly moves), with a margin of four of that part's own
/// standard errors in white noise alone (sigma_white^2 / sqrt(samples), by simulation), so
/// that a noisy gyro (the paper's 0.25 rad/s) is not read as swinging.
fn swinging(levels: &NoiseLevels, limit: f64) -> bool {
    let n = levels.samples.max(2) as f64;
    (0..3).any(|a| {
        let white2 = levels.gyro_white_sigma[a].powi(2);
        levels.gyro_sigma[a].powi(2) - white2 > limit * limit + 4.0 * white2 / n.sqrt()
    })
}

/// The long idle spell's bias when the short rest's (in `levels`) is further from it than
/// noise and the bias's walk explain: the short rest moved (a swell rocks a 1-2 s rest, and
/// its mean rate is the swell's). None when they agree: then the short rest's stays, fresher
/// (in still water a realistic IMU's long-rest bias, a minute old, put 0.16 m/s into the
/// navigation's velocity through the "down" it carried, against 0.01: AMOUR-5 0.013 -> 0.018
/// off). Without a magnetometer the long rest sees no part about gravity: the short one's
/// there, and only the parts across it are compared.
fn long_rest_bias(levels: &NoiseLevels, long: &RestBias) -> Option<Vector3<f64>> {
    let short = Vector3::from(levels.gyro_baseline);
    let white = Vector3::from(levels.gyro_white_sigma);
    let n = levels.samples.max(1) as f64;
    let walk2 = GYRO_BIAS_WALK * GYRO_BIAS_WALK * long.span_s / 3.0;
    let mut gap = long.bias - short;
    let mut bias = long.bias;
    if !long.about_down_seen {
        gap -= long.down * long.down.dot(&gap);
        bias += long.down * long.down.dot(&short);
    }
    let moved = (0..3).any(|a| {
        let sd = (white[a] * white[a] / n + walk2).sqrt();
        gap[a].abs() > REST_MOVED_SIGMAS * sd
    });
    moved.then_some(bias)
}

/// The error of a long idle rest's gyro bias, rad/s per axis: the white noise over the spell's
/// samples at `rate_hz` and the bias's walk over it, as `long_rest_bias` judges the gap by.
fn long_rest_bias_sd(levels: &NoiseLevels, long: &RestBias, rate_hz: f64) -> f64 {
    let white = Vector3::from(levels.gyro_white_sigma).norm() / 3f64.sqrt();
    let n = (long.span_s * rate_hz).max(1.0);
    (white * white / n + GYRO_BIAS_WALK * GYRO_BIAS_WALK * long.span_s / 3.0).sqrt()
}

/// What the rest before an estimation measured, for its navigation: how the vehicle turned
/// (the attitude at its end, and the gyro's bias net of that turning, `rest_rotation`) and
/// the depth's trend (the vertical velocity at its end).
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub(super) struct Rest {
    rotation: RestRotation,
    /// Whether what the accelerometer saw was a turn or a push (`rest_shape`).
    shape: RestShape,
    drift: RestDrift,
    /// Held under control (the hold before an identification): the thrusters' own
    /// accelerations are in the specific force, which then tells nothing of a turn, so the
    /// navigation starts from its mean as before.
    held: bool,
}

impl Rest {
    /// One sample `t_s` into the rest, the thrusters neutral.
    pub(super) fn push(&mut self, m: &Motion, t_s: f64) {
        if self.rotation.push(t_s, &m.gyro, &m.specific_force) {
            let (t, angle) = self.rotation.last();
            self.shape.push(t, &angle, &m.specific_force);
        }
        if let Some(d) = m.depth {
            self.drift.push(t_s, d);
        }
    }

    /// One sample `t_s` into a hold under control (see `held`).
    pub(super) fn push_held(&mut self, m: &Motion, t_s: f64) {
        self.held = true;
        self.push(m, t_s);
    }

    /// The accelerometer saw the vehicle pushed, not turned, during this rest of the
    /// thrusters (`rest_shape`): its rotation would take the push for a turn.
    pub(super) fn pushed(&self) -> bool {
        !self.held && self.shape.pushed(GRAVITY)
    }

    /// `levels` (measured over this rest) with the gyro's bias net of the rotation the
    /// accelerometer saw: a vehicle swinging during its rest does not leave its mean rate in
    /// the bias.
    pub(super) fn correct(&self, mut levels: NoiseLevels) -> NoiseLevels {
        let mean = Vector3::from(levels.gyro_baseline);
        levels.gyro_baseline = self.rotation.gyro_bias(&mean, GRAVITY).into();
        levels
    }

    /// `est`, told where its navigation starts.
    pub(super) fn start(&self, mut est: Estimator) -> Estimator {
        let force = if self.held {
            self.rotation.mean_force()
        } else {
            self.rotation.force_at_end(GRAVITY)
        };
        if let Some(f) = force {
            est = est.with_rest_specific_force(f);
        }
        if let Some(w) = self.drift.velocity_down() {
            est = est.with_rest_velocity_down(w);
        }
        est
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_minutes_rest_knows_the_gyros_bias_far_better_than_a_second() {
        // The paper's gyro (0.25 rad/s per sample) at 200 Hz: a 1.5 s rest knows the bias to
        // 0.25 / sqrt(300) = 0.0144 rad/s; a minute to 0.25 / sqrt(12000) = 0.0023, the walk
        // adding 1e-4 x sqrt(60 / 3) = 0.00045 in quadrature.
        let levels = NoiseLevels::isotropic(0.25, 0.49);
        let long = RestBias {
            bias: Vector3::zeros(),
            down: Vector3::z(),
            about_down_seen: true,
            span_s: 60.0,
        };
        let sd = long_rest_bias_sd(&levels, &long, 200.0);
        let expected = (0.25f64.powi(2) / 12_000.0 + 1e-8 * 20.0).sqrt();
        assert!((sd - expected).abs() < 1e-12, "{sd} {expected}");
        assert!(sd < 0.25 / 300f64.sqrt() / 5.0, "{sd}");
    }
}
