//! `thruster-bridge`: the live view over the tether (Foxglove WebSocket server with the
//! operator's requests as services) and/or the MCAP recording, as one process beside the
//! daemon. Settings from `--config FILE` (config/thruster-bridge.toml documents every key),
//! flags override them. Ends on SIGINT/SIGTERM (or `--duration-s`), printing the summary.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{anyhow, Context, Result};
use clap::Parser;
use thruster_bridge::bridge::{self, Plan};
use thruster_bridge::config::{self, BridgeConfig, Record, Websocket};
use thruster_driver_kit::pipe::BadConfig;
use thruster_driver_kit::systemd::Systemd;
use thruster_recorder::RecordOptions;
use thrusterctl_operator::client::Target;

#[derive(Debug, Parser)]
#[command(
    name = "thruster-bridge",
    about = "Live view over the tether: every topic on a Foxglove WebSocket server, the \
             operator's requests as its services, and optionally the MCAP recording"
)]
struct Args {
    /// Settings file (config/thruster-bridge.toml documents every key). Flags override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// IPC namespace of the daemon.
    #[arg(long)]
    namespace: Option<String>,
    /// Base directory of iceoryx2's files (default /tmp/iceoryx2/thr; /run/thrusterd under
    /// systemd).
    #[arg(long)]
    ipc_root: Option<PathBuf>,
    /// Serve the live view on ADDRESS:PORT (port 0: any free port, printed at start). Off
    /// unless given here or in the config.
    #[arg(long, value_name = "ADDRESS:PORT")]
    ws: Option<SocketAddr>,
    /// Do not offer the operator's requests as services (a view only).
    #[arg(long)]
    no_services: bool,
    /// Record every topic to this MCAP file too (as `thrusterctl record --out`).
    #[arg(long, value_name = "FILE.mcap")]
    record: Option<PathBuf>,
    /// With --record: rotate to FILE-0001.mcap, ... at this size, MiB.
    #[arg(long)]
    max_mb: Option<f64>,
    /// Stop after this many seconds (wall clock).
    #[arg(long)]
    duration_s: Option<f64>,
    /// Print every channel's and service's JSON Schema (what the live view and the recordings
    /// declare) as one JSON object, and exit. The CI check feeds them to the Foxglove app's
    /// parser (tests/node/check_schemas.js).
    #[arg(long)]
    print_schemas: bool,
    /// Print the Foxglove layout for this vehicle file (config/vehicles/*.toml): the shipped
    /// config/foxglove/thrusterd-live.json with the thrust plot showing exactly the vehicle's
    /// thrusters, named as in the file; then exit.
    #[arg(long, value_name = "VEHICLE.toml")]
    layout_for: Option<PathBuf>,
}

/// The settings: the file's, then the flags over them.
fn settings(args: &Args) -> Result<BridgeConfig> {
    let mut c = match &args.config {
        Some(path) => config::load(path)?,
        None => BridgeConfig::default(),
    };
    if let Some(ns) = &args.namespace {
        c.namespace = Some(ns.clone());
    }
    if let Some(root) = &args.ipc_root {
        c.ipc_root = root.clone();
    }
    if let Some(addr) = args.ws {
        match &mut c.websocket {
            Some(w) => w.listen = addr,
            None => c.websocket = Some(Websocket::on(addr)),
        }
    }
    if args.no_services {
        if let Some(w) = &mut c.websocket {
            w.services = false;
        }
    }
    if let Some(out) = &args.record {
        match &mut c.record {
            Some(r) => r.out = out.clone(),
            None => c.record = Some(Record::to(out.clone())),
        }
    }
    if let Some(mb) = args.max_mb {
        let r = c
            .record
            .as_mut()
            .ok_or_else(|| anyhow!("--max-mb needs --record (or [record] out)"))?;
        if !(mb.is_finite() && mb > 0.0 && mb <= 1024.0 * 1024.0) {
            return Err(anyhow!("--max-mb must be in (0, 1048576], got {mb}"));
        }
        r.max_mb = Some(mb);
    }
    Ok(c)
}

fn plan(args: &Args, c: BridgeConfig) -> Result<Plan> {
    let namespace = c.namespace.ok_or_else(|| {
        anyhow!("no namespace: give --namespace or namespace = \"...\" in the config")
    })?;
    let duration = match args.duration_s {
        None => None,
        Some(s) if s.is_finite() && s > 0.0 => Some(Duration::from_secs_f64(s)),
        Some(s) => return Err(anyhow!("--duration-s must be above 0, got {s}")),
    };
    if duration.is_some() && c.record.is_none() && c.websocket.is_none() {
        return Err(anyhow!("--duration-s needs --ws or --record"));
    }
    let record = c.record.map(|r| RecordOptions {
        out: r.out,
        max_bytes: r.max_mb.map(|mb| (mb * 1024.0 * 1024.0) as u64),
        duration,
        queue: r.queue,
        compression: r.compression,
    });
    Ok(Plan {
        target: Target {
            namespace,
            root_base: c.ipc_root,
        },
        websocket: c.websocket,
        record,
    })
}

fn run() -> Result<()> {
    let args = Args::parse();
    if args.print_schemas {
        println!("{}", thruster_bridge::services::every_schema()?);
        return Ok(());
    }
    if let Some(vehicle) = &args.layout_for {
        let names = thrusterctl_operator::geometry::load_names(vehicle)?;
        let stem = vehicle
            .file_stem()
            .map_or_else(|| "vehicle".into(), |s| s.to_string_lossy().into_owned());
        let layout = thruster_bridge::layout::for_vehicle(&stem, &names)?;
        println!("{}", serde_json::to_string_pretty(&layout)?);
        return Ok(());
    }
    let c = settings(&args).map_err(BadConfig::new)?;
    let plan = plan(&args, c)?;
    // A live view without a recording still honours --duration-s: the session needs a
    // deadline, which lives in the recording options, so stop it from a timer instead.
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || stop.store(true, std::sync::atomic::Ordering::SeqCst))
            .context("installing the signal handler")?;
    }
    if plan.record.is_none() {
        if let Some(s) = args.duration_s {
            let stop = Arc::clone(&stop);
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_secs_f64(s));
                stop.store(true, std::sync::atomic::Ordering::SeqCst);
            });
        }
    }
    let mut systemd = Systemd::new();
    let ns = plan.target.namespace.clone();
    if let Some(r) = &plan.record {
        if r.out.as_os_str().is_empty() || r.out.is_dir() {
            return Err(anyhow!("the recording must name a file, got {:?}", r.out));
        }
    }
    let outcome = bridge::run(&plan, &stop, &mut |addr| {
        match addr {
            // The one line a script (or the system test) reads for the port.
            Some(a) => tracing::info!("live view on ws://{a} (namespace {ns})"),
            None => tracing::info!("recording namespace {ns}"),
        }
        systemd.ready();
    })?;
    systemd.stopping();
    let line = outcome.summary.line();
    tracing::info!("{line}; live view logged {}", outcome.live_logged);
    println!("{line}");
    Ok(())
}

fn main() -> ExitCode {
    thruster_driver_kit::pipe::driver_main(run)
}
