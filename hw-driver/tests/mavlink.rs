//! The MAVLink backend against a fake ArduSub on loopback UDP (real `thruster-hw` process,
//! real iceoryx2): HEARTBEATs both ways, message-rate requests with ACKs and retries,
//! DO_MOTOR_TEST contents and resend timing, disarmed autopilot, link loss and recovery,
//! RC_CHANNELS_OVERRIDE, connection failure.

mod common;

use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use common::fake_autopilot::{FakeAutopilot, AP_COMP, AP_SYS, CUBE_BAROS};
use common::*;
use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavMessage, MavModeFlag, MavState, MavType, HEARTBEAT_DATA,
};
use mavlink::{MavHeader, MavlinkVersion};
use thruster_hw::clock::monotonic_ns;
use thruster_protocol::OutputState;

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
    // The period itself is checked on the conversation's own clock
    // (`conversation::tests::heartbeats_every_heartbeat_ms`); here, on the wall clock of a shared
    // machine, that they come at about 1 Hz: a gap is 1 s plus the scheduling delays of the
    // driver's send and of our receipt (tens of ms on a loaded 2-core machine), so [700, 1500)
    // ms, which a 2 Hz or a 0.5 Hz heartbeat fails.
    for g in gaps_ms(&times) {
        assert!((700.0..1500.0).contains(&g), "heartbeat gap {g:.0} ms");
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
    // Never before the timeout (exact); the upper bound leaves room for a loaded machine's
    // scheduling (the retry timing itself: `conversation::tests::unacknowledged_requests_are_
    // retried_then_given_up`, on the conversation's own clock).
    for g in gaps_ms(&times) {
        assert!(
            (280.0..1000.0).contains(&g),
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
            .filter(|(_, c)| c.param1 == motor_index(*ch))
            .collect();
        // 18 at the 100 ms resend period; each resend counts from the last send, so
        // scheduling delays on a loaded machine thin them a little.
        assert!(
            mine.len() >= 9,
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
        // What matters is ArduSub's 0.5 s motor-test timeout (param4): a gap near it stops
        // the motor. The 100 ms resend period itself is checked on the conversation's own clock
        // (`conversation::tests::motor_tests_only_while_armed_at_once_on_change_and_resent`); on
        // the wall clock of a loaded machine the gap is 100 ms plus scheduling delays, held
        // under 400 ms (was 150: a busy 2-core machine can delay a send by tens of ms).
        assert!(
            worst < 400.0,
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

/// Issue 16 item 3: disarmed from the start (not only armed -> disarmed) is visible in the
/// log and on `driver_status`; commands are accepted but no motor test goes out.
#[test]
fn a_disarmed_autopilot_is_reported_from_the_first_heartbeat() {
    let _s = serial();
    let mut h = Harness::<Mavlink>::start_with(100, "", "", |fx| fx.0.with(|s| s.armed = false));
    h.daemon
        .try_sample(TIMEOUT)
        .expect("samples while disarmed");
    // The daemon commands thrust as usual; nothing can reach the water.
    h.daemon.hold(&A, Duration::from_millis(800));
    assert!(h.fx.0.with(|s| s.motor_tests()).is_empty());
    let st = h.daemon.wait_status(TIMEOUT, |m| m.link_up == 1);
    assert_eq!(st.output_state(), Ok(OutputState::Disarmed), "{st:?}");
    assert_eq!((st.armed, st.thruster_count), (0, 4));
    assert_eq!(st.driver(), "thruster-hw mavlink");
    assert!(st.commands_accepted > 0, "{st:?}");
    assert_eq!(st.text(), "autopilot disarmed");
    let log = h.proc.log();
    assert!(log.contains("autopilot disarmed"), "{log}");
    assert!(!log.contains("outputs: active"), "{log}");
    // Armed (seen in the next HEARTBEAT, within a second): thrust reaches the motors.
    h.fx.0.with(|s| s.armed = true);
    h.drive_to(&A, PULSES_A);
    let st = h.daemon.wait_status(TIMEOUT, |m| m.armed == 1);
    assert_eq!(st.link_up, 1);
    let (proc, _) = h.finish();
    assert!(proc.log().contains("autopilot armed"), "{}", proc.log());
}

/// Issue 16 item 7: with nothing to command the driver stays out of ArduSub's motor-test
/// mode (which bypasses the pilot and ends with a disarm 500 ms after the last test), so a
/// driver that never commanded thrust leaves the vehicle armed when it exits.
#[test]
fn nothing_to_command_sends_no_motor_tests_and_exit_leaves_the_vehicle_armed() {
    let _s = serial();
    let h = Harness::<Mavlink>::start(100, "");
    h.daemon.try_sample(TIMEOUT).expect("samples");
    std::thread::sleep(Duration::from_millis(1500));
    assert!(h.fx.0.with(|s| s.motor_tests()).is_empty());
    let (_, fx) = h.finish();
    std::thread::sleep(Duration::from_millis(800));
    fx.0.with(|s| {
        assert_eq!(s.lapses, 0, "motor-test timeout after exit");
        assert!(s.armed, "the exit disarmed the vehicle");
    });
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
    // As docs/hardware.md asks before this mode is used (FS_PILOT_INPUT 2 is the default).
    let mut h = Harness::<Mavlink>::start_with(100, "", "output = \"rc_override\"", |fx| {
        fx.0.with(|s| s.params.insert("FS_PILOT_TIMEOUT".into(), 0.5));
    });
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

/// ArduSub keeps driving our last override until its pilot-input failsafe takes the channels
/// back to neutral, FS_PILOT_TIMEOUT (3 s by default) after it, or never with FS_PILOT_INPUT
/// 0; and it takes back only the RCMAP channels, each to its trim. Until the autopilot says
/// all is well, the driver asks, sends neutral overrides only, and reports its outputs held
/// with the reason, while the vehicle is armed and the link up.
#[test]
fn rc_overrides_stay_neutral_while_the_autopilot_would_keep_a_left_one_long() {
    let _s = serial();
    for (name, value, says) in [
        (
            "FS_PILOT_TIMEOUT",
            3.0,
            "FS_PILOT_TIMEOUT = 3 s: our last override would outlive us 3 s",
        ),
        (
            "FS_PILOT_INPUT",
            0.0,
            "FS_PILOT_INPUT = 0: nothing neutralises our last override",
        ),
        // The failsafe neutralises the RCMAP channels only, each at its trim.
        ("RCMAP_PITCH", 7.0, "channel 1 is not an RCMAP channel"),
        (
            "RC2_TRIM",
            1550.0,
            "RC2_TRIM = 1550: the failsafe leaves channel 2 there, not at",
        ),
        // A stock frame's Motor 3 on output 3: our overrides would be pilot sticks.
        (
            "SERVO3_FUNCTION",
            35.0,
            "SERVO3_FUNCTION = 35 (a motor): ArduSub mixes our overrides as pilot sticks",
        ),
    ] {
        let mut h = Harness::<Mavlink>::start_with(100, "", "output = \"rc_override\"", |fx| {
            fx.0.with(|s| {
                s.params.insert("FS_PILOT_TIMEOUT".into(), 0.5);
                s.params.insert(name.into(), value)
            });
        });
        h.daemon.try_sample(TIMEOUT).expect("samples");
        h.daemon.hold(&A, Duration::from_millis(800));
        let st = h.daemon.wait_status(TIMEOUT, |m| m.text().contains("held"));
        assert_eq!(st.output_state(), Ok(OutputState::Disarmed), "{st:?}");
        assert_eq!((st.armed, st.link_up), (1, 1), "{st:?}");
        assert!(st.text().contains(says), "{}", st.text());
        let (overrides, asked) =
            h.fx.0
                .with(|s| (s.overrides.clone(), s.param_requests.clone()));
        for p in ["FS_PILOT_INPUT", "FS_PILOT_TIMEOUT", "RC_OVERRIDE_TIME"] {
            assert!(
                asked.iter().any(|(_, n)| n == p),
                "{p} not asked: {asked:?}"
            );
        }
        assert!(overrides.len() > 3, "{} overrides", overrides.len());
        for (_, _, o) in &overrides {
            assert_eq!(
                [o.chan1_raw, o.chan2_raw, o.chan3_raw, o.chan4_raw],
                NEUTRAL,
                "thrust went out with {name} = {value}"
            );
        }
        assert!(h.fx.0.with(|s| s.motor_tests()).is_empty());
        let (proc, _) = h.finish();
        assert!(proc.log().contains(says), "{}", proc.log());
    }
}

/// ArduSub's SYS_STATUS reaches `driver_status` as the supply (the receive thread dropped it
/// until the RC override check's test found its filter short of what the conversation handles).
#[test]
fn the_autopilots_battery_reaches_driver_status() {
    let _s = serial();
    let h = Harness::<Mavlink>::start(100, "");
    h.daemon.try_sample(TIMEOUT).expect("samples");
    let st = h
        .daemon
        .wait_status(TIMEOUT, |m| m.supply_voltage_v.is_finite());
    assert!((st.supply_voltage_v - 15.8).abs() < 1e-9, "{st:?}");
    assert!((st.supply_current_a - 12.5).abs() < 1e-9, "{st:?}");
    // No battery monitor (ArduSub sends UINT16_MAX): unknown again once the reading is stale.
    h.fx.0.with(|s| s.battery_mv = u16::MAX);
    let st = h
        .daemon
        .wait_status(Duration::from_secs(8), |m| m.supply_voltage_v.is_nan());
    assert!(st.supply_current_a.is_nan(), "{st:?}");
    h.finish();
}

/// On a Cube the Bar30 is the third barometer, which ArduSub reports in no message, and the
/// second is the tube's air: SCALED_PRESSURE2 says about 0 m at any depth, and a depth hold on
/// it dives. The driver reads the barometers' device ids and publishes no depth, saying why;
/// named in the config, SCALED_PRESSURE2 is refused once the autopilot says it is air.
#[test]
fn the_tubes_air_barometer_on_a_cube_is_never_taken_for_depth() {
    let _s = serial();
    for section in ["", "pressure_message = \"scaled_pressure2\""] {
        let h = Harness::<Mavlink>::start_with(100, "", section, |fx| {
            fx.0.with(|s| {
                *s = std::mem::take(s).baros(CUBE_BAROS);
                // The vehicle at 2.5 m: only the unreported third barometer feels it.
                s.press_hpa = (1013.25 + 2.5 * 997.0 * 9.80665 / 100.0) as f32;
            })
        });
        h.daemon.try_sample(TIMEOUT).expect("samples");
        // The ids come within a second of link-up; from then on, 1.5 s of samples.
        std::thread::sleep(Duration::from_secs(1));
        h.daemon.fresh_sample();
        let t0 = Instant::now();
        let mut n = 0;
        while t0.elapsed() < Duration::from_millis(1500) {
            let s = h.daemon.try_sample(TIMEOUT).expect("samples stopped");
            assert!(
                !s.has_depth(),
                "{section:?}: depth {} m from the air",
                s.depth
            );
            n += 1;
        }
        assert!(n > 100, "{n} samples");
        let asked = h.fx.0.with(|s| s.param_requests.clone());
        assert!(asked.iter().any(|(_, p)| p == "BARO3_DEVID"), "{asked:?}");
        let (proc, _) = h.finish();
        let log = proc.log();
        let says = if section.is_empty() {
            "no depth: the water sensor (MS5837-30BA) is barometer 3, which ArduSub reports in no message"
        } else {
            "no depth: SCALED_PRESSURE2 is barometer 2, an air barometer (MS5611)"
        };
        assert!(log.contains(says), "{section:?}: {log}");
    }
}

/// With bit 6 of BATT_OPTIONS ArduPilot reports a resting estimate (V + I R) in SYS_STATUS,
/// not the voltage at the ESCs: the driver reports the voltage unknown (the current still
/// known) and says which bit to clear.
#[test]
fn a_resting_voltage_estimate_is_not_reported_as_the_escs() {
    let _s = serial();
    let h = Harness::<Mavlink>::start_with(100, "", "", |fx| {
        fx.0.with(|s| s.params.insert("BATT_OPTIONS".to_string(), 64.0));
    });
    h.daemon.try_sample(TIMEOUT).expect("samples");
    let st = h
        .daemon
        .wait_status(TIMEOUT, |m| m.supply_current_a.is_finite());
    // The driver asks for BATT_OPTIONS at link-up: after a few statuses it is known.
    std::thread::sleep(Duration::from_secs(2));
    let st2 = h
        .daemon
        .wait_status(TIMEOUT, |m| m.supply_current_a.is_finite());
    assert!((st2.supply_current_a - 12.5).abs() < 1e-9, "{st2:?}");
    assert!(st2.supply_voltage_v.is_nan(), "{st:?} then {st2:?}");
    let (proc, _) = h.finish();
    assert!(
        proc.log().contains("BATT_OPTIONS = 64: bit 6"),
        "{}",
        proc.log()
    );
}

/// In `rc_override` mode a ground station's joystick overrides the same channels (ArduSub turns
/// its MANUAL_CONTROL into overrides of channels 1-8): the driver sees another sender's values
/// in RC_CHANNELS, stops its overrides (the pilot has the vehicle) and says why on
/// `driver_status`; without the joystick the daemon's thrust goes out.
#[test]
fn a_ground_stations_joystick_on_our_rc_channels_stops_our_overrides() {
    let _s = serial();
    for joystick in [false, true] {
        let mut h = Harness::<Mavlink>::start_with(100, "", "output = \"rc_override\"", |fx| {
            fx.0.with(|s| {
                s.params.insert("FS_PILOT_TIMEOUT".into(), 0.5);
                s.joystick = joystick.then_some([1500; 8]);
            });
        });
        h.daemon.try_sample(TIMEOUT).expect("samples");
        h.daemon.hold(&A, Duration::from_millis(1500));
        let asked = h.fx.0.with(|s| s.interval_requests());
        assert!(
            asked
                .iter()
                .any(|(_, c)| c.param1 == 65.0 && c.param2 == 100_000.0),
            "RC_CHANNELS not asked for: {asked:?}"
        );
        if joystick {
            let st = h
                .daemon
                .wait_status(TIMEOUT, |m| m.text().contains("another sender"));
            assert_eq!(st.output_state(), Ok(OutputState::Disarmed), "{st:?}");
            let n = h.fx.0.with(|s| s.overrides.len());
            h.daemon.hold(&A, Duration::from_millis(500));
            assert_eq!(h.fx.0.with(|s| s.overrides.len()), n, "overrides went on");
            let (proc, _) = h.finish();
            assert!(
                proc.log().contains("disable its joystick"),
                "{}",
                proc.log()
            );
        } else {
            let moved = h.fx.0.with(|s| {
                s.overrides
                    .iter()
                    .filter(|(_, _, o)| o.chan1_raw != NEUTRAL[0])
                    .count()
            });
            assert!(moved > 5, "{moved} overrides with thrust");
            assert!(h
                .daemon
                .statuses()
                .iter()
                .all(|m| !m.text().contains("another sender")));
            h.finish();
        }
    }
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

/// A ground station that connects after us and sends REQUEST_DATA_STREAM resets ArduPilot's
/// message intervals (SCALED_IMU2 to 2 Hz on ArduSub): the driver sees the IMU starve and
/// asks for its rate again, and the samples come back at 100 Hz.
#[test]
fn an_imu_rate_reset_by_a_ground_station_is_asked_for_again() {
    let _s = serial();
    let h = Harness::<Mavlink>::start(100, "");
    h.daemon.try_sample(TIMEOUT).expect("samples");
    let before = h.fx.0.with(|s| s.interval_requests().len());
    // What initialise_message_intervals_for_stream does to SCALED_IMU2 (id 116).
    h.fx.0.with(|s| s.intervals.insert(116, 500_000));
    let t0 = Instant::now();
    loop {
        let (back, asked) = h.fx.0.with(|s| {
            (
                s.intervals.get(&116) == Some(&10_000),
                s.interval_requests().len(),
            )
        });
        if back && asked > before {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(8),
            "the IMU rate was not asked for again"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    eprintln!(
        "IMU rate asked for again {:?} after the reset",
        t0.elapsed()
    );
    // 100 Hz again: at least 50 samples in the next second (2 Hz would give 2).
    let end = Instant::now() + Duration::from_secs(1);
    let mut n = 0;
    while Instant::now() < end {
        if h.daemon.try_sample(Duration::from_millis(50)).is_some() {
            n += 1;
        }
    }
    assert!(
        n >= 50,
        "{n} samples in 1 s after the rate was asked for again"
    );
    let (proc, _) = h.finish();
    assert!(proc.log().contains("asking again"), "{}", proc.log());
}

/// A configuration that cannot be used exits 2 (the unit does not restart it); the
/// unreachable autopilot above, a failure of the run, exits 1 (the unit restarts it).
#[test]
fn a_bad_configuration_exits_2_naming_the_key() {
    let ns = thruster_protocol::services::NamespaceGuard::unique_for_test("badcfg").unwrap();
    let config = format!(
        "namespace = \"{}\"\nbackend = \"mavlink\"\n{}[mavlink]\nmax_override_hold_s = -1\n",
        ns.namespace(),
        thrusters(Mavlink::CHANNELS)
    );
    let mut p = Proc::run(&config, &[]);
    let status = p.wait_exit(Duration::from_secs(5)).expect("exits");
    assert_eq!(status.code(), Some(2), "{}", p.log());
    assert!(p.log().contains("max_override_hold_s"), "{}", p.log());
    assert_namespace_clean(&ns);
}

/// A free loopback UDP port for a driver in udpin mode.
fn free_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A driver listening (`udpin`) with the fake autopilot as the client, like a BlueOS
/// "UDP Client" endpoint; returns the harness and the driver's port.
fn udpin_harness(section_extra: &str) -> (Harness<Mavlink>, u16) {
    let port = free_port();
    let fx = Mavlink(FakeAutopilot::start_client(port));
    (Harness::start_fx(100, "", section_extra, fx), port)
}

fn frame(sys: u8, comp: u8, autopilot: MavAutopilot) -> Vec<u8> {
    let h = MavHeader {
        system_id: u32::from(sys),
        component_id: comp,
        sequence: 0,
    };
    let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 19,
        mavtype: MavType::MAV_TYPE_SUBMARINE,
        autopilot,
        base_mode: MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    });
    let mut v = Vec::new();
    mavlink::write_versioned_msg(&mut v, MavlinkVersion::V2, h, &hb).unwrap();
    v
}

/// Issue 16 item 1: any UDP sender used to capture the motor tests in udpin mode (replies
/// went to the last datagram's source). A flood of stray datagrams (empty, random bytes, a
/// ground station's and a spoofed autopilot's HEARTBEAT) during held thrust: the stray
/// socket gets nothing, the autopilot no gap near ArduSub's 500 ms, and no lapse.
#[test]
fn a_flood_of_stray_datagrams_captures_nothing_and_causes_no_lapse() {
    let _s = serial();
    let (mut h, port) = udpin_harness("");
    h.drive_to(&A, PULSES_A);
    let stray = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    stray.set_nonblocking(true).unwrap();
    let flood_socket = stray.try_clone().unwrap();
    let from = monotonic_ns();
    let flood = std::thread::spawn(move || {
        let end = Instant::now() + Duration::from_secs(2);
        let mut x: u32 = 12345;
        let mut sent = 0u64;
        while Instant::now() < end {
            x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
            let d: Vec<u8> = match sent % 4 {
                0 => Vec::new(),
                1 => (0..(x % 300)).map(|i| (x >> (i % 24)) as u8).collect(),
                2 => frame(255, 190, MavAutopilot::MAV_AUTOPILOT_INVALID),
                _ => frame(AP_SYS, AP_COMP, MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA),
            };
            let _ = flood_socket.send_to(&d, ("127.0.0.1", port));
            sent += 1;
            std::thread::sleep(Duration::from_millis(5));
        }
        sent
    });
    h.daemon.hold(&A, Duration::from_secs(2));
    let sent = flood.join().unwrap();
    let to = monotonic_ns();
    assert!(sent > 200, "{sent} stray datagrams");
    let mut buf = [0u8; 512];
    let mut captured = 0;
    while stray.recv_from(&mut buf).is_ok() {
        captured += 1;
    }
    assert_eq!(captured, 0, "the stray sender received our messages");
    let tests = h.fx.0.with(|s| s.motor_tests());
    for ch in Mavlink::CHANNELS {
        let times: Vec<u64> = tests
            .iter()
            .filter(|(t, c)| (from..to).contains(t) && c.param1 == motor_index(ch))
            .map(|(t, _)| *t)
            .collect();
        assert!(times.len() >= 15, "motor {ch}: {} tests", times.len());
        let worst = gaps_ms(&times).into_iter().fold(0.0, f64::max);
        assert!(
            worst < 200.0,
            "motor {ch}: {worst:.0} ms gap during the flood"
        );
    }
    h.fx.0.with(|s| assert_eq!((s.lapses, s.armed), (0, true)));
    let (proc, _) = h.finish();
    assert!(
        proc.summary_value("datagrams_foreign") > 100,
        "{}",
        proc.log()
    );
}

/// Issue 16 item 5: one empty datagram used to end the driver (exit 1). Empty and garbage
/// datagrams, from the autopilot's own address and from a stranger, change nothing.
#[test]
fn an_empty_datagram_changes_nothing() {
    let _s = serial();
    let (mut h, port) = udpin_harness("");
    h.drive_to(&A, PULSES_A);
    let stray = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    h.fx.0.send_raw(&[], port);
    stray.send_to(&[], ("127.0.0.1", port)).unwrap();
    h.fx.0.send_raw(&[0xfd, 0x01, 0x02], port);
    h.daemon.hold(&A, Duration::from_millis(700));
    assert!(
        h.proc.wait_exit(Duration::from_millis(20)).is_none(),
        "the driver exited\n{}",
        h.proc.log()
    );
    assert_eq!(h.fx.pulses().unwrap(), PULSES_A);
    h.daemon.try_sample(TIMEOUT).expect("samples still flow");
    h.fx.0.with(|s| assert_eq!((s.lapses, s.armed), (0, true)));
    let (proc, _) = h.finish();
    assert_eq!(proc.summary_value("datagrams_empty"), 2, "{}", proc.log());
    assert_eq!(proc.summary_value("datagrams_malformed"), 1);
}

/// Issue 16 item 2: HEARTBEATs lost while the IMU keeps flowing and thrust is held: the
/// link goes down and the last thing the autopilot got is a neutral round, not the held
/// pulses; `driver_status` says LinkDown.
#[test]
fn heartbeat_loss_with_imu_flowing_ends_in_a_neutral_round() {
    let _s = serial();
    let mut h = Harness::<Mavlink>::start_with(100, "", "link_timeout_ms = 1000", |_| {});
    h.drive_to(&A, PULSES_A);
    h.fx.0.with(|s| s.heartbeat = false);
    // Keep answering samples with thrust until they stop (the link is down).
    let stopped = Instant::now();
    let mut last_sample = Instant::now();
    while last_sample.elapsed() < Duration::from_millis(500) {
        assert!(
            stopped.elapsed() < Duration::from_secs(5),
            "samples never stopped"
        );
        if let Some(smp) = h.daemon.try_sample(Duration::from_millis(20)) {
            let c = h.daemon.command(&smp, &A);
            h.daemon.send(&c);
            last_sample = Instant::now();
        }
    }
    assert!(h.fx.0.with(|s| s.imu_sent) > 0);
    let tests = h.fx.0.with(|s| s.motor_tests());
    for (k, ch) in Mavlink::CHANNELS.iter().enumerate() {
        let last = tests
            .iter()
            .rev()
            .find(|(_, c)| c.param1 == motor_index(*ch))
            .map(|(_, c)| c.param3 as u16);
        assert_eq!(
            last,
            Some(NEUTRAL[k]),
            "motor {ch}: last pulse before going quiet"
        );
    }
    let st = h
        .daemon
        .wait_status(TIMEOUT, |m| m.output_state() == Ok(OutputState::LinkDown));
    assert_eq!(st.link_up, 0);
    assert!(st.text().contains("link down"), "{}", st.text());
    let (proc, _) = h.finish();
    assert!(proc.log().contains("link down"), "{}", proc.log());
}

/// Issue 16 item 8: RAW_IMU holding ADC counts (-4096 on z = 1 g at +-8 g) must not be
/// published as -40 m/s^2: rejected and counted; good readings flow again after.
#[test]
fn implausible_raw_imu_readings_are_rejected_and_counted() {
    let _s = serial();
    let h = Harness::<Mavlink>::start_with(100, "", "imu_message = \"raw_imu\"", |_| {});
    let s = h.daemon.try_sample(TIMEOUT).expect("samples");
    assert!((s.accel[2] + 9.80665).abs() < 0.01, "{:?}", s.accel);
    h.fx.0.with(|s| s.acc = [0, 0, -4096]);
    std::thread::sleep(Duration::from_millis(100));
    let end = Instant::now() + Duration::from_millis(600);
    while Instant::now() < end {
        if let Some(s) = h.daemon.try_sample(Duration::from_millis(20)) {
            assert!(s.accel[2] > -30.0, "published {:?}", s.accel);
        }
    }
    h.fx.0.with(|s| s.acc = [0, 0, -1000]);
    let end = Instant::now() + TIMEOUT;
    loop {
        let s = h.daemon.try_sample(TIMEOUT).expect("samples resume");
        if (s.accel[2] + 9.80665).abs() < 0.01 {
            break;
        }
        assert!(Instant::now() < end);
    }
    let (proc, _) = h.finish();
    assert!(proc.summary_value("imu_implausible") > 10, "{}", proc.log());
}

/// Issue 16 item 4: ArduSub's DO_MOTOR_TEST param1 is the 0-based motor index
/// (AP_MotorsMatrix::output_test_num); config channel n is motor n, so channel 8 of an
/// 8-motor frame is param1 7 and is accepted (param1 8 was refused, and channel 1 drove
/// motor 2).
#[test]
fn channel_n_drives_ardusub_motor_n_including_the_last() {
    let _s = serial();
    let ns = thruster_protocol::services::NamespaceGuard::unique_for_test("motnum").unwrap();
    let fx = FakeAutopilot::start();
    let config = format!(
        "namespace = \"{}\"\nbackend = \"mavlink\"\narming_ms = 100\n\
         [[thruster]]\nchannel = 1\n[[thruster]]\nchannel = 8\n\
         [mavlink]\naddress = \"{}\"\ncommand_timeout_ms = 300\n",
        ns.namespace(),
        fx.address()
    );
    let mut daemon = Daemon::new(&ns);
    let mut proc = Proc::run(&config, &[]);
    let end = Instant::now() + TIMEOUT;
    loop {
        daemon.answer(&[0.6, -0.2]);
        let tests = fx.with(|s| s.motor_tests());
        let last = |m: f32| {
            tests
                .iter()
                .rev()
                .find(|(_, c)| c.param1 == m)
                .map(|(_, c)| c.param3)
        };
        if last(0.0) == Some(1750.0) && last(7.0) == Some(1400.0) {
            assert!(tests
                .iter()
                .all(|(_, c)| c.param1 == 0.0 || c.param1 == 7.0));
            break;
        }
        assert!(Instant::now() < end, "{tests:?}\n{}", proc.log());
    }
    proc.terminate();
    drop(daemon);
    assert_namespace_clean(&ns);
    assert_eq!(
        proc.summary_value("motor_test_refused"),
        0,
        "{}",
        proc.log()
    );
}
