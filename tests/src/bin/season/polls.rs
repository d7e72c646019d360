//! The operator's polls of the season soak: in this process on worker threads, or as real
//! `thrusterctl` processes (reaped however the run ends), and `thrusterctl estimate`.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use system_tests::{bin, wait_for};
use thruster_protocol::services::{ControlClient, Inbox, IpcConfig};
use thruster_protocol::{ControlRequest, RequestKind, StatusMsg};

use crate::Tally;

/// One operator poll the way `thrusterctl status` does it, in this process: a fresh node,
/// control client and status inbox, a Status request, the published status; all dropped.
/// Returns the vehicle time the answer carries (when the poll was served).
pub(crate) fn poll_in_process(ipc: &IpcConfig) -> Result<u64> {
    let node = ipc.create_node("season-poll")?;
    let inbox: Inbox<StatusMsg> = Inbox::create_with_buffer(&node, ipc, 1)?;
    let client = ControlClient::create(&node, ipc)?;
    let r = client.call(
        ControlRequest::new(RequestKind::Status),
        Duration::from_secs(2),
    )?;
    anyhow::ensure!(r.is_ok(), "status refused: {}", r.text());
    let s = wait_for(&inbox, Duration::from_secs(2), |_| true).context("no status published")?;
    Ok(s.vehicle_time_ns)
}

/// In-process polls run on worker threads, each with its own fresh node per poll (iceoryx2
/// ports are not Send; a node per thread is fine): a poll mostly waits (about 100 ms for the
/// daemon's status to reach a new subscriber), and one at a time could not keep up with one
/// per vehicle-second at 20x.
pub(crate) struct Pollers {
    jobs: Option<std::sync::mpsc::Sender<u64>>,
    results: std::sync::mpsc::Receiver<(u64, Duration, Result<u64, String>)>,
    threads: Vec<std::thread::JoinHandle<()>>,
    pending: u64,
    pub(crate) max_pending: u64,
}

impl Pollers {
    pub(crate) fn new(ipc: &IpcConfig, n: usize) -> Pollers {
        let (job_tx, job_rx) = std::sync::mpsc::channel::<u64>();
        let (res_tx, results) = std::sync::mpsc::channel();
        let job_rx = std::sync::Arc::new(std::sync::Mutex::new(job_rx));
        let threads = (0..n)
            .map(|_| {
                let (ipc, job_rx, res_tx) = (ipc.clone(), job_rx.clone(), res_tx.clone());
                std::thread::spawn(move || loop {
                    let job = job_rx.lock().unwrap().recv();
                    let Ok(due) = job else { return };
                    let t0 = Instant::now();
                    let r = poll_in_process(&ipc).map_err(|e| format!("{e:#}"));
                    if res_tx.send((due, t0.elapsed(), r)).is_err() {
                        return;
                    }
                })
            })
            .collect();
        Pollers {
            jobs: Some(job_tx),
            results,
            threads,
            pending: 0,
            max_pending: 0,
        }
    }

    pub(crate) fn submit(&mut self, due: u64) {
        if let Some(j) = &self.jobs {
            let _ = j.send(due);
            self.pending += 1;
            self.max_pending = self.max_pending.max(self.pending);
        }
    }

    /// Results so far into `tally`; with `wait`, until every job is done.
    pub(crate) fn collect(&mut self, tally: &mut Tally, wait: bool) {
        loop {
            let r = if wait && self.pending > 0 {
                self.results.recv_timeout(Duration::from_secs(30)).ok()
            } else {
                self.results.try_recv().ok()
            };
            let Some((due, took, r)) = r else { return };
            self.pending -= 1;
            tally.inproc_wall += took;
            if let Ok(served_ns) = r {
                tally.served_lag.record(due, served_ns);
            }
            if let Err(e) = r {
                tally.polls_failed += 1;
                if tally.poll_errors.len() < 20 {
                    tally
                        .poll_errors
                        .push(format!("in-process poll due at {due} ns: {e}"));
                }
            }
        }
    }

    pub(crate) fn join(mut self) {
        self.stop();
    }

    fn stop(&mut self) {
        self.jobs = None;
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// However `run` returns (an error included), the poll threads drop their nodes before the
/// world purges the namespace (a live node makes the purge refuse and leaves files).
impl Drop for Pollers {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Poll processes in flight, killed and reaped when dropped (std's `Child` does neither: one
/// left running keeps its node alive and the namespace could not be purged).
#[derive(Default)]
pub(crate) struct Inflight(pub(crate) Vec<(Child, Instant)>);

impl Drop for Inflight {
    fn drop(&mut self) {
        for (c, _) in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// A real `thrusterctl` process with output discarded (the poll processes: thousands).
pub(crate) fn ctl_quiet(ns: &str, args: &[&str]) -> Result<Child> {
    Command::new(bin("thrusterctl"))
        .args(["--namespace", ns])
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .context("spawning thrusterctl")
}

/// `thrusterctl estimate` as a real process; false when the daemon refused (busy with the
/// re-estimation a reconfiguration started).
pub(crate) fn estimate(ns: &str) -> Result<bool> {
    let st = ctl_quiet(ns, &["estimate"])?.wait()?;
    Ok(st.success())
}
