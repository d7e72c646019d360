//! The identification's focus after a known change follows the dither's amplitude
//! (`IdentificationConfig::focus_at`): at a noisy gyro, where the amplitude reaches
//! `dither_max`, the changed thruster is dithered at `focus_gain_noisy` (2.5) and the others at
//! `focus_others_noisy` (0.3) instead of 1.7 and 0.1, and the stop, which waits for the bounds
//! there, comes sooner. Against the simulator's truth, six_dof's first thruster turned 45 deg
//! and announced, the paper's noise. In-process runs are deterministic: the numbers in the
//! comments are what these seeds gave (docs/study.md, "Under control in 4 s").

mod common;
use common::{rotate_while_holding_on, vehicle, Reestimation, Run};
use thruster_sim::NoisePreset;
use thrusterd_core::model::ModelSource;

fn turned(seed: u64, noisy_focus: Option<(f64, f64)>) -> Reestimation {
    let mut run = Run::new("six_dof", NoisePreset::Paper, seed);
    // As measured: the acceleration rows stopping at 0.06. At the default 0.07 the first model
    // and the identification stop sooner; seeds 1-3 focused 7.82 / 5.72 / 8.72 s, quiet 8.92 /
    // 6.02 / 10.92 s (sooner still), but seed 3's focused model 0.070 / 0.084 off, at the
    // accuracy asserted below.
    run.with_setup(|s| {
        common::acc_target_as_found(s);
        if let Some((gain, others)) = noisy_focus {
            s.identification.focus_gain_noisy = gain;
            s.identification.focus_others_noisy = others;
        }
    });
    let (_, r) = rotate_while_holding_on(run, &vehicle("six_dof"), None, |_, _| {});
    assert_eq!(r.source, ModelSource::Estimated, "{r:?}");
    r
}

/// With the stop decided once a segment, seeds 1 and 2 (since the 0.5 s lead-in,
/// `identification.lead_in_s`) took 10.5 and 8.5 s with the noisy focus, 11.5 and 9.5 s with
/// the quiet one: 1 s each, of which part was the decisions' quantization. Since the stop is
/// decided every `identification.late_decision_s` (0.1 s) after the settle wait, seeds 1-6:
/// focused 9.62 / 8.42 / 9.52 / 9.12 / 8.32 / 9.22 s, quiet 11.22 / 8.72 / 9.72 / 9.72 / 9.32 /
/// 11.52 s: sooner on every seed, by 0.2-2.3 s, 1.0 s on the mean. With the first model fitted
/// to the thrust's shape (`estimator.shaped_thrust`, 2026-12-03): focused 9.72 / 8.32 / 7.92 /
/// 9.22 / 8.42 / 7.32 s, quiet 11.32 / 8.82 / 7.92 / 9.72 / 9.52 / 9.42 s: sooner on five
/// seeds, the same on seed 3 (0.047 against 0.064 off), 0.97 s on the mean. Asserted: never
/// later, and sooner by 0.7 s on the mean.
#[test]
fn at_the_papers_noise_the_stronger_focus_identifies_sooner_within_the_budget() {
    let mut gained = 0.0;
    let seeds = 1..=6;
    let n = seeds.clone().count() as f64;
    for seed in seeds {
        let focused = turned(seed, None);
        let quiet = turned(seed, Some((1.7, 0.1)));
        println!(
            "seed {seed}: focused {:.2} s {:.3} / {:.3}, quiet {:.2} s {:.3} / {:.3}",
            focused.took_s,
            focused.err_rot,
            focused.err_acc,
            quiet.took_s,
            quiet.err_rot,
            quiet.err_acc
        );
        assert!(focused.took_s < 11.0, "seed {seed}: {focused:?}");
        assert!(
            quiet.took_s >= focused.took_s,
            "seed {seed}, the decisive run: {quiet:?} against {focused:?}"
        );
        gained += quiet.took_s - focused.took_s;
        assert!(
            focused.err_rot < 0.07 && focused.err_acc < 0.09,
            "seed {seed}: {focused:?}"
        );
        assert!(focused.max_tilt_deg < 10.0, "seed {seed}: {focused:?}");
    }
    assert!(
        gained / n > 0.7,
        "the focus gained {:.2} s a seed on the mean",
        gained / n
    );
}
