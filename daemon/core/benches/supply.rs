//! The supply's share of the control tick: eight commands carried to the voltage a sagging
//! pack gives under their own draw (`Supply::to_present` with a learned sag line: a 3-step
//! fixed point over the T200 table), and the pulse cap under the pack's sag
//! (`Supply::attainable_loaded`, once per estimation pulse). Both run on the control thread;
//! the budget there is a few tens of microseconds per sample.
//!
//! Run: cargo bench -p thrusterd-core --bench supply

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use thrusterd_core::supply::{Supply, SupplyConfig};

/// A supply that has seen a 4S pack of 20 mOhm under changing load, read every 100 ms.
fn sagging() -> Supply {
    let mut s = Supply::new(SupplyConfig {
        linearize: true,
        ..SupplyConfig::default()
    });
    for k in 0..40 {
        let power = if k % 2 == 0 { 0.9 } else { 0.1 };
        let mut u = [power; 8];
        s.to_present(&mut u);
        // Roughly what eight T200s near full draw pull through 20 mOhm.
        let volts = 16.8 - 0.02 * if k % 2 == 0 { 140.0 } else { 10.0 };
        s.on_reading(0.1 * k as f64, Some(volts));
    }
    assert!(s.sag_line().is_some(), "the line was learned");
    s
}

fn bench(c: &mut Criterion) {
    let mut s = sagging();
    let asked = [0.3, -0.5, 0.8, -0.1, 0.05, 0.6, -0.9, 0.2];
    c.bench_function("supply: 8 commands to the sagging pack's voltage", |b| {
        b.iter(|| {
            let mut u = asked;
            s.to_present(black_box(&mut u));
            u
        })
    });
    c.bench_function("supply: pulse cap under the sag (8 thrusters)", |b| {
        b.iter(|| black_box(&s).attainable_loaded(8))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
