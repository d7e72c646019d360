//! The paper's regression S * A = T, solved by pseudo-inverse (Doniec, Detweiler, Rus, Alg. 1).
//!
//! S holds the kept responses (rows of 3 sensor axes), T the thrust of the same rows. A (3 x N)
//! maps a desired motion x (a row) to thrust t = x A. Kept incrementally as S^T S and S^T T,
//! since pinv(S) T = pinv(S^T S) S^T T for any S.

use nalgebra::{DMatrix, Matrix3, Vector3};

use super::linalg::pinv;

/// Relative singular-value cut for the paper's pseudo-inverses; only round-off is dropped, as a
/// plain Moore-Penrose inverse would (the paper does no rank truncation).
const PINV_TOL: f64 = 1e-12;

#[derive(Debug, Clone)]
pub struct PaperLs {
    sts: Matrix3<f64>,
    stt: DMatrix<f64>,
    rows: u64,
}

impl PaperLs {
    pub fn new(n: usize) -> Self {
        PaperLs {
            sts: Matrix3::zeros(),
            stt: DMatrix::zeros(3, n),
            rows: 0,
        }
    }

    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Append one kept row: response `s` with the thrust `t` applied at the time.
    pub fn add(&mut self, s: &Vector3<f64>, t: &[f64]) {
        if !s.iter().all(|v| v.is_finite()) || !t.iter().all(|v| v.is_finite()) {
            return;
        }
        self.sts += s * s.transpose();
        for (i, &ti) in t.iter().enumerate() {
            if ti != 0.0 {
                for a in 0..3 {
                    self.stt[(a, i)] += s[a] * ti;
                }
            }
        }
        self.rows += 1;
    }

    /// The inverse model A (3 x N): t = x A for a desired motion row x.
    pub fn inverse_model(&self) -> DMatrix<f64> {
        let sts = DMatrix::from_iterator(3, 3, self.sts.iter().cloned());
        pinv(&sts, PINV_TOL) * &self.stt
    }

    /// The inverse model turned back into forward form by pseudo-inverse: B = pinv(A)^T, 3 x N,
    /// so it can be compared with the truth (x = B t).
    pub fn forward_model(&self) -> DMatrix<f64> {
        pinv(&self.inverse_model(), PINV_TOL).transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_square_model_without_noise() {
        // With N = 3 and an invertible B, the paper's inverse is exactly B^-1 (as rows).
        let b = DMatrix::from_row_slice(3, 3, &[1.0, 0.2, 0.0, 0.0, 2.0, 0.3, 0.1, 0.0, 1.5]);
        let mut ls = PaperLs::new(3);
        for k in 0..6 {
            let mut t = vec![0.0; 3];
            t[k / 2] = if k % 2 == 0 { 0.5 } else { -0.5 };
            let y = &b * nalgebra::DVector::from_row_slice(&t);
            ls.add(&Vector3::new(y[0], y[1], y[2]), &t);
        }
        assert!((ls.forward_model() - &b).norm() < 1e-9);
        let a = ls.inverse_model();
        // x A = t  <=>  A^T = B^-1
        assert!((a.transpose() * &b - DMatrix::identity(3, 3)).norm() < 1e-9);
    }
}
