//! systemd's notify protocol for every thrusterd process (`Type=notify` units): READY once
//! the process is safe and its services are up, WATCHDOG=1 from the main loop (so a hung
//! loop gets the process killed and restarted, and a driver's outputs go neutral with it),
//! STATUS= with the state, STOPPING on the way out. Every call is a no-op when not started
//! by systemd (no NOTIFY_SOCKET), and pings only when the unit set WatchdogSec
//! (WATCHDOG_USEC).

use std::time::{Duration, Instant};

use sd_notify::NotifyState;
use tracing::warn;

/// The notify state of one process. Create it once, in the thread running the main loop.
pub struct Systemd {
    /// Ping period: half of WatchdogSec, as sd_watchdog_enabled(3) recommends.
    watchdog: Option<Duration>,
    last_ping: Instant,
    last_status: String,
}

impl Default for Systemd {
    fn default() -> Self {
        Self::new()
    }
}

impl Systemd {
    /// Reads WATCHDOG_USEC (for this process only, as sd_watchdog_enabled(3) checks).
    pub fn new() -> Self {
        Systemd {
            watchdog: sd_notify::watchdog_enabled().map(|d| d / 2),
            last_ping: Instant::now(),
            last_status: String::new(),
        }
    }

    fn send(&self, state: &[NotifyState]) {
        if let Err(e) = sd_notify::notify(state) {
            warn!("systemd notification failed: {e}");
        }
    }

    /// READY=1 (and a first ping): call once the process does its job safely.
    pub fn ready(&mut self) {
        self.send(&[NotifyState::Ready]);
        self.ping();
    }

    /// Whether systemd expects watchdog pings (WatchdogSec set on the unit).
    pub fn watchdog_enabled(&self) -> bool {
        self.watchdog.is_some()
    }

    /// Call from every loop iteration; pings when due.
    pub fn tick(&mut self) {
        if let Some(period) = self.watchdog {
            if self.last_ping.elapsed() >= period {
                self.ping();
            }
        }
    }

    fn ping(&mut self) {
        if self.watchdog.is_some() {
            self.send(&[NotifyState::Watchdog]);
        }
        self.last_ping = Instant::now();
    }

    /// STATUS= line (sent only when it changes).
    pub fn status(&mut self, text: &str) {
        if text != self.last_status {
            self.last_status = text.to_string();
            self.send(&[NotifyState::Status(text)]);
        }
    }

    /// STOPPING=1: the process is shutting down on purpose.
    pub fn stopping(&self) {
        self.send(&[NotifyState::Stopping]);
    }
}
