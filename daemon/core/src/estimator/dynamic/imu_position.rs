//! Where the IMU sits: the accelerometer measures the specific force at its own position r
//! from the vehicle's centre, f_imu = f_centre + alpha x r + omega x (omega x r), so every
//! coefficient of the acceleration rows is the centre's plus a term linear in r.
//!
//! With alpha = B_rot u_lag + Theta_rot . terms (the rotation rows' own model), the fit of the
//! acceleration rows with free coefficients learns beta_a + L_a r for each row a, where L_a
//! (K x 3) is built from the rotation rows' coefficients and the centripetal pattern: the
//! thrust columns come out B_acc + B_rot x r, 144-261 % off for an IMU 10-18 cm from the
//! centre (issue 32). Given r, the centre's coefficients are the fitted ones minus L_a r
//! ([`lever_terms`]): exact, since the regression is linear in both.
//!
//! Learning r needs coefficients whose value at the centre is known: a rigid body's
//! translational acceleration at its centre of mass does not depend on the body rates alone
//! (no omega, |omega| omega or omega_i omega_j term; those appear at any other point as
//! tangential and centripetal acceleration). Fixing those columns of each acceleration row to
//! their lever-arm values and the rest free, r is shared by the three rows: eliminated per
//! row (Schur complement), three unknowns remain ([`learn`]). With a prior (the configured
//! position and how far it is trusted), the data is weighed against it. The centre found
//! this way is the vehicle's centre of mass as far as its added mass is symmetric, which is
//! what the rates pivot about; docs/study.md measures how it lands against the simulator's.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

use super::regressors::{RATE, RATE_QUADRATIC, TERMS};
use super::segmented_ls::scaled_pinv;

/// Index of the term omega_i omega_j (i <= j, body rates 0..3) in the regressors' layout
/// (nu = [v; omega], products nu_i nu_j for i <= j after the down terms).
fn rate_product(i: usize, j: usize) -> usize {
    let (i, j) = (3 + i.min(j), 3 + i.max(j));
    let mut k = super::regressors::DOWN + 3;
    for a in 0..6 {
        for b in a..6 {
            if (a, b) == (i, j) {
                return k;
            }
            k += 1;
        }
    }
    unreachable!("rate indices in 0..3")
}

/// The IMU's position from the centre, body frame, m, and how well it is known.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ImuPosition {
    /// The position the acceleration rows were referred with.
    pub position_m: Vector3<f64>,
    /// Its covariance, m^2: what the bound counts of it.
    pub cov: Matrix3<f64>,
    /// What the data says (relative to the centre of mass), when it was asked and could tell.
    pub learned: Option<Learned>,
    /// The data contradicted the configured position (beyond the tolerance), so `position_m`
    /// is the learned one.
    pub contradicted: bool,
    /// The share of the acceleration rows' relative bound that the stop rule leaves out: the
    /// tolerance when contradicted (no data removes it) and the rotation rows' error carried
    /// over by r (their own bound stops on it).
    pub rel_err_share: f64,
}

/// The position the data found and its covariance.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Learned {
    pub position_m: Vector3<f64>,
    pub cov: Matrix3<f64>,
}

impl Learned {
    /// One standard deviation per axis, m.
    pub fn sd_m(&self) -> Vector3<f64> {
        Vector3::from_fn(|i, _| self.cov[(i, i)].max(0.0).sqrt())
    }
}

impl ImuPosition {
    /// A configured position, taken as exact (nothing learned).
    pub fn configured(position_m: Vector3<f64>) -> Self {
        ImuPosition {
            position_m,
            cov: Matrix3::zeros(),
            learned: None,
            contradicted: false,
            rel_err_share: 0.0,
        }
    }

    /// The position to refer with, given the configured one and the data's `learned` (see
    /// `EstimatorConfig::imu_position_tolerance_m`): the configured one unless an axis differs
    /// by more than `tolerance_m` plus 3 of the data's standard deviations; then the learned
    /// one, uncertain by the tolerance (the centre of mass it is measured from may sit that
    /// far from the reference point). Kept, the configured position is taken as exact: a gap
    /// within the tolerance is put down to the centre of mass lying off the drawings' origin
    /// (AMOUR-5's 2 cm CG offset shows as a 1.1-1.4 cm gap), which moves no coefficient at
    /// the reference point. The risk: drawings wrong by less than the tolerance go unnoticed.
    pub fn decide(configured_m: Vector3<f64>, learned: Learned, tolerance_m: f64) -> Self {
        let gap = learned.position_m - configured_m;
        let sd = learned.sd_m();
        let contradicted = (0..3).any(|i| gap[i].abs() > tolerance_m + 3.0 * sd[i]);
        let (position_m, cov) = if contradicted {
            (
                learned.position_m,
                learned.cov + Matrix3::identity() * tolerance_m.powi(2),
            )
        } else {
            (configured_m, Matrix3::zeros())
        };
        ImuPosition {
            position_m,
            cov,
            learned: Some(learned),
            contradicted,
            rel_err_share: 0.0,
        }
    }

    /// The part of `cov` more data does not remove.
    pub fn irreducible_cov(&self) -> Matrix3<f64> {
        match &self.learned {
            Some(l) if self.contradicted => self.cov - l.cov,
            _ => Matrix3::zeros(),
        }
    }
}

/// L_a for every acceleration row a: `out[a]` is K x 3, the change of row a's coefficients
/// (K = `cols` thrust columns then the terms) per metre of r, given the rotation rows'
/// coefficients `theta_rot` (K x 3, one column per rotation axis).
pub fn lever_terms(theta_rot: &DMatrix<f64>, cols: usize) -> [DMatrix<f64>; 3] {
    let k = theta_rot.nrows();
    // The terms, and disturbance states after them when there are any.
    debug_assert!(k >= cols + TERMS);
    std::array::from_fn(|a| {
        let mut l = DMatrix::zeros(k, 3);
        // Tangential: (alpha x r)_a = sum_{m,n} eps_amn alpha_m r_n, alpha_m = X theta_rot_m.
        for m in 0..3 {
            for n in 0..3 {
                let e = levi_civita(a, m, n);
                if e != 0.0 {
                    for j in 0..k {
                        l[(j, n)] += e * theta_rot[(j, m)];
                    }
                }
            }
        }
        // Centripetal: (omega x (omega x r))_a = omega_a (omega . r) - r_a |omega|^2.
        for b in 0..3 {
            for c in b..3 {
                let j = cols + rate_product(b, c);
                if b == c {
                    if b != a {
                        l[(j, a)] -= 1.0;
                    }
                } else if b == a {
                    l[(j, c)] += 1.0;
                } else if c == a {
                    l[(j, b)] += 1.0;
                }
            }
        }
        l
    })
}

/// The Levi-Civita symbol eps_abc (the cross product's pattern).
pub(crate) fn levi_civita(a: usize, b: usize, c: usize) -> f64 {
    match (a, b, c) {
        (0, 1, 2) | (1, 2, 0) | (2, 0, 1) => 1.0,
        (0, 2, 1) | (2, 1, 0) | (1, 0, 2) => -1.0,
        _ => 0.0,
    }
}

/// Whether term column `j` (0..TERMS) is one the centre's acceleration rows do not have: the
/// body rates alone (omega, |omega| omega, omega_i omega_j).
fn rate_only(j: usize) -> bool {
    (RATE..RATE + 3).contains(&j)
        || (RATE_QUADRATIC..RATE_QUADRATIC + 3).contains(&j)
        || (0..3).any(|b| (b..3).any(|c| rate_product(b, c) == j))
}

/// Learns r from the acceleration rows' centred normal equations (`gram` K x K, `xy` K x 3),
/// the rotation rows' coefficients `theta_rot`, the acceleration rows' noise `sigma`, and a
/// prior (`prior_m`, one standard deviation `prior_sd_m` per axis; infinite: none). None when
/// the data does not determine r (no excitation).
pub fn learn(
    gram: &DMatrix<f64>,
    xy: &DMatrix<f64>,
    theta_rot: &DMatrix<f64>,
    cols: usize,
    sigma: &[f64; 3],
    prior_m: &Vector3<f64>,
    prior_sd_m: f64,
) -> Option<Learned> {
    let k = gram.nrows();
    let free: Vec<usize> = (0..k)
        .filter(|&j| j < cols || !rate_only(j - cols))
        .collect();
    let f = free.len();
    let p = |m: &DMatrix<f64>| DMatrix::from_fn(f, m.ncols(), |i, c| m[(free[i], c)]);
    let a_mat = DMatrix::from_fn(f, f, |i, j| gram[(free[i], free[j])]);
    let (a_inv, _) = scaled_pinv(&a_mat);
    let l = lever_terms(theta_rot, cols);
    let mut s = Matrix3::zeros();
    let mut rhs = Vector3::zeros();
    for a in 0..3 {
        let w = 1.0 / sigma[a].max(1e-12).powi(2);
        let gl = gram * &l[a]; // K x 3
        let c = p(&gl); // f x 3: P' G L_a
        let d = l[a].transpose() * &gl; // 3 x 3
        let b = DVector::from_fn(f, |i, _| xy[(free[i], a)]);
        let ly = l[a].transpose() * xy.column(a);
        let ct_ainv = c.transpose() * &a_inv; // 3 x f
        let schur = d - &ct_ainv * &c;
        let r = ly - &ct_ainv * b;
        for i in 0..3 {
            rhs[i] += w * r[i];
            for j in 0..3 {
                s[(i, j)] += w * schur[(i, j)];
            }
        }
    }
    if prior_sd_m.is_finite() && prior_sd_m > 0.0 {
        let w = 1.0 / (prior_sd_m * prior_sd_m);
        s += Matrix3::identity() * w;
        rhs += prior_m * w;
    }
    let cov = s.try_inverse()?;
    let position_m = cov * rhs;
    (position_m.iter().all(|v| v.is_finite()) && cov.iter().all(|v| v.is_finite())).then_some(
        Learned {
            position_m,
            cov: 0.5 * (cov + cov.transpose()),
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rate_products_land_on_their_named_terms() {
        let names = super::super::regressors::TERM_NAMES;
        assert_eq!(names[rate_product(0, 0)], "pp");
        assert_eq!(names[rate_product(0, 2)], "pr");
        assert_eq!(names[rate_product(2, 1)], "qr");
        assert_eq!(names[rate_product(2, 2)], "rr");
    }

    #[test]
    fn the_lever_terms_are_the_cross_product_and_the_centripetal_pattern() {
        // One thrust column whose angular acceleration is alpha = (1, 2, 3) per unit command.
        let cols = 1;
        let mut theta_rot = DMatrix::zeros(cols + TERMS, 3);
        theta_rot[(0, 0)] = 1.0;
        theta_rot[(0, 1)] = 2.0;
        theta_rot[(0, 2)] = 3.0;
        let l = lever_terms(&theta_rot, cols);
        let r = Vector3::new(0.1, -0.2, 0.3);
        let alpha = Vector3::new(1.0, 2.0, 3.0);
        let expect = alpha.cross(&r);
        for a in 0..3 {
            let got = (l[a].row(0) * r)[0];
            assert!(
                (got - expect[a]).abs() < 1e-12,
                "row {a}: {got} vs {}",
                expect[a]
            );
        }
        // Centripetal at omega = (0.5, -1, 2): sum over the products of L r times omega_i omega_j.
        let w = Vector3::new(0.5, -1.0, 2.0);
        let expect = w.cross(&w.cross(&r));
        for a in 0..3 {
            let mut got = 0.0;
            for b in 0..3 {
                for c in b..3 {
                    let j = cols + rate_product(b, c);
                    got += (l[a].row(j) * r)[0] * w[b] * w[c];
                }
            }
            assert!(
                (got - expect[a]).abs() < 1e-12,
                "row {a}: {got} vs {}",
                expect[a]
            );
        }
    }
}
