//! The command gate: which received thrust commands may reach the simulated thrusters.
//!
//! Pure (no IPC, no clock) so every rule is unit-tested. A command is applied only when it
//! passes the protocol's content validation (count within capacity, known mode, every
//! thrust finite and in [-1, 1]), has the configured thruster count, and answers a sample
//! that was published, with that sample's timestamp. Garbage is counted by category
//! ([`RejectCounters`]) and never applied.

use std::ops::RangeInclusive;

use thruster_protocol::validate::{expect_count, Field, RejectCounters, RejectReason};
use thruster_protocol::{ThrustCommand, Validate};

/// What to do with one received command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// Apply it.
    Accept,
    /// Valid, but it answers a sample older than the ones that may still be answered (a late
    /// answer); dropped without fault.
    Stale,
    /// Invalid: never applied; the caller goes neutral.
    Reject(RejectReason),
}

/// Validates commands against the thruster count and the published samples, and counts.
#[derive(Debug, Clone)]
pub struct CommandGate {
    count: u32,
    period_ns: u64,
    rejected: RejectCounters,
    stale: u64,
    accepted: u64,
}

impl CommandGate {
    /// A gate for `count` thrusters and IMU samples every `period_ns`, sample `seq` (from 1)
    /// taken at `(seq - 1) * period_ns`.
    pub fn new(count: usize, period_ns: u64) -> Self {
        CommandGate {
            count: count as u32,
            period_ns,
            rejected: RejectCounters::default(),
            stale: 0,
            accepted: 0,
        }
    }

    /// The thruster count commands must have.
    pub fn count(&self) -> usize {
        self.count as usize
    }

    /// Changes the expected count (after a thruster was added or removed).
    pub fn set_count(&mut self, count: usize) {
        self.count = count as u32;
    }

    /// Time of sample `seq` (the driver's sample clock is exact: samples are never skipped).
    pub fn sample_time_ns(&self, seq: u64) -> u64 {
        seq.saturating_sub(1).saturating_mul(self.period_ns)
    }

    /// Judges `cmd`, which may answer any sample in `answerable` (inclusive; the end is the
    /// newest published sample), and counts the verdict.
    pub fn check(&mut self, cmd: &ThrustCommand, answerable: RangeInclusive<u64>) -> Verdict {
        let verdict = self.judge(cmd, &answerable);
        match &verdict {
            Verdict::Accept => self.accepted += 1,
            Verdict::Stale => self.stale += 1,
            Verdict::Reject(reason) => self.rejected.record(reason),
        }
        verdict
    }

    fn judge(&self, cmd: &ThrustCommand, answerable: &RangeInclusive<u64>) -> Verdict {
        if let Err(reason) = cmd.validate() {
            return Verdict::Reject(reason);
        }
        if let Err(reason) = expect_count("count", cmd.count, self.count) {
            return Verdict::Reject(reason);
        }
        if cmd.imu_seq > *answerable.end() {
            return Verdict::Reject(RejectReason::Inconsistent {
                field: Field::new("imu_seq"),
                detail: "answers a sample that was not published",
            });
        }
        if cmd.imu_seq < *answerable.start() {
            return Verdict::Stale;
        }
        if cmd.t_ns != self.sample_time_ns(cmd.imu_seq) {
            return Verdict::Reject(RejectReason::Inconsistent {
                field: Field::new("t_ns"),
                detail: "is not the time of the sample named by imu_seq",
            });
        }
        Verdict::Accept
    }

    /// Rejections so far, by category.
    pub fn rejected(&self) -> &RejectCounters {
        &self.rejected
    }

    /// Late (stale) answers dropped so far.
    pub fn stale(&self) -> u64 {
        self.stale
    }

    /// Commands accepted so far.
    pub fn accepted(&self) -> u64 {
        self.accepted
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use thruster_protocol::validate::RejectCategory;
    use thruster_protocol::ThrustMode;

    const PERIOD: u64 = 5_000_000;

    fn cmd(imu_seq: u64, thrust: &[f64]) -> ThrustCommand {
        let mut c = ThrustCommand::neutral(
            imu_seq,
            imu_seq,
            (imu_seq - 1) * PERIOD,
            thrust.len() as u32,
        );
        c.set_mode(ThrustMode::Controlling);
        c.thrusters_mut().copy_from_slice(thrust);
        c
    }

    #[test]
    fn accepts_the_answer_to_a_published_sample() {
        let mut g = CommandGate::new(3, PERIOD);
        assert_eq!(g.check(&cmd(4, &[1.0, -0.5, 0.0]), 4..=4), Verdict::Accept);
        assert_eq!(g.check(&cmd(2, &[1.0, -0.5, 0.0]), 1..=4), Verdict::Accept);
        assert_eq!(g.accepted(), 2);
        assert_eq!(g.rejected().total(), 0);
    }

    #[test]
    fn rejects_garbage_by_category() {
        let mut g = CommandGate::new(3, PERIOD);
        let cases = [
            (cmd(4, &[f64::NAN, 0.0, 0.0]), RejectCategory::NonFinite),
            (
                cmd(4, &[0.0, f64::INFINITY, 0.0]),
                RejectCategory::NonFinite,
            ),
            (cmd(4, &[0.0, 0.0, 1.5]), RejectCategory::Range),
            (cmd(4, &[0.0, 0.0]), RejectCategory::Count),
            (cmd(4, &[0.0; 4]), RejectCategory::Count),
            (
                ThrustCommand {
                    count: 99,
                    ..cmd(4, &[0.0; 3])
                },
                RejectCategory::Count,
            ),
            (
                ThrustCommand {
                    mode: 77,
                    ..cmd(4, &[0.0; 3])
                },
                RejectCategory::Other,
            ),
            // Answers a sample not published yet.
            (cmd(5, &[0.0; 3]), RejectCategory::Other),
            // Wrong timestamp for the sample it names.
            (
                ThrustCommand {
                    t_ns: 1,
                    ..cmd(4, &[0.0; 3])
                },
                RejectCategory::Other,
            ),
        ];
        for (c, category) in cases {
            match g.check(&c, 4..=4) {
                Verdict::Reject(r) => assert_eq!(r.category(), category, "{r}"),
                other => panic!("{c:?} gave {other:?}"),
            }
        }
        let r = g.rejected();
        assert_eq!(
            (r.nonfinite, r.range, r.count, r.other),
            (2, 1, 3, 3),
            "{r:?}"
        );
        assert_eq!(g.accepted(), 0);
    }

    #[test]
    fn late_answers_are_stale_not_faults_and_counts_follow_reconfiguration() {
        let mut g = CommandGate::new(3, PERIOD);
        assert_eq!(g.check(&cmd(3, &[0.2; 3]), 4..=4), Verdict::Stale);
        assert_eq!(g.stale(), 1);
        g.set_count(4);
        assert!(matches!(
            g.check(&cmd(4, &[0.2; 3]), 4..=4),
            Verdict::Reject(_)
        ));
        assert_eq!(g.check(&cmd(4, &[0.2; 4]), 4..=4), Verdict::Accept);
        assert_eq!(g.sample_time_ns(1), 0);
        assert_eq!(g.sample_time_ns(0), 0);
    }
}
