//! The allocation matrix: the truncated pseudo-inverse of the actuated rows.

use nalgebra::DMatrix;

use crate::estimator::analysis::NUMERICAL_REL_TOL;
use crate::estimator::dof::{Dof, DofMask};
use crate::estimator::linalg::pinv_keep;

/// Allocation (N x 6): thruster commands per unit of desired motion in each DOF.
///
/// The rank-`rank` truncated pseudo-inverse of the actuated rows of `b`; the columns of
/// unactuated DOFs are zero, so whatever a controller asks of those, no thruster is commanded
/// for it (the paper's all-aligned robot "learned" to heave, sway and roll and oscillated).
pub fn pseudo_inverse(b: &DMatrix<f64>, actuated: DofMask, rank: usize) -> DMatrix<f64> {
    let n = b.ncols();
    let rows: Vec<usize> = Dof::ALL
        .iter()
        .filter(|d| actuated.contains(**d))
        .map(|d| d.index())
        .collect();
    let mut out = DMatrix::zeros(n, 6);
    if rows.is_empty() || rank == 0 {
        return out;
    }
    let sub = b.select_rows(rows.iter());
    // Exactly the `rank` largest singular values, independent of absolute scale.
    let sub_pinv = pinv_keep(&sub, rank, NUMERICAL_REL_TOL);
    for (c, &row) in rows.iter().enumerate() {
        out.set_column(row, &sub_pinv.column(c));
    }
    out
}
