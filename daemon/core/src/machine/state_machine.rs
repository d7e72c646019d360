//! The machine itself: routes every input to the state it is in, and owns the states and their
//! changes (`transition`, `next_phase`: both through `enter`), faults and recovery. Its other
//! methods live in the child modules, one job each: `requests`, `swaps`, `open_loop` (the
//! estimation with the thrusters free) and `under_control`. The model slot (`models`) and the
//! estimation run (`estimation`) hold what they own.

use nalgebra::{UnitQuaternion, Vector3};
use thruster_protocol::MAX_THRUSTERS;

use super::config::{MachineSetup, ReconfigPolicy};
use super::depth_watch::DepthWatch;
use super::estimation::ESTIMATION;
use super::estimation::{ClosedStep, EstimationRun, IdleRest, Motion, PulseStep, MIN_REST_SAMPLES};
use super::hold_watch::{actuated_error_deg, HoldLost, HoldWatch, Settling, HELD_CLEARS_S};
use super::models::ModelSlot;
use super::types::{
    finish, jump_deadband, Command, DepthInput, Event, Geometry, ImuInput, Mode, Reconfig, Refused,
    Request, SetpointInput, State, StatusSnapshot, NO_IMU_YET,
};
use crate::adaptation::identification::carry_over::{carried_over, ThrusterChange};
use crate::adaptation::identification::fight::PendingConfirmation;
use crate::adaptation::monitor::{MismatchAction, ModelMonitor};
use crate::adaptation::refinement::{Refiner, Tick, WindowVerdict};
use crate::attitude::AttitudeFilter;
use crate::controller::{Controller, Measured, Target};
use crate::estimator::dynamic::prior::DynamicPrior;
use crate::estimator::response::motion_accel;
use crate::estimator::Estimator;
use crate::estimator::{Estimate, NoiseLevels, StopDecision};
use crate::model::{nominal_effectiveness, Model, ModelSource, PreparedModel};
use crate::solve::{owner_of, Purpose, SolveJob, SolveResult, SolverMode};
use crate::supply::Supply;

mod curve_learned;
mod curve_named;
mod gain_gap;
mod open_loop;
mod requests;
mod swaps;
mod under_control;

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
    /// When the vehicle's present hold began, ns: the start of control, kept through an
    /// identification under control (Active <-> Identify is one hold, as for `hold_watch`).
    /// The sea-state gauge's settling counts from it; from `phase_start_ns`, each
    /// identification restarted it, and at the paper's noise in moderate water the gauge
    /// never counted between a swell's false alarms (0-0.6 s in 4 minutes, AMOUR-5 seed 3:
    /// 23 needless re-estimations in 20 minutes).
    hold_start_ns: u64,
    last_t_ns: Option<u64>,
    attitude: AttitudeFilter,
    controller: Controller,
    monitor: ModelMonitor,
    refiner: Refiner,
    target: Option<Target>,
    models: ModelSlot,
    geometry: Option<Geometry>,
    run: EstimationRun,
    /// How far the water moved the vehicle while held (`identification::sea_state`).
    #[serde(default)]
    sea_state: crate::adaptation::identification::sea_state::SeaState,
    /// Whether that gauge says the vehicle is in a sea (the detectors' calibrations apply).
    #[serde(default)]
    in_a_sea: crate::adaptation::identification::sea_state::InASea,
    /// The rest the vehicle takes while idle, for an estimation asked for from idle
    /// (`machine.rest_from_idle`).
    idle_rest: IdleRest,
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
    /// Whether a depth asked for is measured (the status says when it is not).
    #[serde(default)]
    depth_watch: DepthWatch,
    /// The supply voltage and the referral of commands to the reference voltage: every
    /// command inside the machine is referred, only the outgoing one is carried to the
    /// present voltage (`crate::supply`).
    supply: Supply,
    /// How long the vehicle has been too far from its setpoint (`machine.lost_hold_*`).
    #[serde(default)]
    hold_watch: HoldWatch,
    /// The hold was lost once and an estimation from rest followed: lost again before an
    /// operator's estimate or hold, a reconfiguration, or a minute held (`HELD_CLEARS_S`), the
    /// thrusters stay neutral (no estimation loop on a vehicle that cannot be held).
    #[serde(default)]
    hold_lost_once: bool,
    /// Idle after a lost hold, waiting for the vehicle to settle before estimating from rest.
    #[serde(default)]
    settling: Option<Settling>,
    /// The last sample whose command drove a thruster, ns (None: none has yet): a noise
    /// rest soon after it waits for the swing it left (`machine.max_rest_swing_radps`).
    #[serde(default)]
    last_driven_ns: Option<u64>,
    /// The identification under way was started by the daemon's own suspicion (the
    /// refinement's change test or the monitor's mismatch), not an announced change: at its
    /// limit its model is refused (`identification.at_limit_unannounced`).
    #[serde(default)]
    identifying_unannounced: bool,
    /// The identification under way confirms a model fitted on the controller's fight (a
    /// vehicle the model in force could not hold, in still water: `identification::fight`):
    /// if it is a fight again, the daemon lets go and estimates from rest.
    #[serde(default)]
    confirming_fight: bool,
    /// A fight's model in force, its confirmation waiting for the vehicle to be held; cleared
    /// by any state but Active.
    #[serde(default)]
    pending_confirmation: Option<PendingConfirmation>,
    /// A thrust curve an identification named (its model refused), until the next model or
    /// estimation: the detectors' mismatches are then reported, not re-identified
    /// (`curve_named`).
    #[serde(default)]
    curve_named: Option<curve_named::CurveNamed>,
    /// Thrust curves learned since the last model swap (`curve_learned`: an identification
    /// that names a curve learns it and identifies again, at most `MAX_CURVE_LEARNS` times
    /// in a row before it is refused and `curve_named`).
    #[serde(default)]
    curve_learns: u8,
    /// A curve just learned, the identification on it waiting for the vehicle to be held
    /// (`curve_learned`); cleared by any state but Active.
    #[serde(default)]
    curve_pending: Option<curve_learned::CurvePending>,
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
            hold_start_ns: 0,
            last_t_ns: None,
            attitude: AttitudeFilter::new(setup.attitude.clone()),
            controller: Controller::new(setup.controller.clone()),
            monitor: ModelMonitor::new(setup.monitor.clone(), n),
            refiner: Refiner::new(setup.refinement.clone(), n),
            target: None,
            models: ModelSlot::default(),
            geometry: None,
            run: EstimationRun::new(setup.machine.solve_budget_s),
            sea_state: Default::default(),
            in_a_sea: Default::default(),
            idle_rest: IdleRest::default(),
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
            depth_watch: DepthWatch::default(),
            supply: Supply::new(setup.supply.clone()),
            hold_watch: HoldWatch::default(),
            hold_lost_once: false,
            settling: None,
            last_driven_ns: None,
            identifying_unannounced: false,
            confirming_fight: false,
            pending_confirmation: None,
            curve_named: None,
            curve_learns: 0,
            curve_pending: None,
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

    /// How much the vehicle swayed over the long idle rest the last estimation started from,
    /// beyond the IMU's white noise (1: still; None: no long rest;
    /// `navigation::long_rest_sway`).
    pub fn last_rest_sway(&self) -> Option<f64> {
        self.run.idle_sway()
    }

    pub fn last_estimate(&self) -> Option<&Estimate> {
        self.run.last_estimate()
    }

    /// The background refinement's last window verdict (how the closed-loop data fit the
    /// model in force), if a window has ended since start.
    pub fn refinement(&self) -> Option<&WindowVerdict> {
        self.refiner.last()
    }

    /// The refinement's windows' common gain over the model in force, pooled
    /// (`refinement::common_gain`); None without a model or a window judged against it.
    pub fn refinement_gain(
        &self,
    ) -> Option<crate::adaptation::refinement::common_gain::PooledGain> {
        self.refiner
            .pooled_gain(&self.models.current()?.effectiveness)
    }

    /// The change test's largest statistic at the last control tick (passed or not), for
    /// tracing a detection or a false alarm.
    pub fn change_stat(&self) -> Option<crate::adaptation::refinement::change_test::ChangeStat> {
        self.refiner.change_stat()
    }

    /// The RMS attitude error while held, deg, over the last ~10 s of settled control (None
    /// until known; `identification::sea_state`).
    pub fn sea_state_deg(&self) -> Option<f64> {
        self.sea_state.rms_deg()
    }

    /// The control the sea-state gauge has counted, s (`sea_state`).
    pub fn sea_state_counted_s(&self) -> f64 {
        self.sea_state.measured_s()
    }

    /// Whether the detectors take the vehicle to be in a sea (`sea_state::InASea`): their
    /// calibrations against the water apply.
    pub fn in_a_sea(&self) -> bool {
        self.in_a_sea.get()
    }

    /// The thrust curve the commands go out through, learned under control (thrust ~
    /// command^p; `curve_learned`), when one is.
    pub fn learned_thrust_exponent(&self) -> Option<f64> {
        self.supply.learned_exponent()
    }

    /// A fight's model is in force and its confirmation waits for the vehicle to be held
    /// (`adaptation::identification::fight`).
    pub fn confirmation_pending(&self) -> bool {
        self.pending_confirmation.is_some()
    }

    /// The identification under control's dither against the controller's command so far
    /// (None outside one).
    pub fn identification_excitation(&self) -> Option<crate::machine::Excitation> {
        self.run.excitation()
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

    /// The estimator of the estimation under way (None between runs): read-only, for the lab's
    /// decisive runs, which refit its logged samples with parts of them replaced by the truth.
    pub fn estimator(&self) -> Option<&Estimator> {
        self.run.estimator()
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

    /// In Fault: whether clearing it resumes control (or the interrupted estimation) rather
    /// than idle. What a restart after a crash in Fault should resume.
    pub fn fault_resumes_control(&self) -> bool {
        matches!(self.resume, Resume::Active | Resume::Estimate)
    }

    /// The answer to one IMU sample. Always a command: neutral unless estimating or controlling.
    /// Everything the machine computes is referred to the reference supply voltage (what the
    /// estimator learns, what the refinement compares); the command is carried to the present
    /// voltage on its way out, finite and in [-1, 1] whatever happened. In the order the
    /// thruster has them: through a power-law curve (learned or configured), which starts
    /// at the dead band's edge, then over the dead band (`machine.deadband`), then through
    /// the T200's table, which holds its own (`supply`).
    pub fn on_imu(&mut self, s: &ImuInput) -> Command {
        let mut cmd = self.respond(s);
        let n = cmd.count.min(cmd.thrust.len());
        let thrust = &mut cmd.thrust[..n];
        self.supply.through_curve(thrust);
        jump_deadband(thrust, self.setup.machine.deadband);
        self.supply.to_present(thrust);
        if thrust.iter().any(|v| *v != 0.0) {
            self.last_driven_ns = Some(s.t_ns);
        }
        cmd
    }

    /// The supply voltage the driver reports (V, validated), or `None` when it stopped
    /// reporting one: from the next sample on, commands are referred to it (`[supply]`).
    pub fn on_supply(&mut self, voltage_v: Option<f64>) {
        let t_s = self.last_t_ns.map_or(0.0, |t| t as f64 * 1e-9);
        self.supply.on_reading(t_s, voltage_v);
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
        self.depth_watch.on_sample(s.t_ns, s.depth);
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
            State::Idle => {
                if self.setup.machine.rest_from_idle {
                    let m = self.motion(s, &gyro, &accel);
                    self.idle_rest.push(
                        s.t_ns,
                        &m,
                        self.setup.machine.noise_s,
                        self.setup.machine.gyro_bias_rest_s,
                    );
                }
                if self.settling.is_some() {
                    self.await_settled(s.t_ns);
                }
                Command::neutral(self.n)
            }
            State::Solve => Command::neutral(self.n),
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
                let m = self.motion(s, &gyro, &accel);
                let elapsed = self.elapsed_s(s.t_ns);
                // The power whose output (after the deadband jump) the thrusters can still
                // give, referred, at the present voltage: a saturated pulse would teach the
                // estimator a weaker thruster than it has.
                let db = self.setup.machine.deadband.clamp(0.0, 0.5);
                let cap = ((self.supply.attainable() - db) / (1.0 - db)).clamp(0.0, 1.0);
                self.run.rest_sample(&m, s.t_ns);
                let neutral_s = self
                    .last_driven_ns
                    .map(|t| s.t_ns.saturating_sub(t) as f64 * 1e-9);
                let ready = self.run.measure_noise(
                    elapsed,
                    neutral_s,
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
            // A depth hold nothing measures is said on every state's text.
            text: match self.depth_watch.note(
                self.last_t_ns.unwrap_or(0),
                self.target.as_ref().and_then(|t| t.depth),
            ) {
                Some(note) => format!("{}; {note}", self.text),
                None => self.text.clone(),
            },
            supply_voltage_v: self.supply.voltage_v(),
            supply: self.supply.state(),
        }
    }

    // ---- internals ----

    fn elapsed_s(&self, t_ns: u64) -> f64 {
        t_ns.saturating_sub(self.phase_start_ns) as f64 * 1e-9
    }

    /// A change of state the operator is told of: status says `why`, and a StateChanged
    /// event carries it when the state is another one. The phase clock restarts at the last
    /// sample.
    fn transition(&mut self, to: State, why: &str) {
        self.enter(to, self.last_t_ns, why.to_string(), Some(why));
    }

    /// A step between the phases of one estimation (Pulse, Settle, Solve): the phase clock
    /// restarts at `t_ns` and status says where the run is, but no event is raised (an
    /// operator follows one estimation, not each of its pulses).
    fn next_phase(&mut self, to: State, t_ns: u64, text: String) {
        self.enter(to, Some(t_ns), text, None);
    }

    /// Every change of state goes through here: the state, the status text, the phase clock
    /// (restarted at `phase_start`, when there is one), what leaving or entering a state
    /// ends or starts, and the event (`announce`, raised only when the state changes).
    fn enter(&mut self, to: State, phase_start: Option<u64>, text: String, announce: Option<&str>) {
        let from = self.state;
        self.state = to;
        self.text = text;
        if from != State::Idle || to != State::Idle {
            // The rest while idle is the rest of one unbroken idle spell.
            self.idle_rest.clear();
        }
        if to != State::MeasureNoise {
            self.levelling = None;
        }
        if to != State::Active {
            // Any other state ends the fight's model's wait: a new estimation, a lost hold,
            // an operator's idle or stop.
            self.pending_confirmation = None;
            self.end_curve_wait();
        }
        // Leaving Idle ends the wait for the vehicle to settle (so do an operator's idle,
        // stop or abort and a reconfiguration: `on_request`, `on_reconfig`; an estimate or
        // hold leaves Idle).
        if to != State::Idle {
            self.settling = None;
        }
        let holding = |s: State| matches!(s, State::Active | State::Identify);
        if let Some(t) = phase_start {
            self.phase_start_ns = t;
            if !(holding(from) && holding(to)) {
                self.hold_start_ns = t;
            }
        }
        if from == State::Identify && to == State::Active {
            // The dither stops, the hold goes on: the gauge counts again once the vehicle
            // has settled from it, as after a setpoint step.
            self.sea_state
                .manoeuvre_ended(phase_start.or(self.last_t_ns).unwrap_or(0));
        }
        if to == State::Active && from != State::Active {
            // Control (re)starts: judge the model on fresh data only.
            self.monitor.reset(self.n);
            self.refiner.reset();
        }
        if !matches!(to, State::Active | State::Identify) {
            // Not controlling: a later hold is a new one (Active <-> Identify is one hold).
            self.hold_watch.reset();
        }
        if let (true, Some(why)) = (from != to, announce) {
            self.events.push(Event::StateChanged {
                from,
                to,
                why: why.to_string(),
            });
        }
    }

    /// This sample as the estimation sees it: the rate, the acceleration with gravity taken
    /// out along the filtered attitude, the specific force as measured, the depth.
    fn motion(&self, s: &ImuInput, gyro: &Vector3<f64>, accel: &Vector3<f64>) -> Motion {
        Motion {
            gyro: *gyro,
            accel: motion_accel(accel, &self.attitude.attitude()),
            specific_force: *accel,
            depth: s.depth,
            mag: s.mag.map(Vector3::from),
        }
    }

    fn fault(&mut self, _t_ns: u64, why: &str) {
        self.resume = match self.state {
            s if s.is_estimating() => Resume::Estimate,
            // Waiting, neutral, to estimate from rest after a lost hold: the fault's own
            // neutral spell is a wait too, and the estimation follows it.
            State::Idle if self.settling.is_some() => Resume::Estimate,
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

    /// What the controller sees of this sample: filtered attitude, bias-free rate, depth.
    fn measured(&self, s: &ImuInput, gyro: &Vector3<f64>) -> Measured {
        Measured {
            attitude: self.attitude.attitude(),
            rate: gyro - self.attitude.gyro_bias(),
            depth: s.depth,
        }
    }
}

/// A body-frame position as "(x, y, z)" in metres to the centimetre's tenth.
fn fmt_xyz(p: &nalgebra::Vector3<f64>) -> String {
    format!("({:.3}, {:.3}, {:.3})", p.x, p.y, p.z)
}
