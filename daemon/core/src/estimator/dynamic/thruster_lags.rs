//! A lag per thruster, where the data says the thrusters differ.
//!
//! Why: a reconfigurable vehicle gets thrusters of more than one make, and one lag for all is
//! then wrong for every one of them. AMOUR-5 with its thrusters alternating 0.05 and 0.15 s,
//! noise-free, learned one lag of 0.060 s and a model 0.40 / 0.41 off under bounds of 0.033 /
//! 0.026; with 0.03 and 0.2 s, 0.55 off (docs/study.md, "Thrusters of two makes").
//!
//! How: from the common lag ([`super::lag_search`]), a pre-test tries each thruster's lag
//! alone at half and twice the common one, then (if that is not evidence enough) takes one
//! Newton step on all of them: lags a fifth apart, or thrusters that push alike in pairs,
//! are not found by one lag moved alone. The per-thruster lags are searched further and
//! kept only when they explain the data better than one lag by `min_evidence` in the log
//! likelihood ratio (N - 1 more parameters: a vehicle of one make gave 0, one of two makes
//! thousands), so a vehicle of one make keeps the common lag's fit to the digit. The search:
//! two sweeps of each lag alone over the range's grid, one of every pair moved together,
//! then Newton steps on all of them. Their joint covariance (the profile's Hessian) and a
//! floor on each widen B's standard errors and bounds through B's sensitivity to each lag.
//! Lags found alike (within `MIN_SPREAD`) are not kept, but their fit's difference from the
//! common lag's is in the bound.

use std::cell::Cell;

use nalgebra::{DMatrix, DVector, Dyn, SymmetricEigen, Vector3};

use super::lag_search::{LagFit, LagRange, ThrusterLag, STEP};
use super::DynamicRun;

/// Each output's residual variance is floored, in the search's score, at this fraction of
/// its group's largest at the common lag. Why: noise-free, the rows the common lag already
/// fits exactly (AMOUR-5 with its three up-thrusters at the common 0.15 s: heave, roll,
/// pitch) have variances near zero, and the log of those dominated the score: moving the
/// forward thrusters toward their true 0.05 s raised it, and no lag per thruster was found.
/// With noise every variance is far above the floor.
const SCORE_FLOOR: f64 = 1e-4;

/// The floor once the search has converged at [`SCORE_FLOOR`], where an output's variance at
/// the lags found is within [`FINE_TRIGGER`] times it. Why: the floor that let the search
/// start also flattened the outputs the lags explain best, and the rest's misfit then placed
/// them: eight_vectored_two_makes (0.03 / 0.2 s), noise-free, shaped, came out with its
/// 0.2 s lags at 0.2043-0.2064 s and its acceleration rows 0.039 off, and the truth scored
/// 20 worse than them at 1e-4 but 1397 better at 1e-8; searched again from there at 1e-8
/// they come out at 0.1989-0.1995 s and the model 0.015 / 0.024 off, what the true lags gave
/// (that rest was the first sample's lag, since fixed: 0.2004-0.2012 s, 0.004 / 0.003).
/// Searched at 1e-8 from the start, the lags stuck at 0.177 (docs/study.md, "The two makes'
/// lags searched again below the floor").
const FINE_SCORE_FLOOR: f64 = 1e-8;

/// See [`FINE_SCORE_FLOOR`]. At a realistic IMU it still fires where one lag for two makes
/// left the common lag's largest variance, and so the floor, far above the noise: over the
/// two-make cases of docs/study.md, seeds 1-5, each case's mean error moved by at most 0.001.
const FINE_TRIGGER: f64 = 100.0;

/// Newton steps on all lags together after the sweep, at most. Why both: eight_vectored's
/// thrusters push alike in pairs, so their lags trade against each other, and one thruster
/// at a time crawled (eight sweeps left lags of 0.15 s at 0.11 and the model 0.11 off); the
/// sweep alone starts the Newton steps inside their basin.
const NEWTON_STEPS: usize = 8;

/// Per-thruster lags are kept only when the longest is this much longer than the shortest
/// (15 %). Why not less: noise-free, the T200's curve on AMOUR-5 (not linearized) left its
/// one make's lags 0.093-0.102 s apart, evidence 331, and the battery test's first model
/// moved; thrusters 0.10 and 0.12 s apart are found (0.100-0.121 s).
const MIN_SPREAD: f64 = 0.15;

/// The factors on the common lag each thruster's is tried at first, alone.
const PRE_TEST_FACTORS: [f64; 2] = [0.5, 2.0];

/// The finite-difference step in ln(lag) of the Newton steps' gradient and Hessian (5 %).
const H: f64 = 0.05;

/// The finite-difference step of the Newton steps at [`FINE_SCORE_FLOOR`] (1 %). Why: with
/// the floor lowered the valley is sharp, and at 5 % the steps stopped with
/// eight_vectored_two_makes' 0.2 s lags at 0.202-0.208 s; at 2 / 1 / 0.5 %: 0.198-0.200,
/// 0.199-0.1995, 0.1988-0.1995 s.
const FINE_H: f64 = 0.01;

/// The largest Newton step in any ln(lag) (a factor 2).
const MAX_STEP: f64 = 0.693;

/// The Newton step's floor on the local form's curvature, a share of its largest: a flat or
/// curved-down direction moves by the gradient, not to infinity. The directions under it are
/// the ones searched alone where the steps stall.
const CURVATURE_FLOOR: f64 = 1e-2;

/// The per-thruster search's outcome, kept or not.
#[derive(Debug, Clone)]
pub struct ThrusterLagSearch {
    /// ln likelihood ratio of the per-thruster lags over the common one.
    pub log_likelihood_ratio: f64,
    /// The fit, kept: `common` with its run replaced and `per_thruster` set.
    pub fit: Option<LagFit>,
    /// The per-thruster fit found but not kept (its lags alike): what the bound counts.
    pub unkept: Option<DynamicRun>,
}

/// Search a lag per thruster from `common` (the common lag's fit of `run`), the terms at the
/// velocity of the centre with the IMU at `imu_m`. The per-thruster fit is returned in
/// `fit` when its ln likelihood ratio over the common lag exceeds `min_evidence`. None
/// without a log or residual degrees of freedom.
#[allow(clippy::too_many_arguments)]
pub fn search_thruster_lags(
    run: &DynamicRun,
    common: &LagFit,
    range: &LagRange,
    imu_m: &Vector3<f64>,
    min_evidence: f64,
    floor_ln: f64,
    start: Option<&[f64]>,
) -> Option<ThrusterLagSearch> {
    let n = run.thrusters();
    if n < 2 {
        return None;
    }
    let (lo, hi) = (
        range.min_s.max(1e-4).ln(),
        range.max_s.max(range.min_s * 1.01).ln(),
    );
    let at_common = variances(&common.run)?;
    let floor_at = |fraction: f64| -> [f64; 6] {
        std::array::from_fn(|a| {
            let g = 3 * (a / 3);
            fraction * at_common[g..g + 3].iter().fold(0.0f64, |m, v| m.max(*v))
        })
    };
    // The score's floor and the Newton steps' finite-difference step: coarse, then fine
    // once the search has converged (`FINE_SCORE_FLOOR`).
    let stage = Cell::new(Stage {
        floor: floor_at(SCORE_FLOOR),
        h: H,
    });
    let score_with = |fit: &DynamicRun, floor: &[f64; 6]| -> Option<f64> {
        let v = variances(fit)?;
        Some((0..6).map(|a| v[a].max(floor[a]).max(1e-300).ln()).sum())
    };
    let score_of = |fit: &DynamicRun| score_with(fit, &stage.get().floor);
    let refitter = run.refitter(imu_m)?;
    let refit = |lags: &[f64]| refitter.refit(lags);
    let common_score = score_of(&common.run)?;
    let mut best = Best {
        lags: vec![common.lag_s; n],
        score: common_score,
        run: common.run.clone(),
    };
    let try_lags = |best: &mut Best, trial: Vec<f64>| best.try_lags(trial, &refit, &score_of);
    let rows = best.run.samples() as f64;
    let lags_at = |x: &[f64]| -> Vec<f64> { x.iter().map(|v| v.clamp(lo, hi).exp()).collect() };
    // Lags found on this log before it was changed, where the caller has them: a place to
    // search from besides the common lag, kept only where it scores better. Why: the
    // tether's start velocity moved into eight_vectored_lag100_120ms's log, noise-free, the
    // search from the common lag (0.1195 s) stopped at 0.115 / 0.141 s on the vectored
    // thrusters, 0.086 / 0.138 off, where the lags found before the move (0.100 / 0.120)
    // score 15 units of ln likelihood per output better and fit 0.0007 / 0.0004 off
    // (docs/study.md, "The lags searched again after the tow").
    if let Some(start) = start.filter(|s| s.len() == n && s.iter().all(|l| l.is_finite())) {
        let x: Vec<f64> = start.iter().map(|l| l.max(1e-4).ln()).collect();
        try_lags(&mut best, lags_at(&x))?;
    }
    // The score's local quadratic form at `best`, in ln(lag) by finite differences: each
    // output's residual variance over its value here, summed (its gradient here is the
    // profile's; its Hessian is the profile's without the -(v'/v)^2 part, which noise-free,
    // where the residual falls toward zero at the truth, made the finite-difference Hessian
    // indefinite).
    let local_form = |best: &Best| -> Option<(DVector<f64>, DMatrix<f64>)> {
        let Stage { floor, h } = stage.get();
        let x: Vec<f64> = best.lags.iter().map(|l| l.ln()).collect();
        let here = variances(&best.run)?;
        let moved = |d: &[(usize, f64)]| {
            let mut y = x.clone();
            for &(i, dx) in d {
                y[i] += dx;
            }
            let v = variances(&refit(&lags_at(&y))?)?;
            Some(
                (0..6)
                    .map(|a| v[a].max(floor[a]) / here[a].max(floor[a]).max(1e-300))
                    .sum::<f64>(),
            )
        };
        let centre = 6.0;
        let mut plus = vec![0.0; n];
        let mut grad = DVector::zeros(n);
        let mut hessian = DMatrix::zeros(n, n);
        for i in 0..n {
            let (p, m) = (moved(&[(i, h)])?, moved(&[(i, -h)])?);
            plus[i] = p;
            grad[i] = (p - m) / (2.0 * h);
            hessian[(i, i)] = (p + m - 2.0 * centre) / (h * h);
        }
        for i in 0..n {
            for j in 0..i {
                let pp = moved(&[(i, h), (j, h)])?;
                let hij = (pp - plus[i] - plus[j] + centre) / (h * h);
                hessian[(i, j)] = hij;
                hessian[(j, i)] = hij;
            }
        }
        Some((grad, hessian))
    };
    // Along a Newton step `dx` from `best`: the step's length halves while the score does
    // not fall, and doubles while it goes on falling (the local form's curvature overstates
    // the profile's far from its minimum, and noise-free the full steps crawled). (Improved
    // by at least half a unit of ln likelihood, moved at all.)
    let line_search = |best: &mut Best, dx: &DVector<f64>| -> Option<(bool, bool)> {
        let x: Vec<f64> = best.lags.iter().map(|l| l.ln()).collect();
        let (mut improved, mut moved_at_all) = (false, false);
        let mut scale = 1.0;
        let largest = dx.amax().max(1e-12);
        for _ in 0..8 {
            let y: Vec<f64> = x
                .iter()
                .zip(dx.iter())
                .map(|(a, d)| a + scale * d)
                .collect();
            let gain = try_lags(best, lags_at(&y))? * rows / 2.0;
            if gain > 0.0 {
                improved |= gain >= 0.5;
                moved_at_all = true;
                if scale < 1.0 || 2.0 * scale * largest > MAX_STEP {
                    break;
                }
                scale *= 2.0;
            } else if moved_at_all {
                break;
            } else {
                scale *= 0.5;
            }
        }
        Some((improved, moved_at_all))
    };
    // First each thruster's lag alone at half and twice the common one: enough to tell a
    // vehicle of one make from one whose makes differ by a factor of two or more (a vehicle
    // of one make then costs 2 N refits, and the Newton probe below N (N + 3) / 2 more).
    for i in 0..n {
        for factor in PRE_TEST_FACTORS {
            let mut trial = best.lags.clone();
            trial[i] = (common.lag_s * factor).clamp(lo.exp(), hi.exp());
            try_lags(&mut best, trial)?;
        }
    }
    let log_likelihood_ratio = |best: &Best| rows / 2.0 * (common_score - best.score);
    // Lags that differ by tens of per cent, not a factor of two, or thrusters that push alike
    // in pairs (eight_vectored), where one lag moved alone fits worse whichever way: one
    // Newton step on all of them from there. Why: eight_vectored with its thrusters
    // alternating 0.1 and 0.15 s, noise-free, was 0.24 off under bounds of 0.06 / 0.04 with
    // no evidence found; AMOUR-5 at 0.1 and 0.12 s 0.09 off under 0.02.
    if log_likelihood_ratio(&best) <= min_evidence {
        let (grad, hessian) = local_form(&best)?;
        if let Some(dx) = newton_step(&hessian, &grad) {
            line_search(&mut best, &dx)?;
        }
    }
    if log_likelihood_ratio(&best) <= min_evidence {
        return Some(ThrusterLagSearch {
            log_likelihood_ratio: log_likelihood_ratio(&best),
            fit: None,
            unkept: None,
        });
    }
    // Then two sweeps of each lag over the whole range (a factor 4 each way from the common
    // lag left eight_vectored's 0.2 s thrusters beside 0.03 s ones at 0.16), the second from
    // where the first left every lag: thrusters that push alike move in pairs, and the first
    // of a pair was placed while its partner still had the common lag (the same vehicle,
    // noise-free: two of its 0.2 s thrusters stayed at 0.11-0.12 and the model 0.15 / 0.27
    // off). Then every pair moved together to each grid lag, the others held: a pair that
    // pushes alike trades its lags, and neither moves alone (eight_vectored with 0.15 and
    // 0.05 s thrusters, noise-free: a pair left at 0.16 and 0.17).
    let grid = range.grid.max(3);
    let step = (hi - lo) / (grid - 1) as f64;
    let grid_lag = |k: usize| (lo + step * k as f64).exp();
    for _ in 0..2 {
        for i in 0..n {
            for k in 0..grid {
                let mut trial = best.lags.clone();
                trial[i] = grid_lag(k);
                try_lags(&mut best, trial)?;
            }
        }
    }
    for i in 0..n {
        for j in 0..i {
            for k in 0..grid {
                let mut trial = best.lags.clone();
                trial[i] = grid_lag(k);
                trial[j] = trial[i];
                try_lags(&mut best, trial)?;
            }
        }
    }
    // Where a Newton step stalls: each of the local form's eigen-directions alone, downhill
    // from `best`, its first step the finite-difference step in its largest lag. Why: the
    // step floors the curvature at a hundredth of the largest, so a direction far flatter
    // than the sharpest (or curved down) moves by a hundredth of what it needs, and a valley
    // along it looked like a minimum: eight_vectored_lag100_120ms asked for at its release
    // (noise-free, the vehicle still rising) stopped with its four vertical lags 6-8 % short
    // (0.0935 / 0.1107 s), where the score falls all the way to the true 0.1 / 0.12 s along
    // that one direction, 3289 units of ln likelihood better (docs/study.md, "The lags of two
    // makes on a rising vehicle").
    // (improved, moved at all), as the line search says.
    let descend_each = |best: &mut Best, grad: &DVector<f64>, hessian: &DMatrix<f64>| {
        let (mut improved, mut moved) = (false, false);
        let Some((eig, top)) = curvature(hessian, grad) else {
            return Some((improved, moved));
        };
        let h = stage.get().h;
        for k in 0..n {
            // Only the directions the step's floor held back: the others it took in full.
            if eig.eigenvalues[k] >= top * CURVATURE_FLOOR {
                continue;
            }
            let v = eig.eigenvectors.column(k).into_owned();
            let slope = v.dot(grad);
            if slope == 0.0 {
                continue;
            }
            let dir = v * -slope.signum();
            let dx = &dir * (h / dir.amax().max(1e-12));
            let (i, m) = line_search(best, &dx)?;
            (improved, moved) = (improved || i, moved || m);
        }
        Some((improved, moved))
    };
    // Then Newton steps on all of them from where the sweeps left them; the last Hessian is
    // the lags' joint information.
    let newton = |best: &mut Best| -> Option<DMatrix<f64>> {
        let mut hessian = DMatrix::zeros(n, n);
        let mut rescued = false;
        for step in 0..=NEWTON_STEPS {
            let (mut grad, h) = local_form(best)?;
            hessian = h;
            if step == NEWTON_STEPS {
                break;
            }
            let stalled = match newton_step(&hessian, &grad) {
                None => true,
                Some(dx) => match line_search(best, &dx)? {
                    (true, true) => false,
                    (_, moved) => {
                        // Moved by less than half a unit of ln likelihood, or not at all: the
                        // form where the lags now are.
                        if moved {
                            (grad, hessian) = local_form(best)?;
                        }
                        true
                    }
                },
            };
            if !stalled {
                continue;
            }
            // Once per stage: each direction alone, and on from there when one paid.
            if rescued {
                break;
            }
            rescued = true;
            match descend_each(best, &grad, &hessian)? {
                (true, _) => {}
                (false, moved) => {
                    if moved {
                        // Moved a little: the form where the lags now are, for the covariance.
                        hessian = local_form(best)?.1;
                    }
                    break;
                }
            }
        }
        Some(hessian)
    };
    let mut hessian = newton(&mut best)?;
    // Where the floor holds an output's variance at the lags found (noise-free: an output
    // those lags explain to within the floor), the rows it flattens no longer pull, and the
    // others' misfit placed the lags: once more with the floor lowered, from there. Only
    // for lags found apart: lags found alike are one make and not kept, and searched finer
    // they only follow the misfit further, which their difference then adds to the bound
    // (amour5 split, noise-free: the acceleration rows' lag-floor part 0.095 -> 0.25, and
    // the model refused).
    let coarse = stage.get().floor;
    let at_best = variances(&best.run)?;
    if spread_apart(&best.lags) && (0..6).any(|a| at_best[a] < FINE_TRIGGER * coarse[a]) {
        stage.set(Stage {
            floor: floor_at(FINE_SCORE_FLOOR),
            h: FINE_H,
        });
        best.score = score_of(&best.run)?;
        hessian = newton(&mut best)?;
    }
    let Best {
        lags,
        score,
        run: fitted,
    } = best;
    // ln L = -(rows / 2) * score, so cov(ln lags) = 2 / rows * Hessian^-1. Where the
    // finite-difference Hessian is not positive definite (noise-free, the score's valley is
    // too sharp for a 5 % step) each lag's own curvature over the wider STEP is used alone.
    // (The search only lowers the score, so the evidence is still above `min_evidence`.)
    let cov = psd_inverse(&hessian).map(|inv| inv * (2.0 / rows.max(1.0)));
    let mut per_thruster = Vec::with_capacity(n);
    for i in 0..n {
        let x = lags[i].ln();
        let moved = |dx: f64| {
            let mut l = lags.clone();
            l[i] = (x + dx).exp();
            refit(&l)
        };
        let (above, below) = (moved(STEP)?, moved(-STEP)?);
        let sd_ln = match cov.as_ref() {
            Some(c) => c[(i, i)].max(0.0).sqrt(),
            None => {
                let (sa, sb) = (score_of(&above)?, score_of(&below)?);
                let curvature = (sa + sb - 2.0 * score) / (STEP * STEP);
                if curvature > 0.0 && rows > 0.0 {
                    (2.0 / (rows * curvature)).sqrt()
                } else {
                    f64::INFINITY
                }
            }
        };
        per_thruster.push(ThrusterLag {
            lag_s: lags[i],
            sd_ln,
            above,
            below,
        });
    }
    // The evidence at the floor the common lag was scored at.
    let log_likelihood_ratio = rows / 2.0 * (common_score - score_with(&fitted, &coarse)?);
    // Lags that came out alike are one make: noise-free, any misfit (an asymmetry, a curve)
    // is evidence beyond the limit, and the lags then take it up without differing (AMOUR-5's
    // thrusters at 0.03 s: all 0.030, evidence 359; with its gains fitted split, its acceleration
    // rows 0.13 off).
    if !spread_apart(&lags) {
        return Some(ThrusterLagSearch {
            log_likelihood_ratio,
            fit: None,
            unkept: Some(fitted),
        });
    }
    Some(ThrusterLagSearch {
        log_likelihood_ratio,
        fit: Some(LagFit {
            lag_s: lags.iter().sum::<f64>() / n as f64,
            run: fitted,
            per_thruster,
            per_thruster_cov: cov.map_or(Vec::new(), |c| c.transpose().as_slice().to_vec()),
            per_thruster_evidence: log_likelihood_ratio,
            per_thruster_floor_ln: floor_ln,
            ..common.clone()
        }),
        unkept: None,
    })
}

/// What the per-thruster search scores and steps with: each output's variance floor and the
/// finite-difference step in ln(lag).
#[derive(Debug, Clone, Copy)]
struct Stage {
    floor: [f64; 6],
    h: f64,
}

/// Whether the longest of `lags` is at least [`MIN_SPREAD`] longer than the shortest: lags
/// of more than one make.
fn spread_apart(lags: &[f64]) -> bool {
    let (shortest, longest) = lags
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), l| (a.min(*l), b.max(*l)));
    longest >= shortest * (1.0 + MIN_SPREAD)
}

/// The Newton step -H^-1 g on the profile, with H's eigenvalues floored at a hundredth of its
/// largest (a flat or curved-down direction moves by the gradient, not to infinity) and every
/// component clamped to [`MAX_STEP`]. None when H is not finite.
fn newton_step(hessian: &DMatrix<f64>, grad: &DVector<f64>) -> Option<DVector<f64>> {
    let (eig, top) = curvature(hessian, grad)?;
    let floor = top * CURVATURE_FLOOR;
    let g = eig.eigenvectors.transpose() * grad;
    let scaled = DVector::from_fn(g.len(), |k, _| -g[k] / eig.eigenvalues[k].max(floor));
    let mut dx = &eig.eigenvectors * scaled;
    let largest = dx.amax();
    if largest > MAX_STEP {
        dx *= MAX_STEP / largest;
    }
    Some(dx)
}

/// The local form's eigen-decomposition and its largest curvature (by magnitude); None where
/// the form or the gradient is not finite (an eigen-decomposition of NaN need not end) or the
/// form is zero.
fn curvature(
    hessian: &DMatrix<f64>,
    grad: &DVector<f64>,
) -> Option<(SymmetricEigen<f64, Dyn>, f64)> {
    if !hessian.iter().chain(grad.iter()).all(|v| v.is_finite()) {
        return None;
    }
    let eig = hessian.clone().symmetric_eigen();
    let top = eig.eigenvalues.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    (top > 0.0).then_some((eig, top))
}

/// The inverse of the profile's Hessian where it is positive definite; None otherwise (a
/// direction the data does not fix: the lags are then not kept apart).
fn psd_inverse(hessian: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    if !hessian.iter().all(|v| v.is_finite()) {
        return None;
    }
    let eig = hessian.clone().symmetric_eigen();
    if eig.eigenvalues.iter().any(|v| *v <= 0.0) {
        return None;
    }
    let inv = DMatrix::from_diagonal(&eig.eigenvalues.map(|v| 1.0 / v));
    Some(&eig.eigenvectors * inv * eig.eigenvectors.transpose())
}

/// The six outputs' residual variances of `run` (DOF order); None while one has no residual
/// degrees of freedom.
fn variances(run: &DynamicRun) -> Option<[f64; 6]> {
    let (r, a) = (run.rot.residual_variance()?, run.acc.residual_variance()?);
    Some([r[0], r[1], r[2], a[0], a[1], a[2]])
}

/// The best lags found so far, their score and fit.
struct Best {
    lags: Vec<f64>,
    score: f64,
    run: DynamicRun,
}

impl Best {
    /// Fit at `trial` and keep it if it scores lower: by how much (0 when not kept).
    fn try_lags(
        &mut self,
        trial: Vec<f64>,
        refit: &impl Fn(&[f64]) -> Option<DynamicRun>,
        score_of: &impl Fn(&DynamicRun) -> Option<f64>,
    ) -> Option<f64> {
        let run = refit(&trial)?;
        let score = score_of(&run)?;
        if score >= self.score {
            return Some(0.0);
        }
        let gain = self.score - score;
        *self = Best {
            lags: trial,
            score,
            run,
        };
        Some(gain)
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{DMatrix, DVector};

    use super::{newton_step, psd_inverse, MAX_STEP};

    #[test]
    fn a_newton_step_reaches_a_quadratics_minimum_and_never_climbs() {
        // f = (x0 - 0.1)^2 + 4 (x1 + 0.05)^2 from 0: g = (-0.2, 0.4), H = diag(2, 8).
        let h = DMatrix::from_diagonal(&DVector::from_vec(vec![2.0, 8.0]));
        let g = DVector::from_vec(vec![-0.2, 0.4]);
        let dx = newton_step(&h, &g).unwrap();
        assert!(
            (dx[0] - 0.1).abs() < 1e-12 && (dx[1] + 0.05).abs() < 1e-12,
            "{dx}"
        );
        // Curved down along x1: that direction follows the gradient down, scaled by the
        // floored curvature, instead of jumping to the maximum.
        let h = DMatrix::from_diagonal(&DVector::from_vec(vec![2.0, -8.0]));
        let dx = newton_step(&h, &g).unwrap();
        assert!(dx.dot(&g) < 0.0, "{dx}");
        assert!(dx.amax() <= MAX_STEP + 1e-12, "{dx}");
        assert!(newton_step(&h, &DVector::from_vec(vec![f64::NAN, 0.0])).is_none());
    }

    #[test]
    fn only_a_positive_definite_hessian_gives_a_covariance() {
        let h = DMatrix::from_row_slice(2, 2, &[4.0, 1.0, 1.0, 3.0]);
        let inv = psd_inverse(&h).unwrap();
        assert!((&h * inv - DMatrix::identity(2, 2)).amax() < 1e-12);
        let saddle = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert!(psd_inverse(&saddle).is_none());
    }
}
