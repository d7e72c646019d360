//! True thruster effectiveness of a vehicle: what the estimator should learn.
//!
//! `B_fwd` and `B_rev` are 6 x N. Rows are in DOF order `[roll, pitch, yaw, surge, sway,
//! heave]`: rows 0-2 angular acceleration about body x, y, z (rad/s^2), rows 3-5 linear
//! acceleration along body x, y, z (m/s^2), of the vehicle at rest (no Coriolis, damping or
//! restoring terms), per unit of command.
//!
//! * `B_fwd[:, i] = reorder(M^-1 [f; r x f])`, `f = forward_max_n * s * direction`: the response
//!   to `u_i = +1`.
//! * `B_rev[:, i]` is the same with `reverse_max_n`, keeping the sign of the direction, so the
//!   response to a negative command `u_i < 0` is `B_rev[:, i] * u_i` (at `u_i = -1` the vehicle
//!   accelerates by `-B_rev[:, i]`). A symmetric thruster has `B_rev == B_fwd`.
//!
//! `s` is -1 for a `reversed` (left-handed) thruster and +1 otherwise; dead thrusters have zero
//! columns. Beyond the deadband and with `exponent = 1`, the response to a command vector is
//! `sum_i (u_i > 0 ? B_fwd : B_rev)[:, i] * e(u_i)` with `e` the deadband-rescaled command.
//!
//! For a `t200` thruster the thrust at `u = +-1` is the table's at the supply voltage
//! ([`effectiveness_at`]), so the truth follows the battery.

use nalgebra::{DMatrix, Matrix6, Vector6};

use crate::dynamics::fossen_to_dof_order;
use crate::thruster::{steady_thrust_at, FIXED_SUPPLY_V};
use crate::vehicle::ThrusterSpec;

/// `(B_fwd, B_rev)` of `thrusters` for a vehicle whose `M^-1` is `mass_inv` (Fossen order),
/// at the fixed supply.
pub fn effectiveness(
    mass_inv: &Matrix6<f64>,
    thrusters: &[ThrusterSpec],
) -> (DMatrix<f64>, DMatrix<f64>) {
    effectiveness_at(mass_inv, thrusters, FIXED_SUPPLY_V)
}

/// `(B_fwd, B_rev)` at supply voltage `supply_v`: each column the thrust at `u = +1` and the
/// magnitude at `u = -1` that voltage gives (only `t200` thrusters depend on it).
pub fn effectiveness_at(
    mass_inv: &Matrix6<f64>,
    thrusters: &[ThrusterSpec],
    supply_v: f64,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let n = thrusters.len();
    let mut fwd = DMatrix::zeros(6, n);
    let mut rev = DMatrix::zeros(6, n);
    for (i, t) in thrusters.iter().enumerate() {
        if t.dead {
            continue;
        }
        // The signed thrust of +-1 already carries `reversed`; for the power law it is
        // +-forward/reverse_max_n exactly, as before.
        let unit: Vector6<f64> = fossen_to_dof_order(&(mass_inv * t.wrench_per_newton()));
        let full_fwd = steady_thrust_at(t, 1.0, supply_v);
        let full_rev = -steady_thrust_at(t, -1.0, supply_v);
        fwd.set_column(i, &(unit * full_fwd));
        rev.set_column(i, &(unit * full_rev));
    }
    (fwd, rev)
}

/// Numerical rank of `b`: singular values above `rel_tol` times the largest.
pub fn rank(b: &DMatrix<f64>, rel_tol: f64) -> usize {
    if b.is_empty() {
        return 0;
    }
    let sv = b.clone().svd(false, false).singular_values;
    let max = sv.iter().cloned().fold(0.0, f64::max);
    if max == 0.0 {
        return 0;
    }
    sv.iter().filter(|s| **s > rel_tol * max).count()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dynamics::RigidBody;
    use crate::vehicle::Body;

    #[test]
    fn single_vertical_thruster_column() {
        let rb = RigidBody::new(&Body::bluerov2()).expect("valid");
        let mut t = ThrusterSpec::new("up", [0.0, 0.0, 0.0], [0.0, 0.0, -1.0]);
        let (f, r) = effectiveness(rb.mass_matrix_inverse(), std::slice::from_ref(&t));
        // Pure heave at the CO: only the heave row, -F/(m + Z_wdot).
        let expect = -t.forward_max_n / (11.5 + 14.57);
        assert!((f[(5, 0)] - expect).abs() < 1e-12);
        assert!(f.rows(0, 5).norm() < 1e-12);
        assert!((r[(5, 0)] / f[(5, 0)] - 4.1 / 5.25).abs() < 1e-12);
        t.reversed = true;
        let (f2, _) = effectiveness(rb.mass_matrix_inverse(), std::slice::from_ref(&t));
        assert!((f2[(5, 0)] + expect).abs() < 1e-12);
        t.dead = true;
        let (f3, r3) = effectiveness(rb.mass_matrix_inverse(), &[t]);
        assert_eq!(f3.norm() + r3.norm(), 0.0);
    }

    #[test]
    fn rank_counts_independent_columns() {
        let b = DMatrix::from_row_slice(2, 3, &[1.0, 2.0, 0.0, 2.0, 4.0, 0.0]);
        assert_eq!(rank(&b, 1e-9), 1);
        assert_eq!(rank(&DMatrix::zeros(6, 4), 1e-9), 0);
    }
}
