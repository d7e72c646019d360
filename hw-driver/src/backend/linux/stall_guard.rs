//! The outputs neutral when the driver loop stops running, from a thread of their own.
//!
//! Why: the loop reads the IIO sensors and writes the PWM duties on one thread. A sensor read
//! that hangs (an I2C device that stretches the clock for good, a driver stuck in the kernel)
//! stops the loop, and with it the command watchdog that would take the outputs neutral:
//! sysfs PWM keeps its last duty, so the ESCs would hold the last command until systemd's
//! watchdog kills the process (`WatchdogSec`, seconds). This thread sees the loop's last
//! heartbeat; when it is older than the driver's `watchdog_ms` it writes every channel's
//! neutral duty itself (its own writes, not the loop's channels, which the loop may be
//! inside). Where the PWM chip itself hangs, nothing in the process can write it: the
//! systemd unit's `ExecStopPost` (`thruster-hw neutral`) is the layer after this one.
//!
//! The loop resumes the outputs it had if it was only slow: the guard writes neutral first
//! and then raises a flag, and the loop, seeing the flag, forgets what it believes the
//! channels hold and writes its outputs again.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use super::sysfs::write_attr;
use crate::clock::monotonic_ns;
use crate::core::pwm::Pwm;

/// Longest sleep between the guard's looks: how late it may see a stall, beyond the limit.
const MAX_CHECK: Duration = Duration::from_millis(50);
/// Shortest sleep between its looks.
const MIN_CHECK: Duration = Duration::from_millis(1);

#[derive(Debug)]
struct Shared {
    /// CLOCK_MONOTONIC ns of the loop's last call into the backend.
    heartbeat_ns: AtomicU64,
    /// Raised by the guard after it wrote neutral; taken by the loop.
    neutralized: AtomicBool,
    stop: AtomicBool,
}

/// See the module docs. Dropping it stops and joins the thread.
#[derive(Debug)]
pub struct StallGuard {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

impl StallGuard {
    /// Starts watching: `duties` are the channels' `duty_cycle` files and neutral pulses;
    /// `limit` the longest the loop may go without a heartbeat.
    pub fn start(duties: Vec<(PathBuf, Pwm)>, limit: Duration) -> std::io::Result<StallGuard> {
        let shared = Arc::new(Shared {
            heartbeat_ns: AtomicU64::new(monotonic_ns()),
            neutralized: AtomicBool::new(false),
            stop: AtomicBool::new(false),
        });
        let watched = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("pwm-stall-guard".into())
            .spawn(move || watch(&watched, &duties, limit))?;
        Ok(StallGuard {
            shared,
            thread: Some(thread),
        })
    }

    /// The loop is running (called at every entry into the backend).
    pub fn beat(&self) {
        self.shared
            .heartbeat_ns
            .store(monotonic_ns(), Ordering::Release);
    }

    /// Whether the guard wrote neutral since the last call (the flag is taken).
    pub fn take_neutralized(&self) -> bool {
        self.shared.neutralized.swap(false, Ordering::AcqRel)
    }
}

impl Drop for StallGuard {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

fn watch(shared: &Shared, duties: &[(PathBuf, Pwm)], limit: Duration) {
    // Its log lines must not wait on a full journald either.
    thruster_driver_kit::logging::never_wait_on_this_thread();
    let check = (limit / 4).clamp(MIN_CHECK, MAX_CHECK);
    let limit_ns = limit.as_nanos() as u64;
    // The heartbeat the guard last fired for: once per stall.
    let mut fired_at = None;
    while !shared.stop.load(Ordering::Acquire) {
        std::thread::park_timeout(check);
        let beat = shared.heartbeat_ns.load(Ordering::Acquire);
        let silent_ns = monotonic_ns().saturating_sub(beat);
        if silent_ns <= limit_ns || fired_at == Some(beat) || shared.stop.load(Ordering::Acquire) {
            continue;
        }
        fired_at = Some(beat);
        let mut failed = Vec::new();
        for (path, neutral) in duties {
            if let Err(e) = write_attr(path, &neutral.ns().to_string()) {
                failed.push(e.to_string());
            }
        }
        shared.neutralized.store(true, Ordering::Release);
        if failed.is_empty() {
            tracing::error!(
                silent_ms = silent_ns / 1_000_000,
                "the driver loop has not run for {} ms (a sensor read hung?): outputs neutral",
                silent_ns / 1_000_000
            );
        } else {
            tracing::error!(
                silent_ms = silent_ns / 1_000_000,
                "the driver loop has not run for {} ms: outputs neutral failed: {}",
                silent_ns / 1_000_000,
                failed.join("; ")
            );
        }
    }
}
