//! The sweep of vehicles whose thrusters differ from what the daemon was told (issue 31;
//! docs/study.md), moved out of estimation_sweeps.rs.

use thruster_sim::{NoisePreset, SensorConfig};
use thrusterd_core::estimator::EstimatorConfig;

use thruster_inprocess::estimation::*;

/// The measurement behind docs/study.md's "Vehicles the estimator was not told about (issue
/// 31)": AMOUR-5 and eight_vectored with thrusters that differ from the daemon's assumptions
/// (`MISMATCHES`), per case and noise the mean and range of err_rot / err_acc against the
/// simulator's symmetric truth, the largest error / bound (the daemon's own rel_err_rot /
/// rel_err_acc), the fraction of B's entries within 2 standard errors, the vehicle seconds to
/// the model and how many were refused. Knobs: MM_NOISE = none | realistic | paper (default
/// none), MM_SEEDS = the last seed (default 1), MM_VEHICLES (default amour5,eight_vectored),
/// MM_CASES = indices into MISMATCHES (default all), MM_TOLD (set: the daemon told the true
/// reverse ratio, dead band and lag, learning the lag off: the decisive comparison). For example
/// `MM_NOISE=realistic MM_SEEDS=5 cargo run --release -p thrusterctl -- study sweep mismatch_sweep`.
pub(in crate::study::sweep) fn mismatch_sweep() {
    let noise = match std::env::var("MM_NOISE").as_deref() {
        Ok("realistic") => NoisePreset::Realistic,
        Ok("paper") => NoisePreset::Paper,
        _ => NoisePreset::None,
    };
    let n_seeds: u64 = std::env::var("MM_SEEDS").map_or(1, |s| s.parse().unwrap());
    let names = std::env::var("MM_VEHICLES").unwrap_or("amour5,eight_vectored".into());
    let cases: Vec<usize> = std::env::var("MM_CASES")
        .map_or((0..MISMATCHES.len()).collect(), |s| {
            s.split(',').map(|c| c.parse().unwrap()).collect()
        });
    let mut summary = Vec::new();
    for name in names.split(',') {
        for &c in &cases {
            let (what, m) = MISMATCHES[c];
            let mut rot = Vec::new();
            let mut acc = Vec::new();
            let mut ratio = 0.0f64;
            let mut covered = 0;
            let mut within = 0.0;
            let mut secs = Vec::new();
            let mut refused = 0;
            let mut lags = Vec::new();
            for seed in 1..=n_seeds {
                let t0 = std::time::Instant::now();
                let mut cfg = EstimatorConfig::dynamic();
                let mut ideal = Ideal {
                    allow_refusal: true,
                    ..Ideal::default()
                };
                if std::env::var("MM_TOLD").is_ok() {
                    // The decisive comparison: the daemon told the thrusters' true constants.
                    if let Some(r) = m.reverse_ratio {
                        cfg.reverse_ratio = r;
                    }
                    ideal.deadband = m.deadband;
                    if let Some(tau) = m.lag_s {
                        cfg.spin_up_s = tau;
                        cfg.learn_spin_up = false;
                    }
                }
                let sensors = SensorConfig {
                    rate_hz: 200.0,
                    noise,
                    ..SensorConfig::default()
                };
                let o = estimate_on(mismatched(name, m), sensors, seed, cfg, ideal);
                println!(
                    "{name} {what} {noise:?} seed {seed}: err_rot {:.4} err_acc {:.4} bound {:.4} / {:.4} B within 2 se {:.2} lag {:.4} ({}) refused {} tilt {:.0} deg unexplained {:.4} in {:.2} s (wall {:.1} s)",
                    o.err_rot,
                    o.err_acc,
                    o.bound[0],
                    o.bound[1],
                    b_within_2se(&o),
                    o.spin_up_s,
                    if o.spin_up_learned { "learned" } else { "configured" },
                    o.refused,
                    o.max_tilt_deg,
                    o.terms.unexplained_rate_radps,
                    o.seconds,
                    t0.elapsed().as_secs_f64()
                );
                rot.push(o.err_rot);
                acc.push(o.err_acc);
                ratio = ratio
                    .max(o.err_rot / o.bound[0])
                    .max(o.err_acc / o.bound[1]);
                if o.err_rot <= o.bound[0] && o.err_acc <= o.bound[1] {
                    covered += 1;
                }
                within += b_within_2se(&o) / n_seeds as f64;
                secs.push(o.seconds);
                refused += o.refused as usize;
                lags.push(o.spin_up_s);
            }
            let stats = |v: &[f64]| {
                let mean = v.iter().sum::<f64>() / v.len() as f64;
                let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                format!("{mean:.3} ({lo:.3}-{hi:.3})")
            };
            summary.push(format!(
                "| {name} | {what} | {noise:?} | {} | {} | {covered}/{n_seeds}, <= {ratio:.2} x | {within:.2} | {} | lag {} | refused {refused} |",
                stats(&rot),
                stats(&acc),
                stats(&secs),
                stats(&lags),
            ));
        }
    }
    println!("| vehicle | differs | noise | err_rot mean (min-max) | err_acc mean (min-max) | within bound, largest err/bound | B within 2 se | vehicle-s | lag | refused |");
    for line in summary {
        println!("{line}");
    }
}
