//! thrusterctl as an operator uses it: the real binary against real `thrusterd run` and
//! `thruster-sim run --lockstep` processes, checking output, exit codes and effects.

use std::process::Command;
use std::time::{Duration, Instant};

use serde_json::Value;
use system_tests::cli::{ctl, estimate_wait_stepped, expect_code, text};
use system_tests::vehicle_clock::STEPPED_DAEMON;
use system_tests::{bin, state, workspace, Operator, Proc, World};
use thruster_protocol::{DaemonState, ModelSource};

const LONG: Duration = Duration::from_secs(60);

/// Polls `status --json` until `pred` holds; the last status.
fn wait_status(world: &World, what: &str, pred: impl Fn(&Value) -> bool) -> Value {
    system_tests::cli::wait_status(world, what, LONG, pred)
}

/// The operator's session, in vehicle time (the simulator stepped by the test): every command
/// lands at the same vehicle time in every run, so what follows it is asserted exactly.
#[test]
fn operator_session_estimate_inspect_save_steer_reconfigure_shutdown() {
    let world = World::new("ctl");
    let op = Operator::new(&world);
    let mut daemon = world.daemon(&STEPPED_DAEMON);
    let (mut sim, mut clock) =
        world.stepped_sim("amour5", &["--noise", "paper", "--duration", "100000"]);
    clock
        .run_until(&op.status, 5.0, |s| {
            state(s) == DaemonState::Idle && s.samples > 50
        })
        .unwrap_or_else(|| panic!("an idle daemon reading the IMU\n{}", daemon.log_text()));

    // Refused before there is a model: exit 4 with the daemon's reason.
    let out = ctl(&world, &["save"]);
    expect_code(&out, 4, "save without a model");
    assert!(text(&out.stderr).contains("no model to save"));

    // In vehicle time: the estimation starts at the sample after the request in every run.
    let (done, done_at) = estimate_wait_stepped(&world, &mut clock, &op.status, 0, 30.0);
    assert_eq!(done_at.model_version, 1, "one estimation, one model");
    assert!(
        done.contains("estimation done: model version 1 (Estimated, "),
        "{done}\n{}",
        daemon.log_text()
    );

    let out = ctl(&world, &["model", "--json"]);
    expect_code(&out, 0, "model --json");
    let m: Value = serde_json::from_slice(&out.stdout).expect("model JSON");
    // The simulator is held at the sample that swapped the model in: no refinement yet.
    assert_eq!(m["version"], 1, "{m}");
    assert_eq!(m["source"], "Estimated", "{m}");
    assert_eq!(m["count"], 5);
    let eff = m["effectiveness"].as_array().unwrap();
    assert_eq!(eff.len(), 6);
    assert!(eff.iter().all(|row| row.as_array().unwrap().len() == 5));
    assert_eq!(m["allocation"].as_array().unwrap().len(), 5);
    // AMOUR's five thrusters push along x and z only: no sway.
    assert_eq!(m["actuated"]["sway"], false, "{m}");
    assert_eq!(m["actuated"]["yaw"], true, "{m}");
    // The default (dynamic) method's other coefficients come with the model: every DOF row
    // with all 38 terms, for this model's version.
    assert_eq!(m["method"], "Dynamic", "{m}");
    let d = &m["dynamics"];
    assert_eq!(d["model_version"], m["version"], "{m}");
    for row in ["roll", "pitch", "yaw", "surge", "sway", "heave"] {
        let terms = d["per_row_term_value_and_std_err"][row].as_object();
        assert_eq!(terms.map(|t| t.len()), Some(38), "{row}: {d}");
    }

    let out = ctl(&world, &["model"]);
    expect_code(&out, 0, "model");
    assert!(text(&out.stdout).contains("NOT actuated:  sway"));
    assert!(text(&out.stdout).contains("contribution of each thruster"));
    assert!(
        text(&out.stdout).contains("learned dynamics"),
        "{}",
        text(&out.stdout)
    );

    let saved = world.path("saved-model.json");
    let out = ctl(&world, &["save", saved.to_str().unwrap()]);
    expect_code(&out, 0, "save PATH");
    assert!(saved.exists());

    let out = ctl(
        &world,
        &["setpoint", "--roll", "0", "--pitch", "10", "--yaw", "0"],
    );
    expect_code(&out, 0, "setpoint");
    assert!(text(&out.stdout).starts_with("setpoint sent to 1 subscriber(s)"));
    clock.run_for(2.0);

    // A declared geometry swaps in its nominal model at the next sample: proof the event
    // arrived. Then the moved thruster alone is identified under control (the others'
    // columns kept): a new estimated model, one version after the nominal one.
    let before = {
        let out = ctl(&world, &["model", "--json"]);
        let m: Value = serde_json::from_slice(&out.stdout).expect("model JSON");
        m["version"].as_u64().expect("model version")
    };
    let vehicle = workspace().join("config/vehicles/amour5_top45.toml");
    let event_s = clock.now_s();
    let out = ctl(
        &world,
        &[
            "reconfigure",
            "--kind",
            "moved",
            "--thruster",
            "0",
            "--count",
            "5",
            "--geometry",
            vehicle.to_str().unwrap(),
        ],
    );
    expect_code(&out, 0, "reconfigure");
    let nominal = clock
        .run_until(&op.model, 1.0, |m| m.version > before)
        .unwrap_or_else(|| panic!("no model after the reconfiguration\n{}", daemon.log_text()));
    assert_eq!(nominal.version, before + 1);
    assert_eq!(nominal.source(), Ok(ModelSource::Nominal), "{nominal:?}");
    let out = ctl(&world, &["model", "--json"]);
    let m: Value = serde_json::from_slice(&out.stdout).expect("model JSON");
    assert_eq!(m["source"], "Nominal", "{m}");
    assert_eq!(m["version"], before + 1, "{m}");
    let relearned = clock
        .run_until(&op.model, 40.0, |m| m.version > before + 1)
        .unwrap_or_else(|| {
            panic!(
                "the moved thruster not identified within 40 vehicle-s\n{}",
                daemon.log_text()
            )
        });
    assert_eq!(relearned.version, before + 2);
    assert_eq!(
        relearned.source(),
        Ok(ModelSource::Estimated),
        "{relearned:?}"
    );
    println!(
        "moved thruster identified under control {:.2} vehicle-s after the event",
        clock.now_s() - event_s
    );

    let out = ctl(&world, &["shutdown"]);
    expect_code(&out, 0, "shutdown");
    let status = daemon
        .wait_timeout(Duration::from_secs(10))
        .expect("daemon exits on shutdown");
    assert!(status.success(), "{}", daemon.log_text());

    let out = ctl(&world, &["status"]);
    expect_code(&out, 3, "status after shutdown");
    assert!(sim.stop().success(), "{}", sim.log_text());

    drop(op);
    world.assert_nothing_left();
}

/// An absurd model (a units mistake, a hand edit) or a learned one without its error bounds is
/// refused with what is wrong named, the model in force stays, and it is the good one that is
/// saved at shutdown and loaded at restart.
#[test]
fn load_refuses_an_absurd_model_and_the_good_one_stays_saved_and_reloaded() {
    let world = World::new("ctlabsurd");
    let good =
        std::fs::read_to_string(workspace().join("fuzz/corpus/model_parse/model.json")).unwrap();
    let mut v: Value = serde_json::from_str(&good).unwrap();
    v["effectiveness"][1][0] = serde_json::json!(1e300);
    let good_path = world.path("good.json");
    let absurd_path = world.path("absurd.json");
    std::fs::write(&good_path, &good).unwrap();
    std::fs::write(&absurd_path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
    let saved = world.path("state/model.json");

    let mut daemon = world.daemon(&[]);
    wait_status(&world, "a daemon", |_| true);
    let out = ctl(&world, &["load", good_path.to_str().unwrap()]);
    expect_code(&out, 0, "load of a good model");
    let version =
        wait_status(&world, "the good model", |s| s["model_version"] != 0)["model_version"].clone();
    let out = ctl(&world, &["load", absurd_path.to_str().unwrap()]);
    expect_code(&out, 4, "load of an absurd model");
    assert!(
        text(&out.stderr).contains("effectiveness[1][0] = 1e300 is outside the physical bound"),
        "{}",
        text(&out.stderr)
    );
    let s = wait_status(&world, "a status", |_| true);
    assert_eq!(
        s["model_version"], version,
        "the absurd model was swapped in"
    );
    // A learned model with its error bounds cut out of the file: the confidence gate let it
    // through at any error (a missing bound compared as none) until it named what was missing.
    let mut unbounded: Value = serde_json::from_str(&good).unwrap();
    let fields = unbounded.as_object_mut().unwrap();
    fields.remove("rel_err_rot");
    fields.remove("rel_err_acc");
    let unbounded_path = world.path("unbounded.json");
    std::fs::write(
        &unbounded_path,
        serde_json::to_string_pretty(&unbounded).unwrap(),
    )
    .unwrap();
    let out = ctl(&world, &["load", unbounded_path.to_str().unwrap()]);
    expect_code(&out, 4, "load of a learned model without its bounds");
    assert!(
        text(&out.stderr).contains("must carry its error bounds: rel_err_rot unknown"),
        "{}",
        text(&out.stderr)
    );
    let s = wait_status(&world, "a status", |_| true);
    assert_eq!(
        s["model_version"], version,
        "the model without bounds was swapped in"
    );
    assert!(daemon.stop().success(), "{}", daemon.log_text());
    let on_disk: Value = serde_json::from_str(&std::fs::read_to_string(&saved).unwrap()).unwrap();
    let good_value: Value = serde_json::from_str(&good).unwrap();
    assert_eq!(
        on_disk["effectiveness"][1][0], good_value["effectiveness"][1][0],
        "the model saved at shutdown is not the good one"
    );
    // Restart: the good model comes back, no refusal counted.
    let mut daemon = world.daemon(&[]);
    let s = wait_status(&world, "the reloaded model", |s| s["model_version"] != 0);
    assert_eq!(s["requests_refused"], 0, "{s}");
    assert!(daemon.stop().success(), "{}", daemon.log_text());
}

#[test]
fn load_refuses_a_missing_file_with_exit_4() {
    let world = World::new("ctlload");
    let mut daemon = world.daemon(&[]);
    wait_status(&world, "a daemon", |_| true);
    let missing = world.path("nope.json");
    let out = ctl(&world, &["load", missing.to_str().unwrap()]);
    expect_code(&out, 4, "load of a missing file");
    assert!(text(&out.stderr).contains("no such file"));
    // Relative paths are resolved where thrusterctl runs, not where the daemon does.
    let out = Command::new(bin("thrusterctl"))
        .args(["--namespace", &world.namespace(), "load", "nope.json"])
        .current_dir(world.dir.path())
        .output()
        .unwrap();
    expect_code(&out, 4, "load of a relative missing file");
    assert!(
        text(&out.stderr).contains(&format!("{}: no such file", missing.display())),
        "{}",
        text(&out.stderr)
    );
    assert!(daemon.stop().success());
}

/// `sudo thrusterctl` on a vehicle: the ipc root belongs to thrusterd:thrusterd (2770) and the
/// caller is neither. Refused with exit 7, the path and the fix named, before any file exists
/// (files of another user are what stalled the daemon).
#[test]
fn a_user_outside_the_ipc_roots_group_is_refused_with_exit_7_and_no_file() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let root_base = dir.path().join("run");
    std::fs::create_dir(&root_base).unwrap();
    let ns = "ctlacc";
    if unsafe { libc::geteuid() } == 0 {
        std::os::unix::fs::chown(&root_base, Some(65534), Some(65534)).unwrap();
        std::fs::set_permissions(&root_base, std::fs::Permissions::from_mode(0o2770)).unwrap();
    } else {
        // Not root: no chown; a directory with empty owner bits refuses its owner the same way.
        std::fs::set_permissions(&root_base, std::fs::Permissions::from_mode(0o070)).unwrap();
    }
    let out = Command::new(bin("thrusterctl"))
        .args(["--namespace", ns, "--ipc-root", root_base.to_str().unwrap()])
        .args(["--timeout-ms", "500", "status"])
        .output()
        .unwrap();
    expect_code(&out, 7, "a user outside the ipc root's group");
    let err = text(&out.stderr);
    assert!(err.contains(&root_base.display().to_string()), "{err}");
    assert!(err.contains("usermod -aG"), "{err}");
    std::fs::set_permissions(&root_base, std::fs::Permissions::from_mode(0o700)).unwrap();
    assert!(
        !root_base.join(ns).exists(),
        "thrusterctl made its root dir"
    );
    let shm: Vec<String> = std::fs::read_dir("/dev/shm")
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(&format!("thr_{ns}_")))
        .collect();
    assert!(shm.is_empty(), "thrusterctl left shared memory: {shm:?}");
}

/// `--ipc-root` on every binary: a daemon and a simulator started on another root (as under
/// systemd, /run/thrusterd) are reached by a thrusterctl given the same root; one without it
/// is told where it looked.
#[test]
fn an_ipc_root_on_the_command_line_is_used_by_daemon_simulator_and_operator() {
    let world = World::new("ctlroot");
    let root = world.path("ipc");
    let root_s = root.to_str().unwrap().to_string();
    let ns = world.namespace();
    let state = world.path("state2");
    let vehicle = workspace().join("config/vehicles/amour5.toml");
    let mut daemon = system_tests::Proc::spawn(
        "thrusterd",
        &[
            "run",
            "--namespace",
            &ns,
            "--ipc-root",
            &root_s,
            "--state-dir",
            state.to_str().unwrap(),
            "--lockstep",
        ],
        world.dir.path(),
    );
    let mut sim = system_tests::Proc::spawn(
        "thruster-sim",
        &[
            "run",
            "--namespace",
            &ns,
            "--ipc-root",
            &root_s,
            "--vehicle",
            vehicle.to_str().unwrap(),
            "--lockstep",
            "--noise",
            "none",
        ],
        world.dir.path(),
    );
    let ctl_at = |with_root: bool| {
        let mut c = Command::new(bin("thrusterctl"));
        c.args(["--namespace", &ns, "--timeout-ms", "5000"]);
        if with_root {
            c.args(["--ipc-root", &root_s]);
        }
        c.args(["status", "--json"]).output().unwrap()
    };
    let deadline = Instant::now() + LONG;
    let v = loop {
        let out = ctl_at(true);
        if out.status.success() {
            let v: Value = serde_json::from_slice(&out.stdout).unwrap();
            if v["samples"].as_u64().unwrap_or(0) > 0 && !v["driver"].is_null() {
                break v;
            }
        }
        assert!(
            Instant::now() < deadline,
            "no status with samples on {root_s}: {}\n{}\n{}",
            text(&out.stderr),
            daemon.log_text(),
            sim.log_text()
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(v["driver"]["driver"], "thruster-sim", "{v}");
    // Nothing on the default root: the files are where the flag said.
    assert!(
        root.join(&ns).is_dir(),
        "no namespace folder under {root_s}"
    );
    let out = ctl_at(false);
    expect_code(&out, 3, "status on the default root");
    assert!(
        text(&out.stderr).contains(&format!(
            "no control server in {}",
            world.ipc().root_dir().display()
        )),
        "{}",
        text(&out.stderr)
    );
    assert!(daemon.stop().success(), "{}", daemon.log_text());
    assert!(sim.stop().success(), "{}", sim.log_text());
    let ipc = thruster_protocol::services::IpcConfig::with_root_base(&ns, &root).unwrap();
    thruster_protocol::services::purge_namespace(&ipc).unwrap();
    assert_eq!(
        thruster_protocol::services::namespace_files(&ipc).unwrap(),
        Vec::<std::path::PathBuf>::new()
    );
}

/// The demo and the experiments run on a private namespace of their own: a --namespace
/// given to them was silently ignored; now it is refused as a usage error before anything
/// starts.
#[test]
fn demo_refuses_a_namespace_it_would_ignore() {
    let out = Command::new(bin("thrusterctl"))
        .args(["--namespace", "veh9", "demo"])
        .output()
        .unwrap();
    expect_code(&out, 2, "demo --namespace");
    assert!(
        text(&out.stderr).contains("private namespace"),
        "{}",
        text(&out.stderr)
    );
}

/// A cleanly stopped vehicle leaves nothing of its namespace: not even the empty nodes/ and
/// services/ folders and the world-writable global_mgmt segment iceoryx2 leaves behind (the
/// last process to stop removes them). Checked without any purge by the test.
#[test]
fn a_clean_stop_of_every_process_leaves_nothing_of_the_namespace() {
    let mut world = World::new("ctltidy");
    // No node of the test's own in the namespace: the processes are alone in it.
    world.node = None;
    let mut daemon = world.daemon(&[]);
    let mut sim = world.sim("amour5", &["--lockstep", "--noise", "none"]);
    wait_status(&world, "samples", |v| {
        v["samples"].as_u64().unwrap_or(0) > 0
    });
    assert!(daemon.stop().success(), "{}", daemon.log_text());
    assert!(sim.stop().success(), "{}", sim.log_text());
    let files = thruster_protocol::services::namespace_files(world.ipc()).unwrap();
    assert!(
        files.is_empty(),
        "left behind after a clean stop: {files:?}"
    );
    // An operator alone in the namespace (no daemon) leaves nothing either.
    let out = ctl(&world, &["status"]);
    expect_code(&out, 3, "status with no daemon");
    let files = thruster_protocol::services::namespace_files(world.ipc()).unwrap();
    assert!(files.is_empty(), "left behind by thrusterctl: {files:?}");
}

/// An operator killed with -9 mid-session (a `watch`, which polls status and reads the
/// telemetry) leaves its node, ports and shared memory; the daemon removes them within its
/// next dead-node search (every 2 s, on a thread of its own), with no other client arriving to
/// do it. Before the reaper they stayed until the daemon's next start.
#[test]
fn a_client_killed_mid_call_leaves_nothing_after_the_daemons_next_search() {
    let (world, mut daemon, mut sim) = reaper_world("ctlkill");
    let files = || thruster_protocol::services::namespace_files(world.ipc()).unwrap();
    let before = files();

    let mut client = Proc::spawn(
        "thrusterctl",
        &["--namespace", &world.namespace(), "watch"],
        world.dir.path(),
    );
    // The client's own files: those that appeared while it ran.
    let mut theirs: Vec<std::path::PathBuf> = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(20);
    while theirs.len() < 5 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
        theirs = files()
            .into_iter()
            .filter(|p| !before.contains(p))
            .collect();
    }
    assert!(
        theirs.len() >= 5,
        "the client made too few files to judge: {theirs:?}"
    );
    assert!(
        client.is_running(),
        "the watch ended by itself: the kill would test nothing"
    );
    client.signal("KILL");
    client
        .wait_timeout(Duration::from_secs(10))
        .expect("the killed client reaped");
    let killed = Instant::now();

    let deadline = killed + Duration::from_secs(10);
    let left = || left_after(&theirs, &files());
    while !left().is_empty() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    let left = left();
    eprintln!(
        "{} files before, {} of the client's, {} left {:.1} s after the kill",
        before.len(),
        theirs.len(),
        left.len(),
        killed.elapsed().as_secs_f64()
    );
    if !left.is_empty() {
        // Failed this way in CI 2 of 5 runs (never in ~60 runs here): 18-25 of the client's
        // files stayed, the daemon's log silent. The test's own search, asked here, found the
        // node dead and iceoryx2 unable to remove it (`dead_failed: 1`): an iceoryx2 limit for
        // a client killed mid-update of a service's shared state. What the daemon owes then is
        // to say so, that it could not remove them or that iceoryx2's removal is stuck
        // (`reaper::search_watched`), never silence. The search runs on a thread with a
        // deadline: stuck like the reaper's, it must fail the test, not hang it.
        let ipc = world.ipc().clone();
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send(thruster_protocol::services::cleanup_dead_nodes(&ipc));
        });
        let census = rx.recv_timeout(Duration::from_secs(5));
        let log = daemon.log_text();
        let iceoryx_cannot = match &census {
            Ok(Ok(c)) => c.dead_failed > 0,
            // Stuck here too: iceoryx2's removal, not the daemon.
            Err(_) => true,
            Ok(Err(_)) => false,
        };
        let said = log.contains("dead nodes whose files could not be removed")
            || log.contains("the dead-node search has not returned");
        assert!(
            iceoryx_cannot && said,
            "the killed client's files stayed: {left:?}\n\
             the test's own dead-node search: {census:?}\n\
             daemon log:\n{log}"
        );
        eprintln!(
            "iceoryx2 could not remove the killed client's node ({census:?}); the daemon said so"
        );
        assert!(sim.stop().success(), "{}", sim.log_text());
        assert!(daemon.stop().success(), "{}", daemon.log_text());
        return;
    }
    assert!(
        daemon
            .log_text()
            .contains("removed the files of dead nodes"),
        "the daemon did not say it removed them: {}",
        daemon.log_text()
    );
    assert!(sim.stop().success(), "{}", sim.log_text());
    assert!(daemon.stop().success(), "{}", daemon.log_text());
}

/// A daemon and a lockstep simulator serving, and no node of the test's own: only the daemon
/// (the simulator never searches) may remove dead clients' files.
fn reaper_world(prefix: &str) -> (World, Proc, Proc) {
    let mut world = World::new(prefix);
    world.node = None;
    let daemon = world.daemon(&[]);
    let sim = world.sim("amour5", &["--lockstep", "--noise", "none"]);
    wait_status(&world, "samples", |v| {
        v["samples"].as_u64().unwrap_or(0) > 0
    });
    (world, daemon, sim)
}

/// The files of `theirs` still among `now`.
fn left_after(
    theirs: &[std::path::PathBuf],
    now: &[std::path::PathBuf],
) -> Vec<std::path::PathBuf> {
    theirs.iter().filter(|p| now.contains(p)).cloned().collect()
}

/// Clients killed with -9 while they join the namespace (2-9 ms after their start, inside
/// iceoryx2's node creation): measured on 24 such kills, 9 left files the reaper never
/// removed. A node whose liveness guard was never finished (or never begun) was listed as
/// not existing, forever; a dead node without its details file was "cleaned" with iceoryx2's
/// global configuration, another root, so the reaper said "removed" every 2 s and nothing
/// went. Now the unfinished ones go after `UNFINISHED_AFTER` (10 s), and what iceoryx2 cannot
/// remove (a node killed while it joined a service: its tag left, the removal failing with
/// InternalError) is said to stay, not reported removed. Asserted: after 16 s every node these
/// clients left is of that last kind, and if any is, the daemon's log says so.
#[test]
fn clients_killed_while_joining_leave_only_what_the_daemon_reports() {
    let (world, mut daemon, mut sim) = reaper_world("ctljoin");
    let files = || thruster_protocol::services::namespace_files(world.ipc()).unwrap();
    let before = files();
    for delay_ms in 2..10u64 {
        let mut client = Proc::spawn(
            "thrusterctl",
            &["--namespace", &world.namespace(), "watch"],
            world.dir.path(),
        );
        std::thread::sleep(Duration::from_millis(delay_ms));
        client.signal("KILL");
        client
            .wait_timeout(Duration::from_secs(10))
            .expect("the killed client reaped");
    }
    let nodes_dir = world.ipc().root_dir().join("nodes");
    // The clients' nodes still on disk: (id, whether its folder holds a service or port tag).
    let left_nodes = || -> Vec<(String, bool)> {
        let mut ids: Vec<String> = files()
            .into_iter()
            .filter(|p| !before.contains(p) && p.parent() == Some(nodes_dir.as_path()))
            .filter_map(|p| {
                let name = p.file_name()?.to_str()?.to_string();
                let id = name.rsplit('_').next()?.split('.').next()?.to_string();
                id.bytes().all(|b| b.is_ascii_digit()).then_some(id)
            })
            .collect();
        ids.sort();
        ids.dedup();
        ids.into_iter()
            .map(|id| {
                let tagged = std::fs::read_dir(nodes_dir.join(&id)).is_ok_and(|d| {
                    d.flatten().any(|e| {
                        let n = e.file_name();
                        let n = n.to_string_lossy();
                        n.ends_with(".service_tag") || n.ends_with(".port_tag")
                    })
                });
                (id, tagged)
            })
            .collect()
    };
    let deadline = Instant::now() + Duration::from_secs(16);
    while left_nodes().iter().any(|(_, tagged)| !tagged) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(200));
    }
    // One more search after the last removal, for the log to say what stays.
    std::thread::sleep(Duration::from_secs(3));
    let left = left_nodes();
    eprintln!("clients' nodes left after the searches: {left:?}");
    assert!(
        left.iter().all(|(_, tagged)| *tagged),
        "unfinished nodes stayed: {left:?}\n{}",
        daemon.log_text()
    );
    if !left.is_empty() {
        assert!(
            daemon
                .log_text()
                .contains("dead nodes whose files could not be removed"),
            "{} nodes stayed and the daemon did not say so:\n{}",
            left.len(),
            daemon.log_text()
        );
    }
    assert!(sim.stop().success(), "{}", sim.log_text());
    assert!(daemon.stop().success(), "{}", daemon.log_text());
}

/// A `watch` sent SIGTERM while it joins the namespace (its first file made, its node and
/// ports not yet all) ends by itself and removes everything it made, with no reaper needed.
/// Before, the Ctrl-C/SIGTERM handler was installed after connecting (the node was an
/// earlier argument of the same call), so the signal's default action killed it with its
/// node half made and its files stayed until the daemon's next dead-node search.
#[test]
fn a_watch_sent_sigterm_while_joining_ends_cleanly_and_leaves_nothing() {
    let (world, mut daemon, mut sim) = reaper_world("ctlterm");
    let files = || thruster_protocol::services::namespace_files(world.ipc()).unwrap();
    let before = files();
    for round in 0..3 {
        let mut client = Proc::spawn(
            "thrusterctl",
            &["--namespace", &world.namespace(), "watch", "--json"],
            world.dir.path(),
        );
        // Its first file: it is inside Daemon::connect now.
        let deadline = Instant::now() + Duration::from_secs(10);
        let mut theirs = Vec::new();
        while theirs.is_empty() && Instant::now() < deadline {
            theirs = files()
                .into_iter()
                .filter(|p| !before.contains(p))
                .collect();
        }
        assert!(!theirs.is_empty(), "round {round}: the watch made no file");
        client.signal("TERM");
        let status = client
            .wait_timeout(Duration::from_secs(10))
            .expect("the watch ended after SIGTERM");
        let exited = Instant::now();
        assert!(
            status.code().is_some(),
            "round {round}: the watch was killed by the signal ({status}), not stopped by it"
        );
        // What it made alone is gone at its exit: its own drop, not the daemon's search
        // (every 2 s). A connection file is shared with the daemon's port and goes when the
        // last of the two lets it go: the daemon's, on its next round (CI once saw the pair
        // of the control service's connection files 2 ms after the exit). Those get 500 ms,
        // and the daemon must not have reaped anything (it logs every removal).
        let is_connection =
            |p: &std::path::PathBuf| p.extension().is_some_and(|e| e == "connection");
        let new_files = || -> Vec<_> {
            files()
                .into_iter()
                .filter(|p| !before.contains(p))
                .collect()
        };
        let own: Vec<_> = new_files()
            .into_iter()
            .filter(|p| !is_connection(p))
            .collect();
        assert!(
            own.is_empty(),
            "round {round}: left {:.0} ms after a clean exit: {own:?}",
            exited.elapsed().as_secs_f64() * 1e3
        );
        let mut shared = new_files();
        while !shared.is_empty() && exited.elapsed() < Duration::from_millis(500) {
            std::thread::sleep(Duration::from_millis(5));
            shared = new_files();
        }
        assert!(
            shared.is_empty(),
            "round {round}: connection files left {:.0} ms after a clean exit: {shared:?}",
            exited.elapsed().as_secs_f64() * 1e3
        );
        assert!(
            !daemon
                .log_text()
                .contains("removed the files of dead nodes"),
            "round {round}: the daemon's search removed what the watch should have:\n{}",
            daemon.log_text()
        );
    }
    assert!(sim.stop().success(), "{}", sim.log_text());
    assert!(daemon.stop().success(), "{}", daemon.log_text());
}
