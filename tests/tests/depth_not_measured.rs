//! A depth the operator asks to hold while the driver sends no depth (no sensor configured, or
//! one the driver refused: a Cube's air barometer, a pressure thinner than any water's). The
//! controller holds only a depth it measures, so nothing holds it; the daemon's status says so
//! instead of letting the setpoint read as held. The real processes: thrusterd, thruster-hw on
//! its Linux backend over a fake sysfs tree without a pressure sensor, and `thrusterctl
//! setpoint` and `status` as an operator runs them.

#[allow(dead_code)]
#[path = "../../hw-driver/tests/common/fake_sysfs.rs"]
mod fake_sysfs;
#[allow(dead_code)]
#[path = "../../hw-driver/tests/common/inotify.rs"]
mod inotify;

use std::time::Duration;

use fake_sysfs::FakeSysfs;
use system_tests::cli::ctl;
use system_tests::{Operator, World};

const LONG: Duration = Duration::from_secs(60);
const CHANNELS: [u32; 5] = [0, 1, 2, 3, 4];

#[test]
fn a_depth_hold_the_driver_gives_no_depth_for_is_said_not_held() {
    let world = World::new("nodepth");
    let op = Operator::new(&world);
    let fake = FakeSysfs::new(true);
    let cfg = system_tests::linux_driver::config(
        &world.namespace(),
        &CHANNELS,
        200,
        fake.root(),
        fake_sysfs::DENSITY,
        fake_sysfs::SURFACE_KPA,
    )
    .replace("pressure_device = \"ms5837\"\n", "");
    assert!(!cfg.contains("pressure_device"), "{cfg}");
    let mut hw = system_tests::linux_driver::spawn(&world, &cfg);
    let mut daemon = world.daemon(&["--thrusters", "5"]);
    op.wait_status(LONG, |s| s.samples > 100)
        .unwrap_or_else(|| panic!("no samples\n{}\n{}", daemon.log_text(), hw.log_text()));
    // Before any depth is asked, nothing is said.
    let before = op.wait_status(LONG, |_| true).unwrap();
    assert!(!before.text().contains("not held"), "{}", before.text());
    let set = ctl(&world, &["setpoint", "--depth", "2"]);
    assert!(set.status.success(), "{set:?}");
    let said = op
        .wait_status(Duration::from_secs(10), |s| {
            s.text().contains("depth 2.0 m not held")
        })
        .unwrap_or_else(|| panic!("not said\n{}", daemon.log_text()));
    assert!(
        said.text()
            .ends_with("depth 2.0 m not held: the driver sends no depth"),
        "{}",
        said.text()
    );
    // The operator's status shows it too.
    let status = ctl(&world, &["status"]);
    let out = String::from_utf8_lossy(&status.stdout);
    assert!(out.contains("depth 2.0 m not held"), "{out}");
    // Released, it is no longer said.
    assert!(ctl(&world, &["setpoint", "--depth", "free"])
        .status
        .success());
    op.wait_status(Duration::from_secs(10), |s| !s.text().contains("not held"))
        .unwrap_or_else(|| panic!("still said\n{}", daemon.log_text()));
    println!("no depth: {}", said.text());
    daemon.stop();
    hw.stop();
    drop(op);
    world.assert_nothing_left();
}
