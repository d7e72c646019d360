//! The refinement's model updates' research sweeps, moved from thrusterd-core's
//! tests/refinement_update.rs: each prints a table, knobs from environment variables.

use thruster_sim::{NoisePreset, Scenario};
use thrusterd_core::adaptation::refinement::RefinementConfig;
use thrusterd_core::machine::MachineSetup;

use thruster_inprocess::model_update::*;

/// The sweep behind the settings (prints, asserts nothing; run with --ignored --nocapture;
/// `RU_SCALE`, `RU_DRIFT`, `RU_FLOOR`, `RU_UPDATE_REL`, `RU_INFLATE` set the refinement's
/// settings, `RU_NOISE` narrows the noise levels, `RU_DVL` adds a perfect DVL, `RU_WINDOWS`
/// prints each refinement).
pub(super) fn update_sweep() {
    let dvl = std::env::var_os("RU_DVL").is_some();
    let windows = std::env::var_os("RU_WINDOWS").is_some();
    let tune = |r: &mut RefinementConfig| {
        if let Ok(v) = std::env::var("RU_SCALE") {
            r.window_se_scale = v.parse().expect("RU_SCALE is a number");
        }
        if let Ok(v) = std::env::var("RU_DRIFT") {
            r.drift_per_sqrt_s = v.parse().expect("RU_DRIFT is a number");
        }
        if let Ok(v) = std::env::var("RU_FLOOR") {
            r.window_floor = v.parse().expect("RU_FLOOR is a number");
        }
        if let Ok(v) = std::env::var("RU_UPDATE_REL") {
            r.update_rel_err = v.parse().expect("RU_UPDATE_REL is a number");
        }
        if let Ok(v) = std::env::var("RU_INFLATE") {
            r.inflate_above = v.parse().expect("RU_INFLATE is a number");
        }
    };
    let holding = |noise, seed, update, rate| holding_tuned(noise, seed, update, rate, tune);
    // RU_NOISE=paper (or none, realistic) narrows the noise levels.
    let only = std::env::var("RU_NOISE").ok();
    for noise in [
        NoisePreset::None,
        NoisePreset::Realistic,
        NoisePreset::Paper,
    ] {
        if only
            .as_ref()
            .is_some_and(|o| !format!("{noise:?}").eq_ignore_ascii_case(o))
        {
            continue;
        }
        for thruster in ["L", "T"] {
            for update in [false, true] {
                for seed in [1, 2] {
                    let mut run = holding(noise, seed, update, 200.0);
                    let r = fly_with(&mut run, degrade(thruster), 100.0, dvl, windows);
                    println!(
                        "{noise:?} {thruster} update={update} seed {seed}: {r:?} state {:?}",
                        run.machine.state()
                    );
                }
            }
        }
        for seed in [1, 2] {
            let mut run = holding(noise, seed, true, 200.0);
            let r = fly_with(&mut run, Scenario::default(), 180.0, dvl, windows);
            let w: Vec<String> = r
                .windows
                .iter()
                .map(|(e, s)| format!("{e:.3}/{s:.0}s"))
                .collect();
            println!(
                "{noise:?} unchanged seed {seed}: rot {:.3} -> {:.3}, acc {:.3}, {} refinements; windows {}",
                r.err_rot_start, r.err_rot, r.err_acc, r.refinements, w.join(" ")
            );
        }
    }
}

/// The measuring tool behind the settings (prints, asserts nothing; run with `--ignored
/// --nocapture`): `RU_VEHICLES` (comma-separated) narrows the list, `RU_DITHER`, `RU_DRIFT`,
/// `RU_FLOOR`, `RU_INFLATE`, `RU_SCALE` set the refinement's dither, drift per sqrt(s),
/// window floor, inflation threshold and window standard-error scale; `RU_SHAPED` turns
/// `estimator.shaped_thrust` on; `RU_WINDOWS` prints each window's bound.
pub(super) fn every_vehicle_sweep_with_settings_from_the_environment() {
    let num = |k: &str| {
        std::env::var(k).ok().map(|v| {
            v.parse::<f64>()
                .unwrap_or_else(|_| panic!("{k} is a number"))
        })
    };
    let tune = |setup: &mut MachineSetup| {
        let r = &mut setup.refinement;
        if let Some(v) = num("RU_DITHER") {
            r.dither = v;
        }
        if let Some(v) = num("RU_DRIFT") {
            r.drift_per_sqrt_s = v;
        }
        if let Some(v) = num("RU_FLOOR") {
            r.window_floor = v;
        }
        if let Some(v) = num("RU_INFLATE") {
            r.inflate_above = v;
        }
        if let Some(v) = num("RU_SCALE") {
            r.window_se_scale = v;
        }
        if std::env::var_os("RU_SHAPED").is_some() {
            setup.estimator.shaped_thrust = true;
        }
    };
    let only = std::env::var("RU_VEHICLES").ok();
    for (name, r, _) in every_vehicle(only.as_deref(), &tune) {
        if std::env::var_os("RU_WINDOWS").is_some() {
            println!("{name} windows (bound, s): {:?}", r.windows);
        }
    }
}
