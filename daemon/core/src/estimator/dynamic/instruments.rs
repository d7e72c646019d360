//! Instrumental variables for the thrust columns of a [`super::segmented_ls::SegmentedLs`]:
//! the sums that let the fit use the dither, not the command, as what explains the thrust.
//!
//! Why: under control the command is the controller's answer to the motion plus the dither.
//! In moving water the controller answers the swell, so its part of the command correlates
//! with the swell's unmodelled force, the fit's residual, and least squares takes the
//! controller's answer for thrust (moderate water, noise-free: the model 6.7 % off under a
//! bound of 3.2 %, docs/study.md). The dither's signs are drawn independently of everything,
//! the water too, so a thrust column's instrument built from them alone (through the same lag
//! and integral as the command) is uncorrelated with the residual and the estimate is
//! consistent: theta = (Z'X)^-1 Z'y, Z the instruments, X the regressors.
//!
//! Only the first `c` columns (the thrust) are instrumented; the terms instrument themselves,
//! so Z'X differs from X'X only in its first `c` rows, and only those are kept here: c x K
//! cross products with the regressors, c x c with themselves, c x 3 with the outputs, each
//! centred per segment like the least squares' own sums. Per segment (the clusters of the
//! robust covariance) the c x K and c x 3 sums are kept as well.

use std::sync::Arc;

use nalgebra::{DMatrix, DVector, Vector3};

use super::segment_basis::{SegmentSums, CLUSTERS};
use super::DynamicSolution;

/// How far apart (in standard deviations of their difference) the instrumented and the
/// least-squares B may be, at the most different of a row group's 3N entries, before the
/// instrumented one is taken: the largest of 15-24 independent standard normals passes 3.5
/// about once in 100-150 fits. Measured in moderate water (seeds 1-10, realistic IMU): 3, 3.5
/// and 4 gave the same coverage (AMOUR-5 1.24, eight_vectored 1.12); AMOUR-5's decisive
/// values were 2.9-19.6 (rotation) and 1.9-43 (acceleration), eight_vectored's 1.9-4.9.
pub const DISAGREE_Z: f64 = 3.5;

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Instruments {
    c: usize,
    k: usize,
    /// Closed segments' centred sums: Z_t'X (c x K), Z_t'Z_t (c x c), Z_t'y (c x 3).
    tx: DMatrix<f64>,
    tt: DMatrix<f64>,
    ty: DMatrix<f64>,
    // The open segment's raw sums and the instruments' sums.
    seg_tx: DMatrix<f64>,
    seg_tt: DMatrix<f64>,
    seg_ty: DMatrix<f64>,
    seg_t: DVector<f64>,
    /// sum tau z over the open segment (for a ramp per segment).
    #[serde(default)]
    seg_rt: Option<DVector<f64>>,
    cluster_tx: Vec<Arc<DMatrix<f64>>>,
    cluster_ty: Vec<Arc<DMatrix<f64>>>,
}

/// The instrumented rows' centred sums over every row so far (the open segment included),
/// and the open segment's alone (for its cluster).
pub struct InstrumentSums {
    pub tx: DMatrix<f64>,
    pub tt: DMatrix<f64>,
    pub ty: DMatrix<f64>,
    pub open: Option<(DMatrix<f64>, DMatrix<f64>)>,
}

impl Instruments {
    /// Instruments for the first `c` of `k` columns.
    pub fn new(c: usize, k: usize) -> Self {
        Instruments {
            c,
            k,
            tx: DMatrix::zeros(c, k),
            tt: DMatrix::zeros(c, c),
            ty: DMatrix::zeros(c, 3),
            seg_tx: DMatrix::zeros(c, k),
            seg_tt: DMatrix::zeros(c, c),
            seg_ty: DMatrix::zeros(c, 3),
            seg_t: DVector::zeros(c),
            seg_rt: Some(DVector::zeros(c)),
            cluster_tx: (0..CLUSTERS)
                .map(|_| Arc::new(DMatrix::zeros(c, k)))
                .collect(),
            cluster_ty: (0..CLUSTERS)
                .map(|_| Arc::new(DMatrix::zeros(c, 3)))
                .collect(),
        }
    }

    pub fn instrumented(&self) -> usize {
        self.c
    }

    /// One row, the `tau`-th of its segment: the thrust columns' instruments `z` (c values),
    /// the regressors `x`, outputs `y`.
    pub fn add(&mut self, z: &[f64], x: &[f64], y: &Vector3<f64>, tau: f64) {
        for (i, &zi) in z.iter().enumerate().take(self.c) {
            if zi == 0.0 {
                continue;
            }
            for (j, &xj) in x.iter().enumerate().take(self.k) {
                self.seg_tx[(i, j)] += zi * xj;
            }
            for (j, &zj) in z.iter().enumerate().take(self.c) {
                self.seg_tt[(i, j)] += zi * zj;
            }
            for a in 0..3 {
                self.seg_ty[(i, a)] += zi * y[a];
            }
            self.seg_t[i] += zi;
            if let Some(rt) = self.seg_rt.as_mut() {
                rt[i] += tau * zi;
            }
        }
    }

    /// The open segment's centred sums (its intercept, and its ramp when the fit has one,
    /// projected out), given the segment's own sums: a copy, for a solve.
    fn centred_open(&self, seg: &SegmentSums) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
        let b = &seg.basis;
        let rt = |i: usize| self.seg_rt.as_ref().map_or(0.0, |r| r[i]);
        let rx = |j: usize| seg.rx.map_or(0.0, |r| r[j]);
        let (c, k) = (self.c, self.k);
        let t = &self.seg_t;
        let tx = DMatrix::from_fn(c, k, |i, j| {
            self.seg_tx[(i, j)] - b.explained(t[i], rt(i), seg.x[j], rx(j))
        });
        let tt = DMatrix::from_fn(c, c, |i, j| {
            self.seg_tt[(i, j)] - b.explained(t[i], rt(i), t[j], rt(j))
        });
        let ty = DMatrix::from_fn(c, 3, |i, a| {
            self.seg_ty[(i, a)] - b.explained(t[i], rt(i), seg.y[a], seg.ry[a])
        });
        (tx, tt, ty)
    }

    /// The segment closes into cluster `slot`. Centred in the open segment's own buffers, as
    /// the least squares' sums are: this runs on the sample that closes a segment, which must
    /// not allocate.
    pub(super) fn close_segment(&mut self, slot: usize, seg: &SegmentSums) {
        if seg.basis.rows() == 0.0 {
            return;
        }
        let b = &seg.basis;
        let rx = |j: usize| seg.rx.map_or(0.0, |r| r[j]);
        for i in 0..self.c {
            let (ti, ri) = (self.seg_t[i], self.seg_rt.as_ref().map_or(0.0, |r| r[i]));
            for j in 0..self.k {
                self.seg_tx[(i, j)] -= b.explained(ti, ri, seg.x[j], rx(j));
            }
            for j in 0..self.c {
                let rj = self.seg_rt.as_ref().map_or(0.0, |r| r[j]);
                self.seg_tt[(i, j)] -= b.explained(ti, ri, self.seg_t[j], rj);
            }
            for a in 0..3 {
                self.seg_ty[(i, a)] -= b.explained(ti, ri, seg.y[a], seg.ry[a]);
            }
        }
        self.tx += &self.seg_tx;
        self.tt += &self.seg_tt;
        self.ty += &self.seg_ty;
        // In place unless a solve job still holds this slot (then it is copied first).
        *Arc::make_mut(&mut self.cluster_tx[slot]) += &self.seg_tx;
        *Arc::make_mut(&mut self.cluster_ty[slot]) += &self.seg_ty;
        self.seg_tx.fill(0.0);
        self.seg_tt.fill(0.0);
        self.seg_ty.fill(0.0);
        self.seg_t.fill(0.0);
        if let Some(rt) = self.seg_rt.as_mut() {
            rt.fill(0.0);
        }
    }

    /// The sums over every row so far, the open segment counted as if closed now.
    pub(super) fn sums(&self, seg: &SegmentSums) -> InstrumentSums {
        let (mut tx, mut tt, mut ty) = (self.tx.clone(), self.tt.clone(), self.ty.clone());
        let mut open = None;
        if seg.basis.rows() > 0.0 {
            let (otx, ott, oty) = self.centred_open(seg);
            tx += &otx;
            tt += &ott;
            ty += &oty;
            open = Some((otx, oty));
        }
        InstrumentSums { tx, tt, ty, open }
    }

    /// The closed clusters' (Z_t'X, Z_t'y), `used` of them.
    pub fn clusters(&self, used: usize) -> impl Iterator<Item = (&DMatrix<f64>, &DMatrix<f64>)> {
        (0..used).map(|s| (&*self.cluster_tx[s], &*self.cluster_ty[s]))
    }
}

/// Z'X (K x K) and Z'y (K x 3) from the least squares' centred X'X and X'y and the
/// instrumented rows' sums: rows 0..c from the instruments, the rest from X'X and X'y.
pub fn instrumented_normal(
    g: &DMatrix<f64>,
    xy: &DMatrix<f64>,
    tx: &DMatrix<f64>,
    ty: &DMatrix<f64>,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let c = tx.nrows();
    let mut a = g.clone();
    let mut b = xy.clone();
    a.rows_mut(0, c).copy_from(tx);
    b.rows_mut(0, c).copy_from(ty);
    (a, b)
}

/// Z'Z (K x K): the instruments' block `tt`, their cross products with the terms (the last
/// K - c columns of Z_t'X), and the terms' own block of X'X.
pub fn instrument_gram(g: &DMatrix<f64>, tx: &DMatrix<f64>, tt: &DMatrix<f64>) -> DMatrix<f64> {
    let (c, k) = tx.shape();
    let mut zz = g.clone();
    zz.view_mut((0, 0), (c, c)).copy_from(tt);
    for i in 0..c {
        for j in c..k {
            zz[(i, j)] = tx[(i, j)];
            zz[(j, i)] = tx[(i, j)];
        }
    }
    zz
}

/// Per row group (rotation, acceleration): the instrumented fit `iv` where it disagrees with
/// the least-squares fit `ls` of the same rows, `ls` where they agree (a Durbin-Wu-Hausman
/// test). Why: when nothing the controller answers is in the residual, least squares is
/// right and the more precise (it also learns from the controller's commands, not only the
/// dither); instrumented throughout, a thruster turned unannounced during pitch steps in still
/// water (the vehicle swinging 4.3 deg RMS on the wrong model, read as a sea) took 11 s
/// instead of 5. When the controller answers the water, the two differ by more than the
/// instrument's extra spread: the entry-wise largest |b_iv - b_ls| / sqrt(se_iv^2 - se_ls^2)
/// over a group's B beyond [`DISAGREE_Z`] takes the instrumented group.
pub fn choose(iv: DynamicSolution, ls: DynamicSolution, n: usize) -> DynamicSolution {
    let mut out = ls;
    let mut any = false;
    for g in 0..2 {
        let mut worst = 0.0f64;
        for row in 3 * g..3 * g + 3 {
            for i in 0..n {
                let d = iv.b[(row, i)] - out.b[(row, i)];
                let (vi, vl) = (iv.std_err[(row, i)].powi(2), out.std_err[(row, i)].powi(2));
                // The instrument is the less precise; where round-off says otherwise, its own.
                let v = if vi > vl { vi - vl } else { vi };
                if d.is_finite() && v.is_finite() && v > 0.0 {
                    worst = worst.max(d.abs() / v.sqrt());
                }
            }
        }
        if worst <= DISAGREE_Z {
            continue;
        }
        any = true;
        let rows = 3 * g..3 * g + 3;
        for row in rows {
            out.b.set_row(row, &iv.b.row(row));
            out.std_err.set_row(row, &iv.std_err.row(row));
            out.sigma[row] = iv.sigma[row];
            let (t, ti) = (&mut out.terms, &iv.terms);
            t.coefficients.set_row(row, &ti.coefficients.row(row));
            t.std_err.set_row(row, &ti.std_err.row(row));
            t.ols_std_err.set_row(row, &ti.ols_std_err.row(row));
            t.b_ols_std_err.set_row(row, &ti.b_ols_std_err.row(row));
            if let (Some((sb, sse)), Some((ib, ise))) = (out.split.as_mut(), iv.split.as_ref()) {
                sb.set_row(row, &ib.row(row));
                sse.set_row(row, &ise.row(row));
            }
        }
        out.rel_err[g] = iv.rel_err[g];
        out.terms.instrumented[g] = true;
    }
    if any {
        out.excited &= iv.excited;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::segmented_ls::SegmentedLs;
    use nalgebra::Vector3;

    /// One run of a regressor made partly of the residual (the controller answering the
    /// water): (least squares' coefficient, the instrumented one, its robust variance, the
    /// instrumented term's coefficient).
    fn answering_the_water(seed: u64) -> (f64, f64, f64, f64) {
        let mut state = seed;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let (mut ols, mut iv) = (SegmentedLs::new(2), SegmentedLs::new(2).with_instruments(1));
        // Each run its own sea: the swell's phase is random too.
        let phase = 20.0 * uniform();
        for seg in 0..40 {
            for k in 0..100 {
                let t = (seg * 100 + k) as f64 * 0.01;
                let water = (0.9 * t + phase).sin() + 0.3 * uniform();
                let dither = if uniform() > 0.0 { 1.0 } else { -1.0 };
                let term = uniform();
                // The command: dither plus the controller's answer to the water.
                let u = 0.3 * dither - 0.8 * water;
                let y = 2.0 * u - 1.5 * term + water;
                let out = Vector3::new(y, 0.0, 0.0);
                ols.add(&[u, term], &out);
                iv.add_instrumented(&[u, term], &[dither], &out);
            }
            ols.close_segment();
            iv.close_segment();
        }
        let (o, i) = (ols.solve(), iv.solve());
        (
            o.theta[(0, 0)],
            i.theta[(0, 0)],
            i.robust_cov[0][(0, 0)],
            i.theta[(1, 0)],
        )
    }

    /// Least squares takes the controller's answer to the water for thrust; the instrument,
    /// independent of the water, recovers the coefficient, and its robust variance matches
    /// the estimate's spread over runs.
    #[test]
    fn an_instrument_removes_the_bias_of_a_regressor_that_answers_the_residual() {
        let runs: Vec<_> = (1..=40).map(|s| answering_the_water(s * 7919)).collect();
        let k = runs.len() as f64;
        let ols = runs.iter().map(|r| r.0).sum::<f64>() / k;
        let iv = runs.iter().map(|r| r.1).sum::<f64>() / k;
        let term = runs.iter().map(|r| r.3).sum::<f64>() / k;
        assert!((ols - 2.0).abs() > 0.2, "least squares {ols}");
        assert!((iv - 2.0).abs() < 0.02, "instrumented {iv}");
        assert!((term + 1.5).abs() < 0.02, "instrumented term {term}");
        let spread = runs.iter().map(|r| (r.1 - iv).powi(2)).sum::<f64>() / (k - 1.0);
        let claimed = runs.iter().map(|r| r.2).sum::<f64>() / k;
        let ratio = claimed / spread;
        assert!(
            (0.6..1.6).contains(&ratio),
            "claimed / actual variance {ratio:.2}"
        );
    }

    /// A column instrumented by itself is least squares: the same coefficients, robust and
    /// i.i.d. covariances.
    #[test]
    fn a_column_its_own_instrument_is_least_squares() {
        let (mut ols, mut iv) = (SegmentedLs::new(3), SegmentedLs::new(3).with_instruments(2));
        for seg in 0..7 {
            for k in 0..50 {
                let t = (seg * 50 + k) as f64 * 0.02;
                let x = [t.sin(), (2.3 * t).cos(), (0.7 * t).sin() * t];
                let y = Vector3::new(
                    x[0] - 2.0 * x[1] + (5.0 * t).sin(),
                    0.5 * x[2] + (3.0 * t).cos(),
                    seg as f64,
                );
                ols.add(&x, &y);
                iv.add_instrumented(&x, &x[..2], &y);
            }
            // The last segment stays open.
            if seg < 6 {
                ols.close_segment();
                iv.close_segment();
            }
        }
        let (o, i) = (ols.solve(), iv.solve());
        assert_eq!(o.clusters, i.clusters);
        let close = |a: &nalgebra::DMatrix<f64>, b: &nalgebra::DMatrix<f64>| {
            (a - b).norm() <= 1e-8 * (1.0 + a.norm())
        };
        assert!(close(&o.theta, &i.theta), "{} {}", o.theta, i.theta);
        assert!(close(&o.gram_inv, &i.gram_inv));
        for a in 0..3 {
            assert!(close(&o.robust_cov[a], &i.robust_cov[a]), "output {a}");
        }
    }
}
