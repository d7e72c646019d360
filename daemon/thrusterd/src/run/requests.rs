//! Operator requests: answered at once, except a model load or save, which is done off this
//! thread and answered when it is back; every request the machine acted on is journaled.

// The daemon's fields, ports and imports are the parent's: these are its methods, by job.
use super::*;

impl Daemon {
    pub(super) fn on_request(
        &mut self,
        kind: RequestKind,
        req: &thruster_protocol::ControlRequest,
    ) -> Reply {
        if kind == RequestKind::Load {
            // Answered when the file is read (`poll_load`), never on this thread's time.
            let path = PathBuf::from(req.text.as_str());
            let token = self.next_token;
            self.next_token += 1;
            return match self.loader.start(token, &path) {
                Ok(()) => Reply::Later(token),
                Err(busy) => Reply::Now(ControlResponse::new(ResponseCode::Busy, &busy)),
            };
        }
        if kind == RequestKind::Save {
            // Answered when the saving thread is done (`poll_saves`): never waited for here.
            return self.start_save(req);
        }
        Reply::Now(self.on_immediate_request(kind, req))
    }

    /// Every request but a load or a save: answered at once.
    pub(super) fn on_immediate_request(
        &mut self,
        kind: RequestKind,
        req: &thruster_protocol::ControlRequest,
    ) -> ControlResponse {
        let machine_req = match kind {
            RequestKind::Status => {
                let s = self.machine.status();
                return ControlResponse::ok(&format!("{}: {}", s.state.name(), s.text));
            }
            RequestKind::Estimate => {
                if req.value != 0.0 {
                    if let Err(e) = self.machine.set_estimation_power(req.value) {
                        return ControlResponse::new(ResponseCode::InvalidRequest, &e.0);
                    }
                }
                Request::Estimate
            }
            RequestKind::Abort => Request::Abort,
            RequestKind::Hold => Request::Hold,
            RequestKind::Idle => Request::Idle,
            RequestKind::Stop => Request::Stop,
            RequestKind::Revert => Request::Revert,
            RequestKind::Load | RequestKind::Save => {
                unreachable!("loads and saves are answered when done (poll_load, poll_saves)")
            }
            RequestKind::Shutdown => {
                self.shutdown.store(true, Ordering::SeqCst);
                return ControlResponse::ok("shutting down");
            }
        };
        let result = self.machine.on_request(machine_req);
        self.journal_request(kind, req.value, result.is_err());
        if self.machine.state() == thrusterd_core::machine::State::Fault {
            // Idle or stop in Fault change what it recovers to without a state change.
            self.record_intent(thrusterd_core::machine::State::Fault);
        }
        match result {
            Ok(text) => ControlResponse::ok(&text),
            Err(e) => ControlResponse::new(ResponseCode::Rejected, &e.0),
        }
    }

    /// A load in flight: answered when its file is read and installed, or told after
    /// `loader::ANSWER_WAIT` that it is still being read.
    pub(super) fn poll_load(&mut self, control: &ControlServer, out: &Outputs) {
        match self.loader.poll() {
            Progress::Nothing => {}
            Progress::Slow { token, path } => {
                let text = format!(
                    "still reading {} after {:.1} s (a slow or stalled disk?): installed when read, \
                     see status and the log",
                    path.display(),
                    crate::loader::ANSWER_WAIT.as_secs_f64()
                );
                warn!("{text}");
                control.answer(token, ControlResponse::new(ResponseCode::Busy, &text));
            }
            Progress::Done {
                token,
                path,
                result,
                answered,
            } => {
                let shown = path.display().to_string();
                let outcome = (*result).and_then(|model| {
                    let r = self.machine.load_prepared(model);
                    self.journal(|j| j.text(InputKind::Load, 0, r.is_err(), &shown));
                    r.map_err(|e| LoadError::Rejected(e.0))
                });
                let response = match &outcome {
                    Ok(()) => {
                        info!(path = %shown, "model loaded");
                        ControlResponse::ok(&format!("loaded {shown}"))
                    }
                    Err(e) => {
                        self.refused = self.refused.saturating_add(1);
                        warn!("operator request refused: load {shown}: {e}");
                        let code = match e {
                            LoadError::Failed(_) => ResponseCode::Failed,
                            LoadError::Rejected(_) => ResponseCode::Rejected,
                        };
                        ControlResponse::new(code, &e.to_string())
                    }
                };
                // The new model and status before the answer, as for any request.
                self.publish_changes(out);
                if !answered {
                    control.answer(token, response);
                }
            }
        }
    }

    /// Runs `f` on the input journal (there is none before `serve` created the ports).
    pub(super) fn journal(&mut self, f: impl FnOnce(&mut crate::journal::Journal)) {
        if let Some(j) = self.journal.as_mut() {
            f(j);
        }
    }

    /// Journals a request the machine acted on (`value`: an estimate's power).
    pub(super) fn journal_request(&mut self, kind: RequestKind, value: f64, refused: bool) {
        self.journal(|j| {
            j.record(InputKind::Request, refused, |m| {
                m.code = kind.as_u32();
                m.value = value;
            })
        });
    }
}
