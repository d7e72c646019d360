use nalgebra::DMatrix;

use super::design::Excitation;
use super::fisher::{bound, simulate, Spread};
use super::worst_seed::WorstOf;
use super::*;

fn amour5() -> Vehicle {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/vehicles/amour5.toml");
    crate::vehicle::load(&p).unwrap()
}

/// The bound never rises with more excitation time, and scales with the noise: twice the
/// sigma, twice the bound (the information is linear in 1 / sigma^2).
#[test]
fn the_bound_falls_with_time_and_scales_with_the_noise() {
    let v = amour5();
    let ex = Excitation::default_for(v.thrusters.len());
    let tr = simulate(&v, &ex, 4.0, 0.25);
    let mut last = [f64::INFINITY; 2];
    let mut seen = 0;
    for s in &tr.snapshots {
        let Some(b) = bound(s, &tr.b, (0.002, 0.03), true) else {
            continue;
        };
        seen += 1;
        for (l, e) in last.iter_mut().zip(b.rel_err) {
            assert!(e <= *l * (1.0 + 1e-9), "{} s: {:?}", s.t_s, b);
            *l = e;
        }
        let twice = bound(s, &tr.b, (0.004, 0.06), true).unwrap();
        for g in 0..2 {
            assert!((twice.rel_err[g] / b.rel_err[g] - 2.0).abs() < 1e-6);
        }
        // A lag that is known never makes the bound worse.
        let known = bound(s, &tr.b, (0.002, 0.03), false).unwrap();
        assert!(known.rel_err[0] <= b.rel_err[0] * (1.0 + 1e-9));
    }
    assert!(
        seen >= 10,
        "B identifiable within 1.5 s: {seen} of 16 snapshots"
    );
}

/// The reduced information against a closed form: one regressor x and one nuisance column z,
/// the Schur complement x'x - (x'z)^2 / z'z.
#[test]
fn the_schur_complement_matches_the_closed_form() {
    // [B (1) | lag derivative (1) | terms (38)] with only the first term excited.
    let k = 2 + thrusterd_core::estimator::dynamic::regressors::TERMS;
    let mut g = DMatrix::zeros(k, k);
    let (xx, xz, zz) = (4.0, 1.5, 2.0);
    g[(0, 0)] = xx;
    g[(1, 1)] = 1.0;
    g[(0, 2)] = xz;
    g[(2, 0)] = xz;
    g[(2, 2)] = zz;
    let snap = fisher::Snapshot {
        t_s: 1.0,
        max_tilt_deg: 0.0,
        gram: [g.clone(), g],
    };
    let mut b = DMatrix::zeros(6, 1);
    b[(0, 0)] = 1.0;
    b[(3, 0)] = 1.0;
    let sigma = 0.5;
    let out = bound(&snap, &b, (sigma, sigma), false).unwrap();
    // Three rows per group share the variance sigma^2 / (xx - xz^2 / zz); the norm of the
    // group's B is 1.
    let var = sigma * sigma / (xx - xz * xz / zz);
    let expected = (3.0 * var).sqrt();
    assert!(
        (out.rel_err[0] - expected).abs() < 1e-9,
        "{} vs {expected}",
        out.rel_err[0]
    );
}

/// Noise-free, the real estimator recovers B on the bound's best excitation for AMOUR-5 at
/// the realistic IMU (found by the search), to [`NOISE_FREE_ERR`] on both groups (the one
/// column fitted to the thrust's shape, as the machine does: 1.5 % without it).
#[test]
fn noise_free_the_estimator_recovers_b_on_the_designed_excitation() {
    let v = amour5();
    let case = Case {
        noise: "realistic",
        group: 0,
        target: 0.02,
        tilt_budget_deg: 30.0,
        lag_unknown: true,
        floor: 0.0,
        worst_of: None,
    };
    let r = limits("amour5", &v, &[case]).remove(0);
    let best = r.best.expect("reachable within the budget");
    let t = best.t_s.unwrap();
    let ex = by_label(v.thrusters.len(), &best.excitation).unwrap();
    let at = ex.whole(t.max(1.0));
    let p = real::run(&v, &ex, NoisePreset::None, 1, &[at]);
    assert!(
        p[0].err_rot <= NOISE_FREE_ERR && p[0].err_acc <= NOISE_FREE_ERR,
        "{}: {:?}",
        best.excitation,
        p[0]
    );
    // And the search beat or matched the default.
    assert!(t <= r.default.t_s.unwrap_or(f64::INFINITY) + 1e-9);
}

/// The worst of ten seeds against a closed form: one dimension of variance s^2, |e| within q
/// with probability 2 Phi(q / s) - 1, so the median of the worst of ten is s Phi^-1((1 +
/// 0.5^0.1) / 2) = 1.832 s. Another draw set agrees within 1 %.
#[test]
fn the_worst_of_ten_matches_the_gaussian_quantile() {
    let s = 0.01;
    let cov = DMatrix::from_element(1, 1, s * s);
    let w = WorstOf::new(10, 1, 1);
    let q = w.of(&cov);
    assert!((q / s - 1.832).abs() < 0.03, "{} sigma", q / s);
    let other = WorstOf::new(10, 1, 2).of(&cov);
    assert!((other / q - 1.0).abs() < 0.01, "{other} vs {q}");
    // One seed's median of |e|: Phi^-1(0.75) = 0.674 s.
    let one = WorstOf::new(1, 1, 1).of(&cov);
    assert!((one / s - 0.674).abs() < 0.02, "{} sigma", one / s);
}

/// On AMOUR-5's bound the worst of ten sits above the RMS and at most at one dimension's
/// 1.832x (the error spread over 15 columns is narrower than one Gaussian's; where one
/// direction is barely identified it comes near that), and the every-seed limit is later than
/// the RMS limit.
#[test]
fn the_worst_of_ten_is_above_the_rms_and_its_limit_later() {
    let v = amour5();
    let ex = Excitation::default_for(v.thrusters.len());
    let tr = simulate(&v, &ex, 3.5, 0.25);
    let w = WorstOf::new(10, 3 * v.thrusters.len(), 1);
    let sigma = (0.002, 0.03);
    let mut seen = 0;
    for s in &tr.snapshots {
        let Some(c) = fisher::covariance_with(s, &tr.b, sigma, true, true) else {
            continue;
        };
        seen += 1;
        for g in 0..2 {
            let rms = c.rel[g].trace().sqrt();
            let ratio = w.of(&c.rel[g]) / rms;
            assert!(
                (1.1..=1.84).contains(&ratio),
                "{} s group {g}: {ratio}",
                s.t_s
            );
        }
    }
    assert!(seen >= 8, "{seen} snapshots identifiable");
    let time = |spread| {
        fisher::first_reaching_with(&tr, sigma, true, true, spread, 0, 0.02)
            .map(|(i, _, _)| tr.snapshots[i].t_s)
    };
    let (rms, worst) = (time(Spread::Rms).unwrap(), time(Spread::Worst(&w)).unwrap());
    assert!(worst > rms, "every seed {worst} s, RMS {rms} s");
}

/// Issue 30's open-loop targets asked of every seed of ten are beyond AMOUR-5's limit, which
/// is what its clause for such a target rests on (docs/study.md, "Every seed of ten"): the
/// realistic IMU's 0.02 / 0.03 need more than 2.0 s of excitation and the paper's 0.06 more
/// than 5.0 s on every candidate within 30 deg, while the RMS reaches the realistic targets
/// within 2.0 s (measured 2.30 / 2.35 / 5.95 s against 1.95 / 1.95 / 4.75 s).
#[test]
fn issue_30s_targets_for_every_seed_are_beyond_amour5s_limit() {
    let v = amour5();
    let case = |noise, group, target, lag_unknown, worst_of| Case {
        noise,
        group,
        target,
        tilt_budget_deg: 30.0,
        lag_unknown,
        floor: 0.0,
        worst_of,
    };
    let cases = [
        case("realistic", 0, 0.02, true, Some(WORST_OF)),
        case("realistic", 1, 0.03, true, Some(WORST_OF)),
        case("paper", 0, 0.06, false, Some(WORST_OF)),
        case("realistic", 0, 0.02, true, None),
        case("realistic", 1, 0.03, true, None),
    ];
    let r = limits("amour5", &v, &cases);
    let t = |i: usize| r[i].best.as_ref().and_then(|b| b.t_s).unwrap();
    assert!(
        t(0) > 2.0 && t(1) > 2.0,
        "every seed: {} / {} s",
        t(0),
        t(1)
    );
    assert!(t(2) > 5.0, "every seed, paper: {} s", t(2));
    assert!(t(3) <= 2.0 && t(4) <= 2.0, "RMS: {} / {} s", t(3), t(4));
}
