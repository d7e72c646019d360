//! The command gate every driver runs: which received [`ThrustCommand`]s may reach the
//! thrusters. Pure (no IPC, no clock) so every rule is unit-tested here once, and the
//! conformance suite checks each driver process obeys it.
//!
//! A command passes when
//! 1. the protocol's content validation accepts it ([`Validate`]: count within capacity,
//!    known mode, every thrust finite and in [-1, 1]),
//! 2. its count equals the driver's thruster count,
//! 3. it answers a sample this driver published (`imu_seq` from 1 to the newest),
//! 4. it is not older than the oldest sample still answerable ([`Answerable`]); an older
//!    one is *stale*: a late answer, dropped without fault,
//! 5. its `t_ns` is that sample's time ([`SampleTimes`] says how the gate knows it).
//!
//! The two drivers differ only in rules 4 and 5, and say so in [`GateSettings`]: the
//! simulator's sample clock is an exact grid and in lockstep only the newest sample may be
//! answered; hardware samples are stamped by a real clock, so the gate remembers them.
//! Freshness against the clock is each driver's watchdog.

use crate::validate::{expect_count, Field, RejectCounters, RejectReason};
use crate::{ThrustCommand, Validate};

/// How many published samples a [`SampleTimes::Remembered`] gate keeps. At 1 kHz this is
/// 64 ms, more than any useful answer delay below the default 200 ms watchdog would need at
/// 200 Hz (and anything older is refused as stale, never applied).
pub const REMEMBERED_SAMPLES: usize = 64;

/// How the gate knows the time of a published sample (rule 5).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SampleTimes {
    /// Sample `seq` (from 1) is taken at `(seq - 1) * period_ns`: a simulator's exact clock,
    /// which never skips a sample.
    Grid {
        /// The sample period, ns.
        period_ns: u64,
    },
    /// The last [`REMEMBERED_SAMPLES`] published samples are remembered with their times; an
    /// answer to one already forgotten is stale.
    Remembered,
}

/// Which published samples a command may still answer (rule 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Answerable {
    /// The newest published sample and any after the last one answered by an applied
    /// command ([`CommandGate::applied`]).
    SinceApplied,
    /// Only the newest published sample (lockstep: one answer per sample).
    NewestOnly,
}

/// What differs between drivers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GateSettings {
    /// Rule 5.
    pub sample_times: SampleTimes,
    /// Rule 4.
    pub answerable: Answerable,
}

/// What to do with one received command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// Valid and current: apply it (a driver's watchdog may still refuse it).
    Accept,
    /// Valid, but it answers a sample no longer answerable (a late answer): dropped without
    /// fault.
    Stale,
    /// Invalid: never applied; the driver goes neutral.
    Reject(RejectReason),
}

/// Judges commands against the thruster count and the published samples, and counts the
/// verdicts of [`CommandGate::check`].
#[derive(Debug, Clone)]
pub struct CommandGate {
    count: u32,
    settings: GateSettings,
    ring: [(u64, u64); REMEMBERED_SAMPLES],
    newest_seq: u64,
    applied_seq: u64,
    rejected: RejectCounters,
    stale: u64,
    accepted: u64,
}

impl CommandGate {
    /// A gate for `count` thrusters.
    pub fn new(count: usize, settings: GateSettings) -> Self {
        CommandGate {
            count: count as u32,
            settings,
            ring: [(0, 0); REMEMBERED_SAMPLES],
            newest_seq: 0,
            applied_seq: 0,
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

    /// Records a published sample (`seq` increasing from 1) taken at `t_ns`.
    pub fn published(&mut self, seq: u64, t_ns: u64) {
        if self.settings.sample_times == SampleTimes::Remembered {
            self.ring[(seq as usize) % REMEMBERED_SAMPLES] = (seq, t_ns);
        }
        self.newest_seq = self.newest_seq.max(seq);
    }

    /// Records that a command answering `imu_seq` was applied: older samples are no longer
    /// answerable under [`Answerable::SinceApplied`].
    pub fn applied(&mut self, imu_seq: u64) {
        self.applied_seq = self.applied_seq.max(imu_seq);
    }

    /// The newest published sample's seq (0 before the first).
    pub fn newest_seq(&self) -> u64 {
        self.newest_seq
    }

    /// Time of sample `seq` on a [`SampleTimes::Grid`] gate (`None` on a remembering one).
    pub fn grid_time_ns(&self, seq: u64) -> Option<u64> {
        match self.settings.sample_times {
            SampleTimes::Grid { period_ns } => {
                Some(seq.saturating_sub(1).saturating_mul(period_ns))
            }
            SampleTimes::Remembered => None,
        }
    }

    /// Judges `cmd` and counts the verdict.
    pub fn check(&mut self, cmd: &ThrustCommand) -> Verdict {
        let verdict = self.judge(cmd);
        match &verdict {
            Verdict::Accept => self.accepted += 1,
            Verdict::Stale => self.stale += 1,
            Verdict::Reject(reason) => self.rejected.record(reason),
        }
        verdict
    }

    /// Judges `cmd` without counting (for a driver that counts its own outcomes).
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
        let oldest = match self.settings.answerable {
            Answerable::SinceApplied => self.applied_seq,
            Answerable::NewestOnly => self.newest_seq,
        };
        if cmd.imu_seq < oldest {
            return Verdict::Stale;
        }
        let t_ns = match self.settings.sample_times {
            SampleTimes::Grid { period_ns } => {
                cmd.imu_seq.saturating_sub(1).saturating_mul(period_ns)
            }
            SampleTimes::Remembered => {
                let (seq, t_ns) = self.ring[(cmd.imu_seq as usize) % REMEMBERED_SAMPLES];
                if seq != cmd.imu_seq {
                    return Verdict::Stale;
                }
                t_ns
            }
        };
        if cmd.t_ns != t_ns {
            return Verdict::Reject(RejectReason::Inconsistent {
                field: Field::new("t_ns"),
                detail: "is not the time of the sample named by imu_seq",
            });
        }
        Verdict::Accept
    }

    /// Rejections counted by [`CommandGate::check`], by category.
    pub fn rejected(&self) -> &RejectCounters {
        &self.rejected
    }

    /// Late (stale) answers counted by [`CommandGate::check`].
    pub fn stale(&self) -> u64 {
        self.stale
    }

    /// Commands accepted by [`CommandGate::check`].
    pub fn accepted(&self) -> u64 {
        self.accepted
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validate::RejectCategory;
    use crate::ThrustMode;

    const PERIOD: u64 = 5_000_000;

    const GRID: GateSettings = GateSettings {
        sample_times: SampleTimes::Grid { period_ns: PERIOD },
        answerable: Answerable::SinceApplied,
    };
    const LOCKSTEP: GateSettings = GateSettings {
        answerable: Answerable::NewestOnly,
        ..GRID
    };
    const REMEMBERED: GateSettings = GateSettings {
        sample_times: SampleTimes::Remembered,
        answerable: Answerable::SinceApplied,
    };

    fn cmd_at(imu_seq: u64, t_ns: u64, thrust: &[f64]) -> ThrustCommand {
        let mut c = ThrustCommand::neutral(imu_seq, imu_seq, t_ns, thrust.len() as u32);
        c.set_mode(ThrustMode::Controlling);
        c.thrusters_mut().copy_from_slice(thrust);
        c
    }

    /// The answer to sample `imu_seq` of a gate fed by [`gate`].
    fn cmd(imu_seq: u64, thrust: &[f64]) -> ThrustCommand {
        cmd_at(imu_seq, imu_seq.saturating_sub(1) * PERIOD, thrust)
    }

    /// A gate for 3 thrusters that published samples 1..=`samples` on the grid's times.
    fn gate(settings: GateSettings, samples: u64) -> CommandGate {
        let mut g = CommandGate::new(3, settings);
        for s in 1..=samples {
            g.published(s, (s - 1) * PERIOD);
        }
        g
    }

    #[test]
    fn accepts_answers_to_published_samples() {
        for settings in [GRID, REMEMBERED] {
            let mut g = gate(settings, 5);
            assert_eq!(g.check(&cmd(5, &[1.0, -0.5, 0.0])), Verdict::Accept);
            assert_eq!(g.check(&cmd(3, &[0.0; 3])), Verdict::Accept);
            assert_eq!((g.accepted(), g.rejected().total()), (2, 0));
        }
    }

    #[test]
    fn rejects_garbage_by_category_in_every_setting() {
        for settings in [GRID, LOCKSTEP, REMEMBERED] {
            let mut g = gate(settings, 5);
            let cases = [
                (cmd(5, &[f64::NAN, 0.0, 0.0]), RejectCategory::NonFinite),
                (
                    cmd(5, &[0.0, f64::NEG_INFINITY, 0.0]),
                    RejectCategory::NonFinite,
                ),
                (cmd(5, &[0.0, 0.0, 1e9]), RejectCategory::Range),
                (cmd(5, &[0.0, 0.0, -1.0000001]), RejectCategory::Range),
                (cmd(5, &[0.0; 2]), RejectCategory::Count),
                (cmd(5, &[0.0; 4]), RejectCategory::Count),
                (
                    ThrustCommand {
                        count: 17,
                        ..cmd(5, &[0.0; 3])
                    },
                    RejectCategory::Count,
                ),
                (
                    ThrustCommand {
                        mode: 9,
                        ..cmd(5, &[0.0; 3])
                    },
                    RejectCategory::Other,
                ),
                // A sample not published yet, and sample 0, which never is.
                (cmd(6, &[0.0; 3]), RejectCategory::Other),
                (cmd_at(0, 0, &[0.0; 3]), RejectCategory::Other),
                // The wrong time for the sample it names.
                (cmd_at(5, 4 * PERIOD - 1, &[0.0; 3]), RejectCategory::Other),
            ];
            for (c, category) in cases {
                match g.check(&c) {
                    Verdict::Reject(r) => assert_eq!(r.category(), category, "{c:?}: {r}"),
                    other => panic!("{settings:?}: {c:?} gave {other:?}"),
                }
            }
            let r = g.rejected();
            assert_eq!(
                (r.nonfinite, r.range, r.count, r.other),
                (2, 2, 3, 4),
                "{r:?}"
            );
            assert_eq!(g.accepted(), 0);
        }
    }

    #[test]
    fn answers_older_than_the_last_applied_are_stale() {
        for settings in [GRID, REMEMBERED] {
            let mut g = gate(settings, 50);
            g.applied(40);
            assert_eq!(g.check(&cmd(39, &[0.1; 3])), Verdict::Stale);
            assert_eq!(g.check(&cmd(40, &[0.1; 3])), Verdict::Accept);
            assert_eq!(g.stale(), 1);
        }
    }

    #[test]
    fn in_lockstep_only_the_newest_sample_is_answerable() {
        let mut g = gate(LOCKSTEP, 4);
        assert_eq!(g.check(&cmd(3, &[0.2; 3])), Verdict::Stale);
        assert_eq!(g.check(&cmd(4, &[0.2; 3])), Verdict::Accept);
        g.published(5, 4 * PERIOD);
        assert_eq!(g.check(&cmd(4, &[0.2; 3])), Verdict::Stale);
        assert_eq!(g.stale(), 2);
    }

    #[test]
    fn a_remembering_gate_forgets_old_samples_and_a_grid_does_not() {
        let g = gate(REMEMBERED, 100);
        // Sample 30 is no longer remembered (ring of 64).
        assert_eq!(g.judge(&cmd(30, &[0.1; 3])), Verdict::Stale);
        assert_eq!(g.judge(&cmd(40, &[0.1; 3])), Verdict::Accept);
        let g = gate(GRID, 100);
        assert_eq!(g.judge(&cmd(30, &[0.1; 3])), Verdict::Accept);
        assert_eq!((g.grid_time_ns(1), g.grid_time_ns(0)), (Some(0), Some(0)));
        assert_eq!(gate(REMEMBERED, 1).grid_time_ns(1), None);
    }

    #[test]
    fn the_count_follows_reconfiguration() {
        let mut g = gate(GRID, 4);
        g.set_count(4);
        assert_eq!(g.count(), 4);
        assert!(matches!(g.check(&cmd(4, &[0.2; 3])), Verdict::Reject(_)));
        assert_eq!(g.check(&cmd(4, &[0.2; 4])), Verdict::Accept);
        assert_eq!(g.newest_seq(), 4);
    }
}
