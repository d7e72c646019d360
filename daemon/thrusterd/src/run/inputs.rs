//! What comes in: IMU samples (validated, answered with a thrust command each), and what
//! comes before and with them (DVL, the driver's report and supply voltage, setpoints,
//! announced reconfigurations).

// The daemon's fields, ports and imports are the parent's: these are its methods, by job.
use super::*;

impl Daemon {
    /// Hands the machine the driver's supply voltage (taken at the report's `time_ns`) when it
    /// moved by [`SUPPLY_STEP_V`], came or went, or [`SUPPLY_EVERY_NS`] after the last one
    /// handed over (a pack that does not sag under a pulse is a point of its sag line too),
    /// and journals it (replay hands the machine the same values at the same samples).
    pub(super) fn take_supply(&mut self, voltage_v: Option<f64>, time_ns: u64) {
        let moved = match (self.supply_v, voltage_v) {
            (Some(a), Some(b)) => {
                (a - b).abs() >= SUPPLY_STEP_V
                    || time_ns >= self.supply_taken_ns.saturating_add(SUPPLY_EVERY_NS)
            }
            (None, None) => false,
            _ => true,
        };
        if !moved {
            return;
        }
        self.supply_taken_ns = time_ns;
        if voltage_v.is_none() {
            warn!("the driver no longer reports a supply voltage: commands are not compensated");
        } else if self.supply_v.is_none() {
            info!(
                volts = voltage_v,
                "the driver reports the supply voltage ([supply] compensation decides its use)"
            );
        }
        self.supply_v = voltage_v;
        self.machine.on_supply(voltage_v);
        self.journal(|j| {
            j.record(InputKind::Supply, false, |m| {
                m.code = u32::from(voltage_v.is_some());
                m.value = voltage_v.unwrap_or(0.0);
            })
        });
    }

    /// One IMU sample: the inputs that came before it (DVL, the driver's report, setpoints), a
    /// start-up request waiting for the IMU, then the sample itself (which takes announced
    /// reconfigurations, see `on_imu`).
    pub(super) fn on_sample(
        &mut self,
        sample: &ImuSample,
        side: &SideInputs,
        out: &Outputs,
    ) -> Result<()> {
        self.take_inputs_before_sample(side)?;
        self.start_pending();
        self.on_imu(sample, side, out)
    }

    /// `--estimate`, or a hold resumed after a crash, once the IMU is up (before the next
    /// sample, so in lockstep at the same vehicle time every run).
    pub(super) fn start_pending(&mut self) {
        use thrusterd_core::machine::State;
        if self.last_imu.is_none() || self.machine.state() == State::Fault {
            return;
        }
        if self.pending_estimate {
            self.pending_estimate = false;
            let result = self.machine.on_request(Request::Estimate);
            self.journal_request(RequestKind::Estimate, 0.0, result.is_err());
            if let Err(e) = result {
                warn!("start-up estimation refused: {e}");
            }
        }
        if self.pending_hold {
            self.pending_hold = false;
            let result = self.machine.on_request(Request::Hold);
            self.journal_request(RequestKind::Hold, 0.0, result.is_err());
            match result {
                Ok(_) => info!("resumed control after a crash: holding attitude"),
                Err(e) => warn!("could not resume control after a crash: {e}"),
            }
        }
    }

    /// What came before a sample: the DVL's measurement and the driver's report (count,
    /// outputs, supply), which a driver sends just before it, and setpoints. Taken before each
    /// sample is handled (in real time also once per round without one; in lockstep what came
    /// between samples is held for the next one, `side_inputs.rs`), so the sample is handled with
    /// them: in lockstep the sample each input lands at is a matter of vehicle time, not of
    /// how long the loop spun before it looked (a setpoint the lab sent while the simulator
    /// held acts from the next sample, always).
    pub(super) fn take_inputs_before_sample(&mut self, side: &SideInputs) -> Result<()> {
        while let Some(d) = side.next_dvl()? {
            match d.validate() {
                Ok(()) => {
                    self.machine.on_dvl(d.velocity);
                    self.journal(|j| j.record(InputKind::Dvl, false, |m| m.dvl = d.velocity));
                }
                Err(reason) => {
                    self.rejected.record(&reason);
                    warn!("DVL sample rejected: {reason}");
                }
            }
        }
        // The driver's report decides whether thrust may go out at all.
        while let Some(report) = side.next_driver_report()? {
            match report.validate() {
                Ok(()) => {
                    self.driver.observe(&report, self.machine.thrusters());
                    self.driver_judged_for = None;
                    self.take_supply(report.supply_voltage(), report.time_ns);
                }
                Err(reason) => {
                    self.rejected.record(&reason);
                    warn!("driver status rejected: {reason}");
                }
            }
        }
        // Judged on a new report, and when a reconfiguration changed the count the driver
        // must match.
        if self.driver_judged_for != Some(self.machine.thrusters()) {
            self.judge_outputs();
            self.driver_judged_for = Some(self.machine.thrusters());
        }
        while let Some(s) = side.next_setpoint()? {
            match s.validate() {
                Ok(()) => {
                    self.machine.on_setpoint_input(&wire::setpoint(&s));
                    self.journal(|j| j.setpoint(&s));
                }
                Err(reason) => {
                    self.rejected.record(&reason);
                    warn!("setpoint rejected: {reason}");
                }
            }
        }
        Ok(())
    }

    /// Announced reconfigurations: taken once a sample's command is computed and before it
    /// goes out (in real time also once per round without a sample). A driver announces a change just
    /// before the first sample taken after it, so the machine learns of it at that sample's
    /// time (taken before the sample, the new model was stamped one period before the
    /// change), and what it changes is published before that sample's answer.
    pub(super) fn take_reconfigurations(&mut self, side: &SideInputs) -> Result<()> {
        while let Some(e) = side.next_reconfig()? {
            match e.validate().and_then(|_| check_reconfig(&e)) {
                Ok(()) => {
                    self.machine.on_reconfig(wire::reconfig(&e));
                    self.journal(|j| j.reconfig(&e));
                }
                Err(reason) => {
                    self.rejected.record(&reason);
                    warn!("reconfiguration event rejected: {reason}");
                }
            }
        }
        Ok(())
    }

    /// Hands the machine the driver's verdict on its outputs when it changed.
    pub(super) fn judge_outputs(&mut self) {
        let verdict = self.driver.verdict(self.machine.thrusters());
        if verdict == self.driver_verdict {
            return;
        }
        match &verdict {
            OutputVerdict::Blocked(why) => {
                error!("driver outputs unusable: {why}; thrusters neutral");
                self.machine.on_outputs(Some(why));
                let why = why.clone();
                self.journal(|j| j.text(InputKind::Outputs, 1, false, &why));
            }
            OutputVerdict::Usable => {
                info!("driver outputs usable again");
                self.machine.on_outputs(None);
                self.journal(|j| j.text(InputKind::Outputs, 0, false, ""));
            }
        }
        self.driver_verdict = verdict;
    }

    pub(super) fn on_imu(
        &mut self,
        sample: &ImuSample,
        side: &SideInputs,
        out: &Outputs,
    ) -> Result<()> {
        match self.validator.check(sample) {
            Ok(accepted) => {
                self.last_imu = Some((sample.seq, sample.t_ns));
                let input = wire::imu_input(sample);
                // Results first, then the sample is counted: a result handed over now is
                // journaled as before this sample, which is where a replay hands it over.
                self.collect_solves();
                if self.cfg.runtime.lockstep {
                    self.wait_for_due_solves(input.t_ns);
                }
                if let Some(j) = self.journal.as_mut() {
                    j.imu(sample.seq, sample.t_ns);
                }
                if accepted.missed > 0 {
                    // Counted for status so no loss goes unnoticed; logged sparingly.
                    let before = self.missed;
                    self.missed = self.missed.saturating_add(accepted.missed);
                    if before < 20 || before.ilog2() != self.missed.ilog2() {
                        warn!(
                            missed = self.missed,
                            "{} IMU sample(s) missing before seq {}", accepted.missed, sample.seq
                        );
                    }
                }
                if accepted.resynced {
                    warn!(
                        "IMU stream restarted (seq {}): time discontinuity",
                        sample.seq
                    );
                }
                let cmd = self.machine.on_imu(&input);
                self.take_reconfigurations(side)?;
                if self.cfg.runtime.lockstep {
                    // Whatever this sample changed, and the periodic status in vehicle time,
                    // goes out before the answer: when the driver has the answer to sample
                    // k, everything the daemon published up to k is there, whatever the
                    // loop's timing (a lockstep observer reads one stream every run).
                    let changed = self.handle_events(&out.model);
                    if changed || input.t_ns >= self.next_status_ns {
                        self.publish_status(&out.status);
                        self.next_status_ns = input
                            .t_ns
                            .saturating_add(self.cfg.runtime.status_period_ms.max(1) * 1_000_000);
                    }
                }
                let sent = self.send_thrust(&out.thrust, &cmd);
                // After the answer went out: the sample's own latency does not include it.
                self.dispatch_solves();
                if let Some(port) = &out.telemetry {
                    self.publish_telemetry(port, &input, &sent);
                }
                if let (Some(c), Some(j)) = (self.checkpoints.as_mut(), self.journal.as_ref()) {
                    c.after_sample(&self.machine, input.t_ns, j.place());
                }
            }
            Err(reason) => {
                self.rejected.record(&reason);
                if self.rejected.total() < 20 || self.rejected.total().is_power_of_two() {
                    warn!(
                        rejected = self.rejected.total(),
                        "IMU sample rejected: {reason}"
                    );
                }
                // Still answer, with neutral: a driver in lockstep waits for every answer, and
                // a garbage sample must never keep a pulse running.
                let neutral = Command::neutral(self.machine.thrusters());
                let mut msg =
                    wire::thrust_command(self.thrust_seq, sample.seq, sample.t_ns, &neutral);
                self.thrust_seq += 1;
                msg.imu_seq = sample.seq;
                let _ = out.thrust.send(&msg);
            }
        }
        Ok(())
    }
}
