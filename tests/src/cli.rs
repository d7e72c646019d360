//! thrusterctl run the way the system tests run it: against a test's namespace (`ctl`), or a
//! lab command (`lab`: demo, experiment), and `status --json` polled until a condition holds.

use std::process::{Command, Output};
use std::time::{Duration, Instant};

use serde_json::Value;

use thruster_protocol::services::Inbox;
use thruster_protocol::{DaemonState, Setpoint, StatusMsg};

use crate::vehicle_clock::VehicleClock;
use crate::{bin, workspace, Proc, World};

/// `thrusterctl --namespace <world's> --timeout-ms 5000 <args>`, run to its end.
pub fn ctl(world: &World, args: &[&str]) -> Output {
    Command::new(bin("thrusterctl"))
        .args(["--namespace", &world.namespace(), "--timeout-ms", "5000"])
        .args(args)
        .output()
        .expect("thrusterctl runs")
}

/// `thrusterctl` as [`ctl`] runs it, left running: a `--wait` or `watch` beside a stepped
/// simulator, whose vehicle time the test moves while the command waits.
pub fn ctl_spawn(world: &World, args: &[&str]) -> Proc {
    let ns = world.namespace();
    let mut all = vec!["--namespace", &ns, "--timeout-ms", "5000"];
    all.extend_from_slice(args);
    Proc::spawn("thrusterctl", &all, world.dir.path())
}

/// Waits up to `within` (wall clock: the deadline of a hung process, not a schedule) until
/// `p`'s output contains `needle`; that output.
pub fn wait_output(p: &mut Proc, needle: &str, within: Duration) -> String {
    let deadline = Instant::now() + within;
    loop {
        let log = p.log_text();
        if log.contains(needle) {
            return log;
        }
        assert!(
            p.is_running() || p.log_text().contains(needle),
            "{} exited without {needle:?}: {log}",
            p.name
        );
        assert!(
            Instant::now() < deadline,
            "no {needle:?} from {}: {log}",
            p.name
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// `thrusterctl estimate --wait` beside a stepped simulator. The request goes out while the
/// simulator is held, so the estimation starts at the next sample in every run; the clock then
/// moves until the daemon reports a model newer than version `before` (`within_s` vehicle
/// seconds at most) and the command, which has seen it, returns. Its output and the status
/// that brought the model.
pub fn estimate_wait_stepped(
    world: &World,
    clock: &mut VehicleClock,
    status: &Inbox<StatusMsg>,
    before: u64,
    within_s: f64,
) -> (String, StatusMsg) {
    while status.recv().expect("reading the status").is_some() {}
    let mut estimate = ctl_spawn(world, &["estimate", "--wait", "--max-wait-s", "600"]);
    wait_output(&mut estimate, "estimation started", Duration::from_secs(60));
    let done = clock
        .run_until(status, within_s, |s| {
            crate::state(s) == DaemonState::Active && s.model_version > before
        })
        .unwrap_or_else(|| panic!("no model within {within_s} vehicle-s"));
    let code = estimate
        .wait_timeout(Duration::from_secs(60))
        .expect("estimate --wait returns once the model is in");
    let said = estimate.log_text();
    assert!(code.success(), "estimate --wait: {said}");
    (said, done)
}

/// `thrusterctl setpoint <args>` beside a stepped simulator. The setpoint goes out while the
/// simulator is held (a subscriber of the test's own sees it), so the daemon takes it at the
/// next sample in every run; the clock then moves gently (a step per 20 ms: a vehicle-state
/// inbox of 128 keeps up) until the command
/// has read the telemetry saying what the daemon holds, and returns. Its output and the
/// vehicle time the setpoint went out at: the test's schedule counts from there, not from
/// when the command noticed.
pub fn setpoint_stepped(world: &World, clock: &mut VehicleClock, args: &[&str]) -> (String, f64) {
    let sent: Inbox<Setpoint> = Inbox::create(world.node(), world.ipc()).expect("setpoint inbox");
    let mut all = vec!["setpoint"];
    all.extend_from_slice(args);
    let mut cmd = ctl_spawn(world, &all);
    let deadline = Instant::now() + Duration::from_secs(60);
    while sent.recv().expect("reading the setpoint").is_none() {
        assert!(
            Instant::now() < deadline && cmd.is_running(),
            "the setpoint did not go out: {}",
            cmd.log_text()
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    let sent_at = clock.now_s();
    while cmd.is_running() {
        assert!(
            clock.now_s() < sent_at + 5.0,
            "setpoint still waiting 5 vehicle-s on: {}",
            cmd.log_text()
        );
        clock.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    let code = cmd.wait_timeout(Duration::from_secs(5)).expect("reaped");
    let said = cmd.log_text();
    assert!(code.success(), "setpoint {args:?}: {said}");
    (said, sent_at)
}

/// `thrusterctl <args>` from the workspace (the lab finds config/ there), run to its end.
pub fn lab(args: &[&str]) -> Output {
    Command::new(bin("thrusterctl"))
        .args(args)
        .current_dir(workspace())
        .output()
        .expect("thrusterctl runs")
}

pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Asserts the exit code `code`, naming `what` and both outputs; the standard output.
pub fn expect_code(out: &Output, code: i32, what: &str) -> String {
    assert_eq!(
        out.status.code(),
        Some(code),
        "{what}\nstdout: {}\nstderr: {}",
        text(&out.stdout),
        text(&out.stderr)
    );
    text(&out.stdout)
}

/// Polls `status --json` every 100 ms until `pred` holds (`within` at most); that status.
pub fn wait_status(
    world: &World,
    what: &str,
    within: Duration,
    pred: impl Fn(&Value) -> bool,
) -> Value {
    let deadline = Instant::now() + within;
    loop {
        let out = ctl(world, &["status", "--json"]);
        if out.status.success() {
            let v: Value = serde_json::from_slice(&out.stdout).expect("status JSON");
            if pred(&v) {
                return v;
            }
        }
        assert!(
            Instant::now() < deadline,
            "timed out waiting for {what}; last: {}{}",
            text(&out.stdout),
            text(&out.stderr)
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}
