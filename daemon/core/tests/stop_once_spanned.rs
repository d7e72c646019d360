//! The open loop's early stop (`estimator.stop_once_spanned`): a vehicle with fewer
//! thrusters than the Hadamard order (AMOUR-5: 5 thrusters, 8 rows of four pulses) has its
//! thrusters told apart after 5 rows, so the run may stop at 20-28 pulses instead of the 32
//! of a whole cycle when the bound allows. Before the cycle ends the bound must be at
//! `reach_rel_err` too (`short_of_reach_mid_cycle`). Checked against the simulator's truth
//! noise-free first, then at a realistic IMU; eight_vectored, whose 8 thrusters need every
//! row, is unchanged. Figures in docs/study.md ("Stopping once the pulses tell the thrusters
//! apart").

use thruster_inprocess::estimation::{estimate_configured, Outcome};
use thruster_sim::NoisePreset;
use thrusterd_core::estimator::EstimatorConfig;

fn estimate(name: &str, noise: NoisePreset, seed: u64, stop_once_spanned: bool) -> Outcome {
    let cfg = EstimatorConfig {
        stop_once_spanned,
        ..EstimatorConfig::dynamic()
    };
    estimate_configured(name, noise, seed, cfg)
}

/// [`estimate`] without the learned lag's reach (`learned_lag_reach_rel_err`, 0.025 by
/// default since 2026-12-07). With it, AMOUR-5 at a realistic IMU waits mid-cycle for a bound
/// of 0.025 and runs the whole cycle (seeds 1-3: 3.23 s, the same model as without the early
/// stop), so the early stop saves time only where that reach is off.
fn estimate_without_lag_reach(name: &str, noise: NoisePreset, seed: u64, once: bool) -> Outcome {
    let cfg = EstimatorConfig {
        stop_once_spanned: once,
        learned_lag_reach_rel_err: 0.0,
        ..EstimatorConfig::dynamic()
    };
    estimate_configured(name, noise, seed, cfg)
}

fn show(label: &str, o: &Outcome) {
    println!(
        "{label}: {:.2} s, err {:.4} / {:.4} under {:.4} / {:.4}, lag {:.4} s, tilt {:.0} deg",
        o.seconds, o.err_rot, o.err_acc, o.bound[0], o.bound[1], o.spin_up_s, o.max_tilt_deg
    );
}

/// One pulse of the default plan (`machine.pulse_s` 0.1 s): the early stop saves at least
/// one doublet pair (4 pulses), a cycle of 32 pulses takes 3.2 s.
const PULSE_S: f64 = 0.1;

#[test]
fn amour5_stops_before_the_cycle_ends_with_the_model_within_the_targets() {
    // Noise-free: the bound is at its floor as soon as the thrusters are told apart, so the
    // run stops at the first doublet pair after the fifth row (20 pulses).
    let whole = estimate("amour5", NoisePreset::None, 1, false);
    let early = estimate("amour5", NoisePreset::None, 1, true);
    show("noise-free, whole cycle", &whole);
    show("noise-free, once spanned", &early);
    assert!(
        early.seconds <= whole.seconds - 10.0 * PULSE_S,
        "{:.2} s against {:.2} s",
        early.seconds,
        whole.seconds
    );
    assert!(early.err_rot <= 0.005 && early.err_acc <= 0.005);
    assert!(early.err_rot <= early.bound[0] && early.err_acc <= early.bound[1]);
    assert!(
        (early.spin_up_s - 0.1).abs() <= 0.002,
        "{}",
        early.spin_up_s
    );
    // The smaller part of the cycle tilts the vehicle less (22 -> 14 deg measured).
    assert!(early.max_tilt_deg < whole.max_tilt_deg);

    // A realistic IMU: the bound is at `reach_rel_err` a pair or two later (28 pulses on
    // seeds 1-10); the model within issue 30's 0.02 / 0.03 and its own bound.
    for seed in 1..=3 {
        // The shipped reaches: never longer than the whole cycle, the model within targets.
        let shipped = estimate("amour5", NoisePreset::Realistic, seed, true);
        show(
            &format!("realistic seed {seed}, once spanned, shipped"),
            &shipped,
        );
        let whole = estimate_without_lag_reach("amour5", NoisePreset::Realistic, seed, false);
        assert!(shipped.seconds <= whole.seconds + 1e-6);
        assert!(shipped.err_rot <= 0.02 && shipped.err_acc <= 0.03);
        let early = estimate_without_lag_reach("amour5", NoisePreset::Realistic, seed, true);
        show(&format!("realistic seed {seed}, whole cycle"), &whole);
        show(&format!("realistic seed {seed}, once spanned"), &early);
        assert!(
            early.seconds <= whole.seconds - 4.0 * PULSE_S + 1e-6,
            "seed {seed}: {:.2} s against {:.2} s",
            early.seconds,
            whole.seconds
        );
        assert!(
            early.err_rot <= 0.02 && early.err_acc <= 0.03,
            "seed {seed}: err {:.4} / {:.4}",
            early.err_rot,
            early.err_acc
        );
        assert!(
            early.err_rot <= early.bound[0] && early.err_acc <= early.bound[1],
            "seed {seed}: err {:.4} / {:.4} under {:?}",
            early.err_rot,
            early.err_acc,
            early.bound
        );
    }
}

/// Before the cycle ends the bound must be at `reach_rel_err`, not only at the targets: the
/// rule that waits for a bound within reach gives up on a large one (its projection with the
/// model-error floor misses 0.03), and without this six_dof seed 10 stopped at 24 pulses under
/// 0.027 / 0.048, 0.026 / 0.047 off.
#[test]
fn a_large_bound_mid_cycle_goes_on_to_the_cycle_end() {
    let o = estimate("six_dof", NoisePreset::Realistic, 10, true);
    show("six_dof realistic seed 10, once spanned", &o);
    assert!(
        o.err_rot <= 0.02 && o.err_acc <= 0.03,
        "err {:.4} / {:.4} under {:?} in {:.2} s",
        o.err_rot,
        o.err_acc,
        o.bound,
        o.seconds
    );
}

#[test]
fn eight_thrusters_need_the_whole_cycle_either_way() {
    let whole = estimate("eight_vectored", NoisePreset::None, 1, false);
    let early = estimate("eight_vectored", NoisePreset::None, 1, true);
    show("eight_vectored, whole cycle", &whole);
    show("eight_vectored, once spanned", &early);
    assert_eq!(early.seconds, whole.seconds);
    assert_eq!(early.err_rot, whole.err_rot);
    assert_eq!(early.err_acc, whole.err_acc);
}
