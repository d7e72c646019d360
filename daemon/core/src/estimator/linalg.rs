//! Small dense linear-algebra helpers the estimator needs beyond nalgebra's.

use nalgebra::{DMatrix, SymmetricEigen};

/// Relative eigenvalue floor below which a Gram matrix direction counts as unexcited.
/// Well above f64 round-off for the matrix sizes here (<= 32), far below any real excitation.
pub const GRAM_REL_TOL: f64 = 1e-10;

/// Pseudo-inverse of a symmetric positive semi-definite matrix, and its numerical rank.
///
/// Cholesky first (the common, full-rank case, and cheap); eigen-decomposition only when the
/// matrix is singular, so that unexcited directions get a minimum-norm (zero) solution instead
/// of noise amplified by 1/0.
pub fn sym_pinv(g: &DMatrix<f64>) -> (DMatrix<f64>, usize) {
    let n = g.nrows();
    if n == 0 {
        return (DMatrix::zeros(0, 0), 0);
    }
    let max_diag = (0..n).map(|i| g[(i, i)]).fold(0.0_f64, f64::max);
    if max_diag <= 0.0 {
        return (DMatrix::zeros(n, n), 0);
    }
    let min_diag = (0..n).map(|i| g[(i, i)]).fold(f64::INFINITY, f64::min);
    if min_diag > max_diag * 1e-6 {
        if let Some(ch) = g.clone().cholesky() {
            let inv = ch.inverse();
            // Cholesky succeeds on nearly singular matrices too; trust it only when the inverse
            // is not wildly larger than 1/min_diag would allow.
            let max_inv_diag = (0..n).map(|i| inv[(i, i)]).fold(0.0_f64, f64::max);
            if max_inv_diag.is_finite() && max_inv_diag * max_diag < 1.0 / GRAM_REL_TOL {
                return (inv, n);
            }
        }
    }
    let eig = SymmetricEigen::new(g.clone());
    let top = eig.eigenvalues.iter().cloned().fold(0.0_f64, f64::max);
    let mut inv = DMatrix::zeros(n, n);
    let mut rank = 0;
    for (k, &lambda) in eig.eigenvalues.iter().enumerate() {
        if lambda > top * GRAM_REL_TOL {
            rank += 1;
            let v = eig.eigenvectors.column(k);
            inv += (v * v.transpose()) / lambda;
        }
    }
    (inv, rank)
}

/// Symmetric square root of a symmetric positive semi-definite matrix (negative round-off
/// eigenvalues are treated as zero).
pub fn sym_sqrt(g: &DMatrix<f64>) -> DMatrix<f64> {
    let eig = SymmetricEigen::new(g.clone());
    let n = g.nrows();
    let mut out = DMatrix::zeros(n, n);
    for (k, &lambda) in eig.eigenvalues.iter().enumerate() {
        if lambda > 0.0 {
            let v = eig.eigenvectors.column(k);
            out += (v * v.transpose()) * lambda.sqrt();
        }
    }
    out
}

/// Relative size below which a singular value from M^T M is round-off: its eigenvalues carry
/// an absolute error of about eps times the largest, so a singular value's is about
/// sqrt(eps) = 1.5e-8 of the largest. A pseudo-inverse that kept one of those would divide
/// by its square and return garbage.
pub const ROUNDOFF_REL: f64 = 1e-7;

/// Moore-Penrose pseudo-inverse, dropping singular values at or below `rel_tol` (at least
/// [`ROUNDOFF_REL`]) times the largest. Returns the zero matrix (transposed shape) for an
/// all-zero input.
///
/// Computed from the symmetric eigen-decomposition of M^T M (singular values s_k = sqrt of its
/// eigenvalues): pinv(M) = sum_k v_k v_k^T M^T / s_k^2. nalgebra 0.33's general SVD returned
/// visibly wrong factors (errors of several percent) for effectiveness matrices with zero rows,
/// while its symmetric eigen-solver is accurate; squaring the condition number is harmless for
/// these small, truncated problems.
pub fn pinv(m: &DMatrix<f64>, rel_tol: f64) -> DMatrix<f64> {
    pinv_keep(m, usize::MAX, rel_tol)
}

/// [`pinv`] keeping at most the `keep` largest singular values, and never more than
/// min(rows, cols): M^T M of a wide matrix has cols - rows more eigenvalues, zero in exact
/// arithmetic. Why both: a truncation decided by comparing a singular value with a tolerance
/// computed from that same value is a floating-point coin toss. It once kept a round-off
/// value of a 3 x 4 allocation problem (4.8e-7 of 54) and gave four_up's heave a twist of
/// +-1.6 (commands +-1 on alternate thrusters) instead of -0.14 on each, which the thrusters'
/// forward/reverse asymmetry turned into lift: the vehicle surfaced at 0.4 m/s.
pub fn pinv_keep(m: &DMatrix<f64>, keep: usize, rel_tol: f64) -> DMatrix<f64> {
    let (r, c) = m.shape();
    if r == 0 || c == 0 || !m.iter().all(|v| v.is_finite()) {
        return DMatrix::zeros(c, r);
    }
    let (values, vectors) = singular_right(m);
    let top = values.first().copied().unwrap_or(0.0);
    if top <= 0.0 {
        return DMatrix::zeros(c, r);
    }
    let mut out = DMatrix::zeros(c, r);
    let tol = top * rel_tol.max(ROUNDOFF_REL);
    for (k, &s) in values.iter().enumerate().take(keep.min(r).min(c)) {
        if s > tol {
            let v = vectors.column(k);
            out += (v * (v.transpose() * m.transpose())) / (s * s);
        }
    }
    out
}

/// Singular values of `m` (descending) and the matching right singular vectors (columns),
/// from the eigen-decomposition of M^T M.
pub fn singular_right(m: &DMatrix<f64>) -> (Vec<f64>, DMatrix<f64>) {
    sorted_eigen(&(m.transpose() * m))
}

/// Singular values of `m` (descending) and the matching left singular vectors (columns), from
/// the eigen-decomposition of M M^T.
pub fn singular_left(m: &DMatrix<f64>) -> (Vec<f64>, DMatrix<f64>) {
    sorted_eigen(&(m * m.transpose()))
}

fn sorted_eigen(g: &DMatrix<f64>) -> (Vec<f64>, DMatrix<f64>) {
    let n = g.nrows();
    let eig = SymmetricEigen::new(g.clone());
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let values = order
        .iter()
        .map(|&k| eig.eigenvalues[k].max(0.0).sqrt())
        .collect();
    let vectors = DMatrix::from_fn(n, n, |i, j| eig.eigenvectors[(i, order[j])]);
    (values, vectors)
}

/// Frobenius norm of the difference of two equally shaped matrices, relative to the second.
pub fn rel_frobenius_err(estimate: &DMatrix<f64>, truth: &DMatrix<f64>) -> f64 {
    let denom = truth.norm();
    if denom == 0.0 {
        return if estimate.norm() == 0.0 {
            0.0
        } else {
            f64::INFINITY
        };
    }
    (estimate - truth).norm() / denom
}

/// [`rel_frobenius_err`] of each row group of two 6 x N models (rotation rows 0-2,
/// acceleration rows 3-5), as the error bounds are stated. Infinite for differently shaped
/// matrices (a thruster added or removed) or a group that was zero and is not.
pub fn rel_frobenius_err_per_row_group(estimate: &DMatrix<f64>, truth: &DMatrix<f64>) -> [f64; 2] {
    if estimate.shape() != truth.shape() || estimate.nrows() != 6 {
        return [f64::INFINITY; 2];
    }
    [0, 3].map(|r| {
        rel_frobenius_err(
            &estimate.rows(r, 3).into_owned(),
            &truth.rows(r, 3).into_owned(),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sym_pinv_of_full_rank_is_inverse() {
        let g = DMatrix::from_row_slice(2, 2, &[4.0, 1.0, 1.0, 3.0]);
        let (inv, rank) = sym_pinv(&g);
        assert_eq!(rank, 2);
        let id = &g * &inv;
        assert!((id - DMatrix::identity(2, 2)).norm() < 1e-12);
    }

    #[test]
    fn sym_pinv_of_singular_leaves_unexcited_direction_zero() {
        let g = DMatrix::from_row_slice(3, 3, &[2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 5.0]);
        let (inv, rank) = sym_pinv(&g);
        assert_eq!(rank, 2);
        assert!((inv[(0, 0)] - 0.5).abs() < 1e-12);
        assert_eq!(inv[(1, 1)], 0.0);
        assert!((inv[(2, 2)] - 0.2).abs() < 1e-12);
    }

    /// four_up's roll, pitch and heave rows as the refinement once learned them (3 x 4): the
    /// fourth eigenvalue of M^T M is round-off (a singular value of 4.8e-7 against 54). Kept,
    /// it gave a heave allocation of +-1.7 on alternate thrusters; the pseudo-inverse must be
    /// the minimum-norm one, M^T (M M^T)^-1, whatever tolerance the caller asks for.
    #[test]
    fn a_wide_matrix_never_keeps_a_round_off_singular_value() {
        let m = DMatrix::from_row_slice(
            3,
            4,
            &[
                27.222784, -27.211095, 27.242224, -27.205489, //
                24.095591, 24.051452, -24.216631, -24.171046, //
                -1.752289, -1.756102, -1.772083, -1.768692,
            ],
        );
        let exact = m.transpose() * (&m * m.transpose()).try_inverse().unwrap();
        for tol in [1e-12, 1e-9, 1e-8] {
            let p = pinv(&m, tol);
            assert!((&p - &exact).norm() < 1e-9, "tol {tol}: {p:.4}");
        }
        // Keeping fewer: the heave direction (the smallest) dropped.
        let p2 = pinv_keep(&m, 2, 1e-9);
        assert!(p2.column(2).norm() < 1e-3, "{p2:.4}");
        assert!((p2.column(0) - exact.column(0)).norm() < 1e-2 * exact.column(0).norm());
    }

    #[test]
    fn sym_sqrt_squares_back() {
        let g = DMatrix::from_row_slice(2, 2, &[4.0, 1.0, 1.0, 3.0]);
        let s = sym_sqrt(&g);
        assert!((&s * &s - g).norm() < 1e-12);
    }

    #[test]
    fn pinv_is_accurate_with_zero_rows() {
        // The shape that exposed nalgebra's SVD: 6 x 4 with two zero rows.
        let b = DMatrix::from_row_slice(
            6,
            4,
            &[
                0.0, 0.0, -36.8, 36.8, //
                0.0, 0.0, 0.0, 0.0, //
                36.8, -36.8, 0.0, 0.0, //
                3.03, 3.03, 0.0, 0.0, //
                0.0, 0.0, 0.0, 0.0, //
                0.0, 0.0, 1.98, 1.98, //
            ],
        );
        let p = pinv(&b, 1e-9);
        let pb = &p * &b;
        assert!((pb - DMatrix::identity(4, 4)).norm() < 1e-9);
    }

    #[test]
    fn pinv_matches_inverse_and_truncates() {
        let m = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.0, 0.0, 2.0, 0.0]);
        let p = pinv(&m, 1e-12);
        assert!((&m * &p - DMatrix::identity(2, 2)).norm() < 1e-12);
        let tiny = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 1e-9]);
        let p = pinv(&tiny, 1e-6);
        assert_eq!(p[(1, 1)], 0.0);
        assert!((p[(0, 0)] - 1.0).abs() < 1e-12);
    }
}
