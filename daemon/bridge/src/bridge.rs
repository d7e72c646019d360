//! Starting and stopping the bridge's parts around the recorder's drain: the Foxglove
//! context and WebSocket server, the live-view thread, the operator thread behind the
//! services, and the MCAP writer (inside the drain).

use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{anyhow, Context as _, Result};
use foxglove::{Context, WebSocketServer, WebSocketServerHandle};
use thruster_protocol::services::{check_access, owns_root, IpcConfig, TidyOnDrop};
use thruster_recorder::{tap, RecordOptions, RecordSummary};
use thrusterctl_operator::client::{Daemon, Target};

use crate::config::Websocket;
use crate::{live, services, BridgeError};

/// What to run.
#[derive(Debug, Clone)]
pub struct Plan {
    pub target: Target,
    pub websocket: Option<Websocket>,
    pub record: Option<RecordOptions>,
}

/// What ran: the recorder's summary (with the live view's drops among its taps) and how many
/// messages the live view logged.
#[derive(Debug)]
pub struct Outcome {
    pub summary: RecordSummary,
    pub live_logged: u64,
}

/// The WebSocket side while it runs.
struct Live {
    server: WebSocketServerHandle,
    forwarder: JoinHandle<Result<u64, BridgeError>>,
    operator: Option<JoinHandle<()>>,
}

/// Runs `plan` until `stop` (or the recording's duration). `ready` gets the WebSocket
/// server's bound address (None without one) once every topic is subscribed.
pub fn run(
    plan: &Plan,
    stop: &Arc<AtomicBool>,
    ready: &mut dyn FnMut(Option<SocketAddr>),
) -> Result<Outcome> {
    if plan.websocket.is_none() && plan.record.is_none() {
        return Err(anyhow!(
            "nothing to do: give --ws ADDRESS:PORT and/or --record FILE.mcap \
             (or [websocket] listen / [record] out in the config file)"
        ));
    }
    let ns = &plan.target.namespace;
    let ipc = IpcConfig::with_root_base(ns, &plan.target.root_base)
        .with_context(|| format!("namespace {ns}"))?;
    check_access(&ipc)?;
    let ipc = if owns_root(&ipc) {
        ipc
    } else {
        ipc.without_dead_node_cleanup()
    };
    // Declared before the nodes, so it drops after them: the last process to leave the
    // namespace removes iceoryx2's residue.
    let _tidy = TidyOnDrop::new(&ipc);

    let mut taps = Vec::new();
    let mut live = None;
    let mut addr = None;
    if let Some(ws) = &plan.websocket {
        let (tap, rx) = tap::bounded("websocket", ws.queue);
        taps.push(tap);
        let started = start_live(ws, &plan.target, rx, stop)?;
        addr = Some(SocketAddr::new(ws.listen.ip(), started.server.port()));
        live = Some(started);
    }
    let node = ipc
        .create_node("bridge")
        .with_context(|| format!("joining namespace {ns}"))?;
    let drained =
        thruster_recorder::stream_on(&node, &ipc, plan.record.as_ref(), taps, stop, &mut || {
            ready(addr)
        });
    // The drain is over (a signal, or the recording's duration): stop the operator thread
    // too. The drain has dropped its taps, so the live thread ends once its queue is empty.
    stop.store(true, Ordering::SeqCst);
    let live_logged = match live {
        Some(l) => l.stop()?,
        None => 0,
    };
    drop(node);
    if let Some(partial) = drained.as_ref().err().and_then(|e| e.summary()) {
        // What reached the files before the error, on stdout as a finished recording's summary
        // is: the error (a full disk) follows on stderr.
        println!("{}", partial.line());
    }
    let summary = drained.with_context(|| format!("streaming namespace {ns}"))?;
    Ok(Outcome {
        summary,
        live_logged,
    })
}

/// Starts the live-view thread, the operator thread (when services are on) and the server.
fn start_live(
    ws: &Websocket,
    target: &Target,
    rx: mpsc::Receiver<thruster_recorder::Message>,
    stop: &Arc<AtomicBool>,
) -> Result<Live> {
    // A context of its own: its one sink is this server (nothing logs to the SDK's global
    // default context).
    let context = Context::new();
    let latest = live::Latest::default();
    let mut server = WebSocketServer::new()
        .name(format!("thrusterd {}", target.namespace))
        .bind(ws.listen.ip().to_string(), ws.listen.port())
        .context(&context)
        .message_backlog_size(ws.backlog)
        .supported_encodings(["json"])
        .listener(Arc::new(latest.clone()));
    let mut operator = None;
    if ws.services {
        let (queue, calls) = services::queue();
        server = server.services(services::services(&queue));
        operator = Some(start_operator(
            target,
            Duration::from_millis(ws.control_timeout_ms),
            calls,
            stop,
        )?);
    }
    let forwarder = {
        let context = Arc::clone(&context);
        std::thread::Builder::new()
            .name("live-view".into())
            .spawn(move || live::forward(&context, &rx, &latest))
            .context("starting the live-view thread")?
    };
    let server = server
        .start_blocking()
        .map_err(|source| BridgeError::Server {
            addr: ws.listen,
            source,
        })?;
    Ok(Live {
        server,
        forwarder,
        operator,
    })
}

/// The operator thread: connects to the daemon's namespace first (an access problem fails
/// the start, not the first call), then serves the queued calls until `stop`.
fn start_operator(
    target: &Target,
    timeout: Duration,
    calls: mpsc::Receiver<(services::Call, foxglove::websocket::service::Responder)>,
    stop: &Arc<AtomicBool>,
) -> Result<JoinHandle<()>> {
    let (connected_tx, connected) = mpsc::sync_channel(1);
    let target = target.clone();
    let stop = Arc::clone(stop);
    let thread = std::thread::Builder::new()
        .name("operator".into())
        .spawn(move || match Daemon::connect(&target, timeout) {
            Ok(daemon) => {
                let _ = connected_tx.send(Ok(()));
                services::serve(&daemon, &calls, &stop);
            }
            Err(e) => {
                let _ = connected_tx.send(Err(format!("{e:#}")));
            }
        })
        .context("starting the operator thread")?;
    match connected.recv() {
        Ok(Ok(())) => Ok(thread),
        Ok(Err(e)) => {
            let _ = thread.join();
            Err(anyhow!("the services' connection to the daemon: {e}"))
        }
        Err(_) => Err(anyhow!("the operator thread ended before connecting")),
    }
}

impl Live {
    /// Stops the server and waits for both threads; returns what the live view logged.
    fn stop(self) -> Result<u64> {
        self.server.stop().wait_blocking();
        if let Some(op) = self.operator {
            op.join()
                .map_err(|_| anyhow!("the operator thread panicked"))?;
        }
        let logged = self
            .forwarder
            .join()
            .map_err(|_| anyhow!("the live-view thread panicked"))??;
        Ok(logged)
    }
}
