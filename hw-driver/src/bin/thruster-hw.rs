//! `thruster-hw`: the hardware driver process. See `thruster-hw --help`,
//! config/thruster-hw.toml and docs/hardware.md.

use std::process::ExitCode;

use anyhow::Context;
use clap::Parser;
use thruster_driver_kit::pipe::BadConfig;
use thruster_hw::cli::{Cli, Command};
use thruster_hw::config::{Overrides, Settings};
use thruster_hw::driver::{self, shutdown::Shutdown};

fn main() -> ExitCode {
    // Quiet exit on a closed stdout pipe, logging, one-line errors: shared by every driver.
    thruster_driver_kit::pipe::driver_main(|| run(Cli::parse()))
}

fn run(cli: Cli) -> anyhow::Result<()> {
    // Installed before anything touches hardware, so a signal during start-up still ends
    // in the orderly neutral path.
    let stop = Shutdown::on_signals().context("cannot install the signal handlers")?;
    match cli.command {
        Command::Run(args) => {
            let settings = Settings::resolve(&Overrides::from(&args)).map_err(BadConfig::new)?;
            driver::run(&settings, &stop)
                .with_context(|| format!("thruster-hw ({} backend)", settings.backend.name()))?;
            Ok(())
        }
        Command::Neutral(args) => {
            let settings = Settings::resolve(&Overrides::from(&args)).map_err(BadConfig::new)?;
            let lines = driver::after_exit::neutral_after_exit(&settings)
                .with_context(|| format!("thruster-hw neutral ({})", args.config.display()))?;
            for line in lines {
                tracing::info!("{line}");
            }
            Ok(())
        }
    }
}
