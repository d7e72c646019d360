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

mod event_loop;
mod inputs;
mod persistence;
mod publishing;
mod requests;
mod solves;

/// A change of the driver's supply voltage that is handed to the machine (and journaled), V:
/// finer than the T200 table resolves (~0.4 % thrust per 50 mV), coarse enough that a
/// driver's ADC noise does not fill the journal.
const SUPPLY_STEP_V: f64 = 0.01;
/// A steady supply voltage is handed to the machine again after this long, ns of the driver's
/// clock: the sag line (`thrusterd_core::supply::Sag`) needs readings under changing load even
/// when the voltage does not move (a regulated bench supply, a stiff pack).
const SUPPLY_EVERY_NS: u64 = 1_000_000_000;

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
/// How long an operator's `save` request is kept open for the saving thread's outcome (the
/// loop never waits for it: the answer goes out from a later round): a healthy disk or a fast
/// failure (full, read-only) answers well within it; a stalled disk gets a "saving" answer.
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
    /// IMU samples read on wake-ups their notification did not cause (`imu_wakeups.rs`).
    imu_wakeups: crate::imu_wakeups::ImuWakeups,
    /// The driver's own reports on its outputs (count, rejections, armed, link).
    driver: DriverWatch,
    /// The verdict the machine was last given on the driver's outputs.
    driver_verdict: OutputVerdict,
    /// The supply voltage last handed to the machine, V.
    supply_v: Option<f64>,
    /// The driver's time of the reading last handed to the machine, ns.
    supply_taken_ns: u64,
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
    /// Number of the next deferred request (a load or a save).
    next_token: u64,
    /// Operators' saves not yet answered (`persistence::SaveAnswer`).
    save_answers: Vec<persistence::SaveAnswer>,
}

impl Daemon {
    fn new(cfg: &DaemonConfig, shutdown: Arc<AtomicBool>) -> Result<Self> {
        let ipc = match &cfg.ipc.root {
            Some(root) => IpcConfig::with_root_base(&cfg.ipc.namespace, root),
            None => IpcConfig::new(&cfg.ipc.namespace),
        }
        .with_context(|| format!("ipc.namespace {:?}", cfg.ipc.namespace))?;
        // Before any iceoryx2 call: its cleanup of a dead node it cannot read falls back to the
        // global configuration, which must be this namespace's (`services::unfinished`).
        if !ipc.install_as_global() {
            warn!("iceoryx2's global configuration is not this namespace's: a dead node without its details file will not be cleaned up");
        }
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
            save_answers: Vec::new(),
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
            imu_wakeups: Default::default(),
            driver: DriverWatch::for_daemon(cfg.runtime.lockstep),
            driver_verdict: OutputVerdict::Usable,
            supply_v: None,
            supply_taken_ns: 0,
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
