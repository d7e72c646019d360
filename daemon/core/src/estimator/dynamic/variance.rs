//! The variances the dynamic fit reports: the noise level per axis and the honest variance
//! of a combination of coefficients.

use super::segmented_ls::SegmentedSolution;

/// A residual-based noise estimate is trusted once it rests on this many degrees of freedom.
pub(super) const MIN_RESIDUAL_DOF: u64 = 10;

/// The cluster-robust covariance is used once it rests on this many segments: with S clusters
/// it has S - 1 degrees of freedom, and with one it is zero.
const MIN_CLUSTERS: usize = 3;

/// The variance of sum_i w_i theta_i on output `a`: (i.i.d. Gram diagonal, honest variance,
/// i.i.d. variance). The honest one is the larger of the i.i.d. and the cluster-robust
/// variance once enough segments back the latter: the robust one alone is noisy with few
/// clusters, and never the smaller of the two in expectation when residuals are positively
/// autocorrelated.
pub(super) fn combination_var(
    sol: &SegmentedSolution,
    sigma: f64,
    a: usize,
    w: &[(usize, f64)],
) -> (f64, f64, f64) {
    let (mut d, mut robust) = (0.0, 0.0);
    for &(i, wi) in w {
        for &(j, wj) in w {
            d += wi * wj * sol.inverse(a)[(i, j)];
            robust += wi * wj * sol.robust_cov[a][(i, j)];
        }
    }
    let ols = sigma * sigma * d.max(0.0);
    let honest = if sol.clusters >= MIN_CLUSTERS {
        ols.max(robust)
    } else {
        ols
    };
    (d, honest, ols)
}

/// Noise per axis: the at-rest level, or the residual level when larger and well determined.
pub(super) fn group_sigma(sol: &SegmentedSolution, rest: &[f64]) -> [f64; 3] {
    match sol.residual_var {
        Some(var) if sol.residual_dof >= MIN_RESIDUAL_DOF => {
            std::array::from_fn(|a| rest[a].max(var[a].sqrt()))
        }
        _ => std::array::from_fn(|a| rest[a]),
    }
}
