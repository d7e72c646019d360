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

    /// Takes the outcomes of finished saves (non-blocking).
    pub(super) fn poll_saves(&mut self) {
        for outcome in self.saver.poll() {
            self.on_saved(outcome);
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
