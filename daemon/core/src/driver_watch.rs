//! What the driver says of its outputs, judged against what the daemon is about to do.
//!
//! The IMU alone cannot tell the daemon that its commands go nowhere: a driver configured for
//! another thruster count rejects every command, an autopilot that is disarmed or unreachable
//! moves nothing, and the vehicle simply does not respond. Estimating on such a vehicle learns
//! garbage; controlling it is pretending. Each driver reports its own state on the
//! `driver_status` topic; this module turns the latest report into one verdict: the outputs
//! can be used, or why not. Pure: reports in, verdicts out.

use thruster_protocol::{DriverStatusMsg, OutputState};

/// Whether the daemon's commands can reach the water.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum OutputVerdict {
    /// Usable (or not known: a driver that publishes no status is trusted as before).
    Usable,
    /// Not usable, and why, in words for the operator.
    Blocked(String),
}

/// The latest driver report and the verdict it led to.
#[derive(Debug, Default, Clone, serde::Serialize, serde::Deserialize)]
pub struct DriverWatch {
    last: Option<DriverStatusMsg>,
    /// Rejections the latest report counted since the one before it.
    new_rejections: u64,
    /// Reports in a row that counted new rejections.
    rejecting: u32,
    /// The daemon runs in lockstep (`runtime.lockstep`): the simulator's time, no stale-IMU
    /// fault. Only the simulator may drive then (checkpoints from before it read false).
    #[serde(default)]
    lockstep: bool,
}

/// The driver name of the simulator, the one driver lockstep is for.
const SIMULATOR: &str = "thruster-sim";

/// Reports in a row with new rejections that make the outputs unusable. One burst is not
/// enough: when a driver announces a new thruster count, the commands already on their way
/// carry the old one and are rightly refused until the daemon has read the announcement. A
/// driver that keeps refusing (it reports at once on every change) crosses this within a
/// few samples.
const REJECTING_REPORTS: u32 = 2;

impl DriverWatch {
    pub fn new() -> Self {
        Self::default()
    }

    /// A watch for a daemon that runs in lockstep or not (`runtime.lockstep`).
    pub fn for_daemon(lockstep: bool) -> Self {
        DriverWatch {
            lockstep,
            ..Self::default()
        }
    }

    /// Takes a validated report and judges it for a daemon driving `thrusters` thrusters.
    ///
    /// Blocked when the driver is configured for another count (it rejects every command),
    /// when it rejected commands in [`REJECTING_REPORTS`] reports in a row, when the output
    /// device is disarmed, or when its link is down. Rejections clear with the first report
    /// that counts no new one.
    pub fn observe(&mut self, report: &DriverStatusMsg, thrusters: usize) -> OutputVerdict {
        // A restarted driver counts from zero again (a smaller count): compare only within
        // one run; rejections from before this daemon looked are history.
        self.new_rejections = self.last.map_or(0, |prev| {
            report
                .commands_rejected
                .saturating_sub(prev.commands_rejected)
        });
        self.rejecting = if self.new_rejections > 0 {
            self.rejecting.saturating_add(1)
        } else {
            0
        };
        self.last = Some(*report);
        self.verdict(thrusters)
    }

    /// The verdict on the latest report for a daemon driving `thrusters` thrusters (the
    /// count can change with a reconfiguration while the driver's report stays the same).
    pub fn verdict(&self, thrusters: usize) -> OutputVerdict {
        let Some(r) = &self.last else {
            return OutputVerdict::Usable;
        };
        let driver = r.driver();
        let driver = if driver.is_empty() {
            "the driver"
        } else {
            driver
        };
        // Lockstep turns the stale-IMU fault off and lets a solve hold a sample for minutes:
        // harmless against a simulator that waits, dangerous next to real thrusters.
        if self.lockstep && !r.driver().is_empty() && r.driver() != SIMULATOR {
            return OutputVerdict::Blocked(format!(
                "{driver} drives the thrusters but thrusterd runs in lockstep \
                 (runtime.lockstep: the simulator's time, no stale-IMU fault), which is for \
                 {SIMULATOR} only"
            ));
        }
        if r.thruster_count as usize != thrusters {
            return OutputVerdict::Blocked(format!(
                "{driver} drives {} thrusters, the daemon {thrusters}: every command would be \
                 rejected",
                r.thruster_count
            ));
        }
        // The driver's own words, when it gave any.
        let detail = if r.text().is_empty() {
            String::new()
        } else {
            format!(" ({})", r.text())
        };
        if self.rejecting >= REJECTING_REPORTS {
            return OutputVerdict::Blocked(format!(
                "{driver} rejected {} of the daemon's commands{detail}",
                self.new_rejections
            ));
        }
        match r.output_state() {
            // Armed but held back (an autopilot setting the driver will not drive through):
            // the driver's words say which, and arming would not help.
            Ok(OutputState::Disarmed) if r.armed == 1 && !r.text().is_empty() => {
                OutputVerdict::Blocked(format!(
                    "{driver}: {}; thrust does not reach the water",
                    r.text()
                ))
            }
            Ok(OutputState::Disarmed) => OutputVerdict::Blocked(format!(
                "{driver}: outputs disarmed, thrust does not reach the water (arm the vehicle)"
            )),
            Ok(OutputState::LinkDown) => {
                OutputVerdict::Blocked(format!("{driver}: no link to the outputs{detail}"))
            }
            // Validated reports carry known states only; an unknown state is not a reason to
            // stop a vehicle that works.
            _ => OutputVerdict::Usable,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(count: u32, state: OutputState, accepted: u64, rejected: u64) -> DriverStatusMsg {
        let mut r = DriverStatusMsg {
            thruster_count: count,
            commands_accepted: accepted,
            commands_rejected: rejected,
            link_up: 1,
            armed: 1,
            ..Default::default()
        };
        r.set_output_state(state);
        r.driver.set("thruster-test");
        r
    }

    #[test]
    fn in_lockstep_only_the_simulator_may_drive() {
        let mut hw = report(5, OutputState::Active, 10, 0);
        hw.driver.set("thruster-hw linux");
        let mut sim = report(5, OutputState::Active, 10, 0);
        sim.driver.set(SIMULATOR);
        let mut w = DriverWatch::for_daemon(true);
        let OutputVerdict::Blocked(why) = w.observe(&hw, 5) else {
            panic!("thruster-hw allowed in lockstep");
        };
        assert!(
            why.contains("thruster-hw linux") && why.contains("lockstep"),
            "{why}"
        );
        assert_eq!(w.observe(&sim, 5), OutputVerdict::Usable);
        assert_eq!(
            DriverWatch::for_daemon(false).observe(&hw, 5),
            OutputVerdict::Usable
        );
    }

    #[test]
    fn no_report_is_usable_and_a_matching_active_driver_is_usable() {
        let mut w = DriverWatch::new();
        assert_eq!(w.verdict(5), OutputVerdict::Usable);
        assert_eq!(
            w.observe(&report(5, OutputState::Active, 10, 0), 5),
            OutputVerdict::Usable
        );
        assert_eq!(
            w.observe(&report(5, OutputState::Neutral, 20, 0), 5),
            OutputVerdict::Usable
        );
    }

    #[test]
    fn a_count_mismatch_blocks_and_names_both_counts() {
        let mut w = DriverWatch::new();
        let OutputVerdict::Blocked(why) = w.observe(&report(5, OutputState::Neutral, 0, 0), 6)
        else {
            panic!("a 5-thruster driver accepted for 6 thrusters");
        };
        assert!(
            why.contains("thruster-test drives 5 thrusters, the daemon 6"),
            "{why}"
        );
        // Reconfigured back to the driver's count: usable again.
        assert_eq!(w.verdict(5), OutputVerdict::Usable);
    }

    #[test]
    fn new_rejections_block_until_a_report_counts_none() {
        let mut w = DriverWatch::new();
        // Rejections from before this daemon looked are history.
        assert_eq!(
            w.observe(&report(5, OutputState::Active, 100, 7), 5),
            OutputVerdict::Usable
        );
        // One burst (commands in flight while the driver changed its count) is tolerated...
        assert_eq!(
            w.observe(&report(5, OutputState::Active, 100, 8), 5),
            OutputVerdict::Usable
        );
        // ...a driver that goes on refusing is not.
        let mut r = report(5, OutputState::Neutral, 100, 10);
        r.text.set("count = 4 does not match 5");
        let OutputVerdict::Blocked(why) = w.observe(&r, 5) else {
            panic!("rejections not seen");
        };
        assert!(why.contains("rejected 2 of the daemon's commands"), "{why}");
        assert!(why.contains("count = 4 does not match 5"), "{why}");
        assert_eq!(
            w.observe(&report(5, OutputState::Active, 150, 10), 5),
            OutputVerdict::Usable
        );
        // A restarted driver counts from zero: not a rejection.
        assert_eq!(
            w.observe(&report(5, OutputState::Active, 3, 0), 5),
            OutputVerdict::Usable
        );
    }

    #[test]
    fn disarmed_and_link_down_block() {
        let mut w = DriverWatch::new();
        let OutputVerdict::Blocked(why) = w.observe(&report(5, OutputState::Disarmed, 0, 0), 5)
        else {
            panic!("disarmed accepted");
        };
        assert!(why.contains("disarmed"), "{why}");
        assert!(why.contains("arm the vehicle"), "{why}");
        // Armed, but the device holds our thrust back: its reason, not "arm the vehicle".
        let mut held = report(5, OutputState::Disarmed, 0, 0);
        held.armed = 1;
        held.text.set(
            "outputs held neutral: RC_OVERRIDE_TIME = 3 s: our last override would outlive us 3 s",
        );
        let OutputVerdict::Blocked(why) = w.observe(&held, 5) else {
            panic!("held outputs accepted");
        };
        assert!(
            why.contains("outputs held neutral: RC_OVERRIDE_TIME = 3 s"),
            "{why}"
        );
        assert!(!why.contains("arm the vehicle"), "{why}");
        let mut r = report(5, OutputState::LinkDown, 0, 0);
        r.text.set("no heartbeat for 3 s");
        let OutputVerdict::Blocked(why) = w.observe(&r, 5) else {
            panic!("link down accepted");
        };
        assert!(
            why.contains("no link to the outputs (no heartbeat for 3 s)"),
            "{why}"
        );
    }
}
