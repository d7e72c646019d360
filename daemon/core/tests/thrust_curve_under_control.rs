//! Thrust curves nobody configured, under control, in one process against the simulator's
//! truth: a T200's named and its model refused, another make's named and refused (the model in
//! force's bound restated) or learned (the commands out through it, the identification started
//! again), and the identification that confirms a curve just learned run long enough to name
//! what is left of the exponent (`identification.curve_confirm_min_s`). In-process runs are
//! deterministic: the numbers in the comments are what these seeds gave.

mod common;
use common::{vehicle, Run};
use thruster_inprocess::holding::PitchSteps;
use thruster_sim::disturbance::WaterPreset;
use thruster_sim::NoisePreset;
use thrusterd_core::machine::{Event, State};
use thrusterd_core::model::ModelSource;

/// A T200 whose curve nobody configured (`[supply] linearize` off: the daemon's defaults with
/// a driver that passes the PWM, as ArduSub's does): its dead zone and steep top make the
/// thrust far from linear in the command, and the identification under control learned the
/// gain at the hold's amplitude, measured 0.50-0.51 / 0.52-0.53 off the truth under bounds of
/// 0.04-0.05 / 0.06 (realistic IMU, seeds 1-3) and swapped it in. Commands bent to the power
/// 1.5 explain its data with a ln likelihood ratio of 4000-10000 (linear thrusters, every
/// vehicle file and water: at most 11.4): the model is refused naming the curve, and the
/// model in force stays. Linearized, the same change is learned and swapped in.
#[test]
fn a_thrust_curve_nobody_configured_is_named_and_its_model_refused() {
    let v = vehicle("amour5_t200");
    for linearize in [false, true] {
        let mut run = Run::new("amour5_t200", NoisePreset::Realistic, 1);
        // Refused, not learned, with learning on: the commands go through the T200's table
        // (its battery's reading), whose own curve no power law fits (`curve_learned`).
        run.with_setup(|s| s.supply.linearize = linearize);
        let mut named = None;
        // The strongest evidence of any identification in the run: unlinearized, the first is
        // refused, and the refinement calls a change again every 15-20 s on the model in force
        // (with the vehicle swinging on it, in a sea to the detectors since 2026-12-01), each
        // refused with evidence 50-10232.
        let mut curve: Option<
            thrusterd_core::estimator::dynamic::thrust_curve::ThrustCurveEvidence,
        > = None;
        let (_, r) = common::rotate_while_holding_on(run, &v, None, |m, t| {
            let text = m.status().text;
            if named.is_none() && text.contains("does not follow the command linearly") {
                named = Some((t, text));
            }
            let last = m
                .last_estimate()
                .and_then(|e| e.dynamics.as_ref())
                .and_then(|d| d.thrust_curve);
            if let Some(c) = last {
                if curve.is_none_or(|k| c.log_likelihood_ratio > k.log_likelihood_ratio) {
                    curve = Some(c);
                }
            }
        });
        println!("linearize {linearize}: {r:?}, {curve:?}, {named:?}");
        if linearize {
            assert_eq!(r.source, ModelSource::Estimated, "{r:?}");
            assert!(named.is_none(), "{named:?}");
            assert!(r.err_rot < 0.03 && r.err_acc < 0.04, "{r:?}");
            assert!(
                curve.is_some_and(|c| c.log_likelihood_ratio < 20.0),
                "{curve:?}"
            );
        } else {
            let (t, text) = named.expect("the curve named");
            assert!(t < 25.0, "{t} s: {text}");
            assert!(
                text.contains("command^1.50") && text.contains("old model kept"),
                "{text}"
            );
            assert_ne!(r.source, ModelSource::Estimated, "{r:?}");
            assert!(
                curve.is_some_and(|c| c.log_likelihood_ratio > 500.0),
                "{curve:?}"
            );
        }
    }
}

/// eight_vectored_lag80ms_curve (thrust ~ command^1.5, the daemon not told), learned open loop
/// at the pulses' amplitude, then 150 s of +-20 deg pitch steps at a realistic IMU. The
/// refinement calls a change 7 s in, the identification names the curve and is refused; the
/// mismatches after it are counted in the status, not identified again. Before
/// (`curve_named`), the refinement called a change again 7 s after every refusal: six
/// identifications in 3 minutes, each refused for the same curve, the dither never ending.
/// The model in force stays, its bound restated to cover it (`curve_named`): it had kept its
/// open-loop bound, 0.022 where it was 0.086 off.
///
/// With `identification.learn_thrust_curve = false`: learned, the curve is not named again
/// (`an_untold_thrust_curve_is_learned_under_control`).
#[test]
fn a_curve_named_is_not_identified_again_on_every_mismatch() {
    let mut run = Run::new("eight_vectored_lag80ms_curve", NoisePreset::Realistic, 1);
    run.with_setup(|s| s.identification.learn_thrust_curve = false);
    run.learn_then_water(thruster_sim::disturbance::WaterPreset::Still);
    let first = run.machine.model().expect("the open-loop model").clone();
    let truth = run.truth();
    let err = [0, 3].map(|rows| common::rel_err(&first.effectiveness, &truth, rows));
    let mut plan = PitchSteps::new(&run);
    let start = run.sim.time_s();
    let (mut identifications, mut refusals, mut mismatch_events) = (0, 0, 0);
    let mut restated = Vec::new();
    let mut was_identifying = false;
    let mut last_text = String::new();
    while run.sim.time_s() - start < 150.0 {
        let t = run.sim.time_s() - start;
        plan.at(&mut run, t);
        run.tick();
        let identifying = run.machine.state() == State::Identify;
        identifications += usize::from(identifying && !was_identifying);
        was_identifying = identifying;
        for e in run.machine.take_events() {
            match e {
                Event::ModelRejected(why) if why.contains("not follow the command linearly") => {
                    assert!(why.contains("command^1.50"), "{why}");
                    refusals += 1;
                }
                Event::MismatchDetected(_) => mismatch_events += 1,
                Event::ModelSwapped(m) => restated.push(*m),
                _ => {}
            }
        }
        last_text = run.machine.status().text;
    }
    println!("{identifications} identifications, {refusals} curve refusals, {mismatch_events} mismatch events; {last_text}");
    assert_eq!((identifications, refusals), (1, 1), "{last_text}");
    // The model in force is a line through the pulses' amplitude, 8-9 % off the truth: its
    // bound, 2-3 % as learned, is restated to cover that (issue 32 item 4), its B as it was.
    let m = run.machine.model().expect("a model in force");
    println!(
        "open-loop model {:.3} / {:.3} off under {:.3} / {:.3}; restated {:.3} / {:.3} (v{} -> v{})",
        err[0], err[1], first.rel_err_rot, first.rel_err_acc, m.rel_err_rot, m.rel_err_acc,
        first.version, m.version
    );
    assert_eq!(restated.len(), 1, "one restatement, no other swap");
    assert_eq!(m.effectiveness, first.effectiveness);
    assert_eq!(m.version, first.version + 1);
    assert!(
        err[0] > 2.0 * first.rel_err_rot,
        "the learned bound did not cover it: the check below could not fail"
    );
    assert!(
        err[0] <= m.rel_err_rot && err[1] <= m.rel_err_acc,
        "{err:?} under {} / {}",
        m.rel_err_rot,
        m.rel_err_acc
    );
    let d = m
        .dynamics
        .as_ref()
        .expect("dynamic terms")
        .curve_named_rel_err;
    assert!(d.iter().all(|e| *e > 0.05), "{d:?}");
    // The first mismatch (the one identified) and the first after the curve was named.
    assert!(mismatch_events <= 2, "{mismatch_events}");
    assert!(
        last_text.contains("since the thrust curve (~command^1.50) was named, not re-identified"),
        "{last_text}"
    );
}

/// Thrusters whose thrust is not linear in the command, and a daemon not told: the
/// identification under control names the curve, learns it (commands out through it), holds
/// on it and identifies again; the model swapped in carries the exponent and its bound covers
/// the exponent's error. eight_vectored_lag80ms_curve (thrust ~ command^1.5) and the same
/// vehicle with ^1.3 (between the probe's exponents), noise-free and at a realistic IMU,
/// +-20 deg pitch steps. Before: the identification was refused and the open-loop model,
/// 8-9 % off under a 2 % bound, stayed in force for good. The in-process machine jumps the
/// dead band itself (`machine.deadband`): before the dead band was jumped after the curve,
/// the exact ^1.5 was learned as 1.25 and its model was 20 % off.
#[test]
fn an_untold_thrust_curve_is_learned_under_control() {
    use thruster_inprocess::run::vehicle as vehicle_file;
    for (exponent, noise) in [
        (1.5, NoisePreset::None),
        (1.5, NoisePreset::Realistic),
        (1.3, NoisePreset::None),
    ] {
        let mut v = vehicle_file("eight_vectored_lag80ms_curve");
        for t in v.thrusters.iter_mut() {
            t.exponent = exponent;
        }
        let mut run = Run::with_vehicle(v, noise, 1, 200.0);
        run.learn_then_water(thruster_sim::disturbance::WaterPreset::Still);
        let first = run.machine.model().expect("the open-loop model").clone();
        let truth = run.truth();
        let first_err = common::rel_err(&first.effectiveness, &truth, 0);
        let mut plan = PitchSteps::new(&run);
        let start = run.sim.time_s();
        let (mut learned, mut swapped, mut restated) = (0, None, None);
        while run.sim.time_s() - start < 60.0 && swapped.is_none() {
            let t = run.sim.time_s() - start;
            plan.at(&mut run, t);
            run.tick();
            for e in run.machine.take_events() {
                match e {
                    Event::ModelRejected(why) if why.contains("learned; commands go out") => {
                        learned += 1
                    }
                    // While the identification on the curve runs, the line in force says
                    // what the curve puts it off: its B as it was, its bound restated.
                    Event::ModelSwapped(m) if m.curve_named_rel_err() != [0.0; 2] => {
                        restated = Some(*m)
                    }
                    Event::ModelSwapped(m) if m.refinements == 0 && m.version > first.version => {
                        swapped = Some(*m)
                    }
                    _ => {}
                }
            }
        }
        let m = swapped.expect("a model identified on the learned curve");
        let p = m
            .dynamics
            .as_ref()
            .and_then(|d| d.command_exponent)
            .expect("the model carries the curve");
        let (err_rot, err_acc) = (
            common::rel_err(&m.effectiveness, &truth, 0),
            common::rel_err(&m.effectiveness, &truth, 3),
        );
        println!(
            "^{exponent} {noise:?}: {learned} learned, p {p:.3}; open loop {first_err:.4}; now {err_rot:.4} / {err_acc:.4} under {:.3} / {:.3}",
            m.rel_err_rot, m.rel_err_acc
        );
        assert!((1..=3).contains(&learned), "{learned}");
        let line = restated.expect("the line in force restated while the curve was learned");
        let line_err = common::rel_err(&line.effectiveness, &truth, 0);
        assert!(
            line_err <= line.rel_err_rot && first_err > first.rel_err_rot,
            "the line {line_err:.4} off under {:.3} restated (the open loop's {first_err:.4} under {:.3})",
            line.rel_err_rot,
            first.rel_err_rot
        );
        assert!((p / exponent - 1.0).abs() < 0.06, "{p}");
        // Better than the open-loop model at every amplitude, and the bound covers it.
        assert!(
            err_rot < 0.05 && err_rot < 0.6 * first_err,
            "{err_rot} vs {first_err}"
        );
        assert!(err_acc < 0.08, "{err_acc}");
        assert!(
            err_rot <= m.rel_err_rot && err_acc <= m.rel_err_acc,
            "{err_rot} / {err_acc} under {} / {}",
            m.rel_err_rot,
            m.rel_err_acc
        );
        assert_eq!(run.machine.learned_thrust_exponent(), Some(p));
        // The model file keeps the curve, and a daemon that loads it (a restart) sends the
        // commands through it.
        let text = thrusterd_core::model_file::to_json(&m);
        assert!(text.contains("\"format_version\": 3"), "{text}");
        let back = thrusterd_core::model_file::from_json(&text, "m.json").unwrap();
        let mut restarted = Run::new("eight_vectored_lag80ms_curve", noise, 2);
        assert_eq!(restarted.machine.learned_thrust_exponent(), None);
        restarted.machine.load_model(back).unwrap();
        assert_eq!(restarted.machine.learned_thrust_exponent(), Some(p));
    }
}

/// What 90 s of pitch steps left: the curve the model in force carries, its error against
/// the truth over its own bound (the larger row group's), and how long each identification
/// on a learned curve ran, s of dither.
struct Flight {
    exponent: f64,
    coverage: f64,
    confirmations_s: Vec<f64>,
}

fn fly(confirm_min_s: Option<f64>) -> Flight {
    let mut run = Run::new("eight_vectored_lag80ms_curve", NoisePreset::Realistic, 18);
    if let Some(s) = confirm_min_s {
        run.with_setup(|c| c.identification.curve_confirm_min_s = s);
    }
    run.learn_then_water(WaterPreset::Still);
    let mut plan = PitchSteps::new(&run);
    let start = run.sim.time_s();
    let mut confirmations_s = Vec::new();
    // How long an identification ran, from its words ("identified under control in 8.0 s").
    let ran_s = |text: &str| {
        text.split("identified under control in ")
            .nth(1)
            .and_then(|r| r.split(" s").next())
            .and_then(|v| v.parse::<f64>().ok())
    };
    let (mut curve_learned, mut last_status) = (false, String::new());
    while run.sim.time_s() - start < 90.0 {
        let t = run.sim.time_s() - start;
        plan.at(&mut run, t);
        run.tick();
        for e in run.machine.take_events() {
            if let Event::ModelRejected(why) = e {
                if why.contains("learned; commands go out") {
                    // The first names how long the identification that learned it ran; every
                    // later one, a confirmation's.
                    if curve_learned {
                        confirmations_s.extend(ran_s(&why));
                    }
                    curve_learned = true;
                }
            }
        }
        let text = run.machine.status().text;
        if text != last_status {
            if curve_learned {
                confirmations_s.extend(ran_s(&text));
            }
            last_status = text;
        }
    }
    let m = run.machine.model().expect("a model in force");
    let truth = run.truth();
    let coverage = (common::rel_err(&m.effectiveness, &truth, 0) / m.rel_err_rot)
        .max(common::rel_err(&m.effectiveness, &truth, 3) / m.rel_err_acc);
    Flight {
        exponent: m
            .dynamics
            .as_ref()
            .and_then(|d| d.command_exponent)
            .expect("the model carries the curve learned"),
        coverage,
        confirmations_s,
    }
}

/// Seed 18 (realistic, 90 s of pitch steps, `LH_CURVE_CONFIRM=0|8 LH_NOISE=realistic
/// LH_VEHICLES=eight_vectored_lag80ms_curve LH_WATER=still LH_SEEDS=1,...,20 LH_MINUTES=1.5
/// LH_TRACE=1 ... lost_hold_soak`). The test flew seed 10 until 2026-12-07: 1.61x its bound at
/// ^1.378 with the short confirmation. Since the open loop waits for the learned lag's reach
/// (`estimator.learned_lag_reach_rel_err`) its first model is better, and no seed of 20 ends
/// beyond 1.2x with the short one (worst 0.92x, mean rot 0.042; shipped 0.81x, 0.031).
/// Seed 18 is the widest the short one still leaves: ^1.436 (4.3 % low), 0.094 off, 0.92x;
/// shipped ^1.485, 0.022, 0.23x.
#[test]
fn the_curve_confirmation_runs_long_enough_to_name_the_rest() {
    let shipped = fly(None);
    let short = fly(Some(0.0));
    println!(
        "shipped: ^{:.3}, {:.2}x its bound, identifications {:?} s; at min_s: ^{:.3}, {:.2}x, {:?} s",
        shipped.exponent,
        shipped.coverage,
        shipped.confirmations_s,
        short.exponent,
        short.coverage,
        short.confirmations_s
    );
    // Without the longer confirmation the case is what the test is for: the curve 4 % low
    // and the model near its bound. Otherwise the checks below could not fail.
    assert!(
        (short.exponent / 1.5 - 1.0).abs() > 0.035,
        "{}",
        short.exponent
    );
    assert!(short.coverage > 0.7, "{}", short.coverage);
    // Shipped: the curve within 2 % and the model well within its bound.
    assert!(
        (shipped.exponent / 1.5 - 1.0).abs() < 0.02,
        "{}",
        shipped.exponent
    );
    assert!(shipped.coverage < 0.5, "{}", shipped.coverage);
    // The identifications on a learned curve ran at least the confirmation's 8 s, and the
    // short ones did not.
    assert!(
        short.confirmations_s.iter().any(|&s| s < 8.0),
        "{:?}",
        short.confirmations_s
    );
    assert!(
        !shipped.confirmations_s.is_empty()
            && shipped.confirmations_s.iter().all(|&s| s >= 8.0 - 1e-9),
        "{:?}",
        shipped.confirmations_s
    );
}

/// The hold's gain (`refinement.gain_gap_min`): eight_vectored_lag80ms_curve (thrust ~
/// command^1.5, the daemon not told) at the paper's noise, learned open loop at the pulses'
/// amplitude, then 100 s of +-20 deg pitch steps. No identification names the curve there
/// (its evidence 15-32, the limit 50) and each refinement window ends at a bound of 0.4-0.6,
/// so the line stayed in force 0.10-0.13 off under its learned 0.043-0.058. The windows'
/// common gain, pooled, reads 0.52-0.64 of the model's: the model in force's bound is restated
/// to cover the gap, B untouched. Off (`gain_gap_min = 0`) the same flight ends uncovered,
/// so the check can fail. eight_vectored (linear) flown the same way is not touched.
#[test]
fn the_hold_gain_restates_a_line_no_identification_can_name() {
    let fly = |vehicle: &str, gap_min: f64| {
        let mut run = Run::new(vehicle, NoisePreset::Paper, 1);
        run.with_setup(|s| s.refinement.gain_gap_min = gap_min);
        run.learn_then_water(WaterPreset::Still);
        let first = run.machine.model().expect("the open-loop model").clone();
        let mut plan = PitchSteps::new(&run);
        let start = run.sim.time_s();
        let (mut widened, mut identified) = (Vec::new(), false);
        while run.sim.time_s() - start < 100.0 {
            let t = run.sim.time_s() - start;
            plan.at(&mut run, t);
            run.tick();
            identified |= run.machine.state() == State::Identify;
            for e in run.machine.take_events() {
                if let Event::BoundWidened(why) = e {
                    widened.push(why);
                }
            }
        }
        let m = run.machine.model().expect("a model in force").clone();
        let truth = run.truth();
        let err = [0, 3].map(|rows| common::rel_err(&m.effectiveness, &truth, rows));
        println!(
            "{vehicle}, gain_gap_min {gap_min}: {:.3} / {:.3} off under {:.3} / {:.3} (learned {:.3} / {:.3}); identified {identified}; {widened:?}",
            err[0], err[1], m.rel_err_rot, m.rel_err_acc, first.rel_err_rot, first.rel_err_acc
        );
        (first, m, err, widened, identified)
    };
    let (first, m, err, widened, identified) = fly("eight_vectored_lag80ms_curve", 0.0);
    assert!(!identified && widened.is_empty());
    assert!(
        err[0] > 1.5 * m.rel_err_rot,
        "off, the line is a confident wrong model: {err:?} under {}",
        m.rel_err_rot
    );
    assert_eq!(m.effectiveness, first.effectiveness);
    let (first, m, err, widened, identified) = fly("eight_vectored_lag80ms_curve", 0.2);
    assert!(!identified, "nothing re-identified");
    assert_eq!(m.effectiveness, first.effectiveness, "B untouched");
    assert!(
        err[0] <= m.rel_err_rot && err[1] <= m.rel_err_acc,
        "{err:?} under {} / {}",
        m.rel_err_rot,
        m.rel_err_acc
    );
    assert!(
        !widened.is_empty() && widened[0].contains("at the hold's commands"),
        "{widened:?}"
    );
    let (first, m, _, widened, _) = fly("eight_vectored", 0.2);
    assert!(widened.is_empty(), "{widened:?}");
    assert_eq!(
        [m.rel_err_rot, m.rel_err_acc],
        [first.rel_err_rot, first.rel_err_acc]
    );
}
