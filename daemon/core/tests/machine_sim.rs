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

/// AMOUR-5 at the paper's noise (0.25 rad/s, 0.05 g), seeds 1-10 (in-process runs are
/// deterministic): the learned model (the default dynamic method) against the truth, the
/// vehicle time to it, and 5 s of attitude hold with it after.
///
/// Measured (`cargo test -p thrusterd-core --test machine_sim -- --nocapture amour5_`):
/// rotation error 0.043-0.082 (mean 0.057), acceleration 0.045-0.082 (mean 0.064), 6.6-8.2
/// vehicle s (mean 7.4), tilt after 5 s of hold at most 1.9 deg. Bounds at 1.5x: worst seed
/// 0.12 / 0.12, mean 0.085 / 0.095 (a 2x regression of the typical seed fails the mean even
/// where one seed's noise would hide it), tilt 3 deg. The time is issue 11's target of 8
/// vehicle s on the mean, 9 s for the worst seed (pulses come in 0.4 s steps; 1.5x would
/// accept 12 s, far beyond the target). (The static model needed 25 %: it carried a 12-23 %
/// bias from drag and restoring moment.)
#[test]
fn amour5_estimation_at_the_papers_noise_matches_truth() {
    let (mut sum_rot, mut sum_acc, mut sum_t) = (0.0, 0.0, 0.0);
    let seeds = 1..=10u64;
    for seed in seeds.clone() {
        let mut run = Run::new("amour5", NoisePreset::Paper, seed);
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
            "amour5/paper seed {seed}: {t:.1} vehicle s, {} pulses, err rot {e_rot:.3} acc {e_acc:.3}",
            est.pulses
        );
        assert_eq!(run.machine.state(), State::Active, "seed {seed}");
        assert_eq!(model.source, ModelSource::Estimated, "seed {seed}");
        assert!(e_rot < 0.12, "seed {seed}: rotation error {e_rot}");
        assert!(e_acc < 0.12, "seed {seed}: acceleration error {e_acc}");
        assert!(t < 9.0, "seed {seed}: {t:.1} vehicle s");
        assert_eq!(
            model.actuated.names(),
            vec!["roll", "pitch", "yaw", "surge", "heave"],
            "seed {seed}"
        );
        (sum_rot, sum_acc, sum_t) = (sum_rot + e_rot, sum_acc + e_acc, sum_t + t);
        // Then it holds attitude: 5 s of control keep roll and pitch within a few degrees.
        run.run_for(5.0);
        assert_eq!(run.last_mode, Mode::Controlling);
        let desired = run.machine.last_desired();
        assert!(
            desired.iter().all(|v| v.is_finite()) && desired.iter().any(|v| *v != 0.0),
            "the last control tick's desired motion is reported: {desired:?}"
        );
        let [roll, pitch, _] = run.sim.roll_pitch_yaw();
        println!(
            "  after 5 s of hold: roll {:.2} pitch {:.2} deg",
            roll.to_degrees(),
            pitch.to_degrees()
        );
        assert!(
            roll.abs().to_degrees() < 3.0 && pitch.abs().to_degrees() < 3.0,
            "seed {seed}: roll {roll} pitch {pitch}"
        );
    }
    let n = seeds.count() as f64;
    let (rot, acc, t) = (sum_rot / n, sum_acc / n, sum_t / n);
    println!("mean over seeds: err rot {rot:.3} acc {acc:.3}, {t:.2} vehicle s");
    assert!(rot < 0.085, "mean rotation error {rot:.3}");
    assert!(acc < 0.095, "mean acceleration error {acc:.3}");
    assert!(t < 8.0, "mean time to the model {t:.2} vehicle s");
}

/// Dead and reversed thrusters on the default path: the dynamic method through the machine,
/// against the simulator's physics, with the declared geometry as the model in force (what
/// "reversed" is judged against). AMOUR-5 with thruster 4 (R) dead and thruster 1 (LB) spinning
/// the wrong way (its thrust along +z where the vehicle file declares -z): the estimate names
/// exactly those two, and the learned model matches the changed truth.
///
/// Measured (`cargo test -p thrusterd-core --test machine_sim -- --nocapture dead_`): every
/// seed names dead [4] and reversed [1]; the reversed thruster's gain along its declared
/// direction -0.81 to -0.89 (the others +0.81 to +0.90); rotation error noise-free 0.012,
/// realistic IMU 0.004-0.036, paper's noise 0.054-0.080 (seeds 1-5). Bounds at 1.5x the worst:
/// 0.018, 0.054, 0.12.
///
/// Asymmetric forward/reverse gains on the default path: the first estimation (open-loop
/// pulses) reports no forward/reverse split (`reverse_gain_ratio` None on every thruster, also
/// with a thruster weak in reverse: measured); a re-estimation under control does, tested in
/// `closed_loop.rs`'s `under_control_a_thruster_weak_in_reverse_is_diagnosed`.
#[test]
fn dead_and_reversed_thrusters_are_diagnosed_by_the_default_method() {
    use thruster_sim::Action;
    let cases = [
        (NoisePreset::None, 1..=1u64, 0.018),
        (NoisePreset::Realistic, 1..=5, 0.054),
        (NoisePreset::Paper, 1..=5, 0.12),
    ];
    for (noise, seeds, bound) in cases {
        for seed in seeds {
            let v = vehicle("amour5");
            let mut run = Run::with_vehicle(v.clone(), noise, seed, 200.0);
            let mut setup = MachineSetup {
                thrusters: 5,
                geometry: Some(common::geometry(&v)),
                ..MachineSetup::default()
            };
            setup.machine.deadband = 0.05;
            run.machine = Machine::new(setup);
            run.sim
                .apply(&Action::Kill {
                    thruster: "R".into(),
                })
                .unwrap();
            run.sim
                .apply(&Action::SetDirection {
                    thruster: "LB".into(),
                    direction: [0.0, 0.0, 1.0],
                })
                .unwrap();
            run.run_for(1.0);
            run.estimate();
            assert_eq!(run.machine.state(), State::Active, "{noise:?} seed {seed}");
            let e = run.machine.last_estimate().expect("an estimate");
            let dead: Vec<usize> = e
                .thruster
                .iter()
                .filter(|d| d.dead)
                .map(|d| d.index)
                .collect();
            let reversed: Vec<usize> = e
                .thruster
                .iter()
                .filter(|d| d.reversed == Some(true))
                .map(|d| d.index)
                .collect();
            let gains: Vec<f64> = e
                .thruster
                .iter()
                .map(|d| {
                    d.nominal_gain
                        .expect("judged against the declared geometry")
                })
                .collect();
            let err = rel_err(&run.machine.model().unwrap().effectiveness, &run.truth(), 0);
            println!(
                "{noise:?} seed {seed}: dead {dead:?} reversed {reversed:?} gains {gains:.2?} rotation error {err:.3}"
            );
            assert_eq!(dead, vec![4], "{noise:?} seed {seed}");
            assert_eq!(reversed, vec![1], "{noise:?} seed {seed}");
            assert!(gains[1] < -0.5, "{noise:?} seed {seed}: {gains:?}");
            assert!(
                [0, 2, 3].iter().all(|&i| gains[i] > 0.5),
                "{noise:?} seed {seed}: {gains:?}"
            );
            assert!(
                err < bound,
                "{noise:?} seed {seed}: rotation error {err:.3}"
            );
        }
    }
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

/// An estimation is told as three changes of state (it starts, it pulses, it ends), whatever
/// number of pulses and settles lie between: those are phases (`next_phase`), seen in the
/// status text, not events. The end comes from Solve, the phase the concluding solve is in.
#[test]
fn an_estimation_announces_its_start_its_pulses_and_its_end_and_nothing_between() {
    let mut run = Run::new("amour5", NoisePreset::Realistic, 2);
    run.run_for(1.0);
    run.machine.take_events();
    run.machine.on_request(Request::Estimate).unwrap();
    let mut texts = Vec::new();
    let mut changes = Vec::new();
    let start = run.sim.time_s();
    while run.sim.time_s() - start < 30.0 && run.machine.state() != State::Active {
        run.tick();
        texts.push(run.machine.status().text);
        for e in run.machine.take_events() {
            if let Event::StateChanged { from, to, .. } = e {
                changes.push((from, to));
            }
        }
    }
    assert_eq!(run.machine.state(), State::Active, "no model in 30 s");
    assert_eq!(
        changes,
        vec![
            (State::Idle, State::MeasureNoise),
            (State::MeasureNoise, State::Pulse),
            (State::Solve, State::Active),
        ]
    );
    // The default dynamic run pulses back to back (no settles): many pulses, one event.
    let mut pulses: Vec<&String> = texts.iter().filter(|t| t.starts_with("pulse ")).collect();
    pulses.dedup();
    assert!(pulses.len() > 10, "pulses seen in status: {pulses:?}");
}

/// Issue 30: an estimation asked for from idle adopts the rest the vehicle already took
/// (`machine.rest_from_idle`, on by default) and pulses at the next sample; idle for less than
/// `noise_s`, or just after a reconfiguration (the vehicle was handled), it still measures the
/// noise for `noise_s` after the start. The figures are vehicle seconds in MeasureNoise.
#[test]
fn an_estimation_asked_for_from_idle_pulses_on_the_rest_already_taken() {
    let noise_s = MachineSetup::default().machine.noise_s;
    // Vehicle seconds from the start of the estimation to its first pulse.
    let to_first_pulse = |run: &mut Run| {
        let start = run.sim.time_s();
        run.run_until(5.0, |m| m.state() == State::Pulse);
        assert_eq!(run.machine.state(), State::Pulse, "no pulse in 5 s");
        run.sim.time_s() - start
    };
    let mut run = Run::new("amour5", NoisePreset::Realistic, 2);
    run.run_for(1.5);
    run.machine.on_request(Request::Estimate).unwrap();
    let waited = to_first_pulse(&mut run);
    assert!(
        waited <= 0.006,
        "idle 1.5 s: first pulse after {waited:.3} s"
    );
    // The model it makes is as good as with the rest measured after the request.
    run.run_until(30.0, |m| m.state() == State::Active);
    let err = rel_err(&run.machine.model().unwrap().effectiveness, &run.truth(), 0);
    assert!(err <= 0.03, "err_rot {err:.4}");

    let mut run = Run::new("amour5", NoisePreset::Realistic, 2);
    run.run_for(0.5);
    run.machine.on_request(Request::Estimate).unwrap();
    let waited = to_first_pulse(&mut run);
    assert!(
        (noise_s..noise_s + 0.02).contains(&waited),
        "idle 0.5 s: first pulse after {waited:.3} s"
    );

    let mut run = Run::new("amour5", NoisePreset::Realistic, 2);
    run.run_for(3.0);
    run.machine.on_reconfig(Reconfig {
        count: 5,
        geometry: None,
        change: thrusterd_core::machine::ThrusterChange::Unknown,
        what: "thrusters changed".into(),
    });
    assert_eq!(run.machine.state(), State::MeasureNoise);
    let waited = to_first_pulse(&mut run);
    assert!(
        (noise_s..noise_s + 0.02).contains(&waited),
        "after a reconfiguration: first pulse after {waited:.3} s"
    );
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

/// A silent change on the default path (the dynamic method, the mismatch monitor, the
/// refinement's windows and its change test, as shipped) on the real physics with a realistic
/// IMU, seeds 1-6: with the learned model it stays quiet through 24 s of pitch manoeuvres
/// (righting moment, drag, the model's own imperfection); after the top thruster is silently
/// rotated 45 degrees a mismatch is reported, the daemon re-estimates under control, and the
/// new model matches the new truth.
///
/// Measured (`cargo test -p thrusterd-core --test machine_sim -- --nocapture silent_`):
/// detected after 1.3-5.8 s (seed 2 by the monitor, 1, 3 and 6 by a refinement window, 4 and
/// 5 by the change test), re-learned in 5.0 s, rotation error 0.010-0.030. Bounds at 1.5x the
/// worst seed: 8.8 s, 7.5 s, 0.045.
///
/// The monitor alone (refinement off) on the dynamic model is weaker: over the same seeds it
/// fired after 6.1, 10.8, 29.1, 6.4 and 7.1 s and not within 30 s on seed 4 (on a model the
/// static forward method learned, as this test ran before: 1.3-6.0 s over seeds 1-6). With an
/// accurate model in control the monitor's test loses power; why is not measured yet
/// (docs/experiments.md).
#[test]
fn silent_rotation_of_the_top_thruster_is_detected_and_re_estimated() {
    for seed in 1..=6 {
        let mut run = Run::new("amour5", NoisePreset::Realistic, seed);
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
        assert!(run.machine.state().is_estimating());
        let took = run.run_until(120.0, |m| m.state() == State::Active);
        let model = run.machine.model().unwrap().clone();
        assert_eq!(model.source, ModelSource::Estimated);
        let e_rot = rel_err(&model.effectiveness, &run.truth(), 0);
        println!(
            "seed {seed}: detected after {delay:.1} s ({why}), re-learned in {took:.1} s, rotation error {e_rot:.3}"
        );
        assert!(delay < 8.8, "seed {seed}: detection took {delay:.1} s");
        assert!(took < 7.5, "seed {seed}: re-estimation took {took:.1} s");
        assert!(
            e_rot < 0.045,
            "seed {seed}: re-learned rotation error {e_rot:.3}"
        );
    }
}

/// A swell is not a moved thruster, for the monitor either (issue 32 item 5). AMOUR-5 learns in
/// still water at a realistic IMU, then the water comes up (moderate: 0.3 m/s current, 10 N /
/// 1 Nm at 0.15 Hz) and it flies +-20 deg pitch steps with every detector as shipped: the
/// change test and the monitor calibrated against the water once the sea-state gauge says the
/// vehicle is in a sea (`calibrate_when = "in_a_sea"`, the default since 2026-12-01).
/// Uncalibrated (`monitor.calibration_s = 0`), the monitor takes the thruster coefficients'
/// wandering with the wave for a change (measured: seed 1 after 33.2 s; 77 of 78 mismatches in
/// 6 vehicle-hours of the soak); as shipped none in 3 minutes, and the rotated top thruster is
/// still found (by the refinement's windows, 6.4 s) and learned again (0.039).
/// `cargo test -p thrusterd-core --test machine_sim -- --nocapture swell`.
#[test]
fn in_a_swell_the_calibrated_monitor_is_quiet_and_a_rotated_thruster_is_still_found() {
    use thruster_inprocess::holding::pitch_with;
    use thruster_sim::disturbance::WaterPreset;
    let in_the_swell = |monitor_calibration_s: Option<f64>| {
        let mut run = Run::new("amour5", NoisePreset::Realistic, 1);
        run.with_setup(|c| {
            let when = thrusterd_core::adaptation::calibrate_when::CalibrateWhen::InASea;
            assert_eq!(c.monitor.calibration_s, 120.0, "the shipped default");
            assert_eq!(c.monitor.calibrate_when, when, "the shipped default");
            assert_eq!(
                c.refinement.change_calibrate_when, when,
                "the shipped default"
            );
            if let Some(s) = monitor_calibration_s {
                c.monitor.calibration_s = s;
            }
            // As found: on a first model fitted to the thrust's shape the uncalibrated monitor
            // raised nothing in this minute (seed 1).
            common::bare_first_model(c);
        });
        run.learn_then_water(WaterPreset::Moderate);
        run
    };
    let (t, why) = pitch_with(&mut in_the_swell(Some(0.0)), 60.0, |_, _| {})
        .expect("uncalibrated: no false alarm in the swell (the decisive run is gone)");
    println!("uncalibrated: a false alarm after {t:.1} s: {why}");
    assert!(
        why.contains("thrust-driven motion"),
        "not the monitor's: {why}"
    );

    let mut run = in_the_swell(None);
    let quiet = pitch_with(&mut run, 180.0, |_, _| {});
    assert!(quiet.is_none(), "calibrated: false alarm {quiet:?}");
    assert!(run.machine.in_a_sea(), "the swell not taken for a sea");
    run.rotate_top();
    let (t, why) = pitch_with(&mut run, 30.0, |_, _| {}).expect("rotation not found");
    println!("calibrated: the rotated top thruster found after {t:.1} s: {why}");
    assert!(t < 12.0, "{t:.1} s: {why}");
    run.run_until(60.0, |m| m.state() == State::Active);
    let e_rot = rel_err(&run.machine.model().unwrap().effectiveness, &run.truth(), 0);
    println!("learned again: rotation rows {e_rot:.3} off");
    assert!(e_rot < 0.045, "re-learned rotation error {e_rot:.3}");
}

/// The sea-state gauge (`identification/sea_state.rs`, which decides whether an identification
/// under control instruments its fit and whether a low dither share refuses it) reads the
/// water on the axes the model actuates only. four_up (four vertical thrusters: yaw and sway
/// unactuated) held level for 60 s in still water read 3.8-4.1 deg on the whole angle, above
/// `identification.min_sea_state_deg` (3), and 22-30 deg in a 0.3 m/s current that turns its
/// heading; on the actuated axes 0.9-1.0 and under 0.1 (`LH_VEHICLES=four_up LH_LEVEL=1
/// LH_MINUTES=3 cargo run --release -p thrusterctl -- study sweep lost_hold_soak`).
#[test]
fn the_sea_state_gauge_reads_the_actuated_axes_only() {
    use thruster_inprocess::holding::level_with;
    use thruster_sim::disturbance::WaterPreset;
    let limit = MachineSetup::default().identification.min_sea_state_deg;
    for water in [WaterPreset::Still, WaterPreset::Current] {
        let mut run = Run::new("four_up", NoisePreset::Realistic, 1);
        run.learn_then_water(water);
        let alarm = level_with(&mut run, 60.0, |_| {});
        assert!(alarm.is_none(), "{water:?}: {alarm:?}");
        let sea = run
            .machine
            .sea_state_deg()
            .expect("measured after 60 s held");
        println!("four_up {water:?}: sea state {sea:.2} deg");
        assert!(sea < limit / 2.0, "{water:?}: {sea:.2} deg read as water");
    }
}

/// Through +-20 deg pitch steps every 4 s the gauge reads the water, not the steps: AMOUR-5's
/// own ringing 3-4 s after each step (3-5 deg) read 4.4 deg in still water, above the limit,
/// and the identification after a silent change instrumented its fit (once 0.158 off under a
/// bound of 0.052). Now only what follows a step's transient counts (`sea_state`): still
/// water is not known or calm, moderate water a sea (every vehicle file: still 1.4 deg or not
/// known, moderate 7.5-12.4, `LH_MINUTES=3 cargo run --release -p thrusterctl -- study sweep
/// lost_hold_soak`). So the detectors' calibrations, which apply in a sea, stay off in still
/// water (where they would only cost) and keep moderate water's false alarms from ending the
/// run early.
#[test]
fn through_pitch_steps_the_sea_state_gauge_reads_the_water_not_the_steps() {
    use thruster_inprocess::holding::pitch_with;
    use thruster_sim::disturbance::WaterPreset;
    let limit = MachineSetup::default().identification.min_sea_state_deg;
    for water in [WaterPreset::Still, WaterPreset::Moderate] {
        let mut run = Run::new("amour5", NoisePreset::Realistic, 1);
        run.learn_then_water(water);
        let mut seas = 0;
        let alarm = pitch_with(&mut run, 90.0, |_, r| {
            seas += usize::from(r.machine.in_a_sea())
        });
        assert!(alarm.is_none(), "{water:?}: {alarm:?}");
        let sea = run.machine.sea_state_deg();
        println!(
            "amour5 through the steps, {water:?}: sea state {sea:?} deg, in a sea on {seas} ticks"
        );
        match water {
            WaterPreset::Still => {
                assert!(
                    sea.is_none_or(|d| d < limit / 2.0),
                    "still water read {sea:?} deg"
                );
                assert_eq!(seas, 0, "still water taken for a sea");
            }
            _ => {
                assert!(
                    sea.is_some_and(|d| d > 2.0 * limit),
                    "moderate water read {sea:?} deg"
                );
                assert!(run.machine.in_a_sea(), "moderate water not taken for a sea");
            }
        }
    }
}

/// A swell's false alarms must not keep the vehicle from being taken to be in a sea. At the
/// paper's noise the change test's first alarm in moderate water comes before the gauge can
/// read it through the steps (7.9 s here), and each alarm starts an identification under
/// control. Two things kept the vehicle out of a sea: the gauge counted from each
/// identification's end as from a new start of control (5 s `SETTLE_S`), so between alarms it
/// counted 0-0.6 s in 4 minutes; and an identification that found no change (its model within
/// its bounds of the old, or refused at the limit) did not count as evidence of the water.
/// Before: 7 alarms in these 180 s, never in a sea (AMOUR-5 seed 3: 23 in 20 minutes;
/// `LH_TRACE=1 LH_WHY=1 LH_WATER=moderate LH_NOISE=paper LH_SEEDS=3 LH_VEHICLES=amour5 cargo
/// run --release -p thrusterctl -- study sweep lost_hold_soak`). With the gauge counting
/// through identifications alone: 4 alarms, in a sea from 99 s. Now: the first alarm's
/// identification finds nothing (0.016 / 0.053 from the old model under bounds of 0.043 /
/// 0.060), the vehicle is taken to be in a sea from then (23.9 s), and no alarm follows.
#[test]
fn a_swells_false_alarms_do_not_keep_the_vehicle_out_of_a_sea() {
    use thruster_inprocess::holding::PitchSteps;
    use thruster_sim::disturbance::WaterPreset;
    let mut run = Run::new("amour5", NoisePreset::Paper, 3);
    run.learn_then_water(WaterPreset::Moderate);
    let mut plan = PitchSteps::new(&run);
    let start = run.sim.time_s();
    let (mut alarms, mut in_a_sea_at, mut after) = (Vec::new(), None, 0);
    let mut counted_at_60 = None;
    while run.sim.time_s() - start < 180.0 {
        let t = run.sim.time_s() - start;
        plan.at(&mut run, t);
        run.tick();
        if run.machine.in_a_sea() {
            in_a_sea_at.get_or_insert(t);
        }
        if t >= 60.0 {
            counted_at_60.get_or_insert(run.machine.sea_state_counted_s());
        }
        for e in run.machine.take_events() {
            if let Event::MismatchDetected(why) = e {
                println!("{t:.1} s: {why}");
                alarms.push(t);
                after += usize::from(in_a_sea_at.is_some());
            }
        }
    }
    let counted = counted_at_60.unwrap_or(0.0);
    println!(
        "{} false alarms, in a sea from {in_a_sea_at:?} s, {after} after; the gauge counted {counted:.1} s by 60 s",
        alarms.len()
    );
    let entered = in_a_sea_at.expect("moderate water never taken for a sea");
    assert!(entered < 40.0, "taken for a sea only after {entered:.1} s");
    assert!(alarms.len() <= 2, "false alarms at {alarms:?} s");
    assert_eq!(after, 0, "false alarms in a sea at {alarms:?} s");
    assert!(
        counted >= 1.0,
        "the gauge counted {counted:.1} s of the hold by 60 s"
    );
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
/// `cargo run --release -p thrusterctl -- study pulse-power`), at the paper's noise the
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
            latency_us: None,
            supply_report_ns: None,
            next_report_ns: 0,
            truth_voltage_v: None,
            perfect_dvl: false,
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
    setup.monitor.action = thrusterd_core::adaptation::monitor::MismatchAction::Report;
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

/// A pulse limit that cuts the excitation's cycle (`estimator.max_pulses` below it): the
/// pulses so far cannot tell every thruster's column apart, and the model is refused as not
/// excited apart, the thrusters left neutral. Before (`ExcitationPlan::confounded`),
/// eight_vectored stopped at 16 pulses noise-free came out 0.71 off under a 0.02 bound and
/// was swapped in; at 28 pulses, 0.33 off under 0.03. At the whole cycle (32) it is
/// swapped in as always; AMOUR-5 at 20 pulses (five Hadamard rows span its five thrusters)
/// too, within its bound.
#[test]
fn a_pulse_limit_short_of_the_cycle_is_refused_not_swapped_in() {
    for (name, max_pulses, swapped) in [
        ("eight_vectored", 16, false),
        ("eight_vectored", 28, false),
        ("eight_vectored", 32, true),
        ("amour5", 20, true),
    ] {
        let mut run = Run::new(name, NoisePreset::None, 1);
        run.with_setup(|s| s.estimator.max_pulses = max_pulses);
        run.run_for(1.0);
        run.machine.on_request(Request::Estimate).unwrap();
        let mut rejected = None;
        let mut model = None;
        run.run_until(30.0, |m| m.state() == State::Active);
        for e in run.machine.take_events() {
            match e {
                Event::ModelRejected(why) => rejected = Some(why),
                Event::ModelSwapped(m) => model = Some(m),
                _ => {}
            }
        }
        let text = run.machine.status().text;
        println!("{name} at {max_pulses}: {text}");
        if swapped {
            let m = model.expect("swapped in");
            let err = rel_err(&m.effectiveness, &run.truth(), 3);
            assert!(
                err <= 2.0 * m.rel_err_rot.max(0.02),
                "{err} under {}",
                m.rel_err_rot
            );
        } else {
            assert!(model.is_none(), "{text}");
            assert!(
                text.contains("not apart from each other") && text.contains("model rejected"),
                "{text} / {rejected:?}"
            );
            assert_ne!(run.machine.state(), State::Active, "{text}");
        }
    }
}
