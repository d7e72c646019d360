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

use thruster_protocol::services::{cleanup_dead_nodes, IpcConfig, IpcError, NodeCensus};
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

impl Drop for Reaper {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            // Bounded: the reaper thread looks at the stop flag every `STOP_POLL`, also while a
            // search runs (`search_watched` leaves a stuck one behind), so a search stuck on a
            // dead node's shared state cannot hang a clean stop.
            let _ = t.join();
        }
    }
}

/// How long a search may take before the reaper says it is stuck. A search is a listing and
/// a lock probe per node, milliseconds; iceoryx2's removal of a dead node's entries from the
/// services it was joining is what could wait (never seen here; in CI twice a killed
/// client's files stayed with no word from the reaper).
const SEARCH_STUCK_AFTER: Duration = Duration::from_secs(4);

/// One search, on a thread of its own, watched: if it has not returned within
/// [`SEARCH_STUCK_AFTER`] the reaper says so (once) and goes on waiting for it, so a stuck
/// iceoryx2 call is in the log instead of a silent reaper. None when asked to stop first
/// (the search thread is then left to end with the process).
fn search_watched(ipc: &IpcConfig, stop: &AtomicBool) -> Option<Result<NodeCensus, IpcError>> {
    let (tx, rx) = std::sync::mpsc::channel();
    let ipc = ipc.clone();
    let spawned = std::thread::Builder::new()
        .name("reaper-search".into())
        .spawn(move || {
            let _ = tx.send(cleanup_dead_nodes(&ipc));
        });
    if let Err(e) = spawned {
        warn!("dead-node search not started: {e}");
        return Some(Ok(NodeCensus::default()));
    }
    let started = Instant::now();
    let mut said = false;
    loop {
        match rx.recv_timeout(STOP_POLL) {
            Ok(census) => {
                if said {
                    info!(
                        "the dead-node search returned after {:.1} s",
                        started.elapsed().as_secs_f64()
                    );
                }
                return Some(census);
            }
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                warn!("the dead-node search ended without an answer (a panic in iceoryx2?)");
                return Some(Ok(NodeCensus::default()));
            }
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
        }
        if stop.load(Ordering::SeqCst) {
            return None;
        }
        if !said && started.elapsed() >= SEARCH_STUCK_AFTER {
            warn!(
                "the dead-node search has not returned in {} s: iceoryx2 is stuck removing a \
                 dead node's files, which stay until it returns",
                SEARCH_STUCK_AFTER.as_secs()
            );
            said = true;
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
        let Some(census) = search_watched(ipc, stop) else {
            return;
        };
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
