//! Issue 32: a 10 N tether met after two minutes' idle. Its pull varies over 20 s, too slowly
//! for the fit to leave the 0.0025 rad/s of rotation unexplained that opens the moving-water
//! refit, and the models came out up to 4.5x their bound. The long rest sees the vehicle
//! sway on it (`navigation::long_rest_sway`, `machine.max_still_sway`), and where it did the
//! refit is made with a world-fixed constant force and ramp besides the swell's states
//! (`estimator.moving_rest_drift_states`). docs/study.md, "The water a long rest saw".

use thruster_inprocess::estimation::{estimate_ideal, Ideal, Outcome};
use thruster_sim::{NoisePreset, SensorConfig};
use thrusterd_core::estimator::EstimatorConfig;

/// eight_vectored on a 10 N tether, asked for a model after 125 s idle.
fn tethered(noise: NoisePreset, drift_states: bool) -> Outcome {
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise,
        ..SensorConfig::default()
    };
    let cfg = EstimatorConfig {
        moving_rest_drift_states: drift_states,
        ..EstimatorConfig::dynamic()
    };
    let ideal = Ideal {
        allow_refusal: true,
        idle_s: Some(125.0),
        tether_n: Some(10.0),
        ..Ideal::default()
    };
    estimate_ideal("eight_vectored", sensors, 1, cfg, ideal)
}

fn line(o: &Outcome) -> String {
    format!(
        "sway {:?}, refused {}, {:.4} / {:.4} under {:.4} / {:.4}",
        o.rest_sway, o.refused, o.err_rot, o.err_acc, o.bound[0], o.bound[1]
    )
}

fn over(o: &Outcome) -> f64 {
    (o.err_rot / o.bound[0]).max(o.err_acc / o.bound[1])
}

/// Noise-free first, then a realistic IMU. Measured (seed 1): noise-free 0.041 under 0.025
/// (1.64x) without the states, 0.004 / 0.009 with; realistic 0.051 under 0.023 (2.16x)
/// without, 0.019 / 0.033 under 0.025 / 0.038 with.
#[test]
fn a_tether_the_long_rest_saw_is_fitted_as_drift_and_within_its_bound() {
    for (noise, worst_without, within) in [
        (NoisePreset::None, 1.4, 0.01),
        (NoisePreset::Realistic, 1.8, 0.035),
    ] {
        let without = tethered(noise, false);
        let with = tethered(noise, true);
        let what = format!(
            "{noise:?}: without {}\nwith {}",
            line(&without),
            line(&with)
        );
        assert!(with.rest_sway.is_some_and(|r| r > 1.5), "{what}");
        assert!(
            over(&without) > worst_without,
            "the case tests something: {what}"
        );
        assert!(
            !with.refused && with.err_rot < within && with.err_acc < within && over(&with) < 1.0,
            "{what}"
        );
    }
}
