//! The state machine closed around the simulator's physics, in one process (no IPC): the
//! estimation, control, faults and reconfiguration as the daemon runs them, against a 6-DOF
//! vehicle with thruster lag, drag, buoyancy and gravity.

use nalgebra::UnitQuaternion;
use thruster_sim::{NoisePreset, SensorConfig, Simulator, Vehicle};
use thrusterd_core::estimator::EstimatorConfig;
use thrusterd_core::machine::{
    Event, Geometry, Machine, MachineSetup, Mode, Reconfig, Request, State,
};
use thrusterd_core::model::ModelSource;

mod common;
use common::{rel_err, vehicle, Run};

/// AMOUR-5 at the paper's noise (0.25 rad/s, 0.05 g): the learned model (the default dynamic
/// method) is within 10 % of the truth, in 8 vehicle-s. Measured 0.046 / 0.031 in 7.8 s (seed
/// 1); over seeds 1-5 in-process 0.056 / 0.063 in 8.1 s (docs/study.md). In-process the run is
/// deterministic; the margin is for seeds and the bound's optimism at this noise. (The static
/// model needed 25 %: it carried a 12-23 % bias from drag and restoring moment.)
#[test]
fn amour5_estimation_at_the_papers_noise_matches_truth() {
    let mut run = Run::new("amour5", NoisePreset::Paper, 1);
    run.run_for(1.0);
    let t = run.estimate();
    let model = run.machine.model().expect("a model").clone();
    let truth = run.truth();
    let (e_rot, e_acc) = (
        rel_err(&model.effectiveness, &truth, 0),
        rel_err(&model.effectiveness, &truth, 3),
    );
    let est = run.machine.last_estimate().unwrap();
    println!(
        "amour5/paper: {t:.1} vehicle s, {} pulses, err rot {e_rot:.3} acc {e_acc:.3}",
        est.pulses
    );
    assert_eq!(run.machine.state(), State::Active);
    assert_eq!(model.source, ModelSource::Estimated);
    assert!(e_rot < 0.10, "rotation error {e_rot}");
    assert!(e_acc < 0.10, "acceleration error {e_acc}");
    assert!(t < 9.0, "{t:.1} vehicle s");
    assert_eq!(
        model.actuated.names(),
        vec!["roll", "pitch", "yaw", "surge", "heave"]
    );
    // Then it holds attitude: 5 s of control keep roll and pitch within a few degrees.
    run.run_for(5.0);
    assert_eq!(run.last_mode, Mode::Controlling);
    let desired = run.machine.last_desired();
    assert!(
        desired.iter().all(|v| v.is_finite()) && desired.iter().any(|v| *v != 0.0),
        "the last control tick's desired motion is reported: {desired:?}"
    );
    let [roll, pitch, _] = run.sim.roll_pitch_yaw();
    assert!(
        roll.abs().to_degrees() < 5.0 && pitch.abs().to_degrees() < 5.0,
        "roll {roll} pitch {pitch}"
    );
}

#[test]
fn aligned_thrusters_are_reported_with_heave_sway_roll_unactuated() {
    let mut run = Run::new("aligned", NoisePreset::Paper, 2);
    run.run_for(1.0);
    run.estimate();
    let model = run.machine.model().expect("a model");
    assert_eq!(model.actuated.names(), vec!["pitch", "yaw", "surge"]);
    for dof in [0, 4, 5] {
        assert_eq!(model.allocation.column(dof).norm(), 0.0);
    }
}

#[test]
fn imu_gap_mid_pulse_faults_to_neutral_and_recovers() {
    let mut run = Run::new("amour5", NoisePreset::Realistic, 3);
    run.run_for(1.0);
    run.machine.on_request(Request::Estimate).unwrap();
    run.run_until(10.0, |m| m.state() == State::Pulse);
    assert_eq!(run.machine.state(), State::Pulse);
    // The driver goes silent: the IO layer's deadline fires.
    let cmd = run.machine.on_imu_stale("no IMU sample for 100 ms");
    assert_eq!(cmd.mode, Mode::Neutral);
    assert!(cmd.thrust.iter().all(|v| *v == 0.0));
    assert_eq!(run.machine.state(), State::Fault);
    assert!(
        run.machine.on_request(Request::Estimate).is_err(),
        "no estimation while blind"
    );
    // Samples return after 0.5 s (a gap in their timestamps too): still neutral for a while...
    run.sim.set_commands(&[0.0; 5]).unwrap();
    run.sim.step_secs(0.5);
    run.tick();
    assert_eq!(run.machine.state(), State::Fault);
    assert_eq!(run.last_mode, Mode::Neutral);
    // ...then the interrupted estimation restarts from the noise measurement.
    run.run_for(0.2);
    assert_eq!(run.machine.state(), State::MeasureNoise);
    let events = run.machine.take_events();
    assert!(events.iter().any(|e| matches!(
        e,
        Event::StateChanged {
            to: State::Fault,
            ..
        }
    )));
}

#[test]
fn reconfiguration_swaps_nominal_at_once_then_refines_and_cache_swaps_back() {
    let v = vehicle("amour5");
    let geometry = |v: &Vehicle| Geometry {
        positions: v.thrusters.iter().map(|t| t.position_m).collect(),
        directions: v.thrusters.iter().map(|t| t.direction).collect(),
    };
    let mut run = Run::new("amour5", NoisePreset::Realistic, 4);
    run.run_for(1.0);
    run.machine.on_reconfig(Reconfig {
        count: 5,
        geometry: Some(geometry(&v)),
        change: thrusterd_core::machine::ThrusterChange::Unknown,
        what: "declared".into(),
    });
    let nominal = run.machine.model().unwrap().clone();
    assert_eq!(nominal.source, ModelSource::Nominal);
    assert_eq!(
        run.machine.state(),
        State::MeasureNoise,
        "re-estimation starts at once"
    );
    run.run_until(120.0, |m| m.state() == State::Active);
    let learned = run.machine.model().unwrap().clone();
    assert_eq!(learned.source, ModelSource::Estimated);
    assert!(learned.version > nominal.version);

    // Rotate the top thruster 45 degrees (declared): a new nominal, a new estimation.
    let mut moved = geometry(&v);
    let r = UnitQuaternion::from_euler_angles(45f64.to_radians(), 0.0, 0.0);
    moved.directions[0] = (r * nalgebra::Vector3::from(moved.directions[0])).into();
    run.machine.on_reconfig(Reconfig {
        count: 5,
        geometry: Some(moved),
        change: thrusterd_core::machine::ThrusterChange::Moved(0),
        what: "top thruster rotated".into(),
    });
    assert_eq!(run.machine.model().unwrap().source, ModelSource::Nominal);
    run.machine.on_request(Request::Abort).unwrap();

    // Back to the original layout: the learned model returns from the cache, no pulses.
    run.machine.on_reconfig(Reconfig {
        count: 5,
        geometry: Some(geometry(&v)),
        change: thrusterd_core::machine::ThrusterChange::Moved(0),
        what: "top thruster back".into(),
    });
    let back = run.machine.model().unwrap();
    assert_eq!(back.source, ModelSource::Cache);
    assert_eq!(back.effectiveness, learned.effectiveness);
    assert!(!run.machine.state().is_estimating());
}

#[test]
fn count_change_without_geometry_drops_the_model_until_estimated() {
    let mut run = Run::new("amour5", NoisePreset::Realistic, 5);
    run.run_for(1.0);
    run.estimate();
    assert!(run.machine.model().is_some());
    run.machine.on_reconfig(Reconfig {
        count: 4,
        geometry: None,
        change: thrusterd_core::machine::ThrusterChange::Unknown,
        what: "thruster removed".into(),
    });
    assert!(
        run.machine.model().is_none(),
        "a 5-thruster model cannot drive 4 thrusters"
    );
    assert!(run
        .machine
        .take_events()
        .iter()
        .any(|e| matches!(e, Event::ModelDropped(_))));
    assert_eq!(run.machine.thrusters(), 4);
    assert_eq!(run.machine.state(), State::MeasureNoise);
}

/// Pitch manoeuvres (alternating +-20 degrees every 4 s at the current heading) for `seconds`;
/// the mismatch reports seen, with their vehicle time.
fn pitch_manoeuvres(run: &mut Run, seconds: f64) -> Vec<(f64, String)> {
    pitch_steps(run, seconds, 4.0, [20.0, -20.0])
}

/// Pitch setpoints alternating between `pitches` (degrees) every `every_s`, at the current
/// heading and depth, for `seconds` or until the machine leaves Active; the mismatch reports
/// seen, with their vehicle time.
fn pitch_steps(run: &mut Run, seconds: f64, every_s: f64, pitches: [f64; 2]) -> Vec<(f64, String)> {
    let yaw = run.sim.roll_pitch_yaw()[2];
    let depth = run.sim.position_ned().z;
    let start = run.sim.time_s();
    let mut seen = Vec::new();
    let mut step = 0;
    while run.sim.time_s() - start < seconds {
        let t = run.sim.time_s() - start;
        if t >= every_s * step as f64 {
            let pitch: f64 = pitches[step % 2];
            run.machine.on_setpoint(
                UnitQuaternion::from_euler_angles(0.0, pitch.to_radians(), yaw),
                Some(depth),
            );
            step += 1;
        }
        run.tick();
        for e in run.machine.take_events() {
            if let Event::MismatchDetected(why) = e {
                seen.push((run.sim.time_s(), why));
            }
        }
        if run.machine.state() != State::Active {
            break;
        }
    }
    seen
}

/// The model-mismatch monitor on the real physics with a realistic IMU: with the learned model
/// it stays quiet through 24 s of pitch manoeuvres (righting moment, drag, the model's own
/// after the top thruster is silently rotated 45 degrees it fires within
/// seconds (measured 1.3-6.0 s over seeds 1-6), the daemon re-estimates, and the new model
/// matches the new truth. The 10 s limit leaves room for a slower seed.
///
/// Run on a model learned by the static forward method: with an accurate model in control the
/// monitor is slower. Measured over seeds 1-6 (a run forcing each model in after the first
/// estimation): dynamic-learned 6.2 / 10.6 / 9.7 s and seed 4 not within 30 s; the simulator's
/// true model 6.2-6.9 s on four seeds, 21.0 and 25.5 s on two. So the slowdown comes with an
/// accurate model, not from the dynamic estimator as such; why the monitor's test loses power
/// then is not measured yet (docs/experiments.md).
#[test]
fn silent_rotation_of_the_top_thruster_is_detected_and_re_estimated() {
    for seed in [1, 2] {
        let mut run = Run::forward("amour5", NoisePreset::Realistic, seed);
        run.run_for(1.0);
        run.estimate();
        run.machine.take_events();
        let quiet = pitch_manoeuvres(&mut run, 24.0);
        assert!(quiet.is_empty(), "seed {seed}: false alarm {quiet:?}");
        assert_eq!(run.machine.state(), State::Active);

        let changed_at = run.sim.time_s();
        run.rotate_top();
        let seen = pitch_manoeuvres(&mut run, 30.0);
        let (t, why) = seen.first().expect("the rotation was not detected");
        let delay = t - changed_at;
        println!("seed {seed}: detected after {delay:.1} s: {why}");
        assert!(delay < 10.0, "seed {seed}: detection took {delay:.1} s");
        assert!(run.machine.state().is_estimating());
        run.run_until(120.0, |m| m.state() == State::Active);
        let model = run.machine.model().unwrap().clone();
        assert_eq!(model.source, ModelSource::Estimated);
        let e_rot = rel_err(&model.effectiveness, &run.truth(), 0);
        assert!(
            e_rot < 0.3,
            "seed {seed}: re-learned rotation error {e_rot:.3}"
        );
    }
}

/// At the paper's very noisy IMU the monitor must not cry wolf: 60 s of pitch manoeuvres with
/// an unchanged vehicle raise no mismatch (8 seeds measured quiet; lower thresholds than the
/// default z = 10 raised false alarms in 2 of them).
#[test]
fn at_the_papers_noise_an_unchanged_vehicle_raises_no_mismatch() {
    for seed in [5, 6] {
        let mut run = Run::new("amour5", NoisePreset::Paper, seed);
        run.run_for(1.0);
        run.estimate();
        run.machine.take_events();
        let seen = pitch_manoeuvres(&mut run, 60.0);
        assert!(seen.is_empty(), "seed {seed}: false alarm {seen:?}");
        assert_eq!(run.machine.state(), State::Active);
    }
}

/// The 11-minute soak's situation in-process: the paper's noise at 1 kHz, the hold toggling
/// between level and 10 degrees of pitch every 20 s. A new operating point is no changed
/// thruster: before the monitor split forward and reverse thrust this raised a "mismatch" at
/// the first toggle (z 12 against the then threshold of 10) and the soak re-estimated twice for
/// nothing; split, this run peaks at z 9.1 (seeds 2 and 3: 3.4, 2.7) against the default 15.
#[test]
fn a_new_operating_point_is_not_a_mismatch() {
    let mut run = Run::with_rate("amour5", NoisePreset::Paper, 1, 1000.0);
    run.run_for(1.0);
    run.estimate();
    run.machine.take_events();
    let seen = pitch_steps(&mut run, 120.0, 20.0, [0.0, 10.0]);
    assert!(seen.is_empty(), "false alarm {seen:?}");
    assert_eq!(run.machine.state(), State::Active);
}

/// With closed-loop identification off: an estimation requested while the daemon holds a 20
/// degree pitch first levels the vehicle
/// with the model in force (thrusters driven, state MeasureNoise), then measures the noise with
/// the thrusters neutral and the vehicle level and at rest, then pulses; without levelling
/// (`level_max_s = 0`) the thrusters go neutral at once, with the vehicle still pitched.
#[test]
fn an_estimation_started_mid_manoeuvre_levels_the_vehicle_first() {
    for level in [true, false] {
        let mut run = Run::new("amour5", NoisePreset::Realistic, 3);
        let mut setup = MachineSetup {
            thrusters: 5,
            ..MachineSetup::default()
        };
        setup.machine.deadband = 0.05;
        // The open-loop path (closed-loop identification off; see closed_loop.rs for it).
        setup.identification.closed_loop = false;
        if !level {
            setup.machine.level_max_s = 0.0;
        }
        run.machine = Machine::new(setup);
        run.run_for(1.0);
        run.estimate();
        pitch_steps(&mut run, 6.0, 10.0, [20.0, 20.0]);
        let pitch = run.sim.roll_pitch_yaw()[1].to_degrees();
        assert!(pitch > 12.0, "holding the pitch: {pitch:.1} deg");
        run.machine.on_request(Request::Estimate).unwrap();
        assert_eq!(run.machine.state(), State::MeasureNoise);
        // Through the noise measurement: the largest tilt once the thrusters went neutral,
        // and whether they were driven before.
        let (mut driven, mut tilt_at_rest) = (false, 0.0f64);
        while run.machine.state() == State::MeasureNoise {
            run.tick();
            if run.last_mode == Mode::Controlling {
                driven = true;
            } else {
                let [r, p, _] = run.sim.roll_pitch_yaw();
                tilt_at_rest = tilt_at_rest.max(r.abs().max(p.abs()).to_degrees());
            }
        }
        assert_eq!(run.machine.state(), State::Pulse);
        if level {
            assert!(driven, "levelling drives the thrusters");
            assert!(
                tilt_at_rest < 8.0,
                "noise measured {tilt_at_rest:.1} deg from level"
            );
        } else {
            assert!(!driven);
            assert!(tilt_at_rest > 10.0, "{tilt_at_rest:.1} deg");
        }
    }
}

/// With the declared geometry as the model in force, the first pulse is only as strong as the
/// measured noise needs: with a realistic IMU the 0.2 floor (the vehicle tilts less than half
/// as far and the model comes out better, measured 17 vs 43 deg and 0.12 vs 0.16 error by
/// `cargo run --release -p thrusterd-core --example pulse_power_study`), at the paper's noise the
/// configured 0.8 as before.
#[test]
fn with_a_declared_geometry_the_pulses_are_as_strong_as_the_noise_needs() {
    for (noise, want_power) in [(NoisePreset::Realistic, 0.2), (NoisePreset::Paper, 0.8)] {
        let v = vehicle("amour5");
        let sensors = SensorConfig {
            rate_hz: 200.0,
            noise,
            ..SensorConfig::default()
        };
        let mut setup = MachineSetup {
            thrusters: 5,
            geometry: Some(Geometry {
                positions: v.thrusters.iter().map(|t| t.position_m).collect(),
                directions: v.thrusters.iter().map(|t| t.direction).collect(),
            }),
            // Pulse sizing is the static methods' (the dynamic one pulses at a fixed strength).
            estimator: EstimatorConfig::forward(),
            ..MachineSetup::default()
        };
        setup.machine.deadband = 0.05;
        let mut run = Run {
            machine: Machine::new(setup),
            sim: Simulator::new(v, sensors, 2).unwrap(),
            last_mode: Mode::Neutral,
            max_abs_cmd: 0.0,
        };
        run.run_for(1.0);
        run.machine.on_request(Request::Estimate).unwrap();
        let mut tilt = 0.0f64;
        let mut power = None;
        while run.machine.state() != State::Active {
            run.tick();
            if run.machine.state() == State::Pulse {
                power.get_or_insert(run.machine.status().power);
            }
            let [r, p, _] = run.sim.roll_pitch_yaw();
            tilt = tilt.max(r.abs().max(p.abs()).to_degrees());
            assert!(run.sim.time_s() < 120.0, "no model");
        }
        let power = power.expect("pulsed");
        assert!(
            (power - want_power).abs() < 1e-9,
            "{noise:?}: power {power}"
        );
        let e_rot = rel_err(&run.machine.model().unwrap().effectiveness, &run.truth(), 0);
        println!("{noise:?}: power {power}, tilt {tilt:.0} deg, error {e_rot:.3}");
        if want_power < 0.5 {
            assert!(tilt < 25.0, "tilt {tilt:.0} deg");
            assert!(e_rot < 0.16, "rotation error {e_rot:.3}");
        }
    }
}

/// `thrusterctl setpoint --pitch 10`: the angles left out keep what is held. Against the
/// simulator's true attitude: the vehicle pitches to 10 deg, and its heading and roll stay
/// where they were held (first the held level at the start heading, then a 30 deg turn kept
/// through a later pitch-only change).
#[test]
fn a_setpoint_with_angles_left_out_keeps_the_held_ones() {
    use thrusterd_core::machine::SetpointInput;
    let mut run = Run::new("amour5", NoisePreset::Realistic, 5);
    // The mismatch monitor only reports here: holding 10 deg of pitch against the restoring
    // moment, which the static model leaves out, it calls a re-estimation (issue 11's bias),
    // and this test is about which angles are held.
    let mut setup = MachineSetup {
        thrusters: 5,
        ..MachineSetup::default()
    };
    setup.machine.deadband = 0.05;
    setup.monitor.action = thrusterd_core::monitor::MismatchAction::Report;
    run.machine = Machine::new(setup);
    run.run_for(1.0);
    run.estimate();
    run.run_for(5.0);
    let heading = run.sim.roll_pitch_yaw()[2];
    let only = |pitch: Option<f64>, yaw: Option<f64>| SetpointInput {
        attitude: UnitQuaternion::from_euler_angles(
            0.0,
            pitch.unwrap_or(0.0).to_radians(),
            yaw.unwrap_or(0.0).to_radians(),
        ),
        keep: [true, pitch.is_none(), yaw.is_none()],
        depth: thrusterd_core::machine::DepthInput::Keep,
    };
    run.machine.on_setpoint_input(&only(Some(10.0), None));
    run.run_for(10.0);
    let [roll, pitch, yaw] = run.sim.roll_pitch_yaw();
    let deg = f64::to_degrees;
    let wrap = |a: f64| {
        (a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
    };
    assert!((deg(pitch) - 10.0).abs() < 3.0, "pitch {}", deg(pitch));
    assert!(deg(roll).abs() < 3.0, "roll {}", deg(roll));
    assert!(
        deg(wrap(yaw - heading)).abs() < 5.0,
        "heading moved {}",
        deg(wrap(yaw - heading))
    );
    // Turn to heading + 30 deg, pitch kept at 10; then level pitch, heading kept.
    let turned = deg(heading) + 30.0;
    run.machine.on_setpoint_input(&only(None, Some(turned)));
    run.run_for(10.0);
    run.machine.on_setpoint_input(&only(Some(0.0), None));
    run.run_for(10.0);
    assert_eq!(run.machine.state(), State::Active);
    let [_, pitch, yaw] = run.sim.roll_pitch_yaw();
    assert!(deg(pitch).abs() < 3.0, "pitch {}", deg(pitch));
    assert!(
        deg(wrap(yaw - turned.to_radians())).abs() < 5.0,
        "heading {} vs {turned}",
        deg(yaw)
    );
}
