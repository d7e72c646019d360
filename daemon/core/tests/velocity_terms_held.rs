//! Issue 30, the paper's noise: the dead-reckoned velocity there is 0.6-2.5 m/s off where
//! the vehicle moves a few tenths, and the nuisance of the terms built from it (damping in v,
//! the products with a velocity) was most of the bound the open loop waits on. Held lightly
//! at zero (`estimator.velocity_term_prior_sd`, 0.1 by default), the run stops sooner with a
//! model no worse; where the velocity is good (noise-free) the data outweighs the prior. Only
//! where a long idle rest saw still water (`machine.max_still_sway`): in a swell at the
//! paper's noise the prior's bound was not honest, and only a long rest sees that swell there.
//! docs/study.md, "The velocity terms held where a long rest saw still water".

use thruster_inprocess::estimation::{estimate_ideal, Ideal, Outcome};
use thruster_sim::disturbance::WaterPreset;
use thruster_sim::{NoisePreset, SensorConfig};
use thrusterd_core::estimator::EstimatorConfig;

/// Idle this long before the request: past `machine.gyro_bias_rest_s` (60 s), so the run
/// starts from a long rest.
const LONG_IDLE_S: f64 = 125.0;

/// One open-loop estimation after `idle_s` idle, the velocity terms' prior `sd` (0: none),
/// in still water or the moderate preset's swell times `swell`.
fn flight(
    vehicle: &str,
    noise: NoisePreset,
    seed: u64,
    sd: f64,
    idle_s: f64,
    swell: Option<f64>,
) -> Outcome {
    let cfg = EstimatorConfig {
        velocity_term_prior_sd: sd,
        ..EstimatorConfig::dynamic()
    };
    flight_with(vehicle, noise, seed, cfg, idle_s, swell)
}

/// [`flight`] with the estimator's configuration given whole.
fn flight_with(
    vehicle: &str,
    noise: NoisePreset,
    seed: u64,
    cfg: EstimatorConfig,
    idle_s: f64,
    swell: Option<f64>,
) -> Outcome {
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise,
        ..SensorConfig::default()
    };
    let ideal = Ideal {
        allow_refusal: true,
        idle_s: Some(idle_s),
        water: swell.map_or(WaterPreset::Still, |_| WaterPreset::Moderate),
        no_current: swell.is_some(),
        wave_scale: swell,
        ..Ideal::default()
    };
    estimate_ideal(vehicle, sensors, seed, cfg, ideal)
}

#[test]
fn at_the_papers_noise_after_a_still_long_rest_the_velocity_terms_held_stop_sooner() {
    let default_sd = EstimatorConfig::dynamic().velocity_term_prior_sd;
    assert!(default_sd > 0.0, "held by default");
    let (mut free_s, mut held_s, mut free_rot, mut held_rot) = (0.0, 0.0, 0.0, 0.0);
    let mut lines = Vec::new();
    for vehicle in ["amour5", "six_dof"] {
        for seed in 1..=4 {
            let paper = NoisePreset::Paper;
            let free = flight(vehicle, paper, seed, 0.0, LONG_IDLE_S, None);
            let held = flight(vehicle, paper, seed, default_sd, LONG_IDLE_S, None);
            lines.push(format!(
                "{vehicle} seed {seed}: sway {:?}, free {:.2} s {:.4} / {:.4}, held {:.2} s {:.4} / {:.4} under {:.4} / {:.4}",
                held.rest_sway, free.seconds, free.err_rot, free.err_acc, held.seconds,
                held.err_rot, held.err_acc, held.bound[0], held.bound[1]
            ));
            // The long rest read still water: its sway about what the white noise explains.
            let sway = held.rest_sway.unwrap_or(f64::NAN);
            assert!((0.7..1.5).contains(&sway), "{}", lines.join("\n"));
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
    let summary = format!(
        "mean {:.2} -> {:.2} s, err_rot {:.4} -> {:.4}\n{}",
        free_s / n,
        held_s / n,
        free_rot / n,
        held_rot / n,
        lines.join("\n")
    );
    eprintln!("{summary}");
    // Measured: 5.27 -> 4.12 s on these eight flights, err_rot 0.0530 -> 0.0444 (with the
    // acceleration rows at 0.06, before 2026-12-05: 6.52 -> 5.22 s, 0.0458 -> 0.0380).
    assert!(
        held_s / n < free_s / n - 0.5 && held_rot <= free_rot + 0.005 * n,
        "{summary}"
    );
}

/// Issue 30, the acceleration rows' own target (`estimator.target_rel_err_acc`, 0.07 since
/// 2026-12-05, 0.06 before): with the velocity terms held after a still long rest the rotation
/// rows are well inside 0.06 when the acceleration rows stop the run, and at 0.07 it stops
/// sooner with every model within 1.5x its bound. docs/study.md, "The acceleration rows'
/// target at 0.07".
#[test]
fn at_the_papers_noise_after_a_still_long_rest_the_acceleration_rows_at_0_07_stop_sooner() {
    let shipped = EstimatorConfig::dynamic();
    assert_eq!(shipped.acc_target(), 0.07);
    let before = EstimatorConfig {
        target_rel_err_acc: None,
        ..shipped.clone()
    };
    assert_eq!(before.acc_target(), 0.06);
    let (mut s06, mut s07, mut rot07) = (0.0, 0.0, 0.0);
    let mut lines = Vec::new();
    for vehicle in ["amour5", "six_dof"] {
        for seed in 1..=4 {
            let paper = NoisePreset::Paper;
            let at06 = flight_with(vehicle, paper, seed, before.clone(), LONG_IDLE_S, None);
            let at07 = flight_with(vehicle, paper, seed, shipped.clone(), LONG_IDLE_S, None);
            lines.push(format!(
                "{vehicle} seed {seed}: 0.06 {:.2} s {:.4} / {:.4}, 0.07 {:.2} s {:.4} / {:.4} under {:.4} / {:.4}",
                at06.seconds, at06.err_rot, at06.err_acc, at07.seconds, at07.err_rot,
                at07.err_acc, at07.bound[0], at07.bound[1]
            ));
            assert!(
                !at07.refused
                    && at07.seconds <= at06.seconds
                    && at07.err_rot < 1.5 * at07.bound[0]
                    && at07.err_acc < 1.5 * at07.bound[1],
                "{}",
                lines.join("\n")
            );
            s06 += at06.seconds;
            s07 += at07.seconds;
            rot07 += at07.err_rot;
        }
    }
    let n = 8.0;
    let summary = format!(
        "mean {:.2} -> {:.2} s, err_rot at 0.07 {:.4}\n{}",
        s06 / n,
        s07 / n,
        rot07 / n,
        lines.join("\n")
    );
    eprintln!("{summary}");
    // Measured: 5.22 -> 4.12 s on these eight flights (0.7-1.6 s sooner on seven, 0.4 on
    // six_dof seed 4), err_rot at 0.07 0.0444.
    assert!(
        s07 / n < s06 / n - 0.5 && s07 / n < 5.0 && rot07 / n < 0.06,
        "{summary}"
    );
}

/// A tenth of the moderate preset's swell at the paper's noise: the long rest sees it (sway
/// well over the limit) and the fit is the free one, to the bit. Without a long rest (3 s
/// idle) nothing says the water is still: the free fit again.
#[test]
fn a_swell_the_long_rest_saw_or_no_long_rest_leaves_the_velocity_terms_free() {
    let default_sd = EstimatorConfig::dynamic().velocity_term_prior_sd;
    for (idle_s, swell) in [(LONG_IDLE_S, Some(0.1)), (3.0, None)] {
        let free = flight("amour5", NoisePreset::Paper, 1, 0.0, idle_s, swell);
        let held = flight("amour5", NoisePreset::Paper, 1, default_sd, idle_s, swell);
        let what = format!(
            "idle {idle_s} s, swell {swell:?}: sway {:?}, free {:.2} s {:.4} / {:.4}, held {:.2} s {:.4} / {:.4}",
            held.rest_sway, free.seconds, free.err_rot, free.err_acc, held.seconds, held.err_rot,
            held.err_acc
        );
        match swell {
            Some(_) => assert!(held.rest_sway.is_some_and(|r| r > 5.0), "{what}"),
            None => assert!(held.rest_sway.is_none(), "{what}"),
        }
        assert!(
            held.seconds == free.seconds
                && held.err_rot == free.err_rot
                && held.err_acc == free.err_acc,
            "{what}"
        );
    }
}

#[test]
fn noise_free_the_velocity_terms_held_leave_the_model_as_it_was() {
    for vehicle in ["amour5", "eight_vectored"] {
        let free = flight(vehicle, NoisePreset::None, 1, 0.0, LONG_IDLE_S, None);
        let held = flight(vehicle, NoisePreset::None, 1, 0.1, LONG_IDLE_S, None);
        assert!(
            held.rest_sway.is_some_and(|r| r < 1.5)
                && !held.refused
                && held.err_rot < 0.01
                && held.err_acc < 0.01
                && (held.seconds - free.seconds).abs() < 1e-9,
            "{vehicle}: sway {:?}, free {:.2} s {:.4} / {:.4}, held {:.2} s {:.4} / {:.4}",
            held.rest_sway,
            free.seconds,
            free.err_rot,
            free.err_acc,
            held.seconds,
            held.err_rot,
            held.err_acc
        );
    }
}
