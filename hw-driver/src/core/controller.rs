//! The output stage: commands in, pulse widths out. Pure: time passed in.
//!
//! Combines the [`CommandGate`] (is this command valid and current?), the [`Watchdog`]
//! (is it fresh, are we past arming, has it expired?) and one [`OutputMap`] per thruster.
//! Outputs are the mapped command while the watchdog is live and every thruster's neutral
//! otherwise. An invalid command withdraws the held one at once: a daemon that sends
//! garbage gets neutral, not its previous command.

use std::fmt;

use thruster_protocol::validate::{RejectCounters, RejectReason};
use thruster_protocol::ThrustCommand;

use super::pwm::{OutputMap, Pwm};
use super::watchdog::{Refusal, Watchdog, WatchdogState};
use thruster_protocol::gate::{Answerable, CommandGate, GateSettings, SampleTimes, Verdict};

/// What happened to one command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outcome {
    /// Applied: the outputs follow it.
    Applied,
    /// Valid, but during the arming hold: not applied.
    Arming,
    /// Valid, but late or older than the watchdog: dropped.
    Stale,
    /// Invalid: counted, outputs neutral.
    Rejected(RejectReason),
}

/// Why the outputs are neutral, or that they are not.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputState {
    /// Start-up neutral hold.
    Arming,
    /// Waiting for the first command.
    Waiting,
    /// Following commands.
    Active,
    /// No fresh valid command within the watchdog.
    Watchdog,
    /// The last command was invalid.
    Rejected,
}

impl fmt::Display for OutputState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            OutputState::Arming => "arming (neutral)",
            OutputState::Waiting => "waiting for commands (neutral)",
            OutputState::Active => "active",
            OutputState::Watchdog => "watchdog expired (neutral)",
            OutputState::Rejected => "invalid command (neutral)",
        })
    }
}

/// Command counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    /// Commands applied.
    pub applied: u64,
    /// Valid commands received during arming.
    pub arming: u64,
    /// Late or old commands dropped.
    pub stale: u64,
    /// Invalid commands, by category.
    pub rejected: RejectCounters,
}

/// See the module docs.
#[derive(Debug, Clone)]
pub struct Controller {
    maps: Vec<OutputMap>,
    gate: CommandGate,
    watchdog: Watchdog,
    commanded: Vec<Pwm>,
    neutral: Vec<Pwm>,
    last_rejected: bool,
    counters: Counters,
}

impl Controller {
    /// An output stage for `maps` (one per thruster, in command order) started at
    /// `start_ns`, holding neutral for `arming_ns`, with a watchdog of `watchdog_ns`.
    pub fn new(maps: Vec<OutputMap>, start_ns: u64, arming_ns: u64, watchdog_ns: u64) -> Self {
        let neutral: Vec<Pwm> = maps.iter().map(OutputMap::neutral).collect();
        Controller {
            gate: CommandGate::new(
                maps.len(),
                GateSettings {
                    // Samples are stamped by a real clock: the gate remembers their times.
                    sample_times: SampleTimes::Remembered,
                    answerable: Answerable::SinceApplied,
                },
            ),
            watchdog: Watchdog::new(start_ns, arming_ns, watchdog_ns),
            commanded: neutral.clone(),
            neutral,
            maps,
            last_rejected: false,
            counters: Counters::default(),
        }
    }

    /// Records a published IMU sample, so commands answering it can be checked.
    pub fn published(&mut self, seq: u64, t_ns: u64) {
        self.gate.published(seq, t_ns);
    }

    /// Takes one received command at `now_ns`.
    pub fn on_command(&mut self, cmd: &ThrustCommand, now_ns: u64) -> Outcome {
        match self.gate.judge(cmd) {
            Verdict::Reject(reason) => {
                self.counters.rejected.record(&reason);
                self.watchdog.withdraw(now_ns);
                self.commanded.clone_from(&self.neutral);
                self.last_rejected = true;
                Outcome::Rejected(reason)
            }
            Verdict::Stale => {
                self.counters.stale += 1;
                Outcome::Stale
            }
            Verdict::Accept => match self.watchdog.feed(cmd.t_ns, now_ns) {
                Ok(()) => {
                    for ((out, map), &u) in self
                        .commanded
                        .iter_mut()
                        .zip(&self.maps)
                        .zip(cmd.thrusters())
                    {
                        *out = map.map(u);
                    }
                    self.gate.applied(cmd.imu_seq);
                    self.last_rejected = false;
                    self.counters.applied += 1;
                    Outcome::Applied
                }
                Err(Refusal::Arming) => {
                    self.counters.arming += 1;
                    Outcome::Arming
                }
                Err(Refusal::Stale { .. }) => {
                    self.counters.stale += 1;
                    Outcome::Stale
                }
            },
        }
    }

    /// The pulse per thruster at `now_ns`.
    pub fn outputs(&self, now_ns: u64) -> &[Pwm] {
        if self.watchdog.is_live(now_ns) {
            &self.commanded
        } else {
            &self.neutral
        }
    }

    /// Every thruster's neutral pulse.
    pub fn neutral(&self) -> &[Pwm] {
        &self.neutral
    }

    /// The mappings.
    pub fn maps(&self) -> &[OutputMap] {
        &self.maps
    }

    /// The state at `now_ns`.
    pub fn state(&self, now_ns: u64) -> OutputState {
        match self.watchdog.state(now_ns) {
            WatchdogState::Arming => OutputState::Arming,
            WatchdogState::Waiting if self.last_rejected => OutputState::Rejected,
            WatchdogState::Waiting => OutputState::Waiting,
            WatchdogState::Live => OutputState::Active,
            WatchdogState::Expired if self.last_rejected => OutputState::Rejected,
            WatchdogState::Expired => OutputState::Watchdog,
        }
    }

    /// The next time the outputs change without input (end of arming, expiry).
    pub fn next_change_ns(&self, now_ns: u64) -> Option<u64> {
        self.watchdog.next_change_ns(now_ns)
    }

    /// Counters so far.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::pwm::OutputParams;
    use thruster_protocol::ThrustMode;

    const MS: u64 = 1_000_000;

    fn controller() -> Controller {
        let maps = vec![
            OutputMap::new(OutputParams::default()),
            OutputMap::new(OutputParams {
                reversed: true,
                ..OutputParams::default()
            }),
            OutputMap::new(OutputParams {
                trim_us: 10,
                ..OutputParams::default()
            }),
        ];
        Controller::new(maps, 0, 100 * MS, 200 * MS)
    }

    fn cmd(imu_seq: u64, t_ns: u64, thrust: &[f64]) -> ThrustCommand {
        let mut c = ThrustCommand::neutral(imu_seq, imu_seq, t_ns, thrust.len() as u32);
        c.set_mode(ThrustMode::Controlling);
        c.thrusters_mut().copy_from_slice(thrust);
        c
    }

    fn us(p: &[Pwm]) -> Vec<u16> {
        p.iter().map(|p| p.us()).collect()
    }

    #[test]
    fn neutral_while_arming_then_follows_commands_then_watchdog() {
        let mut c = controller();
        assert_eq!(us(c.outputs(0)), [1500, 1500, 1510]);
        c.published(1, 50 * MS);
        assert_eq!(
            c.on_command(&cmd(1, 50 * MS, &[0.6, 0.6, 0.0]), 51 * MS),
            Outcome::Arming
        );
        assert_eq!(c.state(51 * MS), OutputState::Arming);
        assert_eq!(us(c.outputs(51 * MS)), [1500, 1500, 1510]);
        assert_eq!(c.state(100 * MS), OutputState::Waiting);

        c.published(2, 150 * MS);
        let o = c.on_command(&cmd(2, 150 * MS, &[0.6, 0.6, -1.0]), 151 * MS);
        assert_eq!(o, Outcome::Applied);
        assert_eq!(us(c.outputs(151 * MS)), [1750, 1250, 1100]);
        assert_eq!(c.state(151 * MS), OutputState::Active);
        assert_eq!(c.next_change_ns(151 * MS), Some(350 * MS));
        // The watchdog: 200 ms after the sample, neutral.
        assert_eq!(us(c.outputs(350 * MS)), [1500, 1500, 1510]);
        assert_eq!(c.state(350 * MS), OutputState::Watchdog);
        // A late answer to the same old sample does not bring the thrust back.
        assert_eq!(
            c.on_command(&cmd(2, 150 * MS, &[0.6, 0.6, -1.0]), 360 * MS),
            Outcome::Stale
        );
        assert_eq!(us(c.outputs(360 * MS)), [1500, 1500, 1510]);
        let k = c.counters();
        assert_eq!((k.applied, k.arming, k.stale), (1, 1, 1));
    }

    #[test]
    fn garbage_withdraws_the_held_command_and_is_counted() {
        let mut c = controller();
        for s in 1..=10 {
            c.published(s, (100 + s) * MS);
        }
        c.on_command(&cmd(5, 105 * MS, &[1.0, 1.0, 1.0]), 106 * MS);
        assert_eq!(us(c.outputs(106 * MS)), [1900, 1100, 1900]);
        let garbage = [
            cmd(6, 106 * MS, &[f64::NAN, 0.0, 0.0]),
            cmd(6, 106 * MS, &[1e9, 0.0, 0.0]),
            cmd(6, 106 * MS, &[0.5, 0.5]),
        ];
        for g in &garbage {
            assert!(matches!(c.on_command(g, 107 * MS), Outcome::Rejected(_)));
            assert_eq!(us(c.outputs(107 * MS)), [1500, 1500, 1510]);
            assert_eq!(c.state(107 * MS), OutputState::Rejected);
        }
        let r = c.counters().rejected;
        assert_eq!((r.nonfinite, r.range, r.count), (1, 1, 1));
        // A valid fresh command resumes.
        c.on_command(&cmd(7, 107 * MS, &[-0.2, 0.0, 0.0]), 108 * MS);
        assert_eq!(us(c.outputs(108 * MS)), [1400, 1500, 1510]);
        assert_eq!(c.state(108 * MS), OutputState::Active);
    }
}
