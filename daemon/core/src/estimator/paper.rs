//! The paper's regression S * A = T, solved by pseudo-inverse (Doniec, Detweiler, Rus, Alg. 1).
//!
//! S holds the kept responses (rows of 3 sensor axes), T the thrust of the same rows. A (3 x N)
//! maps a desired motion x (a row) to thrust t = x A. Kept incrementally as S^T S and S^T T,
//! since pinv(S) T = pinv(S^T S) S^T T for any S.

use nalgebra::{DMatrix, Matrix3, Vector3};

/// Relative eigenvalue cut for the 3 x 3 Gram pseudo-inverses (a singular-value ratio of 1e-7):
/// only round-off is dropped, as a plain Moore-Penrose inverse would (the paper does no rank
/// truncation).
const GRAM_TOL: f64 = 1e-14;

/// Pseudo-inverse of a symmetric positive semi-definite 3 x 3 matrix.
fn sym_pinv3(m: &Matrix3<f64>) -> Matrix3<f64> {
    let eig = m.symmetric_eigen();
    let top = eig.eigenvalues.iter().cloned().fold(0.0_f64, f64::max);
    let mut out = Matrix3::zeros();
    if top <= 0.0 || !top.is_finite() {
        return out;
    }
    for k in 0..3 {
        let lambda = eig.eigenvalues[k];
        if lambda > top * GRAM_TOL {
            let v = eig.eigenvectors.column(k);
            out += (v * v.transpose()) / lambda;
        }
    }
    out
}

/// Multiply a 3 x 3 matrix into a 3 x N one.
fn mul3(m: &Matrix3<f64>, x: &DMatrix<f64>) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(3, x.ncols());
    for c in 0..x.ncols() {
        for r in 0..3 {
            out[(r, c)] = (0..3).map(|k| m[(r, k)] * x[(k, c)]).sum();
        }
    }
    out
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
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
        mul3(&sym_pinv3(&self.sts), &self.stt)
    }

    /// The inverse model turned back into forward form by pseudo-inverse: B = pinv(A)^T, 3 x N,
    /// so it can be compared with the truth (x = B t).
    pub fn forward_model(&self) -> DMatrix<f64> {
        // pinv(A) = A^T pinv(A A^T), so pinv(A)^T = pinv(A A^T) A: only a 3 x 3 inverse.
        let a = self.inverse_model();
        let aat = Matrix3::from_fn(|r, c| a.row(r).dot(&a.row(c)));
        mul3(&sym_pinv3(&aat), &a)
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
