//! `thrusterd study ...`: offline studies writing CSV and SVG files.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Subcommand;

use thrusterd_core::study::fig2::{run_study, to_csv, StudyParams};
use thrusterd_core::study::report::figures;

#[derive(Subcommand)]
pub enum Study {
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
}

pub fn run(study: Study) -> Result<()> {
    match study {
        Study::Fig2 {
            out,
            seed,
            configs,
            pulses,
        } => fig2(&out, seed, configs, pulses),
    }
}

fn fig2(out: &Path, seed: u64, configs: usize, pulses: usize) -> Result<()> {
    anyhow::ensure!(configs >= 1, "--configs must be at least 1");
    anyhow::ensure!(pulses >= 1, "--pulses must be at least 1");
    let params = StudyParams {
        seed,
        configs,
        pulses,
        ..StudyParams::default()
    };
    let started = Instant::now();
    let rows = run_study(&params);
    let compute = started.elapsed();
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let csv_path = out.join("study.csv");
    std::fs::write(&csv_path, to_csv(&rows))
        .with_context(|| format!("writing {}", csv_path.display()))?;
    let mut written = vec![csv_path];
    for (name, svg) in figures(&rows) {
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
