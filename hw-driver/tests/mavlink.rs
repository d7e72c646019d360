//! The MAVLink backend against a fake ArduSub on loopback UDP (real `thruster-hw` process,
//! real iceoryx2): HEARTBEATs both ways, message-rate requests with ACKs and retries,
//! DO_MOTOR_TEST contents and resend timing, disarmed autopilot, link loss and recovery,
//! RC_CHANNELS_OVERRIDE, connection failure.

mod common;

use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use common::fake_autopilot::{AP_COMP, AP_SYS};
use common::*;
use mavlink::dialects::ardupilotmega::{MavAutopilot, MavType};
use thruster_hw::clock::monotonic_ns;

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

const A: [f64; 4] = [0.6, 0.2, 0.0, 1.0];
const PULSES_A: [u16; 4] = [1750, 1400, 1510, 1800];

fn gaps_ms(times: &[u64]) -> Vec<f64> {
    times
        .windows(2)
        .map(|w| (w[1] - w[0]) as f64 / 1e6)
        .collect()
}

#[test]
fn heartbeats_at_1_hz_and_rate_requests_acknowledged_once_each() {
    let _s = serial();
    let h = Harness::<Mavlink>::start(100, "");
    std::thread::sleep(Duration::from_millis(2300));
    let (hbs, requests) =
        h.fx.0
            .with(|s| (s.heartbeats.clone(), s.interval_requests()));
    assert!(hbs.len() >= 2, "{} heartbeats in 2.3 s", hbs.len());
    for (_, hdr, hb) in &hbs {
        assert_eq!((hdr.system_id, hdr.component_id), (255, 191));
        assert_eq!(hb.mavtype, MavType::MAV_TYPE_ONBOARD_CONTROLLER);
        assert_eq!(hb.autopilot, MavAutopilot::MAV_AUTOPILOT_INVALID);
    }
    let times: Vec<u64> = hbs.iter().map(|(t, _, _)| *t).collect();
    for g in gaps_ms(&times) {
        assert!((900.0..1100.0).contains(&g), "heartbeat gap {g:.0} ms");
    }
    // SCALED_IMU2 at 100 Hz, ATTITUDE at 50 Hz, SCALED_PRESSURE2 at 20 Hz; one each when ACKed.
    let got: Vec<(f32, f32, u8, u8, u8)> = requests
        .iter()
        .map(|(_, c)| {
            (
                c.param1,
                c.param2,
                c.target_system,
                c.target_component,
                c.confirmation,
            )
        })
        .collect();
    assert_eq!(
        got,
        [
            (116.0, 10_000.0, AP_SYS, AP_COMP, 0),
            (30.0, 20_000.0, AP_SYS, AP_COMP, 0),
            (137.0, 50_000.0, AP_SYS, AP_COMP, 0)
        ]
    );
    assert!(
        h.fx.0.with(|s| s.imu_sent) > 100,
        "the fake streams what was requested"
    );
    h.finish();
}

#[test]
fn unacknowledged_rate_requests_are_retried_then_the_next_goes_out() {
    let _s = serial();
    let h = Harness::<Mavlink>::start_with(100, "", "command_retries = 2", |fx| {
        fx.0.with(|s| s.ack_requests = false)
    });
    // command_timeout_ms = 300: three tries of the first request, then the second.
    std::thread::sleep(Duration::from_millis(1300));
    let requests = h.fx.0.with(|s| s.interval_requests());
    let first: Vec<(u64, f32, u8)> = requests
        .iter()
        .map(|(t, c)| (*t, c.param1, c.confirmation))
        .collect();
    assert!(first.len() >= 4, "{first:?}");
    assert_eq!(
        first[..4].iter().map(|r| (r.1, r.2)).collect::<Vec<_>>(),
        [(116.0, 0), (116.0, 1), (116.0, 2), (30.0, 0)]
    );
    let times: Vec<u64> = first[..4].iter().map(|r| r.0).collect();
    for g in gaps_ms(&times) {
        assert!(
            (280.0..450.0).contains(&g),
            "retry gap {g:.0} ms (timeout 300 ms)"
        );
    }
    let (proc, _) = h.finish();
    assert!(proc.log().contains("giving up"), "{}", proc.log());
}

#[test]
fn motor_tests_carry_board_order_pwm_and_are_resent_well_inside_500_ms() {
    let _s = serial();
    let mut h = Harness::<Mavlink>::start(100, "");
    h.drive_to(&A, PULSES_A);
    let from = monotonic_ns();
    // A constant command for a second: only resends carry it.
    h.daemon.hold(&A, Duration::from_secs(1));
    // Then no command at all: the watchdog's neutral must keep going out too.
    std::thread::sleep(Duration::from_millis(800));
    let to = monotonic_ns();
    let tests: Vec<_> =
        h.fx.0
            .with(|s| s.motor_tests())
            .into_iter()
            .filter(|(t, _)| (from..to).contains(t))
            .collect();
    let headers = h.fx.0.with(|s| {
        s.commands
            .iter()
            .map(|(_, hdr, _)| (hdr.system_id, hdr.component_id))
            .collect::<Vec<_>>()
    });
    assert!(headers.iter().all(|&h| h == (255, 191)));
    for (k, ch) in Mavlink::CHANNELS.iter().enumerate() {
        let mine: Vec<_> = tests
            .iter()
            .filter(|(_, c)| c.param1 == *ch as f32)
            .collect();
        assert!(
            mine.len() >= 15,
            "motor {ch}: {} commands in 1.8 s",
            mine.len()
        );
        for (_, c) in &mine {
            assert_eq!(c.param2, 1.0, "throttle type PWM");
            assert_eq!(
                (c.param4, c.param5, c.param6),
                (0.5, 0.0, 2.0),
                "timeout, count, board order"
            );
            assert_eq!((c.target_system, c.target_component), (AP_SYS, AP_COMP));
            let (lo, hi) = RANGES[k];
            assert!(
                (f32::from(lo)..=f32::from(hi)).contains(&c.param3),
                "{}",
                c.param3
            );
            assert!(c.param3 == f32::from(PULSES_A[k]) || c.param3 == f32::from(NEUTRAL[k]));
        }
        let times: Vec<u64> = mine.iter().map(|(t, _)| *t).collect();
        let worst = gaps_ms(&times).into_iter().fold(0.0, f64::max);
        assert!(
            worst < 150.0,
            "motor {ch}: {worst:.0} ms between commands (resend 100 ms, ArduSub gives up at 500)"
        );
        assert_eq!(
            mine.last().unwrap().1.param3,
            f32::from(NEUTRAL[k]),
            "neutral after the watchdog"
        );
    }
    h.finish();
}

#[test]
fn a_disarmed_autopilot_gets_no_motor_tests_but_samples_flow() {
    let _s = serial();
    let h = Harness::<Mavlink>::start_with(100, "", "", |fx| fx.0.with(|s| s.armed = false));
    let s = h
        .daemon
        .try_sample(TIMEOUT)
        .expect("samples while disarmed");
    assert!(s.seq >= 1);
    std::thread::sleep(Duration::from_millis(800));
    assert!(h.fx.0.with(|s| s.motor_tests()).is_empty());
    // Armed (seen in the next HEARTBEAT, within a second): neutral motor tests begin.
    h.fx.0.with(|s| s.armed = true);
    h.wait_pulses(Duration::from_secs(3), |p| p == NEUTRAL);
    let (proc, _) = h.finish();
    assert!(proc.log().contains("autopilot armed"), "{}", proc.log());
}

#[test]
fn heartbeat_loss_stops_samples_and_recovery_resumes_them() {
    let _s = serial();
    let h = Harness::<Mavlink>::start_with(100, "", "link_timeout_ms = 1500", |_| {});
    h.daemon.try_sample(TIMEOUT).expect("samples");
    let requests_before = h.fx.0.with(|s| s.interval_requests().len());
    // Heartbeats stop; the IMU stream goes on.
    h.fx.0.with(|s| s.heartbeat = false);
    let stopped = Instant::now();
    let mut last_sample = Instant::now();
    while stopped.elapsed() < Duration::from_millis(3500) {
        if h.daemon.try_sample(Duration::from_millis(20)).is_some() {
            last_sample = Instant::now();
        }
    }
    let quiet_after = last_sample.duration_since(stopped);
    // The last HEARTBEAT came up to 1 s before `stopped`; the link times out 1.5 s after it.
    assert!(
        quiet_after < Duration::from_millis(1500 + 300),
        "samples went on {quiet_after:?} after heartbeats stopped"
    );
    assert!(
        quiet_after > Duration::from_millis(300),
        "stopped too early: {quiet_after:?}"
    );
    assert!(h.fx.0.with(|s| s.imu_sent) > 0);
    // Heartbeats back: link up, rates requested again, samples again.
    h.fx.0.with(|s| s.heartbeat = true);
    h.daemon
        .try_sample(Duration::from_secs(3))
        .expect("samples resume");
    // The driver sends its rate requests when the link comes up, but the fake autopilot's
    // thread records them asynchronously: a sample can arrive first (once, in CI).
    let asked = Instant::now();
    while h.fx.0.with(|s| s.interval_requests().len()) <= requests_before {
        assert!(
            asked.elapsed() < Duration::from_secs(2),
            "no rate request after the link came back"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let (proc, _) = h.finish();
    assert!(proc.log().contains("link down"), "{}", proc.log());
}

#[test]
fn rc_override_sets_the_configured_channels_only() {
    let _s = serial();
    let mut h = Harness::<Mavlink>::start_with(100, "", "output = \"rc_override\"", |_| {});
    let end = Instant::now() + TIMEOUT;
    loop {
        h.daemon.answer(&A);
        let last = h.fx.0.with(|s| s.overrides.last().cloned());
        if let Some((_, hdr, o)) = last {
            if [o.chan1_raw, o.chan2_raw, o.chan3_raw, o.chan4_raw] == PULSES_A {
                assert_eq!((hdr.system_id, hdr.component_id), (255, 191));
                assert_eq!((o.target_system, o.target_component), (AP_SYS, AP_COMP));
                assert_eq!(
                    [o.chan5_raw, o.chan6_raw, o.chan7_raw, o.chan8_raw],
                    [u16::MAX; 4]
                );
                break;
            }
        }
        assert!(
            Instant::now() < end,
            "no override with the commanded pulses"
        );
    }
    assert!(h.fx.0.with(|s| s.motor_tests()).is_empty());
    let (_, fx) = h.finish();
    let last = fx.0.with(|s| s.overrides.last().cloned()).unwrap().2;
    assert_eq!(
        [
            last.chan1_raw,
            last.chan2_raw,
            last.chan3_raw,
            last.chan4_raw
        ],
        NEUTRAL
    );
}

#[test]
fn an_unreachable_autopilot_is_an_error_naming_the_address() {
    let _s = serial();
    let ns = thruster_protocol::services::NamespaceGuard::unique_for_test("conn").unwrap();
    let config = format!(
        "namespace = \"{}\"\nbackend = \"mavlink\"\n{}[mavlink]\naddress = \"serial:/dev/thruster-hw-none:115200\"\n",
        ns.namespace(),
        thrusters(Mavlink::CHANNELS)
    );
    let mut p = Proc::run(&config, &[]);
    let status = p.wait_exit(Duration::from_secs(5)).expect("exits");
    assert_eq!(status.code(), Some(1), "{}", p.log());
    assert!(p.log().contains("/dev/thruster-hw-none"), "{}", p.log());
    assert_namespace_clean(&ns);
}
