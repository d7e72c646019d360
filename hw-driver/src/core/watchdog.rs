//! The output watchdog: pure, time passed in (ns on the driver's monotonic clock).
//!
//! - Arming: for `arming` after start every output is neutral and commands are not taken
//!   (ESCs arm on a steady neutral pulse).
//! - A valid command answering an IMU sample taken at `t` keeps the outputs live until
//!   `t + timeout`. Expiry is measured from the sample, not from the command's arrival, so
//!   an output is never held longer than `timeout` past the data it was computed from.
//! - A command whose sample is already older than `timeout` is stale: it neither re-arms
//!   expired outputs nor extends live ones.

use std::fmt;

/// Where the watchdog stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WatchdogState {
    /// Start-up neutral hold; commands are not taken.
    Arming,
    /// Armed, but no command was taken yet.
    Waiting,
    /// A fresh command holds the outputs.
    Live,
    /// The last command expired (or was withdrawn): outputs neutral until a fresh one.
    Expired,
}

impl fmt::Display for WatchdogState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            WatchdogState::Arming => "arming",
            WatchdogState::Waiting => "waiting",
            WatchdogState::Live => "live",
            WatchdogState::Expired => "expired",
        })
    }
}

/// Why a valid command was not taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// Still in the start-up neutral hold.
    Arming,
    /// Its sample is `age_ns` old, not younger than the timeout.
    Stale {
        /// Age of the sample the command answers, ns.
        age_ns: u64,
    },
}

/// See the module docs.
#[derive(Debug, Clone)]
pub struct Watchdog {
    arming_end_ns: u64,
    timeout_ns: u64,
    expires_ns: Option<u64>,
}

impl Watchdog {
    /// A watchdog started at `start_ns` that holds neutral for `arming_ns` and lets a
    /// command live `timeout_ns` past its sample (at least 1 ns).
    pub fn new(start_ns: u64, arming_ns: u64, timeout_ns: u64) -> Self {
        Watchdog {
            arming_end_ns: start_ns.saturating_add(arming_ns),
            timeout_ns: timeout_ns.max(1),
            expires_ns: None,
        }
    }

    /// The timeout, ns.
    pub fn timeout_ns(&self) -> u64 {
        self.timeout_ns
    }

    /// When the arming hold ends, ns.
    pub fn arming_end_ns(&self) -> u64 {
        self.arming_end_ns
    }

    /// Offers a valid command answering a sample taken at `sample_t_ns`, at `now_ns`.
    /// `Ok` when it holds the outputs until `sample_t_ns + timeout`.
    pub fn feed(&mut self, sample_t_ns: u64, now_ns: u64) -> Result<(), Refusal> {
        if now_ns < self.arming_end_ns {
            return Err(Refusal::Arming);
        }
        // A sample time in the future cannot come from our clock; treat it as taken now so
        // it cannot extend the hold beyond one timeout from now.
        let t = sample_t_ns.min(now_ns);
        let age_ns = now_ns - t;
        if age_ns >= self.timeout_ns {
            return Err(Refusal::Stale { age_ns });
        }
        self.expires_ns = Some(t + self.timeout_ns);
        Ok(())
    }

    /// Withdraws the current command (e.g. after an invalid one): outputs neutral now.
    pub fn withdraw(&mut self, now_ns: u64) {
        if self.expires_ns.is_some_and(|e| e > now_ns) {
            self.expires_ns = Some(now_ns);
        }
    }

    /// The state at `now_ns`.
    pub fn state(&self, now_ns: u64) -> WatchdogState {
        if now_ns < self.arming_end_ns {
            return WatchdogState::Arming;
        }
        match self.expires_ns {
            None => WatchdogState::Waiting,
            Some(e) if now_ns < e => WatchdogState::Live,
            Some(_) => WatchdogState::Expired,
        }
    }

    /// True when a command holds the outputs at `now_ns`.
    pub fn is_live(&self, now_ns: u64) -> bool {
        self.state(now_ns) == WatchdogState::Live
    }

    /// The next time the state changes without input (end of arming or expiry), if any.
    pub fn next_change_ns(&self, now_ns: u64) -> Option<u64> {
        if now_ns < self.arming_end_ns {
            return Some(self.arming_end_ns);
        }
        self.expires_ns.filter(|&e| e > now_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn arming_hold_then_commands_live_for_the_timeout_after_their_sample() {
        let mut w = Watchdog::new(1_000 * MS, 500 * MS, 200 * MS);
        assert_eq!(w.state(1_000 * MS), WatchdogState::Arming);
        assert_eq!(w.feed(1_400 * MS, 1_401 * MS), Err(Refusal::Arming));
        assert_eq!(w.next_change_ns(1_200 * MS), Some(1_500 * MS));
        assert_eq!(w.state(1_500 * MS), WatchdogState::Waiting);
        assert_eq!(w.next_change_ns(1_500 * MS), None);

        w.feed(1_600 * MS, 1_601 * MS).unwrap();
        assert_eq!(w.state(1_601 * MS), WatchdogState::Live);
        assert_eq!(w.next_change_ns(1_601 * MS), Some(1_800 * MS));
        // Exactly the timeout after the sample: expired (not one nanosecond more).
        assert!(w.is_live(1_800 * MS - 1));
        assert_eq!(w.state(1_800 * MS), WatchdogState::Expired);
        assert_eq!(w.next_change_ns(1_800 * MS), None);
    }

    #[test]
    fn an_old_command_does_not_re_arm_or_extend() {
        let mut w = Watchdog::new(0, 0, 200 * MS);
        w.feed(1_000 * MS, 1_010 * MS).unwrap();
        // Arrives while live, but its sample is 200 ms old: refused, expiry unchanged.
        assert_eq!(
            w.feed(900 * MS, 1_100 * MS),
            Err(Refusal::Stale { age_ns: 200 * MS })
        );
        assert_eq!(w.next_change_ns(1_100 * MS), Some(1_200 * MS));
        // After expiry an old command does not re-arm...
        assert_eq!(
            w.feed(1_050 * MS, 1_300 * MS),
            Err(Refusal::Stale { age_ns: 250 * MS })
        );
        assert_eq!(w.state(1_300 * MS), WatchdogState::Expired);
        // ...a fresh one does.
        w.feed(1_299 * MS, 1_300 * MS).unwrap();
        assert!(w.is_live(1_300 * MS));
    }

    #[test]
    fn future_sample_times_cannot_extend_the_hold_and_withdraw_is_immediate() {
        let mut w = Watchdog::new(0, 0, 200 * MS);
        w.feed(u64::MAX, 1_000 * MS).unwrap();
        assert_eq!(w.next_change_ns(1_000 * MS), Some(1_200 * MS));
        w.withdraw(1_050 * MS);
        assert_eq!(w.state(1_050 * MS), WatchdogState::Expired);
        // Withdrawing an expired command changes nothing.
        w.withdraw(2_000 * MS);
        assert_eq!(w.state(2_000 * MS), WatchdogState::Expired);
    }
}
