use super::*;
use crate::backend::mavlink::motor_test::ardusub_motor_index;

const AP: (u8, u8) = (1, 1);

fn specs() -> Vec<OutputSpec> {
    vec![
        OutputSpec {
            channel: 1,
            neutral: Pwm(1500),
        },
        OutputSpec {
            channel: 4,
            neutral: Pwm(1510),
        },
    ]
}

fn hdr(sys: u8, comp: u8) -> MavHeader {
    MavHeader {
        system_id: u32::from(sys),
        component_id: comp,
        sequence: 0,
    }
}

fn heartbeat(autopilot: MavAutopilot, armed: bool) -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_SUBMARINE,
        autopilot,
        base_mode: if armed {
            MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
        } else {
            MavModeFlag::empty()
        },
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

fn ap_heartbeat(armed: bool) -> MavMessage {
    heartbeat(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA, armed)
}

fn ack(command: MavCmd, result: MavResult) -> MavMessage {
    MavMessage::COMMAND_ACK(COMMAND_ACK_DATA { command, result })
}

fn imu2(acc: [i16; 3], gyro: [i16; 3]) -> MavMessage {
    MavMessage::SCALED_IMU2(SCALED_IMU2_DATA {
        xacc: acc[0],
        yacc: acc[1],
        zacc: acc[2],
        xgyro: gyro[0],
        ygyro: gyro[1],
        zgyro: gyro[2],
        ..SCALED_IMU2_DATA::DEFAULT
    })
}

fn commands(out: &[MavMessage]) -> Vec<COMMAND_LONG_DATA> {
    out.iter()
        .filter_map(|m| match m {
            MavMessage::COMMAND_LONG(c) => Some(c.clone()),
            _ => None,
        })
        .collect()
}

fn param(name: &str, v: f32) -> MavMessage {
    MavMessage::PARAM_VALUE(mavlink::dialects::ardupilotmega::PARAM_VALUE_DATA {
        param_value: v,
        param_count: 900,
        param_index: 31,
        param_id: name.into(),
        param_type: mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_REAL32,
    })
}

/// A device id as ArduPilot's `make_bus_id` builds it.
fn devid(bus_type: u32, address: u32, devtype: u32) -> f32 {
    (bus_type | address << 8 | devtype << 16) as f32
}

/// A Navigator's barometers: its BMP280 onboard (I2C 0x76), the Bar30 second.
const NAVIGATOR: [(u32, u32, u32); 3] = [(1, 0x76, 0x03), (1, 0x76, 0x12), (0, 0, 0)];
/// A Cube's: two MS5611 on SPI, the Bar30 third.
const CUBE: [(u32, u32, u32); 3] = [(2, 1, 0x0b), (2, 3, 0x0b), (1, 0x76, 0x12)];

/// The autopilot tells its barometers' device ids.
fn baros(s: &mut Conversation, t: u64, ids: [(u32, u32, u32); 3]) {
    for (i, (bus, address, devtype)) in ids.into_iter().enumerate() {
        let name = format!("BARO{}_DEVID", i + 1);
        s.on_message(t, &hdr(1, 1), &param(&name, devid(bus, address, devtype)));
    }
}

/// The names asked for with PARAM_REQUEST_READ in `out`.
fn asked(out: &[MavMessage]) -> Vec<String> {
    out.iter()
        .filter_map(|m| match m {
            MavMessage::PARAM_REQUEST_READ(r) => Some(
                r.param_id
                    .to_str()
                    .unwrap()
                    .trim_end_matches('\0')
                    .to_string(),
            ),
            _ => None,
        })
        .collect()
}

/// A conversation with the link up (armed as given) and the set-up requests acknowledged.
fn up(armed: bool) -> Conversation {
    let mut s = Conversation::new(MavlinkConfig::default(), specs(), 0);
    s.on_message(1, &hdr(AP.0, AP.1), &ap_heartbeat(armed));
    baros(&mut s, 1, NAVIGATOR);
    s.service(1);
    for _ in 0..3 {
        s.on_message(
            2,
            &hdr(AP.0, AP.1),
            &ack(
                MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                MavResult::MAV_RESULT_ACCEPTED,
            ),
        );
    }
    s.drain_outgoing();
    s
}

/// Our HEARTBEAT every `heartbeat_ms` on the conversation's own clock: one at the start, none
/// before the period is up, the next at the deadline (the process test, on the wall clock
/// of a shared machine, checks only that they keep coming at about 1 Hz).
#[test]
fn heartbeats_every_heartbeat_ms() {
    let heartbeats = |s: &mut Conversation| {
        s.drain_outgoing()
            .iter()
            .filter(|m| matches!(m, MavMessage::HEARTBEAT(_)))
            .count()
    };
    let mut s = up(false);
    let period = MavlinkConfig::default().heartbeat_ms * MS;
    assert_eq!(period, 1_000 * MS, "the shipped period");
    // `up` sent the first at its first service, 1 ns.
    let t0 = 1;
    for k in 1..=3u64 {
        s.service(t0 + k * period - 1);
        assert_eq!(heartbeats(&mut s), 0, "early before heartbeat {k}");
        s.service(t0 + k * period);
        assert_eq!(heartbeats(&mut s), 1, "heartbeat {k}");
        assert!(s.next_deadline_ns() <= t0 + (k + 1) * period);
    }
}

#[test]
fn finds_the_autopilot_and_requests_rates_one_at_a_time() {
    let mut s = Conversation::new(MavlinkConfig::default(), specs(), 0);
    s.service(0);
    let out = s.drain_outgoing();
    assert!(
        matches!(out.as_slice(), [MavMessage::HEARTBEAT(h)] if h.mavtype == MavType::MAV_TYPE_ONBOARD_CONTROLLER)
    );
    assert_eq!(s.header().system_id, 255);
    // A ground station's heartbeat is not the autopilot.
    s.on_message(
        1,
        &hdr(255, 190),
        &heartbeat(MavAutopilot::MAV_AUTOPILOT_INVALID, false),
    );
    assert_eq!((s.target(), s.link()), (None, LinkState::Connecting));
    s.on_message(2, &hdr(1, 1), &ap_heartbeat(false));
    assert_eq!((s.target(), s.link()), (Some(AP), LinkState::Up));
    s.service(3);
    let c = commands(&s.drain_outgoing());
    assert_eq!(c.len(), 1, "one request in flight");
    assert_eq!(c[0].command, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL);
    assert_eq!((c[0].param1, c[0].param2), (116.0, 10_000.0));
    assert_eq!(
        (c[0].target_system, c[0].target_component, c[0].confirmation),
        (1, 1, 0)
    );
    // The ACK sends the next at once: ATTITUDE at 50 Hz, then, once the barometers are
    // known, SCALED_PRESSURE2 at 20 Hz.
    s.on_message(
        4,
        &hdr(1, 1),
        &ack(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    let c = commands(&s.drain_outgoing());
    assert_eq!((c[0].param1, c[0].param2), (30.0, 20_000.0));
    s.on_message(
        5,
        &hdr(1, 1),
        &ack(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            MavResult::MAV_RESULT_DENIED,
        ),
    );
    assert!(commands(&s.drain_outgoing()).is_empty(), "depth not known");
    baros(&mut s, 5, NAVIGATOR);
    s.service(5);
    let c = commands(&s.drain_outgoing());
    assert_eq!((c[0].param1, c[0].param2), (137.0, 50_000.0));
    s.on_message(
        6,
        &hdr(1, 1),
        &ack(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    assert!(commands(&s.drain_outgoing()).is_empty());
}

#[test]
fn unacknowledged_requests_are_retried_then_given_up() {
    let cfg = MavlinkConfig {
        command_retries: 2,
        // Longer than the retries take: a link loss clears the queue.
        link_timeout_ms: 60_000,
        attitude_rate_hz: 0.0,
        pressure_rate_hz: 0.0,
        ..MavlinkConfig::default()
    };
    let timeout = cfg.command_timeout_ms * MS;
    let mut s = Conversation::new(cfg, specs(), 0);
    s.on_message(0, &hdr(1, 1), &ap_heartbeat(false));
    let mut confirmations = Vec::new();
    let mut t = 0;
    for _ in 0..5 {
        s.service(t);
        confirmations.extend(commands(&s.drain_outgoing()).iter().map(|c| c.confirmation));
        t += timeout;
    }
    assert_eq!(confirmations, [0, 1, 2]);
    assert_eq!(s.counters().commands_unacked, 1);
    // No IMU message in the 2 s after giving up: the rate is asked for again (`rate_watch`).
    s.service(t);
    let again = commands(&s.drain_outgoing());
    assert_eq!(
        again
            .iter()
            .map(|c| (c.param1, c.confirmation))
            .collect::<Vec<_>>(),
        [(116.0, 0)]
    );
}

/// A ground station's REQUEST_DATA_STREAM drops the IMU to 2 Hz: after a 2 s window under
/// half the rate asked for, the rates are asked for again; at the rate asked for, never.
#[test]
fn an_imu_stream_a_ground_station_slowed_is_asked_for_again() {
    let mut s = up(true);
    let ms = |k: u64| 10 + k * MS;
    // 100 Hz for 4 s: nothing asked.
    for k in 0..400 {
        s.on_message(ms(k * 10), &hdr(1, 1), &ap_heartbeat(true));
        s.on_message(ms(k * 10), &hdr(1, 1), &imu2([0, 0, -1000], [0; 3]));
        s.service(ms(k * 10));
    }
    assert!(
        commands(&s.drain_outgoing()).is_empty(),
        "asked again at 100 Hz"
    );
    // 2 Hz from then on: within the next two windows the IMU rate is asked for again.
    let mut asked = Vec::new();
    for k in 0..10 {
        let t = ms(4000 + k * 500);
        s.on_message(t, &hdr(1, 1), &ap_heartbeat(true));
        s.on_message(t, &hdr(1, 1), &imu2([0, 0, -1000], [0; 3]));
        s.service(t);
        asked.extend(
            commands(&s.drain_outgoing())
                .iter()
                .map(|c| (c.param1, c.param2)),
        );
    }
    assert_eq!(asked.first(), Some(&(116.0, 10_000.0)), "{asked:?}");
}

#[test]
fn the_supply_comes_from_the_autopilots_battery_reports_and_goes_stale() {
    use mavlink::dialects::ardupilotmega::{BATTERY_STATUS_DATA, SYS_STATUS_DATA};
    let mut s = up(true);
    assert_eq!(s.supply(10), Supply::default(), "nothing reported yet");
    let sys = |mv: u16, ca: i16| {
        MavMessage::SYS_STATUS(SYS_STATUS_DATA {
            voltage_battery: mv,
            current_battery: ca,
            ..SYS_STATUS_DATA::default()
        })
    };
    s.on_message(100, &hdr(AP.0, AP.1), &sys(15_600, 850));
    assert_eq!(
        s.supply(200),
        Supply {
            voltage_v: Some(15.6),
            current_a: Some(8.5)
        }
    );
    // Another system's battery is not ours; an unknown voltage keeps the last one.
    s.on_message(300, &hdr(7, 1), &sys(12_000, -1));
    s.on_message(300, &hdr(AP.0, AP.1), &sys(u16::MAX, -1));
    assert_eq!(s.supply(400).voltage_v, Some(15.6));
    // BATTERY_STATUS of monitor 0 counts once SYS_STATUS has said nothing for the stale
    // time (while it is fresh, its pack voltage wins: `battery::SupplyTracker`).
    let mut cells = [u16::MAX; 10];
    cells[0] = 14_900;
    let status = MavMessage::BATTERY_STATUS(BATTERY_STATUS_DATA {
        voltages: cells,
        current_battery: -1,
        ..BATTERY_STATUS_DATA::default()
    });
    s.on_message(500, &hdr(AP.0, AP.1), &status);
    assert_eq!(s.supply(600).voltage_v, Some(15.6));
    let later = 100 + SUPPLY_STALE_NS + 1;
    s.on_message(later, &hdr(AP.0, AP.1), &status);
    assert_eq!(
        s.supply(later),
        Supply {
            voltage_v: Some(14.9),
            current_a: None
        }
    );
    // Older than SUPPLY_STALE_NS: unknown.
    assert_eq!(s.supply(later + SUPPLY_STALE_NS + 1), Supply::default());
}

#[test]
fn imu_messages_become_si_readings_with_fresh_depth_only_while_up() {
    let mut s = Conversation::new(MavlinkConfig::default(), specs(), 0);
    // Before the link is up: dropped.
    s.on_message(1, &hdr(1, 1), &imu2([0, 0, -1000], [0, 0, 0]));
    assert_eq!(s.take_reading(), None);
    s.on_message(2, &hdr(1, 1), &ap_heartbeat(false));
    baros(&mut s, 2, NAVIGATOR);
    assert_eq!(
        s.counters().dropped_link_down,
        0,
        "before the target is known it is not even ours"
    );
    // From another system: ignored.
    s.on_message(3, &hdr(2, 1), &imu2([0, 0, -1000], [0, 0, 0]));
    assert_eq!(s.take_reading(), None);
    let p = 1013.25 + 2.0 * 997.0 * 9.80665 / 100.0;
    s.on_message(
        10 * MS,
        &hdr(1, 1),
        &MavMessage::SCALED_PRESSURE2(SCALED_PRESSURE2_DATA {
            press_abs: p as f32,
            ..SCALED_PRESSURE2_DATA::DEFAULT
        }),
    );
    s.on_message(
        20 * MS,
        &hdr(1, 1),
        &imu2([100, -200, -1000], [10, -20, 3000]),
    );
    let r = s.take_reading().unwrap();
    assert_eq!(r.t_ns, 20 * MS);
    assert_eq!(r.gyro, [0.01, -0.02, 3.0]);
    assert!((r.accel[2] + 9.80665).abs() < 1e-12);
    assert!((r.depth.unwrap() - 2.0).abs() < 1e-3, "{:?}", r.depth);
    assert_eq!(r.mag, None);
    // 600 ms later the depth is too old to attach.
    s.on_message(610 * MS, &hdr(1, 1), &imu2([0, 0, -1000], [0, 0, 0]));
    assert_eq!(s.take_reading().unwrap().depth, None);
}

#[test]
fn link_loss_stops_readings_and_recovery_requests_rates_again() {
    let mut s = up(true);
    let timeout = MavlinkConfig::default().link_timeout_ms * MS;
    s.on_message(timeout, &hdr(1, 1), &imu2([0, 0, -1000], [0, 0, 0]));
    s.service(timeout + 1);
    assert!(matches!(s.link(), LinkState::Down(_)));
    assert_eq!(
        s.take_reading(),
        None,
        "pending readings are dropped with the link"
    );
    s.on_message(timeout + 2, &hdr(1, 1), &imu2([0, 0, -1000], [0, 0, 0]));
    assert_eq!(s.take_reading(), None);
    assert!(
        s.next_deadline_ns() > timeout + 1,
        "no deadline stuck in the past"
    );
    s.on_message(timeout + 3, &hdr(1, 1), &ap_heartbeat(true));
    assert_eq!(s.link(), LinkState::Up);
    s.service(timeout + 4);
    let c = commands(&s.drain_outgoing());
    assert!(c
        .iter()
        .any(|c| c.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL));
    assert_eq!(s.counters().link_losses, 1);
}

#[test]
fn motor_tests_only_while_armed_at_once_on_change_and_resent() {
    let mut s = up(false);
    s.set_outputs(&[Pwm(1700), Pwm(1300)]);
    s.service(10 * MS);
    assert!(
        commands(&s.drain_outgoing()).is_empty(),
        "disarmed: no motor test"
    );
    s.on_message(11 * MS, &hdr(1, 1), &ap_heartbeat(true));
    s.service(12 * MS);
    let c = commands(&s.drain_outgoing());
    assert_eq!(c.len(), 2);
    // Channels 1 and 4 are ArduSub's motors 0 and 3 (0-based).
    for (c, (motor, pwm)) in c.iter().zip([(0.0, 1700.0), (3.0, 1300.0)]) {
        assert_eq!(c.command, MavCmd::MAV_CMD_DO_MOTOR_TEST);
        assert_eq!(
            [c.param1, c.param2, c.param3, c.param4, c.param5, c.param6],
            [motor, 1.0, pwm, 0.5, 0.0, 2.0]
        );
    }
    // Nothing new before the resend period...
    s.service(50 * MS);
    assert!(commands(&s.drain_outgoing()).is_empty());
    // ...a change goes out at once...
    s.set_outputs(&[Pwm(1500), Pwm(1300)]);
    s.service(60 * MS);
    assert_eq!(commands(&s.drain_outgoing())[0].param3, 1500.0);
    // ...and the same pulses again after resend_ms.
    assert_eq!(s.next_deadline_ns(), 160 * MS);
    s.service(160 * MS);
    assert_eq!(commands(&s.drain_outgoing()).len(), 2);
    // Refusals are counted.
    s.on_message(
        161 * MS,
        &hdr(1, 1),
        &ack(MavCmd::MAV_CMD_DO_MOTOR_TEST, MavResult::MAV_RESULT_FAILED),
    );
    assert_eq!(s.counters().motor_test_refused, 1);
    // Shutdown: neutral at once.
    s.set_outputs(&[Pwm(1900), Pwm(1900)]);
    s.shutdown(170 * MS);
    let c = commands(&s.drain_outgoing());
    assert_eq!(
        c.iter().map(|c| c.param3).collect::<Vec<_>>(),
        [1500.0, 1510.0]
    );
}

fn overrides(
    out: Vec<MavMessage>,
) -> Vec<mavlink::dialects::ardupilotmega::RC_CHANNELS_OVERRIDE_DATA> {
    out.into_iter()
        .filter_map(|m| match m {
            MavMessage::RC_CHANNELS_OVERRIDE(r) => Some(r),
            _ => None,
        })
        .collect()
}

/// The autopilot's answers: its pilot-input failsafe's action and timeout, RC_OVERRIDE_TIME,
/// and ArduSub's default RCMAP (2, 1, 3, 4, 5, 6) and trims (1500).
fn failsafe(s: &mut Conversation, t: u64, input: f32, timeout: f32) {
    s.on_message(t, &hdr(1, 1), &param("FS_PILOT_INPUT", input));
    s.on_message(t, &hdr(1, 1), &param("FS_PILOT_TIMEOUT", timeout));
    s.on_message(t, &hdr(1, 1), &param("RC_OVERRIDE_TIME", 3.0));
    for (axis, ch) in [
        ("ROLL", 2.0),
        ("PITCH", 1.0),
        ("THROTTLE", 3.0),
        ("YAW", 4.0),
        ("FORWARD", 5.0),
        ("LATERAL", 6.0),
    ] {
        s.on_message(t, &hdr(1, 1), &param(&format!("RCMAP_{axis}"), ch));
    }
    for n in 1..=6 {
        s.on_message(t, &hdr(1, 1), &param(&format!("RC{n}_TRIM"), 1500.0));
    }
    // Outputs n pass RC input n through (RCINn = 50 + n).
    for n in 1..=16 {
        let f = if n <= 8 { 50.0 + n as f32 } else { 0.0 };
        s.on_message(t, &hdr(1, 1), &param(&format!("SERVO{n}_FUNCTION"), f));
    }
}

#[test]
fn rc_override_sets_our_channels_and_ignores_the_rest() {
    let cfg = MavlinkConfig {
        output: OutputMode::RcOverride,
        ..MavlinkConfig::default()
    };
    let mut s = Conversation::new(cfg, specs(), 0);
    s.on_message(1, &hdr(1, 1), &ap_heartbeat(false));
    failsafe(&mut s, 2, 2.0, 0.5);
    s.set_outputs(&[Pwm(1600), Pwm(1400)]);
    s.service(2);
    let rc = overrides(s.drain_outgoing());
    assert_eq!(rc.len(), 1, "sent even while disarmed");
    let r = &rc[0];
    assert_eq!((r.chan1_raw, r.chan4_raw), (1600, 1400));
    assert_eq!(
        (r.chan2_raw, r.chan3_raw, r.chan8_raw),
        (RC_IGNORE, RC_IGNORE, RC_IGNORE)
    );
    assert_eq!((r.target_system, r.target_component), (1, 1));
}

/// The pilot-input failsafe and RC_OVERRIDE_TIME are asked for at link-up; overrides carry
/// neutral until they are known and say our last override is taken back soon, and again when
/// a re-read finds otherwise; a new link asks again.
#[test]
fn rc_overrides_carry_thrust_only_while_the_autopilot_would_take_a_left_one_back_soon() {
    let cfg = MavlinkConfig {
        output: OutputMode::RcOverride,
        ..MavlinkConfig::default()
    };
    let mut s = Conversation::new(cfg, specs(), 0);
    s.on_message(1, &hdr(1, 1), &ap_heartbeat(true));
    s.set_outputs(&[Pwm(1600), Pwm(1400)]);
    s.service(2);
    let out = s.drain_outgoing();
    // Every reader's names, in the order the conversation serves them: the override check's
    // (rc_override mode only), the barometers', the battery monitor's.
    let readers = crate::backend::mavlink::override_hold::PARAMS
        .iter()
        .chain(&crate::backend::mavlink::water_baro::PARAMS)
        .chain(&[crate::backend::mavlink::battery::BATT_OPTIONS]);
    assert_eq!(asked(&out), readers.copied().collect::<Vec<_>>(), "{out:?}");
    assert_eq!(asked(&out).len(), 35);
    let rc = overrides(out);
    assert_eq!(
        (rc[0].chan1_raw, rc[0].chan4_raw),
        (1500, 1510),
        "thrust before the failsafe is known"
    );
    assert!(s.held().unwrap().contains("waiting"), "{:?}", s.held());
    // ArduSub's defaults: the failsafe 3 s after our last override. Refused.
    failsafe(&mut s, 3, 2.0, 3.0);
    s.service(4);
    let rc = overrides(s.drain_outgoing());
    assert_eq!((rc[0].chan1_raw, rc[0].chan4_raw), (1500, 1510));
    assert!(s.held().unwrap().contains("outlive us 3 s"));
    // Set short from the ground station, seen at the re-read: thrust.
    s.on_message(5, &hdr(1, 1), &param("FS_PILOT_TIMEOUT", 0.5));
    s.service(6);
    let rc = overrides(s.drain_outgoing());
    assert_eq!((rc[0].chan1_raw, rc[0].chan4_raw), (1600, 1400));
    assert_eq!(s.held(), None);
    // The failsafe turned off: nothing would take a left override back. Neutral at once.
    s.on_message(7, &hdr(1, 1), &param("FS_PILOT_INPUT", 0.0));
    s.service(8);
    let rc = overrides(s.drain_outgoing());
    assert_eq!((rc[0].chan1_raw, rc[0].chan4_raw), (1500, 1510));
    assert!(s.held().unwrap().contains("nothing neutralises"));
    // A lost link forgets it; the next link-up asks again.
    s.on_message(9, &hdr(1, 1), &param("FS_PILOT_INPUT", 2.0));
    s.on_disconnect("test");
    assert_eq!(s.held(), None, "no link: the link state says it");
    s.on_message(10, &hdr(1, 1), &ap_heartbeat(true));
    assert!(s.held().unwrap().contains("waiting"));
    s.service(11);
    assert!(asked(&s.drain_outgoing()).contains(&"FS_PILOT_INPUT".to_string()));
}

/// Motor tests never ask for the failsafe: it does not concern them. The barometers and the
/// battery monitor's options are asked for in every mode.
#[test]
fn motor_tests_do_not_ask_for_the_override_hold() {
    let mut s = Conversation::new(MavlinkConfig::default(), specs(), 0);
    s.on_message(1, &hdr(1, 1), &ap_heartbeat(true));
    s.service(2);
    assert_eq!(
        asked(&s.drain_outgoing()),
        ["BARO1_DEVID", "BARO2_DEVID", "BARO3_DEVID", "BATT_OPTIONS"]
    );
    assert_eq!(s.held(), None);
}

/// Depth only from the barometer the autopilot says is in the water: SCALED_PRESSURE2 on a
/// Navigator; on a Cube the second barometer is the tube's air (depth about 0 at any depth)
/// and the Bar30 is the third, which ArduSub reports in no message: no depth.
#[test]
fn depth_comes_only_from_the_barometer_in_the_water() {
    let p2m = 1013.25 + 2.0 * 997.0 * 9.80665 / 100.0;
    let pressures = |s: &mut Conversation, t: u64| {
        s.on_message(
            t,
            &hdr(1, 1),
            &MavMessage::SCALED_PRESSURE(SCALED_PRESSURE_DATA {
                press_abs: 1013.0,
                ..SCALED_PRESSURE_DATA::DEFAULT
            }),
        );
        s.on_message(
            t,
            &hdr(1, 1),
            &MavMessage::SCALED_PRESSURE2(SCALED_PRESSURE2_DATA {
                press_abs: p2m as f32,
                ..SCALED_PRESSURE2_DATA::DEFAULT
            }),
        );
        s.on_message(t + 1, &hdr(1, 1), &imu2([0, 0, -1000], [0, 0, 0]));
        s.take_reading().unwrap().depth
    };
    for (ids, want) in [(NAVIGATOR, Some(2.0)), (CUBE, None)] {
        let mut s = Conversation::new(MavlinkConfig::default(), specs(), 0);
        s.on_message(1, &hdr(1, 1), &ap_heartbeat(false));
        assert_eq!(pressures(&mut s, 10), None, "before the ids came");
        baros(&mut s, 20, ids);
        let depth = pressures(&mut s, 30);
        assert_eq!(depth.is_some(), want.is_some(), "{ids:?}: {depth:?}");
        if let (Some(d), Some(w)) = (depth, want) {
            assert!((d - w).abs() < 1e-3, "{d}");
        }
    }
    // Named, SCALED_PRESSURE2 is used until the autopilot says it is an air barometer.
    let cfg = MavlinkConfig {
        pressure_message: crate::config::PressureMessage::ScaledPressure2,
        ..MavlinkConfig::default()
    };
    let mut s = Conversation::new(cfg, specs(), 0);
    s.on_message(1, &hdr(1, 1), &ap_heartbeat(false));
    assert!(pressures(&mut s, 10).is_some(), "unverified, used");
    baros(&mut s, 20, CUBE);
    assert_eq!(pressures(&mut s, 30), None);
}

#[test]
fn arming_is_requested_and_undone_when_configured() {
    let cfg = MavlinkConfig {
        arm: true,
        attitude_rate_hz: 0.0,
        pressure_rate_hz: 0.0,
        ..MavlinkConfig::default()
    };
    let mut s = Conversation::new(cfg, specs(), 0);
    s.on_message(1, &hdr(1, 1), &ap_heartbeat(false));
    s.service(2);
    s.on_message(
        3,
        &hdr(1, 1),
        &ack(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    let c = commands(&s.drain_outgoing());
    assert_eq!(
        (c.last().unwrap().command, c.last().unwrap().param1),
        (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    );
    s.on_message(
        4,
        &hdr(1, 1),
        &ack(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    assert!(s.armed_by_us());
    s.shutdown(5);
    let c = commands(&s.drain_outgoing());
    assert_eq!(
        (c.last().unwrap().command, c.last().unwrap().param1),
        (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 0.0)
    );
}
#[test]
fn motor_test_param1_is_ardusubs_zero_based_motor_index() {
    assert_eq!(ardusub_motor_index(1), 0.0);
    assert_eq!(ardusub_motor_index(8), 7.0);
    let m = motor_test(1, 1, 8, Pwm(1600), 0.5);
    let MavMessage::COMMAND_LONG(c) = m else {
        panic!("{m:?}")
    };
    assert_eq!((c.param1, c.param3), (7.0, 1600.0));
}

#[test]
fn no_motor_tests_while_there_is_nothing_to_command() {
    let mut s = up(true);
    // Armed, link up, outputs neutral: motor-test mode would bypass the pilot and
    // disarm the vehicle after we stop, so nothing goes out.
    for t in 1..=10 {
        s.service(t * 100 * MS);
    }
    assert!(commands(&s.drain_outgoing()).is_empty());
    assert!(!s.engaged());
    // A shutdown with nothing of ours on the outputs sends nothing either.
    let mut quiet = up(true);
    quiet.shutdown(5 * MS);
    assert!(commands(&quiet.drain_outgoing()).is_empty());
    // The first real pulse starts them; neutral then keeps going out.
    s.set_outputs(&[Pwm(1600), Pwm(1510)]);
    s.service(1100 * MS);
    assert_eq!(commands(&s.drain_outgoing()).len(), 2);
    assert!(s.engaged());
    s.set_outputs(&[Pwm(1500), Pwm(1510)]);
    s.service(1110 * MS);
    s.service(1210 * MS);
    let c = commands(&s.drain_outgoing());
    assert_eq!(c.len(), 4);
    assert!(c.iter().all(|c| c.param3 == 1500.0 || c.param3 == 1510.0));
}

#[test]
fn heartbeat_loss_with_imu_flowing_ends_in_a_neutral_round() {
    let mut s = up(true);
    s.set_outputs(&[Pwm(1750), Pwm(1300)]);
    s.service(10 * MS);
    s.drain_outgoing();
    let timeout = MavlinkConfig::default().link_timeout_ms * MS;
    // IMU keeps coming, HEARTBEATs do not.
    let mut t = 20 * MS;
    let mut sent = Vec::new();
    while t <= timeout + 200 * MS {
        s.on_message(t, &hdr(1, 1), &imu2([0, 0, -1000], [0, 0, 0]));
        s.service(t);
        sent.extend(commands(&s.drain_outgoing()));
        t += 10 * MS;
    }
    assert!(matches!(s.link(), LinkState::Down(_)));
    let last: Vec<f32> = sent[sent.len() - 2..].iter().map(|c| c.param3).collect();
    assert_eq!(last, [1500.0, 1510.0], "the last motor tests are neutral");
    // Nothing more while down, whatever the loop asks.
    s.set_outputs(&[Pwm(1900), Pwm(1900)]);
    s.service(t + 500 * MS);
    assert!(commands(&s.drain_outgoing()).is_empty());
}

#[test]
fn a_vehicle_disarmed_from_the_start_is_known_as_such() {
    let mut s = Conversation::new(MavlinkConfig::default(), specs(), 0);
    assert_eq!(s.armed_state(), None);
    s.on_message(1, &hdr(1, 1), &ap_heartbeat(false));
    assert_eq!(s.armed_state(), Some(false));
    s.on_message(2, &hdr(1, 1), &ap_heartbeat(true));
    assert_eq!(s.armed_state(), Some(true));
}

#[test]
fn implausible_imu_readings_are_dropped_and_counted() {
    let cfg = MavlinkConfig {
        imu_message: ImuMessage::RawImu,
        ..MavlinkConfig::default()
    };
    let mut s = Conversation::new(cfg, specs(), 0);
    s.on_message(1, &hdr(1, 1), &ap_heartbeat(true));
    let raw = |z: i16, mag: [i16; 3]| {
        MavMessage::RAW_IMU(RAW_IMU_DATA {
            zacc: z,
            xmag: mag[0],
            ymag: mag[1],
            zmag: mag[2],
            ..RAW_IMU_DATA::DEFAULT
        })
    };
    // ADC counts (1 g = 4096) are not mG.
    s.on_message(2, &hdr(1, 1), &raw(-4096, [0; 3]));
    assert_eq!(s.take_reading(), None);
    assert_eq!(s.counters().imu_implausible, 1);
    s.on_message(3, &hdr(1, 1), &raw(-1000, [30000, 0, 0]));
    let r = s.take_reading().unwrap();
    assert!((r.accel[2] + 9.80665).abs() < 1e-9);
    assert_eq!(r.mag, None, "an implausible magnetometer is dropped alone");
    assert_eq!(s.counters().mag_implausible, 1);
}

/// A ground station's joystick overrides RC channels 1-8 too (ArduSub turns its
/// MANUAL_CONTROL into overrides): once RC_CHANNELS shows another sender's values on our
/// channels for three settled reports, our overrides stop and `held` says why, until the link
/// restarts.
#[test]
fn another_sender_on_our_rc_channels_stops_our_overrides() {
    use mavlink::dialects::ardupilotmega::RC_CHANNELS_DATA;
    let cfg = MavlinkConfig {
        output: OutputMode::RcOverride,
        ..MavlinkConfig::default()
    };
    let mut s = Conversation::new(cfg, specs(), 0);
    s.on_message(1, &hdr(1, 1), &ap_heartbeat(true));
    failsafe(&mut s, 2, 2.0, 0.5);
    s.service(2);
    // RC_CHANNELS asked for at 10 Hz in this mode, after the IMU and ATTITUDE.
    let mut asked = Vec::new();
    for t in 3..8 {
        asked.extend(
            commands(&s.drain_outgoing())
                .iter()
                .map(|c| (c.param1, c.param2)),
        );
        s.on_message(
            t,
            &hdr(1, 1),
            &ack(
                MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                MavResult::MAV_RESULT_ACCEPTED,
            ),
        );
    }
    assert!(asked.contains(&(65.0, 100_000.0)), "{asked:?}");
    let applied = |ch1: u16, ch4: u16| {
        MavMessage::RC_CHANNELS(RC_CHANNELS_DATA {
            chan1_raw: ch1,
            chan4_raw: ch4,
            chancount: 8,
            ..RC_CHANNELS_DATA::default()
        })
    };
    s.set_outputs(&[Pwm(1600), Pwm(1400)]);
    s.service(10 * MS);
    assert_eq!(overrides(s.drain_outgoing()).len(), 1);
    // Ours applied: nothing happens.
    for k in 0..5 {
        s.on_message(300 * MS + k * 100 * MS, &hdr(1, 1), &applied(1600, 1400));
    }
    assert_eq!(s.held(), None);
    // The joystick's idle stick on every channel, three reports in a row.
    for k in 0..3 {
        s.on_message(800 * MS + k * 100 * MS, &hdr(1, 1), &applied(1500, 1500));
    }
    let why = s.held().expect("a fight");
    assert!(why.contains("another sender overrides"), "{why}");
    s.service(1_200 * MS);
    assert!(overrides(s.drain_outgoing()).is_empty(), "ours stopped");
    // A new link judges again.
    s.on_disconnect("test");
    s.on_message(2 * 1_000 * MS, &hdr(1, 1), &ap_heartbeat(true));
    failsafe(&mut s, 2 * 1_000 * MS, 2.0, 0.5);
    assert_eq!(s.held(), None);
}
