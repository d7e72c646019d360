//! Lockstep (`thrusterd run --lockstep`, `runtime.lockstep`) is the simulator's mode: the
//! daemon acts in the simulator's time, its stale-IMU fault is off and a solve may hold a
//! sample for minutes. Next to real thrusters that is a vehicle without its watchdog, so a
//! daemon in lockstep refuses to drive thruster-hw: outputs unusable, thrust neutral, the
//! reason in its status. The real processes: thruster-hw on its Linux backend over a fake
//! sysfs tree.

#[allow(dead_code)]
#[path = "../../hw-driver/tests/common/fake_sysfs.rs"]
mod fake_sysfs;
#[allow(dead_code)]
#[path = "../../hw-driver/tests/common/inotify.rs"]
mod inotify;

use std::time::{Duration, Instant};

use fake_sysfs::FakeSysfs;
use system_tests::{state, Operator, World};
use thruster_protocol::services::Inbox;
use thruster_protocol::{DaemonState, RequestKind, ThrustCommand};

const LONG: Duration = Duration::from_secs(60);
const CHANNELS: [u32; 5] = [0, 1, 2, 3, 4];

#[test]
fn a_daemon_in_lockstep_will_not_drive_real_thrusters() {
    let world = World::new("lockhw");
    let op = Operator::new(&world);
    let fake = FakeSysfs::new(true);
    let cfg = system_tests::linux_driver::config(
        &world.namespace(),
        &CHANNELS,
        200,
        fake.root(),
        fake_sysfs::DENSITY,
        fake_sysfs::SURFACE_KPA,
    );
    let thrust: Inbox<ThrustCommand> = Inbox::create(world.node(), world.ipc()).unwrap();
    let mut hw = system_tests::linux_driver::spawn(&world, &cfg);
    let mut daemon = world.daemon(&["--thrusters", "5", "--lockstep"]);
    let blocked = op
        .wait_status(LONG, |s| s.text().contains("runs in lockstep"))
        .unwrap_or_else(|| panic!("not refused\n{}\n{}", daemon.log_text(), hw.log_text()));
    assert!(
        blocked.text().contains("thruster-hw linux"),
        "{}",
        blocked.text()
    );
    // Asked to estimate (pulse the thrusters), it refuses or stays neutral: every command
    // it sends for a second is all zeros, and the outputs never leave neutral.
    let _ = op.request(RequestKind::Estimate);
    let end = Instant::now() + Duration::from_secs(1);
    let mut commands = 0;
    while Instant::now() < end {
        while let Some(c) = thrust.recv().unwrap() {
            commands += 1;
            assert!(
                c.thrusters().iter().all(|&u| u == 0.0),
                "thrust {:?} in lockstep on thruster-hw\n{}",
                c.thrusters(),
                daemon.log_text()
            );
        }
        for ch in CHANNELS {
            assert_eq!(fake.pulse_us(ch), Some(1500), "pwm{ch}");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    assert!(commands > 50, "only {commands} commands in a second");
    let st = op.wait_status(LONG, |_| true).unwrap();
    assert_ne!(state(&st), DaemonState::Pulse, "{}", st.text());
    println!("lockstep on thruster-hw: {}", blocked.text());
    daemon.stop();
    hw.stop();
    drop(thrust);
    drop(op);
    world.assert_nothing_left();
}
