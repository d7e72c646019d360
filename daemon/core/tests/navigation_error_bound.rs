//! Issue 32 item 4 at the paper's noise: the acceleration rows' bound did not count the
//! navigation's own errors (the gyro's bias from a 1-2 s rest turning "down", the gravity that
//! leaks in, integrated into the velocity), and their error was 1.25x it on the RMS. Once the
//! open loop stops, its log is fitted again with draws of those errors
//! (`estimator.navigation_error_draws`) and their spread joins the bound. The run, its stop
//! and its model are unchanged; only the bound the model claims moves, and only where the gyro
//! is too noisy to learn the lag. docs/study.md, "The navigation's errors in the bound".

use thruster_inprocess::estimation::{estimate_ideal, Ideal, Outcome};
use thruster_sim::{NoisePreset, SensorConfig};
use thrusterd_core::estimator::EstimatorConfig;

/// One open-loop estimation in still water after the default idle, `draws` refits (0: off).
fn flight(vehicle: &str, noise: NoisePreset, seed: u64, draws: usize) -> Outcome {
    let cfg = EstimatorConfig {
        navigation_error_draws: draws,
        ..EstimatorConfig::dynamic()
    };
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise,
        ..SensorConfig::default()
    };
    let ideal = Ideal {
        allow_refusal: true,
        ..Ideal::default()
    };
    estimate_ideal(vehicle, sensors, seed, cfg, ideal)
}

fn rms(xs: &[f64]) -> f64 {
    (xs.iter().map(|x| x * x).sum::<f64>() / xs.len() as f64).sqrt()
}

#[test]
fn at_the_papers_noise_the_acceleration_rows_bound_counts_the_navigations_errors() {
    let draws = EstimatorConfig::dynamic().navigation_error_draws;
    assert!(draws > 0, "on by default");
    let (mut before, mut after, mut lines) = (Vec::new(), Vec::new(), Vec::new());
    for vehicle in ["amour5", "eight_vectored"] {
        for seed in 1..=4 {
            let off = flight(vehicle, NoisePreset::Paper, seed, 0);
            let on = flight(vehicle, NoisePreset::Paper, seed, draws);
            lines.push(format!(
                "{vehicle} seed {seed}: {:.2} s, err {:.4} / {:.4}, bound {:.4} / {:.4} -> {:.4} / {:.4} (navigation {:.4})",
                on.seconds, on.err_rot, on.err_acc, off.bound[0], off.bound[1], on.bound[0],
                on.bound[1], on.terms.navigation_rel_err[1]
            ));
            let report = lines.join("\n");
            // The same run, stop and model: only the claim moves.
            assert_eq!(on.seconds, off.seconds, "{report}");
            assert_eq!(on.err_rot, off.err_rot, "{report}");
            assert_eq!(on.err_acc, off.err_acc, "{report}");
            assert_eq!(on.bound[0], off.bound[0], "{report}");
            // The acceleration rows' bound takes the spread in quadrature.
            let spread = on.terms.navigation_rel_err[1];
            assert!(spread > 0.01, "{report}");
            assert!(
                (on.bound[1] - off.bound[1].hypot(spread)).abs() < 1e-12,
                "{report}"
            );
            before.push(on.err_acc / off.bound[1]);
            after.push(on.err_acc / on.bound[1]);
        }
    }
    let summary = format!(
        "acceleration rows, error / bound: RMS {:.2} -> {:.2}, worst {:.2} -> {:.2}\n{}",
        rms(&before),
        rms(&after),
        before.iter().cloned().fold(0.0, f64::max),
        after.iter().cloned().fold(0.0, f64::max),
        lines.join("\n")
    );
    eprintln!("{summary}");
    // Measured on these eight flights: RMS 1.34 -> 1.08, worst 1.72 -> 1.34 (the spread
    // 0.031-0.053 against bounds of 0.057-0.068). The claim: the RMS near 1 and no model
    // beyond 1.5x its bound.
    assert!(
        rms(&after) < 1.1 && rms(&after) < rms(&before) - 0.1,
        "{summary}"
    );
    assert!(after.iter().all(|r| *r < 1.5), "{summary}");
}

#[test]
fn where_the_gyro_learns_the_lag_the_bound_is_the_fits_own() {
    let draws = EstimatorConfig::dynamic().navigation_error_draws;
    for noise in [NoisePreset::None, NoisePreset::Realistic] {
        let off = flight("amour5", noise, 1, 0);
        let on = flight("amour5", noise, 1, draws);
        assert_eq!(on.bound, off.bound, "{noise:?}");
        assert_eq!(on.terms.navigation_rel_err, [0.0; 2], "{noise:?}");
    }
}

/// Under control after an announced change, at the paper's noise: the identification keeps
/// every column but the changed one, and with them the error the first run's navigation left
/// in them. Its bound takes it (in the share of B those columns are) as a floor its stop does
/// not wait on: the same stop and model, an honest claim. Measured over seeds 1-10
/// (`sweep_identification`): eight_vectored's acceleration rows 1.28 -> 1.06 on the RMS.
#[test]
fn under_control_the_kept_columns_keep_their_navigation_error_in_the_bound() {
    use thruster_inprocess::run::{rotate_while_holding_on, vehicle, Run};
    let draws = EstimatorConfig::dynamic().navigation_error_draws;
    let (mut before, mut after, mut lines) = (Vec::new(), Vec::new(), Vec::new());
    for seed in [3u64, 5, 7] {
        let mut out = Vec::new();
        for d in [0, draws] {
            let mut run = Run::new("eight_vectored", NoisePreset::Paper, seed);
            run.with_setup(|s| s.estimator.navigation_error_draws = d);
            let (run, r) =
                rotate_while_holding_on(run, &vehicle("eight_vectored"), None, |_, _| {});
            let m = run.machine.model().expect("a model").clone();
            out.push((r, m));
        }
        let ((r0, m0), (r1, m1)) = (&out[0], &out[1]);
        let inherited = m1.navigation_rel_err()[1];
        lines.push(format!(
            "seed {seed}: {:.1} s, err {:.4} / {:.4}, bound {:.4} / {:.4} -> {:.4} / {:.4} (inherited {inherited:.4})",
            r1.took_s, r1.err_rot, r1.err_acc, m0.rel_err_rot, m0.rel_err_acc, m1.rel_err_rot,
            m1.rel_err_acc
        ));
        let report = lines.join("\n");
        // The same identification: its stop and model; only the claim moves.
        assert_eq!(
            (r1.took_s, r1.err_rot, r1.err_acc),
            (r0.took_s, r0.err_rot, r0.err_acc),
            "{report}"
        );
        assert_eq!(m1.effectiveness, m0.effectiveness, "{report}");
        assert_eq!(m0.navigation_rel_err(), [0.0; 2], "{report}");
        assert!(
            inherited > 0.01 && m1.rel_err_acc > m0.rel_err_acc,
            "{report}"
        );
        before.push(r0.err_acc / m0.rel_err_acc);
        after.push(r1.err_acc / m1.rel_err_acc);
    }
    let summary = format!(
        "acceleration rows, error / bound: {:.2?} -> {:.2?}\n{}",
        before,
        after,
        lines.join("\n")
    );
    eprintln!("{summary}");
    // Measured: seeds 3, 5 and 7 (the three of ten furthest out) 1.36 / 1.51 / 1.63 -> 1.11 /
    // 1.26 / 1.31, the inherited error 0.040-0.052.
    assert!(after.iter().all(|r| *r < 1.5), "{summary}");
    assert!(rms(&after) < rms(&before) - 0.1, "{summary}");
}
