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

fn record_demo(dir: &Path) -> PathBuf {
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

/// A recorder started after the daemon (the pool-day case, issue 26): it gets the daemon's
/// configuration (published once at start, history 1, reaching a late subscriber because the
/// daemon refreshes its connections with every status), so the file has its `config` channel.
/// Replaying it is still refused, with the reason: the input journal starts after the daemon's
/// start and the machine's state at the recording's start is not in the file (no checkpoint
/// yet; docs/recording.md, "Not done").
#[test]
fn a_late_recording_has_the_configuration_and_its_replay_is_refused_with_the_reason() {
    system_tests::python::venv_python();
    let world = system_tests::World::new("laterec");
    let ns = world.namespace();
    let op = system_tests::Operator::new(&world);
    let mut daemon = world.daemon(&["--thrusters", "5"]);
    let mut sim = world.sim("amour5", &["--realtime", "--duration", "60"]);
    op.wait_status(Duration::from_secs(60), |s| s.samples > 400)
        .unwrap_or_else(|| panic!("no samples\n{}", daemon.log_text()));
    // A journal entry before the recorder joins.
    assert!(op.request(thruster_protocol::RequestKind::Estimate).is_ok());
    std::thread::sleep(Duration::from_millis(500));
    let out = world.path("late.mcap");
    let o = Command::new(bin("thrusterctl"))
        .args(["--namespace", &ns, "record", "--duration-s", "3", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let config = mcap_messages(std::slice::from_ref(&out), "config");
    assert_eq!(config.len(), 1, "no configuration in a late recording");
    assert!(
        config[0]["toml"].as_str().unwrap().contains("[estimator]"),
        "{}",
        config[0]
    );
    assert_eq!(config[0]["truncated"], 0);
    let o = replay(&[], &out);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "a late recording replayed: {stderr}");
    assert!(
        stderr.contains("the input journal starts at entry"),
        "{stderr}"
    );
    assert!(!stderr.contains("no \"config\" channel"), "{stderr}");
    sim.signal("INT");
    let _ = sim.wait_timeout(Duration::from_secs(10));
    assert!(daemon.stop().success(), "{}", daemon.log_text());
}
