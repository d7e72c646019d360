//! `thrusterctl study`: research run in one process against the simulator's physics or pure
//! arithmetic, no daemon: the estimation methods scored on every vehicle (the default, in
//! [`methods`]), the paper's Fig. 2 ([`fig2`]), the first pulse's power ([`pulse_power`]) and
//! the research sweeps ([`sweep`]) and the time-to-model limit ([`time_limit`]).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};

pub mod fig2;
pub mod fig2_figures;
pub mod methods;
pub mod pulse_power;
pub mod sweep;
pub mod time_limit;

/// Without a subcommand, the methods study (`thrusterctl study --out DIR`, as before the
/// subcommands existed); a subcommand runs one of the other studies, or a sweep, instead.
#[derive(Args, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct StudyArgs {
    #[command(subcommand)]
    pub command: Option<StudyCommand>,
    #[command(flatten)]
    pub methods: methods::MethodsArgs,
}

#[derive(Subcommand, Debug)]
pub enum StudyCommand {
    /// The paper's Fig. 2: error against pulses for random configurations, both methods, every
    /// excitation plan, with the Cramer-Rao bound. Writes DIR/study.csv and SVG figures.
    Fig2 {
        /// Output folder (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// Seed of every random draw; the same seed gives byte-identical output.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Random configurations per (N, p).
        #[arg(long, default_value_t = 100)]
        configs: usize,
        /// Pulses per run.
        #[arg(long, default_value_t = 50)]
        pulses: usize,
    },
    /// The first estimation of four vehicles with the first pulse's power fixed or sized to
    /// the noise, seeds 1-3: prints power, tilt, rotation error and time (docs/study.md).
    PulsePower,
    /// A research sweep by name (`--list` lists them): prints its table; knobs are environment
    /// variables. Use a release build: `cargo run --release -p thrusterctl -- study sweep NAME`.
    Sweep(sweep::SweepArgs),
    /// Issue 30: the least excitation time in which any candidate excitation within the
    /// budgets (|command| <= 1, tilt <= 30 / 10 deg) can reach the targets, by the dynamic
    /// model's Cramer-Rao bound; `--check` runs the real estimator on them. Use a release build.
    TimeLimit(time_limit::TimeLimitArgs),
}

pub fn run(args: StudyArgs) -> Result<()> {
    match args.command {
        None => methods::run(args.methods),
        Some(StudyCommand::Fig2 {
            out,
            seed,
            configs,
            pulses,
        }) => run_fig2(&out, seed, configs, pulses),
        Some(StudyCommand::PulsePower) => pulse_power::run(),
        Some(StudyCommand::Sweep(args)) => sweep::run(args),
        Some(StudyCommand::TimeLimit(args)) => time_limit::run(args),
    }
}

/// `thrusterctl study fig2`: the study's CSV and figures written into `out`.
fn run_fig2(out: &Path, seed: u64, configs: usize, pulses: usize) -> Result<()> {
    anyhow::ensure!(configs >= 1, "--configs must be at least 1");
    anyhow::ensure!(pulses >= 1, "--pulses must be at least 1");
    let params = fig2::StudyParams {
        seed,
        configs,
        pulses,
        ..fig2::StudyParams::default()
    };
    let started = Instant::now();
    let rows = fig2::run_study(&params);
    let compute = started.elapsed();
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let csv_path = out.join("study.csv");
    std::fs::write(&csv_path, fig2::to_csv(&rows))
        .with_context(|| format!("writing {}", csv_path.display()))?;
    let mut written = vec![csv_path];
    for (name, svg) in fig2_figures::figures(&rows) {
        let path = out.join(name);
        std::fs::write(&path, svg).with_context(|| format!("writing {}", path.display()))?;
        written.push(path);
    }
    println!(
        "fig2 study: {} rows ({} configurations x {} pulses per cell) computed in {:.3} s",
        rows.len(),
        configs,
        pulses,
        compute.as_secs_f64()
    );
    for p in written {
        println!("  wrote {}", p.display());
    }
    Ok(())
}
