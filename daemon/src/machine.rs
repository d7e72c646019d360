//! The daemon's state machine: Idle -> MeasureNoise -> Pulse -> Settle -> ... -> Solve ->
//! Active, plus Fault. Pure: IMU samples (with their own timestamps), operator requests,
//! setpoints and reconfiguration events in; a thrust command for every sample, model swaps and
//! status out. Time comes only from sample timestamps, so real time and a faster-than-real-time
//! simulator run the same code.

use std::collections::HashMap;

use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use thruster_protocol::MAX_THRUSTERS;

use crate::attitude::{AttitudeConfig, AttitudeFilter};
use crate::controller::{Controller, ControllerConfig, Measured, Target};
use crate::estimator::power::pulse_power;
use crate::estimator::response::motion_accel;
use crate::estimator::{
    Estimate, Estimator, EstimatorConfig, NoiseLevels, NoiseMeter, StopDecision,
};
use crate::model::{geometry_key, nominal_effectiveness, Model, ModelSource, RigidBody};
use crate::monitor::{Mismatch, MismatchAction, ModelMonitor, MonitorConfig};

/// Why estimation and control are refused before the first IMU sample: the vehicle cannot be
/// measured, and a run started now would wait at "measuring noise" forever.
pub const NO_IMU_YET: &str =
    "no IMU samples from any driver yet: is thruster-sim or thruster-hw running on this namespace?";

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum State {
    Idle,
    MeasureNoise,
    Pulse,
    Settle,
    Solve,
    Active,
    Fault,
}

impl State {
    pub fn name(self) -> &'static str {
        match self {
            State::Idle => "idle",
            State::MeasureNoise => "measure_noise",
            State::Pulse => "pulse",
            State::Settle => "settle",
            State::Solve => "solve",
            State::Active => "active",
            State::Fault => "fault",
        }
    }

    pub fn is_estimating(self) -> bool {
        matches!(
            self,
            State::MeasureNoise | State::Pulse | State::Settle | State::Solve
        )
    }
}

/// What a reconfiguration event leads to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReconfigPolicy {
    /// Re-estimate at once (default).
    Estimate,
    /// Swap nominal/cached models where possible, estimate only on request.
    OnRequest,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MachineConfig {
    /// Rest period for the noise levels, s (default 1.0: 200 samples at 200 Hz put the sigma
    /// within ~5 %).
    pub noise_s: f64,
    /// An estimation that starts while the daemon controls (a reconfiguration, a mismatch, a
    /// request) first levels the vehicle with the model in force, for at most this long, s
    /// (default 5; 0 = pulse from wherever the vehicle is). Why: started mid-manoeuvre, the
    /// "rest" the noise is measured in was a swinging vehicle, and the pulses then tumbled
    /// AMOUR-5 past 150 deg in the hot-swap experiment.
    pub level_max_s: f64,
    /// Levelling ends once the tilt stayed below `level_tilt_deg` for `level_hold_s`
    /// (defaults 5 deg, 1 s).
    pub level_tilt_deg: f64,
    pub level_hold_s: f64,
    /// Length of one excitation pulse, s (default 0.1; the paper used 1.0). Short pulses keep
    /// the vehicle in the regime where the response is still the thrust's, not the drag's: on a
    /// BlueROV2-class body quadratic roll/yaw damping already takes ~5 % off the rate after
    /// 0.1 s (docs/simulation.md).
    pub pulse_s: f64,
    /// Minimum pause after a pulse, s (default 0.15).
    pub settle_min_s: f64,
    /// Maximum pause after a pulse, s (default 1.0; the paper paused a fixed 3 s). The per-pulse
    /// intercept absorbs what is left of the last pulse's motion.
    pub settle_max_s: f64,
    /// The pause ends once every gyro axis stayed within k sigma of rest for this long, s
    /// (default 0.1).
    pub settle_quiet_s: f64,
    /// A new estimated model is swapped in only if both relative error bounds are below this
    /// (default 0.25).
    pub max_swap_rel_err: f64,
    /// "estimate" (default) or "on_request".
    pub on_reconfig: ReconfigPolicy,
    /// Hold attitude with the new model after an estimation (default true); otherwise Idle.
    pub control_after_estimate: bool,
    /// A gap between sample timestamps above this is a sensor dropout, s (default 0.1).
    pub max_sample_gap_s: f64,
    /// Consecutive good samples that end a fault (default 20).
    pub recover_samples: u32,
    /// Thruster deadband the daemon compensates, as a fraction of full command (default 0: the
    /// drivers, thruster-sim and thruster-hw, own their actuators' deadband). For a driver that
    /// does not, a command u != 0 goes out as sign(u) (deadband + (1 - deadband) |u|), so thrust
    /// stays proportional to what the estimator and controller asked for.
    pub deadband: f64,
}

impl Default for MachineConfig {
    fn default() -> Self {
        MachineConfig {
            noise_s: 1.0,
            level_max_s: 5.0,
            level_tilt_deg: 5.0,
            level_hold_s: 1.0,
            pulse_s: 0.1,
            settle_min_s: 0.15,
            settle_max_s: 1.0,
            settle_quiet_s: 0.1,
            max_swap_rel_err: 0.25,
            on_reconfig: ReconfigPolicy::Estimate,
            control_after_estimate: true,
            max_sample_gap_s: 0.1,
            recover_samples: 20,
            deadband: 0.0,
        }
    }
}

/// Everything the machine is configured with.
#[derive(Debug, Clone, Default)]
pub struct MachineSetup {
    pub machine: MachineConfig,
    pub estimator: EstimatorConfig,
    pub controller: ControllerConfig,
    pub attitude: AttitudeConfig,
    pub monitor: MonitorConfig,
    pub body: RigidBody,
    /// Thrusters at start.
    pub thrusters: usize,
    /// Declared geometry at start (positions m, directions), if known.
    pub geometry: Option<Geometry>,
}

/// Declared thruster layout.
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    pub positions: Vec<[f64; 3]>,
    pub directions: Vec<[f64; 3]>,
}

impl Geometry {
    pub fn key(&self) -> u64 {
        geometry_key(&self.positions, &self.directions)
    }
}

/// One validated IMU sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuInput {
    pub seq: u64,
    pub t_ns: u64,
    pub gyro: [f64; 3],
    pub accel: [f64; 3],
    pub mag: Option<[f64; 3]>,
    pub depth: Option<f64>,
}

/// Why the thrusters are doing what they do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    Neutral,
    Estimating,
    Controlling,
}

/// The answer to one IMU sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Command {
    pub count: usize,
    pub thrust: [f64; MAX_THRUSTERS],
    pub mode: Mode,
}

impl Command {
    fn neutral(count: usize) -> Self {
        Command {
            count,
            thrust: [0.0; MAX_THRUSTERS],
            mode: Mode::Neutral,
        }
    }
}

/// Something the IO layer must publish or persist.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A new current model (publish it; save it when estimated).
    ModelSwapped(Box<Model>),
    /// The current model was dropped (thruster count changed, no geometry): neutral until a
    /// new one exists.
    ModelDropped(String),
    /// A candidate was refused; the old model stays.
    ModelRejected(String),
    /// While controlling, the thrusters stopped doing what the model says (see `monitor`).
    MismatchDetected(String),
    StateChanged {
        from: State,
        to: State,
        why: String,
    },
}

/// An operator request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request {
    Estimate,
    Abort,
    Hold,
    Idle,
    Revert,
}

/// A request that cannot be carried out now.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct Refused(pub String);

/// A reconfiguration event, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct Reconfig {
    pub count: usize,
    pub geometry: Option<Geometry>,
    pub what: String,
}

/// An operator's setpoint: the attitude wanted, which of roll, pitch, yaw keep the value held
/// now instead, and the depth to hold (None: heave free).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetpointInput {
    pub attitude: UnitQuaternion<f64>,
    pub keep: [bool; 3],
    pub depth: Option<f64>,
}

/// Status numbers for the status message.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatusSnapshot {
    pub state: State,
    pub pulse: usize,
    pub pulses_planned: usize,
    pub error_bound: f64,
    pub power: f64,
    pub sigma_rot: f64,
    pub sigma_acc: f64,
    pub samples: u64,
    pub model_version: u64,
    pub imu_rate_hz: f64,
    pub vehicle_time_ns: u64,
    pub thrusters: usize,
    pub text: String,
}

/// Levelling before the noise measurement: the attitude held, and since when it is level.
struct Levelling {
    target: Target,
    level_since_ns: Option<u64>,
}

/// What to go back to after a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Resume {
    Idle,
    Active,
    Estimate,
}

pub struct Machine {
    setup: MachineSetup,
    n: usize,
    state: State,
    phase_start_ns: u64,
    last_t_ns: Option<u64>,
    attitude: AttitudeFilter,
    controller: Controller,
    monitor: ModelMonitor,
    target: Option<Target>,
    model: Option<Model>,
    previous: Option<Model>,
    versions: u64,
    cache: HashMap<u64, Model>,
    geometry: Option<Geometry>,
    noise: NoiseMeter,
    levels: Option<NoiseLevels>,
    est: Option<Estimator>,
    last_estimate: Option<Estimate>,
    quiet_since_ns: Option<u64>,
    levelling: Option<Levelling>,
    resume: Resume,
    good_samples: u32,
    events: Vec<Event>,
    imu_rate_hz: f64,
    samples: u64,
    text: String,
    last_desired: [f64; 6],
    /// Why the driver's outputs cannot be used (see `driver_watch`), while they cannot: the
    /// machine stays in Fault, neutral, and does not recover on good IMU samples alone.
    output_block: Option<String>,
}

impl Machine {
    pub fn new(setup: MachineSetup) -> Self {
        let n = setup.thrusters.clamp(1, MAX_THRUSTERS);
        let mut m = Machine {
            n,
            state: State::Idle,
            phase_start_ns: 0,
            last_t_ns: None,
            attitude: AttitudeFilter::new(setup.attitude.clone()),
            controller: Controller::new(setup.controller.clone()),
            monitor: ModelMonitor::new(setup.monitor.clone(), n),
            target: None,
            model: None,
            previous: None,
            versions: 0,
            cache: HashMap::new(),
            geometry: None,
            noise: NoiseMeter::new(),
            levels: None,
            est: None,
            last_estimate: None,
            quiet_since_ns: None,
            levelling: None,
            resume: Resume::Idle,
            good_samples: 0,
            events: Vec::new(),
            imu_rate_hz: 0.0,
            samples: 0,
            text: "idle: waiting for an estimate request".into(),
            last_desired: [0.0; 6],
            output_block: None,
            setup,
        };
        if let Some(g) = m.setup.geometry.clone() {
            if g.positions.len() == n {
                m.geometry = Some(g.clone());
                let b = nominal_effectiveness(&m.setup.body, &g.positions, &g.directions);
                let _ = m.try_swap(Model::nominal(b, Some(g.key())), ModelSource::Nominal);
            }
        }
        m
    }

    pub fn state(&self) -> State {
        self.state
    }

    pub fn thrusters(&self) -> usize {
        self.n
    }

    pub fn model(&self) -> Option<&Model> {
        self.model.as_ref()
    }

    pub fn last_estimate(&self) -> Option<&Estimate> {
        self.last_estimate.as_ref()
    }

    /// The desired motion (DOF order) of the last control tick.
    pub fn last_desired(&self) -> [f64; 6] {
        self.last_desired
    }

    pub fn attitude(&self) -> UnitQuaternion<f64> {
        self.attitude.attitude()
    }

    /// Events since the last call (model swaps, state changes), oldest first.
    pub fn take_events(&mut self) -> Vec<Event> {
        std::mem::take(&mut self.events)
    }

    /// Install a model from a file (at start, or an operator's load request): its
    /// allocation is derived again from its effectiveness, and it must pass the same checks
    /// as any swap, the physical bounds included.
    pub fn load_model(&mut self, model: Model) -> Result<(), Refused> {
        let model = model.with_derived_allocation(&self.setup.estimator);
        self.try_swap(model, ModelSource::Loaded)
            .map_err(|e| Refused(format!("model not used: {e}")))?;
        self.describe_swap("model loaded");
        Ok(())
    }

    /// After an operator's swap (revert, load): status says which model is in force and
    /// where it came from, instead of the words of the run that made the old one.
    fn describe_swap(&mut self, what: &str) -> String {
        let Some(m) = &self.model else {
            return what.to_string();
        };
        self.text = format!("{what}: model v{}, {}", m.version, m.provenance());
        self.text.clone()
    }

    /// The answer to one IMU sample. Always a command: neutral unless estimating or controlling.
    pub fn on_imu(&mut self, s: &ImuInput) -> Command {
        self.samples += 1;
        let dt = match self.last_t_ns {
            Some(last) if s.t_ns > last => (s.t_ns - last) as f64 * 1e-9,
            Some(_) => 0.0,
            None => 0.0,
        };
        self.last_t_ns = Some(s.t_ns);
        if dt > 0.0 {
            let rate = 1.0 / dt;
            self.imu_rate_hz = if self.imu_rate_hz == 0.0 {
                rate
            } else {
                self.imu_rate_hz + (rate - self.imu_rate_hz) * 0.01
            };
        }
        if dt > self.setup.machine.max_sample_gap_s && self.state != State::Fault {
            self.fault(s.t_ns, &format!("IMU gap of {dt:.3} s between samples"));
        }
        let gyro = Vector3::from(s.gyro);
        let accel = Vector3::from(s.accel);
        let mag = s.mag.map(Vector3::from);
        // No accelerometer/magnetometer correction during pulses (see AttitudeFilter).
        let correct = self.state != State::Pulse;
        self.attitude
            .update_with(&gyro, &accel, mag.as_ref(), dt, correct);

        match self.state {
            State::Idle | State::Solve => Command::neutral(self.n),
            State::Fault => {
                if self.output_block.is_none() {
                    self.good_samples += 1;
                }
                if self.good_samples >= self.setup.machine.recover_samples {
                    self.recover(s.t_ns);
                }
                Command::neutral(self.n)
            }
            State::MeasureNoise if self.levelling.is_some() => self.level_tick(s, &gyro, dt),
            State::MeasureNoise => {
                let motion = motion_accel(&accel, &self.attitude.attitude());
                self.noise.push(&s.gyro, &[motion.x, motion.y, motion.z]);
                let elapsed = self.elapsed_s(s.t_ns);
                if elapsed >= self.setup.machine.noise_s && self.noise.samples() >= 10 {
                    let levels = self.noise.levels();
                    self.levels = Some(levels);
                    let mut cfg = self.setup.estimator.clone();
                    if let Some(p) = self
                        .model
                        .as_ref()
                        .filter(|_| cfg.pulse_snr > 0.0)
                        .and_then(|m| {
                            pulse_power(
                                &m.effectiveness,
                                self.n,
                                &levels,
                                self.setup.machine.pulse_s,
                                cfg.pulse_snr,
                                cfg.min_power,
                                cfg.initial_power,
                            )
                        })
                    {
                        cfg.initial_power = p;
                    }
                    let mut est = Estimator::new(cfg, self.n, levels);
                    if let Some(nominal) = self
                        .model
                        .as_ref()
                        .filter(|m| m.source == ModelSource::Nominal)
                    {
                        est = est.with_nominal(nominal.effectiveness.clone());
                    }
                    self.est = Some(est);
                    return self.start_pulse(s.t_ns);
                }
                Command::neutral(self.n)
            }
            State::Pulse => self.pulse_tick(s, &gyro, &accel),
            State::Settle => self.settle_tick(s, &gyro, &accel),
            State::Active => self.control_tick(s, &gyro, dt),
        }
    }

    /// The IMU went stale (no sample within the deadline): neutral and Fault.
    pub fn on_imu_stale(&mut self, why: &str) -> Command {
        if self.state != State::Fault {
            let t = self.last_t_ns.unwrap_or(0);
            self.fault(t, why);
        }
        self.good_samples = 0;
        // No samples, no rate: status must not go on showing the last one.
        self.imu_rate_hz = 0.0;
        Command::neutral(self.n)
    }

    /// No IMU sample has come from any driver yet, for `why`: said in status while idle (a
    /// daemon started before its driver is not in fault), and estimation and control are
    /// refused with it until a sample comes.
    pub fn on_no_imu_yet(&mut self, why: &str) {
        if self.state == State::Idle && self.samples == 0 {
            self.text = format!("idle: {why}");
        }
    }

    /// The driver's verdict on its outputs (`None`: usable). Blocked outputs fault the
    /// machine, thrusters neutral, and keep it there: it recovers as after any fault, on good
    /// samples, only once the outputs are usable again.
    pub fn on_outputs(&mut self, blocked: Option<&str>) {
        if self.output_block.as_deref() == blocked {
            return;
        }
        self.output_block = blocked.map(str::to_string);
        self.good_samples = 0;
        if let Some(why) = blocked {
            let t = self.last_t_ns.unwrap_or(0);
            self.fault(t, why);
        }
    }

    pub fn on_request(&mut self, req: Request) -> Result<String, Refused> {
        match req {
            Request::Estimate => {
                if self.samples == 0 {
                    return Err(Refused(NO_IMU_YET.into()));
                }
                if self.state == State::Fault {
                    return Err(Refused(format!(
                        "in fault ({}); estimate after it clears",
                        self.text
                    )));
                }
                let t = self.last_t_ns.unwrap_or(0);
                self.start_estimation(t, "estimate requested");
                Ok(format!("estimating {} thrusters", self.n))
            }
            Request::Abort => {
                if !self.state.is_estimating() {
                    return Err(Refused(format!(
                        "nothing to abort (state {})",
                        self.state.name()
                    )));
                }
                self.est = None;
                self.transition(State::Idle, "estimation aborted: thrusters neutral");
                Ok("aborted".into())
            }
            Request::Hold => {
                if self.state == State::Fault {
                    return Err(Refused("in fault: cannot hold".into()));
                }
                if self.model.is_none() {
                    return Err(Refused("no model yet: estimate first".into()));
                }
                if self.samples == 0 {
                    return Err(Refused(NO_IMU_YET.into()));
                }
                self.est = None;
                self.target = None;
                self.controller.reset();
                self.transition(State::Active, "holding attitude");
                Ok("holding".into())
            }
            Request::Idle => {
                self.est = None;
                let t = self.last_t_ns.unwrap_or(0);
                if self.state == State::Fault {
                    self.resume = Resume::Idle;
                    return Ok("will stay idle after the fault clears".into());
                }
                self.phase_start_ns = t;
                self.transition(State::Idle, "idle on request: thrusters neutral");
                Ok("idle".into())
            }
            Request::Revert => {
                let Some(prev) = self.previous.take() else {
                    return Err(Refused("no previous model to revert to".into()));
                };
                let source = prev.source;
                self.try_swap(prev, source)
                    .map_err(|e| Refused(format!("revert refused: {e}")))?;
                Ok(self.describe_swap("reverted to the previous model"))
            }
        }
    }

    /// Pulse strength for the next estimation (a fraction of full command, within the
    /// configured maximum): the operator's `estimate --power`.
    pub fn set_estimation_power(&mut self, power: f64) -> Result<(), Refused> {
        let max = self.setup.estimator.max_power;
        if !(power.is_finite() && power > 0.0 && power <= max) {
            return Err(Refused(format!("power {power} is not in (0, {max}]")));
        }
        self.setup.estimator.initial_power = power;
        Ok(())
    }

    /// A new attitude (body to NED) and optional depth to hold.
    pub fn on_setpoint(&mut self, attitude: UnitQuaternion<f64>, depth: Option<f64>) {
        self.target = Some(Target { attitude, depth });
    }

    /// An operator's setpoint in which some angles may be left out: those keep the value held
    /// now (the current target's, or, before any target, what control would hold: level at
    /// the current heading).
    pub fn on_setpoint_input(&mut self, s: &SetpointInput) {
        let held = match &self.target {
            Some(t) => t.attitude.euler_angles(),
            None => (0.0, 0.0, self.attitude.attitude().euler_angles().2),
        };
        let held = [held.0, held.1, held.2];
        let (r, p, y) = s.attitude.euler_angles();
        let want = [r, p, y];
        let pick = |i: usize| if s.keep[i] { held[i] } else { want[i] };
        let attitude = UnitQuaternion::from_euler_angles(pick(0), pick(1), pick(2));
        self.on_setpoint(attitude, s.depth);
    }

    pub fn on_reconfig(&mut self, r: Reconfig) {
        let count = r.count.clamp(1, MAX_THRUSTERS);
        let count_changed = count != self.n;
        self.n = count;
        self.geometry = r.geometry.clone().filter(|g| g.positions.len() == count);
        let t = self.last_t_ns.unwrap_or(0);
        let mut estimate = self.setup.machine.on_reconfig == ReconfigPolicy::Estimate;
        if self.state.is_estimating() {
            self.est = None;
        }
        match self.geometry.clone() {
            Some(g) => {
                let key = g.key();
                if let Some(cached) = self.cache.get(&key).cloned() {
                    // Seen before: its learned model is back at once, no pulses needed.
                    if self.try_swap(cached, ModelSource::Cache).is_ok() {
                        estimate = false;
                    }
                } else {
                    let b = nominal_effectiveness(&self.setup.body, &g.positions, &g.directions);
                    let mut nominal = Model::nominal(b, Some(key));
                    nominal.made_t_ns = self.last_t_ns.unwrap_or(0);
                    let _ = self.try_swap(nominal, ModelSource::Nominal);
                }
            }
            None => {
                if count_changed {
                    if let Some(old) = self.model.take() {
                        self.previous = Some(old);
                    }
                    self.events.push(Event::ModelDropped(format!(
                        "{}: now {count} thrusters and no declared geometry",
                        r.what
                    )));
                }
            }
        }
        if estimate {
            self.start_estimation(t, &format!("{}: re-estimating", r.what));
        } else if self.model.is_some() && self.state != State::Fault {
            if self.state.is_estimating() || self.state == State::Active {
                self.transition(State::Active, &format!("{}: model swapped", r.what));
            }
        } else if self.state != State::Fault {
            self.transition(
                State::Idle,
                &format!("{}: no model, waiting for an estimate request", r.what),
            );
        }
    }

    pub fn status(&self) -> StatusSnapshot {
        let (pulse, planned, power) = match (&self.est, &self.last_estimate) {
            (Some(e), _) => (e.pulses(), e.planned_pulses(), e.power()),
            // Not estimating: how many pulses the model in force took (0 for a nominal
            // one), not the last run's, which may have been refused or reverted.
            (None, _) => {
                let p = self.model.as_ref().map_or(0, |m| m.pulses);
                (p, p, 0.0)
            }
        };
        // Likewise the bound: the running estimate's, else the model in force's (NaN when it
        // has none: nominal, or the paper's method).
        let error_bound = match (&self.est, &self.model) {
            (Some(_), _) => self
                .last_estimate
                .as_ref()
                .map(|e| e.rel_err_rot.max(e.rel_err_acc))
                .unwrap_or(f64::NAN),
            (None, Some(m)) => m.rel_err_rot.max(m.rel_err_acc),
            (None, None) => f64::NAN,
        };
        let levels = self
            .levels
            .unwrap_or(NoiseLevels::isotropic(f64::NAN, f64::NAN));
        StatusSnapshot {
            state: self.state,
            pulse,
            pulses_planned: planned,
            error_bound,
            power,
            sigma_rot: levels.sigma_rot(),
            sigma_acc: levels.sigma_acc(),
            samples: self.samples,
            model_version: self.model.as_ref().map(|m| m.version).unwrap_or(0),
            imu_rate_hz: self.imu_rate_hz,
            vehicle_time_ns: self.last_t_ns.unwrap_or(0),
            thrusters: self.n,
            text: self.text.clone(),
        }
    }

    // ---- internals ----

    fn elapsed_s(&self, t_ns: u64) -> f64 {
        t_ns.saturating_sub(self.phase_start_ns) as f64 * 1e-9
    }

    fn transition(&mut self, to: State, why: &str) {
        let from = self.state;
        self.state = to;
        self.text = why.to_string();
        if to != State::MeasureNoise {
            self.levelling = None;
        }
        if let Some(t) = self.last_t_ns {
            self.phase_start_ns = t;
        }
        if to == State::Active && from != State::Active {
            // Control (re)starts: judge the model on fresh data only.
            self.monitor.reset(self.n);
        }
        if from != to {
            self.events.push(Event::StateChanged {
                from,
                to,
                why: why.to_string(),
            });
        }
    }

    fn fault(&mut self, _t_ns: u64, why: &str) {
        self.resume = match self.state {
            s if s.is_estimating() => Resume::Estimate,
            State::Active => Resume::Active,
            State::Fault => self.resume,
            _ => Resume::Idle,
        };
        self.est = None;
        self.good_samples = 0;
        self.controller.reset();
        self.transition(State::Fault, &format!("fault: {why}; thrusters neutral"));
    }

    fn recover(&mut self, t_ns: u64) {
        // The vehicle's attitude may have changed a lot while blind.
        self.attitude.reset();
        match self.resume {
            Resume::Estimate => {
                self.start_estimation(t_ns, "IMU back: restarting the interrupted estimation")
            }
            Resume::Active if self.model.is_some() => {
                self.target = None;
                self.transition(State::Active, "IMU back: holding attitude again")
            }
            _ => self.transition(State::Idle, "IMU back: idle"),
        }
    }

    fn start_estimation(&mut self, t_ns: u64, why: &str) {
        self.noise = NoiseMeter::new();
        self.est = None;
        self.last_t_ns = self.last_t_ns.or(Some(t_ns));
        // Controlling with a model: level the vehicle first (see MachineConfig::level_max_s).
        // A reconfiguration while levelling levels on (the vehicle is no more at rest).
        self.levelling = ((self.state == State::Active || self.levelling.is_some())
            && self.model.is_some()
            && self.setup.machine.level_max_s > 0.0)
            .then(|| Levelling {
                target: Target {
                    attitude: UnitQuaternion::from_euler_angles(
                        0.0,
                        0.0,
                        self.attitude.attitude().euler_angles().2,
                    ),
                    depth: self.target.and_then(|t| t.depth),
                },
                level_since_ns: None,
            });
        let then = if self.levelling.is_some() {
            "levelling, then measuring noise at rest"
        } else {
            "measuring noise at rest"
        };
        self.transition(State::MeasureNoise, &format!("{why}: {then}"));
    }

    /// Levelling before the noise measurement: the controller holds level at the heading the
    /// estimation started with (no monitor: the model is about to be replaced). Ends, thrusters
    /// neutral and the noise clock restarted, once level for `level_hold_s` or after
    /// `level_max_s` whatever the tilt.
    fn level_tick(&mut self, s: &ImuInput, gyro: &Vector3<f64>, dt: f64) -> Command {
        let elapsed = self.elapsed_s(s.t_ns);
        let meas = self.measured(s, gyro);
        let (Some(model), Some(lev)) = (self.model.as_ref(), self.levelling.as_mut()) else {
            self.levelling = None;
            return Command::neutral(self.n);
        };
        let up = meas.attitude * Vector3::z();
        let tilt_deg = up.z.clamp(-1.0, 1.0).acos().to_degrees();
        let m = &self.setup.machine;
        if tilt_deg <= m.level_tilt_deg {
            lev.level_since_ns.get_or_insert(s.t_ns);
        } else {
            lev.level_since_ns = None;
        }
        let level_for = lev
            .level_since_ns
            .map_or(0.0, |t| s.t_ns.saturating_sub(t) as f64 * 1e-9);
        if level_for >= m.level_hold_s || elapsed >= m.level_max_s {
            self.levelling = None;
            self.controller.reset();
            self.phase_start_ns = s.t_ns;
            self.text = if level_for >= m.level_hold_s {
                "level: measuring noise at rest".to_string()
            } else {
                format!("still {tilt_deg:.0} deg tilted after levelling: measuring noise")
            };
            return Command::neutral(self.n);
        }
        let mut cmd = Command::neutral(self.n);
        cmd.mode = Mode::Controlling;
        let n = self.n.min(model.thrusters());
        let target = lev.target;
        self.last_desired = self
            .controller
            .update(&meas, &target, model, dt, &mut cmd.thrust[..n]);
        finish(&mut cmd, self.setup.machine.deadband);
        cmd
    }

    fn start_pulse(&mut self, t_ns: u64) -> Command {
        let mut cmd = Command::neutral(self.n);
        cmd.mode = Mode::Estimating;
        if let Some(est) = self.est.as_mut() {
            let u = est.begin_pulse_at(t_ns as f64 * 1e-9);
            for (o, v) in cmd.thrust.iter_mut().zip(u) {
                *o = *v;
            }
            let k = est.pulses() + 1;
            self.phase_start_ns = t_ns;
            let from = self.state;
            self.state = State::Pulse;
            self.text = format!("pulse {k}");
            if from != State::Pulse && from != State::Settle {
                self.events.push(Event::StateChanged {
                    from,
                    to: State::Pulse,
                    why: "noise measured: pulsing".into(),
                });
            }
        }
        finish(&mut cmd, self.setup.machine.deadband);
        cmd
    }

    fn pulse_tick(&mut self, s: &ImuInput, gyro: &Vector3<f64>, accel: &Vector3<f64>) -> Command {
        let elapsed = self.elapsed_s(s.t_ns);
        let motion = motion_accel(accel, &self.attitude.attitude());
        let (Some(est), Some(levels)) = (self.est.as_mut(), self.levels) else {
            self.transition(State::Idle, "internal: pulse without an estimator");
            return Command::neutral(self.n);
        };
        let gyro_d = levels.gyro_delta(&[gyro.x, gyro.y, gyro.z]);
        let acc_d = levels.accel_delta(&[motion.x, motion.y, motion.z]);
        est.push_pulse_sample(elapsed, &gyro_d, &acc_d);
        if elapsed < self.setup.machine.pulse_s {
            let mut cmd = Command::neutral(self.n);
            cmd.mode = Mode::Estimating;
            if let Some(u) = est.current_command() {
                for (o, v) in cmd.thrust.iter_mut().zip(u) {
                    *o = *v;
                }
            }
            finish(&mut cmd, self.setup.machine.deadband);
            return cmd;
        }
        est.end_pulse();
        let decision = est.stop_decision();
        self.last_estimate = Some(est.estimate());
        if decision.is_stop() {
            self.solve(decision);
        } else {
            self.quiet_since_ns = None;
            self.state = State::Settle;
            self.phase_start_ns = s.t_ns;
            self.text = format!("settling after pulse {}", est.pulses());
        }
        Command::neutral(self.n)
    }

    fn settle_tick(&mut self, s: &ImuInput, gyro: &Vector3<f64>, accel: &Vector3<f64>) -> Command {
        let elapsed = self.elapsed_s(s.t_ns);
        let Some(levels) = self.levels else {
            return Command::neutral(self.n);
        };
        let k = self.setup.estimator.k_sigma;
        let d = levels.gyro_delta(&[gyro.x, gyro.y, gyro.z]);
        let motion = motion_accel(accel, &self.attitude.attitude());
        if let Some(est) = self.est.as_mut() {
            est.push_rest_sample(
                s.t_ns as f64 * 1e-9,
                &d,
                &levels.accel_delta(&[motion.x, motion.y, motion.z]),
            );
        }
        let quiet = (0..3).all(|a| d[a].abs() <= k * levels.gyro_sigma[a].max(1e-6));
        if quiet {
            self.quiet_since_ns.get_or_insert(s.t_ns);
        } else {
            self.quiet_since_ns = None;
        }
        let quiet_for = self
            .quiet_since_ns
            .map(|q| (s.t_ns - q) as f64 * 1e-9)
            .unwrap_or(0.0);
        let m = &self.setup.machine;
        if (elapsed >= m.settle_min_s && quiet_for >= m.settle_quiet_s) || elapsed >= m.settle_max_s
        {
            return self.start_pulse(s.t_ns);
        }
        Command::neutral(self.n)
    }

    fn solve(&mut self, decision: StopDecision) {
        self.state = State::Solve;
        let Some(est) = self.est.take() else { return };
        let estimate = est.estimate();
        let key = self.geometry.as_ref().map(|g| g.key());
        let candidate = Model::from_estimate(&estimate, key, self.last_t_ns.unwrap_or(0));
        self.last_estimate = Some(estimate);
        let why = match decision {
            StopDecision::Converged { rel_err_rot, rel_err_acc } => format!(
                "converged after {} pulses (error bound rot {rel_err_rot:.3}, acc {rel_err_acc:.3})",
                est.pulses()
            ),
            StopDecision::PlanComplete => format!("planned {} pulses done", est.pulses()),
            StopDecision::MaxPulses => format!("pulse limit {} reached", est.pulses()),
            StopDecision::Continue => "stopped".into(),
        };
        match self.try_swap(candidate, ModelSource::Estimated) {
            Ok(()) => {
                if let (Some(k), Some(m)) = (key, self.model.clone()) {
                    self.cache.insert(k, m);
                }
                if self.setup.machine.control_after_estimate {
                    self.target = None;
                    self.controller.reset();
                    self.transition(
                        State::Active,
                        &format!("{why}: new model, holding attitude"),
                    );
                } else {
                    self.transition(State::Idle, &format!("{why}: new model"));
                }
            }
            Err(e) => {
                let next = if self.model.is_some() && self.setup.machine.control_after_estimate {
                    State::Active
                } else {
                    State::Idle
                };
                self.transition(
                    next,
                    &format!("{why}: model rejected ({e}); old model kept"),
                );
            }
        }
    }

    /// Validate and install a model between two ticks.
    fn try_swap(
        &mut self,
        mut model: Model,
        source: ModelSource,
    ) -> Result<(), crate::model::SwapRejection> {
        if let Err(e) = model.check(self.n, self.setup.machine.max_swap_rel_err) {
            self.events.push(Event::ModelRejected(e.to_string()));
            return Err(e);
        }
        self.versions += 1;
        model.version = self.versions;
        self.monitor.reset(self.n);
        model.source = source;
        if let Some(old) = self.model.replace(model.clone()) {
            self.previous = Some(old);
        }
        self.events.push(Event::ModelSwapped(Box::new(model)));
        Ok(())
    }

    /// What the controller sees of this sample: filtered attitude, bias-free rate, depth.
    fn measured(&self, s: &ImuInput, gyro: &Vector3<f64>) -> Measured {
        Measured {
            attitude: self.attitude.attitude(),
            rate: gyro - self.attitude.gyro_bias(),
            depth: s.depth,
        }
    }

    fn control_tick(&mut self, s: &ImuInput, gyro: &Vector3<f64>, dt: f64) -> Command {
        let Some(model) = self.model.as_ref() else {
            return Command::neutral(self.n);
        };
        let meas = self.measured(s, gyro);
        let attitude = meas.attitude;
        // Without a setpoint, hold level at the current heading and depth: a vehicle may enter
        // Active still swinging from the last pulse, and that tilt is nothing to keep.
        let target = *self.target.get_or_insert_with(|| Target {
            attitude: UnitQuaternion::from_euler_angles(0.0, 0.0, attitude.euler_angles().2),
            depth: s.depth,
        });
        let mut cmd = Command::neutral(self.n);
        cmd.mode = Mode::Controlling;
        let n = self.n.min(model.thrusters());
        self.last_desired = self
            .controller
            .update(&meas, &target, model, dt, &mut cmd.thrust[..n]);
        // The monitor compares in model units: the command before deadband compensation.
        let gravity_body = attitude.inverse() * Vector3::z();
        let mismatch = self.monitor.observe(
            dt,
            attitude.angle_to(&target.attitude),
            &meas.rate,
            &gravity_body,
            &model.effectiveness,
            &cmd.thrust[..n],
        );
        finish(&mut cmd, self.setup.machine.deadband);
        if let Some(m) = mismatch {
            self.on_mismatch(s.t_ns, m);
        }
        cmd
    }

    /// The monitor found the thrusters doing something else than the model says.
    fn on_mismatch(&mut self, t_ns: u64, m: Mismatch) {
        let why = m.to_string();
        self.events.push(Event::MismatchDetected(why.clone()));
        self.monitor.reset(self.n);
        match self.monitor.action() {
            MismatchAction::Estimate => {
                self.start_estimation(t_ns, &format!("{why}: re-estimating"))
            }
            MismatchAction::Report | MismatchAction::Off => {
                self.text = format!("holding attitude; {why}");
            }
        }
    }
}

/// Last line of defence: nothing non-finite or out of range leaves the machine; then the
/// deadband compensation (which maps [-1, 1] onto itself).
fn finish(cmd: &mut Command, deadband: f64) {
    let db = if deadband.is_finite() {
        deadband.clamp(0.0, 0.5)
    } else {
        0.0
    };
    for (i, v) in cmd.thrust.iter_mut().enumerate() {
        let u = if i < cmd.count && v.is_finite() {
            v.clamp(-1.0, 1.0)
        } else {
            0.0
        };
        // Commands this small are numerical dust: send true neutral, not the deadband edge.
        *v = if u.abs() < 1e-6 {
            0.0
        } else {
            u.signum() * (db + (1.0 - db) * u.abs())
        };
    }
}
