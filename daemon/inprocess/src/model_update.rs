//! The refinement's model update under way: AMOUR-5 (or another vehicle) held with
//! `refinement.update` on while the simulator degrades a thruster, tracked against the truth.
//! What the core's model-update tests assert on and the lab's update sweeps print.

use nalgebra::UnitQuaternion;
use thruster_sim::{NoisePreset, Scenario};
use thrusterd_core::adaptation::refinement::RefinementConfig;
use thrusterd_core::machine::{Event, Machine, MachineSetup};

use crate::run::{rel_err, vehicle, Run};

pub fn holding_tuned(
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
pub struct Tracked {
    pub err_rot_start: f64,
    pub err_rot: f64,
    pub err_acc: f64,
    pub refinements: u32,
    pub mismatches: usize,
    /// Each window's (rotation bound, length in s).
    pub windows: Vec<(f64, f64)>,
}

/// Holds through pitch steps of +-10 deg every 5 s for `seconds`, applying the scenario's
/// events as they fall due (times from the start of this call).
/// `fly_with` without a DVL and quiet: what every asserting test uses.
pub fn fly(run: &mut Run, scenario: Scenario, seconds: f64) -> Tracked {
    fly_with(run, scenario, seconds, false, false)
}

/// `dvl`: a perfect DVL (the decisive run for the navigation's share of the bias);
/// `print_windows`: each refinement as it comes. The measuring sweeps set them from `RU_DVL`
/// and `RU_WINDOWS`; no asserting test reads the environment.
pub fn fly_with(
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
        pitch_step(run, t, &mut step, yaw, depth);
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

/// The refinement tests' manoeuvre, `t` s into it: a new pitch setpoint of +10 or -10 deg
/// (alternating, heading `yaw`, depth `depth`) every 5 s; `step` counts the setpoints given.
pub fn pitch_step(run: &mut Run, t: f64, step: &mut usize, yaw: f64, depth: f64) {
    if t >= 5.0 * *step as f64 {
        let p: f64 = [10.0, -10.0][*step % 2];
        run.machine.on_setpoint(
            UnitQuaternion::from_euler_angles(0.0, p.to_radians(), yaw),
            Some(depth),
        );
        *step += 1;
    }
}

pub fn degrade(thruster: &str) -> Scenario {
    let text = format!(
        "[[event]]\nt_s = 10\nannounce = false\naction = {{ kind = \"degrade\", thruster = \"{thruster}\", to = 0.7, over_s = 60 }}\n"
    );
    Scenario::from_toml_str(&text, "degrade").unwrap()
}

/// Every vehicle file (or those `only` names), noise-free, the default settings changed by
/// `tune`: estimated, then 60 s of pitch steps with the refinement's updates. Each vehicle's
/// result and a line saying it.
pub fn every_vehicle(
    only: Option<&str>,
    tune: &dyn Fn(&mut MachineSetup),
) -> Vec<(&'static str, Tracked, String)> {
    let mut out = Vec::new();
    for name in crate::run::VEHICLES {
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
