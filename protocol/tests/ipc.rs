//! Real iceoryx2 round trips, each test in its own namespace, each leaving nothing on disk.

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use iceoryx2::prelude::CallbackProgression;
use thruster_protocol::services::*;
use thruster_protocol::*;

const TIMEOUT: Duration = Duration::from_secs(5);

fn sample(seq: u64) -> ImuSample {
    ImuSample {
        seq,
        t_ns: seq * 2_500_000,
        gyro: [0.01 * seq as f64, -0.02, 0.03],
        accel: [0.0, 0.0, -9.81],
        ..Default::default()
    }
}

fn model(version: u64) -> ModelMsg {
    let mut m = ModelMsg {
        seq: version,
        version,
        count: 3,
        actuated: ALL_DOFS_MASK,
        ..Default::default()
    };
    m.effectiveness[2][1] = version as f64;
    m
}

/// What iceoryx2 0.10 leaves after every port and node of a namespace was dropped
/// normally: the per-prefix global_mgmt node counter in /dev/shm and empty directories.
fn assert_only_iceoryx_residue(ipc: &IpcConfig) {
    let files = namespace_files(ipc).unwrap();
    let root = ipc.root_dir();
    let expected_dirs = [root.clone(), root.join("nodes"), root.join("services")];
    let (dirs, others): (Vec<PathBuf>, Vec<PathBuf>) = files.into_iter().partition(|p| p.is_dir());
    assert_eq!(dirs, expected_dirs.to_vec(), "directories left");
    assert_eq!(others.len(), 1, "files left: {others:?}");
    let name = others[0].file_name().unwrap().to_string_lossy().to_string();
    assert!(others[0].starts_with(SHM_DIR), "{others:?}");
    assert!(
        name.starts_with(&ipc.prefix()) && name.ends_with(".global_mgmt"),
        "{name}"
    );
}

fn assert_purged(ipc: &IpcConfig) {
    let report = purge_namespace(ipc).unwrap();
    assert!(report.kept.is_empty(), "kept {:?}", report.kept);
    assert_eq!(namespace_files(ipc).unwrap(), Vec::<PathBuf>::new());
    assert!(!ipc.root_dir().exists());
}

#[test]
fn pubsub_round_trip_with_event_wakeup_leaves_nothing() {
    let ipc = NamespaceGuard::unique_for_test("rt").unwrap();
    {
        let driver = ipc.create_node("driver").unwrap();
        let daemon = ipc.create_node("daemon").unwrap();
        let imu_out = Port::<ImuSample>::create(&driver, &ipc).unwrap();
        let thrust_in = Inbox::<ThrustCommand>::create(&driver, &ipc).unwrap();
        let imu_in = Inbox::<ImuSample>::create(&daemon, &ipc).unwrap();
        let thrust_out = Port::<ThrustCommand>::create(&daemon, &ipc).unwrap();
        assert_eq!(imu_out.service_name(), format!("{}/imu", ipc.namespace()));

        let waitset = create_waitset().unwrap();
        let guard = waitset.attach_notification(imu_in.listener()).unwrap();

        for seq in 1..=3 {
            assert_eq!(
                imu_out.send(&sample(seq)).unwrap(),
                1,
                "one subscriber reached"
            );
        }

        // The daemon side wakes through the wait set, drains events, then samples.
        let mut received = Vec::new();
        let start = Instant::now();
        while received.len() < 3 && start.elapsed() < TIMEOUT {
            waitset
                .wait_and_process_once_with_timeout(
                    |id| {
                        if id.has_event_from(&guard) {
                            imu_in.drain_events().unwrap();
                            while let Some(s) = imu_in.recv().unwrap() {
                                received.push(s);
                            }
                        }
                        CallbackProgression::Continue
                    },
                    TIMEOUT,
                )
                .unwrap();
        }
        assert_eq!(received, vec![sample(1), sample(2), sample(3)]);

        // Answer the last sample; the driver waits on its inbox.
        let mut cmd = ThrustCommand::neutral(1, 3, sample(3).t_ns, 4);
        cmd.set_mode(ThrustMode::Controlling);
        cmd.thrusters_mut().copy_from_slice(&[0.5, -0.25, 0.0, 1.0]);
        thrust_out.send(&cmd).unwrap();
        assert!(thrust_in.wait(TIMEOUT).unwrap(), "driver not woken");
        let got = thrust_in.recv().unwrap().expect("command delivered");
        assert_eq!(got, cmd);
        assert_eq!(got.thrusters(), &[0.5, -0.25, 0.0, 1.0]);
        assert_eq!(got.mode().unwrap(), ThrustMode::Controlling);
        assert_eq!(thrust_in.recv().unwrap(), None);
        assert!(!thrust_in.wait(Duration::from_millis(10)).unwrap());
        drop(guard);
    }
    assert_only_iceoryx_residue(&ipc);
    assert_purged(&ipc);
}

#[test]
fn late_joiner_gets_the_last_model_from_history() {
    let ipc = NamespaceGuard::unique_for_test("hist").unwrap();
    {
        let daemon = ipc.create_node("daemon").unwrap();
        let model_out = Port::<ModelMsg>::create(&daemon, &ipc).unwrap();
        assert_eq!(model_out.send(&model(1)).unwrap(), 0, "nobody listens yet");
        model_out.send(&model(2)).unwrap();

        let operator = ipc.create_node("operator").unwrap();
        let model_in = Inbox::<ModelMsg>::create(&operator, &ipc).unwrap();
        // iceoryx2 hands out history only when the publisher updates its connections.
        assert_eq!(model_in.recv().unwrap(), None);
        model_out.update_connections().unwrap();
        let got = model_in.recv().unwrap().expect("history delivered");
        assert_eq!(got.version, 2, "history 1 keeps only the newest model");
        assert_eq!(got, model(2));
        assert_eq!(model_in.recv().unwrap(), None);

        // Later models arrive normally, and recv_latest skips to the newest.
        model_out.send(&model(3)).unwrap();
        model_out.send(&model(4)).unwrap();
        assert_eq!(model_in.recv_latest().unwrap().map(|m| m.version), Some(4));
    }
    assert_only_iceoryx_residue(&ipc);
    assert_purged(&ipc);
}

#[test]
fn status_history_reaches_a_late_joiner_on_the_next_send() {
    let ipc = NamespaceGuard::unique_for_test("stat").unwrap();
    let daemon = ipc.create_node("daemon").unwrap();
    let out = Port::<StatusMsg>::create(&daemon, &ipc).unwrap();
    let mut s = StatusMsg::default();
    s.set_state(DaemonState::Active);
    s.set_text("controlling");
    out.send(&s).unwrap();
    let operator = ipc.create_node("operator").unwrap();
    let inbox = Inbox::<StatusMsg>::create_with_buffer(&operator, &ipc, 1).unwrap();
    s.seq = 2;
    out.send(&s).unwrap();
    // History (seq 0) and the new message (seq 1) with a buffer of 1: only the newest.
    let got = inbox.recv().unwrap().unwrap();
    assert_eq!((got.seq, got.text()), (2, "controlling"));
    assert_eq!(got.state().unwrap(), DaemonState::Active);
    assert_eq!(inbox.recv().unwrap(), None);
}

#[test]
fn several_publishers_can_inject_into_one_topic() {
    let ipc = NamespaceGuard::unique_for_test("inj").unwrap();
    let reader = ipc.create_node("daemon").unwrap();
    let inbox = Inbox::<ReconfigEvent>::create(&reader, &ipc).unwrap();
    let nodes: Vec<_> = (0..4)
        .map(|i| ipc.create_node(&format!("op{i}")).unwrap())
        .collect();
    let ports: Vec<_> = nodes
        .iter()
        .map(|n| Port::<ReconfigEvent>::create(n, &ipc).unwrap())
        .collect();
    for (i, p) in ports.iter().enumerate() {
        let e = ReconfigEvent {
            seq: i as u64 + 1,
            thruster: i as u32,
            count: 6,
            ..Default::default()
        };
        assert_eq!(p.send(&e).unwrap(), 1);
    }
    let mut seen: Vec<u32> = std::iter::from_fn(|| inbox.recv().unwrap())
        .map(|e| e.thruster)
        .collect();
    seen.sort();
    assert_eq!(seen, vec![0, 1, 2, 3]);
}

#[test]
fn namespaces_are_isolated() {
    let a = NamespaceGuard::unique_for_test("isoa").unwrap();
    let b = NamespaceGuard::unique_for_test("isob").unwrap();
    let node_a = a.create_node("a").unwrap();
    let node_b = b.create_node("b").unwrap();
    let out_a = Port::<ImuSample>::create(&node_a, &a).unwrap();
    let in_b = Inbox::<ImuSample>::create(&node_b, &b).unwrap();
    assert_eq!(out_a.send(&sample(1)).unwrap(), 0);
    assert_eq!(in_b.recv().unwrap(), None);
    // Files of each namespace carry only its own prefix.
    for p in namespace_files(&a).unwrap() {
        if p.starts_with(SHM_DIR) {
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            assert!(name.starts_with(&a.prefix()) && !name.starts_with(&b.prefix()));
        } else {
            assert!(p.starts_with(a.root_dir()));
        }
    }
}

#[test]
fn wait_set_deadline_reports_a_silent_sensor() {
    let ipc = NamespaceGuard::unique_for_test("dl").unwrap();
    let node = ipc.create_node("daemon").unwrap();
    let inbox = Inbox::<ImuSample>::create(&node, &ipc).unwrap();
    let waitset = create_waitset().unwrap();
    let guard = waitset
        .attach_deadline(inbox.listener(), Duration::from_millis(30))
        .unwrap();
    let mut missed = false;
    let start = Instant::now();
    waitset
        .wait_and_process_once_with_timeout(
            |id| {
                missed |= id.has_missed_deadline(&guard);
                CallbackProgression::Continue
            },
            TIMEOUT,
        )
        .unwrap();
    assert!(missed, "deadline not reported");
    let waited = start.elapsed();
    assert!(
        waited >= Duration::from_millis(25) && waited < Duration::from_secs(2),
        "{waited:?}"
    );
}

#[test]
fn longest_namespace_fits_socket_paths() {
    let unique = IpcConfig::unique_for_test("long").unwrap();
    let ns = format!("{:-<16}", unique.namespace());
    let ipc = NamespaceGuard::new(IpcConfig::new(&ns).unwrap());
    let node = ipc.create_node("n").unwrap();
    let inbox = Inbox::<ImuSample>::create(&node, &ipc).unwrap();
    let port = Port::<ImuSample>::create(&node, &ipc).unwrap();
    port.send(&sample(1)).unwrap();
    assert!(inbox.wait(TIMEOUT).unwrap());
    assert_eq!(inbox.recv().unwrap(), Some(sample(1)));
}

// ---- request / response ----------------------------------------------------------------

/// Runs a control server on its own thread (ports are not Send, so the thread creates
/// its own node) until it answers a Shutdown request.
fn spawn_server(
    ipc: IpcConfig,
) -> (
    std::thread::JoinHandle<Vec<RequestKind>>,
    mpsc::Receiver<()>,
) {
    let (ready_tx, ready_rx) = mpsc::channel();
    let handle = std::thread::spawn(move || {
        let node = ipc.create_node("daemon").unwrap();
        let server = ControlServer::create(&node, &ipc).unwrap();
        let waitset = create_waitset().unwrap();
        let guard = waitset.attach_notification(server.listener()).unwrap();
        ready_tx.send(()).unwrap();
        let mut seen = Vec::new();
        let mut done = false;
        let start = Instant::now();
        while !done && start.elapsed() < TIMEOUT {
            waitset
                .wait_and_process_once_with_timeout(
                    |id| {
                        if id.has_event_from(&guard) {
                            server.drain_events().unwrap();
                            server
                                .serve(|kind, req| {
                                    seen.push(kind);
                                    match kind {
                                        RequestKind::Status => {
                                            ControlResponse::ok("idle, no model")
                                        }
                                        RequestKind::Estimate => ControlResponse::ok(&format!(
                                            "estimating at power {}",
                                            req.value
                                        )),
                                        RequestKind::Save => ControlResponse::new(
                                            ResponseCode::Failed,
                                            &format!("cannot write {}", req.text),
                                        ),
                                        RequestKind::Shutdown => {
                                            done = true;
                                            ControlResponse::ok("bye")
                                        }
                                        _ => {
                                            ControlResponse::new(ResponseCode::Rejected, "not now")
                                        }
                                    }
                                })
                                .unwrap();
                        }
                        CallbackProgression::Continue
                    },
                    Duration::from_millis(100),
                )
                .unwrap();
        }
        seen
    });
    (handle, ready_rx)
}

#[test]
fn request_response_round_trip() {
    let ipc = NamespaceGuard::unique_for_test("ctl").unwrap();
    {
        let op = ipc.create_node("thrusterctl").unwrap();
        let client = ControlClient::create(&op, &ipc).unwrap();
        // No daemon yet.
        let err = client
            .call(ControlRequest::new(RequestKind::Status), TIMEOUT)
            .unwrap_err();
        assert!(matches!(err, IpcError::NoServer { .. }), "{err}");

        let (server, ready) = spawn_server(ipc.config().clone());
        ready.recv_timeout(TIMEOUT).unwrap();

        let r = client
            .call(ControlRequest::new(RequestKind::Status), TIMEOUT)
            .unwrap();
        assert!(r.is_ok());
        assert_eq!(r.text(), "idle, no model");

        let r = client
            .call(
                ControlRequest::with_value(RequestKind::Estimate, 0.4),
                TIMEOUT,
            )
            .unwrap();
        assert_eq!(r.text(), "estimating at power 0.4");

        let r = client
            .call(
                ControlRequest::with_text(RequestKind::Save, "/nope/m.json"),
                TIMEOUT,
            )
            .unwrap();
        assert_eq!(r.code().unwrap(), ResponseCode::Failed);
        assert_eq!(r.text(), "cannot write /nope/m.json");

        // Invalid requests are answered by the protocol layer; the handler never sees them.
        let r = client
            .call(
                ControlRequest::with_value(RequestKind::Estimate, 2.0),
                TIMEOUT,
            )
            .unwrap();
        assert_eq!(r.code().unwrap(), ResponseCode::InvalidRequest);
        assert_eq!(r.text(), "value = 2 is outside [0, 1]");
        let mut bad = ControlRequest::new(RequestKind::Status);
        bad.kind = 1234;
        let r = client.call(bad, TIMEOUT).unwrap();
        assert_eq!(r.code().unwrap(), ResponseCode::InvalidRequest);
        assert_eq!(r.text(), "kind has unknown value 1234");

        let r = client
            .call(ControlRequest::new(RequestKind::Hold), TIMEOUT)
            .unwrap();
        assert_eq!(r.code().unwrap(), ResponseCode::Rejected);
        assert!(!r.is_ok());

        // A second daemon in the same namespace cannot serve.
        let other = ipc.create_node("daemon2").unwrap();
        assert!(ControlServer::create(&other, &ipc).is_err());

        let r = client
            .call(ControlRequest::new(RequestKind::Shutdown), TIMEOUT)
            .unwrap();
        assert_eq!(r.text(), "bye");
        let seen = server.join().unwrap();
        assert_eq!(
            seen,
            vec![
                RequestKind::Status,
                RequestKind::Estimate,
                RequestKind::Save,
                RequestKind::Hold,
                RequestKind::Shutdown
            ]
        );
    }
    assert_only_iceoryx_residue(&ipc);
    assert_purged(&ipc);
}

#[test]
fn client_times_out_when_the_server_does_not_answer() {
    let ipc = NamespaceGuard::unique_for_test("to").unwrap();
    let daemon = ipc.create_node("daemon").unwrap();
    let _server = ControlServer::create(&daemon, &ipc).unwrap();
    let op = ipc.create_node("op").unwrap();
    let client = ControlClient::create(&op, &ipc).unwrap();
    let start = Instant::now();
    let err = client
        .call(
            ControlRequest::new(RequestKind::Status),
            Duration::from_millis(50),
        )
        .unwrap_err();
    assert!(matches!(err, IpcError::Timeout { .. }), "{err}");
    assert!(start.elapsed() >= Duration::from_millis(50));
}

// ---- cleanup -----------------------------------------------------------------------------

#[test]
fn purge_refuses_while_a_node_is_alive() {
    let ipc = NamespaceGuard::unique_for_test("busy").unwrap();
    let node = ipc.create_node("alive").unwrap();
    let _port = Port::<StatusMsg>::create(&node, &ipc).unwrap();
    match purge_namespace(&ipc) {
        Err(IpcError::NamespaceInUse { alive, .. }) => assert_eq!(alive, 1),
        other => panic!("purge while alive: {other:?}"),
    }
    assert!(ipc
        .root_dir()
        .join("services")
        .read_dir()
        .unwrap()
        .next()
        .is_some());
}

#[test]
fn purge_of_an_unused_namespace_is_a_no_op() {
    let ipc = IpcConfig::unique_for_test("none").unwrap();
    let report = purge_namespace(&ipc).unwrap();
    assert!(report.removed.is_empty() && report.kept.is_empty());
    assert_eq!(report.census, NodeCensus::default());
    assert!(!ipc.root_dir().exists());
}

/// Environment variable that turns `crash_child` into a process that dies holding ports.
const CHILD_NS: &str = "THRUSTER_PROTOCOL_CRASH_CHILD_NS";

/// Not a test on its own: `dead_process_resources_are_cleaned_up` runs this test binary
/// again with only this test and `CHILD_NS` set.
#[test]
#[ignore = "helper process for dead_process_resources_are_cleaned_up"]
fn crash_child() {
    let Ok(ns) = std::env::var(CHILD_NS) else {
        return;
    };
    let ipc = IpcConfig::new(&ns).unwrap();
    let node = ipc.create_node("crasher").unwrap();
    let port = Port::<ImuSample>::create(&node, &ipc).unwrap();
    let inbox = Inbox::<ThrustCommand>::create(&node, &ipc).unwrap();
    let server = ControlServer::create(&node, &ipc).unwrap();
    port.send(&sample(1)).unwrap();
    // Die without running any destructor, as a crash would.
    std::mem::forget((node, port, inbox, server));
    std::process::exit(0);
}

#[test]
fn dead_process_resources_are_cleaned_up() {
    let ipc = NamespaceGuard::unique_for_test("dead").unwrap();
    let status = Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "crash_child",
            "--ignored",
            "--test-threads=1",
            "--quiet",
        ])
        .env(CHILD_NS, ipc.namespace())
        .stdout(Stdio::null())
        .status() // waits, so the child is reaped and really counts as dead
        .unwrap();
    assert!(status.success());

    let files = namespace_files(&ipc).unwrap();
    let count = |suffix: &str| {
        files
            .iter()
            .filter(|p| p.to_string_lossy().ends_with(suffix))
            .count()
    };
    // imu, imu/event, thrust, thrust/event, control, control/event
    assert_eq!(count(".service"), 6, "{files:#?}");
    // One unix socket per listener: the thrust inbox and the control server.
    assert!(
        count(".node_monitor") == 1 && count(".event") == 2,
        "{files:#?}"
    );

    let census = cleanup_dead_nodes(&ipc).unwrap();
    assert_eq!(
        census,
        NodeCensus {
            alive: 0,
            dead_cleaned: 1,
            dead_failed: 0,
            unknown: 0,
            unfinished_removed: 0,
        }
    );
    assert_only_iceoryx_residue(&ipc);

    // The services are usable again, including the single control server slot.
    {
        let node = ipc.create_node("daemon").unwrap();
        let _server = ControlServer::create(&node, &ipc).unwrap();
    }
    assert_purged(&ipc);
}

#[test]
fn new_node_removes_dead_nodes_on_creation() {
    let ipc = NamespaceGuard::unique_for_test("reap").unwrap();
    let status = Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "crash_child",
            "--ignored",
            "--test-threads=1",
            "--quiet",
        ])
        .env(CHILD_NS, ipc.namespace())
        .stdout(Stdio::null())
        .status()
        .unwrap();
    assert!(status.success());
    // iceoryx2's cleanup_dead_nodes_on_creation: the daemon starting after a crashed
    // driver finds a clean namespace and can take the control server slot.
    let node = ipc.create_node("daemon").unwrap();
    let _server = ControlServer::create(&node, &ipc).unwrap();
    let census = cleanup_dead_nodes(&ipc).unwrap();
    assert_eq!((census.alive, census.dead_cleaned), (1, 0));
}

/// iceoryx2's own timed wait turns a timeout into a socket timeout of whole microseconds, and
/// the kernel reads `{0, 0}` as "forever": a remainder like `deadline - now` of a few hundred
/// nanoseconds once hung a real-time simulator in `recvfrom`. Every short timeout, zero
/// included, must come back promptly.
#[test]
fn a_sub_microsecond_wait_returns_instead_of_blocking_forever() {
    let ipc = NamespaceGuard::unique_for_test("shortwait").unwrap();
    let cfg: IpcConfig = (*ipc).clone();
    let (tx, rx) = mpsc::channel();
    // In a thread of its own, so that a wait that blocks forever fails the test instead of
    // hanging it (the thread is then leaked with the process, which ends right after).
    let waiter = std::thread::spawn(move || {
        let node = cfg.create_node("waiter").unwrap();
        let inbox = Inbox::<ImuSample>::create(&node, &cfg).unwrap();
        for timeout in [
            Duration::ZERO,
            Duration::from_nanos(1),
            Duration::from_nanos(300),
            Duration::from_nanos(999),
            Duration::from_micros(1),
        ] {
            let start = Instant::now();
            let notified = inbox.wait(timeout).unwrap();
            tx.send((timeout, notified, start.elapsed())).unwrap();
        }
    });
    for _ in 0..5 {
        let (timeout, notified, took) = rx
            .recv_timeout(TIMEOUT)
            .expect("a short wait blocked for more than 5 s");
        assert!(
            !notified,
            "nothing was sent, yet {timeout:?} reported a notification"
        );
        assert!(took < Duration::from_secs(1), "{timeout:?} took {took:?}");
    }
    waiter.join().unwrap();
}

/// A wait shorter than a scheduler tick ends near its deadline, not a tick or two later: on a
/// socket timeout (iceoryx2's `timed_wait`) a 500 us wait took 5-10 ms on a 100 Hz kernel,
/// and a real-time simulator pacing 1 kHz on it published its samples in bursts of eight.
/// The median of 21 waits is judged, against five times the timeout, so that a busy machine
/// delaying a few wake-ups does not decide it.
#[test]
fn a_short_wait_ends_near_its_deadline() {
    let ipc = NamespaceGuard::unique_for_test("precisewait").unwrap();
    {
        let node = ipc.create_node("waiter").unwrap();
        let inbox = Inbox::<ImuSample>::create(&node, &ipc).unwrap();
        let timeout = Duration::from_micros(500);
        let mut took: Vec<Duration> = (0..21)
            .map(|_| {
                let start = Instant::now();
                assert!(!inbox.wait(timeout).unwrap(), "nothing was sent");
                start.elapsed()
            })
            .collect();
        took.sort();
        let median = took[took.len() / 2];
        assert!(
            median >= timeout,
            "the wait returned before its timeout: {took:?}"
        );
        assert!(
            median < 5 * timeout,
            "a {timeout:?} wait took {median:?} (median of {took:?})"
        );
    }
    assert_only_iceoryx_residue(&ipc);
    assert_purged(&ipc);
}
