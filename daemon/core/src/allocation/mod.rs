//! Allocation: how a desired body motion becomes thruster commands, given an effectiveness.
//!
//! The cut follows PX4's `control_allocator`: where the effectiveness comes from (the
//! estimator, a nominal model from the vehicle file, a model file) is apart from how it is
//! inverted. This room holds the inversion and nothing else:
//! - [`pseudo_inverse`]: the allocation matrix (N x 6) from the effectiveness and the DOFs it
//!   actuates, computed once per model (an SVD, off the control loop when it can be);
//! - [`product`]: allocation times a desired motion, once per sample, allocation-free;
//! - [`desaturate`]: sequential desaturation, translation gives way before rotation.
//!
//! Which DOFs are actuated (the rank report) is a question about the effectiveness and its
//! uncertainty, so it stays with the estimator's analysis.

mod desaturation;
mod pseudo_inverse;

pub use desaturation::{desaturate, desaturate_within};
pub use pseudo_inverse::pseudo_inverse;

use nalgebra::DMatrix;

/// Thruster commands for a desired motion (6, DOF order): `out = allocation * desired`, for
/// the first `min(out.len(), allocation.nrows())` thrusters. Unactuated DOFs contribute nothing
/// because their allocation columns are zero.
pub fn product(allocation: &DMatrix<f64>, desired: &[f64; 6], out: &mut [f64]) {
    let n = allocation.nrows().min(out.len());
    for (i, o) in out.iter_mut().enumerate().take(n) {
        *o = (0..6).map(|j| allocation[(i, j)] * desired[j]).sum();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn product_fills_only_the_thrusters_the_allocation_has() {
        let a = DMatrix::from_row_slice(
            2,
            6,
            &[1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0],
        );
        let mut out = [9.0; 3];
        product(&a, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], &mut out);
        assert_eq!(out, [9.0, -4.0, 9.0]);
    }
}
