//! Whether the thrust follows the command linearly: the same fit under control made with the
//! commands bent to a power (thrust ~ sign(u) |u|^p, p = 2/3 and 3/2 beside the linear 1), and
//! the profile likelihood of each.
//!
//! Why: the model is linear in the command. A thruster whose thrust is not (another make's
//! curve, thrust ~ command^1.5, or a T200 whose dead zone nobody configured) is learned at the
//! amplitude the excitation used. Open loop that is the pulses' one amplitude (0.8 of full
//! command: eight_vectored_lag80ms_curve 9.6 % off under a 2 % bound), which cannot tell. Under
//! control it is the hold's and the dither's, a third of full command: a T200 without its curve
//! came out 50 % off under a 5 % bound and was swapped in (docs/study.md). The commands under
//! control take every level, so a bent command that explains them better says the linear model
//! is right at one amplitude only.

use nalgebra::Vector3;

use super::lag_search::profile_score;
use super::DynamicRun;
use crate::navigation::{DepthAid, NavState};

/// The exponents the commands are bent by; index 1 is the linear model.
pub const EXPONENTS: [f64; 3] = [2.0 / 3.0, 1.0, 1.5];

/// The fit made again with each of [`EXPONENTS`], fed the main fit's navigation.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ThrustCurveProbe {
    runs: Vec<DynamicRun>,
    /// The bent command of the sample in hand (allocated once).
    bent: Vec<f64>,
}

/// What the probe found.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ThrustCurveEvidence {
    /// The exponent whose fit explains the data best (1: linear).
    pub exponent: f64,
    /// ln of the likelihood ratio of that fit over the linear one, over all six outputs with
    /// every sample counted as independent (0 when the linear fit is best). The residuals are
    /// correlated from sample to sample, so this overstates the evidence: its threshold is
    /// set by runs on linear thrusters, not by a chi-square table.
    pub log_likelihood_ratio: f64,
}

impl ThrustCurveProbe {
    /// Probes shaped like `run` (its thrusters, split, lags and segments), before any sample,
    /// each built anew: a clone would share the segmented fits' cluster slots (`Arc`s written
    /// copy-on-write), and every slot's first write under control would allocate. Without a
    /// log, instruments or navigation of their own: only the profile score is wanted, and
    /// the main fit's navigation is handed in.
    pub fn new(run: &DynamicRun) -> Self {
        let fresh = || {
            let mut probe = DynamicRun {
                lags_learned: run.lags_learned,
                floor_when_split: run.floor_when_split,
                asymmetry: run.asymmetry,
                ..DynamicRun::with_columns(
                    run.n,
                    run.split,
                    0.0,
                    run.segment_s,
                    &Vector3::new(0.0, 0.0, -1.0),
                    DepthAid::default(),
                )
            };
            probe.set_lags(&run.lags);
            probe
        };
        Self {
            runs: EXPONENTS.iter().map(|_| fresh()).collect(),
            bent: vec![0.0; run.n],
        }
    }

    /// One sample the main fit took at `t_s` with navigation state `nav`: gyro (rad/s) and
    /// `u`, the command in model units. Dropped unless finite and later than the last one.
    pub fn push(&mut self, t_s: f64, gyro: &Vector3<f64>, nav: &NavState, u: &[f64]) {
        if u.len() != self.bent.len() || !u.iter().chain(gyro.iter()).all(|v| v.is_finite()) {
            return;
        }
        for (run, p) in self.runs.iter_mut().zip(EXPONENTS) {
            if run.last_t_s.is_some_and(|t0| t_s <= t0) {
                continue;
            }
            for (b, v) in self.bent.iter_mut().zip(u) {
                *b = v.signum() * v.abs().powf(p);
            }
            run.fit(t_s, gyro, nav, Some(&self.bent), None);
        }
    }

    /// The best exponent and its evidence; None until every fit has residual degrees of
    /// freedom.
    pub fn evidence(&self) -> Option<ThrustCurveEvidence> {
        let scores: Vec<f64> = self.runs.iter().map(profile_score).collect::<Option<_>>()?;
        let rows = self.runs[1].samples() as f64;
        let (best, score) = scores
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, s)| (i, *s))?;
        // ln L = -(rows / 2) * score (see lag_search).
        Some(ThrustCurveEvidence {
            exponent: EXPONENTS[best],
            log_likelihood_ratio: 0.5 * rows * (scores[1] - score),
        })
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;

    /// The probe's evidence on a rolling body whose rate is the integral of one thruster's
    /// thrust `thrust(u)`, the command stepping every 0.1 s through levels of every size.
    fn evidence_for(thrust: impl Fn(f64) -> f64) -> ThrustCurveEvidence {
        let levels = [
            0.1, -0.3, 0.6, -0.9, 0.2, -0.5, 1.0, -0.15, 0.4, -0.7, 0.8, -1.0,
        ];
        let g = Vector3::new(0.0, 0.0, -9.80665);
        let mut run = DynamicRun::split(1, 0.0, 1.0, &g, DepthAid::default());
        let mut probe = ThrustCurveProbe::new(&run);
        let (mut rate, mut last) = (0.0, None::<f64>);
        for k in 0..2400 {
            let t = k as f64 * 0.005;
            let u = levels[(t / 0.1) as usize % levels.len()];
            if let Some(f0) = last {
                rate += 0.5 * (f0 + thrust(u)) * 0.005;
            }
            last = Some(thrust(u));
            // A little deterministic jitter, the same for every fit, so no residual is 0.
            let jitter = 1e-4 * (977.0 * t).sin();
            let gyro = Vector3::new(rate + jitter, jitter, -jitter);
            run.push(t, &gyro, &(-g), Some(5.0), Some(&[u]));
            let &(t_nav, nav) = run.last_nav().expect("a sample taken");
            assert_eq!(t_nav, t);
            probe.push(t, &gyro, &nav, &[u]);
        }
        probe
            .evidence()
            .expect("every fit has residual degrees of freedom")
    }

    #[test]
    fn a_curved_thrust_is_told_from_a_linear_one() {
        let curved = evidence_for(|u: f64| 2.0 * u.signum() * u.abs().powf(1.5));
        assert_eq!(curved.exponent, 1.5, "{curved:?}");
        assert!(curved.log_likelihood_ratio > 100.0, "{curved:?}");
        let concave = evidence_for(|u: f64| 2.0 * u.signum() * u.abs().powf(2.0 / 3.0));
        assert_eq!(concave.exponent, 2.0 / 3.0, "{concave:?}");
        let linear = evidence_for(|u| 2.0 * u);
        assert_eq!(linear.exponent, 1.0, "{linear:?}");
        assert_eq!(linear.log_likelihood_ratio, 0.0, "{linear:?}");
    }
}
