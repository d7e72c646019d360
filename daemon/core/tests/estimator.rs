//! Behaviour of the estimator as the daemon and the simulator drive it (the paper's study,
//! which drives it too, is tested where it lives: thruster-lab's `study::fig2`).

use nalgebra::{DMatrix, DVector, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use thrusterd_core::estimator::{
    Dof, Estimator, EstimatorConfig, Excitation, Method, NoiseLevels, PulseShape, StopDecision,
};

/// A plausible 6 x 5 effectiveness (AMOUR-like: sway unactuated).
fn five_thruster_truth() -> DMatrix<f64> {
    DMatrix::from_row_slice(
        6,
        5,
        &[
            0.0, 0.0, 4.0, -4.0, 0.0, // roll
            0.0, 0.0, -3.0, -3.0, 6.0, // pitch
            5.0, -5.0, 0.0, 0.0, 0.5, // yaw
            1.2, 1.2, 0.0, 0.0, 0.0, // surge
            0.0, 0.0, 0.0, 0.0, 0.0, // sway
            0.0, 0.0, -1.5, -1.5, -1.5, // heave
        ],
    )
}

/// All thrusters along body x at different y and z: pitch, yaw, surge only (the paper's Fig. 4c).
fn aligned_truth() -> DMatrix<f64> {
    DMatrix::from_row_slice(
        6,
        4,
        &[
            0.0, 0.0, 0.0, 0.0, //
            2.0, 2.0, -3.0, -1.0, //
            4.0, -4.0, 1.0, -1.0, //
            1.0, 1.0, 1.0, 1.0, //
            0.0, 0.0, 0.0, 0.0, //
            0.0, 0.0, 0.0, 0.0, //
        ],
    )
}

fn gauss(rng: &mut impl Rng, sigma: f64) -> Vector3<f64> {
    let mut d = || -> f64 { StandardNormal.sample(rng) };
    Vector3::new(sigma * d(), sigma * d(), sigma * d())
}

fn response(b: &DMatrix<f64>, u: &[f64]) -> (Vector3<f64>, Vector3<f64>) {
    let y = b * DVector::from_row_slice(u);
    (
        Vector3::new(y[0], y[1], y[2]),
        Vector3::new(y[3], y[4], y[5]),
    )
}

/// Drive the live pulse API with a synthetic vehicle whose response follows the assumed shape
/// exactly: rate = B_rot u s(t), accel = B_acc u h(t), sampled at `rate_hz` for `pulse_s`.
fn run_live(
    est: &mut Estimator,
    truth: &DMatrix<f64>,
    pulses: usize,
    sigma: (f64, f64),
    rng: &mut impl Rng,
) {
    let shape = PulseShape {
        lag_s: est.config().spin_up_s,
    };
    let (rate_hz, pulse_s) = (100.0, 0.5);
    for _ in 0..pulses {
        // The quiet samples before each pulse anchor its intercept, as in the daemon.
        for k in 0..est.config().baseline_samples {
            let t = k as f64 / rate_hz;
            est.push_rest_sample(t, &gauss(rng, sigma.0), &gauss(rng, sigma.1));
        }
        let u = est.begin_pulse().to_vec();
        let (rot, acc) = response(truth, &u);
        for k in 1..=((pulse_s * rate_hz) as usize) {
            let t = k as f64 / rate_hz;
            let g = rot * shape.rate(t) + gauss(rng, sigma.0);
            let a = acc * shape.accel(t) + gauss(rng, sigma.1);
            est.push_pulse_sample(t, &g, &a);
        }
        est.end_pulse();
    }
}

#[test]
fn forward_recovers_exactly_without_noise_for_every_plan() {
    let truth = five_thruster_truth();
    for excitation in Excitation::ALL {
        let cfg = EstimatorConfig {
            excitation,
            ..EstimatorConfig::forward()
        };
        let mut est = Estimator::new(cfg, 5, NoiseLevels::isotropic(0.0, 0.0));
        let cycle = est.plan().cycle_len();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        run_live(&mut est, &truth, cycle, (0.0, 0.0), &mut rng);
        let e = est.estimate();
        assert!(e.excited, "{excitation:?}");
        let err = (&e.effectiveness - &truth).norm() / truth.norm();
        assert!(err < 1e-9, "{excitation:?}: relative error {err}");
        assert_eq!(e.rank.rank, 5, "{excitation:?}");
        assert_eq!(
            e.rank.actuated.names(),
            vec!["roll", "pitch", "yaw", "surge", "heave"],
            "{excitation:?}"
        );
        // The allocation reproduces every actuated DOF and leaves sway alone.
        let ba = &truth * &e.allocation;
        for dof in Dof::ALL {
            let j = dof.index();
            if dof == Dof::Sway {
                assert_eq!(e.allocation.column(j).norm(), 0.0);
            } else {
                assert!((ba[(j, j)] - 1.0).abs() < 1e-9, "{dof:?}");
            }
        }
    }
}

#[test]
fn paper_method_recovers_exactly_without_noise_on_a_balanced_plan() {
    // Noise-free samples all exceed k * 0 and the round-robin Gram matrix is balanced, so S A = T
    // inverts back to the truth (with noise it is biased; see the study).
    let truth = five_thruster_truth();
    let cfg = EstimatorConfig {
        method: Method::Paper,
        excitation: Excitation::RoundRobin,
        ..EstimatorConfig::forward()
    };
    let mut est = Estimator::new(cfg, 5, NoiseLevels::isotropic(0.0, 0.0));
    for k in 0..10 {
        let mut u = vec![0.0; 5];
        u[k / 2] = if k % 2 == 0 { 50.0 } else { -50.0 };
        let (rot, acc) = response(&truth, &u);
        est.push_observation(&u, &rot, &acc);
    }
    let e = est.estimate();
    assert!((&e.effectiveness - &truth).norm() / truth.norm() < 1e-9);
    assert_eq!(e.method, Method::Paper);
    assert_eq!(
        e.rank.actuated.count(),
        6,
        "the paper's method cannot see missing DOFs"
    );
    assert_eq!(est.stop_decision(), StopDecision::PlanComplete);
}

#[test]
fn noisy_estimate_lies_within_its_own_confidence() {
    // Over many independent runs, |b_est - b| / se must behave like a standard normal: about
    // 95.4 % of entries inside 2 se, and the mean squared normalised error near 1.
    let truth = five_thruster_truth();
    let (sr, sa) = (0.25, 0.5);
    let mut inside = 0usize;
    let mut total = 0usize;
    let mut z2 = 0.0;
    let mut bound_ratio = 0.0;
    let runs = 200;
    for seed in 0..runs {
        let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
        let mut est = Estimator::new(
            EstimatorConfig::forward(),
            5,
            NoiseLevels::isotropic(sr, sa),
        );
        run_live(&mut est, &truth, 16, (sr, sa), &mut rng);
        let e = est.estimate();
        for j in 0..6 {
            for i in 0..5 {
                let z = (e.effectiveness[(j, i)] - truth[(j, i)]) / e.std_err[(j, i)];
                z2 += z * z;
                total += 1;
                if z.abs() <= 2.0 {
                    inside += 1;
                }
            }
        }
        let rot_err =
            (e.effectiveness.rows(0, 3) - truth.rows(0, 3)).norm() / truth.rows(0, 3).norm();
        bound_ratio += (rot_err / e.rel_err_rot).powi(2);
    }
    let share = inside as f64 / total as f64;
    let mean_z2 = z2 / total as f64;
    assert!(
        (0.93..=0.975).contains(&share),
        "share inside 2 se: {share}"
    );
    assert!((0.9..=1.1).contains(&mean_z2), "mean z^2: {mean_z2}");
    // The 1-sigma relative bound is an RMS prediction of the actual relative error.
    let rms = (bound_ratio / runs as f64).sqrt();
    assert!((0.85..=1.15).contains(&rms), "actual / bound (RMS): {rms}");
}

#[test]
fn k_sigma_selection_and_power_escalation() {
    let truth = five_thruster_truth() * 0.01; // tiny responses: below 3 sigma at any power
                                              // Algorithm 1's schedule: start at 0.5, +0.1 per silent pulse, capped at 1.0.
    let cfg = EstimatorConfig {
        excitation: Excitation::RoundRobin,
        initial_power: 0.5,
        ..EstimatorConfig::forward()
    };
    let mut est = Estimator::new(cfg, 5, NoiseLevels::isotropic(0.25, 0.5));
    let mut powers = Vec::new();
    for _ in 0..8 {
        let u = est.begin_pulse().to_vec();
        powers.push(est.power());
        assert!(u.iter().all(|v| v.abs() <= 1.0));
        let (rot, acc) = response(&truth, &u);
        // Noise-free but tiny: every sample is below k * sigma and must be dropped.
        est.push_pulse_sample(0.3, &rot, &acc);
        let s = est.end_pulse().unwrap();
        assert_eq!((s.kept_rot, s.kept_acc), (0, 0));
    }
    let want = [0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.0, 1.0];
    for (p, w) in powers.iter().zip(want) {
        assert!((p - w).abs() < 1e-12, "powers {powers:?}");
    }

    // A strong response is kept, and the power stays where it is.
    let paper_power = EstimatorConfig {
        initial_power: 0.5,
        ..EstimatorConfig::forward()
    };
    let mut est = Estimator::new(paper_power, 5, NoiseLevels::isotropic(0.25, 0.5));
    let u = est.begin_pulse().to_vec();
    // k * sigma = 0.75 rad/s and 1.5 m/s^2; one sample above both, one below both.
    est.push_pulse_sample(
        0.5,
        &Vector3::new(0.8, 0.0, 0.0),
        &Vector3::new(0.0, 1.6, 0.0),
    );
    est.push_pulse_sample(
        0.6,
        &Vector3::new(0.7, 0.0, 0.0),
        &Vector3::new(0.0, 1.4, 0.0),
    );
    let s = est.end_pulse().unwrap();
    assert_eq!((s.kept_rot, s.kept_acc, s.samples), (1, 1, 2));
    assert_eq!(s.next_power, 0.5);
    assert!(
        u.iter().all(|v| v.abs() == 0.5),
        "orthogonal: every thruster at +-power"
    );
    // Only one group silent is enough to escalate (Algorithm 1: flag_acc or flag_rot).
    est.begin_pulse();
    est.push_pulse_sample(0.5, &Vector3::new(0.8, 0.0, 0.0), &Vector3::zeros());
    assert_eq!(est.end_pulse().unwrap().next_power, 0.6);
}

#[test]
fn all_parallel_thrusters_report_missing_dofs() {
    let truth = aligned_truth();
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let mut est = Estimator::new(
        EstimatorConfig::forward(),
        4,
        NoiseLevels::isotropic(0.25, 0.5),
    );
    run_live(&mut est, &truth, 16, (0.25, 0.5), &mut rng);
    let e = est.estimate();
    assert_eq!(
        e.rank.rank, 3,
        "singular values {:?}",
        e.rank.singular_values
    );
    assert_eq!(e.rank.actuated.names(), vec!["pitch", "yaw", "surge"]);
    for dof in [Dof::Roll, Dof::Sway, Dof::Heave] {
        assert_eq!(
            e.allocation.column(dof.index()).norm(),
            0.0,
            "{dof:?} commanded"
        );
    }
    // The paper's method, same data, "learns" all six (its Fig. 5b blue bars).
    let paper = Estimator::new(
        EstimatorConfig {
            method: Method::Paper,
            ..EstimatorConfig::forward()
        },
        4,
        NoiseLevels::isotropic(0.25, 0.5),
    );
    let mut paper = paper;
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    run_live(&mut paper, &truth, 16, (0.25, 0.5), &mut rng);
    let p = paper.estimate();
    assert!(p.allocation.column(Dof::Heave.index()).norm() > 0.0);
}

#[test]
fn dead_and_reversed_thrusters_are_diagnosed() {
    let nominal = five_thruster_truth();
    let mut truth = nominal.clone();
    truth.column_mut(1).scale_mut(-1.0); // left-handed screw
    truth.column_mut(4).fill(0.0); // dead
    let cfg = EstimatorConfig {
        initial_power: 1.0,
        ..EstimatorConfig::forward()
    };
    let mut est = Estimator::new(cfg, 5, NoiseLevels::isotropic(0.25, 0.5)).with_nominal(nominal);
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    run_live(&mut est, &truth, 16, (0.25, 0.5), &mut rng);
    let e = est.estimate();
    let dead: Vec<usize> = e
        .thruster
        .iter()
        .filter(|t| t.dead)
        .map(|t| t.index)
        .collect();
    let reversed: Vec<usize> = e
        .thruster
        .iter()
        .filter(|t| t.reversed == Some(true))
        .map(|t| t.index)
        .collect();
    assert_eq!(dead, vec![4]);
    assert_eq!(reversed, vec![1]);
    // Without thruster 5's pitch the vehicle has lost rank but still drives the rest.
    assert_eq!(e.rank.rank, 4, "{:?}", e.rank.singular_values);
}

#[test]
fn asymmetric_forward_and_reverse_gains_are_detected() {
    // Per-thruster forward and reverse gains are only identifiable when thrusters differ in |u|
    // from pulse to pulse: round robin does that, the orthogonal plan (every thruster always at
    // |u| = p) cannot, and says so by leaving the ratio unset.
    let truth = five_thruster_truth();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let cfg = EstimatorConfig {
        excitation: Excitation::RoundRobin,
        ..EstimatorConfig::forward()
    };
    let mut est = Estimator::new(cfg, 5, NoiseLevels::isotropic(0.05, 0.1));
    let shape = PulseShape { lag_s: 0.1 };
    for _ in 0..32 {
        let u = est.begin_pulse().to_vec();
        // T200-like: reverse thrust 4.1 / 5.25 of forward, for thruster 0 only.
        let eff: Vec<f64> = u
            .iter()
            .enumerate()
            .map(|(i, &v)| if i == 0 && v < 0.0 { v * 4.1 / 5.25 } else { v })
            .collect();
        let (rot, acc) = response(&truth, &eff);
        for k in 1..=50 {
            let t = k as f64 / 100.0;
            est.push_pulse_sample(
                t,
                &(rot * shape.rate(t) + gauss(&mut rng, 0.05)),
                &(acc * shape.accel(t) + gauss(&mut rng, 0.1)),
            );
        }
        est.end_pulse();
    }
    let e = est.estimate();
    let t0 = &e.thruster[0];
    assert!(t0.asymmetric, "{t0:?}");
    assert!(
        (t0.reverse_gain_ratio.unwrap() - 4.1 / 5.25).abs() < 0.05,
        "{t0:?}"
    );
    assert!(
        e.thruster[1..].iter().all(|t| !t.asymmetric),
        "{:?}",
        e.thruster
    );

    let mut orth = Estimator::new(
        EstimatorConfig::forward(),
        5,
        NoiseLevels::isotropic(0.05, 0.1),
    );
    run_live(&mut orth, &truth, 16, (0.05, 0.1), &mut rng);
    let e = orth.estimate();
    assert!(e
        .thruster
        .iter()
        .all(|t| t.reverse_gain_ratio.is_none() && !t.asymmetric));
}

#[test]
fn automatic_stop_fires_at_the_target_and_means_it() {
    let truth = five_thruster_truth();
    let mut hits = 0;
    for seed in 0..40 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let cfg = EstimatorConfig {
            target_rel_err: 0.05,
            ..EstimatorConfig::forward()
        };
        let mut est = Estimator::new(cfg, 5, NoiseLevels::isotropic(0.25, 0.5));
        let mut stop = StopDecision::Continue;
        while !stop.is_stop() {
            run_live(&mut est, &truth, 1, (0.25, 0.5), &mut rng);
            stop = est.stop_decision();
        }
        let StopDecision::Converged { rel_err_rot, .. } = stop else {
            panic!(
                "seed {seed}: stopped with {stop:?} after {} pulses",
                est.pulses()
            );
        };
        assert!(rel_err_rot <= 0.05);
        let e = est.estimate();
        let actual =
            (e.effectiveness.rows(0, 3) - truth.rows(0, 3)).norm() / truth.rows(0, 3).norm();
        if actual <= 0.1 {
            hits += 1;
        }
    }
    // A 1-sigma bound of 5 %: the actual error stays under twice that nearly always.
    assert!(hits >= 38, "{hits}/40 runs within 2x the target");
}

/// Issue 27: `estimate --wait` read "pulse 40 of 32" and ran to "pulse 60 of 32" when the
/// plan grew past its minimum. The extent shown never falls below the pulses begun, grows to
/// the next point where the run may stop, and the run does stop there or grows it again.
#[test]
fn the_plan_extent_grows_with_the_plan_and_never_trails_the_pulses() {
    let truth = five_thruster_truth();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let cfg = EstimatorConfig {
        // Never met: the run extends to its pulse limit.
        target_rel_err: 1e-9,
        max_pulses: 90,
        ..EstimatorConfig::forward()
    };
    let mut est = Estimator::new(cfg, 5, NoiseLevels::isotropic(0.25, 0.5));
    let min = est.planned_pulses();
    assert_eq!(est.plan_extent(), min);
    let mut grew = false;
    let mut stop = StopDecision::Continue;
    while !stop.is_stop() {
        run_live(&mut est, &truth, 1, (0.25, 0.5), &mut rng);
        let (done, extent) = (est.pulses(), est.plan_extent());
        assert!(done <= extent, "{done} pulses done of {extent}");
        assert!(extent <= 90, "{extent}");
        grew |= extent > min;
        stop = est.stop_decision();
        if !stop.is_stop() && done == extent {
            // Going on past the extent: the pulse it begins is inside the new one.
            let _ = est.begin_pulse();
            assert!(
                est.plan_extent() > done,
                "extent {} at {done}",
                est.plan_extent()
            );
            est.end_pulse();
            stop = est.stop_decision();
        }
    }
    assert!(
        grew,
        "the plan never grew past {min}: the check could not fail"
    );
    assert_eq!(est.pulses(), 90, "{stop:?}");
    assert_eq!(est.plan_extent(), 90);
}
