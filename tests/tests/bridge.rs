//! The live view end to end: the real `thrusterd run`, `thruster-sim run --realtime` and
//! `thruster-bridge --ws 127.0.0.1:0 --record FILE` as processes on a private namespace, checked
//! by a Foxglove WebSocket client this project did not write (`FoxgloveClient` of the npm
//! package @foxglove/ws-protocol, tests/node, installed by `system_tests::node`): it lists the
//! channels, receives and parses telemetry, calls the `thrusterd/estimate` service (the daemon
//! must then estimate) and a setpoint the operator's checks refuse. The same drain records the
//! session to MCAP, read back by Foxglove's Python `mcap` package.

use std::process::Output;
use std::time::Duration;

use serde_json::Value;
use system_tests::python::read_mcap;
use system_tests::{bin, state, Operator, World};
use thruster_protocol::{DaemonState, RequestKind};

/// Longest the client may take: connect, wait for the daemon's status, call, watch 3 s more.
const CLIENT_S: u64 = 60;

fn client(port: u16) -> (Value, Output) {
    client_with(port, &[])
}

fn client_with(port: u16, args: &[&str]) -> (Value, Output) {
    client_for(port, CLIENT_S, args)
}

/// The client with its time limit (`--watch`: how long it counts).
fn client_for(port: u16, seconds: u64, args: &[&str]) -> (Value, Output) {
    let out = system_tests::node::script("bridge_client.js")
        .arg(format!("ws://127.0.0.1:{port}"))
        .arg(seconds.to_string())
        .args(args)
        .output()
        .expect("node runs tests/node/bridge_client.js");
    let summary = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "the client printed no JSON ({e}), exit {:?}\nstdout: {}\nstderr: {}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (summary, out)
}

#[test]
fn a_foxglove_client_sees_every_topic_live_and_starts_an_estimation_through_a_service() {
    // Install (or find) both readers first: a broken Node or Python setup fails here.
    system_tests::node::node_modules();
    system_tests::python::venv_python();
    let world = World::new("bridge");
    let out = world.path("live.mcap");
    let (mut bridge, port) = world.live_bridge(&out);
    let mut daemon = world.daemon(&["--thrusters", "5"]);
    let mut sim = world.sim("amour5", &["--realtime", "--duration", "120"]);
    let operator = Operator::new(&world);

    let (summary, output) = client(port);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success(),
        "client exit {:?}: {summary}\n{stderr}\nbridge: {}",
        output.status,
        bridge.log_text()
    );
    assert_eq!(summary["subprotocol"], "foxglove.sdk.v1", "{summary}");
    assert_eq!(summary["errors"], Value::Array(vec![]), "{summary}");
    // Every advertised schema (channels, service requests and responses) parses in Foxglove
    // Studio's own parser (tests/node/foxglove_parser.js).
    assert_eq!(summary["schema_errors"], serde_json::json!({}), "{summary}");
    assert!(
        summary["schemas_checked"].as_u64().unwrap() >= 6 + 2 * 6,
        "{summary}"
    );
    // Channels: the recorder's, named by topic leaf, JSON with a JSON Schema.
    for topic in [
        "imu",
        "thrust",
        "telemetry",
        "status",
        "driver_status",
        "truth",
    ] {
        let c = &summary["channels"][topic];
        assert_eq!(c["encoding"], "json", "{topic}: {summary}");
        assert_eq!(c["schemaEncoding"], "jsonschema", "{topic}: {c}");
        assert_eq!(c["schemaIsJson"], true, "{topic}: {c}");
        assert!(
            c["schemaName"].as_str().unwrap().starts_with("thrusterd."),
            "{topic}: {c}"
        );
    }
    // Telemetry received and parsed (200 Hz IMU, telemetry every 10th sample: 20 Hz).
    assert_eq!(summary["json_errors"], 0, "{summary}");
    let count = |t: &str| summary["counts"][t].as_u64().unwrap_or(0);
    assert!(count("imu") >= 200, "{}", summary["counts"]);
    assert!(count("thrust") >= 200, "{}", summary["counts"]);
    assert!(count("telemetry") >= 20, "{}", summary["counts"]);
    assert!(
        summary["first"]["telemetry"]["attitude"].is_array(),
        "{}",
        summary["first"]
    );
    // Services: the operator's requests.
    for name in ["estimate", "abort", "hold", "idle", "stop", "setpoint"] {
        let s = &summary["services"][format!("thrusterd/{name}")];
        assert!(s.is_object(), "no service {name}: {}", summary["services"]);
    }
    // The estimate call: accepted, and the daemon left Idle for the estimation.
    assert_eq!(summary["estimate"]["ok"], true, "{}", summary["estimate"]);
    let idle = DaemonState::Idle as u64;
    assert!(
        summary["states_before_call"]
            .as_array()
            .unwrap()
            .iter()
            .any(|s| s.as_u64() == Some(idle)),
        "{summary}"
    );
    let estimating = [
        DaemonState::MeasureNoise,
        DaemonState::Pulse,
        DaemonState::Settle,
        DaemonState::Solve,
        DaemonState::Active,
    ]
    .map(|s| s as u64);
    assert!(
        summary["states_after_call"]
            .as_array()
            .unwrap()
            .iter()
            .any(|s| s.as_u64().is_some_and(|s| estimating.contains(&s))),
        "no estimation state on the live status after the call: {summary}"
    );
    // The test's own view of the daemon agrees.
    let st = operator
        .wait_status(Duration::from_secs(10), |s| state(s) != DaemonState::Idle)
        .expect("the daemon left Idle after the estimate service");
    assert_ne!(state(&st), DaemonState::Fault, "{st:?}");
    // A request the operator's checks refuse fails with the reason, naming the JSON key.
    assert_eq!(summary["bad_setpoint"]["ok"], false, "{summary}");
    assert!(
        summary["bad_setpoint"]["message"]
            .as_str()
            .unwrap()
            .contains("pitch_deg must be in"),
        "{summary}"
    );

    // Clients offering each subprotocol name connect and see the same channels and services;
    // a refused call answers each with the reason. `foxglove.websocket.v1` (the name older apps
    // offer, Lichtblick 1.10 among them) gets the failure as a response `{"error": ...}`: their
    // ws-protocol client has no `serviceCallFailure` and would wait forever.
    let topics = |v: &Value| -> std::collections::BTreeSet<String> {
        v.as_object().unwrap().keys().cloned().collect()
    };
    for offer in [
        "foxglove.sdk.v1.1",
        "foxglove.websocket.v1",
        "foxglove.sdk.v1",
    ] {
        let (other, output) = client_with(port, &["--quick", "--offer", offer]);
        assert!(output.status.success(), "{offer}: {other}");
        assert_eq!(other["subprotocol"], offer, "{other}");
        assert_eq!(other["errors"], Value::Array(vec![]), "{offer}: {other}");
        assert_eq!(
            other["schema_errors"],
            serde_json::json!({}),
            "{offer}: {other}"
        );
        assert_eq!(
            topics(&other["services"]),
            topics(&summary["services"]),
            "{offer}"
        );
        // Channels appear with their first message: this later client sees at least as many.
        assert!(
            topics(&other["channels"]).is_superset(&topics(&summary["channels"])),
            "{offer}: {} vs {}",
            other["channels"],
            summary["channels"]
        );
        for (topic, c) in summary["channels"].as_object().unwrap() {
            assert_eq!(
                other["channels"][topic]["schemaName"], c["schemaName"],
                "{offer}: {topic}"
            );
        }
        let refused = &other["bad_setpoint"];
        let reason = if offer == "foxglove.websocket.v1" {
            assert_eq!(refused["ok"], true, "{offer}: {refused}");
            let body: Value = serde_json::from_str(refused["response"].as_str().unwrap())
                .expect("the failure as a JSON response");
            body["error"].as_str().unwrap_or_default().to_string()
        } else {
            assert_eq!(refused["ok"], false, "{offer}: {refused}");
            refused["message"].as_str().unwrap_or_default().to_string()
        };
        assert!(
            reason.contains("pitch_deg must be in [-90, 90] degrees, got 100"),
            "{offer}: {refused}"
        );
    }

    // An app opened late (topside, after the vehicle was set up) gets the daemon's state at
    // once: the configuration was published once, at the daemon's start, and the model at the
    // estimation, both long before this client; without the bridge's latch it saw neither
    // within its 2 s. Status comes every 100 ms anyway, telemetry is a stream (not latched).
    // The late client needs a model in force. In real time on a loaded machine (the whole
    // workspace's tests at once on 2 cores) the daemon can miss samples and refuse its first
    // estimate, honestly ("row groups put the lag 12 % apart ...: model rejected"): asked
    // again as an operator would, at most twice, each refusal printed.
    for attempt in 0.. {
        let st = operator
            .wait_status(Duration::from_secs(30), |s| {
                s.model_version > 0 || state(s) == DaemonState::Idle
            })
            .expect("a model, or the daemon idle after a refusal");
        if st.model_version > 0 {
            break;
        }
        assert!(attempt < 2, "three estimations refused: {}", st.text());
        println!("estimation {attempt} refused: {}; asking again", st.text());
        assert!(operator.request(RequestKind::Estimate).is_ok());
        operator
            .wait_status(Duration::from_secs(10), |s| state(s) != DaemonState::Idle)
            .expect("the daemon left Idle for the estimation asked again");
    }
    let (late, output) = client_for(port, 2, &["--watch"]);
    assert!(output.status.success(), "{late}");
    for topic in ["config", "model", "dynamics", "status"] {
        assert!(
            late["counts"][topic].as_u64().unwrap_or(0) >= 1,
            "a late client got no {topic}: {}",
            late["counts"]
        );
    }

    // SIGINT: the bridge finishes the file and reports no loss, no drop.
    bridge.signal("INT");
    let status = bridge
        .wait_timeout(Duration::from_secs(30))
        .expect("the bridge ends on SIGINT");
    let log = bridge.log_text();
    assert!(status.success(), "{log}");
    assert!(
        log.contains("; lost 0; dropped 0 (writer queue full)"),
        "{log}"
    );
    assert!(log.contains("; websocket dropped 0 (queue full)"), "{log}");
    assert!(daemon.stop().success(), "{}", daemon.log_text());
    sim.signal("INT");
    sim.wait_timeout(Duration::from_secs(10));

    // The same drain fed the file: the channels the client saw, every IMU sample in order.
    let rec = read_mcap(&[out]);
    for topic in ["imu", "thrust", "telemetry", "status"] {
        let c = &rec["channels"][topic];
        assert_eq!(c["schema_encoding"], "jsonschema", "{topic}: {rec}");
        assert_eq!(
            c["schema_name"], summary["channels"][topic]["schemaName"],
            "{topic}"
        );
    }
    assert_eq!(rec["channels"]["imu"]["seq_contiguous"], true, "{rec}");
    assert_eq!(rec["metadata"]["thruster-recorder"]["dropped"], "0");

    drop(operator);
    drop(bridge);
    drop(daemon);
    drop(sim);
    world.assert_nothing_left();
}

/// Neither a WebSocket address nor a recording: the bridge refuses to start, saying what to
/// give; a bad config names the file, line and key.
#[test]
fn the_bridge_refuses_to_run_without_a_job_or_with_a_bad_config() {
    let world = World::new("bridgecfg");
    let o = std::process::Command::new(bin("thruster-bridge"))
        .args(["--namespace", &world.namespace()])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("nothing to do"), "{err}");
    let cfg = world.path("b.toml");
    std::fs::write(
        &cfg,
        "namespace = \"x\"\n[websocket]\nlisten = \"nowhere\"\n",
    )
    .unwrap();
    let o = std::process::Command::new(bin("thruster-bridge"))
        .args(["--config", cfg.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("b.toml:3") && err.contains("websocket.listen"),
        "{err}"
    );
}

/// Every schema the bridge declares, including the channels a short session never advertises
/// (model, dynamics, input, config, reconfig, dvl, ...), and each service's request and
/// response, passes Foxglove Studio's own JSON Schema parser (`parseJsonSchema` from the npm
/// package @foxglove/studio-base) and Lichtblick's (its source file, tests/node/lichtblick),
/// tests/node/check_schemas.js: the same schemas as in the recordings, declared from the
/// message types.
#[test]
fn every_declared_schema_passes_the_foxglove_apps_parser() {
    let o = std::process::Command::new(bin("thruster-bridge"))
        .arg("--print-schemas")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let declared: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(declared["channels"].as_array().unwrap().len(), 15);
    let mut node = system_tests::node::script("check_schemas.js")
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("node runs tests/node/check_schemas.js");
    {
        use std::io::Write;
        let mut stdin = node.stdin.take().unwrap();
        stdin.write_all(&o.stdout).unwrap();
    }
    let out = node.wait_with_output().unwrap();
    assert!(out.status.success(), "{out:?}");
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["errors"], serde_json::json!({}), "{report}");
    // Both apps' parsers on every schema.
    assert_eq!(
        report["checked"].as_array().unwrap().len(),
        2 * (15 + 2 * 6),
        "{report}"
    );
    let parser = |p: &str| {
        report["parsers"][p]
            .as_str()
            .unwrap_or_default()
            .to_string()
    };
    assert!(
        parser("foxglove").contains("@foxglove/studio-base"),
        "{report}"
    );
    assert!(
        parser("lichtblick").ends_with("parseJsonSchema.ts"),
        "{report}"
    );
    // The parsers saw the fields: a model has its matrices (as row objects) and every scalar.
    let fields = |what: &str| report["fields"][what].as_u64().unwrap_or(0);
    for p in ["foxglove", "lichtblick"] {
        assert!(fields(&format!("{p} channel model")) >= 15, "{report}");
        assert!(fields(&format!("{p} channel status")) >= 20, "{report}");
    }
}
