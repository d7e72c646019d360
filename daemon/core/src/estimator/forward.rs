//! The forward regression y = B u + e, accumulated as normal equations.
//!
//! The thrust u is known exactly and the response y is noisy, so ordinary least squares on
//! this form is unbiased and, for Gaussian noise, efficient: Cov(row j of B) = sigma_j^2 G^-1
//! with G = sum x x^T. The paper's S * A = T puts the noisy y on the regressor side instead
//! (errors in variables), which biases it. Only G (N x N), H = sum x y^T (N x 3) and sum y^2
//! are kept, so a fresh estimate after every pulse costs one small solve, never a refit.

use nalgebra::{DMatrix, Vector3};

use super::linalg::sym_pinv;

/// Normal equations for one 3-axis sensor group (rotation or acceleration).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ForwardLs {
    gram: DMatrix<f64>,
    cross: DMatrix<f64>,
    yy: [f64; 3],
    rows: u64,
}

/// A solved forward regression for one sensor group.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ForwardSolution {
    /// Estimated effectiveness, 3 x N (row per sensor axis, column per regressor).
    pub b: DMatrix<f64>,
    /// Pseudo-inverse of the Gram matrix: the coefficient covariance per unit noise variance.
    pub gram_inv: DMatrix<f64>,
    /// Numerical rank of the Gram matrix (N once every regressor has been excited).
    pub rank: usize,
    /// Residual variance per axis, when there are more rows than unknowns.
    pub residual_var: Option<[f64; 3]>,
    /// Degrees of freedom of the residual (rows - rank).
    pub residual_dof: u64,
}

impl ForwardLs {
    /// Empty accumulator for `n` regressors.
    pub fn new(n: usize) -> Self {
        ForwardLs {
            gram: DMatrix::zeros(n, n),
            cross: DMatrix::zeros(n, 3),
            yy: [0.0; 3],
            rows: 0,
        }
    }

    pub fn regressors(&self) -> usize {
        self.gram.nrows()
    }

    pub fn rows(&self) -> u64 {
        self.rows
    }

    pub fn gram(&self) -> &DMatrix<f64> {
        &self.gram
    }

    /// Add one measurement row: regressor `x` (length N) and 3-axis response `y`.
    /// Non-finite input is ignored, so one bad sample cannot poison the accumulated state.
    pub fn add(&mut self, x: &[f64], y: &Vector3<f64>) {
        let n = self.gram.nrows();
        debug_assert_eq!(x.len(), n);
        if x.len() != n || !x.iter().all(|v| v.is_finite()) || !y.iter().all(|v| v.is_finite()) {
            return;
        }
        for (i, &xi) in x.iter().enumerate() {
            if xi == 0.0 {
                continue; // round-robin rows are mostly zeros
            }
            for (j, &xj) in x.iter().enumerate() {
                self.gram[(i, j)] += xi * xj;
            }
            for a in 0..3 {
                self.cross[(i, a)] += xi * y[a];
            }
        }
        for a in 0..3 {
            self.yy[a] += y[a] * y[a];
        }
        self.rows += 1;
    }

    /// Add a whole pulse at once from its centred moments: every row of the pulse had the
    /// regressor `dir * s_k` and response `y_k`; `sxx` = sum (s_k - mean s)^2, `sxy` = sum
    /// (s_k - mean s)(y_k - mean y), `syy` = sum (y_k - mean y)^2, over `samples` rows.
    ///
    /// Centring removes a per-pulse constant (the vehicle still turning slowly from the last
    /// pulse, a drifting bias), which would otherwise leak into B; it costs one degree of freedom
    /// per pulse.
    pub fn add_centred(
        &mut self,
        dir: &[f64],
        sxx: f64,
        sxy: &Vector3<f64>,
        syy: &Vector3<f64>,
        samples: u64,
    ) {
        let n = self.gram.nrows();
        if dir.len() != n
            || samples < 2
            || !sxx.is_finite()
            || !dir.iter().all(|v| v.is_finite())
            || !sxy.iter().chain(syy.iter()).all(|v| v.is_finite())
        {
            return;
        }
        for (i, &xi) in dir.iter().enumerate() {
            if xi == 0.0 {
                continue;
            }
            for (j, &xj) in dir.iter().enumerate() {
                self.gram[(i, j)] += sxx * xi * xj;
            }
            for a in 0..3 {
                self.cross[(i, a)] += xi * sxy[a];
            }
        }
        for a in 0..3 {
            self.yy[a] += syy[a];
        }
        self.rows += samples - 1;
    }

    /// Least-squares solution (minimum-norm where some regressor was never excited).
    pub fn solve(&self) -> ForwardSolution {
        let (gram_inv, rank) = sym_pinv(&self.gram);
        let coef = &gram_inv * &self.cross; // N x 3
        let b = coef.transpose();
        let residual_dof = self.rows.saturating_sub(rank as u64);
        let residual_var = (residual_dof > 0).then(|| {
            std::array::from_fn(|a| {
                // RSS = y'y - h' G+ h; clamp the round-off that can make it slightly negative.
                let h = self.cross.column(a);
                let explained = h.dot(&(&gram_inv * h));
                ((self.yy[a] - explained).max(0.0)) / residual_dof as f64
            })
        });
        ForwardSolution {
            b,
            gram_inv,
            rank,
            residual_var,
            residual_dof,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_recovery_without_noise() {
        let truth = DMatrix::from_row_slice(3, 2, &[1.0, -2.0, 0.5, 0.0, 0.0, 3.0]);
        let mut ls = ForwardLs::new(2);
        for x in [[1.0, 0.0], [-1.0, 0.0], [0.0, 0.5], [0.3, -0.7]] {
            let y = &truth * nalgebra::DVector::from_row_slice(&x);
            ls.add(&x, &Vector3::new(y[0], y[1], y[2]));
        }
        let s = ls.solve();
        assert_eq!(s.rank, 2);
        assert!((s.b - truth).norm() < 1e-12);
        // Only round-off of y^T y (about 10 here) remains.
        assert!(s.residual_var.unwrap().iter().all(|v| *v < 1e-12));
    }

    #[test]
    fn centred_pulses_ignore_a_constant_offset() {
        // y = b * s(t) + c_pulse: the per-pulse constant must not bias b.
        let b = [2.0, -1.0];
        let mut ls = ForwardLs::new(2);
        for (u, offset) in [([1.0, 0.0], 0.7), ([0.0, 1.0], -0.4), ([1.0, 1.0], 0.2)] {
            let (mut ss, mut s2, mut sy, mut sy2, mut ssy) = (0.0, 0.0, 0.0, 0.0, 0.0);
            let m = 10.0;
            for k in 0..10 {
                let s = k as f64 * 0.1;
                let y = (b[0] * u[0] + b[1] * u[1]) * s + offset;
                ss += s;
                s2 += s * s;
                sy += y;
                sy2 += y * y;
                ssy += s * y;
            }
            let sxx = s2 - ss * ss / m;
            let sxy = ssy - ss * sy / m;
            let syy = sy2 - sy * sy / m;
            ls.add_centred(
                &u,
                sxx,
                &Vector3::new(sxy, 0.0, 0.0),
                &Vector3::new(syy, 0.0, 0.0),
                10,
            );
        }
        let sol = ls.solve();
        assert!((sol.b[(0, 0)] - 2.0).abs() < 1e-9 && (sol.b[(0, 1)] + 1.0).abs() < 1e-9);
        assert_eq!(ls.rows(), 27);
    }

    #[test]
    fn unexcited_regressor_stays_zero() {
        let mut ls = ForwardLs::new(3);
        ls.add(&[1.0, 0.0, 0.0], &Vector3::new(2.0, 0.0, 0.0));
        let s = ls.solve();
        assert_eq!(s.rank, 1);
        assert!((s.b[(0, 0)] - 2.0).abs() < 1e-12);
        assert_eq!(s.b.column(1).norm(), 0.0);
        assert_eq!(s.b.column(2).norm(), 0.0);
    }

    #[test]
    fn non_finite_rows_are_ignored() {
        let mut ls = ForwardLs::new(1);
        ls.add(&[f64::NAN], &Vector3::new(1.0, 1.0, 1.0));
        ls.add(&[1.0], &Vector3::new(f64::INFINITY, 0.0, 0.0));
        assert_eq!(ls.rows(), 0);
        assert_eq!(ls.gram()[(0, 0)], 0.0);
    }
}
