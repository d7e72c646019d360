//! What goes out besides thrust: events (models, state changes), the model and its
//! dynamics, status and telemetry.

// The daemon's fields, ports and imports are the parent's: these are its methods, by job.
use super::*;

impl Daemon {
    /// Publishes the machine's events (a new model) and, if there were any, the status.
    pub(super) fn publish_changes(&mut self, out: &Outputs) {
        if self.handle_events(&out.model) {
            self.publish_status(&out.status);
        }
    }

    /// Sends `cmd` for the latest sample; returns the message as it went out.
    pub(super) fn send_thrust(
        &mut self,
        thrust_out: &Port<ThrustCommand>,
        cmd: &Command,
    ) -> ThrustCommand {
        let (imu_seq, t_ns) = self.last_imu.unwrap_or((0, 0));
        let mut msg = wire::thrust_command(self.thrust_seq, imu_seq, t_ns, cmd);
        // The machine already sanitises; this is the protocol's own last check before the wire.
        thruster_protocol::validate::sanitize_thrust(msg.thrusters_mut());
        self.thrust_seq += 1;
        if let Err(e) = thrust_out.send(&msg) {
            error!("thrust command not sent: {e}");
        }
        msg
    }

    /// Telemetry for every `every_n`-th accepted sample, after its thrust command went out (the
    /// driver never waits for it). The port never blocks: iceoryx2's safe overflow drops a
    /// slow reader's oldest message instead.
    pub(super) fn publish_telemetry(
        &mut self,
        port: &Port<TelemetryMsg>,
        input: &thrusterd_core::machine::ImuInput,
        sent: &ThrustCommand,
    ) {
        self.since_telemetry += 1;
        if self.since_telemetry < self.cfg.telemetry.every_n {
            return;
        }
        self.since_telemetry = 0;
        let snapshot = self.machine.telemetry(input);
        let msg = wire::telemetry_msg(self.telemetry_seq, &snapshot, sent);
        self.telemetry_seq += 1;
        if let Err(e) = port.send(&msg) {
            self.telemetry_failures += 1;
            let n = self.telemetry_failures;
            if n < 5 || n.is_power_of_two() {
                warn!(failures = n, "telemetry not published: {e}");
            }
        }
    }

    /// Publish and persist what the machine did; true when status should go out now.
    pub(super) fn handle_events(&mut self, model_out: &ModelPorts) -> bool {
        let events = self.machine.take_events();
        let changed = !events.is_empty();
        for event in events {
            match event {
                Event::ModelSwapped(model) => {
                    if model.refinements == 0 {
                        info!(version = model.version, source = ?model.source, actuated = ?model.actuated.names(), "model swapped in");
                    } else {
                        debug!(
                            version = model.version,
                            refinements = model.refinements,
                            rel_err_rot = model.rel_err_rot,
                            "model refined"
                        );
                    }
                    self.publish_model(model_out, &model);
                    if let Some(c) = self.checkpoints.as_mut() {
                        c.model_swapped();
                    }
                    if model.source == thrusterd_core::model::ModelSource::Estimated
                        && self.refined_save_due(&model)
                    {
                        self.save(&model);
                    }
                }
                Event::ModelDropped(why) => warn!("model dropped: {why}"),
                Event::ModelRejected(why) => warn!("model rejected, old one kept: {why}"),
                Event::MismatchDetected(why) => warn!("{why}"),
                Event::HoldLost(why) => warn!("{why}"),
                Event::BoundWidened(why) => warn!("{why}"),
                Event::StateChanged { from, to, why } => {
                    info!("{} -> {}: {why}", from.name(), to.name());
                    self.record_intent(to);
                }
            }
        }
        changed
    }

    pub(super) fn publish_model(
        &mut self,
        model_out: &ModelPorts,
        model: &thrusterd_core::model::Model,
    ) {
        let msg = wire::model_msg(self.model_seq, model);
        self.model_seq += 1;
        if let Err(e) = model_out.model.send(&msg) {
            error!("model not published: {e}");
        }
        if let Some(d) = wire::dynamics_msg(self.dynamics_seq, model) {
            self.dynamics_seq += 1;
            if let Err(e) = model_out.dynamics.send(&d) {
                error!("dynamic coefficients not published: {e}");
            }
        }
    }

    pub(super) fn status_msg(&mut self) -> StatusMsg {
        let mut msg = wire::status_msg(self.status_seq, &self.machine.status());
        self.status_seq += 1;
        self.rejected.write_to(&mut msg);
        msg.requests_refused = self.refused;
        msg.samples_missed = self.missed;
        let late = self.machine.late_solves();
        if late > 0 {
            // Before the save note: it is rarer and more urgent, so it goes first.
            let text = format!("{late} late solves | {}", msg.text());
            msg.set_text(&text);
        }
        if let Some(why) = &self.save_error {
            // First, since the text is bounded (128 bytes) and the state has its own field: the
            // machine's words are what gets cut.
            let text = format!("model not saved: {why} | {}", msg.text());
            msg.set_text(&text);
        }
        msg
    }

    pub(super) fn publish_status(&mut self, status_out: &Port<StatusMsg>) {
        let msg = self.status_msg();
        if let Err(e) = status_out.send(&msg) {
            error!("status not published: {e}");
        }
    }
}
