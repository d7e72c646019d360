//! systemd integration: READY once the services are up, WATCHDOG=1 from the main loop (so a
//! hung loop gets the daemon restarted), STATUS= with the state, STOPPING on the way out.
//! Every call is a no-op when not started by systemd (no NOTIFY_SOCKET).

use std::time::{Duration, Instant};

use sd_notify::NotifyState;
use tracing::warn;

pub struct Systemd {
    /// Ping period: half of WatchdogSec, as sd_watchdog_enabled(3) recommends.
    watchdog: Option<Duration>,
    last_ping: Instant,
    last_status: String,
}

impl Systemd {
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

    pub fn ready(&mut self) {
        self.send(&[NotifyState::Ready]);
        self.ping();
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

    pub fn stopping(&self) {
        self.send(&[NotifyState::Stopping]);
    }
}
