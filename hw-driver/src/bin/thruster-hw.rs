//! `thruster-hw`: the hardware driver process. See `thruster-hw --help`,
//! config/thruster-hw.toml and docs/hardware.md.

use std::process::ExitCode;

use anyhow::Context;
use clap::Parser;
use thruster_hw::cli::{Cli, Command};
use thruster_hw::config::Settings;
use thruster_hw::driver::{self, shutdown::Shutdown};

fn main() -> ExitCode {
    // A closed stdout pipe ends the process quietly (one helper for every binary).
    thruster_driver_kit::pipe::main(|| {
        // journald under systemd (JOURNAL_STREAM names our stderr), stderr otherwise.
        thruster_driver_kit::logging::init("info");
        let cli = Cli::parse();
        match run(cli) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                tracing::error!("{e:#}");
                ExitCode::FAILURE
            }
        }
    })
}

fn run(cli: Cli) -> anyhow::Result<()> {
    // Installed before anything touches hardware, so a signal during start-up still ends
    // in the orderly neutral path.
    let stop = Shutdown::on_signals().context("cannot install the signal handlers")?;
    match cli.command {
        Command::Run(args) => {
            let settings = Settings::resolve(&args)?;
            driver::run(&settings, &stop)
                .with_context(|| format!("thruster-hw ({} backend)", settings.backend.name()))?;
            Ok(())
        }
    }
}
