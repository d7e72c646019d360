//! IMU sample -> thrust command latency through the real daemon, beside a raw iceoryx2
//! ping-pong of the same payloads (`thruster-sim respond`, which only validates and answers),
//! measured in the same run, in event mode and in low-latency (spin) mode; the daemon with
//! telemetry off, at its default (every 10th sample) and on every sample, each with a reader
//! subscribed to it (so every message is delivered and its listener woken).
//!
//! Run: cargo bench -p system-tests --bench latency [-- ROUND_TRIPS]

use std::time::{Duration, Instant};

use system_tests::{state, Operator, Proc, World};
use thruster_protocol::services::{Inbox, Port};
use thruster_protocol::{DaemonState, ImuSample, RequestKind, TelemetryMsg, ThrustCommand};

const WARMUP: usize = 2_000;

struct Stats {
    p50: f64,
    p99: f64,
    p999: f64,
    mean: f64,
}

fn stats(mut us: Vec<f64>) -> Stats {
    us.sort_by(|a, b| a.total_cmp(b));
    let q = |p: f64| us[((us.len() as f64 - 1.0) * p).round() as usize];
    Stats {
        p50: q(0.5),
        p99: q(0.99),
        p999: q(0.999),
        mean: us.iter().sum::<f64>() / us.len() as f64,
    }
}

fn sample(seq: u64) -> ImuSample {
    ImuSample {
        seq,
        t_ns: 1_000_000_000 + seq * 1_000_000,
        gyro: [0.001, -0.002, 0.0005],
        accel: [0.0, 0.0, -9.80665],
        mag: [20.0, 0.0, 45.0],
        depth: 5.0,
        flags: ImuSample::HAS_MAG | ImuSample::HAS_DEPTH,
    }
}

/// One round trip per sample, busy-polling for the answer. Microseconds.
fn round_trips(
    imu: &Port<ImuSample>,
    thrust: &Inbox<ThrustCommand>,
    seq: &mut u64,
    count: usize,
) -> Vec<f64> {
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        *seq += 1;
        let start = Instant::now();
        imu.send(&sample(*seq)).unwrap();
        loop {
            if let Some(c) = thrust.recv().unwrap() {
                if c.imu_seq == *seq {
                    break;
                }
            }
            assert!(
                start.elapsed() < Duration::from_secs(5),
                "no answer to sample {seq}"
            );
            std::hint::spin_loop();
        }
        out.push(start.elapsed().as_secs_f64() * 1e6);
    }
    out
}

/// Ping-pong `n` samples after a handshake, `setup` and a warm-up.
fn ping_pong(world: &World, n: usize, setup: impl FnOnce()) -> Vec<f64> {
    let imu: Port<ImuSample> = Port::create(world.node(), world.ipc()).unwrap();
    let thrust: Inbox<ThrustCommand> = Inbox::create(world.node(), world.ipc()).unwrap();
    let mut seq = 0u64;
    // Handshake: until the peer answers at all.
    let start = Instant::now();
    loop {
        seq += 1;
        imu.send(&sample(seq)).unwrap();
        std::thread::sleep(Duration::from_millis(5));
        if thrust.recv().unwrap().is_some() {
            while thrust.recv().unwrap().is_some() {}
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "peer never answered"
        );
    }
    setup();
    round_trips(&imu, &thrust, &mut seq, WARMUP);
    round_trips(&imu, &thrust, &mut seq, n)
}

fn daemon_config(world: &World, telemetry_every_n: u32) -> std::path::PathBuf {
    // Eight declared thrusters (directions need not be unit: the daemon normalises them): the
    // daemon starts with a nominal model and can hold attitude.
    let mut text = String::from("[vehicle]\n");
    for (p, d) in [
        ([0.15, -0.1, 0.0], [1.0, 1.0, 0.0]),
        ([0.15, 0.1, 0.0], [1.0, -1.0, 0.0]),
        ([-0.15, -0.1, 0.0], [1.0, -1.0, 0.0]),
        ([-0.15, 0.1, 0.0], [1.0, 1.0, 0.0]),
        ([0.12, -0.22, 0.0], [0.0, 0.0, 1.0]),
        ([0.12, 0.22, 0.0], [0.0, 0.0, -1.0]),
        ([-0.12, -0.22, 0.0], [0.0, 0.0, -1.0]),
        ([-0.12, 0.22, 0.0], [0.0, 0.0, 1.0]),
    ] {
        text += &format!("[[vehicle.thruster]]\nposition_m = {p:?}\ndirection = {d:?}\n");
    }
    text += &format!("[telemetry]\nevery_n = {telemetry_every_n}\n");
    let path = world.path("thrusterd.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// Round trips through `thrusterd run` holding attitude, telemetry every `every_n`-th sample
/// (0: off) with a reader attached.
fn through_daemon(n: usize, spin: &str, every_n: u32) -> Stats {
    let world = World::new("lat-d");
    let ns = world.namespace();
    let cfg = daemon_config(&world, every_n);
    let state_dir = world.path("state");
    let mut peer = Proc::spawn(
        "thrusterd",
        &[
            "run",
            "--config",
            cfg.to_str().unwrap(),
            "--namespace",
            &ns,
            "--state-dir",
            state_dir.to_str().unwrap(),
            "--spin-us",
            spin,
        ],
        world.dir.path(),
    );
    let op = Operator::new(&world);
    // A reader as `thrusterctl watch --interval-ms 0` is, with the topic's full buffer: every
    // message is delivered and its listener notified. Read only after the run (reading here
    // would be measured); a full buffer drops its oldest, which costs the daemon the same.
    let telemetry: Inbox<TelemetryMsg> = Inbox::create(world.node(), world.ipc()).unwrap();
    let us = ping_pong(&world, n, || {
        // Hold attitude, so every sample runs the attitude filter and the controller.
        let r = op.request(RequestKind::Hold);
        assert!(r.is_ok(), "{}", r.text());
        op.wait_status(Duration::from_secs(10), |s| state(s) == DaemonState::Active)
            .expect("daemon active");
    });
    let got = telemetry.recv().unwrap().is_some();
    assert_eq!(
        got,
        every_n > 0,
        "telemetry every {every_n}: received {got}"
    );
    peer.stop();
    stats(us)
}

fn main() {
    // Never measure a binary left from an older build.
    system_tests::build_binaries();
    let n: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(20_000);
    println!(
        "IMU sample -> thrust command round trip, {n} samples after {WARMUP} warm-up, microseconds"
    );
    println!("| mode | path | p50 | p99 | p99.9 | mean | p50 ratio daemon/raw |");
    println!("|---|---|---|---|---|---|---|");
    for (mode, spin) in [
        ("event (spin 0)", "0"),
        ("low-latency (spin 1000 us)", "1000"),
    ] {
        let raw = {
            let world = World::new("lat-raw");
            let ns = world.namespace();
            let mut peer = Proc::spawn(
                "thruster-sim",
                &[
                    "respond",
                    "--namespace",
                    &ns,
                    "--count",
                    "8",
                    "--spin-us",
                    spin,
                ],
                world.dir.path(),
            );
            let us = ping_pong(&world, n, || {});
            peer.stop();
            stats(us)
        };
        let mut rows = vec![("raw iceoryx2 ping-pong".to_string(), raw, None)];
        for (what, every_n) in [
            ("telemetry off", 0),
            ("telemetry every 10th, default", 10),
            ("telemetry every sample", 1),
        ] {
            let s = through_daemon(n, spin, every_n);
            let ratio = s.p50 / rows[0].1.p50;
            rows.push((
                format!("through thrusterd (controlling, {what})"),
                s,
                Some(ratio),
            ));
        }
        for (path, s, ratio) in &rows {
            let ratio = ratio.map_or_else(String::new, |r| format!("{r:.2}"));
            println!(
                "| {mode} | {path} | {:.1} | {:.1} | {:.1} | {:.1} | {ratio} |",
                s.p50, s.p99, s.p999, s.mean
            );
        }
    }
}
