//! Learning the thrusters' spin-up time constant: the one unknown the dynamic regression is
//! not linear in.
//!
//! Why it must be learned: B is the thrust's gain through a first-order lag, and a lag that is
//! wrong by 20 ms moves AMOUR-5's learned B by 20-25 % noise-free (issue 29: 0.05 s true against
//! 0.1 s assumed gave err_rot 1.05). Nobody knows a real thruster's lag to 20 ms.
//!
//! How: for a given lag the fit is linear, so the lag is found by its profile likelihood. With
//! Gaussian residuals of unknown variance per output, the likelihood maximised over every
//! other coefficient is -(n/2) sum_a ln(residual variance_a), so the lag that minimises
//! sum_a ln(s_a^2) over the six outputs is the maximum-likelihood lag. It is searched on a
//! log-spaced grid over the allowed range (the profile is not guaranteed unimodal over a
//! decade, and the grid finds the right valley), then by golden section inside the best
//! grid cell. Each evaluation refits the logged samples ([`super::sample_log`]); the search
//! runs in the solve job, off the control thread.

use nalgebra::{DMatrix, Vector3};

use super::DynamicRun;

/// Where and how finely the lag is searched.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LagRange {
    /// Smallest and largest lag considered, s.
    pub min_s: f64,
    pub max_s: f64,
    /// Grid points over the range before the golden section (>= 3).
    pub grid: usize,
    /// Stop when the bracket is this narrow, as a ratio of its ends minus 1 (0.005: 0.5 %).
    pub tolerance: f64,
}

impl Default for LagRange {
    /// 10 ms to 0.5 s (an ESC-driven thruster spins up in 30-200 ms), 8 grid points (a ratio
    /// of 1.75 between neighbours), to 0.5 %.
    fn default() -> Self {
        LagRange {
            min_s: 0.01,
            max_s: 0.5,
            grid: 8,
            tolerance: 0.005,
        }
    }
}

/// The learned lag and the fit made with it.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct LagFit {
    /// The maximum-likelihood lag, s.
    pub lag_s: f64,
    /// The fit at that lag.
    pub run: DynamicRun,
    /// The fits at the lag times and divided by `exp(STEP)`: B's sensitivity to the lag.
    pub above: DynamicRun,
    pub below: DynamicRun,
    /// One standard deviation of ln(lag), from the profile's curvature (infinite when the
    /// profile is flat there).
    pub sd_ln: f64,
    /// (lag s, score) of every evaluation, in the order made: the profile, for reports.
    pub profile: Vec<(f64, f64)>,
    /// A lag per thruster (`thruster_lags.rs`) where the data said the thrusters
    /// differ: `run` is then the fit at these, and `lag_s` their mean. Empty: one lag for all.
    #[serde(default)]
    pub per_thruster: Vec<ThrusterLag>,
    /// ln likelihood ratio of a lag per thruster over one for all (0 when not searched).
    #[serde(default)]
    pub per_thruster_evidence: f64,
    /// With `per_thruster`: the lags' joint covariance in ln(lag), row-major N x N (from the
    /// profile's Hessian); empty otherwise.
    #[serde(default)]
    pub per_thruster_cov: Vec<f64>,
    /// With `per_thruster`: the standard deviation in ln(lag) each lag gets beyond the data's
    /// (`EstimatorConfig::thruster_lag_floor`).
    #[serde(default)]
    pub per_thruster_floor_ln: f64,
    /// One lag for all kept although a lag per thruster explained the data better, because
    /// the lags found were alike (`thruster_lags::MIN_SPREAD`): that fit. The difference of
    /// its B from this one's is counted in the bound as a floor (see `widen`).
    #[serde(default)]
    pub unkept_per_thruster: Option<Box<DynamicRun>>,
    /// Where the rotation and the acceleration rows alone put the lag
    /// ([`super::lag_agreement`], judged on the common lag's fit); None where not judged.
    #[serde(default)]
    pub groups: Option<super::lag_agreement::LagAgreement>,
}

/// One thruster's learned lag and the fits with it moved by `exp(STEP)` either way (the
/// others held): B's sensitivity to it.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ThrusterLag {
    pub lag_s: f64,
    /// One standard deviation of ln(lag), from the profile's curvature along this lag alone
    /// (infinite when flat).
    pub sd_ln: f64,
    pub above: DynamicRun,
    pub below: DynamicRun,
}

/// The step in ln(lag) of the curvature and sensitivity differences (10 %).
pub const STEP: f64 = 0.0953;

impl LagFit {
    /// The lags of `run`: one per thruster, or the common one alone.
    pub fn lags(&self) -> Vec<f64> {
        if self.per_thruster.is_empty() {
            vec![self.lag_s]
        } else {
            self.per_thruster.iter().map(|t| t.lag_s).collect()
        }
    }

    /// Widen `sol` (the fit at the learned lag) by what the lag's uncertainty does to B (and
    /// to the other coefficients):
    /// dB/dln(lag) from `above_sol` and `below_sol` (the fits at the neighbouring lags),
    /// times `sd_ln`, added in quadrature to every standard error and to both bounds. Why:
    /// at a realistic IMU after 4 s the lag is known to +-10-20 %, which moves B by several
    /// per cent, and a bound without it claimed 2 % on a model 7 % off (eight_vectored, lag
    /// 0.2 s).
    ///
    /// With a lag per thruster, the lags' joint covariance through each one's sensitivity,
    /// plus `per_thruster_floor_ln` on each lag alone: what the data's model error leaves in
    /// them (reported apart, `DynamicTerms::spin_up_floor_rel_err`, since no more data
    /// removes it).
    pub fn widen(
        &self,
        sol: &mut super::DynamicSolution,
        solve: impl Fn(&DynamicRun) -> super::DynamicSolution,
    ) {
        // The sensitivities dB/dln(lag) (and of the terms) along each lag, and the lags'
        // covariance in ln: one lag, or one per thruster with their joint covariance (their
        // profile's Hessian: the lags of thrusters that push alike trade against each other).
        let flat = |sd_ln: f64| if sd_ln.is_finite() { sd_ln } else { 1.0 };
        let (directions, cov): (Vec<(&DynamicRun, &DynamicRun)>, DMatrix<f64>) =
            if self.per_thruster.is_empty() {
                let sd = flat(self.sd_ln);
                (
                    vec![(&self.above, &self.below)],
                    DMatrix::from_element(1, 1, sd * sd),
                )
            } else {
                let k = self.per_thruster.len();
                let cov = if self.per_thruster_cov.len() == k * k
                    && self.per_thruster_cov.iter().all(|v| v.is_finite())
                {
                    DMatrix::from_row_slice(k, k, &self.per_thruster_cov)
                } else {
                    // Flat somewhere: each lag anywhere in the range, a factor e either way.
                    DMatrix::from_fn(k, k, |i, j| {
                        if i == j {
                            flat(self.per_thruster[i].sd_ln).powi(2)
                        } else {
                            0.0
                        }
                    })
                };
                (
                    self.per_thruster
                        .iter()
                        .map(|t| (&t.above, &t.below))
                        .collect(),
                    cov,
                )
            };
        let sens: Vec<(DMatrix<f64>, DMatrix<f64>)> = directions
            .iter()
            .map(|(above, below)| {
                let (a, b) = (solve(above), solve(below));
                (
                    (&a.b - &b.b) / (2.0 * STEP),
                    // The damping, restoring and Coriolis coefficients trade against the lag
                    // as well (noise-free, 0.1 ms of lag moved AMOUR-5's pitch damping by 5 %).
                    (&a.terms.coefficients - &b.terms.coefficients) / (2.0 * STEP),
                )
            })
            .collect();
        let mut var_b = DMatrix::zeros(sol.b.nrows(), sol.b.ncols());
        let mut var_terms = DMatrix::zeros(sol.terms.std_err.nrows(), sol.terms.std_err.ncols());
        for (i, (bi, ti)) in sens.iter().enumerate() {
            for (j, (bj, tj)) in sens.iter().enumerate() {
                var_b += bi.component_mul(bj) * cov[(i, j)];
                var_terms += ti.component_mul(tj) * cov[(i, j)];
            }
        }
        let mut var_floor = DMatrix::zeros(sol.b.nrows(), sol.b.ncols());
        // Lags a tenth apart, found but not kept: the data cannot say which of the two models
        // is the vehicle's, so their difference is in the bound (AMOUR-5 with thrusters at 0.1
        // and 0.11 s, noise-free: 0.047 / 0.053 off under bounds of 0.020).
        if let Some(other) = &self.unkept_per_thruster {
            let d = &solve(other).b - &sol.b;
            if d.shape() == var_floor.shape() && d.iter().all(|v| v.is_finite()) {
                var_floor += d.component_mul(&d);
            }
        }
        if !self.per_thruster.is_empty() {
            let f2 = self.per_thruster_floor_ln.powi(2);
            for (bi, ti) in &sens {
                var_floor += bi.component_mul(bi) * f2;
                var_terms += ti.component_mul(ti) * f2;
            }
        }
        let n = sol.b.ncols();
        for g in 0..2 {
            let rows = 3 * g..3 * g + 3;
            let norm2: f64 = rows
                .clone()
                .flat_map(|r| (0..n).map(move |i| (r, i)))
                .map(|(r, i)| sol.b[(r, i)].powi(2))
                .sum();
            let (mut extra, mut floor) = (0.0, 0.0);
            for r in rows {
                for i in 0..n {
                    let (e2, f2) = (var_b[(r, i)], var_floor[(r, i)]);
                    if e2.is_finite() && f2.is_finite() {
                        sol.std_err[(r, i)] = (sol.std_err[(r, i)].powi(2) + e2 + f2).sqrt();
                        extra += e2;
                        floor += f2;
                    }
                }
            }
            if norm2 > 0.0 && sol.rel_err[g].is_finite() {
                sol.rel_err[g] = (sol.rel_err[g].powi(2) + (extra + floor) / norm2).sqrt();
                sol.terms.spin_up_rel_err[g] = (extra / norm2).sqrt();
                sol.terms.spin_up_floor_rel_err[g] = (floor / norm2).sqrt();
            }
        }
        sol.terms.spin_up_sd_ln = self.sd_ln;
        sol.terms.spin_up_groups = self.groups;
        sol.terms.spin_up_per_thruster_s = self.per_thruster.iter().map(|t| t.lag_s).collect();
        sol.terms.thruster_lag_evidence = self.per_thruster_evidence;
        for (se, e2) in sol.terms.std_err.iter_mut().zip(var_terms.iter()) {
            if e2.is_finite() {
                *se = (*se * *se + e2).sqrt();
            }
        }
    }
}

/// The profile score of a fit: sum over the six outputs of ln(residual variance). None while
/// an output has no residual degrees of freedom.
pub fn profile_score(run: &DynamicRun) -> Option<f64> {
    profile_score_weighted(run, &ALL_OUTPUTS)
}

/// Every output counted once in the score.
pub const ALL_OUTPUTS: [f64; 6] = [1.0; 6];

/// [`profile_score`] with output a's ln(residual variance) weighted by `weights[a]` (DOF order):
/// the lab's decisive runs score one group of rows alone.
pub fn profile_score_weighted(run: &DynamicRun, weights: &[f64; 6]) -> Option<f64> {
    let mut score = 0.0;
    for (g, ls) in [&run.rot, &run.acc].into_iter().enumerate() {
        score += ls
            .ln_residual_variance()?
            .iter()
            .zip(&weights[3 * g..3 * g + 3])
            .map(|(v, w)| w * v)
            .sum::<f64>();
    }
    Some(score)
}

/// The fit at a lag already learned (`lag_s`, one standard deviation `sd_ln` in ln(lag)),
/// without searching: three refits instead of ~22. For progress estimates between the
/// decisions, which search (see `Estimator::estimate_progress`).
pub fn fit_at(run: &DynamicRun, lags: &[f64], sd_ln: f64) -> Option<LagFit> {
    fit_at_centred(run, lags, sd_ln, &Vector3::zeros())
}

/// [`fit_at`] with the terms at the velocity of the centre, the IMU at `imu_m` from it (see
/// [`DynamicRun::refit_with`]).
///
/// `lags`: one for all thrusters, or one each (moved together for the sensitivity: a
/// progress figure, not the decision's).
pub fn fit_at_centred(
    run: &DynamicRun,
    lags: &[f64],
    sd_ln: f64,
    imu_m: &Vector3<f64>,
) -> Option<LagFit> {
    let scaled = |k: f64| -> Vec<f64> { lags.iter().map(|l| l.max(1e-4) * k).collect() };
    let refitter = run.refitter(imu_m)?;
    let refit = |l: &[f64]| refitter.refit(l);
    Some(LagFit {
        lag_s: lags.iter().sum::<f64>() / lags.len().max(1) as f64,
        run: refit(lags)?,
        above: refit(&scaled(STEP.exp()))?,
        below: refit(&scaled((-STEP).exp()))?,
        sd_ln,
        profile: Vec::new(),
        per_thruster: Vec::new(),
        per_thruster_evidence: 0.0,
        per_thruster_cov: Vec::new(),
        per_thruster_floor_ln: 0.0,
        unkept_per_thruster: None,
        groups: None,
    })
}

/// The common lag of all thrusters that best explains `run`'s logged samples, searched over
/// `range`. None without a log or before the fit has residual degrees of freedom.
pub fn learn_common_lag(run: &DynamicRun, range: &LagRange) -> Option<LagFit> {
    learn_common_lag_centred(run, range, &Vector3::zeros())
}

/// [`learn_common_lag`] with the terms at the velocity of the centre, the IMU at `imu_m` from
/// it (see [`DynamicRun::refit_with`]).
pub fn learn_common_lag_centred(
    run: &DynamicRun,
    range: &LagRange,
    imu_m: &Vector3<f64>,
) -> Option<LagFit> {
    learn_common_lag_weighted(run, range, imu_m, &ALL_OUTPUTS)
}

/// [`learn_common_lag_centred`] scored by [`profile_score_weighted`] with `weights`.
pub fn learn_common_lag_weighted(
    run: &DynamicRun,
    range: &LagRange,
    imu_m: &Vector3<f64>,
    weights: &[f64; 6],
) -> Option<LagFit> {
    let refitter = run.refitter(imu_m)?;
    let profile_score = |r: &DynamicRun| profile_score_weighted(r, weights);
    let refit = |lag: f64| refitter.refit(&[lag]);
    let (lo, hi) = (
        range.min_s.max(1e-4).ln(),
        range.max_s.max(range.min_s * 1.01).ln(),
    );
    let grid = range.grid.max(3);
    let mut profile = Vec::with_capacity(grid + 24);
    let mut best: Option<(f64, f64, DynamicRun)> = None;
    let eval =
        |x: f64, profile: &mut Vec<(f64, f64)>, best: &mut Option<(f64, f64, DynamicRun)>| {
            let lag = x.exp();
            let fit = refit(lag)?;
            let score = profile_score(&fit)?;
            profile.push((lag, score));
            if best.as_ref().is_none_or(|(_, s, _)| score < *s) {
                *best = Some((x, score, fit));
            }
            Some(score)
        };
    let step = (hi - lo) / (grid - 1) as f64;
    let mut scores = Vec::with_capacity(grid);
    for k in 0..grid {
        scores.push(eval(lo + step * k as f64, &mut profile, &mut best)?);
    }
    let k_best = (0..grid)
        .min_by(|&a, &b| scores[a].total_cmp(&scores[b]))
        .unwrap_or(0);
    // Golden section inside the best point's neighbours (one side only at an end of the range).
    let (mut a, mut b) = (
        lo + step * k_best.saturating_sub(1) as f64,
        lo + step * (k_best + 1).min(grid - 1) as f64,
    );
    let phi = 0.5 * (5f64.sqrt() - 1.0);
    let tol = (1.0 + range.tolerance.max(1e-6)).ln();
    let (mut c, mut d) = (b - phi * (b - a), a + phi * (b - a));
    let (mut fc, mut fd) = (
        eval(c, &mut profile, &mut best)?,
        eval(d, &mut profile, &mut best)?,
    );
    while b - a > tol {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - phi * (b - a);
            fc = eval(c, &mut profile, &mut best)?;
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + phi * (b - a);
            fd = eval(d, &mut profile, &mut best)?;
        }
    }
    let (x, s0, fit) = best?;
    let above = refit((x + STEP).exp())?;
    let below = refit((x - STEP).exp())?;
    let (sa, sb) = (profile_score(&above)?, profile_score(&below)?);
    let rows = fit.samples() as f64;
    // ln L = -(rows / 2) * score, so var(ln lag) = 2 / (rows * score'').
    let curvature = (sa + sb - 2.0 * s0) / (STEP * STEP);
    let sd_ln = if curvature > 0.0 && rows > 0.0 {
        (2.0 / (rows * curvature)).sqrt()
    } else {
        f64::INFINITY
    };
    Some(LagFit {
        lag_s: x.exp(),
        run: fit,
        above,
        below,
        sd_ln,
        profile,
        per_thruster: Vec::new(),
        per_thruster_evidence: 0.0,
        per_thruster_cov: Vec::new(),
        per_thruster_floor_ln: 0.0,
        unkept_per_thruster: None,
        groups: None,
    })
}

#[cfg(test)]
pub(super) mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::navigation::DepthAid;

    /// A run of `n` (2 or 3) thrusters fed a synthetic response to commands stepping every
    /// 0.3 s, `samples` at 200 Hz in 1 s segments.
    pub(in super::super) fn logged_run(n: usize, lag_s: f64, samples: usize) -> DynamicRun {
        let mut run = DynamicRun::new(
            n,
            lag_s,
            1.0,
            &Vector3::new(0.0, 0.0, -9.80665),
            DepthAid::default(),
        )
        .with_log(64);
        for k in 0..samples {
            let t = k as f64 * 0.005;
            let step = (t / 0.3) as usize;
            let u = [
                if step.is_multiple_of(2) { 0.6 } else { -0.6 },
                if step % 4 < 2 { 0.4 } else { -0.4 },
                if step.is_multiple_of(3) { 0.0 } else { 0.8 },
            ];
            let gyro = Vector3::new(
                0.1 * (3.0 * t).sin(),
                0.05 * (1.7 * t).cos(),
                0.02 * t.sin(),
            );
            let f = Vector3::new(
                0.2 * (2.0 * t).sin(),
                0.1 * t.cos(),
                -9.80665 + 0.05 * (5.0 * t).sin(),
            );
            run.push(t, &gyro, &f, Some(5.0), Some(&u[..n]));
        }
        run
    }

    #[test]
    fn a_refit_at_the_same_lag_is_the_same_fit() {
        let run = logged_run(2, 0.1, 1200);
        let again = run.refit(&[0.1]).unwrap();
        let rest = [0.01; 6];
        let (a, b) = (
            run.solve(&rest, 0.0, 0.0, None),
            again.solve(&rest, 0.0, 0.0, None),
        );
        let diff = (&a.b - &b.b).abs().max();
        assert!(diff <= 1e-9 * a.b.abs().max(), "B differs by {diff}");
        let diff = (&a.terms.coefficients - &b.terms.coefficients).abs().max();
        assert!(
            diff <= 1e-9 * a.terms.coefficients.abs().max().max(1.0),
            "terms differ by {diff}"
        );
    }
}
