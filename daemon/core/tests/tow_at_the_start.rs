//! Issue 32: a vehicle a 10 N tether tows through the water while idle. The navigation starts
//! its velocity from zero at the rest, and a steady speed is rest to an accelerometer, so the
//! damping terms acted on a velocity 0.77 m/s off: at a realistic IMU AMOUR-5's lag came out
//! 4 % long and its rotation rows 2.1x their bound. Where a long rest saw the vehicle move,
//! the stopped open loop's model is made again with the start velocity searched
//! (`estimator.start_velocity_search_mps`, `estimator::dynamic::start_velocity`).
//! docs/study.md, "A tether's tow at the start".

use thruster_inprocess::estimation::{estimate_ideal, estimate_observed, Ideal, Outcome};
use thruster_inprocess::vehicle;
use thruster_sim::{NoisePreset, SensorConfig};
use thrusterd_core::estimator::EstimatorConfig;

/// A 10 N tether, the model asked for after 125 s idle.
fn tethered() -> Ideal {
    Ideal {
        allow_refusal: true,
        idle_s: Some(125.0),
        tether_n: Some(10.0),
        ..Ideal::default()
    }
}

/// `vehicle` on the tether (`tethered`); `search_mps` the key.
fn towed(vehicle: &str, noise: NoisePreset, seed: u64, search_mps: f64) -> Outcome {
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise,
        ..SensorConfig::default()
    };
    let cfg = EstimatorConfig {
        start_velocity_search_mps: search_mps,
        ..EstimatorConfig::dynamic()
    };
    estimate_ideal(vehicle, sensors, seed, cfg, tethered())
}

fn line(o: &Outcome) -> String {
    format!(
        "refused {}, lag {:.4}, {:.4} / {:.4} under {:.4} / {:.4}, start velocity {:?}",
        o.refused,
        o.spin_up_s,
        o.err_rot,
        o.err_acc,
        o.bound[0],
        o.bound[1],
        o.terms.start_velocity_ned_mps
    )
}

fn over(o: &Outcome) -> f64 {
    (o.err_rot / o.bound[0]).max(o.err_acc / o.bound[1])
}

/// Noise-free the search finds the tow (the truth at the log's start: AMOUR-5 -0.765 m/s
/// north, eight_vectored -0.260) and the models come closer to the truth. Measured (seed 1):
/// AMOUR-5 -0.727, 0.0066 / 0.0065 -> 0.0040 / 0.0040; eight_vectored -0.258, 0.0038 / 0.0092
/// -> 0.0017 / 0.0018.
#[test]
fn noise_free_the_search_finds_the_tow() {
    for (vehicle, tow) in [("amour5", -0.765), ("eight_vectored", -0.260)] {
        let without = towed(vehicle, NoisePreset::None, 1, 0.0);
        let with = towed(vehicle, NoisePreset::None, 1, 1.5);
        let what = format!(
            "{vehicle}: without {}\nwith {}",
            line(&without),
            line(&with)
        );
        assert!(without.terms.start_velocity_ned_mps.is_none(), "{what}");
        let v = with.terms.start_velocity_ned_mps.expect(&what);
        assert!(
            (v[0] - tow).abs() < 0.05 && v[1].abs() < 0.05 && v[2] == 0.0,
            "{what}"
        );
        assert!(
            !with.refused
                && with.err_rot.max(with.err_acc) < 0.005
                && with.err_rot.max(with.err_acc) < 0.8 * without.err_rot.max(without.err_acc),
            "{what}"
        );
    }
}

/// At a realistic IMU the decisive seeds: AMOUR-5's 7 and 9 had their rotation rows 2.09x and
/// 2.04x their bound, the lag 104.0 / 104.1 ms; with the search 0.13x and 1.15x, 99.8 / 102.3
/// ms. The run and its stop are the same (the search is made only in the job that makes the
/// model).
/// Thrusters of two lags (0.1 s and 0.12 s, alternating), noise-free: the lags searched again
/// on the moved log start from those found before the move too. From the common lag alone
/// the search stopped at 0.115 / 0.141 s on the vectored thrusters and the model was 0.086 /
/// 0.138 off, 2.35x its bound (the review's every-vehicle check, 2026-12-06); from there it is
/// 0.0076 / 0.0091 off, lags within 1 %.
#[test]
fn noise_free_two_lags_are_found_again_after_the_move() {
    let o = towed("eight_vectored_lag100_120ms", NoisePreset::None, 1, 1.5);
    let what = format!("{}, lags {:?}", line(&o), o.terms.spin_up_per_thruster_s);
    assert!(o.terms.start_velocity_ned_mps.is_some(), "{what}");
    let lags = &o.terms.spin_up_per_thruster_s;
    assert_eq!(lags.len(), 8, "{what}");
    for (i, lag) in lags.iter().enumerate() {
        let truth = if i % 2 == 0 { 0.1 } else { 0.12 };
        assert!((lag / truth - 1.0).abs() < 0.02, "thruster {i}: {what}");
    }
    assert!(!o.refused && over(&o) < 0.5, "{what}");
    assert!(o.err_rot.max(o.err_acc) < 0.015, "{what}");
}

#[test]
fn at_a_realistic_imu_the_tow_no_longer_makes_a_confident_wrong_model() {
    for seed in [7, 9] {
        let without = towed("amour5", NoisePreset::Realistic, seed, 0.0);
        let with = towed("amour5", NoisePreset::Realistic, seed, 1.5);
        let what = format!(
            "seed {seed}: without {}\nwith {}",
            line(&without),
            line(&with)
        );
        assert!(over(&without) > 1.8, "the case tests something: {what}");
        assert!(with.terms.start_velocity_ned_mps.is_some(), "{what}");
        assert!(!with.refused && over(&with) < 1.3, "{what}");
        assert!((with.spin_up_s / 0.1 - 1.0).abs() < 0.03, "{what}");
        assert_eq!(with.seconds, without.seconds, "{what}");
    }
}

/// The operator is told: the status the model converged with names the speed the fit found
/// (no sensor showed it). Noise-free AMOUR-5, seed 1: 0.73 m/s.
#[test]
fn the_status_says_the_vehicle_was_moving() {
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise: NoisePreset::None,
        ..SensorConfig::default()
    };
    let mut said = Vec::<String>::new();
    let o = estimate_observed(
        vehicle("amour5"),
        sensors,
        1,
        EstimatorConfig {
            start_velocity_search_mps: 1.5,
            ..EstimatorConfig::dynamic()
        },
        tethered(),
        &mut |m, _| {
            let text = m.status().text;
            if said.last() != Some(&text) {
                said.push(text);
            }
        },
    );
    assert!(o.terms.start_velocity_ned_mps.is_some(), "{}", line(&o));
    assert!(
        said.iter().any(|t| t.starts_with("converged")
            && t.contains("moving 0.7")
            && t.contains("m/s at the start")
            && t.len() <= 128),
        "{said:#?}"
    );
}

/// Where no long rest saw the vehicle move nothing is searched: still water after the same
/// idle gives the same model with the key on and off.
#[test]
fn still_water_is_not_searched() {
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise: NoisePreset::Realistic,
        ..SensorConfig::default()
    };
    let run = |search_mps: f64| {
        let cfg = EstimatorConfig {
            start_velocity_search_mps: search_mps,
            ..EstimatorConfig::dynamic()
        };
        let ideal = Ideal {
            allow_refusal: true,
            idle_s: Some(125.0),
            ..Ideal::default()
        };
        estimate_ideal("amour5", sensors.clone(), 1, cfg, ideal)
    };
    let (off, on) = (run(0.0), run(1.5));
    assert!(on.terms.start_velocity_ned_mps.is_none(), "{}", line(&on));
    assert_eq!(
        (on.err_rot, on.err_acc, on.bound, on.seconds),
        (off.err_rot, off.err_acc, off.bound, off.seconds)
    );
}
