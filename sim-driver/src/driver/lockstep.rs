//! Lockstep pacing: the simulation advances only when the daemon has answered.
//!
//! Protocol, per sample `k` (seq from 1, `t_k = (k - 1) * period`):
//! 1. publish `ImuSample { seq: k, t_ns: t_k }` and notify `<ns>/imu/event`;
//! 2. wait for a `ThrustCommand` with `imu_seq == k` (and `t_ns == t_k`, `count` = the current
//!    thruster count), polling for `spin_us`, then blocking on the thrust listener, for at
//!    most `timeout_ms` of wall time;
//! 3. valid answer: hold it; invalid answer to `k` (NaN, out of range, wrong count, ...):
//!    neutral, counted; commands answering older samples: dropped (stale); no answer in
//!    time: neutral and a warning, and from then on each sample waits at most
//!    `idle_period_ms` until answers come back;
//! 4. step the physics one period with the held thrust, apply due scenario events, go to 1.
//!
//! With `--stepped`, before step 4 the simulator may take the next sample only when its
//! controller allows it (`stepping.rs`).
//!
//! Start: nothing is sent until the thrust topic has a publisher (the daemon, which subscribes
//! to every input before it creates that publisher): the driver's first report, the vehicle
//! state and a DVL measurement go out with sample 1, and a daemon that started after the
//! simulator would miss them, so what it learns would depend on which process the machine
//! started first (a lost first supply reading moved eight_vectored_t200's err_rot by 2e-8).
//! Then sample 1 is re-sent every 20 ms until a subscriber receives it, and its answer is
//! awaited without a time limit, so the simulator waits for the daemon without consuming
//! vehicle time.

use std::time::{Duration, Instant};

use thruster_protocol::ThrustCommand;
use tracing::{debug, info, warn};

use super::wait::{recv_until, Received};
use super::{Driver, DriverError, StopReason};
use thruster_protocol::gate::Verdict;

/// Pause between re-sends of the first sample while nobody subscribes.
const SUBSCRIBER_POLL: Duration = Duration::from_millis(20);

/// How the wait for the answer to one sample ended.
enum Answer {
    /// A valid answer.
    Valid(ThrustCommand),
    /// The answer to this sample was invalid (already counted and logged).
    Invalid,
    /// Nothing answered in time.
    None,
    /// Stopping was requested.
    Shutdown,
}

/// How far behind its schedule a paced run may make up by running unpaced. Why: after a
/// stall (a descheduled process, or the daemon's stopping decision at the paper's noise,
/// which now searches the lag to check the configured one) the whole stall was made up at
/// the daemon's speed, tens of kHz of samples, which can outrun a recorder's 128-sample
/// buffers. A CI run of the demo's recording (paper noise) lost 62 IMU and thrust samples,
/// not reproduced in 4 reruns; this removes the one way the pacing itself could cause it.
const MAX_CATCH_UP: Duration = Duration::from_millis(20);

impl Driver {
    pub(super) fn run_lockstep(&mut self) -> Result<StopReason, DriverError> {
        let cfg = self.settings.lockstep.clone();
        self.publish_truth("start")?;
        let first = self.take_sample()?;
        if !self.wait_for_subscriber(&first)? {
            return Ok(StopReason::Signal);
        }
        if !self.wait_for_first_answer(cfg.timeout())? {
            return Ok(StopReason::Signal);
        }
        let mut answering = true;
        if self.settings.stepped {
            self.stepping = Some(super::stepping::Stepping::from_stdin());
        }
        loop {
            if self.duration_reached() {
                return Ok(StopReason::Duration);
            }
            // Stepped: the newest sample is answered; the controller decides whether the
            // next one may be taken (it acts at exactly this vehicle time meanwhile).
            if let Some(stepping) = self.stepping.as_mut() {
                if stepping.will_wait() {
                    // History (the truth) reaches a new reader only on a connection update,
                    // which housekeeping does on the wall clock: do it before waiting, so a
                    // reader that looks while the run holds finds it without a step.
                    self.ports.truth.update_connections()?;
                }
                if !stepping.permit(self.imu_seq, self.sim.time_ns(), &self.stop)? {
                    return Ok(StopReason::Signal);
                }
            }
            self.pace(cfg.pace);
            self.sim.step(self.period_ns);
            self.apply_due_events()?;
            let sample = self.take_sample()?;
            self.send_sample(&sample)?;
            self.housekeeping()?;
            let k = self.imu_seq;
            let wait = if answering {
                cfg.timeout()
            } else {
                cfg.idle_period()
            };
            let window = self.spin.window();
            let published = Instant::now();
            let answer = self.await_answer(k, published + wait, window)?;
            if matches!(answer, Answer::Valid(_) | Answer::Invalid) {
                self.spin.record(window, published.elapsed());
            }
            match answer {
                Answer::Valid(cmd) => {
                    if !answering {
                        info!(imu_seq = k, "answers are back: lockstep resumes");
                    }
                    answering = true;
                    self.hold(cmd.thrusters())?;
                }
                Answer::Invalid => {
                    answering = true;
                    self.go_neutral();
                }
                Answer::None => {
                    self.timeouts += 1;
                    self.go_neutral();
                    if answering {
                        warn!(
                            imu_seq = k,
                            t_s = self.sim.time_s(),
                            timeout_ms = cfg.timeout_ms,
                            idle_period_ms = cfg.idle_period_ms,
                            "no answer to the IMU sample: thrust neutral; continuing at one \
                             sample per idle period until the daemon answers"
                        );
                    }
                    answering = false;
                }
                Answer::Shutdown => return Ok(StopReason::Signal),
            }
        }
    }

    /// With `pace` > 0, sleeps until the wall clock has caught up with vehicle time / pace.
    /// Behind by more than [`MAX_CATCH_UP`], the schedule moves to now instead: "no faster
    /// than X times real time" holds after a stall too.
    fn pace(&mut self, pace: f64) {
        let (Some(started), true) = (self.started, pace > 0.0) else {
            return;
        };
        let due = Duration::from_secs_f64(self.sim.time_s() / pace);
        let elapsed = started.elapsed();
        match due.checked_sub(elapsed) {
            Some(wait) => std::thread::sleep(wait),
            None if elapsed - due > MAX_CATCH_UP => {
                if let Some(anchor) = Instant::now().checked_sub(due) {
                    self.started = Some(anchor);
                }
            }
            None => {}
        }
    }

    /// Waits without a time limit for the answer to sample 1 and applies it; false on
    /// shutdown. A daemon may subscribe well before it can answer (loading its model), and no
    /// vehicle time should pass meanwhile.
    fn wait_for_first_answer(&mut self, slice: Duration) -> Result<bool, DriverError> {
        let mut logged = false;
        loop {
            match self.await_answer(1, Instant::now() + slice, Duration::ZERO)? {
                Answer::Valid(cmd) => {
                    self.hold(cmd.thrusters())?;
                    return Ok(true);
                }
                Answer::Invalid => {
                    self.go_neutral();
                    return Ok(true);
                }
                Answer::None => {
                    if !logged {
                        info!("a subscriber is there but no command yet: waiting for the answer to the first sample");
                        logged = true;
                    }
                }
                Answer::Shutdown => return Ok(false),
            }
        }
    }

    /// Re-sends the first sample until a subscriber gets it; false on shutdown.
    fn wait_for_subscriber(
        &mut self,
        first: &thruster_protocol::ImuSample,
    ) -> Result<bool, DriverError> {
        if !self.wait_for_answerer()? {
            return Ok(false);
        }
        let mut logged = false;
        loop {
            // A daemon that subscribes to the truth (or the reports) before the IMU finds
            // them there.
            self.ports.truth.update_connections()?;
            self.ports.driver_status.update_connections()?;
            if self.send_sample(first)? > 0 {
                if logged {
                    info!("subscriber found: lockstep starts");
                }
                // Pacing starts now, not when the process started.
                self.started = Some(Instant::now());
                return Ok(true);
            }
            if !logged {
                info!(
                    service = self.ports.imu.service_name(),
                    "waiting for a subscriber to the IMU samples"
                );
                logged = true;
            }
            if self.stop.requested() {
                return Ok(false);
            }
            std::thread::sleep(SUBSCRIBER_POLL);
        }
    }

    /// Waits until the thrust topic has a publisher, the process that will answer; false on
    /// shutdown.
    fn wait_for_answerer(&mut self) -> Result<bool, DriverError> {
        let mut logged = false;
        while self.ports.thrust.publishers() == 0 {
            if !logged {
                info!(
                    service = self.ports.thrust.service_name(),
                    "waiting for a publisher of thrust commands (the daemon) before the first sample"
                );
                logged = true;
            }
            if self.stop.requested() {
                return Ok(false);
            }
            std::thread::sleep(SUBSCRIBER_POLL);
        }
        Ok(true)
    }

    /// Waits until `deadline` for the command answering sample `k`.
    fn await_answer(
        &mut self,
        k: u64,
        deadline: Instant,
        spin: Duration,
    ) -> Result<Answer, DriverError> {
        loop {
            match recv_until(&self.ports.thrust, deadline, spin, &self.stop)? {
                Received::Message(cmd) => match self.gate.check(&cmd) {
                    Verdict::Accept => return Ok(Answer::Valid(cmd)),
                    Verdict::Stale => {
                        debug!(imu_seq = cmd.imu_seq, k, "late answer dropped");
                    }
                    Verdict::Reject(reason) => {
                        self.log_rejection(&cmd, &reason);
                        // It claims to answer this sample: that was the answer, and it is
                        // garbage. Anything else may still be followed by the real answer.
                        if cmd.imu_seq == k {
                            return Ok(Answer::Invalid);
                        }
                    }
                },
                Received::Timeout => return Ok(Answer::None),
                Received::Shutdown => return Ok(Answer::Shutdown),
            }
        }
    }
}
