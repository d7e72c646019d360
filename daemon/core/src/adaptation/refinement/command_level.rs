//! How far below full command a window's commands were, as the linear fit weighs them: the
//! mean of ln |u| with weights u^2 (a least-squares fit's own weighting of its samples).
//!
//! Why: on a learned thrust curve whose exponent is off by d (relative), a linear fit at
//! commands of level L = E[ln |u|] has the gain at full command off by about d |L|. The
//! refinement's windows fit at the hold's commands, and the bound's floor for the exponent
//! (`thrust_curve::learned_curve_rel_err`) had assumed a third of full command, |L| = 1.2:
//! eight_vectored_lag80ms_curve held through pitch steps is at |L| of about 2, and the windows
//! carried its model from 0.04 to 0.08-0.17 off under a bound of 0.066-0.08 (docs/study.md,
//! "A curve named: the model in force's bound restated, the windows' level, and the demo's
//! operator").

/// The running weighted sums over the samples of one window.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CommandLevel {
    /// Sum of u^2 ln |u| over every thruster's command of every sample.
    weighted_log: f64,
    /// Sum of u^2.
    weight: f64,
}

/// Commands below this are left out: their weight is nothing and their logarithm unbounded.
const SMALLEST: f64 = 1e-6;

impl CommandLevel {
    /// One sample's commands (model units, |u| <= 1).
    pub fn push(&mut self, commands: &[f64]) {
        for u in commands {
            let a = u.abs();
            if a.is_finite() && a > SMALLEST {
                let w = a * a;
                self.weighted_log += w * a.ln();
                self.weight += w;
            }
        }
    }

    /// |E[ln |u|]| under the weights u^2; None before any command.
    pub fn log_level(&self) -> Option<f64> {
        (self.weight > 0.0)
            .then(|| (self.weighted_log / self.weight).abs())
            .filter(|l| l.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::CommandLevel;

    #[test]
    fn the_level_is_the_weighted_mean_log_of_the_commands() {
        let mut l = CommandLevel::default();
        assert_eq!(l.log_level(), None);
        l.push(&[0.0, 1e-9]);
        assert_eq!(l.log_level(), None, "nothing with weight");
        // One level: its logarithm.
        l.push(&[0.3, -0.3]);
        assert!((l.log_level().unwrap() - 0.3f64.ln().abs()).abs() < 1e-12);
        // A full-command sample weighs 1/0.09 as much and has ln 1 = 0.
        l.push(&[1.0]);
        let want = (2.0 * 0.09 * 0.3f64.ln() / (2.0 * 0.09 + 1.0)).abs();
        assert!((l.log_level().unwrap() - want).abs() < 1e-12);
        // Non-finite commands are left out.
        l.push(&[f64::NAN, f64::INFINITY]);
        assert!((l.log_level().unwrap() - want).abs() < 1e-12);
    }
}
