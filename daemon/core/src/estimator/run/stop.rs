//! Where the open loop may stop, and whether it does: the plan's extent, the gate that
//! needs no estimate (counts only, asked on the control thread), and the decision with one.

use super::{Estimate, Estimator, StopDecision};
use crate::estimator::config::Method;

impl Estimator {
    /// Pulses the run plans before it may stop: one for the paper method's fixed plan, the
    /// minimum cycles for the forward method (which then stops on its bound).
    pub fn planned_pulses(&self) -> usize {
        let cycles = match self.cfg.method {
            Method::Paper => self.cfg.paper_cycles,
            Method::Dynamic if self.stops_once_spanned() => {
                return self.plan.spanned_at(4).min(self.cfg.max_pulses);
            }
            Method::Forward | Method::Dynamic => self.cfg.min_cycles,
        };
        (cycles * self.plan.cycle_len()).min(self.cfg.max_pulses)
    }

    /// Whether this run may stop before its first cycle ends (`stop_once_spanned`): not
    /// where a learned curve needs the whole cycle's two levels.
    fn stops_once_spanned(&self) -> bool {
        self.cfg.stop_once_spanned && self.cfg.second_amplitude >= 1.0
    }

    /// The pulses the plan runs to as it stands, for progress: the minimum plan
    /// (`planned_pulses`) until a pulse beyond it begins; then the plan has grown (the bound
    /// was not met) to the next point where the estimator may stop, at most `max_pulses`.
    /// Never below the pulses begun, so progress never reads "pulse 40 of 32".
    pub fn plan_extent(&self) -> usize {
        let min = self.planned_pulses();
        let begun = self.pulses + usize::from(self.pulse.is_some());
        if begun <= min {
            return min;
        }
        // Where stop_gate lets the run end (see there).
        let step = match self.cfg.method {
            Method::Paper => 1,
            Method::Forward => self.plan.cycle_len(),
            Method::Dynamic => 4,
        };
        begun
            .div_ceil(step)
            .saturating_mul(step)
            .min(self.cfg.max_pulses)
            .max(begun)
    }

    /// Go on pulsing, or stop (and why).
    pub fn stop_decision(&self) -> StopDecision {
        self.stop_gate()
            .unwrap_or_else(|| self.bound_decision(&self.estimate(), true))
    }

    /// The same with the estimate of this moment already made (the machine makes one after
    /// every pulse): the solve is not done twice.
    pub fn stop_decision_with(&self, estimate: &Estimate) -> StopDecision {
        self.stop_gate()
            .unwrap_or_else(|| self.bound_decision(estimate, true))
    }

    /// The decision when it does not depend on the estimate; None when the bound decides.
    /// Cheap (counts only): the machine asks it on the control thread and leaves the solve
    /// for the estimate to a job (`crate::solve`).
    pub fn stop_gate(&self) -> Option<StopDecision> {
        if self.pulses >= self.cfg.max_pulses {
            return Some(StopDecision::MaxPulses);
        }
        let aligned = match self.cfg.method {
            Method::Paper => {
                return Some(if self.pulses >= self.planned_pulses() {
                    StopDecision::PlanComplete
                } else {
                    StopDecision::Continue
                });
            }
            // Stop only at the end of a cycle: mid-cycle the design is unbalanced (some
            // thrusters pushed forward more than in reverse), which biases the symmetric model
            // of a thruster that is weaker in reverse.
            Method::Forward => self.pulses.is_multiple_of(self.plan.cycle_len()),
            // After a whole cycle (every pattern seen, see planned_pulses), at the end of a
            // doublet pair, when the vehicle is back near rest.
            Method::Dynamic => self.pulses.is_multiple_of(4),
        };
        (self.pulses < self.planned_pulses() || !aligned).then_some(StopDecision::Continue)
    }
}
