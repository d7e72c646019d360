//! The session marker: a small file in the state directory that exists while a thrusterd
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

use tracing::warn;

/// File name of the marker inside the state directory.
pub const SESSION_FILE: &str = "session";

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

pub struct Session {
    path: PathBuf,
    /// What the marker says now: the intent, and whether the daemon is in Fault.
    written: Option<(Intent, bool)>,
    warned: bool,
    /// The predecessor's marker said it was in Fault (its intent is what it would have
    /// recovered to).
    previous_in_fault: bool,
}

impl Session {
    /// The marker in `state_dir`, and the intent of a predecessor that did not stop cleanly
    /// (None after a clean stop or on the first start). Nothing is written yet.
    pub fn open(state_dir: &Path) -> (Session, Option<Intent>) {
        let path = state_dir.join(SESSION_FILE);
        let mut previous_in_fault = false;
        let previous = match fs::read_to_string(&path) {
            Ok(text) => {
                previous_in_fault = text.lines().any(|l| l == "state=fault");
                Some(parse(&text))
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            // Unreadable: a predecessor was there, but what it did is unknown; idle is safe.
            Err(e) => {
                warn!("{}: {e}; resuming idle", path.display());
                Some(Intent::Idle)
            }
        };
        let session = Session {
            path,
            written: None,
            warned: false,
            previous_in_fault,
        };
        (session, previous)
    }

    /// Records what a restart after a crash from now on should resume (written on change).
    pub fn record(&mut self, intent: Intent) {
        self.write(intent, false);
    }

    /// As `record`, in Fault: `intent` is what the daemon will recover to, and the marker
    /// says it was in Fault, so a restart does not call it idle (issue 27).
    pub fn record_in_fault(&mut self, intent: Intent) {
        self.write(intent, true);
    }

    /// True when the predecessor's marker said it was in Fault.
    pub fn previous_in_fault(&self) -> bool {
        self.previous_in_fault
    }

    fn write(&mut self, intent: Intent, in_fault: bool) {
        if self.written == Some((intent, in_fault)) {
            return;
        }
        // Temp file and rename: a crash mid-write never leaves half a marker. No fsync: the
        // marker guards against the process dying, whose completed writes the kernel keeps.
        let tmp = self.path.with_extension("tmp");
        let state = if in_fault { "state=fault\n" } else { "" };
        let text = format!("thrusterd session\nresume={}\n{state}", intent.word());
        let result = self
            .path
            .parent()
            .map_or(Ok(()), fs::create_dir_all)
            .and_then(|()| fs::write(&tmp, text))
            .and_then(|()| fs::rename(&tmp, &self.path));
        match result {
            Ok(()) => self.written = Some((intent, in_fault)),
            Err(e) => {
                let _ = fs::remove_file(&tmp);
                if !self.warned {
                    warn!(
                        "{}: {e}; a restart after a crash will not resume control",
                        self.path.display()
                    );
                    self.warned = true;
                }
            }
        }
    }

    /// A clean stop: the next start is a fresh one.
    pub fn finish(self) {
        if let Err(e) = fs::remove_file(&self.path) {
            if e.kind() != std::io::ErrorKind::NotFound {
                warn!("{}: {e}", self.path.display());
            }
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

    #[test]
    fn a_marker_left_behind_gives_the_predecessors_intent_and_a_clean_stop_removes_it() {
        let dir = tempfile::tempdir().unwrap();
        let (mut s, previous) = Session::open(dir.path());
        assert_eq!(previous, None);
        s.record(Intent::Hold);
        // The process dies here: the next start sees the marker.
        let (mut s2, previous) = Session::open(dir.path());
        assert_eq!(previous, Some(Intent::Hold));
        s2.record(Intent::Idle);
        let (s3, previous) = Session::open(dir.path());
        assert_eq!(previous, Some(Intent::Idle));
        s3.finish();
        assert_eq!(Session::open(dir.path()).1, None);
    }

    /// Issue 27: after kill -9 in Fault the restart said "it was idle".
    #[test]
    fn a_marker_written_in_fault_says_so_and_what_it_would_recover_to() {
        let dir = tempfile::tempdir().unwrap();
        let (mut s, _) = Session::open(dir.path());
        s.record(Intent::Hold);
        s.record_in_fault(Intent::Hold);
        let (mut s2, previous) = Session::open(dir.path());
        assert_eq!(previous, Some(Intent::Hold));
        assert!(s2.previous_in_fault());
        s2.record(Intent::Idle);
        let (s3, previous) = Session::open(dir.path());
        assert_eq!(previous, Some(Intent::Idle));
        assert!(!s3.previous_in_fault());
        s3.finish();
    }

    #[test]
    fn garbage_resumes_idle() {
        assert_eq!(parse(""), Intent::Idle);
        assert_eq!(parse("resume=spin\n"), Intent::Idle);
        assert_eq!(parse("thrusterd session\nresume=hold\n"), Intent::Hold);
    }
}
