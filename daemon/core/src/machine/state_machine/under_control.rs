//! Holding attitude with a model: control ticks with the refinement and the monitor watching,
//! identification under control after a change, and what a mismatch starts.

// The machine's fields and helpers are the parent's: these are its methods, by job.
use super::curve_named::CurveNamed;
use super::*;
use crate::adaptation::identification::fight::{self, PendingConfirmation};
use crate::adaptation::identification::AtLimit;

impl Machine {
    /// While controlling with closed-loop identification: the attitude error (deg) when it is
    /// beyond the identification's budget, where no dither would be applied and the run could
    /// not learn (an operator's request is refused then; an automatic start waits in Identify,
    /// its dither faded out, until the vehicle is back within the budget).
    pub(super) fn beyond_identification_budget(&self) -> Option<f64> {
        let controlling = self.state == State::Active && self.models.current().is_some();
        if !(controlling && EstimationRun::closed_loop_possible(&self.setup)) {
            return None;
        }
        let target = self.target?;
        let err_deg = self
            .attitude
            .attitude()
            .angle_to(&target.attitude)
            .to_degrees();
        (err_deg > self.setup.identification.attitude_budget_deg).then_some(err_deg)
    }

    /// Under control: the controller output with the dither on top, the estimator fed with
    /// the total command; at a stop the new model is swapped in without a bump (the target and
    /// the controller's state stay).
    pub(super) fn identify_tick(
        &mut self,
        s: &ImuInput,
        gyro: &Vector3<f64>,
        accel: &Vector3<f64>,
        dt: f64,
    ) -> Command {
        if self.models.current().is_none() {
            self.run.stop();
            self.transition(State::Idle, "no model to identify under: thrusters neutral");
            return Command::neutral(self.n);
        }
        let Some((mut cmd, meas, target)) = self.controller_command(s, gyro, dt, Mode::Estimating)
        else {
            return Command::neutral(self.n);
        };
        let attitude = meas.attitude;
        let Some(model) = self.models.current() else {
            return Command::neutral(self.n);
        };
        let n = self.n.min(model.thrusters());
        // The filter's attitude, which `measured` gave the controller.
        let m = self.motion(s, gyro, accel);
        let err_deg = attitude.angle_to(&target.attitude).to_degrees();
        let ident = &self.setup.identification;
        let instrument = ident.instrument.applies(
            self.sea_state.rms_deg(),
            ident.min_sea_state_deg,
            self.in_a_sea.get(),
        );
        let step = self.run.closed_loop_sample(
            s.t_ns,
            &m,
            &self.attitude.gyro_bias(),
            err_deg,
            &self.setup,
            Some(model),
            instrument,
            self.n,
            &mut cmd.thrust[..n],
        );
        finish(&mut cmd);
        if let Some(lost) = self.watch_hold(s.t_ns, &attitude, &target.attitude) {
            self.on_hold_lost(s.t_ns, lost);
            return Command::neutral(self.n);
        }
        match step {
            // The text stays the transition's (why the identification began) until the
            // first decision: a status reader must be able to see it.
            ClosedStep::Holding | ClosedStep::Exciting => {}
            ClosedStep::Decide { elapsed_s } => {
                let key = self.geometry_key();
                self.run
                    .submit_interval(s.t_ns, elapsed_s, &self.setup, key);
            }
        }
        cmd
    }

    /// A detector's alarm that its identification did not confirm (refused at the limit, or a
    /// model within its bounds of the one in force) is taken for the water moving the vehicle,
    /// unless the sea-state gauge reads calm: the detectors' calibrations then apply
    /// (`calibrate_when = "in_a_sea"`). Why: at the paper's noise a swell's first false alarms
    /// come before the gauge can read it through pitch steps, and each one re-estimated
    /// (docs/study.md, issue 32 item 5). A calm gauge leaves it as it was: the alarm was
    /// something else, and in still water the calibrations only cost.
    /// Returns whether the vehicle is now taken to be in a sea.
    fn alarm_not_confirmed(&mut self) -> bool {
        let gauge = self.sea_state.sea_reading_deg();
        if gauge.is_none_or(|d| d > self.setup.identification.min_sea_state_deg) {
            self.in_a_sea.assume();
        }
        self.in_a_sea.get()
    }

    /// The identification's model refused for `text` (the event and the status say it), the
    /// model in force kept, holding on.
    fn keep_old_model(&mut self, text: String) {
        self.events.push(Event::ModelRejected(text.clone()));
        self.follow_model_curve();
        self.transition(State::Active, &text);
    }

    pub(super) fn solve_under_control(&mut self, decision: StopDecision, result: SolveResult) {
        let key = self.geometry_key();
        let t_ns = self.last_t_ns.unwrap_or(0);
        let seconds = self.run.excited_s(t_ns);
        let share = self.run.excitation().map(|x| x.dither_share());
        // Which rows the dither's instrument decided (where it and least squares disagreed).
        let instrumented = result
            .estimate
            .dynamics
            .as_ref()
            .map_or([false; 2], |d| d.instrumented);
        let bound = (result.estimate.rel_err_rot, result.estimate.rel_err_acc);
        let curve = result
            .estimate
            .dynamics
            .as_ref()
            .and_then(|d| d.thrust_curve);
        // The thrusters' state the identification tracked: the refinement (and a
        // confirmation starting now) go on from it.
        let spin = self.run.spin_state().cloned();
        let prior = self.run.prior().cloned();
        // Where on a thrust curve the identification's line sits, and the lines the
        // refinement carried the model in force to (`widen_in_force_for_curve`): the deeper.
        let level = self
            .run
            .command_log_level()
            .into_iter()
            .chain(self.refiner.deepest_command_level())
            .reduce(f64::max);
        let Some((mut candidate, _)) = self.run.conclude(result) else {
            return;
        };
        self.stamp_curve(&mut candidate);
        if let Some(spin) = spin {
            self.refiner.adopt_spin_state(spin);
        }
        let confirming = std::mem::take(&mut self.confirming_fight);
        let mut why = match decision {
            StopDecision::Converged { rel_err_rot, rel_err_acc } => format!(
                "identified under control in {seconds:.1} s (error bound rot {rel_err_rot:.3}, acc {rel_err_acc:.3})"
            ),
            _ => format!("identification limit reached after {seconds:.1} s"),
        };
        let rows = match instrumented {
            [true, true] => Some(""),
            [true, false] => Some(" in the rotation rows"),
            [false, true] => Some(" in the acceleration rows"),
            [false, false] => None,
        };
        if let Some(rows) = rows {
            why.push_str(&format!(
                " with the dither as the thrust's instrument{rows} (the water moving the held vehicle)"
            ));
        }
        // The controller's answer to the water was most of what the thrusters did: the fit
        // takes it for thrust (issue 32: rough water, 57 % off under a 14 % bound). Only when
        // the water had moved the held vehicle (`sea_state`): a vehicle tumbling in still
        // water on a bad model leaves no room for dither either, and its fit is the model it
        // needs.
        // Instrumented too: the instrument keeps the controller's answer out of B, but with
        // the dither faded out the terms (their own instruments) still take the swell, and
        // in rough water (share 0.10) 7 of 10 instrumented models at a realistic IMU were up
        // to 2.3x outside their rotation bound (docs/study.md).
        let cfg = &self.setup.identification;
        let limit = cfg.min_dither_share;
        let low_share = share.filter(|s| *s < limit);
        let sea_up = (self.sea_state.rms_deg()).filter(|d| *d > cfg.min_sea_state_deg);
        if let (Some(share), Some(sea_deg)) = (low_share, sea_up) {
            let text = format!(
                "{why}: the dither was {:.0} % of the commands' variation (limit {:.0} %) with the water moving the held vehicle by {sea_deg:.1} deg RMS: the fit takes the controller's answer for thrust: model rejected; old model kept",
                100.0 * share,
                100.0 * limit
            );
            self.keep_old_model(text);
            return;
        }
        // The thrust does not follow the command linearly (a curve nobody configured): the
        // linear model holds only at the hold's amplitude (a T200 without its curve: 50 % off
        // under a 5 % bound; `identification.max_curve_evidence`). Learned, and identified
        // again on it (`learn_curve`), or refused.
        // Not on a fight's data (the dither under its share, still water): the commands there
        // answer the motion, and the curve they seem to follow is the controller's (amour5_top45
        // at a realistic IMU, seed 28: thrust ~ command^1.79 named on a share of 0.02, learned,
        // and the wait for a hold on the nominal model never ended: 40 deg off for 112 s). The
        // fight's model is confirmed once held, and that identification, with its dither,
        // judges the curve.
        let curve_limit = cfg.max_curve_evidence;
        // The probe bent the commands as they went out: through the curve in use.
        let in_use = self.supply.learned_exponent();
        let strong = curve
            .filter(|_| low_share.is_none())
            .filter(|c| curve_limit > 0.0 && c.log_likelihood_ratio > curve_limit);
        if let Some(c) = strong {
            let named = in_use.unwrap_or(1.0) * c.fitted_exponent;
            if self.learn_curve(&why, c) {
                // The model in force holds on until the identification on the curve is
                // swapped in (8-20 s): it is the same line through the pulses' amplitude, and
                // says so (`widen_in_force_for_curve`); kept at its own bound it claimed 2 %
                // where it was 8 % off through that wait.
                self.widen_in_force_for_curve(&candidate.effectiveness, named, level);
                return;
            }
            let exponent = in_use.unwrap_or(1.0) * c.exponent;
            let text = format!(
                "{why}: the thrust does not follow the command linearly (thrust ~ command^{exponent:.2} explains the data better, ln likelihood ratio {:.0}, limit {:.0}): configure the thrusters' curve ([supply] linearize for T200s, power_law_exponent for another make): model rejected; old model kept",
                c.log_likelihood_ratio, curve_limit
            );
            // The model in force is a line through its pulses' amplitude: what the hold's
            // line puts it off goes into its bound before the status says it is kept.
            let restated = self.widen_in_force_for_curve(&candidate.effectiveness, named, level);
            let text = match restated {
                Some([r, a]) => text.replace(
                    "old model kept",
                    &format!("old model kept, its bound widened to rot {r:.3}, acc {a:.3}"),
                ),
                None => text,
            };
            self.keep_old_model(text);
            self.curve_named = Some(CurveNamed::new(
                exponent,
                c.log_likelihood_ratio,
                t_ns as f64 * 1e-9,
            ));
            return;
        }
        // On a learned curve, the exponent's own error is in the model's (`curve_learned`).
        if let Some(scale) = self.learned_curve_scale(&candidate) {
            candidate.widen(scale);
        }
        // A suspected change (the change test's or the monitor's) the data could not pin down
        // within the limit is not confirmed: the model in force stays (see
        // `IdentificationConfig::at_limit_unannounced`).
        let cfg = &self.setup.identification;
        let at_limit = !matches!(decision, StopDecision::Converged { .. });
        if at_limit && self.identifying_unannounced && cfg.at_limit_unannounced == AtLimit::KeepOld
        {
            self.alarm_not_confirmed();
            let text = format!(
                "{why}: the suspected change is not confirmed (bound rot {:.3}, acc {:.3}, above the target): model rejected; old model kept",
                bound.0, bound.1
            );
            self.keep_old_model(text);
            return;
        }
        let found_nothing = self.identifying_unannounced
            && self.models.current().is_some_and(|old| {
                within_bounds(
                    &candidate.effectiveness,
                    &old.effectiveness,
                    [bound.0, bound.1],
                )
            });
        let water = if found_nothing && self.alarm_not_confirmed() {
            "; no change found: taken for the water"
        } else {
            ""
        };
        // Still water and little dither: the fit is the controller's fight against a model
        // that could not hold the vehicle (`identification::fight`). Its bound is widened to
        // what the dither alone supports, and a second identification starts once the new
        // model has held the vehicle (`confirm_when_held`). A confirmation that is a fight
        // again (the fight's model does not hold it either), or a fight's model refused, lets
        // go: thrusters neutral and an estimation from rest, which needs no model.
        let fight = low_share.map(|share| (share, fight::bound_scale(share)));
        if let Some((share, scale)) = fight {
            let fought = format!(
                "the dither was {:.0} % of the commands' variation (limit {:.0} %) in still water: the fit is the controller's fight",
                100.0 * share,
                100.0 * limit
            );
            if confirming {
                self.events.push(Event::ModelRejected(format!(
                    "{why}: {fought} again, on the model the first fight made"
                )));
                self.let_go_and_estimate(
                    t_ns,
                    format!("{fought} twice"),
                    "no model fitted under control holds it",
                );
                return;
            }
            candidate.widen([scale; 2]);
        }
        let (bound_rot, bound_acc) = (candidate.rel_err_rot, candidate.rel_err_acc);
        // The confidence gate judges a fight's fit by its own bound: the model in force
        // could not hold the vehicle, and the fight's model holds it through the
        // confirmation whatever its widened bound (amour5_top45: 0.36 reported against a
        // 0.25 gate at a realistic IMU; refused, the vehicle tumbled to the hold watch and was
        // re-estimated from rest, 23 s; swapped, the confirmation's model came at 12-14 s,
        // docs/study.md, "A model fitted on the controller's fight").
        // Otherwise: the data pulled the fit away from the columns the change left alone,
        // beyond both their errors, and its bound is widened by as much
        // (`widen_for_disagreement`). A fight's bound is widened by its share instead: its
        // data is the fight, and it is confirmed once held.
        let gate_scale = match fight {
            Some((_, k)) => k,
            None => {
                let (scale, text) = self.widen_for_disagreement(&mut candidate);
                why.push_str(text.as_deref().unwrap_or(""));
                scale
            }
        };
        let gate = self.setup.machine.max_swap_rel_err * gate_scale;
        match self.try_swap_within(candidate, ModelSource::Estimated, gate) {
            Ok(()) => {
                // A fight's model is not kept for its geometry: the confirmation's is.
                if let (Some(k), None) = (key, fight) {
                    self.models.remember_current(k);
                }
                let Some((share, _)) = fight else {
                    self.transition(
                        State::Active,
                        &format!("{why}: new model, holding attitude{water}"),
                    );
                    return;
                };
                self.transition(
                    State::Active,
                    &format!(
                        "{why}: new model, holding attitude, confirming once held; the dither was {:.0} % of the commands' variation: the controller's fight, bound widened to rot {bound_rot:.3}, acc {bound_acc:.3}",
                        100.0 * share
                    ),
                );
                self.pending_confirmation = Some(PendingConfirmation::new(prior));
            }
            Err(e) if fight.is_some() => self.let_go_and_estimate(
                t_ns,
                format!("{why}: the fight's model was refused ({e})"),
                "the model in force does not hold it",
            ),
            Err(e) => self.transition(
                State::Active,
                &format!("{why}: model rejected ({e}); old model kept"),
            ),
        }
    }

    /// What the controller sees of this sample, and the target it holds. Without a setpoint,
    /// hold level at the current heading and depth: a vehicle may enter Active still swinging
    /// from the last pulse, and that tilt is nothing to keep.
    pub(super) fn measured_and_target(
        &mut self,
        s: &ImuInput,
        gyro: &Vector3<f64>,
    ) -> (Measured, Target) {
        let meas = self.measured(s, gyro);
        let heading = meas.attitude.euler_angles().2;
        let target = *self.target.get_or_insert_with(|| Target {
            attitude: UnitQuaternion::from_euler_angles(0.0, 0.0, heading),
            depth: s.depth,
        });
        (meas, target)
    }

    /// The controller's command for this sample toward the target (held level at the current
    /// heading and depth when none was set), in `mode`, before anything is added to it; what
    /// the controller saw and held. None without a model.
    fn controller_command(
        &mut self,
        s: &ImuInput,
        gyro: &Vector3<f64>,
        dt: f64,
        mode: Mode,
    ) -> Option<(Command, Measured, Target)> {
        // Without a model nothing is held: no target is taken either.
        self.models.current()?;
        let (meas, target) = self.measured_and_target(s, gyro);
        let model = self.models.current()?;
        let mut cmd = Command::neutral(self.n);
        cmd.mode = mode;
        let n = self.n.min(model.thrusters());
        self.last_desired = self
            .controller
            .update(&meas, &target, model, dt, &mut cmd.thrust[..n]);
        Some((cmd, meas, target))
    }

    pub(super) fn control_tick(&mut self, s: &ImuInput, gyro: &Vector3<f64>, dt: f64) -> Command {
        let Some((mut cmd, meas, target)) = self.controller_command(s, gyro, dt, Mode::Controlling)
        else {
            return Command::neutral(self.n);
        };
        let attitude = meas.attitude;
        let Some(model) = self.models.current() else {
            return Command::neutral(self.n);
        };
        let n = self.n.min(model.thrusters());
        let err_rad = attitude.angle_to(&target.attitude);
        // The water as the controller meets it: the error on the axes the model actuates only
        // (four_up, yaw and sway unactuated, read 3.8-4.1 deg held level in still water on the
        // whole angle, above `identification.min_sea_state_deg`).
        self.sea_state.push(
            s.t_ns,
            self.hold_start_ns,
            dt,
            &target.attitude,
            actuated_error_deg(&attitude, &target.attitude, model.actuated),
        );
        let in_a_sea = self.in_a_sea.update(
            s.t_ns,
            self.sea_state.sea_reading_deg(),
            self.setup.identification.min_sea_state_deg,
        );
        self.refiner.set_in_a_sea(in_a_sea);
        self.monitor.set_in_a_sea(in_a_sea);
        let verdict = self.refiner.observe(
            &Tick {
                t_ns: s.t_ns,
                gyro,
                gyro_bias: &self.attitude.gyro_bias(),
                attitude: &attitude,
                specific_force: &Vector3::from(s.accel),
                depth: s.depth,
                err_deg: err_rad.to_degrees(),
                setpoint: &target.attitude,
            },
            model,
            self.run.levels(),
            &self.setup.estimator,
            &mut cmd.thrust[..n],
        );
        // The monitor compares in model units: the command sent (dither included) before
        // deadband compensation.
        let gravity_body = attitude.inverse() * Vector3::z();
        let mismatch = self.monitor.observe(
            dt,
            err_rad,
            &meas.rate,
            &gravity_body,
            &model.effectiveness,
            &cmd.thrust[..n],
        );
        finish(&mut cmd);
        if let Some(lost) = self.watch_hold(s.t_ns, &attitude, &target.attitude) {
            self.on_hold_lost(s.t_ns, lost);
            return Command::neutral(self.n);
        }
        if self.confirm_when_held(s.t_ns, &attitude, &target.attitude) {
            return cmd;
        }
        if self.identify_when_curve_held(s.t_ns, &attitude, &target.attitude) {
            return cmd;
        }
        let judged = self.refiner.take_judged();
        if let Some(m) = mismatch {
            self.on_mismatch(s.t_ns, m.to_string(), ThrusterChange::Unknown);
        } else if let Some(v) = verdict.filter(|v| v.changed) {
            self.on_mismatch(s.t_ns, v.to_string(), ThrusterChange::Moved(v.thruster));
        } else if let Some(fused) = self.refiner.take_refined() {
            self.install_refined(fused.model);
        } else if judged {
            // A window judged against the model in force and not folded into it.
            self.restate_for_gain_gap();
        }
        cmd
    }

    /// A fight's model in force (`identification::fight`): once it has held the vehicle
    /// within the identification's attitude budget, its confirmation starts. Returns whether
    /// it started.
    fn confirm_when_held(
        &mut self,
        t_ns: u64,
        attitude: &UnitQuaternion<f64>,
        target: &UnitQuaternion<f64>,
    ) -> bool {
        let (Some(pending), Some(model)) =
            (self.pending_confirmation.as_mut(), self.models.current())
        else {
            return false;
        };
        let budget = self.setup.identification.attitude_budget_deg;
        let err_deg = actuated_error_deg(attitude, target, model.actuated);
        if !pending.held(t_ns, err_deg, budget) {
            if pending.waited_too_long(t_ns) {
                // `let_go_and_estimate` ends the wait (it leaves Active).
                self.let_go_and_estimate(
                    t_ns,
                    format!(
                        "the fight's model did not hold the vehicle within {} deg in {:.0} s",
                        budget,
                        fight::MAX_WAIT_FOR_HOLD_S
                    ),
                    "no model fitted under control holds it",
                );
                return true;
            }
            return false;
        }
        let prior = pending.prior.take();
        // The fight's: nothing starts an estimation while the confirmation waits (any start
        // leaves Active, which ends the wait), so it is still the fight's run's.
        let unannounced = self.identifying_unannounced;
        self.start_estimation_with(
            t_ns,
            "confirming a model fitted on the controller's fight",
            prior,
        );
        self.identifying_unannounced = unannounced;
        self.confirming_fight = self.state == State::Identify;
        true
    }

    /// This control sample's error on the axes the model actuates, into the hold watch.
    fn watch_hold(
        &mut self,
        t_ns: u64,
        attitude: &UnitQuaternion<f64>,
        target: &UnitQuaternion<f64>,
    ) -> Option<HoldLost> {
        let actuated = self.models.current()?.actuated;
        let m = &self.setup.machine;
        let err_deg = actuated_error_deg(attitude, target, actuated);
        let lost = self
            .hold_watch
            .observe(t_ns, err_deg, m.lost_hold_deg, m.lost_hold_s);
        if self.hold_lost_once && self.hold_watch.held_for_s(t_ns) >= HELD_CLEARS_S {
            // The model learned after the loss held the vehicle: a later loss is news.
            self.hold_lost_once = false;
        }
        lost
    }

    /// The model in force does not hold the vehicle (`hold_watch`): thrusters neutral, so the
    /// vehicle rights itself on its restoring moment, then an estimation from rest, which
    /// needs no model (the identification under control does: it dithers on top of it).
    /// Lost again before an operator's estimate or hold, or a reconfiguration, or with the
    /// monitor told not to re-estimate on its own: neutral, idle.
    fn on_hold_lost(&mut self, t_ns: u64, lost: HoldLost) {
        let off = format!(
            "{:.0} deg off the setpoint on average over {:.0} s, machine.lost_hold_deg {:.0}",
            lost.err_deg, lost.for_s, self.setup.machine.lost_hold_deg
        );
        self.let_go_and_estimate(
            t_ns,
            off,
            "the model in force does not hold it (a thruster declared reversed, \
             misplaced or turned?)",
        );
    }

    /// The vehicle is not held, as `off` measured and for `cause`: see `on_hold_lost`.
    pub(super) fn let_go_and_estimate(&mut self, t_ns: u64, off: String, cause: &str) {
        self.run.stop();
        self.controller.reset();
        self.hold_watch.reset();
        // The status text is cut at the protocol's 128 bytes: what the daemon does comes
        // first, why after; the journal's event has it all.
        self.events
            .push(Event::HoldLost(format!("hold lost: {off}: {cause}")));
        self.phase_start_ns = t_ns;
        self.hold_start_ns = t_ns;
        let estimate = self.monitor.action() == MismatchAction::Estimate;
        if self.hold_lost_once || !estimate {
            let (what, why) = if self.hold_lost_once {
                ("hold lost again", "")
            } else {
                ("hold lost", "monitor.action is not \"estimate\"; ")
            };
            self.transition(
                State::Idle,
                &format!(
                    "{what}: thrusters neutral until an estimate or hold request ({why}{off}: {cause})"
                ),
            );
            return;
        }
        self.hold_lost_once = true;
        self.transition(
            State::Idle,
            &format!(
                "hold lost: thrusters neutral, estimating from rest once the vehicle settles ({off}: {cause})"
            ),
        );
        self.settling = Some(Settling::new(t_ns));
    }

    /// Idle after a lost hold, thrusters neutral: the estimation from rest starts once the
    /// vehicle has settled (`hold_watch::Settling`).
    pub(super) fn await_settled(&mut self, t_ns: u64) {
        let attitude = self.attitude.attitude();
        let Some(waited_s) = self
            .settling
            .as_mut()
            .and_then(|s| s.observe(t_ns, &attitude))
        else {
            return;
        };
        self.settling = None;
        let why =
            format!("hold lost; the vehicle settled with the thrusters neutral in {waited_s:.1} s");
        self.start_estimation(t_ns, &why);
    }

    /// The monitor (or the refinement, which names the thruster: `change`) found the
    /// thrusters doing something else than the model says.
    pub(super) fn on_mismatch(&mut self, t_ns: u64, why: String, change: ThrusterChange) {
        self.refiner.reset();
        self.monitor.reset(self.n);
        // A curve just learned: the model in force is per unit of the commands before it,
        // and the identification on the new ones starts once the vehicle is held.
        if self.curve_pending.is_some() {
            return;
        }
        // The curve an identification named explains it: identified again, it would be
        // refused again (`curve_named`). The journal hears of the first mismatch after it,
        // saying why; the status counts the rest (one every 7-8 s while the curve is not
        // configured).
        let estimate = self.monitor.action() == MismatchAction::Estimate;
        if let Some(c) = self.curve_named.as_mut().filter(|_| estimate) {
            let said = c.mismatch(&why);
            if let Some(journal) = said.journal {
                self.events.push(Event::MismatchDetected(journal));
            }
            self.text = said.status;
            return;
        }
        self.events.push(Event::MismatchDetected(why.clone()));
        if estimate {
            let prior = self.carry_over(change, self.n);
            self.start_estimation_with(t_ns, &format!("{why}: re-estimating"), prior);
            // Set after the start, which clears it for every other cause.
            self.identifying_unannounced = true;
        } else {
            self.text = format!("holding attitude; {why}");
        }
    }
}

/// Whether `new` differs from `old` on each row group (rotation rows 0-2, acceleration rows
/// 3-5) by at most `UNCONFIRMED_BOUNDS` times that group's error bound (relative Frobenius,
/// as the bounds are). Differently shaped models (a thruster added or removed) differ.
fn within_bounds(
    new: &nalgebra::DMatrix<f64>,
    old: &nalgebra::DMatrix<f64>,
    bound: [f64; 2],
) -> bool {
    use crate::adaptation::identification::sea_state::UNCONFIRMED_BOUNDS;
    use crate::estimator::linalg::rel_frobenius_err_per_row_group;
    // A NaN bound (none) or an infinite error (another shape, or the old group all zero and
    // the new not) compares false.
    rel_frobenius_err_per_row_group(new, old)
        .iter()
        .zip(bound)
        .all(|(e, b)| *e <= UNCONFIRMED_BOUNDS * b)
}

#[cfg(test)]
mod tests {
    use super::within_bounds;
    use nalgebra::DMatrix;

    /// AMOUR-5-like: five columns of unit size.
    fn b() -> DMatrix<f64> {
        DMatrix::from_fn(6, 5, |r, c| if (r + c) % 3 == 0 { 1.0 } else { 0.2 })
    }

    #[test]
    fn a_model_within_its_bounds_of_the_old_found_nothing_a_moved_column_did() {
        let old = b();
        let norm_rot = old.rows(0, 3).norm();
        // Rotation rows moved by 1.4x a 4 % bound, the acceleration rows not at all: nothing.
        let mut new = old.clone();
        new[(0, 0)] += 1.4 * 0.04 * norm_rot;
        assert!(within_bounds(&new, &old, [0.04, 0.06]));
        // 1.6x: found.
        let mut new = old.clone();
        new[(0, 0)] += 1.6 * 0.04 * norm_rot;
        assert!(!within_bounds(&new, &old, [0.04, 0.06]));
        // A thruster's column turned 45 deg in the rotation rows: far beyond.
        let mut new = old.clone();
        let (a, c) = (old[(0, 2)], old[(1, 2)]);
        let (s, k) = std::f64::consts::FRAC_PI_4.sin_cos();
        new[(0, 2)] = k * a - s * c;
        new[(1, 2)] = s * a + k * c;
        assert!(!within_bounds(&new, &old, [0.06, 0.06]));
        // Another shape (a thruster added), or a bound not known: not "the same".
        let wider = DMatrix::from_fn(6, 6, |r, c| if c < 5 { old[(r, c)] } else { 0.1 });
        assert!(!within_bounds(&wider, &old, [0.06, 0.06]));
        assert!(!within_bounds(&old, &old, [f64::NAN, 0.06]));
    }
}
