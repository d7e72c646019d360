//! A thrust curve an identification under control named, learned: the commands go out
//! through it, and once the vehicle is held on them the identification starts again.
//!
//! Why: with thrusters whose thrust is not linear in the command and a daemon not told (another
//! make's thrust ~ command^1.5: eight_vectored_lag80ms_curve), the open-loop model is right
//! at the pulses' amplitude only (8-9 % off under a 2 % bound), and the identification under
//! control names the curve (`estimator::dynamic::thrust_curve`). Refusing it left that model
//! in force for good (`curve_named`). Learned, the commands are linear in thrust again and the
//! identification's model is right at every amplitude (docs/study.md, "A thrust curve
//! learned").
//!
//! Why wait for the hold: started at once, on the vehicle the 20 s identification had left
//! swinging through the switch of curves, the new identification stopped in 4 s on acceleration
//! rows 0.069 off under a 0.021 bound (noise-free); started after the vehicle had held on the
//! new commands for a second and a half, 0.006-0.010 (the fight's confirmation waits the
//! same way, `identification::fight`).

use super::*;
use crate::adaptation::identification::fight::{PendingConfirmation, MAX_WAIT_FOR_HOLD_S};
use crate::estimator::dynamic::thrust_curve::{
    ThrustCurveEvidence, FITTED_RANGE, LEARNED_CURVE_REL_ERR,
};

/// Thrust curves learned in a row (no model swapped in between) before a named curve is
/// refused instead: the wide grid's parabola is off by up to 15 % between its points, and
/// the narrow grid's names and takes what is left beyond half its step (once or twice:
/// `thrust_curve`'s tests); a fourth would mean the data do not settle on one.
pub(super) const MAX_CURVE_LEARNS: u8 = 3;

/// The identification waiting for the vehicle to be held on a curve just learned.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub(super) struct CurvePending {
    hold: PendingConfirmation,
    /// The identification it ends was a detector's (`identifying_unannounced`): so is the
    /// next.
    unannounced: bool,
}

impl Machine {
    /// A thrust curve the identification named (`c`), learned as `exponent` on the commands
    /// as they went out: from now on the commands go out through it
    /// (`supply::Supply::set_learned_exponent`, composed with the one in use: the data were
    /// taken through that, so thrust ~ command^(q p)), holding on the model in
    /// force until the vehicle is held, then identifying again from no prior (every column
    /// carried would be per unit of the commands before). The new model carries the curve;
    /// refused, or the wait ended, the model in force's comes back (`follow_model_curve`).
    /// Returns false, nothing done, when learning is off, the thrusters are taken for T200s
    /// with their curve kept (`Supply::takes_t200_curve`), the curve learned is outside what
    /// a thruster has, or `MAX_CURVE_LEARNS` were learned since the last swap.
    pub(super) fn learn_curve(&mut self, why: &str, c: ThrustCurveEvidence) -> bool {
        let in_use = self.supply.learned_exponent().unwrap_or(1.0);
        let learned = in_use * c.fitted_exponent;
        let (lo, hi) = FITTED_RANGE;
        // Thrusters taken for T200s with their curve kept: the curve named is the T200's own
        // (its dead zone, its shape), which no power law fits; `linearize` is the answer, and
        // the refusal says so (a power law learned on amour5_t200 left its model 0.12 off
        // under a 0.06 bound). Another make's thrusters are `compensation = "none"`.
        if !self.setup.identification.learn_thrust_curve
            || self.supply.takes_t200_curve()
            || self.curve_learns >= MAX_CURVE_LEARNS
            || !(lo..=hi).contains(&learned)
        {
            return false;
        }
        self.curve_learns += 1;
        self.events.push(Event::ModelRejected(format!(
            "{why}: the thrust does not follow the command linearly (thrust ~ command^{learned:.3} explains the data better, ln likelihood ratio {:.0}): learned; commands go out through it, and once the vehicle is held the identification starts again; model rejected",
            c.log_likelihood_ratio
        )));
        self.supply.set_learned_exponent(Some(learned));
        let unannounced = self.identifying_unannounced;
        // The detectors' windows hold the commands before the curve.
        self.monitor.reset(self.n);
        self.refiner.reset();
        self.transition(
            State::Active,
            &format!(
                "thrust ~ command^{learned:.3} learned: holding on it, then identifying again"
            ),
        );
        // After the transition, which ends any wait but Active's.
        self.curve_pending = Some(CurvePending {
            hold: PendingConfirmation::new(None),
            unannounced,
        });
        true
    }

    /// A curve just learned (`learn_curve`): once the vehicle has been held on it within the
    /// identification's attitude budget (`fight::HELD_S`), the identification starts again.
    /// Returns whether it started.
    pub(super) fn identify_when_curve_held(
        &mut self,
        t_ns: u64,
        attitude: &UnitQuaternion<f64>,
        target: &UnitQuaternion<f64>,
    ) -> bool {
        let (Some(pending), Some(model)) = (self.curve_pending.as_mut(), self.models.current())
        else {
            return false;
        };
        let budget = self.setup.identification.attitude_budget_deg;
        let err_deg = actuated_error_deg(attitude, target, model.actuated);
        if !pending.hold.held(t_ns, err_deg, budget) {
            if pending.hold.waited_too_long(t_ns) {
                // `let_go_and_estimate` ends the wait: the curve goes with the model again.
                self.let_go_and_estimate(
                    t_ns,
                    format!(
                        "the model in force did not hold the vehicle within {budget} deg in {:.0} s on the curve learned",
                        MAX_WAIT_FOR_HOLD_S
                    ),
                    "no model holds it on that curve",
                );
                return true;
            }
            return false;
        }
        let Some(pending) = self.curve_pending.take() else {
            return false;
        };
        // The curve the commands go through now (the one learned, or a loaded model's).
        let p = self.supply.learned_exponent().unwrap_or(1.0);
        self.start_estimation_with(
            t_ns,
            &format!("thrust ~ command^{p:.2} learned and the vehicle held on it"),
            None,
        );
        // Long enough for the narrow grid to name what is left of the exponent.
        self.run.run_at_least(
            self.setup.identification.curve_confirm_min_s,
            &self.setup.identification,
        );
        self.identifying_unannounced = pending.unannounced;
        true
    }

    /// The factors a model identified on a learned curve has its bound widened by: the
    /// curve's exponent is an estimate, known to within what the narrow grid leaves unnamed,
    /// which is B's error too (`thrust_curve::LEARNED_CURVE_REL_ERR`), added in quadrature
    /// to each row group's bound. None without a learned curve.
    pub(super) fn learned_curve_scale(&self, candidate: &Model) -> Option<[f64; 2]> {
        self.supply.learned_exponent()?;
        let extra = LEARNED_CURVE_REL_ERR;
        let scale = |bound: f64| {
            if bound > 0.0 && bound.is_finite() {
                bound.hypot(extra) / bound
            } else {
                1.0
            }
        };
        Some([scale(candidate.rel_err_rot), scale(candidate.rel_err_acc)])
    }

    /// The wait for the hold ended otherwise (an operator's request, a lost hold, a new
    /// estimation): the curve goes with the model in force again. Returns whether one was
    /// waiting.
    pub(super) fn end_curve_wait(&mut self) -> bool {
        let waited = self.curve_pending.take().is_some();
        if waited {
            self.follow_model_curve();
        }
        waited
    }
}
