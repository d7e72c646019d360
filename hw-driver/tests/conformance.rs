//! The conformance suites, against every backend, each with the real `thruster-hw` process
//! on fake hardware (a fake ArduSub on loopback UDP; a fake sysfs tree with PWM and IIO) and
//! the test as the daemon over real iceoryx2. Each test has its own namespace and leaves no
//! process and no file behind.
//!
//! - The driver contract's suite (`thruster_driver_kit::conformance`, modules
//!   `contract_mavlink` and `contract_linux`): what every driver does, seen through the
//!   protocol only; the simulator runs the same suite (sim-driver/tests/conformance.rs).
//! - The hardware suite below (modules `mavlink` and `linux`): what reaches the outputs as
//!   pulses, and the IMU's units, which only hardware backends have.
//!
//! The tests run one at a time (a lock): they measure timing, and the machine has 2 cores.
//! Precise timing rules are unit-tested in `core::watchdog`; the margins here are generous.
//!
//! Latency figures for docs/hardware.md:
//! `cargo test -p thruster-hw --test conformance latency -- --nocapture`

mod common;

use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use common::*;
use thruster_hw::clock::monotonic_ns;
use thruster_protocol::{ThrustCommand, Validate};

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

const A: [f64; 4] = [0.6, 0.2, 0.0, 1.0];
const PULSES_A: [u16; 4] = [1750, 1400, 1510, 1800];
const B: [f64; 4] = [0.3, -0.3, 0.5, -0.5];
const PULSES_B: [u16; 4] = [1638, 1638, 1718, 1338];

fn in_range(history: &[(u64, usize, u16)]) {
    for &(t, i, us) in history {
        let (lo, hi) = RANGES[i];
        assert!(
            (lo..=hi).contains(&us),
            "thruster {i} got {us} us at {t} ns, outside [{lo}, {hi}]"
        );
    }
}

fn neutral_at_start_and_while_arming<F: Fixture>() {
    let _s = serial();
    let spawned = monotonic_ns();
    let mut h = Harness::<F>::start(800, "");
    assert_eq!(h.wait_pulses(TIMEOUT, |_| true), NEUTRAL, "first pulses");
    // Valid commands during the arming hold are not applied.
    h.daemon.hold(&A, Duration::from_millis(300));
    assert_eq!(h.fx.pulses().unwrap(), NEUTRAL);
    h.drive_to(&A, PULSES_A);
    let history = h.fx.history();
    // The fake sysfs records writes from an inotify thread that reads the file after the
    // event; on a loaded machine it can read a later value and miss the active pulse
    // altogether (seen in CI). When it did record it, its time must be after the arming hold;
    // the neutral check during the hold above holds either way.
    if let Some(first_active) = history
        .iter()
        .find(|(_, i, us)| *us != NEUTRAL[*i])
        .map(|(t, _, _)| *t)
    {
        assert!(
            first_active >= spawned + 800 * MS,
            "thrust {} ms after spawn, before the 800 ms arming hold ended",
            (first_active - spawned) / MS
        );
    }
    in_range(&history);
    let (proc, _) = h.finish();
    assert!(proc.summary_value("arming") > 0, "{}", proc.log());
}

fn commands_map_to_the_configured_pulses<F: Fixture>() {
    let _s = serial();
    let mut h = Harness::<F>::start(100, "");
    h.wait_pulses(TIMEOUT, |p| p == NEUTRAL);
    let cases: [([f64; 4], [u16; 4]); 5] = [
        (A, PULSES_A),
        ([-1.0; 4], [1100, 1900, 1100, 1200]),
        ([1.0, 1.0, 1.0, -0.5], [1900, 1100, 1900, 1338]),
        ([0.01; 4], [1529, 1471, 1539, 1528]),
        ([0.0; 4], NEUTRAL),
    ];
    for (thrust, expected) in cases {
        h.drive_to(&thrust, expected);
    }
    in_range(&h.fx.history());
    h.finish();
}

type MakeCommand = fn(&mut Daemon) -> ThrustCommand;

fn garbage_is_rejected_counted_and_neutral<F: Fixture>() {
    let _s = serial();
    let mut h = Harness::<F>::start(100, "");
    // (name, command, fails the protocol's content validation on its own)
    let garbage: [(&str, MakeCommand, bool); 5] = [
        (
            "NaN",
            |d| {
                let s = d.fresh_sample();
                d.command(&s, &[f64::NAN, 1.0, 1.0, 1.0])
            },
            true,
        ),
        (
            "1e9",
            |d| {
                let s = d.fresh_sample();
                d.command(&s, &[1.0, 1e9, 1.0, 1.0])
            },
            true,
        ),
        (
            "-inf",
            |d| {
                let s = d.fresh_sample();
                d.command(&s, &[1.0, 1.0, f64::NEG_INFINITY, 1.0])
            },
            true,
        ),
        (
            "wrong count",
            |d| {
                let s = d.fresh_sample();
                d.command(&s, &[1.0, 1.0, 1.0])
            },
            false,
        ),
        (
            "unpublished sample",
            |d| {
                let s = d.fresh_sample();
                let mut c = d.command(&s, &[1.0; 4]);
                c.imu_seq += 1000;
                c
            },
            false,
        ),
    ];
    for (name, make, invalid_content) in garbage {
        h.drive_to(&[1.0; 4], [1900, 1100, 1900, 1800]);
        let cmd = make(&mut h.daemon);
        assert_eq!(cmd.validate().is_err(), invalid_content, "{name}");
        h.daemon.send(&cmd);
        // Neutral at once (well before the watchdog could act), and it stays neutral while
        // no valid command follows.
        let t = Instant::now();
        h.wait_pulses(Duration::from_secs(2), |p| p == NEUTRAL);
        assert!(
            t.elapsed() < Duration::from_millis(150),
            "{name}: neutral after {:?}",
            t.elapsed()
        );
        std::thread::sleep(Duration::from_millis(250));
        assert_eq!(h.fx.pulses().unwrap(), NEUTRAL, "{name}");
    }
    in_range(&h.fx.history());
    let (proc, _) = h.finish();
    assert_eq!(proc.summary_value("rejected_nonfinite"), 2);
    assert_eq!(proc.summary_value("rejected_range"), 1);
    assert_eq!(proc.summary_value("rejected_count"), 1);
    assert_eq!(proc.summary_value("rejected_other"), 1);
}

fn watchdog_neutral_and_old_commands_do_not_re_arm<F: Fixture>() {
    let _s = serial();
    let mut h = Harness::<F>::start(100, "");
    h.drive_to(&A, PULSES_A);
    // The last command: from here the watchdog (200 ms after its sample) must take over.
    let (last, _) = h.daemon.answer(&A);
    let neutral = h.wait_pulses(Duration::from_secs(2), |p| p == NEUTRAL);
    assert_eq!(neutral, NEUTRAL);
    // The fake kernel thread notes a write when it gets the CPU: on a loaded 2-core CI the
    // outputs read neutral before the history held the write (a panic here, once). Wait for it.
    let deadline = Instant::now() + Duration::from_secs(2);
    let went_neutral = loop {
        let first =
            h.fx.history()
                .iter()
                .filter(|(t, i, us)| *t > last.t_ns && *i == 0 && *us == NEUTRAL[0])
                .map(|(t, _, _)| *t)
                .next();
        match first {
            Some(t) => break t,
            None if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(10)),
            None => panic!("no neutral write of channel 0 recorded after the last command"),
        }
    };
    let after_ms = (went_neutral - last.t_ns) as f64 / 1e6;
    // Lower bound exact (never before the watchdog); upper bound generous, since the fake
    // kernel thread notes the write only when it gets the CPU (the pure watchdog unit tests
    // check the timing itself to the nanosecond).
    assert!(
        (195.0..2000.0).contains(&after_ms),
        "neutral {after_ms:.1} ms after the last commanded sample (watchdog 200 ms)"
    );
    // A command answering that old sample (older than the watchdog) does not re-arm.
    let old = h.daemon.command(&last, &A);
    h.daemon.send(&old);
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(h.fx.pulses().unwrap(), NEUTRAL);
    // A fresh one does.
    h.drive_to(&A, PULSES_A);
    let (proc, _) = h.finish();
    assert!(proc.summary_value("stale") >= 1, "{}", proc.log());
    assert!(proc.log().contains("watchdog expired"), "{}", proc.log());
}

fn sigterm_leaves_neutral_and_nothing_behind<F: Fixture>() {
    let _s = serial();
    let mut h = Harness::<F>::start(100, "");
    h.drive_to(&[1.0; 4], [1900, 1100, 1900, 1800]);
    // Keep commanding right up to the signal, so only the exit path can make it neutral.
    h.daemon.hold(&[1.0; 4], Duration::from_millis(100));
    let (proc, fx) = h.finish();
    assert_eq!(fx.pulses().unwrap(), NEUTRAL, "{}", proc.log());
    assert!(proc.log().contains("outputs neutral"), "{}", proc.log());
    assert!(proc.summary_value("applied") > 0);
}

fn imu_samples_in_si_units<F: Fixture>() {
    let _s = serial();
    let h = Harness::<F>::start(100, "");
    let imu = Imu {
        gyro: [0.1, -0.2, 0.3],
        accel: [0.5, -0.3, -9.81],
        mag_ut: [20.0, -5.0, 40.0],
        depth_m: 2.5,
    };
    h.fx.set_imu(&imu);
    // Let a sample with the new values through (and the depth, which a MAVLink driver takes
    // once the autopilot named its water barometer), then check a run of them.
    std::thread::sleep(Duration::from_millis(100));
    let until = std::time::Instant::now() + Duration::from_secs(3);
    let first = loop {
        let s = h.daemon.fresh_sample();
        if s.has_depth() || std::time::Instant::now() > until {
            break s;
        }
    };
    let t0 = monotonic_ns();
    let mut samples = vec![first];
    while samples.len() < 50 {
        samples.push(h.daemon.try_sample(TIMEOUT).expect("samples stopped"));
    }
    let elapsed_s = (monotonic_ns() - t0) as f64 / 1e9;
    let rate = 49.0 / elapsed_s;
    assert!(
        (60.0..=140.0).contains(&rate),
        "{rate:.1} Hz, configured 100 Hz"
    );
    let [tg, ta, tm, td] = F::TOLERANCE;
    for w in samples.windows(2) {
        assert_eq!(w[1].seq, w[0].seq + 1, "consecutive seq");
        assert!(w[1].t_ns > w[0].t_ns, "time advances");
    }
    for s in &samples {
        s.validate().unwrap();
        // t_ns is CLOCK_MONOTONIC at reading: comparable with our own clock.
        let now = monotonic_ns();
        assert!(
            s.t_ns <= now && now - s.t_ns < 2_000 * MS,
            "t_ns {} vs now {now}",
            s.t_ns
        );
        let close = |got: [f64; 3], want: [f64; 3], tol: f64, what: &str| {
            for k in 0..3 {
                assert!(
                    (got[k] - want[k]).abs() <= tol,
                    "{what}[{k}] = {} expected {} +- {tol}",
                    got[k],
                    want[k]
                );
            }
        };
        close(s.gyro, imu.gyro, tg, "gyro rad/s");
        close(s.accel, imu.accel, ta, "accel m/s^2");
        close(s.mag, imu.mag_ut, tm, "mag uT");
        assert!(s.has_mag() && s.has_depth(), "flags {:#x}", s.flags);
        assert!((s.depth - imu.depth_m).abs() <= td, "depth {} m", s.depth);
    }
    // The latest sample was read at most a few periods ago.
    let last = samples.last().unwrap();
    assert!(monotonic_ns() - last.t_ns < 200 * MS);
    h.finish();
}

fn percentile(sorted: &[u64], p: f64) -> f64 {
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i] as f64 / 1e3
}

fn command_to_output_latency<F: Fixture>() {
    let _s = serial();
    let mut h = Harness::<F>::start(100, "");
    h.drive_to(&A, PULSES_A);
    const N: usize = 100;
    let (mut first, mut all) = (Vec::with_capacity(N), Vec::with_capacity(N));
    for i in 0..N {
        let (thrust, expected) = if i % 2 == 0 {
            (B, PULSES_B)
        } else {
            (A, PULSES_A)
        };
        let (_, sent) = h.daemon.answer(&thrust);
        let end = Instant::now() + Duration::from_secs(2);
        loop {
            let history = h.fx.history();
            let seen: Vec<Option<u64>> = (0..4)
                .map(|k| {
                    history
                        .iter()
                        .find(|(t, j, us)| *t >= sent && *j == k && *us == expected[k])
                        .map(|(t, _, _)| *t)
                })
                .collect();
            if seen.iter().all(Option::is_some) {
                let ts: Vec<u64> = seen.into_iter().flatten().collect();
                first.push(ts.iter().min().unwrap() - sent);
                all.push(ts.iter().max().unwrap() - sent);
                break;
            }
            assert!(
                Instant::now() < end,
                "command {i} never reached every output"
            );
            // The fake hardware timestamps; polling slowly leaves the CPU to the driver.
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    first.sort_unstable();
    all.sort_unstable();
    eprintln!(
        "latency {} (ThrustCommand publish -> hardware, {N} commands, 4 thrusters), us: \
         first output p50 {:.0} p90 {:.0} max {:.0}; all outputs p50 {:.0} p90 {:.0} p99 {:.0} max {:.0}",
        F::BACKEND,
        percentile(&first, 0.5),
        percentile(&first, 0.9),
        percentile(&first, 1.0),
        percentile(&all, 0.5),
        percentile(&all, 0.9),
        percentile(&all, 0.99),
        percentile(&all, 1.0),
    );
    // A defect check, not a speed target: wall-clock figures on a shared machine. Measured
    // (this command, debug build, 2 cores): all outputs p50 0.13-0.22 ms, max 0.25-8.8 ms;
    // with three busy loops beside it (`for i in 1 2 3; do (while :; do :; done) & done`)
    // p50 0.09-0.40 ms, max 2.1-29.6 ms. A driver that applied commands on its own 100 Hz
    // tick instead of on arrival would show a median near 5 ms, so the median is held below
    // 2.5 ms (6x the loaded figure); the worst case below 100 ms (3x the loaded worst). The
    // figures docs/hardware.md quotes are this test's output.
    assert!(percentile(&all, 0.5) < 2_500.0, "median above 2.5 ms");
    assert!(percentile(&all, 1.0) < 100_000.0, "worst case above 100 ms");
    h.finish();
}

macro_rules! conformance {
    ($($backend:ident: $fixture:ty),* $(,)?) => {$(
        mod $backend {
            use super::*;
            #[test]
            fn neutral_at_start_and_while_arming() {
                super::neutral_at_start_and_while_arming::<$fixture>()
            }
            #[test]
            fn commands_map_to_the_configured_pulses() {
                super::commands_map_to_the_configured_pulses::<$fixture>()
            }
            #[test]
            fn garbage_is_rejected_counted_and_neutral() {
                super::garbage_is_rejected_counted_and_neutral::<$fixture>()
            }
            #[test]
            fn watchdog_neutral_and_old_commands_do_not_re_arm() {
                super::watchdog_neutral_and_old_commands_do_not_re_arm::<$fixture>()
            }
            #[test]
            fn sigterm_leaves_neutral_and_nothing_behind() {
                super::sigterm_leaves_neutral_and_nothing_behind::<$fixture>()
            }
            #[test]
            fn imu_samples_in_si_units() {
                super::imu_samples_in_si_units::<$fixture>()
            }
            #[test]
            fn latency() {
                super::command_to_output_latency::<$fixture>()
            }
        }
    )*};
}

conformance!(mavlink: Mavlink, linux: Linux);

thruster_driver_kit::conformance_suite!(
    contract_mavlink: Contract<Mavlink>,
    contract_linux: Contract<Linux>,
);
