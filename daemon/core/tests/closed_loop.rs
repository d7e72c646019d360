//! Closed-loop identification in one process, against the simulator's truth: AMOUR-5's top
//! thruster is rotated 45 degrees and announced while the machine holds level; the machine
//! swaps in the new geometry's nominal model, keeps holding with it and learns the new model
//! from a dither on top of the controller's commands (`thrusterd_core::adaptation::identification`).
//! In-process runs are deterministic: the numbers in the comments are what these seeds gave.

mod common;
use common::{
    env_list, rotate_while_holding_in, rotate_while_holding_on, rotate_while_holding_with,
    swell_phase, vehicle, Reestimation, Run,
};
use thruster_sim::NoisePreset;
use thrusterd_core::adaptation::identification::IdentificationConfig;
use thrusterd_core::machine::{Machine, MachineSetup, Mode, State};
use thrusterd_core::model::ModelSource;

/// First model open loop, then hold level for 3 s, then the announced rotation.
fn rotate_while_holding(noise: NoisePreset, seed: u64) -> (Run, Reestimation) {
    let (run, r) = rotate_while_holding_with(noise, seed, None, |_, _| {});
    assert_eq!(
        r.source,
        ModelSource::Estimated,
        "{noise:?} seed {seed}: {r:?}"
    );
    (run, r)
}

/// Noise-free the fit is exact up to the navigation: measured 0.003 / 0.005 of the truth in
/// 3.5 s (0.5 s holding, `identification.lead_in_s`, then 3 s of dither), never more than 4
/// deg from level (0.005 / 0.007 in 4.0 s with the 1 s hold of before).
/// Before the command was fitted with the sample that ends its interval (one sample late),
/// this gave 0.10 / 0.08; with an uncoded random dither, 9-14 deg of tilt.
#[test]
fn noise_free_the_model_learned_under_control_matches_the_truth() {
    let (_, r) = rotate_while_holding(NoisePreset::None, 1);
    assert!(r.err_rot < 0.01 && r.err_acc < 0.02, "{r:?}");
    assert!(r.took_s < 6.5, "{r:?}");
    assert!(r.max_tilt_deg < 5.0, "{r:?}");
}

/// eight_vectored under control, noise-free. With the 1 s hold before the dither of before
/// 2026-12-02 the navigation started 1.4 deg off the true tilt (the hold's mean specific
/// force: the vehicle turned and accelerated while held on the new geometry's nominal model)
/// and the acceleration rows came out 0.029 off at 5.0 s; after the 0.5 s lead-in
/// (`identification.lead_in_s`) 0.002 / 0.010 at 3.5 s.
#[test]
fn noise_free_eight_vectored_under_control_matches_the_truth() {
    let v = vehicle("eight_vectored");
    let run = Run::new("eight_vectored", NoisePreset::None, 1);
    let (_, r) = rotate_while_holding_on(run, &v, None, |_, _| {});
    assert_eq!(r.source, ModelSource::Estimated, "{r:?}");
    assert!(r.err_rot < 0.01 && r.err_acc < 0.02, "{r:?}");
    assert!(r.took_s < 4.0, "{r:?}");
}

/// With a realistic IMU: measured over seeds 1-10 0.013 / 0.019 in 5.0 s, 4.1 deg of largest
/// tilt, 1.8 deg mean error (the open-loop re-estimation tilted it 16-22 deg).
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

/// At the paper's noise (0.25 rad/s gyro). The announcement names the moved thruster, so the
/// other columns and the hull's dynamics are kept from the first model
/// (`identification::carry_over`) and the dither goes to the moved thruster at full command,
/// the others at 0.1 of the amplitude. Measured over seeds 1-10 (the geometry announced from the
/// centre of mass, as a driver does, 2026-11-30): the new model after 11.2 s (8-15 s), 0.054 /
/// 0.060 off the truth, 8.6 deg of largest tilt, 5.7 deg mean error. Seeds 1 and 2: 9 and 12 s
/// (a decision every second, applied 20 ms later).
/// Learning everything anew (carry_over off), the 5 % target is out of reach within the 20 s
/// limit and the best fit is swapped in at 21 s: 0.047 / 0.110 over seeds 1-5 (docs/experiments.md).
#[test]
fn at_the_papers_noise_a_known_change_is_learned_within_12_s_near_level() {
    for seed in [1, 2] {
        let (_, r) = rotate_while_holding(NoisePreset::Paper, seed);
        assert!(r.err_rot < 0.07 && r.err_acc < 0.09, "seed {seed}: {r:?}");
        assert!(r.took_s <= 12.1, "seed {seed}: {r:?}");
        assert!(r.max_tilt_deg < 10.0, "seed {seed}: {r:?}");
    }
    let everything = IdentificationConfig {
        carry_over: false,
        ..IdentificationConfig::default()
    };
    let (_, r) = rotate_while_holding_with(NoisePreset::Paper, 1, Some(everything), |_, _| {});
    assert!(r.took_s > 20.0, "learning every column anew: {r:?}");
    assert!(r.err_rot < 0.1 && r.err_acc < 0.2, "{r:?}");
}

/// The announcement names the wrong thruster (1, while the top thruster 0 turned): the data
/// contradicts the carried-over column of thruster 0 and it is learned anew instead of pinned.
#[test]
fn a_change_announced_for_the_wrong_thruster_is_not_pinned_on_the_old_column() {
    use thrusterd_core::machine::ThrusterChange;
    for noise in [NoisePreset::None, NoisePreset::Realistic] {
        let v = vehicle("amour5");
        let mut run = Run::new("amour5", noise, 1);
        run.run_for(1.0);
        run.estimate();
        run.run_for(3.0);
        let r = run.announced_rotation_as(&v, ThrusterChange::Moved(1), |_, _| {});
        println!("{noise:?}: {r:?}");
        assert_eq!(r.source, ModelSource::Estimated, "{noise:?}: {r:?}");
        assert!(r.err_rot < 0.05 && r.err_acc < 0.08, "{noise:?}: {r:?}");
    }
}

/// Without some dither on the thrusters the prior covers, their commands are the controller's
/// reaction to the motion alone, confounded with the damping and restoring terms: noise-free
/// the fit then ended 0.037 / 0.025 off the truth after 9 s, against 0.003 / 0.008 after 5 s
/// with 0.1 of the amplitude (re-measured 2026-12-01 with the fit's lags started where the
/// thrusters are; before, 0.034 / 0.048 and 0.005 / 0.016).
#[test]
fn noise_free_the_thrusters_the_prior_covers_keep_some_dither() {
    let none = IdentificationConfig {
        focus_others: 0.0,
        ..IdentificationConfig::default()
    };
    let (_, without) = rotate_while_holding_with(NoisePreset::None, 1, Some(none), |_, _| {});
    let (_, r) = rotate_while_holding(NoisePreset::None, 1);
    println!("no dither on the others: {without:?}\nthe default: {r:?}");
    assert!(r.err_rot < 0.01 && r.err_acc < 0.02, "{r:?}");
    assert!(
        without.err_rot > 0.02 && without.err_rot > 4.0 * r.err_rot,
        "no dither on the others: {without:?}"
    );
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
    use thrusterd_core::machine::Request;
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
/// (ratio 0.39 of its 51.5 N forward, the others 0.78). Measured reverse/forward ratios
/// (`cargo test -p thrusterd-core --test closed_loop -- --nocapture weak_in_reverse`), seed 1,
/// with the stop decided once a segment: noise-free [0.811, 0.367, 0.809, 0.800, 0.795];
/// realistic IMU [0.822, 0.395, 0.789, 0.736, 0.781]. Since it is decided every 0.1 s after
/// the settle wait (`identification.late_decision_s`), the runs end 0.6-0.9 s sooner:
/// noise-free [0.775, 0.384, 0.781, 0.756, 0.772], realistic [0.774, 0.420, 0.768, 0.695,
/// 0.777] (standard errors 0.012-0.020). LB's ratio is within 0.032 of the truth on seeds
/// 1-5; the others' worst error 0.086 (seed 1's thruster 3, 4.3 standard errors: the ratio's
/// error is not covered by its standard error; noise-free the same thruster is 0.025 off at
/// 5), so LB is held to 0.07 and the others to 0.12, well apart from LB's 0.39.
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
        let ses: Vec<f64> = e
            .thruster
            .iter()
            .map(|d| d.reverse_gain_ratio_se.expect("a split fit"))
            .collect();
        println!("{noise:?}: reverse/forward gain {ratios:.3?} se {ses:.3?}");
        let t200 = 40.2 / 51.5;
        for (i, r) in ratios.iter().enumerate() {
            let (want, within) = if i == 1 {
                (20.0 / 51.5, 0.07)
            } else {
                (t200, 0.12)
            };
            assert!(
                (r - want).abs() < within,
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

/// The model in force after `rotate_while_holding_in` against its own bounds: (error / bound)
/// for the rotation and acceleration rows.
fn coverage(run: &Run, r: &Reestimation) -> (f64, f64) {
    let m = run.machine.model().unwrap();
    (r.err_rot / m.rel_err_rot, r.err_acc / m.rel_err_acc)
}

/// In rough water (current 0.5 m/s, a 0.15 Hz swell of 20 N and 2 Nm) AMOUR-5 cannot be held
/// within the identification's attitude budget: the dither fades out and the commands are
/// mostly the controller answering the swell (dither share 0.11-0.19, the held vehicle's sea
/// state 16.5 deg RMS). Without the share check (seeds 1-5, re-measured 2026-12-01 with the
/// fit's lags started where the thrusters are, `estimator::dynamic::spin_state`):
/// - noise-free, by least squares (`instrument = never`) 0.079 / 0.034 under a bound of
///   0.039 / 0.027 (2.0x), instrumented 0.037 / 0.014 under 0.024 / 0.051 (1.5x);
/// - at a realistic IMU least squares is within its bound (at most 1.14x; before the lags
///   started spun up it was 4 of 5 models 0.41-0.64 off under bounds of 0.09-0.14), the
///   instrumented fit swaps in seed 5 at 0.073 / 0.064 under 0.039 / 0.083 (1.9x);
///
/// so the share check stays: the model is refused with the reason (once in the 120 s), the
/// nominal model of the announced geometry stays and the machine keeps holding.
/// docs/study.md, "Under control in moving water" and "The under-control fit's floor".
#[test]
fn in_rough_water_the_model_the_controller_made_is_refused_and_holding_goes_on() {
    use thruster_sim::disturbance::WaterPreset;
    use thrusterd_core::adaptation::identification::Instrument;
    use thrusterd_core::machine::Event;
    let rough = || Some(WaterPreset::Rough.disturbance());
    let (mut run, r) = rotate_while_holding_in(NoisePreset::None, 1, None, rough(), |_, _| {});
    assert_eq!(r.source, ModelSource::Nominal, "{r:?}");
    assert!(r.took_s >= 119.0, "no model swapped in: {r:?}");
    assert_eq!(run.machine.state(), State::Active);
    let refusals: Vec<String> = run
        .machine
        .take_events()
        .into_iter()
        .filter_map(|e| match e {
            Event::ModelRejected(why) => Some(why),
            _ => None,
        })
        .collect();
    assert!(
        refusals.len() == 1
            && refusals.iter().all(|w| {
                w.contains("% of the commands' variation (limit 50 %")
                    && w.contains("deg RMS")
                    && w.contains("the dither as the thrust's instrument")
            }),
        "{refusals:?}"
    );
    // The decisive run, without the check: noise-free, by least squares, the fit takes the
    // controller's answer to the swell for thrust and swaps in a model 0.076 / 0.034 off.
    // Until 2026-12-02 that was twice outside its own bound (0.079 / 0.034 under 0.039 /
    // 0.027); the data now moves the kept columns beyond their errors and the bound is
    // widened to cover it (0.42 / 0.64 of it, `carry_over::disagreement_scale`), but the
    // model is still 4x what the check keeps out.
    let unchecked = IdentificationConfig {
        min_dither_share: 0.0,
        instrument: Instrument::Never,
        ..IdentificationConfig::default()
    };
    let (run, r) =
        rotate_while_holding_in(NoisePreset::None, 1, Some(unchecked), rough(), |_, _| {});
    assert_eq!(r.source, ModelSource::Estimated, "{r:?}");
    let (rot, acc) = coverage(&run, &r);
    assert!(
        r.err_rot > 0.05 && rot.max(acc) <= 1.5,
        "{r:?}: error / bound {rot:.2} / {acc:.2}"
    );
}

/// In moderate water (current 0.3 m/s, a 0.15 Hz swell of 10 N / 1 Nm) the vehicle holds within
/// its budget and the dither is 84-89 % of the commands. With the dither as the thrust's
/// instrument (the default when the held vehicle swung more than 3 deg RMS) the model is
/// within issue 32's 1.5x of its bound. Error / bound, seeds 1-5 (re-measured 2026-12-01, the
/// fit's lags started where the thrusters are, `estimator::dynamic::spin_state`; before, with
/// the lags from rest: AMOUR-5 1.69 noise-free, eight_vectored 2.03): AMOUR-5 noise-free 1.25
/// (0.015 / 0.014), realistic at most 1.00; eight_vectored noise-free 0.81. By least squares
/// AMOUR-5 is within its bound too now (noise-free 1.15: most of its old 2.8x was the lags
/// started from rest), but eight_vectored noise-free is not (0.048 / 0.033, 2.29x): the
/// instrument stays. docs/study.md, "The under-control fit's floor". Since 2026-12-02 a fit
/// that moved the kept columns beyond their errors is reported widened
/// (`carry_over::disagreement_scale`): AMOUR-5 noise-free (2.7 per entry) 0.015 / 0.018
/// under 0.017 / 0.023, and eight_vectored by least squares within 1.34x of its widened
/// bound, but still 0.049 off against the instrument's 0.017: the instrument stays for that.
#[test]
fn in_moderate_water_the_instrumented_identification_stays_within_its_bound() {
    use thruster_sim::disturbance::WaterPreset;
    use thrusterd_core::adaptation::identification::Instrument;
    let moderate = || Some(WaterPreset::Moderate.disturbance());
    for (noise, seed) in [(NoisePreset::None, 1), (NoisePreset::Realistic, 5)] {
        let (run, r) = rotate_while_holding_in(noise, seed, None, moderate(), |_, _| {});
        assert_eq!(r.source, ModelSource::Estimated, "{noise:?} {seed}: {r:?}");
        // (Where the instrument and least squares agree, least squares is kept and the status
        // does not name the instrument: AMOUR-5 here, since the lags start spun up.)
        println!("{noise:?} {seed}: {r:?}: {}", run.machine.status().text);
        let (rot, acc) = coverage(&run, &r);
        assert!(
            rot <= 1.5 && acc <= 1.5,
            "{noise:?} {seed}: {r:?}: error / bound {rot:.2} / {acc:.2}"
        );
        assert!(
            r.err_rot < 0.03 && r.err_acc < 0.03,
            "{noise:?} {seed}: {r:?}"
        );
        assert!(r.took_s <= 6.0, "{noise:?} {seed}: {r:?}");
    }
    // eight_vectored noise-free: instrumented within its bound; by least squares within its
    // widened bound, but three times as far off.
    let v = vehicle("eight_vectored");
    let least_squares = IdentificationConfig {
        instrument: Instrument::Never,
        ..IdentificationConfig::default()
    };
    let (mut coverages, mut errors) = (Vec::new(), Vec::new());
    for identification in [IdentificationConfig::default(), least_squares] {
        let mut run = Run::new("eight_vectored", NoisePreset::None, 1);
        run.with_identification(identification);
        let (run, r) = rotate_while_holding_on(run, &v, moderate(), |_, _| {});
        assert_eq!(r.source, ModelSource::Estimated, "{r:?}");
        let (rot, acc) = coverage(&run, &r);
        println!("eight_vectored: {r:?}: error / bound {rot:.2} / {acc:.2}");
        coverages.push(rot.max(acc));
        errors.push(r.err_rot);
    }
    assert!(
        coverages[0] <= 1.5 && coverages[1] <= 1.5,
        "instrumented, least squares: {coverages:?}"
    );
    assert!(
        errors[1] > 2.0 * errors[0],
        "instrumented, least squares: {errors:?}"
    );
}

/// The swell at another phase (the presets start it at 0 on every seed): AMOUR-5 at the
/// paper's noise, the water coming up 20 s before the announced change. Found at the swell's
/// phase 2.47 rad and noise seed 4 (seed 4's phase in `study sweep sweep_identification`'s
/// `ID_WAVE_PHASE=seed`): the change test takes the water for a moved thruster 4.5 s after it
/// comes up, and that identification finds no change ("taken for the water"); it leaves the
/// sea-state gauge short of a reading, so the announced change's fit was made by least
/// squares to its 20 s limit: 0.222 off under a bound of 0.049, swapped in. Since 2026-12-02
/// the machine's own verdict instruments it while the gauge cannot read (`Instrument::
/// applies`): 0.053 / 0.043 under 0.052 / 0.063. Since 2026-12-03 (the open-loop fit's lags
/// started at the first pulse, so the first model and every flight after it differ) that
/// phase and seed give the same fit either way (0.067); over the phases of seeds 1-12 and
/// noise seeds 1-6 the case (gauge unread, taken for the water, the two fits apart) recurs at
/// phase 2 / noise 5 (here: 0.063 at 1.00x its bound instrumented, 0.100 at 1.74x by least
/// squares) and phase 11 / noise 3 (0.067 at 1.65x, 0.224 at 4.89x).
#[test]
fn a_swell_taken_for_the_water_instruments_the_next_identification() {
    use thruster_sim::disturbance::WaterPreset;
    use thrusterd_core::adaptation::identification::Instrument;
    let water = || {
        let mut d = WaterPreset::Moderate.disturbance();
        swell_phase::set(&mut d, swell_phase::of_seed(2));
        Some(d)
    };
    let (mut errors, mut coverages) = (Vec::new(), Vec::new());
    for instrument in [Instrument::InASea, Instrument::Never] {
        // As found: the first model on the bare command. On one fitted to the thrust's shape
        // both fits are covered here (1.17x and 1.07x their bounds).
        let mut run = Run::new("amour5", NoisePreset::Paper, 5);
        run.with_setup(|s| {
            common::bare_first_model(s);
            // As found, too: with the acceleration rows stopping at 0.07 the flight differs
            // and the case (the gauge unread, the alarm taken for the water) does not arise.
            common::acc_target_as_found(s);
            s.identification.instrument = instrument;
        });
        let (run, r) = rotate_while_holding_on(run, &vehicle("amour5"), water(), |_, _| {});
        let (rot, acc) = coverage(&run, &r);
        println!("{instrument:?}: {r:?}: error / bound {rot:.2} / {acc:.2}");
        assert_eq!(r.source, ModelSource::Estimated, "{r:?}");
        if instrument == Instrument::InASea {
            assert!(
                run.machine.sea_state_deg().is_none() && run.machine.in_a_sea(),
                "the case needs the gauge without a reading and the alarm taken for the water"
            );
        }
        errors.push(r.err_rot);
        coverages.push(rot.max(acc));
    }
    // The decisive run: by least squares, over its bound beyond the standard, and worse.
    assert!(
        coverages[0] <= 1.5 && coverages[1] > 1.5,
        "instrumented, least squares: error / bound {coverages:?}"
    );
    assert!(
        errors[0] < 0.07 && errors[1] > 1.4 * errors[0],
        "instrumented, least squares: {errors:?}"
    );
}

/// After an announced change the model in force is the new geometry's nominal one, which
/// knows neither the learned lag nor the IMU's position. The identification keeps both from
/// the learned model its prior came from and never learns the position from closed-loop data:
/// before, eight_vectored in moderate water (noise-free) found its IMU, which sits at the
/// centre, at (0.034, 0.157, 0.013) m, used it, and its acceleration rows came out 158 % off
/// under a bound of 20 %; now 2-4 % off.
#[test]
fn after_an_announced_change_the_identification_keeps_the_learned_lag_and_imu_position() {
    use thruster_sim::disturbance::WaterPreset;
    let v = vehicle("eight_vectored");
    let run = Run::new("eight_vectored", NoisePreset::None, 1);
    let (run, r) = common::rotate_while_holding_on(
        run,
        &v,
        Some(WaterPreset::Moderate.disturbance()),
        |_, _| {},
    );
    let learned = run.machine.model().unwrap();
    assert_eq!(r.source, ModelSource::Estimated, "{r:?}");
    // The first model (open loop, still water) found the IMU within the tolerance of the
    // configured centre and used that; the simulator's thrusters lag 0.1 s.
    let imu = learned.imu_position_m().expect("the position kept");
    assert!(imu.norm() < 1e-9, "{imu:?}");
    let lag = learned.learned_spin_up_s().expect("the learned lag kept");
    assert!((lag - 0.1).abs() < 0.002, "{lag}");
    assert!(r.err_acc < 0.1, "{r:?}");
}

/// The same for the lag, on a vehicle whose thrusters lag 30 ms (the configured
/// `estimator.spin_up_s` is 0.1 s): before, the identification after an announced change used
/// the configured lag and swapped in a model 93 % / 84 % off the truth (noise-free; 61x its
/// bound at a realistic IMU); with the learned lag kept, 0.9 % / 1.6 %.
#[test]
fn after_an_announced_change_a_fast_thrusters_lag_is_kept() {
    let v = vehicle("amour5_lag30ms");
    let run = Run::new("amour5_lag30ms", NoisePreset::None, 1);
    let (run, r) = common::rotate_while_holding_on(run, &v, None, |_, _| {});
    assert_eq!(r.source, ModelSource::Estimated, "{r:?}");
    let lag = run.machine.model().unwrap().learned_spin_up_s();
    assert!(lag.is_some_and(|l| (l - 0.03).abs() < 0.002), "{lag:?}");
    assert!(r.err_rot < 0.03 && r.err_acc < 0.03, "{r:?}");
}

/// ... and the error those lags carry comes with them (`Model::lag_rel_err`): eight_vectored
/// with thrusters at 0.1 and 0.12 s, noise-free. The first model learned a lag per thruster,
/// the vertical ones 5 % short, and said so in its bound's lag floor (0.093 / 0.063). The
/// identification after an announced change keeps those lags, and came out 0.040 / 0.042 off
/// under bounds of 0.004 / 0.025 (10x); with the lags' error carried, under 0.093 / 0.068.
#[test]
fn after_an_announced_change_the_kept_lags_keep_their_error_in_the_bound() {
    let name = "eight_vectored_lag100_120ms";
    let run = Run::new(name, NoisePreset::None, 1);
    let (run, r) = common::rotate_while_holding_on(run, &vehicle(name), None, |_, _| {});
    assert_eq!(r.source, ModelSource::Estimated, "{r:?}");
    let m = run.machine.model().unwrap();
    let floor = m.dynamics.as_ref().unwrap().spin_up_floor_rel_err;
    assert!(floor[0] > 0.05 && floor[1] > 0.04, "{floor:?}");
    assert!(
        r.err_rot <= m.rel_err_rot && r.err_acc <= m.rel_err_acc,
        "{r:?} under bounds {} / {}",
        m.rel_err_rot,
        m.rel_err_acc
    );
    // Still a model worth having: the lag floor is not the stop's to wait for (5 s).
    assert!(
        r.took_s < 6.0 && r.err_rot < 0.05 && r.err_acc < 0.05,
        "{r:?}"
    );
}

// The other side of the refusal above, a vehicle tumbling in still water on a model that
// cannot hold it: tests/fight_confirmation.rs.

/// A silent change, found by the refinement while the vehicle flies +-20 deg pitch steps with a
/// realistic IMU: the verdict names the thruster, so the re-estimation keeps the others'
/// columns. Measured, seeds 1-5: 0.012-0.019 / 0.013-0.045 off the truth after 9.5-13.5 s;
/// keeping nothing, 0.013-0.058 / 0.037-0.053 after 11.5-16.5 s; keeping the hull's dynamics
/// too, 0.016-0.116 (they were learned near level and do not extrapolate). Knobs for the
/// sweep of these figures: P_SEEDS, P_SCALE (carry_over_se_scale), P_OTHERS (focus_others),
/// P_CARRY (1/0).
#[test]
fn a_silent_change_found_under_pitch_steps_keeps_the_other_columns() {
    let seeds = env_list("P_SEEDS", &[1u64, 3]);
    let scales = env_list("P_SCALE", &[1.0]);
    let others = env_list("P_OTHERS", &[0.1]);
    let carry = env_list("P_CARRY", &[1u8]);
    let mut cases = Vec::new();
    for &seed in &seeds {
        for &scale in &scales {
            for &other in &others {
                for &carry in &carry {
                    cases.push((seed, scale, other, carry));
                }
            }
        }
    }
    for (seed, scale, other, carry) in cases {
        let identification = IdentificationConfig {
            carry_over: carry == 1,
            carry_over_se_scale: scale,
            focus_others: other,
            ..IdentificationConfig::default()
        };
        let (err_rot, err_acc, took_s, why) = silent_rotation_while_pitching(seed, identification);
        println!(
            "seed {seed} carry {carry} se_scale {scale} others {other}: {err_rot:.3} / \
             {err_acc:.3} after {took_s:.1} s; {why}"
        );
        assert!(why.contains("thruster"), "seed {seed}: {why}");
        if carry == 1 && scale == 1.0 && other == 0.1 {
            assert!(
                err_rot < 0.03 && err_acc < 0.05,
                "seed {seed}: {err_rot} / {err_acc}"
            );
            assert!(took_s < 16.0, "seed {seed}: {took_s}");
        }
    }
}

/// AMOUR-5 with a realistic IMU learns its first model, holds, then flies +-20 deg pitch steps
/// while its top thruster is rotated 45 degrees unannounced. Returns the model in force at
/// the end against the truth (rotation, acceleration rows), the seconds from the rotation to
/// that model, and the mismatch report.
fn silent_rotation_while_pitching(
    seed: u64,
    identification: IdentificationConfig,
) -> (f64, f64, f64, String) {
    use nalgebra::UnitQuaternion;
    use thrusterd_core::machine::Event;
    let mut run = Run::new("amour5", NoisePreset::Realistic, seed);
    run.with_identification(identification);
    run.run_for(1.0);
    run.estimate();
    run.run_for(3.0);
    run.rotate_top();
    let before = run.machine.model().unwrap().version;
    let yaw = run.sim.roll_pitch_yaw()[2];
    let start = run.sim.time_s();
    let mut step = 0;
    let mut why = String::new();
    while run.sim.time_s() - start < 90.0 {
        let t = run.sim.time_s() - start;
        if t >= 4.0 * step as f64 {
            let p: f64 = [20.0, -20.0][step % 2];
            let sp = UnitQuaternion::from_euler_angles(0.0, p.to_radians(), yaw);
            run.machine.on_setpoint(sp, None);
            step += 1;
        }
        run.tick();
        for e in run.machine.take_events() {
            if let Event::MismatchDetected(w) = e {
                why = format!("at {t:.1} s: {w}");
            }
        }
        let m = run.machine.model().unwrap();
        let new = m.version > before && m.source == ModelSource::Estimated;
        if run.machine.state() == State::Active && new && !why.is_empty() {
            break;
        }
    }
    let m = run.machine.model().unwrap();
    let truth = run.truth();
    (
        common::rel_err(&m.effectiveness, &truth, 0),
        common::rel_err(&m.effectiveness, &truth, 3),
        run.sim.time_s() - start,
        why,
    )
}
