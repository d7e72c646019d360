//! `thrusterctl experiment NAME`: the paper's four pool experiments (Doniec, Detweiler, Rus,
//! Section 5, Fig. 6) reproduced in simulation, each run with thrusterd and thruster-sim as real
//! processes at the paper's noise level (one [`Session`] per run).
//!
//! Table-driven: an experiment is a list of runs ([`RunSpec`]: vehicle, daemon config, scenario,
//! maneuver plan) and a summary of their scores. Every run records the true attitude against
//! the setpoint in effect at each vehicle sample; the pure scoring lives in [`crate::scoring`].
//!
//! One file per job: [`plan`] (the runs as data, the daemon's config and the scenario each
//! gets), [`drive`] (one run started, driven and recorded), [`results`] (the scores computed and
//! the headline from them), [`scores`] (the results as types, their JSON the output),
//! [`report`] (the text and the output folder) and [`figure`] (the SVG); [`degrade`] and
//! [`dive`] hold their experiments' runs and scores. This file is the command line and the
//! loop over runs and seeds. The children share this module's imports (`use super::*`): one
//! list for the whole experiment.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use nalgebra::{Quaternion, UnitQuaternion};
use serde_json::{json, Value};
use thruster_protocol::{
    DaemonState, ModelMsg, RequestKind, ThrustMode, TruthMsg, VehicleStateMsg, MAX_THRUSTERS,
};

use crate::plot::{nice_range, render, Grid, Panel, Series};
use crate::recording::{run_path, RECORD_PACE};
use crate::scoring::{
    angle_error_deg, euler_deg, high_pass_rms, recovered_at, tilt_error_deg, window_means,
    wrap_deg, yaw_error_deg, Plan, Stats, Step,
};
use crate::session::{config_file, Binaries, DaemonConfig, Session, SessionSpec, Shutdown};

mod degrade;
mod dive;
mod drive;
mod figure;
mod plan;
mod report;
mod results;
mod scores;

use drive::*;
use figure::*;
use plan::*;
use report::*;
use results::*;
use scores::*;

const DOFS: [&str; 6] = ["roll", "pitch", "yaw", "surge", "sway", "heave"];
/// Samples this long after a setpoint step are its transient; "settled" errors leave them out.
const SETTLE_S: f64 = 2.0;
/// Window of the recovery detector (hot-swap), s.
const WINDOW_S: f64 = 2.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Name {
    /// AMOUR-5: yaw, pitch and roll steps, learned model against the manual (nominal) one.
    ManualVsLearned,
    /// Top thruster rotated 45 degrees: yaw error during pitch steps, manual against learned.
    Misaligned,
    /// All thrusters along the body: the paper's estimator against ours.
    Aligned,
    /// The top thruster rotated 45 degrees mid-run, announced and silent.
    HotSwap,
    /// Thruster L loses 30 % of its thrust over a minute, unannounced: the continuously
    /// refined model against the one learned at the start.
    Degrade,
    /// A T200 vehicle holding through 30 vehicle minutes on a draining battery: commands
    /// referred to the reference voltage against commands as computed.
    Dive,
}

impl Name {
    fn id(self) -> &'static str {
        match self {
            Name::ManualVsLearned => "manual-vs-learned",
            Name::Misaligned => "misaligned",
            Name::Aligned => "aligned",
            Name::HotSwap => "hot-swap",
            Name::Degrade => "degrade",
            Name::Dive => "dive",
        }
    }
}

#[derive(Args, Debug, Clone)]
pub struct ExperimentArgs {
    /// Which experiment.
    #[arg(value_enum)]
    pub name: Name,
    /// Print one JSON object with every number instead of the report.
    #[arg(long)]
    pub json: bool,
    /// Write per-run CSV time series, the figure (SVG) and the JSON summary into this folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Seed of the simulator's sensor noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Run every seed of `A-B` (e.g. 1-10) and report each headline figure's mean, standard
    /// deviation and range over them (one line per figure; with --json every seed's
    /// headline too). Each seed's run is the one `--seed` gives.
    #[arg(long, value_name = "A-B", conflicts_with_all = ["seed", "out", "record"])]
    pub seeds: Option<String>,
    /// Lockstep, but no faster than this many times real time (needs `thruster-sim --pace`),
    /// for watching a run. 0: as fast as possible. The lab steps the simulator's vehicle
    /// time itself, so the result is the same at any pace.
    #[arg(long, default_value_t = 0.0)]
    pub pace: f64,
    /// hot-swap: vehicle time of the thruster rotation, s (after the first estimation);
    /// degrade: when the thruster starts losing thrust.
    #[arg(long, default_value_t = 40.0)]
    pub t_change: f64,
    /// Sensor noise of every run: paper, realistic or none (default: each run's own, the
    /// paper's noise except hot-swap's silent run, which uses the realistic IMU).
    #[arg(long)]
    pub noise: Option<String>,
    /// Record each run's session (every topic of its namespace) to its own MCAP file,
    /// FILE-<run>.mcap (`top45.mcap` -> `top45-announced.mcap`, ...). The runs are then paced
    /// to at most 5x real time so the recorder loses nothing.
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<PathBuf>,
    /// dive: the vehicle file (config/vehicles/NAME.toml) with `model = "t200"` thrusters and
    /// a `[battery]` (its capacity and hotel load are set so 30 minutes drain it).
    #[arg(long, default_value = "amour5_t200")]
    pub vehicle: String,
    /// dive: the battery's capacity, Ah (default 4.6: full to ~13.7 V in 30 minutes with the
    /// dive's 8 A hotel load); a large one gives the same dive on a battery that stays full.
    #[arg(long, default_value_t = dive::CAPACITY_AH)]
    pub capacity_ah: f64,
    /// Every run's daemon commands through the thruster's curve (`[supply] linearize`: thrust
    /// linear in the command, the T200's dead zone stepped over; the dive's compensated run
    /// always does).
    #[arg(long)]
    pub linearize: bool,
    /// Every run's simulated IMU position and water (the daemon is told neither).
    #[command(flatten)]
    pub water: crate::water::WaterArgs,
}

pub fn run(args: ExperimentArgs) -> Result<()> {
    let bins = Binaries::locate()?;
    // A command line's vehicle lives as long as the process: leaked once, like a literal.
    let vehicle: &'static str = Box::leak(args.vehicle.clone().into_boxed_str());
    let mut specs = runs(args.name, args.t_change, vehicle);
    if !(args.capacity_ah.is_finite() && args.capacity_ah > 0.0 && args.capacity_ah <= 1000.0) {
        return Err(thrusterctl_operator::exit::Failure::usage(format!(
            "--capacity-ah must be in (0, 1000], got {}",
            args.capacity_ah
        ))
        .into());
    }
    for s in &mut specs {
        if let Some((_, hotel)) = s.battery {
            s.battery = Some((args.capacity_ah, hotel));
        }
        s.linearize |= args.linearize;
    }
    if let Some(noise) = &args.noise {
        let noise: &'static str = match noise.as_str() {
            "paper" => "paper",
            "realistic" => "realistic",
            "none" => "none",
            other => {
                return Err(thrusterctl_operator::exit::Failure::usage(format!(
                    "--noise must be paper, realistic or none, got {other:?}"
                ))
                .into())
            }
        };
        for s in &mut specs {
            s.noise = noise;
        }
    }
    if let Some(range) = &args.seeds {
        let seeds: Vec<u64> = crate::seeds::parse_range(range)
            .map_err(|e| thrusterctl_operator::exit::Failure::usage(e.to_string()))?
            .collect();
        let mut headlines = Vec::new();
        for &seed in &seeds {
            if !args.json {
                eprintln!("seed {seed} ...");
            }
            let one = ExperimentArgs {
                seed,
                json: true,
                ..args.clone()
            };
            let (_, summary) =
                run_seed(&bins, &one, &specs).with_context(|| format!("seed {seed}"))?;
            headlines.push(summary.headline);
        }
        if args.json {
            println!(
                "{}",
                crate::seeds::summary(args.name.id(), &seeds, &headlines)
            );
        } else {
            print!(
                "{}",
                crate::seeds::table(args.name.id(), &seeds, &headlines)
            );
        }
        return Ok(());
    }
    let (outs, summary) = run_seed(&bins, &args, &specs)?;
    if let Some(dir) = &args.out {
        write_out(dir, args.name, &outs, &summary)?;
    }
    if args.json {
        println!("{}", summary.json()?);
    } else {
        print_report(args.name, &outs, &summary)?;
    }
    Ok(())
}

/// Every run of the experiment with `args.seed`; their outputs and the JSON summary.
fn run_seed(
    bins: &Binaries,
    args: &ExperimentArgs,
    specs: &[RunSpec],
) -> Result<(Vec<RunOutput>, Summary)> {
    let mut outs = Vec::new();
    for spec in specs {
        if !args.json {
            eprintln!("running {} / {} ...", args.name.id(), spec.label);
        }
        outs.push(run_one(bins, args, spec)?);
    }
    let mut runs = Runs::default();
    for o in &outs {
        let mut v = common(o);
        v.hot_swap = (args.name == Name::HotSwap).then(|| hot_swap(o));
        v.degrade = (args.name == Name::Degrade).then(|| degrade::summary(o));
        v.dive = (args.name == Name::Dive).then(|| dive::summary(o));
        runs.0.insert(o.spec.label.into(), v);
    }
    let headline = headline(args.name, &runs)?;
    let summary = Summary {
        experiment: args.name.id().into(),
        seed: args.seed,
        vehicle_as_is: args.water.json()?,
        noise: args
            .noise
            .clone()
            .unwrap_or_else(|| "paper (per run: runs.*.noise)".into()),
        pace_requested: args.pace,
        sim_has_pace: bins.sim_pace,
        daemon_has_monitor: bins.daemon_monitor,
        runs,
        headline,
    };
    Ok((outs, summary))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(t: f64, state: DaemonState) -> Row {
        Row {
            t,
            sp: [0.0; 3],
            tru: [0.0; 3],
            err: 0.0,
            yaw_err: 0.0,
            tilt_err: 0.0,
            since_step: 0.0,
            step: 0,
            state,
            rate: [0.0; 3],
            vel: [0.0; 3],
            u: [0.0; MAX_THRUSTERS],
            nu: 0,
        }
    }

    /// Issue 27: "detected after 0.67 s, re-estimation after 0.56 s" and "-" for what did not
    /// happen. In order, the status's lag named, and absent events said in words.
    #[test]
    fn hot_swap_events_in_order_and_in_words() {
        let silent = HotSwapScores {
            reestimation_start_delay_s: num(0.31),
            detection_delay_s: num(0.35),
            first_swap_delay_s: num(5.3),
            first_swap_source: Some("Estimated".into()),
            new_model_delay_s: num(5.3),
            recovery_threshold_deg: num(13.18),
            recovered_after_s: num(1.72),
            ..HotSwapScores::default()
        };
        assert_eq!(
            hot_swap_events(&silent),
            "re-estimation began after 0.31 s, mismatch in status after 0.35 s, first swap after \
             5.30 s (Estimated), new model after 5.30 s, recovered (2 s windows < 13.18 deg) \
             after 1.72 s"
        );
        let oracle = HotSwapScores {
            recovery_threshold_deg: num(12.18),
            recovered_after_s: Num::NONE,
            ..HotSwapScores::default()
        };
        let text = hot_swap_events(&oracle);
        assert_eq!(
            text,
            "no re-estimation, not recovered (2 s windows < 12.18 deg)"
        );
        assert!(!text.contains(" - ") && !text.contains("- s"), "{text}");
    }

    #[test]
    fn grey_is_promised_only_where_drawn_and_settled_says_so() {
        let panel = |shade| Panel {
            title: String::new(),
            series: vec![],
            y_range: None,
            shade,
        };
        // An estimation before the hold began (negative x) is not drawn.
        assert!(!shading_drawn(&[panel(vec![(-8.0, -0.5)])], 30.0));
        assert!(!shading_drawn(&[panel(vec![])], 30.0));
        assert!(shading_drawn(
            &[panel(vec![]), panel(vec![(12.0, 20.0)])],
            30.0
        ));
        assert_eq!(settled(Num::NONE), "not settled");
        assert_eq!(settled(num(1.234)), "settled 1.23 deg");
    }

    #[test]
    fn estimation_periods_are_the_shaded_intervals() {
        use DaemonState::*;
        let states = [
            Active, Pulse, Settle, Pulse, Active, Active, Identify, Identify,
        ];
        let rows: Vec<Row> = states
            .iter()
            .enumerate()
            .map(|(k, s)| row(10.0 + k as f64, *s))
            .collect();
        // Open-loop pulses 1..4 s after the hold began, identification from 6 s to the end.
        assert_eq!(
            estimating_intervals(&rows, 10.0),
            vec![(1.0, 4.0), (6.0, 7.0)]
        );
    }

    #[test]
    fn every_experiment_has_its_runs_an_oracle_and_a_plan_that_ends() {
        for name in Name::value_variants() {
            let specs = runs(*name, 40.0, "amour5_t200");
            if *name == Name::Dive {
                // Compensated against not; the truth moves with the battery, so no oracle.
                assert_eq!(specs.len(), 2);
                for s in &specs {
                    let d = s.plan.duration_s();
                    assert!(
                        (dive::DIVE_S - 1.0..=dive::DIVE_S + 80.0).contains(&d),
                        "{d}"
                    );
                    assert!(s.battery.is_some());
                }
                continue;
            }
            // Two runs compared, and the true model as their reference; hot-swap: announced
            // (manoeuvring and holding level), silent at two noise levels, and the true model
            // loaded again at the change.
            let oracles = specs.iter().filter(|s| s.start == Start::Oracle).count();
            let want = if *name == Name::HotSwap {
                (5, 1)
            } else {
                (3, 1)
            };
            assert_eq!((specs.len(), oracles), want, "{name:?}");
            for s in specs {
                let d = s.plan.duration_s();
                // The longest: hot-swap's silent run at the paper's noise, 90 s after the
                // change at 40 s.
                assert!(d > 20.0 && d <= 130.0, "{name:?} {}: {d}", s.label);
                assert!(s.plan.step_at(d + 1.0).is_none());
            }
        }
    }

    #[test]
    fn scenario_parses_as_the_sims_format() {
        let v: toml::Value = toml::from_str(&scenario(40.0, false, ROTATE_TOP)).unwrap();
        let e = &v["event"].as_array().unwrap()[0];
        assert_eq!(e["t_s"].as_float(), Some(40.0));
        assert_eq!(e["announce"].as_bool(), Some(false));
        assert_eq!(e["action"]["angle_deg"].as_integer(), Some(45));
    }
}
