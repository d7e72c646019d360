//! thrusterd: the thruster-configuration daemon (`run`), and its offline studies (`study`).

mod run;
mod session;
mod study;

use std::path::PathBuf;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "thrusterd",
    version,
    about = "Learns an underwater robot's thruster configuration and controls it"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the daemon: serve drivers and operators over iceoryx2 until SIGINT/SIGTERM.
    Run(run::RunArgs),
    /// Check a configuration file and print the effective settings.
    CheckConfig {
        /// The file (e.g. config/thrusterd.toml).
        file: PathBuf,
    },
    /// Offline studies of the estimator (no vehicle, no IPC).
    Study {
        #[command(subcommand)]
        study: study::Study,
    },
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Run(args) => run::run(args),
        Command::CheckConfig { file } => {
            let cfg = thrusterd::config::DaemonConfig::load(&file)?;
            println!("{}: ok", file.display());
            println!("{}", toml::to_string_pretty(&cfg)?);
            Ok(())
        }
        Command::Study { study } => study::run(study),
    }
}
