//! Real-time pacing: one sample per period of the wall clock, as a hardware driver.
//!
//! Sample `k` is due at `origin + t_k` (absolute deadlines, so sleeping never accumulates
//! drift). Between deadlines the driver blocks on the thrust listener; a command that passes
//! the gate takes effect at the moment it arrives (the physics is first stepped to that
//! moment), so the daemon's latency shows up in the plant as it would in the water. The last
//! valid command is held; thrust goes neutral at once on an invalid command and when no
//! valid command arrived for `watchdog_ms`.

use std::time::{Duration, Instant};

use tracing::warn;

use super::wait::{recv_until, Received};
use super::{Driver, DriverError, StopReason};
use thruster_protocol::gate::Verdict;

/// Lag behind the wall clock after which pacing restarts from now instead of publishing a
/// burst of overdue samples (the process was suspended or starved).
const MAX_LAG: Duration = Duration::from_secs(1);

impl Driver {
    pub(super) fn run_realtime(&mut self) -> Result<StopReason, DriverError> {
        let watchdog = self.settings.realtime.watchdog();
        self.publish_truth("start")?;
        let first = self.take_sample()?;
        let mut origin = Instant::now();
        self.send_sample(&first)?;
        let mut last_valid: Option<Instant> = None;
        loop {
            // Checked before waiting: the last sample is not followed by a period of waiting.
            if self.duration_reached() {
                return Ok(StopReason::Duration);
            }
            let next_t_ns = self.sim.time_ns() + self.period_ns;
            let deadline = origin + Duration::from_nanos(next_t_ns);
            loop {
                match recv_until(&self.ports.thrust, deadline, Duration::ZERO, &self.stop)? {
                    Received::Message(cmd) => match self.gate.check(&cmd) {
                        Verdict::Accept => {
                            let now = Instant::now();
                            let arrived_ns = now.saturating_duration_since(origin).as_nanos();
                            let arrived_ns = u64::try_from(arrived_ns).unwrap_or(u64::MAX);
                            self.sim.step_to(arrived_ns.min(next_t_ns));
                            self.hold(cmd.thrusters())?;
                            if let Some(stats) = &mut self.stats {
                                stats.answered(cmd.imu_seq, now);
                            }
                            last_valid = Some(now);
                            self.gate.applied(cmd.imu_seq);
                        }
                        Verdict::Stale => {}
                        Verdict::Reject(reason) => {
                            self.log_rejection(&cmd, &reason);
                            self.go_neutral();
                        }
                    },
                    Received::Timeout => break,
                    Received::Shutdown => return Ok(StopReason::Signal),
                }
            }
            if !self.neutral && last_valid.is_none_or(|t| t.elapsed() > watchdog) {
                warn!(
                    watchdog_ms = self.settings.realtime.watchdog_ms,
                    t_s = self.sim.time_s(),
                    "no valid thrust command within the watchdog: thrust neutral"
                );
                // Counted as lockstep counts its timeouts: driver_status reports expiries.
                self.timeouts += 1;
                self.go_neutral();
            }
            self.sim.step_to(next_t_ns);
            self.apply_due_events()?;
            let sample = self.take_sample()?;
            self.send_sample(&sample)?;
            let due = origin + Duration::from_nanos(self.sim.time_ns());
            if let Some(stats) = &mut self.stats {
                stats.paced(Instant::now().saturating_duration_since(due));
            }
            self.housekeeping()?;
            self.write_stats(false)?;
            let lag = Instant::now().saturating_duration_since(due);
            if lag > MAX_LAG {
                warn!(
                    lag_ms = lag.as_millis() as u64,
                    "fell behind the wall clock: pacing restarts from now"
                );
                origin = Instant::now() - Duration::from_nanos(self.sim.time_ns());
            }
        }
    }
}
