//! The estimation with the thrusters free: levelling, the noise at rest, pulses and settles,
//! the solves and the model they conclude in.

// The machine's fields and helpers are the parent's: these are its methods, by job.
use super::*;

impl Machine {
    /// What an estimation after `change` (now `count` thrusters) keeps from the model in force.
    pub(super) fn carry_over(&self, change: ThrusterChange, count: usize) -> Option<DynamicPrior> {
        let cfg = &self.setup.identification;
        if !cfg.carry_over {
            return None;
        }
        carried_over(
            self.models.current()?,
            change,
            count,
            cfg.carry_over_se_scale,
        )
    }

    pub(super) fn start_estimation(&mut self, t_ns: u64, why: &str) {
        self.start_estimation_with(t_ns, why, None);
    }

    /// An estimation starts, keeping `prior` (see `identification::carry_over`).
    pub(super) fn start_estimation_with(
        &mut self,
        t_ns: u64,
        why: &str,
        prior: Option<DynamicPrior>,
    ) {
        let kept = if prior.is_some() {
            "; the other thrusters' columns are kept"
        } else {
            ""
        };
        let why = &format!("{why}{kept}");
        self.identifying_unannounced = false;
        // A new estimation judges the thrusters afresh (a curve configured since, or another
        // vehicle): a curve it names is remembered again.
        self.curve_named = None;
        self.last_t_ns = self.last_t_ns.or(Some(t_ns));
        // Controlling with a model: identify under control (see `crate::adaptation::identification`).
        let controlling =
            matches!(self.state, State::Active | State::Identify) || self.levelling.is_some();
        if controlling
            && self.models.current().is_some()
            && EstimationRun::closed_loop_possible(&self.setup)
        {
            self.levelling = None;
            // The thrusters' state the refinement tracked while holding: the fit's lags
            // start from it even when the hold before the dither is short.
            let spin = self.refiner.spin_state().clone();
            let curve_learned = self.supply.learned_exponent().is_some();
            self.run.begin_closed_loop(
                t_ns,
                &self.setup.identification,
                self.n,
                spin,
                curve_learned,
            );
            self.run.carry(prior, &self.setup.identification);
            self.transition(
                State::Identify,
                &format!("{why}: identifying under control"),
            );
            return;
        }
        self.run.restart();
        self.run.carry(prior, &self.setup.identification);
        // From idle, the rest the vehicle has just taken is the noise measurement, or its
        // first part (`machine.rest_from_idle`).
        if self.state == State::Idle && self.setup.machine.rest_from_idle {
            let now = self.last_t_ns.unwrap_or(t_ns);
            if let Some(taken) = self.idle_rest.take(
                now,
                self.setup.machine.noise_s,
                self.setup.machine.gyro_bias_rest_s,
                MIN_REST_SAMPLES,
            ) {
                self.run.adopt_rest(taken);
            }
        }
        // Controlling with a model: level the vehicle first (see MachineConfig::level_max_s).
        // A reconfiguration while levelling levels on (the vehicle is no more at rest).
        self.levelling = ((self.state == State::Active || self.levelling.is_some())
            && self.models.current().is_some()
            && self.setup.machine.level_max_s > 0.0)
            .then(|| Levelling {
                target: Target {
                    attitude: UnitQuaternion::from_euler_angles(
                        0.0,
                        0.0,
                        self.attitude.attitude().euler_angles().2,
                    ),
                    depth: self.target.and_then(|t| t.depth),
                },
                level_since_ns: None,
            });
        let then = if self.levelling.is_some() {
            "levelling, then measuring noise at rest"
        } else {
            "measuring noise at rest"
        };
        self.transition(State::MeasureNoise, &format!("{why}: {then}"));
    }

    /// Levelling before the noise measurement: the controller holds level at the heading the
    /// estimation started with (no monitor: the model is about to be replaced). Ends, thrusters
    /// neutral and the noise clock restarted, once level for `level_hold_s` or after
    /// `level_max_s` whatever the tilt.
    pub(super) fn level_tick(&mut self, s: &ImuInput, gyro: &Vector3<f64>, dt: f64) -> Command {
        let elapsed = self.elapsed_s(s.t_ns);
        let meas = self.measured(s, gyro);
        let (Some(model), Some(lev)) = (self.models.current(), self.levelling.as_mut()) else {
            self.levelling = None;
            return Command::neutral(self.n);
        };
        let up = meas.attitude * Vector3::z();
        let tilt_deg = up.z.clamp(-1.0, 1.0).acos().to_degrees();
        let m = &self.setup.machine;
        if tilt_deg <= m.level_tilt_deg {
            lev.level_since_ns.get_or_insert(s.t_ns);
        } else {
            lev.level_since_ns = None;
        }
        let level_for = lev
            .level_since_ns
            .map_or(0.0, |t| s.t_ns.saturating_sub(t) as f64 * 1e-9);
        if level_for >= m.level_hold_s || elapsed >= m.level_max_s {
            self.levelling = None;
            self.controller.reset();
            self.phase_start_ns = s.t_ns;
            self.text = if level_for >= m.level_hold_s {
                "level: measuring noise at rest".to_string()
            } else {
                format!("still {tilt_deg:.0} deg tilted after levelling: measuring noise")
            };
            return Command::neutral(self.n);
        }
        let mut cmd = Command::neutral(self.n);
        cmd.mode = Mode::Controlling;
        let n = self.n.min(model.thrusters());
        let target = lev.target;
        self.last_desired = self
            .controller
            .update(&meas, &target, model, dt, &mut cmd.thrust[..n]);
        finish(&mut cmd);
        cmd
    }

    pub(super) fn start_pulse(&mut self, t_ns: u64) -> Command {
        let mut cmd = Command::neutral(self.n);
        cmd.mode = Mode::Estimating;
        // What the thrusters give with the pack sagging under all of them, once the readings
        // have shown its sag (the cap at the rest's end knew only the resting voltage).
        let power_cap = (self.supply.state() == thruster_protocol::SupplyCompensation::Active)
            .then(|| {
                let db = self.setup.machine.deadband.clamp(0.0, 0.5);
                ((self.supply.attainable_loaded(self.n) - db) / (1.0 - db)).clamp(0.0, 1.0)
            });
        if let Some(k) = self.run.begin_pulse(t_ns, power_cap, &mut cmd.thrust) {
            // The first pulse is the estimation's news; the ones after a settle are phases.
            let first = !matches!(self.state, State::Pulse | State::Settle);
            let news = first.then(|| self.first_pulse_news());
            self.enter(
                State::Pulse,
                Some(t_ns),
                format!("pulse {k}"),
                news.as_deref(),
            );
        }
        finish(&mut cmd);
        cmd
    }

    /// The estimation's news at its first pulse: the noise measured, how often the rest
    /// started over, and what the long idle rest read of the water
    /// (`navigation::long_rest_sway`: the operator's word for why the fit holds the velocity
    /// terms or fits a drift). Made only for the first pulse, not on every one.
    fn first_pulse_news(&self) -> String {
        let mut news = match self.run.rest_restarts() {
            0 => "noise measured: pulsing".to_string(),
            r => format!(
                "noise measured: pulsing (the rest started over {r} time{}: the accelerometer saw the vehicle pushed, not turned)",
                if r == 1 { "" } else { "s" }
            ),
        };
        let swung = self.run.swing_restarts();
        if swung > 0 {
            // The rest waited for the swing the thrusters' last push left (about a second a
            // time: `machine.max_rest_swing_radps`).
            news.push_str(&format!(
                "; the rest waited {swung} time{} for the vehicle to stop swinging",
                if swung == 1 { "" } else { "s" }
            ));
        }
        let water = self.run.idle_water(self.setup.machine.max_still_sway);
        if let (Some(sway), Some(water)) = (self.run.idle_sway(), water) {
            news.push_str(&format!(
                "; the long rest: {} (sway {sway:.1}x the IMU's noise)",
                water.text()
            ));
        }
        news
    }

    pub(super) fn pulse_tick(
        &mut self,
        s: &ImuInput,
        gyro: &Vector3<f64>,
        accel: &Vector3<f64>,
    ) -> Command {
        let elapsed = self.elapsed_s(s.t_ns);
        let m = self.motion(s, gyro, accel);
        let mut cmd = Command::neutral(self.n);
        cmd.mode = Mode::Estimating;
        let step = self.run.pulse_sample(
            s.t_ns,
            elapsed,
            &m,
            self.setup.machine.pulse_s,
            &mut cmd.thrust,
        );
        match step {
            PulseStep::NoRun => {
                self.transition(State::Idle, "internal: pulse without an estimator");
            }
            PulseStep::Pulsing => {
                finish(&mut cmd);
                return cmd;
            }
            PulseStep::Ended {
                gate: Some(d),
                pulses,
            } if d.is_stop() => {
                // A limit: the run's model is solved while the thrusters rest.
                self.run
                    .submit_pulse(s.t_ns, Purpose::Conclude, self.geometry_key());
                self.next_phase(
                    State::Solve,
                    s.t_ns,
                    format!("solving the model of {pulses} pulses"),
                );
            }
            PulseStep::Ended { gate, .. } if self.run.back_to_back() => {
                // Back to back the excitation goes on while the decision is out, as it did
                // when the decision was made on this sample: a stop applied at its due sample
                // ends the next pulse early and swaps in the model of the data up to here, the
                // same model as then (a rest at neutral instead changed every later pulse's
                // excitation, and with it every model learned after the first stop point).
                let purpose = if gate.is_some() {
                    Purpose::Progress
                } else {
                    Purpose::Decide
                };
                self.run.submit_pulse(s.t_ns, purpose, self.geometry_key());
                return self.start_pulse(s.t_ns);
            }
            PulseStep::Ended { gate, pulses } => {
                let purpose = if gate.is_some() {
                    Purpose::Progress
                } else {
                    // The bound decides: the pause after the pulse (longer than the solve's
                    // budget by default) does not end before the decision is applied.
                    Purpose::Decide
                };
                self.run.submit_pulse(s.t_ns, purpose, self.geometry_key());
                self.next_phase(
                    State::Settle,
                    s.t_ns,
                    format!("settling after pulse {pulses}"),
                );
            }
        }
        Command::neutral(self.n)
    }

    pub(super) fn geometry_key(&self) -> Option<u64> {
        self.geometry.as_ref().map(|g| g.key())
    }

    /// A solve's result at its due sample (see `crate::solve`). The queue is emptied when
    /// a run stops, so every result applied belongs to the run under way.
    pub(super) fn apply_solve(&mut self, purpose: Purpose, result: SolveResult) {
        let decision = result.decision;
        self.run.hint_lag(&result.estimate);
        match purpose {
            Purpose::Progress => self.run.keep_estimate(result.estimate),
            Purpose::Decide | Purpose::Conclude if decision.is_stop() => {
                self.solve(decision, result)
            }
            Purpose::Decide => self.run.keep_estimate(result.estimate),
            Purpose::Conclude => {
                // A limit that is no stop cannot come from the estimator; never leave the
                // run stuck in Solve.
                self.run.stop();
                self.transition(State::Idle, "internal: a concluding solve did not stop");
            }
            Purpose::Interval if decision.is_stop() => self.solve_under_control(decision, result),
            // The refinement's own (see `Refiner::observe`); never the run's.
            Purpose::Window => {}
            Purpose::Interval => {
                self.run
                    .remember_interval(&result.estimate, result.elapsed_s);
                self.run.keep_estimate(result.estimate);
                let t = self.last_t_ns.unwrap_or(0);
                let excited = self.run.excited_s(t);
                self.text = format!("identifying under control: {excited:.0} s of dither");
            }
        }
    }

    pub(super) fn settle_tick(
        &mut self,
        s: &ImuInput,
        gyro: &Vector3<f64>,
        accel: &Vector3<f64>,
    ) -> Command {
        let elapsed = self.elapsed_s(s.t_ns);
        let m = self.motion(s, gyro, accel);
        let k = self.setup.estimator.k_sigma;
        let Some(quiet_for) = self.run.settle_sample(s.t_ns, &m, k) else {
            return Command::neutral(self.n);
        };
        if self.run.waiting_for(Purpose::Decide) {
            // The stop decision is out: the pause goes on at neutral (the samples feed the
            // fit) until it is applied.
            return Command::neutral(self.n);
        }
        let m = &self.setup.machine;
        if (elapsed >= m.settle_min_s && quiet_for >= m.settle_quiet_s) || elapsed >= m.settle_max_s
        {
            return self.start_pulse(s.t_ns);
        }
        Command::neutral(self.n)
    }

    pub(super) fn solve(&mut self, decision: StopDecision, result: SolveResult) {
        // Solve until this call's transition says what came of it (its event is from Solve).
        let t = self.last_t_ns.unwrap_or(self.phase_start_ns);
        self.next_phase(State::Solve, t, "concluding the estimation".into());
        let key = self.geometry_key();
        let Some((mut candidate, pulses)) = self.run.conclude(result) else {
            self.transition(State::Idle, "internal: a stopping solve made no model");
            return;
        };
        // A curve the estimate learned from its own two levels (`estimator.second_amplitude`):
        // refused where the identification's would be (`learn_curve`): learning off, or the
        // thrusters taken for T200s with their curve kept, whose curve is the table's.
        let own_curve = candidate
            .dynamics
            .as_ref()
            .and_then(|d| d.command_exponent.zip(d.thrust_curve));
        if let Some((p, c)) = own_curve {
            if !self.setup.identification.learn_thrust_curve || self.supply.takes_t200_curve() {
                // Within the status's 128 bytes (a 5-digit ratio: 125), the advice included.
                let text = format!(
                    "thrust ~ command^{p:.2}, not linear (lnLR {:.0}): model rejected, old kept; set [supply] linearize (T200) or power_law_exponent",
                    c.log_likelihood_ratio
                );
                self.events.push(Event::ModelRejected(text.clone()));
                self.transition(self.after_refusal(), &text);
                return;
            }
        }
        self.stamp_curve(&mut candidate);
        let why = match decision {
            // The model's bound, not the decision's: the solve job added the navigation's
            // errors to it after deciding (`Estimator::count_navigation_error`), and says so.
            StopDecision::Converged { .. } => {
                let navigation = candidate.navigation_rel_err()[1];
                let (rot, acc) = (candidate.rel_err_rot, candidate.rel_err_acc);
                // The fit found the vehicle moving through the water at the start (a tow,
                // `Estimator::search_start_velocity`): said, since no sensor showed it.
                let towed = candidate
                    .dynamics
                    .as_ref()
                    .and_then(|d| d.start_velocity_ned_mps)
                    .map(|v| v[0].hypot(v[1]));
                // The stopping job took the dead-reckoned velocity's drift out
                // (`Estimator::search_velocity_drift`): said, since it moved the model.
                let drift = candidate
                    .dynamics
                    .as_ref()
                    .and_then(|d| d.velocity_drift_ned_mps2)
                    .map(|r| r[0].hypot(r[1]));
                if let Some(speed) = towed {
                    format!("converged after {pulses} pulses (error bound rot {rot:.3}, acc {acc:.3}), moving {speed:.2} m/s at the start")
                } else if let Some(rate) = drift {
                    format!("converged after {pulses} pulses (error bound rot {rot:.3}, acc {acc:.3}), velocity drift {rate:.4} m/s^2 taken out")
                } else if navigation > 0.0 {
                    format!("converged after {pulses} pulses (error bound rot {rot:.3}, acc {acc:.3} with navigation {navigation:.3})")
                } else {
                    format!(
                        "converged after {pulses} pulses (error bound rot {rot:.3}, acc {acc:.3})"
                    )
                }
            }
            StopDecision::PlanComplete => format!("planned {pulses} pulses done"),
            StopDecision::MaxPulses => format!("pulse limit {pulses} reached"),
            StopDecision::Continue => "stopped".into(),
        };
        // The status text holds 128 bytes: the IMU's position leads, the bound is in the
        // rejection event and the model's dynamics.
        let imu_note = match candidate.dynamics.as_ref().and_then(|d| d.imu_position) {
            Some(p) if p.contradicted => Some(format!(
                "IMU found at {} m, not as configured (estimator.imu_position_m)",
                fmt_xyz(&p.position_m)
            )),
            _ => None,
        };
        let why = match &imu_note {
            Some(note) => format!("{why}; {note}"),
            None => why,
        };
        // Rotation that neither thrust nor the vehicle's own dynamics explain (a swell, a
        // tether): the fit absorbed it somewhere, and its bound does not know it.
        let (unexplained, tilt_deg) = candidate.dynamics.as_ref().map_or((0.0, 0.0), |d| {
            (d.unexplained_rate_radps, d.max_tilt_rad.to_degrees())
        });
        let limit = self.setup.machine.max_unexplained_rate_radps;
        if unexplained > limit {
            let text = format!(
                "{unexplained:.3} rad/s of rotation unexplained (limit {limit:.3}; water?), tilted {tilt_deg:.0} deg: model rejected; old model kept"
            );
            self.events.push(Event::ModelRejected(text.clone()));
            self.transition(self.after_refusal(), &text);
            return;
        }
        // In moving water, a lag the two row groups each alone put far apart (a swell's
        // moment and force pull it differently): the lag is off by about that gap, the model
        // with it, and its bound does not know it (estimator::dynamic::lag_agreement). Not
        // in still water, where the groups of vehicles with slow or mixed lags are up to 7 sd
        // apart on good models.
        let gap_limit = self.setup.machine.max_lag_gap_over_bound;
        // Fitted again with the swell's states, the fit without them says it
        // (`lag_gap_without_states`).
        let (gap, without_states) =
            candidate
                .dynamics
                .as_ref()
                .map_or((0.0, false), |d| match d.lag_gap_without_states {
                    Some(g) => (g, true),
                    None => (
                        crate::estimator::dynamic::lag_agreement::gap_over_bound(
                            d,
                            [candidate.rel_err_rot, candidate.rel_err_acc],
                        ),
                        false,
                    ),
                });
        if gap_limit > 0.0
            && unexplained > crate::estimator::STILL_WATER_UNEXPLAINED_RADPS
            && gap > gap_limit
        {
            let groups = candidate.dynamics.as_ref().and_then(|d| d.spin_up_groups);
            let (apart, z) = groups.map_or((0.0, 0.0), |g| (g.gap_ln() * 100.0, g.z));
            // Within the status's 128 bytes, "model rejected" included (the operator's tools
            // look for it).
            let text = if !without_states {
                format!(
                    "row groups put the lag {apart:.0} % apart ({z:.1} sd), {gap:.1}x B's bound (limit {gap_limit:.1}; water?): model rejected; old model kept"
                )
            } else {
                format!(
                    "row groups put the lag apart without swell states, {gap:.1}x B's bound (limit {gap_limit:.1}; water?): model rejected; old model kept"
                )
            };
            self.events.push(Event::ModelRejected(text.clone()));
            self.transition(self.after_refusal(), &text);
            return;
        }
        // In moving water, a vehicle tilted beyond what the pulses do in still water: the
        // water threw it, and the acceleration rows rest on a velocity dead-reckoned through
        // that (machine.max_moving_water_tilt_deg). The tilt is the navigation's: where its
        // attitude went astray in a swell (118 deg against a true 30) the fit's regressors
        // did too. After the lag's check, which names a more particular cause.
        let tilt_limit = self.setup.machine.max_moving_water_tilt_deg;
        if tilt_limit > 0.0
            && unexplained > crate::estimator::STILL_WATER_UNEXPLAINED_RADPS
            && tilt_deg > tilt_limit
        {
            let text = format!(
                "tilted {tilt_deg:.0} deg in moving water (limit {tilt_limit:.0}; {unexplained:.3} rad/s unexplained): model rejected; old model kept"
            );
            self.events.push(Event::ModelRejected(text.clone()));
            self.transition(self.after_refusal(), &text);
            return;
        }
        // A lag configured because the gyro is too noisy to learn it, which the data
        // contradicts: the model is as wrong as the lag (AMOUR-5 at 0.05 s: 95-109 % off) and
        // its bound does not know it (estimator::dynamic::lag_check).
        let lag_reason = candidate
            .dynamics
            .as_ref()
            .and_then(|d| d.lag_check)
            .and_then(|c| c.reason());
        if let Some(reason) = lag_reason {
            let text = format!("{reason}: model rejected; old model kept");
            self.events.push(Event::ModelRejected(text.clone()));
            self.transition(self.after_refusal(), &text);
            return;
        }
        // A prior carried over from the model in force that the data moved beyond its errors
        // (`widen_for_disagreement`).
        let (gate_scale, widened) = self.widen_for_disagreement(&mut candidate);
        let why = why + widened.as_deref().unwrap_or("");
        let gate = self.setup.machine.max_swap_rel_err * gate_scale;
        match self.try_swap_within(candidate, ModelSource::Estimated, gate) {
            Ok(()) => {
                if let Some(k) = key {
                    self.models.remember_current(k);
                }
                if self.setup.machine.control_after_estimate {
                    self.target = None;
                    self.controller.reset();
                    self.transition(
                        State::Active,
                        &format!("{why}: new model, holding attitude"),
                    );
                    // A burst that already reached the target needs no refining.
                    let coarse = self.models.current().is_some_and(|m| {
                        let e = &self.setup.estimator;
                        m.rel_err_rot > e.target_rel_err || m.rel_err_acc > e.acc_target()
                    });
                    if self.run.was_burst() && coarse {
                        let t = self.last_t_ns.unwrap_or(0);
                        self.start_estimation(t, &format!("{why}: burst model in"));
                    }
                } else {
                    self.transition(State::Idle, &format!("{why}: new model"));
                }
            }
            Err(e) => {
                let next = self.after_refusal();
                let text = match &imu_note {
                    Some(note) => format!("{note}: model rejected; old model kept"),
                    None => format!("{why}: model rejected ({e}); old model kept"),
                };
                self.transition(next, &text);
            }
        }
    }
}
