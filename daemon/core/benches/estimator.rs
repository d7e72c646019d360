//! Per-pulse update and solve costs of the estimator, N = 8 and N = 16: the static forward
//! method (`EstimatorConfig::forward()`) and the dynamic method (the default); and the
//! refinement's per-sample change test, one sample with every candidate live.
//! Run: cargo bench -p thrusterd-core --bench estimator

use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion};
use nalgebra::Vector3;

use thrusterd_core::estimator::{Estimator, EstimatorConfig, NoiseLevels};

/// An estimator that has seen two full orthogonal cycles (so every solve is full rank).
fn warmed(n: usize) -> Estimator {
    // A high pulse limit so the stop decision really evaluates the bound.
    let cfg = EstimatorConfig {
        max_pulses: 1000,
        ..EstimatorConfig::forward()
    };
    let mut est = Estimator::new(cfg, n, NoiseLevels::isotropic(0.25, 0.5));
    for k in 0..2 * est.plan().cycle_len() {
        let u = est.begin_pulse().to_vec();
        for s in 1..=50 {
            let t = s as f64 * 0.01;
            let y = Vector3::new(u[0] * t, u[1 % n] * t, (k % 3) as f64 * 0.01);
            est.push_pulse_sample(t, &y, &(y * 0.5));
        }
        est.end_pulse();
    }
    est
}

const REST_FORCE: Vector3<f64> = Vector3::new(0.0, 0.0, -9.80665);

/// One synthetic IMU sample at `t` s: a swaying vehicle (bias-free gyro rad/s, raw specific
/// force m/s^2), every regressor non-zero.
fn dynamic_sample(t: f64) -> (Vector3<f64>, Vector3<f64>) {
    (
        Vector3::new(0.2 * (3.0 * t).sin(), -0.1 * (2.0 * t).cos(), 0.05),
        Vector3::new(0.3 * (5.0 * t).sin(), 0.1, -9.80665 + 0.2 * t.cos()),
    )
}

/// `dynamic_sample` with a rate jitter of about 0.01 rad/s the terms cannot explain (a
/// deterministic hash of the time, so every run is the same), five times a realistic gyro's
/// noise: rotation left unexplained as in moving water.
fn jittered_sample(t: f64) -> (Vector3<f64>, Vector3<f64>) {
    let (w, f) = dynamic_sample(t);
    let jitter = |k: f64| ((t * 7919.0 + k).sin() * 43758.547).fract() * 0.035;
    (w + Vector3::new(jitter(1.0), jitter(2.0), jitter(3.0)), f)
}

/// A dynamic-method estimator (the default config) that has seen `pulses` back-to-back pulses
/// of 0.1 s at 200 Hz, for the `estimate()` cost.
fn warmed_dynamic(n: usize, pulses: usize) -> Estimator {
    warmed_dynamic_at(n, pulses, NoiseLevels::isotropic(0.25, 0.5))
}

/// The same at rest noise `noise`: at a quiet gyro (below `spin_up_max_gyro_sigma`) the run
/// logs its samples and every estimate learns the thrusters' lag.
fn warmed_dynamic_at(n: usize, pulses: usize, noise: NoiseLevels) -> Estimator {
    warmed_dynamic_with(n, pulses, noise, EstimatorConfig::default())
}

/// The same with estimator configuration `cfg`.
fn warmed_dynamic_with(
    n: usize,
    pulses: usize,
    noise: NoiseLevels,
    cfg: EstimatorConfig,
) -> Estimator {
    warmed_dynamic_on(n, pulses, noise, cfg, dynamic_sample)
}

/// The same with the IMU samples of `sample`.
fn warmed_dynamic_on(
    n: usize,
    pulses: usize,
    noise: NoiseLevels,
    cfg: EstimatorConfig,
    sample: fn(f64) -> (Vector3<f64>, Vector3<f64>),
) -> Estimator {
    let cfg = EstimatorConfig {
        max_pulses: 1000,
        ..cfg
    };
    let mut est = Estimator::new(cfg, n, noise).with_rest_specific_force(REST_FORCE);
    let mut t = 0.0;
    for _ in 0..pulses {
        est.begin_pulse_at(t);
        for _ in 0..20 {
            t += 0.005;
            let (w, f) = sample(t);
            est.push_dynamic_sample(t, &w, &f, Some(5.0));
        }
        est.end_pulse();
    }
    est
}

fn bench(c: &mut Criterion) {
    for n in [8usize, 16] {
        let base = warmed(n);
        let u: Vec<f64> = (0..n)
            .map(|i| if i % 2 == 0 { 0.5 } else { -0.5 })
            .collect();
        let y = Vector3::new(0.1, -0.2, 0.3);

        c.bench_with_input(
            BenchmarkId::new("pulse_update_observation", n),
            &n,
            |b, _| {
                let mut est = base.clone();
                b.iter(|| est.push_observation(black_box(&u), black_box(&y), black_box(&y)))
            },
        );
        c.bench_with_input(BenchmarkId::new("sample_update", n), &n, |b, _| {
            let mut est = base.clone();
            est.begin_pulse();
            b.iter(|| est.push_pulse_sample(black_box(0.3), black_box(&y), black_box(&y)))
        });
        c.bench_with_input(BenchmarkId::new("solve_forward", n), &n, |b, _| {
            b.iter(|| black_box(base.forward_solutions()))
        });
        c.bench_with_input(BenchmarkId::new("estimate_full_analysis", n), &n, |b, _| {
            b.iter(|| black_box(base.estimate()))
        });
        c.bench_with_input(BenchmarkId::new("stop_decision", n), &n, |b, _| {
            b.iter(|| black_box(base.stop_decision()))
        });

        // The dynamic method (EstimatorConfig::default()). One IMU sample during a pulse: the
        // time must advance (a sample not later than the last one is dropped), so each
        // iteration is 5 ms after the previous one; segments close every 1 s as in a run.
        c.bench_with_input(BenchmarkId::new("dynamic_sample_update", n), &n, |b, _| {
            let mut est = Estimator::new(
                EstimatorConfig::default(),
                n,
                NoiseLevels::isotropic(0.25, 0.5),
            )
            .with_rest_specific_force(REST_FORCE);
            est.begin_pulse_at(0.0);
            let samples: Vec<_> = (0..200).map(|k| dynamic_sample(k as f64 * 0.005)).collect();
            let mut k = 0u64;
            b.iter(|| {
                k += 1;
                let (w, f) = &samples[(k % 200) as usize];
                est.push_dynamic_sample(black_box(k as f64 * 0.005), w, f, black_box(Some(5.0)))
            })
        });
        // The same at a quiet gyro, where the run also logs each navigated sample for the lag
        // search (`estimator::dynamic::sample_log`).
        c.bench_with_input(
            BenchmarkId::new("dynamic_sample_update_learning_lag", n),
            &n,
            |b, _| {
                let mut est = Estimator::new(
                    EstimatorConfig::default(),
                    n,
                    NoiseLevels::isotropic(0.002, 0.03),
                )
                .with_rest_specific_force(REST_FORCE);
                est.begin_pulse_at(0.0);
                let samples: Vec<_> = (0..200).map(|k| dynamic_sample(k as f64 * 0.005)).collect();
                let mut k = 0u64;
                b.iter(|| {
                    k += 1;
                    let (w, f) = &samples[(k % 200) as usize];
                    est.push_dynamic_sample(black_box(k as f64 * 0.005), w, f, black_box(Some(5.0)))
                })
            },
        );
        // Under control (the identification): one sample of the split fit by least squares,
        // and the same instrumented in a sea (`estimator::dynamic::instruments`: the
        // instruments' sums and a least-squares twin besides), and the same with the
        // thrust-curve probe (`estimator::dynamic::thrust_curve`: three more fits, as the
        // identification runs it); then an estimate after 10 s, and its job copy.
        for (instrumented, probe) in [(false, false), (true, false), (false, true)] {
            let suffix = match (instrumented, probe) {
                (true, _) => "_instrumented",
                (_, true) => "_curve_probe",
                _ => "",
            };
            let name = format!("closed_loop_sample_update{suffix}");
            let fresh = || {
                let mut est = Estimator::new(
                    EstimatorConfig::default(),
                    n,
                    NoiseLevels::isotropic(0.002, 0.03),
                )
                .with_rest_specific_force(REST_FORCE);
                if instrumented {
                    est.begin_instrumented_closed_loop();
                } else {
                    est.begin_closed_loop();
                }
                if probe {
                    est.probe_thrust_curve(thrusterd_core::estimator::dynamic::thrust_curve::WIDE);
                }
                est
            };
            let samples: Vec<_> = (0..200).map(|k| dynamic_sample(k as f64 * 0.005)).collect();
            let command = |k: u64| -> Vec<f64> {
                (0..n)
                    .map(|i| 0.3 * (((k / 10) as usize + i) % 3) as f64 - 0.3)
                    .collect()
            };
            let commands: Vec<Vec<f64>> = (0..200).map(command).collect();
            let signs: Vec<Vec<f64>> = commands
                .iter()
                .map(|u| u.iter().map(|v| v.signum()).collect())
                .collect();
            c.bench_with_input(BenchmarkId::new(name, n), &n, |b, _| {
                let mut est = fresh();
                let mut k = 0u64;
                b.iter(|| {
                    k += 1;
                    let j = (k % 200) as usize;
                    let (w, f) = &samples[j];
                    est.push_commanded_sample(
                        black_box(k as f64 * 0.005),
                        w,
                        f,
                        Some(5.0),
                        &commands[j],
                        instrumented.then_some(&signs[j][..]),
                    )
                })
            });
            let mut est = fresh();
            for k in 1..=2000u64 {
                let j = (k % 200) as usize;
                let (w, f) = &samples[j];
                est.push_commanded_sample(
                    k as f64 * 0.005,
                    w,
                    f,
                    Some(5.0),
                    &commands[j],
                    instrumented.then_some(&signs[j][..]),
                );
            }
            let name = format!("closed_loop_estimate{suffix}");
            c.bench_with_input(BenchmarkId::new(name, n), &n, |b, _| {
                b.iter(|| black_box(est.estimate()))
            });
            let name = format!("closed_loop_job_copy{suffix}");
            c.bench_with_input(BenchmarkId::new(name, n), &n, |b, _| {
                b.iter(|| black_box(Box::new(est.clone())))
            });
        }
        // A full dynamic estimate after 64 pulses (the default stops at a bound or 80 pulses),
        // at the paper's noise, where the lag is not learned.
        let dynamic = warmed_dynamic(n, 64);
        // What the estimate a run stops with costs more there: the lag searched to check
        // the configured one (`estimator::dynamic::lag_check`).
        assert!(dynamic.checks_configured_lag());
        c.bench_with_input(
            BenchmarkId::new("dynamic_estimate_checking_lag", n),
            &n,
            |b, _| {
                b.iter(|| {
                    let mut e = dynamic.estimate();
                    dynamic.check_configured_lag(&mut e);
                    black_box(e)
                })
            },
        );
        // And the whole of what the stopping job computes there: the navigation's errors
        // drawn into the acceleration rows' bound besides (`navigation_error_draws` refits,
        // `estimator::dynamic::navigation_error`), which it asserts it drew.
        c.bench_with_input(
            BenchmarkId::new("dynamic_estimate_stopping_with_navigation", n),
            &n,
            |b, _| {
                b.iter(|| {
                    let mut e = dynamic.estimate();
                    dynamic.check_configured_lag(&mut e);
                    dynamic.count_navigation_error(&mut e);
                    assert!(e
                        .dynamics
                        .as_ref()
                        .is_some_and(|d| d.navigation_rel_err[1] > 0.0));
                    black_box(e)
                })
            },
        );
        c.bench_with_input(BenchmarkId::new("dynamic_estimate", n), &n, |b, _| {
            b.iter(|| black_box(dynamic.estimate()))
        });
        // The same at a realistic IMU's noise, where the estimate also learns the lag
        // (`estimator::dynamic::lag_search`: ~22 refits of the logged samples), and the job
        // copy, which then also copies the log's open chunk.
        let learning = warmed_dynamic_at(n, 64, NoiseLevels::isotropic(0.002, 0.03));
        assert!(learning.learns_lag());
        c.bench_with_input(
            BenchmarkId::new("dynamic_estimate_learning_lag", n),
            &n,
            |b, _| b.iter(|| black_box(learning.estimate())),
        );
        // What the job a run stops in adds there in still water: the velocity's drift
        // searched (`run/velocity_drift_search.rs`, ~120 refits), and where the log supports
        // one, the estimate made again on the corrected log (its lag searched again).
        c.bench_with_input(
            BenchmarkId::new("dynamic_estimate_stopping_searching_velocity_drift", n),
            &n,
            |b, _| {
                b.iter(|| {
                    let mut e = learning.estimate();
                    assert!(learning.search_velocity_drift(&mut e));
                    black_box(e)
                })
            },
        );
        // The lag per thruster (`estimator::dynamic::thruster_lags`): the default above pays
        // its pre-test (2 N refits) whatever the vehicle; not searched at all (one lag,
        // `learn_thruster_lags = false`); and searched to the end (pair sweep, Newton steps,
        // the covariance), as a vehicle of two makes is (`thruster_lag_evidence = 0`).
        for (label, learn, evidence) in [("one_lag", false, 100.0), ("lag_per_thruster", true, 0.0)]
        {
            let cfg = EstimatorConfig {
                learn_thruster_lags: learn,
                thruster_lag_evidence: evidence,
                ..EstimatorConfig::default()
            };
            let est = warmed_dynamic_with(n, 64, NoiseLevels::isotropic(0.002, 0.03), cfg);
            c.bench_with_input(
                BenchmarkId::new(format!("dynamic_estimate_{label}"), n),
                &n,
                |b, _| b.iter(|| black_box(est.estimate())),
            );
        }
        // In moving water (`run/fits.rs in_moving_water`): the jittered rate leaves more
        // rotation unexplained than `MOVING_WATER_REFIT_RADPS`, so the default estimate
        // refits the log with the swell's two states and searches the lag again; the same
        // estimator with the refit off (`moving_water_swell_hz = 0`) is the still-water cost.
        for (label, swell_hz) in [("moving_water_refit", 0.15), ("moving_water_off", 0.0)] {
            let cfg = EstimatorConfig {
                moving_water_swell_hz: swell_hz,
                ..EstimatorConfig::default()
            };
            let noise = NoiseLevels::isotropic(0.002, 0.03);
            let est = warmed_dynamic_on(n, 64, noise, cfg, jittered_sample);
            let water = est
                .estimate()
                .dynamics
                .map_or(0.0, |d| d.unexplained_rate_radps);
            assert!(
                water > thrusterd_core::estimator::MOVING_WATER_REFIT_RADPS,
                "the jitter must take the moving-water refit ({water} rad/s unexplained)"
            );
            c.bench_with_input(
                BenchmarkId::new(format!("dynamic_estimate_{label}"), n),
                &n,
                |b, _| b.iter(|| black_box(est.estimate())),
            );
        }
        // After a long rest that saw the vehicle move (`with_rest_water`): the estimate refits
        // with the drift states, and the job a run stops in makes the model again with the
        // start velocity searched (`run/start_velocity_search.rs`, ~120 refits with the states).
        let moved = warmed_dynamic_on(
            n,
            64,
            NoiseLevels::isotropic(0.002, 0.03),
            EstimatorConfig {
                start_velocity_search_mps: 1.5,
                ..EstimatorConfig::default()
            },
            jittered_sample,
        )
        .with_rest_water(thrusterd_core::navigation::long_rest_sway::RestWater::Moved);
        c.bench_with_input(
            BenchmarkId::new("dynamic_estimate_after_a_moving_rest", n),
            &n,
            |b, _| b.iter(|| black_box(moved.estimate())),
        );
        c.bench_with_input(
            BenchmarkId::new("dynamic_estimate_stopping_searching_start_velocity", n),
            &n,
            |b, _| {
                b.iter(|| {
                    let mut e = moved.estimate();
                    moved.search_start_velocity(&mut e);
                    black_box(e)
                })
            },
        );
        c.bench_with_input(
            BenchmarkId::new("dynamic_job_copy_learning_lag", n),
            &n,
            |b, _| b.iter(|| black_box(Box::new(learning.clone()))),
        );
        c.bench_with_input(BenchmarkId::new("dynamic_stop_decision", n), &n, |b, _| {
            b.iter(|| black_box(dynamic.stop_decision()))
        });
        // What the control thread pays when it hands that solve out (`solve::SolveJob`): a copy
        // of the running estimator, the segmented fits' closed cluster slots shared, not copied.
        c.bench_with_input(BenchmarkId::new("dynamic_job_copy", n), &n, |b, _| {
            b.iter(|| black_box(Box::new(dynamic.clone())))
        });
        // What opening a refinement window under control costs the control thread
        // (`adaptation::refinement::open_window`): a new dynamic estimator (its excitation
        // plan, the segmented fits' slots) set to closed loop.
        c.bench_with_input(
            BenchmarkId::new("closed_loop_window_open", n),
            &n,
            |b, _| {
                b.iter(|| {
                    let mut est = Estimator::new(
                        EstimatorConfig::default(),
                        n,
                        NoiseLevels::isotropic(1e-3, 1e-2),
                    )
                    .with_rest_specific_force(REST_FORCE);
                    est.begin_closed_loop();
                    black_box(est)
                })
            },
        );
        // The same with every column but thruster 0's carried over (an identification after a
        // known change): three more Gram solves per group, and the contradiction check.
        let mut se = nalgebra::DMatrix::from_element(6, n, 0.05);
        se.column_mut(0).fill(f64::INFINITY);
        let prior = thrusterd_core::estimator::dynamic::prior::DynamicPrior {
            b: nalgebra::DMatrix::from_element(6, n, 1.0),
            b_std_err: se,
            spin_up_s: None,
            imu_position_m: None,
            thruster_lags_s: Vec::new(),
            lag_rel_err: [0.0; 2],
            navigation_rel_err: [0.0; 2],
        };
        let carried = dynamic.clone().with_prior(prior);
        c.bench_with_input(
            BenchmarkId::new("dynamic_estimate_with_prior", n),
            &n,
            |b, _| b.iter(|| black_box(carried.estimate())),
        );
    }
}

/// The change test's cost per control tick (`refinement::change_test`, shipped settings: 40
/// candidate change times), N = 8 and 16, every candidate live and every row judged.
fn change_test(c: &mut Criterion) {
    use nalgebra::{DMatrix, UnitQuaternion};
    use thrusterd_core::adaptation::refinement::{change_test::ChangeTest, RefinementConfig};
    use thrusterd_core::model::Model;
    for n in [8usize, 16] {
        let b = DMatrix::from_fn(6, n, |r, i| ((r * 7 + i * 3) % 11) as f64 - 5.0);
        let model = Model::nominal(b, None);
        let mut test = ChangeTest::new(RefinementConfig::default().change_settings(0.1));
        let u: Vec<f64> = (0..n).map(|i| 0.1 * (i as f64 - 3.0)).collect();
        let mut k = 0u64;
        let tick = |test: &mut ChangeTest, k: &mut u64| {
            *k += 1;
            let w = Vector3::new(0.01 * (*k % 7) as f64, -0.02, 0.005 * (*k % 3) as f64);
            test.observe(
                *k * 5_000_000,
                &w,
                &UnitQuaternion::identity(),
                &model,
                &u,
                &[0.01; 3],
                [true; 3],
            )
        };
        // Past the warm-up (5 s) and the horizon (10 s) at 200 Hz.
        for _ in 0..4000 {
            tick(&mut test, &mut k);
        }
        c.bench_with_input(BenchmarkId::new("change_test_observe", n), &n, |bch, _| {
            bch.iter(|| black_box(tick(&mut test, &mut k)))
        });
    }
}

/// The refiner's and the identification's per-tick cost of knowing the thrusters' state: one
/// advance of the commands sent through the fit's lags, and the hold of the next command
/// (`estimator::dynamic::spin_state`), N = 8 and 16.
fn spin_state(c: &mut Criterion) {
    use thrusterd_core::estimator::dynamic::spin_state::{lags_for_fit, SpinState};
    for n in [8usize, 16] {
        let lags = lags_for_fit(n, 0.1, None, None);
        let mut state = SpinState::default();
        let mut t = 0.0;
        let mut k = 0u64;
        c.bench_with_input(BenchmarkId::new("spin_state_tick", n), &n, |b, _| {
            b.iter(|| {
                t += 0.005;
                k += 1;
                state.advance_to(black_box(t), &lags[..n]);
                let u = if k.is_multiple_of(2) { 0.4 } else { -0.3 };
                state.hold(black_box(&[u; 16][..n]));
            })
        });
    }
}

/// One refit of a logged run (the lag search's unit of work: ~22 per common lag, ~550 for a
/// lag per thruster searched to the end), N = 8 and 16, 64 pulses of 20 samples: in full,
/// and by a refitter that sums the lag-free terms' products once
/// (`estimator::dynamic::refit::Refitter`).
fn refit(c: &mut Criterion) {
    use thrusterd_core::estimator::dynamic::DynamicRun;
    use thrusterd_core::navigation::DepthAid;
    for n in [8usize, 16] {
        let mut run = DynamicRun::new(n, 0.1, 1.0, &REST_FORCE, DepthAid::default()).with_log(64);
        let mut t = 0.0;
        for pulse in 0..64usize {
            let u: Vec<f64> = (0..n)
                .map(|i| if (pulse + i) % 3 == 0 { 0.8 } else { -0.3 })
                .collect();
            for _ in 0..20 {
                t += 0.005;
                let (w, f) = dynamic_sample(t);
                run.push(t, &w, &f, Some(5.0), Some(&u));
            }
        }
        let imu = Vector3::zeros();
        let lags = vec![0.08; n];
        c.bench_with_input(BenchmarkId::new("dynamic_refit", n), &n, |b, _| {
            b.iter(|| black_box(run.refit_with(&lags, true, &imu)))
        });
        let refitter = run.refitter(&imu).expect("logged");
        c.bench_with_input(
            BenchmarkId::new("dynamic_refit_terms_summed_once", n),
            &n,
            |b, _| b.iter(|| black_box(refitter.refit(&lags))),
        );
    }
}

criterion_group!(benches, bench, change_test, refit, spin_state);
criterion_main!(benches);
