//! The input journal: every input the daemon hands its state machine besides an IMU sample,
//! published on the `input` topic with the count of accepted IMU samples it came after, and
//! the effective configuration on `config`. A recording of the IMU stream, the journal and
//! the configuration is everything the machine saw, so `thrusterd replay` can run the same
//! machine offline (docs/recording.md, "Replay").
//!
//! Publishing never waits (iceoryx2's safe overflow), and inputs are rare (requests,
//! setpoints, reconfigurations, driver verdicts): nothing here is on the per-sample path
//! except counting.

use thruster_protocol::services::Port;
use thruster_protocol::{ConfigMsg, InputKind, InputMsg, ReconfigEvent, Setpoint};
use tracing::{error, warn};

pub struct Journal {
    port: Port<InputMsg>,
    seq: u64,
    /// Accepted IMU samples handed to the machine so far, and the last one's seq and time.
    imu_count: u64,
    imu_seq: u64,
    t_ns: u64,
    failures: u64,
}

impl Journal {
    pub fn new(port: Port<InputMsg>) -> Self {
        Self {
            port,
            seq: 0,
            imu_count: 0,
            imu_seq: 0,
            t_ns: 0,
            failures: 0,
        }
    }

    /// An accepted IMU sample went to the machine.
    pub fn imu(&mut self, seq: u64, t_ns: u64) {
        self.imu_count += 1;
        self.imu_seq = seq;
        self.t_ns = t_ns;
    }

    /// Where the journal stands: accepted samples so far, the last one's seq and time, and the
    /// seq the next entry will get (a checkpoint's place, `checkpoints`).
    pub fn place(&self) -> thrusterd_core::checkpoint_parts::Place {
        thrusterd_core::checkpoint_parts::Place {
            imu_count: self.imu_count,
            imu_seq: self.imu_seq,
            t_ns: self.t_ns,
            journal_next: self.seq,
            ..Default::default()
        }
    }

    /// Publishes one input; `fill` sets its kind-specific fields.
    pub fn record(&mut self, kind: InputKind, refused: bool, fill: impl FnOnce(&mut InputMsg)) {
        let mut msg = InputMsg {
            seq: self.seq,
            imu_count: self.imu_count,
            imu_seq: self.imu_seq,
            t_ns: self.t_ns,
            refused: u32::from(refused),
            ..InputMsg::default()
        };
        msg.set_kind(kind);
        fill(&mut msg);
        self.seq += 1;
        if let Err(e) = self.port.send(&msg) {
            // A lost journal entry makes a recording unreplayable, never the daemon wrong.
            self.failures += 1;
            if self.failures < 5 || self.failures.is_power_of_two() {
                error!(failures = self.failures, "input journal not published: {e}");
            }
        }
    }

    pub fn setpoint(&mut self, s: &Setpoint) {
        self.record(InputKind::Setpoint, false, |m| m.setpoint = *s);
    }

    pub fn reconfig(&mut self, e: &ReconfigEvent) {
        self.record(InputKind::Reconfig, false, |m| m.reconfig = *e);
    }

    /// A text input (why, a path): `code` and `refused` as the kind defines them.
    pub fn text(&mut self, kind: InputKind, code: u32, refused: bool, text: &str) {
        self.record(kind, refused, |m| {
            m.code = code;
            m.text.set(text);
        });
    }
}

/// The effective configuration as a message: TOML, cut (and marked so) when it does not fit.
pub fn config_msg(cfg: &thrusterd_core::config::DaemonConfig) -> ConfigMsg {
    let text = match toml::to_string(cfg) {
        Ok(t) => t,
        Err(e) => {
            warn!("configuration not serialisable for the config topic: {e}");
            String::new()
        }
    };
    let mut msg = ConfigMsg::default();
    let stored = msg.toml.set(&text);
    if stored < text.len() || text.is_empty() {
        warn!(
            bytes = text.len(),
            "configuration does not fit the config topic: a recording of this daemon cannot be replayed with its own settings"
        );
        msg.truncated = 1;
    }
    msg
}
