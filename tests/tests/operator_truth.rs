//! Issue 27: what thrusterctl says, and what the vehicle does, checked the way a new user met
//! them. Real thrusterd and thruster-sim processes on a private namespace (lockstep, paced so
//! vehicle time advances evenly), the simulator's true vehicle state as the judge; every child
//! reaped and the namespace's files checked at the end.

use std::process::{Command, Output};
use std::time::{Duration, Instant};

use serde_json::Value;
use system_tests::cli::{ctl, estimate_wait_stepped, expect_code, setpoint_stepped, text};
use system_tests::vehicle_clock::STEPPED_DAEMON;
use system_tests::{bin, Operator, World};
use thruster_protocol::services::Inbox;
use thruster_protocol::VehicleStateMsg;

fn expect_ok(out: &Output, what: &str) -> String {
    expect_code(out, 0, what)
}

/// `estimate --wait`, asked again while the daemon refuses it because the vehicle is still
/// swinging from the last estimation's pulses (beyond the identification's attitude budget):
/// in lockstep the status saying the first estimation is done comes at its very sample, so
/// the next request can land before the vehicle has settled. Its output once accepted.
fn estimate_wait(world: &World) -> Output {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let out = ctl(world, &["estimate", "--wait", "--max-wait-s", "120"]);
        let refused_unsettled =
            !out.status.success() && text(&out.stderr).contains("beyond the identification budget");
        if !refused_unsettled || Instant::now() > deadline {
            return out;
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Polls `status --json` until `pred` holds (60 s at most); the last status.
fn wait_status(world: &World, what: &str, pred: impl Fn(&Value) -> bool) -> Value {
    system_tests::cli::wait_status(world, what, Duration::from_secs(60), pred)
}

fn depth_range(states: &[VehicleStateMsg]) -> (f64, f64) {
    states.iter().fold((f64::MAX, f64::MIN), |(lo, hi), v| {
        (lo.min(v.position_ned[2]), hi.max(v.position_ned[2]))
    })
}

/// Item 1, the safety defect: `setpoint --pitch 10` from a depth hold answered "depth free"
/// and the vehicle rose 7 m. Now the held depth is kept (within 0.3 m of the true depth for 30
/// vehicle-s), the reply says so, and only `--depth free` lets go (then the buoyant vehicle
/// rises, which shows the check can fail).
#[test]
fn a_pitch_setpoint_from_a_depth_hold_keeps_the_depth() {
    let world = World::new("spdepth");
    let vehicle: Inbox<VehicleStateMsg> =
        Inbox::create_with_buffer(world.node(), world.ipc(), 128).unwrap();
    let op = Operator::new(&world);
    let mut daemon = world.daemon(&STEPPED_DAEMON);
    let (mut sim, mut clock) =
        world.stepped_sim("amour5", &["--noise", "realistic", "--duration", "100000"]);
    clock
        .run_until(&op.status, 5.0, |s| s.samples > 50)
        .expect("an idle daemon reading the IMU");
    estimate_wait_stepped(&world, &mut clock, &op.status, 0, 30.0);
    let now = clock.collect_for(&vehicle, 0.05);
    let d0 = now.last().unwrap().position_ned[2];
    let held = format!("{d0:.2}");
    let (said, t0) = setpoint_stepped(
        &world,
        &mut clock,
        &["--roll", "0", "--pitch", "0", "--depth", &held],
    );
    assert!(said.contains(&format!("depth {held} m")), "{said}");
    let d0: f64 = held.parse().unwrap();
    // Settle on the held depth and level.
    clock.run_to(t0 + 10.0);

    while vehicle.recv().unwrap().is_some() {}
    let (said, t1) = setpoint_stepped(&world, &mut clock, &["--pitch", "10"]);
    assert!(
        said.contains("depth kept") && said.contains(&format!("depth {held} m")),
        "the reply must say depth is kept and which: {said}"
    );
    let states = clock.collect_until(&vehicle, t1 + 30.0);
    let (lo, hi) = depth_range(&states);
    println!("pitch 10 from a hold at {d0:.2} m: depth {lo:.3}-{hi:.3} m over 30 vehicle-s");
    assert!(
        (lo - d0).abs() <= 0.3 && (hi - d0).abs() <= 0.3,
        "held {d0:.2} m, the vehicle went {lo:.2}-{hi:.2} m over 30 vehicle-s"
    );
    let pitch = {
        let q = states.last().unwrap().attitude;
        let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            q[0], q[1], q[2], q[3],
        ));
        q.euler_angles().1.to_degrees()
    };
    assert!((pitch - 10.0).abs() < 3.0, "pitch {pitch:.1} deg");

    // Released on request only: the buoyant vehicle then rises.
    let (said, t2) = setpoint_stepped(&world, &mut clock, &["--depth", "free"]);
    assert!(said.contains("depth free"), "{said}");
    clock.run_to(t2 + 30.0);
    let last = clock
        .collect_for(&vehicle, 0.05)
        .last()
        .unwrap()
        .position_ned[2];
    println!("depth free: from {d0:.2} m to {last:.2} m in 30 vehicle-s");
    assert!(
        d0 - last > 0.3,
        "free depth: from {d0:.2} m to {last:.2} m, the check could not fail"
    );

    let out = ctl(&world, &["shutdown"]);
    expect_ok(&out, "shutdown");
    assert!(daemon.wait_timeout(Duration::from_secs(20)).is_some());
    sim.stop();
    drop((vehicle, op));
    world.assert_nothing_left();
}

/// Item 3: the daemon started before the simulator, as the README does. Once samples flow,
/// `status` must not go on saying none came.
#[test]
fn status_drops_no_imu_yet_once_the_simulator_runs() {
    let world = World::new("noimu");
    let mut daemon = world.daemon(&["--lockstep"]);
    let first = wait_status(&world, "the daemon saying no IMU came", |v| {
        v["text"].as_str().unwrap_or("").contains("no IMU samples")
    });
    assert_eq!(first["state"], "Idle", "{first}");
    let mut sim = world.sim(
        "amour5",
        &[
            "--noise",
            "paper",
            "--lockstep",
            "--pace",
            "5",
            "--duration",
            "100000",
        ],
    );
    let flowing = wait_status(&world, "samples", |v| {
        v["samples"].as_u64().unwrap_or(0) > 200
    });
    let text = flowing["text"].as_str().unwrap();
    assert!(
        !text.contains("no IMU"),
        "stale text beside samples: {flowing}"
    );
    assert_eq!(flowing["state"], "Idle", "{flowing}");
    // And the human form, as the user read it.
    let out = ctl(&world, &["status"]);
    let said = expect_ok(&out, "status");
    assert!(!said.contains("no IMU samples"), "{said}");
    let out = ctl(&world, &["shutdown"]);
    expect_ok(&out, "shutdown");
    assert!(daemon.wait_timeout(Duration::from_secs(20)).is_some());
    sim.stop();
    world.assert_nothing_left();
}

/// "pulse X of Y" in a line of `estimate --wait` or `watch`: (X, Y).
fn pulse_counts(line: &str) -> Option<(u64, u64)> {
    let rest = line.split("pulse ").nth(1)?;
    let mut words = rest.split_whitespace();
    let x = words.next()?.parse().ok()?;
    (words.next()? == "of").then_some(())?;
    let y = words.next()?.trim_end_matches(',').parse().ok()?;
    Some((x, y))
}

/// Every "bound N %" figure of a line, in percent.
fn bounds(line: &str) -> Vec<f64> {
    line.split("bound ")
        .skip(1)
        .filter_map(|r| r.split_whitespace().next()?.parse().ok())
        .collect()
}

/// Items 2 and 5 as the user met them. `estimate --wait` at the paper's noise, where the
/// estimator extends its plan: no line counts a pulse beyond the plan it shows. A second
/// estimation under `watch`: its first pulse shows no error bound (the old model's was shown),
/// and no bound above 100 % is printed as a number. Then the daemon is shut down and a new one
/// started under the same `watch`: it says stopped (not the old state), then that a new
/// instance runs, and shows that one's state.
#[test]
fn progress_bounds_and_watch_across_a_restart_say_what_is_so() {
    let world = World::new("progress");
    let mut daemon = world.daemon(&["--lockstep"]);
    let mut sim = world.sim(
        "amour5",
        &[
            "--noise",
            "paper",
            "--lockstep",
            "--pace",
            "20",
            "--duration",
            "100000",
        ],
    );
    wait_status(&world, "an idle daemon reading the IMU", |v| {
        v["state"] == "Idle" && v["samples"].as_u64().unwrap_or(0) > 50
    });
    let ns = world.namespace();
    let mut watch = system_tests::Proc::spawn(
        "thrusterctl",
        &["--namespace", &ns, "watch", "--interval-ms", "0"],
        world.dir.path(),
    );
    let mut extents = Vec::new();
    for run in 0..2 {
        let out = estimate_wait(&world);
        expect_ok(&out, "estimate --wait");
        let progress = text(&out.stderr);
        for line in progress.lines() {
            if let Some((x, y)) = pulse_counts(line) {
                assert!(x <= y, "run {run}: {line}\n{progress}");
                extents.push(y);
            }
        }
    }
    let (lo, hi) = (
        extents.iter().min().copied().unwrap_or(0),
        extents.iter().max().copied().unwrap_or(0),
    );
    assert!(
        hi > lo,
        "the plan never grew ({lo}..{hi}): the count check could not fail"
    );

    let out = ctl(&world, &["shutdown"]);
    expect_ok(&out, "shutdown");
    assert!(daemon.wait_timeout(Duration::from_secs(20)).is_some());
    let stopped_at = Instant::now();
    while !watch.log_text().contains("thrusterd stopped") {
        assert!(
            stopped_at.elapsed() < Duration::from_secs(10),
            "{}",
            watch.log_text()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut daemon = world.daemon(&["--lockstep"]);
    let back = Instant::now();
    while !watch.log_text().contains("restarted") || !watch.log_text().contains("] Idle") {
        assert!(
            back.elapsed() < Duration::from_secs(20),
            "{}",
            watch.log_text()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    watch.signal("INT");
    assert!(watch.wait_timeout(Duration::from_secs(10)).is_some());
    let log = watch.log_text();

    // The second estimation's first pulse (a model in force): no bound yet.
    for line in log.lines() {
        if line.contains("Pulse") && pulse_counts(line).is_some_and(|(x, _)| x == 1) {
            assert!(
                bounds(line).is_empty(),
                "a bound before any estimate: {line}"
            );
        }
        for b in bounds(line) {
            assert!(b <= 100.0, "an absurd bound: {line}");
        }
        if let Some((x, y)) = pulse_counts(line) {
            assert!(x <= y, "{line}");
        }
    }
    let stop_line = log
        .lines()
        .find(|l| l.contains("thrusterd stopped"))
        .unwrap();
    assert!(
        stop_line.contains("] Stopped") && !stop_line.contains("] Active"),
        "{stop_line}"
    );
    let after: Vec<&str> = log
        .lines()
        .skip_while(|l| !l.contains("restarted"))
        .collect();
    assert!(
        after.iter().any(|l| l.contains("] Idle")),
        "the new daemon's state: {log}"
    );
    assert!(
        !after.iter().skip(1).any(|l| l.contains("Active")),
        "the old daemon's state after the restart: {log}"
    );

    let out = ctl(&world, &["shutdown"]);
    expect_ok(&out, "shutdown");
    assert!(daemon.wait_timeout(Duration::from_secs(20)).is_some());
    sim.stop();
    world.assert_nothing_left();
}

/// Item 8: a demo whose daemon refuses its configuration failed with `kill: (N): No such
/// process` and named a log file the demo had already deleted. Now it says why, with the log's
/// last lines, and names no file that is gone.
#[test]
fn a_failed_demo_names_no_deleted_file_and_no_kill_error() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[machine]\nmax_unexplained_rate_radps = -3\n").unwrap();
    let out = Command::new(bin("thrusterctl"))
        .args([
            "demo",
            "--hold-s",
            "0",
            "--daemon-config",
            bad.to_str().unwrap(),
        ])
        .env_remove("THRUSTERCTL_KEEP_LOGS")
        .output()
        .expect("thrusterctl runs");
    let said = format!("{}{}", text(&out.stdout), text(&out.stderr));
    assert!(!out.status.success(), "{said}");
    assert!(
        said.contains("max_unexplained_rate_radps"),
        "the reason: {said}"
    );
    assert!(!said.contains("No such process"), "{said}");
    for word in said.split(|c: char| c.is_whitespace() || c == '(' || c == ')') {
        if word.starts_with('/') && word.ends_with(".log") {
            assert!(
                std::path::Path::new(word).exists(),
                "names {word}, which does not exist: {said}"
            );
        }
    }
    assert!(said.contains("last lines of its log"), "{said}");
}

fn demo(args: &[&str]) -> String {
    let out = Command::new(bin("thrusterctl"))
        .arg("demo")
        .args(args)
        .output()
        .expect("thrusterctl runs");
    expect_ok(&out, "demo")
}

/// Items 6 and 10, on the aligned vehicle (roll, sway and heave not actuated): one tilt figure
/// for the estimation, the simulator's true one, named; no coefficient printed for roll; and
/// the JSON carries the matrices the text prints, rows named.
#[test]
fn the_demo_says_one_tilt_no_coefficient_of_an_axis_not_actuated_and_gives_its_matrices() {
    let vehicle = system_tests::workspace().join("config/vehicles/aligned.toml");
    let vehicle = vehicle.to_str().unwrap();
    let text = demo(&["--hold-s", "0", "--vehicle", vehicle]);
    assert_eq!(text.matches("tilted up to").count(), 1, "{text}");
    assert!(text.contains("(the simulator's true attitude)"), "{text}");
    assert!(!text.contains("navigation estimate"), "{text}");
    assert!(
        text.contains("   roll: axis not actuated: not identified"),
        "{text}"
    );
    assert!(!text.contains("|p|p"), "{text}");
    assert!(text.contains("pitch: damping q"), "{text}");

    let json: Value =
        serde_json::from_str(&demo(&["--hold-s", "0", "--json", "--vehicle", vehicle]))
            .expect("demo JSON");
    let e = &json["effectiveness"];
    assert_eq!(
        e["rows"],
        serde_json::json!(["roll", "pitch", "yaw", "surge", "sway", "heave"]),
        "{json}"
    );
    for key in ["learned", "truth"] {
        let rows = e[key].as_array().unwrap_or_else(|| panic!("{key}: {json}"));
        assert_eq!(rows.len(), 6, "{key}: {json}");
        assert!(
            rows.iter().all(|r| r.as_array().unwrap().len() == 5),
            "{key}: {json}"
        );
    }
    // The numbers are the model's: the relative rotation error recomputed from them is the
    // one the demo reports.
    let m = |k: &str| -> Vec<f64> {
        e[k].as_array().unwrap()[..3]
            .iter()
            .flat_map(|r| r.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()))
            .collect()
    };
    let (l, t) = (m("learned"), m("truth"));
    let diff: f64 = l
        .iter()
        .zip(&t)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    let norm: f64 = t.iter().map(|b| b * b).sum::<f64>().sqrt();
    let err_rot = json["err_rot"].as_f64().unwrap();
    assert!(
        (diff / norm - err_rot).abs() < 1e-9,
        "{} vs {err_rot}",
        diff / norm
    );
}

/// SIGKILL through kill(2): the test's own child, not reaped yet.
fn kill9(proc: &mut system_tests::Proc) {
    // SAFETY: kill(2) on our own child, which Proc reaps only on exit.
    let rc = unsafe { libc::kill(proc.pid() as i32, libc::SIGKILL) };
    assert_eq!(rc, 0, "kill: {}", std::io::Error::last_os_error());
    proc.wait_timeout(Duration::from_secs(5))
        .expect("a SIGKILLed process is reaped at once");
}

/// Item 11 as the operator met it. A model saved as v2 comes back as v2 after a restart (it
/// came back as v1). Then, in Fault (the simulator gone) with `idle` asked for, a kill -9: the
/// restart says the predecessor was in Fault and stays idle (the marker still said "hold", so
/// a restart would have resumed control the operator had stopped).
#[test]
fn a_saved_model_keeps_its_version_and_a_crash_in_fault_is_told_as_such() {
    let world = World::new("version");
    let op = Operator::new(&world);
    let mut daemon = world.daemon(&STEPPED_DAEMON);
    let (mut sim, mut clock) =
        world.stepped_sim("amour5", &["--noise", "realistic", "--duration", "100000"]);
    clock
        .run_until(&op.status, 5.0, |s| s.samples > 50)
        .expect("samples");
    // Two estimations, in vehicle time; the second after the vehicle has settled from the
    // first's pulses (asked at once it is refused: beyond the identification's budget).
    let (_, first) = estimate_wait_stepped(&world, &mut clock, &op.status, 0, 30.0);
    assert_eq!(first.model_version, 1);
    clock.run_for(5.0);
    let (said, saved) = estimate_wait_stepped(&world, &mut clock, &op.status, 1, 30.0);
    assert!(said.contains("model version 2"), "{said}");
    let version = saved.model_version;
    assert_eq!(version, 2);
    let out = ctl(&world, &["shutdown"]);
    expect_ok(&out, "shutdown");
    assert!(daemon.wait_timeout(Duration::from_secs(20)).is_some());
    sim.stop();
    drop((clock, op));
    let mut sim = world.sim("amour5", &["--noise", "realistic", "--duration", "100000"]);

    // From here on in real time: a daemon in lockstep takes a silent simulator for a pause,
    // not a lost IMU, and this part needs the IMU watchdog's Fault.
    let mut daemon = world.daemon(&[]);
    let back = wait_status(&world, "the restarted daemon", |v| {
        v["samples"].as_u64().unwrap_or(0) > 10
    });
    assert_eq!(back["model_version"].as_u64(), Some(version), "{back}");

    // Hold, lose the simulator: Fault. The operator asks for idle, then the daemon dies.
    let out = ctl(&world, &["hold"]);
    expect_ok(&out, "hold");
    sim.stop();
    wait_status(&world, "Fault", |v| v["state"] == "Fault");
    let out = ctl(&world, &["idle"]);
    let said = expect_ok(&out, "idle in Fault");
    assert!(said.contains("idle after the fault clears"), "{said}");
    // The marker is written off the loop after the answer (a slow disk must not stall it):
    // the crash is meant to come after the idle is on disk. Killed at once, a loaded machine
    // (the whole workspace's tests at once on 2 cores) read the marker from before the idle
    // and resumed control.
    let marker = world.path("state").join("resume");
    let deadline = Instant::now() + Duration::from_secs(10);
    while !std::fs::read_to_string(&marker)
        .is_ok_and(|t| t.contains("resume=idle") && t.contains("state=fault"))
    {
        assert!(
            Instant::now() < deadline,
            "the marker never said idle in Fault: {:?}",
            std::fs::read_to_string(&marker)
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    kill9(&mut daemon);
    let mut daemon = world.daemon(&[]);
    let deadline = Instant::now() + Duration::from_secs(20);
    while !daemon.log_text().contains("did not stop cleanly") {
        assert!(Instant::now() < deadline, "{}", daemon.log_text());
        std::thread::sleep(Duration::from_millis(50));
    }
    let log = daemon.log_text();
    assert!(
        log.contains("it was in Fault and would have recovered to idle"),
        "{log}"
    );
    assert!(!log.contains("resuming control"), "{log}");
    let out = ctl(&world, &["shutdown"]);
    expect_ok(&out, "shutdown");
    assert!(daemon.wait_timeout(Duration::from_secs(20)).is_some());
    world.assert_nothing_left();
}
