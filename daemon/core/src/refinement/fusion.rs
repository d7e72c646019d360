//! Folding a refinement window's fit into the model in force, so the model follows a thruster
//! that changes slowly (a fouled propeller, a tired motor, a battery sagging) without a
//! re-estimation.
//!
//! Each entry of B is a random walk: between two updates its variance grows by
//! `(drift_per_sqrt_s * column norm)^2` per second. A window's fit is a measurement of it with
//! the window's standard error times `window_se_scale` (a window's own errors understate its
//! real error at the paper's noise; see `RefinementConfig::window_se_scale`). The update is the
//! scalar Kalman step per entry; the model's standard errors become the posterior's, so the
//! published bound says how sure the refined model is.
//!
//! A window in which a column moved by more than the detector's `min_change` is not used at
//! all: that is a changed thruster, which the detector reports and a re-estimation answers. Only models that
//! carry standard errors (learned ones) are refined: a nominal model has no uncertainty to
//! weigh a window against.

use nalgebra::DMatrix;

use crate::estimator::{Estimate, EstimatorConfig};
use crate::model::Model;

/// How a window is weighed against the model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FusionSettings {
    /// Random-walk rate of each entry, share of its column's norm per sqrt(s).
    pub drift_per_sqrt_s: f64,
    /// The window's standard errors are multiplied by this.
    pub window_se_scale: f64,
    /// A column whose rotation part moved by more than this share is not fused.
    pub max_change: f64,
}

/// What a fusion made.
#[derive(Debug, Clone, PartialEq)]
pub struct Fused {
    /// The refined model (not yet checked or installed).
    pub model: Model,
    /// Columns updated.
    pub columns: usize,
    /// Largest move of a rotation column, share of its norm.
    pub largest_step: f64,
}

/// Rows of the two blocks: rotation (rad/s^2) and acceleration (m/s^2).
const BLOCKS: [std::ops::Range<usize>; 2] = [0..3, 3..6];

/// The model refined by the window's estimate `e`, ended at vehicle time `t_ns`; None when the
/// model cannot be refined (no standard errors) or nothing was updated.
pub fn fuse(
    model: &Model,
    e: &Estimate,
    t_ns: u64,
    window_s: f64,
    settings: &FusionSettings,
    est_cfg: &EstimatorConfig,
) -> Option<Fused> {
    if !model.estimated || !model.std_err.iter().all(|v| v.is_finite()) {
        return None;
    }
    let b = &model.effectiveness;
    let n = b.ncols().min(e.effectiveness.ncols());
    if e.effectiveness.nrows() != 6 || e.std_err.shape() != e.effectiveness.shape() {
        return None;
    }
    // Time the model's entries have been drifting since it was made or last refined; a model
    // of unknown age (from an older file) counts from this window's start.
    let since_s = if model.made_t_ns > 0 && t_ns > model.made_t_ns {
        (t_ns - model.made_t_ns) as f64 * 1e-9
    } else {
        window_s
    };
    let since_s = since_s.clamp(0.0, 3600.0);
    let biggest: [f64; 2] = std::array::from_fn(|g| {
        (0..n)
            .map(|i| b.view((BLOCKS[g].start, i), (3, 1)).norm())
            .fold(0.0, f64::max)
    });
    let mut out = b.clone();
    let mut var = model.std_err.map(|s| s * s);
    let mut columns = 0;
    let mut largest_step = 0.0f64;
    for i in 0..n {
        let rot_norm = b.view((0, i), (3, 1)).norm();
        let moved = (0..3)
            .map(|j| (e.effectiveness[(j, i)] - b[(j, i)]).powi(2))
            .sum::<f64>()
            .sqrt();
        if rot_norm > 0.05 * biggest[0] && moved / rot_norm > settings.max_change {
            // A changed thruster: the window saw another vehicle. Nothing of it is folded
            // in (the other columns were fitted together with the changed one).
            return None;
        }
        let mut updated = false;
        for (g, rows) in BLOCKS.iter().enumerate() {
            // A thruster with (almost) no part in a block still drifts by a share of the
            // block's largest column, or its entries could never move.
            let norm = b
                .view((rows.start, i), (3, 1))
                .norm()
                .max(0.05 * biggest[g]);
            let q = (settings.drift_per_sqrt_s * norm).powi(2) * since_s;
            for j in rows.clone() {
                let (w, se) = (e.effectiveness[(j, i)], e.std_err[(j, i)]);
                if !(w.is_finite() && se.is_finite() && se > 0.0) {
                    continue;
                }
                let prior = var[(j, i)] + q;
                let r = (settings.window_se_scale * se).powi(2);
                let gain = prior / (prior + r);
                out[(j, i)] = b[(j, i)] + gain * (w - b[(j, i)]);
                var[(j, i)] = (1.0 - gain) * prior;
                updated = true;
            }
        }
        if updated {
            columns += 1;
            if rot_norm > 0.0 {
                let step = (out.view((0, i), (3, 1)) - b.view((0, i), (3, 1))).norm() / rot_norm;
                largest_step = largest_step.max(step);
            }
        }
    }
    if columns == 0 {
        return None;
    }
    let mut refined = model.clone();
    refined.rel_err_rot = block_bound(&out, &var, 0..3, n);
    refined.rel_err_acc = block_bound(&out, &var, 3..6, n);
    refined.effectiveness = out;
    refined.std_err = var.map(f64::sqrt);
    refined.made_t_ns = t_ns;
    refined.refinements = model.refinements.saturating_add(1);
    Some(Fused {
        model: refined.with_derived_allocation(est_cfg),
        columns,
        largest_step,
    })
}

/// The block's error bound as the estimator defines it: sqrt of its total variance over its
/// norm.
fn block_bound(
    b: &DMatrix<f64>,
    var: &DMatrix<f64>,
    rows: std::ops::Range<usize>,
    n: usize,
) -> f64 {
    let len = rows.len();
    let norm = b.view((rows.start, 0), (len, n)).norm();
    let total: f64 = var.view((rows.start, 0), (len, n)).sum();
    if norm > 0.0 {
        total.sqrt() / norm
    } else {
        f64::INFINITY
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn learned(b: DMatrix<f64>, se: f64) -> Model {
        let n = b.ncols();
        let mut m = Model::nominal(b, None);
        m.estimated = true;
        m.std_err = DMatrix::from_element(6, n, se);
        m.made_t_ns = 1_000_000_000;
        m
    }

    fn window(b: DMatrix<f64>, se: f64) -> Estimate {
        crate::refinement::test_window_estimate(b, se)
    }

    fn b() -> DMatrix<f64> {
        DMatrix::from_row_slice(
            6,
            2,
            &[1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0],
        )
    }

    const SETTINGS: FusionSettings = FusionSettings {
        drift_per_sqrt_s: 0.01,
        window_se_scale: 1.0,
        max_change: 0.55,
    };

    #[test]
    fn a_weakened_column_is_followed_by_its_weight_and_the_error_shrinks() {
        let model = learned(b(), 0.02);
        let mut weak = b();
        weak.column_mut(0).scale_mut(0.8);
        // 10 s since the model: prior variance 0.02^2 + 0.01^2 * 10 = 0.0014; the window's
        // 0.02^2 = 0.0004: gain 0.0014 / 0.0018.
        let t = 11_000_000_000;
        let f = fuse(
            &model,
            &window(weak, 0.02),
            t,
            10.0,
            &SETTINGS,
            &EstimatorConfig::default(),
        )
        .expect("fused");
        let gain = 0.0014 / 0.0018;
        assert!((f.model.effectiveness[(0, 0)] - (1.0 - 0.2 * gain)).abs() < 1e-12);
        assert!((f.model.std_err[(0, 0)] - ((1.0 - gain) * 0.0014f64).sqrt()).abs() < 1e-12);
        // The unchanged column stays; its error shrinks all the same (one more measurement).
        assert!((f.model.effectiveness[(1, 1)] - 1.0).abs() < 1e-12);
        assert!(f.model.std_err[(1, 1)] < 0.02);
        assert_eq!(
            (f.columns, f.model.refinements, f.model.made_t_ns),
            (2, 1, t)
        );
        assert!(
            (f.largest_step - 0.2 * gain).abs() < 1e-9,
            "{}",
            f.largest_step
        );
        // The allocation follows: thruster 1 now rolls less, so it is commanded more for roll.
        assert!(f.model.allocation[(0, 0)].abs() > model.allocation[(0, 0)].abs());
        assert!(f.model.check(2, 1.0).is_ok());
    }

    #[test]
    fn a_changed_column_and_a_nominal_model_are_left_to_the_detector() {
        let model = learned(b(), 0.02);
        let mut rotated = b();
        rotated[(1, 0)] = 0.8; // 80 % of its column: a changed thruster, not a drift
        let cfg = EstimatorConfig::default();
        let t = 2_000_000_000;
        assert!(fuse(&model, &window(rotated, 0.02), t, 1.0, &SETTINGS, &cfg).is_none());
        let nominal = Model::nominal(b(), None);
        assert!(fuse(&nominal, &window(b(), 0.02), t, 1.0, &SETTINGS, &cfg).is_none());
    }

    #[test]
    fn a_noisy_window_barely_moves_a_confident_model() {
        let model = learned(b(), 0.01);
        let mut off = b();
        off[(0, 0)] = 1.3;
        let f = fuse(
            &model,
            &window(off, 0.5),
            1_100_000_000,
            0.1,
            &SETTINGS,
            &EstimatorConfig::default(),
        )
        .unwrap();
        assert!(
            f.model.effectiveness[(0, 0)] < 1.001,
            "{}",
            f.model.effectiveness[(0, 0)]
        );
    }
}
