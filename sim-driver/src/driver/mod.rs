//! The `thruster-sim run` process: the physics core at the IPC edge.
//!
//! The rest of this crate is pure; this module owns the clock, the iceoryx2 ports and the
//! files. Per sample it publishes an [`ImuSample`] on `<ns>/imu` (+ its event), applies the
//! [`ThrustCommand`]s that pass the protocol's command gate ([`thruster_protocol::gate`]), plays the scenario, announces changes on
//! `<ns>/reconfig`, publishes the true effectiveness on `<ns>/truth` (history 1) at start,
//! after every change and at the end, and the true vehicle state on `<ns>/vehicle` before
//! every sample.
//!
//! Sample clock: sample `seq` (from 1) is taken at `t_ns = (seq - 1) * period`; seq 1 is the
//! vehicle at rest at t = 0. Two pacing modes share everything else:
//! - [`Mode::Realtime`](crate::settings::Mode): see `realtime.rs`.
//! - [`Mode::Lockstep`](crate::settings::Mode): see `lockstep.rs`.

pub mod convert;
pub mod shutdown;
pub mod stats_file;
pub mod truth_file;
pub mod wait;

mod lockstep;
mod realtime;
mod stepping;

use std::time::{Duration, Instant};
use thruster_driver_kit::LogLimiter;

use thruster_protocol::gate::{Answerable, CommandGate, GateSettings, SampleTimes};
use thruster_protocol::services::{Inbox, IpcConfig, IpcError, IpcNode, Port};
use thruster_protocol::validate::{RejectCounters, RejectReason};
use thruster_protocol::{
    DriverStatusMsg, DvlSample, ImuSample, OutputState, ReconfigEvent, ThrustCommand, TruthMsg,
    Validate, VehicleStateMsg,
};
use tracing::{debug, error, info, warn};

use crate::load::LoadError;
use crate::scenario::{Action, Event, Scenario};
use crate::settings::{Mode, Settings};
use crate::sim::{SimError, Simulator};
use crate::vehicle::Vehicle;
use shutdown::Shutdown;
use stats_file::{StatsFile, StatsFileError};
use truth_file::{TruthEntry, TruthFile, TruthFileError};

/// How long the ports stay open after the last sample, so readers can take it.
const EXIT_LINGER: std::time::Duration = std::time::Duration::from_millis(100);
/// Node name of the driver in iceoryx2 listings.
pub const NODE_NAME: &str = "thruster-sim";

/// A battery's voltage change that republishes the truth, V (the T200's thrust moves ~0.4 %
/// per 50 mV at 16 V).
const TRUTH_VOLTAGE_STEP_V: f64 = 0.05;

/// How often the truth port hands its history to late subscribers, wall time.
const HOUSEKEEPING_PERIOD: Duration = Duration::from_millis(50);
/// How often progress is logged, wall time.
const REPORT_PERIOD: Duration = Duration::from_secs(10);

/// Failures of the driver.
#[derive(Debug, thiserror::Error)]
pub enum DriverError {
    /// IPC setup or transfer failed.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// The vehicle or scenario file is invalid.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// The simulator refused a configuration.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// A scenario event cannot be applied to this vehicle (checked before the run starts).
    // The reason is in the message and not a `source`: a chain printed whole ("{:#}") said
    // it twice.
    #[error("{origin}: event[{index}] at t = {t_s} s ({action}): {error}")]
    Scenario {
        /// The scenario file.
        origin: String,
        /// Index of the event in time order.
        index: usize,
        /// Its time, s.
        t_s: f64,
        /// Its action kind.
        action: &'static str,
        /// Why it fails (boxed: keeps every `Result` of the driver small).
        error: Box<SimError>,
    },
    /// The truth file could not be written.
    #[error(transparent)]
    TruthFile(#[from] TruthFileError),
    /// The link statistics file could not be written.
    #[error(transparent)]
    StatsFile(#[from] StatsFileError),
    /// `--stats-file` was given in lockstep (it measures the real-time loop only).
    #[error("--stats-file needs real-time mode")]
    StatsNeedRealtime,
    /// The stepping controller sent a bad line or closed standard output.
    #[error(transparent)]
    Stepping(#[from] stepping::SteppingError),
    /// The integration produced non-finite values.
    #[error("the simulation diverged at t = {t_s} s (non-finite sensor values)")]
    Diverged {
        /// Simulation time, s.
        t_s: f64,
    },
}

/// Why a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// `duration_s` of vehicle time has passed.
    Duration,
    /// SIGINT, SIGTERM or SIGHUP.
    Signal,
}

/// What a run did.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Why it ended.
    pub reason: StopReason,
    /// Vehicle time simulated, s.
    pub vehicle_s: f64,
    /// Wall time from the first sample to the end, s.
    pub wall_s: f64,
    /// IMU samples published.
    pub samples: u64,
    /// Commands applied.
    pub applied: u64,
    /// Lockstep samples that got no answer in time; in real time, the watchdog's expiries
    /// (both are `watchdog_expiries` on driver_status).
    pub timeouts: u64,
    /// Commands rejected, by category.
    pub rejected: RejectCounters,
    /// Late answers dropped.
    pub stale: u64,
    /// Sensor values clipped to the protocol's ranges.
    pub clipped: u64,
}

impl Summary {
    /// Vehicle seconds per wall second.
    pub fn speedup(&self) -> f64 {
        if self.wall_s > 0.0 {
            self.vehicle_s / self.wall_s
        } else {
            0.0
        }
    }
}

/// The ports of the driver. The node is declared last so it is dropped after its ports.
struct Ports {
    thrust: Inbox<ThrustCommand>,
    imu: Port<ImuSample>,
    truth: Port<TruthMsg>,
    reconfig: Port<ReconfigEvent>,
    vehicle: Port<VehicleStateMsg>,
    driver_status: Port<DriverStatusMsg>,
    /// Only when the sensors include a DVL (no service otherwise).
    dvl: Option<Port<DvlSample>>,
    _node: IpcNode,
    /// After the node: the last process of the namespace to stop removes iceoryx2's residue.
    _tidy: thruster_protocol::services::TidyOnDrop,
}

/// The simulator process: settings, physics, scenario and ports.
pub struct Driver {
    settings: Settings,
    sim: Simulator,
    scenario: Scenario,
    gate: CommandGate,
    truth_file: Option<TruthFile>,
    /// `--stats-file` (real time only).
    stats: Option<StatsFile>,
    /// `--stepped`: the allowance of samples from standard input.
    stepping: Option<stepping::Stepping>,
    stop: Shutdown,
    period_ns: u64,
    /// Seq of the newest sample taken (0 before the first).
    imu_seq: u64,
    /// The DVL's measurement taken with the current sample, sent just before it.
    dvl_pending: Option<DvlSample>,
    dvl_seq: u64,
    /// The true state at the newest sample, and whether it was published.
    state: VehicleStateMsg,
    state_sent: bool,
    truth_seq: u64,
    reconfig_seq: u64,
    /// The held commands are all zero.
    neutral: bool,
    applied: u64,
    timeouts: u64,
    clipped: u64,
    reject_log: LogLimiter,
    /// Lockstep busy-poll policy.
    spin: wait::AdaptiveSpin,
    started: Option<Instant>,
    next_housekeeping: Instant,
    next_report: Instant,
    /// Vehicle time at which the next driver status is due, and what the last one said
    /// (rejections, output state, count) so a change goes out at once.
    next_driver_status_ns: u64,
    /// Supply voltage of the last truth published, V.
    truth_voltage_v: f64,
    driver_status_seq: u64,
    last_driver_status: Option<(u64, u32, u32)>,
    /// Why the last thrust command was rejected, for the driver status.
    last_rejection: Option<String>,
    /// systemd notify: READY when the loop starts, WATCHDOG=1 from its housekeeping.
    systemd: thruster_driver_kit::Systemd,
    ports: Ports,
}

impl DriverError {
    /// The error is the configuration's (a vehicle, scenario or simulator setting), not the
    /// run's: the process then exits `EXIT_CONFIG`.
    pub fn is_config(&self) -> bool {
        matches!(
            self,
            DriverError::Load(_) | DriverError::Sim(_) | DriverError::Scenario { .. }
        )
    }
}

impl Driver {
    /// Loads the vehicle and scenario, checks that every scenario event applies, builds the
    /// simulator and opens the ports in `settings.namespace`.
    pub fn new(settings: Settings, stop: Shutdown) -> Result<Driver, DriverError> {
        let vehicle = Vehicle::load(&settings.vehicle)?;
        let sim = Simulator::with_options(
            vehicle,
            settings.sensors.clone(),
            settings.seed,
            settings.sim.clone(),
        )?;
        let scenario = match &settings.scenario {
            Some(path) => {
                let s = Scenario::load(path)?;
                dry_run(&sim, &s, &path.display().to_string())?;
                s
            }
            None => Scenario::default(),
        };
        let ipc = IpcConfig::with_root_base(&settings.namespace, &settings.ipc_root)?;
        let node = ipc.create_node(NODE_NAME)?;
        // The inbox first: an answer can never arrive before it exists.
        let ports = Ports {
            thrust: Inbox::create(&node, &ipc)?,
            imu: Port::create(&node, &ipc)?,
            truth: Port::create(&node, &ipc)?,
            reconfig: Port::create(&node, &ipc)?,
            vehicle: Port::create(&node, &ipc)?,
            driver_status: Port::create(&node, &ipc)?,
            dvl: match settings.sensors.dvl {
                Some(_) => Some(Port::create(&node, &ipc)?),
                None => None,
            },
            _node: node,
            _tidy: thruster_protocol::services::TidyOnDrop::new(&ipc),
        };
        let truth_file = settings
            .truth_file
            .as_ref()
            .map(|p| TruthFile::new(p, &sim.vehicle().name));
        let stats = match (&settings.stats_file, settings.mode) {
            (None, _) => None,
            (Some(path), Mode::Realtime) => Some(StatsFile::create(path)?),
            (Some(_), Mode::Lockstep) => return Err(DriverError::StatsNeedRealtime),
        };
        let period_ns = settings.sample_period_ns();
        let now = Instant::now();
        Ok(Driver {
            gate: CommandGate::new(
                sim.thruster_count(),
                GateSettings {
                    // The simulator's sample clock is exact: sample seq is at (seq - 1) periods.
                    sample_times: SampleTimes::Grid { period_ns },
                    // Lockstep waits for the answer to the newest sample; real time applies
                    // any answer not older than the last one applied.
                    answerable: match settings.mode {
                        Mode::Lockstep => Answerable::NewestOnly,
                        Mode::Realtime => Answerable::SinceApplied,
                    },
                },
            ),
            sim,
            scenario,
            truth_file,
            stats,
            stepping: None,
            stop,
            period_ns,
            imu_seq: 0,
            dvl_pending: None,
            dvl_seq: 0,
            state: VehicleStateMsg::default(),
            state_sent: true,
            truth_seq: 0,
            reconfig_seq: 0,
            neutral: true,
            applied: 0,
            timeouts: 0,
            clipped: 0,
            reject_log: LogLimiter::default(),
            spin: wait::AdaptiveSpin::new(settings.lockstep.spin()),
            started: None,
            next_housekeeping: now,
            next_report: now + REPORT_PERIOD,
            next_driver_status_ns: 0,
            truth_voltage_v: f64::NAN,
            driver_status_seq: 0,
            last_driver_status: None,
            last_rejection: None,
            systemd: thruster_driver_kit::Systemd::new(),
            ports,
            settings,
        })
    }

    /// Runs until `duration_s` or a signal, then goes neutral, publishes the final truth and
    /// returns what happened. The ports are closed when the driver is dropped.
    pub fn run(mut self) -> Result<Summary, DriverError> {
        let v = self.sim.vehicle();
        info!(
            namespace = %self.settings.namespace,
            vehicle = %v.name,
            thrusters = v.thrusters.len(),
            mode = ?self.settings.mode,
            rate_hz = self.settings.sensors.rate_hz,
            noise = ?self.settings.sensors.noise,
            seed = self.settings.seed,
            scenario_events = self.scenario.events().len(),
            duration_s = ?self.settings.duration_s,
            "thruster-sim starting"
        );
        // The ports are up and the thrusters neutral (nothing applied yet): safe to be ready.
        self.systemd.ready();
        let reason = match self.settings.mode {
            Mode::Lockstep => self.run_lockstep()?,
            Mode::Realtime => self.run_realtime()?,
        };
        self.systemd.stopping();
        self.go_neutral();
        self.publish_truth("final")?;
        self.write_stats(true)?;
        // iceoryx2 drops what a reader has not taken yet once the publisher goes away
        // (eclipse-iceoryx/iceoryx2#39): give readers a moment to take the last samples, or a
        // reader descheduled just then never sees the end of the run (a real-time process test
        // waited 10 s for its t = 1 s sample).
        std::thread::sleep(EXIT_LINGER);
        let summary = self.summary(reason);
        info!(
            reason = ?summary.reason,
            vehicle_s = summary.vehicle_s,
            wall_s = format!("{:.3}", summary.wall_s),
            speedup = format!("{:.1}", summary.speedup()),
            samples = summary.samples,
            applied = summary.applied,
            timeouts = summary.timeouts,
            rejected = summary.rejected.total(),
            stale = summary.stale,
            clipped = summary.clipped,
            "thruster-sim stopped"
        );
        Ok(summary)
    }

    fn summary(&self, reason: StopReason) -> Summary {
        Summary {
            reason,
            vehicle_s: self.sim.time_s(),
            wall_s: self.started.map_or(0.0, |t| t.elapsed().as_secs_f64()),
            samples: self.imu_seq,
            applied: self.applied,
            timeouts: self.timeouts,
            rejected: *self.gate.rejected(),
            stale: self.gate.stale(),
            clipped: self.clipped,
        }
    }

    /// Takes the next sample (seq + 1) at the current simulation time.
    fn take_sample(&mut self) -> Result<ImuSample, DriverError> {
        let reading = self.sim.sample();
        if !reading.is_finite() {
            return Err(DriverError::Diverged {
                t_s: self.sim.time_s(),
            });
        }
        self.imu_seq += 1;
        self.gate.published(self.imu_seq, reading.t_ns);
        self.state = convert::vehicle_state(self.imu_seq, &self.sim);
        if let Some(v) = self.sim.dvl_measurement() {
            self.dvl_seq += 1;
            self.dvl_pending = Some(DvlSample {
                seq: self.dvl_seq,
                t_ns: reading.t_ns,
                velocity: v.into(),
            });
        }
        self.state_sent = false;
        let (sample, clipped) = convert::imu_sample(self.imu_seq, &reading);
        if clipped > 0 {
            if self.clipped == 0 {
                warn!(
                    t_s = self.sim.time_s(),
                    // The simulator always has depth; NaN would say it had none.
                    depth_m = reading.depth.unwrap_or(f64::NAN),
                    "sensor values clipped to the protocol's ranges (the simulator has no free \
                     surface: a buoyant vehicle left alone rises above it)"
                );
            }
            self.clipped += clipped as u64;
        }
        Ok(sample)
    }

    /// Publishes a sample, preceded by the true state at that instant (once per sample, also
    /// when the first sample is re-sent); returns how many subscribers got the sample.
    fn send_sample(&mut self, sample: &ImuSample) -> Result<usize, DriverError> {
        self.started.get_or_insert_with(Instant::now);
        if !self.state_sent {
            // Before the IMU sample, so whoever sees the daemon react to it finds the state.
            self.ports.vehicle.send(&self.state)?;
            self.state_sent = true;
        }
        self.publish_driver_status()?;
        // Before the IMU sample too: the daemon reads the DVL when the sample wakes it.
        if let (Some(port), Some(d)) = (&self.ports.dvl, self.dvl_pending.take()) {
            port.send(&d)?;
        }
        let sent = self.ports.imu.send(sample)?;
        if let Some(stats) = &mut self.stats {
            stats.published(sample.seq);
        }
        Ok(sent)
    }

    /// Publishes this driver's status when due: every [`DriverStatusMsg::PERIOD_MS`] of
    /// vehicle time (so a lockstep run far faster than real time reports as often, per
    /// vehicle second, as a real-time one), and at once when the thruster count, the output
    /// state or the rejections changed. Sent before the IMU sample, so a daemon sees a count
    /// mismatch no later than the sample it would answer with the wrong count.
    fn publish_driver_status(&mut self) -> Result<(), DriverError> {
        let rejected = self.gate.rejected().total();
        let output = if self.neutral {
            OutputState::Neutral
        } else {
            OutputState::Active
        };
        let count = self.sim.thruster_count() as u32;
        let now_ns = self.sim.time_ns();
        let changed = self.last_driver_status != Some((rejected, output.as_u32(), count));
        if !changed && now_ns < self.next_driver_status_ns {
            return Ok(());
        }
        self.driver_status_seq += 1;
        let mut msg = DriverStatusMsg {
            seq: self.driver_status_seq,
            time_ns: now_ns,
            thruster_count: count,
            commands_accepted: self.gate.accepted(),
            commands_rejected: rejected,
            watchdog_expiries: self.timeouts,
            link_up: 1,
            armed: 1,
            ..Default::default()
        };
        msg.set_output_state(output);
        // The supply as a real driver measures it, at its report rate; none without a battery
        // (a fixed supply is not measured, so a daemon works as it did before batteries).
        if let Some(b) = self.sim.battery() {
            msg.supply_voltage_v = b.voltage_v();
            msg.supply_current_a = b.current_a();
        }
        msg.driver.set(NODE_NAME);
        if let Some(reason) = &self.last_rejection {
            msg.text.set(reason);
        }
        self.ports.driver_status.send(&msg)?;
        self.last_driver_status = Some((rejected, output.as_u32(), count));
        self.next_driver_status_ns = now_ns + DriverStatusMsg::PERIOD_MS * 1_000_000;
        // The truth at the present voltage, republished (IPC only) when the supply moved by
        // more than TRUTH_VOLTAGE_STEP_V since the last one: with table thrusters the
        // effectiveness follows the battery.
        if self.sim.battery().is_some()
            && (self.sim.supply_voltage_v() - self.truth_voltage_v).abs() > TRUTH_VOLTAGE_STEP_V
        {
            self.publish_truth_ipc()?;
        }
        Ok(())
    }

    /// Appends a `--stats-file` line when one is due (or `force`).
    fn write_stats(&mut self, force: bool) -> Result<(), DriverError> {
        let wall_s = self.started.map_or(0.0, |t| t.elapsed().as_secs_f64());
        let vehicle_s = self.sim.time_s();
        let counters = (
            self.applied,
            self.gate.stale(),
            self.gate.rejected().total(),
        );
        if let Some(stats) = &mut self.stats {
            stats.tick(force, wall_s, vehicle_s, counters)?;
        }
        Ok(())
    }

    /// Publishes the current truth (and appends it to the truth file).
    fn publish_truth(&mut self, cause: &str) -> Result<(), DriverError> {
        self.publish_truth_ipc()?;
        if let Some(file) = &mut self.truth_file {
            file.push(TruthEntry::of(&self.sim, cause))?;
        }
        Ok(())
    }

    /// Publishes the current truth on the truth topic only.
    fn publish_truth_ipc(&mut self) -> Result<(), DriverError> {
        let (fwd, rev) = self.sim.truth();
        self.truth_seq += 1;
        let msg = convert::truth_msg(
            self.truth_seq,
            self.sim.time_ns(),
            &fwd,
            &rev,
            self.sim.supply_voltage_v(),
            self.sim.battery().is_some(),
        );
        self.truth_voltage_v = self.sim.supply_voltage_v();
        if let Err(reason) = msg.validate() {
            // Only an absurd vehicle file gets here (effectiveness beyond the protocol's
            // bound); readers would drop the message, so say why.
            error!(%reason, "truth message fails protocol validation");
        }
        self.ports.truth.send(&msg)?;
        Ok(())
    }

    /// Applies the scenario events due at the current time; announces those that say so.
    fn apply_due_events(&mut self) -> Result<(), DriverError> {
        // Copied out: applying an event needs `self` mutably while the scenario is borrowed.
        let due: Vec<Event> = self.scenario.due(self.sim.time_ns()).to_vec();
        for event in due {
            let before = self.sim.thruster_count();
            let change = self.sim.apply(&event.action)?;
            info!(
                t_s = self.sim.time_s(),
                action = action_name(&event.action),
                thruster = event.action.thruster(),
                kind = ?change.kind,
                index = change.index,
                count = change.thruster_count,
                announce = event.announce,
                "scenario event applied"
            );
            if change.thruster_count != before {
                // Commands for the old thruster list mean nothing now.
                self.gate.set_count(change.thruster_count);
                self.go_neutral();
            }
            self.publish_truth(action_name(&event.action))?;
            if event.announce {
                self.reconfig_seq += 1;
                let mut ev =
                    convert::reconfig_event(self.reconfig_seq, &change, self.sim.vehicle());
                if let Err(reason) = ev.validate() {
                    error!(%reason, "declared geometry fails protocol validation; announcing without it");
                    ev.has_geometry = 0;
                }
                self.ports.reconfig.send(&ev)?;
            }
        }
        Ok(())
    }

    /// Holds `u` (already validated by the gate) until the next command.
    ///
    /// Like a real driver (thruster-hw jumps the ESC's +-25 us), this one owns a power-law
    /// actuator's deadband: a command u != 0 goes to the thruster as sign(u) (db + (1 - db)
    /// |u|), so thrust is proportional to what the daemon asked for. A `t200` thruster's dead
    /// zone is the measured table's: the command goes out as the PWM 1500 + 400 u us, as
    /// ArduSub's or thruster-hw's with `deadband_us = 0` does (the daemon's `[supply]
    /// linearize` steps over it; jumped here as well it would be jumped twice).
    fn hold(&mut self, u: &[f64]) -> Result<(), DriverError> {
        let mut out = [0.0; thruster_protocol::MAX_THRUSTERS];
        let n = u.len().min(out.len());
        for (i, (o, &v)) in out.iter_mut().zip(u).enumerate().take(n) {
            let db = self
                .sim
                .vehicle()
                .thrusters
                .get(i)
                .filter(|t| t.model != crate::vehicle::ThrusterModel::T200)
                .map(|t| t.deadband)
                .unwrap_or(0.0);
            *o = if v == 0.0 {
                0.0
            } else {
                v.signum() * (db + (1.0 - db) * v.abs()).min(1.0)
            };
        }
        self.sim.set_commands(&out[..n])?;
        self.neutral = u.iter().all(|&x| x == 0.0);
        self.applied += 1;
        Ok(())
    }

    /// All thrust zero.
    fn go_neutral(&mut self) {
        let zeros = vec![0.0; self.sim.thruster_count()];
        // Cannot fail: the length is the simulator's own count.
        let _ = self.sim.set_commands(&zeros);
        self.neutral = true;
    }

    fn log_rejection(&mut self, cmd: &ThrustCommand, reason: &RejectReason) {
        self.last_rejection = Some(format!("last command rejected: {reason}"));
        if let Some(suppressed) = self.reject_log.allow() {
            warn!(
                %reason,
                cmd_seq = cmd.seq,
                imu_seq = cmd.imu_seq,
                suppressed,
                "thrust command rejected; thrust neutral"
            );
        }
    }

    /// True when publishing another sample would pass `duration_s`.
    fn duration_reached(&self) -> bool {
        self.settings
            .duration_ns()
            .is_some_and(|d| self.sim.time_ns() + self.period_ns > d)
    }

    /// Once per sample: hands the truth history to late subscribers now and then, and logs
    /// progress.
    fn housekeeping(&mut self) -> Result<(), DriverError> {
        // Every loop round of both modes comes here: a loop that stops coming is hung.
        self.systemd.tick();
        let now = Instant::now();
        if now < self.next_housekeeping {
            return Ok(());
        }
        self.next_housekeeping = now + HOUSEKEEPING_PERIOD;
        // iceoryx2 delivers history only when the publisher updates its connections.
        self.ports.truth.update_connections()?;
        if now >= self.next_report {
            self.next_report = now + REPORT_PERIOD;
            let s = self.summary(StopReason::Signal);
            info!(
                t_s = format!("{:.1}", s.vehicle_s),
                speedup = format!("{:.1}", s.speedup()),
                samples = s.samples,
                applied = s.applied,
                timeouts = s.timeouts,
                rejected = s.rejected.total(),
                neutral = self.neutral,
                "running"
            );
        }
        Ok(())
    }

    /// The simulator (for inspection in tests).
    pub fn simulator(&self) -> &Simulator {
        &self.sim
    }
}

/// Applies every event of `scenario` to a copy of `sim`, so a scenario that names a missing
/// thruster fails at start, not minutes into a run.
fn dry_run(sim: &Simulator, scenario: &Scenario, origin: &str) -> Result<(), DriverError> {
    let mut copy = sim.clone();
    for (index, e) in scenario.events().iter().enumerate() {
        copy.apply(&e.action)
            .map_err(|error| DriverError::Scenario {
                origin: origin.to_string(),
                index,
                t_s: e.t_s,
                action: action_name(&e.action),
                error: Box::new(error),
            })?;
    }
    debug!(events = scenario.events().len(), "scenario checked");
    Ok(())
}

/// The `kind` of an action as written in scenario files.
pub fn action_name(action: &Action) -> &'static str {
    match action {
        Action::Rotate { .. } => "rotate",
        Action::SetDirection { .. } => "set_direction",
        Action::Move { .. } => "move",
        Action::Remove { .. } => "remove",
        Action::Add { .. } => "add",
        Action::Kill { .. } => "kill",
        Action::Weaken { .. } => "weaken",
        Action::Degrade { .. } => "degrade",
    }
}
