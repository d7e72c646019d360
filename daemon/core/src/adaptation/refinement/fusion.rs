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
//! Two guards keep an unchanged model from following each window's own error. A window's
//! entries are never trusted beyond `window_floor` of their column's norm: noise-free, a
//! closed-loop window is 0.02-0.06 off the truth while its standard errors say 0.001. And the
//! drift rate is slow; a thruster that really changes faster shows as an innovation (window
//! minus model) beyond what prior and window allow, in two windows in a row, and its column's
//! prior is widened to match (covariance matching, `inflate_above`), so the model catches up in
//! a window or two. The acceleration rows start from the model scaled by the gain the rotation
//! rows now see: a weakening thruster scales its whole column.
//!
//! A window in which a column moved by more than the detector's `min_change` is not used at
//! all: that is a changed thruster, which the detector reports and a re-estimation answers. Only models that
//! carry standard errors (learned ones) are refined: a nominal model has no uncertainty to
//! weigh a window against.

use nalgebra::DMatrix;

use crate::estimator::{Estimate, EstimatorConfig};
use crate::model::Model;

/// How a window is weighed against the model.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FusionSettings {
    /// Random-walk rate of each entry, share of its column's norm per sqrt(s).
    pub drift_per_sqrt_s: f64,
    /// The window's standard errors are multiplied by this.
    pub window_se_scale: f64,
    /// A column whose rotation part moved by more than this share is not fused.
    pub max_change: f64,
    /// Each window entry's error is at least this share of its column's norm (added in
    /// quadrature to its scaled standard error): what a closed-loop window gets wrong however
    /// clean the data.
    pub window_floor: f64,
    /// A column whose innovation (window minus model, over the block's three rows) scores a
    /// chi-square above this has its prior widened to match it: the model is behind a real
    /// change, and follows it at once instead of at the slow drift rate.
    pub inflate_above: f64,
}

/// What a fusion made.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Fused {
    /// The refined model (not yet checked or installed).
    pub model: Model,
    /// Columns updated.
    pub columns: usize,
    /// Largest move of a rotation column, share of its norm.
    pub largest_step: f64,
}

/// Rows of the two blocks: rotation (rad/s^2) and acceleration (m/s^2).
pub(super) const BLOCKS: [std::ops::Range<usize>; 2] = [0..3, 3..6];

/// A window's fit as the fusion takes it.
#[derive(Debug, Clone, Copy)]
pub struct WindowFit<'a> {
    /// The window's estimate.
    pub estimate: &'a Estimate,
    /// Vehicle time the window ended, ns.
    pub t_ns: u64,
    /// Its length, s.
    pub window_s: f64,
    /// How far below full command its commands were (`command_level`); None when unknown.
    pub command_log_level: Option<f64>,
}

/// The model refined by the window's estimate (`window.estimate`), ended at vehicle time
/// `window.t_ns`; None when the model cannot be refined (no standard errors) or nothing was
/// updated.
pub fn fuse(
    model: &Model,
    window: WindowFit,
    settings: &FusionSettings,
    est_cfg: &EstimatorConfig,
    exceeded: &mut [bool],
) -> Option<Fused> {
    let WindowFit {
        estimate: e,
        t_ns,
        window_s,
        command_log_level,
    } = window;
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
    // A changed thruster: the window saw another vehicle. Nothing of it is folded in (the
    // other columns were fitted together with the changed one), and nothing is remembered.
    let changed = (0..n).any(|i| {
        let rot_norm = b.view((0, i), (3, 1)).norm();
        let moved = (e.effectiveness.view((0, i), (3, 1)) - b.view((0, i), (3, 1))).norm();
        rot_norm > 0.05 * biggest[0] && moved / rot_norm > settings.max_change
    });
    if changed {
        return None;
    }
    let mut out = b.clone();
    let mut var = model.std_err.map(|s| s * s);
    let mut columns = 0;
    let mut largest_step = 0.0f64;
    for i in 0..n {
        let rot_norm = b.view((0, i), (3, 1)).norm();
        let usable = |j: usize| {
            let (w, se) = (e.effectiveness[(j, i)], e.std_err[(j, i)]);
            w.is_finite() && se.is_finite() && se > 0.0
        };
        // Per block: the drift since the model (q) and the window's floor, both a share of
        // the column's norm in that block. A thruster with (almost) no part in a block still
        // drifts by a share of the block's largest column, or its entries could never move.
        let per_block: [(f64, f64); 2] = std::array::from_fn(|g| {
            let rows = &BLOCKS[g];
            let norm = b
                .view((rows.start, i), (3, 1))
                .norm()
                .max(0.05 * biggest[g]);
            (
                (settings.drift_per_sqrt_s * norm).powi(2) * since_s,
                (settings.window_floor * norm).powi(2),
            )
        });
        let block_of = |j: usize| usize::from(j >= 3);
        let r_of = |j: usize| {
            (settings.window_se_scale * e.std_err[(j, i)]).powi(2) + per_block[block_of(j)].1
        };
        // Covariance matching, per column: an innovation far beyond what prior and window
        // allow (in either block) means the thruster has changed faster than the drift rate
        // says; both blocks' priors widen by the excess, so the model catches up in a window
        // or two. A weakening thruster scales its whole column, and the rotation rows, the
        // better determined, see it first.
        let widen_now = BLOCKS
            .iter()
            .map(|rows| {
                let (mut nis, mut dof) = (0.0, 0);
                for j in rows.clone().filter(|&j| usable(j)) {
                    let d = e.effectiveness[(j, i)] - b[(j, i)];
                    nis += d * d / (var[(j, i)] + per_block[block_of(j)].0 + r_of(j));
                    dof += 1;
                }
                if dof > 0 && nis > settings.inflate_above {
                    nis / dof as f64
                } else {
                    1.0
                }
            })
            .fold(1.0, f64::max);
        // Only the second window in a row beyond the bound widens: a real change persists,
        // while one stray window (noise-free, eight_vectored's are up to ~0.06 off) would
        // otherwise be taken at face value.
        let armed = exceeded.get(i).copied().unwrap_or(false);
        if let Some(flag) = exceeded.get_mut(i) {
            *flag = widen_now > 1.0;
        }
        let widen = if armed { widen_now } else { 1.0 };
        let mut updated = false;
        // One block's Kalman steps, each entry starting from the model's value times `scale`.
        let mut fold = |rows: &std::ops::Range<usize>, scale: f64, out: &mut DMatrix<f64>| {
            for j in rows.clone().filter(|&j| usable(j)) {
                let prior = (var[(j, i)] + per_block[block_of(j)].0) * widen;
                let gain = prior / (prior + r_of(j));
                let predicted = b[(j, i)] * scale;
                out[(j, i)] = predicted + gain * (e.effectiveness[(j, i)] - predicted);
                var[(j, i)] = (1.0 - gain) * prior;
                updated = true;
            }
        };
        fold(&BLOCKS[0], 1.0, &mut out);
        // The thruster's gain as the rotation rows now see it: a thruster that weakens scales
        // its whole column, and the rotation rows are the better determined, so the
        // acceleration rows start from the model scaled by it. Without this their noisier
        // windows left them lagging a 30 % loss (0.04-0.06 off through the processes while the
        // rotation rows were within 0.02). Only for a column with a real moment.
        let scale = if rot_norm > 0.25 * biggest[0] {
            let rot = b.view((0, i), (3, 1));
            (out.view((0, i), (3, 1)).dot(&rot) / (rot_norm * rot_norm)).clamp(0.5, 1.5)
        } else {
            1.0
        };
        fold(&BLOCKS[1], scale, &mut out);
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
    // On a learned thrust curve the exponent's error stays in the bound: the windows, all at
    // the hold's amplitude, cannot tell it, and they carry B by it (eight_vectored_lag80ms_
    // curve, realistic: from 0.024 to 0.048 off in 40 s while the windows took the bound from
    // 0.060 to 0.032), by as much as the window's commands are below full command
    // (`command_level`: held through pitch steps, from 0.04 to 0.08-0.17 off under a floor
    // that assumed a third of full command).
    let floor = if model
        .dynamics
        .as_ref()
        .is_some_and(|d| d.command_exponent.is_some())
    {
        crate::estimator::dynamic::thrust_curve::learned_curve_rel_err(command_log_level)
    } else {
        0.0
    };
    // So does what the model's own navigation left in it (`Model::navigation_rel_err`):
    // counted in its bound, not in its standard errors, so not in `var`.
    let navigation = model.navigation_rel_err();
    // And a thrust curve named and not learned: the windows at the hold's amplitude carry the
    // line toward the hold's gain, but the pulses' amplitude is as far from it as before.
    let curve = model.curve_named_rel_err();
    refined.rel_err_rot = block_bound(&out, &var, 0..3, n)
        .hypot(floor)
        .hypot(navigation[0])
        .hypot(curve[0]);
    refined.rel_err_acc = block_bound(&out, &var, 3..6, n)
        .hypot(floor)
        .hypot(navigation[1])
        .hypot(curve[1]);
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
        crate::adaptation::refinement::test_window_estimate(b, se)
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
        window_floor: 0.0,
        inflate_above: f64::INFINITY,
    };

    /// The window `e`, ended at `t_ns` after `window_s`, its commands at `level`.
    fn at(e: &Estimate, t_ns: u64, window_s: f64, level: Option<f64>) -> WindowFit<'_> {
        WindowFit {
            estimate: e,
            t_ns,
            window_s,
            command_log_level: level,
        }
    }

    /// `m` refined by a window that agrees with `b()` (0.02 per entry, 10 s, 11 s after the
    /// model), its commands at `level`.
    fn steady_window_on(m: &Model, level: Option<f64>) -> Model {
        fuse(
            m,
            at(&window(b(), 0.02), 11_000_000_000, 10.0, level),
            &SETTINGS,
            &EstimatorConfig::default(),
            &mut [false; 2],
        )
        .expect("fused")
        .model
    }

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
            at(&window(weak, 0.02), t, 10.0, None),
            &SETTINGS,
            &EstimatorConfig::default(),
            &mut [false; 2],
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
    fn the_navigations_share_of_the_bound_stays_in_the_refined_bound() {
        // A model whose acceleration rows' bound counts 0.04 of its navigation's errors
        // beside a statistical 0.02 per entry (`Model::navigation_rel_err`).
        let mut model = learned(b(), 0.02);
        let mut terms = crate::estimator::dynamic::DynamicTerms::blank(2);
        terms.navigation_rel_err = [0.0, 0.04];
        model.dynamics = Some(terms);
        let with = steady_window_on(&model, None);
        model.dynamics = None;
        let without = steady_window_on(&model, None);
        // The same fusion: B and its standard errors; the acceleration rows' bound takes the
        // navigation's share in quadrature, the rotation rows' nothing.
        assert_eq!(with.effectiveness, without.effectiveness);
        assert_eq!(with.std_err, without.std_err);
        assert_eq!(with.rel_err_rot, without.rel_err_rot);
        assert!((with.rel_err_acc - without.rel_err_acc.hypot(0.04)).abs() < 1e-12);
    }

    #[test]
    fn a_learned_curves_floor_follows_the_windows_command_level() {
        use crate::estimator::dynamic::thrust_curve::NARROW_HALF_STEP;
        // A model on a learned curve (its exponent's error a floor of the bound), and one
        // with a thrust curve named and not learned (the line's distance, 0.3 / 0.5).
        let mut model = learned(b(), 0.02);
        let mut terms = crate::estimator::dynamic::DynamicTerms::blank(2);
        terms.command_exponent = Some(1.5);
        model.dynamics = Some(terms);
        let mut plain = model.clone();
        plain.dynamics = None;
        let stat = steady_window_on(&plain, None);
        let floor = |level: f64| level * NARROW_HALF_STEP;
        for (level, want) in [(None, 1.2), (Some(0.5), 1.2), (Some(2.3), 2.3)] {
            let m = steady_window_on(&model, level);
            assert_eq!(m.effectiveness, stat.effectiveness, "the bound only");
            let expect = stat.rel_err_rot.hypot(floor(want));
            assert!(
                (m.rel_err_rot - expect).abs() < 1e-12,
                "{level:?}: {}",
                m.rel_err_rot
            );
        }
        let mut named = plain.clone();
        let mut terms = crate::estimator::dynamic::DynamicTerms::blank(2);
        terms.curve_named_rel_err = [0.3, 0.5];
        named.dynamics = Some(terms);
        let m = steady_window_on(&named, Some(2.3));
        assert!((m.rel_err_rot - stat.rel_err_rot.hypot(0.3)).abs() < 1e-12);
        assert!((m.rel_err_acc - stat.rel_err_acc.hypot(0.5)).abs() < 1e-12);
    }

    #[test]
    fn a_changed_column_and_a_nominal_model_are_left_to_the_detector() {
        let model = learned(b(), 0.02);
        let mut rotated = b();
        rotated[(1, 0)] = 0.8; // 80 % of its column: a changed thruster, not a drift
        let cfg = EstimatorConfig::default();
        let t = 2_000_000_000;
        assert!(fuse(
            &model,
            at(&window(rotated, 0.02), t, 1.0, None),
            &SETTINGS,
            &cfg,
            &mut [false; 2]
        )
        .is_none());
        let nominal = Model::nominal(b(), None);
        assert!(fuse(
            &nominal,
            at(&window(b(), 0.02), t, 1.0, None),
            &SETTINGS,
            &cfg,
            &mut [false; 2],
        )
        .is_none());
    }

    #[test]
    fn a_window_is_never_trusted_beyond_its_floor() {
        let model = learned(b(), 0.02);
        let mut off = b();
        off[(0, 0)] = 1.05;
        let settings = FusionSettings {
            window_floor: 0.04,
            drift_per_sqrt_s: 0.0,
            ..SETTINGS
        };
        // The window claims 1e-6; the floor makes it 0.04 (column norm 1): gain
        // 0.0004 / (0.0004 + 0.0016) = 0.2.
        let f = fuse(
            &model,
            at(&window(off, 1e-6), 2_000_000_000, 1.0, None),
            &settings,
            &EstimatorConfig::default(),
            &mut [false; 2],
        )
        .unwrap();
        assert!((f.model.effectiveness[(0, 0)] - 1.01).abs() < 1e-9);
    }

    #[test]
    fn a_column_far_outside_its_bounds_is_followed_at_once() {
        let model = learned(b(), 0.01);
        let mut weak = b();
        weak.column_mut(0).scale_mut(0.8);
        let slow = FusionSettings {
            drift_per_sqrt_s: 0.0,
            window_floor: 0.02,
            ..SETTINGS
        };
        let fast = FusionSettings {
            inflate_above: 7.8,
            ..slow
        };
        let cfg = EstimatorConfig::default();
        let w = window(weak, 0.01);
        let t = 2_000_000_000;
        let step = |s: &FusionSettings| {
            1.0 - fuse(&model, at(&w, t, 1.0, None), s, &cfg, &mut [true; 2])
                .unwrap()
                .model
                .effectiveness[(0, 0)]
        };
        // Without widening: prior 0.0001 against 0.0001 + 0.0004, gain 1/6 of the 0.2 drop.
        assert!((step(&slow) - 0.2 / 6.0).abs() < 1e-9, "{}", step(&slow));
        // The innovation's chi-square on thruster 1's rotation rows: 0.2^2 / 0.0006 = 67 over
        // three rows, so the prior widens 22-fold (gain 0.82) and the model takes most of the
        // drop at once; the unchanged column stays.
        assert!(step(&fast) > 0.15, "{}", step(&fast));
        let mut exceeded = [true; 2];
        let f = fuse(&model, at(&w, t, 1.0, None), &fast, &cfg, &mut exceeded).unwrap();
        assert!((f.model.effectiveness[(1, 1)] - 1.0).abs() < 1e-12);
        assert_eq!(exceeded, [true, false]);
        // A first window beyond the bound only arms the widening: one stray window is not
        // taken at face value.
        let mut exceeded = [false; 2];
        let f = fuse(&model, at(&w, t, 1.0, None), &fast, &cfg, &mut exceeded).unwrap();
        assert!((1.0 - f.model.effectiveness[(0, 0)] - 0.2 / 6.0).abs() < 1e-9);
        assert_eq!(exceeded, [true, false]);
    }

    #[test]
    fn a_noisy_window_barely_moves_a_confident_model() {
        let model = learned(b(), 0.01);
        let mut off = b();
        off[(0, 0)] = 1.3;
        let f = fuse(
            &model,
            at(&window(off, 0.5), 1_100_000_000, 0.1, None),
            &SETTINGS,
            &EstimatorConfig::default(),
            &mut [false; 2],
        )
        .unwrap();
        assert!(
            f.model.effectiveness[(0, 0)] < 1.001,
            "{}",
            f.model.effectiveness[(0, 0)]
        );
    }
}
