//! The `thruster-hw run` process: the pure core and a backend at the IPC edge.
//!
//! One thread, one wait set. It wakes on a thrust command (the `<ns>/thrust/event`
//! listener), on a backend wake-up (a reading arrived on the backend's receive thread), or
//! at the earliest deadline (a backend poll or resend, the watchdog's expiry, the status
//! line), and then does everything that is due:
//! 1. publish every new sensor reading as an [`ImuSample`] (seq from 1, `t_ns` the reading's
//!    CLOCK_MONOTONIC time) on `<ns>/imu`;
//! 2. take every received [`ThrustCommand`] through the [`Controller`] (validation, count,
//!    freshness, watchdog);
//! 3. write the outputs to the backend when they changed;
//! 4. let the backend do its periodic work.
//!
//! Neutral is written at start (held for `arming_ms`), whenever the watchdog expires or a
//! command is invalid, and before leaving for any reason: signal, backend error, panic
//! (the backends' `Drop`).

pub mod after_exit;
pub mod shutdown;
pub mod status;
pub mod wake;

use std::time::Duration;

use iceoryx2::prelude::CallbackProgression;
use thruster_protocol::services::{create_waitset, Inbox, IpcConfig, IpcError, Port};
use thruster_protocol::validate::limits::{MAX_DEPTH_M, MIN_DEPTH_M};
use thruster_protocol::{DriverStatusMsg, ImuReading, ImuSample, ThrustCommand, Validate};
use tracing::{error, info, warn};

use crate::backend::linux::LinuxBackend;
use crate::backend::mavlink::MavlinkBackend;
use crate::backend::{Backend, BackendError, LinkState, OutputSpec};
use crate::clock::monotonic_ns;
use crate::config::{BackendKind, Settings};
use crate::core::controller::{Controller, Counters, Outcome, OutputState};
use crate::core::pwm::{OutputMap, Pwm};
use shutdown::Shutdown;
use status::StatusReporter;
use thruster_driver_kit::LogLimiter;
use wake::WakePipe;

/// Node name of the driver in iceoryx2 listings.
pub const NODE_NAME: &str = "thruster-hw";

/// Longest single wait, so the stop flag is seen promptly even if a signal does not
/// interrupt the wait.
pub const MAX_BLOCK: Duration = Duration::from_millis(50);

/// Shortest wait: a deadline already past is handled on the next round without spinning.
const MIN_BLOCK: Duration = Duration::from_micros(20);

/// Consecutive failed waits taken as signal interruptions before the error is returned.
const MAX_WAIT_ERRORS: u32 = 3;

/// Failures of the driver.
#[derive(Debug, thiserror::Error)]
pub enum DriverError {
    /// IPC setup or transfer failed.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// The hardware failed (outputs were set neutral before this was returned, as far as
    /// the hardware allowed).
    #[error(transparent)]
    Backend(#[from] BackendError),
    /// The wait set or its wake-up socket failed.
    #[error("wait set: {0}")]
    Wait(String),
}

/// Why a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// SIGINT, SIGTERM or SIGHUP.
    Signal,
}

/// What a run did.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Why it ended.
    pub reason: StopReason,
    /// IMU samples published.
    pub samples: u64,
    /// Readings not published because they failed the protocol's validation.
    pub sensor_rejected: u64,
    /// Depths dropped (out of the protocol's range) from otherwise good samples.
    pub depth_dropped: u64,
    /// Command counters.
    pub commands: Counters,
}

/// The output specs the backend needs and the mappings the core needs, from the settings.
pub fn outputs(settings: &Settings) -> (Vec<OutputMap>, Vec<OutputSpec>) {
    let maps: Vec<OutputMap> = settings
        .thrusters
        .iter()
        .map(|t| OutputMap::new(t.params()))
        .collect();
    let specs = settings
        .thrusters
        .iter()
        .zip(&maps)
        .map(|(t, m)| OutputSpec {
            channel: t.channel,
            neutral: m.neutral(),
        })
        .collect();
    (maps, specs)
}

/// The backend the settings select (not started).
pub fn build_backend(settings: &Settings) -> Box<dyn Backend> {
    let (_, specs) = outputs(settings);
    match settings.backend {
        BackendKind::Mavlink => Box::new(MavlinkBackend::new(settings.mavlink.clone(), specs)),
        BackendKind::Linux => Box::new(
            LinuxBackend::new(settings.linux.clone(), specs)
                .with_stall_guard(stall_limit(settings)),
        ),
    }
}

/// How long the loop may stop calling the Linux backend before its guard thread takes the
/// outputs neutral: the command watchdog's time, but never under two of the loop's longest
/// waits (a loop idle between samples calls in every `MAX_BLOCK` at least).
pub fn stall_limit(settings: &Settings) -> Duration {
    Duration::from_millis(settings.watchdog_ms).max(2 * MAX_BLOCK)
}

/// Runs the driver with the backend the settings select until `stop` is requested.
pub fn run(settings: &Settings, stop: &Shutdown) -> Result<Summary, DriverError> {
    run_with(settings, build_backend(settings), stop)
}

/// Runs the driver with `backend` until `stop` is requested (or anything fails). Outputs
/// are neutral when this returns, whatever it returns.
pub fn run_with(
    settings: &Settings,
    mut backend: Box<dyn Backend>,
    stop: &Shutdown,
) -> Result<Summary, DriverError> {
    let result = run_inner(settings, backend.as_mut(), stop);
    // Always, also after errors: neutral and release. A failure here is reported but does
    // not hide the error that ended the loop.
    if let Err(e) = backend.stop() {
        error!("could not leave the outputs neutral: {e}");
        if result.is_ok() {
            return Err(e.into());
        }
    } else {
        info!(backend = backend.name(), "outputs neutral");
    }
    result
}

fn run_inner(
    settings: &Settings,
    backend: &mut dyn Backend,
    stop: &Shutdown,
) -> Result<Summary, DriverError> {
    let ipc = IpcConfig::with_root_base(&settings.namespace, &settings.ipc_root)?;
    // Before the node, so it drops after it: the last process of the namespace to stop
    // removes iceoryx2's residue.
    let _tidy = thruster_protocol::services::TidyOnDrop::new(&ipc);
    // Declared before its ports so it is dropped after them.
    let node = ipc.create_node(NODE_NAME)?;
    let imu = Port::<ImuSample>::create(&node, &ipc)?;
    let driver_status = Port::<DriverStatusMsg>::create(&node, &ipc)?;
    let thrust = Inbox::<ThrustCommand>::create(&node, &ipc)?;
    let wake = WakePipe::new().map_err(DriverError::Wait)?;
    let waitset = create_waitset()?;
    let wait_err = |e: &dyn std::fmt::Debug| DriverError::Wait(format!("{e:?}"));
    let _thrust_guard = waitset
        .attach_notification(thrust.listener())
        .map_err(|e| wait_err(&e))?;
    let _wake_guard = waitset
        .attach_notification(wake.socket())
        .map_err(|e| wait_err(&e))?;

    let start_ns = monotonic_ns();
    let (maps, _) = outputs(settings);
    let controller = Controller::new(
        maps,
        start_ns,
        settings.arming_ms * 1_000_000,
        settings.watchdog_ms * 1_000_000,
    );
    backend.start(wake.waker(), start_ns)?;
    info!(
        namespace = %settings.namespace,
        backend = backend.name(),
        thrusters = settings.thrusters.len(),
        neutral_us = ?us(controller.neutral()),
        arming_ms = settings.arming_ms,
        watchdog_ms = settings.watchdog_ms,
        "thruster-hw running: outputs neutral"
    );
    // READY only now: the outputs are neutral (arming) and the ports are up. Pings come from
    // the loop below, so a hung loop is killed by systemd (WatchdogSec) and restarted neutral.
    let mut systemd = thruster_driver_kit::Systemd::new();
    systemd.ready();
    let mut lp = Loop {
        last_written: controller.neutral().to_vec(),
        controller,
        seq: 0,
        last_t_ns: 0,
        sensor_rejected: 0,
        depth_dropped: 0,
        reject_log: LogLimiter::default(),
        sensor_log: LogLimiter::default(),
        state_log: LogLimiter::new(10, Duration::from_secs(10)),
        last_state: OutputState::Arming,
        last_link: LinkState::Connecting,
        next_status_ns: start_ns + settings.status_period_ms * 1_000_000,
        status_period_ns: settings.status_period_ms * 1_000_000,
        reporter: StatusReporter::new(backend.name(), settings.thrusters.len(), start_ns),
        driver_status,
        last_reported: None,
    };
    let mut wait_errors = 0;
    // This thread drives the thrusters: a log line that finds journald's queue full is
    // dropped rather than waited for (a stalled journald must not stall the outputs).
    thruster_driver_kit::logging::never_wait_on_this_thread();
    loop {
        if stop.requested() {
            break;
        }
        lp.round(backend, &imu, &thrust)?;
        systemd.tick();

        let now = monotonic_ns();
        let deadline = [
            lp.controller.next_change_ns(now),
            backend.next_deadline_ns(),
            Some(lp.next_status_ns),
            Some(lp.reporter.next_ns()),
        ]
        .into_iter()
        .flatten()
        .min()
        .unwrap_or(u64::MAX);
        let timeout =
            Duration::from_nanos(deadline.saturating_sub(now)).clamp(MIN_BLOCK, MAX_BLOCK);
        match waitset.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, timeout)
        {
            Ok(_) => wait_errors = 0,
            // A signal interrupts the wait before ctrlc's thread sets the flag; only a
            // repeated failure is real.
            Err(e) => {
                wait_errors += 1;
                if wait_errors > MAX_WAIT_ERRORS {
                    return Err(wait_err(&e));
                }
            }
        }
        // Drain before the next round's reads: a notification arriving after this drain
        // belongs to a message the round will find, or wakes the next wait.
        wake.drain();
        thrust.drain_events()?;
    }
    systemd.stopping();
    let summary = lp.summary();
    let c = &summary.commands;
    let backend_stats: String = backend
        .stats()
        .iter()
        .map(|(k, v)| format!(" {k}={v}"))
        .collect();
    info!(
        "thruster-hw stopped reason=signal samples={} applied={} arming={} stale={} rejected={} \
         rejected_nonfinite={} rejected_range={} rejected_count={} rejected_time={} \
         rejected_other={} sensor_rejected={} depth_dropped={} watchdog_expiries={}{}",
        summary.samples,
        c.applied,
        c.arming,
        c.stale,
        c.rejected.total(),
        c.rejected.nonfinite,
        c.rejected.range,
        c.rejected.count,
        c.rejected.time,
        c.rejected.other,
        summary.sensor_rejected,
        summary.depth_dropped,
        lp.reporter.watchdog_expiries(),
        backend_stats,
    );
    Ok(summary)
}

fn us(p: &[Pwm]) -> Vec<u16> {
    p.iter().map(|p| p.us()).collect()
}

/// The loop's state between rounds.
struct Loop {
    controller: Controller,
    last_written: Vec<Pwm>,
    seq: u64,
    last_t_ns: u64,
    sensor_rejected: u64,
    depth_dropped: u64,
    reject_log: LogLimiter,
    sensor_log: LogLimiter,
    state_log: LogLimiter,
    last_state: OutputState,
    last_link: LinkState,
    next_status_ns: u64,
    status_period_ns: u64,
    reporter: StatusReporter,
    driver_status: Port<DriverStatusMsg>,
    last_reported: Option<thruster_protocol::OutputState>,
}

impl Loop {
    /// Everything that is due now.
    fn round(
        &mut self,
        backend: &mut dyn Backend,
        imu: &Port<ImuSample>,
        thrust: &Inbox<ThrustCommand>,
    ) -> Result<(), DriverError> {
        // Samples first: the daemon computes the next command from them.
        while let Some(r) = backend.read_sensors(monotonic_ns())? {
            self.publish(imu, r)?;
        }
        while let Some(cmd) = thrust.recv()? {
            let outcome = self.controller.on_command(&cmd, monotonic_ns());
            if let Outcome::Rejected(reason) = outcome {
                self.reporter.rejected(&reason.to_string());
                if let Some(suppressed) = self.reject_log.allow() {
                    warn!(
                        seq = cmd.seq,
                        imu_seq = cmd.imu_seq,
                        suppressed,
                        "thrust command rejected: {reason}; outputs neutral"
                    );
                }
            }
        }
        let now = monotonic_ns();
        let outs = self.controller.outputs(now);
        if outs != self.last_written.as_slice() {
            backend.write_outputs(outs, now)?;
            self.last_written.clear();
            self.last_written.extend_from_slice(outs);
        }
        backend.service(now)?;
        self.report(backend, now)
    }

    /// The driver's own status on `driver_status` (see [`status`]). `held`: the backend's
    /// [`Backend::held`] this round.
    fn publish_status(
        &mut self,
        backend: &dyn Backend,
        held: Option<&str>,
        now: u64,
    ) -> Result<(), DriverError> {
        let core = self.controller.state(now);
        let (link, armed) = (backend.link(), backend.armed());
        let supply = backend.supply(now);
        let device = status::Device {
            link: &link,
            armed,
            held,
            supply,
        };
        if let Some(msg) = self
            .reporter
            .report(now, core, self.controller.counters(), device)
        {
            self.driver_status.send(&msg)?;
        }
        Ok(())
    }

    fn publish(&mut self, imu: &Port<ImuSample>, r: ImuReading) -> Result<(), DriverError> {
        let mut r = ImuReading {
            seq: self.seq + 1,
            // Strictly increasing even if two readings share a clock value.
            t_ns: r.t_ns.max(self.last_t_ns + 1),
            ..r
        };
        if let Some(d) = r.depth {
            if !(d.is_finite() && (MIN_DEPTH_M..=MAX_DEPTH_M).contains(&d)) {
                // A bad depth must not cost the gyro and accelerometer: drop only the depth.
                r.depth = None;
                self.depth_dropped += 1;
            }
        }
        let s = r.to_sample();
        if let Err(reason) = s.validate() {
            self.sensor_rejected += 1;
            if let Some(suppressed) = self.sensor_log.allow() {
                warn!(suppressed, "sensor reading not published: {reason}");
            }
            return Ok(());
        }
        imu.send(&s)?;
        self.seq = s.seq;
        self.last_t_ns = s.t_ns;
        self.controller.published(s.seq, s.t_ns);
        Ok(())
    }

    fn report(&mut self, backend: &dyn Backend, now: u64) -> Result<(), DriverError> {
        // Asked once a round: a held backend says why in a new String.
        let held = backend.held();
        self.publish_status(backend, held.as_deref(), now)?;
        let state = self.controller.state(now);
        // What reaches the water: the backend's link and armed state win over the core's.
        let moves = backend.armed() && held.is_none();
        let reported = status::output_state(state, &backend.link(), moves);
        let described = status::describe(state, reported, held.as_deref());
        if state != self.last_state || Some(reported) != self.last_reported {
            if let Some(suppressed) = self.state_log.allow() {
                info!(suppressed, pwm_us = ?us(self.controller.outputs(now)), "outputs: {described}");
            }
            self.last_state = state;
            self.last_reported = Some(reported);
        }
        let link = backend.link();
        if link != self.last_link {
            info!("link: {link}");
            self.last_link = link;
        }
        if now >= self.next_status_ns {
            let c = self.controller.counters();
            info!(
                outputs = %described,
                link = %self.last_link,
                samples = self.seq,
                applied = c.applied,
                stale = c.stale,
                rejected = c.rejected.total(),
                sensor_rejected = self.sensor_rejected,
                pwm_us = ?us(self.controller.outputs(now)),
                "status"
            );
            self.next_status_ns = now + self.status_period_ns;
        }
        Ok(())
    }

    fn summary(&self) -> Summary {
        Summary {
            reason: StopReason::Signal,
            samples: self.seq,
            sensor_rejected: self.sensor_rejected,
            depth_dropped: self.depth_dropped,
            commands: *self.controller.counters(),
        }
    }
}
