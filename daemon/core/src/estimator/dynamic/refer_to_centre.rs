//! The acceleration rows referred from the IMU to the vehicle's centre (`DynamicRun::refer_to_centre`):
//! the position learned (or configured, or known from the model in force) subtracted as L_a r
//! from every coefficient, its uncertainty carried into the bound. The position's own
//! mathematics is [`super::imu_position`].

use nalgebra::DMatrix;

use super::imu_position::{self, ImuPosition};
use super::regressors::TERMS;
use super::{DynamicRun, DynamicSolution, ImuSetting};

/// The prior that keeps the learned position defined when the data barely moves it: 1 m,
/// far wider than any vehicle's IMU offset, so it never pulls a position the data holds.
const IMU_PRIOR_SD_M: f64 = 1.0;

impl DynamicRun {
    /// Refers the acceleration rows of `sol` (this run's solution) from the IMU to the
    /// vehicle's centre ([`imu_position`]): the position learned (or configured) is subtracted
    /// as L_a r from every coefficient, and its uncertainty and the rotation rows' (through
    /// L) are added to the standard errors and the bound in quadrature. Records the position
    /// in `sol.terms.imu_position`.
    // Index loops: DOF row, thruster column and term address several matrices at once.
    #[allow(clippy::needless_range_loop)]
    pub fn refer_to_centre(&self, sol: &mut DynamicSolution, setting: &ImuSetting) {
        let (n, c) = (self.n, self.cols);
        // With disturbance states, their columns after the terms: the swell's angular
        // acceleration is alpha too.
        let k = c + TERMS + sol.disturbance.as_ref().map_or(0, |d| d.ncols());
        let mut theta_rot = DMatrix::zeros(k, 3);
        let mut se_rot = DMatrix::zeros(k, 3);
        for m in 0..3 {
            for i in 0..c {
                let (b, se) = match &sol.split {
                    Some((sb, sse)) => (sb[(m, i)], sse[(m, i)]),
                    None => (sol.b[(m, i)], sol.std_err[(m, i)]),
                };
                theta_rot[(i, m)] = b;
                se_rot[(i, m)] = if se.is_finite() { se } else { 0.0 };
            }
            for j in 0..TERMS {
                theta_rot[(c + j, m)] = sol.terms.coefficients[(m, j)];
                se_rot[(c + j, m)] = sol.terms.std_err[(m, j)];
            }
            if let Some(d) = &sol.disturbance {
                for e in 0..d.ncols() {
                    theta_rot[(c + TERMS + e, m)] = d[(m, e)];
                }
            }
        }
        let learned = (setting.learn && sol.excited)
            .then(|| {
                let (gram, xy) = self.acc.centred_sums();
                let sigma = [sol.sigma[3], sol.sigma[4], sol.sigma[5]];
                imu_position::learn(
                    &gram,
                    &xy,
                    &theta_rot,
                    c,
                    &sigma,
                    &setting.position_m,
                    IMU_PRIOR_SD_M,
                )
            })
            .flatten();
        let mut imu = learned.map_or(ImuPosition::configured(setting.position_m), |l| {
            ImuPosition::decide(setting.position_m, l, setting.tolerance_m)
        });
        let r = imu.position_m;
        let irreducible = imu.irreducible_cov();
        let lever = imu_position::lever_terms(&theta_rot, c);
        // Shift and variance of coefficient j of acceleration row a; the second variance is
        // the rotation rows' share, which their own bound stops on.
        let shift = |a: usize, j: usize| -> (f64, f64, f64) {
            let l = lever[a].row(j);
            let d = (l * r)[0];
            let from_r = (l * imu.cov * l.transpose())[0];
            // The rotation rows' own error moves L: d/dtheta_rot_m of (alpha x r)_a.
            let mut from_rot = 0.0;
            for m in 0..3 {
                for nn in 0..3 {
                    let e = imu_position::levi_civita(a, m, nn);
                    from_rot += (e * se_rot[(j, m)] * r[nn]).powi(2);
                }
            }
            (d, from_r + from_rot, from_rot)
        };
        let mut var_sum = 0.0;
        let mut share_sum = 0.0;
        let mut norm2 = 0.0;
        for a in 0..3 {
            let row = 3 + a;
            for i in 0..n {
                let l = if self.split {
                    0.5 * (lever[a].row(i) + lever[a].row(n + i))
                } else {
                    lever[a].row(i).into_owned()
                };
                share_sum += (&l * irreducible * l.transpose())[0];
            }
            if let Some((sb, sse)) = sol.split.as_mut() {
                for i in 0..c {
                    let (d, v, _) = shift(a, i);
                    sb[(row, i)] -= d;
                    sse[(row, i)] = (sse[(row, i)].powi(2) + v).sqrt();
                }
            }
            for i in 0..n {
                // The symmetric gain: the mean of forward and reverse when split.
                let (d, v, v_rot) = if self.split {
                    let (d0, v0, r0) = shift(a, i);
                    let (d1, v1, r1) = shift(a, n + i);
                    (0.5 * (d0 + d1), 0.25 * (v0 + v1), 0.25 * (r0 + r1))
                } else {
                    shift(a, i)
                };
                share_sum += v_rot;
                sol.b[(row, i)] -= d;
                sol.std_err[(row, i)] = (sol.std_err[(row, i)].powi(2) + v).sqrt();
                var_sum += sol.std_err[(row, i)].powi(2);
                norm2 += sol.b[(row, i)].powi(2);
            }
            for j in 0..TERMS {
                let (d, v, _) = shift(a, c + j);
                sol.terms.coefficients[(row, j)] -= d;
                sol.terms.std_err[(row, j)] = (sol.terms.std_err[(row, j)].powi(2) + v).sqrt();
            }
        }
        if sol.rel_err[1].is_finite() && norm2 > 0.0 {
            sol.rel_err[1] = var_sum.sqrt() / norm2.sqrt();
            imu.rel_err_share = share_sum.max(0.0).sqrt() / norm2.sqrt();
        }
        sol.terms.imu_position = Some(imu);
    }
}
