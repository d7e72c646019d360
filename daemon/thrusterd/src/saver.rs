//! Saving models off the control loop.
//!
//! A save is a write, an fsync, a rename and an fsync of the folder: on a busy SD card or a
//! stalled disk it takes from milliseconds to forever (0.7-1.1 s was seen under systemd right
//! after an estimation, enough to lose 90 IMU samples and fault on the gap). The control loop
//! must never wait for it, so saves run on a thread of their own: the loop hands over a copy
//! of the model and reads the outcomes when they come, without blocking. The copy comes back
//! with its outcome and is freed on the control thread, where it was made (a free into
//! another thread's malloc arena can wait on that arena's lock: `solver.rs`).

use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, Receiver, Sender};
use std::time::{Duration, Instant};

use crate::store;
use thrusterd_core::model::Model;

/// One save to do.
struct Job {
    id: u64,
    model: Model,
    path: PathBuf,
}

/// How a save ended.
#[derive(Debug)]
pub struct Outcome {
    pub id: u64,
    pub path: PathBuf,
    pub version: u64,
    /// The reason, when it failed.
    pub result: Result<(), String>,
    /// The copy that was saved, back to be freed on the thread that made it.
    _spent: Option<Model>,
}

/// The saving thread and the two channels to it.
pub struct Saver {
    jobs: Option<Sender<Job>>,
    outcomes: Receiver<Outcome>,
    /// Outcomes made here (a submission the thread could not take), handed out by
    /// [`Saver::poll`].
    early: Vec<Outcome>,
    next_id: u64,
    pending: usize,
}

impl Saver {
    pub fn spawn() -> std::io::Result<Saver> {
        let (jobs, job_rx) = mpsc::channel::<Job>();
        let (outcome_tx, outcomes) = mpsc::channel();
        std::thread::Builder::new()
            .name("model-saver".into())
            .spawn(move || {
                for job in job_rx {
                    let result = save(&job.model, &job.path);
                    let outcome = Outcome {
                        id: job.id,
                        path: job.path,
                        version: job.model.version,
                        result,
                        _spent: Some(job.model),
                    };
                    if outcome_tx.send(outcome).is_err() {
                        break;
                    }
                }
            })?;
        Ok(Saver {
            jobs: Some(jobs),
            outcomes,
            early: Vec::new(),
            next_id: 0,
            pending: 0,
        })
    }

    /// Queues a save of `model` to `path`; returns its id. Never blocks.
    pub fn submit(&mut self, model: &Model, path: &Path) -> u64 {
        self.next_id += 1;
        let job = Job {
            id: self.next_id,
            model: model.clone(),
            path: path.to_path_buf(),
        };
        let sent = self.jobs.as_ref().is_some_and(|tx| tx.send(job).is_ok());
        if sent {
            self.pending += 1;
        } else {
            // The thread is gone (it only ends when its channel closes): say so as an
            // outcome rather than losing the save silently.
            self.early.push(Outcome {
                id: self.next_id,
                path: path.to_path_buf(),
                version: model.version,
                result: Err("the saving thread is not running".into()),
                _spent: None,
            });
        }
        self.next_id
    }

    /// Every outcome that has come, without waiting.
    pub fn poll(&mut self) -> Vec<Outcome> {
        let mut out = std::mem::take(&mut self.early);
        while let Ok(o) = self.outcomes.try_recv() {
            self.pending -= 1;
            out.push(o);
        }
        out
    }

    /// At shutdown (thrusters already neutral): waits up to `within` for the saves still
    /// under way and returns their outcomes, plus how many were abandoned (a disk that never
    /// answers must not keep the process from exiting; the thread ends with it).
    /// Later submissions fail (as outcomes).
    pub fn finish(&mut self, within: Duration) -> (Vec<Outcome>, usize) {
        self.jobs = None;
        let deadline = Instant::now() + within;
        let mut out = self.poll();
        while self.pending > 0 {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.outcomes.recv_timeout(left) {
                Ok(o) => {
                    self.pending -= 1;
                    out.push(o);
                }
                Err(_) => break,
            }
        }
        (out, self.pending)
    }
}

/// The save itself: the folder first (it may not exist yet), then the atomic write.
fn save(model: &Model, path: &Path) -> Result<(), String> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    store::save_atomic(model, path).map_err(|e| e.to_string())
}
