//! The identification that starts again on a thrust curve just learned runs long enough to
//! name what is left of the exponent (`identification.curve_confirm_min_s`).
//!
//! eight_vectored_lag80ms_curve (thrust ~ command^1.5, the daemon not told), a realistic IMU,
//! seed 10, +-20 deg pitch steps: the first identification under control learns ^1.378 (the
//! wide grid's parabola, 8 % low). Stopped at 4 s by its bound, the confirmation's narrow grid
//! judged what was left linear, the curve stayed 8 % low, and the refinement carried the model
//! to the hold's gain: 0.17 off against the truth under a 0.115 bound after 90 s (1.61x).
//! Run for 8 s, it names the rest and learns ^1.507 (docs/study.md, "The curve's
//! confirmation, long enough to name what is left"). In-process runs are deterministic.

use thruster_inprocess::holding::PitchSteps;
use thruster_inprocess::run::{rel_err, Run};
use thruster_sim::disturbance::WaterPreset;
use thruster_sim::NoisePreset;
use thrusterd_core::machine::Event;

/// What 90 s of pitch steps left: the curve the model in force carries, its error against
/// the truth over its own bound (the larger row group's), and how long each identification
/// on a learned curve ran, s of dither.
struct Flight {
    exponent: f64,
    coverage: f64,
    confirmations_s: Vec<f64>,
}

fn fly(confirm_min_s: Option<f64>) -> Flight {
    let mut run = Run::new("eight_vectored_lag80ms_curve", NoisePreset::Realistic, 10);
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
    let coverage = (rel_err(&m.effectiveness, &truth, 0) / m.rel_err_rot)
        .max(rel_err(&m.effectiveness, &truth, 3) / m.rel_err_acc);
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
    // Without the longer confirmation the case is what the test is for: the curve 8 % low
    // and the model beyond its bound. Otherwise the check below could not fail.
    assert!(
        (short.exponent / 1.5 - 1.0).abs() > 0.05,
        "{}",
        short.exponent
    );
    assert!(short.coverage > 1.2, "{}", short.coverage);
    // Shipped: the curve within 2 % and the model within its bound.
    assert!(
        (shipped.exponent / 1.5 - 1.0).abs() < 0.02,
        "{}",
        shipped.exponent
    );
    assert!(shipped.coverage < 1.0, "{}", shipped.coverage);
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
