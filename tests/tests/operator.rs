//! What an operator meets at the command line: quiet exits on a closed pipe, refusals that
//! name what is wrong, and no files left behind. Real processes, each test on its own
//! namespace, every child reaped.

use std::process::{Command, ExitStatus, Output, Stdio};
use std::time::Duration;

use system_tests::{bin, workspace, Operator, Proc, World};
use thruster_protocol::RequestKind;

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
    // (The demo runs on a private namespace of its own, which it purges.)
    let out = run_into_closed_pipe("thrusterctl", &["demo", "--hold-s", "0"]);
    assert_quiet_success("thrusterctl demo | head -0", &out);
}

/// Runs a short-lived command to its end (10 s at most), its output merged into a log.
fn finish(mut p: Proc, what: &str) -> (ExitStatus, String) {
    let status = p
        .wait_timeout(Duration::from_secs(10))
        .unwrap_or_else(|| panic!("{what}: still running after 10 s\n{}", p.log_text()));
    (status, p.log_text())
}

#[test]
fn config_errors_give_file_line_column_key_and_range_and_check_config_catches_what_run_refuses() {
    let world = World::new("cfg");
    let cases: [(&str, &str, &str); 3] = [
        (
            "the issue's example",
            "[machine]\npulse_s = -3\n",
            ".toml:2:11: machine.pulse_s: must be in (0, inf), got -3",
        ),
        (
            "a namespace iceoryx2 cannot use (check-config passed it)",
            "[ipc]\nnamespace = \"a-namespace-too-long\"\n",
            ".toml:2:13: ipc.namespace: ",
        ),
        (
            "a state directory that is a regular file",
            "[runtime]\nstate_dir = \"/etc/hostname\"\n",
            ".toml:2:13: runtime.state_dir: /etc/hostname is not a directory",
        ),
    ];
    for (i, (what, text, want)) in cases.iter().enumerate() {
        let path = world.path(&format!("c{i}.toml"));
        std::fs::write(&path, text).unwrap();
        let path_s = path.to_str().unwrap();
        let check = Proc::spawn("thrusterd", &["check-config", path_s], world.dir.path());
        let (status, log) = finish(check, what);
        assert_eq!(status.code(), Some(2), "{what}: check-config\n{log}");
        assert!(
            log.contains(&format!("{path_s}:")) && log.contains(want),
            "{what}:\n{log}"
        );
        assert!(
            !log.contains("Caused by") && !log.contains("panicked"),
            "{what}:\n{log}"
        );
        // `run` refuses it the same way, before any IPC (no --namespace or --state-dir
        // here: the file's own are the point).
        let run = Proc::spawn("thrusterd", &["run", "--config", path_s], world.dir.path());
        let (status, log) = finish(run, what);
        assert_eq!(status.code(), Some(2), "{what}: run\n{log}");
        assert!(!log.contains("did not stop cleanly"), "{what}:\n{log}");
    }
}

#[test]
fn a_second_daemon_on_a_live_namespace_refuses_without_a_crash_message() {
    let world = World::new("two");
    let mut first = world.daemon(&[]);
    let op = Operator::new(&world);
    assert!(op.request(RequestKind::Status).is_ok());
    let marker = world.path("state").join("resume");
    let before = std::fs::read_to_string(&marker).expect("the live daemon's resume marker");
    // Same namespace, same state directory: what a second `systemctl start` by hand does.
    let second = world.daemon(&[]);
    let (status, log) = finish(second, "the second daemon");
    assert!(!status.success(), "{log}");
    assert!(log.contains("another thrusterd already serves"), "{log}");
    assert!(
        !log.contains("did not stop cleanly") && !log.contains("resum"),
        "a live daemon taken for a crashed one:\n{log}"
    );
    assert_eq!(std::fs::read_to_string(&marker).unwrap(), before);
    assert!(first.is_running());
    assert!(first.stop().success());
}

#[test]
fn a_state_dir_that_is_a_file_is_refused_at_start_with_the_path() {
    let world = World::new("stf");
    let file = world.path("state-file");
    std::fs::write(&file, "not a directory").unwrap();
    let ns = world.namespace();
    let daemon = Proc::spawn(
        "thrusterd",
        &[
            "run",
            "--namespace",
            &ns,
            "--state-dir",
            file.to_str().unwrap(),
        ],
        world.dir.path(),
    );
    let (status, log) = finish(daemon, "a daemon with a file for a state dir");
    assert_eq!(status.code(), Some(2), "{log}");
    assert!(
        log.contains(&format!(
            "runtime.state_dir: {} is not a directory",
            file.display()
        )),
        "{log}"
    );
    assert!(!log.contains("did not stop cleanly"), "{log}");
}

#[test]
fn a_demo_refused_for_its_vehicle_or_noise_leaves_no_namespace_folder() {
    let world = World::new("dbad");
    let zero = world.path("zero.toml");
    std::fs::write(&zero, "# no [[thruster]] tables\n").unwrap();
    let seventeen = world.path("seventeen.toml");
    let amour = std::fs::read_to_string(workspace().join("config/vehicles/amour5.toml")).unwrap();
    let one = &amour[amour.find("[[thruster]]").unwrap()..];
    let one = &one[..one[1..].find("[[thruster]]").map_or(one.len(), |i| i + 1)];
    std::fs::write(&seventeen, format!("{amour}\n{}", one.repeat(12))).unwrap();
    let amour5 = workspace().join("config/vehicles/amour5.toml");
    for (what, args, want) in [
        (
            "0 thrusters",
            vec!["--vehicle", zero.to_str().unwrap()],
            "must be in [1, 16], got 0",
        ),
        (
            "17 thrusters",
            vec!["--vehicle", seventeen.to_str().unwrap()],
            "must be in [1, 16], got 17",
        ),
        (
            "an unknown noise preset",
            vec!["--vehicle", amour5.to_str().unwrap(), "--noise", "bogus"],
            "--noise must be paper, realistic or none",
        ),
    ] {
        let mut argv = vec!["demo"];
        argv.extend(args);
        let demo = Proc::spawn("thrusterctl", &argv, world.dir.path());
        let pid = demo.pid();
        let (status, log) = finish(demo, what);
        assert!(!status.success() && log.contains(want), "{what}:\n{log}");
        // The demo's namespace is `demo-<pid>-<n>` (session.rs), its folder under the default
        // root.
        let folder = std::path::Path::new(thruster_protocol::services::DEFAULT_ROOT_BASE)
            .join(format!("demo-{}-0", pid % 1_000_000));
        assert!(!folder.exists(), "{what}: {} left", folder.display());
    }
}

/// The processes whose command line names `needle`.
fn processes_naming(needle: &str) -> Vec<String> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        if let Ok(raw) = std::fs::read(entry.path().join("cmdline")) {
            let cmd = String::from_utf8_lossy(&raw).replace('\0', " ");
            if cmd.contains(needle) {
                found.push(format!("{}: {cmd}", entry.file_name().to_string_lossy()));
            }
        }
    }
    found
}

/// Waits up to `within` for `pred` on the processes naming `needle`.
fn wait_processes(needle: &str, within: Duration, pred: impl Fn(&[String]) -> bool) -> Vec<String> {
    let end = std::time::Instant::now() + within;
    loop {
        let p = processes_naming(needle);
        if pred(&p) || std::time::Instant::now() > end {
            return p;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A demo stopped by SIGTERM (a supervisor, a CI timeout) stops its daemon and simulator and
/// removes its namespace, saying it was interrupted; one killed by SIGKILL runs no code, but
/// its daemon and simulator still go (they die with their parent). Before, both left a
/// lockstep daemon running forever.
#[test]
fn an_interrupted_demo_leaves_no_process_and_no_namespace() {
    let world = World::new("dint");
    for sig in ["TERM", "KILL"] {
        let demo = Proc::spawn(
            "thrusterctl",
            &["demo", "--hold-s", "3600", "--noise", "paper"],
            world.dir.path(),
        );
        // The demo's namespace is `demo-<pid>-<n>` (session.rs).
        let name = format!("demo-{}-0", demo.pid() % 1_000_000);
        let ns = format!("--namespace {name} ");
        let running = wait_processes(&ns, Duration::from_secs(20), |p| p.len() >= 2);
        assert!(
            running.len() >= 2,
            "{sig}: daemon and simulator not up: {running:?}"
        );
        demo.signal(sig);
        let (status, log) = finish(demo, sig);
        assert!(!status.success(), "{sig}: {log}");
        if sig == "TERM" {
            assert!(log.contains("interrupted"), "{sig}: {log}");
        }
        let left = wait_processes(&ns, Duration::from_secs(5), |p| p.is_empty());
        assert!(left.is_empty(), "{sig}: still running: {left:?}");
        if sig == "TERM" {
            let folder =
                std::path::Path::new(thruster_protocol::services::DEFAULT_ROOT_BASE).join(&name);
            assert!(!folder.exists(), "{} left", folder.display());
        }
    }
}
