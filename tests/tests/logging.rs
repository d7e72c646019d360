//! Where the real binaries log (thruster_driver_kit::logging): stderr normally, stderr also
//! when systemd's JOURNAL_STREAM names some other stream, and journald when it names their
//! stderr — falling back to stderr, with the reason, when no journal socket can be used (as on
//! a machine without systemd). The selection itself is unit-tested in driver-kit.

use std::fs::File;
use std::os::unix::fs::MetadataExt;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use system_tests::{bin, World};

const FALLBACK: &str = "logging to stderr";
const JOURNAL_SOCKET: &str = "/run/systemd/journal/socket";

/// Runs `name args` (which must exit on its own) with stderr to a file; `journal` sets
/// JOURNAL_STREAM: None = unset, Some(true) = the file's own device:inode (stderr "is the
/// journal"), Some(false) = another stream's. Returns what it wrote to stderr.
fn stderr_of(name: &str, args: &[&str], journal: Option<bool>) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("stderr.log");
    let file = File::create(&path).unwrap();
    let meta = file.metadata().unwrap();
    let mut cmd = Command::new(bin(name));
    cmd.args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(file)
        .env("RUST_LOG", "info")
        .env_remove("JOURNAL_STREAM");
    match journal {
        Some(true) => cmd.env("JOURNAL_STREAM", format!("{}:{}", meta.dev(), meta.ino())),
        Some(false) => cmd.env(
            "JOURNAL_STREAM",
            format!("{}:{}", meta.dev(), meta.ino() + 1),
        ),
        None => &mut cmd,
    };
    let status = cmd.status().unwrap();
    assert!(
        !status.success(),
        "{name} was expected to fail on its missing config"
    );
    std::fs::read_to_string(&path).unwrap()
}

#[test]
fn drivers_and_daemon_log_to_stderr_and_fall_back_without_a_journal() {
    let missing = "/nonexistent/thrusterd-test.toml";
    // thruster-hw logs its start-up error through tracing; thrusterd's logging is set up
    // before it reads its config.
    let cases: [(&str, &[&str]); 2] = [
        ("thruster-hw", &["run", "--config", missing]),
        ("thrusterd", &["run", "--config", missing]),
    ];
    for (name, args) in cases {
        for journal in [None, Some(false)] {
            let text = stderr_of(name, args, journal);
            assert!(
                text.contains("thrusterd-test.toml"),
                "{name} {journal:?}:\n{text}"
            );
            assert!(!text.contains(FALLBACK), "{name} {journal:?}:\n{text}");
        }
        let text = stderr_of(name, args, Some(true));
        if std::path::Path::new(JOURNAL_SOCKET).exists() {
            // A real journal took the lines (or refused them and we fell back): either way
            // the process ran and did not crash on the logging setup.
            eprintln!("{JOURNAL_SOCKET} exists: journald path not asserted");
        } else {
            assert!(
                text.contains(FALLBACK),
                "{name}: no fallback warning:\n{text}"
            );
            assert!(text.contains("thrusterd-test.toml"), "{name}:\n{text}");
        }
    }
}

#[test]
fn the_daemon_logs_to_stderr_while_serving() {
    let world = World::new("log");
    let mut daemon = world.daemon(&[]);
    let start = Instant::now();
    while !daemon.log_text().contains("thrusterd serving") {
        assert!(
            start.elapsed() < Duration::from_secs(20) && daemon.is_running(),
            "no 'thrusterd serving' on stderr:\n{}",
            daemon.log_text()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(daemon.stop().success());
    assert!(!daemon.log_text().contains(FALLBACK));
}
