//! What a local user outside group `thrusterd` can do to a running vehicle's namespace: run
//! by tests/systemd/run.sh as such a user (docs/reliability.md, "Access").
//!
//! 1. For every path listed in `--paths-from` (the namespace's files as root sees them:
//!    /dev/shm/thr_<ns>_* and everything under the ipc root), try to open it for reading and
//!    for writing (a socket: connect to it, which needs write permission).
//! 2. Join the namespace with iceoryx2 directly, as a hostile program would (no
//!    `check_access`, unlike thrusterctl), and publish a setpoint (pitch 45 degrees unless
//!    `--pitch-deg` says otherwise).
//!
//! Prints one JSON line: `{"paths":N,"readable":R,"writable":W,"published":bool,"error":..}`.
//! Exits 0 when it ran; the caller judges (0 readable, 0 writable, nothing published).

use std::fs::OpenOptions;
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Parser;
use thruster_protocol::services::{IpcConfig, Port};
use thruster_protocol::Setpoint;

#[derive(Parser)]
struct Args {
    /// The namespace to attack.
    #[arg(long)]
    namespace: String,
    /// Its ipc root base (e.g. /run/thrusterd).
    #[arg(long)]
    ipc_root: PathBuf,
    /// A file listing the namespace's paths, one per line.
    #[arg(long)]
    paths_from: PathBuf,
    /// The pitch of the setpoint it publishes, degrees (a group member's control run uses 0,
    /// so it does not move the vehicle).
    #[arg(long, default_value_t = 45.0)]
    pitch_deg: f64,
}

fn main() -> Result<()> {
    let args = Args::parse();
    let list = std::fs::read_to_string(&args.paths_from)
        .with_context(|| format!("reading {}", args.paths_from.display()))?;
    let paths: Vec<&Path> = list
        .lines()
        .filter(|l| !l.is_empty())
        .map(Path::new)
        .collect();
    let (mut readable, mut writable) = (0, 0);
    for p in &paths {
        let (r, w) = probe(p);
        if r {
            eprintln!("readable: {}", p.display());
            readable += 1;
        }
        if w {
            eprintln!("writable: {}", p.display());
            writable += 1;
        }
    }
    let (published, error) = match publish_setpoint(&args) {
        Ok(()) => (true, String::new()),
        Err(e) => (false, format!("{e:#}")),
    };
    println!(
        "{}",
        serde_json::json!({
            "paths": paths.len(),
            "readable": readable,
            "writable": writable,
            "published": published,
            "error": error,
        })
    );
    Ok(())
}

/// Whether `path` opens for reading and for writing. Directories: listing is reading,
/// creating an entry is writing (tried with a probe file, removed again).
fn probe(path: &Path) -> (bool, bool) {
    let Ok(meta) = std::fs::symlink_metadata(path) else {
        // Not even its attributes: neither.
        return (false, false);
    };
    if meta.is_dir() {
        let r = std::fs::read_dir(path).is_ok();
        let probe = path.join(".intruder-probe");
        let w = std::fs::File::create(&probe).is_ok();
        if w {
            let _ = std::fs::remove_file(&probe);
        }
        return (r, w);
    }
    use std::os::unix::fs::FileTypeExt;
    if meta.file_type().is_socket() {
        // A datagram socket is read by its owner only; sending to it needs write permission.
        let w = UnixDatagram::unbound()
            .and_then(|s| s.connect(path))
            .is_ok();
        return (false, w);
    }
    let r = OpenOptions::new().read(true).open(path).is_ok();
    let w = OpenOptions::new().write(true).open(path).is_ok();
    (r, w)
}

fn publish_setpoint(args: &Args) -> Result<()> {
    let ipc =
        IpcConfig::with_root_base(&args.namespace, &args.ipc_root)?.without_dead_node_cleanup();
    let node = ipc.create_node("intruder").context("creating a node")?;
    let port: Port<Setpoint> = Port::create(&node, &ipc).context("opening the setpoint topic")?;
    let half = args.pitch_deg.to_radians() / 2.0;
    let sp = Setpoint {
        seq: 1,
        attitude: [half.cos(), 0.0, half.sin(), 0.0],
        ..Setpoint::default()
    };
    port.send(&sp).context("publishing")?;
    Ok(())
}
