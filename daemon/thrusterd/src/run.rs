//! The daemon's event loop: iceoryx2 in and out around the pure state machine.
//!
//! One thread, one WaitSet. IMU samples are validated and answered with a thrust command each;
//! a deadline on the IMU listener turns a silent driver into Fault with neutral thrust.
//! Reconfiguration events, setpoints and operator requests feed the machine; model swaps are
//! published (history 1) and saved; status is published on change and periodically; telemetry
//! after every `telemetry.every_n`-th accepted sample, right after its thrust command.
//!
//! The control thread only controls: the machine's solves go to the solver thread
//! (`solver.rs`) and come back to be applied at their due sample; an operator's model load is
//! read and prepared on a thread of its own (`loader.rs`) and answered when it is back.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::Args;
use iceoryx2::prelude::CallbackProgression;
use tracing::{debug, error, info, warn};

use crate::store;
use thruster_protocol::services::{
    cleanup_dead_nodes, create_waitset, ControlServer, Inbox, IpcConfig, Port, Reply,
};
use thruster_protocol::validate::{ImuSampleValidator, RejectCounters, RejectReason, Validate};
use thruster_protocol::{
    CheckpointMsg, ConfigMsg, ControlResponse, DriverStatusMsg, DvlSample, DynamicsMsg, ImuSample,
    InputKind, InputMsg, ModelMsg, ReconfigEvent, RequestKind, ResponseCode, Setpoint, StatusMsg,
    TelemetryMsg, ThrustCommand, MAX_THRUSTERS,
};
use thrusterd_core::config::DaemonConfig;
use thrusterd_core::driver_watch::{DriverWatch, OutputVerdict};
use thrusterd_core::machine::{Command, Event, Machine, Request, SolveResult, SolverMode};

use crate::loader::{LoadError, Loader, Progress};
use crate::side_inputs::SideInputs;
use crate::solver::SolverThread;
use thrusterd_core::wire;

/// A change of the driver's supply voltage that is handed to the machine (and journaled), V:
/// finer than the T200 table resolves (~0.4 % thrust per 50 mV), coarse enough that a
/// driver's ADC noise does not fill the journal.
const SUPPLY_STEP_V: f64 = 0.01;

#[derive(Args)]
pub struct RunArgs {
    /// Configuration file (see config/thrusterd.toml); defaults apply without one.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Override `ipc.namespace`.
    #[arg(long)]
    namespace: Option<String>,
    /// Override `ipc.root`: base folder of iceoryx2's files, the same for every process of
    /// the namespace.
    #[arg(long)]
    ipc_root: Option<PathBuf>,
    /// Override `runtime.state_dir`.
    #[arg(long)]
    state_dir: Option<PathBuf>,
    /// Override `vehicle.thrusters`.
    #[arg(long)]
    thrusters: Option<usize>,
    /// Override `runtime.spin_us` (low-latency polling before blocking).
    #[arg(long)]
    spin_us: Option<u64>,
    /// Start an estimation as soon as the IMU is up.
    #[arg(long)]
    estimate: bool,
    /// The driver runs in lockstep (sets `runtime.lockstep`): wait, bounded, for a solve
    /// due by a sample's time before handling the sample.
    #[arg(long)]
    lockstep: bool,
    /// Override `runtime.lockstep_wait_ms` (the longest wait for a due solve in lockstep).
    #[arg(long, value_name = "MS")]
    lockstep_wait_ms: Option<u64>,
    /// Override `runtime.realtime_priority` (SCHED_FIFO priority of the control thread, 1-99;
    /// 0 = normal scheduling).
    #[arg(long, value_name = "PRIORITY", value_parser = clap::value_parser!(u8).range(0..=99))]
    realtime_priority: Option<u8>,
}

/// Least vehicle time between two saves of a refined model, ns (a minute).
const REFINED_SAVE_EVERY_NS: u64 = 60_000_000_000;
/// In low-latency mode, other inputs and status are looked at least this often.
const HOUSEKEEPING: Duration = Duration::from_millis(1);
/// How long an operator's `save` request may wait for the saving thread inside the loop: a
/// healthy disk or a fast failure (full, read-only) answers well within it; a stalled disk
/// gets a "saving" answer instead of stalling control.
const SAVE_ANSWER_WAIT: Duration = Duration::from_millis(50);
/// How long a stopping daemon waits for its last saves (thrust already neutral).
const SHUTDOWN_SAVE_WAIT: Duration = Duration::from_secs(3);

pub fn run(args: RunArgs) -> Result<()> {
    init_logging();
    let mut cfg = match &args.config {
        Some(path) => crate::config_file::load(path)?,
        None => DaemonConfig::default(),
    };
    if let Some(ns) = args.namespace {
        cfg.ipc.namespace = ns;
    }
    if let Some(root) = args.ipc_root {
        cfg.ipc.root = Some(root);
    }
    if let Some(dir) = args.state_dir {
        cfg.runtime.state_dir = dir;
    }
    if let Some(n) = args.thrusters {
        crate::config_file::set_thrusters(&mut cfg, n)?;
    }
    if let Some(spin) = args.spin_us {
        cfg.runtime.spin_us = spin;
    }
    if args.lockstep {
        cfg.runtime.lockstep = true;
    }
    if let Some(ms) = args.lockstep_wait_ms {
        cfg.runtime.lockstep_wait_ms = ms;
    }
    if let Some(p) = args.realtime_priority {
        cfg.runtime.realtime_priority = p;
    }

    // Refused here, before anything is created, with the command line applied: a state_dir
    // that is a file used to start anyway, its unreadable marker taken for a crashed
    // predecessor ("did not stop cleanly"); check-config runs the same check.
    let origin = args
        .config
        .as_ref()
        .map_or_else(|| "command line".to_string(), |p| p.display().to_string());
    cfg.check_runnable("", &origin)?;
    std::fs::create_dir_all(&cfg.runtime.state_dir).map_err(|e| {
        thrusterd_core::config::ConfigError::value(
            &origin,
            "",
            "runtime.state_dir",
            format!("{}: {e}", cfg.runtime.state_dir.display()),
        )
    })?;

    let shutdown = Arc::new(AtomicBool::new(false));
    {
        let flag = shutdown.clone();
        ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
            .context("installing the SIGINT/SIGTERM handler")?;
    }
    let mut daemon = Daemon::new(&cfg, shutdown)?;
    if args.estimate {
        daemon.pending_estimate = true;
    }
    daemon.serve()
}

/// journald with structured fields under systemd (when `JOURNAL_STREAM` names our stderr),
/// stderr otherwise; one setup shared with the drivers (thruster_driver_kit::logging).
fn init_logging() {
    thruster_driver_kit::logging::init("info");
}

struct Daemon {
    cfg: DaemonConfig,
    machine: Machine,
    shutdown: Arc<AtomicBool>,
    model_path: PathBuf,
    ipc: IpcConfig,
    validator: ImuSampleValidator,
    rejected: RejectCounters,
    /// Operator requests refused (invalid, wrong state, failed) and saved model files refused
    /// at start: status `requests_refused`.
    refused: u32,
    /// IMU samples that never arrived (sequence gaps between accepted samples).
    missed: u64,
    /// Why the model in use is not on disk (the last save to `model_path` failed), until a
    /// save there succeeds: appended to the status text, so an operator sees it without the log.
    save_error: Option<String>,
    /// Vehicle time of the last refined model saved, ns: refinements (every 5-30 s) are
    /// saved at most every [`REFINED_SAVE_EVERY_NS`], not to wear a vehicle's flash.
    refined_saved_t_ns: Option<u64>,
    /// Saves run here, off the loop (see `saver`).
    saver: crate::saver::Saver,
    thrust_seq: u64,
    status_seq: u64,
    model_seq: u64,
    dynamics_seq: u64,
    telemetry_seq: u64,
    /// Accepted IMU samples since the last telemetry message (decimation).
    since_telemetry: u64,
    /// Telemetry messages that could not be published (logged sparingly).
    telemetry_failures: u64,
    last_imu: Option<(u64, u64)>,
    /// In lockstep: vehicle time at which the next periodic status is due, ns.
    next_status_ns: u64,
    pending_estimate: bool,
    /// The predecessor died while controlling (see `resume_marker`): hold with the loaded model
    /// as soon as the IMU is up.
    pending_hold: bool,
    resume_marker: Option<crate::resume_marker::ResumeMarker>,
    stale_reported: bool,
    /// The driver's own reports on its outputs (count, rejections, armed, link).
    driver: DriverWatch,
    /// The verdict the machine was last given on the driver's outputs.
    driver_verdict: OutputVerdict,
    /// The supply voltage last handed to the machine, V.
    supply_v: Option<f64>,
    /// The thruster count the latest report was judged for; `None` when a new report came.
    /// Judging again only then keeps the per-round work (and its text) off the hot path.
    driver_judged_for: Option<usize>,
    /// Every input the machine takes besides the IMU samples, published for recordings
    /// (`journal`); created with the other ports in `serve`.
    journal: Option<crate::journal::Journal>,
    /// Checkpoints of the machine (`checkpoints`), beside the journal they are placed in;
    /// None when `[checkpoint] enabled = false`.
    checkpoints: Option<crate::checkpoints::Checkpoints>,
    /// Runs the machine's solves off this thread.
    solver: SolverThread,
    /// Late solves already logged (the machine counts them).
    late_logged: u64,
    /// Reads operators' model files off this thread.
    loader: Loader,
    /// Number of the next deferred request (a load).
    next_token: u64,
}

impl Daemon {
    fn new(cfg: &DaemonConfig, shutdown: Arc<AtomicBool>) -> Result<Self> {
        let ipc = match &cfg.ipc.root {
            Some(root) => IpcConfig::with_root_base(&cfg.ipc.namespace, root),
            None => IpcConfig::new(&cfg.ipc.namespace),
        }
        .with_context(|| format!("ipc.namespace {:?}", cfg.ipc.namespace))?;
        let setup = cfg.machine_setup();
        let loader = Loader::new(setup.estimator.clone());
        let mut machine = Machine::new(setup);
        let model_path = cfg.runtime.state_dir.join(store::MODEL_FILE);
        // A refused saved model counts like a refused Load request, so status shows it.
        let mut refused = 0u32;
        if cfg.runtime.load_model {
            match store::load(&model_path) {
                Ok(Some(model)) => match machine.load_model(model) {
                    Ok(()) => info!(path = %model_path.display(), "loaded the saved model"),
                    Err(e) => {
                        refused += 1;
                        warn!("saved model ignored, starting without it: {e}")
                    }
                },
                Ok(None) => info!(path = %model_path.display(), "no saved model yet"),
                Err(e) => {
                    refused += 1;
                    warn!("saved model ignored, starting without it: {e}")
                }
            }
        }
        // From here on the machine's solves go to the solver thread (the start-up load above
        // made none).
        machine.set_solver_mode(SolverMode::External);
        Ok(Daemon {
            cfg: cfg.clone(),
            machine,
            solver: SolverThread::spawn().context("starting the solver thread")?,
            late_logged: 0,
            loader,
            next_token: 1,
            shutdown,
            model_path,
            ipc,
            validator: ImuSampleValidator::default(),
            rejected: RejectCounters::default(),
            refused,
            missed: 0,
            save_error: None,
            refined_saved_t_ns: None,
            saver: crate::saver::Saver::spawn().context("starting the model-saving thread")?,
            thrust_seq: 0,
            status_seq: 0,
            model_seq: 0,
            dynamics_seq: 0,
            telemetry_seq: 0,
            since_telemetry: 0,
            telemetry_failures: 0,
            last_imu: None,
            next_status_ns: 0,
            pending_estimate: false,
            pending_hold: false,
            resume_marker: None,
            stale_reported: false,
            driver: DriverWatch::new(),
            driver_verdict: OutputVerdict::Usable,
            supply_v: None,
            driver_judged_for: None,
            journal: None,
            checkpoints: None,
        })
    }

    fn serve(&mut self) -> Result<()> {
        // A crashed predecessor leaves its resources; clean them so it never blocks a restart.
        match cleanup_dead_nodes(&self.ipc) {
            Ok(census) => info!(?census, "iceoryx2 namespace {} ready", self.ipc.namespace()),
            Err(e) => warn!("could not clean up dead nodes: {e}"),
        }
        // Before the node, so it drops after it: a clean stop of the last process of the
        // namespace leaves no iceoryx2 residue behind.
        let _tidy = thruster_protocol::services::TidyOnDrop::new(&self.ipc);
        // Dead clients' files, while running (not only at the next start); stopped before
        // the tidy runs.
        let _reaper = crate::reaper::Reaper::start(&self.ipc, crate::reaper::REAP_EVERY)
            .context("starting the dead-node reaper")?;
        let result = self.serve_node();
        // The journal's port lives in `self`, beyond the node: it must go before the tidy,
        // or its service is still open then and the namespace's global segment stays.
        self.journal = None;
        self.checkpoints = None;
        result
    }

    fn serve_node(&mut self) -> Result<()> {
        let node = self.ipc.create_node("thrusterd")?;
        // The control server first: it is what tells a live daemon on this namespace apart
        // from a crashed one, and the resume marker of a live daemon must neither be read as
        // a crash ("did not stop cleanly ... resuming control") nor overwritten.
        let control = ControlServer::create(&node, &self.ipc)
            .context("another thrusterd already serves this namespace")?;
        self.open_resume_marker();
        let imu_in = Inbox::<ImuSample>::create(&node, &self.ipc)?;
        let side = SideInputs::new(
            Inbox::<ReconfigEvent>::create(&node, &self.ipc)?,
            Inbox::<Setpoint>::create(&node, &self.ipc)?,
            Inbox::<DriverStatusMsg>::create(&node, &self.ipc)?,
            // Optional: only a vehicle with a DVL publishes here.
            Inbox::<DvlSample>::create(&node, &self.ipc)?,
        );
        let thrust = Port::<ThrustCommand>::create(&node, &self.ipc)?;
        // Off (every_n = 0): no service at all, so nothing in the loop pays for it.
        let telemetry = match self.cfg.telemetry.every_n {
            0 => None,
            _ => Some(Port::<TelemetryMsg>::create(&node, &self.ipc)?),
        };
        let out = Outputs {
            thrust,
            telemetry,
            model: ModelPorts {
                model: Port::<ModelMsg>::create(&node, &self.ipc)?,
                dynamics: Port::<DynamicsMsg>::create(&node, &self.ipc)?,
            },
            status: Port::<StatusMsg>::create(&node, &self.ipc)?,
        };
        // The effective configuration (history 1) and the input journal: what a replay of a
        // recording needs besides the IMU stream. Before the first sample is read.
        let config_out = Port::<ConfigMsg>::create(&node, &self.ipc)?;
        if let Err(e) = config_out.send(&crate::journal::config_msg(&self.cfg)) {
            // Only a replay needs it (and then asks for --config): never worth not serving.
            warn!("configuration not published: {e}");
        }
        let mut journal = crate::journal::Journal::new(Port::<InputMsg>::create(&node, &self.ipc)?);
        journal.text(
            InputKind::Start,
            u32::from(self.machine.model().is_some()),
            false,
            &format!("thrusterd {}", env!("CARGO_PKG_VERSION")),
        );
        self.journal = Some(journal);
        if self.cfg.checkpoint.enabled {
            self.checkpoints = Some(crate::checkpoints::Checkpoints::new(
                Port::<CheckpointMsg>::create(&node, &self.ipc)?,
                &self.cfg.checkpoint,
                self.cfg.runtime.lockstep,
            ));
        }

        let waitset = create_waitset()?;
        let imu_timeout = Duration::from_millis(self.cfg.runtime.imu_timeout_ms);
        let imu_guard = waitset.attach_deadline(imu_in.listener(), imu_timeout)?;
        let reconfig_guard = waitset.attach_notification(side.reconfig.listener())?;
        let setpoint_guard = waitset.attach_notification(side.setpoint.listener())?;
        let driver_guard = waitset.attach_notification(side.driver.listener())?;
        let control_guard = waitset.attach_notification(control.listener())?;
        let status_period = Duration::from_millis(self.cfg.runtime.status_period_ms.max(1));
        let spin = Duration::from_micros(self.cfg.runtime.spin_us);

        if let Some(model) = self.machine.model().cloned() {
            self.publish_model(&out.model, &model);
        }
        self.raise_control_thread();
        info!(thrusters = self.machine.thrusters(), "thrusterd serving");
        // From here this thread answers samples: a log line that finds journald's queue full
        // is dropped rather than waited for (a stalled journald must not stall control).
        thruster_driver_kit::logging::never_wait_on_this_thread();
        let mut systemd = thruster_driver_kit::Systemd::new();
        systemd.ready();
        self.publish_status(&out.status);
        let mut last_status = Instant::now();
        let mut wait_errors = 0u32;

        while !self.shutdown.load(Ordering::SeqCst) {
            // Low-latency mode: keep polling for samples (answering each at once) until none
            // came for `spin`, or housekeeping is due; only then pay for the WaitSet (a
            // syscall, and a wake-up if it blocks). Other inputs wait at most ~1 ms.
            if !spin.is_zero() {
                let housekeeping = Instant::now();
                let mut idle_since = Instant::now();
                while idle_since.elapsed() < spin && housekeeping.elapsed() < HOUSEKEEPING {
                    if let Some(sample) = imu_in.recv()? {
                        self.on_sample(&sample, &side, &out)?;
                        self.stale_reported = false;
                        idle_since = Instant::now();
                    } else {
                        std::hint::spin_loop();
                    }
                }
            }
            let (mut imu, mut stale, mut reconf, mut setp, mut ctrl, mut drv) =
                (false, false, false, false, false, false);
            let waited = waitset.wait_and_process_once_with_timeout(
                |id| {
                    imu |= id.has_event_from(&imu_guard);
                    stale |= id.has_missed_deadline(&imu_guard);
                    reconf |= id.has_event_from(&reconfig_guard);
                    setp |= id.has_event_from(&setpoint_guard);
                    drv |= id.has_event_from(&driver_guard);
                    ctrl |= id.has_event_from(&control_guard);
                    CallbackProgression::Continue
                },
                if spin.is_zero() {
                    status_period
                } else {
                    Duration::from_micros(1)
                },
            );
            if let Err(e) = waited {
                // A signal interrupts the wait (EINTR) before the handler's flag is seen: that
                // is the shutdown path, not a failure; anything persistent is.
                if self.shutdown.load(Ordering::SeqCst) {
                    break;
                }
                wait_errors += 1;
                warn!("waiting for events failed ({wait_errors} in a row): {e:?}");
                anyhow::ensure!(wait_errors < 100, "the event loop keeps failing: {e:?}");
                continue;
            }
            wait_errors = 0;
            if imu {
                imu_in.drain_events()?;
            }
            side.dvl.drain_events()?;
            if reconf {
                side.reconfig.drain_events()?;
            }
            if drv {
                side.driver.drain_events()?;
            }
            if setp {
                side.setpoint.drain_events()?;
            }
            // The inbox is read on every wake-up, not only on an IMU event: a sample whose
            // notification was lost (a driver that notified before this listener was
            // connected, at start) would otherwise sit unread while a lockstep driver waits
            // for its answer forever. An empty inbox costs one check.
            let mut got = false;
            while let Some(sample) = imu_in.recv()? {
                self.on_sample(&sample, &side, &out)?;
                got = true;
            }
            // What came without a sample (a setpoint while a real-time driver is quiet). In
            // lockstep it is read now but applied with the next sample (`on_sample`): the
            // simulator publishes its events just before a sample, and applying one here or
            // there would depend on which of the two this loop saw first (an announced
            // reconfiguration applied one sample apart moved an identification's end by 3
            // vehicle-s between two runs of one seed). Read now all the same: an operator's
            // publisher may be gone by the next sample, and an unread message with it.
            if self.cfg.runtime.lockstep {
                let dropped = side.hold_all()?;
                if dropped > 0 {
                    warn!(
                        dropped,
                        "inputs held for the next sample overflowed: oldest dropped"
                    );
                }
            } else {
                self.take_inputs_before_sample(&side)?;
                self.take_reconfigurations(&side)?;
            }
            if got {
                self.stale_reported = false;
            }
            // Results that came back while no sample did (handed over now, applied at their
            // due sample).
            self.collect_solves();
            // Before the first sample there is nothing to go stale: the driver is not up yet.
            // Status says so, and estimation and control are refused until a sample comes.
            if stale && self.last_imu.is_none() {
                let why = format!(
                    "no IMU samples from any driver for {} ms (namespace {})",
                    imu_timeout.as_millis(),
                    self.ipc.namespace()
                );
                self.machine.on_no_imu_yet(&why);
                self.journal(|j| j.text(InputKind::NoImuYet, 0, false, &why));
            }
            // In lockstep no vehicle time passes while the driver sends nothing (it waits for
            // us, or for whoever steps it): silence there is a pause, not a lost IMU.
            if stale
                && !got
                && !self.stale_reported
                && self.last_imu.is_some()
                && !self.cfg.runtime.lockstep
            {
                let why = format!("no IMU sample for {} ms", imu_timeout.as_millis());
                let cmd = self.machine.on_imu_stale(&why);
                self.journal(|j| j.text(InputKind::ImuStale, 0, false, &why));
                self.send_thrust(&out.thrust, &cmd);
                self.stale_reported = true;
            }
            if ctrl {
                control.drain_events()?;
            }
            // Serve on every round, not only after a notification: a request whose
            // notification was lost while this daemon started (the client notified before
            // our listener existed) would otherwise wait unanswered until the client gave up
            // (thrusterctl exit 5 right after a restart, seen in tests/faults.rs). An empty
            // queue costs one check per round, after the IMU answer.
            {
                // Count every refusal (invalid request, wrong state, failure) for status.
                let mut refused = 0u32;
                let served = control.serve_deferring(|kind, req| {
                    let reply = self.on_request(kind, req);
                    // What the request changed goes out before its answer: a client that
                    // reads status after the answer finds it there (and the lab, stepping a
                    // lockstep simulator, acts on it at the same vehicle time every run).
                    self.publish_changes(&out);
                    if let Reply::Now(response) = &reply {
                        if !response.is_ok() {
                            refused += 1;
                            warn!(?kind, "operator request refused: {}", response.text());
                        }
                    }
                    reply
                })?;
                if served.invalid > 0 {
                    warn!(invalid = served.invalid, "invalid operator request refused");
                }
                self.refused = self
                    .refused
                    .saturating_add(refused)
                    .saturating_add(served.invalid as u32);
            }
            self.start_pending();
            self.poll_load(&control, &out);
            let changed = self.handle_events(&out.model);
            self.poll_saves();
            systemd.tick();
            let wall_due = last_status.elapsed() >= status_period;
            if changed || wall_due {
                let s = self.machine.status();
                if s.text.starts_with(s.state.name()) {
                    systemd.status(&s.text);
                } else {
                    systemd.status(&format!("{}: {}", s.state.name(), s.text));
                }
            }
            // In lockstep the periodic status goes out with the samples, every
            // `status_period_ms` of vehicle time (`on_imu`): on the wall clock its count and
            // its vehicle times would depend on the machine's speed.
            let periodic = wall_due && !(self.cfg.runtime.lockstep && self.last_imu.is_some());
            if changed || periodic {
                self.publish_status(&out.status);
            }
            if wall_due {
                // History-1 services only reach late joiners on a send or this call.
                let _ = out.model.model.update_connections();
                let _ = out.model.dynamics.update_connections();
                let _ = out.status.update_connections();
                // The configuration is sent once: a recorder that joins later gets it only
                // from here (issue 26: a late `thrusterctl record` had no `config` channel).
                let _ = config_out.update_connections();
                last_status = Instant::now();
            }
        }

        info!("shutting down: thrusters neutral");
        systemd.stopping();
        let neutral = Command::neutral(self.machine.thrusters());
        self.send_thrust(&out.thrust, &neutral);
        self.handle_events(&out.model);
        if let Some(model) = self.machine.model().cloned() {
            self.save(&model);
        }
        // Thrust is neutral: now the saves may be waited for, but not forever (a disk that
        // never answers must not keep the process, and systemd's stop, waiting).
        let (outcomes, abandoned) = self.saver.finish(SHUTDOWN_SAVE_WAIT);
        for outcome in outcomes {
            self.on_saved(outcome);
        }
        if abandoned > 0 {
            error!(
                "{abandoned} model save(s) still waiting for the disk after {} s: abandoned",
                SHUTDOWN_SAVE_WAIT.as_secs()
            );
        }
        // A clean stop: the next start begins idle.
        if let Some(marker) = self.resume_marker.take() {
            marker.finish(SHUTDOWN_SAVE_WAIT);
        }
        let mut status = self.status_msg();
        status.set_text(StatusMsg::STOPPED_TEXT);
        let _ = out.status.send(&status);
        Ok(())
    }

    /// Hands the machine the driver's supply voltage when it moved by [`SUPPLY_STEP_V`] or
    /// came or went, and journals it (replay hands the machine the same values at the same
    /// samples).
    fn take_supply(&mut self, voltage_v: Option<f64>) {
        let moved = match (self.supply_v, voltage_v) {
            (Some(a), Some(b)) => (a - b).abs() >= SUPPLY_STEP_V,
            (None, None) => false,
            _ => true,
        };
        if !moved {
            return;
        }
        if voltage_v.is_none() {
            warn!("the driver no longer reports a supply voltage: commands are not compensated");
        } else if self.supply_v.is_none() {
            info!(
                volts = voltage_v,
                "the driver reports the supply voltage ([supply] compensation decides its use)"
            );
        }
        self.supply_v = voltage_v;
        self.machine.on_supply(voltage_v);
        self.journal(|j| {
            j.record(InputKind::Supply, false, |m| {
                m.code = u32::from(voltage_v.is_some());
                m.value = voltage_v.unwrap_or(0.0);
            })
        });
    }

    /// One IMU sample: the inputs that came before it (DVL, the driver's report, setpoints), a
    /// start-up request waiting for the IMU, then the sample itself (which takes announced
    /// reconfigurations, see `on_imu`).
    fn on_sample(&mut self, sample: &ImuSample, side: &SideInputs, out: &Outputs) -> Result<()> {
        self.take_inputs_before_sample(side)?;
        self.start_pending();
        self.on_imu(sample, side, out)
    }

    /// `--estimate`, or a hold resumed after a crash, once the IMU is up (before the next
    /// sample, so in lockstep at the same vehicle time every run).
    fn start_pending(&mut self) {
        use thrusterd_core::machine::State;
        if self.last_imu.is_none() || self.machine.state() == State::Fault {
            return;
        }
        if self.pending_estimate {
            self.pending_estimate = false;
            let result = self.machine.on_request(Request::Estimate);
            self.journal_request(RequestKind::Estimate, 0.0, result.is_err());
            if let Err(e) = result {
                warn!("start-up estimation refused: {e}");
            }
        }
        if self.pending_hold {
            self.pending_hold = false;
            let result = self.machine.on_request(Request::Hold);
            self.journal_request(RequestKind::Hold, 0.0, result.is_err());
            match result {
                Ok(_) => info!("resumed control after a crash: holding attitude"),
                Err(e) => warn!("could not resume control after a crash: {e}"),
            }
        }
    }

    /// Publishes the machine's events (a new model) and, if there were any, the status.
    fn publish_changes(&mut self, out: &Outputs) {
        if self.handle_events(&out.model) {
            self.publish_status(&out.status);
        }
    }

    /// What came before a sample: the DVL's measurement and the driver's report (count,
    /// outputs, supply), which a driver sends just before it, and setpoints. Taken before each
    /// sample is handled (in real time also once per round without one; in lockstep what came
    /// between samples is held for the next one, `side_inputs.rs`), so the sample is handled with
    /// them: in lockstep the sample each input lands at is a matter of vehicle time, not of
    /// how long the loop spun before it looked (a setpoint the lab sent while the simulator
    /// held acts from the next sample, always).
    fn take_inputs_before_sample(&mut self, side: &SideInputs) -> Result<()> {
        while let Some(d) = side.next_dvl()? {
            match d.validate() {
                Ok(()) => {
                    self.machine.on_dvl(d.velocity);
                    self.journal(|j| j.record(InputKind::Dvl, false, |m| m.dvl = d.velocity));
                }
                Err(reason) => {
                    self.rejected.record(&reason);
                    warn!("DVL sample rejected: {reason}");
                }
            }
        }
        // The driver's report decides whether thrust may go out at all.
        while let Some(report) = side.next_driver_report()? {
            match report.validate() {
                Ok(()) => {
                    self.driver.observe(&report, self.machine.thrusters());
                    self.driver_judged_for = None;
                    self.take_supply(report.supply_voltage());
                }
                Err(reason) => {
                    self.rejected.record(&reason);
                    warn!("driver status rejected: {reason}");
                }
            }
        }
        // Judged on a new report, and when a reconfiguration changed the count the driver
        // must match.
        if self.driver_judged_for != Some(self.machine.thrusters()) {
            self.judge_outputs();
            self.driver_judged_for = Some(self.machine.thrusters());
        }
        while let Some(s) = side.next_setpoint()? {
            match s.validate() {
                Ok(()) => {
                    self.machine.on_setpoint_input(&wire::setpoint(&s));
                    self.journal(|j| j.setpoint(&s));
                }
                Err(reason) => {
                    self.rejected.record(&reason);
                    warn!("setpoint rejected: {reason}");
                }
            }
        }
        Ok(())
    }

    /// Announced reconfigurations: taken once a sample's command is computed and before it
    /// goes out (in real time also once per round without a sample). A driver announces a change just
    /// before the first sample taken after it, so the machine learns of it at that sample's
    /// time (taken before the sample, the new model was stamped one period before the
    /// change), and what it changes is published before that sample's answer.
    fn take_reconfigurations(&mut self, side: &SideInputs) -> Result<()> {
        while let Some(e) = side.next_reconfig()? {
            match e.validate().and_then(|_| check_reconfig(&e)) {
                Ok(()) => {
                    self.machine.on_reconfig(wire::reconfig(&e));
                    self.journal(|j| j.reconfig(&e));
                }
                Err(reason) => {
                    self.rejected.record(&reason);
                    warn!("reconfiguration event rejected: {reason}");
                }
            }
        }
        Ok(())
    }

    /// Hands the machine the driver's verdict on its outputs when it changed.
    fn judge_outputs(&mut self) {
        let verdict = self.driver.verdict(self.machine.thrusters());
        if verdict == self.driver_verdict {
            return;
        }
        match &verdict {
            OutputVerdict::Blocked(why) => {
                error!("driver outputs unusable: {why}; thrusters neutral");
                self.machine.on_outputs(Some(why));
                let why = why.clone();
                self.journal(|j| j.text(InputKind::Outputs, 1, false, &why));
            }
            OutputVerdict::Usable => {
                info!("driver outputs usable again");
                self.machine.on_outputs(None);
                self.journal(|j| j.text(InputKind::Outputs, 0, false, ""));
            }
        }
        self.driver_verdict = verdict;
    }

    fn on_imu(&mut self, sample: &ImuSample, side: &SideInputs, out: &Outputs) -> Result<()> {
        match self.validator.check(sample) {
            Ok(accepted) => {
                self.last_imu = Some((sample.seq, sample.t_ns));
                let input = wire::imu_input(sample);
                // Results first, then the sample is counted: a result handed over now is
                // journaled as before this sample, which is where a replay hands it over.
                self.collect_solves();
                if self.cfg.runtime.lockstep {
                    self.wait_for_due_solves(input.t_ns);
                }
                if let Some(j) = self.journal.as_mut() {
                    j.imu(sample.seq, sample.t_ns);
                }
                if accepted.missed > 0 {
                    // Counted for status so no loss goes unnoticed; logged sparingly.
                    let before = self.missed;
                    self.missed = self.missed.saturating_add(accepted.missed);
                    if before < 20 || before.ilog2() != self.missed.ilog2() {
                        warn!(
                            missed = self.missed,
                            "{} IMU sample(s) missing before seq {}", accepted.missed, sample.seq
                        );
                    }
                }
                if accepted.resynced {
                    warn!(
                        "IMU stream restarted (seq {}): time discontinuity",
                        sample.seq
                    );
                }
                let cmd = self.machine.on_imu(&input);
                self.take_reconfigurations(side)?;
                if self.cfg.runtime.lockstep {
                    // Whatever this sample changed, and the periodic status in vehicle time,
                    // goes out before the answer: when the driver has the answer to sample
                    // k, everything the daemon published up to k is there, whatever the
                    // loop's timing (a lockstep observer reads one stream every run).
                    let changed = self.handle_events(&out.model);
                    if changed || input.t_ns >= self.next_status_ns {
                        self.publish_status(&out.status);
                        self.next_status_ns = input
                            .t_ns
                            .saturating_add(self.cfg.runtime.status_period_ms.max(1) * 1_000_000);
                    }
                }
                let sent = self.send_thrust(&out.thrust, &cmd);
                // After the answer went out: the sample's own latency does not include it.
                self.dispatch_solves();
                if let Some(port) = &out.telemetry {
                    self.publish_telemetry(port, &input, &sent);
                }
                if let (Some(c), Some(j)) = (self.checkpoints.as_mut(), self.journal.as_ref()) {
                    c.after_sample(&self.machine, input.t_ns, j.place());
                }
            }
            Err(reason) => {
                self.rejected.record(&reason);
                if self.rejected.total() < 20 || self.rejected.total().is_power_of_two() {
                    warn!(
                        rejected = self.rejected.total(),
                        "IMU sample rejected: {reason}"
                    );
                }
                // Still answer, with neutral: a driver in lockstep waits for every answer, and
                // a garbage sample must never keep a pulse running.
                let neutral = Command::neutral(self.machine.thrusters());
                let mut msg =
                    wire::thrust_command(self.thrust_seq, sample.seq, sample.t_ns, &neutral);
                self.thrust_seq += 1;
                msg.imu_seq = sample.seq;
                let _ = out.thrust.send(&msg);
            }
        }
        Ok(())
    }

    /// `runtime.realtime_priority`: this thread, the one that answers samples, to SCHED_FIFO
    /// (the solver, saver, loader and reaper threads stay normal). Refused, the daemon runs on
    /// at normal priority and says why: a vehicle that will not start over a scheduling
    /// permission is worse off than one with a slower answer.
    fn raise_control_thread(&self) {
        let priority = self.cfg.runtime.realtime_priority;
        if priority == 0 {
            return;
        }
        match thruster_driver_kit::realtime::make_this_thread_fifo(priority) {
            Ok(()) => info!(priority, "control thread at SCHED_FIFO"),
            Err(e) => {
                warn!("runtime.realtime_priority: {e}; the control thread runs at normal priority")
            }
        }
    }

    /// Hands the machine the solve results that are back (never waits).
    fn collect_solves(&mut self) {
        loop {
            match self.solver.try_result() {
                Ok(Some(r)) => self.deliver(r),
                Ok(None) => return,
                Err(lost) => return self.solver_lost(&lost.0),
            }
        }
    }

    /// Lockstep: the results due by `t_ns` are waited for, each up to
    /// `runtime.lockstep_wait_ms`, so the outcome is the inline one (see `runtime.lockstep`).
    fn wait_for_due_solves(&mut self, t_ns: u64) {
        // The configuration's own range (checked at load); clamped again so no value can
        // make the wait unbounded or zero.
        let wait = Duration::from_millis(self.cfg.runtime.lockstep_wait_ms.clamp(1, 600_000));
        while let Some(id) = self.machine.awaiting_result(t_ns) {
            match self.solver.wait_result(wait) {
                Ok(Some(r)) => self.deliver(r),
                Ok(None) => {
                    let why = format!(
                        "solve {id} not back after {} ms in lockstep (runtime.lockstep_wait_ms)",
                        wait.as_millis()
                    );
                    return self.solver_lost(&why);
                }
                Err(lost) => return self.solver_lost(&lost.0),
            }
        }
    }

    /// Hands a solve's result to the machine and journals when it did: a result back after
    /// its due sample is applied at the next one, which a replay can only reproduce from the
    /// journal.
    fn deliver(&mut self, r: SolveResult) {
        let id = r.id();
        self.machine.deliver(r);
        self.journal(|j| {
            j.record(InputKind::SolveDelivered, false, |m| {
                m.code = u32::try_from(id).unwrap_or(u32::MAX)
            })
        });
    }

    /// Gives the solver thread the jobs the last sample made; logs late results.
    fn dispatch_solves(&mut self) {
        while let Some(job) = self.machine.take_job() {
            if let Err(lost) = self.solver.submit(job) {
                return self.solver_lost(&lost.0);
            }
        }
        let late = self.machine.late_solves();
        if late > self.late_logged {
            // Logged sparingly: on a machine that cannot keep up, every solve is late.
            if self.late_logged < 10 || late.ilog2() != self.late_logged.ilog2() {
                warn!(
                    late,
                    "a solve's result was not back by its due sample (machine.solve_budget_s): applied when it comes"
                );
            }
            self.late_logged = late;
        }
    }

    /// The solver thread died or did not answer: what waited for it faults (neutral), and a
    /// fresh thread takes what comes next.
    fn solver_lost(&mut self, why: &str) {
        error!("{why}; thrusters neutral");
        self.machine.on_solver_lost(why);
        if let Err(e) = self.solver.restart() {
            error!("the solver thread could not be restarted: {e}");
        }
    }

    /// A load in flight: answered when its file is read and installed, or told after
    /// `loader::ANSWER_WAIT` that it is still being read.
    fn poll_load(&mut self, control: &ControlServer, out: &Outputs) {
        match self.loader.poll() {
            Progress::Nothing => {}
            Progress::Slow { token, path } => {
                let text = format!(
                    "still reading {} after {:.1} s (a slow or stalled disk?): installed when read, \
                     see status and the log",
                    path.display(),
                    crate::loader::ANSWER_WAIT.as_secs_f64()
                );
                warn!("{text}");
                control.answer(token, ControlResponse::new(ResponseCode::Busy, &text));
            }
            Progress::Done {
                token,
                path,
                result,
                answered,
            } => {
                let shown = path.display().to_string();
                let outcome = (*result).and_then(|model| {
                    let r = self.machine.load_prepared(model);
                    self.journal(|j| j.text(InputKind::Load, 0, r.is_err(), &shown));
                    r.map_err(|e| LoadError::Rejected(e.0))
                });
                let response = match &outcome {
                    Ok(()) => {
                        info!(path = %shown, "model loaded");
                        ControlResponse::ok(&format!("loaded {shown}"))
                    }
                    Err(e) => {
                        self.refused = self.refused.saturating_add(1);
                        warn!("operator request refused: load {shown}: {e}");
                        let code = match e {
                            LoadError::Failed(_) => ResponseCode::Failed,
                            LoadError::Rejected(_) => ResponseCode::Rejected,
                        };
                        ControlResponse::new(code, &e.to_string())
                    }
                };
                // The new model and status before the answer, as for any request.
                self.publish_changes(out);
                if !answered {
                    control.answer(token, response);
                }
            }
        }
    }

    /// Sends `cmd` for the latest sample; returns the message as it went out.
    fn send_thrust(&mut self, thrust_out: &Port<ThrustCommand>, cmd: &Command) -> ThrustCommand {
        let (imu_seq, t_ns) = self.last_imu.unwrap_or((0, 0));
        let mut msg = wire::thrust_command(self.thrust_seq, imu_seq, t_ns, cmd);
        // The machine already sanitises; this is the protocol's own last check before the wire.
        thruster_protocol::validate::sanitize_thrust(msg.thrusters_mut());
        self.thrust_seq += 1;
        if let Err(e) = thrust_out.send(&msg) {
            error!("thrust command not sent: {e}");
        }
        msg
    }

    /// Telemetry for every `every_n`-th accepted sample, after its thrust command went out (the
    /// driver never waits for it). The port never blocks: iceoryx2's safe overflow drops a
    /// slow reader's oldest message instead.
    fn publish_telemetry(
        &mut self,
        port: &Port<TelemetryMsg>,
        input: &thrusterd_core::machine::ImuInput,
        sent: &ThrustCommand,
    ) {
        self.since_telemetry += 1;
        if self.since_telemetry < self.cfg.telemetry.every_n {
            return;
        }
        self.since_telemetry = 0;
        let snapshot = self.machine.telemetry(input);
        let msg = wire::telemetry_msg(self.telemetry_seq, &snapshot, sent);
        self.telemetry_seq += 1;
        if let Err(e) = port.send(&msg) {
            self.telemetry_failures += 1;
            let n = self.telemetry_failures;
            if n < 5 || n.is_power_of_two() {
                warn!(failures = n, "telemetry not published: {e}");
            }
        }
    }

    fn on_request(&mut self, kind: RequestKind, req: &thruster_protocol::ControlRequest) -> Reply {
        if kind == RequestKind::Load {
            // Answered when the file is read (`poll_load`), never on this thread's time.
            let path = PathBuf::from(req.text.as_str());
            let token = self.next_token;
            self.next_token += 1;
            return match self.loader.start(token, &path) {
                Ok(()) => Reply::Later(token),
                Err(busy) => Reply::Now(ControlResponse::new(ResponseCode::Busy, &busy)),
            };
        }
        Reply::Now(self.on_immediate_request(kind, req))
    }

    /// Every request but a load: answered at once.
    fn on_immediate_request(
        &mut self,
        kind: RequestKind,
        req: &thruster_protocol::ControlRequest,
    ) -> ControlResponse {
        let machine_req = match kind {
            RequestKind::Status => {
                let s = self.machine.status();
                return ControlResponse::ok(&format!("{}: {}", s.state.name(), s.text));
            }
            RequestKind::Estimate => {
                if req.value != 0.0 {
                    if let Err(e) = self.machine.set_estimation_power(req.value) {
                        return ControlResponse::new(ResponseCode::InvalidRequest, &e.0);
                    }
                }
                Request::Estimate
            }
            RequestKind::Abort => Request::Abort,
            RequestKind::Hold => Request::Hold,
            RequestKind::Idle => Request::Idle,
            RequestKind::Stop => Request::Stop,
            RequestKind::Revert => Request::Revert,
            RequestKind::Save => {
                let Some(model) = self.machine.model().cloned() else {
                    return ControlResponse::new(ResponseCode::Rejected, "no model to save");
                };
                let path = if req.text.as_str().is_empty() {
                    self.model_path.clone()
                } else {
                    PathBuf::from(req.text.as_str())
                };
                // On the saving thread; the answer waits for it a few milliseconds at most
                // (a healthy disk, or a fast failure such as a full one), never for a stalled
                // disk: then the answer says so and status reports the outcome.
                let id = self.saver.submit(&model, &path);
                return match self.saver.wait_for(id, SAVE_ANSWER_WAIT) {
                    Some(outcome) => {
                        let result = outcome.result.clone();
                        self.on_saved(outcome);
                        match result {
                            Ok(()) => ControlResponse::ok(&format!(
                                "saved model v{} to {}",
                                model.version,
                                path.display()
                            )),
                            Err(e) => ControlResponse::new(ResponseCode::Failed, &e),
                        }
                    }
                    None => ControlResponse::ok(&format!(
                        "saving model v{} to {} (the disk is slow: status reports a failure)",
                        model.version,
                        path.display()
                    )),
                };
            }
            RequestKind::Load => {
                unreachable!("loads are answered by poll_load")
            }
            RequestKind::Shutdown => {
                self.shutdown.store(true, Ordering::SeqCst);
                return ControlResponse::ok("shutting down");
            }
        };
        let result = self.machine.on_request(machine_req);
        self.journal_request(kind, req.value, result.is_err());
        if self.machine.state() == thrusterd_core::machine::State::Fault {
            // Idle or stop in Fault change what it recovers to without a state change.
            self.record_intent(thrusterd_core::machine::State::Fault);
        }
        match result {
            Ok(text) => ControlResponse::ok(&text),
            Err(e) => ControlResponse::new(ResponseCode::Rejected, &e.0),
        }
    }

    /// Runs `f` on the input journal (there is none before `serve` created the ports).
    fn journal(&mut self, f: impl FnOnce(&mut crate::journal::Journal)) {
        if let Some(j) = self.journal.as_mut() {
            f(j);
        }
    }

    /// Journals a request the machine acted on (`value`: an estimate's power).
    fn journal_request(&mut self, kind: RequestKind, value: f64, refused: bool) {
        self.journal(|j| {
            j.record(InputKind::Request, refused, |m| {
                m.code = kind.as_u32();
                m.value = value;
            })
        });
    }

    /// Publish and persist what the machine did; true when status should go out now.
    fn handle_events(&mut self, model_out: &ModelPorts) -> bool {
        let events = self.machine.take_events();
        let changed = !events.is_empty();
        for event in events {
            match event {
                Event::ModelSwapped(model) => {
                    if model.refinements == 0 {
                        info!(version = model.version, source = ?model.source, actuated = ?model.actuated.names(), "model swapped in");
                    } else {
                        debug!(
                            version = model.version,
                            refinements = model.refinements,
                            rel_err_rot = model.rel_err_rot,
                            "model refined"
                        );
                    }
                    self.publish_model(model_out, &model);
                    if let Some(c) = self.checkpoints.as_mut() {
                        c.model_swapped();
                    }
                    if model.source == thrusterd_core::model::ModelSource::Estimated
                        && self.refined_save_due(&model)
                    {
                        self.save(&model);
                    }
                }
                Event::ModelDropped(why) => warn!("model dropped: {why}"),
                Event::ModelRejected(why) => warn!("model rejected, old one kept: {why}"),
                Event::MismatchDetected(why) => warn!("{why}"),
                Event::StateChanged { from, to, why } => {
                    info!("{} -> {}: {why}", from.name(), to.name());
                    self.record_intent(to);
                }
            }
        }
        changed
    }

    /// Reads what a crashed predecessor was doing and starts this daemon's own marker.
    fn open_resume_marker(&mut self) {
        use crate::resume_marker::{Intent, ResumeMarker};
        let (mut marker, previous) = ResumeMarker::open(&self.cfg.runtime.state_dir);
        let resume = match previous {
            Some(Intent::Hold) if self.pending_estimate => Intent::Hold,
            Some(Intent::Hold) if !self.cfg.runtime.resume_after_crash => {
                warn!("the previous thrusterd did not stop cleanly while controlling; runtime.resume_after_crash = false: idle");
                Intent::Idle
            }
            Some(Intent::Hold) if self.machine.model().is_some() => {
                warn!("the previous thrusterd did not stop cleanly while controlling: resuming control with the saved model");
                self.pending_hold = true;
                Intent::Hold
            }
            Some(Intent::Hold) => {
                warn!("the previous thrusterd did not stop cleanly while controlling, but there is no model to resume with: idle");
                Intent::Idle
            }
            Some(Intent::Idle) if marker.previous_in_fault() => {
                info!("the previous thrusterd did not stop cleanly; it was in Fault and would have recovered to idle: idle");
                Intent::Idle
            }
            Some(Intent::Idle) => {
                info!("the previous thrusterd did not stop cleanly; it was idle: idle");
                Intent::Idle
            }
            None => Intent::Idle,
        };
        marker.record(resume);
        self.resume_marker = Some(marker);
    }

    /// Keeps the resume marker in step: controlling and estimating move the vehicle, so a
    /// crash in them resumes control; Fault keeps whatever it will recover to.
    fn record_intent(&mut self, to: thrusterd_core::machine::State) {
        use thrusterd_core::machine::State;
        let intent = match to {
            State::Active => crate::resume_marker::Intent::Hold,
            s if s.is_estimating() => crate::resume_marker::Intent::Hold,
            State::Idle => crate::resume_marker::Intent::Idle,
            State::Fault => {
                // What clearing the fault resumes, marked as Fault (an operator's idle or stop
                // in Fault changes it without a state change: called after every request).
                let intent = if self.machine.fault_resumes_control() {
                    crate::resume_marker::Intent::Hold
                } else {
                    crate::resume_marker::Intent::Idle
                };
                if let Some(marker) = self.resume_marker.as_mut() {
                    marker.record_in_fault(intent);
                }
                return;
            }
            _ => return,
        };
        if let Some(marker) = self.resume_marker.as_mut() {
            marker.record(intent);
        }
    }

    /// Queues a save of `model` to the state directory; the outcome comes back through
    /// [`Daemon::poll_saves`]. Never blocks the loop.
    /// A new estimate is always saved; a refinement of one only when the last refined save
    /// is [`REFINED_SAVE_EVERY_NS`] old.
    fn refined_save_due(&mut self, model: &thrusterd_core::model::Model) -> bool {
        if model.refinements == 0 {
            self.refined_saved_t_ns = None;
            return true;
        }
        let due = self
            .refined_saved_t_ns
            .is_none_or(|t| model.made_t_ns.saturating_sub(t) >= REFINED_SAVE_EVERY_NS);
        if due {
            self.refined_saved_t_ns = Some(model.made_t_ns);
        }
        due
    }

    fn save(&mut self, model: &thrusterd_core::model::Model) {
        let path = self.model_path.clone();
        self.saver.submit(model, &path);
    }

    /// Takes the outcomes of finished saves (non-blocking).
    fn poll_saves(&mut self) {
        for outcome in self.saver.poll() {
            self.on_saved(outcome);
        }
    }

    /// Logs a save's outcome; one to the state directory sets or clears the status note.
    fn on_saved(&mut self, outcome: crate::saver::Outcome) {
        let to_state_dir = outcome.path == self.model_path;
        match &outcome.result {
            Ok(()) => {
                info!(path = %outcome.path.display(), version = outcome.version, "model saved")
            }
            Err(e) => warn!("model not saved (daemon keeps running): {e}"),
        }
        if to_state_dir {
            self.save_error = outcome.result.err();
        }
    }

    fn publish_model(&mut self, model_out: &ModelPorts, model: &thrusterd_core::model::Model) {
        let msg = wire::model_msg(self.model_seq, model);
        self.model_seq += 1;
        if let Err(e) = model_out.model.send(&msg) {
            error!("model not published: {e}");
        }
        if let Some(d) = wire::dynamics_msg(self.dynamics_seq, model) {
            self.dynamics_seq += 1;
            if let Err(e) = model_out.dynamics.send(&d) {
                error!("dynamic coefficients not published: {e}");
            }
        }
    }

    fn status_msg(&mut self) -> StatusMsg {
        let mut msg = wire::status_msg(self.status_seq, &self.machine.status());
        self.status_seq += 1;
        self.rejected.write_to(&mut msg);
        msg.requests_refused = self.refused;
        msg.samples_missed = self.missed;
        let late = self.machine.late_solves();
        if late > 0 {
            // Before the save note: it is rarer and more urgent, so it goes first.
            let text = format!("{late} late solves | {}", msg.text());
            msg.set_text(&text);
        }
        if let Some(why) = &self.save_error {
            // First, since the text is bounded (128 bytes) and the state has its own field: the
            // machine's words are what gets cut.
            let text = format!("model not saved: {why} | {}", msg.text());
            msg.set_text(&text);
        }
        msg
    }

    fn publish_status(&mut self, status_out: &Port<StatusMsg>) {
        let msg = self.status_msg();
        if let Err(e) = status_out.send(&msg) {
            error!("status not published: {e}");
        }
    }
}

/// Indices and counts the machine must never see out of range.
fn check_reconfig(e: &ReconfigEvent) -> Result<(), RejectReason> {
    thruster_protocol::validate::expect_count(
        "count",
        e.count,
        e.count.clamp(1, MAX_THRUSTERS as u32),
    )?;
    Ok(())
}

/// Where a swapped-in model goes out: B and allocation, and the dynamic coefficients when the
/// dynamic method made it.
struct ModelPorts {
    model: Port<ModelMsg>,
    dynamics: Port<DynamicsMsg>,
}

/// What the daemon publishes: the thrust command answering each sample, telemetry when it is
/// on, models and status.
struct Outputs {
    thrust: Port<ThrustCommand>,
    telemetry: Option<Port<TelemetryMsg>>,
    model: ModelPorts,
    status: Port<StatusMsg>,
}
