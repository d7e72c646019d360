//! What is known before a dynamic fit starts: thruster columns carried over from the model in
//! force when only part of the vehicle changed (one thruster moved, added or removed), each
//! entry with its standard error. The fit weighs them like measurements (a Gaussian prior, the
//! information form of a Kalman update), so the data only has to teach it what changed.
//!
//! Why: after an announced change of one thruster, re-learning every column from nothing
//! spends the attitude budget on what is already known. At the paper's noise a full
//! closed-loop fit needed 15 s for the rotation rows and about 55 s for the acceleration rows
//! (docs/experiments.md); the moved thruster's column alone is six unknowns, not 6 N.

use nalgebra::DMatrix;

/// Known coefficients of a dynamic fit for N thrusters. Entries with an infinite or NaN
/// standard error (or a NaN value) are unknown and left to the data.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DynamicPrior {
    /// 6 x N effectiveness, DOF rows (the symmetric gain: the mean of forward and reverse).
    pub b: DMatrix<f64>,
    /// 6 x N standard errors of `b`.
    pub b_std_err: DMatrix<f64>,
    /// What the model it came from had learned of the vehicle besides B, which a thruster's
    /// change does not move: the thrusters' spin-up lag (s, when learned) and the IMU's
    /// position from the centre (m). Why here: after an announced change the model in force is
    /// the new geometry's nominal one, which knows neither, and the identification then used
    /// the configured lag and learned the IMU's position again from closed-loop data, which
    /// cannot place it (eight_vectored in moderate water: 16 cm off, its acceleration rows
    /// 158 % off under a 20 % bound).
    #[serde(default)]
    pub spin_up_s: Option<f64>,
    #[serde(default)]
    pub imu_position_m: Option<[f64; 3]>,
    /// Each thruster's own lag (s, in the new numbering) when the model learned one per
    /// thruster ([`super::thruster_lags`]); empty otherwise.
    #[serde(default)]
    pub thruster_lags_s: Vec<f64>,
    /// The relative error those lags put into B, rotation and acceleration rows
    /// ([`crate::model::Model::lag_rel_err`]): a fit that keeps them keeps it too.
    #[serde(default)]
    pub lag_rel_err: [f64; 2],
    /// The relative error the model's navigation left in B that its bound counts and its
    /// standard errors do not ([`crate::model::Model::navigation_rel_err`]): the kept columns
    /// keep it.
    #[serde(default)]
    pub navigation_rel_err: [f64; 2],
}

/// A carried-over column is contradicted by the data when the data alone moved it by more
/// than this share of its rotation column ... (a 45 degree rotation moves it by 0.77; the
/// closed-loop data's own bias is a few per cent) ...
pub const CONTRADICTION_SHARE: f64 = 0.25;

/// ... and significantly: chi-square of the move over three rotation rows (about 4.7 sigma).
pub const CONTRADICTION_CHI2: f64 = 30.0;

/// How far a fit that weighed the data against `prior` strayed from it, per row group
/// (rotation, acceleration; `thetas` the fit's coefficients of each, one column per output):
/// [`group_disagreement`], 0 without a prior or without entries in the group.
pub fn disagreement(
    prior: Option<&DynamicPrior>,
    thetas: [&DMatrix<f64>; 2],
    split: bool,
) -> [f64; 2] {
    std::array::from_fn(|g| {
        prior
            .and_then(|p| group_disagreement(p, thetas[g], g, split))
            .unwrap_or(0.0)
    })
}

/// How far a fit that weighed the data against this prior strayed from it, per entry: the
/// mean over the prior's entries of DOF rows `3 g .. 3 g + 3` (`g` 0: rotation, 1:
/// acceleration) of ((fitted - prior) / prior's standard error)^2, with `theta` the fit's
/// coefficients (one column per output of the group). None without entries in the group.
///
/// Why: where the data and the prior agree this is below 1 (the fit sits between them and
/// nearer the better known), so a mean above 1 says that one of them is wrong beyond its
/// stated error, and the fit's variances, which assume both right, are too small by about
/// that factor (the Birge ratio). On `aligned` after a misdeclared screw, what the fight left
/// in the confirmation's data pulled LB's carried-over pitch gain from 13.9 +- 0.34 to 16.9
/// (the truth 14.1): 9.8 per entry, and the model 3.6x its bound.
fn group_disagreement(
    prior: &DynamicPrior,
    theta: &DMatrix<f64>,
    group: usize,
    split: bool,
) -> Option<f64> {
    let (mut chi2, mut k) = (0.0, 0usize);
    for a in 0..3 {
        for e in prior.entries(3 * group + a, split) {
            let fitted: f64 = e
                .weights
                .iter()
                .map(|&(j, w)| if w == 0.0 { 0.0 } else { w * theta[(j, a)] })
                .sum();
            let z2 = ((fitted - e.value) / e.std_err).powi(2);
            if z2.is_finite() {
                chi2 += z2;
                k += 1;
            }
        }
    }
    (k > 0).then(|| chi2 / k as f64)
}

/// One prior on a linear combination `sum w_i theta_i` of one output's coefficients.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PriorEntry {
    /// (coefficient index, weight); a second weight of 0 is unused.
    pub weights: [(usize, f64); 2],
    pub value: f64,
    pub std_err: f64,
}

impl DynamicPrior {
    /// Thrusters in the prior.
    pub fn thrusters(&self) -> usize {
        self.b.ncols()
    }

    /// Thrusters with nothing known about them (every entry of their column unknown): the
    /// ones the run has to learn.
    pub fn unknown_thrusters(&self) -> Vec<usize> {
        (0..self.thrusters())
            .filter(|&i| self.b_std_err.column(i).iter().all(|s| !s.is_finite()))
            .collect()
    }

    /// This prior without the columns the data contradicts: a carried-over thruster whose
    /// data-only gains `data_b` (6 x N, variances `data_var`) moved away from the prior by more
    /// than [`CONTRADICTION_SHARE`] of its rotation column and with a chi-square (rotation
    /// rows, over the data's and the prior's variance) above [`CONTRADICTION_CHI2`] is left
    /// to the data. Why: the sender may name the wrong thruster, or more than one may have
    /// changed; a prior held against the data would then pin a wrong column, with a confident
    /// bound. While the data is weak its variance keeps the chi-square small and the prior in.
    pub fn without_contradicted(&self, data_b: &DMatrix<f64>, data_var: &DMatrix<f64>) -> Self {
        let mut out = self.clone();
        for i in 0..self.thrusters() {
            let (mut chi2, mut moved2, mut norm2) = (0.0, 0.0, 0.0);
            for r in 0..3 {
                let (p, se) = (self.b[(r, i)], self.b_std_err[(r, i)]);
                let (d, v) = (data_b[(r, i)], data_var[(r, i)]);
                if !(p.is_finite() && se.is_finite() && d.is_finite() && v.is_finite()) {
                    continue;
                }
                chi2 += (d - p).powi(2) / (v + se * se).max(f64::MIN_POSITIVE);
                moved2 += (d - p).powi(2);
                norm2 += p * p;
            }
            let share = if norm2 > 0.0 {
                (moved2 / norm2).sqrt()
            } else {
                0.0
            };
            if chi2 > CONTRADICTION_CHI2 && share > CONTRADICTION_SHARE {
                out.b.column_mut(i).fill(f64::NAN);
                out.b_std_err.column_mut(i).fill(f64::INFINITY);
            }
        }
        out
    }

    /// Whether the shapes fit a fit of `n` thrusters.
    pub fn fits(&self, n: usize) -> bool {
        self.b.shape() == (6, n) && self.b_std_err.shape() == (6, n)
    }

    /// The prior entries of DOF row `row` for a fit whose coefficient vector starts with the
    /// thrust columns (`n`, or `2 n` forward then reverse when `split`).
    pub fn entries(&self, row: usize, split: bool) -> Vec<PriorEntry> {
        let n = self.thrusters();
        let usable = |v: f64, se: f64| v.is_finite() && se.is_finite() && se > 0.0;
        let mut out = Vec::new();
        for i in 0..n {
            let (v, se) = (self.b[(row, i)], self.b_std_err[(row, i)]);
            if !usable(v, se) {
                continue;
            }
            // Split, the model's gain is the mean of forward and reverse: the prior is on that
            // mean, and the data alone tells them apart.
            let weights = if split {
                [(i, 0.5), (n + i, 0.5)]
            } else {
                [(i, 1.0), (i, 0.0)]
            };
            out.push(PriorEntry {
                weights,
                value: v,
                std_err: se,
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prior(n: usize) -> DynamicPrior {
        let mut se = DMatrix::from_element(6, n, 0.1);
        se.column_mut(1).fill(f64::INFINITY);
        DynamicPrior {
            b: DMatrix::from_element(6, n, 2.0),
            b_std_err: se,
            spin_up_s: None,
            thruster_lags_s: Vec::new(),
            lag_rel_err: [0.0; 2],
            navigation_rel_err: [0.0; 2],
            imu_position_m: None,
        }
    }

    #[test]
    fn a_fit_on_its_prior_disagrees_by_nothing_and_one_two_errors_off_by_four() {
        let p = prior(3);
        // theta: one column per output of the group, the thrust columns first.
        let on = DMatrix::from_element(5, 3, 2.0);
        assert_eq!(group_disagreement(&p, &on, 0, false), Some(0.0));
        // Every kept entry (thrusters 0 and 2; 1 is unknown) two standard errors off.
        let mut off = on.clone();
        off.row_mut(0).fill(2.2);
        off.row_mut(2).fill(1.8);
        off.row_mut(1).fill(-100.0);
        let d = group_disagreement(&p, &off, 1, false).unwrap();
        assert!((d - 4.0).abs() < 1e-9, "{d}");
        // Split, the prior is on the mean of forward (i) and reverse (n + i).
        let mut split = DMatrix::from_element(8, 3, 2.0);
        split.row_mut(0).fill(2.4);
        split.row_mut(3).fill(2.0);
        let d = group_disagreement(&p, &split, 0, true).unwrap();
        assert!((d - 2.0).abs() < 1e-9, "{d}");
        // No entries in the group: nothing to say.
        let mut none = p.clone();
        none.b_std_err.fill(f64::INFINITY);
        assert_eq!(group_disagreement(&none, &on, 0, false), None);
        // Both groups at once; no prior, nothing.
        assert_eq!(disagreement(Some(&p), [&on, &off], false)[0], 0.0);
        assert_eq!(disagreement(None, [&off, &off], false), [0.0; 2]);
    }

    #[test]
    fn unknown_columns_are_left_to_the_data() {
        let p = prior(3);
        let e = p.entries(4, false);
        assert_eq!(e.len(), 2);
        assert_eq!(e[0].weights[0], (0, 1.0));
        assert_eq!(e[1].weights[0], (2, 1.0));
        assert_eq!(e[1].std_err, 0.1);
        assert_eq!(p.unknown_thrusters(), vec![1]);
    }

    #[test]
    fn split_the_prior_is_on_the_mean_of_forward_and_reverse() {
        let e = prior(3).entries(0, true);
        assert_eq!(e[1].weights, [(2, 0.5), (5, 0.5)]);
    }

    #[test]
    fn a_column_the_data_contradicts_is_dropped_and_a_weak_contradiction_is_not() {
        let p = prior(3);
        let mut data = p.b.clone();
        // Thruster 0 moved by half its column, measured precisely; thruster 2 by as much,
        // but the data is still weak.
        for r in 0..3 {
            data[(r, 0)] = 1.0;
            data[(r, 2)] = 1.0;
        }
        let mut var = DMatrix::from_element(6, 3, 1e-4);
        var.column_mut(2).fill(10.0);
        let kept = p.without_contradicted(&data, &var);
        assert_eq!(kept.unknown_thrusters(), vec![0, 1]);
        assert_eq!(kept.b[(0, 2)], 2.0);
        // A small move, however precise, is the data's own bias: kept.
        let mut close = p.b.clone();
        close[(0, 0)] = 2.1;
        assert_eq!(
            p.without_contradicted(&close, &var).unknown_thrusters(),
            vec![1]
        );
    }

    #[test]
    fn shapes_are_checked() {
        assert!(prior(3).fits(3));
        assert!(!prior(3).fits(4));
    }
}
