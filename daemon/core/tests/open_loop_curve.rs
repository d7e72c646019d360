//! The open loop's second level (`estimator.second_amplitude`): with one level per direction
//! an untold thrust curve (eight_vectored_lag80ms_curve: thrust ~ command^1.5, 0.58 in
//! reverse where 0.78 is assumed, an 80 ms lag) was learned right at the pulses' level only,
//! 8 % off under a 2 % bound, and swapped in. With each row's second doublet at 0.6 of the
//! first the log names the curve, the estimate learns its exponent and carries it, and its
//! bound covers what is left. Linear thrusters learn no curve. Figures in docs/study.md ("A
//! second level: the open loop sees the curve").

use thruster_inprocess::estimation::{estimate_configured, Outcome};
use thruster_sim::NoisePreset;
use thrusterd_core::estimator::EstimatorConfig;

fn estimate(name: &str, noise: NoisePreset, seed: u64, second_amplitude: f64) -> Outcome {
    let cfg = EstimatorConfig {
        second_amplitude,
        ..EstimatorConfig::dynamic()
    };
    estimate_configured(name, noise, seed, cfg)
}

fn worst_over_bound(o: &Outcome) -> f64 {
    (o.err_rot / o.bound[0]).max(o.err_acc / o.bound[1])
}

#[test]
fn an_untold_curve_is_learned_in_the_open_loop_with_a_second_level() {
    let curve = "eight_vectored_lag80ms_curve";
    // One level: the confident wrong model this closes (0.083 under 0.020 noise-free).
    let one = estimate(curve, NoisePreset::None, 1, 1.0);
    assert_eq!(one.terms.command_exponent, None);
    assert!(
        worst_over_bound(&one) > 3.0,
        "err {:.4} / {:.4} under {:?}",
        one.err_rot,
        one.err_acc,
        one.bound
    );
    for (noise, p_tol, err_max) in [
        (NoisePreset::None, 0.01, 0.035),
        (NoisePreset::Realistic, 0.03, 0.045),
    ] {
        let o = estimate(curve, noise, 1, 0.6);
        let p = o.terms.command_exponent.expect("the curve learned");
        println!(
            "{noise:?}: p {p:.4}, err {:.4} / {:.4} under {:.4} / {:.4}, lag {:.3} s, {:.2} s",
            o.err_rot, o.err_acc, o.bound[0], o.bound[1], o.spin_up_s, o.seconds
        );
        assert!((p / 1.5 - 1.0).abs() <= p_tol, "{noise:?}: p {p}");
        assert!(
            o.err_rot <= err_max && o.err_acc <= err_max,
            "{noise:?}: err {:.4} / {:.4}",
            o.err_rot,
            o.err_acc
        );
        assert!(
            worst_over_bound(&o) <= 1.0,
            "{noise:?}: err {:.4} / {:.4} under {:?}",
            o.err_rot,
            o.err_acc,
            o.bound
        );
        assert!(
            (o.spin_up_s - 0.08).abs() <= 0.005,
            "{noise:?}: lag {}",
            o.spin_up_s
        );
        let c = o.terms.thrust_curve.expect("the evidence reported");
        assert!(c.log_likelihood_ratio > 1000.0, "{c:?}");
    }
}

/// At the paper's noise the lag is not learned (the gyro is too noisy) and the configured
/// 0.1 s stands for the file's 0.08 s: learned there, the curve took up the lag's error
/// (^1.52-1.66, the model 0.18-0.24 off under 0.08, seeds 1-5). So no curve is learned
/// where the lag cannot be.
#[test]
fn no_curve_is_learned_where_the_lag_cannot_be() {
    let o = estimate("eight_vectored_lag80ms_curve", NoisePreset::Paper, 1, 0.6);
    println!(
        "paper: err {:.4} / {:.4} under {:.4} / {:.4}, lag {:.3} learned {}",
        o.err_rot, o.err_acc, o.bound[0], o.bound[1], o.spin_up_s, o.spin_up_learned
    );
    assert!(!o.spin_up_learned);
    assert_eq!(o.terms.command_exponent, None);
}

#[test]
fn linear_thrusters_learn_no_curve_at_two_levels() {
    for name in ["amour5", "eight_vectored"] {
        for (noise, err_max) in [(NoisePreset::None, 0.005), (NoisePreset::Realistic, 0.035)] {
            let o = estimate(name, noise, 1, 0.6);
            println!(
                "{name} {noise:?}: err {:.4} / {:.4} under {:.4} / {:.4}, {:.2} s",
                o.err_rot, o.err_acc, o.bound[0], o.bound[1], o.seconds
            );
            assert_eq!(o.terms.command_exponent, None, "{name} {noise:?}");
            assert!(
                o.err_rot <= err_max && o.err_acc <= err_max,
                "{name} {noise:?}"
            );
        }
    }
}

/// Flown on: the model swapped in carries the curve (the commands then go out through it),
/// and the vehicle follows a 15 deg pitch step closer than on the one-level model.
#[test]
fn the_curve_learned_open_loop_is_flown() {
    use nalgebra::UnitQuaternion;
    use thruster_inprocess::run::Run;
    let fly = |second_amplitude: f64| {
        let mut run = Run::new("eight_vectored_lag80ms_curve", NoisePreset::Realistic, 1);
        run.with_setup(|s| s.estimator.second_amplitude = second_amplitude);
        run.run_for(1.0);
        run.estimate();
        let carried = run
            .machine
            .model()
            .and_then(|m| m.dynamics.as_ref())
            .and_then(|d| d.command_exponent);
        let setpoint = UnitQuaternion::from_euler_angles(0.0, 15f64.to_radians(), 0.0);
        run.machine.on_setpoint(setpoint, None);
        run.run_for(5.0);
        let (mut sum, mut count) = (0.0, 0);
        let start = run.sim.time_s();
        while run.sim.time_s() - start < 10.0 {
            run.tick();
            sum += (setpoint.inverse() * run.sim.attitude())
                .angle()
                .to_degrees();
            count += 1;
        }
        (carried, sum / count as f64)
    };
    let (one_curve, one_err) = fly(1.0);
    let (two_curve, two_err) = fly(0.6);
    println!("one level: curve {one_curve:?}, {one_err:.2} deg; two levels: curve {two_curve:?}, {two_err:.2} deg");
    assert_eq!(one_curve, None);
    let p = two_curve.expect("the model in force carries the curve");
    assert!((p / 1.5 - 1.0).abs() < 0.03, "{p}");
    assert!(two_err < one_err, "{two_err} vs {one_err}");
}
