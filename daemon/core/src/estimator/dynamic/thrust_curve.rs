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

/// The ratio r of the probe's exponents 1/r, 1, r (index 1 the linear model) on commands as
/// the machine computes them: 2/3, 1, 3/2, for a curve nobody configured could be anything.
pub const WIDE: f64 = 1.5;
/// The ratio on commands already through a learned curve (`supply`): what is left is a few
/// percent of the exponent, which the wide grid's parabola cannot place. What is left within
/// half a step of it goes unnamed ([`NARROW_HALF_STEP`]).
pub const NARROW: f64 = 1.1;

/// The relative error of an exponent the narrow grid leaves unnamed: the linear fit stays the
/// best of the three until the curve is half a step (in ln p) from it.
pub const NARROW_HALF_STEP: f64 = 0.048_808_848_170_151_55; // sqrt(1.1) - 1

/// B's relative error from a learned curve's exponent, at most: a linear fit on thrust ~
/// |u|^(1 + d) has the gain at |u| = 1 times (1 + d E[ln |u|]), the hold's commands are about
/// a third of full command (|ln 0.3| = 1.2), and d is within [`NARROW_HALF_STEP`]. Measured
/// (noise-free): an exponent 2.8 % low gave B 3.6-3.9 % off, 1.3 % low 1.5-2.0 %. A floor of
/// every bound on such a model: no window of the refinement removes it, as no data at the
/// hold's amplitude tells the exponent (`refinement::fusion`).
pub const LEARNED_CURVE_REL_ERR: f64 = THIRD_OF_FULL_COMMAND * NARROW_HALF_STEP;

/// |ln 0.3|: the level [`LEARNED_CURVE_REL_ERR`] takes the commands at, and the least the
/// refinement's floor takes them at.
const THIRD_OF_FULL_COMMAND: f64 = 1.2;

/// The same at commands whose weighted mean |ln |u|| is `log_level` (the refinement's window,
/// `refinement::command_level`), never below the third of full command's; that one without a
/// level. Held through pitch steps eight_vectored_lag80ms_curve's windows are at about 2, and
/// they carried B by twice the exponent's error.
pub fn learned_curve_rel_err(log_level: Option<f64>) -> f64 {
    let level = log_level
        .filter(|l| l.is_finite())
        .map_or(THIRD_OF_FULL_COMMAND, |l| l.max(THIRD_OF_FULL_COMMAND));
    level * NARROW_HALF_STEP
}

/// The exponents a fitted one is kept within: the configuration's `power_law_exponent` range
/// (thrust from the square root to the cube of the command).
pub const FITTED_RANGE: (f64, f64) = (0.5, 3.0);

fn linear() -> f64 {
    1.0
}

/// The exponent whose fit the data like best, between and around the probe's three (1/r, 1,
/// r): each output's residual variance interpolated by the parabola through its three fits
/// in ln p (where they are evenly spaced by h = ln r), and the likelihood of all six
/// maximized on it within two steps of 1. Why the variances and not the profile score's
/// logarithms: a fit's residual variance is quadratic in a small error of the exponent (the
/// residual is linear in it), its logarithm is not where the noise is small: the parabola
/// through the scores put thrust ~ command^1.33 at 2.25 noise-free and ^1.5 at 2.25 with a
/// little noise; through the variances 1.42 and 1.44, and never further off than the
/// nearest of the three (a curve learned is then refined on the narrow grid, [`NARROW`]).
/// The best of the three where an output has no variance to interpolate.
fn fitted_exponent(runs: &[DynamicRun], exponents: &[f64; 3], best: usize) -> f64 {
    let h = (exponents[2] / exponents[1]).ln();
    let mut parabolas = [[0.0; 3]; 6];
    for (j, run) in runs.iter().enumerate().take(3) {
        for (g, ls) in [&run.rot, &run.acc].into_iter().enumerate() {
            let Some(var) = ls.residual_variance() else {
                return exponents[best];
            };
            for (a, v) in var.iter().enumerate() {
                parabolas[3 * g + a][j] = *v;
            }
        }
    }
    if h.is_nan()
        || h <= 0.0
        || parabolas
            .iter()
            .flatten()
            .any(|v| !(v.is_finite() && *v > 0.0))
    {
        return exponents[best];
    }
    // -2 ln L / rows = sum ln v(x): the sum is what is minimized.
    let score = |x: f64| -> f64 {
        parabolas
            .iter()
            .map(|[lo, mid, hi]| {
                let slope = (hi - lo) / (2.0 * h);
                let curve = (hi - 2.0 * mid + lo) / (2.0 * h * h);
                let floor = 1e-3 * lo.min(*mid).min(*hi);
                (mid + slope * x + curve * x * x).max(floor).ln()
            })
            .sum()
    };
    // A grid of h/100 over [-2h, 2h]: 401 evaluations of six parabolas, once per decision.
    let x = (0..=400)
        .map(|i| h * (-2.0 + i as f64 / 100.0))
        .map(|x| (x, score(x)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0.0, |(x, _)| x);
    (exponents[1].ln() + x)
        .exp()
        .clamp(FITTED_RANGE.0, FITTED_RANGE.1)
}

/// The fit made again with each of the probe's three exponents, fed the main fit's navigation.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ThrustCurveProbe {
    runs: Vec<DynamicRun>,
    /// The exponents bent by: 1/r, 1 and r.
    exponents: [f64; 3],
    /// The bent command of the sample in hand (allocated once).
    bent: Vec<f64>,
}

/// What the probe found.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ThrustCurveEvidence {
    /// The exponent whose fit explains the data best (1: linear).
    pub exponent: f64,
    /// The exponent between and around the three where the likelihood peaks, each output's
    /// residual variance interpolated between them ([`fitted_exponent`]): what is learned
    /// (`supply`'s learned curve), the three being a grid and a thruster's curve anything.
    /// Within two grid steps of 1 and [`FITTED_RANGE`] (1 in files of daemons before it).
    #[serde(default = "linear")]
    pub fitted_exponent: f64,
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
    /// `ratio`: r of the exponents 1/r, 1, r ([`WIDE`], [`NARROW`]).
    pub fn new(run: &DynamicRun, ratio: f64) -> Self {
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
            runs: (0..3).map(|_| fresh()).collect(),
            exponents: [1.0 / ratio, 1.0, ratio],
            bent: vec![0.0; run.n],
        }
    }

    /// One sample the main fit took at `t_s` with navigation state `nav`: gyro (rad/s) and
    /// `u`, the command in model units. Dropped unless finite and later than the last one.
    pub fn push(&mut self, t_s: f64, gyro: &Vector3<f64>, nav: &NavState, u: &[f64]) {
        if u.len() != self.bent.len() || !u.iter().chain(gyro.iter()).all(|v| v.is_finite()) {
            return;
        }
        for (run, p) in self.runs.iter_mut().zip(self.exponents) {
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
            exponent: self.exponents[best],
            fitted_exponent: fitted_exponent(&self.runs, &self.exponents, best),
            log_likelihood_ratio: 0.5 * rows * (scores[1] - score),
        })
    }
}

/// The ln likelihood ratio over the linear fit above which an open-loop estimate learns the
/// curve its log names (the identification's `max_curve_evidence` default; no linear vehicle
/// learned a curve over 165 runs at two levels, docs/study.md).
pub const OPEN_LOOP_CURVE_EVIDENCE: f64 = 50.0;

/// The exponent whose fit (commands bent with each direction's top level kept) has the least
/// profile score, searched in ln p within a factor `within`^1.5 of `start` and
/// [`FITTED_RANGE`]: a golden-section search, 24 refits. Why a search and not the probe's
/// parabola: the parabola through three points a factor 1.5 apart placed ^1.5 at 1.62
/// noise-free and 1.84 at a realistic IMU; the refits are cheap where the log is at hand.
pub fn best_exponent(run: &DynamicRun, lags: &[f64], start: f64, within: f64) -> Option<f64> {
    let within = within.powf(1.5);
    let score = |x: f64| -> Option<f64> {
        profile_score(&run.with_commands_bent(x.exp(), true)?.refit(lags)?)
    };
    let (lo, hi) = (
        (start / within).max(FITTED_RANGE.0).ln(),
        (start * within).min(FITTED_RANGE.1).ln(),
    );
    // NaN (a start that is not a number) or an empty range: nothing to search.
    if lo.partial_cmp(&hi) != Some(std::cmp::Ordering::Less) {
        return None;
    }
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (lo, hi);
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (score(c)?, score(d)?);
    for _ in 0..22 {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = score(c)?;
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = score(d)?;
        }
    }
    Some((0.5 * (a + b)).exp())
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;

    /// The probe's evidence on a rolling body whose rate is the integral of one thruster's
    /// thrust `thrust(u)`, the command stepping every 0.1 s through levels of every size.
    fn evidence_for(thrust: impl Fn(f64) -> f64) -> ThrustCurveEvidence {
        evidence_on(thrust, WIDE)
    }

    /// The same with the probe's exponents 1/`ratio`, 1, `ratio`.
    fn evidence_on(thrust: impl Fn(f64) -> f64, ratio: f64) -> ThrustCurveEvidence {
        let levels = [
            0.1, -0.3, 0.6, -0.9, 0.2, -0.5, 1.0, -0.15, 0.4, -0.7, 0.8, -1.0,
        ];
        let g = Vector3::new(0.0, 0.0, -9.80665);
        let mut run = DynamicRun::split(1, 0.0, 1.0, &g, DepthAid::default());
        let mut probe = ThrustCurveProbe::new(&run, ratio);
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
        assert!((curved.fitted_exponent - 1.5).abs() < 0.1, "{curved:?}");
        assert!(curved.log_likelihood_ratio > 100.0, "{curved:?}");
        let concave = evidence_for(|u: f64| 2.0 * u.signum() * u.abs().powf(2.0 / 3.0));
        assert_eq!(concave.exponent, 2.0 / 3.0, "{concave:?}");
        let linear = evidence_for(|u| 2.0 * u);
        assert_eq!(linear.exponent, 1.0, "{linear:?}");
        assert_eq!(linear.log_likelihood_ratio, 0.0, "{linear:?}");
        // (Its fitted exponent is not 1 noise-free, 1.06: nothing is learned while the linear
        // fit is the best of the three.)
    }

    /// Off the grid the wide parabola comes within 15 % of the exponent; on the commands
    /// through what it found (the machine's next identifications), the narrow grid names
    /// what is left beyond half its step and takes it within half a step (what a model on a
    /// learned curve adds to its bound, `NARROW_HALF_STEP`).
    #[test]
    fn an_exponent_between_the_three_is_fitted_and_refined() {
        for p in [1.25, 1.75, 0.8, 1.33, 2.0, 0.6] {
            let wide = evidence_for(|u: f64| 2.0 * u.signum() * u.abs().powf(p));
            assert!(
                (wide.fitted_exponent / p - 1.0).abs() < 0.15,
                "thrust ~ command^{p}: {wide:?}"
            );
            let mut learned = wide.fitted_exponent;
            for _ in 0..2 {
                let rest = evidence_on(
                    |u: f64| 2.0 * u.signum() * u.abs().powf(p / learned),
                    NARROW,
                );
                if rest.exponent == 1.0 {
                    break;
                }
                assert!(rest.log_likelihood_ratio > 50.0, "{rest:?}");
                learned *= rest.fitted_exponent;
            }
            assert!(
                (learned / p).ln().abs() <= NARROW.ln() / 2.0 + 1e-9,
                "thrust ~ command^{p}: wide {wide:?}, learned {learned}"
            );
        }
        let steep = evidence_for(|u: f64| 2.0 * u.signum() * u.abs().powi(4));
        assert!((NARROW.sqrt() - 1.0 - NARROW_HALF_STEP).abs() < 1e-12);
        assert!(steep.fitted_exponent <= 1.5 * 1.5 * 1.5 + 1e-9, "{steep:?}");
        assert!(steep.fitted_exponent >= 1.5, "{steep:?}");
    }
}
