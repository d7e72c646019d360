//! The refinement's model updates' research sweeps, moved from thrusterd-core's
//! tests/refinement_update.rs: each prints a table, knobs from environment variables.

use nalgebra::UnitQuaternion;
use thruster_sim::{NoisePreset, Scenario};
use thrusterd_core::adaptation::refinement::RefinementConfig;
use thrusterd_core::machine::{Event, Machine, MachineSetup};

use thruster_inprocess::{rel_err, vehicle, Run, VEHICLES};

fn holding_tuned(
    noise: NoisePreset,
    seed: u64,
    update: bool,
    rate_hz: f64,
    tune: impl FnOnce(&mut RefinementConfig),
) -> Run {
    let mut run = Run::with_rate("amour5", noise, seed, rate_hz);
    let mut setup = MachineSetup {
        thrusters: 5,
        ..MachineSetup::default()
    };
    setup.machine.deadband = 0.05;
    setup.refinement.update = update;
    tune(&mut setup.refinement);
    run.machine = Machine::new(setup);
    run.run_for(1.0);
    run.estimate();
    run.machine.take_events();
    run
}

/// What a run did: the model's error against the truth at the end, and what happened.
#[derive(Debug)]
struct Tracked {
    err_rot_start: f64,
    err_rot: f64,
    err_acc: f64,
    refinements: u32,
    mismatches: usize,
    /// Each window's (rotation bound, length in s).
    windows: Vec<(f64, f64)>,
}

/// Holds through pitch steps of +-10 deg every 5 s for `seconds`, applying the scenario's
/// events as they fall due (times from the start of this call).
/// `fly_with` without a DVL and quiet: what every asserting test uses.
fn fly(run: &mut Run, scenario: Scenario, seconds: f64) -> Tracked {
    fly_with(run, scenario, seconds, false, false)
}

/// `dvl`: a perfect DVL (the decisive run for the navigation's share of the bias);
/// `print_windows`: each refinement as it comes. The measuring sweeps set them from `RU_DVL`
/// and `RU_WINDOWS`; no asserting test reads the environment.
fn fly_with(
    run: &mut Run,
    mut scenario: Scenario,
    seconds: f64,
    dvl: bool,
    print_windows: bool,
) -> Tracked {
    let yaw = run.sim.roll_pitch_yaw()[2];
    let depth = run.sim.position_ned().z;
    let start = run.sim.time_s();
    let model = |run: &Run| run.machine.model().expect("a model").clone();
    let err_rot_start = rel_err(&model(run).effectiveness, &run.truth(), 0);
    let mut step = 0;
    let mut mismatches = 0;
    let mut windows = Vec::new();
    while run.sim.time_s() - start < seconds {
        let t = run.sim.time_s() - start;
        if t >= 5.0 * step as f64 {
            let p: f64 = [10.0, -10.0][step % 2];
            run.machine.on_setpoint(
                UnitQuaternion::from_euler_angles(0.0, p.to_radians(), yaw),
                Some(depth),
            );
            step += 1;
        }
        let due: Vec<_> = scenario.due((t * 1e9) as u64).to_vec();
        for e in due {
            run.sim.apply(&e.action).unwrap();
        }
        let before = run.machine.refinement().copied();
        if dvl {
            // The true body velocity, as a perfect DVL would give it.
            let v = run.sim.linear_velocity();
            run.machine.on_dvl([v.x, v.y, v.z]);
        }
        run.tick();
        if let Some(v) = run
            .machine
            .refinement()
            .copied()
            .filter(|v| Some(*v) != before)
        {
            if print_windows {
                println!("{:.2} s: {v}", run.sim.time_s());
            }
            windows.push((v.rel_err_rot, v.window_s));
        }
        for e in run.machine.take_events() {
            if let Event::MismatchDetected(why) = &e {
                println!("mismatch at {:.2} s: {why}", run.sim.time_s());
                mismatches += 1;
            }
        }
    }
    let m = model(run);
    Tracked {
        err_rot_start,
        err_rot: rel_err(&m.effectiveness, &run.truth(), 0),
        err_acc: rel_err(&m.effectiveness, &run.truth(), 3),
        refinements: m.refinements,
        mismatches,
        windows,
    }
}

fn degrade(thruster: &str) -> Scenario {
    let text = format!(
        "[[event]]\nt_s = 10\nannounce = false\naction = {{ kind = \"degrade\", thruster = \"{thruster}\", to = 0.7, over_s = 60 }}\n"
    );
    Scenario::from_toml_str(&text, "degrade").unwrap()
}

/// Every vehicle file (or those `only` names), noise-free, the default settings changed by
/// `tune`: estimated, then 60 s of pitch steps with the refinement's updates. Each vehicle's
/// result and a line saying it.
fn every_vehicle(
    only: Option<&str>,
    tune: &dyn Fn(&mut MachineSetup),
) -> Vec<(&'static str, Tracked, String)> {
    let mut out = Vec::new();
    for name in VEHICLES {
        if only.is_some_and(|o| !o.split(',').any(|v| v == name)) {
            continue;
        }
        let v = vehicle(name);
        let n = v.thrusters.len();
        let mut run = Run::with_vehicle(v, NoisePreset::None, 1, 200.0);
        let mut setup = MachineSetup {
            thrusters: n,
            ..MachineSetup::default()
        };
        setup.machine.deadband = 0.05;
        tune(&mut setup);
        run.machine = Machine::new(setup);
        run.run_for(1.0);
        run.estimate();
        run.machine.take_events();
        let r = fly(&mut run, Scenario::default(), 60.0);
        let what = format!(
            "{name}: rot {:.3} -> {:.3}, acc {:.3}, {} refinements, {} mismatches",
            r.err_rot_start, r.err_rot, r.err_acc, r.refinements, r.mismatches
        );
        println!("{what}");
        out.push((name, r, what));
    }
    out
}

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
/// window floor, inflation threshold and window standard-error scale; `RU_WINDOWS` prints
/// each window's bound.
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
    };
    let only = std::env::var("RU_VEHICLES").ok();
    for (name, r, _) in every_vehicle(only.as_deref(), &tune) {
        if std::env::var_os("RU_WINDOWS").is_some() {
            println!("{name} windows (bound, s): {:?}", r.windows);
        }
    }
}
