//! Continuous refinement in one process, against the simulator's truth: while the machine
//! holds AMOUR-5 through pitch manoeuvres, the background fit (`thrusterd_core::refinement`)
//! must stay quiet on an unchanged vehicle and find the top thruster rotated 45 degrees, at a
//! realistic IMU and at the paper's (where the older monitor is blind by design). The monitor's
//! own test is off here (infinite threshold), so every mismatch is the refinement's.
//!
//! Measured (in-process runs are deterministic). With one window deciding and a 0.4 share, a
//! 10-minute soak through the processes at the paper's noise (1 kHz, pitch toggled 0/10 deg
//! every 20 s) re-estimated 10 times on an unchanged vehicle, and in process 1.3-4 false alarms
//! per 180 s appeared (1 kHz and 200 Hz, seeds 1-3). Now a change must hold in two windows in a
//! row (or score chi2 > 200 in one) and move the column by 55 %: no false alarm in the same
//! 9 x 180 s; a rotation found after 2.9 s and 7.9 s with a realistic IMU (seeds 1, 4; a window
//! that straddles the change moves the column less, so the next one decides) and after 49.5 s
//! at the paper's noise (seed 4). With the estimator's honest (larger) standard errors since:
//! 8.9 s and 7.9 s, and 79.9 s at the paper's noise.
mod common;
use common::Run;
use nalgebra::UnitQuaternion;
use thruster_sim::NoisePreset;
use thrusterd_core::machine::{Event, Machine, MachineSetup, State};
use thrusterd_core::monitor::MismatchAction;

fn holding(noise: NoisePreset, seed: u64) -> Run {
    let mut run = Run::new("amour5", noise, seed);
    let mut setup = MachineSetup {
        thrusters: 5,
        ..MachineSetup::default()
    };
    setup.machine.deadband = 0.05;
    // The monitor's own test never fires (infinite threshold); its action still decides what
    // a mismatch does: re-estimate.
    setup.monitor.action = MismatchAction::Estimate;
    setup.monitor.z = f64::INFINITY;
    run.machine = Machine::new(setup);
    run.run_for(1.0);
    run.estimate();
    run.machine.take_events();
    run
}

/// Pitch steps of +-20 deg every 4 s for `seconds`; the first mismatch's time, if any.
fn pitch_until_mismatch(run: &mut Run, seconds: f64) -> Option<(f64, String)> {
    let yaw = run.sim.roll_pitch_yaw()[2];
    let depth = run.sim.position_ned().z;
    let start = run.sim.time_s();
    let mut step = 0;
    while run.sim.time_s() - start < seconds {
        let t = run.sim.time_s() - start;
        if t >= 4.0 * step as f64 {
            let p: f64 = [20.0, -20.0][step % 2];
            run.machine.on_setpoint(
                UnitQuaternion::from_euler_angles(0.0, p.to_radians(), yaw),
                Some(depth),
            );
            step += 1;
        }
        run.tick();
        for e in run.machine.take_events() {
            if let Event::MismatchDetected(why) = e {
                return Some((t, why));
            }
        }
        assert_eq!(
            run.machine.state(),
            State::Active,
            "left control at {t:.1} s"
        );
    }
    None
}

fn rotate_top(run: &mut Run) {
    run.sim
        .apply(&thruster_sim::Action::Rotate {
            thruster: "T".into(),
            axis: [1.0, 0.0, 0.0],
            angle_deg: 45.0,
        })
        .unwrap();
}

#[test]
fn with_a_realistic_imu_a_rotated_thruster_is_found_within_seconds_and_nothing_else() {
    for seed in [1, 4] {
        let mut run = holding(NoisePreset::Realistic, seed);
        let quiet = pitch_until_mismatch(&mut run, 60.0);
        assert!(quiet.is_none(), "seed {seed}: false alarm {quiet:?}");
        assert!(run.machine.refinement().is_some(), "no window ended");
        rotate_top(&mut run);
        let (t, why) = pitch_until_mismatch(&mut run, 30.0).expect("rotation not found");
        println!("seed {seed}: found after {t:.1} s: {why}");
        // One 5 s window after the one that straddles the change: 10 s.
        assert!(t < 10.0, "seed {seed}: {t:.1} s");
        assert!(why.contains("thruster 1"), "{why}");
        // The mismatch starts a re-estimation, under control.
        assert_eq!(run.machine.state(), State::Identify);
    }
}

#[test]
fn at_the_papers_noise_a_rotated_thruster_is_found_and_an_unchanged_one_is_not() {
    let mut run = holding(NoisePreset::Paper, 4);
    let quiet = pitch_until_mismatch(&mut run, 120.0);
    assert!(quiet.is_none(), "false alarm {quiet:?}");
    rotate_top(&mut run);
    // Measured 79.9 s: 30 s windows (the honest standard errors keep the bound above
    // `window_rel_err` until the limit), and the change must show in two of them.
    let (t, why) = pitch_until_mismatch(&mut run, 120.0).expect("rotation not found");
    println!("found after {t:.1} s: {why}");
    assert!(why.contains("thruster 1"), "{why}");
}

/// Holding through the soak's manoeuvres (pitch 0 / 10 deg every 20 s) at 1 kHz and the
/// paper's noise, with the shipped settings (monitor included): nothing changed, so nothing may
/// be reported. This is where one window deciding failed (see the module docs).
#[test]
fn at_1_khz_and_the_papers_noise_an_unchanged_vehicle_raises_no_alarm_in_three_minutes() {
    for seed in 1..=3 {
        let mut run = Run::with_rate("amour5", NoisePreset::Paper, seed, 1000.0);
        run.machine = Machine::new(MachineSetup {
            thrusters: 5,
            ..MachineSetup::default()
        });
        run.run_for(1.0);
        run.estimate();
        run.machine.take_events();
        let yaw = run.sim.roll_pitch_yaw()[2];
        let depth = run.sim.position_ned().z;
        let start = run.sim.time_s();
        let mut step = 0;
        let mut windows = 0;
        while run.sim.time_s() - start < 180.0 {
            let t = run.sim.time_s() - start;
            if t >= 20.0 * step as f64 {
                let p: f64 = [10.0, 0.0][step % 2];
                run.machine.on_setpoint(
                    UnitQuaternion::from_euler_angles(0.0, p.to_radians(), yaw),
                    Some(depth),
                );
                step += 1;
            }
            let before = run.machine.refinement().copied();
            run.tick();
            if run.machine.refinement().copied() != before {
                windows += 1;
            }
            for e in run.machine.take_events() {
                assert!(
                    !matches!(e, Event::MismatchDetected(_)),
                    "seed {seed}: false alarm at {t:.1} s: {e:?}"
                );
            }
            assert_eq!(
                run.machine.state(),
                State::Active,
                "seed {seed} at {t:.1} s"
            );
        }
        // The refinement judged the whole time (a window every 5-30 s), it did not sleep.
        assert!(windows >= 6, "seed {seed}: only {windows} windows in 180 s");
    }
}
