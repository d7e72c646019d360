//! The driver's own report on `<ns>/driver_status` ([`DriverStatusMsg`]): what the daemon
//! cannot see in the IMU stream. Published at start, at least every
//! [`DriverStatusMsg::PERIOD_MS`], and at once when the reported output state, the link or
//! the armed flag changes.
//!
//! The reported [`OutputState`] combines the core's state with the backend's: a command the
//! core applies reaches nothing while the link is down or the autopilot is disarmed, so
//! those win over `Active`.

use thruster_protocol::{DriverStatusMsg, OutputState, Text};

use crate::backend::{LinkState, Supply};
use crate::core::controller::{Counters, OutputState as CoreState};

const MS: u64 = 1_000_000;

/// The state to report. `moves`: the device is armed and holds none of our thrust back
/// ([`crate::backend::Backend::held`]); a device that holds it is reported as `Disarmed`
/// (nothing reaches the water), with the reason in the text.
pub fn output_state(core: CoreState, link: &LinkState, moves: bool) -> OutputState {
    match link {
        LinkState::Connecting => OutputState::Unknown,
        LinkState::Down(_) => OutputState::LinkDown,
        LinkState::Up | LinkState::Local if !moves => OutputState::Disarmed,
        LinkState::Up | LinkState::Local => match core {
            CoreState::Active => OutputState::Active,
            _ => OutputState::Neutral,
        },
    }
}

/// The outputs as the log says them: the core's state unless the backend's overrides it
/// (a disarmed vehicle's outputs are not "active", whatever the core applies). `held`: why
/// the device holds our thrust back, if it does.
pub fn describe(core: CoreState, reported: OutputState, held: Option<&str>) -> String {
    match reported {
        OutputState::Disarmed if held.is_some() => {
            format!("held neutral, {} ({core})", held.unwrap_or_default())
        }
        OutputState::Unknown => format!("{core}; waiting for the output device"),
        OutputState::LinkDown => format!("link down, nothing reaches the thrusters ({core})"),
        OutputState::Disarmed => {
            format!("disarmed, the autopilot moves no thruster ({core})")
        }
        OutputState::Active | OutputState::Neutral => core.to_string(),
    }
}

/// The output device as the backend reports it.
#[derive(Debug, Clone, Copy)]
pub struct Device<'a> {
    pub link: &'a LinkState,
    /// The device moves thrusters when told ([`crate::backend::Backend::armed`]).
    pub armed: bool,
    /// Why it holds our thrust back, if it does ([`crate::backend::Backend::held`]).
    pub held: Option<&'a str>,
    pub supply: Supply,
}

/// Builds the reports; the loop publishes them.
#[derive(Debug)]
pub struct StatusReporter {
    driver: Text,
    thrusters: u32,
    seq: u64,
    next_ns: u64,
    last: Option<(OutputState, bool, bool, bool)>,
    last_core: CoreState,
    watchdog_expiries: u64,
    last_rejection: Option<String>,
}

impl StatusReporter {
    /// For `thrusters` outputs of backend `backend` ("mavlink"), first report due now.
    pub fn new(backend: &str, thrusters: usize, now_ns: u64) -> Self {
        StatusReporter {
            driver: Text::from_str_truncated(&format!("thruster-hw {backend}")),
            thrusters: thrusters as u32,
            seq: 0,
            next_ns: now_ns,
            last: None,
            last_core: CoreState::Arming,
            watchdog_expiries: 0,
            last_rejection: None,
        }
    }

    /// When the next periodic report is due.
    pub fn next_ns(&self) -> u64 {
        self.next_ns
    }

    /// A command was rejected for `reason`.
    pub fn rejected(&mut self, reason: &str) {
        self.last_rejection = Some(reason.to_string());
    }

    /// Watchdog expiries counted so far.
    pub fn watchdog_expiries(&self) -> u64 {
        self.watchdog_expiries
    }

    /// The report due at `now_ns`, if one is (periodic, or a change).
    pub fn report(
        &mut self,
        now_ns: u64,
        core: CoreState,
        counters: &Counters,
        device: Device<'_>,
    ) -> Option<DriverStatusMsg> {
        let Device {
            link,
            armed,
            held,
            supply,
        } = device;
        // An expiry is the core going from following commands to the watchdog's neutral.
        if core == CoreState::Watchdog && self.last_core == CoreState::Active {
            self.watchdog_expiries += 1;
        }
        self.last_core = core;
        let state = output_state(core, link, armed && held.is_none());
        let link_up = matches!(link, LinkState::Up | LinkState::Local);
        let now = (state, link_up, armed, held.is_some());
        if self.last == Some(now) && now_ns < self.next_ns {
            return None;
        }
        self.last = Some(now);
        self.seq += 1;
        self.next_ns = now_ns + DriverStatusMsg::PERIOD_MS * MS;
        let text = match (state, link) {
            (OutputState::LinkDown, LinkState::Down(why)) => format!("link down: {why}"),
            (OutputState::Unknown, _) => "waiting for the output device".to_string(),
            (OutputState::Disarmed, _) => match held {
                Some(why) if armed => format!("outputs held neutral: {why}"),
                _ => "autopilot disarmed".to_string(),
            },
            _ => self
                .last_rejection
                .as_ref()
                .map(|r| format!("last rejected command: {r}"))
                .unwrap_or_default(),
        };
        let mut msg = DriverStatusMsg {
            seq: self.seq,
            time_ns: now_ns,
            thruster_count: self.thrusters,
            commands_accepted: counters.applied + counters.arming + counters.stale,
            commands_rejected: counters.rejected.total(),
            watchdog_expiries: self.watchdog_expiries,
            link_up: u32::from(link_up),
            armed: u32::from(armed),
            driver: self.driver,
            text: Text::from_str_truncated(&text),
            ..DriverStatusMsg::default()
        };
        msg.set_output_state(state);
        // Unknown stays NaN (the message's default); a non-finite measurement is unknown too.
        if let Some(v) = supply.voltage_v.filter(|v| v.is_finite()) {
            msg.supply_voltage_v = v;
        }
        if let Some(a) = supply.current_a.filter(|a| a.is_finite()) {
            msg.supply_current_a = a;
        }
        Some(msg)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backend_state_wins_over_the_cores() {
        let up = LinkState::Up;
        let down = LinkState::Down("no HEARTBEAT".into());
        assert_eq!(
            output_state(CoreState::Active, &up, true),
            OutputState::Active
        );
        assert_eq!(
            output_state(CoreState::Watchdog, &up, true),
            OutputState::Neutral
        );
        assert_eq!(
            output_state(CoreState::Active, &up, false),
            OutputState::Disarmed
        );
        assert_eq!(
            output_state(CoreState::Active, &down, true),
            OutputState::LinkDown
        );
        assert_eq!(
            output_state(CoreState::Active, &LinkState::Connecting, true),
            OutputState::Unknown
        );
        assert_eq!(
            output_state(CoreState::Active, &LinkState::Local, true),
            OutputState::Active
        );
        assert!(!describe(CoreState::Active, OutputState::Disarmed, None).starts_with("active"));
    }

    fn dev<'a>(link: &'a LinkState, armed: bool, held: Option<&'a str>) -> Device<'a> {
        Device {
            link,
            armed,
            held,
            supply: Supply::default(),
        }
    }

    #[test]
    fn reports_at_start_periodically_and_at_once_on_change() {
        let mut r = StatusReporter::new("mavlink", 5, 0);
        let c = Counters::default();
        let up = LinkState::Up;
        let first = r
            .report(0, CoreState::Arming, &c, dev(&up, false, None))
            .unwrap();
        assert_eq!(first.driver(), "thruster-hw mavlink");
        assert_eq!(
            (first.thruster_count, first.armed, first.link_up),
            (5, 0, 1)
        );
        assert_eq!(first.output_state(), Ok(OutputState::Disarmed));
        assert!(r
            .report(50 * MS, CoreState::Arming, &c, dev(&up, false, None))
            .is_none());
        // Armed: at once.
        let armed = r
            .report(60 * MS, CoreState::Waiting, &c, dev(&up, true, None))
            .unwrap();
        assert_eq!(armed.output_state(), Ok(OutputState::Neutral));
        // Nothing new: the next after 100 ms.
        assert!(r
            .report(159 * MS, CoreState::Waiting, &c, dev(&up, true, None))
            .is_none());
        assert!(r
            .report(160 * MS, CoreState::Waiting, &c, dev(&up, true, None))
            .is_some());
        // Active, then the watchdog: counted once.
        r.report(170 * MS, CoreState::Active, &c, dev(&up, true, None))
            .unwrap();
        let w = r
            .report(400 * MS, CoreState::Watchdog, &c, dev(&up, true, None))
            .unwrap();
        assert_eq!(w.watchdog_expiries, 1);
        r.rejected("count 4, configured 5");
        let t = r
            .report(600 * MS, CoreState::Rejected, &c, dev(&up, true, None))
            .unwrap();
        assert!(t.text().contains("count 4"), "{}", t.text());
        // Held back by the device while armed: reported at once as reaching nothing, with why;
        // released: at once again.
        let held = r
            .report(
                610 * MS,
                CoreState::Active,
                &c,
                dev(&up, true, Some("RC_OVERRIDE_TIME = -1")),
            )
            .unwrap();
        assert_eq!(held.output_state(), Ok(OutputState::Disarmed));
        assert_eq!(held.armed, 1);
        assert_eq!(held.text(), "outputs held neutral: RC_OVERRIDE_TIME = -1");
        let released = r
            .report(620 * MS, CoreState::Active, &c, dev(&up, true, None))
            .unwrap();
        assert_eq!(released.output_state(), Ok(OutputState::Active));
        assert!(describe(
            CoreState::Active,
            OutputState::Disarmed,
            Some("RC_OVERRIDE_TIME = 3 s")
        )
        .starts_with("held neutral, RC_OVERRIDE_TIME = 3 s"));
    }
}
