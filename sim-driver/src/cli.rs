//! Command line of the `thruster-sim` process (clap types only; merging with the config file
//! is in [`crate::settings`]).
//!
//! ```text
//! thruster-sim run --namespace NS --vehicle FILE [--config FILE] [--noise paper|realistic|none]
//!                  [--rate HZ] [--seed S] [--scenario FILE] [--lockstep | --realtime]
//!                  [--duration SECONDS] [--truth-file PATH] [--stats-file PATH]
//! thruster-sim respond --namespace NS [--neutral] [--count N] [--spin-us US] [--idle-exit S]
//! ```
//!
//! Every `run` option is optional on the command line because it may come from `--config`;
//! a value given here overrides the file.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

use crate::sensors::NoisePreset;

/// `thruster-sim`: a 6-DOF underwater vehicle simulator that speaks the thrusterd driver
/// protocol over iceoryx2.
#[derive(Debug, Parser)]
#[command(name = "thruster-sim", version, about, long_about = None)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Simulate a vehicle: publish IMU samples, apply thrust commands, play a scenario.
    Run(RunArgs),
    /// Answer every IMU sample with a neutral thrust command (a stand-in daemon for tests and
    /// speed measurements).
    #[command(hide = true)]
    Respond(RespondArgs),
}

/// Options of `thruster-sim run`; each overrides the same key of `--config`.
#[derive(Debug, Clone, Default, Args)]
pub struct RunArgs {
    /// Config file (TOML, see config/thruster-sim.toml). Relative paths inside it are relative
    /// to the file's directory.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// IPC namespace shared with the daemon (1-16 ASCII letters, digits or '-').
    #[arg(long, value_name = "NS")]
    pub namespace: Option<String>,
    /// Base folder of iceoryx2's files, the same for every process of the namespace (the
    /// daemon's `[ipc] root`) [file default: /tmp/iceoryx2/thr].
    #[arg(long, value_name = "DIR")]
    pub ipc_root: Option<PathBuf>,
    /// Vehicle file (config/vehicles/*.toml).
    #[arg(long, value_name = "FILE")]
    pub vehicle: Option<PathBuf>,
    /// Sensor noise preset [file default: realistic].
    #[arg(long, value_name = "PRESET", value_parser = parse_noise)]
    pub noise: Option<NoisePreset>,
    /// IMU sample rate, Hz, 100..=1000 [file default: 200].
    #[arg(long, value_name = "HZ")]
    pub rate: Option<f64>,
    /// Seed of the sensor noise [file default: 1].
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,
    /// Scenario file (config/scenarios/*.toml): scripted reconfigurations.
    #[arg(long, value_name = "FILE")]
    pub scenario: Option<PathBuf>,
    /// Lockstep: wait for the command answering each sample before stepping (as fast as the
    /// daemon answers).
    #[arg(long, conflicts_with = "realtime")]
    pub lockstep: bool,
    /// Real time: one sample per period of the wall clock (the default).
    #[arg(long)]
    pub realtime: bool,
    /// Lockstep, but no faster than this many times real time (e.g. 50), so an observer
    /// polling the vehicle state sees vehicle time advance evenly [default: as fast as the
    /// daemon answers].
    #[arg(long, value_name = "X", requires = "lockstep")]
    pub pace: Option<f64>,
    /// Lockstep, advancing only as far as standard input allows (`run N` lines; the
    /// simulator answers `at SEQ T_NS` on standard output when it has used them up): the
    /// process that started it acts at exact vehicle times (thrusterctl demo, experiment).
    /// Each answer is then awaited up to 600 s of wall time (`[lockstep] timeout_ms` raised
    /// to it): going on without it would make the run depend on the machine's speed.
    #[arg(long, requires = "lockstep")]
    pub stepped: bool,
    /// Stop after this much vehicle time, s [default: run until SIGINT/SIGTERM].
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
    /// Write the true effectiveness (at start and after every change) to this JSON file.
    #[arg(long, value_name = "PATH")]
    pub truth_file: Option<PathBuf>,
    /// Real time only: append link statistics (samples published / answered / unanswered,
    /// sample -> thrust latency histogram) to this file once per second, one JSON line each
    /// (`thruster_sim::link_stats::StatsLine`). Used by the soak run.
    #[arg(long, value_name = "PATH")]
    pub stats_file: Option<PathBuf>,
}

/// Options of `thruster-sim respond`.
#[derive(Debug, Clone, Args)]
pub struct RespondArgs {
    /// IPC namespace of the simulator.
    #[arg(long, value_name = "NS")]
    pub namespace: String,
    /// Answer with neutral (all zero) thrust; the only behaviour so far, accepted for
    /// clarity in scripts.
    #[arg(long)]
    pub neutral: bool,
    /// Thruster count to command [default: the count of the simulator's truth message, which
    /// follows reconfigurations].
    #[arg(long, value_name = "N")]
    pub count: Option<u32>,
    /// Busy-poll this long for the next sample before blocking, microseconds (blocking costs a
    /// wake-up of tens of microseconds per sample).
    #[arg(long, value_name = "US", default_value_t = 200)]
    pub spin_us: u64,
    /// Exit when no sample arrived for this long after the first one, s [default: never].
    #[arg(long, value_name = "S")]
    pub idle_exit: Option<f64>,
}

/// Parses a noise preset name.
pub fn parse_noise(s: &str) -> Result<NoisePreset, String> {
    match s {
        "none" => Ok(NoisePreset::None),
        "realistic" => Ok(NoisePreset::Realistic),
        "paper" => Ok(NoisePreset::Paper),
        _ => Err(format!(
            "unknown noise preset {s:?}, expected paper, realistic or none"
        )),
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
            "thruster-sim",
            "run",
            "--namespace",
            "veh1",
            "--vehicle",
            "v.toml",
            "--noise",
            "paper",
            "--rate",
            "400",
            "--lockstep",
            "--duration",
            "12.5",
        ])
        .unwrap();
        let Command::Run(args) = cli.command else {
            panic!("not run")
        };
        assert_eq!(args.namespace.as_deref(), Some("veh1"));
        assert_eq!(args.noise, Some(NoisePreset::Paper));
        assert_eq!(args.rate, Some(400.0));
        assert!(args.lockstep && !args.realtime);
        assert_eq!(args.duration, Some(12.5));
    }

    #[test]
    fn lockstep_and_realtime_conflict_and_bad_noise_fails() {
        assert!(Cli::try_parse_from(["thruster-sim", "run", "--lockstep", "--realtime"]).is_err());
        let err = Cli::try_parse_from(["thruster-sim", "run", "--noise", "loud"]).unwrap_err();
        assert!(err.to_string().contains("loud"), "{err}");
    }
}
