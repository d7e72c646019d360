//! Issue 29: the dead-reckoned velocity's drift. A tilt of a milliradian left after the rest
//! leaks gravity into the velocity the damping acts on, and on AMOUR-5's slow thrusters at a
//! realistic IMU the longer runs' lag walked with it: 4-6 ms short, the model 0.027-0.038 off.
//! The job a stopping open loop makes its model in searches the drift (a world-fixed
//! horizontal ramp from the run's start) and makes the model again without it
//! (`estimator.velocity_drift_search_mps2`, `estimator::dynamic::velocity_drift`).
//! docs/study.md, "The velocity's drift searched, and a reach for slow thrusters".

use thruster_inprocess::estimation::{estimate_observed, estimate_on, with_lag, Ideal, Outcome};
use thruster_sim::{NoisePreset, SensorConfig};
use thrusterd_core::estimator::EstimatorConfig;

/// `vehicle` with every thruster's lag `tau_s` (0: the file's), the drift searched up to
/// `search_mps2` (0: off), everything else the defaults.
fn run(vehicle: &str, tau_s: f64, noise: NoisePreset, seed: u64, search_mps2: f64) -> Outcome {
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise,
        ..SensorConfig::default()
    };
    let cfg = EstimatorConfig {
        velocity_drift_search_mps2: search_mps2,
        ..EstimatorConfig::dynamic()
    };
    estimate_on(
        with_lag(vehicle, tau_s),
        sensors,
        seed,
        cfg,
        Ideal::default(),
    )
}

fn line(o: &Outcome) -> String {
    format!(
        "{:.2} s, lag {:.4}, {:.4} / {:.4} under {:.4} / {:.4}, drift {:?}",
        o.seconds,
        o.spin_up_s,
        o.err_rot,
        o.err_acc,
        o.bound[0],
        o.bound[1],
        o.terms.velocity_drift_ned_mps2
    )
}

/// The decisive seeds: AMOUR-5 at 0.2 s, realistic IMU, the slow lags' reach on. Without the
/// search seed 5 stops 0.038 / 0.032 off with its lag 0.1936 s and seed 8 0.027 / 0.025 at
/// 0.1954 s (the drift's walk; a perfect DVL takes both right). With it, measured: seed 5
/// drift (-0.0075, 0.0044) m/s^2, lag 0.1970 s, 0.016 / 0.021; seed 8 (-0.0044, 0.0038),
/// 0.2005 s, 0.004 / 0.018.
#[test]
fn the_drift_taken_out_brings_amour5s_slow_lags_back() {
    let on = EstimatorConfig::dynamic().velocity_drift_search_mps2;
    assert!(on > 0.0, "the search is on by default");
    for seed in [5, 8] {
        let with = run("amour5", 0.2, NoisePreset::Realistic, seed, on);
        let without = run("amour5", 0.2, NoisePreset::Realistic, seed, 0.0);
        let msg = format!(
            "seed {seed}: with {}; without {}",
            line(&with),
            line(&without)
        );
        println!("{msg}");
        // Without: the lag walked and the model is over issue 29's 0.025 on a row.
        assert!(without.terms.velocity_drift_ned_mps2.is_none(), "{msg}");
        assert!(without.spin_up_s < 0.196, "{msg}");
        assert!(without.err_rot.max(without.err_acc) > 0.024, "{msg}");
        // With: a drift of the size a milliradian of tilt leaks, the lag back within 4 ms.
        let drift = with.terms.velocity_drift_ned_mps2.expect(&msg);
        let rate = drift[0].hypot(drift[1]);
        assert!((0.003..=0.015).contains(&rate), "{msg}");
        assert_eq!(drift[2], 0.0, "{msg}");
        assert!((with.spin_up_s - 0.2).abs() <= 0.004, "{msg}");
        assert!(with.err_rot <= 0.02 && with.err_acc <= 0.025, "{msg}");
        // The same stop: the search makes the stopped run's model again, nothing sooner.
        assert_eq!(with.seconds, without.seconds, "{msg}");
        // Its bound no tighter than the model's without the search.
        assert!(
            with.bound[0] >= without.bound[0] - 1e-12 && with.bound[1] >= without.bound[1] - 1e-12,
            "{msg}"
        );
    }
}

/// Where the pulses barely move the vehicle sideways a ramp soaks up what the fit leaves:
/// four_up at a realistic IMU found 0.030 m/s^2 on seeds 6 and 9 (the navigation's true drift
/// 0.002) with ln likelihood ratios of 17 and 15, and kept at 10 they made the acceleration
/// rows 0.015 -> 0.025 and 0.019 -> 0.025 off. At `VELOCITY_DRIFT_EVIDENCE` (20) they are not
/// kept: the models are those without the search, to the bit.
#[test]
fn a_drift_the_pulses_cannot_tell_is_not_kept() {
    let on = EstimatorConfig::dynamic().velocity_drift_search_mps2;
    for seed in [6, 9] {
        let with = run("four_up", 0.0, NoisePreset::Realistic, seed, on);
        let without = run("four_up", 0.0, NoisePreset::Realistic, seed, 0.0);
        let msg = format!(
            "seed {seed}: with {}; without {}",
            line(&with),
            line(&without)
        );
        println!("{msg}");
        assert!(with.terms.velocity_drift_ned_mps2.is_none(), "{msg}");
        assert_eq!(
            (with.err_rot, with.err_acc),
            (without.err_rot, without.err_acc),
            "{msg}"
        );
    }
}

/// Noise-free the navigation's velocity has only its discretisation's drift: a drift may be
/// kept, and the model moves by less than 0.0005 (measured: every vehicle file within 0.0001).
#[test]
fn noise_free_the_search_moves_no_model() {
    let on = EstimatorConfig::dynamic().velocity_drift_search_mps2;
    for vehicle in ["amour5", "eight_vectored"] {
        let with = run(vehicle, 0.2, NoisePreset::None, 1, on);
        let without = run(vehicle, 0.2, NoisePreset::None, 1, 0.0);
        let msg = format!(
            "{vehicle}: with {}; without {}",
            line(&with),
            line(&without)
        );
        println!("{msg}");
        assert!((with.err_rot - without.err_rot).abs() <= 5e-4, "{msg}");
        assert!((with.err_acc - without.err_acc).abs() <= 5e-4, "{msg}");
        assert!(with.err_rot <= 0.02 && with.err_acc <= 0.02, "{msg}");
        assert!((with.spin_up_s - 0.2).abs() <= 0.002, "{msg}");
    }
}

/// The operator is told: a model made again without a drift says so in the status, since no
/// sensor showed the drift and it moved the model (AMOUR-5 at 0.2 s, seed 5: 0.0087 m/s^2).
#[test]
fn the_status_says_a_drift_was_taken_out() {
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise: NoisePreset::Realistic,
        ..SensorConfig::default()
    };
    let mut said: Vec<String> = Vec::new();
    let o = estimate_observed(
        with_lag("amour5", 0.2),
        sensors,
        5,
        EstimatorConfig::dynamic(),
        Ideal::default(),
        &mut |m, _| {
            let text = m.status().text;
            if said.last() != Some(&text) {
                said.push(text);
            }
        },
    );
    let drift = o
        .terms
        .velocity_drift_ned_mps2
        .unwrap_or_else(|| panic!("{}", line(&o)));
    let rate = format!("{:.4}", drift[0].hypot(drift[1]));
    assert!(
        said.iter().any(|t| t.starts_with("converged")
            && t.contains(&format!("velocity drift {rate} m/s^2 taken out"))
            && t.len() <= 128),
        "{said:#?}"
    );
}
