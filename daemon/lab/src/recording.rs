//! `--record FILE.mcap` of the demo: the session's namespace recorded by the same recorder
//! as `thrusterctl record`, in a thread of this process.
//!
//! A thread rather than a child `thrusterctl record` process: the recorder is subscribers
//! only (iceoryx2's publishers never wait for a subscriber, so it cannot slow the daemon or
//! the simulator whichever process it lives in), the session already joins the namespace,
//! and in a thread it subscribes to every topic *before* the daemon and the simulator start
//! (nothing of the session is missed, which a separately started process could not promise
//! without a handshake), ends before the namespace is purged, and reports its counts
//! without parsing another process's output.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{anyhow, Context, Result};
use thruster_protocol::services::IpcConfig;
use thruster_recorder::{RecordError, RecordOptions, RecordSummary};

/// How much faster than real time a recorded lockstep session runs, at most. Unpaced,
/// lockstep runs as fast as the daemon answers (tens of kHz of samples), which outruns the
/// recorder's 128-sample buffers whenever the machine deschedules it for a few ms (measured:
/// ~100 of 4000 IMU samples lost on a busy 2-core VM). 5x real time is 1 kHz of samples at
/// the simulator's default 200 Hz IMU: the rate the recorder is specified (and tested) for.
pub const RECORD_PACE: f64 = 5.0;

/// Where run `label` of an experiment recorded to `out` goes: `out` with `-label` before its
/// extension (`top45.mcap` -> `top45-announced.mcap`), so the runs never share a file.
pub fn run_path(out: &Path, label: &str) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match out.extension() {
        Some(ext) => format!("{stem}-{label}.{}", ext.to_string_lossy()),
        None => format!("{stem}-{label}"),
    };
    out.with_file_name(name)
}

/// Longest wait for the recorder to subscribe.
const READY_TIMEOUT: Duration = Duration::from_secs(10);

/// A recorder running in its own thread.
pub struct Recording {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<Result<RecordSummary, RecordError>>>,
}

impl Recording {
    /// Starts recording `ipc`'s namespace; returns once every topic is subscribed.
    pub fn start(ipc: &IpcConfig, options: RecordOptions) -> Result<Recording> {
        let stop = Arc::new(AtomicBool::new(false));
        let (tx, rx) = mpsc::channel();
        let ipc = ipc.clone();
        let flag = Arc::clone(&stop);
        let handle = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || {
                // The node lives in this thread (iceoryx2 nodes are not shared across threads).
                let node = ipc
                    .create_node("recorder")
                    .map_err(|source| RecordError::Ipc {
                        namespace: ipc.namespace().to_string(),
                        source,
                    })?;
                thruster_recorder::record_on(&node, &ipc, &options, &flag, &mut || {
                    let _ = tx.send(());
                })
            })
            .context("starting the recorder thread")?;
        let mut recording = Recording {
            stop,
            handle: Some(handle),
        };
        if rx.recv_timeout(READY_TIMEOUT).is_err() {
            // The thread ended (an error) or hangs: stop it and say why.
            return Err(match recording.stop() {
                Err(e) => e,
                Ok(_) => anyhow!("the recorder did not subscribe within {READY_TIMEOUT:?}"),
            });
        }
        Ok(recording)
    }

    /// Stops the recorder, which drains what is buffered and finishes its file.
    pub fn stop(&mut self) -> Result<RecordSummary> {
        self.stop.store(true, Ordering::Relaxed);
        let handle = self
            .handle
            .take()
            .ok_or_else(|| anyhow!("the recorder was stopped already"))?;
        handle
            .join()
            .map_err(|_| anyhow!("the recorder thread panicked"))?
            .map_err(|e| {
                // A session stopped by an error (a full disk) still says what it wrote.
                let line = e.summary().map(|s| format!(": {}", s.line()));
                anyhow::Error::new(e).context(format!("recording{}", line.unwrap_or_default()))
            })
    }
}

impl Drop for Recording {
    fn drop(&mut self) {
        if self.handle.is_some() {
            let _ = self.stop();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_run_gets_its_own_file_beside_the_one_named() {
        assert_eq!(
            run_path(Path::new("/data/top45.mcap"), "announced"),
            Path::new("/data/top45-announced.mcap")
        );
        assert_eq!(
            run_path(Path::new("session"), "oracle"),
            Path::new("session-oracle")
        );
    }
}
