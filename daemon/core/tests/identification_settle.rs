//! The identification under control stops at `identification.min_s` (3 s of dither) only when
//! its estimate has settled (`identification.settle`): since the decision before, each row
//! group moved by at most its own bound or 1 %. Otherwise it waits up to `settle_wait_s` (1 s)
//! more. Against the simulator's truth, after the first thruster is turned 45 deg and
//! announced. In-process runs are deterministic: the numbers in the comments are what these
//! seeds gave (docs/study.md, "Under control in 4 s").

mod common;
use common::{rotate_while_holding_on, vehicle, Reestimation, Run};
use thruster_sim::NoisePreset;
use thrusterd_core::model::ModelSource;

/// The announced turn on `name`, with the identification's settle factor `settle`.
fn turned(name: &str, noise: NoisePreset, seed: u64, settle: f64) -> Reestimation {
    turned_with(name, noise, seed, |s| s.identification.settle = settle)
}

fn turned_with(
    name: &str,
    noise: NoisePreset,
    seed: u64,
    setup: impl FnOnce(&mut thrusterd_core::machine::MachineSetup),
) -> Reestimation {
    let mut run = Run::new(name, noise, seed);
    run.with_setup(setup);
    let (_, r) = rotate_while_holding_on(run, &vehicle(name), None, |_, _| {});
    assert_eq!(r.source, ModelSource::Estimated, "{name}: {r:?}");
    r
}

/// A steady estimate stops at 3 s of dither: 3.5 s after the announcement (0.5 s of holding
/// first, `identification.lead_in_s`). AMOUR-5 noise-free: 0.003 / 0.005 off (0.005 / 0.007
/// at 4 s after the 1 s hold of before).
#[test]
fn a_steady_estimate_stops_at_the_minimum() {
    let r = turned("amour5", NoisePreset::None, 1, 1.0);
    assert!(r.took_s < 4.0, "{r:?}");
    assert!(r.err_rot < 0.01 && r.err_acc < 0.01, "{r:?}");
}

/// A vehicle whose thrusters are weaker in reverse than the model can say (amour5_reverse60,
/// noise-free): the estimate wanders with the stop time, moving 1.5 % from the decision at 2 s
/// to the one at 3 s under a rotation bound of 0.6 %. Waiting for it to settle: 0.008 /
/// 0.016 at 4.5 s. Without the wait (the decisive run): 0.008 / 0.024 at 3.5 s (with the 1 s
/// hold of before: 0.011 / 0.017 at 5 s against 0.019 / 0.030 at 4 s).
///
/// The flight as found: the first model on the bare command. With the first model fitted to
/// the thrust's shape (`estimator.shaped_thrust`) nothing wanders here: the hasty run stops at
/// 3.5 s, 0.006 / 0.018 off.
#[test]
fn a_wandering_estimate_is_waited_for() {
    let as_found = |settle: f64| {
        turned_with("amour5_reverse60", NoisePreset::None, 1, |s| {
            common::bare_first_model(s);
            s.identification.settle = settle;
        })
    };
    let settled = as_found(1.0);
    let hasty = as_found(0.0);
    assert!(hasty.took_s < 4.0, "{hasty:?}");
    assert!(
        settled.took_s > 4.0 && settled.took_s < 5.0,
        "waited at most settle_wait_s: {settled:?}"
    );
    assert!(
        settled.err_rot < 0.012 && settled.err_acc < 0.02,
        "{settled:?}"
    );
    assert!(hasty.err_acc > 0.022, "the decisive run: {hasty:?}");
}

/// Thrusters of two makes (lags 0.03 and 0.2 s) on eight_vectored, noise-free: at 3 s of
/// dither the estimate is still moving, and the run waits. With the 1 s hold of before the
/// wait took it from 0.031 / 0.070 to 0.012 / 0.048 off; after the 0.5 s lead-in the hasty
/// run is 0.021 / 0.018 at 3.5 s and the settled one 0.015 / 0.027 at 4.5 s, both within
/// their bounds (0.055 / 0.051, the lags' error): the wait no longer pays here.
#[test]
fn two_makes_of_thruster_are_waited_for() {
    let settled = turned("eight_vectored_two_makes", NoisePreset::None, 1, 1.0);
    let hasty = turned("eight_vectored_two_makes", NoisePreset::None, 1, 0.0);
    assert!(
        hasty.took_s < 4.0 && settled.took_s > 4.0,
        "{hasty:?} {settled:?}"
    );
    assert!(
        settled.err_rot < 0.02 && settled.err_acc < 0.035,
        "{settled:?}"
    );
}

/// A steady estimate that moved just over its bound at `min_s` (AMOUR-5, a realistic IMU,
/// seeds 5 and 8, which the sweep over seeds 1-30 found waiting): deciding the wait only once a
/// segment (`settle_decision_s` = 1, the default until 2026-12-06) holds it a whole second;
/// deciding every 0.1 s (the default), each time against the estimate a segment older, it
/// stops as soon as it has settled. Measured (from the announcement): 4.52 s against 3.62 /
/// 3.72 s, 0.006 / 0.010 and 0.008 / 0.013 off against 0.008 / 0.009 and 0.007 / 0.010.
#[test]
fn a_steady_estimate_is_not_held_a_whole_second() {
    for seed in [5, 8] {
        let once_a_segment = turned_with("amour5", NoisePreset::Realistic, seed, |s| {
            s.identification.settle_decision_s = 1.0
        });
        let finer = turned_with("amour5", NoisePreset::Realistic, seed, |_| {});
        eprintln!("seed {seed}: {once_a_segment:?} {finer:?}");
        assert!(
            once_a_segment.took_s > 4.4,
            "the decisive run waits a second (seed {seed}): {once_a_segment:?}"
        );
        assert!(
            finer.took_s < 4.0 && finer.took_s > 3.5,
            "stopped once settled, after min_s (seed {seed}): {finer:?}"
        );
        assert!(
            finer.err_rot < 0.02 && finer.err_acc < 0.03,
            "issue 30's accuracy (seed {seed}): {finer:?}"
        );
    }
}
