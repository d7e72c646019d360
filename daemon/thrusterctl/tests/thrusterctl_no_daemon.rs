//! The real thrusterctl binary on a namespace where no daemon runs: every command must say
//! so and exit 3 well within its timeout (never hang), and leave nothing behind.

use std::path::PathBuf;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use thruster_protocol::services::{namespace_files, purge_namespace, IpcConfig, NamespaceGuard};

/// Far below what a hang would take, far above a normal run (~30 ms).
const QUICK: Duration = Duration::from_secs(5);

fn thrusterctl(ipc: &IpcConfig, args: &[&str]) -> (Output, Duration) {
    let started = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_thrusterctl"))
        .args(["--namespace", ipc.namespace(), "--timeout-ms", "2000"])
        .args(args)
        .output()
        .expect("thrusterctl runs");
    (out, started.elapsed())
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// After clean exits iceoryx2 keeps only its per-prefix node counter segment and empty
/// directories; anything else (a service file, a node monitor, a socket) means a port
/// or node was not dropped.
fn assert_only_clean_exit_traces(ipc: &IpcConfig) {
    let left: Vec<PathBuf> = namespace_files(ipc).expect("list namespace files");
    for path in &left {
        let name = path.file_name().unwrap().to_string_lossy();
        assert!(
            path.is_dir() || name.ends_with(".global_mgmt"),
            "left behind: {}",
            path.display()
        );
    }
}

#[test]
fn status_exits_3_with_the_message_quickly_and_leaves_nothing() {
    let guard = NamespaceGuard::unique_for_test("ctl").expect("namespace");
    let (out, took) = thrusterctl(&guard, &["status"]);
    assert_eq!(out.status.code(), Some(3), "stderr: {}", stderr(&out));
    let expected = format!(
        "thrusterd is not running on namespace {} (no control server in {}; a daemon \
         elsewhere needs --namespace and --ipc-root)",
        guard.namespace(),
        guard.root_dir().display()
    );
    assert!(stderr(&out).contains(&expected), "stderr: {}", stderr(&out));
    assert!(out.stdout.is_empty(), "stdout: {:?}", out.stdout);
    assert!(took < QUICK, "took {took:?}");
    assert_only_clean_exit_traces(&guard);
    purge_namespace(&guard).expect("purge");
    assert_eq!(namespace_files(&guard).unwrap(), Vec::<PathBuf>::new());
}

#[test]
fn every_daemon_command_exits_3_quickly() {
    let guard = NamespaceGuard::unique_for_test("ctl").expect("namespace");
    let commands: &[&[&str]] = &[
        &["status", "--json"],
        &["model"],
        &["model", "--json"],
        &["estimate"],
        &["estimate", "--wait", "--power", "0.5"],
        &["abort"],
        &["hold"],
        &["idle"],
        &["save"],
        &["save", "/tmp/model.toml"],
        &["revert"],
        &["load", "/tmp/model.toml"],
        &["shutdown"],
        &["watch"],
    ];
    for args in commands {
        let (out, took) = thrusterctl(&guard, args);
        assert_eq!(out.status.code(), Some(3), "{args:?}: {}", stderr(&out));
        assert!(
            stderr(&out).contains("is not running on namespace"),
            "{args:?}: {}",
            stderr(&out)
        );
        assert!(took < QUICK, "{args:?} took {took:?}");
    }
    assert_only_clean_exit_traces(&guard);
}

#[test]
fn publishing_without_subscriber_warns_and_exits_3() {
    let guard = NamespaceGuard::unique_for_test("ctl").expect("namespace");
    let vehicle = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/vehicles/amour5.toml"
    );
    let commands: &[&[&str]] = &[
        &["setpoint", "--roll", "0", "--pitch", "-10", "--yaw", "90"],
        &[
            "reconfigure",
            "--kind",
            "moved",
            "--thruster",
            "0",
            "--count",
            "5",
            "--geometry",
            vehicle,
        ],
    ];
    for args in commands {
        let (out, took) = thrusterctl(&guard, args);
        assert_eq!(out.status.code(), Some(3), "{args:?}: {}", stderr(&out));
        assert!(
            stderr(&out).contains("nobody subscribes to"),
            "{args:?}: {}",
            stderr(&out)
        );
        assert!(took < QUICK, "{args:?} took {took:?}");
    }
    assert_only_clean_exit_traces(&guard);
}

#[test]
fn bad_input_exits_2_before_touching_ipc() {
    let guard = NamespaceGuard::unique_for_test("ctl").expect("namespace");
    let cases: &[(&[&str], &str)] = &[
        (
            &["setpoint", "--roll", "nan", "--pitch", "0", "--yaw", "0"],
            "--roll must be a finite number",
        ),
        (
            &["setpoint", "--roll", "0", "--pitch", "95", "--yaw", "0"],
            "--pitch must be in [-90, 90]",
        ),
        (
            &[
                "reconfigure",
                "--kind",
                "added",
                "--thruster",
                "16",
                "--count",
                "16",
            ],
            "--thruster must be below 16",
        ),
        (
            &["reconfigure", "--kind", "unknown", "--count", "0"],
            "--count must be in 1..=16",
        ),
        (
            &[
                "reconfigure",
                "--kind",
                "moved",
                "--thruster",
                "0",
                "--count",
                "4",
                "--geometry",
                concat!(
                    env!("CARGO_MANIFEST_DIR"),
                    "/../../config/vehicles/amour5.toml"
                ),
            ],
            "declares 5 thrusters but --count is 4",
        ),
        (&["estimate", "--power", "1.5"], "--power must be in (0, 1]"),
        (&["status", "--timeout-ms", "0"], "--timeout-ms must be in"),
    ];
    for (args, message) in cases {
        let (out, _) = thrusterctl(&guard, args);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(message), "{args:?}: {}", stderr(&out));
    }
    // Rejected before any node was created: not even a directory.
    assert_eq!(namespace_files(&guard).unwrap(), Vec::<PathBuf>::new());
}

/// The demo's numbers are checked before it starts anything (it runs its own daemon on a
/// private namespace, so no --namespace here). NaN or a negative `--hold-s` left the hold
/// out of the report with exit 0, inf never ended, and "-5" was taken for a flag.
#[test]
fn the_demos_numbers_are_refused_with_their_range() {
    for (args, message) in [
        (["--hold-s", "nan"], "must be within 0..=3600 s, got NaN"),
        (["--hold-s", "-1"], "must be within 0..=3600 s, got -1"),
        (["--hold-s", "inf"], "must be within 0..=3600 s, got inf"),
        (["--tether", "-5"], "must be within 0..=1000 N, got -5"),
        (["--tether", "nan"], "must be within 0..=1000 N, got NaN"),
    ] {
        let started = Instant::now();
        let out = Command::new(env!("CARGO_BIN_EXE_thrusterctl"))
            .arg("demo")
            .args(args)
            .output()
            .expect("thrusterctl runs");
        assert!(started.elapsed() < QUICK, "{args:?} ran");
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(message), "{args:?}: {}", stderr(&out));
    }
}
