//! What an identification may keep from the model in force when it knows what changed: after
//! one thruster moved, was added or was removed, every other thruster's column is still what
//! was learned, to within its standard error. They become the fit's prior
//! (`estimator::dynamic::prior`), and the data only has to teach it the changed thruster.
//!
//! The hull's own coefficients (damping, restoring, Coriolis) are not kept, although they did
//! not change either: they were learned near the attitude the first estimation held and do not
//! extrapolate. Measured (AMOUR-5, realistic IMU, top thruster rotated silently during +-20 deg
//! pitch steps, seeds 1-5): keeping them pinned a misfit onto the moved thruster's column,
//! 0.05-0.12 off the truth; keeping B alone, 0.012-0.019 (0.013-0.058 keeping nothing).
//!
//! Only a learned model is carried over (a nominal one has no standard errors: it is a guess,
//! not knowledge), and only when the thruster counts agree with the change. An unknown change
//! keeps nothing.

use nalgebra::DMatrix;

use crate::estimator::dynamic::prior::DynamicPrior;
use crate::model::Model;

/// What changed in the thruster configuration, as far as the sender could say.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum ThrusterChange {
    /// Something changed, nobody says what: nothing is carried over.
    #[default]
    Unknown,
    /// Thruster `i` (0-based, in the new numbering) was added.
    Added(usize),
    /// Thruster `i` (in the old numbering) was removed; those after it shift down by one.
    Removed(usize),
    /// Thruster `i` was moved or re-oriented (or found changed under control).
    Moved(usize),
}

impl ThrusterChange {
    /// For each thruster of the new configuration (`new_count` of them), the old thruster it
    /// is, or None for the changed one; None overall when the change does not fit the counts.
    pub fn old_index(&self, old_count: usize, new_count: usize) -> Option<Vec<Option<usize>>> {
        match *self {
            ThrusterChange::Unknown => None,
            ThrusterChange::Moved(k) => (new_count == old_count && k < new_count)
                .then(|| (0..new_count).map(|i| (i != k).then_some(i)).collect()),
            ThrusterChange::Added(k) => (new_count == old_count + 1 && k < new_count).then(|| {
                (0..new_count)
                    .map(|i| match i.cmp(&k) {
                        std::cmp::Ordering::Less => Some(i),
                        std::cmp::Ordering::Equal => None,
                        std::cmp::Ordering::Greater => Some(i - 1),
                    })
                    .collect()
            }),
            ThrusterChange::Removed(k) => {
                (new_count + 1 == old_count && k < old_count).then(|| {
                    (0..new_count)
                        .map(|i| Some(if i < k { i } else { i + 1 }))
                        .collect()
                })
            }
        }
    }
}

/// The prior the model in force gives a fit of `new_count` thrusters after `change`, its
/// standard errors multiplied by `se_scale` (at least 1: the model may have drifted since it
/// was learned). None when nothing can be carried over.
pub fn carried_over(
    model: &Model,
    change: ThrusterChange,
    new_count: usize,
    se_scale: f64,
) -> Option<DynamicPrior> {
    if !model.estimated {
        return None;
    }
    let old = model.effectiveness.ncols();
    let map = change.old_index(old, new_count)?;
    if model.std_err.shape() != (6, old) {
        return None;
    }
    let scale = if se_scale.is_finite() {
        se_scale.max(1.0)
    } else {
        1.0
    };
    let mut b = DMatrix::from_element(6, new_count, f64::NAN);
    let mut se = DMatrix::from_element(6, new_count, f64::INFINITY);
    for (i, from) in map.iter().enumerate() {
        let Some(j) = *from else { continue };
        for r in 0..6 {
            let (v, s) = (model.effectiveness[(r, j)], model.std_err[(r, j)]);
            if v.is_finite() && s.is_finite() && s > 0.0 {
                b[(r, i)] = v;
                se[(r, i)] = s * scale;
            }
        }
    }
    if se.iter().all(|s| !s.is_finite()) {
        return None;
    }
    Some(DynamicPrior {
        b,
        b_std_err: se,
        spin_up_s: model.learned_spin_up_s(),
        imu_position_m: model.imu_position_m().map(Into::into),
        thruster_lags_s: carried_lags(model, change, &map),
        lag_rel_err: model.lag_rel_err(),
        navigation_rel_err: model.navigation_rel_err(),
    })
}

/// The factor a fit's bound in one row group is widened by when it strayed from the prior it
/// was given by `disagreement` per entry (`DynamicTerms::prior_disagreement`):
/// `sqrt(max(1, disagreement))`, the Birge ratio. Why: a fit between data and a prior that
/// agree sits within their errors (below 1 per entry); above it one of them is wrong beyond
/// its stated error, a bias no more data removes, and the fit's variances, which assume both
/// right, are too small by about that ratio. Measured on `aligned` after a misdeclared screw
/// (docs/study.md, "The kept columns and the data disagree"): what the fight left in the
/// confirmation's data pulled LB's kept pitch gain from 13.9 +- 0.34 to 16.9 (the truth 14.1),
/// 9.8 per entry, and the model was 3.6x its bound. Non-finite reads as no widening beyond
/// [`MAX_DISAGREEMENT_SCALE`].
pub fn disagreement_scale(disagreement: f64) -> f64 {
    if disagreement.is_nan() {
        return 1.0;
    }
    disagreement.max(1.0).sqrt().min(MAX_DISAGREEMENT_SCALE)
}

/// `model`'s bounds and standard errors widened per row group (rotation rows 0-2,
/// acceleration rows 3-5) by [`disagreement_scale`] of its fit's `disagreement` with the
/// prior; the larger of the two factors and what the status says of it, None when nothing
/// was widened.
pub fn widen_for_disagreement(model: &mut Model, disagreement: [f64; 2]) -> Option<(f64, String)> {
    let scale = disagreement.map(disagreement_scale);
    if scale.iter().all(|k| *k <= 1.0) {
        return None;
    }
    model.widen(scale);
    let text = format!(
        "; the kept columns moved {:.1} / {:.1} sd^2 per entry: bound widened to rot {:.3}, acc {:.3}",
        disagreement[0], disagreement[1], model.rel_err_rot, model.rel_err_acc
    );
    Some((scale[0].max(scale[1]), text))
}

/// The most `disagreement_scale` widens a bound (a fit 30x off its prior's errors per entry is
/// refused by any gate long before).
pub const MAX_DISAGREEMENT_SCALE: f64 = 30.0;

/// Each thruster's own lag after `change` (`map`: the old index of each new thruster), when
/// the model learned one per thruster: a lag is the thruster's make, not its place, so a moved
/// thruster keeps its own and an added one gets the others' mean. Empty otherwise.
fn carried_lags(model: &Model, change: ThrusterChange, map: &[Option<usize>]) -> Vec<f64> {
    let Some(old) = model.learned_thruster_lags() else {
        return Vec::new();
    };
    let mean = old.iter().sum::<f64>() / old.len().max(1) as f64;
    map.iter()
        .enumerate()
        .map(|(i, from)| match (*from, change) {
            (Some(j), _) => old.get(j).copied().unwrap_or(mean),
            (None, ThrusterChange::Moved(k)) if k == i => old.get(k).copied().unwrap_or(mean),
            _ => mean,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ModelSource;

    #[test]
    fn the_changed_thruster_is_left_out_and_the_others_follow_their_numbering() {
        assert_eq!(
            ThrusterChange::Moved(1).old_index(3, 3),
            Some(vec![Some(0), None, Some(2)])
        );
        assert_eq!(
            ThrusterChange::Added(1).old_index(2, 3),
            Some(vec![Some(0), None, Some(1)])
        );
        assert_eq!(
            ThrusterChange::Removed(0).old_index(3, 2),
            Some(vec![Some(1), Some(2)])
        );
        // Counts that do not fit the change, and an unknown change: nothing is kept.
        assert_eq!(ThrusterChange::Moved(0).old_index(3, 4), None);
        assert_eq!(ThrusterChange::Added(5).old_index(2, 3), None);
        assert_eq!(ThrusterChange::Unknown.old_index(3, 3), None);
    }

    fn learned(n: usize) -> Model {
        let b = DMatrix::from_fn(6, n, |r, c| (r * 10 + c) as f64 + 1.0);
        let mut m = Model::nominal(b, None);
        m.source = ModelSource::Estimated;
        m.estimated = true;
        m.std_err = DMatrix::from_element(6, n, 0.5);
        m
    }

    #[test]
    fn a_learned_model_carries_its_other_columns_with_their_scaled_errors() {
        let p = carried_over(&learned(3), ThrusterChange::Added(0), 4, 2.0).unwrap();
        assert!(p.b.column(0).iter().all(|v| v.is_nan()));
        assert!(p.b_std_err.column(0).iter().all(|s| s.is_infinite()));
        // New thruster 1 is the old thruster 0.
        assert_eq!(p.b[(2, 1)], 21.0);
        assert_eq!(p.b_std_err[(2, 1)], 1.0);
        assert_eq!(p.b[(5, 3)], 53.0);
    }

    #[test]
    fn a_fit_within_its_priors_errors_keeps_its_bound_and_one_beyond_them_is_widened() {
        assert_eq!(disagreement_scale(0.0), 1.0);
        assert_eq!(disagreement_scale(0.9), 1.0);
        assert!((disagreement_scale(9.0) - 3.0).abs() < 1e-12);
        assert_eq!(disagreement_scale(f64::NAN), 1.0);
        assert_eq!(disagreement_scale(f64::INFINITY), MAX_DISAGREEMENT_SCALE);
    }

    #[test]
    fn a_nominal_model_or_an_unknown_change_carries_nothing() {
        let mut nominal = learned(3);
        nominal.estimated = false;
        assert!(carried_over(&nominal, ThrusterChange::Moved(0), 3, 1.0).is_none());
        assert!(carried_over(&learned(3), ThrusterChange::Unknown, 3, 1.0).is_none());
        let mut unknown_se = learned(3);
        unknown_se.std_err.fill(f64::NAN);
        assert!(carried_over(&unknown_se, ThrusterChange::Moved(0), 3, 1.0).is_none());
    }
}
