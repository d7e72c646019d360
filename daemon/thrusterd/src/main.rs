//! thrusterd: the thruster-configuration daemon (`run`) and the replay of a recorded session
//! (`replay`). The offline studies live in the lab (`thrusterctl study`).

mod checkpoints;
mod config_file;
mod imu_wakeups;
mod journal;
mod loader;
mod reaper;
mod replay;
mod resume_marker;
mod run;
mod saver;
mod side_inputs;
mod solver;
mod store;

use std::path::PathBuf;
use std::process::ExitCode;

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
    /// Run a recording (MCAP) through the state machine and estimator offline and print the
    /// model: the daemon's, with the recording's configuration; another's with --config.
    Replay(replay::ReplayArgs),
}

/// Exit code of a configuration that cannot be used (file or command line): a script tells
/// "fix the config" from "the daemon failed", and the unit does not restart it. The drivers'.
const EXIT_CONFIG: u8 = thruster_driver_kit::pipe::EXIT_CONFIG;

fn main() -> ExitCode {
    // A closed stdout pipe (`thrusterd check-config FILE | head -1`) ends quietly.
    thruster_driver_kit::pipe::main(|| match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if thruster_driver_kit::pipe::is_broken_pipe(e.as_ref()) => ExitCode::SUCCESS,
        // `{:#}`: the message and its causes on one line, no "Caused by" list or backtrace
        // (what anyhow's Debug form, the default for `main -> Result`, prints).
        Err(e) => {
            eprintln!("thrusterd: {e:#}");
            // Under systemd, also the unit's status text: `systemctl status` shows why.
            thruster_driver_kit::systemd::report_failure(&format!("{e:#}"));
            let config = e
                .chain()
                .any(|c| c.is::<thrusterd_core::config::ConfigError>());
            ExitCode::from(if config { EXIT_CONFIG } else { 1 })
        }
    })
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Run(args) => run::run(args),
        Command::CheckConfig { file } => {
            let origin = file.display().to_string();
            let text = thruster_driver_kit::read_text(&file)?;
            let cfg = thrusterd_core::config::DaemonConfig::from_toml_str(&text, &origin)?;
            // Everything `run` would refuse about this file, not only its values.
            cfg.check_runnable(&text, &origin)?;
            println!("{}: ok", file.display());
            println!("{}", toml::to_string_pretty(&cfg)?);
            Ok(())
        }
        Command::Replay(args) => replay::run(args),
    }
}
