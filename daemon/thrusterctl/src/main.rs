//! thrusterctl: the operator's tool for thrusterd.
//!
//! The operator's verbs live in `thrusterctl_operator` (they talk to the daemon only through
//! `thruster_protocol`); `demo` and `experiment` come from the simulation lab
//! (`thruster_lab`, cargo feature `lab`, on by default). This file is the top-level command
//! line and the dispatch between the two. Exit codes are in `thrusterctl_operator::exit`.

use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};

use thrusterctl_operator::cli::{self, Globals};
use thrusterctl_operator::{commands, exit};

#[derive(Parser, Debug)]
#[command(
    name = "thrusterctl",
    version,
    about = "Operator tool for thrusterd: estimate the thruster model, watch, inspect, steer"
)]
struct Cli {
    #[command(flatten)]
    globals: Globals,

    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// The simulated demo: start thrusterd and thruster-sim on a private namespace, learn the
    /// vehicle's thrusters, hold attitude, report, shut everything down.
    #[cfg(feature = "lab")]
    Demo(thruster_lab::demo::DemoArgs),
    /// The paper's pool experiments in simulation (manual-vs-learned, misaligned, aligned,
    /// hot-swap) and ours (degrade, dive): daemon and simulator on a private namespace,
    /// scored against the truth.
    #[cfg(feature = "lab")]
    Experiment(thruster_lab::experiment::ExperimentArgs),
    /// Research in one process (no daemon): by default the estimation methods against the
    /// simulator's truth, every vehicle x noise x method x seed (runs.csv, trace.csv and
    /// error-vs-time figures); `fig2`, `pulse-power` and the research `sweep`s as subcommands.
    #[cfg(feature = "lab")]
    Study(thruster_lab::study::StudyArgs),
    /// Not in this build: thrusterctl was built without the simulation lab (feature `lab`).
    #[cfg(not(feature = "lab"))]
    #[command(disable_help_flag = true)]
    Demo {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        args: Vec<std::ffi::OsString>,
    },
    /// Not in this build: thrusterctl was built without the simulation lab (feature `lab`).
    #[cfg(not(feature = "lab"))]
    #[command(disable_help_flag = true)]
    Experiment {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        args: Vec<std::ffi::OsString>,
    },
    /// Not in this build: thrusterctl was built without the simulation lab (feature `lab`).
    #[cfg(not(feature = "lab"))]
    #[command(disable_help_flag = true)]
    Study {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        args: Vec<std::ffi::OsString>,
    },
    #[command(flatten)]
    Operator(cli::Command),
}

fn main() -> ExitCode {
    // `thrusterctl demo | head -1`: a print to the closed pipe ends the process quietly,
    // after unwinding has stopped the demo's children and purged its namespace.
    thruster_driver_kit::pipe::main(|| {
        init_logging();
        let cli = parse_cli();
        // `run` returns instead of exiting so every iceoryx2 port and node is dropped
        // normally: a process::exit would leave the namespace's files behind.
        match run(cli) {
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

/// The lab's verbs run their own daemon: the operator's options for reaching one are refused
/// there (see `run`), so their help does not list them (issue 27: `demo --help` did).
#[cfg(feature = "lab")]
const LAB_VERBS: [&str; 3] = ["demo", "experiment", "study"];
#[cfg(not(feature = "lab"))]
const LAB_VERBS: [&str; 0] = [];

fn command() -> clap::Command {
    use clap::CommandFactory;
    let mut cmd = Cli::command();
    // Global options reach the subcommands when the command is built, so hide them after,
    // in place: the built parser refers to arguments and subcommands by position
    // (`mut_arg`/`mut_subcommand` move them to the end, and `demo --namespace` then parsed
    // as `--help`).
    cmd.build();
    cmd.mut_subcommands(|sub| {
        if !LAB_VERBS.contains(&sub.get_name()) {
            return sub;
        }
        hide_refused(sub)
    })
}

/// The operator's options hidden on a lab verb and its own subcommands (`study fig2`,
/// `study sweep`), which refuse them alike.
fn hide_refused(cmd: clap::Command) -> clap::Command {
    cmd.mut_args(|a| {
        let refused = ["namespace", "ipc_root", "timeout_ms"].contains(&a.get_id().as_str());
        if refused {
            a.hide(true)
        } else {
            a
        }
    })
    .mut_subcommands(hide_refused)
}

fn parse_cli() -> Cli {
    use clap::FromArgMatches;
    let matches = command().get_matches();
    Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit())
}

fn run(cli: Cli) -> Result<()> {
    let (target, timeout) = commands::target(cli.globals)?;
    let lab_verb = !matches!(cli.command, Command::Operator(_));
    // The demo and the experiments run their own daemon on a private namespace: a
    // --namespace or --ipc-root given to them would be silently ignored, so refuse it.
    if lab_verb
        && (target.namespace != cli::DEFAULT_NAMESPACE
            || target.root_base.as_path()
                != std::path::Path::new(thruster_protocol::services::DEFAULT_ROOT_BASE))
    {
        return Err(exit::Failure::usage(
            "demo and experiment start their own thrusterd and thruster-sim on a private \
             namespace under the default ipc root, study runs none; --namespace and \
             --ipc-root are for talking to a running daemon",
        )
        .into());
    }
    match cli.command {
        #[cfg(feature = "lab")]
        Command::Demo(args) => thruster_lab::demo::run(args),
        #[cfg(feature = "lab")]
        Command::Experiment(args) => thruster_lab::experiment::run(args),
        #[cfg(feature = "lab")]
        Command::Study(args) => thruster_lab::study::run(args),
        #[cfg(not(feature = "lab"))]
        Command::Demo { .. } | Command::Experiment { .. } | Command::Study { .. } => {
            Err(exit::Failure::usage(
                "this thrusterctl was built without the simulation lab (cargo feature `lab`): \
             demo, experiment and study are not available; build it with the default features",
            )
            .into())
        }
        Command::Operator(command) => commands::run(target, timeout, command),
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{CommandFactory, FromArgMatches};

    #[test]
    fn clap_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    /// Issue 27: `demo --help` listed --namespace and --ipc-root, which demo then refuses.
    #[cfg(feature = "lab")]
    #[test]
    fn lab_help_does_not_offer_the_options_it_refuses() {
        let mut cmd = command();
        for verb in LAB_VERBS {
            let help = cmd
                .find_subcommand_mut(verb)
                .unwrap()
                .render_long_help()
                .to_string();
            for hidden in ["--namespace", "--ipc-root", "--timeout-ms"] {
                assert!(
                    !help.contains(hidden),
                    "{verb} --help offers {hidden}:\n{help}"
                );
            }
        }
        // And on the lab verbs' own subcommands (`study fig2`, `study sweep`).
        let study = cmd.find_subcommand_mut("study").unwrap();
        let nested: Vec<String> = study
            .get_subcommands()
            .map(|s| s.get_name().to_string())
            .collect();
        assert!(nested.iter().any(|n| n == "fig2"), "{nested:?}");
        for name in nested {
            let help = study
                .find_subcommand_mut(&name)
                .unwrap()
                .render_long_help()
                .to_string();
            for hidden in ["--namespace", "--ipc-root", "--timeout-ms"] {
                assert!(
                    !help.contains(hidden),
                    "study {name} --help offers {hidden}:\n{help}"
                );
            }
        }
        let help = cmd
            .find_subcommand_mut("status")
            .unwrap()
            .render_long_help()
            .to_string();
        assert!(
            help.contains("--namespace") && help.contains("--ipc-root"),
            "{help}"
        );
        // Still parsed (and refused by `run` with a reason) rather than an unknown option.
        let m = command()
            .try_get_matches_from(["thrusterctl", "demo", "--namespace", "veh9"])
            .unwrap();
        assert_eq!(Cli::from_arg_matches(&m).unwrap().globals.namespace, "veh9");
    }
}
