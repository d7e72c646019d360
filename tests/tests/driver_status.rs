//! What the daemon knows of its driver, with the real processes: a driver that cannot take
//! the daemon's commands (another thruster count) faults the daemon, neutral, instead of
//! letting it pulse into nothing; a daemon with no driver at all refuses to estimate and says
//! why; the operator sees the driver's own report.

// The hardware driver's fake ArduSub (heartbeats armed or not, IMU stream, motor tests),
// used as is rather than copied.
#[allow(dead_code)]
#[path = "../../hw-driver/tests/common/fake_autopilot.rs"]
mod fake_autopilot;

use std::process::Command;
use std::time::Duration;

use serde_json::Value;
use system_tests::{bin, state, Operator, Proc, World};
use thruster_protocol::services::Inbox;
use thruster_protocol::{
    DaemonState, DriverStatusMsg, OutputState, ReconfigEvent, ReconfigKind, RequestKind,
};

const LONG: Duration = Duration::from_secs(60);

/// thrusterd (with `daemon_args`) and a lockstep, noise-free AMOUR-5 (5 thrusters).
fn daemon_and_sim(world: &World, daemon_args: &[&str]) -> (Proc, Proc) {
    let mut args = daemon_args.to_vec();
    args.push("--lockstep");
    let daemon = world.daemon(&args);
    let sim = world.sim(
        "amour5",
        &["--noise", "none", "--lockstep", "--duration", "100000"],
    );
    (daemon, sim)
}

/// The daemon controlling with its first estimated model.
fn until_active(op: &Operator, daemon: &Proc) {
    op.wait_status(LONG, |s| {
        state(s) == DaemonState::Active && s.model_version >= 1
    })
    .unwrap_or_else(|| panic!("no model\n{}", daemon.log_text()));
}

#[test]
fn a_daemon_for_six_thrusters_on_a_five_thruster_driver_faults_and_never_pulses() {
    let world = World::new("drvcount");
    {
        let op = Operator::new(&world);
        let driver: Inbox<DriverStatusMsg> = Inbox::create(world.node(), world.ipc()).unwrap();
        let (mut daemon, mut sim) = daemon_and_sim(&world, &["--thrusters", "6", "--estimate"]);
        let s = op
            .wait_status(LONG, |s| {
                state(s) == DaemonState::Fault
                    && s.text()
                        .contains("thruster-sim drives 5 thrusters, the daemon 6")
            })
            .unwrap_or_else(|| panic!("no fault on the count mismatch\n{}", daemon.log_text()));
        assert_eq!(
            s.pulse, 0,
            "pulsed into a driver that rejects every command"
        );
        // It stays there: good IMU samples alone do not clear it.
        std::thread::sleep(Duration::from_millis(500));
        let r = op.request(RequestKind::Estimate);
        assert!(!r.is_ok(), "an estimation started: {}", r.text());
        assert!(r.text().contains("fault"), "{}", r.text());
        let s = op
            .wait_status(Duration::from_secs(5), |_| true)
            .expect("a status");
        assert_eq!(state(&s), DaemonState::Fault, "{}", s.text());
        assert_eq!(s.pulse, 0);
        // The driver's own report says the same, for anyone to read.
        let report =
            system_tests::wait_for(&driver, Duration::from_secs(5), |d| d.commands_rejected > 0)
                .expect("the driver reports its rejections");
        assert_eq!(report.thruster_count, 5);
        assert_eq!(report.driver(), "thruster-sim");
        assert!(report.text().contains("count"), "{}", report.text());
        // And the operator tool shows it.
        let out = Command::new(bin("thrusterctl"))
            .args(["--namespace", &world.namespace(), "status", "--json"])
            .output()
            .unwrap();
        assert!(out.status.success(), "{out:?}");
        let v: Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v["state"], "Fault", "{v}");
        assert_eq!(v["driver"]["thruster_count"], 5, "{v}");
        assert_eq!(v["driver"]["driver"], "thruster-sim", "{v}");
        assert!(
            v["driver"]["commands_rejected"].as_u64().unwrap() > 0,
            "{v}"
        );
        assert!(daemon.stop().success(), "{}", daemon.log_text());
        assert!(sim.stop().success(), "{}", sim.log_text());
        assert!(
            daemon.log_text().contains("driver outputs unusable"),
            "{}",
            daemon.log_text()
        );
    }
    world.assert_nothing_left();
}

#[test]
fn reconfigured_to_a_count_the_driver_lacks_while_controlling_faults_neutral() {
    let world = World::new("drvreconf");
    {
        let op = Operator::new(&world);
        let reconfig =
            thruster_protocol::services::Port::<ReconfigEvent>::create(world.node(), world.ipc())
                .unwrap();
        let (mut daemon, mut sim) = daemon_and_sim(&world, &["--estimate"]);
        until_active(&op, &daemon);
        let mut e = ReconfigEvent {
            seq: 1,
            thruster: 5,
            count: 6,
            ..Default::default()
        };
        e.set_kind(ReconfigKind::ThrusterAdded);
        reconfig.send(&e).unwrap();
        let s = op
            .wait_status(LONG, |s| state(s) == DaemonState::Fault)
            .unwrap_or_else(|| panic!("no fault\n{}", daemon.log_text()));
        assert!(
            s.text().contains("drives 5 thrusters, the daemon 6"),
            "{}",
            s.text()
        );
        // No estimation runs on: for a second no status shows a pulse, and it is still in
        // fault at the end.
        let mut states = Vec::new();
        let end = std::time::Instant::now() + Duration::from_secs(1);
        while std::time::Instant::now() < end {
            while let Some(s) = op.status.recv().unwrap() {
                states.push(state(&s));
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(
            !states.contains(&DaemonState::Pulse),
            "pulsed into a driver that rejects every command: {states:?}"
        );
        let s = op
            .wait_status(Duration::from_secs(5), |_| true)
            .expect("a status");
        assert_eq!(state(&s), DaemonState::Fault, "{}", s.text());
        assert!(daemon.stop().success(), "{}", daemon.log_text());
        assert!(sim.stop().success(), "{}", sim.log_text());
    }
    world.assert_nothing_left();
}

#[test]
fn with_no_driver_an_estimate_is_refused_and_status_says_why() {
    let world = World::new("drvnone");
    {
        let op = Operator::new(&world);
        let mut daemon = world.daemon(&[]);
        op.wait_status(Duration::from_secs(30), |_| true)
            .expect("a status");
        let r = op.request(RequestKind::Estimate);
        assert!(!r.is_ok(), "an estimation started with no IMU");
        assert!(
            r.text().contains("no IMU samples from any driver"),
            "{}",
            r.text()
        );
        let r = op.request(RequestKind::Hold);
        assert!(!r.is_ok());
        let s = op
            .wait_status(Duration::from_secs(10), |s| {
                s.text().contains("no IMU samples from any driver for")
            })
            .unwrap_or_else(|| panic!("status does not say it\n{}", daemon.log_text()));
        assert_eq!(state(&s), DaemonState::Idle);
        assert_eq!(s.samples, 0);
        assert!(daemon.stop().success(), "{}", daemon.log_text());
    }
    world.assert_nothing_left();
}

#[test]
fn the_simulators_report_counts_what_it_accepted() {
    // A driver that takes every command reports outputs active, link up, nothing rejected.
    let world = World::new("drvok");
    {
        let op = Operator::new(&world);
        let driver: Inbox<DriverStatusMsg> = Inbox::create(world.node(), world.ipc()).unwrap();
        let (mut daemon, mut sim) = daemon_and_sim(&world, &["--estimate"]);
        until_active(&op, &daemon);
        // However long the estimation takes, holding attitude afterwards adds 200 a second.
        let report = system_tests::wait_for(&driver, Duration::from_secs(5), |d| {
            d.output_state() == Ok(OutputState::Active) && d.commands_accepted > 1000
        })
        .expect("an active report with more than 1000 commands");
        assert_eq!(report.commands_rejected, 0, "{}", report.text());
        assert!(report.commands_accepted > 1000, "{report:?}");
        assert_eq!((report.link_up, report.armed), (1, 1));
        assert!(daemon.stop().success(), "{}", daemon.log_text());
        assert!(sim.stop().success(), "{}", sim.log_text());
    }
    world.assert_nothing_left();
}

/// thruster-hw on an ArduSub that is disarmed: the driver says so, and the daemon does not
/// pulse into a vehicle that cannot move (it faults, neutral, with the reason); once the
/// autopilot is armed, the interrupted estimation runs and its pulses reach the motors.
#[test]
fn a_disarmed_autopilot_holds_the_estimation_until_it_is_armed() {
    let world = World::new("drvarm");
    {
        let op = Operator::new(&world);
        let fake = fake_autopilot::FakeAutopilot::start();
        fake.with(|s| s.armed = false);
        let config = world.path("thruster-hw.toml");
        std::fs::write(
            &config,
            format!(
                "namespace = \"{}\"\nbackend = \"mavlink\"\nwatchdog_ms = 200\narming_ms = 100\n\
                 [[thruster]]\nchannel = 1\n[[thruster]]\nchannel = 2\n\
                 [[thruster]]\nchannel = 3\n[[thruster]]\nchannel = 4\n\
                 [mavlink]\naddress = \"{}\"\nimu_rate_hz = 100.0\n",
                world.namespace(),
                fake.address()
            ),
        )
        .unwrap();
        let mut hw = Proc::spawn(
            "thruster-hw",
            &["run", "--config", config.to_str().unwrap()],
            world.dir.path(),
        );
        let mut daemon = world.daemon(&["--thrusters", "4", "--estimate"]);
        let s = op
            .wait_status(LONG, |s| {
                state(s) == DaemonState::Fault && s.text().contains("disarmed")
            })
            .unwrap_or_else(|| {
                panic!(
                    "no fault on a disarmed autopilot\n{}\n{}",
                    daemon.log_text(),
                    hw.log_text()
                )
            });
        assert!(s.text().contains("thruster-hw mavlink"), "{}", s.text());
        std::thread::sleep(Duration::from_millis(500));
        assert!(
            fake.with(|s| s.motor_tests()).is_empty(),
            "motor tests sent to a disarmed autopilot"
        );
        let s = op
            .wait_status(Duration::from_secs(5), |_| true)
            .expect("a status");
        assert_eq!(state(&s), DaemonState::Fault, "{}", s.text());
        // Armed: the estimation runs and its pulses reach the motors.
        fake.with(|s| s.armed = true);
        op.wait_status(LONG, |s| state(s) == DaemonState::Pulse)
            .unwrap_or_else(|| panic!("no pulse once armed\n{}", daemon.log_text()));
        let deadline = std::time::Instant::now() + Duration::from_secs(10);
        while fake.with(|s| s.motor_tests()).is_empty() {
            assert!(
                std::time::Instant::now() < deadline,
                "no motor test once armed\n{}",
                hw.log_text()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        assert!(daemon.stop().success(), "{}", daemon.log_text());
        assert!(hw.stop().success(), "{}", hw.log_text());
    }
    world.assert_nothing_left();
}

/// A simulated battery's voltage reaches the daemon through the driver's report: its status
/// carries it with commands referred to the reference voltage, and the operator sees both the
/// daemon's and the driver's figures. A vehicle without a battery reports no voltage, and the
/// daemon says it does not compensate.
#[test]
fn the_supply_voltage_reaches_the_daemon_and_the_operator() {
    for (vehicle, battery) in [("amour5_t200", true), ("amour5", false)] {
        let world = World::new("drvbat");
        {
            let op = Operator::new(&world);
            let mut daemon = world.daemon(&["--lockstep"]);
            let mut sim = world.sim(
                vehicle,
                &["--noise", "none", "--lockstep", "--duration", "100000"],
            );
            let s = op
                .wait_status(LONG, |s| s.samples > 200)
                .unwrap_or_else(|| panic!("no status\n{}", daemon.log_text()));
            let out = Command::new(bin("thrusterctl"))
                .args(["--namespace", &world.namespace(), "status", "--json"])
                .output()
                .unwrap();
            assert!(out.status.success(), "{out:?}");
            let v: Value = serde_json::from_slice(&out.stdout).unwrap();
            let text = Command::new(bin("thrusterctl"))
                .args(["--namespace", &world.namespace(), "status"])
                .output()
                .unwrap();
            let text = String::from_utf8_lossy(&text.stdout).to_string();
            if battery {
                // Idle at neutral: the open-circuit 16.8 V less the 1 A hotel load's 0.02 V.
                let volts = s.supply_voltage_v;
                assert!((volts - 16.78).abs() < 0.01, "{volts}");
                assert_eq!(
                    s.supply_compensation(),
                    Ok(thruster_protocol::SupplyCompensation::Active)
                );
                assert!(
                    (v["supply_voltage_v"].as_f64().unwrap() - 16.78).abs() < 0.01,
                    "{v}"
                );
                assert_eq!(v["supply_compensation"], "Active", "{v}");
                assert!(
                    (v["driver"]["supply_voltage_v"].as_f64().unwrap() - 16.78).abs() < 0.01,
                    "{v}"
                );
                assert!(
                    v["driver"]["supply_current_a"].as_f64().unwrap() > 0.9,
                    "{v}"
                );
                // The text is asked for after the JSON, the simulator running on meanwhile:
                // on a loaded machine tens of vehicle-s later, the pack a hundredth of a volt
                // lower (16.77 V at 83 s), so the figure is read, not matched.
                let line = text
                    .lines()
                    .find(|l| l.starts_with("  supply "))
                    .unwrap_or_else(|| panic!("no supply line\n{text}"));
                let shown: f64 = line
                    .split_whitespace()
                    .nth(1)
                    .and_then(|w| w.parse().ok())
                    .unwrap_or_else(|| panic!("no figure in {line:?}"));
                assert!(
                    (shown - 16.78).abs() < 0.03
                        && line.ends_with(" V, commands referred to the reference voltage"),
                    "{text}"
                );
            } else {
                assert!(s.supply_voltage_v.is_nan(), "{}", s.supply_voltage_v);
                assert_eq!(
                    s.supply_compensation(),
                    Ok(thruster_protocol::SupplyCompensation::NoReading)
                );
                assert!(v["supply_voltage_v"].is_null(), "{v}");
                assert!(v["driver"]["supply_voltage_v"].is_null(), "{v}");
                assert!(
                    text.contains("no voltage reading, not compensated (no voltage reading)"),
                    "{text}"
                );
            }
            assert!(daemon.stop().success(), "{}", daemon.log_text());
            assert!(sim.stop().success(), "{}", sim.log_text());
        }
        world.assert_nothing_left();
    }
}
