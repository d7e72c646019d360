//! The emergency stop (`Request::Stop`, `RequestKind::Stop` on the wire) against the simulator:
//! from Active, Pulse and Identify the very next command (the next IMU sample: one control
//! period) is neutral, all zeros; the vehicle then stays neutral through what would otherwise
//! start the thrusters again (a declared reconfiguration, a fault that clears) until an
//! operator asks for hold or estimate.

use nalgebra::UnitQuaternion;
use thruster_sim::NoisePreset;
use thrusterd_core::machine::{Mode, Reconfig, Request, State, ThrusterChange};

mod common;
use common::{geometry, vehicle, Run};

/// The next command after the stop, and a second of commands after it: all neutral.
fn assert_neutral_from_the_next_sample(run: &mut Run, from: State) {
    assert_eq!(run.machine.state(), from);
    let before = run.max_abs_cmd;
    assert!(
        before > 0.0,
        "{from:?}: the thrusters were driven before the stop"
    );
    let reply = run.machine.on_request(Request::Stop).unwrap();
    assert!(reply.contains("emergency stop"), "{reply}");
    assert_eq!(run.machine.state(), State::Idle, "{from:?}");
    // One control period: the next sample's command.
    run.max_abs_cmd = 0.0;
    run.tick();
    assert_eq!(run.last_mode, Mode::Neutral, "{from:?}");
    assert_eq!(
        run.max_abs_cmd, 0.0,
        "{from:?}: the first command after the stop"
    );
    run.run_for(1.0);
    assert_eq!(run.last_mode, Mode::Neutral, "{from:?}");
    assert_eq!(run.max_abs_cmd, 0.0, "{from:?}: a second after the stop");
    assert!(run.machine.status().text.contains("emergency stop"));
}

#[test]
fn a_stop_is_neutral_within_one_control_period_from_active_pulse_and_identify() {
    // Active: holding with a learned model.
    let mut run = Run::new("amour5", NoisePreset::Realistic, 3);
    run.run_for(1.0);
    run.estimate();
    run.run_for(1.0);
    assert_eq!(run.last_mode, Mode::Controlling);
    assert_neutral_from_the_next_sample(&mut run, State::Active);
    // The model stays: hold resumes control.
    run.machine.on_request(Request::Hold).unwrap();
    run.run_for(0.5);
    assert_eq!(run.last_mode, Mode::Controlling);

    // Identify: estimating under control (dither on the controller's commands).
    run.machine.on_request(Request::Estimate).unwrap();
    run.run_for(0.5);
    assert_eq!(run.last_mode, Mode::Estimating);
    assert_neutral_from_the_next_sample(&mut run, State::Identify);

    // Pulse: an open-loop estimation from scratch, mid-pulse.
    let mut run = Run::new("amour5", NoisePreset::Realistic, 4);
    run.run_for(1.0);
    run.machine.on_request(Request::Estimate).unwrap();
    run.run_until(10.0, |m| m.state() == State::Pulse);
    run.run_for(0.1);
    assert_neutral_from_the_next_sample(&mut run, State::Pulse);
}

#[test]
fn after_a_stop_nothing_starts_the_thrusters_until_an_operator_asks() {
    let v = vehicle("amour5");
    let mut run = Run::new("amour5", NoisePreset::Realistic, 5);
    run.run_for(1.0);
    run.estimate();
    run.machine.on_request(Request::Stop).unwrap();
    // A declared reconfiguration would re-estimate (pulses); after a stop it only swaps in
    // the nominal model.
    let mut moved = geometry(&v);
    let r = UnitQuaternion::from_euler_angles(45f64.to_radians(), 0.0, 0.0);
    moved.directions[0] = (r * nalgebra::Vector3::from(moved.directions[0])).into();
    run.machine.on_reconfig(Reconfig {
        count: 5,
        geometry: Some(moved),
        change: ThrusterChange::Moved(0),
        what: "top thruster rotated".into(),
    });
    assert_eq!(run.machine.state(), State::Idle);
    run.max_abs_cmd = 0.0;
    run.run_for(1.0);
    assert_eq!(run.max_abs_cmd, 0.0, "thrust after a reconfiguration");
    // A fault that clears: idle again, not the hold it interrupted.
    run.machine.on_imu_stale("no IMU sample for 100 ms");
    assert_eq!(run.machine.state(), State::Fault);
    run.run_for(1.0);
    assert_eq!(run.machine.state(), State::Idle);
    assert_eq!(run.max_abs_cmd, 0.0, "thrust after a fault cleared");
    // Stop in any state, Fault included, is answered OK.
    run.machine.on_imu_stale("no IMU sample for 100 ms");
    assert!(run.machine.on_request(Request::Stop).is_ok());
    run.run_for(1.0);
    assert_eq!(run.machine.state(), State::Idle);
    // The operator's estimate clears the stop: pulses again.
    run.machine.on_request(Request::Estimate).unwrap();
    run.run_until(10.0, |m| m.state() == State::Pulse);
    run.run_for(0.2);
    assert!(run.max_abs_cmd > 0.0);
}
