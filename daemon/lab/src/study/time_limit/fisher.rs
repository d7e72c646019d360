//! The dynamic model's Fisher information along a noise-free trajectory, and the Cramer-Rao
//! bound of B with the vehicle's other coefficients and the thruster lag as nuisance.
//!
//! The model is the estimator's (`thrusterd_core::estimator::dynamic`), sample for sample:
//! - rotation rows, integrated form: omega_a(t) = c_seg + B_a . int u_lag +
//!   theta_a . int terms + e, e white with the gyro's per-sample sigma (the estimator
//!   regresses the gyro reading, not a differentiated rate, so this is the noise model it
//!   assumes and the one the sensor has);
//! - acceleration rows, direct: f_a = c_seg + B_a . u_lag + theta_a . terms + e, e white with
//!   the accelerometer's sigma;
//!
//! with one intercept per 1 s segment (projected out per segment, as the estimator's
//! `SegmentedLs` does), the 38 terms of `regressors::terms` evaluated on the simulator's true
//! state, and u_lag the commands through a first-order lag tau. The lag enters nonlinearly: it
//! is linearised (d u_lag / d tau, exact for the discrete filter the estimator runs), and is
//! common to all six rows. Per group the Gram matrix of [X_B | dX/dtau | terms] is accumulated;
//! the terms are eliminated by a Schur complement (pseudo-inverse of their block, scaled to a
//! unit diagonal as the estimator does), then the lag across the six rows.
//!
//! Not in the bound: the errors in the regressors (the terms are built from the measured rate
//! and the navigated velocity), the navigation's own unknowns (accelerometer bias, IMU
//! position), the thrusters' forward/reverse asymmetry (the truth is the symmetric gain).

use nalgebra::{DMatrix, DVector, Vector3};
use thruster_sim::{NoisePreset, SensorConfig, Simulator, Vehicle};
use thrusterd_core::estimator::dynamic::regressors::{terms, TERMS};
use thrusterd_core::estimator::linalg::sym_pinv;

use super::design::Excitation;
use super::worst_seed::WorstOf;

/// IMU rate of every run, Hz (the daemon's tests and the demo's).
pub const RATE_HZ: f64 = 200.0;
/// The estimator's segment length, s (`EstimatorConfig::segment_s`).
pub const SEGMENT_S: f64 = 1.0;
/// The dead band the machine compensates (the simulator's default).
pub const DEADBAND: f64 = 0.05;

/// The command sent to the simulator for the estimator's command `u` (the machine's dead-band
/// compensation).
pub fn compensate(u: f64) -> f64 {
    if u == 0.0 {
        0.0
    } else {
        u.signum() * (DEADBAND + (1.0 - DEADBAND) * u.abs())
    }
}

/// Gram sums of one group with one intercept per segment projected out.
#[derive(Clone)]
struct Gram {
    closed: DMatrix<f64>,
    seg: DMatrix<f64>,
    seg_x: DVector<f64>,
    seg_n: f64,
}

impl Gram {
    fn new(k: usize) -> Self {
        Gram {
            closed: DMatrix::zeros(k, k),
            seg: DMatrix::zeros(k, k),
            seg_x: DVector::zeros(k),
            seg_n: 0.0,
        }
    }
    fn add(&mut self, x: &DVector<f64>) {
        self.seg.ger(1.0, x, x, 1.0);
        self.seg_x += x;
        self.seg_n += 1.0;
    }
    fn centred_open(&self) -> DMatrix<f64> {
        if self.seg_n > 0.0 {
            &self.seg - &self.seg_x * self.seg_x.transpose() / self.seg_n
        } else {
            self.seg.clone()
        }
    }
    fn close(&mut self) {
        self.closed += self.centred_open();
        self.seg.fill(0.0);
        self.seg_x.fill(0.0);
        self.seg_n = 0.0;
    }
    fn total(&self) -> DMatrix<f64> {
        &self.closed + self.centred_open()
    }
}

/// The information a trajectory holds, at every snapshot.
pub struct Snapshot {
    /// Excitation time, s.
    pub t_s: f64,
    /// Largest true tilt so far, deg.
    pub max_tilt_deg: f64,
    /// Per group (rotation, acceleration): the centred Gram matrix of
    /// [B columns (N) | their lag derivatives (N) | terms (38)].
    pub gram: [DMatrix<f64>; 2],
}

/// A noise-free run of `excitation` for `t_max_s` on vehicle `v`, its information snapshotted
/// every `snap_s`, with the estimator's segments of [`SEGMENT_S`].
pub struct Trajectory {
    pub n: usize,
    /// The symmetric truth (mean of forward and reverse gain), 6 x N.
    pub b: DMatrix<f64>,
    /// The thrusters' (mean) lag, s.
    pub lag_s: f64,
    pub snapshots: Vec<Snapshot>,
}

pub fn simulate(v: &Vehicle, excitation: &Excitation, t_max_s: f64, snap_s: f64) -> Trajectory {
    simulate_segmented(v, excitation, t_max_s, snap_s, SEGMENT_S)
}

/// The same with segments (one intercept each, integrals restarted) of `segment_s`.
pub fn simulate_segmented(
    v: &Vehicle,
    excitation: &Excitation,
    t_max_s: f64,
    snap_s: f64,
    segment_s: f64,
) -> Trajectory {
    let n = v.thrusters.len();
    let lag_s = v.thrusters.iter().map(|t| t.time_constant_s).sum::<f64>() / n as f64;
    let sensors = SensorConfig {
        rate_hz: RATE_HZ,
        noise: NoisePreset::None,
        ..SensorConfig::default()
    };
    let mut sim = Simulator::new(v.clone(), sensors, 1).expect("vehicle");
    let (f, r) = sim.truth();
    let b = (f + r) * 0.5;
    let k = 2 * n + TERMS;
    let mut grams = [Gram::new(k), Gram::new(k)];
    let dt = 1.0 / RATE_HZ;
    let mut u = vec![0.0; n];
    let mut sent = vec![0.0; n];
    let mut lag = vec![0.0; n];
    let mut dlag = vec![0.0; n];
    let mut lag_abs = 0.0;
    let mut term = [0.0; TERMS];
    let mut term_prev: [f64; TERMS];
    let mut integral = DVector::zeros(k);
    let mut direct = DVector::zeros(k);
    let mut row_prev = DVector::zeros(2 * n);
    let e = (-dt / lag_s).exp();
    let a = 1.0 - e;
    let da = -e * dt / (lag_s * lag_s);
    let mut snapshots = Vec::new();
    let mut next_snap = snap_s;
    let mut max_tilt = 0.0_f64;
    let mut segment_start: Option<f64> = None;
    let steps = (t_max_s * RATE_HZ).round() as usize;
    for step in 0..steps {
        let t = step as f64 * dt;
        excitation.command(t, &mut u);
        for (s, v) in sent.iter_mut().zip(&u) {
            *s = compensate(*v);
        }
        sim.set_commands(&sent).expect("commands");
        sim.advance_and_sample();
        let t_end = t + dt;
        let w = sim.angular_velocity();
        let vel = sim.linear_velocity();
        let down = sim.attitude().inverse_transform_vector(&Vector3::z());
        max_tilt = max_tilt.max(down.z.clamp(-1.0, 1.0).acos().to_degrees());
        // The lag filter and its derivative in tau (the estimator's discrete filter).
        for i in 0..n {
            dlag[i] = dlag[i] * (1.0 - a) + da * (u[i] - lag[i]);
            lag[i] += a * (u[i] - lag[i]);
        }
        let abs_mean = u.iter().map(|x| x.abs()).sum::<f64>() / n as f64;
        lag_abs += a * (abs_mean - lag_abs);
        term_prev = term;
        terms(&vel, &w, &down, lag_abs, &mut term);
        let new_segment = segment_start.is_none_or(|s0| t_end - s0 >= segment_s - 1e-9);
        let mut row = DVector::zeros(2 * n);
        for i in 0..n {
            row[i] = lag[i];
            row[n + i] = dlag[i];
        }
        if new_segment {
            for g in grams.iter_mut() {
                g.close();
            }
            segment_start = Some(t_end);
            integral.fill(0.0);
        } else {
            for j in 0..2 * n {
                integral[j] += 0.5 * (row_prev[j] + row[j]) * dt;
            }
            for j in 0..TERMS {
                integral[2 * n + j] += 0.5 * (term_prev[j] + term[j]) * dt;
            }
        }
        row_prev.copy_from(&row);
        direct.rows_mut(0, 2 * n).copy_from(&row);
        for j in 0..TERMS {
            direct[2 * n + j] = term[j];
        }
        grams[0].add(&integral);
        grams[1].add(&direct);
        if t_end >= next_snap - 1e-9 {
            snapshots.push(Snapshot {
                t_s: t_end,
                max_tilt_deg: max_tilt,
                gram: [grams[0].total(), grams[1].total()],
            });
            next_snap += snap_s;
        }
    }
    Trajectory {
        n,
        b,
        lag_s,
        snapshots,
    }
}

/// Per-sample noise sigma of the gyro and the accelerometer of a preset.
pub fn preset_sigma(p: NoisePreset) -> (f64, f64) {
    let q = p.params();
    (q.gyro_std_radps, q.accel_std_mps2)
}

/// What the bound says at one snapshot: the RMS relative Frobenius error of the rotation and
/// acceleration rows of B an unbiased estimator can at best reach.
#[derive(Debug, Clone, Copy)]
pub struct Bound {
    pub rel_err: [f64; 2],
    /// The lag's own 1-sigma, s, when it is a nuisance (0 when known).
    pub lag_sd_s: f64,
}

/// The reduced information of one group: the unknown terms' block eliminated from
/// [B | dB/dtau | terms], a 2N x 2N matrix (per unit noise); the terms `known` are not
/// eliminated (their contribution is taken as known and removed from the data).
fn reduced(g: &DMatrix<f64>, n: usize, known: &[bool; TERMS]) -> DMatrix<f64> {
    let m = 2 * n;
    let keep: Vec<usize> = (0..m)
        .chain((0..TERMS).filter(|j| !known[*j]).map(|j| m + j))
        .collect();
    let g = g.select_rows(&keep).select_columns(&keep);
    let k = g.nrows();
    let z = k - m;
    // Scale the terms' block to a unit diagonal; unexcited terms drop out.
    let scale: Vec<f64> = (m..k)
        .map(|j| {
            let d = g[(j, j)];
            if d > 0.0 {
                1.0 / d.sqrt()
            } else {
                0.0
            }
        })
        .collect();
    let mut gzz = g.view((m, m), (z, z)).into_owned();
    for i in 0..z {
        for j in 0..z {
            gzz[(i, j)] *= scale[i] * scale[j];
        }
    }
    let (pinv, _) = sym_pinv(&gzz);
    let mut gwz = g.view((0, m), (m, z)).into_owned();
    for i in 0..m {
        for j in 0..z {
            gwz[(i, j)] *= scale[j];
        }
    }
    let gww = g.view((0, 0), (m, m)).into_owned();
    let red = gww - &gwz * pinv * gwz.transpose();
    (&red + red.transpose()) * 0.5
}

/// The bound at one snapshot for noise sigmas (gyro, accelerometer) per sample; `lag_unknown`
/// makes the lag a nuisance (else it is known). None when B is not identifiable yet.
pub fn bound(
    s: &Snapshot,
    b: &DMatrix<f64>,
    sigma: (f64, f64),
    lag_unknown: bool,
) -> Option<Bound> {
    bound_with(s, b, sigma, lag_unknown, true)
}

/// [`bound`] with the damping, restoring and Coriolis terms unknown (`terms_unknown`, the
/// estimator's case) or known (the floor a model with known dynamics would have).
pub fn bound_with(
    s: &Snapshot,
    b: &DMatrix<f64>,
    sigma: (f64, f64),
    lag_unknown: bool,
    terms_unknown: bool,
) -> Option<Bound> {
    covariance_with(s, b, sigma, lag_unknown, terms_unknown).map(|c| c.bound())
}

/// The Cramer-Rao covariance of B's rows, group by group, relative to the group's norm: the
/// 3N x 3N covariance of the rotation (acceleration) rows stacked row after row, over
/// |B_rot|^2 (|B_acc|^2). Its trace is the squared relative bound; its eigenvalues give the
/// error's whole distribution (`worst_seed`).
pub struct Covariance {
    pub rel: [DMatrix<f64>; 2],
    /// The lag's own 1-sigma, s, when it is a nuisance (0 when known).
    pub lag_sd_s: f64,
}

impl Covariance {
    /// The bound: the square root of each group's trace.
    pub fn bound(&self) -> Bound {
        let rel = |g: usize| self.rel[g].trace().max(0.0).sqrt();
        Bound {
            rel_err: [rel(0), rel(1)],
            lag_sd_s: self.lag_sd_s,
        }
    }
}

/// The covariance behind [`bound_with`]. Per row a the information of b_a is M_bb / sigma^2
/// (the rows share the regressors, so their blocks are independent but for the lag, which is
/// common to all six: eliminating it adds w_a w_b' / schur between any two rows).
pub fn covariance_with(
    s: &Snapshot,
    b: &DMatrix<f64>,
    sigma: (f64, f64),
    lag_unknown: bool,
    terms_unknown: bool,
) -> Option<Covariance> {
    let known = &[!terms_unknown; TERMS];
    let n = b.ncols();
    let sig = [sigma.0, sigma.1];
    // Per group: M_bb^-1, M_bd.
    let mut inv_bb = Vec::with_capacity(2);
    let mut m_bd = Vec::with_capacity(2);
    let mut m_dd = Vec::with_capacity(2);
    for g in 0..2 {
        let red = reduced(&s.gram[g], n, known);
        let bb = red.view((0, 0), (n, n)).into_owned();
        // Scale for a well-conditioned inverse.
        let d: Vec<f64> = (0..n).map(|i| bb[(i, i)].max(0.0).sqrt()).collect();
        if d.iter().any(|x| *x <= 0.0) {
            return None;
        }
        let scaled = DMatrix::from_fn(n, n, |i, j| bb[(i, j)] / (d[i] * d[j]));
        let ch = scaled.cholesky()?;
        let inv_s = ch.inverse();
        let inv = DMatrix::from_fn(n, n, |i, j| inv_s[(i, j)] / (d[i] * d[j]));
        if (0..n).any(|i| !(inv[(i, i)] > 0.0 && inv[(i, i)].is_finite())) {
            return None;
        }
        inv_bb.push(inv);
        m_bd.push(red.view((0, n), (n, n)).into_owned());
        m_dd.push(red.view((n, n), (n, n)).into_owned());
    }
    // Per row a: A_a^-1 = sigma^2 M_bb^-1, c_a = M_bd b_a / sigma^2.
    let mut cov = [DMatrix::zeros(3 * n, 3 * n), DMatrix::zeros(3 * n, 3 * n)];
    let mut j_tt = 0.0;
    let mut ws: Vec<DVector<f64>> = Vec::with_capacity(6);
    let mut cw = 0.0;
    for row in 0..6 {
        let (g, r) = (row / 3, row % 3);
        let s2 = sig[g] * sig[g];
        let b_a = DVector::from_iterator(n, b.row(row).iter().copied());
        cov[g]
            .view_mut((r * n, r * n), (n, n))
            .copy_from(&(&inv_bb[g] * s2));
        let c = &m_bd[g] * &b_a / s2;
        j_tt += (b_a.transpose() * &m_dd[g] * &b_a)[0] / s2;
        let w = &inv_bb[g] * &c * s2;
        cw += c.dot(&w);
        ws.push(w);
    }
    let schur = j_tt - cw;
    if lag_unknown {
        if schur.is_nan() || schur <= 0.0 {
            return None;
        }
        for g in 0..2 {
            let w = DVector::from_iterator(
                3 * n,
                ws[3 * g..3 * g + 3].iter().flat_map(|w| w.iter().copied()),
            );
            cov[g].ger(1.0 / schur, &w, &w, 1.0);
        }
    }
    for (g, c) in cov.iter_mut().enumerate() {
        *c /= b.rows(3 * g, 3).norm_squared();
    }
    Some(Covariance {
        rel: cov,
        lag_sd_s: if lag_unknown {
            (1.0 / schur).sqrt()
        } else {
            0.0
        },
    })
}

/// How the error over seeds is read against a target: its RMS (the bound itself), or the
/// median of the worst of several seeds ([`WorstOf`]).
#[derive(Clone, Copy)]
pub enum Spread<'a> {
    Rms,
    Worst(&'a WorstOf),
}

impl Spread<'_> {
    /// Group `g`'s error figure at one snapshot, and the bound there.
    pub fn at(
        &self,
        s: &Snapshot,
        b: &DMatrix<f64>,
        sigma: (f64, f64),
        lag_unknown: bool,
        terms_unknown: bool,
        g: usize,
    ) -> Option<(f64, Bound)> {
        let c = covariance_with(s, b, sigma, lag_unknown, terms_unknown)?;
        let bound = c.bound();
        let figure = match self {
            Spread::Rms => bound.rel_err[g],
            Spread::Worst(w) => w.of(&c.rel[g]),
        };
        Some((figure, bound))
    }
}

/// The first snapshot at which the bound of group `g` reaches `target` (the bound never rises
/// with more data, so a binary search over the snapshots), and the bound there.
pub fn first_reaching(
    tr: &Trajectory,
    sigma: (f64, f64),
    lag_unknown: bool,
    g: usize,
    target: f64,
) -> Option<(usize, Bound)> {
    first_reaching_with(tr, sigma, lag_unknown, true, Spread::Rms, g, target)
        .map(|(i, b, _)| (i, b))
}

/// [`first_reaching`] with the terms known or not (see [`bound_with`]) and the error read as
/// `spread`; also the figure reached.
pub fn first_reaching_with(
    tr: &Trajectory,
    sigma: (f64, f64),
    lag_unknown: bool,
    terms_unknown: bool,
    spread: Spread,
    g: usize,
    target: f64,
) -> Option<(usize, Bound, f64)> {
    let at = |i: usize| {
        spread.at(
            &tr.snapshots[i],
            &tr.b,
            sigma,
            lag_unknown,
            terms_unknown,
            g,
        )
    };
    let ok = |i: usize| at(i).is_some_and(|(f, _)| f <= target);
    let last = tr.snapshots.len().checked_sub(1)?;
    if !ok(last) {
        return None;
    }
    let (mut lo, mut hi) = (0usize, last);
    if ok(0) {
        return at(0).map(|(f, b)| (0, b, f));
    }
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if ok(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    at(hi).map(|(f, b)| (hi, b, f))
}
