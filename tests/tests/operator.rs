//! What an operator meets at the command line: quiet exits on a closed pipe, refusals that
//! name what is wrong, and no files left behind. Real processes, each test on its own
//! namespace, every child reaped.

use std::process::{Command, Output, Stdio};

use system_tests::{bin, workspace};
use thruster_protocol::services::NamespaceGuard;

/// Runs `name args` with stdout a pipe whose reader is already gone (`| head -0`).
fn run_into_closed_pipe(name: &str, args: &[&str]) -> Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    Command::new(bin(name))
        .args(args)
        .stdin(Stdio::null())
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .unwrap_or_else(|e| panic!("running {name}: {e}"))
}

fn assert_quiet_success(what: &str, out: &Output) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && !stderr.contains("panicked"),
        "{what}: {:?}\n{stderr}",
        out.status
    );
}

#[test]
fn a_closed_stdout_pipe_ends_thrusterd_quietly() {
    let config = workspace().join("config/thrusterd.toml");
    let out = run_into_closed_pipe("thrusterd", &["check-config", config.to_str().unwrap()]);
    assert_quiet_success("thrusterd check-config | head -0", &out);
}

#[test]
fn a_closed_stdout_pipe_ends_the_demo_quietly() {
    // The case: `thrusterctl demo | head -1`. Unwinding stops the demo's daemon and
    // simulator and purges its namespace.
    let ns = NamespaceGuard::unique_for_test("pipe").unwrap();
    let out = run_into_closed_pipe(
        "thrusterctl",
        &["demo", "--hold-s", "0", "--namespace", ns.namespace()],
    );
    assert_quiet_success("thrusterctl demo | head -0", &out);
}
