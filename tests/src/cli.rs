//! thrusterctl run the way the system tests run it: against a test's namespace (`ctl`), or a
//! lab command (`lab`: demo, experiment), and `status --json` polled until a condition holds.

use std::process::{Command, Output};
use std::time::{Duration, Instant};

use serde_json::Value;

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
