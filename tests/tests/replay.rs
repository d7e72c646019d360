//! `thrusterd replay` end to end: a real demo session (thrusterd and thruster-sim as processes,
//! recorded by `thrusterctl demo --record`) replayed offline. The models the daemon swapped in
//! are read from the recording by Foxglove's Python `mcap` package (not our reader) and
//! compared with the replay's, entry for entry and exactly; then the same recording with
//! another stop bound, and a truncated and a corrupted copy.
//!
//! The demo runs on its own private namespace and fails (exit 1) if it leaves a file of it
//! behind; the replay opens no IPC at all.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use serde_json::Value;
use system_tests::bin;
use system_tests::python::{mcap_messages, rewrite_mcap};

/// Entries of a model message compared exactly (6 x count each): the same machine fed the
/// same bits computes the same bits, and both JSON writers (serde_json, Python's repr) print
/// the shortest form that reads back to the same f64, so no tolerance is needed.
const MATRICES: [&str; 3] = ["effectiveness", "std_err", "allocation"];
/// The scalar fields that must match too.
const FIELDS: [&str; 10] = [
    "version",
    "t_ns",
    "count",
    "source",
    "method",
    "actuated",
    "pulses",
    "rel_err_rot",
    "rel_err_acc",
    "provenance",
];

/// One recorded session at a time (as in recording.rs): the demo's and the late recording's
/// processes at once starved the demo's recorder on two busy cores (309 messages lost, the
/// IMU, thrust and vehicle streams alike), the test machine's doing, not the recorder's.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    // A failed test poisons the lock; the others still run.
    ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())
}

fn record_demo(dir: &Path) -> PathBuf {
    let _one = one_at_a_time();
    let out = dir.join("demo.mcap");
    let o = Command::new(bin("thrusterctl"))
        .args(["demo", "--json", "--hold-s", "2", "--seed", "1", "--record"])
        .arg(&out)
        .output()
        .expect("thrusterctl demo runs");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "demo failed: {stderr}");
    // A lost IMU sample or journal entry would make the recording unreplayable.
    assert!(stderr.contains("; lost 0"), "{stderr}");
    out
}

fn replay(args: &[&str], file: &Path) -> Output {
    Command::new(bin("thrusterd"))
        .arg("replay")
        .arg(file)
        .args(args)
        .output()
        .expect("thrusterd replay runs")
}

fn replay_json(args: &[&str], file: &Path) -> Value {
    let o = replay(&[args, &["--json"]].concat(), file);
    assert!(
        o.status.success(),
        "thrusterd replay {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "replay --json printed no JSON ({e}): {}",
            String::from_utf8_lossy(&o.stdout)
        )
    })
}

/// Compares two model messages exactly; returns the number of matrix entries compared.
fn assert_same_model(replayed: &Value, recorded: &Value, what: &str) -> usize {
    for f in FIELDS {
        assert_eq!(replayed[f], recorded[f], "{what}: field {f}");
    }
    let n = recorded["count"].as_u64().expect("count") as usize;
    let mut compared = 0;
    for m in MATRICES {
        // effectiveness and std_err are 6 x 16 (DOF rows), allocation 16 x 6.
        for d in 0..6 {
            for t in 0..n {
                let (r, c) = if m == "allocation" { (t, d) } else { (d, t) };
                // The recording holds matrices as row objects (`[{"row": [...]}]`, what the
                // Foxglove apps parse); `replay --json` prints the message as serde does.
                let (a, b) = (&replayed[m][r][c], &recorded[m][r]["row"][c]);
                // JSON writes a non-finite value as null, on both sides alike.
                if !(a.is_null() && b.is_null()) {
                    let (x, y) = (a.as_f64(), b.as_f64());
                    assert!(
                        x.is_some() && y.is_some(),
                        "{what}: {m}[{r}][{c}]: {a} vs {b}"
                    );
                    assert_eq!(
                        x.unwrap().to_bits(),
                        y.unwrap().to_bits(),
                        "{what}: {m}[{r}][{c}]: replayed {x:?}, recorded {y:?}"
                    );
                }
                compared += 1;
            }
        }
    }
    compared
}

/// The length field of the MCAP record at `at` (opcode u8, then length u64).
fn record_len(bytes: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap())
}

/// The offset of the first chunk record starting at or after `from`, walking the file's
/// top-level records from the magic (the MCAP layout, not our reader).
fn chunk_after(bytes: &[u8], from: usize) -> usize {
    let mut at = 8;
    while at + 9 <= bytes.len() {
        if bytes[at] == 0x06 && at >= from {
            return at;
        }
        at += 9 + record_len(bytes, at) as usize;
    }
    panic!("no chunk after byte {from}");
}

/// The byte offset an error names ("byte offset N: ...").
fn named_offset(stderr: &str) -> u64 {
    let at = stderr
        .find("byte offset ")
        .unwrap_or_else(|| panic!("no byte offset named: {stderr}"));
    stderr[at + "byte offset ".len()..]
        .split(|c: char| !c.is_ascii_digit())
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no number after \"byte offset\": {stderr}"))
}

#[test]
fn a_replayed_demo_reproduces_the_daemons_model_and_answers_for_another_config() {
    system_tests::python::venv_python();
    let dir = tempfile::tempdir().unwrap();
    let file = record_demo(dir.path());

    // 1. The recording's own configuration: the daemon's models, entry for entry.
    let recorded = mcap_messages(std::slice::from_ref(&file), "model");
    assert!(!recorded.is_empty(), "the demo swapped in no model");
    let r = replay_json(&[], &file);
    let models = r["models"].as_array().expect("models");
    assert_eq!(models.len(), recorded.len(), "{r}");
    let mut entries = 0;
    for (i, (a, b)) in models.iter().zip(&recorded).enumerate() {
        entries += assert_same_model(a, b, &format!("swap {}", i + 1));
    }
    assert!(entries >= 3 * 6 * 5, "{entries} entries");
    assert_eq!(r["reproduces_recording"], true, "{r}");
    assert_eq!(r["commands_diverged_at"], Value::Null, "{r}");
    assert!(r["commands_compared"].as_u64().unwrap() > 1000, "{r}");
    assert_eq!(r["divergences"], serde_json::json!([]), "{r}");
    eprintln!(
        "replay reproduced {} model swap(s), {entries} entries exactly; {} commands identical",
        models.len(),
        r["commands_compared"]
    );

    // 2. A looser stop bound: the same samples answer "what would 0.1 have learned". The
    //    estimator stops at the first eligible point below the bound, so no later than the
    //    daemon did (0.05), with its own, different model; made before the replayed commands
    //    left the recorded ones, so it is a valid answer.
    let other = dir.path().join("other.toml");
    std::fs::write(
        &other,
        "[vehicle]\nthrusters = 5\n\n[estimator]\ntarget_rel_err = 0.1\n",
    )
    .unwrap();
    let o = replay_json(&["--config", other.to_str().unwrap()], &file);
    let model = &o["model"];
    assert!(model.is_object(), "no model with the other config: {o}");
    assert_eq!(o["model_valid"], true, "{o}");
    let daemon = &recorded[0];
    assert!(
        model["pulses"].as_u64() <= daemon["pulses"].as_u64(),
        "looser bound, more pulses: {} vs {}",
        model["pulses"],
        daemon["pulses"]
    );
    // The recording's rows are objects (`{"row": [...]}`); compare the numbers.
    let daemon_rows: Vec<Value> = daemon["effectiveness"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["row"].clone())
        .collect();
    assert_eq!(daemon_rows.len(), 6, "{daemon}");
    assert_ne!(model["effectiveness"], Value::Array(daemon_rows), "{o}");
    assert_eq!(o["reproduces_recording"], false, "{o}");
    for key in ["rel_err_rot", "rel_err_acc"] {
        let bound = model[key].as_f64().unwrap();
        assert!(bound > 0.0 && bound < 0.1, "{key} {bound}: {o}");
    }
    assert_eq!(model["actuated"], daemon["actuated"], "{o}");
    // Issue 27: the bit mask alone said nothing; the axes are named beside it.
    assert_eq!(
        model["actuated_dof"],
        serde_json::json!(["roll", "pitch", "yaw", "surge", "heave"]),
        "{o}"
    );
    let n = model["count"].as_u64().unwrap() as usize;
    assert_eq!(n, 5);
    for row in model["effectiveness"].as_array().unwrap() {
        for v in &row.as_array().unwrap()[..n] {
            assert!(v.as_f64().is_some_and(f64::is_finite), "{o}");
        }
    }
    eprintln!(
        "target_rel_err 0.1: {} pulses (daemon: {}), bounds rot {} acc {}",
        model["pulses"], daemon["pulses"], model["rel_err_rot"], model["rel_err_acc"]
    );

    // 3. A truncated and a corrupted copy are refused, naming the byte where they break.
    let bytes = std::fs::read(&file).unwrap();
    let cut = bytes.len() * 2 / 3;
    let truncated = dir.path().join("truncated.mcap");
    std::fs::write(&truncated, &bytes[..cut]).unwrap();
    let o = replay(&["--json"], &truncated);
    let cut_err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(
        !o.status.success(),
        "a truncated file was replayed: {cut_err}"
    );
    assert!(
        o.stdout.is_empty(),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    assert!(cut_err.contains("truncated"), "{cut_err}");
    assert!(named_offset(&cut_err) <= cut as u64, "{cut_err}");

    // 16 bytes flipped in the middle of the first chunk past the file's middle (a flip in a
    // message index between chunks would hurt nothing a replay reads).
    let chunk = chunk_after(&bytes, bytes.len() / 2);
    let mut corrupt = bytes.clone();
    let at = chunk + 9 + (record_len(&bytes, chunk) as usize) / 2;
    for b in &mut corrupt[at..at + 16] {
        *b ^= 0x5a;
    }
    let corrupted = dir.path().join("corrupt.mcap");
    std::fs::write(&corrupted, &corrupt).unwrap();
    let o = replay(&[], &corrupted);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "a corrupt file was replayed: {stderr}");
    assert!(stderr.contains("corrupt"), "{stderr}");
    // Named at the chunk that holds the flipped bytes (it no longer decompresses, or fails
    // its CRC).
    assert_eq!(
        named_offset(&stderr),
        chunk as u64,
        "flipped at {at}: {stderr}"
    );
    eprintln!("truncated at {cut}: {cut_err}corrupted at {at}: {stderr}");

    // 4. The recorder writes zstd chunks; the same recording rewritten by another MCAP writer
    //    (Python's `mcap` Writer: its own chunking, indexes and summary, zstd) replays the same,
    //    entry for entry.
    assert!(
        bytes.windows(4).any(|w| w == b"zstd"),
        "the recording's chunks are not zstd-compressed"
    );
    let rewritten = dir.path().join("python.mcap");
    let info = rewrite_mcap(&rewritten, std::slice::from_ref(&file));
    assert_eq!(info["compression"], "zstd", "{info}");
    assert!(info["messages"].as_u64().unwrap() > 1000, "{info}");
    let again = replay_json(&[], &rewritten);
    assert_eq!(again["reproduces_recording"], true, "{again}");
    let models = again["models"].as_array().expect("models");
    assert_eq!(models.len(), recorded.len(), "{again}");
    for (i, (a, b)) in models.iter().zip(&recorded).enumerate() {
        assert_same_model(a, b, &format!("python rewrite, swap {}", i + 1));
    }
    assert_eq!(
        again["commands_compared"], r["commands_compared"],
        "{again}"
    );
    eprintln!(
        "python-rewritten copy ({} bytes, {} messages, zstd; the recorder's {} bytes) replayed identically",
        info["bytes"],
        info["messages"],
        bytes.len()
    );
}

/// `thrusterctl record` on this world's namespace, started now; returns once the recorder
/// has subscribed to every topic (it writes the file's header then).
fn start_recorder(world: &system_tests::World, out: &Path) -> system_tests::Proc {
    let ns = world.namespace();
    let out_arg = out.to_str().unwrap();
    let mut recorder = system_tests::Proc::spawn(
        "thrusterctl",
        &["--namespace", &ns, "record", "--out", out_arg],
        world.dir.path(),
    );
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    while !out.exists() {
        assert!(recorder.is_running(), "{}", recorder.log_text());
        assert!(
            std::time::Instant::now() < deadline,
            "no {out_arg} after 60 s"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    recorder
}

/// Ends a recorder (SIGINT) and requires a clean exit with nothing lost.
fn stop_recorder(mut recorder: system_tests::Proc) -> String {
    recorder.signal("INT");
    let status = recorder
        .wait_timeout(Duration::from_secs(60))
        .expect("the recorder exits on SIGINT");
    let log = recorder.log_text();
    assert!(status.success(), "recorder: {log}");
    assert!(
        log.contains("; lost 0"),
        "the recorder lost messages: {log}"
    );
    log
}

/// Issue 26 item 5: a recorder that joins late (the pool-day case) gets the configuration
/// (history 1) and the daemon's checkpoints (its whole state, published periodically while
/// idle or holding and after each model swap), and `thrusterd replay` of its file starts
/// from the first checkpoint and reproduces every model swapped in after it, entry for
/// entry, and every command. In vehicle time (a stepped simulator, realistic IMU): the
/// recorder starts 10 vehicle-s after the daemon, an estimation is asked for 11 vehicle-s
/// later (a periodic checkpoint at 20 s is in the file by then). A second recorder that only
/// saw the estimation (no checkpoint: none is taken while an estimation runs) is refused
/// with that reason.
#[test]
fn a_late_recording_replays_from_its_first_checkpoint_and_reproduces_the_swapped_model() {
    use system_tests::vehicle_clock::STEPPED_DAEMON;
    use thruster_protocol::{DaemonState, RequestKind};
    system_tests::python::venv_python();
    let _one = one_at_a_time();
    let world = system_tests::World::new("laterec");
    let op = system_tests::Operator::new(&world);
    let mut daemon = world.daemon(&STEPPED_DAEMON);
    let (mut sim, mut clock) =
        world.stepped_sim("amour5", &["--noise", "realistic", "--duration", "100000"]);
    clock.run_to(10.0);
    let late = world.path("late.mcap");
    let recorder = start_recorder(&world, &late);
    // Paced so the recorder (draining every 10 ms, 128 samples buffered) keeps up: 5x real
    // time at 200 Hz is 1 kHz of samples, as `demo --record` paces.
    clock.pace(5.0);
    clock.run_to(21.0);
    let r = op.request(RequestKind::Estimate);
    assert!(r.is_ok(), "{}", r.text());
    let request_s = clock.now_s();
    // The second recorder: from 1 to 3 vehicle-s into the estimation.
    clock.run_for(1.0);
    let during = world.path("during.mcap");
    let recorder2 = start_recorder(&world, &during);
    clock.run_for(2.0);
    stop_recorder(recorder2);
    let active = clock
        .run_until(&op.status, 60.0, |s| {
            system_tests::state(s) == DaemonState::Active && s.model_version >= 1
        })
        .unwrap_or_else(|| panic!("no model\n{}", daemon.log_text()));
    println!(
        "model v{} after {:.2} vehicle-s of estimation",
        active.model_version,
        clock.now_s() - request_s
    );
    // Holding a while: the swap's checkpoint, and the controller's commands compared too
    // (5 s: the estimation from idle takes 3.2 s, so the file runs past 29 vehicle-s).
    clock.run_for(5.0);
    let summary = stop_recorder(recorder);
    println!("late recorder: {}", summary.trim());
    sim.signal("INT");
    let _ = sim.wait_timeout(Duration::from_secs(30));
    assert!(daemon.stop().success(), "{}", daemon.log_text());
    let log = daemon.log_text();
    let first = log
        .lines()
        .find(|l| l.contains("first checkpoint published"))
        .unwrap_or_else(|| panic!("no checkpoint published: {log}"));
    println!("daemon: {first}");

    // The late file: the configuration (history 1), checkpoints taken after it joined.
    let files = std::slice::from_ref(&late);
    let config = mcap_messages(files, "config");
    assert_eq!(config.len(), 1, "no configuration in a late recording");
    assert!(config[0]["toml"].as_str().unwrap().contains("[checkpoint]"));
    let parts = mcap_messages(files, "checkpoint");
    assert!(!parts.is_empty(), "no checkpoint recorded");
    let first_t = parts[0]["t_ns"].as_u64().unwrap() as f64 * 1e-9;
    assert!(
        (10.0..=21.0).contains(&first_t),
        "first recorded checkpoint at {first_t} vehicle-s"
    );
    let journal = mcap_messages(files, "input");
    assert!(
        journal[0]["seq"].as_u64().unwrap() > 0,
        "the late journal starts at the daemon's start"
    );

    // The replay starts from the first checkpoint and reproduces the swap(s) after it.
    let text = replay(&[], &late);
    let out = String::from_utf8_lossy(&text.stdout);
    assert!(
        text.status.success(),
        "{out}{}",
        String::from_utf8_lossy(&text.stderr)
    );
    println!("{out}");
    assert!(out.contains("started from checkpoint "), "{out}");
    let j = replay_json(&[], &late);
    let c = &j["checkpoint"];
    assert_eq!(
        c["model_version"], 0,
        "the first checkpoint is before any model: {c}"
    );
    assert!(c["imu_count"].as_u64().unwrap() >= 2000, "{c}");
    assert_eq!(j["reproduces_recording"], true, "{}", j["first_difference"]);
    assert!(
        j["commands_diverged_at"].is_null(),
        "{}",
        j["commands_diverged_at"]
    );
    assert!(
        j["divergences"].as_array().unwrap().is_empty(),
        "{}",
        j["divergences"]
    );
    let compared = j["commands_compared"].as_u64().unwrap();
    // Every sample from the checkpoint (at most 21 vehicle-s) to the end (at least 29 s), at 200 Hz.
    assert!(compared >= 1600, "{compared} commands compared");
    let replayed = j["models"].as_array().unwrap();
    let recorded: Vec<Value> = mcap_messages(files, "model")
        .into_iter()
        .filter(|m| m["version"].as_u64().unwrap() > 0)
        .collect();
    assert!(!replayed.is_empty(), "no swap after the checkpoint");
    assert_eq!(replayed.len(), recorded.len(), "swaps replayed vs recorded");
    assert_eq!(replayed[0]["version"], 1);
    let mut entries = 0;
    for (i, (a, b)) in replayed.iter().zip(&recorded).enumerate() {
        entries += assert_same_model(a, b, &format!("swap {}", i + 1));
    }
    assert_eq!(entries as u64, j["entries_compared"].as_u64().unwrap());
    println!(
        "late recording: from checkpoint {} (t {:.3} s, {} bytes), {} swap(s), {entries} entries identical, {compared} commands identical",
        c["id"],
        c["t_ns"].as_u64().unwrap() as f64 * 1e-9,
        c["bytes"],
        replayed.len()
    );

    // The recording made during the estimation only: no checkpoint, refused saying so.
    let o = replay(&[], &during);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success(),
        "a recording without a checkpoint replayed: {stderr}"
    );
    assert!(
        stderr.contains("no checkpoint of the daemon's state to start from"),
        "{stderr}"
    );
    drop(op);
    drop(clock);
    world.assert_nothing_left();
}
