//! Checkpoints of the state machine on the `checkpoint` topic: the machine's whole state
//! (`Machine::checkpoint`) with its place in the input journal, after each model swap and
//! every `checkpoint.period_s` vehicle seconds. A recording started after the daemon replays
//! from its first checkpoint (`thrusterd replay`, docs/recording.md "Checkpoints").
//!
//! When: after a sample's answer went out and its solve jobs were handed to the worker (so
//! the sample's own latency never includes it), at the first such sample where the state is
//! complete (no job out with the worker: its work is not in the state) and small (no
//! estimation under way, no refinement window open: about 0.2 MB). Publishing never waits
//! (safe overflow).
//!
//! Where: the control thread only copies the machine (`Clone`, tens of microseconds); a
//! writer thread serialises and splits the copy (0.2-1 ms, a period at 1 kHz, issue 25), and
//! the control thread publishes the parts when they are back, at a later sample. Free
//! running, that is whichever sample finds them back; in lockstep the control thread waits
//! for them (bounded) at the sample that took the copy, so the stream is the same on every
//! run. Each allocation is freed on the thread that made it (the copy comes back with the
//! parts, the parts go back to the writer): a free into another thread's glibc arena can
//! wait on that arena's lock (`solver.rs`).

use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender, TryRecvError};
use std::time::Duration;

use thruster_protocol::services::Port;
use thruster_protocol::CheckpointMsg;
use thrusterd_core::checkpoint_parts::{self, Place};
use thrusterd_core::config::CheckpointSection;
use thrusterd_core::machine::Machine;
use tracing::{debug, info, warn};

/// How long a lockstep sample waits for the writer (a stuck writer costs that once: the
/// checkpoint is then published when it comes, or never).
const LOCKSTEP_WAIT: Duration = Duration::from_secs(2);

/// A copy of the machine to serialise, and where it was taken.
struct Snapshot {
    machine: Box<Machine>,
    id: u64,
    place: Place,
    first_seq: u64,
    /// What the copy cost the control thread (logged with its checkpoint).
    copy_us: u128,
}

/// The writer's answer: the parts (or why none), and the copy back to be freed where it was
/// made.
struct Written {
    parts: Result<(usize, Vec<CheckpointMsg>), String>,
    id: u64,
    imu_count: u64,
    copy_us: u128,
    serialise_us: u128,
    copy: Box<Machine>,
}

enum ToWriter {
    Write(Snapshot),
    /// Parts published: freed on the writer, which made them.
    Free(Vec<CheckpointMsg>),
}

/// The writer thread: serialises copies of the machine, one at a time.
struct Writer {
    tx: SyncSender<ToWriter>,
    rx: Receiver<Written>,
}

impl Writer {
    fn spawn() -> std::io::Result<Writer> {
        // One copy in flight at a time, and its parts on their way back.
        let (tx, jobs) = mpsc::sync_channel::<ToWriter>(4);
        let (done, rx) = mpsc::sync_channel::<Written>(1);
        std::thread::Builder::new()
            .name("thrusterd-checkpoint".into())
            .spawn(move || {
                crate::solver::lower_priority();
                for msg in jobs {
                    match msg {
                        ToWriter::Write(snap) => {
                            if done.send(write(snap)).is_err() {
                                break;
                            }
                        }
                        ToWriter::Free(parts) => drop(parts),
                    }
                }
            })?;
        Ok(Writer { tx, rx })
    }
}

/// Serialise and split one copy (on the writer thread).
fn write(snap: Snapshot) -> Written {
    let started = std::time::Instant::now();
    let parts = snap
        .machine
        .checkpoint()
        .map_err(|e| e.to_string())
        .and_then(|bytes| {
            checkpoint_parts::split(snap.id, &snap.place, &bytes, snap.first_seq)
                .map(|parts| (bytes.len(), parts))
                .map_err(|e| e.to_string())
        });
    Written {
        parts,
        id: snap.id,
        imu_count: snap.place.imu_count,
        copy_us: snap.copy_us,
        serialise_us: started.elapsed().as_micros(),
        copy: snap.machine,
    }
}

pub struct Checkpoints {
    port: Port<CheckpointMsg>,
    /// None when the thread could not be started (then checkpoints are not taken, said once).
    writer: Option<Writer>,
    /// A copy is with the writer: no other is taken until its parts are back.
    in_flight: bool,
    lockstep: bool,
    /// 0: only after swaps.
    period_ns: u64,
    /// Vehicle time from which the next periodic one is due (the first at the first sample).
    next_periodic_ns: u64,
    swap_pending: bool,
    id: u64,
    seq: u64,
    failures: u64,
}

impl Checkpoints {
    /// `lockstep`: the daemon runs in lockstep (the writer is waited for, see the module).
    pub fn new(port: Port<CheckpointMsg>, cfg: &CheckpointSection, lockstep: bool) -> Self {
        let writer = Writer::spawn()
            .map_err(|e| warn!("checkpoints off: their writer thread did not start: {e}"))
            .ok();
        Checkpoints {
            port,
            writer,
            in_flight: false,
            lockstep,
            period_ns: (cfg.period_s.clamp(0.0, 3600.0) * 1e9) as u64,
            next_periodic_ns: 0,
            swap_pending: false,
            id: 0,
            seq: 0,
            failures: 0,
        }
    }

    /// A model was swapped in: the next checkpoint holds it.
    pub fn model_swapped(&mut self) {
        self.swap_pending = true;
    }

    /// After an accepted sample at vehicle time `t_ns` was answered: publishes a checkpoint
    /// the writer has finished, and hands it a copy of the machine if one is due and the
    /// machine's state allows it. `place`: the journal's position now (accepted samples, the
    /// last one's seq and time, the next entry's seq).
    pub fn after_sample(&mut self, machine: &Machine, t_ns: u64, place: Place) {
        self.publish_written(None);
        let periodic = self.period_ns > 0 && t_ns >= self.next_periodic_ns;
        if !(periodic || self.swap_pending)
            || self.in_flight
            || !machine.checkpointable()
            || !machine.checkpoint_small()
        {
            return;
        }
        let Some(writer) = self.writer.as_ref() else {
            return;
        };
        let reason = if self.swap_pending {
            CheckpointMsg::AFTER_SWAP
        } else {
            CheckpointMsg::PERIODIC
        };
        self.swap_pending = false;
        if self.period_ns > 0 {
            self.next_periodic_ns = t_ns.saturating_add(self.period_ns);
        }
        let place = Place {
            model_version: machine.model().map_or(0, |m| m.version),
            reason,
            ..place
        };
        let copied = std::time::Instant::now();
        let machine = Box::new(machine.clone());
        let snap = Snapshot {
            machine,
            id: self.id,
            place,
            first_seq: self.seq,
            copy_us: copied.elapsed().as_micros(),
        };
        if writer.tx.try_send(ToWriter::Write(snap)).is_err() {
            return self.failed("its writer thread is gone or stuck");
        }
        self.in_flight = true;
        if self.lockstep {
            self.publish_written(Some(LOCKSTEP_WAIT));
        }
    }

    /// Publishes the writer's checkpoint if it is back, waiting up to `wait` for it.
    fn publish_written(&mut self, wait: Option<Duration>) {
        if !self.in_flight {
            return;
        }
        let Some(writer) = self.writer.as_ref() else {
            return;
        };
        let written = match wait {
            None => match writer.rx.try_recv() {
                Ok(w) => w,
                Err(TryRecvError::Empty) => return,
                Err(TryRecvError::Disconnected) => return self.writer_lost(),
            },
            Some(wait) => match writer.rx.recv_timeout(wait) {
                Ok(w) => w,
                Err(RecvTimeoutError::Timeout) => {
                    warn!(
                        "checkpoint {} not serialised within {wait:?}: published when it comes",
                        self.id
                    );
                    return;
                }
                Err(RecvTimeoutError::Disconnected) => return self.writer_lost(),
            },
        };
        self.in_flight = false;
        let Written {
            parts,
            id,
            imu_count,
            copy_us,
            serialise_us,
            copy,
        } = written;
        let freed = std::time::Instant::now();
        drop(copy);
        let free_us = freed.elapsed().as_micros();
        let (bytes, parts) = match parts {
            Ok(p) => p,
            Err(e) => return self.failed(&e),
        };
        let published = std::time::Instant::now();
        let mut sent = Ok(());
        for part in &parts {
            if let Err(e) = self.port.send(part) {
                sent = Err(e.to_string());
                break;
            }
        }
        let publish_us = published.elapsed().as_micros();
        let count = parts.len() as u64;
        if let Some(w) = self.writer.as_ref() {
            // Never waits: a full queue means a stuck writer; then they are freed here.
            let _ = w.tx.try_send(ToWriter::Free(parts));
        }
        if let Err(e) = sent {
            return self.failed(&e);
        }
        self.seq += count;
        if id == 0 {
            info!(
                bytes,
                parts = count,
                copy_us,
                serialise_us,
                free_us,
                publish_us,
                "first checkpoint published (after IMU sample {imu_count})"
            );
        } else {
            debug!(
                id,
                bytes,
                parts = count,
                copy_us,
                serialise_us,
                free_us,
                publish_us,
                "checkpoint published"
            );
        }
        self.id = id + 1;
    }

    fn writer_lost(&mut self) {
        self.in_flight = false;
        self.writer = None;
        warn!("checkpoints off: their writer thread ended");
    }

    fn failed(&mut self, why: &str) {
        // A lost checkpoint costs a late recording its start there, never the daemon anything.
        self.failures += 1;
        if self.failures < 5 || self.failures.is_power_of_two() {
            warn!(failures = self.failures, "checkpoint not published: {why}");
        }
    }
}
