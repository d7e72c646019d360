//! Whether the IMU samples still wake the loop: samples read on wake-ups their notification
//! did not cause, counted, so the loop can re-arm the listener and say so.
//!
//! Why: the loop reads the IMU inbox on every wake-up, so a sample whose notification never
//! arrived is still answered, but only when something else wakes the loop (another input, or
//! the 100 ms deadline). Twice a lockstep run crawled at 11 samples/s for minutes with both
//! processes waiting and nothing in either log (docs/reliability.md, "The same stall on
//! glibc"): the simulator's notifications had stopped waking the daemon. In real time the
//! same would put control at 10 Hz. The cause, found later, was a lost wake-up in iceoryx2's
//! event drain (patched in vendor/iceoryx2-cal; docs/reliability.md, "The stall found"); this
//! watch stays as the second line. One sample read without its notification is normal (it
//! came between another input's wake-up and the read, and its notification wakes the next
//! wait); several in a row are not.

/// Wake-ups in a row with samples but without an IMU notification before the loop says the
/// notifications have stopped.
pub const STOPPED_AFTER: u32 = 3;
/// Wake-ups in a row after which re-arming has not brought them back and the listener is
/// replaced (once per stop): about a second of vehicle time at the 100 ms wake-ups.
pub const RENEW_AFTER: u32 = 10;

/// What the loop should do after a wake-up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wakeup {
    /// Nothing to do.
    Fine,
    /// Samples came without their notification: drain the listener's pending events, which
    /// re-arms it (iceoryx2 skips a notifier's wake-up while it takes a notification as still
    /// pending, so one left pending would silence every later one).
    Rearm,
    /// As `Rearm`, and the notifications have now been missing `STOPPED_AFTER` wake-ups in a
    /// row: say so (once per stop).
    Stopped,
    /// Re-arming did not bring them back for `RENEW_AFTER` wake-ups: replace the listener, so
    /// that the drivers' notifiers connect to a new one (once per stop).
    Renew,
    /// Notifications wake the loop again after a stop: say so, with how many samples were read
    /// without one.
    Resumed { unnotified: u64 },
}

/// Counts wake-ups that read IMU samples without an IMU notification.
#[derive(Debug, Default)]
pub struct ImuWakeups {
    in_a_row: u32,
    /// Samples read without a notification since the last stop was said.
    since_stop: u64,
    stopped: bool,
    /// Wake-ups with samples and without a notification, over the whole run.
    pub unnotified_total: u64,
}

impl ImuWakeups {
    /// After a wake-up: `notified` when the IMU listener's event caused it, `samples` how many
    /// IMU samples were read.
    pub fn after(&mut self, notified: bool, samples: usize) -> Wakeup {
        if notified {
            self.in_a_row = 0;
            if self.stopped {
                self.stopped = false;
                return Wakeup::Resumed {
                    unnotified: std::mem::take(&mut self.since_stop),
                };
            }
            return Wakeup::Fine;
        }
        if samples == 0 {
            return Wakeup::Fine;
        }
        self.unnotified_total += 1;
        self.in_a_row = self.in_a_row.saturating_add(1);
        if self.stopped {
            self.since_stop += samples as u64;
        }
        if self.in_a_row == STOPPED_AFTER {
            self.stopped = true;
            self.since_stop = samples as u64;
            return Wakeup::Stopped;
        }
        if self.in_a_row == RENEW_AFTER {
            return Wakeup::Renew;
        }
        Wakeup::Rearm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn notified_samples_are_fine() {
        let mut w = ImuWakeups::default();
        for _ in 0..10 {
            assert_eq!(w.after(true, 1), Wakeup::Fine);
        }
        assert_eq!(
            w.after(false, 0),
            Wakeup::Fine,
            "a wake-up for another input"
        );
        assert_eq!(w.unnotified_total, 0);
    }

    #[test]
    fn one_sample_without_its_notification_rearms_without_a_word() {
        let mut w = ImuWakeups::default();
        assert_eq!(w.after(false, 1), Wakeup::Rearm);
        assert_eq!(w.after(true, 0), Wakeup::Fine, "its notification, late");
        assert_eq!(w.after(false, 1), Wakeup::Rearm, "the count started again");
        assert_eq!(w.unnotified_total, 2);
    }

    #[test]
    fn a_stop_is_said_once_and_its_end_with_the_samples_read_meanwhile() {
        let mut w = ImuWakeups::default();
        assert_eq!(w.after(false, 1), Wakeup::Rearm);
        assert_eq!(w.after(false, 1), Wakeup::Rearm);
        assert_eq!(w.after(false, 1), Wakeup::Stopped);
        for _ in 0..5 {
            assert_eq!(w.after(false, 2), Wakeup::Rearm);
        }
        assert_eq!(w.after(false, 0), Wakeup::Fine);
        assert_eq!(w.after(true, 1), Wakeup::Resumed { unnotified: 11 });
        assert_eq!(w.after(true, 1), Wakeup::Fine);
        assert_eq!(w.unnotified_total, 8);
    }

    #[test]
    fn a_stop_that_re_arming_does_not_end_renews_the_listener_once() {
        let mut w = ImuWakeups::default();
        let got: Vec<Wakeup> = (0..2 * RENEW_AFTER).map(|_| w.after(false, 1)).collect();
        let at = |v: Wakeup| got.iter().position(|g| *g == v).map(|i| i + 1);
        assert_eq!(at(Wakeup::Stopped), Some(STOPPED_AFTER as usize));
        assert_eq!(at(Wakeup::Renew), Some(RENEW_AFTER as usize));
        assert_eq!(got.iter().filter(|g| **g == Wakeup::Renew).count(), 1);
        assert_eq!(
            w.after(true, 1),
            Wakeup::Resumed {
                unnotified: u64::from(2 * RENEW_AFTER - STOPPED_AFTER + 1)
            }
        );
    }
}
