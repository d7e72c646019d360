//! Checkpoints of the state machine on the `checkpoint` topic: the machine's whole state
//! (`Machine::checkpoint`) with its place in the input journal, after each model swap and
//! every `checkpoint.period_s` vehicle seconds. A recording started after the daemon replays
//! from its first checkpoint (`thrusterd replay`, docs/recording.md "Checkpoints").
//!
//! When: after a sample's answer went out and its solve jobs were handed to the worker (so
//! the sample's own latency never includes it), at the first such sample where the state is
//! complete (no job out with the worker: its work is not in the state) and small (no
//! estimation under way, no refinement window open: about 0.2 MB, serialised in well under a
//! millisecond; docs/recording.md has the figures). Publishing never waits (safe overflow).

use std::time::Instant;

use thruster_protocol::services::Port;
use thruster_protocol::CheckpointMsg;
use thrusterd_core::checkpoint_parts::{self, Place};
use thrusterd_core::config::CheckpointSection;
use thrusterd_core::machine::Machine;
use tracing::{debug, info, warn};

pub struct Checkpoints {
    port: Port<CheckpointMsg>,
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
    pub fn new(port: Port<CheckpointMsg>, cfg: &CheckpointSection) -> Self {
        Checkpoints {
            port,
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

    /// After an accepted sample at vehicle time `t_ns` was answered: takes and publishes a
    /// checkpoint if one is due and the machine's state allows it. `place`: the journal's
    /// position now (accepted samples, the last one's seq and time, the next entry's seq).
    pub fn after_sample(&mut self, machine: &Machine, t_ns: u64, place: Place) {
        let periodic = self.period_ns > 0 && t_ns >= self.next_periodic_ns;
        if !(periodic || self.swap_pending)
            || !machine.checkpointable()
            || !machine.checkpoint_small()
        {
            return;
        }
        let reason = if self.swap_pending {
            CheckpointMsg::AFTER_SWAP
        } else {
            CheckpointMsg::PERIODIC
        };
        self.swap_pending = false;
        if self.period_ns > 0 {
            self.next_periodic_ns = t_ns.saturating_add(self.period_ns);
        }
        let started = Instant::now();
        let place = Place {
            model_version: machine.model().map_or(0, |m| m.version),
            reason,
            ..place
        };
        let parts = machine
            .checkpoint()
            .map_err(|e| e.to_string())
            .and_then(|bytes| {
                checkpoint_parts::split(self.id, &place, &bytes, self.seq)
                    .map(|parts| (bytes.len(), parts))
                    .map_err(|e| e.to_string())
            });
        let (bytes, parts) = match parts {
            Ok(p) => p,
            Err(e) => return self.failed(&e),
        };
        for part in &parts {
            if let Err(e) = self.port.send(part) {
                return self.failed(&e.to_string());
            }
        }
        self.seq += parts.len() as u64;
        let us = started.elapsed().as_micros();
        if self.id == 0 {
            info!(
                bytes,
                parts = parts.len(),
                us,
                "first checkpoint published (after IMU sample {})",
                place.imu_count
            );
        } else {
            debug!(
                id = self.id,
                bytes,
                parts = parts.len(),
                us,
                "checkpoint published"
            );
        }
        self.id += 1;
    }

    fn failed(&mut self, why: &str) {
        // A lost checkpoint costs a late recording its start there, never the daemon anything.
        self.failures += 1;
        if self.failures < 5 || self.failures.is_power_of_two() {
            warn!(failures = self.failures, "checkpoint not published: {why}");
        }
    }
}
