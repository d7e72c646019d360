//! One simulated session: thrusterd and thruster-sim started as separate processes on a private
//! iceoryx2 namespace, the operator-side ports to talk to them, and a shutdown that leaves no
//! process and no shared-memory file behind. Used by `thrusterctl demo` and by every run of
//! `thrusterctl experiment`.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

use crate::child::{keep_logs, ChildProc};
use crate::excursion::Excursion;
use nalgebra::UnitQuaternion;
use thruster_protocol::services::{
    namespace_files, purge_namespace, ControlClient, Inbox, IpcConfig, IpcNode, Port, TopicMessage,
};
use thruster_protocol::{
    ControlRequest, ControlResponse, DaemonState, DynamicsMsg, ModelMsg, RequestKind, Setpoint,
    StatusMsg, ThrustCommand, TruthMsg, VehicleStateMsg,
};

/// The daemon and simulator binaries, and what this build of them supports.
#[derive(Debug, Clone)]
pub struct Binaries {
    pub daemon: PathBuf,
    pub sim: PathBuf,
    /// `thruster-sim run --pace X` exists (lockstep, but no faster than X times real time).
    pub sim_pace: bool,
    /// The daemon's config accepts a `[monitor]` table (the model-mismatch monitor).
    pub daemon_monitor: bool,
    /// `thrusterd run --lockstep` exists (waits for a due solve in lockstep).
    pub daemon_lockstep: bool,
    /// `thruster-sim run --stepped` exists (the lab steps vehicle time itself).
    pub sim_stepped: bool,
}

impl Binaries {
    /// The binaries next to this one; under `cargo run` they are built first (cargo only builds
    /// the binary it runs). Optional features are probed, so this tool works with a daemon or
    /// simulator that predates them.
    pub fn locate() -> Result<Binaries> {
        let exe = std::env::current_exe()?;
        let dir = exe
            .parent()
            .context("thrusterctl has no folder")?
            .to_path_buf();
        // Only `cargo run` of thrusterctl itself: a process started by another crate's
        // `cargo test` (the system tests) inherits the variables too, and a `-p` build from
        // there re-unifies features, rebuilds and can wait minutes for cargo's lock (a CI run
        // sat on it in `thrusterctl demo | head`).
        let run_by_cargo = std::env::var("CARGO_MANIFEST_DIR")
            .ok()
            .filter(|m| Path::new(m).file_name().is_some_and(|n| n == "thrusterctl"));
        if let (Ok(cargo), Some(manifest)) = (std::env::var("CARGO"), run_by_cargo) {
            let mut cmd = Command::new(cargo);
            cmd.args([
                "build",
                "-q",
                "-p",
                "thrusterd",
                "-p",
                "thruster-sim",
                "--bins",
            ]);
            if dir.ends_with("release") {
                cmd.arg("--release");
            }
            let status = cmd
                .current_dir(manifest)
                .status()
                .context("building thrusterd and thruster-sim")?;
            if !status.success() {
                bail!("building thrusterd and thruster-sim failed");
            }
        }
        let (daemon, sim) = (dir.join("thrusterd"), dir.join("thruster-sim"));
        for p in [&daemon, &sim] {
            if !p.exists() {
                bail!(
                    "{} not found: build the workspace (cargo build --release)",
                    p.display()
                );
            }
        }
        let sim_help = Command::new(&sim)
            .args(["run", "--help"])
            .output()
            .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
            .unwrap_or_default();
        let sim_pace = sim_help.contains("--pace");
        let sim_stepped = sim_help.contains("--stepped");
        let daemon_monitor = probe_config(&daemon, "[monitor]\naction = \"report\"\n");
        let daemon_lockstep = Command::new(&daemon)
            .args(["run", "--help"])
            .output()
            .map(|o| String::from_utf8_lossy(&o.stdout).contains("--lockstep"))
            .unwrap_or(false);
        Ok(Binaries {
            daemon,
            sim,
            sim_pace,
            daemon_monitor,
            daemon_lockstep,
            sim_stepped,
        })
    }
}

/// True when `thrusterd check-config` accepts `text`.
fn probe_config(daemon: &Path, text: &str) -> bool {
    let Ok(dir) = TempDir::new("probe") else {
        return false;
    };
    let file = dir.path.join("probe.toml");
    if std::fs::write(&file, text).is_err() {
        return false;
    }
    Command::new(daemon)
        .arg("check-config")
        .arg(&file)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// A folder under the system temp dir (the children's logs and config), removed on drop
/// unless `THRUSTERCTL_KEEP_LOGS` is set: then its path is printed for a post-mortem.
struct TempDir {
    path: PathBuf,
}

impl TempDir {
    fn new(tag: &str) -> Result<TempDir> {
        static N: AtomicU32 = AtomicU32::new(0);
        let path = std::env::temp_dir().join(format!(
            "thrusterd-{tag}-{}-{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&path).with_context(|| format!("creating {}", path.display()))?;
        Ok(TempDir { path })
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if keep_logs() {
            eprintln!("kept {}", self.path.display());
            return;
        }
        let _ = std::fs::remove_dir_all(&self.path);
    }
}

/// Where a file of the repository's `config/` folder is: beside the sources under cargo, the
/// workspace of the binary (target/<profile>/..), the current folder, or /etc/thrusterd.
pub fn config_file(relative: &str) -> PathBuf {
    let mut candidates = Vec::new();
    if let Ok(d) = std::env::var("CARGO_MANIFEST_DIR") {
        candidates.push(Path::new(&d).join("../../config").join(relative));
    }
    if let Ok(exe) = std::env::current_exe() {
        if let Some(ws) = exe.parent().and_then(Path::parent).and_then(Path::parent) {
            candidates.push(ws.join("config").join(relative));
        }
    }
    candidates.push(Path::new("config").join(relative));
    candidates.push(Path::new("/etc/thrusterd").join(relative));
    candidates
        .iter()
        .find(|p| p.exists())
        .cloned()
        .unwrap_or_else(|| Path::new("config").join(relative))
}

/// The daemon's configuration for a session.
#[derive(Debug, Clone)]
pub enum DaemonConfig {
    /// The daemon's defaults.
    Defaults,
    /// The operator's file.
    File(PathBuf),
    /// Generated TOML, written into the session's temp folder.
    Text(String),
}

impl DaemonConfig {
    /// The `[supply]` section the daemon runs with (its default without a file), parsed by
    /// the daemon's own loader: what the lab scores a model's voltage by.
    pub fn supply(&self) -> Result<thrusterd_core::supply::SupplyConfig> {
        let (text, origin) = match self {
            DaemonConfig::Defaults => return Ok(Default::default()),
            DaemonConfig::File(p) => (
                std::fs::read_to_string(p).with_context(|| format!("{}", p.display()))?,
                p.display().to_string(),
            ),
            DaemonConfig::Text(t) => (t.clone(), "generated thrusterd.toml".to_string()),
        };
        Ok(thrusterd_core::config::DaemonConfig::from_toml_str(&text, &origin)?.supply)
    }
}

/// The daemon refused the model an estimation made (its status text says why).
#[derive(Debug, Clone, PartialEq)]
pub struct ModelRefused(pub String);

impl std::fmt::Display for ModelRefused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "the daemon refused the estimated model: {}", self.0)
    }
}

impl std::error::Error for ModelRefused {}

/// What to start.
#[derive(Debug, Clone)]
pub struct SessionSpec {
    /// Namespace prefix (the process id and a counter make it unique).
    pub tag: &'static str,
    pub vehicle: PathBuf,
    pub noise: String,
    pub seed: u64,
    /// Simulator against the wall clock instead of lockstep.
    pub realtime: bool,
    /// In lockstep, no faster than this many times real time (when the simulator supports it).
    pub pace: Option<f64>,
    pub daemon_config: DaemonConfig,
    /// Scenario TOML (scripted reconfigurations), written into the session's temp folder.
    pub scenario: Option<String>,
    /// Record the session's namespace to MCAP (`--record`), from before the processes start.
    pub record: Option<thruster_recorder::RecordOptions>,
    /// The simulator's config file (its IMU position and water, [`crate::water`]), written
    /// into the session's temp folder; None: its defaults.
    pub sim_config: Option<String>,
}

impl SessionSpec {
    /// What can be wrong with the spec itself (the vehicle file, the noise preset): checked
    /// before anything is built or started, so a typo is answered at once. The vehicle's
    /// thruster count.
    pub fn check(&self) -> Result<usize> {
        if !self.vehicle.exists() {
            bail!("vehicle file {} not found", self.vehicle.display());
        }
        let count = crate::vehicle::load(&self.vehicle)?.thrusters.len();
        if !["paper", "realistic", "none"].contains(&self.noise.as_str()) {
            return Err(thrusterctl_operator::exit::Failure::usage(format!(
                "--noise must be paper, realistic or none, got {:?}",
                self.noise
            ))
            .into());
        }
        Ok(count)
    }
}

/// The operator-side ports. Dropped before the node, and both before the namespace is purged.
struct Ports {
    status: Inbox<StatusMsg>,
    model: Inbox<ModelMsg>,
    dynamics: Inbox<DynamicsMsg>,
    truth: Inbox<TruthMsg>,
    vehicle: Inbox<VehicleStateMsg>,
    thrust: Inbox<ThrustCommand>,
    setpoint: Port<Setpoint>,
    client: ControlClient,
}

/// How a session ended.
#[derive(Debug, Clone, Copy)]
pub struct Shutdown {
    /// Both processes exited with status 0 after SIGTERM.
    pub clean: bool,
    /// Files of the namespace still on disk after the purge.
    pub leftovers: usize,
}

/// A running daemon + simulator pair and the ports to them.
pub struct Session {
    /// First: stopped (its file finished) before anything else of the session goes.
    recording: Option<crate::recording::Recording>,
    ports: Option<Ports>,
    node: Option<IpcNode>,
    ipc: IpcConfig,
    daemon: ChildProc,
    sim: ChildProc,
    /// The pace the simulator runs at, if any.
    pub pace: Option<f64>,
    /// In lockstep: the lab steps vehicle time itself ([`thruster_sim::stepper`]).
    stepper: Option<thruster_sim::stepper::Stepper>,
    /// While an estimation runs: how far the vehicle moves (from the true vehicle state).
    excursion: Option<Excursion>,
    last_excursion: Option<Excursion>,
    // Last: removed after the processes that write into it are gone.
    _tmp: TempDir,
}

impl Session {
    /// The daemon's state directory (its model file, checkpoint and journal).
    pub fn state_dir(&self) -> PathBuf {
        self._tmp.path.join("state")
    }

    /// Start both processes. The daemon is told the thruster count (and whatever the config
    /// says), never the simulator's geometry.
    pub fn start(bins: &Binaries, spec: &SessionSpec) -> Result<Session> {
        // Every check before the first iceoryx2 file: a vehicle file with 0 or 17 thrusters
        // used to fail after the session's node existed, leaving its namespace folder.
        let count = spec.check()?.to_string();
        static N: AtomicU32 = AtomicU32::new(0);
        // Namespaces are at most 16 characters.
        let ns = format!(
            "{}-{}-{}",
            &spec.tag[..spec.tag.len().min(4)],
            std::process::id() % 1_000_000,
            N.fetch_add(1, Ordering::Relaxed) % 1000
        );
        let ipc = IpcConfig::new(&ns)?;
        // The interrupt handler, before anything needs cleaning up.
        let _ = interrupted();
        // A crashed earlier run with the same id must not confuse this one.
        let _ = purge_namespace(&ipc);
        let tmp = TempDir::new(spec.tag)?;
        let node = ipc.create_node("thrusterctl-session")?;
        let ports = Ports {
            // The largest buffers the topics allow: the runner reads in bursts.
            status: Inbox::create_with_buffer(&node, &ipc, 4)?,
            model: Inbox::create_with_buffer(&node, &ipc, 4)?,
            dynamics: Inbox::create_with_buffer(&node, &ipc, 4)?,
            truth: Inbox::create_with_buffer(&node, &ipc, 4)?,
            vehicle: Inbox::create_with_buffer(&node, &ipc, 16)?,
            thrust: Inbox::create_with_buffer(&node, &ipc, 16)?,
            setpoint: Port::create(&node, &ipc)?,
            client: ControlClient::create(&node, &ipc)?,
        };

        let state = tmp.path.join("state");
        let mut daemon_args: Vec<String> = [
            "run",
            "--namespace",
            &ns,
            "--state-dir",
            state.to_str().unwrap_or("."),
        ]
        .map(String::from)
        .to_vec();
        // A generated config says the count itself, possibly with a declared layout, which
        // `--thrusters` would clear.
        if !matches!(spec.daemon_config, DaemonConfig::Text(_)) {
            daemon_args.extend(["--thrusters".into(), count]);
        }
        // In lockstep the simulator waits for every answer: the daemon's low-latency mode
        // (poll before blocking) saves a wake-up per sample, and the daemon waits (bounded)
        // for a solve due by a sample's time, so one seed gives one outcome however busy the
        // machine is (`runtime.lockstep`).
        if !spec.realtime {
            daemon_args.extend(["--spin-us".into(), "500".into()]);
            if bins.daemon_lockstep {
                daemon_args.push("--lockstep".into());
            }
            // Stepped: a solve starved by a loaded machine is waited for (as the simulator
            // waits for every answer), never taken for a hung solver.
            if bins.sim_stepped {
                daemon_args.extend(["--lockstep-wait-ms".into(), "300000".into()]);
            }
        }
        match &spec.daemon_config {
            DaemonConfig::Defaults => {}
            DaemonConfig::File(p) => daemon_args.extend(["--config".into(), path_arg(p)]),
            DaemonConfig::Text(text) => {
                let p = tmp.path.join("thrusterd.toml");
                std::fs::write(&p, text)?;
                daemon_args.extend(["--config".into(), path_arg(&p)]);
            }
        }
        let mut sim_args: Vec<String> = vec![
            "run".into(),
            "--namespace".into(),
            ns.clone(),
            "--vehicle".into(),
            path_arg(&spec.vehicle),
            "--noise".into(),
            spec.noise.clone(),
            "--seed".into(),
            spec.seed.to_string(),
        ];
        let mut pace = None;
        let stepped = !spec.realtime && bins.sim_stepped;
        if spec.realtime {
            sim_args.push("--realtime".into());
        } else {
            sim_args.push("--lockstep".into());
            if stepped {
                sim_args.push("--stepped".into());
            }
            if let (Some(x), true) = (spec.pace, bins.sim_pace) {
                sim_args.extend(["--pace".into(), x.to_string()]);
                pace = Some(x);
            }
        }
        if let Some(text) = &spec.sim_config {
            let p = tmp.path.join("thruster-sim.toml");
            std::fs::write(&p, text)?;
            sim_args.extend(["--config".into(), path_arg(&p)]);
        }
        if let Some(text) = &spec.scenario {
            let p = tmp.path.join("scenario.toml");
            std::fs::write(&p, text)?;
            sim_args.extend(["--scenario".into(), path_arg(&p)]);
        }
        // Subscribed before the processes start: the recording holds the whole session.
        let recording = match &spec.record {
            Some(options) => Some(crate::recording::Recording::start(&ipc, options.clone())?),
            None => None,
        };
        let daemon = ChildProc::spawn("thrusterd", &bins.daemon, &daemon_args, &tmp.path, false)?;
        let mut sim = ChildProc::spawn("thruster-sim", &bins.sim, &sim_args, &tmp.path, stepped)?;
        let stepper = match sim.take_pipes() {
            Some((to_sim, from_sim)) => {
                Some(thruster_sim::stepper::Stepper::new(to_sim, from_sim)?)
            }
            None => None,
        };
        Ok(Session {
            recording,
            ports: Some(ports),
            node: Some(node),
            ipc,
            daemon,
            sim,
            pace,
            stepper,
            excursion: None,
            last_excursion: None,
            _tmp: tmp,
        })
    }

    /// A path in the session's own temporary folder (removed with the session).
    pub fn scratch_path(&self, name: &str) -> PathBuf {
        self._tmp.path.join(name)
    }

    fn ports(&self) -> &Ports {
        self.ports.as_ref().expect("ports live until finish")
    }

    pub fn status_inbox(&self) -> &Inbox<StatusMsg> {
        &self.ports().status
    }
    pub fn model_inbox(&self) -> &Inbox<ModelMsg> {
        &self.ports().model
    }
    pub fn truth_inbox(&self) -> &Inbox<TruthMsg> {
        &self.ports().truth
    }
    pub fn vehicle_inbox(&self) -> &Inbox<VehicleStateMsg> {
        &self.ports().vehicle
    }
    pub fn thrust_inbox(&self) -> &Inbox<ThrustCommand> {
        &self.ports().thrust
    }

    /// The daemon's log so far.
    pub fn daemon_log(&self) -> String {
        self.daemon.log_text()
    }

    /// An error if either process has exited, or the lab was interrupted (Ctrl-C, SIGTERM:
    /// the session is then dropped, which stops both processes and removes the namespace).
    pub fn check_alive(&mut self, what: &str) -> Result<()> {
        if interrupted() {
            bail!("interrupted while waiting for {what}: thrusterd and thruster-sim stopped");
        }
        if !self.daemon.alive() {
            bail!(
                "thrusterd exited while waiting for {what}:\n{}",
                self.daemon.tail()
            );
        }
        if !self.sim.alive() {
            bail!(
                "thruster-sim exited while waiting for {what}:\n{}",
                self.sim.tail()
            );
        }
        Ok(())
    }

    /// An error naming `what`, with both logs' ends.
    pub fn timeout_error(&self, what: &str) -> anyhow::Error {
        anyhow::anyhow!(
            "timed out waiting for {what}\n{}\n{}",
            self.daemon.tail(),
            self.sim.tail()
        )
    }

    /// The first status satisfying `pred` (every status is shown to it, oldest first).
    pub fn wait_status(
        &mut self,
        what: &str,
        timeout: Duration,
        pred: &mut dyn FnMut(&StatusMsg) -> bool,
    ) -> Result<StatusMsg> {
        let start = Instant::now();
        loop {
            if self.excursion.is_some() {
                while let Some(v) = self.vehicle_inbox().recv()? {
                    if let Some(e) = self.excursion.as_mut() {
                        e.push(&v);
                    }
                }
            }
            while let Some(st) = self.status_inbox().recv()? {
                if pred(&st) {
                    return Ok(st);
                }
            }
            self.check_alive(what)?;
            if start.elapsed() > timeout {
                return Err(self.timeout_error(what));
            }
            self.tick()?;
        }
    }

    /// Lets vehicle time pass: a step of [`thruster_sim::stepper::STEP_SAMPLES`] samples when the
    /// lab steps the simulator, a short sleep otherwise. Every wait of the lab goes through
    /// here, so in lockstep it acts only between steps, at vehicle times that do not depend
    /// on the machine's speed.
    pub fn tick(&mut self) -> Result<()> {
        if interrupted() {
            bail!("interrupted: thrusterd and thruster-sim stopped");
        }
        match self.stepper.as_mut() {
            Some(stepper) => {
                // A daemon that died mid-step (a bad configuration, an abort) is told at once,
                // not after the step's two-minute limit.
                let (daemon, sim) = (&mut self.daemon, &mut self.sim);
                let alive = || !interrupted() && daemon.alive() && sim.alive();
                if let Err(e) = stepper.advance_while(thruster_sim::stepper::STEP_SAMPLES, alive) {
                    self.check_alive("the next step of the simulator")?;
                    return Err(anyhow::Error::new(e)
                        .context(self.timeout_error("the next step of the simulator")));
                }
                Ok(())
            }
            None => {
                std::thread::sleep(Duration::from_micros(200));
                Ok(())
            }
        }
    }

    /// The vehicle time the stepped simulator holds at, ns (None when not stepped, or
    /// before its first sample was answered).
    pub fn held_ns(&self) -> Option<u64> {
        self.stepper.as_ref().and_then(|s| s.held()).map(|h| h.t_ns)
    }

    /// Both processes up, the daemon answering samples, the simulator's truth received.
    pub fn ready(&mut self) -> Result<(StatusMsg, TruthMsg)> {
        let first =
            self.wait_status("the first IMU samples", Duration::from_secs(30), &mut |s| {
                s.samples > 20
            })?;
        let start = Instant::now();
        // History 1: the simulator's truth reaches us on its next connection update.
        loop {
            if let Some(t) = latest(self.truth_inbox())? {
                return Ok((first, t));
            }
            self.check_alive("the simulator's truth")?;
            if start.elapsed() > Duration::from_secs(10) {
                bail!("the simulator published no truth");
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// A control request, retried while the daemon's server is not reachable yet.
    pub fn request(&self, request: ControlRequest) -> Result<ControlResponse> {
        let start = Instant::now();
        loop {
            match self.ports().client.call(request, Duration::from_secs(2)) {
                Ok(r) => return Ok(r),
                Err(e) if start.elapsed() < Duration::from_secs(10) => {
                    let _ = e;
                    std::thread::sleep(Duration::from_millis(20));
                }
                Err(e) => return Err(e).context(format!("{:?} request", request.kind())),
            }
        }
    }

    /// A request that must succeed.
    pub fn command(&self, kind: RequestKind) -> Result<String> {
        let r = self.request(ControlRequest::new(kind))?;
        if !r.is_ok() {
            bail!("{kind:?} refused: {}", r.text());
        }
        Ok(r.text().to_string())
    }

    /// Request an estimate and wait until the daemon holds attitude with a new model;
    /// `progress` sees every status on the way. The final status.
    pub fn estimate(
        &mut self,
        timeout: Duration,
        progress: &mut dyn FnMut(&StatusMsg),
    ) -> Result<StatusMsg> {
        let before = latest(self.status_inbox())?
            .map(|s| s.model_version)
            .unwrap_or(0);
        // Only what happens from the request on counts.
        while self.vehicle_inbox().recv()?.is_some() {}
        self.excursion = Some(Excursion::default());
        self.command(RequestKind::Estimate)?;
        // A refused model (the daemon back in Idle, or holding the old model, with "model
        // rejected" in its status) ends the wait at once, with the daemon's reason.
        let refused = |s: &StatusMsg| {
            matches!(s.state(), Ok(DaemonState::Idle) | Ok(DaemonState::Active))
                && s.text().contains("model rejected")
        };
        // An estimation that faulted (a lost IMU, a solve past its time) or was aborted ends
        // in Fault or Idle without a model: the wait ends there, with the daemon's words,
        // not at the timeout while vehicle time runs on.
        let mut started = false;
        let mut ended = None;
        let done = self.wait_status("the estimated model", timeout, &mut |s| {
            progress(s);
            let state = s.state();
            started |= matches!(
                state,
                Ok(DaemonState::MeasureNoise
                    | DaemonState::Pulse
                    | DaemonState::Settle
                    | DaemonState::Solve)
            );
            if started
                && matches!(state, Ok(DaemonState::Fault | DaemonState::Idle))
                && s.model_version <= before
                && !refused(s)
            {
                ended = Some(format!(
                    "{}: {}",
                    state.map(|x| x.name()).unwrap_or("?"),
                    s.text()
                ));
                return true;
            }
            (state == Ok(DaemonState::Active) && s.model_version > before) || refused(s)
        });
        self.last_excursion = self.excursion.take();
        let done = done?;
        if let Some(why) = ended {
            bail!("the estimation ended without a model ({why})");
        }
        if refused(&done) && done.model_version <= before {
            return Err(ModelRefused(done.text().to_string()).into());
        }
        Ok(done)
    }

    /// How far the vehicle moved during the last `estimate` (the vehicle states the session
    /// received: every one when the lab steps the simulator; the inbox keeps the newest 16,
    /// so in unstepped fast lockstep some are skipped).
    pub fn last_excursion(&self) -> Option<Excursion> {
        self.last_excursion
    }

    /// The dynamic coefficients of model `version`, when its method learned any (waits up to
    /// 2 s for them: they are published right after the model).
    pub fn dynamics(&mut self, version: u64) -> Result<Option<DynamicsMsg>> {
        let start = Instant::now();
        let mut newest = None;
        loop {
            while let Some(d) = self.ports().dynamics.recv()? {
                newest = Some(d);
            }
            match newest {
                Some(d) if d.model_version == version => return Ok(Some(d)),
                _ if start.elapsed() > Duration::from_secs(2) => return Ok(None),
                _ => {}
            }
            self.check_alive("the dynamic coefficients")?;
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// The latest model (waits up to 10 s for one).
    pub fn model(&mut self) -> Result<ModelMsg> {
        self.latest_blocking(|s| s.model_inbox(), "a model")
    }

    /// The newest vehicle state (waits up to 10 s for one).
    pub fn vehicle_state(&mut self) -> Result<VehicleStateMsg> {
        self.latest_blocking(|s| s.vehicle_inbox(), "the vehicle state")
    }

    fn latest_blocking<T: TopicMessage>(
        &mut self,
        inbox: fn(&Session) -> &Inbox<T>,
        what: &str,
    ) -> Result<T> {
        let start = Instant::now();
        loop {
            if let Some(m) = latest(inbox(self))? {
                return Ok(m);
            }
            self.check_alive(what)?;
            if start.elapsed() > Duration::from_secs(10) {
                return Err(self.timeout_error(what));
            }
            self.tick()?;
        }
    }

    /// Send an attitude (body to NED) and depth to hold.
    pub fn send_setpoint(&self, attitude: &UnitQuaternion<f64>, depth: Option<f64>) -> Result<()> {
        let q = attitude.into_inner();
        let sp = Setpoint {
            attitude: [q.w, q.i, q.j, q.k],
            depth: depth.unwrap_or(0.0),
            // None releases depth; a setpoint without either flag would keep the held one.
            flags: if depth.is_some() {
                Setpoint::HOLD_DEPTH
            } else {
                Setpoint::RELEASE_DEPTH
            },
            ..Setpoint::default()
        };
        self.ports().setpoint.send(&sp)?;
        Ok(())
    }

    /// Stops the recording (`--record`), if any, and returns what it wrote. Call it before
    /// [`Session::finish`] (the processes still run; the recording ends here).
    pub fn stop_recording(&mut self) -> Option<Result<thruster_recorder::RecordSummary>> {
        self.recording.take().map(|mut r| r.stop())
    }

    /// SIGTERM both processes, drop every port, purge the namespace.
    pub fn finish(mut self) -> Shutdown {
        // A recording not stopped by `stop_recording` ends here, before the namespace goes.
        self.recording = None;
        // The simulator first: the daemon then sees no more samples and exits on its own signal.
        let clean = self.sim.stop() & self.daemon.stop();
        self.ports = None;
        self.node = None;
        let _ = purge_namespace(&self.ipc);
        let leftovers = namespace_files(&self.ipc).map(|f| f.len()).unwrap_or(0);
        Shutdown { clean, leftovers }
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        // finish() did this already on the normal path; on an error path kill first.
        self.recording = None;
        self.daemon.kill();
        self.sim.kill();
        self.ports = None;
        self.node = None;
        let _ = purge_namespace(&self.ipc);
    }
}

/// True once Ctrl-C or SIGTERM reached the lab (the handler is installed by the first
/// session: the wait loops then end with an error and the session's drop cleans up, where the
/// default action would kill the lab and leave its namespace's files behind).
fn interrupted() -> bool {
    static FLAG: std::sync::OnceLock<Option<std::sync::Arc<std::sync::atomic::AtomicBool>>> =
        std::sync::OnceLock::new();
    FLAG.get_or_init(|| thrusterctl_operator::console::interrupt_flag().ok())
        .as_ref()
        .is_some_and(|f| f.load(Ordering::SeqCst))
}

fn path_arg(p: &Path) -> String {
    p.display().to_string()
}

/// The newest message in `inbox`, draining it.
pub fn latest<T: TopicMessage>(inbox: &Inbox<T>) -> Result<Option<T>> {
    let mut last = None;
    while let Some(m) = inbox.recv()? {
        last = Some(m);
    }
    Ok(last)
}
