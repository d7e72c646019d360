//! systemd's notify protocol for every thrusterd process (`Type=notify` units): READY once
//! the process is safe and its services are up, WATCHDOG=1 from the main loop (so a hung
//! loop gets the process killed and restarted, and a driver's outputs go neutral with it),
//! STATUS= with the state, STOPPING on the way out. Every call is a no-op when not started
//! by systemd (no NOTIFY_SOCKET), and pings only when the unit set WatchdogSec
//! (WATCHDOG_USEC).

use std::io::ErrorKind;
use std::os::unix::net::UnixDatagram;
use std::time::{Duration, Instant};

use sd_notify::NotifyState;
use tracing::warn;

/// The notify state of one process. Create it once, in the thread running the main loop.
pub struct Systemd {
    /// Ping period: half of WatchdogSec, as sd_watchdog_enabled(3) recommends.
    watchdog: Option<Duration>,
    last_ping: Instant,
    last_status: String,
    notifier: Option<Notifier>,
}

/// A non-blocking datagram socket connected to `$NOTIFY_SOCKET`. Why not `sd_notify::notify`:
/// it sends on a blocking socket, and a sender that finds PID 1's queue full waits, on the
/// thread that runs the control loop or drives the thrusters (the same failure a full
/// journald queue was). Here a message that does not fit is dropped and counted: a watchdog
/// ping is sent again within half the watchdog period, and a STATUS= line is informative.
pub struct Notifier {
    addr: String,
    socket: UnixDatagram,
    /// Messages dropped because the queue was full.
    dropped: u64,
}

impl Notifier {
    /// Connects to `addr`, `$NOTIFY_SOCKET`'s form: a path, or `@name` for an abstract
    /// socket.
    pub fn connect(addr: &str) -> std::io::Result<Notifier> {
        Ok(Notifier {
            addr: addr.to_string(),
            socket: connected(addr)?,
            dropped: 0,
        })
    }

    /// Sends one message (`KEY=value` lines); never waits. False if it was dropped.
    pub fn send(&mut self, message: &str) -> bool {
        let mut reconnected = false;
        loop {
            match self.socket.send(message.as_bytes()) {
                Ok(_) => return true,
                Err(e) if e.kind() == ErrorKind::WouldBlock => {
                    self.dropped += 1;
                    return false;
                }
                // The manager's socket was made anew (as sd_notify does, connect again,
                // once).
                Err(_) if !reconnected => {
                    reconnected = true;
                    match connected(&self.addr) {
                        Ok(s) => self.socket = s,
                        Err(e) => {
                            warn!("systemd notification failed: {e}");
                            return false;
                        }
                    }
                }
                Err(e) => {
                    warn!("systemd notification failed: {e}");
                    return false;
                }
            }
        }
    }

    /// Messages dropped so far (the queue was full).
    pub fn dropped(&self) -> u64 {
        self.dropped
    }
}

/// A non-blocking datagram socket connected to `addr` (a path, or `@name`: abstract).
fn connected(addr: &str) -> std::io::Result<UnixDatagram> {
    let socket = UnixDatagram::unbound()?;
    if let Some(name) = addr.strip_prefix('@') {
        use std::os::linux::net::SocketAddrExt;
        let abstract_addr = std::os::unix::net::SocketAddr::from_abstract_name(name)?;
        socket.connect_addr(&abstract_addr)?;
    } else {
        socket.connect(addr)?;
    }
    socket.set_nonblocking(true)?;
    Ok(socket)
}

/// The notify protocol's text of `state`.
fn message(state: &NotifyState) -> String {
    match state {
        // One line per assignment: a newline in a status would start another.
        NotifyState::Status(text) => format!("STATUS={}\n", text.replace('\n', " ")),
        other => format!("{other}\n"),
    }
}

impl Default for Systemd {
    fn default() -> Self {
        Self::new()
    }
}

impl Systemd {
    /// Reads WATCHDOG_USEC (for this process only, as sd_watchdog_enabled(3) checks).
    pub fn new() -> Self {
        let notifier = std::env::var("NOTIFY_SOCKET")
            .ok()
            .filter(|a| !a.is_empty())
            .and_then(|addr| match Notifier::connect(&addr) {
                Ok(n) => Some(n),
                Err(e) => {
                    warn!("systemd's NOTIFY_SOCKET {addr}: cannot connect: {e}");
                    None
                }
            });
        Systemd {
            watchdog: sd_notify::watchdog_enabled().map(|d| d / 2),
            last_ping: Instant::now(),
            last_status: String::new(),
            notifier,
        }
    }

    fn send(&mut self, state: &[NotifyState]) {
        if let Some(n) = self.notifier.as_mut() {
            let text: String = state.iter().map(message).collect();
            n.send(&text);
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
    pub fn stopping(&mut self) {
        self.send(&[NotifyState::Stopping]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_protocols_lines() {
        assert_eq!(message(&NotifyState::Ready), "READY=1\n");
        assert_eq!(message(&NotifyState::Watchdog), "WATCHDOG=1\n");
        assert_eq!(message(&NotifyState::Stopping), "STOPPING=1\n");
        assert_eq!(
            message(&NotifyState::Status("holding\nlevel")),
            "STATUS=holding level\n"
        );
    }

    /// A manager that reads nothing: its queue fills, and every send after that returns at
    /// once, dropped (on a blocking socket the first of them waited for good).
    #[test]
    fn a_full_queue_drops_and_never_waits() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("notify");
        let manager = UnixDatagram::bind(&path).unwrap();
        let mut n = Notifier::connect(path.to_str().unwrap()).unwrap();
        let start = Instant::now();
        let mut sent = 0;
        for _ in 0..100_000 {
            sent += u64::from(n.send("WATCHDOG=1\n"));
        }
        assert!(start.elapsed() < Duration::from_secs(10));
        assert!(
            sent > 0 && n.dropped() > 0,
            "sent {sent}, dropped {}",
            n.dropped()
        );
        let mut buf = [0u8; 64];
        let got = manager.recv(&mut buf).unwrap();
        assert_eq!(&buf[..got], b"WATCHDOG=1\n");
    }

    #[test]
    fn an_abstract_address_is_reached() {
        let name = format!("thrusterd-notify-test-{}", std::process::id());
        use std::os::linux::net::SocketAddrExt;
        let addr = std::os::unix::net::SocketAddr::from_abstract_name(&name).unwrap();
        let manager = UnixDatagram::bind_addr(&addr).unwrap();
        let mut n = Notifier::connect(&format!("@{name}")).unwrap();
        assert!(n.send("READY=1\n"));
        let mut buf = [0u8; 64];
        let got = manager.recv(&mut buf).unwrap();
        assert_eq!(&buf[..got], b"READY=1\n");
    }
}
