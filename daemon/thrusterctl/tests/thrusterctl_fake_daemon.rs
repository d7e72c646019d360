//! The real thrusterctl binary against a scripted stand-in for thrusterd (a thread with
//! the daemon's end of every service): request encoding, output, exit codes, and that
//! published messages still arrive after thrusterctl has exited.
//!
//! The real daemon is covered by the system tests; this pins thrusterctl's side of the
//! protocol without depending on estimation timing.

use std::path::PathBuf;
use std::process::{Command, Output, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde_json::Value;
use thruster_protocol::services::{ControlServer, Inbox, IpcConfig, NamespaceGuard, Port};
use thruster_protocol::{
    ControlRequest, ControlResponse, DaemonState, Dof, ModelMethod, ModelMsg, ModelSource,
    ReconfigEvent, ReconfigKind, RequestKind, ResponseCode, Setpoint, StatusMsg,
};

const TICK: Duration = Duration::from_millis(10);

/// How the stand-in behaves.
#[derive(Clone)]
struct Script {
    /// Answer to every request except Estimate.
    respond: fn(RequestKind, &ControlRequest) -> ControlResponse,
    /// Answer to Estimate; when Ok, `estimation` is played, one step per `step`.
    estimate: ControlResponse,
    estimation: Vec<(StatusMsg, Option<ModelMsg>)>,
    step: Duration,
    status: StatusMsg,
    model: Option<ModelMsg>,
}

/// What the stand-in received.
#[derive(Default, Debug)]
struct Received {
    requests: Vec<ControlRequest>,
    setpoints: Vec<Setpoint>,
    reconfigs: Vec<ReconfigEvent>,
}

struct FakeDaemon {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<Received>>,
    status_tx: mpsc::Sender<StatusMsg>,
}

impl FakeDaemon {
    fn start(ipc: &IpcConfig, script: Script) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = mpsc::channel();
        let (status_tx, status_rx) = mpsc::channel::<StatusMsg>();
        let ipc = ipc.clone();
        let stop_flag = stop.clone();
        // iceoryx2 ports are not Send: everything lives on the thread.
        let handle = std::thread::spawn(move || {
            let node = ipc.create_node("fake-thrusterd").unwrap();
            let server = ControlServer::create(&node, &ipc).unwrap();
            let status_port = Port::<StatusMsg>::create(&node, &ipc).unwrap();
            let model_port = Port::<ModelMsg>::create(&node, &ipc).unwrap();
            let setpoints = Inbox::<Setpoint>::create(&node, &ipc).unwrap();
            let reconfigs = Inbox::<ReconfigEvent>::create(&node, &ipc).unwrap();
            ready_tx.send(()).unwrap();
            let mut received = Received::default();
            let mut status = script.status;
            let mut plan: Vec<(StatusMsg, Option<ModelMsg>)> = Vec::new();
            let mut next_step = Instant::now();
            if let Some(m) = script.model {
                model_port.send(&m).unwrap();
            }
            while !stop_flag.load(Ordering::SeqCst) {
                // Inputs before control requests, as thrusterd does (thrusterctl's
                // delivery barrier relies on it).
                while let Some(sp) = setpoints.recv().unwrap() {
                    received.setpoints.push(sp);
                }
                while let Some(ev) = reconfigs.recv().unwrap() {
                    received.reconfigs.push(ev);
                }
                server
                    .serve(|kind, req| {
                        received.requests.push(*req);
                        if kind == RequestKind::Estimate {
                            if script.estimate.is_ok() {
                                plan = script.estimation.iter().rev().copied().collect();
                            }
                            script.estimate
                        } else {
                            (script.respond)(kind, req)
                        }
                    })
                    .unwrap();
                // A daemon numbers its statuses on, whatever they say: `watch` takes a
                // sequence number going back for a restarted daemon.
                let seq = status.seq;
                while let Ok(s) = status_rx.try_recv() {
                    status = StatusMsg { seq, ..s };
                }
                if Instant::now() >= next_step {
                    if let Some((s, m)) = plan.pop() {
                        status = StatusMsg { seq, ..s };
                        if let Some(m) = m {
                            model_port.send(&m).unwrap();
                        }
                    }
                    next_step = Instant::now() + script.step;
                }
                status.seq += 1;
                status.vehicle_time_ns += TICK.as_nanos() as u64;
                status_port.send(&status).unwrap();
                model_port.update_connections().unwrap();
                std::thread::sleep(TICK);
            }
            received
        });
        ready_rx
            .recv_timeout(Duration::from_secs(10))
            .expect("fake daemon ready");
        Self {
            stop,
            handle: Some(handle),
            status_tx,
        }
    }

    /// Replaces the published status from the next tick on.
    fn set_status(&self, s: StatusMsg) {
        self.status_tx.send(s).unwrap();
    }

    /// Stops the thread (after a few more ticks, so late messages are read) and returns
    /// what it received.
    fn finish(mut self) -> Received {
        std::thread::sleep(5 * TICK);
        self.stop.store(true, Ordering::SeqCst);
        self.handle
            .take()
            .unwrap()
            .join()
            .expect("fake daemon thread")
    }
}

impl Drop for FakeDaemon {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn status(state: DaemonState, version: u64) -> StatusMsg {
    let mut s = StatusMsg {
        pulses_planned: 2,
        power: 0.5,
        sigma_rot: 0.01,
        sigma_acc: 0.05,
        samples: 1000,
        model_version: version,
        imu_rate_hz: 400.0,
        vehicle_time_ns: 1_000_000_000,
        ..StatusMsg::default()
    };
    s.set_state(state);
    s
}

fn pulse(state: DaemonState, i: u32, version: u64) -> StatusMsg {
    StatusMsg {
        pulse: i,
        error_bound: 0.2 / f64::from(i + 1),
        ..status(state, version)
    }
}

fn model(version: u64) -> ModelMsg {
    let mut m = ModelMsg {
        version,
        count: 2,
        actuated: Dof::Yaw.mask() | Dof::Surge.mask(),
        rel_err_rot: 0.05,
        rel_err_acc: 0.12,
        ..ModelMsg::default()
    };
    m.set_source(ModelSource::Estimated);
    m.set_method(ModelMethod::Forward);
    m.effectiveness[Dof::Yaw.index()][..2].copy_from_slice(&[1.5, -1.5]);
    m.effectiveness[Dof::Surge.index()][..2].copy_from_slice(&[0.8, 0.8]);
    m.std_err[Dof::Yaw.index()][..2].copy_from_slice(&[0.01, f64::NAN]);
    m.allocation[0][Dof::Yaw.index()] = 1.0 / 3.0;
    m.allocation[0][Dof::Surge.index()] = 0.625;
    m.allocation[1][Dof::Yaw.index()] = -1.0 / 3.0;
    m.allocation[1][Dof::Surge.index()] = 0.625;
    m
}

fn refuse_abort(kind: RequestKind, _: &ControlRequest) -> ControlResponse {
    match kind {
        RequestKind::Abort => ControlResponse::new(ResponseCode::Rejected, "nothing to abort"),
        RequestKind::Status => ControlResponse::ok("Active"),
        _ => ControlResponse::ok("done"),
    }
}

fn script() -> Script {
    Script {
        respond: refuse_abort,
        estimate: ControlResponse::ok("estimating"),
        estimation: Vec::new(),
        step: Duration::from_millis(30),
        status: status(DaemonState::Active, 1),
        model: Some(model(1)),
    }
}

fn thrusterctl(ipc: &IpcConfig, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_thrusterctl"))
        .args(["--namespace", ipc.namespace(), "--timeout-ms", "2000"])
        .args(args)
        .output()
        .expect("thrusterctl runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn expect_code(out: &Output, code: i32) {
    assert_eq!(
        out.status.code(),
        Some(code),
        "stdout: {}\nstderr: {}",
        text(&out.stdout),
        text(&out.stderr)
    );
}

#[test]
fn status_text_and_json() {
    let guard = NamespaceGuard::unique_for_test("fake").unwrap();
    let daemon = FakeDaemon::start(&guard, script());
    let out = thrusterctl(&guard, &["status"]);
    expect_code(&out, 0);
    let stdout = text(&out.stdout);
    assert!(stdout.contains("  state        Active\n"), "{stdout}");
    assert!(stdout.contains("  model        version 1\n"), "{stdout}");

    let out = thrusterctl(&guard, &["status", "--json"]);
    expect_code(&out, 0);
    let v: Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(v["state"], "Active");
    assert_eq!(v["model_version"], 1);
    assert_eq!(v["imu_rate_hz"], 400.0);
    // One JSON key per wire field but the padding (`reserved`, since v3 added the supply),
    // so a field added to the protocol cannot be forgotten here, plus the driver's own report
    // beside them (null: this fake has no driver).
    let wire = serde_json::to_value(thruster_protocol::StatusMsg::default()).unwrap();
    let wire = wire.as_object().unwrap();
    assert!(wire.contains_key("reserved"));
    assert!(!v.as_object().unwrap().contains_key("reserved"));
    assert_eq!(v.as_object().unwrap().len(), wire.len() - 1 + 1);
    assert!(v["driver"].is_null(), "{v}");
    assert!(
        stdout.contains("  driver       no driver status published"),
        "{stdout}"
    );
    assert_eq!(v["requests_refused"], 0);
    let received = daemon.finish();
    assert!(received
        .requests
        .iter()
        .all(|r| r.kind().unwrap() == RequestKind::Status));
}

#[test]
fn model_text_and_json() {
    let guard = NamespaceGuard::unique_for_test("fake").unwrap();
    let _daemon = FakeDaemon::start(&guard, script());
    let out = thrusterctl(&guard, &["model"]);
    expect_code(&out, 0);
    let stdout = text(&out.stdout);
    assert!(
        stdout.starts_with("model version 1: 2 thrusters, source Estimated"),
        "{stdout}"
    );
    assert!(
        stdout.contains("NOT actuated:  roll, pitch, sway, heave"),
        "{stdout}"
    );
    assert!(stdout.contains("│████"), "{stdout}");

    let out = thrusterctl(&guard, &["model", "--json"]);
    expect_code(&out, 0);
    let v: Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(v["version"], 1);
    assert_eq!(v["effectiveness"][2], serde_json::json!([1.5, -1.5]));
    assert_eq!(v["std_err"][2], serde_json::json!([0.01, null]));
    assert_eq!(v["allocation"].as_array().unwrap().len(), 2);
}

#[test]
fn commands_print_the_answer_and_refusals_exit_4() {
    let guard = NamespaceGuard::unique_for_test("fake").unwrap();
    let daemon = FakeDaemon::start(&guard, script());
    let out = thrusterctl(&guard, &["hold"]);
    expect_code(&out, 0);
    assert_eq!(text(&out.stdout), "thrusterd: done\n");

    let out = thrusterctl(&guard, &["abort"]);
    expect_code(&out, 4);
    assert!(text(&out.stderr).contains("thrusterd refused (Rejected): nothing to abort"));

    let out = thrusterctl(&guard, &["save", "relative/model.toml"]);
    expect_code(&out, 0);
    let out = thrusterctl(&guard, &["estimate", "--power", "0.3"]);
    expect_code(&out, 0);
    assert_eq!(text(&out.stdout), "estimation started: estimating\n");

    let received = daemon.finish();
    let kinds: Vec<RequestKind> = received
        .requests
        .iter()
        .map(|r| r.kind().unwrap())
        .collect();
    assert_eq!(
        kinds,
        [
            RequestKind::Hold,
            RequestKind::Abort,
            RequestKind::Save,
            RequestKind::Estimate
        ]
    );
    let save = received.requests[2].text.as_str();
    let expected = std::env::current_dir().unwrap().join("relative/model.toml");
    assert_eq!(PathBuf::from(save), expected);
    assert_eq!(received.requests[3].value, 0.3);
}

#[test]
fn estimate_wait_follows_to_the_new_model() {
    let guard = NamespaceGuard::unique_for_test("fake").unwrap();
    let mut s = script();
    s.estimation = vec![
        (status(DaemonState::MeasureNoise, 1), None),
        (pulse(DaemonState::Pulse, 0, 1), None),
        (pulse(DaemonState::Settle, 0, 1), None),
        (pulse(DaemonState::Pulse, 1, 1), None),
        (pulse(DaemonState::Settle, 1, 1), None),
        (status(DaemonState::Solve, 1), None),
        (status(DaemonState::Active, 2), Some(model(2))),
    ];
    let _daemon = FakeDaemon::start(&guard, s);
    let out = thrusterctl(&guard, &["estimate", "--wait"]);
    expect_code(&out, 0);
    assert_eq!(
        text(&out.stdout),
        "estimation done: model version 2 (Estimated, Forward), relative error bound 5.0 % \
         rotation, 12.0 % translation; daemon Active\n"
    );
    // Not a terminal: progress comes as plain lines on stderr.
    let stderr = text(&out.stderr);
    assert!(stderr.contains("pulse 2 of 2"), "{stderr}");
    assert!(stderr.contains("measuring noise"), "{stderr}");
}

#[test]
fn estimate_wait_reports_a_fault_with_exit_6() {
    let guard = NamespaceGuard::unique_for_test("fake").unwrap();
    let mut s = script();
    let mut fault = status(DaemonState::Fault, 1);
    fault.set_text("IMU stale for 100 ms");
    s.estimation = vec![(status(DaemonState::MeasureNoise, 1), None), (fault, None)];
    let _daemon = FakeDaemon::start(&guard, s);
    let out = thrusterctl(&guard, &["estimate", "--wait"]);
    expect_code(&out, 6);
    assert!(
        text(&out.stderr).contains("estimation failed: daemon in Fault: IMU stale for 100 ms"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn estimate_refused_exits_4() {
    let guard = NamespaceGuard::unique_for_test("fake").unwrap();
    let mut s = script();
    s.estimate = ControlResponse::new(ResponseCode::Busy, "already estimating");
    let _daemon = FakeDaemon::start(&guard, s);
    let out = thrusterctl(&guard, &["estimate", "--wait"]);
    expect_code(&out, 4);
    assert!(text(&out.stderr).contains("refused (Busy): already estimating"));
}

#[test]
fn published_messages_arrive_after_thrusterctl_exits() {
    let guard = NamespaceGuard::unique_for_test("fake").unwrap();
    let daemon = FakeDaemon::start(&guard, script());
    let out = thrusterctl(
        &guard,
        &[
            "setpoint", "--roll", "0", "--pitch", "0", "--yaw", "90", "--depth", "2.5",
        ],
    );
    expect_code(&out, 0);
    assert!(text(&out.stdout).starts_with("setpoint sent to 1 subscriber(s)"));
    let vehicle = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/vehicles/amour5_top45.toml"
    );
    let out = thrusterctl(
        &guard,
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
    );
    expect_code(&out, 0);
    let received = daemon.finish();

    assert_eq!(received.setpoints.len(), 1);
    let sp = received.setpoints[0];
    let h = std::f64::consts::FRAC_1_SQRT_2;
    for (got, want) in sp.attitude.iter().zip([h, 0.0, 0.0, h]) {
        assert!((got - want).abs() < 1e-12, "{:?}", sp.attitude);
    }
    assert!(sp.hold_depth());
    assert_eq!(sp.depth, 2.5);

    assert_eq!(received.reconfigs.len(), 1);
    let ev = received.reconfigs[0];
    assert_eq!(ev.kind().unwrap(), ReconfigKind::ThrusterMoved);
    assert_eq!((ev.thruster, ev.count), (0, 5));
    assert!(ev.geometry_declared());
    // Thruster T of amour5_top45, from the default CG (2 cm below the CO).
    for (got, want) in ev.position[0].iter().zip([0.2, 0.0, -0.17]) {
        assert!((got - want).abs() < 1e-12, "{:?}", ev.position[0]);
    }
    assert!((ev.direction[0][1] - h).abs() < 1e-12);
}

#[test]
fn watch_prints_changes_until_interrupted() {
    let guard = NamespaceGuard::unique_for_test("fake").unwrap();
    let daemon = FakeDaemon::start(&guard, script());
    let child = Command::new(env!("CARGO_BIN_EXE_thrusterctl"))
        .args(["--namespace", guard.namespace(), "watch"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn watch");
    std::thread::sleep(Duration::from_millis(500));
    let mut s = status(DaemonState::Fault, 1);
    s.set_text("IMU stale");
    daemon.set_status(s);
    std::thread::sleep(Duration::from_millis(500));
    let interrupted = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("kill -INT");
    assert!(interrupted.success());
    let out = child.wait_with_output().expect("watch exits");
    expect_code(&out, 0);
    let stdout = text(&out.stdout);
    let lines: Vec<&str> = stdout.lines().collect();
    // Dozens of statuses were published, only the two distinct ones are printed.
    assert_eq!(lines.len(), 2, "{stdout}");
    assert!(lines[0].contains("Active"), "{stdout}");
    assert!(
        lines[1].contains("Fault") && lines[1].ends_with("| IMU stale"),
        "{stdout}"
    );
}
