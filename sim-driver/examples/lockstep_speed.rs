//! Lockstep speed: vehicle seconds per wall second of `thruster-sim run --lockstep` over
//! iceoryx2, driven by the neutral responder (this process), the stand-in for the daemon.
//!
//! ```sh
//! cargo build --release -p thruster-sim --bin thruster-sim --example lockstep_speed
//! target/release/examples/lockstep_speed [--vehicle amour5] [--seconds 120] [--rate 200] \
//!     [--noise realistic] [--spin-us 200] [--runs 3]
//! ```
//!
//! The simulator binary is looked up beside the example's directory (`target/<profile>/`)
//! unless `THRUSTER_SIM_BIN` names it. The speed is measured on the responder's side, from
//! the first to the last answered sample (process start-up excluded); the simulator's own
//! summary line is printed too.

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;

use anyhow::{bail, Context};
use clap::Parser;
use thruster_protocol::services::NamespaceGuard;
use thruster_sim::driver::shutdown::Shutdown;
use thruster_sim::responder::{respond, ResponderOptions};

#[derive(Debug, Parser)]
struct Args {
    /// Vehicle file name in config/vehicles (without .toml).
    #[arg(long, default_value = "amour5")]
    vehicle: String,
    /// Vehicle time per run, s.
    #[arg(long, default_value_t = 120.0)]
    seconds: f64,
    /// IMU rate, Hz.
    #[arg(long, default_value_t = 200.0)]
    rate: f64,
    /// Noise preset.
    #[arg(long, default_value = "realistic")]
    noise: String,
    /// Responder busy-poll window, us.
    #[arg(long, default_value_t = 200)]
    spin_us: u64,
    /// Simulator busy-poll window (`[lockstep] spin_us`), us [default: the simulator's].
    #[arg(long)]
    sim_spin_us: Option<u64>,
    /// Number of runs.
    #[arg(long, default_value_t = 3)]
    runs: usize,
}

fn sim_binary() -> anyhow::Result<PathBuf> {
    if let Some(p) = std::env::var_os("THRUSTER_SIM_BIN") {
        return Ok(PathBuf::from(p));
    }
    let exe = std::env::current_exe()?;
    let profile_dir = exe
        .parent()
        .and_then(|examples| examples.parent())
        .context("cannot locate the target directory")?;
    let bin = profile_dir.join("thruster-sim");
    if !bin.exists() {
        bail!(
            "{} not found: build it (cargo build --release -p thruster-sim) or set THRUSTER_SIM_BIN",
            bin.display()
        );
    }
    Ok(bin)
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let bin = sim_binary()?;
    let vehicle = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../config/vehicles")
        .join(format!("{}.toml", args.vehicle));
    let mut speeds = Vec::new();
    for run in 1..=args.runs {
        let ns = NamespaceGuard::unique_for_test("spd")?;
        let log = tempfile::NamedTempFile::new()?;
        let config = tempfile::NamedTempFile::new()?;
        if let Some(us) = args.sim_spin_us {
            std::fs::write(config.path(), format!("[lockstep]\nspin_us = {us}\n"))?;
        }
        let mut sim = Command::new(&bin)
            .args(["run", "--lockstep", "--namespace", ns.namespace()])
            .arg("--config")
            .arg(config.path())
            .arg("--vehicle")
            .arg(&vehicle)
            .args(["--noise", &args.noise])
            .args(["--rate", &args.rate.to_string()])
            .args(["--duration", &args.seconds.to_string()])
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(log.reopen()?)
            .spawn()
            .with_context(|| format!("starting {}", bin.display()))?;
        let opts = ResponderOptions {
            count: None,
            spin: Duration::from_micros(args.spin_us),
            idle_exit: Some(Duration::from_millis(500)),
        };
        let report = respond(&ns, &opts, &Shutdown::new());
        let status = sim.wait()?;
        let report = report?;
        let text = std::fs::read_to_string(log.path())?;
        if !status.success() {
            bail!("thruster-sim failed ({status}):\n{text}");
        }
        let speed = report.speedup().context("too few samples answered")?;
        println!(
            "run {run}: {} samples answered, {:.1} s vehicle time, speed-up {speed:.0}x real time",
            report.answered, args.seconds
        );
        if let Some(line) = text.lines().find(|l| l.contains("thruster-sim stopped")) {
            println!("  sim: {}", line.trim());
        }
        speeds.push(speed);
    }
    speeds.sort_by(f64::total_cmp);
    let median = speeds[speeds.len() / 2];
    let per_sample_us = 1e6 / (median * args.rate);
    println!(
        "median speed-up: {median:.0}x real time at {} Hz ({per_sample_us:.1} us wall per sample \
         round trip incl. physics); target >= 200x",
        args.rate
    );
    Ok(())
}
