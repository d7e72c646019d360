//! Closed-loop identification in one process, against the simulator's truth: AMOUR-5's top
//! thruster is rotated 45 degrees and announced while the machine holds level; the machine
//! swaps in the new geometry's nominal model, keeps holding with it and learns the new model
//! from a dither on top of the controller's commands (`thrusterd_core::identification`).
//! In-process runs are deterministic: the numbers in the comments are what these seeds gave.

mod common;
use common::{vehicle, Reestimation, Run};
use thruster_sim::NoisePreset;
use thrusterd_core::machine::{Mode, State};
use thrusterd_core::model::ModelSource;

/// First model open loop, then hold level for 3 s, then the announced rotation.
fn rotate_while_holding(noise: NoisePreset, seed: u64) -> (Run, Reestimation) {
    let v = vehicle("amour5");
    let mut run = Run::new("amour5", noise, seed);
    run.run_for(1.0);
    run.estimate();
    run.run_for(3.0);
    assert_eq!(run.machine.state(), State::Active);
    let r = run.announced_rotation(&v);
    assert_eq!(
        r.source,
        ModelSource::Estimated,
        "{noise:?} seed {seed}: {r:?}"
    );
    (run, r)
}

/// Noise-free the fit is exact up to the navigation: measured 0.003 / 0.006 of the truth in
/// 5.0 s (1 s holding, then 4 s of dither, the minimum), never more than 3.6 deg from level.
/// Before the command was fitted with the sample that ends its interval (one sample late),
/// this gave 0.10 / 0.08; with an uncoded random dither, 9-14 deg of tilt.
#[test]
fn noise_free_the_model_learned_under_control_matches_the_truth() {
    let (_, r) = rotate_while_holding(NoisePreset::None, 1);
    assert!(r.err_rot < 0.01 && r.err_acc < 0.02, "{r:?}");
    assert!(r.took_s < 6.5, "{r:?}");
    assert!(r.max_tilt_deg < 5.0, "{r:?}");
}

/// With a realistic IMU: measured over seeds 1-5 0.007 / 0.037 in 5.0 s, 3.9 deg of largest
/// tilt, 2.1 deg mean error (the open-loop re-estimation tilted it 16-22 deg).
#[test]
fn with_a_realistic_imu_it_stays_near_level_and_learns_within_a_few_percent() {
    for seed in [1, 2] {
        let (run, r) = rotate_while_holding(NoisePreset::Realistic, seed);
        assert!(r.err_rot < 0.03 && r.err_acc < 0.08, "seed {seed}: {r:?}");
        assert!(r.took_s < 10.0, "seed {seed}: {r:?}");
        assert!(r.max_tilt_deg < 6.0, "seed {seed}: {r:?}");
        assert!(r.mean_err_deg < 4.0, "seed {seed}: {r:?}");
        // The thrusters were driven all along: control never let go.
        assert!(run.max_abs_cmd <= 1.0);
    }
}

/// At the paper's noise (0.25 rad/s gyro) the dither is sized up to 0.6 of full command and
/// the 5 % target is still out of reach within the 20 s limit; the best fit is then swapped in.
/// Measured over seeds 1-5: 0.048 / 0.108 after 21 s (worst seed 0.054 on the rotation rows),
/// 7.9 deg of largest tilt, 5.9 deg mean error, of which ~4.5 deg is the noise's own (holding
/// with no dither at all). With the quiet-IMU amplitude of 0.3: 0.081 / 0.159 at 5.1 deg.
#[test]
fn at_the_papers_noise_the_limit_swaps_the_best_fit_still_near_level() {
    let (_, r) = rotate_while_holding(NoisePreset::Paper, 1);
    assert!(r.err_rot < 0.1 && r.err_acc < 0.2, "{r:?}");
    assert!(r.took_s < 23.0, "{r:?}");
    assert!(r.max_tilt_deg < 10.0, "{r:?}");
}

/// The identification is a state of its own, thrusters driven throughout (never neutral),
/// and an abort keeps holding with the model in force instead of letting go.
#[test]
fn identification_keeps_control_and_an_abort_keeps_holding() {
    let mut run = Run::new("amour5", NoisePreset::Realistic, 3);
    run.run_for(1.0);
    run.estimate();
    run.run_for(2.0);
    run.machine
        .on_request(thrusterd_core::machine::Request::Estimate)
        .unwrap();
    assert_eq!(run.machine.state(), State::Identify);
    let t0 = run.sim.time_s();
    while run.sim.time_s() - t0 < 2.0 {
        run.tick();
        assert_eq!(run.last_mode, Mode::Estimating);
        assert_eq!(run.machine.state(), State::Identify);
    }
    let version = run.machine.model().unwrap().version;
    let reply = run
        .machine
        .on_request(thrusterd_core::machine::Request::Abort)
        .unwrap();
    assert!(reply.contains("holding"), "{reply}");
    assert_eq!(run.machine.state(), State::Active);
    assert_eq!(run.machine.model().unwrap().version, version);
    run.run_for(1.0);
    assert_eq!(run.last_mode, Mode::Controlling);
}

/// From scratch with `identification.burst_rel_err = 0.15` at the paper's noise: the open-loop
/// pulses stop after the minimum cycle, the coarse model is swapped in, and the estimation goes
/// on under control. Measured over seeds 1-5: first model after 4.4 s (open loop to the 5 %
/// target: 8.1 s), final model after 25.4 s at 0.051 / 0.089 (open loop: 0.056 / 0.063), largest
/// tilt 22.4 deg during the pulses (open loop: 23.8) and 11.2 deg under control (the vehicle
/// still swings from the pulses when control begins). Not the default: the first cycle already
/// tilts the vehicle as far as the whole open-loop run, and the final model comes 17 s later.
/// With a realistic IMU the first cycle reaches the target and there is nothing to refine.
#[test]
fn from_scratch_a_burst_then_identification_under_control() {
    use nalgebra::Vector3;
    use thrusterd_core::machine::{Machine, MachineSetup, Request};
    for (noise, refines) in [(NoisePreset::Paper, true), (NoisePreset::Realistic, false)] {
        let mut run = Run::new("amour5", noise, 1);
        let mut setup = MachineSetup {
            thrusters: 5,
            ..MachineSetup::default()
        };
        setup.machine.deadband = 0.05;
        setup.identification.burst_rel_err = 0.15;
        run.machine = Machine::new(setup);
        run.run_for(1.0);
        run.machine.on_request(Request::Estimate).unwrap();
        let t0 = run.sim.time_s();
        let (mut first, mut identified, mut tilt_closed) = (None, false, 0.0f64);
        while run.sim.time_s() - t0 < 60.0 && run.machine.state() != State::Active {
            run.tick();
            if first.is_none() && run.machine.model().is_some() {
                first = Some(run.sim.time_s() - t0);
            }
            if run.machine.state() == State::Identify {
                identified = true;
                let down = run.sim.attitude().inverse() * Vector3::z();
                tilt_closed = tilt_closed.max(down.z.clamp(-1.0, 1.0).acos().to_degrees());
            }
        }
        let took = run.sim.time_s() - t0;
        let model = run.machine.model().unwrap().clone();
        let err = common::rel_err(&model.effectiveness, &run.truth(), 0);
        println!("{noise:?}: first model {first:?} s, final {took:.1} s, err {err:.3}, tilt under control {tilt_closed:.1}");
        assert_eq!(identified, refines, "{noise:?}");
        assert_eq!(model.source, ModelSource::Estimated);
        assert!(
            first.unwrap() < if refines { 5.5 } else { 5.0 },
            "{first:?}"
        );
        assert!(err < 0.1, "{noise:?}: {err}");
        if refines {
            assert!(took > 15.0 && took < 30.0, "{took}");
            assert!(tilt_closed < 20.0, "{tilt_closed}");
        }
    }
}

/// Under control the commands take every level around zero, so forward and reverse thrust are
/// fitted apart (the open-loop doublets drive every thruster at the same +-p, which makes the
/// |command| column common to all thrusters and the split unidentifiable): a thruster weak in
/// reverse is diagnosed. AMOUR-5's LB gives 20 N in reverse instead of the T200's 40.2 N
/// (ratio 0.39 of its 51.5 N forward, the others 0.78). Measured reverse/forward ratios, seed
/// 1: noise-free [0.759, 0.396, 0.782, 0.772, 0.775]; realistic IMU [0.837, 0.411, 0.809, 0.777, 0.728].
#[test]
fn under_control_a_thruster_weak_in_reverse_is_diagnosed() {
    use thrusterd_core::machine::Request;
    for noise in [NoisePreset::None, NoisePreset::Realistic] {
        let mut v = vehicle("amour5");
        v.thrusters[1].reverse_max_n = 20.0;
        let mut run = Run::with_vehicle(v, noise, 1, 200.0);
        run.run_for(1.0);
        run.estimate();
        run.run_for(3.0);
        run.machine.on_request(Request::Estimate).unwrap();
        assert_eq!(run.machine.state(), State::Identify);
        run.run_until(40.0, |m| m.state() == State::Active);
        let e = run.machine.last_estimate().expect("an estimate");
        let ratios: Vec<f64> = e
            .thruster
            .iter()
            .map(|d| d.reverse_gain_ratio.expect("a split fit"))
            .collect();
        println!("{noise:?}: reverse/forward gain {ratios:.3?}");
        let t200 = 40.2 / 51.5;
        for (i, r) in ratios.iter().enumerate() {
            let want = if i == 1 { 20.0 / 51.5 } else { t200 };
            assert!(
                (r - want).abs() < 0.08,
                "{noise:?}: thruster {i}: {r:.3}, truth {want:.3}"
            );
        }
        assert!(e.thruster[1].asymmetric);
    }
}

/// An operator's estimate is refused, with the reason and the key to change, while the vehicle
/// is beyond the identification's attitude budget (here right after a 30 deg pitch setpoint),
/// and accepted once it has settled.
#[test]
fn an_estimate_beyond_the_attitude_budget_is_refused_with_the_reason() {
    use nalgebra::UnitQuaternion;
    use thrusterd_core::machine::Request;
    let mut run = Run::new("amour5", NoisePreset::Realistic, 2);
    run.run_for(1.0);
    run.estimate();
    run.run_for(2.0);
    let yaw = run.sim.roll_pitch_yaw()[2];
    run.machine.on_setpoint(
        UnitQuaternion::from_euler_angles(0.0, 30f64.to_radians(), yaw),
        None,
    );
    run.run_for(0.05);
    let refused = run.machine.on_request(Request::Estimate).unwrap_err();
    assert!(
        refused.0.contains("identification.attitude_budget_deg")
            && refused.0.contains("deg from its setpoint"),
        "{}",
        refused.0
    );
    assert_eq!(run.machine.state(), State::Active);
    run.run_for(6.0);
    run.machine.on_request(Request::Estimate).unwrap();
    assert_eq!(run.machine.state(), State::Identify);
}
