//! Receiving with a deadline: busy-poll briefly, then block on the inbox's listener.
//!
//! A wake-up through an iceoryx2 event costs tens of microseconds per hop on the development
//! VM, against about a microsecond when polling shared memory. In lockstep every sample is
//! a round trip, so both sides poll for a short window first and block only when the peer is
//! slow. While the receiver polls without draining its listener, iceoryx2 skips the
//! notifier's syscall (the listener is already marked notified), which makes the sender's
//! side cheap as well.

use std::time::{Duration, Instant};

use thruster_protocol::services::{Inbox, IpcError, TopicMessage};

use super::shutdown::Shutdown;

/// Longest single block, so the stop flag is seen promptly even if a signal does not
/// interrupt the wait.
pub const MAX_BLOCK: Duration = Duration::from_millis(50);

/// Consecutive failed waits taken as interruptions before the error is returned.
const MAX_WAIT_ERRORS: u32 = 3;

/// Outcome of [`recv_until`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Received<T> {
    /// The next message (unvalidated).
    Message(T),
    /// The deadline passed.
    Timeout,
    /// Stopping was requested.
    Shutdown,
}

/// The next message of `inbox`, polling for `spin` and then blocking in slices of at most
/// [`MAX_BLOCK`] until `deadline`.
pub fn recv_until<T: TopicMessage>(
    inbox: &Inbox<T>,
    deadline: Instant,
    spin: Duration,
    stop: &Shutdown,
) -> Result<Received<T>, IpcError> {
    let spin_end = Instant::now() + spin;
    let mut interrupted = 0;
    loop {
        if let Some(m) = inbox.recv()? {
            return Ok(Received::Message(m));
        }
        if stop.requested() {
            return Ok(Received::Shutdown);
        }
        let now = Instant::now();
        if now >= deadline {
            return Ok(Received::Timeout);
        }
        if now < spin_end {
            std::hint::spin_loop();
            continue;
        }
        // Drain first, then look once more: a message that arrived between the last receive
        // and the drain has had its notification consumed and would otherwise be slept on.
        inbox.drain_events()?;
        if let Some(m) = inbox.recv()? {
            return Ok(Received::Message(m));
        }
        match inbox.wait((deadline - now).min(MAX_BLOCK)) {
            Ok(_) => interrupted = 0,
            // SIGINT/SIGTERM interrupt the wait (EINTR: socket timeouts are not restarted)
            // before ctrlc's handler thread has set the flag, so an error is first taken as
            // a wake-up; the loop sees the flag on a later round. Only a repeated failure is
            // real.
            Err(e) => {
                interrupted += 1;
                if interrupted > MAX_WAIT_ERRORS {
                    return Err(e);
                }
            }
        }
    }
}

/// When to busy-poll: spin while the peer answers within the window, block when it does not.
///
/// Spinning pays only when the answer comes within the window; with a slow peer (a debug
/// build, an estimator solving, a loaded machine) every spin is CPU taken from the peer on a
/// small machine. After [`AdaptiveSpin::MISSES_TO_BLOCK`] answers in a row that needed the
/// blocking wait, the window drops to zero; every [`AdaptiveSpin::PROBE_EVERY`]th wait then
/// probes with the full window and spinning resumes when the answer came within it.
#[derive(Debug, Clone)]
pub struct AdaptiveSpin {
    max: Duration,
    blocking: bool,
    misses: u32,
    waits: u64,
}

impl AdaptiveSpin {
    /// Consecutive misses after which waits block at once.
    pub const MISSES_TO_BLOCK: u32 = 4;
    /// While blocking, one wait in this many probes with the full window.
    pub const PROBE_EVERY: u64 = 32;

    /// A policy that starts spinning for up to `max`.
    pub fn new(max: Duration) -> Self {
        AdaptiveSpin {
            max,
            blocking: max.is_zero(),
            misses: 0,
            waits: 0,
        }
    }

    /// The window for the next wait.
    pub fn window(&mut self) -> Duration {
        self.waits += 1;
        if !self.blocking || self.waits.is_multiple_of(Self::PROBE_EVERY) {
            self.max
        } else {
            Duration::ZERO
        }
    }

    /// Records how long the wait that used `window` took until its message came.
    pub fn record(&mut self, window: Duration, waited: Duration) {
        if window.is_zero() {
            return;
        }
        if waited <= window {
            self.blocking = false;
            self.misses = 0;
        } else {
            self.misses += 1;
            if self.misses >= Self::MISSES_TO_BLOCK {
                self.blocking = true;
            }
        }
    }

    /// True while waits block at once (except probes).
    pub fn is_blocking(&self) -> bool {
        self.blocking
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spins_while_answers_are_fast_blocks_when_slow_and_probes_back() {
        let max = Duration::from_micros(50);
        let fast = Duration::from_micros(10);
        let slow = Duration::from_micros(500);
        let mut p = AdaptiveSpin::new(max);
        for _ in 0..10 {
            let w = p.window();
            assert_eq!(w, max);
            p.record(w, fast);
        }
        for _ in 0..AdaptiveSpin::MISSES_TO_BLOCK {
            let w = p.window();
            assert_eq!(w, max);
            p.record(w, slow);
        }
        assert!(p.is_blocking());
        // Blocking: zero windows except one probe per PROBE_EVERY waits.
        let windows: Vec<Duration> = (0..AdaptiveSpin::PROBE_EVERY)
            .map(|_| {
                let w = p.window();
                p.record(w, slow);
                w
            })
            .collect();
        assert_eq!(windows.iter().filter(|w| !w.is_zero()).count(), 1);
        assert!(p.is_blocking());
        // A probe answered within the window turns spinning back on.
        loop {
            let w = p.window();
            p.record(w, fast);
            if !w.is_zero() {
                break;
            }
        }
        assert!(!p.is_blocking());
        assert!(AdaptiveSpin::new(Duration::ZERO).window().is_zero());
    }
}
