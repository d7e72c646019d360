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
use thrusterd_core::refinement::RefinementConfig;

fn holding(noise: NoisePreset, seed: u64) -> Run {
    holding_with(noise, seed, RefinementConfig::default())
}

/// [`holding`] with the refinement's settings replaced.
fn holding_with(noise: NoisePreset, seed: u64, refinement: RefinementConfig) -> Run {
    let mut run = Run::new("amour5", noise, seed);
    let mut setup = MachineSetup {
        thrusters: 5,
        refinement,
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
    pitch_scored(run, seconds).0
}

/// [`pitch_until_mismatch`], and the mean angle between the true attitude and the setpoint
/// over the samples flown, deg.
fn pitch_scored(run: &mut Run, seconds: f64) -> (Option<(f64, String)>, f64) {
    let (mut sum, mut k) = (0.0, 0u64);
    let found = pitch_with(run, seconds, |sp, run| {
        sum += run.sim.attitude().angle_to(sp).to_degrees();
        k += 1;
    });
    (found, sum / k.max(1) as f64)
}

fn pitch_with(
    run: &mut Run,
    seconds: f64,
    mut each: impl FnMut(&UnitQuaternion<f64>, &Run),
) -> Option<(f64, String)> {
    let yaw = run.sim.roll_pitch_yaw()[2];
    let depth = run.sim.position_ned().z;
    let start = run.sim.time_s();
    let mut step = 0;
    let mut sp = UnitQuaternion::identity();
    while run.sim.time_s() - start < seconds {
        let t = run.sim.time_s() - start;
        if t >= 4.0 * step as f64 {
            let p: f64 = [20.0, -20.0][step % 2];
            sp = UnitQuaternion::from_euler_angles(0.0, p.to_radians(), yaw);
            run.machine.on_setpoint(sp, Some(depth));
            step += 1;
        }
        run.tick();
        each(&sp, run);
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

/// The refinement's dither against detection and hold at a given noise: for each seed, 120 s
/// of pitch steps on the unchanged vehicle (a false alarm ends it), then the top thruster
/// rotated and up to 120 s more. Prints the first alarm, the detection time and the mean
/// angle from the setpoint. A measuring tool; knobs RF_NOISE (paper, realistic), RF_SEEDS
/// (comma list), RF_DITHER (comma list). Run with
/// `cargo test --release -p thrusterd-core --test refinement -- --ignored dither_sweep --nocapture`.
#[test]
#[ignore]
fn dither_sweep() {
    let noise = match std::env::var("RF_NOISE").as_deref() {
        Ok("realistic") => NoisePreset::Realistic,
        _ => NoisePreset::Paper,
    };
    let list = |key: &str, default: &str| -> Vec<f64> {
        std::env::var(key)
            .unwrap_or_else(|_| default.into())
            .split(',')
            .map(|v| v.trim().parse().unwrap_or_else(|_| panic!("{key}: {v}")))
            .collect()
    };
    for dither in list("RF_DITHER", "0.1") {
        let (mut found_sum, mut found_n, mut alarms, mut err_sum) = (0.0, 0, 0, 0.0);
        let seeds = list("RF_SEEDS", "1,2,3,4");
        for &seed in &seeds {
            let cfg = RefinementConfig {
                dither,
                ..RefinementConfig::default()
            };
            let mut run = holding_with(noise, seed as u64, cfg);
            let (quiet, err) = pitch_scored(&mut run, 120.0);
            err_sum += err;
            let found = if quiet.is_none() {
                rotate_top(&mut run);
                pitch_until_mismatch(&mut run, 120.0)
            } else {
                alarms += 1;
                None
            };
            if let Some((t, _)) = &found {
                found_sum += t;
                found_n += 1;
            }
            println!(
                "dither {dither} seed {seed}: false alarm {:?}, found after {:?}, mean error {err:.2} deg",
                quiet.map(|q| q.0),
                found.map(|f| f.0)
            );
        }
        println!(
            "dither {dither}: {alarms} false alarms in {} x 120 s, found in {found_n} (mean {:.1} s), mean error {:.2} deg",
            seeds.len(),
            found_sum / found_n.max(1) as f64,
            err_sum / seeds.len() as f64
        );
    }
}
