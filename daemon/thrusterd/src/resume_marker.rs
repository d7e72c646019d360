//! The resume marker: a small file in the state directory that exists while a thrusterd
//! runs and says what it would resume after a crash.
//!
//! systemd restarts a crashed daemon (`Restart=on-failure`) within seconds, usually with the
//! vehicle in the water. A restarted daemon that sat idle would leave the vehicle drifting; one
//! that always held attitude at start would spin the thrusters on deck. The marker tells the two
//! apart: it is written at start, kept up to date when the daemon starts or stops keeping the
//! vehicle under control, and removed on a clean stop (SIGINT/SIGTERM, `thrusterctl shutdown`).
//! Finding it at start means the predecessor died (SIGKILL, panic, abort, power loss), and its
//! content says whether it was controlling (or estimating, which also moves the vehicle).
//!
//! Failures to write it (read-only or full state directory) are logged once and otherwise
//! ignored: the marker only decides what a restart resumes, never whether the daemon runs.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use tracing::warn;

/// File name of the marker inside the state directory.
pub const MARKER_FILE: &str = "resume";

/// The marker's name before 2026-11-27 ("session" now means the lab's run of the processes
/// only): read at start when there is no [`MARKER_FILE`], then removed, so a daemon updated
/// while its predecessor's marker was on the disk still resumes.
const LEGACY_FILE: &str = "session";

/// What a restarted daemon resumes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Intent {
    /// Thrusters neutral until an operator asks for something.
    Idle,
    /// Hold attitude with the saved model.
    Hold,
}

impl Intent {
    fn word(self) -> &'static str {
        match self {
            Intent::Idle => "idle",
            Intent::Hold => "hold",
        }
    }
}

pub struct ResumeMarker {
    path: PathBuf,
    /// What was last handed to the writer (a repeat is not written again).
    queued: Option<(Intent, bool)>,
    previous_in_fault: bool,
    /// The thread that writes the marker; None when it could not be started (then the
    /// marker is written on the caller's thread, said once).
    writer: Option<MarkerWriter>,
    warned: bool,
}

/// What the marker's thread is asked to do. Only the newest matters: a write superseded by a
/// queued one is skipped.
enum Msg {
    Write(Intent, bool),
    /// Answered once everything queued before it is on the disk (tests).
    #[cfg(test)]
    Sync(mpsc::Sender<()>),
    /// Remove the marker (a clean stop), then end.
    Finish(mpsc::Sender<()>),
}

/// The marker's writes leave the control thread: the marker changes with the state (a fault,
/// a hold), and a write and rename on a stalled disk would hold the loop for as long as the
/// disk (perf sched saw the control thread in `blkdev_issue_discard` at a state change).
struct MarkerWriter {
    tx: mpsc::Sender<Msg>,
}

impl MarkerWriter {
    fn spawn(path: PathBuf) -> std::io::Result<MarkerWriter> {
        let (tx, rx) = mpsc::channel::<Msg>();
        std::thread::Builder::new()
            .name("resume-marker".into())
            .spawn(move || {
                crate::solver::lower_priority();
                let mut warned = false;
                let mut next = None;
                while let Some(mut msg) = next.take().or_else(|| rx.recv().ok()) {
                    // A write followed by another write is skipped: only the newest matters.
                    while let Msg::Write(..) = msg {
                        match rx.try_recv() {
                            Ok(newer @ Msg::Write(..)) => msg = newer,
                            Ok(other) => {
                                next = Some(other);
                                break;
                            }
                            Err(_) => break,
                        }
                    }
                    match msg {
                        Msg::Write(intent, in_fault) => {
                            write_marker(&path, intent, in_fault, &mut warned)
                        }
                        #[cfg(test)]
                        Msg::Sync(done) => {
                            let _ = done.send(());
                        }
                        Msg::Finish(done) => {
                            remove_marker(&path);
                            let _ = done.send(());
                            break;
                        }
                    }
                }
            })?;
        Ok(MarkerWriter { tx })
    }
}

impl ResumeMarker {
    /// Reads the marker a predecessor left (None: it stopped cleanly, or this is the first
    /// start) and starts this daemon's own. Called once, before the loop: it reads a file.
    pub fn open(state_dir: &Path) -> (ResumeMarker, Option<Intent>) {
        let path = state_dir.join(MARKER_FILE);
        let legacy = state_dir.join(LEGACY_FILE);
        let mut previous_in_fault = false;
        let read = match fs::read_to_string(&path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                let read = fs::read_to_string(&legacy);
                if read.is_ok() {
                    let _ = fs::remove_file(&legacy);
                }
                read
            }
            read => read,
        };
        let previous = match read {
            Ok(text) => {
                previous_in_fault = text.lines().any(|l| l == "state=fault");
                Some(parse(&text))
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => {
                warn!("{}: {e}; resuming idle", path.display());
                Some(Intent::Idle)
            }
        };
        let writer = MarkerWriter::spawn(path.clone())
            .map_err(|e| {
                warn!(
                    "the resume marker's thread did not start ({e}): written on the control thread"
                )
            })
            .ok();
        let marker = ResumeMarker {
            path,
            queued: None,
            previous_in_fault,
            writer,
            warned: false,
        };
        (marker, previous)
    }

    /// Marks what a restart would resume (never waits: the write is the marker thread's).
    pub fn record(&mut self, intent: Intent) {
        self.write(intent, false);
    }

    /// As [`ResumeMarker::record`], marked as in Fault: a restart says so, and resumes what
    /// clearing the fault would have resumed.
    pub fn record_in_fault(&mut self, intent: Intent) {
        self.write(intent, true);
    }

    /// The predecessor's marker said it was in Fault.
    pub fn previous_in_fault(&self) -> bool {
        self.previous_in_fault
    }

    fn write(&mut self, intent: Intent, in_fault: bool) {
        if self.queued == Some((intent, in_fault)) {
            return;
        }
        self.queued = Some((intent, in_fault));
        let sent = self
            .writer
            .as_ref()
            .is_some_and(|w| w.tx.send(Msg::Write(intent, in_fault)).is_ok());
        if !sent {
            self.writer = None;
            write_marker(&self.path, intent, in_fault, &mut self.warned);
        }
    }

    /// Waits up to `within` until every marker handed over is written; false if not by then.
    #[cfg(test)]
    pub fn sync(&self, within: Duration) -> bool {
        let Some(w) = self.writer.as_ref() else {
            return true;
        };
        let (done, rx) = mpsc::channel();
        w.tx.send(Msg::Sync(done)).is_ok() && rx.recv_timeout(within).is_ok()
    }

    /// A clean stop: the marker is removed (after any write still queued), waiting at most
    /// `within` for the disk (the thrusters are already neutral; a stalled disk must not keep
    /// the process from exiting, and then the next start reads the last marker written).
    pub fn finish(self, within: Duration) {
        let Some(w) = self.writer.as_ref() else {
            return remove_marker(&self.path);
        };
        let (done, rx) = mpsc::channel();
        if w.tx.send(Msg::Finish(done)).is_err() {
            return remove_marker(&self.path);
        }
        if rx.recv_timeout(within).is_err() {
            warn!(
                "{}: not removed within {} s (a stalled disk?): the next start will read it as a crash",
                self.path.display(),
                within.as_secs_f64()
            );
        }
    }
}

/// Writes the marker (a temporary file renamed over it). Failures are logged once.
fn write_marker(path: &Path, intent: Intent, in_fault: bool, warned: &mut bool) {
    let tmp = path.with_extension("tmp");
    let state = if in_fault { "state=fault\n" } else { "" };
    let text = format!("thrusterd resume marker\nresume={}\n{state}", intent.word());
    let result = path
        .parent()
        .map_or(Ok(()), fs::create_dir_all)
        .and_then(|()| fs::write(&tmp, text))
        .and_then(|()| fs::rename(&tmp, path));
    if let Err(e) = result {
        let _ = fs::remove_file(&tmp);
        if !*warned {
            warn!(
                "{}: {e}; a restart after a crash will not resume control",
                path.display()
            );
            *warned = true;
        }
    }
}

fn remove_marker(path: &Path) {
    if let Err(e) = fs::remove_file(path) {
        if e.kind() != std::io::ErrorKind::NotFound {
            warn!("{}: {e}", path.display());
        }
    }
}

fn parse(text: &str) -> Intent {
    match text.lines().find_map(|l| l.strip_prefix("resume=")) {
        Some("hold") => Intent::Hold,
        _ => Intent::Idle,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const WAIT: Duration = Duration::from_secs(10);

    /// The newest of a burst of changes is what ends on the disk, and a finish queued behind
    /// writes removes the marker after them.
    #[test]
    fn the_newest_marker_wins_and_finish_removes_it_after_queued_writes() {
        let dir = tempfile::tempdir().unwrap();
        let (mut s, _) = ResumeMarker::open(dir.path());
        for k in 0..200 {
            if k % 2 == 0 {
                s.record(Intent::Hold);
            } else {
                s.record_in_fault(Intent::Idle);
            }
        }
        s.record(Intent::Hold);
        assert!(s.sync(WAIT));
        let text = fs::read_to_string(dir.path().join(MARKER_FILE)).unwrap();
        assert_eq!(text, "thrusterd resume marker\nresume=hold\n");
        s.record(Intent::Idle);
        s.finish(WAIT);
        assert!(
            !dir.path().join(MARKER_FILE).exists(),
            "removed after the queued write"
        );
        assert!(!dir.path().join("resume.tmp").exists());
    }

    #[test]
    fn a_marker_left_behind_gives_the_predecessors_intent_and_a_clean_stop_removes_it() {
        let dir = tempfile::tempdir().unwrap();
        let (mut s, previous) = ResumeMarker::open(dir.path());
        assert_eq!(previous, None);
        s.record(Intent::Hold);
        assert!(s.sync(WAIT), "the marker's thread wrote it");
        // The process dies here: the next start sees the marker.
        let (mut s2, previous) = ResumeMarker::open(dir.path());
        assert_eq!(previous, Some(Intent::Hold));
        s2.record(Intent::Idle);
        assert!(s2.sync(WAIT));
        let (s3, previous) = ResumeMarker::open(dir.path());
        assert_eq!(previous, Some(Intent::Idle));
        s3.finish(WAIT);
        assert_eq!(ResumeMarker::open(dir.path()).1, None);
    }

    /// Issue 27: after kill -9 in Fault the restart said "it was idle".
    #[test]
    fn a_marker_written_in_fault_says_so_and_what_it_would_recover_to() {
        let dir = tempfile::tempdir().unwrap();
        let (mut s, _) = ResumeMarker::open(dir.path());
        s.record(Intent::Hold);
        s.record_in_fault(Intent::Hold);
        assert!(s.sync(WAIT));
        let (mut s2, previous) = ResumeMarker::open(dir.path());
        assert_eq!(previous, Some(Intent::Hold));
        assert!(s2.previous_in_fault());
        s2.record(Intent::Idle);
        assert!(s2.sync(WAIT));
        let (s3, previous) = ResumeMarker::open(dir.path());
        assert_eq!(previous, Some(Intent::Idle));
        assert!(!s3.previous_in_fault());
        s3.finish(WAIT);
    }

    #[test]
    fn a_marker_under_its_old_name_is_read_once_and_removed() {
        let dir = tempfile::tempdir().unwrap();
        fs::write(
            dir.path().join(LEGACY_FILE),
            "thrusterd session\nresume=hold\nstate=fault\n",
        )
        .unwrap();
        let (m, previous) = ResumeMarker::open(dir.path());
        assert_eq!(previous, Some(Intent::Hold));
        assert!(m.previous_in_fault());
        assert!(!dir.path().join(LEGACY_FILE).exists());
        m.finish(WAIT);
        assert_eq!(ResumeMarker::open(dir.path()).1, None);
    }

    #[test]
    fn garbage_resumes_idle() {
        assert_eq!(parse(""), Intent::Idle);
        assert_eq!(parse("resume=spin\n"), Intent::Idle);
        assert_eq!(parse("thrusterd session\nresume=hold\n"), Intent::Hold);
    }
}
