//! The machine itself: routes every input to the state it is in, and owns the states and their
//! changes (`transition`), faults and recovery, levelling before a run, and control. The model
//! slot (`models`) and the estimation run (`estimation`) hold what they own.

use nalgebra::{UnitQuaternion, Vector3};
use thruster_protocol::MAX_THRUSTERS;

use super::config::{MachineSetup, ReconfigPolicy};
use super::estimation::ESTIMATION;
use super::estimation::{ClosedStep, EstimationRun, Motion, PulseStep};
use super::models::ModelSlot;
use super::types::{
    finish, Command, DepthInput, Event, Geometry, ImuInput, Mode, Reconfig, Refused, Request,
    SetpointInput, State, StatusSnapshot, NO_IMU_YET,
};
use crate::attitude::AttitudeFilter;
use crate::controller::{Controller, Measured, Target};
use crate::estimator::dynamic::prior::DynamicPrior;
use crate::estimator::response::motion_accel;
use crate::estimator::{Estimate, NoiseLevels, StopDecision};
use crate::identification::carry_over::{carried_over, ThrusterChange};
use crate::model::{nominal_effectiveness, Model, ModelSource, PreparedModel};
use crate::monitor::{MismatchAction, ModelMonitor};
use crate::refinement::{Refiner, Tick, WindowVerdict};
use crate::solve::{owner_of, Purpose, SolveJob, SolveResult, SolverMode};
use crate::supply::Supply;

/// Levelling before the noise measurement: the attitude held, and since when it is level.
#[derive(Clone, serde::Serialize, serde::Deserialize)]
struct Levelling {
    target: Target,
    level_since_ns: Option<u64>,
}

/// What to go back to after a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
enum Resume {
    Idle,
    Active,
    Estimate,
}

#[derive(Clone, serde::Serialize, serde::Deserialize)]
pub struct Machine {
    /// Not in a checkpoint: the configuration is published on its own (`config`), and a
    /// restored machine is given it (`Machine::restore`).
    #[serde(skip)]
    setup: MachineSetup,
    n: usize,
    state: State,
    phase_start_ns: u64,
    last_t_ns: Option<u64>,
    attitude: AttitudeFilter,
    controller: Controller,
    monitor: ModelMonitor,
    refiner: Refiner,
    target: Option<Target>,
    models: ModelSlot,
    geometry: Option<Geometry>,
    run: EstimationRun,
    levelling: Option<Levelling>,
    resume: Resume,
    /// An emergency stop holds the thrusters off: set by `Request::Stop`, cleared only by an
    /// operator's estimate or hold. While set nothing starts them on its own (a
    /// reconfiguration does not re-estimate, a cleared fault does not resume).
    stopped: bool,
    good_samples: u32,
    /// Outputs waiting for the caller (`take_events`), not state: not in a checkpoint.
    #[serde(skip)]
    events: Vec<Event>,
    imu_rate_hz: f64,
    samples: u64,
    text: String,
    /// `text` says no IMU sample has come yet (set by `on_no_imu_yet`).
    text_says_no_imu: bool,
    last_desired: [f64; 6],
    /// Why the driver's outputs cannot be used (see `driver_watch`), while they cannot: the
    /// machine stays in Fault, neutral, and does not recover on good IMU samples alone.
    output_block: Option<String>,
    /// The supply voltage and the referral of commands to the reference voltage: every
    /// command inside the machine is referred, only the outgoing one is carried to the
    /// present voltage (`crate::supply`).
    supply: Supply,
}

/// What status says while idle with samples coming and nothing asked.
const IDLE_TEXT: &str = "idle: waiting for an estimate request";

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
            refiner: Refiner::new(setup.refinement.clone(), n),
            target: None,
            models: ModelSlot::default(),
            geometry: None,
            run: EstimationRun::new(setup.machine.solve_budget_s),
            levelling: None,
            resume: Resume::Idle,
            stopped: false,
            good_samples: 0,
            events: Vec::new(),
            imu_rate_hz: 0.0,
            samples: 0,
            text: IDLE_TEXT.into(),
            text_says_no_imu: false,
            last_desired: [0.0; 6],
            output_block: None,
            supply: Supply::new(setup.supply.clone()),
            setup,
        };
        m.refiner.set_solve_budget(m.setup.machine.solve_budget_s);
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
        self.models.current()
    }

    pub fn last_estimate(&self) -> Option<&Estimate> {
        self.run.last_estimate()
    }

    /// The background refinement's last window verdict (how the closed-loop data fit the
    /// model in force), if a window has ended since start.
    pub fn refinement(&self) -> Option<&WindowVerdict> {
        self.refiner.last()
    }

    /// The desired motion (DOF order) of the last control tick.
    pub fn last_desired(&self) -> [f64; 6] {
        self.last_desired
    }

    pub fn attitude(&self) -> UnitQuaternion<f64> {
        self.attitude.attitude()
    }

    /// For `telemetry`: what the controller tracks now (levelling's target before a run, the
    /// setpoint while holding or identifying under control), None while it does not control.
    pub(super) fn tracked_target(&self) -> Option<Target> {
        match (&self.levelling, self.state) {
            (Some(l), State::MeasureNoise) => Some(l.target),
            (None, State::Active | State::Identify) if self.models.current().is_some() => {
                self.target
            }
            _ => None,
        }
    }

    /// For `telemetry`: the estimation run (its progress).
    pub(super) fn run(&self) -> &EstimationRun {
        &self.run
    }

    /// For `telemetry`: the attitude filter's gyro bias estimate, rad/s.
    pub(super) fn gyro_bias(&self) -> Vector3<f64> {
        self.attitude.gyro_bias()
    }

    /// Who runs the solve jobs (default `Inline`: the machine itself, on the sample that
    /// submits them). The daemon sets `External` and runs them on its worker thread.
    pub fn set_solver_mode(&mut self, mode: SolverMode) {
        self.run.solver().set_mode(mode);
        self.refiner.set_solver_mode(mode);
    }

    /// Whether a checkpoint (`checkpoint`) taken now holds everything the machine needs to go
    /// on: no solve job is out with the caller (its work would be on the caller's worker,
    /// not in the state). Jobs not yet taken, and results back but not yet due, are state.
    pub fn checkpointable(&self) -> bool {
        self.run.jobs_out() == 0 && self.refiner.jobs_out() == 0
    }

    /// Bytes each part of the state takes in a checkpoint (for docs/recording.md's table).
    #[doc(hidden)]
    pub fn checkpoint_breakdown(&self) -> Vec<(&'static str, usize)> {
        fn size<T: serde::Serialize>(v: &T) -> usize {
            postcard::to_allocvec(v).map_or(0, |b| b.len())
        }
        vec![
            ("attitude filter", size(&self.attitude)),
            ("controller", size(&self.controller)),
            ("monitor", size(&self.monitor)),
            ("refinement", size(&self.refiner)),
            ("model slot", size(&self.models)),
            ("estimation run", size(&self.run)),
            ("supply", size(&self.supply)),
        ]
    }

    /// Whether the state is small now (about 0.2 MB): no estimation under way and no
    /// refinement window open. Their estimators hold every sample of the run or window (1-3 MB
    /// at 200 Hz, up to 4 MB more at 1 kHz), too much to serialise on the control thread; the
    /// daemon takes its checkpoints only when this holds (`[checkpoint]`).
    pub fn checkpoint_small(&self) -> bool {
        !self.state.is_estimating() && !self.refiner.window_open()
    }

    /// A restored machine (`checkpoint::restore`) is given the configuration it ran with:
    /// the settings are published on their own (`config`), not in every checkpoint.
    pub(super) fn with_setup(mut self, setup: MachineSetup) -> Self {
        self.setup = setup;
        self
    }

    /// The next solve job to run (`External` mode; None inline or when there is none).
    pub fn take_job(&mut self) -> Option<SolveJob> {
        self.run
            .solver()
            .take_job()
            .or_else(|| self.refiner.take_job())
    }

    /// A job's result is back. It is applied at the first sample at or after the job's due
    /// time (see `crate::solve`); a result for a job the machine no longer waits for (the
    /// run was aborted, faulted, restarted) is dropped.
    pub fn deliver(&mut self, result: SolveResult) {
        if owner_of(result.id()) == ESTIMATION {
            self.run.solver().deliver(result);
        } else {
            self.refiner.deliver(result);
        }
    }

    /// The job a sample at `t_ns` would need and whose result is not back: a caller that must
    /// reproduce the inline outcome (lockstep) waits for it before handing over the sample.
    pub fn awaiting_result(&self, t_ns: u64) -> Option<u64> {
        // The refinement's only matters where a control tick will judge it.
        let refining = self.state == State::Active;
        self.run
            .awaiting(t_ns)
            .or_else(|| self.refiner.awaiting(t_ns).filter(|_| refining))
    }

    /// Solves whose result was not back by their due sample, since start (applied late:
    /// such a run is not reproduced exactly by an inline replay).
    pub fn late_solves(&self) -> u64 {
        self.run.late_solves() + self.refiner.late_solves()
    }

    /// The solver is gone (the worker thread died, or in lockstep a result did not come back
    /// in time): whatever was waiting for it cannot go on. Fault, thrusters neutral; the
    /// fault clears as after any other, but an interrupted estimation is not restarted on
    /// its own (it would need the solver again): idle, or holding when a model is in force.
    pub fn on_solver_lost(&mut self, why: &str) {
        let t = self.last_t_ns.unwrap_or(0);
        if self.state != State::Fault {
            self.fault(t, why);
        } else {
            self.run.stop();
        }
        if self.resume == Resume::Estimate {
            self.resume = if self.models.current().is_some() {
                Resume::Active
            } else {
                Resume::Idle
            };
        }
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
        self.install_loaded(model)
    }

    /// The same for a model already prepared off the control thread
    /// ([`Model::prepared`], with the same estimator settings): only the checks against the
    /// machine (thruster count, confidence) and the swap are left.
    pub fn load_prepared(&mut self, model: PreparedModel) -> Result<(), Refused> {
        self.install_loaded(model.into_model())
    }

    fn install_loaded(&mut self, model: Model) -> Result<(), Refused> {
        let saved = model.version;
        self.try_swap(model, ModelSource::Loaded)
            .map_err(|e| Refused(format!("model not used: {e}")))?;
        // Versions only go up here: a file older than the model in force gets a new number,
        // and status says which version it was saved as.
        let what = match self.models.current() {
            Some(m) if saved > 0 && m.version != saved => {
                format!("model loaded (saved as v{saved})")
            }
            _ => "model loaded".to_string(),
        };
        self.describe_swap(&what);
        Ok(())
    }

    /// After an operator's swap (revert, load): status says which model is in force and
    /// where it came from, instead of the words of the run that made the old one.
    fn describe_swap(&mut self, what: &str) -> String {
        let Some(m) = self.models.current() else {
            return what.to_string();
        };
        self.text = format!("{what}: model v{}, {}", m.version, m.provenance());
        self.text.clone()
    }

    /// In Fault: whether clearing it resumes control (or the interrupted estimation) rather
    /// than idle. What a restart after a crash in Fault should resume.
    pub fn fault_resumes_control(&self) -> bool {
        matches!(self.resume, Resume::Active | Resume::Estimate)
    }

    /// The answer to one IMU sample. Always a command: neutral unless estimating or controlling.
    /// Everything the machine computes is referred to the reference supply voltage (what the
    /// estimator learns, what the refinement compares); the command is carried to the present
    /// voltage on its way out, finite and in [-1, 1] whatever happened.
    pub fn on_imu(&mut self, s: &ImuInput) -> Command {
        let mut cmd = self.respond(s);
        let n = cmd.count.min(cmd.thrust.len());
        self.supply.to_present(&mut cmd.thrust[..n]);
        cmd
    }

    /// The supply voltage the driver reports (V, validated), or `None` when it stopped
    /// reporting one: from the next sample on, commands are referred to it (`[supply]`).
    pub fn on_supply(&mut self, voltage_v: Option<f64>) {
        self.supply.on_voltage(voltage_v);
    }

    fn respond(&mut self, s: &ImuInput) -> Command {
        if self.samples == 0 {
            self.first_sample();
        }
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
        // Solves due by this sample's time, before the state acts on it (the due-time rule,
        // `crate::solve`).
        while let Some((purpose, result)) = self.run.solver().take_due(s.t_ns) {
            self.apply_solve(purpose, result);
        }

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
                let m = Motion {
                    gyro,
                    accel: motion_accel(&accel, &self.attitude.attitude()),
                    specific_force: accel,
                    depth: s.depth,
                };
                let elapsed = self.elapsed_s(s.t_ns);
                // The power whose output (after the deadband jump) the thrusters can still
                // give, referred, at the present voltage: a saturated pulse would teach the
                // estimator a weaker thruster than it has.
                let db = self.setup.machine.deadband.clamp(0.0, 0.5);
                let cap = ((self.supply.attainable() - db) / (1.0 - db)).clamp(0.0, 1.0);
                let ready = self.run.measure_noise(
                    &m,
                    elapsed,
                    &self.setup,
                    self.models.current(),
                    self.n,
                    cap,
                );
                if ready {
                    return self.start_pulse(s.t_ns);
                }
                Command::neutral(self.n)
            }
            State::Pulse => self.pulse_tick(s, &gyro, &accel),
            State::Settle => self.settle_tick(s, &gyro, &accel),
            State::Active => self.control_tick(s, &gyro, dt),
            State::Identify => self.identify_tick(s, &gyro, &accel, dt),
        }
    }

    /// A DVL's body velocity (m/s), when the vehicle has one: used by the dynamic
    /// estimation's navigation while it excites, and by the refinement's window while it
    /// controls; ignored otherwise (control does not use velocity).
    pub fn on_dvl(&mut self, velocity: [f64; 3]) {
        let v = Vector3::from(velocity);
        match self.state {
            State::Pulse | State::Settle | State::Identify => self.run.velocity_fix(&v),
            State::Active => self.refiner.velocity_fix(&v),
            _ => {}
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
            self.text_says_no_imu = true;
        }
    }

    /// The first sample ends "no IMU yet": status must not go on saying it beside a rate and
    /// a sample count (issue 27: it stayed until the next state change).
    fn first_sample(&mut self) {
        if std::mem::take(&mut self.text_says_no_imu) && self.state == State::Idle {
            self.text = IDLE_TEXT.into();
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
                    // What to do first: the fault's own text is long and may be cut.
                    return Err(Refused(format!(
                        "in fault: estimate once it clears ({})",
                        self.text
                    )));
                }
                if let Some(err_deg) = self.beyond_identification_budget() {
                    return Err(Refused(format!(
                        "the vehicle is {err_deg:.0} deg from its setpoint, beyond the \
                         identification budget of {:.0} deg (identification.attitude_budget_deg): \
                         let it settle, or hold, then estimate",
                        self.setup.identification.attitude_budget_deg
                    )));
                }
                let t = self.last_t_ns.unwrap_or(0);
                self.stopped = false;
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
                self.run.stop();
                if self.state == State::Identify && self.models.current().is_some() {
                    // Under control the vehicle is held: it stays held, by the model in force.
                    let why = self.describe_swap("estimation aborted: holding attitude");
                    self.transition(State::Active, &why);
                    return Ok("aborted; holding attitude".into());
                }
                self.transition(State::Idle, "estimation aborted: thrusters neutral");
                Ok("aborted".into())
            }
            Request::Hold => {
                if self.state == State::Fault {
                    return Err(Refused("in fault: cannot hold".into()));
                }
                if self.models.current().is_none() {
                    return Err(Refused("no model yet: estimate first".into()));
                }
                if self.samples == 0 {
                    return Err(Refused(NO_IMU_YET.into()));
                }
                self.run.stop();
                self.stopped = false;
                self.target = None;
                self.controller.reset();
                self.transition(State::Active, "holding attitude");
                Ok("holding".into())
            }
            Request::Idle => {
                self.run.stop();
                let t = self.last_t_ns.unwrap_or(0);
                if self.state == State::Fault {
                    self.resume = Resume::Idle;
                    return Ok("will stay idle after the fault clears".into());
                }
                self.phase_start_ns = t;
                self.transition(State::Idle, "idle on request: thrusters neutral");
                Ok("idle".into())
            }
            Request::Stop => {
                // Whatever runs (an estimation, its solve, levelling, control) ends here; the
                // next command is neutral. The model in force stays, so `hold` can resume.
                self.run.stop();
                self.levelling = None;
                self.controller.reset();
                self.stopped = true;
                self.resume = Resume::Idle;
                let t = self.last_t_ns.unwrap_or(0);
                if self.state == State::Fault {
                    // Already neutral; after the fault clears it stays idle.
                    return Ok(
                        "emergency stop: in fault, thrusters neutral; idle after it \
                               clears, until estimate or hold"
                            .into(),
                    );
                }
                self.phase_start_ns = t;
                self.transition(
                    State::Idle,
                    "emergency stop: thrusters neutral until estimate or hold",
                );
                Ok("emergency stop: thrusters neutral until estimate or hold".into())
            }
            Request::Revert => {
                let Some(prev) = self.models.take_previous() else {
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
    /// the current heading). Depth left out keeps the held depth, as angles do.
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
        let depth = match s.depth {
            DepthInput::Keep => self.target.as_ref().and_then(|t| t.depth),
            DepthInput::Release => None,
            DepthInput::Hold(d) => Some(d),
        };
        self.on_setpoint(attitude, depth);
    }

    pub fn on_reconfig(&mut self, r: Reconfig) {
        let count = r.count.clamp(1, MAX_THRUSTERS);
        let count_changed = count != self.n;
        self.n = count;
        self.geometry = r.geometry.clone().filter(|g| g.positions.len() == count);
        let t = self.last_t_ns.unwrap_or(0);
        // After an emergency stop a reconfiguration swaps models but drives no thruster.
        let mut estimate =
            self.setup.machine.on_reconfig == ReconfigPolicy::Estimate && !self.stopped;
        // Before any swap: what the learned model in force says about the unchanged rest.
        let prior = self.carry_over(r.change, count);
        if self.state.is_estimating() {
            self.run.stop();
        }
        match self.geometry.clone() {
            Some(g) => {
                let key = g.key();
                if let Some(cached) = self.models.cached(key) {
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
                    self.models.drop_current();
                    self.events.push(Event::ModelDropped(format!(
                        "{}: now {count} thrusters and no declared geometry",
                        r.what
                    )));
                }
            }
        }
        if estimate {
            self.start_estimation_with(t, &format!("{}: re-estimating", r.what), prior);
        } else if self.models.current().is_some() && self.state != State::Fault {
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
        let (pulse, planned, power) = match self.run.estimator() {
            Some(e) => (e.pulses(), e.plan_extent(), e.power()),
            // Not estimating: how many pulses the model in force took (0 for a nominal
            // one), not the last run's, which may have been refused or reverted.
            None => {
                let p = self.models.current().map_or(0, |m| m.pulses);
                (p, p, 0.0)
            }
        };
        // Likewise the bound: the running estimate's, else the model in force's (NaN when it
        // has none: nominal, or the paper's method).
        let error_bound = match (self.run.estimator(), self.models.current()) {
            // Only this run's estimate: the run keeps the previous one until its first solve,
            // and status once showed the old model's bound at the start of a new estimation
            // (as telemetry, which filters the same way).
            (Some(e), _) => self
                .run
                .last_estimate()
                .filter(|last| e.pulses() > 0 && last.pulses == e.pulses())
                .map(|e| e.rel_err_rot.max(e.rel_err_acc))
                .unwrap_or(f64::NAN),
            (None, Some(m)) => m.rel_err_rot.max(m.rel_err_acc),
            (None, None) => f64::NAN,
        };
        let levels = self
            .run
            .levels()
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
            model_version: self.models.current().map(|m| m.version).unwrap_or(0),
            imu_rate_hz: self.imu_rate_hz,
            vehicle_time_ns: self.last_t_ns.unwrap_or(0),
            thrusters: self.n,
            text: self.text.clone(),
            supply_voltage_v: self.supply.voltage_v(),
            supply: self.supply.state(),
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
            self.refiner.reset();
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
        self.run.stop();
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
            Resume::Active if self.models.current().is_some() => {
                self.target = None;
                self.transition(State::Active, "IMU back: holding attitude again")
            }
            _ => self.transition(State::Idle, "IMU back: idle"),
        }
    }

    /// What an estimation after `change` (now `count` thrusters) keeps from the model in force.
    fn carry_over(&self, change: ThrusterChange, count: usize) -> Option<DynamicPrior> {
        let cfg = &self.setup.identification;
        if !cfg.carry_over {
            return None;
        }
        carried_over(
            self.models.current()?,
            change,
            count,
            cfg.carry_over_se_scale,
        )
    }

    fn start_estimation(&mut self, t_ns: u64, why: &str) {
        self.start_estimation_with(t_ns, why, None);
    }

    /// An estimation starts, keeping `prior` (see `identification::carry_over`).
    fn start_estimation_with(&mut self, t_ns: u64, why: &str, prior: Option<DynamicPrior>) {
        let kept = if prior.is_some() {
            "; the other thrusters' columns are kept"
        } else {
            ""
        };
        let why = &format!("{why}{kept}");
        self.last_t_ns = self.last_t_ns.or(Some(t_ns));
        // Controlling with a model: identify under control (see `crate::identification`).
        let controlling =
            matches!(self.state, State::Active | State::Identify) || self.levelling.is_some();
        if controlling
            && self.models.current().is_some()
            && EstimationRun::closed_loop_possible(&self.setup)
        {
            self.levelling = None;
            self.run
                .begin_closed_loop(t_ns, &self.setup.identification, self.n);
            self.run.carry(prior, &self.setup.identification);
            self.transition(
                State::Identify,
                &format!("{why}: identifying under control"),
            );
            return;
        }
        self.run.restart();
        self.run.carry(prior, &self.setup.identification);
        // Controlling with a model: level the vehicle first (see MachineConfig::level_max_s).
        // A reconfiguration while levelling levels on (the vehicle is no more at rest).
        self.levelling = ((self.state == State::Active || self.levelling.is_some())
            && self.models.current().is_some()
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
        let (Some(model), Some(lev)) = (self.models.current(), self.levelling.as_mut()) else {
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
        if let Some(k) = self.run.begin_pulse(t_ns, &mut cmd.thrust) {
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
        let m = Motion {
            gyro: *gyro,
            accel: motion_accel(accel, &self.attitude.attitude()),
            specific_force: *accel,
            depth: s.depth,
        };
        let mut cmd = Command::neutral(self.n);
        cmd.mode = Mode::Estimating;
        let step = self.run.pulse_sample(
            s.t_ns,
            elapsed,
            &m,
            self.setup.machine.pulse_s,
            &mut cmd.thrust,
        );
        match step {
            PulseStep::NoRun => {
                self.transition(State::Idle, "internal: pulse without an estimator");
            }
            PulseStep::Pulsing => {
                finish(&mut cmd, self.setup.machine.deadband);
                return cmd;
            }
            PulseStep::Ended {
                gate: Some(d),
                pulses,
            } if d.is_stop() => {
                // A limit: the run's model is solved while the thrusters rest.
                self.run
                    .submit_pulse(s.t_ns, Purpose::Conclude, self.geometry_key());
                self.state = State::Solve;
                self.phase_start_ns = s.t_ns;
                self.text = format!("solving the model of {pulses} pulses");
            }
            PulseStep::Ended { gate, .. } if self.run.back_to_back() => {
                // Back to back the excitation goes on while the decision is out, as it did
                // when the decision was made on this sample: a stop applied at its due sample
                // ends the next pulse early and swaps in the model of the data up to here, the
                // same model as then (a rest at neutral instead changed every later pulse's
                // excitation, and with it every model learned after the first stop point).
                let purpose = if gate.is_some() {
                    Purpose::Progress
                } else {
                    Purpose::Decide
                };
                self.run.submit_pulse(s.t_ns, purpose, self.geometry_key());
                return self.start_pulse(s.t_ns);
            }
            PulseStep::Ended { gate, pulses } => {
                let purpose = if gate.is_some() {
                    Purpose::Progress
                } else {
                    // The bound decides: the pause after the pulse (longer than the solve's
                    // budget by default) does not end before the decision is applied.
                    Purpose::Decide
                };
                self.run.submit_pulse(s.t_ns, purpose, self.geometry_key());
                self.state = State::Settle;
                self.phase_start_ns = s.t_ns;
                self.text = format!("settling after pulse {pulses}");
            }
        }
        Command::neutral(self.n)
    }

    fn geometry_key(&self) -> Option<u64> {
        self.geometry.as_ref().map(|g| g.key())
    }

    /// A solve's result at its due sample (see `crate::solve`). The queue is emptied when
    /// a run stops, so every result applied belongs to the run under way.
    fn apply_solve(&mut self, purpose: Purpose, result: SolveResult) {
        let decision = result.decision;
        self.run.hint_lag(&result.estimate);
        match purpose {
            Purpose::Progress => self.run.keep_estimate(result.estimate),
            Purpose::Decide | Purpose::Conclude if decision.is_stop() => {
                self.solve(decision, result)
            }
            Purpose::Decide => self.run.keep_estimate(result.estimate),
            Purpose::Conclude => {
                // A limit that is no stop cannot come from the estimator; never leave the
                // run stuck in Solve.
                self.run.stop();
                self.transition(State::Idle, "internal: a concluding solve did not stop");
            }
            Purpose::Interval if decision.is_stop() => self.solve_under_control(decision, result),
            // The refinement's own (see `Refiner::observe`); never the run's.
            Purpose::Window => {}
            Purpose::Interval => {
                self.run.keep_estimate(result.estimate);
                let t = self.last_t_ns.unwrap_or(0);
                let excited = self.run.excited_s(t);
                self.text = format!("identifying under control: {excited:.0} s of dither");
            }
        }
    }

    fn settle_tick(&mut self, s: &ImuInput, gyro: &Vector3<f64>, accel: &Vector3<f64>) -> Command {
        let elapsed = self.elapsed_s(s.t_ns);
        let m = Motion {
            gyro: *gyro,
            accel: motion_accel(accel, &self.attitude.attitude()),
            specific_force: *accel,
            depth: s.depth,
        };
        let k = self.setup.estimator.k_sigma;
        let Some(quiet_for) = self.run.settle_sample(s.t_ns, &m, k) else {
            return Command::neutral(self.n);
        };
        if self.run.waiting_for(Purpose::Decide) {
            // The stop decision is out: the pause goes on at neutral (the samples feed the
            // fit) until it is applied.
            return Command::neutral(self.n);
        }
        let m = &self.setup.machine;
        if (elapsed >= m.settle_min_s && quiet_for >= m.settle_quiet_s) || elapsed >= m.settle_max_s
        {
            return self.start_pulse(s.t_ns);
        }
        Command::neutral(self.n)
    }

    /// While controlling with closed-loop identification: the attitude error (deg) when it is
    /// beyond the identification's budget, where no dither would be applied and the run could
    /// not learn (an operator's request is refused then; an automatic start waits in Identify,
    /// its dither faded out, until the vehicle is back within the budget).
    fn beyond_identification_budget(&self) -> Option<f64> {
        let controlling = self.state == State::Active && self.models.current().is_some();
        if !(controlling && EstimationRun::closed_loop_possible(&self.setup)) {
            return None;
        }
        let target = self.target?;
        let err_deg = self
            .attitude
            .attitude()
            .angle_to(&target.attitude)
            .to_degrees();
        (err_deg > self.setup.identification.attitude_budget_deg).then_some(err_deg)
    }

    /// Under control: the controller output with the dither on top, the estimator fed with
    /// the total command; at a stop the new model is swapped in without a bump (the target and
    /// the controller's state stay).
    fn identify_tick(
        &mut self,
        s: &ImuInput,
        gyro: &Vector3<f64>,
        accel: &Vector3<f64>,
        dt: f64,
    ) -> Command {
        if self.models.current().is_none() {
            self.run.stop();
            self.transition(State::Idle, "no model to identify under: thrusters neutral");
            return Command::neutral(self.n);
        }
        let (meas, target) = self.measured_and_target(s, gyro);
        let attitude = meas.attitude;
        let Some(model) = self.models.current() else {
            return Command::neutral(self.n);
        };
        let mut cmd = Command::neutral(self.n);
        cmd.mode = Mode::Estimating;
        let n = self.n.min(model.thrusters());
        self.last_desired = self
            .controller
            .update(&meas, &target, model, dt, &mut cmd.thrust[..n]);
        let m = Motion {
            gyro: *gyro,
            accel: motion_accel(accel, &attitude),
            specific_force: *accel,
            depth: s.depth,
        };
        let err_deg = attitude.angle_to(&target.attitude).to_degrees();
        let step = self.run.closed_loop_sample(
            s.t_ns,
            &m,
            &self.attitude.gyro_bias(),
            err_deg,
            &self.setup,
            Some(model),
            self.n,
            &mut cmd.thrust[..n],
        );
        finish(&mut cmd, self.setup.machine.deadband);
        match step {
            // The text stays the transition's (why the identification began) until the
            // first decision: a status reader must be able to see it.
            ClosedStep::Holding | ClosedStep::Exciting => {}
            ClosedStep::Decide { elapsed_s } => {
                let key = self.geometry_key();
                self.run
                    .submit_interval(s.t_ns, elapsed_s, &self.setup, key);
            }
        }
        cmd
    }

    fn solve_under_control(&mut self, decision: StopDecision, result: SolveResult) {
        let key = self.geometry_key();
        let t_ns = self.last_t_ns.unwrap_or(0);
        let seconds = self.run.excited_s(t_ns);
        let Some((candidate, _)) = self.run.conclude(result) else {
            return;
        };
        let why = match decision {
            StopDecision::Converged { rel_err_rot, rel_err_acc } => format!(
                "identified under control in {seconds:.1} s (error bound rot {rel_err_rot:.3}, acc {rel_err_acc:.3})"
            ),
            _ => format!("identification limit reached after {seconds:.1} s"),
        };
        match self.try_swap(candidate, ModelSource::Estimated) {
            Ok(()) => {
                if let Some(k) = key {
                    self.models.remember_current(k);
                }
                self.transition(
                    State::Active,
                    &format!("{why}: new model, holding attitude"),
                );
            }
            Err(e) => self.transition(
                State::Active,
                &format!("{why}: model rejected ({e}); old model kept"),
            ),
        }
    }

    fn solve(&mut self, decision: StopDecision, result: SolveResult) {
        self.state = State::Solve;
        let key = self.geometry_key();
        let Some((candidate, pulses)) = self.run.conclude(result) else {
            self.transition(State::Idle, "internal: a stopping solve made no model");
            return;
        };
        let why = match decision {
            StopDecision::Converged { rel_err_rot, rel_err_acc } => format!(
                "converged after {pulses} pulses (error bound rot {rel_err_rot:.3}, acc {rel_err_acc:.3})"
            ),
            StopDecision::PlanComplete => format!("planned {pulses} pulses done"),
            StopDecision::MaxPulses => format!("pulse limit {pulses} reached"),
            StopDecision::Continue => "stopped".into(),
        };
        // The status text holds 128 bytes: the IMU's position leads, the bound is in the
        // rejection event and the model's dynamics.
        let imu_note = match candidate.dynamics.as_ref().and_then(|d| d.imu_position) {
            Some(p) if p.contradicted => Some(format!(
                "IMU found at {} m, not as configured (estimator.imu_position_m)",
                fmt_xyz(&p.position_m)
            )),
            _ => None,
        };
        let why = match &imu_note {
            Some(note) => format!("{why}; {note}"),
            None => why,
        };
        // Rotation that neither thrust nor the vehicle's own dynamics explain (a swell, a
        // tether): the fit absorbed it somewhere, and its bound does not know it.
        let (unexplained, tilt_deg) = candidate.dynamics.as_ref().map_or((0.0, 0.0), |d| {
            (d.unexplained_rate_radps, d.max_tilt_rad.to_degrees())
        });
        let limit = self.setup.machine.max_unexplained_rate_radps;
        if unexplained > limit {
            let text = format!(
                "{unexplained:.3} rad/s of rotation unexplained (limit {limit:.3}; water?), tilted {tilt_deg:.0} deg: model rejected; old model kept"
            );
            self.events.push(Event::ModelRejected(text.clone()));
            self.transition(self.after_refusal(), &text);
            return;
        }
        match self.try_swap(candidate, ModelSource::Estimated) {
            Ok(()) => {
                if let Some(k) = key {
                    self.models.remember_current(k);
                }
                if self.setup.machine.control_after_estimate {
                    self.target = None;
                    self.controller.reset();
                    self.transition(
                        State::Active,
                        &format!("{why}: new model, holding attitude"),
                    );
                    // A burst that already reached the target needs no refining.
                    let coarse = self.models.current().is_some_and(|m| {
                        m.rel_err_rot.max(m.rel_err_acc) > self.setup.estimator.target_rel_err
                    });
                    if self.run.was_burst() && coarse {
                        let t = self.last_t_ns.unwrap_or(0);
                        self.start_estimation(t, &format!("{why}: burst model in"));
                    }
                } else {
                    self.transition(State::Idle, &format!("{why}: new model"));
                }
            }
            Err(e) => {
                let next = self.after_refusal();
                let text = match &imu_note {
                    Some(note) => format!("{note}: model rejected; old model kept"),
                    None => format!("{why}: model rejected ({e}); old model kept"),
                };
                self.transition(next, &text);
            }
        }
    }

    /// Where a refused estimate leaves the vehicle: holding with the old model, if there is
    /// one and control follows estimation, else Idle (thrusters neutral).
    fn after_refusal(&self) -> State {
        if self.models.current().is_some() && self.setup.machine.control_after_estimate {
            State::Active
        } else {
            State::Idle
        }
    }

    /// Validate and install a model between two ticks: the monitor judges the new one on fresh
    /// data only.
    fn try_swap(
        &mut self,
        model: Model,
        source: ModelSource,
    ) -> Result<(), crate::model::SwapRejection> {
        match self
            .models
            .swap(model, source, self.n, self.setup.machine.max_swap_rel_err)
        {
            Ok(installed) => {
                self.monitor.reset(self.n);
                self.refiner.reset();
                self.events.push(Event::ModelSwapped(Box::new(installed)));
                Ok(())
            }
            Err(e) => {
                self.events.push(Event::ModelRejected(e.to_string()));
                Err(e)
            }
        }
    }

    /// What the controller sees of this sample: filtered attitude, bias-free rate, depth.
    fn measured(&self, s: &ImuInput, gyro: &Vector3<f64>) -> Measured {
        Measured {
            attitude: self.attitude.attitude(),
            rate: gyro - self.attitude.gyro_bias(),
            depth: s.depth,
        }
    }

    /// What the controller sees of this sample, and the target it holds. Without a setpoint,
    /// hold level at the current heading and depth: a vehicle may enter Active still swinging
    /// from the last pulse, and that tilt is nothing to keep.
    fn measured_and_target(&mut self, s: &ImuInput, gyro: &Vector3<f64>) -> (Measured, Target) {
        let meas = self.measured(s, gyro);
        let heading = meas.attitude.euler_angles().2;
        let target = *self.target.get_or_insert_with(|| Target {
            attitude: UnitQuaternion::from_euler_angles(0.0, 0.0, heading),
            depth: s.depth,
        });
        (meas, target)
    }

    fn control_tick(&mut self, s: &ImuInput, gyro: &Vector3<f64>, dt: f64) -> Command {
        if self.models.current().is_none() {
            return Command::neutral(self.n);
        }
        let (meas, target) = self.measured_and_target(s, gyro);
        let attitude = meas.attitude;
        let Some(model) = self.models.current() else {
            return Command::neutral(self.n);
        };
        let mut cmd = Command::neutral(self.n);
        cmd.mode = Mode::Controlling;
        let n = self.n.min(model.thrusters());
        self.last_desired = self
            .controller
            .update(&meas, &target, model, dt, &mut cmd.thrust[..n]);
        let err_rad = attitude.angle_to(&target.attitude);
        let verdict = self.refiner.observe(
            &Tick {
                t_ns: s.t_ns,
                gyro,
                gyro_bias: &self.attitude.gyro_bias(),
                attitude: &attitude,
                specific_force: &Vector3::from(s.accel),
                depth: s.depth,
                err_deg: err_rad.to_degrees(),
                setpoint: &target.attitude,
            },
            model,
            self.run.levels(),
            &self.setup.estimator,
            &mut cmd.thrust[..n],
        );
        // The monitor compares in model units: the command sent (dither included) before
        // deadband compensation.
        let gravity_body = attitude.inverse() * Vector3::z();
        let mismatch = self.monitor.observe(
            dt,
            err_rad,
            &meas.rate,
            &gravity_body,
            &model.effectiveness,
            &cmd.thrust[..n],
        );
        finish(&mut cmd, self.setup.machine.deadband);
        if let Some(m) = mismatch {
            self.on_mismatch(s.t_ns, m.to_string(), ThrusterChange::Unknown);
        } else if let Some(v) = verdict.filter(|v| v.changed) {
            self.on_mismatch(s.t_ns, v.to_string(), ThrusterChange::Moved(v.thruster));
        } else if let Some(fused) = self.refiner.take_refined() {
            self.install_refined(fused.model);
        }
        cmd
    }

    /// A model the continuous refinement updated: checked like every other and swapped in.
    /// The monitor and the refiner keep going: the model moved by a window's worth of drift,
    /// not to a new vehicle.
    fn install_refined(&mut self, model: Model) {
        match self.models.swap(
            model,
            ModelSource::Estimated,
            self.n,
            self.setup.machine.max_swap_rel_err,
        ) {
            Ok(installed) => {
                if let Some(k) = installed.geometry_key {
                    self.models.remember_current(k);
                }
                self.events.push(Event::ModelSwapped(Box::new(installed)));
            }
            Err(e) => self
                .events
                .push(Event::ModelRejected(format!("refined model: {e}"))),
        }
    }

    /// The monitor (or the refinement, which names the thruster: `change`) found the
    /// thrusters doing something else than the model says.
    fn on_mismatch(&mut self, t_ns: u64, why: String, change: ThrusterChange) {
        self.refiner.reset();
        self.events.push(Event::MismatchDetected(why.clone()));
        self.monitor.reset(self.n);
        match self.monitor.action() {
            MismatchAction::Estimate => {
                let prior = self.carry_over(change, self.n);
                self.start_estimation_with(t_ns, &format!("{why}: re-estimating"), prior)
            }
            MismatchAction::Report | MismatchAction::Off => {
                self.text = format!("holding attitude; {why}");
            }
        }
    }
}

/// A body-frame position as "(x, y, z)" in metres to the centimetre's tenth.
fn fmt_xyz(p: &nalgebra::Vector3<f64>) -> String {
    format!("({:.3}, {:.3}, {:.3})", p.x, p.y, p.z)
}
