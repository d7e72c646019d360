//! Putting a model in force: every swap (learned, refined, loaded) is checked and announced
//! here, and a refused one says where it leaves the vehicle.

// The machine's fields and helpers are the parent's: these are its methods, by job.
use super::*;
use crate::adaptation::identification::carry_over;

impl Machine {
    /// Install a model from a file (at start, or an operator's load request): its
    /// allocation is derived again from its effectiveness, and it must pass the same checks
    /// as any swap, the physical bounds included.
    pub fn load_model(&mut self, model: Model) -> Result<(), Refused> {
        let model = model.with_derived_allocation(&self.setup.estimator);
        self.install_loaded(model)
    }

    /// The same for a model already prepared off the control thread
    /// ([`Model::prepared`], with the same estimator settings): only the checks against the
    /// machine (thruster count, confidence) and the swap are left.
    pub fn load_prepared(&mut self, model: PreparedModel) -> Result<(), Refused> {
        self.install_loaded(model.into_model())
    }

    pub(super) fn install_loaded(&mut self, model: Model) -> Result<(), Refused> {
        let saved = model.version;
        self.try_swap(model, ModelSource::Loaded)
            .map_err(|e| Refused(format!("model not used: {e}")))?;
        // Versions only go up here: a file older than the model in force gets a new number,
        // and status says which version it was saved as.
        let what = match self.models.current() {
            Some(m) if saved > 0 && m.version != saved => {
                format!("model loaded (saved as v{saved})")
            }
            _ => "model loaded".to_string(),
        };
        self.describe_swap(&what);
        Ok(())
    }

    /// After an operator's swap (revert, load): status says which model is in force and
    /// where it came from, instead of the words of the run that made the old one.
    pub(super) fn describe_swap(&mut self, what: &str) -> String {
        let Some(m) = self.models.current() else {
            return what.to_string();
        };
        self.text = format!("{what}: model v{}, {}", m.version, m.provenance());
        self.text.clone()
    }

    /// Validate and install a model between two ticks: the monitor judges the new one on fresh
    /// data only.
    pub(super) fn try_swap(
        &mut self,
        model: Model,
        source: ModelSource,
    ) -> Result<(), crate::model::SwapRejection> {
        let limit = self.swap_gate(&model);
        self.try_swap_within(model, source, limit)
    }

    /// The confidence gate `model` passes: `machine.max_swap_rel_err` on what the data know,
    /// with the line's known distance from a curve named and not learned (`curve_named`,
    /// in its bound too) let through. Without it a T200 without `linearize` stopped following
    /// its draining pack (3 refinements in 60 s instead of 10, `supply::
    /// a_draining_battery_is_not_a_weakening_thruster`), and the model it flew on would not
    /// load at the next start. A fit's own models have none.
    pub(super) fn swap_gate(&self, model: &Model) -> f64 {
        let curve = model.curve_named_rel_err();
        self.setup
            .machine
            .max_swap_rel_err
            .hypot(curve[0].max(curve[1]))
    }

    /// `candidate`'s bound widened for how far its fit strayed from the prior it kept
    /// (`carry_over::widen_for_disagreement`). Returns the factor the confidence gate is to be
    /// scaled by, and what the status says when anything was widened. The gate judges the
    /// widened bound against a learned model in force, and the fit's own against a nominal
    /// one, which is a guess with no bound: on `aligned` with a screw declared the wrong way
    /// round, refusing a fit 0.15 (widened 0.40) for it kept a model 0.99 off and the vehicle
    /// 27 deg off level (docs/study.md, "The kept columns and the data disagree").
    pub(super) fn widen_for_disagreement(&self, candidate: &mut Model) -> (f64, Option<String>) {
        let disagreement = candidate
            .dynamics
            .as_ref()
            .map_or([0.0; 2], |d| d.prior_disagreement);
        match carry_over::widen_for_disagreement(candidate, disagreement) {
            None => (1.0, None),
            Some((scale, text)) => {
                let guess_in_force = self.models.current().is_some_and(|m| !m.estimated);
                (if guess_in_force { scale } else { 1.0 }, Some(text))
            }
        }
    }

    /// `try_swap` with the confidence gate at `max_rel_err` instead of
    /// `machine.max_swap_rel_err` (a fight's model: `solve_under_control`).
    pub(super) fn try_swap_within(
        &mut self,
        model: Model,
        source: ModelSource,
        max_rel_err: f64,
    ) -> Result<(), crate::model::SwapRejection> {
        match self.models.swap(model, source, self.n, max_rel_err) {
            Ok(installed) => {
                // The detectors judge the new model afresh.
                self.curve_named = None;
                self.curve_learns = 0;
                self.follow_model_curve();
                self.monitor.reset(self.n);
                self.refiner.reset();
                self.refiner.model_estimated();
                self.hold_watch.reset();
                self.events.push(Event::ModelSwapped(Box::new(installed)));
                Ok(())
            }
            Err(e) => {
                self.events.push(Event::ModelRejected(e.to_string()));
                self.follow_model_curve();
                Err(e)
            }
        }
    }

    /// The commands go out through the thrust curve the model in force was learned with
    /// (`supply::Supply::set_learned_exponent`): its B is per unit of those commands. After
    /// every swap, and after a refusal (an identification that learned a curve, refused,
    /// leaves the model in force and its curve). A model without dynamic terms (a nominal
    /// one, from the declared geometry after an announced change, or the paper's method)
    /// says nothing of the thrusters' curve and leaves the one in use: a nominal B is the
    /// declared thrust per unit command, linear, which is what a learned curve gives.
    pub(super) fn follow_model_curve(&mut self) {
        if let Some(d) = self.models.current().and_then(|m| m.dynamics.as_ref()) {
            self.supply.set_learned_exponent(d.command_exponent);
        }
    }

    /// A model this daemon's estimation just made is per unit of the commands as they went
    /// out: it carries the thrust curve they went through, composed with one the estimate
    /// learned from its own data (the open loop's two levels, `Estimator::
    /// with_learned_curve`: relative to the commands as they went out, so q p).
    pub(super) fn stamp_curve(&self, candidate: &mut Model) {
        if let Some(d) = candidate.dynamics.as_mut() {
            d.command_exponent = match (self.supply.learned_exponent(), d.command_exponent) {
                (Some(q), Some(p)) => Some(q * p),
                (q, p) => q.or(p),
            };
        }
    }

    /// Where a refused estimate leaves the vehicle: holding with the old model, if there is
    /// one and control follows estimation, else Idle (thrusters neutral).
    pub(super) fn after_refusal(&self) -> State {
        if self.models.current().is_some() && self.setup.machine.control_after_estimate {
            State::Active
        } else {
            State::Idle
        }
    }

    /// A model the continuous refinement updated: checked like every other and swapped in.
    /// The monitor and the refiner keep going: the model moved by a window's worth of drift,
    /// not to a new vehicle.
    pub(super) fn install_refined(&mut self, model: Model) {
        // A curve just learned: the refined model is per unit of the commands before it.
        if self.curve_pending.is_some() {
            return;
        }
        let gate = self.swap_gate(&model);
        match self
            .models
            .swap(model, ModelSource::Estimated, self.n, gate)
        {
            Ok(installed) => {
                self.follow_model_curve();
                if let Some(k) = installed.geometry_key {
                    self.models.remember_current(k);
                }
                self.events.push(Event::ModelSwapped(Box::new(installed)));
            }
            Err(e) => self
                .events
                .push(Event::ModelRejected(format!("refined model: {e}"))),
        }
    }
}
