//! A model fitted on the controller's fight (`adaptation::identification::fight`), against the
//! simulator's truth: after an announced change the model in force cannot hold the vehicle, the
//! controller's answer to the tumble swamps the dither, and the identification's fit is made of
//! that fight. Its own bound then does not cover its error; the daemon reports it widened by
//! 1 / sqrt(dither share), swaps it in to hold the vehicle, and confirms it at once with a
//! second identification, or lets go and estimates from rest when that is a fight again (or the
//! fight's model is refused). In-process runs are deterministic: the numbers in the comments
//! are what these seeds gave.

mod common;
use common::{bare_first_model, rel_err, rotate_while_holding_on, vehicle, Reestimation, Run};
use nalgebra::DMatrix;
use thruster_sim::NoisePreset;
use thrusterd_core::machine::{Event, ThrusterChange};
use thrusterd_core::model::ModelSource;

/// An estimated model as it was swapped in: its effectiveness, the bounds it was reported
/// with, and the dither's share of the identification that made it.
#[derive(Debug)]
struct Swapped {
    effectiveness: DMatrix<f64>,
    bound: (f64, f64),
    share: f64,
}

/// Every estimated model swapped in after the announcement, in order, with the outcome.
fn swaps_through(
    run: Run,
    observe_run: impl FnOnce(
        Run,
        &mut dyn FnMut(&thrusterd_core::machine::Machine, f64),
    ) -> (Run, Reestimation),
) -> (Run, Reestimation, Vec<Swapped>) {
    let mut seen = Vec::new();
    let mut version = None;
    let mut share = f64::NAN;
    let mut observe = |m: &thrusterd_core::machine::Machine, _t: f64| {
        if let Some(x) = m.identification_excitation() {
            share = x.dither_share();
        }
        let Some(model) = m.model() else { return };
        if version.is_some_and(|v| v == model.version) {
            return;
        }
        let first = version.is_none();
        version = Some(model.version);
        if !first && model.source == ModelSource::Estimated {
            seen.push(Swapped {
                effectiveness: model.effectiveness.clone(),
                bound: (model.rel_err_rot, model.rel_err_acc),
                share,
            });
        }
    };
    let (run, r) = observe_run(run, &mut observe);
    (run, r, seen)
}

/// AMOUR-5 with its top thruster at 45 deg, the first thruster turned 45 deg more and
/// announced while held: the nominal model of the new geometry lets it tumble to 95 deg.
/// The first model fitted to the bare command, as these flights were found (with the shape,
/// realistic seed 2 takes the let-go branch seed 1 takes bare: the model from rest at 43.9 s,
/// 0.010 / 0.010 off; at the paper's noise seed 2's confirmation is no fight and nothing lets
/// go).
fn top45(noise: NoisePreset, seed: u64) -> (Run, Reestimation, Vec<Swapped>) {
    top45_with(noise, seed, bare_first_model)
}

/// The same flight with the daemon's setup changed by `setup` (from the shipped one).
fn top45_with(
    noise: NoisePreset,
    seed: u64,
    setup: impl FnOnce(&mut thrusterd_core::machine::MachineSetup),
) -> (Run, Reestimation, Vec<Swapped>) {
    let v = vehicle("amour5_top45");
    let mut run = Run::new("amour5_top45", noise, seed);
    run.with_setup(setup);
    swaps_through(run, |run, observe| {
        rotate_while_holding_on(run, &v, None, observe)
    })
}

/// Each swapped model's error against the truth over its reported bound (rotation, acc).
fn coverage(run: &Run, s: &Swapped) -> (f64, f64) {
    let truth = run.truth();
    (
        rel_err(&s.effectiveness, &truth, 0) / s.bound.0,
        rel_err(&s.effectiveness, &truth, 3) / s.bound.1,
    )
}

/// Noise-free: the fight (share 0.02) made a model 0.133 / 0.080 off the truth under its own
/// bound of 0.051 / 0.040 (2.6x), swapped in so until 2026-12-02; the vehicle held on it and
/// the refinement took 30-60 s to repair it. Now (the gyro bias no longer learned in the
/// tumble, `attitude::BIAS_LEARNING_MAX_RADPS`) the fight's model is 1.27x its own bound and
/// is reported widened by 1 / sqrt(0.02); the confirmation starts once it holds the vehicle,
/// dithers at 0.99 of the commands and ends 0.0020 / 0.0056 off at 14.1 s.
#[test]
fn noise_free_the_fights_model_is_reported_widened_and_confirmed_once_held() {
    let (run, r, swaps) = top45(NoisePreset::None, 1);
    println!("{r:?}\n{swaps:#?}");
    assert_eq!(swaps.len(), 2, "the fight's model, then the confirmation's");
    let (fight, confirmed) = (&swaps[0], &swaps[1]);
    assert!(fight.share < 0.1, "{fight:?}");
    let (rot, acc) = coverage(&run, fight);
    assert!(
        rot <= 1.5 && acc <= 1.5,
        "widened: {rot:.2} / {acc:.2} of the bound"
    );
    assert!(confirmed.share > 0.9, "{confirmed:?}");
    assert!(r.err_rot < 0.005 && r.err_acc < 0.01, "{r:?}");
    assert!(r.took_s < 15.0, "{r:?}");
}

/// A realistic IMU. Until 2026-12-02 the fights' models were swapped in 0.035-0.074 off under
/// their own bounds of 0.022-0.040 (up to 2.5x). Now, seeds 1-10: every model swapped in is
/// within 1.07x of the bound it is reported with; the confirmations' are 0.008-0.015 /
/// 0.012-0.021 off in 12-16 s (seed 1's fight leaves no dither at all, share 0.00: the hold
/// watch lets go first and the model comes from rest at 22 s, 0.006 / 0.015). Seed 3's fight
/// is the decisive run for the widening: 2.8x its own bound, 0.39x the widened one.
#[test]
fn with_a_realistic_imu_every_model_swapped_is_within_its_reported_bound() {
    for seed in [2, 3] {
        let (run, r, swaps) = top45(NoisePreset::Realistic, seed);
        println!("seed {seed}: {r:?}");
        assert_eq!(swaps.len(), 2, "seed {seed}: {swaps:#?}");
        for s in &swaps {
            let (rot, acc) = coverage(&run, s);
            println!("  share {:.2}: {rot:.2} / {acc:.2} of the bound", s.share);
            assert!(rot <= 1.5 && acc <= 1.5, "seed {seed}: {s:?}");
        }
        if seed == 3 {
            let fight = &swaps[0];
            let own = coverage(&run, fight).0 / fight.share.sqrt();
            assert!(own > 1.5, "its own bound would have covered it: {own:.2}");
        }
        assert!(r.err_rot < 0.02 && r.err_acc < 0.025, "seed {seed}: {r:?}");
        assert!(r.took_s < 15.0, "seed {seed}: {r:?}");
    }
}

/// At the paper's noise the identification on the tumbling vehicle runs to its 20 s limit.
/// Seed 2: the fight's model is swapped in widened, its confirmation starts 5 s later once it
/// holds the vehicle, and is a fight again (share 0.00): the daemon lets go, and the estimation
/// from rest ends 0.054 / 0.058 off under 0.037 / 0.059 at 61 s. Seed 3: the fight's model is
/// refused (its own bound over the 0.25 gate), and the daemon lets go at once instead of
/// holding on the nominal model until the hold watch fires: 0.057 / 0.089 under 0.037 / 0.060
/// at 58 s (1.5x: the open-loop estimation's own coverage at this noise). Until 2026-12-02
/// seed 2 swapped in a fight's model 0.65 / 1.32 off under its own bound of 0.21 / 0.17 and
/// kept it.
///
/// Since the 0.5 s lead-in (`identification.lead_in_s`) seed 3's fight's model has an own
/// bound of 0.10 / 0.15, within the gate: swapped in widened and confirmed at 35 s, 0.035 /
/// 0.072 off under 0.044 / 0.060. The refusal is taken with a gate of 0.09 there.
#[test]
fn at_the_papers_noise_a_fight_twice_or_a_refused_fight_lets_go() {
    for (seed, cause, gate) in [
        (2, "twice", None),
        (3, "the fight's model was refused", Some(0.09)),
    ] {
        let (mut run, r, swaps) = top45_with(NoisePreset::Paper, seed, |s| {
            bare_first_model(s);
            // As found: with the acceleration rows stopping at 0.07 seed 2 flies otherwise and
            // does not fight twice.
            common::acc_target_as_found(s);
            if let Some(gate) = gate {
                s.machine.max_swap_rel_err = gate;
            }
        });
        let events = run.machine.take_events();
        println!("seed {seed}: {r:?}");
        let let_go = events
            .iter()
            .any(|e| matches!(e, Event::HoldLost(w) if w.contains(cause)));
        assert!(let_go, "seed {seed}: no let-go for {cause:?}");
        for s in &swaps {
            let (rot, acc) = coverage(&run, s);
            println!("  share {:.2}: {rot:.2} / {acc:.2} of the bound", s.share);
            assert!(rot <= 1.6 && acc <= 1.6, "seed {seed}: {s:?}");
        }
        assert_eq!(r.source, ModelSource::Estimated, "seed {seed}: {r:?}");
        assert!(r.err_rot < 0.065 && r.err_acc < 0.095, "seed {seed}: {r:?}");
    }
}

/// `aligned` learned, then its first thruster turned 45 deg and announced with its left-handed
/// L declared right-handed, 3 s after its first model (before the sea-state gauge has read
/// anything): every estimated model swapped in after the announcement.
fn misdeclared_screw(noise: NoisePreset, seed: u64) -> (Run, Reestimation, Vec<Swapped>) {
    use nalgebra::Vector3;
    let v = vehicle("aligned");
    let mut run = Run::with_vehicle(v.clone(), noise, seed, 200.0);
    // As found (with the shape the dither is not faded out in the tumble).
    run.with_setup(bare_first_model);
    run.run_for(1.0);
    run.estimate();
    run.run_for(3.0);
    assert_eq!(run.machine.sea_state_deg(), None);
    let d = Vector3::from(v.thrusters[0].direction);
    let across = if d.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let axis = d.cross(&across).normalize();
    let mut declared = v.clone();
    let l = declared.thrusters.iter().position(|t| t.reversed).unwrap();
    declared.thrusters[l].reversed = false;
    swaps_through(run, |mut run, observe| {
        let r = run.announced_turn(
            &declared,
            0,
            axis.into(),
            45.0,
            ThrusterChange::Moved(0),
            observe,
        );
        (run, r)
    })
}

/// The tumble on `aligned`: its first thruster turned 45 deg and announced with its
/// left-handed L declared right-handed (a mistake in the declaration), 3 s after its first
/// model, before the sea-state gauge has read anything. The dither fades out (share 0.003) and
/// the fight's model, 0.076 / 0.033 off the truth, was swapped in with its own bound until
/// 2026-12-02 (refusing it on the share alone kept the nominal model, 0.99 off, and the vehicle
/// tumbling). Now it is swapped in widened (0.08 / 0.11 of that bound), and the confirmation
/// starts once it holds the vehicle: 0.048 / 0.014 off at 19.3 s. **Open: that is 2.2x its
/// rotation bound** (since the 0.5 s lead-in, `identification.lead_in_s`: the fight's share
/// 0.086, its model at 0.65 / 0.48 of the widened bound, confirmed at 15.4 s 0.051 / 0.015
/// off, 3.6x a rotation bound of 0.014; a 1 s hold for the confirmation alone gave the same).
/// The error is in columns the prior kept (LB's pitch 16.9 against 14.1, L's 0.7 against
/// 2.2), pulled by what is left of the fight while the vehicle yaws back from 180 deg;
/// decisive runs: dithering every thruster alike instead of focusing on the changed one,
/// 0.012 / 0.004, still 2.1x (and at a realistic IMU on amour5_top45 worse, up to 1.67x, so
/// not taken); starting 3 s later, or only within half the attitude budget, no better; a
/// perfect DVL, no better. What tells: the fit moved the kept pitch gains 9.8 of their
/// standard errors squared per entry (LB's 13.9 +- 0.34 to 16.9), which data and a prior that
/// agree never do. Since 2026-12-02 the bound is widened by that (`carry_over::
/// disagreement_scale`, sqrt(9.8)): 0.014 -> 0.044, and the confirmed model is 1.15x / 0.99x of
/// it.
#[test]
fn a_tumble_on_a_misdeclared_thruster_is_held_by_the_fights_model_and_confirmed() {
    let (run, r, swaps) = misdeclared_screw(NoisePreset::None, 1);
    println!("{r:?}\n{swaps:#?}");
    assert!(!swaps.is_empty(), "{r:?}");
    assert!(
        swaps[0].share < 0.5,
        "the dither was faded out: {:?}",
        swaps[0]
    );
    assert_eq!(swaps.len(), 2, "the fight's model, then the confirmation's");
    for s in &swaps {
        let (rot, acc) = coverage(&run, s);
        println!("  share {:.3}: {rot:.2} / {acc:.2} of the bound", s.share);
        assert!(rot <= 1.5 && acc <= 1.5, "{s:?}");
    }
    assert_eq!(r.source, ModelSource::Estimated, "{r:?}");
    assert!(r.err_rot < 0.06 && r.err_acc < 0.02, "{r:?}");
    assert!(r.took_s < 21.0, "{r:?}");
}

/// The operator aborts the confirmation while it waits for the hold (`thrusterctl abort`): the
/// fight's model stays in force, holding, and no confirmation starts later. Before, `abort`
/// was refused there ("nothing to abort": no estimation had started yet).
#[test]
fn an_abort_while_the_confirmation_waits_keeps_the_fights_model_and_starts_nothing() {
    use thrusterd_core::machine::{Request, State};
    let v = vehicle("amour5_top45");
    let mut run = Run::new("amour5_top45", NoisePreset::None, 1);
    run.run_for(1.0);
    run.estimate();
    run.run_for(3.0);
    run.announce_turn(&v, 0, [1.0, 0.0, 0.0], 45.0, ThrusterChange::Moved(0));
    let start = run.sim.time_s();
    while !run.machine.confirmation_pending() {
        assert!(run.sim.time_s() - start < 30.0, "no fight's model in 30 s");
        run.tick();
    }
    let fight = run.machine.model().unwrap().version;
    assert_eq!(
        run.machine.on_request(Request::Abort).as_deref(),
        Ok("aborted; holding attitude")
    );
    assert!(!run.machine.confirmation_pending());
    // Held long past the 1 s the confirmation would have waited: nothing starts.
    for _ in 0..(10 * 200) {
        run.tick();
        assert_eq!(
            run.machine.state(),
            State::Active,
            "{}",
            run.machine.status().text
        );
    }
    assert!(run.machine.model().unwrap().version >= fight);
    assert_eq!(run.machine.model().unwrap().source, ModelSource::Estimated);
    // And with nothing waiting, an abort is refused as before.
    assert!(run.machine.on_request(Request::Abort).is_err());
}

/// The same misdeclared screw at a realistic IMU, seeds 1-5 (measured 2026-12-02): only seed 1
/// tumbles into a fight (share 0.38, its model 0.53 / 0.79 of its widened bound, confirmed
/// 0.010 / 0.015 off at 14.3 s); the others are identified under control in 3.5 s, 0.011-0.027
/// / 0.013-0.053 off, at most 1.26x / 1.32x their bounds (seeds 2 and 5). The bound is never
/// widened for the kept columns here: the data and the prior agree within their errors.
#[test]
fn at_a_realistic_imu_every_model_after_a_misdeclared_screw_is_within_its_bound() {
    for seed in 1..=5 {
        let (run, r, swaps) = misdeclared_screw(NoisePreset::Realistic, seed);
        assert!(!swaps.is_empty(), "seed {seed}: {r:?}");
        for s in &swaps {
            let (rot, acc) = coverage(&run, s);
            println!(
                "seed {seed}: share {:.2}: {rot:.2} / {acc:.2} of the bound",
                s.share
            );
            assert!(rot <= 1.5 && acc <= 1.5, "seed {seed}: {s:?}");
        }
        assert_eq!(r.source, ModelSource::Estimated, "seed {seed}: {r:?}");
        assert!(r.err_rot < 0.04 && r.err_acc < 0.07, "seed {seed}: {r:?}");
    }
}

/// A fight's data name no thrust curve: the commands answer the motion there, and the curve
/// they seem to follow is the controller's. AMOUR-5 with its top thruster at 45 deg, the
/// defaults, a realistic IMU, seed 28 (of 30 swept, the one that named a curve): the fight
/// (share 0.02) named thrust ~ command^1.79 (ln likelihood ratio 244), the curve was learned,
/// and the wait for the vehicle to be held on it and the nominal model never ended: 40 deg off
/// on the mean, under the hold watch's 45, for the 112 s the flight had left. Now the fight's
/// model is swapped in widened and confirmed once held: 0.006 / 0.010 off at 13.4 s.
#[test]
fn a_fights_data_name_no_thrust_curve() {
    let (mut run, r, swaps) = top45_with(NoisePreset::Realistic, 28, |_| {});
    let events = run.machine.take_events();
    println!("{r:?}\n{swaps:#?}");
    let named = events
        .iter()
        .any(|e| matches!(e, Event::ModelRejected(w) if w.contains("linearly")));
    assert!(!named, "a curve was named: {events:#?}");
    assert_eq!(swaps.len(), 2, "the fight's model, then the confirmation's");
    assert!(swaps[0].share < 0.1 && swaps[1].share > 0.9, "{swaps:#?}");
    assert_eq!(r.source, ModelSource::Estimated, "{r:?}");
    assert!(r.err_rot < 0.02 && r.err_acc < 0.03, "{r:?}");
    assert!(r.took_s < 20.0, "{r:?}");
}

/// A wait for the vehicle to be held that never ends is ended: after
/// `fight::MAX_WAIT_FOR_HOLD_S` (15 s) the daemon lets go and estimates from rest. Made
/// decisive with an attitude budget no vehicle is held within (0.01 deg: the dither fades out
/// at once, so the identification is a fight, and its confirmation waits for a hold within
/// 0.01 deg) and a confidence gate that takes the fight's model widened 30x (else refused, it
/// lets go at once): AMOUR-5 top45 noise-free, seed 1. Without the limit the fight's model
/// would be held on for good, unconfirmed.
#[test]
fn a_wait_for_a_hold_that_never_comes_ends_in_an_estimate_from_rest() {
    let (mut run, r, swaps) = top45_with(NoisePreset::None, 1, |s| {
        s.identification.attitude_budget_deg = 0.01;
        s.machine.max_swap_rel_err = 100.0;
    });
    let events = run.machine.take_events();
    println!("{r:?}\n{swaps:#?}");
    let ended = events
        .iter()
        .any(|e| matches!(e, Event::HoldLost(w) if w.contains("did not hold the vehicle")));
    for e in &events {
        if let Event::HoldLost(w) = e {
            println!("{w}");
        }
    }
    assert!(ended, "no end to the wait: {events:#?}");
    assert_eq!(r.source, ModelSource::Estimated, "{r:?}");
    assert!(r.err_rot < 0.01 && r.err_acc < 0.01, "{r:?}");
}
