//! A change the daemon only suspects (the refinement's change test or the monitor's mismatch)
//! in a swell, which the identification under control then cannot pin down within its limit,
//! is not confirmed: the model in force stays (`identification.at_limit_unannounced`).
//!
//! The case (found by `study sweep lost_hold_soak` at the paper's noise): AMOUR-5 with its top
//! thruster at 45 deg flies +-20 deg pitch steps in moderate water. The change test's false
//! alarms in the swell start identifications; one ends at the 20 s limit with a least-squares
//! fit 0.30 off the truth under a bound of 0.09 (the sea-state gauge never measured between the
//! steps, so neither the instrument nor the share check applied). Swapped in, with a second one
//! like it, the vehicle lost its hold 10 s later, 50 deg off.

use thruster_sim::disturbance::WaterPreset;
use thruster_sim::NoisePreset;
use thrusterd_core::adaptation::identification::{AtLimit, Instrument};
use thrusterd_core::machine::Event;

mod common;
use common::holding::PitchSteps;
use common::{rel_err, Run};

struct Outcome {
    /// Identifications at their limit refused as unconfirmed changes.
    unconfirmed: usize,
    /// Models swapped in, and the worst of them against the truth (rotation rows).
    swaps: usize,
    worst_err_rot: f64,
    /// `HoldLost` events.
    lost: usize,
}

/// The limit's rule at work (`keep_old`): an identification reached its limit and was refused,
/// the hold was kept, and no model far off the truth went in.
fn assert_the_model_in_force_was_kept(kept: &Outcome) {
    assert!(kept.unconfirmed >= 1, "no identification reached its limit");
    assert_eq!(
        kept.lost, 0,
        "the hold was lost with the model in force kept"
    );
    assert!(
        kept.worst_err_rot < 0.15,
        "a model {:.3} off was swapped in",
        kept.worst_err_rot
    );
}

/// The flight as the case was found: the change test's name margin 0 (the largest joint
/// chi-square named) and the first model on the bare command (`estimator.shaped_thrust` off).
/// The shipped margin 20 (since 2026-12-03) waits for a clearer name, and the swell's alarms
/// come later and stronger (below, `at_the_shipped_name_margin_...`); on a first model fitted
/// to the thrust's shape no identification here reached its limit. The change test's terms
/// as they were then, too (`refinement.change_term_z` 4; 8 since 2026-12-04, when this
/// flight's alarms start other identifications: docs/study.md, "The change test's terms"),
/// and the first model's acceleration rows stopping at 0.06 (0.07 since 2026-12-05, when no
/// identification here reached its limit either).
const AS_FOUND: Flight = Flight {
    name_margin: 0.0,
    bare_first_model: true,
    term_z: 4.0,
};

/// What of the setup the flight varies besides the limit's rule.
#[derive(Clone, Copy)]
struct Flight {
    name_margin: f64,
    bare_first_model: bool,
    term_z: f64,
}

fn pitch_steps_in_a_swell(
    at_limit: AtLimit,
    late_decision_s: f64,
    instrument: Instrument,
    flight: Flight,
    seconds: f64,
) -> Outcome {
    let mut run = Run::new("amour5_top45", NoisePreset::Paper, 2);
    run.with_setup(|s| {
        s.identification.at_limit_unannounced = at_limit;
        // The stop's spacing in the settle wait and after it (both 0.1 s by default).
        s.identification.late_decision_s = late_decision_s;
        s.identification.settle_decision_s = late_decision_s;
        s.identification.instrument = instrument;
        s.refinement.change_name_margin = flight.name_margin;
        s.refinement.change_term_z = flight.term_z;
        if flight.bare_first_model {
            common::bare_first_model(s);
            common::acc_target_as_found(s);
        }
        // The detectors uncalibrated, as they were when this was found: since 2026-12-01 an
        // alarm its identification does not confirm is taken for the water, the calibrations
        // then apply, and in these 100 s no identification reaches its limit at all (the
        // first alarm's finds nothing). The limit's rule is what this test is about.
        s.refinement.change_calibration_s = 0.0;
        s.monitor.calibration_s = 0.0;
    });
    run.learn_then_water(WaterPreset::Moderate);
    let mut plan = PitchSteps::new(&run);
    let start = run.sim.time_s();
    let mut last = run.machine.model().map(|m| m.effectiveness.clone());
    let mut out = Outcome {
        unconfirmed: 0,
        swaps: 0,
        worst_err_rot: 0.0,
        lost: 0,
    };
    while run.sim.time_s() - start < seconds {
        let t = run.sim.time_s() - start;
        plan.at(&mut run, t);
        run.tick();
        for e in run.machine.take_events() {
            match e {
                Event::ModelRejected(why) if why.contains("suspected change is not confirmed") => {
                    out.unconfirmed += 1
                }
                Event::HoldLost(_) => out.lost += 1,
                _ => {}
            }
        }
        let b = run.machine.model().map(|m| &m.effectiveness);
        if b != last.as_ref() {
            if let Some(b) = b {
                out.swaps += 1;
                out.worst_err_rot = out.worst_err_rot.max(rel_err(b, &run.truth(), 0));
            }
            last = b.cloned();
        }
    }
    out
}

#[test]
fn a_change_the_identification_cannot_confirm_in_a_swell_keeps_the_model_in_force() {
    // Measured: keep_old 1 refusal, 2 swaps (the worst 0.072 off), no hold lost; swap 3
    // swaps, the worst 0.300 off (under a bound of 0.088), and the hold lost at 93.8 s. Since
    // the paper noise's dither may reach full command (`dither_max` 1.0, 2026-12-01): keep_old
    // 1 refusal, 2 swaps (0.060); swap 3 swaps, the worst 0.227 off, the hold kept in these
    // 100 s (the soaks' 12 vehicle-hours at the paper's noise lost none either way). Measured
    // 2026-12-02: keep_old 2 refusals, 2 swaps (0.062); swap 4 swaps, the worst 0.257 off.
    // 2026-12-03 (the open-loop fit's lags started at the first pulse, so the first model and
    // the flight differ): keep_old 1 refusal, 3 swaps (0.109: an identification the alarms
    // started that stopped before its limit, not the limit's rule); swap 3 swaps (0.289).
    // What is decisive is the model far off the truth put in force.
    // The stop decided once a segment (`identification.late_decision_s` = 1, the default
    // until 2026-12-02): with the default 0.1 s no identification here reaches its limit (the
    // runs the alarms start stop sooner; below), and the limit's rule is what this is about.
    // The fits by least squares (`instrument = "never"`), as the shipped rule made them here
    // until 2026-12-02: the gauge had no reading through the steps, and only since then does
    // the machine's own verdict, an alarm taken for the water, instrument them (below).
    let kept = pitch_steps_in_a_swell(AtLimit::KeepOld, 1.0, Instrument::Never, AS_FOUND, 100.0);
    let swapped = pitch_steps_in_a_swell(AtLimit::Swap, 1.0, Instrument::Never, AS_FOUND, 100.0);
    eprintln!(
        "keep_old: {} unconfirmed, {} swaps (worst {:.3}), {} lost; swap: {} swaps (worst {:.3}), {} lost",
        kept.unconfirmed,
        kept.swaps,
        kept.worst_err_rot,
        kept.lost,
        swapped.swaps,
        swapped.worst_err_rot,
        swapped.lost
    );
    assert_the_model_in_force_was_kept(&kept);
    // The decisive comparison: swapped at the limit, the same flight puts a model far off the
    // truth in force and loses the hold.
    assert_eq!(swapped.unconfirmed, 0);
    assert!(
        swapped.worst_err_rot > 0.2 && swapped.worst_err_rot > 2.0 * kept.worst_err_rot,
        "swapping at the limit gave nothing worse than {:.3} (kept: {:.3})",
        swapped.worst_err_rot,
        kept.worst_err_rot
    );
    // Instrumented once the first unconfirmed alarm is taken for the water (the shipped
    // `instrument = "in_a_sea"` since 2026-12-02), the same flight's models at the limit are
    // no longer far off: measured 3 swaps, the worst 0.079 (least squares: 0.257); since
    // 2026-12-03 3 swaps, the worst 0.108 (least squares 0.289), the same model as keep_old's
    // worst (above): one stopped before its limit.
    let instrumented =
        pitch_steps_in_a_swell(AtLimit::Swap, 1.0, Instrument::InASea, AS_FOUND, 100.0);
    eprintln!(
        "swap, instrumented in a sea taken for the water: {} swaps (worst {:.3}), {} lost",
        instrumented.swaps, instrumented.worst_err_rot, instrumented.lost
    );
    assert!(
        instrumented.worst_err_rot < 0.15
            && 2.0 * instrumented.worst_err_rot < swapped.worst_err_rot
            && instrumented.lost == 0,
        "instrumented, swapped at the limit: the worst {:.3} off, {} lost",
        instrumented.worst_err_rot,
        instrumented.lost
    );
}

/// The same flight with the stop decided every 0.1 s after the settle wait (the default since
/// 2026-12-02): the alarms' identifications all stop before their limit, on a noisy bound met
/// sooner (more looks at it), so more models go in: measured 5 swaps, the worst 0.095 off
/// (0.090 before the fits were instrumented in a sea taken for the water), against 2 (0.060)
/// deciding once a segment, and no hold lost; 2026-12-03: 2 refusals, 1 swap (0.048). The
/// detectors as shipped (calibrated, and the name margin 20) raise no such alarms here; this
/// is the cost of the finer stop where they do (with the shipped margin: 2 refusals, no swap,
/// the test above).
#[test]
fn deciding_the_stop_every_tenth_of_a_second_in_a_swell_keeps_the_hold() {
    let late = thrusterd_core::machine::MachineSetup::default()
        .identification
        .late_decision_s;
    let shipped = thrusterd_core::machine::MachineSetup::default()
        .identification
        .instrument;
    let out = pitch_steps_in_a_swell(AtLimit::KeepOld, late, shipped, AS_FOUND, 100.0);
    eprintln!(
        "late decisions every {late} s: {} unconfirmed, {} swaps (worst {:.3}), {} lost",
        out.unconfirmed, out.swaps, out.worst_err_rot, out.lost
    );
    assert_eq!(out.lost, 0, "the hold was lost");
    assert!(
        out.swaps >= 1 && out.worst_err_rot < 0.1,
        "{} swaps, the worst {:.3} off",
        out.swaps,
        out.worst_err_rot
    );
}

/// The same flight with the change test's name margin as shipped (20 since 2026-12-03): the
/// swell's alarms whose name leads by less wait, and the ones that come are later and stronger
/// (measured: the first at 31.3 s, chi-square 64, against 8.0 s, 10, as found). The limit's rule
/// still decides: kept, 2 refusals and no model swapped in; swapped at the limit, models 0.239
/// and 0.278 off go in. Instrumented, swapped at the limit gives the same 0.278: no earlier
/// alarm was left unconfirmed (taken for the water) to instrument this one, which is what
/// the shipped `keep_old` is for.
#[test]
fn at_the_shipped_name_margin_the_swells_alarms_reach_the_limit_and_the_model_is_kept() {
    let shipped = thrusterd_core::machine::MachineSetup::default();
    let margin = shipped.refinement.change_name_margin;
    // The change test's terms as when this was measured (4; see `AS_FOUND`).
    let flight = Flight {
        name_margin: margin,
        bare_first_model: false,
        term_z: 4.0,
    };
    let (late, instrument) = (
        shipped.identification.late_decision_s,
        shipped.identification.instrument,
    );
    let kept = pitch_steps_in_a_swell(AtLimit::KeepOld, 1.0, Instrument::Never, flight, 100.0);
    let swapped = pitch_steps_in_a_swell(AtLimit::Swap, 1.0, Instrument::Never, flight, 100.0);
    let as_shipped = pitch_steps_in_a_swell(AtLimit::KeepOld, late, instrument, flight, 100.0);
    eprintln!(
        "margin {margin}: keep_old {} unconfirmed, {} swaps (worst {:.3}), {} lost; swap {} swaps \
         (worst {:.3}), {} lost; as shipped {} unconfirmed, {} swaps (worst {:.3}), {} lost",
        kept.unconfirmed,
        kept.swaps,
        kept.worst_err_rot,
        kept.lost,
        swapped.swaps,
        swapped.worst_err_rot,
        swapped.lost,
        as_shipped.unconfirmed,
        as_shipped.swaps,
        as_shipped.worst_err_rot,
        as_shipped.lost
    );
    assert_the_model_in_force_was_kept(&kept);
    assert!(
        swapped.worst_err_rot > 0.2,
        "swapping at the limit gave nothing worse than {:.3}",
        swapped.worst_err_rot
    );
    assert_eq!(as_shipped.lost, 0, "the hold was lost as shipped");
    assert!(
        as_shipped.worst_err_rot < 0.1,
        "as shipped, a model {:.3} off was swapped in",
        as_shipped.worst_err_rot
    );
}
