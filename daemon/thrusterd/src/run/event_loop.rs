//! The loop that serves: the ports and the WaitSet, the rounds (spin for samples, wait,
//! take what woke it, serve requests, keep status) and the stop (thrusters neutral, last
//! saves, the marker removed).

// The daemon's fields, ports and imports are the parent's: these are its methods, by job.
use super::*;
use crate::imu_wakeups::Wakeup;
use iceoryx2::prelude::FileDescriptorBased;

/// Everything the daemon serves on, created in `open_ports`. Fields drop in this order, the
/// reverse of their creation: the control server, which tells a live daemon from a crashed
/// one, goes last.
struct Ports {
    /// The effective configuration (history 1), sent once and kept reachable for late joiners.
    config_out: Port<ConfigMsg>,
    out: Outputs,
    side: SideInputs,
    imu_in: Inbox<ImuSample>,
    control: ControlServer,
}

/// What one wait of the WaitSet reported.
#[derive(Default)]
struct Woken {
    imu: bool,
    /// The IMU's deadline passed without a sample.
    stale: bool,
    reconfig: bool,
    setpoint: bool,
    control: bool,
    driver: bool,
}

/// The wall clock's share of the loop: when status was last published.
struct StatusClock {
    period: Duration,
    last: Instant,
}

impl Daemon {
    pub(super) fn serve_node(&mut self) -> Result<()> {
        let node = self.ipc.create_node("thrusterd")?;
        let mut ports = self.open_ports(&node)?;
        let mut clock = StatusClock {
            period: Duration::from_millis(self.cfg.runtime.status_period_ms.max(1)),
            last: Instant::now(),
        };
        let mut systemd = self.start_serving(&ports.out);
        if let Err(e) = self.serve_rounds(&node, &mut ports, &mut clock, &mut systemd) {
            // An IPC or wait failure ends the process; the thrusters are not left to the
            // driver's watchdog: neutral now, as far as the thrust port still works.
            error!("serving failed: thrusters neutral before exit: {e:#}");
            let neutral = Command::neutral(self.machine.thrusters());
            self.send_thrust(&ports.out.thrust, &neutral);
            return Err(e);
        }
        self.shut_down(&ports.out, &mut systemd);
        Ok(())
    }

    /// Serves rounds until stopped, renewing the IMU listener when asked to.
    fn serve_rounds(
        &mut self,
        node: &thruster_protocol::services::IpcNode,
        ports: &mut Ports,
        clock: &mut StatusClock,
        systemd: &mut thruster_driver_kit::Systemd,
    ) -> Result<()> {
        let mut imu_socket = socket_of(ports.imu_in.listener());
        while self.serve_until_renewal(ports, clock, systemd)? {
            // The wait set and its guards are gone: the IMU listener may be replaced.
            let old = ports.imu_in.replace_listener(node)?;
            let now = socket_of(&old);
            if now == imu_socket {
                drop(old);
            } else {
                // Its descriptor no longer refers to the socket it was created with (closed,
                // and the number reused): dropping it would close whatever has that number now.
                error!(
                    was = imu_socket,
                    now, "the IMU listener's descriptor no longer refers to its socket: left open"
                );
                std::mem::forget(old);
            }
            imu_socket = socket_of(ports.imu_in.listener());
            info!(
                socket = imu_socket,
                "IMU listener replaced: the drivers' notifiers connect to the new one"
            );
        }
        Ok(())
    }

    /// Serves rounds (spin for samples, wait, take what woke it, serve requests, keep status)
    /// until stopped (false) or until the IMU listener is to be replaced (true, at the end of
    /// a round: the wait set holds the listener, so it is rebuilt around the new one).
    fn serve_until_renewal(
        &mut self,
        ports: &Ports,
        clock: &mut StatusClock,
        systemd: &mut thruster_driver_kit::Systemd,
    ) -> Result<bool> {
        let Ports {
            control,
            imu_in,
            side,
            out,
            config_out,
        } = ports;
        let waitset = create_waitset()?;
        let imu_timeout = Duration::from_millis(self.cfg.runtime.imu_timeout_ms);
        let imu_guard = waitset.attach_deadline(imu_in.listener(), imu_timeout)?;
        let reconfig_guard = waitset.attach_notification(side.reconfig.listener())?;
        let setpoint_guard = waitset.attach_notification(side.setpoint.listener())?;
        let driver_guard = waitset.attach_notification(side.driver.listener())?;
        let control_guard = waitset.attach_notification(control.listener())?;
        let spin = Duration::from_micros(self.cfg.runtime.spin_us);

        let mut wait_errors = 0u32;
        while !self.shutdown.load(Ordering::SeqCst) {
            if !spin.is_zero() {
                self.spin_for_samples(spin, imu_in, side, out)?;
            }
            let mut woken = Woken::default();
            let waited = waitset.wait_and_process_once_with_timeout(
                |id| {
                    woken.imu |= id.has_event_from(&imu_guard);
                    woken.stale |= id.has_missed_deadline(&imu_guard);
                    woken.reconfig |= id.has_event_from(&reconfig_guard);
                    woken.setpoint |= id.has_event_from(&setpoint_guard);
                    woken.driver |= id.has_event_from(&driver_guard);
                    woken.control |= id.has_event_from(&control_guard);
                    CallbackProgression::Continue
                },
                if spin.is_zero() {
                    clock.period
                } else {
                    Duration::from_micros(1)
                },
            );
            if let Err(e) = waited {
                // A signal interrupts the wait (EINTR) before the handler's flag is seen: that
                // is the shutdown path, not a failure; anything persistent is.
                if self.shutdown.load(Ordering::SeqCst) {
                    break;
                }
                wait_errors += 1;
                warn!("waiting for events failed ({wait_errors} in a row): {e:?}");
                anyhow::ensure!(wait_errors < 100, "the event loop keeps failing: {e:?}");
                continue;
            }
            wait_errors = 0;
            let renew = self.take_woken(&woken, imu_in, side, out, imu_timeout)?;
            if woken.control {
                control.drain_events()?;
            }
            self.serve_requests(control, out)?;
            self.start_pending();
            self.poll_load(control, out);
            let changed = self.handle_events(&out.model);
            self.poll_saves(control);
            systemd.tick();
            self.keep_status(changed, clock, systemd, out, config_out);
            if renew {
                return Ok(true);
            }
        }
        Ok(false)
    }

    /// Creates every port. The control server first: it is what tells a live daemon on this
    /// namespace apart from a crashed one, and the resume marker of a live daemon must neither
    /// be read as a crash ("did not stop cleanly ... resuming control") nor overwritten.
    fn open_ports(
        &mut self,
        node: &iceoryx2::node::Node<iceoryx2::service::ipc::Service>,
    ) -> Result<Ports> {
        let control = ControlServer::create(node, &self.ipc)
            .context("another thrusterd already serves this namespace")?;
        self.open_resume_marker();
        // Every input before the IMU, and the thrust publisher after them all: a simulator in
        // lockstep starts (sends the driver's first report and the first sample) once the
        // thrust topic has a publisher, so whatever it sends with the first sample finds this
        // daemon subscribed, whichever process started first (one seed, one result).
        let side = SideInputs::new(
            Inbox::<ReconfigEvent>::create(node, &self.ipc)?,
            Inbox::<Setpoint>::create(node, &self.ipc)?,
            Inbox::<DriverStatusMsg>::create(node, &self.ipc)?,
            // Optional: only a vehicle with a DVL publishes here.
            Inbox::<DvlSample>::create(node, &self.ipc)?,
        );
        let imu_in = Inbox::<ImuSample>::create(node, &self.ipc)?;
        let thrust = Port::<ThrustCommand>::create(node, &self.ipc)?;
        // Off (every_n = 0): no service at all, so nothing in the loop pays for it.
        let telemetry = match self.cfg.telemetry.every_n {
            0 => None,
            _ => Some(Port::<TelemetryMsg>::create(node, &self.ipc)?),
        };
        let out = Outputs {
            thrust,
            telemetry,
            model: ModelPorts {
                model: Port::<ModelMsg>::create(node, &self.ipc)?,
                dynamics: Port::<DynamicsMsg>::create(node, &self.ipc)?,
            },
            status: Port::<StatusMsg>::create(node, &self.ipc)?,
        };
        // The effective configuration (history 1) and the input journal: what a replay of a
        // recording needs besides the IMU stream. Before the first sample is read.
        let config_out = Port::<ConfigMsg>::create(node, &self.ipc)?;
        if let Err(e) = config_out.send(&crate::journal::config_msg(&self.cfg)) {
            // Only a replay needs it (and then asks for --config): never worth not serving.
            warn!("configuration not published: {e}");
        }
        let mut journal = crate::journal::Journal::new(Port::<InputMsg>::create(node, &self.ipc)?);
        journal.text(
            InputKind::Start,
            u32::from(self.machine.model().is_some()),
            false,
            &format!("thrusterd {}", env!("CARGO_PKG_VERSION")),
        );
        self.journal = Some(journal);
        if self.cfg.checkpoint.enabled {
            self.checkpoints = Some(crate::checkpoints::Checkpoints::new(
                Port::<CheckpointMsg>::create(node, &self.ipc)?,
                &self.cfg.checkpoint,
                self.cfg.runtime.lockstep,
            ));
        }
        Ok(Ports {
            control,
            imu_in,
            side,
            out,
            config_out,
        })
    }

    /// From here this thread answers samples: the model in force published, the thread
    /// raised, systemd told it is ready, the first status out.
    fn start_serving(&mut self, out: &Outputs) -> thruster_driver_kit::Systemd {
        if let Some(model) = self.machine.model().cloned() {
            self.publish_model(&out.model, &model);
        }
        self.raise_control_thread();
        info!(thrusters = self.machine.thrusters(), "thrusterd serving");
        // A log line that finds journald's queue full is dropped rather than waited for (a
        // stalled journald must not stall control).
        thruster_driver_kit::logging::never_wait_on_this_thread();
        let mut systemd = thruster_driver_kit::Systemd::new();
        systemd.ready();
        self.publish_status(&out.status);
        systemd
    }

    /// Low-latency mode: keep polling for samples (answering each at once) until none came
    /// for `spin`, or housekeeping is due; only then pay for the WaitSet (a syscall, and a
    /// wake-up if it blocks). Other inputs wait at most ~1 ms.
    fn spin_for_samples(
        &mut self,
        spin: Duration,
        imu_in: &Inbox<ImuSample>,
        side: &SideInputs,
        out: &Outputs,
    ) -> Result<()> {
        let housekeeping = Instant::now();
        let mut idle_since = Instant::now();
        while idle_since.elapsed() < spin && housekeeping.elapsed() < HOUSEKEEPING {
            if let Some(sample) = imu_in.recv()? {
                self.on_sample(&sample, side, out)?;
                self.stale_reported = false;
                idle_since = Instant::now();
            } else {
                std::hint::spin_loop();
            }
        }
        Ok(())
    }

    /// What a wait reported: events drained, samples answered, inputs without a sample taken
    /// (or held, in lockstep), results handed over, and a silent IMU told.
    fn take_woken(
        &mut self,
        woken: &Woken,
        imu_in: &Inbox<ImuSample>,
        side: &SideInputs,
        out: &Outputs,
        imu_timeout: Duration,
    ) -> Result<bool> {
        if woken.imu {
            imu_in.drain_events()?;
        }
        side.dvl.drain_events()?;
        if woken.reconfig {
            side.reconfig.drain_events()?;
        }
        if woken.driver {
            side.driver.drain_events()?;
        }
        if woken.setpoint {
            side.setpoint.drain_events()?;
        }
        // The inbox is read on every wake-up, not only on an IMU event: a sample whose
        // notification was lost (a driver that notified before this listener was
        // connected, at start) would otherwise sit unread while a lockstep driver waits
        // for its answer forever. An empty inbox costs one check.
        let mut read = self.answer_inbox(imu_in, side, out)?;
        let mut renew = false;
        match self.imu_wakeups.after(woken.imu, read) {
            Wakeup::Fine => {}
            Wakeup::Rearm => read += self.rearm_imu(imu_in, side, out)?,
            Wakeup::Renew => {
                read += self.rearm_imu(imu_in, side, out)?;
                warn!(
                    "IMU notifications still missing after {} wake-ups; re-arming did not bring \
                     them back: replacing the listener. {}",
                    crate::imu_wakeups::RENEW_AFTER,
                    listener_report(imu_in.listener())
                );
                renew = true;
            }
            Wakeup::Stopped => {
                read += self.rearm_imu(imu_in, side, out)?;
                let why = format!(
                    "IMU samples are being read without their notifications ({} wake-ups in a \
                     row): answered only when something else wakes this loop; the listener was \
                     re-armed. {}",
                    crate::imu_wakeups::STOPPED_AFTER,
                    listener_report(imu_in.listener())
                );
                warn!("{why}");
            }
            Wakeup::Resumed { unnotified } => info!(
                unnotified,
                total = self.imu_wakeups.unnotified_total,
                "IMU notifications wake this loop again"
            ),
        }
        let got = read > 0;
        // What came without a sample (a setpoint while a real-time driver is quiet). In
        // lockstep it is read now but applied with the next sample (`on_sample`): the
        // simulator publishes its events just before a sample, and applying one here or
        // there would depend on which of the two this loop saw first (an announced
        // reconfiguration applied one sample apart moved an identification's end by 3
        // vehicle-s between two runs of one seed). Read now all the same: an operator's
        // publisher may be gone by the next sample, and an unread message with it.
        if self.cfg.runtime.lockstep {
            let dropped = side.hold_all()?;
            if dropped > 0 {
                warn!(
                    dropped,
                    "inputs held for the next sample overflowed: oldest dropped"
                );
            }
        } else {
            self.take_inputs_before_sample(side)?;
            self.take_reconfigurations(side)?;
        }
        if got {
            self.stale_reported = false;
        }
        // Results that came back while no sample did (handed over now, applied at their
        // due sample).
        self.collect_solves();
        // Before the first sample there is nothing to go stale: the driver is not up yet.
        // Status says so, and estimation and control are refused until a sample comes.
        if woken.stale && self.last_imu.is_none() {
            let why = format!(
                "no IMU samples from any driver for {} ms (namespace {})",
                imu_timeout.as_millis(),
                self.ipc.namespace()
            );
            self.machine.on_no_imu_yet(&why);
            self.journal(|j| j.text(InputKind::NoImuYet, 0, false, &why));
        }
        // In lockstep no vehicle time passes while the driver sends nothing (it waits for
        // us, or for whoever steps it): silence there is a pause, not a lost IMU.
        if woken.stale
            && !got
            && !self.stale_reported
            && self.last_imu.is_some()
            && !self.cfg.runtime.lockstep
        {
            let why = format!("no IMU sample for {} ms", imu_timeout.as_millis());
            let cmd = self.machine.on_imu_stale(&why);
            self.journal(|j| j.text(InputKind::ImuStale, 0, false, &why));
            self.send_thrust(&out.thrust, &cmd);
            self.stale_reported = true;
        }
        Ok(renew)
    }

    /// Answers every sample in the IMU inbox; how many there were.
    fn answer_inbox(
        &mut self,
        imu_in: &Inbox<ImuSample>,
        side: &SideInputs,
        out: &Outputs,
    ) -> Result<usize> {
        let mut read = 0;
        while let Some(sample) = imu_in.recv()? {
            self.on_sample(&sample, side, out)?;
            read += 1;
        }
        Ok(read)
    }

    /// Drains the IMU listener's pending events (re-arming it) and answers what came since:
    /// a lockstep driver sends its next sample as soon as it has our answer, and a drain after
    /// that sample would swallow its notification, so the inbox is read again after each drain
    /// until a drain finds it empty.
    fn rearm_imu(
        &mut self,
        imu_in: &Inbox<ImuSample>,
        side: &SideInputs,
        out: &Outputs,
    ) -> Result<usize> {
        let mut read = 0;
        loop {
            imu_in.drain_events()?;
            match self.answer_inbox(imu_in, side, out)? {
                0 => return Ok(read),
                n => read += n,
            }
        }
    }

    /// Serves operator requests on every round, not only after a notification: a request
    /// whose notification was lost while this daemon started (the client notified before our
    /// listener existed) would otherwise wait unanswered until the client gave up (thrusterctl
    /// exit 5 right after a restart, seen in tests/faults.rs). An empty queue costs one check
    /// per round, after the IMU answer.
    fn serve_requests(&mut self, control: &ControlServer, out: &Outputs) -> Result<()> {
        // Count every refusal (invalid request, wrong state, failure) for status.
        let mut refused = 0u32;
        let served = control.serve_deferring(|kind, req| {
            let reply = self.on_request(kind, req);
            // What the request changed goes out before its answer: a client that reads
            // status after the answer finds it there (and the lab, stepping a lockstep
            // simulator, acts on it at the same vehicle time every run).
            self.publish_changes(out);
            if let Reply::Now(response) = &reply {
                if !response.is_ok() {
                    refused += 1;
                    warn!(?kind, "operator request refused: {}", response.text());
                }
            }
            reply
        })?;
        if served.invalid > 0 {
            warn!(invalid = served.invalid, "invalid operator request refused");
        }
        self.refused = self
            .refused
            .saturating_add(refused)
            .saturating_add(served.invalid as u32);
        Ok(())
    }

    /// systemd's status line on a change or every status period, the status topic with it
    /// (in real time), and the history-1 services made reachable to late joiners.
    fn keep_status(
        &mut self,
        changed: bool,
        clock: &mut StatusClock,
        systemd: &mut thruster_driver_kit::Systemd,
        out: &Outputs,
        config_out: &Port<ConfigMsg>,
    ) {
        let wall_due = clock.last.elapsed() >= clock.period;
        if changed || wall_due {
            let s = self.machine.status();
            if s.text.starts_with(s.state.name()) {
                systemd.status(&s.text);
            } else {
                systemd.status(&format!("{}: {}", s.state.name(), s.text));
            }
        }
        // In lockstep the periodic status goes out with the samples, every
        // `status_period_ms` of vehicle time (`on_imu`): on the wall clock its count and
        // its vehicle times would depend on the machine's speed.
        let periodic = wall_due && !(self.cfg.runtime.lockstep && self.last_imu.is_some());
        if changed || periodic {
            self.publish_status(&out.status);
        }
        if wall_due {
            // History-1 services only reach late joiners on a send or this call.
            let _ = out.model.model.update_connections();
            let _ = out.model.dynamics.update_connections();
            let _ = out.status.update_connections();
            // The configuration is sent once: a recorder that joins later gets it only
            // from here (issue 26: a late `thrusterctl record` had no `config` channel).
            let _ = config_out.update_connections();
            clock.last = Instant::now();
        }
    }

    /// A stop: thrusters neutral first, then the last model saved (waited for, bounded), the
    /// resume marker removed (a clean stop begins idle next time), status says stopped.
    fn shut_down(&mut self, out: &Outputs, systemd: &mut thruster_driver_kit::Systemd) {
        info!(
            imu_unnotified_wakeups = self.imu_wakeups.unnotified_total,
            "shutting down: thrusters neutral"
        );
        systemd.stopping();
        let neutral = Command::neutral(self.machine.thrusters());
        self.send_thrust(&out.thrust, &neutral);
        self.handle_events(&out.model);
        if let Some(model) = self.machine.model().cloned() {
            self.save(&model);
        }
        // Thrust is neutral: now the saves may be waited for, but not forever (a disk that
        // never answers must not keep the process, and systemd's stop, waiting).
        let (outcomes, abandoned) = self.saver.finish(SHUTDOWN_SAVE_WAIT);
        for outcome in outcomes {
            self.on_saved(outcome);
        }
        if abandoned > 0 {
            error!(
                "{abandoned} model save(s) still waiting for the disk after {} s: abandoned",
                SHUTDOWN_SAVE_WAIT.as_secs()
            );
        }
        if let Some(marker) = self.resume_marker.take() {
            marker.finish(SHUTDOWN_SAVE_WAIT);
        }
        let mut status = self.status_msg();
        status.set_text(StatusMsg::STOPPED_TEXT);
        let _ = out.status.send(&status);
    }

    /// `runtime.realtime_priority`: this thread, the one that answers samples, to SCHED_FIFO
    /// (the solver, saver, loader and reaper threads stay normal). Refused, the daemon runs on
    /// at normal priority and says why: a vehicle that will not start over a scheduling
    /// permission is worse off than one with a slower answer.
    pub(super) fn raise_control_thread(&self) {
        let priority = self.cfg.runtime.realtime_priority;
        if priority == 0 {
            return;
        }
        match thruster_driver_kit::realtime::make_this_thread_fifo(priority) {
            Ok(()) => info!(priority, "control thread at SCHED_FIFO"),
            Err(e) => {
                warn!("runtime.realtime_priority: {e}; the control thread runs at normal priority")
            }
        }
    }
}

/// The IMU listener's socket as the kernel has it: its descriptor, what the descriptor points
/// at, and that socket's line of /proc/net/unix (references, state, bound path). Said when the
/// notifications stop, so a log tells a closed or replaced socket from a live one nobody
/// writes to.
fn listener_report(
    listener: &iceoryx2::port::listener::Listener<thruster_protocol::services::Ipc>,
) -> String {
    // SAFETY: the number is only formatted, never read, written or closed.
    let fd = unsafe { listener.file_descriptor().native_handle() };
    let target = socket_of(listener);
    let line = target
        .strip_prefix("socket:[")
        .and_then(|s| s.strip_suffix(']'))
        .and_then(|inode| {
            std::fs::read_to_string("/proc/net/unix")
                .ok()
                .and_then(|t| {
                    t.lines()
                        .find(|l| l.split_whitespace().nth(6) == Some(inode))
                        .map(|l| l.split_whitespace().collect::<Vec<_>>().join(" "))
                })
        })
        .unwrap_or_else(|| "not in /proc/net/unix".into());
    format!("listener fd {fd} -> {target} [{line}]")
}

/// What the listener's descriptor points at now ("socket:[inode]"), to tell its socket from a
/// descriptor closed and reused.
fn socket_of(
    listener: &iceoryx2::port::listener::Listener<thruster_protocol::services::Ipc>,
) -> String {
    // SAFETY: the number is only formatted into a /proc path, never read, written or closed.
    let fd = unsafe { listener.file_descriptor().native_handle() };
    std::fs::read_link(format!("/proc/self/fd/{fd}"))
        .map_or_else(|e| format!("unreadable ({e})"), |t| t.display().to_string())
}
