//! The season soak's longer-lived clients: `thrusterctl watch` processes and the recorder,
//! started by the loop and ended here as planned (SIGTERM, every third SIGKILL).

use std::path::{Path, PathBuf};
use std::process::ExitStatus;
use std::time::{Duration, Instant};

use system_tests::season::Ending;
use system_tests::Proc;

use crate::Tally;

/// A watch client and when (vehicle ns) and how it ends.
pub(crate) struct Watch {
    pub(crate) proc: Proc,
    pub(crate) stop_ns: u64,
    pub(crate) ending: Ending,
    pub(crate) started: Instant,
}

/// The recorder session in progress.
pub(crate) struct Recording {
    pub(crate) proc: Proc,
    pub(crate) stop_ns: u64,
    pub(crate) stem: PathBuf,
    pub(crate) started: Instant,
}

/// Least wall time a watch or recorder runs before it is signalled: thrusterctl installs its
/// SIGTERM handler once the command starts waiting, and a signal before that kills it
/// uncleanly (no operator stops a command within a second of starting it).
pub(crate) const MIN_LIFE: Duration = Duration::from_millis(1500);

/// Signals a watch client as planned and reaps it; a SIGTERM must end it cleanly.
pub(crate) fn end_watch(mut w: Watch, tally: &mut Tally) {
    if let Some(rest) = MIN_LIFE.checked_sub(w.started.elapsed()) {
        std::thread::sleep(rest);
    }
    w.proc.signal(w.ending.signal());
    match w.proc.wait_timeout(Duration::from_secs(10)) {
        Some(st) => {
            if w.ending == Ending::Term && !st.success() {
                tally
                    .watch_failures
                    .push(format!("thrusterctl watch exited {st} on SIGTERM"));
            }
        }
        None => tally.watch_failures.push(format!(
            "thrusterctl watch still running 10 s after SIG{}",
            w.ending.signal()
        )),
    }
    let _ = std::fs::remove_file(&w.proc.log);
}

/// Stops the recorder (SIGTERM), counts the files it rotated through and removes them.
pub(crate) fn end_recording(mut r: Recording, dir: &Path, tally: &mut Tally) {
    if let Some(rest) = MIN_LIFE.checked_sub(r.started.elapsed()) {
        std::thread::sleep(rest);
    }
    r.proc.signal("TERM");
    let st: Option<ExitStatus> = r.proc.wait_timeout(Duration::from_secs(60));
    match st {
        Some(st) if st.success() => {}
        other => tally.recorder_failures.push(format!(
            "thrusterctl record ended {other:?}: {}",
            r.proc.log_text().lines().last().unwrap_or("")
        )),
    }
    let stem = r.stem.file_name().unwrap().to_string_lossy().to_string();
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().to_string();
            if name.starts_with(&format!("{stem}.")) || name.starts_with(&format!("{stem}-")) {
                tally.recorded_files += 1;
                tally.recorded_bytes += e.metadata().map_or(0, |m| m.len());
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}
