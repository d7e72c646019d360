//! The season soak, short: a quarter of a vehicle-hour in lockstep with the day's rhythm 16
//! times faster (a checkpoint every 225 vehicle-s, an estimate every 75 s, a reconfiguration
//! every 225 s, watch clients every 26 s, a recording in every interval) and a status poll
//! every vehicle second. About 50 s of wall time on the 2-core VM. It runs the real `season`
//! binary (which starts thrusterd, thruster-sim and the thrusterctl clients on its own
//! namespace, reaps them and purges it) and asserts its verdict and that its counts are
//! those of the plan.

use std::process::Command;

#[test]
fn a_short_season_leaves_nothing_behind() {
    // The binaries the soak starts; built by `cargo test --workspace` before any test runs.
    for name in ["thrusterd", "thrusterctl", "thruster-sim"] {
        system_tests::bin(name);
    }
    let out = tempfile::tempdir().unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_season"))
        .args([
            "--hours", "0.25", "--scale", "0.0625", "--pace", "20", "--out",
        ])
        .arg(out.path())
        .env("RUST_LOG", "info")
        .output()
        .expect("running season");
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        run.status.success(),
        "season failed ({:?})\n{stdout}\n{stderr}",
        run.status
    );
    assert!(stdout.contains("verdict: PASS"), "{stdout}");

    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["failures"].as_array().unwrap().len(), 0, "{stdout}");
    assert_eq!(summary["left_after_exit"].as_array().unwrap().len(), 0);
    let rows = summary["rows"].as_array().unwrap();
    // start, three checkpoints (225, 450, 675 s), end.
    let labels: Vec<&str> = rows.iter().map(|r| r["label"].as_str().unwrap()).collect();
    assert_eq!(labels, ["start", "h1", "h2", "h3", "end"], "{stdout}");
    let end = rows.last().unwrap();
    let n = |k: &str| end[k].as_u64().unwrap();
    // A poll every vehicle second of 900: 899 (the one at 900 s is the end).
    assert_eq!(n("polls_process") + n("polls_inproc"), 899, "{stdout}");
    assert!(
        n("polls_process") >= 10,
        "some polls were real processes: {stdout}"
    );
    assert_eq!(n("polls_failed"), 0);
    // The first estimate and one every 75 s from 37.5 s.
    assert_eq!(n("estimates"), 13, "{stdout}");
    assert_eq!(n("reconfigs"), 3, "{stdout}");
    assert_eq!(n("watches_started"), 34, "{stdout}");
    assert_eq!(n("recordings"), 4, "{stdout}");
    assert!(
        n("recorded_files") >= 4,
        "every session wrote a file: {stdout}"
    );
    // The link: 200 Hz for at least 900 vehicle s, every sample counted, every command on time.
    let link = &end["link"];
    assert!(link["published"].as_u64().unwrap() >= 180_000, "{stdout}");
    assert_eq!(link["uncounted"].as_u64(), Some(0));
    assert_eq!(link["missed"].as_u64(), Some(0));
    assert_eq!(link["commands_rejected"].as_u64(), Some(0));
    assert_eq!(link["unanswered"].as_u64(), Some(0));
    // The processes were measured (a zero would mean /proc was not read).
    assert!(end["daemon"]["rss_kib"].as_u64().unwrap() > 1000);
    assert!(end["daemon"]["fds"].as_u64().unwrap() > 3);
    assert!(end["files"]["shm_files"].as_u64().unwrap() > 0);
}
