//! Which received thrust commands may reach the thrusters. Pure: no IPC, no clock.
//!
//! A command passes when
//! 1. the protocol's content validation accepts it ([`thruster_protocol::Validate`]: count
//!    within capacity, known mode, every thrust finite and in [-1, 1]),
//! 2. its count equals the configured number of thrusters,
//! 3. it answers a sample this driver published (`imu_seq`) with that sample's `t_ns`,
//! 4. it is not older than a command already applied (a late answer is *stale*, dropped
//!    without fault).
//!
//! Freshness against the clock is the watchdog's job ([`super::watchdog`]).

use thruster_protocol::validate::{expect_count, Field, RejectReason};
use thruster_protocol::{ThrustCommand, Validate};

/// How many published samples are remembered for rule 3. At 1 kHz this is 64 ms, more than
/// any useful answer delay below the default 200 ms watchdog would need at 200 Hz (and
/// anything older is refused as stale, never applied).
pub const REMEMBERED_SAMPLES: usize = 64;

/// What to do with one command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// Valid and current: offer it to the watchdog.
    Accept,
    /// Valid but answers a sample older than one already answered, or one too old to be
    /// remembered: dropped.
    Stale,
    /// Invalid: never applied; outputs go neutral.
    Reject(RejectReason),
}

/// Remembers the published samples and judges commands against them.
#[derive(Debug, Clone)]
pub struct CommandGate {
    count: u32,
    ring: [(u64, u64); REMEMBERED_SAMPLES],
    newest_seq: u64,
    applied_seq: u64,
}

impl CommandGate {
    /// A gate for `count` thrusters.
    pub fn new(count: usize) -> Self {
        CommandGate {
            count: count as u32,
            ring: [(0, 0); REMEMBERED_SAMPLES],
            newest_seq: 0,
            applied_seq: 0,
        }
    }

    /// The thruster count commands must have.
    pub fn count(&self) -> usize {
        self.count as usize
    }

    /// Records a published sample (`seq` increasing from 1).
    pub fn published(&mut self, seq: u64, t_ns: u64) {
        self.ring[(seq as usize) % REMEMBERED_SAMPLES] = (seq, t_ns);
        self.newest_seq = self.newest_seq.max(seq);
    }

    /// Records that a command answering `imu_seq` was applied.
    pub fn applied(&mut self, imu_seq: u64) {
        self.applied_seq = self.applied_seq.max(imu_seq);
    }

    /// The newest published sample's seq (0 before the first).
    pub fn newest_seq(&self) -> u64 {
        self.newest_seq
    }

    /// Judges `cmd`.
    pub fn judge(&self, cmd: &ThrustCommand) -> Verdict {
        if let Err(reason) = cmd.validate() {
            return Verdict::Reject(reason);
        }
        if let Err(reason) = expect_count("count", cmd.count, self.count) {
            return Verdict::Reject(reason);
        }
        if cmd.imu_seq == 0 || cmd.imu_seq > self.newest_seq {
            return Verdict::Reject(RejectReason::Inconsistent {
                field: Field::new("imu_seq"),
                detail: "answers a sample that was not published",
            });
        }
        if cmd.imu_seq < self.applied_seq {
            return Verdict::Stale;
        }
        let (seq, t_ns) = self.ring[(cmd.imu_seq as usize) % REMEMBERED_SAMPLES];
        if seq != cmd.imu_seq {
            return Verdict::Stale;
        }
        if t_ns != cmd.t_ns {
            return Verdict::Reject(RejectReason::Inconsistent {
                field: Field::new("t_ns"),
                detail: "is not the time of the sample named by imu_seq",
            });
        }
        Verdict::Accept
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use thruster_protocol::validate::RejectCategory;
    use thruster_protocol::ThrustMode;

    fn cmd(imu_seq: u64, t_ns: u64, thrust: &[f64]) -> ThrustCommand {
        let mut c = ThrustCommand::neutral(imu_seq, imu_seq, t_ns, thrust.len() as u32);
        c.set_mode(ThrustMode::Controlling);
        c.thrusters_mut().copy_from_slice(thrust);
        c
    }

    fn gate_with(samples: u64) -> CommandGate {
        let mut g = CommandGate::new(3);
        for s in 1..=samples {
            g.published(s, s * 1000);
        }
        g
    }

    #[test]
    fn accepts_answers_to_published_samples() {
        let g = gate_with(5);
        assert_eq!(g.judge(&cmd(5, 5000, &[1.0, -0.5, 0.0])), Verdict::Accept);
        assert_eq!(g.judge(&cmd(3, 3000, &[0.0; 3])), Verdict::Accept);
    }

    #[test]
    fn rejects_garbage_by_category() {
        let g = gate_with(5);
        let cases = [
            (
                cmd(5, 5000, &[f64::NAN, 0.0, 0.0]),
                RejectCategory::NonFinite,
            ),
            (
                cmd(5, 5000, &[0.0, f64::NEG_INFINITY, 0.0]),
                RejectCategory::NonFinite,
            ),
            (cmd(5, 5000, &[0.0, 0.0, 1e9]), RejectCategory::Range),
            (cmd(5, 5000, &[0.0, 0.0, -1.0000001]), RejectCategory::Range),
            (cmd(5, 5000, &[0.0; 2]), RejectCategory::Count),
            (cmd(5, 5000, &[0.0; 4]), RejectCategory::Count),
            (
                ThrustCommand {
                    count: 17,
                    ..cmd(5, 5000, &[0.0; 3])
                },
                RejectCategory::Count,
            ),
            (
                ThrustCommand {
                    mode: 9,
                    ..cmd(5, 5000, &[0.0; 3])
                },
                RejectCategory::Other,
            ),
            (cmd(6, 6000, &[0.0; 3]), RejectCategory::Other),
            (cmd(0, 0, &[0.0; 3]), RejectCategory::Other),
            (cmd(5, 4999, &[0.0; 3]), RejectCategory::Other),
        ];
        for (c, category) in cases {
            match g.judge(&c) {
                Verdict::Reject(r) => assert_eq!(r.category(), category, "{c:?}: {r}"),
                other => panic!("{c:?} gave {other:?}"),
            }
        }
    }

    #[test]
    fn late_and_forgotten_answers_are_stale() {
        let mut g = gate_with(100);
        g.applied(90);
        assert_eq!(g.judge(&cmd(89, 89_000, &[0.1; 3])), Verdict::Stale);
        assert_eq!(g.judge(&cmd(90, 90_000, &[0.1; 3])), Verdict::Accept);
        let mut g = gate_with(100);
        // Sample 30 is no longer remembered (ring of 64).
        assert_eq!(g.judge(&cmd(30, 30_000, &[0.1; 3])), Verdict::Stale);
        g.published(101, 101_000);
        assert_eq!(g.newest_seq(), 101);
        assert_eq!(g.count(), 3);
    }
}
