//! Least squares y = X theta (three outputs) with one free intercept per segment, accumulated
//! one sample at a time without allocating, with standard errors robust to autocorrelation.
//!
//! The intercept of a segment is projected out when the segment closes (Frisch-Waugh): with
//! s_x, s_y the segment's sums and n its length, the centred normal equations are
//! sum x x' - s_x s_x' / n and sum x y' - s_x s_y' / n. Solving scales the Gram matrix to a unit
//! diagonal first: the regressors (commands, rates, squared velocities, products) span many
//! orders of magnitude.
//!
//! Why the robust covariance: within a segment the residuals are strongly autocorrelated (the
//! rotation rows regress an integral; the navigation's velocity error and the model's own
//! error are slow), so sigma^2 (X'X)^-1 is far too small. Segments are nearly independent
//! (each has its own intercept and restarts the integrals), so each segment is one cluster:
//! cov = G^-1 (sum_s h_s h_s') G^-1 with h_s = sum over the segment of x e = r_s - G_s theta,
//! which needs each segment's centred Gram matrix G_s and cross products r_s. They are kept in
//! `CLUSTERS` slots allocated up front; past that many segments, slot s % CLUSTERS sums several
//! segments, which is still a valid (coarser) cluster.

use nalgebra::{DMatrix, DVector, Vector3};

use crate::estimator::linalg::sym_pinv;

/// Cluster slots kept for the robust covariance (each at least one segment, 1 s by default).
pub const CLUSTERS: usize = 32;

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
    /// Per output, the K x K cluster-robust covariance of theta (segments as clusters, with
    /// the small-sample factor S / (S - 1)), and S, the clusters it rests on.
    pub robust_cov: [DMatrix<f64>; 3],
    pub clusters: usize,
}

#[derive(Debug, Clone)]
pub struct SegmentedLs {
    k: usize,
    gram: DMatrix<f64>,
    xy: DMatrix<f64>,
    yy: Vector3<f64>,
    rows: u64,
    segments: u64,
    // The open segment: raw sums (upper triangle of its Gram matrix).
    seg_n: u64,
    seg_gram: DMatrix<f64>,
    seg_xy: DMatrix<f64>,
    seg_yy: Vector3<f64>,
    seg_x: DVector<f64>,
    seg_y: Vector3<f64>,
    // Closed segments' centred sums, slot s % CLUSTERS (full symmetric Gram matrices).
    cluster_gram: Vec<DMatrix<f64>>,
    cluster_xy: Vec<DMatrix<f64>>,
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
            seg_gram: DMatrix::zeros(k, k),
            seg_xy: DMatrix::zeros(k, 3),
            seg_yy: Vector3::zeros(),
            seg_x: DVector::zeros(k),
            seg_y: Vector3::zeros(),
            cluster_gram: vec![DMatrix::zeros(k, k); CLUSTERS],
            cluster_xy: vec![DMatrix::zeros(k, 3); CLUSTERS],
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
                self.seg_gram[(i, j)] += xi * x[j];
            }
            for a in 0..3 {
                self.seg_xy[(i, a)] += xi * y[a];
            }
            self.seg_x[i] += xi;
        }
        self.seg_yy += y.component_mul(y);
        self.seg_y += y;
        self.seg_n += 1;
        self.rows += 1;
    }

    /// The open segment's centred sums (Gram matrix full), into `gram` and `xy`; its centred
    /// sum of squared outputs is returned.
    fn centred_open(&self, gram: &mut DMatrix<f64>, xy: &mut DMatrix<f64>) -> Vector3<f64> {
        let n = self.seg_n as f64;
        for i in 0..self.k {
            let si = self.seg_x[i];
            for j in i..self.k {
                let v = self.seg_gram[(i, j)] - si * self.seg_x[j] / n;
                gram[(i, j)] = v;
                gram[(j, i)] = v;
            }
            for a in 0..3 {
                xy[(i, a)] = self.seg_xy[(i, a)] - si * self.seg_y[a] / n;
            }
        }
        self.seg_yy - self.seg_y.component_mul(&self.seg_y) / n
    }

    /// Close the open segment: its intercept is projected out.
    pub fn close_segment(&mut self) {
        if self.seg_n == 0 {
            return;
        }
        let slot = (self.segments % CLUSTERS as u64) as usize;
        // Centre into the slot's spare room: the slot is summed into, so centre into the
        // open segment's own buffers first (no allocation).
        let mut g = std::mem::replace(&mut self.seg_gram, DMatrix::zeros(0, 0));
        let mut xy = std::mem::replace(&mut self.seg_xy, DMatrix::zeros(0, 0));
        let n = self.seg_n as f64;
        for i in 0..self.k {
            let si = self.seg_x[i];
            for j in i..self.k {
                g[(i, j)] -= si * self.seg_x[j] / n;
                g[(j, i)] = g[(i, j)];
            }
            for a in 0..3 {
                xy[(i, a)] -= si * self.seg_y[a] / n;
            }
        }
        self.yy += self.seg_yy - self.seg_y.component_mul(&self.seg_y) / n;
        self.gram += &g;
        self.xy += &xy;
        self.cluster_gram[slot] += &g;
        self.cluster_xy[slot] += &xy;
        g.fill(0.0);
        xy.fill(0.0);
        self.seg_gram = g;
        self.seg_xy = xy;
        self.segments += 1;
        self.seg_n = 0;
        self.seg_yy = Vector3::zeros();
        self.seg_x.fill(0.0);
        self.seg_y = Vector3::zeros();
    }

    /// The fit over every row so far (the open segment counted as if closed now).
    pub fn solve(&self) -> SegmentedSolution {
        let k = self.k;
        let mut g = self.gram.clone();
        let mut xy = self.xy.clone();
        let mut yy = self.yy;
        let mut segments = self.segments;
        let mut open = None;
        if self.seg_n > 0 {
            let (mut og, mut oxy) = (DMatrix::zeros(k, k), DMatrix::zeros(k, 3));
            yy += self.centred_open(&mut og, &mut oxy);
            g += &og;
            xy += &oxy;
            segments += 1;
            open = Some((og, oxy));
        }
        // The stored Gram matrix is upper-triangular; make it symmetric.
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
        let theta = &gram_inv * &xy;
        let residual_dof = self.rows.saturating_sub(segments + rank as u64);
        let residual_var = (residual_dof > 0).then(|| {
            std::array::from_fn(|a| {
                let fitted = xy.column(a).dot(&theta.column(a));
                ((yy[a] - fitted) / residual_dof as f64).max(0.0)
            })
        });
        // Cluster-robust covariance: each closed slot and the open segment is one cluster.
        let mut robust_cov: [DMatrix<f64>; 3] = std::array::from_fn(|_| DMatrix::zeros(k, k));
        let used = (self.segments.min(CLUSTERS as u64)) as usize;
        let stored = (0..used).map(|s| (&self.cluster_gram[s], &self.cluster_xy[s]));
        let clusters_iter = stored.chain(open.as_ref().map(|(og, oxy)| (og, oxy)));
        let mut clusters = 0;
        for (cg, cxy) in clusters_iter {
            clusters += 1;
            for (a, cov) in robust_cov.iter_mut().enumerate() {
                let h = cxy.column(a) - cg * theta.column(a);
                let u = &gram_inv * h;
                cov.ger(1.0, &u, &u, 1.0);
            }
        }
        if clusters > 1 {
            let c = clusters as f64 / (clusters as f64 - 1.0);
            for cov in robust_cov.iter_mut() {
                *cov *= c;
            }
        }
        SegmentedSolution {
            theta,
            gram_inv,
            rank,
            residual_var,
            residual_dof,
            robust_cov,
            clusters,
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

    /// Residual noise that random-walks within each segment (as the integrated rotation rows'
    /// does) makes the clustered variance far larger than the i.i.d. one; white noise leaves
    /// the two alike.
    #[test]
    fn the_clustered_variance_sees_autocorrelated_residuals() {
        let mut state = 12345u64;
        let mut normal = move || {
            // Sum of uniforms: close enough to Gaussian for a variance ratio.
            (0..12)
                .map(|_| {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    (state >> 11) as f64 / (1u64 << 53) as f64
                })
                .sum::<f64>()
                - 6.0
        };
        let ratio = |walk: bool, normal: &mut dyn FnMut() -> f64| {
            let mut ls = SegmentedLs::new(1);
            for _ in 0..30 {
                let mut e = 0.0;
                for k in 0..100 {
                    let x = (k as f64 * 0.07).sin() + 0.3 * normal();
                    e = if walk { e + 0.1 * normal() } else { normal() };
                    ls.add(&[x], &Vector3::new(2.0 * x + e, 0.0, 0.0));
                }
                ls.close_segment();
            }
            let s = ls.solve();
            let ols = s.residual_var.unwrap()[0] * s.gram_inv[(0, 0)];
            assert_eq!(s.clusters, 30);
            s.robust_cov[0][(0, 0)] / ols
        };
        let white = ratio(false, &mut normal);
        let walk = ratio(true, &mut normal);
        assert!((0.5..2.0).contains(&white), "white noise: ratio {white:.2}");
        assert!(walk > 3.0, "random walk: ratio {walk:.2}");
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
