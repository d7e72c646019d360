//! `thrusterctl study sweep NAME`: the research sweeps, each a measuring tool that prints a
//! table (the figures of docs/study.md and docs/experiments.md). They were `#[ignore]` tests in
//! thrusterd-core's test files and kept their names, their environment-variable knobs and
//! their output, so a command in the docs reproduces the same figures; the core's tests now
//! only assert. Run them from a release build: `cargo run --release -p thrusterctl -- study
//! sweep NAME`.

use anyhow::Result;
use clap::Args;

mod detection_bound;
mod disturbance_states;
mod estimation_sweeps;
mod identification;
mod lost_hold;
mod mismatch;
mod refinement;
mod refinement_update;
mod silent_change;
mod time_to_model;
mod true_terms;
mod window_floor;

#[derive(Args, Debug)]
pub struct SweepArgs {
    /// The sweep to run (`--list` names them). Its knobs are environment variables, as listed.
    #[arg(required_unless_present = "list")]
    pub name: Option<String>,
    /// List the sweeps, one line each: name, knobs, what it measures.
    #[arg(long)]
    pub list: bool,
}

/// One sweep: its name (the test it was), its knobs' prefix and what it measures.
pub struct Sweep {
    pub name: &'static str,
    pub knobs: &'static str,
    pub about: &'static str,
    run: fn(),
}

/// Every sweep, in the order of the files they came from.
pub const SWEEPS: &[Sweep] = &[
    Sweep {
        name: "ttm_sweep",
        knobs: "TTM_*",
        about: "time to model from an idle request, in-process, its settings varied (issue 30)",
        run: time_to_model::ttm_sweep,
    },
    Sweep {
        name: "carry_over_on_every_vehicle",
        knobs: "CO_*",
        about: "every vehicle, a thruster turned 45 deg and announced, carry-over on and off",
        run: identification::carry_over_on_every_vehicle,
    },
    Sweep {
        name: "lost_hold_soak",
        knobs: "LH_*",
        about: "every vehicle and water, pitch steps: does the hold watch fire on a held vehicle",
        run: lost_hold::lost_hold_soak,
    },
    Sweep {
        name: "sweep_identification",
        knobs: "ID_*",
        about: "the announced rotation under control with the identification's settings varied",
        run: identification::sweep_identification,
    },
    Sweep {
        name: "bias_sweep",
        knobs: "-",
        about: "AMOUR-5, accelerometer turn-on bias against the bias state's prior, seeds 1-10",
        run: estimation_sweeps::bias_sweep,
    },
    Sweep {
        name: "coverage_sweep",
        knobs: "COV_*",
        about: "standard errors against the error vs the truth, every noise, seeds 1-10",
        run: estimation_sweeps::coverage_sweep,
    },
    Sweep {
        name: "presets_sweep",
        knobs: "-",
        about: "AMOUR-5 at every noise preset, bias state off and on, seeds 1-5",
        run: estimation_sweeps::presets_sweep,
    },
    Sweep {
        name: "stop_threshold_sweep",
        knobs: "-",
        about: "the stop threshold against the time to model at the paper's noise",
        run: estimation_sweeps::stop_threshold_sweep,
    },
    Sweep {
        name: "vehicles_sweep",
        knobs: "-",
        about: "every vehicle at every noise preset, seeds 1-5, and the mean",
        run: estimation_sweeps::vehicles_sweep,
    },
    Sweep {
        name: "coefficient_error_by_vehicle",
        knobs: "COEF_*",
        about: "per vehicle, the learned damping and restoring against the simulator's",
        run: estimation_sweeps::coefficient_error_by_vehicle,
    },
    Sweep {
        name: "lag_sweep",
        knobs: "LAG_*",
        about: "thrusters spinning up faster or slower than assumed: the lag learned",
        run: estimation_sweeps::lag_sweep,
    },
    Sweep {
        name: "imu_and_water_sweep",
        knobs: "LA_*",
        about: "the IMU off the centre and the water, over seeds",
        run: estimation_sweeps::imu_and_water_sweep,
    },
    Sweep {
        name: "mismatch_sweep",
        knobs: "MM_*",
        about: "thrusters' reverse ratio, dead band or lag not what the daemon assumes",
        run: mismatch::mismatch_sweep,
    },
    Sweep {
        name: "khz_sweep",
        knobs: "KHZ_*, RUN_LATENCY_US",
        about: "the 1 kHz hold at the paper's noise: refinement windows, no false alarm",
        run: refinement::khz_sweep,
    },
    Sweep {
        name: "dither_sweep",
        knobs: "RF_*, DB_TERM_PRIOR",
        about: "the refinement's dither against detection and hold",
        run: refinement::dither_sweep,
    },
    Sweep {
        name: "change_test_soak",
        knobs: "CT_*",
        about: "minutes unchanged (no alarm allowed), then the top thruster rotated",
        run: refinement::change_test_soak,
    },
    Sweep {
        name: "refinement_in_water",
        knobs: "RW_*",
        about: "the model in force's error while the refinement updates it in moving water",
        run: refinement::refinement_in_water,
    },
    Sweep {
        name: "change_test_on_every_vehicle",
        knobs: "CT_*",
        about: "the change test on every vehicle and noise, unchanged: no alarm allowed",
        run: refinement::change_test_on_every_vehicle,
    },
    Sweep {
        name: "detection_bound",
        knobs: "DB_*",
        about: "the best detection time any detector could reach (a GLR beside the machine)",
        run: detection_bound::detection_bound,
    },
    Sweep {
        name: "update_sweep",
        knobs: "RU_*",
        about: "the refinement's model updates following a degrading thruster",
        run: refinement_update::update_sweep,
    },
    Sweep {
        name: "every_vehicle_sweep_with_settings_from_the_environment",
        knobs: "RU_*",
        about: "every vehicle, noise-free, pitch steps with the refinement's updates",
        run: refinement_update::every_vehicle_sweep_with_settings_from_the_environment,
    },
    Sweep {
        name: "silent_change_in_water",
        knobs: "SC_*",
        about: "every detector as shipped, in moving water: false alarms, then a rotated thruster",
        run: silent_change::silent_change_in_water,
    },
    Sweep {
        name: "window_floor",
        knobs: "WF_*",
        about: "the under-control fit against the truth, noise-free, thrusters made ideal one way at a time",
        run: window_floor::window_floor,
    },
];

/// The `--list` text: one line per sweep.
pub fn list() -> String {
    let width = SWEEPS.iter().map(|s| s.name.len()).max().unwrap_or(0);
    SWEEPS
        .iter()
        .map(|s| format!("{:width$}  {:22}  {}\n", s.name, s.knobs, s.about))
        .collect()
}

pub fn run(args: SweepArgs) -> Result<()> {
    if args.list {
        print!("{}", list());
        return Ok(());
    }
    let name = args.name.unwrap_or_default();
    let Some(sweep) = SWEEPS.iter().find(|s| s.name == name) else {
        return Err(thrusterctl_operator::exit::Failure::usage(format!(
            "no sweep {name:?}; `thrusterctl study sweep --list` lists them"
        ))
        .into());
    };
    (sweep.run)();
    Ok(())
}

/// A wave phase, rad, from the sweep's knob `key` set to `knob`: a number, or `seed` for the
/// seed's own phase (`thruster_inprocess::swell_phase::of_seed`).
fn wave_phase(key: &str, knob: &str, seed: u64) -> f64 {
    if knob == "seed" {
        thruster_inprocess::swell_phase::of_seed(seed)
    } else {
        knob.parse()
            .unwrap_or_else(|_| panic!("{key}: {knob} is neither a phase in rad nor seed"))
    }
}

/// A water preset named by the environment variable `key` (the demo's `--water` names;
/// unset: None), for the sweeps that bring the water up mid-run.
fn water_from_env(key: &str) -> Option<thruster_sim::disturbance::WaterPreset> {
    use clap::ValueEnum;
    let name = std::env::var(key).ok()?;
    Some(
        thruster_sim::disturbance::WaterPreset::from_str(&name, true)
            .unwrap_or_else(|e| panic!("{key}: {e}")),
    )
}

/// When the detectors' calibrations apply, named by the environment variable `key`
/// ("in_a_sea" or "always"; unset: None, the shipped setting), for the sweeps of issue 32
/// item 5.
fn calibrate_when_from_env(
    key: &str,
) -> Option<thrusterd_core::adaptation::calibrate_when::CalibrateWhen> {
    use thrusterd_core::adaptation::calibrate_when::CalibrateWhen;
    match std::env::var(key).ok()?.as_str() {
        "in_a_sea" => Some(CalibrateWhen::InASea),
        "always" => Some(CalibrateWhen::Always),
        other => panic!("{key}: {other} is not in_a_sea or always"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_sweep_is_listed_once_and_an_unknown_one_is_refused() {
        let text = list();
        assert_eq!(text.lines().count(), SWEEPS.len());
        for s in SWEEPS {
            let lines = text
                .lines()
                .filter(|l| l.split_whitespace().next() == Some(s.name))
                .count();
            assert_eq!(lines, 1, "{}", s.name);
        }
        let e = run(SweepArgs {
            name: Some("lag_swep".into()),
            list: false,
        })
        .unwrap_err();
        assert!(e.to_string().contains("--list"), "{e}");
    }

    #[test]
    fn a_wave_phase_knob_is_a_phase_or_the_seeds_own() {
        assert_eq!(
            wave_phase("K", "seed", 4),
            thruster_inprocess::swell_phase::of_seed(4)
        );
        assert_eq!(wave_phase("K", "1.5", 7), 1.5);
        let e = std::panic::catch_unwind(|| wave_phase("ID_WAVE_PHASE", "half", 1)).unwrap_err();
        let e = e.downcast_ref::<String>().unwrap();
        assert!(e.contains("ID_WAVE_PHASE: half"), "{e}");
    }
}
