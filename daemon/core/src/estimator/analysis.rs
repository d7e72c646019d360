//! What an estimated effectiveness matrix says about the vehicle: how many independent motions
//! the thrusters can make (rank), which of the six DOFs those are, and the health of each
//! thruster. The allocation built from the rank report is `crate::allocation`'s.
//!
//! Significance is judged in standard-error units: the matrix is scaled row by row by its
//! typical standard error, so estimation noise becomes roughly i.i.d. N(0, 1) and a pure-noise
//! 6 x N matrix has singular values up to about sqrt(6) + sqrt(N). Larger ones are real.

use nalgebra::DMatrix;
use serde::Serialize;

use super::config::EstimatorConfig;
use super::dof::{Dof, DofMask};
use super::linalg::singular_left;

/// Singular values below this fraction of the largest are round-off, whatever the noise says.
pub(crate) const NUMERICAL_REL_TOL: f64 = 1e-9;

/// Rank and DOF report.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct RankReport {
    /// Singular values of the effectiveness matrix scaled to standard-error units, descending.
    pub singular_values: Vec<f64>,
    /// The noise-derived threshold they are compared with.
    pub threshold: f64,
    /// Number of independently actuated motions.
    pub rank: usize,
    /// Share (0..1) of each DOF's unit vector inside the actuated subspace, in DOF order
    /// (diagnostic: below 1 means the DOF only moves together with another).
    pub dof_share: [f64; 6],
    /// The DOFs the actuated motions are assigned to, by the configured priority.
    pub actuated: DofMask,
}

/// Health of one thruster as the data shows it.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct ThrusterDiagnosis {
    pub index: usize,
    /// Chi-square of the column against zero (6 dof); large = a clear response.
    pub chi2: f64,
    pub responds: bool,
    /// Strongest command this thruster received, |u|.
    pub max_command: f64,
    /// No significant response although pulsed at (near) full power.
    pub dead: bool,
    /// Pushes against its declared direction (needs a declared nominal model).
    pub reversed: Option<bool>,
    /// Projection of the estimate on the declared column, relative (1 = as declared).
    pub nominal_gain: Option<f64>,
    /// Reverse gain over forward gain (1 = symmetric), from the split forward/reverse fit.
    pub reverse_gain_ratio: Option<f64>,
    /// Standard error of `reverse_gain_ratio`.
    pub reverse_gain_ratio_se: Option<f64>,
    /// Forward and reverse gains differ significantly.
    pub asymmetric: bool,
}

/// Row scale (typical standard error of an entry in that row), for rank decisions.
fn row_scales(std_err: &DMatrix<f64>) -> Vec<f64> {
    (0..std_err.nrows())
        .map(|j| {
            let (sum, count) = std_err
                .row(j)
                .iter()
                .filter(|v| v.is_finite())
                .fold((0.0, 0usize), |(s, c), v| (s + v * v, c + 1));
            if count == 0 {
                0.0
            } else {
                (sum / count as f64).sqrt()
            }
        })
        .collect()
}

/// Rank, actuated subspace and DOF report of `b` (6 x N) given its standard errors.
pub fn rank_report(b: &DMatrix<f64>, std_err: &DMatrix<f64>, cfg: &EstimatorConfig) -> RankReport {
    let n = b.ncols();
    let scales = row_scales(std_err);
    // A row with no noise information (or no noise at all) keeps its physical scale; a tiny floor
    // avoids dividing by zero in noiseless runs.
    let floor = b.amax().max(1e-300) * 1e-12;
    let mut z = b.clone();
    for (j, s) in scales.iter().enumerate() {
        let s = if s.is_finite() && *s > floor {
            *s
        } else {
            floor
        };
        z.row_mut(j).scale_mut(1.0 / s);
    }
    // Unexcited columns (infinite standard error) carry no information: leave them out.
    for i in 0..n {
        if std_err.column(i).iter().any(|v| !v.is_finite()) {
            z.column_mut(i).fill(0.0);
        }
    }
    let threshold = cfg.rank_threshold * (6f64.sqrt() + (n as f64).sqrt());
    // Left singular vectors span the motions the thrusters can make (6-dimensional space).
    let (mut singular_values, u) = singular_left(&z);
    singular_values.truncate(n.min(6));
    let top = singular_values.first().copied().unwrap_or(0.0);
    let significant: Vec<usize> = (0..singular_values.len())
        .filter(|&k| {
            let s = singular_values[k];
            s > threshold && s > top * NUMERICAL_REL_TOL
        })
        .collect();
    let mut dof_share = [0.0; 6];
    for (j, share) in dof_share.iter_mut().enumerate() {
        *share = significant.iter().map(|&k| u[(j, k)].powi(2)).sum::<f64>();
    }
    let rank = significant.len();
    let actuated = assign_dofs(&z, rank, threshold, top, &cfg.dof_priority);
    RankReport {
        singular_values,
        threshold,
        rank,
        dof_share,
        actuated,
    }
}

/// The DOFs the `rank` actuated motions are assigned to: in `priority` order, each DOF whose
/// row of `z` (standard-error units) is independent of the rows already taken, above the noise
/// threshold, until `rank` are taken.
///
/// Why not "every DOF mostly inside the actuated subspace": when the subspace is not aligned
/// with the axes (AMOUR-5 with its top thruster tilted 45 deg about x can only pitch while
/// swaying), a DOF's share sits near any cut-off and flips between runs with the noise, and
/// dropping pitch left the attitude controller unable to hold it. Taking a DOF needs the
/// smallest singular value of the taken rows above the threshold; by interlacing that is at
/// most the rank-th singular value of the whole matrix, so never more than `rank` are taken.
fn assign_dofs(
    z: &DMatrix<f64>,
    rank: usize,
    threshold: f64,
    top: f64,
    priority: &[Dof; 6],
) -> DofMask {
    let mut taken = DofMask::NONE;
    for &dof in priority {
        if taken.count() == rank {
            break;
        }
        let mut trial = taken;
        trial.0[dof.index()] = true;
        let rows: Vec<usize> = Dof::ALL
            .iter()
            .filter(|d| trial.contains(**d))
            .map(|d| d.index())
            .collect();
        // A direct SVD, not the Gram matrix: squaring would lift round-off of exactly-zero
        // rows (noise-free nominal models, scaled by a tiny floor) above the threshold.
        let sv = z.select_rows(rows.iter()).singular_values();
        // Fewer thrusters than rows: the missing singular values are zero.
        let smallest = if sv.len() < rows.len() { 0.0 } else { sv.min() };
        if smallest > threshold && smallest > top * NUMERICAL_REL_TOL {
            taken = trial;
        }
    }
    taken
}

/// Per-thruster diagnosis.
///
/// `b`/`std_err`: the 6 x N estimate. `split`/`split_se`: the 6 x 2N fit with separate forward
/// (columns 0..N) and reverse (N..2N) gains, when available. `nominal`: the declared 6 x N
/// model, when the vehicle file or a reconfiguration event gave one.
pub fn diagnose(
    b: &DMatrix<f64>,
    std_err: &DMatrix<f64>,
    max_command: &[f64],
    split: Option<(&DMatrix<f64>, &DMatrix<f64>)>,
    nominal: Option<&DMatrix<f64>>,
    cfg: &EstimatorConfig,
) -> Vec<ThrusterDiagnosis> {
    let n = b.ncols();
    (0..n)
        .map(|i| {
            let chi2: f64 = (0..6)
                .map(|j| {
                    let se = std_err[(j, i)];
                    if se.is_finite() && se > 0.0 {
                        (b[(j, i)] / se).powi(2)
                    } else if se == 0.0 && b[(j, i)] != 0.0 {
                        f64::INFINITY
                    } else {
                        0.0
                    }
                })
                .sum();
            let responds = chi2 > cfg.response_chi2;
            let max_cmd = max_command.get(i).copied().unwrap_or(0.0);
            let dead = !responds && max_cmd >= cfg.dead_min_command;

            let (reversed, nominal_gain) = match nominal {
                Some(nom) if i < nom.ncols() && nom.column(i).norm() > 0.0 => {
                    let d = nom.column(i);
                    let dd = d.norm_squared();
                    let gain = b.column(i).dot(&d) / dd;
                    let se = ((0..6)
                        .map(|j| (d[j] * std_err[(j, i)]).powi(2))
                        .sum::<f64>())
                    .sqrt()
                        / dd;
                    let se = if se.is_finite() { se } else { f64::INFINITY };
                    (Some(gain < -cfg.diagnosis_z * se), Some(gain))
                }
                _ => (None, None),
            };

            let (ratio, ratio_se, asymmetric) = match split {
                Some((sb, sse)) if sb.ncols() == 2 * n => {
                    let fwd = sb.column(i);
                    let rev = sb.column(n + i);
                    let ff = fwd.norm_squared();
                    if ff > 0.0 && responds {
                        let g = rev.dot(&fwd) / ff;
                        let var: f64 = (0..6)
                            .map(|j| {
                                (fwd[j] / ff).powi(2)
                                    * (sse[(j, n + i)].powi(2) + g * g * sse[(j, i)].powi(2))
                            })
                            .sum();
                        let se = var.sqrt();
                        let asym = se.is_finite() && (g - 1.0).abs() > cfg.diagnosis_z * se;
                        (Some(g), se.is_finite().then_some(se), asym)
                    } else {
                        (None, None, false)
                    }
                }
                _ => (None, None, false),
            };

            ThrusterDiagnosis {
                index: i,
                chi2,
                responds,
                max_command: max_cmd,
                dead,
                reversed,
                nominal_gain,
                reverse_gain_ratio: ratio,
                reverse_gain_ratio_se: ratio_se,
                asymmetric,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::allocation::pseudo_inverse as allocation;

    fn aligned_truth() -> DMatrix<f64> {
        // Three thrusters pushing along x at different y/z: pitch, yaw and surge only.
        DMatrix::from_row_slice(
            6,
            3,
            &[
                0.0, 0.0, 0.0, // roll
                1.0, 1.0, -2.0, // pitch
                2.0, -2.0, 0.0, // yaw
                1.0, 1.0, 1.0, // surge
                0.0, 0.0, 0.0, // sway
                0.0, 0.0, 0.0, // heave
            ],
        )
    }

    #[test]
    fn aligned_configuration_actuates_three_dofs() {
        let b = aligned_truth();
        let se = DMatrix::from_element(6, 3, 0.01);
        let r = rank_report(&b, &se, &EstimatorConfig::default());
        assert_eq!(r.rank, 3);
        assert_eq!(r.actuated.names(), vec!["pitch", "yaw", "surge"]);
        let a = allocation(&b, r.actuated, r.rank);
        for dof in [Dof::Roll, Dof::Sway, Dof::Heave] {
            assert_eq!(a.column(dof.index()).norm(), 0.0, "{dof:?} commanded");
        }
        // Actuated DOFs are reproduced exactly: B A = I on them.
        let ba = &b * &a;
        for dof in [Dof::Pitch, Dof::Yaw, Dof::Surge] {
            let j = dof.index();
            for k in 0..6 {
                let want = if k == j { 1.0 } else { 0.0 };
                assert!(
                    (ba[(k, j)] - want).abs() < 1e-9,
                    "BA[{k},{j}]={}",
                    ba[(k, j)]
                );
            }
        }
    }

    /// AMOUR-5 with its top thruster T rotated 45 deg about x (unit mass and inertia): five
    /// thrusters, rank 5, and pitch only comes with sway (T is the only one that pitches
    /// differently from how it heaves, and it also sways).
    fn amour5_top45() -> DMatrix<f64> {
        let c = std::f64::consts::FRAC_1_SQRT_2;
        DMatrix::from_row_slice(
            6,
            5,
            &[
                0.15 * c,
                0.15,
                -0.15,
                0.0,
                0.0, // roll
                0.2 * c,
                -0.2,
                -0.2,
                0.0,
                0.0, // pitch
                0.2 * c,
                0.0,
                0.0,
                0.2,
                -0.2, // yaw
                0.0,
                0.0,
                0.0,
                1.0,
                1.0, // surge
                c,
                0.0,
                0.0,
                0.0,
                0.0, // sway
                -c,
                -1.0,
                -1.0,
                0.0,
                0.0, // heave
            ],
        )
    }

    #[test]
    fn coupled_dofs_go_to_the_controlled_ones_first_whatever_the_row_noise() {
        let b = amour5_top45();
        let cfg = EstimatorConfig::default();
        // The pitch row's standard error from 1x to 30x the others' (a vehicle that swung
        // during the pulses leaves more unexplained pitch): pitch's share of the actuated
        // subspace falls, but it stays the DOF taken, sway the one left out.
        for pitch_noise in [1.0, 3.0, 10.0, 30.0] {
            let mut se = DMatrix::from_element(6, 5, 0.001);
            se.row_mut(Dof::Pitch.index()).fill(0.001 * pitch_noise);
            let r = rank_report(&b, &se, &cfg);
            assert_eq!(r.rank, 5, "x{pitch_noise}");
            assert_eq!(
                r.actuated.names(),
                vec!["roll", "pitch", "yaw", "surge", "heave"],
                "x{pitch_noise}: shares {:?}",
                r.dof_share
            );
            // The allocation reproduces the five exactly; sway follows as a side effect.
            let ba = &b * allocation(&b, r.actuated, r.rank);
            for dof in [Dof::Roll, Dof::Pitch, Dof::Yaw, Dof::Surge, Dof::Heave] {
                let j = dof.index();
                assert!((ba[(j, j)] - 1.0).abs() < 1e-9, "{dof:?}: {}", ba[(j, j)]);
            }
        }
        // At 30x the old rule (share >= 0.5) would have dropped pitch: the share is low.
        let mut se = DMatrix::from_element(6, 5, 0.001);
        se.row_mut(Dof::Pitch.index()).fill(0.03);
        let r = rank_report(&b, &se, &cfg);
        assert!(r.dof_share[Dof::Pitch.index()] < 0.5, "{:?}", r.dof_share);
        // A vehicle that would rather sway than pitch says so.
        let sway_first = EstimatorConfig {
            dof_priority: [
                Dof::Roll,
                Dof::Sway,
                Dof::Yaw,
                Dof::Heave,
                Dof::Surge,
                Dof::Pitch,
            ],
            ..cfg
        };
        let r = rank_report(&b, &DMatrix::from_element(6, 5, 0.001), &sway_first);
        assert_eq!(
            r.actuated.names(),
            vec!["roll", "yaw", "surge", "sway", "heave"]
        );
    }

    #[test]
    fn a_priority_that_misses_a_dof_is_refused() {
        let mut cfg = EstimatorConfig::default();
        cfg.dof_priority[5] = Dof::Roll;
        let e = cfg.validate().unwrap_err();
        assert_eq!(e.key, "dof_priority");
    }

    #[test]
    fn noise_sized_rows_are_not_actuated() {
        let mut b = aligned_truth();
        // Roll row holds noise at one standard error: must not count.
        b[(0, 0)] = 0.01;
        b[(0, 1)] = -0.012;
        b[(0, 2)] = 0.008;
        let se = DMatrix::from_element(6, 3, 0.01);
        let r = rank_report(&b, &se, &EstimatorConfig::default());
        assert_eq!(r.rank, 3);
        assert!(!r.actuated.contains(Dof::Roll), "{:?}", r.dof_share);
    }

    #[test]
    fn dead_reversed_and_asymmetric_thrusters_are_found() {
        let cfg = EstimatorConfig::default();
        // Three identical declared columns: some yaw, pitch and surge each.
        let col = [0.0, 0.5, 1.0, 2.0, 0.0, 0.0];
        let nominal = DMatrix::from_fn(6, 3, |j, _| col[j]);
        // Thruster 0 as declared, thruster 1 reversed, thruster 2 dead.
        let mut b = nominal.clone();
        b.column_mut(1).scale_mut(-1.0);
        b.column_mut(2).fill(0.001);
        let se = DMatrix::from_element(6, 3, 0.01);
        // Split fit: thruster 0 pushes 0.6x as hard in reverse.
        let mut split = DMatrix::zeros(6, 6);
        for i in 0..3 {
            split.set_column(i, &b.column(i));
            split.set_column(3 + i, &b.column(i));
        }
        split.column_mut(3).scale_mut(0.6);
        let split_se = DMatrix::from_element(6, 6, 0.01);
        let d = diagnose(
            &b,
            &se,
            &[1.0, 1.0, 1.0],
            Some((&split, &split_se)),
            Some(&nominal),
            &cfg,
        );
        assert!(d[0].responds && !d[0].dead && d[0].reversed == Some(false));
        assert!(d[0].asymmetric);
        assert!((d[0].reverse_gain_ratio.unwrap() - 0.6).abs() < 1e-12);
        assert!(d[1].responds && d[1].reversed == Some(true) && !d[1].asymmetric);
        assert!(!d[2].responds && d[2].dead);
        // Not pulsed hard enough: silent, but not declared dead yet.
        let d = diagnose(&b, &se, &[1.0, 1.0, 0.5], None, None, &cfg);
        assert!(!d[2].responds && !d[2].dead && d[2].reversed.is_none());
    }
}
