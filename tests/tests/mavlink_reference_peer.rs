//! thruster-hw's MAVLink against a peer we did not write: an ArduSub stand-in written with
//! pymavlink, MAVLink's reference implementation (`tests/python/ardusub_peer.py`, installed
//! by the tests into their venv from tests/python/requirements.txt). Our own fake autopilot
//! (`hw-driver/tests/common/fake_autopilot.rs`) is built on the same `mavlink` crate as the
//! driver, so a mistake both share (a field's order, a CRC extra, a string's padding) would
//! pass there; here every message is encoded or decoded by other code.
//!
//! The whole chain runs: thrusterd (realtime) <- iceoryx2 -> thruster-hw (mavlink backend,
//! udpin) <- UDP -> the pymavlink peer. No real ArduSub or SITL can run on this machine
//! (docs/hardware.md).

use std::process::{Child, Command, Stdio};
use std::time::Duration;

use serde_json::Value;
use system_tests::{python, state, Operator, Proc, World};
use thruster_protocol::{DaemonState, RequestKind};

const LONG: Duration = Duration::from_secs(30);
const THRUSTERS: usize = 5;

fn free_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn hw_config(namespace: &str, port: u16, output: &str) -> String {
    let mut cfg = format!(
        "namespace = \"{namespace}\"\nbackend = \"mavlink\"\nwatchdog_ms = 200\n\
         arming_ms = 200\nstatus_period_ms = 1000\n"
    );
    for ch in 1..=THRUSTERS {
        cfg += &format!("[[thruster]]\nchannel = {ch}\n");
    }
    cfg += &format!(
        "[mavlink]\naddress = \"udpin:127.0.0.1:{port}\"\noutput = \"{output}\"\n\
         max_override_hold_s = 1.0\n"
    );
    cfg
}

fn peer(port: u16, seconds: f64, params: &[&str]) -> Child {
    Command::new(python::venv_python())
        .arg(system_tests::workspace().join("tests/python/ardusub_peer.py"))
        .args(["--port", &port.to_string()])
        .args(["--seconds", &seconds.to_string()])
        .args(params.iter().flat_map(|p| ["--param", p]))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("starting the pymavlink peer")
}

fn peer_report(child: Child) -> Value {
    let out = child
        .wait_with_output()
        .expect("the pymavlink peer's output");
    assert!(
        out.status.success(),
        "pymavlink peer failed: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("peer's JSON: {e}\n{}", String::from_utf8_lossy(&out.stdout)))
}

/// Runs thrusterd and thruster-hw (`output`) against the peer for `seconds` and asks the
/// daemon to estimate once it has samples: its pulses are the thrust that goes out, when
/// `expect_pulses`; otherwise the daemon is to refuse, its status saying the driver holds
/// the outputs neutral. `params`: the peer's parameters, `NAME=VALUE`.
/// Returns the peer's report, the daemon's supply voltage, samples, and that status text.
fn session(
    name: &str,
    output: &str,
    params: &[&str],
    seconds: f64,
    expect_pulses: bool,
) -> (Value, f64, u64, String) {
    let world = World::new(name);
    let op = Operator::new(&world);
    let port = free_port();
    let hw_cfg = world.path("thruster-hw.toml");
    std::fs::write(&hw_cfg, hw_config(&world.namespace(), port, output)).unwrap();
    let mut hw = Proc::spawn(
        "thruster-hw",
        &["run", "--config", hw_cfg.to_str().unwrap()],
        world.dir.path(),
    );
    let mut daemon = world.daemon(&["--thrusters", &THRUSTERS.to_string()]);
    let child = peer(port, seconds, params);
    let ready = op
        .wait_status(LONG, |s| s.samples > 200)
        .unwrap_or_else(|| {
            panic!(
                "no samples through the pymavlink peer\n{}\n{}",
                daemon.log_text(),
                hw.log_text()
            )
        });
    let answer = op.request(RequestKind::Estimate);
    println!("estimate: {answer:?}");
    let voltage = op
        .wait_status(LONG, |s| s.supply_voltage_v.is_finite())
        .map_or(f64::NAN, |s| s.supply_voltage_v);
    let text = if expect_pulses {
        let pulsing = op.wait_status(LONG, |s| state(s) == DaemonState::Pulse);
        assert!(pulsing.is_some(), "never pulsed\n{}", daemon.log_text());
        String::new()
    } else {
        op.wait_status(LONG, |s| s.text().contains("outputs held neutral"))
            .unwrap_or_else(|| panic!("no reason in status\n{}", daemon.log_text()))
            .text()
            .to_string()
    };
    let report = peer_report(child);
    daemon.stop();
    hw.stop();
    drop(op);
    world.assert_nothing_left();
    (report, voltage, ready.samples, text)
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

#[test]
fn motor_tests_heartbeats_and_requests_are_what_pymavlink_reads_and_its_imu_and_battery_reach_the_daemon(
) {
    let (r, voltage, samples, _) = session("pymav", "motor_test", &[], 14.0, true);
    println!("{r}");
    assert_eq!(r["bad_data"], 0, "messages pymavlink could not parse: {r}");
    // Our HEARTBEAT: 255/191, an onboard controller (18), autopilot INVALID (8).
    assert_eq!(
        r["heartbeats"],
        serde_json::json!([[255, 191, 18, 8]]),
        "{r}"
    );
    // Message rates: SCALED_IMU2 100 Hz, ATTITUDE 50 Hz, SCALED_PRESSURE2 20 Hz (the Bar30's,
    // from the barometer ids pymavlink sent).
    let iv = &r["intervals"];
    assert_eq!(
        (f(&iv["116"]), f(&iv["30"]), f(&iv["137"])),
        (10_000.0, 20_000.0, 50_000.0),
        "{r}"
    );
    // In motor-test mode only the barometers' ids and the battery monitor's options are
    // asked for (SCALED_PRESSURE2's rate above was asked once pymavlink's BARO2_DEVID said it
    // is the Bar30).
    let names: Vec<&str> = r["param_requests"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|a| a[0].as_str())
        .collect();
    assert!(
        names
            .iter()
            .all(|n| ["BARO1_DEVID", "BARO2_DEVID", "BARO3_DEVID", "BATT_OPTIONS"].contains(n))
            && names.contains(&"BARO2_DEVID"),
        "{r}"
    );
    // The daemon's pulses as DO_MOTOR_TEST: motors 0-4 (0-based), PWM throttle type (1),
    // board order (2), addressed to the peer (1/1), pulses within the ESC's range and some
    // away from neutral.
    let tests = r["motor_tests"].as_array().unwrap();
    assert!(tests.len() > 50, "{} motor tests", tests.len());
    let mut motors = [false; THRUSTERS];
    let mut moved = 0;
    for t in tests {
        let p: Vec<f64> = t.as_array().unwrap().iter().map(f).collect();
        let motor = p[0] as usize;
        assert!(motor < THRUSTERS && p[0].fract() == 0.0, "motor {t}");
        motors[motor] = true;
        assert_eq!((p[1], p[4], p[5], p[6]), (1.0, 2.0, 1.0, 1.0), "{t}");
        assert!((1100.0..=1900.0).contains(&p[2]), "pulse {t}");
        if p[2] != 1500.0 {
            moved += 1;
        }
    }
    assert!(motors.iter().all(|m| *m), "motors reached {motors:?}");
    assert!(moved > 10, "only {moved} motor tests away from neutral");
    // pymavlink's SCALED_IMU2 stream became the daemon's samples, its SYS_STATUS the supply.
    assert!(samples > 200, "{samples} samples");
    assert!((voltage - 15.8).abs() < 1e-9, "supply {voltage} V");
}

/// The RC override check against PARAM_VALUEs pymavlink encoded: with FS_PILOT_TIMEOUT 0.5
/// s the daemon's thrust goes out as RC_CHANNELS_OVERRIDE; with ArduSub's default 3 s every
/// override stays neutral, and the daemon refuses to estimate with the driver's reason in its
/// status.
#[test]
fn the_pilot_input_failsafe_read_from_pymavlink_gates_the_overrides() {
    for (timeout, thrust_expected) in [
        ("FS_PILOT_TIMEOUT=0.5", true),
        ("FS_PILOT_TIMEOUT=3", false),
    ] {
        let (r, _, _, text) = session("pymavrc", "rc_override", &[timeout], 12.0, thrust_expected);
        assert_eq!(r["bad_data"], 0, "{r}");
        let asked = r["param_requests"].as_array().unwrap();
        for p in ["FS_PILOT_INPUT", "FS_PILOT_TIMEOUT", "RC_OVERRIDE_TIME"] {
            assert!(asked.iter().any(|a| a[0] == p && a[1] == -1), "{p}: {r}");
        }
        let overrides = r["overrides"].as_array().unwrap();
        assert!(overrides.len() > 20, "{} overrides", overrides.len());
        // pymavlink's RC_CHANNELS (what it applied: our overrides) were asked for at 10 Hz
        // and read as ours: no fight was called (the thrust below went on).
        assert_eq!(f(&r["intervals"]["65"]), 100_000.0, "{r}");
        assert!(f(&r["rc_channels_sent"]) > 20.0, "{r}");
        let moved = overrides
            .iter()
            .filter(|o| (0..THRUSTERS).any(|i| f(&o[i]) != 1500.0))
            .count();
        for o in overrides {
            let unused = &o.as_array().unwrap()[THRUSTERS..];
            assert!(unused.iter().all(|c| c == 65535), "unused channels: {o}");
        }
        if thrust_expected {
            assert!(moved > 10, "{timeout}: {moved} with thrust");
        } else {
            assert_eq!(moved, 0, "{timeout}: thrust went out");
            assert!(
                text.contains("outputs held neutral: FS_PILOT_TIMEOUT = 3 s"),
                "{text}"
            );
        }
        assert!(r["motor_tests"].as_array().unwrap().is_empty(), "{r}");
    }
}
