//! thrusterctl: the operator's tool for thrusterd.
//!
//! It talks to the daemon only through `thruster_protocol` (control requests, published
//! status and model, reconfiguration events and setpoints). Exit codes are in [`exit`].

mod attitude;
mod chart;
mod checks;
mod cli;
mod client;
mod commands;
mod demo;
mod estimate;
mod exit;
mod experiment;
mod geometry;
mod json;
mod publish;
mod render;
mod scoring;
mod session;
mod watch;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // `thrusterctl demo | head -1`: a print to the closed pipe ends the process quietly,
    // after unwinding has stopped the demo's children and purged its namespace.
    thruster_driver_kit::pipe::main(|| {
        init_logging();
        let cli = cli::Cli::parse();
        // `run` returns instead of exiting so every iceoryx2 port and node is dropped
        // normally: a process::exit would leave the namespace's files behind.
        match commands::run(cli) {
            Ok(()) => ExitCode::SUCCESS,
            // `thrusterctl watch | head`: the reader is gone, nothing more to say.
            Err(e) if thruster_driver_kit::pipe::is_broken_pipe(e.as_ref()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("thrusterctl: {e:#}");
                ExitCode::from(exit::code_of(&e))
            }
        }
    })
}

/// iceoryx2 logs through `tracing`; show it only when asked (RUST_LOG), since operators
/// read our own messages on stderr.
fn init_logging() {
    if std::env::var_os("RUST_LOG").is_some() {
        tracing_subscriber::fmt()
            .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
            .with_writer(std::io::stderr)
            .init();
    }
}
