//! `thrusterd replay FILE.mcap`: a recorded session through the daemon's own machine,
//! offline (the work is in `thrusterd-replay`; this is its command line and output).

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;
use thrusterd_replay::report::{self, Context};

#[derive(Args)]
pub struct ReplayArgs {
    /// The recording (from `thrusterctl record` or `thrusterctl demo --record`), and its
    /// rotated continuations (FILE-0001.mcap, ...) in order.
    #[arg(required = true, value_name = "FILE.mcap")]
    files: Vec<PathBuf>,
    /// Replay with this configuration instead of the recording's own: what would these
    /// settings have learned from the same samples?
    #[arg(long)]
    config: Option<PathBuf>,
    /// Override `vehicle.thrusters`, as `thrusterd run --thrusters` does (give the count
    /// the recorded daemon ran with when `--config`'s file does not say it).
    #[arg(long)]
    thrusters: Option<usize>,
    /// Print one JSON object (every model swap as the `model` channel carries it).
    #[arg(long)]
    json: bool,
}

pub fn run(args: ReplayArgs) -> Result<()> {
    let rec = thrusterd_replay::recording::read(&args.files)?;
    let mut cfg = match &args.config {
        Some(path) => crate::config_file::load(path)?,
        None => thrusterd_replay::recorded_config(&rec)?,
    };
    if let Some(n) = args.thrusters {
        crate::config_file::set_thrusters(&mut cfg, n)?;
    }
    let replayed = thrusterd_replay::replay(&rec, &cfg)?;
    let files = thrusterd_replay::recording::names(&args.files);
    let config = args.config.as_ref().map(|p| p.display().to_string());
    let ctx = Context {
        files: &files,
        config: config.as_deref(),
    };
    if args.json {
        println!("{}", report::json(&ctx, &replayed));
    } else {
        print!("{}", report::text(&ctx, &replayed));
    }
    // With the daemon's own settings the replay must be the daemon's session; anything else
    // is a bug (or a recording that is not what it claims) and must not pass silently.
    if args.config.is_none() && args.thrusters.is_none() {
        if let Some(d) = &replayed.difference {
            bail!("the replay with the recording's configuration differs from the recording: {d}");
        }
        if let Some(d) = &replayed.outcome.diverged_at {
            bail!(
                "the replay with the recording's configuration answered accepted IMU sample {} (seq {}) with another command than the daemon",
                d.imu_count,
                d.imu_seq
            );
        }
        if let Some(d) = replayed.outcome.divergences.first() {
            bail!("the replay with the recording's configuration diverged: {d}");
        }
    }
    Ok(())
}
