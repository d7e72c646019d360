//! What telemetry costs the control tick in the pure core: the snapshot
//! (`Machine::telemetry`) and its message (`wire::telemetry_msg`) after one IMU sample, beside
//! the tick itself (`Machine::on_imu` while holding attitude, and while idle with and without
//! the long rest's windows, `machine.gyro_bias_rest_s`), 8 thrusters. The IPC part (one
//! copy into shared memory and a listener's wake-up) is in `cargo bench -p system-tests --bench
//! latency`.
//! Run: cargo bench -p thrusterd-core --bench telemetry

use criterion::{black_box, criterion_group, criterion_main, Criterion};

use thrusterd_core::machine::{Geometry, ImuInput, Machine, MachineSetup, Request, State};
use thrusterd_core::wire;

fn sample(k: u64) -> ImuInput {
    ImuInput {
        seq: k,
        t_ns: 1_000_000_000 + k * 5_000_000,
        gyro: [0.001 * (k % 5) as f64, -0.002, 0.001],
        accel: [0.0, 0.01 * (k % 3) as f64, -9.80665],
        mag: Some([20.0, 0.0, 45.0]),
        depth: Some(5.0),
    }
}

/// Eight declared thrusters (vectored horizontal, four vertical), holding attitude and depth.
fn holding() -> (Machine, u64) {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let mut positions = Vec::new();
    let mut directions = Vec::new();
    for (p, d) in [
        ([0.15, -0.1, 0.0], [h, h, 0.0]),
        ([0.15, 0.1, 0.0], [h, -h, 0.0]),
        ([-0.15, -0.1, 0.0], [h, -h, 0.0]),
        ([-0.15, 0.1, 0.0], [h, h, 0.0]),
        ([0.12, -0.22, 0.0], [0.0, 0.0, 1.0]),
        ([0.12, 0.22, 0.0], [0.0, 0.0, -1.0]),
        ([-0.12, -0.22, 0.0], [0.0, 0.0, -1.0]),
        ([-0.12, 0.22, 0.0], [0.0, 0.0, 1.0]),
    ] {
        positions.push(p);
        directions.push(d);
    }
    let mut m = Machine::new(MachineSetup {
        thrusters: 8,
        geometry: Some(Geometry {
            positions,
            directions,
        }),
        ..MachineSetup::default()
    });
    let mut k = 0;
    for _ in 0..20 {
        k += 1;
        m.on_imu(&sample(k));
    }
    m.on_request(Request::Hold).unwrap();
    for _ in 0..20 {
        k += 1;
        m.on_imu(&sample(k));
    }
    assert_eq!(m.state(), State::Active);
    (m, k)
}

/// The same machine idle for two minutes (the long rest's windows full), with
/// `gyro_bias_rest_s`.
fn idle(gyro_bias_rest_s: f64) -> (Machine, u64) {
    let mut setup = MachineSetup {
        thrusters: 8,
        ..MachineSetup::default()
    };
    setup.machine.gyro_bias_rest_s = gyro_bias_rest_s;
    let mut m = Machine::new(setup);
    let mut k = 0;
    for _ in 0..24_000 {
        k += 1;
        m.on_imu(&sample(k));
    }
    assert_eq!(m.state(), State::Idle);
    (m, k)
}

fn bench(c: &mut Criterion) {
    for (name, bias_s) in [
        ("control tick (on_imu, idle, long rest 60 s)", 60.0),
        ("control tick (on_imu, idle, long rest off)", 0.0),
    ] {
        let (mut m, mut k) = idle(bias_s);
        c.bench_function(name, |b| {
            b.iter(|| {
                k += 1;
                black_box(m.on_imu(black_box(&sample(k))))
            })
        });
    }
    let (mut m, mut k) = holding();
    c.bench_function("control tick (on_imu, holding)", |b| {
        b.iter(|| {
            k += 1;
            black_box(m.on_imu(black_box(&sample(k))))
        })
    });
    let s = sample(k);
    let cmd = m.on_imu(&s);
    let sent = wire::thrust_command(1, s.seq, s.t_ns, &cmd);
    c.bench_function("telemetry snapshot + message", |b| {
        b.iter(|| {
            let snapshot = m.telemetry(black_box(&s));
            black_box(wire::telemetry_msg(1, &snapshot, black_box(&sent)))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
