//! The dead-node reaper: removes what killed or crashed processes of the namespace left (an
//! operator's `thrusterctl` killed with -9 mid-call, a recorder that lost power), on a thread
//! of its own so that listing and removing files never delays a control tick.
//!
//! Why the daemon: iceoryx2 removes a dead node's files only when another node of the
//! namespace is created or asks. Operators of another user than the daemon's must not try
//! (`IpcConfig::without_dead_node_cleanup`), and nothing else may come for hours, so without
//! this a killed client's segments stayed in /dev/shm until the daemon's next start. Under the
//! shipped unit the daemon holds CAP_FOWNER, so it may remove another user's files in the
//! sticky /dev/shm.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use thruster_protocol::services::{cleanup_dead_nodes, IpcConfig, NodeCensus};
use tracing::{debug, info, warn};

/// How often the namespace is searched for dead nodes: a killed client's files are gone
/// within this. A search is a directory listing and one file-lock probe per node, on this
/// thread, never the control thread's.
pub const REAP_EVERY: Duration = Duration::from_secs(2);
/// How often the reaper looks at the stop flag between two searches.
const STOP_POLL: Duration = Duration::from_millis(50);

/// A running reaper; stops (and is joined) when dropped.
pub struct Reaper {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Reaper {
    /// Starts searching `ipc` every `every`.
    pub fn start(ipc: &IpcConfig, every: Duration) -> std::io::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let ipc = ipc.clone();
        let flag = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("reaper".into())
            .spawn(move || reap_until(&ipc, every, &flag))?;
        Ok(Self {
            stop,
            thread: Some(thread),
        })
    }
}

/// How long a stopping daemon waits for the reaper's search in progress before leaving it
/// behind.
const JOIN_WITHIN: Duration = Duration::from_secs(2);

impl Drop for Reaper {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            // A search is a listing and a lock probe per node, normally milliseconds. But it
            // removes a dead node's entries from shared service state that the dead process
            // may have been changing when it was killed, so it is not waited for without
            // end: a shutdown must not hang on it (systemd would kill the daemon instead of
            // its clean stop). Left behind, the thread ends with the process.
            let deadline = Instant::now() + JOIN_WITHIN;
            while !t.is_finished() && Instant::now() < deadline {
                std::thread::sleep(STOP_POLL.min(Duration::from_millis(10)));
            }
            if t.is_finished() {
                let _ = t.join();
            } else {
                warn!(
                    "the dead-node reaper did not stop within {} s (a search stuck on a dead \
                     node's files?); leaving it",
                    JOIN_WITHIN.as_secs()
                );
            }
        }
    }
}

fn reap_until(ipc: &IpcConfig, every: Duration, stop: &AtomicBool) {
    let mut next = Instant::now() + every;
    // What the last search could not judge, said once when it changes rather than every
    // 2 s: a node in an undefined state (one killed while it was being created or removed)
    // or a failed listing keeps its files, and the log is where anyone would look for why.
    let mut last_unjudged: Option<String> = None;
    let mut last_failed = 0;
    while !stop.load(Ordering::SeqCst) {
        if Instant::now() < next {
            std::thread::sleep(STOP_POLL.min(next.saturating_duration_since(Instant::now())));
            continue;
        }
        next = Instant::now() + every;
        let census = cleanup_dead_nodes(ipc);
        debug!(?census, "dead-node search");
        let unjudged = match &census {
            Ok(c) if c.unknown > 0 => Some(format!("{} nodes in an undefined state", c.unknown)),
            Ok(_) => None,
            Err(e) => Some(format!("the search failed: {e}")),
        };
        if unjudged != last_unjudged {
            match &unjudged {
                Some(what) => info!("dead-node search: {what}; their files stay"),
                None if last_unjudged.is_some() => info!("dead-node search: every node judged"),
                None => {}
            }
            last_unjudged = unjudged;
        }
        let failed = census.as_ref().map_or(last_failed, |c| c.dead_failed);
        match census {
            Ok(NodeCensus {
                dead_cleaned: 0,
                dead_failed: 0,
                unfinished_removed: 0,
                ..
            }) => {}
            Ok(census) if census.dead_failed > 0 => {
                // Said when the count changes, not every 2 s: iceoryx2 fails the same way on
                // every search for a client killed while it joined a service
                // (`services::unfinished`), and the files stay until the next purge.
                if census.dead_failed != last_failed {
                    warn!(?census, "dead nodes whose files could not be removed")
                } else {
                    debug!(?census, "dead nodes whose files could not be removed")
                }
            }
            Ok(census) => info!(?census, "removed the files of dead nodes"),
            Err(_) => {}
        }
        last_failed = failed;
    }
}
