//! What the operator and the vehicle's other inputs ask of the machine: requests (estimate,
//! hold, stop, revert, ...), setpoints and reconfigurations.

// The machine's fields and helpers are the parent's: these are its methods, by job.
use super::*;

impl Machine {
    pub fn on_request(&mut self, req: Request) -> Result<String, Refused> {
        match req {
            Request::Estimate => {
                if self.samples == 0 {
                    return Err(Refused(NO_IMU_YET.into()));
                }
                if self.state == State::Fault {
                    // What to do first: the fault's own text is long and may be cut.
                    return Err(Refused(format!(
                        "in fault: estimate once it clears ({})",
                        self.text
                    )));
                }
                if let Some(err_deg) = self.beyond_identification_budget() {
                    return Err(Refused(format!(
                        "the vehicle is {err_deg:.0} deg from its setpoint, beyond the \
                         identification budget of {:.0} deg (identification.attitude_budget_deg): \
                         let it settle, or hold, then estimate",
                        self.setup.identification.attitude_budget_deg
                    )));
                }
                let t = self.last_t_ns.unwrap_or(0);
                self.stopped = false;
                self.hold_lost_once = false;
                self.start_estimation(t, "estimate requested");
                Ok(format!("estimating {} thrusters", self.n))
            }
            Request::Abort => {
                if self.settling.take().is_some() {
                    // Idle after a lost hold, waiting to estimate from rest: that is what the
                    // operator aborts.
                    self.text = "estimation from rest after the lost hold aborted: thrusters \
                                 neutral until an estimate or hold request"
                        .into();
                    return Ok("aborted".into());
                }
                if self.end_curve_wait() {
                    // A curve just learned, the identification on it waiting for the hold:
                    // that is what the operator aborts; the model in force stays, with its
                    // own curve.
                    self.text = "identification on the learned thrust curve aborted: holding \
                                 attitude with the model in force"
                        .into();
                    return Ok("aborted; holding attitude".into());
                }
                if self.pending_confirmation.take().is_some() {
                    // A fight's model in force, its confirmation waiting for the hold: that
                    // is what the operator aborts; the model stays, its bound widened.
                    self.text = "confirmation of the fight's model aborted: holding attitude \
                                 with it"
                        .into();
                    return Ok("aborted; holding attitude".into());
                }
                if !self.state.is_estimating() {
                    return Err(Refused(format!(
                        "nothing to abort (state {})",
                        self.state.name()
                    )));
                }
                self.run.stop();
                if self.state == State::Identify && self.models.current().is_some() {
                    // Under control the vehicle is held: it stays held, by the model in force.
                    let why = self.describe_swap("estimation aborted: holding attitude");
                    self.transition(State::Active, &why);
                    return Ok("aborted; holding attitude".into());
                }
                self.transition(State::Idle, "estimation aborted: thrusters neutral");
                Ok("aborted".into())
            }
            Request::Hold => {
                if self.state == State::Fault {
                    return Err(Refused("in fault: cannot hold".into()));
                }
                if self.models.current().is_none() {
                    return Err(Refused("no model yet: estimate first".into()));
                }
                if self.samples == 0 {
                    return Err(Refused(NO_IMU_YET.into()));
                }
                self.run.stop();
                self.stopped = false;
                self.hold_lost_once = false;
                self.target = None;
                self.controller.reset();
                self.transition(State::Active, "holding attitude");
                Ok("holding".into())
            }
            Request::Idle => {
                self.run.stop();
                self.settling = None;
                let t = self.last_t_ns.unwrap_or(0);
                if self.state == State::Fault {
                    self.resume = Resume::Idle;
                    return Ok("will stay idle after the fault clears".into());
                }
                self.phase_start_ns = t;
                self.transition(State::Idle, "idle on request: thrusters neutral");
                Ok("idle".into())
            }
            Request::Stop => {
                // Whatever runs (an estimation, its solve, levelling, control) ends here; the
                // next command is neutral. The model in force stays, so `hold` can resume.
                self.run.stop();
                self.levelling = None;
                self.settling = None;
                self.controller.reset();
                self.stopped = true;
                self.resume = Resume::Idle;
                let t = self.last_t_ns.unwrap_or(0);
                if self.state == State::Fault {
                    // Already neutral; after the fault clears it stays idle.
                    return Ok(
                        "emergency stop: in fault, thrusters neutral; idle after it \
                               clears, until estimate or hold"
                            .into(),
                    );
                }
                self.phase_start_ns = t;
                self.transition(
                    State::Idle,
                    "emergency stop: thrusters neutral until estimate or hold",
                );
                Ok("emergency stop: thrusters neutral until estimate or hold".into())
            }
            Request::Revert => {
                let Some(prev) = self.models.take_previous() else {
                    return Err(Refused("no previous model to revert to".into()));
                };
                let source = prev.source;
                self.try_swap(prev, source)
                    .map_err(|e| Refused(format!("revert refused: {e}")))?;
                Ok(self.describe_swap("reverted to the previous model"))
            }
        }
    }

    /// Pulse strength for the next estimation (a fraction of full command, within the
    /// configured maximum): the operator's `estimate --power`.
    pub fn set_estimation_power(&mut self, power: f64) -> Result<(), Refused> {
        let max = self.setup.estimator.max_power;
        if !(power.is_finite() && power > 0.0 && power <= max) {
            return Err(Refused(format!("power {power} is not in (0, {max}]")));
        }
        self.setup.estimator.initial_power = power;
        Ok(())
    }

    /// A new attitude (body to NED) and optional depth to hold.
    pub fn on_setpoint(&mut self, attitude: UnitQuaternion<f64>, depth: Option<f64>) {
        self.target = Some(Target { attitude, depth });
    }

    /// An operator's setpoint in which some angles may be left out: those keep the value held
    /// now (the current target's, or, before any target, what control would hold: level at
    /// the current heading). Depth left out keeps the held depth, as angles do.
    pub fn on_setpoint_input(&mut self, s: &SetpointInput) {
        let held = match &self.target {
            Some(t) => t.attitude.euler_angles(),
            None => (0.0, 0.0, self.attitude.attitude().euler_angles().2),
        };
        let held = [held.0, held.1, held.2];
        let (r, p, y) = s.attitude.euler_angles();
        let want = [r, p, y];
        let pick = |i: usize| if s.keep[i] { held[i] } else { want[i] };
        let attitude = UnitQuaternion::from_euler_angles(pick(0), pick(1), pick(2));
        let depth = match s.depth {
            DepthInput::Keep => self.target.as_ref().and_then(|t| t.depth),
            DepthInput::Release => None,
            DepthInput::Hold(d) => Some(d),
        };
        self.on_setpoint(attitude, depth);
    }

    pub fn on_reconfig(&mut self, r: Reconfig) {
        let count = r.count.clamp(1, MAX_THRUSTERS);
        let count_changed = count != self.n;
        self.n = count;
        self.geometry = r.geometry.clone().filter(|g| g.positions.len() == count);
        let t = self.last_t_ns.unwrap_or(0);
        // The vehicle was changed, so handled: its rest must be taken after the change.
        self.idle_rest.clear();
        self.hold_lost_once = false;
        self.settling = None;
        // After an emergency stop a reconfiguration swaps models but drives no thruster.
        let mut estimate =
            self.setup.machine.on_reconfig == ReconfigPolicy::Estimate && !self.stopped;
        // Before any swap: what the learned model in force says about the unchanged rest.
        let prior = self.carry_over(r.change, count);
        if self.state.is_estimating() {
            self.run.stop();
        }
        match self.geometry.clone() {
            Some(g) => {
                let key = g.key();
                if let Some(cached) = self.models.cached(key) {
                    // Seen before: its learned model is back at once, no pulses needed.
                    if self.try_swap(cached, ModelSource::Cache).is_ok() {
                        estimate = false;
                    }
                } else {
                    let b = nominal_effectiveness(&self.setup.body, &g.positions, &g.directions);
                    let mut nominal = Model::nominal(b, Some(key));
                    nominal.made_t_ns = self.last_t_ns.unwrap_or(0);
                    let _ = self.try_swap(nominal, ModelSource::Nominal);
                }
            }
            None => {
                if count_changed {
                    self.models.drop_current();
                    self.events.push(Event::ModelDropped(format!(
                        "{}: now {count} thrusters and no declared geometry",
                        r.what
                    )));
                }
            }
        }
        if estimate {
            self.start_estimation_with(t, &format!("{}: re-estimating", r.what), prior);
        } else if self.models.current().is_some() && self.state != State::Fault {
            if self.state.is_estimating() || self.state == State::Active {
                self.transition(State::Active, &format!("{}: model swapped", r.what));
            }
        } else if self.state != State::Fault {
            self.transition(
                State::Idle,
                &format!("{}: no model, waiting for an estimate request", r.what),
            );
        }
    }
}
