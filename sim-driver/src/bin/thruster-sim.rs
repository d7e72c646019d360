//! `thruster-sim`: the simulated vehicle as a driver process. See `thruster-sim --help`,
//! config/thruster-sim.toml and the `thruster_sim::driver` docs.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::Parser;
use thruster_driver_kit::pipe::BadConfig;
use thruster_protocol::services::IpcConfig;
use thruster_sim::cli::{Cli, Command, RespondArgs, RunArgs};
use thruster_sim::driver::shutdown::Shutdown;
use thruster_sim::driver::Driver;
use thruster_sim::responder::{respond, ResponderOptions};
use thruster_sim::settings::Settings;

fn main() -> ExitCode {
    // Quiet exit on a closed stdout pipe, logging, one-line errors: shared by every driver.
    thruster_driver_kit::pipe::driver_main(|| run(Cli::parse()))
}

fn run(cli: Cli) -> anyhow::Result<()> {
    let stop = Shutdown::on_signals().context("cannot install the signal handlers")?;
    match cli.command {
        Command::Run(args) => run_sim(&args, stop),
        Command::Respond(args) => run_responder(&args, &stop),
    }
}

fn run_sim(args: &RunArgs, stop: Shutdown) -> anyhow::Result<()> {
    let settings = Settings::resolve(args).map_err(BadConfig::new)?;
    // Only the set-up's errors can be the configuration's: the run's (`driver.run`) are the
    // run's, a simulator that diverged included.
    let driver = Driver::new(settings, stop).map_err(|e| {
        if e.is_config() {
            anyhow::Error::new(BadConfig::new(e))
        } else {
            e.into()
        }
    })?;
    driver.run()?;
    Ok(())
}

fn run_responder(args: &RespondArgs, stop: &Shutdown) -> anyhow::Result<()> {
    let ipc = IpcConfig::new(&args.namespace)?;
    let idle_exit = match args.idle_exit {
        Some(s) if s.is_finite() && s > 0.0 => Some(Duration::from_secs_f64(s)),
        Some(s) => anyhow::bail!("--idle-exit must be > 0 s, got {s}"),
        None => None,
    };
    let opts = ResponderOptions {
        count: args.count,
        spin: Duration::from_micros(args.spin_us),
        idle_exit,
    };
    let report = respond(&ipc, &opts, stop)?;
    tracing::info!(
        answered = report.answered,
        skipped = report.skipped,
        speedup = ?report.speedup(),
        "responder stopped"
    );
    Ok(())
}
