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
//!
//! The slots are shared (`Arc`) between copies: the daemon hands a copy of a running fit to its
//! solver thread after every pulse (`crate::solve`), and copying the 32 closed slots of both
//! 70-wide fits (N = 16, under control) was 2.5 MB on the control thread. A closed slot changes only when a segment
//! closes into it, and only then is it copied, if a job still holds it.

use std::sync::Arc;

use nalgebra::{DMatrix, DVector, Vector3};

use super::instruments::{self, Instruments};
use super::prior::PriorEntry;
use crate::estimator::linalg::sym_pinv;

pub use super::segment_basis::CLUSTERS;
use super::segment_basis::{Basis, SegmentSums};

/// Rows and columns [a, b) of `from` into `to` (square, the same size), column by column.
fn copy_block(to: &mut DMatrix<f64>, from: &DMatrix<f64>, a: usize, b: usize) {
    for j in a..b {
        to.column_mut(j)
            .rows_mut(a, b - a)
            .copy_from(&from.column(j).rows(a, b - a));
    }
}

/// The fit: coefficients, the scaled pseudo-inverse of the Gram matrix, residuals.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct SegmentedSolution {
    /// K x 3 coefficients.
    pub theta: DMatrix<f64>,
    /// K x K inverse Gram matrix (covariance / sigma^2).
    pub gram_inv: DMatrix<f64>,
    /// With a prior (`SegmentedLs::solve_with_prior`): per output, the inverse of the Gram
    /// matrix with that output's prior information added, which replaces `gram_inv` there.
    pub output_inv: Option<[DMatrix<f64>; 3]>,
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

impl SegmentedSolution {
    /// The inverse Gram matrix that holds for output `a` (the prior's, when there is one).
    pub fn inverse(&self, a: usize) -> &DMatrix<f64> {
        self.output_inv.as_ref().map_or(&self.gram_inv, |o| &o[a])
    }
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct SegmentedLs {
    k: usize,
    gram: DMatrix<f64>,
    xy: DMatrix<f64>,
    yy: Vector3<f64>,
    rows: u64,
    segments: u64,
    // The open segment: raw sums (lower triangle of its Gram matrix).
    seg_n: u64,
    seg_gram: DMatrix<f64>,
    seg_xy: DMatrix<f64>,
    seg_yy: Vector3<f64>,
    seg_x: DVector<f64>,
    seg_y: Vector3<f64>,
    // Closed segments' centred sums, slot s % CLUSTERS (full symmetric Gram matrices).
    cluster_gram: Vec<Arc<DMatrix<f64>>>,
    cluster_xy: Vec<Arc<DMatrix<f64>>>,
    /// Instruments for the first columns (`with_instruments`): the fit is then
    /// theta = (Z'X)^-1 Z'y ([`instruments`]).
    #[serde(default)]
    iv: Option<Instruments>,
    /// The open segment's ramp sums, when each segment has a ramp besides its intercept
    /// (`with_ramp`).
    #[serde(default)]
    ramp: Option<RampSums>,
    /// Columns [a, b) whose products with each other are not accumulated
    /// ([`Self::skip_block`]): a refit takes them from another fit of the same rows
    /// ([`Self::adopt_block`]).
    #[serde(skip)]
    skip: Option<(usize, usize)>,
}

/// Sums over the open segment weighted by tau, the row's index in it: what a ramp per
/// segment needs besides the plain sums.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct RampSums {
    /// sum tau x (K), sum tau y, sum tau, sum tau^2.
    x: DVector<f64>,
    y: Vector3<f64>,
    t: f64,
    tt: f64,
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
            // One matrix per slot (not one shared by all): a slot is written in place.
            cluster_gram: (0..CLUSTERS)
                .map(|_| Arc::new(DMatrix::zeros(k, k)))
                .collect(),
            cluster_xy: (0..CLUSTERS)
                .map(|_| Arc::new(DMatrix::zeros(k, 3)))
                .collect(),
            iv: None,
            ramp: None,
            skip: None,
        }
    }

    /// Leave the products of columns [a, b) with each other out of the Gram matrices: they
    /// are to be taken from another fit of the same rows whose columns [a, b) are the same
    /// ([`Self::adopt_block`]). Why: the lag search refits the same samples some 20-550 times
    /// with other thrust columns, and the terms' block (37 of the N + 38 columns, ~2/3 of
    /// the products at N = 8) is the same every time. Call before the first row; without
    /// instruments.
    pub fn skip_block(&mut self, a: usize, b: usize) {
        debug_assert!(self.rows == 0 && self.iv.is_none());
        self.skip = Some((a.min(self.k), b.min(self.k)));
    }

    /// Take the skipped block's products from `from`, a fit of the same rows (the same
    /// segments) in which columns [a, b) were the same. Every product is then what a full
    /// fit would hold, bit for bit: each was summed over the same rows in the same order.
    /// False (nothing taken) when `from` is not such a fit.
    pub fn adopt_block(&mut self, from: &SegmentedLs) -> bool {
        let Some((a, b)) = self.skip else {
            return true;
        };
        if from.k != self.k
            || from.skip.is_some()
            || from.rows != self.rows
            || from.segments != self.segments
            || from.seg_n != self.seg_n
        {
            return false;
        }
        let used = (self.segments.min(CLUSTERS as u64)) as usize;
        copy_block(&mut self.gram, &from.gram, a, b);
        copy_block(&mut self.seg_gram, &from.seg_gram, a, b);
        for slot in 0..used {
            copy_block(
                Arc::make_mut(&mut self.cluster_gram[slot]),
                &from.cluster_gram[slot],
                a,
                b,
            );
        }
        self.skip = None;
        true
    }

    /// Each segment gets a ramp besides its intercept (in the row's index within the
    /// segment). Why: the rotation rows regress the integrated rate, so a torque the model
    /// does not have (a swell's) appears in a segment as a ramp, not a constant; with the
    /// ramp, each segment has its own constant disturbance torque.
    pub fn with_ramp(mut self) -> Self {
        self.ramp = Some(RampSums {
            x: DVector::zeros(self.k),
            y: Vector3::zeros(),
            t: 0.0,
            tt: 0.0,
        });
        self
    }

    /// The open segment's basis sums.
    fn basis(&self) -> Basis {
        Basis {
            n: self.seg_n as f64,
            t: self.ramp.as_ref().map_or(0.0, |r| r.t),
            tt: self.ramp.as_ref().map_or(0.0, |r| r.tt),
            ramp: self.ramp.is_some(),
        }
    }

    /// Column i's sum tau x over the open segment (0 without a ramp).
    fn ramp_x(&self, i: usize) -> f64 {
        self.ramp.as_ref().map_or(0.0, |r| r.x[i])
    }

    /// Output a's sum tau y over the open segment (0 without a ramp).
    fn ramp_y(&self, a: usize) -> f64 {
        self.ramp.as_ref().map_or(0.0, |r| r.y[a])
    }

    /// The open segment's sums for the instruments' centring.
    fn segment_sums(&self) -> SegmentSums<'_> {
        SegmentSums {
            x: &self.seg_x,
            rx: self.ramp.as_ref().map(|r| &r.x),
            y: self.seg_y,
            ry: self.ramp.as_ref().map_or(Vector3::zeros(), |r| r.y),
            basis: self.basis(),
        }
    }

    /// The first `c` columns get instruments ([`Self::add_instrumented`]); the fit is then by
    /// instrumental variables.
    pub fn with_instruments(mut self, c: usize) -> Self {
        self.iv = Some(Instruments::new(c.min(self.k), self.k));
        self
    }

    /// Whether the fit is by instrumental variables.
    pub fn instrumented(&self) -> bool {
        self.iv.is_some()
    }

    /// The same rows fitted by least squares: a copy without the instruments (it keeps their
    /// least-squares sums anyway), for a solve to compare with.
    pub fn without_instruments(&self) -> SegmentedLs {
        SegmentedLs {
            iv: None,
            ..self.clone()
        }
    }

    /// One row with the first columns' instruments `z` (as many as `with_instruments` said;
    /// without instruments, `z` is ignored).
    pub fn add_instrumented(&mut self, x: &[f64], z: &[f64], y: &Vector3<f64>) {
        let tau = self.seg_n as f64;
        if let Some(iv) = self.iv.as_mut() {
            iv.add(z, x, y, tau);
        }
        self.add(x, y);
    }

    /// Columns.
    pub fn width(&self) -> usize {
        self.k
    }

    /// Rows added so far.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// One row; `x` has `width()` entries. Only the lower triangle of the open segment's Gram
    /// matrix is accumulated, column by column: a column's rows are contiguous in memory, so
    /// the products vectorise (summed along the rows of the upper triangle, strided, this was
    /// 61 % of a lag search's time). Each sum gets the same products in the same order as
    /// before, so the fit is the same to the bit.
    pub fn add(&mut self, x: &[f64], y: &Vector3<f64>) {
        debug_assert_eq!(x.len(), self.k);
        let k = self.k;
        let (a, b) = self.skip.unwrap_or((0, 0));
        let gram = self.seg_gram.as_mut_slice();
        for (i, &xi) in x.iter().enumerate() {
            if xi == 0.0 {
                continue;
            }
            // In the skipped block, only the products with the columns after it.
            let from = if (a..b).contains(&i) { b } else { i };
            let column = &mut gram[i * k + from..(i + 1) * k];
            for (g, xj) in column.iter_mut().zip(&x[from..]) {
                *g += xi * xj;
            }
        }
        let xy = self.seg_xy.as_mut_slice();
        for (out, column) in xy.chunks_exact_mut(k).enumerate() {
            let ya = y[out];
            for (s, xi) in column.iter_mut().zip(x) {
                *s += xi * ya;
            }
        }
        for (s, xi) in self.seg_x.iter_mut().zip(x) {
            *s += xi;
        }
        self.seg_yy += y.component_mul(y);
        self.seg_y += y;
        if let Some(r) = self.ramp.as_mut() {
            let tau = self.seg_n as f64;
            for (rx, xi) in r.x.iter_mut().zip(x) {
                *rx += tau * xi;
            }
            r.y += y * tau;
            r.t += tau;
            r.tt += tau * tau;
        }
        self.seg_n += 1;
        self.rows += 1;
    }

    /// The open segment's centred sums (Gram matrix full), into `gram` and `xy`; its centred
    /// sum of squared outputs is returned.
    fn centred_open(&self, gram: &mut DMatrix<f64>, xy: &mut DMatrix<f64>) -> Vector3<f64> {
        let b = self.basis();
        for i in 0..self.k {
            let (si, ri) = (self.seg_x[i], self.ramp_x(i));
            for j in i..self.k {
                let v = self.seg_gram[(j, i)] - b.explained(si, ri, self.seg_x[j], self.ramp_x(j));
                gram[(i, j)] = v;
                gram[(j, i)] = v;
            }
            for a in 0..3 {
                xy[(i, a)] =
                    self.seg_xy[(i, a)] - b.explained(si, ri, self.seg_y[a], self.ramp_y(a));
            }
        }
        self.centred_yy(&b)
    }

    /// The open segment's sum of squared outputs with its nuisance projected out.
    fn centred_yy(&self, b: &Basis) -> Vector3<f64> {
        Vector3::from_fn(|a, _| {
            let (s, r) = (self.seg_y[a], self.ramp_y(a));
            self.seg_yy[a] - b.explained(s, r, s, r)
        })
    }

    /// Close the open segment: its intercept is projected out.
    pub fn close_segment(&mut self) {
        if self.seg_n == 0 {
            return;
        }
        let slot = (self.segments % CLUSTERS as u64) as usize;
        if let Some(mut iv) = self.iv.take() {
            iv.close_segment(slot, &self.segment_sums());
            self.iv = Some(iv);
        }
        // Centre into the slot's spare room: the slot is summed into, so centre into the
        // open segment's own buffers first (no allocation).
        let mut g = std::mem::replace(&mut self.seg_gram, DMatrix::zeros(0, 0));
        let mut xy = std::mem::replace(&mut self.seg_xy, DMatrix::zeros(0, 0));
        let b = self.basis();
        for i in 0..self.k {
            let (si, ri) = (self.seg_x[i], self.ramp_x(i));
            for j in i..self.k {
                g[(j, i)] -= b.explained(si, ri, self.seg_x[j], self.ramp_x(j));
                g[(i, j)] = g[(j, i)];
            }
            for a in 0..3 {
                xy[(i, a)] -= b.explained(si, ri, self.seg_y[a], self.ramp_y(a));
            }
        }
        self.yy += self.centred_yy(&b);
        self.gram += &g;
        self.xy += &xy;
        // In place unless a solve job still holds this slot (then it is copied first).
        *Arc::make_mut(&mut self.cluster_gram[slot]) += &g;
        *Arc::make_mut(&mut self.cluster_xy[slot]) += &xy;
        g.fill(0.0);
        xy.fill(0.0);
        self.seg_gram = g;
        self.seg_xy = xy;
        self.segments += 1;
        self.seg_n = 0;
        self.seg_yy = Vector3::zeros();
        self.seg_x.fill(0.0);
        self.seg_y = Vector3::zeros();
        if let Some(r) = self.ramp.as_mut() {
            r.x.fill(0.0);
            r.y = Vector3::zeros();
            r.t = 0.0;
            r.tt = 0.0;
        }
    }

    /// The centred normal equations over every row so far: the symmetric Gram matrix X'X
    /// (K x K) and the cross products X'y (K x 3), the segments' intercepts projected out.
    pub fn centred_sums(&self) -> (DMatrix<f64>, DMatrix<f64>) {
        let n = self.normal_equations();
        (n.g, n.xy)
    }

    /// The normal equations over every row so far (the open segment counted as if closed
    /// now), the Gram matrix made symmetric.
    fn normal_equations(&self) -> Normal {
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
        Normal {
            g,
            xy,
            yy,
            segments,
            open,
        }
    }

    /// Every cluster's centred (Gram matrix, cross products): each closed slot and the open
    /// segment.
    fn clusters<'a>(
        &'a self,
        open: &'a Option<(DMatrix<f64>, DMatrix<f64>)>,
    ) -> impl Iterator<Item = (&'a DMatrix<f64>, &'a DMatrix<f64>)> {
        let used = (self.segments.min(CLUSTERS as u64)) as usize;
        let stored = (0..used).map(|s| (&*self.cluster_gram[s], &*self.cluster_xy[s]));
        stored.chain(open.as_ref().map(|(og, oxy)| (og, oxy)))
    }

    /// The residual variance per output of the fit over every row so far, without the
    /// covariances `solve` also makes: the lag search's score. None without residual degrees
    /// of freedom. Solved by Cholesky on the scaled Gram matrix with a 1e-9 ridge rather than
    /// `solve`'s rank-truncated pseudo-inverse: the truncation flips with a tiny change of
    /// the lag and made the profile jagged by 0.01-0.03 in ln(variance), as much as the
    /// signal between lags 20 ms apart (eight_vectored, realistic IMU). Floored at 1e-10 of
    /// the output's own variance: below that, `yy - fitted` is rounding (noise-free, an
    /// output the model explains exactly came out 0 or 1e-300 at random).
    pub fn residual_variance(&self) -> Option<[f64; 3]> {
        let Normal {
            g,
            xy,
            yy,
            segments,
            ..
        } = self.normal_equations();
        let k = self.k;
        let d = DVector::from_fn(k, |i, _| {
            let v = g[(i, i)];
            if v > 0.0 {
                1.0 / v.sqrt()
            } else {
                0.0
            }
        });
        let used = d.iter().filter(|v| **v > 0.0).count();
        let scaled = DMatrix::from_fn(k, k, |i, j| {
            g[(i, j)] * d[i] * d[j] + if i == j { 1e-9 } else { 0.0 }
        });
        let chol = scaled.cholesky()?;
        let dof = self.rows.saturating_sub(segments + used as u64);
        if dof == 0 {
            return None;
        }
        Some(std::array::from_fn(|a| {
            let b = DVector::from_fn(k, |i, _| xy[(i, a)] * d[i]);
            let theta = chol.solve(&b);
            let fitted = b.dot(&theta);
            let floor = 1e-10 * yy[a].max(0.0) / dof as f64;
            ((yy[a] - fitted) / dof as f64).max(floor)
        }))
    }

    /// ln of [`Self::residual_variance`] per output, as the lag's profile scores it: a
    /// noise-free fit can leave an exactly zero residual, floored at 1e-300, not -inf.
    pub fn ln_residual_variance(&self) -> Option<[f64; 3]> {
        Some(self.residual_variance()?.map(|v| v.max(1e-300).ln()))
    }

    /// The fit over every row so far (the open segment counted as if closed now).
    pub fn solve(&self) -> SegmentedSolution {
        if let Some(iv) = &self.iv {
            return self.solve_instrumented(iv, None);
        }
        let Normal {
            g,
            xy,
            yy,
            segments,
            open,
        } = self.normal_equations();
        let (gram_inv, rank) = scaled_pinv(&g);
        let theta = &gram_inv * &xy;
        let residual_dof = self.rows.saturating_sub(segments + rank as u64);
        let residual_var = (residual_dof > 0).then(|| {
            std::array::from_fn(|a| {
                let fitted = xy.column(a).dot(&theta.column(a));
                ((yy[a] - fitted) / residual_dof as f64).max(0.0)
            })
        });
        // Cluster-robust covariance: each closed slot and the open segment is one cluster.
        let mut robust_cov: [DMatrix<f64>; 3] =
            std::array::from_fn(|_| DMatrix::zeros(self.k, self.k));
        let mut clusters = 0;
        for (cg, cxy) in self.clusters(&open) {
            clusters += 1;
            for (a, cov) in robust_cov.iter_mut().enumerate() {
                let h = cxy.column(a) - cg * theta.column(a);
                let u = &gram_inv * h;
                cov.ger(1.0, &u, &u, 1.0);
            }
        }
        scale_small_sample(&mut robust_cov, clusters);
        SegmentedSolution {
            theta,
            gram_inv,
            output_inv: None,
            rank,
            residual_var,
            residual_dof,
            robust_cov,
            clusters,
        }
    }

    /// The fit with prior knowledge of some coefficients: per output `a`, `priors[a]` (linear
    /// combinations with a value and a standard error), weighed against the data at that
    /// output's noise `sigma[a]`: the normal equations gain sigma^2 / se^2 w w' and
    /// sigma^2 / se^2 w value (the information form of a Gaussian prior). The residual level
    /// and degrees of freedom stay the data's. The robust covariance is the data clusters'
    /// sandwich plus the prior's own share, G_a^-1 sigma^2 P_a G_a^-1, so a coefficient the data
    /// barely touches keeps the prior's standard error rather than none.
    /// `base` is this fit's own `solve()`, already at hand where the prior is checked.
    pub fn solve_with_prior(
        &self,
        base: SegmentedSolution,
        priors: &[Vec<PriorEntry>; 3],
        sigma: &[f64; 3],
    ) -> SegmentedSolution {
        if let Some(iv) = &self.iv {
            return self.solve_instrumented(iv, Some((priors, sigma)));
        }
        let Normal { g, xy, open, .. } = self.normal_equations();
        let k = self.k;
        let mut theta = DMatrix::zeros(k, 3);
        let mut robust_cov: [DMatrix<f64>; 3] = std::array::from_fn(|_| DMatrix::zeros(k, k));
        let mut output_inv: [DMatrix<f64>; 3] = std::array::from_fn(|_| DMatrix::zeros(k, k));
        for a in 0..3 {
            let s2 = sigma[a] * sigma[a];
            let mut ga = g.clone();
            let mut ra = xy.column(a).clone_owned();
            let pa = prior_information(k, &priors[a], s2, &mut ra);
            ga += &pa;
            let (inv, _) = scaled_pinv(&ga);
            let th = &inv * &ra;
            let mut meat = &pa * s2;
            let mut data = DMatrix::zeros(k, k);
            for (cg, cxy) in self.clusters(&open) {
                let h = cxy.column(a) - cg * &th;
                data.ger(1.0, &h, &h, 1.0);
            }
            if base.clusters > 1 {
                data *= base.clusters as f64 / (base.clusters as f64 - 1.0);
            }
            meat += data;
            robust_cov[a] = &inv * meat * &inv;
            theta.set_column(a, &th);
            output_inv[a] = inv;
        }
        SegmentedSolution {
            theta,
            output_inv: Some(output_inv),
            robust_cov,
            ..base
        }
    }
}

impl SegmentedLs {
    /// The fit by instrumental variables ([`instruments`]), with a prior's information when
    /// `prior` (entries and noise per output) is given. Solved as two-stage least squares,
    /// which is the instrumental-variables estimate when Z'X is invertible and keeps the
    /// least squares' rank handling when it is not (under control some terms barely move):
    /// with H = (Z'X)' (Z'Z)^-1 (Z'X), theta = (H + P)^-1 ((Z'X)' (Z'Z)^-1 Z'y + P theta0).
    /// Covariances: i.i.d. (H + P)^-1 per sigma^2 (in `gram_inv` / `output_inv`); robust
    /// M (sum_s h_s h_s') M' + (H + P)^-1 sigma^2 P (H + P)^-1, M = (H + P)^-1 (Z'X)' (Z'Z)^-1,
    /// h_s = sum over the segment of z e.
    fn solve_instrumented(
        &self,
        iv: &Instruments,
        prior: Option<(&[Vec<PriorEntry>; 3], &[f64; 3])>,
    ) -> SegmentedSolution {
        let Normal {
            g,
            xy,
            yy,
            segments,
            open,
        } = self.normal_equations();
        let k = self.k;
        let c = iv.instrumented();
        let sums = iv.sums(&self.segment_sums());
        let (za, zb) = instruments::instrumented_normal(&g, &xy, &sums.tx, &sums.ty);
        let zz = instruments::instrument_gram(&g, &sums.tx, &sums.tt);
        let (zz_inv, _) = scaled_pinv(&zz);
        // (Z'X)' (Z'Z)^-1: the first stage's projection, shared by H, the right-hand side and M.
        let proj = za.transpose() * &zz_inv;
        let mut h = &proj * &za;
        for i in 0..k {
            for j in 0..i {
                let v = 0.5 * (h[(i, j)] + h[(j, i)]);
                h[(i, j)] = v;
                h[(j, i)] = v;
            }
        }
        let rhs0 = &proj * &zb;
        let used = (self.segments.min(CLUSTERS as u64)) as usize;
        let mut theta = DMatrix::zeros(k, 3);
        let mut robust_cov: [DMatrix<f64>; 3] = std::array::from_fn(|_| DMatrix::zeros(k, k));
        let mut output_inv: [DMatrix<f64>; 3] = std::array::from_fn(|_| DMatrix::zeros(k, k));
        let mut rank = 0;
        let mut clusters = 0;
        for a in 0..3 {
            let mut rhs = rhs0.column(a).clone_owned();
            let s2 = prior.map_or(0.0, |(_, sigma)| sigma[a] * sigma[a]);
            let pa = match prior {
                Some((entries, _)) => prior_information(k, &entries[a], s2, &mut rhs),
                None => DMatrix::zeros(k, k),
            };
            let (inv, r) = scaled_pinv(&(&h + &pa));
            rank = r;
            let th = &inv * rhs;
            let m = &inv * &proj;
            let iv_clusters = iv
                .clusters(used)
                .chain(sums.open.as_ref().map(|(t, y)| (t, y)));
            let mut data = DMatrix::zeros(k, k);
            clusters = 0;
            for ((cg, cxy), (ctx, cty)) in self.clusters(&open).zip(iv_clusters) {
                clusters += 1;
                let mut hs = cxy.column(a) - cg * &th;
                let ht = cty.column(a) - ctx * &th;
                hs.rows_mut(0, c).copy_from(&ht);
                let u = &m * hs;
                data.ger(1.0, &u, &u, 1.0);
            }
            if clusters > 1 {
                data *= clusters as f64 / (clusters as f64 - 1.0);
            }
            robust_cov[a] = data + &inv * (&pa * s2) * &inv;
            output_inv[a] = inv;
            theta.set_column(a, &th);
        }
        let residual_dof = self.rows.saturating_sub(segments + rank as u64);
        let residual_var = (residual_dof > 0).then(|| {
            std::array::from_fn(|a| {
                let th = theta.column(a);
                let fitted = 2.0 * xy.column(a).dot(&th) - th.dot(&(&g * th));
                ((yy[a] - fitted) / residual_dof as f64).max(0.0)
            })
        });
        let gram_inv = output_inv[0].clone();
        SegmentedSolution {
            theta,
            gram_inv,
            output_inv: Some(output_inv),
            rank,
            residual_var,
            residual_dof,
            robust_cov,
            clusters,
        }
    }
}

/// A prior's information for one output at noise variance `s2`: returns P (K x K) and adds
/// P theta0 to `rhs` (the information form of a Gaussian prior, sigma^2 / se^2 w w').
fn prior_information(
    k: usize,
    entries: &[PriorEntry],
    s2: f64,
    rhs: &mut DVector<f64>,
) -> DMatrix<f64> {
    let mut pa = DMatrix::zeros(k, k);
    for e in entries {
        if !(e.std_err > 0.0 && e.std_err.is_finite() && e.value.is_finite()) {
            continue;
        }
        let w = s2 / (e.std_err * e.std_err);
        for &(i, wi) in &e.weights {
            if wi == 0.0 || i >= k {
                continue;
            }
            rhs[i] += w * wi * e.value;
            for &(j, wj) in &e.weights {
                if wj != 0.0 && j < k {
                    pa[(i, j)] += w * wi * wj;
                }
            }
        }
    }
    pa
}

/// The normal equations of a [`SegmentedLs`] and its open segment's centred sums.
#[derive(serde::Serialize, serde::Deserialize)]
struct Normal {
    g: DMatrix<f64>,
    xy: DMatrix<f64>,
    yy: Vector3<f64>,
    segments: u64,
    open: Option<(DMatrix<f64>, DMatrix<f64>)>,
}

/// Pseudo-inverse of a Gram matrix, scaled to a unit diagonal first (Jacobi): the regressors
/// (commands, rates, squared velocities, products) span many orders of magnitude. Unexcited
/// columns stay zero.
pub(crate) fn scaled_pinv(g: &DMatrix<f64>) -> (DMatrix<f64>, usize) {
    let k = g.nrows();
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
    (
        DMatrix::from_fn(k, k, |i, j| inv_s[(i, j)] * d[i] * d[j]),
        rank,
    )
}

/// The cluster-robust covariance's small-sample factor S / (S - 1).
fn scale_small_sample(cov: &mut [DMatrix<f64>; 3], clusters: usize) {
    if clusters > 1 {
        let c = clusters as f64 / (clusters as f64 - 1.0);
        for m in cov.iter_mut() {
            *m *= c;
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
