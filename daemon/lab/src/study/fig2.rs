//! The paper's Fig. 2 simulation study, reproduced and extended.
//!
//! Setup (Doniec, Detweiler, Rus, section 3): N = 2, 4, 6, 8 thrusters, pulse strength p = 20 or
//! 50 in thrust units (-100..100), 100 random configurations each, 50 pulses, one measurement per
//! pulse: rot = R t + N(0, 0.25^2), acc = A t + N(0, 0.05^2) per axis, columns of R and A drawn
//! uniformly inside balls of radius 0.05 and 0.02. After every pulse the relative Frobenius error
//! of each method's forward model, for every excitation plan, beside the Cramer-Rao expected
//! error sigma sqrt(3 tr((U^T U)^-1)) / ||M||_F of the same pulses.

use nalgebra::{DMatrix, DVector, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use thrusterd_core::estimator::linalg::rel_frobenius_err;
use thrusterd_core::estimator::{
    Estimator, EstimatorConfig, Excitation, ExcitationPlan, Method, NoiseLevels,
};

/// The paper's noise on rotation (rad/s) and acceleration (g), per axis.
pub const SIGMA_ROT: f64 = 0.25;
pub const SIGMA_ACC: f64 = 0.05;
/// Radii of the balls the columns of R and A are drawn from.
pub const RADIUS_ROT: f64 = 0.05;
pub const RADIUS_ACC: f64 = 0.02;

/// Study parameters; `Default` is the paper's.
#[derive(Debug, Clone, PartialEq)]
pub struct StudyParams {
    pub thrusters: Vec<usize>,
    pub powers: Vec<f64>,
    pub configs: usize,
    pub pulses: usize,
    pub seed: u64,
}

impl Default for StudyParams {
    fn default() -> Self {
        StudyParams {
            thrusters: vec![2, 4, 6, 8],
            powers: vec![20.0, 50.0],
            configs: 100,
            pulses: 50,
            seed: 1,
        }
    }
}

/// Mean and standard deviation over configurations, for one curve point.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Stat {
    pub mean: f64,
    pub std: f64,
}

/// One row of study.csv.
#[derive(Debug, Clone, PartialEq)]
pub struct StudyRow {
    pub n: usize,
    pub p: f64,
    pub method: Method,
    pub excitation: Excitation,
    /// 1-based pulse count.
    pub pulse: usize,
    pub err_rot: Stat,
    pub err_acc: Stat,
    /// Mean over configurations of the Cramer-Rao RMS relative error; None until every thruster
    /// has been pulsed (the bound is infinite before).
    pub crlb_rot: Option<f64>,
    pub crlb_acc: Option<f64>,
}

/// Per-configuration relative errors after each pulse, for one (n, p, excitation).
#[derive(Debug, Clone)]
pub struct RunErrors {
    /// [pulse] -> (paper rot, paper acc, forward rot, forward acc, crlb rot, crlb acc)
    pub per_pulse: Vec<[f64; 6]>,
}

/// A random configuration: R (3 x n) and A (3 x n), columns uniform in balls.
pub fn random_configuration(rng: &mut impl Rng, n: usize) -> (DMatrix<f64>, DMatrix<f64>) {
    let r = DMatrix::from_columns(
        &(0..n)
            .map(|_| uniform_in_ball(rng, RADIUS_ROT))
            .collect::<Vec<_>>(),
    );
    let a = DMatrix::from_columns(
        &(0..n)
            .map(|_| uniform_in_ball(rng, RADIUS_ACC))
            .collect::<Vec<_>>(),
    );
    (r, a)
}

/// Uniform in a 3-D ball by rejection (exact, and cheap: 52 % acceptance).
fn uniform_in_ball(rng: &mut impl Rng, radius: f64) -> DVector<f64> {
    loop {
        let v = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        if v.norm_squared() <= 1.0 {
            return DVector::from_column_slice((v * radius).as_slice());
        }
    }
}

fn gaussian3(rng: &mut impl Rng, sigma: f64) -> Vector3<f64> {
    let mut draw = || -> f64 { StandardNormal.sample(rng) };
    Vector3::new(sigma * draw(), sigma * draw(), sigma * draw())
}

/// Deterministic seed per (study seed, n, p, configuration), independent of run order.
fn config_seed(seed: u64, n: usize, p: f64, config: usize) -> u64 {
    let mut h = seed ^ 0x9E37_79B9_7F4A_7C15;
    for v in [n as u64, p.to_bits(), config as u64] {
        h = (h ^ v).wrapping_mul(0x1000_0000_01B3).rotate_left(29);
    }
    h
}

/// Simulate one configuration under one excitation plan: errors after every pulse.
///
/// Both methods see exactly the same measurements (one estimator feeds both regressions).
pub fn run_configuration(
    n: usize,
    p: f64,
    excitation: Excitation,
    pulses: usize,
    seed: u64,
    config: usize,
) -> RunErrors {
    let mut rng = ChaCha8Rng::seed_from_u64(config_seed(seed, n, p, config));
    let (r, a) = random_configuration(&mut rng, n);
    // Noise streams differ per excitation so plans are compared over independent draws.
    let mut noise_rng = ChaCha8Rng::seed_from_u64(
        config_seed(seed, n, p, config)
            ^ (excitation as u64 + 1).wrapping_mul(0xA24B_AED4_963E_E407),
    );
    let cfg = EstimatorConfig {
        excitation,
        ..EstimatorConfig::forward()
    };
    let mut est = Estimator::new(cfg, n, NoiseLevels::isotropic(SIGMA_ROT, SIGMA_ACC));
    let plan = ExcitationPlan::new(excitation, n);
    let (r_norm, a_norm) = (r.norm(), a.norm());
    let mut per_pulse = Vec::with_capacity(pulses);
    for k in 0..pulses {
        let u = DVector::from_iterator(n, plan.pattern(k).iter().map(|s| s * p));
        let rot_true = &r * &u;
        let acc_true = &a * &u;
        let rot = Vector3::new(rot_true[0], rot_true[1], rot_true[2])
            + gaussian3(&mut noise_rng, SIGMA_ROT);
        let acc = Vector3::new(acc_true[0], acc_true[1], acc_true[2])
            + gaussian3(&mut noise_rng, SIGMA_ACC);
        est.push_observation(u.as_slice(), &rot, &acc);

        let [fwd_rot, fwd_acc] = est.forward_solutions();
        let pap = est.paper_effectiveness();
        let rows = |m: &DMatrix<f64>, top: usize| m.rows(top, 3).into_owned();
        // In this study rotation and acceleration share one Gram matrix, U^T U.
        let (crlb_rot, crlb_acc) = if fwd_rot.rank == n {
            let t = fwd_rot.gram_inv.trace();
            (
                SIGMA_ROT * (3.0 * t).sqrt() / r_norm,
                SIGMA_ACC * (3.0 * t).sqrt() / a_norm,
            )
        } else {
            (f64::NAN, f64::NAN)
        };
        per_pulse.push([
            rel_frobenius_err(&rows(&pap, 0), &r),
            rel_frobenius_err(&rows(&pap, 3), &a),
            rel_frobenius_err(&fwd_rot.b, &r),
            rel_frobenius_err(&fwd_acc.b, &a),
            crlb_rot,
            crlb_acc,
        ]);
    }
    RunErrors { per_pulse }
}

fn stat(values: impl Iterator<Item = f64> + Clone) -> Stat {
    let n = values.clone().count();
    if n == 0 {
        return Stat::default();
    }
    let mean = values.clone().sum::<f64>() / n as f64;
    let var = if n > 1 {
        values.map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64
    } else {
        0.0
    };
    Stat {
        mean,
        std: var.sqrt(),
    }
}

/// Rows for one (n, p): every excitation and method, every pulse.
fn study_cell(params: &StudyParams, n: usize, p: f64) -> Vec<StudyRow> {
    let mut rows = Vec::new();
    for excitation in Excitation::ALL {
        let runs: Vec<RunErrors> = (0..params.configs)
            .map(|c| run_configuration(n, p, excitation, params.pulses, params.seed, c))
            .collect();
        for (method, off) in [(Method::Paper, 0), (Method::Forward, 2)] {
            for k in 0..params.pulses {
                let col = |i: usize| runs.iter().map(move |r| r.per_pulse[k][i]);
                let crlb = |i: usize| {
                    let s = stat(col(i));
                    s.mean.is_finite().then_some(s.mean)
                };
                rows.push(StudyRow {
                    n,
                    p,
                    method,
                    excitation,
                    pulse: k + 1,
                    err_rot: stat(col(off)),
                    err_acc: stat(col(off + 1)),
                    crlb_rot: crlb(4),
                    crlb_acc: crlb(5),
                });
            }
        }
    }
    rows
}

/// Run the whole study. Cells run on all cores; results do not depend on scheduling.
pub fn run_study(params: &StudyParams) -> Vec<StudyRow> {
    let cells: Vec<(usize, f64)> = params
        .thrusters
        .iter()
        .flat_map(|&n| params.powers.iter().map(move |&p| (n, p)))
        .collect();
    let workers = std::thread::available_parallelism()
        .map(|w| w.get())
        .unwrap_or(1)
        .min(cells.len().max(1));
    let mut results: Vec<Option<Vec<StudyRow>>> = vec![None; cells.len()];
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..workers)
            .map(|w| {
                let cells = &cells;
                s.spawn(move || {
                    (w..cells.len())
                        .step_by(workers)
                        .map(|i| (i, study_cell(params, cells[i].0, cells[i].1)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        for h in handles {
            // A panicking worker is a bug in the study itself; surface it.
            for (i, rows) in h.join().expect("study worker panicked") {
                results[i] = Some(rows);
            }
        }
    });
    results.into_iter().flatten().flatten().collect()
}

/// The CSV header the study writes.
pub const CSV_HEADER: &str = "n,p,method,excitation,pulse,mean_err_rot,std_err_rot,mean_err_acc,std_err_acc,crlb_err_rot,crlb_err_acc";

/// study.csv contents (empty CRLB fields before every thruster has been pulsed).
pub fn to_csv(rows: &[StudyRow]) -> String {
    let mut out = String::with_capacity(rows.len() * 96);
    out.push_str(CSV_HEADER);
    out.push('\n');
    let opt = |v: Option<f64>| v.map(|x| format!("{x:.6}")).unwrap_or_default();
    for r in rows {
        out.push_str(&format!(
            "{},{},{},{},{},{:.6},{:.6},{:.6},{:.6},{},{}\n",
            r.n,
            r.p,
            r.method.name(),
            r.excitation.name(),
            r.pulse,
            r.err_rot.mean,
            r.err_rot.std,
            r.err_acc.mean,
            r.err_acc.std,
            opt(r.crlb_rot),
            opt(r.crlb_acc),
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use thrusterd_core::estimator::NoiseLevels;

    fn gauss(rng: &mut impl Rng, sigma: f64) -> Vector3<f64> {
        let mut d = || -> f64 { StandardNormal.sample(rng) };
        Vector3::new(sigma * d(), sigma * d(), sigma * d())
    }

    #[test]
    fn forward_error_matches_the_cramer_rao_bound() {
        // The forward regression is efficient: its mean squared relative error over many random
        // configurations matches the Cramer-Rao value sigma^2 3 tr(G^-1) / ||M||^2 within 10 %.
        for excitation in [Excitation::RoundRobin, Excitation::Orthogonal] {
            let (n, p, pulses, configs) = (4, 50.0, 24, 600);
            let mut err2 = [0.0; 2];
            let mut crlb2 = [0.0; 2];
            for c in 0..configs {
                let mut rng = ChaCha8Rng::seed_from_u64(7000 + c as u64);
                let (r, a) = random_configuration(&mut rng, n);
                let cfg = EstimatorConfig {
                    excitation,
                    ..EstimatorConfig::forward()
                };
                let mut est = Estimator::new(cfg, n, NoiseLevels::isotropic(0.25, 0.05));
                let mut gram = DMatrix::<f64>::zeros(n, n);
                for k in 0..pulses {
                    let u = DVector::from_iterator(n, est.plan().pattern(k).iter().map(|s| s * p));
                    let rot = &r * &u;
                    let acc = &a * &u;
                    est.push_observation(
                        u.as_slice(),
                        &(Vector3::new(rot[0], rot[1], rot[2]) + gauss(&mut rng, 0.25)),
                        &(Vector3::new(acc[0], acc[1], acc[2]) + gauss(&mut rng, 0.05)),
                    );
                    gram += &u * u.transpose();
                }
                let b = est.forward_effectiveness();
                let tr = gram.try_inverse().unwrap().trace();
                err2[0] += ((b.rows(0, 3) - &r).norm() / r.norm()).powi(2);
                err2[1] += ((b.rows(3, 3) - &a).norm() / a.norm()).powi(2);
                crlb2[0] += 0.25f64.powi(2) * 3.0 * tr / r.norm_squared();
                crlb2[1] += 0.05f64.powi(2) * 3.0 * tr / a.norm_squared();
            }
            for g in 0..2 {
                let ratio = (err2[g] / crlb2[g]).sqrt();
                assert!(
                    (0.9..=1.1).contains(&ratio),
                    "{excitation:?} group {g}: RMS error / CRLB = {ratio}"
                );
            }
        }
    }

    #[test]
    fn study_output_is_deterministic_for_a_seed() {
        let params = StudyParams {
            thrusters: vec![2, 4],
            powers: vec![20.0, 50.0],
            configs: 8,
            pulses: 12,
            seed: 42,
        };
        let a = to_csv(&run_study(&params));
        let b = to_csv(&run_study(&params));
        assert_eq!(a, b);
        assert!(a.starts_with(CSV_HEADER));
        // 2 N x 2 p x 3 plans x 2 methods x 12 pulses, plus the header.
        assert_eq!(a.lines().count(), 1 + 2 * 2 * 3 * 2 * 12);
        let other = to_csv(&run_study(&StudyParams { seed: 43, ..params }));
        assert_ne!(a, other, "the seed must matter");
    }

    #[test]
    fn ball_sampling_stays_inside_and_fills() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let norms: Vec<f64> = (0..4000)
            .map(|_| uniform_in_ball(&mut rng, 2.0).norm())
            .collect();
        assert!(norms.iter().all(|r| *r <= 2.0));
        // Uniform in a ball: P(r < R/2) = 1/8.
        let inner = norms.iter().filter(|r| **r < 1.0).count() as f64 / 4000.0;
        assert!((inner - 0.125).abs() < 0.02, "{inner}");
    }

    #[test]
    fn run_is_deterministic_and_errors_shrink() {
        let a = run_configuration(4, 50.0, Excitation::RoundRobin, 50, 3, 0);
        let b = run_configuration(4, 50.0, Excitation::RoundRobin, 50, 3, 0);
        // Bitwise, since the bound is NaN before every thruster has been pulsed.
        let bits = |r: &RunErrors| -> Vec<u64> {
            r.per_pulse.iter().flatten().map(|v| v.to_bits()).collect()
        };
        assert_eq!(bits(&a), bits(&b));
        // Before every thruster was pulsed the forward error is large; after 50 pulses small.
        assert!(a.per_pulse[0][2] > 0.4);
        assert!(a.per_pulse[49][2] < a.per_pulse[7][2]);
        // Thruster 4 first fires on pulse 7 (index 6): the bound exists from there on.
        assert!(a.per_pulse[5][4].is_nan() && a.per_pulse[6][4].is_finite());
    }
}
