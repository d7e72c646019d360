//! An operator's `load`, off the control thread: the file is read, parsed and prepared
//! (`Model::prepared`: actuated DOFs and allocation derived again, the physical bounds
//! checked) on a thread of its own; the loop installs the prepared model when it is back and
//! only then answers the request. A read that does not finish (a stalled disk, a network
//! mount) never holds the loop: after [`ANSWER_WAIT`] the operator is told it is still being
//! read, and the outcome goes to the log and status when it comes.
//!
//! One load at a time: a thread stuck in a read keeps its load in flight, and later loads are
//! refused with the path and how long it has been stuck, so stuck threads cannot pile up.
//!
//! The loop installs its own copy of what was read and hands the thread's back to it to be
//! freed there: a free into another thread's malloc arena can wait on that arena's lock
//! (`solver.rs`). The thread waits at most [`GIVE_BACK_WAIT`] for it.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, Receiver, SyncSender, TryRecvError};
use std::time::{Duration, Instant};

use thrusterd_core::estimator::EstimatorConfig;
use thrusterd_core::model::PreparedModel;

use crate::store;

/// How long an operator's `load` waits for its file before it is answered "still reading":
/// a healthy disk reads a model file in well under a millisecond, and the operator tool waits
/// 2 s by default.
pub const ANSWER_WAIT: Duration = Duration::from_millis(1000);

/// How long a reading thread waits, once it has handed over its result, for that result to
/// come back to be freed (the loop copies it at once; this only bounds a thread whose loop
/// went away).
const GIVE_BACK_WAIT: Duration = Duration::from_secs(10);

type Read = Result<PreparedModel, LoadError>;

/// A load in flight.
struct InFlight {
    token: u64,
    path: PathBuf,
    since: Instant,
    done: Receiver<Read>,
    /// The thread's result goes back on this to be freed where it was made.
    give_back: SyncSender<Read>,
    /// The operator was already answered ("still reading").
    answered: bool,
}

/// Why a load did not give a model.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LoadError {
    /// The file could not be read or parsed.
    Failed(String),
    /// The file's model breaks a physical bound or actuates nothing.
    Rejected(String),
}

impl std::fmt::Display for LoadError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LoadError::Failed(why) | LoadError::Rejected(why) => f.write_str(why),
        }
    }
}

/// What became of a load.
pub enum Progress {
    /// Nothing to report this round.
    Nothing,
    /// Still reading after [`ANSWER_WAIT`]: answer the request (`token`) now.
    Slow { token: u64, path: PathBuf },
    /// Read: install it (or report why not). `answered`: the operator was told it was slow.
    Done {
        token: u64,
        path: PathBuf,
        result: Box<Result<PreparedModel, LoadError>>,
        answered: bool,
    },
}

pub struct Loader {
    estimator: EstimatorConfig,
    in_flight: Option<InFlight>,
}

impl Loader {
    /// Loads prepared with these estimator settings (the machine's).
    pub fn new(estimator: EstimatorConfig) -> Self {
        Loader {
            estimator,
            in_flight: None,
        }
    }

    /// Starts reading `path` for the request `token`. Refused while another load is in
    /// flight, or when no thread can be started.
    pub fn start(&mut self, token: u64, path: &Path) -> Result<(), String> {
        if let Some(f) = &self.in_flight {
            return Err(format!(
                "still reading {} (for {:.1} s; the file system does not answer): try again later",
                f.path.display(),
                f.since.elapsed().as_secs_f64()
            ));
        }
        let (tx, done) = mpsc::sync_channel(1);
        let (give_back, given_back) = mpsc::sync_channel::<Read>(1);
        let owned = path.to_path_buf();
        let cfg = self.estimator.clone();
        std::thread::Builder::new()
            .name("thrusterd-load".into())
            .spawn(move || {
                // Parsing a large file is seconds of CPU: never at the control thread's cost.
                crate::solver::lower_priority();
                if tx.send(read(&owned, &cfg)).is_ok() {
                    // Freed here, where it was allocated (dropped at the end of this scope).
                    let _ = given_back.recv_timeout(GIVE_BACK_WAIT);
                }
            })
            .map_err(|e| format!("cannot start a thread to read {}: {e}", path.display()))?;
        self.in_flight = Some(InFlight {
            token,
            path: path.to_path_buf(),
            since: Instant::now(),
            done,
            give_back,
            answered: false,
        });
        Ok(())
    }

    /// What became of the load in flight (never waits).
    pub fn poll(&mut self) -> Progress {
        let Some(f) = self.in_flight.as_mut() else {
            return Progress::Nothing;
        };
        let result = match f.done.try_recv() {
            Ok(theirs) => {
                let mine = theirs.clone();
                // Never waits (a channel of one, used once); if the thread is gone, it is
                // freed here.
                let _ = f.give_back.try_send(theirs);
                mine
            }
            Err(TryRecvError::Empty) => {
                if !f.answered && f.since.elapsed() >= ANSWER_WAIT {
                    f.answered = true;
                    return Progress::Slow {
                        token: f.token,
                        path: f.path.clone(),
                    };
                }
                return Progress::Nothing;
            }
            Err(TryRecvError::Disconnected) => Err(LoadError::Failed(
                "the reading thread ended without a result".into(),
            )),
        };
        let f = self.in_flight.take().expect("in flight");
        Progress::Done {
            token: f.token,
            path: f.path,
            result: Box::new(result),
            answered: f.answered,
        }
    }
}

/// Read, parse and prepare: everything but the install.
fn read(path: &Path, cfg: &EstimatorConfig) -> Result<PreparedModel, LoadError> {
    match store::load(path) {
        Ok(Some(model)) => model
            .prepared(cfg)
            .map_err(|e| LoadError::Rejected(format!("model not used: {e}"))),
        Ok(None) => Err(LoadError::Failed(format!(
            "{}: no such file",
            path.display()
        ))),
        Err(e) => Err(LoadError::Failed(e.to_string())),
    }
}
