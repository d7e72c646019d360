//! What outlives the process: the resume marker kept in step with the state, and model
//! saves (off the loop, their outcome in status).

// The daemon's fields, ports and imports are the parent's: these are its methods, by job.
use super::*;

impl Daemon {
    /// Reads what a crashed predecessor was doing and starts this daemon's own marker.
    pub(super) fn open_resume_marker(&mut self) {
        use crate::resume_marker::{Intent, ResumeMarker};
        let (mut marker, previous) = ResumeMarker::open(&self.cfg.runtime.state_dir);
        let resume = match previous {
            Some(Intent::Hold) if self.pending_estimate => Intent::Hold,
            Some(Intent::Hold) if !self.cfg.runtime.resume_after_crash => {
                warn!("the previous thrusterd did not stop cleanly while controlling; runtime.resume_after_crash = false: idle");
                Intent::Idle
            }
            Some(Intent::Hold) if self.machine.model().is_some() => {
                warn!("the previous thrusterd did not stop cleanly while controlling: resuming control with the saved model");
                self.pending_hold = true;
                Intent::Hold
            }
            Some(Intent::Hold) => {
                warn!("the previous thrusterd did not stop cleanly while controlling, but there is no model to resume with: idle");
                Intent::Idle
            }
            Some(Intent::Idle) if marker.previous_in_fault() => {
                info!("the previous thrusterd did not stop cleanly; it was in Fault and would have recovered to idle: idle");
                Intent::Idle
            }
            Some(Intent::Idle) => {
                info!("the previous thrusterd did not stop cleanly; it was idle: idle");
                Intent::Idle
            }
            None => Intent::Idle,
        };
        marker.record(resume);
        self.resume_marker = Some(marker);
    }

    /// Keeps the resume marker in step: controlling and estimating move the vehicle, so a
    /// crash in them resumes control; Fault keeps whatever it will recover to.
    pub(super) fn record_intent(&mut self, to: thrusterd_core::machine::State) {
        use thrusterd_core::machine::State;
        let intent = match to {
            State::Active => crate::resume_marker::Intent::Hold,
            s if s.is_estimating() => crate::resume_marker::Intent::Hold,
            State::Idle => crate::resume_marker::Intent::Idle,
            State::Fault => {
                // What clearing the fault resumes, marked as Fault (an operator's idle or stop
                // in Fault changes it without a state change: called after every request).
                let intent = if self.machine.fault_resumes_control() {
                    crate::resume_marker::Intent::Hold
                } else {
                    crate::resume_marker::Intent::Idle
                };
                if let Some(marker) = self.resume_marker.as_mut() {
                    marker.record_in_fault(intent);
                }
                return;
            }
            _ => return,
        };
        if let Some(marker) = self.resume_marker.as_mut() {
            marker.record(intent);
        }
    }

    /// Queues a save of `model` to the state directory; the outcome comes back through
    /// [`Daemon::poll_saves`]. Never blocks the loop.
    /// A new estimate is always saved; a refinement of one only when the last refined save
    /// is [`REFINED_SAVE_EVERY_NS`] old.
    pub(super) fn refined_save_due(&mut self, model: &thrusterd_core::model::Model) -> bool {
        if model.refinements == 0 {
            self.refined_saved_t_ns = None;
            return true;
        }
        let due = self
            .refined_saved_t_ns
            .is_none_or(|t| model.made_t_ns.saturating_sub(t) >= REFINED_SAVE_EVERY_NS);
        if due {
            self.refined_saved_t_ns = Some(model.made_t_ns);
        }
        due
    }

    pub(super) fn save(&mut self, model: &thrusterd_core::model::Model) {
        let path = self.model_path.clone();
        self.saver.submit(model, &path);
    }

    /// An operator's `save`: the model in force handed to the saving thread, the request kept
    /// open until `poll_saves` sees its outcome.
    pub(super) fn start_save(&mut self, req: &thruster_protocol::ControlRequest) -> Reply {
        let Some(model) = self.machine.model().cloned() else {
            return Reply::Now(ControlResponse::new(
                ResponseCode::Rejected,
                "no model to save",
            ));
        };
        let path = if req.text.as_str().is_empty() {
            self.model_path.clone()
        } else {
            PathBuf::from(req.text.as_str())
        };
        let id = self.saver.submit(&model, &path);
        let token = self.next_token;
        self.next_token += 1;
        self.save_answers.push(SaveAnswer {
            token,
            id,
            version: model.version,
            path,
            since: Instant::now(),
        });
        Reply::Later(token)
    }

    /// Takes the outcomes of finished saves (non-blocking) and answers the operators' saves
    /// among them; one still under way after [`SAVE_ANSWER_WAIT`] is answered that it is
    /// (a stalled disk), and status reports how it ends.
    pub(super) fn poll_saves(&mut self, control: &ControlServer) {
        for outcome in self.saver.poll() {
            if let Some(i) = self.save_answers.iter().position(|a| a.id == outcome.id) {
                let asked = self.save_answers.swap_remove(i);
                let response = match &outcome.result {
                    Ok(()) => ControlResponse::ok(&format!(
                        "saved model v{} to {}",
                        asked.version,
                        asked.path.display()
                    )),
                    Err(e) => ControlResponse::new(ResponseCode::Failed, e),
                };
                control.answer(asked.token, response);
            }
            self.on_saved(outcome);
        }
        let mut i = 0;
        while i < self.save_answers.len() {
            if self.save_answers[i].since.elapsed() < SAVE_ANSWER_WAIT {
                i += 1;
                continue;
            }
            let asked = self.save_answers.swap_remove(i);
            control.answer(
                asked.token,
                ControlResponse::ok(&format!(
                    "saving model v{} to {} (the disk is slow: status reports a failure)",
                    asked.version,
                    asked.path.display()
                )),
            );
        }
    }

    /// Logs a save's outcome; one to the state directory sets or clears the status note.
    pub(super) fn on_saved(&mut self, outcome: crate::saver::Outcome) {
        let to_state_dir = outcome.path == self.model_path;
        match &outcome.result {
            Ok(()) => {
                info!(path = %outcome.path.display(), version = outcome.version, "model saved")
            }
            Err(e) => warn!("model not saved (daemon keeps running): {e}"),
        }
        if to_state_dir {
            self.save_error = outcome.result.err();
        }
    }
}

/// An operator's save kept open until its outcome (or [`SAVE_ANSWER_WAIT`]).
pub(crate) struct SaveAnswer {
    token: u64,
    /// The saver's id of the save.
    id: u64,
    version: u64,
    path: PathBuf,
    since: Instant,
}
