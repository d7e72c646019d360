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

    /// sd_notify_barrier(3): sends BARRIER=1 with the write end of a pipe, which the manager
    /// closes once it has processed every message sent before it, and waits at most
    /// `timeout` for that. True if the manager got there. For a process about to exit:
    /// without it, the manager may reap the process before it reads its last STATUS=, and
    /// then drops that message (it no longer knows whose it was).
    pub fn barrier(&self, timeout: Duration) -> std::io::Result<bool> {
        use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
        let mut fds = [0i32; 2];
        // SAFETY: pipe2 fills two descriptors on success, owned right below.
        if unsafe { libc::pipe2(fds.as_mut_ptr(), libc::O_CLOEXEC) } != 0 {
            return Err(std::io::Error::last_os_error());
        }
        // SAFETY: fresh descriptors nobody else owns.
        let (read, write) = unsafe { (OwnedFd::from_raw_fd(fds[0]), OwnedFd::from_raw_fd(fds[1])) };
        send_with_fd(self.socket.as_raw_fd(), b"BARRIER=1\n", write.as_raw_fd())?;
        drop(write);
        let mut pfd = libc::pollfd {
            fd: read.as_raw_fd(),
            events: 0, // POLLHUP is reported whatever is asked for
            revents: 0,
        };
        // Clamped: at least 1 ms, at most a minute.
        let ms = timeout.as_millis().clamp(1, 60_000) as i32;
        // SAFETY: one valid pollfd.
        let n = unsafe { libc::poll(&mut pfd, 1, ms) };
        Ok(n == 1 && pfd.revents & libc::POLLHUP != 0)
    }
}

/// sendmsg(2) of `data` with one descriptor (SCM_RIGHTS).
fn send_with_fd(socket: i32, data: &[u8], fd: i32) -> std::io::Result<()> {
    let mut iov = libc::iovec {
        iov_base: data.as_ptr() as *mut libc::c_void,
        iov_len: data.len(),
    };
    // A u64 buffer: aligned for cmsghdr; CMSG_SPACE of one int is 24 bytes on Linux.
    let mut control = [0u64; 4];
    // SAFETY: msghdr is plain data; every pointer set below outlives the call, and the
    // control buffer holds CMSG_SPACE(sizeof(int)) bytes (checked).
    unsafe {
        let space = libc::CMSG_SPACE(std::mem::size_of::<i32>() as u32) as usize;
        assert!(space <= std::mem::size_of_val(&control));
        let mut msg: libc::msghdr = std::mem::zeroed();
        msg.msg_iov = &mut iov;
        msg.msg_iovlen = 1;
        msg.msg_control = control.as_mut_ptr() as *mut libc::c_void;
        msg.msg_controllen = space as _;
        let cmsg = libc::CMSG_FIRSTHDR(&msg);
        (*cmsg).cmsg_level = libc::SOL_SOCKET;
        (*cmsg).cmsg_type = libc::SCM_RIGHTS;
        (*cmsg).cmsg_len = libc::CMSG_LEN(std::mem::size_of::<i32>() as u32) as _;
        std::ptr::write_unaligned(libc::CMSG_DATA(cmsg) as *mut i32, fd);
        if libc::sendmsg(socket, &msg, libc::MSG_NOSIGNAL) < 0 {
            return Err(std::io::Error::last_os_error());
        }
    }
    Ok(())
}

/// A process that is about to exit on a failure tells systemd why: `STATUS=failed: <why>`,
/// then a barrier (at most 1 s) so that the manager has it before it reaps the process.
/// systemd keeps a unit's status text until its next start, so `systemctl status` shows
/// the reason of a unit that failed at once, whose own log lines journald may not be able to
/// attribute to the unit any more (systemd issue #2913; `journalctl -u` then misses them).
/// A no-op outside systemd.
pub fn report_failure(why: &str) {
    let Some(addr) = notify_socket() else {
        return;
    };
    let Ok(mut notifier) = Notifier::connect(&addr) else {
        return;
    };
    if notifier.send(&message(&NotifyState::Status(&format!("failed: {why}")))) {
        let _ = notifier.barrier(Duration::from_secs(1));
    }
}

/// `$NOTIFY_SOCKET`, set and not empty: started by systemd for a notify unit.
fn notify_socket() -> Option<String> {
    std::env::var("NOTIFY_SOCKET")
        .ok()
        .filter(|a| !a.is_empty())
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
        let notifier = notify_socket().and_then(|addr| match Notifier::connect(&addr) {
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

    /// The barrier waits for the manager to close the descriptor it was sent, and no longer
    /// than its timeout for a manager that does not.
    #[test]
    fn the_barrier_returns_once_the_manager_closed_its_descriptor() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("notify");
        let manager = UnixDatagram::bind(&path).unwrap();
        let n = Notifier::connect(path.to_str().unwrap()).unwrap();
        let answering = std::thread::spawn(move || {
            let (text, fd) = recv_with_fd(&manager);
            std::thread::sleep(Duration::from_millis(50));
            drop(fd);
            (text, manager)
        });
        let start = Instant::now();
        assert!(n.barrier(Duration::from_secs(5)).unwrap());
        let (text, manager) = answering.join().unwrap();
        assert_eq!(text, "BARRIER=1\n");
        assert!(start.elapsed() >= Duration::from_millis(50));
        // A manager that keeps the descriptor: false after the timeout.
        let start = Instant::now();
        let kept = std::thread::spawn(move || recv_with_fd(&manager));
        assert!(!n.barrier(Duration::from_millis(100)).unwrap());
        assert!(start.elapsed() >= Duration::from_millis(100));
        drop(kept.join().unwrap());
    }

    /// recvmsg(2) of one message and the descriptor it carries.
    fn recv_with_fd(socket: &UnixDatagram) -> (String, std::os::fd::OwnedFd) {
        use std::os::fd::{AsRawFd, FromRawFd};
        let mut buf = [0u8; 64];
        let mut iov = libc::iovec {
            iov_base: buf.as_mut_ptr() as *mut libc::c_void,
            iov_len: buf.len(),
        };
        let mut control = [0u64; 4];
        // SAFETY: as in send_with_fd; the kernel fills at most msg_controllen bytes.
        unsafe {
            let mut msg: libc::msghdr = std::mem::zeroed();
            msg.msg_iov = &mut iov;
            msg.msg_iovlen = 1;
            msg.msg_control = control.as_mut_ptr() as *mut libc::c_void;
            msg.msg_controllen = std::mem::size_of_val(&control) as _;
            let got = libc::recvmsg(socket.as_raw_fd(), &mut msg, 0);
            assert!(got > 0, "{}", std::io::Error::last_os_error());
            let cmsg = libc::CMSG_FIRSTHDR(&msg);
            assert!(!cmsg.is_null() && (*cmsg).cmsg_type == libc::SCM_RIGHTS);
            let fd = std::ptr::read_unaligned(libc::CMSG_DATA(cmsg) as *const i32);
            (
                String::from_utf8_lossy(&buf[..got as usize]).into_owned(),
                std::os::fd::OwnedFd::from_raw_fd(fd),
            )
        }
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
