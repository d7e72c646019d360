//! Issue 32, what breaks the acceleration rows in a swell: a 1-2 s rest takes the swell's
//! rotation for the gyro's bias, and its last accelerometer reading, swell and all, for
//! "down"; the navigation carries both through the run. After `machine.gyro_bias_rest_s` (60
//! s) of idling the machine takes the bias from how the gyro turned gravity and the magnetic
//! field over the idle spell (`navigation::long_rest_bias`) and "down" from the accelerometer
//! averaged over its last 20 s, carried by the gyro (`navigation::long_rest_down`).
//! docs/study.md, "The gyro's bias from a long rest".

use thruster_inprocess::estimation::{estimate_ideal, Ideal, Outcome};
use thruster_inprocess::swell_phase;
use thruster_sim::disturbance::WaterPreset;
use thruster_sim::{NoisePreset, SensorConfig};
use thrusterd_core::estimator::EstimatorConfig;

/// AMOUR-5 asked for a model after idling 125 s in the moderate water at 0.7 of its swell
/// (the swell at seed 2's phase; noise-free IMU at the centre), the long rest `bias_rest_s`.
fn flight(bias_rest_s: f64) -> Outcome {
    swell_flight("amour5", SensorConfig::ideal(200.0), 0.7, 2, bias_rest_s)
}

/// `vehicle` asked for a model after idling 125 s in the moderate water at `scale` of its
/// swell, at seed `seed`'s phase and with its sensors' noise, the long rest `bias_rest_s`.
fn swell_flight(
    vehicle: &str,
    sensors: SensorConfig,
    scale: f64,
    seed: u64,
    bias_rest_s: f64,
) -> Outcome {
    let ideal = Ideal {
        allow_refusal: true,
        water: WaterPreset::Moderate,
        wave_scale: Some(scale),
        idle_s: Some(125.0),
        wave_phase_rad: Some(swell_phase::of_seed(seed)),
        gyro_bias_rest_s: Some(bias_rest_s),
        ..Ideal::default()
    };
    estimate_ideal(vehicle, sensors, seed, EstimatorConfig::dynamic(), ideal)
}

/// The largest error over its own bound, of the two row groups.
fn coverage(o: &Outcome) -> f64 {
    (o.err_rot / o.bound[0]).max(o.err_acc / o.bound[1])
}

#[test]
fn after_a_long_rest_in_a_swell_the_model_is_right_and_within_its_bound() {
    // The short rest's bias and "down": a wrong model swapped in, over its bound.
    let short = flight(0.0);
    // The long rest's: the same flight's model within 0.02 and its bound.
    let long = flight(60.0);
    let show = |o: &Outcome| {
        format!(
            "refused {} ({:?}), err {:.4} / {:.4} under {:.4} / {:.4}",
            o.refused, o.rejection, o.err_rot, o.err_acc, o.bound[0], o.bound[1]
        )
    };
    assert!(
        !short.refused && short.err_rot.max(short.err_acc) > 0.04 && coverage(&short) > 1.5,
        "short rest: {}",
        show(&short)
    );
    assert!(
        !long.refused && long.err_rot < 0.02 && long.err_acc < 0.02 && coverage(&long) < 1.0,
        "long rest: {}",
        show(&long)
    );
}

/// At the paper's noise (0.25 rad/s white gyro) the short rest's spread hides a weak swell,
/// but the full one still moves it: eight_vectored in the moderate preset's whole swell at
/// seed 8's phase, after 125 s idle. With the short rest its acceleration rows were swapped in
/// 0.32 off, 3.5x their bound; with the long rest 0.071 under a bound that covers it
/// (docs/study.md, "At the paper's noise": of 150 such flights the worst kept model 3.50x ->
/// 1.63x its bound).
#[test]
fn at_the_papers_noise_the_long_rest_keeps_the_full_swell_within_its_bound() {
    let sensors = || SensorConfig {
        rate_hz: 200.0,
        noise: NoisePreset::Paper,
        ..SensorConfig::default()
    };
    let short = swell_flight("eight_vectored", sensors(), 1.0, 8, 0.0);
    let long = swell_flight("eight_vectored", sensors(), 1.0, 8, 60.0);
    let show = |o: &Outcome| {
        format!(
            "refused {} ({:?}), err {:.4} / {:.4} under {:.4} / {:.4}",
            o.refused, o.rejection, o.err_rot, o.err_acc, o.bound[0], o.bound[1]
        )
    };
    assert!(
        !short.refused && short.err_acc > 0.15 && coverage(&short) > 2.0,
        "short rest: {}",
        show(&short)
    );
    assert!(
        !long.refused && long.err_acc < 0.1 && coverage(&long) < 1.5,
        "long rest: {}",
        show(&long)
    );
}
