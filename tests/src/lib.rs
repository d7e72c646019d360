//! Helpers shared by the system tests: the real binaries started as separate processes on a
//! private iceoryx2 namespace, always reaped, and the namespace purged afterwards.

use std::path::{Path, PathBuf};
use std::process::{ChildStdin, ChildStdout, Command, ExitStatus};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Once;

use std::time::{Duration, Instant};
use thruster_driver_kit::test_process::{Launch, TestProcess};

use thruster_protocol::services::{
    ControlClient, Inbox, IpcConfig, IpcNode, NamespaceGuard, TopicMessage,
};
use thruster_protocol::{
    ControlRequest, ControlResponse, DaemonState, DynamicsMsg, ModelMsg, RequestKind, StatusMsg,
    TruthMsg,
};

pub mod cli;
pub mod driver_stand_in;
pub mod linux_driver;
pub mod mount;
pub mod node;
pub mod python;
pub mod season;
pub mod soak;
pub mod vehicle_clock;

/// Workspace root (this crate lives in tests/).
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// Path of a workspace binary in the same profile as the running test.
///
/// `cargo test --workspace` (what CI runs) builds every binary before any test starts. Run
/// alone (`cargo test -p system-tests`) a binary may be missing: it is built then. Benches call
/// [`build_binaries`] first, since a binary left from an older build would measure old code.
///
/// With `THRUSTER_BIN_DIR` set, the binaries are taken from that folder as they are (the
/// season soak copies them there first: a run of an hour must not pick up a binary that a
/// build in the shared target folder replaced meanwhile).
pub fn bin(name: &str) -> PathBuf {
    if let Some(dir) = std::env::var_os(BIN_DIR_ENV) {
        return Path::new(&dir).join(name);
    }
    let path = target_dir().join(name);
    if !path.exists() {
        build_binaries();
    }
    assert!(path.exists(), "{} not built", path.display());
    path
}

/// Environment variable naming a folder to take the binaries from instead (see [`bin`]).
pub const BIN_DIR_ENV: &str = "THRUSTER_BIN_DIR";

/// target/<profile> of the running test, bench or tool.
fn target_dir() -> PathBuf {
    // Tests and benches: target/<profile>/deps/<binary>; tools such as `soak` are binaries of
    // this crate: target/<profile>/<binary>.
    let exe = std::env::current_exe().unwrap();
    let dir = exe.parent().unwrap();
    if dir.ends_with("deps") {
        dir.parent().unwrap().to_path_buf()
    } else {
        dir.to_path_buf()
    }
}

/// Build thrusterd, thrusterctl, thruster-sim, thruster-hw and thruster-bridge in the running profile, once per process.
/// (`-p` selects a different feature set than the whole workspace, so this can rebuild the
/// project's own crates: that is why tests do not call it when the binaries exist.)
pub fn build_binaries() {
    static BUILD: Once = Once::new();
    BUILD.call_once(|| {
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut cmd = Command::new(cargo);
        cmd.args([
            "build",
            "-q",
            "-p",
            "thrusterd",
            "-p",
            "thrusterctl",
            "-p",
            "thruster-sim",
            "-p",
            "thruster-hw",
            "-p",
            "thruster-bridge",
            "--bins",
        ]);
        if target_dir().ends_with("release") {
            cmd.arg("--release");
        }
        let status = cmd
            .current_dir(workspace())
            .status()
            .expect("running cargo build");
        assert!(status.success(), "building the binaries failed");
    });
}

/// One of our binaries as a child process: driver-kit's one test launcher (`TestProcess`:
/// killed and reaped however the test ends, its log printed when the test panics, signals by
/// name), started from this workspace's build with its log in a world's folder. Everything
/// else (`signal`, `wait_timeout`, `stop`, `log_text`, `is_running`, `pid`, `log`, `name`)
/// is the launcher's, through `Deref`.
pub struct Proc(TestProcess);

impl std::ops::Deref for Proc {
    type Target = TestProcess;
    fn deref(&self) -> &TestProcess {
        &self.0
    }
}

impl std::ops::DerefMut for Proc {
    fn deref_mut(&mut self) -> &mut TestProcess {
        &mut self.0
    }
}

impl Proc {
    /// Start `bin(name)` with `args`; stdout and stderr go to a log file in `logs`.
    pub fn spawn(name: &str, args: &[&str], logs: &Path) -> Proc {
        Proc::spawn_with_env(name, args, &[], logs)
    }

    /// As `spawn`, with extra environment variables.
    pub fn spawn_with_env(name: &str, args: &[&str], env: &[(&str, &str)], logs: &Path) -> Proc {
        Proc::spawn_path(&bin(name), name, args, env, logs)
    }

    /// As `spawn_with_env`, the binary at `path` (a bench comparing another build's binary).
    pub fn spawn_path(
        path: &Path,
        name: &str,
        args: &[&str],
        env: &[(&str, &str)],
        logs: &Path,
    ) -> Proc {
        let launched = Launch::new(path)
            .name(name)
            .args(args)
            .envs(env)
            .log_to(Proc::new_log(name, logs))
            .spawn()
            .unwrap_or_else(|e| panic!("spawning {name}: {e}"));
        Proc(launched)
    }

    /// As `spawn`, with standard input and output piped to the caller (a protocol such as the
    /// simulator's stepping); standard error goes to the log.
    pub fn spawn_piped(name: &str, args: &[&str], logs: &Path) -> (Proc, ChildStdin, ChildStdout) {
        let (launched, stdin, stdout) = Launch::new(&bin(name))
            .name(name)
            .args(args)
            .log_to(Proc::new_log(name, logs))
            .spawn_piped()
            .unwrap_or_else(|e| panic!("spawning {name}: {e}"));
        (Proc(launched), stdin, stdout)
    }

    /// A fresh log file name in `logs`. One file per process: two of the same binary (say, two
    /// `thrusterctl watch`) in one test must not share a log, or each truncates and
    /// interleaves the other's lines.
    fn new_log(name: &str, logs: &Path) -> PathBuf {
        static NEXT_LOG: AtomicU64 = AtomicU64::new(0);
        logs.join(format!(
            "{name}-{}.log",
            NEXT_LOG.fetch_add(1, Ordering::Relaxed)
        ))
    }

    /// SIGTERM, then wait; the exit status (panics with the log after 5 s).
    pub fn stop(&mut self) -> ExitStatus {
        self.0.stop_within(Duration::from_secs(5))
    }
}

/// The name of the first of `procs` that is no longer running, if any (a soak stops there).
pub fn first_exited<'a>(procs: &mut [(&'a str, &mut Proc)]) -> Option<&'a str> {
    procs
        .iter_mut()
        .find_map(|(name, p)| (!p.is_running()).then_some(*name))
}

/// A test's private world: namespace (purged on drop), temp folder for logs and state.
pub struct World {
    pub dir: tempfile::TempDir,
    // Declared before `ns` so nodes drop first; the guard then purges the namespace.
    pub node: Option<IpcNode>,
    pub ns: NamespaceGuard,
}

impl World {
    pub fn new(tag: &str) -> World {
        let ns = NamespaceGuard::unique_for_test(tag).unwrap();
        let node = ns.create_node("system-test").unwrap();
        World {
            dir: tempfile::tempdir().unwrap(),
            node: Some(node),
            ns,
        }
    }

    pub fn node(&self) -> &IpcNode {
        self.node.as_ref().unwrap()
    }

    pub fn ipc(&self) -> &IpcConfig {
        &self.ns
    }

    pub fn namespace(&self) -> String {
        self.ns.namespace().to_string()
    }

    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// `thrusterd run` on this namespace with a state directory in the temp folder.
    pub fn daemon(&self, extra: &[&str]) -> Proc {
        let ns = self.namespace();
        let state = self.path("state");
        let mut args = vec![
            "run",
            "--namespace",
            &ns,
            "--state-dir",
            state.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        Proc::spawn("thrusterd", &args, self.dir.path())
    }

    /// `thrusterd run` with extra environment variables (e.g. systemd's NOTIFY_SOCKET).
    pub fn daemon_with_env(&self, extra: &[&str], env: &[(&str, &str)]) -> Proc {
        let ns = self.namespace();
        let state = self.path("state");
        let mut args = vec![
            "run",
            "--namespace",
            &ns,
            "--state-dir",
            state.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        Proc::spawn_with_env("thrusterd", &args, env, self.dir.path())
    }

    /// `thruster-sim run` on this namespace.
    pub fn sim(&self, vehicle: &str, extra: &[&str]) -> Proc {
        let args = self.sim_args(vehicle, extra);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        Proc::spawn("thruster-sim", &args, self.dir.path())
    }

    /// `run --namespace <this> --vehicle config/vehicles/<vehicle>.toml <extra>`.
    fn sim_args(&self, vehicle: &str, extra: &[&str]) -> Vec<String> {
        let vehicle = workspace()
            .join("config/vehicles")
            .join(format!("{vehicle}.toml"));
        let mut args: Vec<String> = ["run", "--namespace", &self.namespace(), "--vehicle"]
            .map(String::from)
            .into();
        args.push(vehicle.display().to_string());
        args.extend(extra.iter().map(|a| a.to_string()));
        args
    }

    /// `thruster-bridge` on this namespace serving the live view on a free local port and
    /// recording to `out`; returns once its start line names the port.
    pub fn live_bridge(&self, out: &Path) -> (Proc, u16) {
        let ns = self.namespace();
        let args = [
            "--namespace",
            ns.as_str(),
            "--ws",
            "127.0.0.1:0",
            "--record",
            out.to_str().unwrap(),
        ];
        let mut bridge = Proc::spawn("thruster-bridge", &args, self.dir.path());
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let log = bridge.log_text();
            if let Some(rest) = log.split("live view on ws://127.0.0.1:").nth(1) {
                let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
                return (bridge, digits.parse().expect("a port number"));
            }
            assert!(bridge.is_running(), "the bridge exited: {log}");
            assert!(Instant::now() < deadline, "no start line after 60 s: {log}");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// The end of a test: the test's own node dropped (so it leaves nothing either), no file
    /// of the namespace may be left on disk. Call after every process has exited.
    pub fn assert_nothing_left(mut self) {
        self.node = None;
        let left = self.leftovers();
        assert!(left.is_empty(), "files of the namespace left: {left:?}");
    }

    /// Files of this namespace still on disk (after every process has exited).
    pub fn leftovers(&self) -> Vec<PathBuf> {
        thruster_protocol::services::purge_namespace(&self.ns).unwrap();
        thruster_protocol::services::namespace_files(&self.ns).unwrap()
    }
}

/// Operator-side view of the daemon, from the test process.
pub struct Operator {
    pub client: ControlClient,
    pub status: Inbox<StatusMsg>,
    pub model: Inbox<ModelMsg>,
    pub truth: Inbox<TruthMsg>,
    pub dynamics: Inbox<DynamicsMsg>,
}

impl Operator {
    pub fn new(world: &World) -> Operator {
        Operator {
            client: ControlClient::create(world.node(), world.ipc()).unwrap(),
            status: Inbox::create(world.node(), world.ipc()).unwrap(),
            model: Inbox::create(world.node(), world.ipc()).unwrap(),
            truth: Inbox::create(world.node(), world.ipc()).unwrap(),
            dynamics: Inbox::create(world.node(), world.ipc()).unwrap(),
        }
    }

    pub fn request(&self, kind: RequestKind) -> ControlResponse {
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            match self
                .client
                .call(ControlRequest::new(kind), Duration::from_secs(2))
            {
                Ok(r) => return r,
                Err(e) if Instant::now() < deadline => {
                    let _ = e;
                    std::thread::sleep(Duration::from_millis(20));
                }
                Err(e) => panic!("{kind:?}: {e}"),
            }
        }
    }

    /// First status satisfying `pred`, waiting up to `timeout`.
    pub fn wait_status(
        &self,
        timeout: Duration,
        pred: impl Fn(&StatusMsg) -> bool,
    ) -> Option<StatusMsg> {
        wait_for(&self.status, timeout, pred)
    }

    /// First model satisfying `pred`, waiting up to `timeout`.
    pub fn wait_model(
        &self,
        timeout: Duration,
        pred: impl Fn(&ModelMsg) -> bool,
    ) -> Option<ModelMsg> {
        wait_for(&self.model, timeout, pred)
    }

    /// First dynamic terms message satisfying `pred`, waiting up to `timeout`.
    pub fn wait_dynamics(
        &self,
        timeout: Duration,
        pred: impl Fn(&DynamicsMsg) -> bool,
    ) -> Option<DynamicsMsg> {
        wait_for(&self.dynamics, timeout, pred)
    }

    /// Latest truth (the simulator publishes it with history 1).
    pub fn latest_truth(&self, timeout: Duration) -> Option<TruthMsg> {
        let start = Instant::now();
        let mut last = None;
        while start.elapsed() < timeout && last.is_none() {
            while let Some(t) = self.truth.recv().unwrap() {
                last = Some(t);
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        while let Some(t) = self.truth.recv().unwrap() {
            last = Some(t);
        }
        last
    }
}

/// First message on `inbox` satisfying `pred`, polling up to `timeout`.
pub fn wait_for<T: TopicMessage>(
    inbox: &Inbox<T>,
    timeout: Duration,
    pred: impl Fn(&T) -> bool,
) -> Option<T> {
    let start = Instant::now();
    while start.elapsed() < timeout {
        while let Some(m) = inbox.recv().unwrap() {
            if pred(&m) {
                return Some(m);
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    None
}

pub fn state(s: &StatusMsg) -> DaemonState {
    s.state().unwrap_or(DaemonState::Fault)
}

/// Relative Frobenius error of the model's rows [first, first+3) against the symmetric truth
/// (mean of forward and reverse gains, which is what a linear model learns).
pub fn model_error(model: &ModelMsg, truth: &TruthMsg, first: usize) -> f64 {
    truth.relative_error(model, first)
}
