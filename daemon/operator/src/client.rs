//! The connection to one daemon: a node in its namespace, the control client, and
//! subscriptions to what it publishes. IPC errors become [`Failure`]s with the exit code
//! the operator (or a script) acts on.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use thruster_protocol::services::{
    check_access, cleanup_dead_nodes, owns_root, Inbox, IpcConfig, IpcError, IpcNode, Port,
    TidyOnDrop, TopicMessage,
};
use thruster_protocol::{ControlRequest, ControlResponse, RequestKind};

use crate::exit::{self, Failure};

/// Longest sleep between checks while waiting for a published message. A late joiner
/// gets the history sample when the publisher calls `update_connections`, which does not
/// notify, so we cannot rely on a wake-up alone.
const POLL: Duration = Duration::from_millis(20);

/// Which daemon: namespace and iceoryx2 root base, as given on the command line.
#[derive(Debug, Clone)]
pub struct Target {
    pub namespace: String,
    pub root_base: PathBuf,
}

/// An open line to the daemon of one namespace. Ports and the node are released when it
/// drops, so callers return (never `process::exit`) to leave no files behind.
pub struct Daemon {
    control: thruster_protocol::services::ControlClient,
    ipc: IpcConfig,
    /// Whether this user may remove dead nodes' files (see `owns_root`).
    owns_root: bool,
    timeout: Duration,
    // Declared after the ports so it drops after every port created from it.
    node: IpcNode,
    /// After the node: the last process to leave a namespace removes iceoryx2's residue.
    _tidy: TidyOnDrop,
}

impl Daemon {
    /// Joins `namespace` (files under `root_base`) and creates the control client. This
    /// does not contact the daemon yet; [`Daemon::call`] does.
    pub fn connect(target: &Target, timeout: Duration) -> Result<Self> {
        let namespace = target.namespace.as_str();
        let ipc = IpcConfig::with_root_base(namespace, &target.root_base)
            .map_err(|e| Failure::usage(format!("--namespace/--ipc-root: {e}")))?;
        // Before the node: joining creates files, and files the daemon cannot open stall it.
        check_access(&ipc).map_err(|e| match e {
            IpcError::AccessDenied(denied) => Failure::new(exit::FORBIDDEN, denied.to_string()),
            other => Failure::new(exit::GENERIC, other.to_string()),
        })?;
        // An operator of another user than the daemon leaves dead nodes to the daemon.
        let ipc = if owns_root(&ipc) {
            ipc
        } else {
            ipc.without_dead_node_cleanup()
        };
        let node = ipc
            .create_node("thrusterctl")
            .with_context(|| format!("joining namespace {namespace}"))?;
        let control = thruster_protocol::services::ControlClient::create(&node, &ipc)
            .context("opening the control service")?;
        let tidy = TidyOnDrop::new(&ipc);
        Ok(Self {
            control,
            owns_root: owns_root(&ipc),
            ipc,
            timeout,
            node,
            _tidy: tidy,
        })
    }

    pub fn namespace(&self) -> &str {
        self.ipc.namespace()
    }

    /// The folder of the namespace's iceoryx2 files.
    pub fn root_dir(&self) -> std::path::PathBuf {
        self.ipc.root_dir()
    }

    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    /// Sends `request` and returns the daemon's validated answer, whatever its code.
    /// Never waits longer than the timeout: no server fails at once.
    pub fn call(&self, request: ControlRequest) -> Result<ControlResponse> {
        // A daemon that died (SIGKILL, crash) after we joined the namespace keeps its server
        // port registered until someone removes its resources: the call would wait out the
        // whole timeout and report a slow daemon (exit 5) instead of a dead one (exit 3).
        // Joining cleans up once; long waits (`estimate --wait`, `watch`) ask again later,
        // so clean up before every call (a directory listing; failures change nothing).
        if self.owns_root {
            let _ = cleanup_dead_nodes(&self.ipc);
        }
        self.control
            .call(request, self.timeout)
            .map_err(|e| self.ipc_failure(e).into())
    }

    /// Sends `request` and returns the daemon's text when it succeeded; a refusal is a
    /// [`Failure`] with [`exit::REFUSED`] and the daemon's reason.
    pub fn command(&self, request: ControlRequest) -> Result<String> {
        let response = self.call(request)?;
        accepted(&response).map_err(Into::into)
    }

    /// Fails with [`exit::NOT_RUNNING`] unless a daemon answers a status request.
    pub fn ensure_running(&self) -> Result<ControlResponse> {
        self.call(ControlRequest::new(RequestKind::Status))
    }

    /// Subscribes to `T` with a buffer of one: we only ever want the newest state.
    pub fn inbox<T: TopicMessage>(&self) -> Result<Inbox<T>> {
        Inbox::create_with_buffer(&self.node, &self.ipc, 1)
            .with_context(|| format!("subscribing to {}", T::TOPIC.leaf()))
    }

    /// Subscribes to `T` with a buffer of `buffer` messages (clamped to the topic's maximum),
    /// for a reader that wants every message of a stream, not only the newest.
    pub fn inbox_with_buffer<T: TopicMessage>(&self, buffer: usize) -> Result<Inbox<T>> {
        Inbox::create_with_buffer(&self.node, &self.ipc, buffer)
            .with_context(|| format!("subscribing to {}", T::TOPIC.leaf()))
    }

    /// A publisher of `T` (for reconfiguration events and setpoints).
    pub fn port<T: TopicMessage>(&self) -> Result<Port<T>> {
        Port::create(&self.node, &self.ipc)
            .with_context(|| format!("opening {} for publishing", T::TOPIC.leaf()))
    }

    /// The operator-facing form of an IPC error.
    pub fn ipc_failure(&self, error: IpcError) -> Failure {
        let ns = self.namespace();
        match error {
            IpcError::NoServer { .. } => {
                Failure::new(exit::NOT_RUNNING, not_running(ns, &self.ipc.root_dir()))
            }
            IpcError::Timeout { timeout, .. } => Failure::new(
                exit::TIMEOUT,
                format!(
                    "thrusterd on namespace {ns} did not answer within {} ms",
                    timeout.as_millis()
                ),
            ),
            other => Failure::new(exit::GENERIC, format!("talking to thrusterd: {other}")),
        }
    }
}

/// The message for a namespace without a control server.
/// The words for "no daemon": the namespace and the folder searched, since a daemon on
/// another `--ipc-root` (under systemd, /run/thrusterd) is invisible from the default one.
pub fn not_running(namespace: &str, root: &std::path::Path) -> String {
    format!(
        "thrusterd is not running on namespace {namespace} (no control server in {}; \
         a daemon elsewhere needs --namespace and --ipc-root)",
        root.display()
    )
}

/// The daemon's text when `response` is a success, else a refusal [`Failure`].
pub fn accepted(response: &ControlResponse) -> Result<String, Failure> {
    if response.is_ok() {
        return Ok(response.text().to_string());
    }
    let code = response
        .code()
        .map_or_else(|e| e.to_string(), |c| c.name().to_string());
    let text = response.text();
    let reason = if text.is_empty() {
        "no reason given"
    } else {
        text
    };
    Err(Failure::new(
        exit::REFUSED,
        format!("thrusterd refused ({code}): {reason}"),
    ))
}

/// Waits up to `timeout` for a message on `inbox` and returns the newest one.
pub fn wait_latest<T: TopicMessage>(inbox: &Inbox<T>, timeout: Duration) -> Result<Option<T>> {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(msg) = inbox.recv_latest()? {
            return Ok(Some(msg));
        }
        let now = Instant::now();
        if now >= deadline {
            return Ok(None);
        }
        inbox.wait((deadline - now).min(POLL))?;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use thruster_protocol::ResponseCode;

    #[test]
    fn refusals_carry_code_and_reason() {
        assert_eq!(accepted(&ControlResponse::ok("saved")).unwrap(), "saved");
        let e = accepted(&ControlResponse::new(ResponseCode::Busy, "estimating")).unwrap_err();
        assert_eq!(e.code, exit::REFUSED);
        assert_eq!(e.to_string(), "thrusterd refused (Busy): estimating");
        let e = accepted(&ControlResponse::new(ResponseCode::Rejected, "")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "thrusterd refused (Rejected): no reason given"
        );
    }

    #[test]
    fn not_running_names_the_namespace() {
        assert_eq!(
            not_running("veh1", std::path::Path::new("/run/thrusterd/veh1")),
            "thrusterd is not running on namespace veh1 (no control server in \
             /run/thrusterd/veh1; a daemon elsewhere needs --namespace and --ipc-root)"
        );
    }
}
