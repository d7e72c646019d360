//! Issue 30, the paper's noise: the dead-reckoned velocity there is 0.6-2.5 m/s off where
//! the vehicle moves a few tenths, and the nuisance of the terms built from it (damping in v,
//! the products with a velocity) was most of the bound the open loop waits on. Held lightly
//! at zero (`estimator.velocity_term_prior_sd`, opt-in), the run stops sooner with a model no
//! worse; where the velocity is good (noise-free) the data outweighs the prior.
//! docs/study.md, "At the paper's noise".

use thruster_inprocess::estimation::{estimate_ideal, Ideal, Outcome};
use thruster_sim::{NoisePreset, SensorConfig};
use thrusterd_core::estimator::EstimatorConfig;

/// One open-loop estimation in still water, the velocity terms' prior `sd` (0: none).
fn flight(vehicle: &str, noise: NoisePreset, seed: u64, sd: f64) -> Outcome {
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise,
        ..SensorConfig::default()
    };
    let cfg = EstimatorConfig {
        velocity_term_prior_sd: sd,
        ..EstimatorConfig::dynamic()
    };
    let ideal = Ideal {
        allow_refusal: true,
        ..Ideal::default()
    };
    estimate_ideal(vehicle, sensors, seed, cfg, ideal)
}

#[test]
fn at_the_papers_noise_the_velocity_terms_held_stop_sooner_with_a_model_no_worse() {
    let (mut free_s, mut held_s, mut free_rot, mut held_rot) = (0.0, 0.0, 0.0, 0.0);
    let mut lines = Vec::new();
    for vehicle in ["amour5", "six_dof"] {
        for seed in 1..=4 {
            let free = flight(vehicle, NoisePreset::Paper, seed, 0.0);
            let held = flight(vehicle, NoisePreset::Paper, seed, 0.1);
            lines.push(format!(
                "{vehicle} seed {seed}: free {:.2} s {:.4} / {:.4}, held {:.2} s {:.4} / {:.4} under {:.4} / {:.4}",
                free.seconds, free.err_rot, free.err_acc, held.seconds, held.err_rot,
                held.err_acc, held.bound[0], held.bound[1]
            ));
            assert!(!held.refused, "{}", lines.join("\n"));
            // Each held model as good as the paper's noise allows, and within 1.5x its bound.
            assert!(
                held.err_rot < 0.07
                    && held.err_acc < 0.10
                    && held.err_rot < 1.5 * held.bound[0]
                    && held.err_acc < 1.5 * held.bound[1],
                "{}",
                lines.join("\n")
            );
            free_s += free.seconds;
            held_s += held.seconds;
            free_rot += free.err_rot;
            held_rot += held.err_rot;
        }
    }
    let n = 8.0;
    eprintln!(
        "mean {:.2} -> {:.2} s, err_rot {:.4} -> {:.4}",
        free_s / n,
        held_s / n,
        free_rot / n,
        held_rot / n
    );
    // Measured: 6.23 -> 5.22 s on these eight flights, err_rot 0.0440 -> 0.0395.
    assert!(
        held_s / n < free_s / n - 0.5 && held_rot <= free_rot + 0.005 * n,
        "mean {:.2} -> {:.2} s, err_rot {:.4} -> {:.4}\n{}",
        free_s / n,
        held_s / n,
        free_rot / n,
        held_rot / n,
        lines.join("\n")
    );
}

#[test]
fn noise_free_the_velocity_terms_held_leave_the_model_as_it_was() {
    for vehicle in ["amour5", "eight_vectored"] {
        let free = flight(vehicle, NoisePreset::None, 1, 0.0);
        let held = flight(vehicle, NoisePreset::None, 1, 0.1);
        assert!(
            !held.refused
                && held.err_rot < 0.01
                && held.err_acc < 0.01
                && (held.seconds - free.seconds).abs() < 1e-9,
            "{vehicle}: free {:.2} s {:.4} / {:.4}, held {:.2} s {:.4} / {:.4}",
            free.seconds,
            free.err_rot,
            free.err_acc,
            held.seconds,
            held.err_rot,
            held.err_acc
        );
    }
}
