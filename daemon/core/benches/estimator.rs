//! Per-pulse update and solve costs of the estimator, N = 8 and N = 16.
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
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
