//! Command line of the `thruster-hw` process (clap types only; merging with the config file
//! is in [`crate::config`]).
//!
//! ```text
//! thruster-hw run --config FILE [--namespace NS] [--backend mavlink|linux]
//! thruster-hw neutral --config FILE [--backend mavlink|linux]
//! ```

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

use crate::config::{BackendKind, Overrides};

/// `thruster-hw`: drives a vehicle's thrusters and reads its IMU for thrusterd, over
/// iceoryx2 (ArduSub over MAVLink, or Linux sysfs PWM and IIO).
#[derive(Debug, Parser)]
#[command(name = "thruster-hw", version, about, long_about = None)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Publish IMU samples and apply thrust commands until SIGINT/SIGTERM.
    Run(RunArgs),
    /// Leave the outputs neutral after the driver process is gone, however it ended
    /// (systemd's ExecStopPost): every exported PWM channel of the config gets its neutral
    /// pulse. Touches no IPC; exits non-zero if an output could not be written.
    Neutral(NeutralArgs),
}

/// Options of `thruster-hw neutral`.
#[derive(Debug, Clone, Args)]
pub struct NeutralArgs {
    /// The config file the driver ran with.
    #[arg(long, value_name = "FILE")]
    pub config: PathBuf,
    /// Hardware backend (as given to `run`).
    #[arg(long, value_name = "BACKEND", value_parser = parse_backend)]
    pub backend: Option<BackendKind>,
}

impl From<&NeutralArgs> for Overrides {
    fn from(args: &NeutralArgs) -> Overrides {
        Overrides {
            config: args.config.clone(),
            // No IPC here: any valid name satisfies the settings' check, so a config that
            // leaves the namespace to `run --namespace` still works.
            namespace: Some("neutral".to_string()),
            backend: args.backend,
        }
    }
}

/// Options of `thruster-hw run`; each overrides the same key of `--config`.
#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// Config file (TOML, see config/thruster-hw.toml): thrusters, backend settings.
    #[arg(long, value_name = "FILE")]
    pub config: PathBuf,
    /// IPC namespace shared with the daemon (1-16 ASCII letters, digits or '-').
    #[arg(long, value_name = "NS")]
    pub namespace: Option<String>,
    /// Hardware backend.
    #[arg(long, value_name = "BACKEND", value_parser = parse_backend)]
    pub backend: Option<BackendKind>,
}

impl From<&RunArgs> for Overrides {
    fn from(args: &RunArgs) -> Overrides {
        Overrides {
            config: args.config.clone(),
            namespace: args.namespace.clone(),
            backend: args.backend,
        }
    }
}

/// Parses a backend name.
pub fn parse_backend(s: &str) -> Result<BackendKind, String> {
    match s {
        "mavlink" => Ok(BackendKind::Mavlink),
        "linux" => Ok(BackendKind::Linux),
        _ => Err(format!("unknown backend {s:?}, expected mavlink or linux")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn cli_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn run_options_parse() {
        let cli = Cli::try_parse_from([
            "thruster-hw",
            "run",
            "--config",
            "hw.toml",
            "--namespace",
            "veh1",
            "--backend",
            "linux",
        ])
        .unwrap();
        let Command::Run(a) = cli.command else {
            panic!("not run")
        };
        assert_eq!(a.config, PathBuf::from("hw.toml"));
        assert_eq!(a.namespace.as_deref(), Some("veh1"));
        assert_eq!(a.backend, Some(BackendKind::Linux));
        let e = Cli::try_parse_from(["thruster-hw", "run", "--config", "x", "--backend", "pca"])
            .unwrap_err();
        assert!(e.to_string().contains("pca"), "{e}");
        assert!(Cli::try_parse_from(["thruster-hw", "run"]).is_err());
        let cli = Cli::try_parse_from(["thruster-hw", "neutral", "--config", "hw.toml"]).unwrap();
        let Command::Neutral(a) = cli.command else {
            panic!("not neutral")
        };
        assert_eq!(Overrides::from(&a).config, PathBuf::from("hw.toml"));
        assert!(Cli::try_parse_from(["thruster-hw", "neutral"]).is_err());
    }
}
