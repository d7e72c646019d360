//! Least squares y = X theta (three outputs) with one free intercept per segment, accumulated
//! one sample at a time without allocating.
//!
//! The intercept of a segment is projected out when the segment closes (Frisch-Waugh): with
//! s_x, s_y the segment's sums and n its length, the centred normal equations are
//! sum x x' - s_x s_x' / n and sum x y' - s_x s_y' / n. Solving scales the Gram matrix to a unit
//! diagonal first: the regressors (commands, rates, squared velocities, products) span many
//! orders of magnitude.

use nalgebra::{DMatrix, DVector, Vector3};

use crate::estimator::linalg::sym_pinv;

/// The fit: coefficients, the scaled pseudo-inverse of the Gram matrix, residuals.
#[derive(Debug, Clone)]
pub struct SegmentedSolution {
    /// K x 3 coefficients.
    pub theta: DMatrix<f64>,
    /// K x K inverse Gram matrix (covariance / sigma^2).
    pub gram_inv: DMatrix<f64>,
    /// Numerical rank of the Gram matrix.
    pub rank: usize,
    /// Residual variance per output, once there are degrees of freedom left.
    pub residual_var: Option<[f64; 3]>,
    pub residual_dof: u64,
}

#[derive(Debug, Clone)]
pub struct SegmentedLs {
    k: usize,
    gram: DMatrix<f64>,
    xy: DMatrix<f64>,
    yy: Vector3<f64>,
    rows: u64,
    segments: u64,
    // The open segment.
    seg_n: u64,
    seg_x: DVector<f64>,
    seg_y: Vector3<f64>,
}

impl SegmentedLs {
    pub fn new(k: usize) -> Self {
        SegmentedLs {
            k,
            gram: DMatrix::zeros(k, k),
            xy: DMatrix::zeros(k, 3),
            yy: Vector3::zeros(),
            rows: 0,
            segments: 0,
            seg_n: 0,
            seg_x: DVector::zeros(k),
            seg_y: Vector3::zeros(),
        }
    }

    /// Columns.
    pub fn width(&self) -> usize {
        self.k
    }

    /// Rows added so far.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// One row; `x` has `width()` entries. Only the upper triangle is accumulated.
    // Index loops: row i and column j of the same Gram matrix, clearer than zipped iterators.
    #[allow(clippy::needless_range_loop)]
    pub fn add(&mut self, x: &[f64], y: &Vector3<f64>) {
        debug_assert_eq!(x.len(), self.k);
        for i in 0..self.k {
            let xi = x[i];
            if xi == 0.0 {
                continue;
            }
            for j in i..self.k {
                self.gram[(i, j)] += xi * x[j];
            }
            for a in 0..3 {
                self.xy[(i, a)] += xi * y[a];
            }
            self.seg_x[i] += xi;
        }
        self.yy += y.component_mul(y);
        self.seg_y += y;
        self.seg_n += 1;
        self.rows += 1;
    }

    /// Close the open segment: its intercept is projected out.
    pub fn close_segment(&mut self) {
        if self.seg_n == 0 {
            return;
        }
        let n = self.seg_n as f64;
        for i in 0..self.k {
            let si = self.seg_x[i];
            if si == 0.0 {
                continue;
            }
            for j in i..self.k {
                self.gram[(i, j)] -= si * self.seg_x[j] / n;
            }
            for a in 0..3 {
                self.xy[(i, a)] -= si * self.seg_y[a] / n;
            }
        }
        self.yy -= self.seg_y.component_mul(&self.seg_y) / n;
        self.segments += 1;
        self.seg_n = 0;
        self.seg_x.fill(0.0);
        self.seg_y = Vector3::zeros();
    }

    /// The fit over every row so far (the open segment counted as if closed now).
    pub fn solve(&self) -> SegmentedSolution {
        let mut closed = self.clone();
        closed.close_segment();
        closed.solve_closed()
    }

    fn solve_closed(&self) -> SegmentedSolution {
        let k = self.k;
        let mut g = self.gram.clone();
        for i in 0..k {
            for j in 0..i {
                g[(i, j)] = g[(j, i)];
            }
        }
        // Jacobi scaling: unit diagonal (unexcited columns stay zero).
        let d = DVector::from_fn(k, |i, _| {
            let v = g[(i, i)];
            if v > 0.0 {
                1.0 / v.sqrt()
            } else {
                0.0
            }
        });
        let scaled = DMatrix::from_fn(k, k, |i, j| g[(i, j)] * d[i] * d[j]);
        let (inv_s, rank) = sym_pinv(&scaled);
        let gram_inv = DMatrix::from_fn(k, k, |i, j| inv_s[(i, j)] * d[i] * d[j]);
        let theta = &gram_inv * &self.xy;
        let residual_dof = self.rows.saturating_sub(self.segments + rank as u64);
        let residual_var = (residual_dof > 0).then(|| {
            std::array::from_fn(|a| {
                let fitted = self.xy.column(a).dot(&theta.column(a));
                ((self.yy[a] - fitted) / residual_dof as f64).max(0.0)
            })
        });
        SegmentedSolution {
            theta,
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
    fn recovers_coefficients_with_a_different_intercept_per_segment() {
        let mut ls = SegmentedLs::new(2);
        let theta = [2.0, -0.5];
        for seg in 0..4 {
            let c = [10.0, -3.0, 0.5, 7.0][seg];
            for k in 0..50 {
                let t = k as f64 * 0.1;
                let x = [t.sin(), (0.3 * t).cos() * 1e-3];
                let y = theta[0] * x[0] + theta[1] * x[1] + c;
                ls.add(&x, &Vector3::new(y, 2.0 * y, -y));
            }
            ls.close_segment();
        }
        let s = ls.solve();
        assert_eq!(s.rank, 2);
        assert!((s.theta[(0, 0)] - 2.0).abs() < 1e-9);
        assert!((s.theta[(1, 0)] + 0.5).abs() < 1e-6, "{}", s.theta[(1, 0)]);
        assert!((s.theta[(0, 1)] - 4.0).abs() < 1e-9);
        assert!(s.residual_var.unwrap()[0] < 1e-12);
    }

    #[test]
    fn an_unexcited_column_gets_no_coefficient() {
        let mut ls = SegmentedLs::new(2);
        for k in 0..20 {
            ls.add(&[k as f64, 0.0], &Vector3::new(3.0 * k as f64, 0.0, 0.0));
        }
        let s = ls.solve();
        assert_eq!(s.rank, 1);
        assert!((s.theta[(0, 0)] - 3.0).abs() < 1e-9);
        assert_eq!(s.theta[(1, 0)], 0.0);
    }
}
