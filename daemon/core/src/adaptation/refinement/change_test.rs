//! The per-sample change test: a generalized-likelihood-ratio (GLR) test, on every control
//! tick, of "thruster i's rotation column changed at time t0" against "nothing changed", for
//! every thruster and a sliding set of candidate change times t0.
//!
//! An observer predicts the body rates from the commands sent with the model in force (its
//! effectiveness on the commands through the thrusters' spin-up lag, and those of its damping,
//! restoring and Coriolis terms that are significant, shrunk by their standard errors, with
//! the body velocity taken as zero: the vehicle holds), and is corrected towards the gyro by
//! the share `dt / tau_s` of its innovation `e = gyro - predicted` each sample. While the model
//! holds, `e` is the gyro's noise plus the model's error. A change `d` (3 rows, rad/s^2 per
//! unit command) of thruster i's rotation column from t0 on adds `phi_i(t) d` to the
//! innovation, with `phi_i(t0) = 0` and `phi_i <- (1 - dt / tau_s) phi_i + dt u_i` (u_i the
//! thruster's lagged command). The least-squares `d` on each axis, with an unknown constant
//! innovation per candidate (the model's bias is not a change), is `S / F`, S and F the
//! centred sums of `phi e` and `phi^2`; the statistic is `chi2 = sum over the rows judged of
//! S^2 / (F sigma^2)`, sigma^2 the innovation's variance (a slow running estimate). A thruster
//! changed when its chi2 passes `chi2`, its estimated move `|d|` is at least `min_share` of
//! the model's column, and the same holds (at the rows' 99 % point) with every thruster's
//! move fitted jointly, which also names the thruster.
//!
//! Rows: a row is judged only while its axis is held (near its setpoint, the setpoint not
//! stepping about it) for `warmup_s`, and a candidate loses a row for good once its axis left
//! the hold. Through pitch steps the roll and yaw rows go on being judged, and they are where
//! a turned pitch thruster shows: at the paper's noise, AMOUR-5 pitching +-20 deg every 4 s,
//! the top thruster turned 45 deg was found after 4.2-4.4 s in 10 of 10 seeds (in process,
//! `change_test_soak`), with no false alarm in 10 x 20 minutes, where judging every row with
//! the learned model's full terms saw "changes" of chi2 800-1700 on the unchanged vehicle
//! (`detection_bound`).
//!
//! Why the gyro: it measures the rates the torque changes, white noise per sample; the
//! attitude sees the same torque integrated once more with less noise at low frequencies, but
//! the attitude filter's error is what the controller acts on, so the commands are correlated
//! with it: a predictor that took its restoring moment from the filter's attitude and
//! integrated slowly (tau 2 s) saw "changes" of chi2 100-400 on an unchanged vehicle at the
//! paper's noise (tests/refinement.rs, `detection_bound`). Why a short `tau_s`: the observer's
//! correction is a high-pass filter, which keeps the dither's and the controller's fast
//! command changes (0.05 s holds) and drops the slow errors of the model and of the attitude.
//!
//! In a swell the controller's answer to the waves makes the thrusters' signatures correlate
//! with the waves' torque; with `calibration_s` set, each candidate's variance is scaled by the
//! apparent moves measured on batches of the recent past ([`Calibration`], opt-in).
//!
//! Cost: O(candidates x thrusters) per sample (40 x 5 with the defaults), no allocation after
//! `new`. Pure: samples and time in, a verdict out.

use nalgebra::{UnitQuaternion, Vector3};
use thruster_protocol::MAX_THRUSTERS;

use crate::estimator::dynamic::regressors::{terms, TERMS};
use crate::estimator::dynamic::DynamicTerms;
use crate::model::Model;

use super::calibration::{Calibration, Snapshot};
use crate::adaptation::calibrate_when::CalibrateWhen;

/// The change test's settings (documented on `RefinementConfig`'s `change_*` keys).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ChangeSettings {
    pub tau_s: f64,
    pub horizon_s: f64,
    pub spacing_s: f64,
    pub chi2: f64,
    pub min_share: f64,
    pub noise_s: f64,
    pub warmup_s: f64,
    /// The model's own error assumed for every entry, a share of its column's norm.
    pub model_floor: f64,
    /// The thrusters' spin-up time constant the model was fitted with, s.
    pub lag_s: f64,
    /// How significant a damping, restoring or Coriolis term of the model must be to take
    /// part in the prediction: coefficient c with standard error se is used as
    /// `c (1 - (term_z se / c)^2)` when positive, else not at all (0: every term as fitted).
    pub term_z: f64,
    /// A candidate is judged from this age on, s.
    pub min_age_s: f64,
    /// The candidates' variance is calibrated on the apparent moves of batches of this long,
    /// s, over `calibration_s` of the recent past ([`Calibration`]); 0: not calibrated.
    #[serde(default)]
    pub calibration_s: f64,
    #[serde(default)]
    pub batch_s: f64,
    /// When the calibration applies ([`CalibrateWhen`]).
    #[serde(default)]
    pub calibrate_when: CalibrateWhen,
    /// The joint fit's named thruster must lead every other thruster's joint chi-square by
    /// this much; by less, the test names nobody yet and waits for more evidence (0: the
    /// largest is named).
    #[serde(default)]
    pub name_margin: f64,
}

/// The test's largest statistic at one sample.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ChangeStat {
    /// Thruster, 0-based.
    pub thruster: usize,
    /// Chi-square of its column's change since the candidate time, 3 rows.
    pub chi2: f64,
    /// The estimated move as a share of the model's rotation column.
    pub share: f64,
    /// Seconds since the candidate change time.
    pub since_s: f64,
}

/// One candidate change time and the regression since then, per thruster.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
struct Candidate {
    live: bool,
    /// The rows still judged: an axis that left its hold since `start_ns` is not (its
    /// innovation then carries the manoeuvre's unmodelled damping and restoring).
    rows: [bool; 3],
    start_ns: u64,
    count: f64,
    sum_e: [f64; 3],
    phi: [f64; MAX_THRUSTERS],
    sum_phi: [f64; MAX_THRUSTERS],
    sum_phi_e: [[f64; 3]; MAX_THRUSTERS],
    /// Sums of `phi_i phi_k` (i <= k): the diagonal is each thruster's own regression, the
    /// rest the joint fit that names the thruster.
    sum_cross: [[f64; MAX_THRUSTERS]; MAX_THRUSTERS],
    /// The calibration at `start_ns`, fixed then.
    #[serde(default)]
    calibration: Snapshot,
}

impl Candidate {
    const EMPTY: Candidate = Candidate {
        live: false,
        rows: [false; 3],
        start_ns: 0,
        count: 0.0,
        sum_e: [0.0; 3],
        phi: [0.0; MAX_THRUSTERS],
        sum_phi: [0.0; MAX_THRUSTERS],
        sum_phi_e: [[0.0; 3]; MAX_THRUSTERS],
        sum_cross: [[0.0; MAX_THRUSTERS]; MAX_THRUSTERS],
        calibration: Snapshot::NONE,
    };
}

/// The test's state: observer, noise statistics and candidates.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ChangeTest {
    s: ChangeSettings,
    candidates: Vec<Candidate>,
    next: usize,
    next_candidate_ns: u64,
    started_ns: Option<u64>,
    /// Since when each axis has been held (within its error bound), if it is.
    held_since_ns: [Option<u64>; 3],
    last_ns: Option<u64>,
    /// Predicted body rate, rad/s.
    rate: Vector3<f64>,
    /// Every thruster's signature since the observer started (as a candidate's, from 0 at
    /// the start): what the calibration regresses on.
    #[serde(default)]
    signature: [f64; MAX_THRUSTERS],
    #[serde(default)]
    calibration: Calibration,
    /// When the observer started (its first sample).
    #[serde(default)]
    observer_started_ns: u64,
    /// The thrusters of the model judged against.
    #[serde(default)]
    thrusters: usize,
    /// The vehicle is in a sea (`set_in_a_sea`).
    #[serde(default)]
    in_a_sea: bool,
    lag: [f64; MAX_THRUSTERS],
    lag_abs: f64,
    #[serde(with = "crate::serde_arrays::array")]
    terms: [f64; TERMS],
    mean: [f64; 3],
    var: [f64; 3],
    seen: u64,
    last_stat: Option<ChangeStat>,
    /// The model version the candidates were judged against.
    version: u64,
}

impl ChangeTest {
    /// The candidates' storage is allocated here, once: `horizon_s / spacing_s` of them.
    pub fn new(s: ChangeSettings) -> Self {
        let count = if s.spacing_s > 0.0 && s.horizon_s.is_finite() {
            (s.horizon_s / s.spacing_s).ceil().clamp(1.0, 1000.0) as usize
        } else {
            1
        };
        ChangeTest {
            s,
            candidates: vec![Candidate::EMPTY; count],
            next: 0,
            next_candidate_ns: 0,
            started_ns: None,
            held_since_ns: [None; 3],
            last_ns: None,
            rate: Vector3::zeros(),
            signature: [0.0; MAX_THRUSTERS],
            calibration: Calibration::default(),
            observer_started_ns: 0,
            thrusters: 0,
            in_a_sea: false,
            lag: [0.0; MAX_THRUSTERS],
            lag_abs: 0.0,
            terms: [0.0; TERMS],
            mean: [0.0; 3],
            var: [0.0; 3],
            seen: 0,
            last_stat: None,
            version: 0,
        }
    }

    /// Start over (a new model, control restarted): the observer restarts from the next
    /// gyro sample and the test waits `warmup_s` before it judges.
    pub fn reset(&mut self) {
        for c in self.candidates.iter_mut() {
            c.live = false;
        }
        self.next = 0;
        self.started_ns = None;
        self.held_since_ns = [None; 3];
        self.last_ns = None;
        self.seen = 0;
        self.last_stat = None;
        self.calibration.reset();
    }

    /// Whether the water moves the held vehicle (`sea_state::InASea`), every control tick. A
    /// calibration that applies only in a sea starts afresh on entering one, and the
    /// candidates judged uncalibrated until then are dropped (their variance is not this
    /// water's; new ones wait for the calibration's batches).
    pub fn set_in_a_sea(&mut self, in_a_sea: bool) {
        let was = self.calibrating();
        self.in_a_sea = in_a_sea;
        if self.calibrating() && !was {
            self.calibration.reset();
            for c in self.candidates.iter_mut() {
                c.live = false;
            }
        }
    }

    /// Whether the calibration against the water applies now.
    fn calibrating(&self) -> bool {
        self.s
            .calibrate_when
            .applies(self.s.calibration_s, self.in_a_sea)
    }

    /// The thrusters' spin-up time constant of the model's fit, s.
    pub fn set_lag_s(&mut self, lag_s: f64) {
        self.s.lag_s = lag_s;
    }

    /// The largest statistic of the last sample (whether or not it passed), for telemetry
    /// and the tests.
    pub fn last_stat(&self) -> Option<ChangeStat> {
        self.last_stat
    }

    /// One control tick: `rate` the bias-free gyro (rad/s) now, `attitude` the filter's,
    /// `sent` the commands sent from now on (model units, dither included; at most the
    /// model's thrusters). `sigma_floor` (rad/s, per axis) is the least noise assumed.
    /// `held`: per body axis (roll, pitch, yaw), the vehicle holds that axis near its
    /// setpoint now. A row is judged only while its axis has been held for `warmup_s`, and a
    /// candidate loses a row for good once its axis left the hold (a manoeuvre about that
    /// axis, where the unmodelled damping and restoring are largest); the other rows go on
    /// being judged through it. Returns the change found, if any.
    // Indexing by thruster and axis over several fixed-size arrays at once reads clearer than
    // zipped iterators here.
    #[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
    pub fn observe(
        &mut self,
        t_ns: u64,
        rate: &Vector3<f64>,
        attitude: &UnitQuaternion<f64>,
        model: &Model,
        sent: &[f64],
        sigma_floor: &[f64; 3],
        held: [bool; 3],
    ) -> Option<ChangeStat> {
        let n = sent.len().min(model.thrusters()).min(MAX_THRUSTERS);
        // B multiplies the commands' thrust shape, not the bare commands (see
        // `DynamicTerms::thrust_asymmetry`): without it a learned model's prediction misses
        // each thruster's forward surplus.
        let k = model.dynamics.as_ref().map_or(0.0, DynamicTerms::asymmetry);
        let finite = rate.iter().all(|v| v.is_finite()) && sent[..n].iter().all(|v| v.is_finite());
        if !finite || n == 0 {
            return None;
        }
        if model.version != self.version {
            // A new model (the refinement's update included): the candidates were judged
            // against the old one, and its switch is a step in the prediction. Noise-free, an
            // update installed mid-flight was "a change" 0.4 s later.
            self.version = model.version;
            for c in self.candidates.iter_mut() {
                c.live = false;
            }
            //
            // The warm-up starts over too. Measured (docs/study.md): with a realistic IMU the
            // refinement updates the model every 5-6 s, so in still water the test judged 0
            // of 48000 samples in 4 minutes. Kept warm, it judged 47 % and found the rotated
            // top thruster 0.5-0.6 s after the change, but on candidates started before it,
            // naming thruster 2 on 4 of 10 seeds (10 of 10 noise-free), and the re-estimation
            // would carry the moved thruster's old column over: open.
            self.started_ns = None;
            // The calibration outlives an update of the same thrusters (the refinement's
            // small moves; the machine resets the test on any other swap).
            if model.thrusters() != self.thrusters {
                self.calibration.reset();
                self.thrusters = model.thrusters();
            }
        }
        let Some(last) = self.last_ns else {
            // The first sample: the observer starts at the gyro, the lag at the command.
            self.started_ns = Some(t_ns);
            self.last_ns = Some(t_ns);
            self.rate = *rate;
            self.observer_started_ns = t_ns;
            self.signature = [0.0; MAX_THRUSTERS];
            for (l, u) in self.lag.iter_mut().zip(&sent[..n]) {
                *l = DynamicTerms::thrust_shape(k, *u);
            }
            self.lag_abs = sent[..n].iter().map(|v| v.abs()).sum::<f64>() / n as f64;
            self.mean = [0.0; 3];
            self.var = [0.0; 3];
            self.next_candidate_ns = t_ns;
            return None;
        };
        if t_ns <= last {
            return None;
        }
        let dt = ((t_ns - last) as f64 * 1e-9).min(0.1);
        self.last_ns = Some(t_ns);
        let gain = (dt / self.s.tau_s).clamp(0.0, 1.0);
        let e = rate - self.rate;

        // Judge this sample's innovation against every candidate, on the rows whose axis
        // has been held for `warmup_s` (after a manoeuvre about it the vehicle swings back
        // first), once the observer has run `warmup_s` on this model.
        let mut settled = [false; 3];
        for j in 0..3 {
            if !held[j] {
                self.held_since_ns[j] = None;
                continue;
            }
            let since = *self.held_since_ns[j].get_or_insert(t_ns);
            settled[j] = (t_ns - since) as f64 * 1e-9 >= self.s.warmup_s;
        }
        let started = *self.started_ns.get_or_insert(t_ns);
        let warm = (t_ns - started) as f64 * 1e-9 >= self.s.warmup_s;
        let mut best: Option<ChangeStat> = None;
        let mut found: Option<ChangeStat> = None;
        for c in self.candidates.iter_mut().filter(|c| c.live) {
            for j in 0..3 {
                c.rows[j] &= settled[j];
            }
            c.live = c.rows.iter().any(|&r| r);
        }
        let mut z = [0.0; 3];
        let mut inv = [0.0; 3];
        for j in 0..3 {
            z[j] = e[j] - self.mean[j];
            let floor = sigma_floor[j].max(1e-6);
            inv[j] = 1.0 / self.var[j].max(floor * floor);
        }
        // The calibration runs across model versions (the refinement updates the model every
        // window, 5 s with a realistic IMU, and each update restarts the candidates' warm-up),
        // on the rows held, once the observer has run `warmup_s`.
        let observing = (t_ns - self.observer_started_ns) as f64 * 1e-9 >= self.s.warmup_s;
        if self.calibrating() && observing {
            let keep = (-self.s.batch_s / self.s.calibration_s).exp();
            let var = std::array::from_fn(|j| 1.0 / inv[j]);
            self.calibration.add(
                &self.signature[..n],
                &z,
                &var,
                settled,
                dt,
                self.s.batch_s,
                keep,
            );
        }
        if warm && settled.iter().any(|&r| r) {
            if t_ns >= self.next_candidate_ns {
                // Calibrated, a row is judged only once its calibration has batches.
                let calibration = if self.calibrating() {
                    self.calibration.snapshot(n)
                } else {
                    Snapshot::NONE
                };
                let rows = std::array::from_fn(|j| settled[j] && calibration.rows[j]);
                self.candidates[self.next] = Candidate {
                    live: rows.iter().any(|&r| r),
                    rows,
                    start_ns: t_ns,
                    calibration,
                    ..Candidate::EMPTY
                };
                self.next = (self.next + 1) % self.candidates.len();
                self.next_candidate_ns = t_ns + (self.s.spacing_s * 1e9) as u64;
            }
            let b = &model.effectiveness;
            let mut col_norm = [0.0; MAX_THRUSTERS];
            let mut biggest: f64 = 0.0;
            for (i, c) in col_norm.iter_mut().enumerate().take(n) {
                *c = b.fixed_view::<3, 1>(0, i).norm();
                biggest = biggest.max(*c);
            }
            // A thruster with (almost) no moment in the model is never named, alone or
            // jointly: its share would be a move over a column of nearly nothing.
            let nameable = col_norm.map(|c| c > 0.0 && c >= MIN_COLUMN * biggest);
            let mut found_in: Option<usize> = None;
            for (ci, c) in self
                .candidates
                .iter_mut()
                .enumerate()
                .filter(|(_, c)| c.live)
            {
                c.count += 1.0;
                for j in 0..3 {
                    c.sum_e[j] += z[j];
                }
                for i in 0..n {
                    for k in i..n {
                        c.sum_cross[i][k] += c.phi[i] * c.phi[k];
                    }
                }
                let since_s = (t_ns - c.start_ns) as f64 * 1e-9;
                for i in 0..n {
                    let p = c.phi[i];
                    c.sum_phi[i] += p;
                    for j in 0..3 {
                        c.sum_phi_e[i][j] += p * z[j];
                    }
                    // A candidate younger than `min_age_s`: its signatures have barely risen
                    // and cannot be told apart (see `RefinementConfig::change_min_age_s`).
                    if c.count < 3.0 || !nameable[i] || since_s < self.s.min_age_s {
                        continue;
                    }
                    let phi2 = c.sum_cross[i][i];
                    let f = phi2 - c.sum_phi[i] * c.sum_phi[i] / c.count;
                    if f.is_nan() || f <= (1e-12 * phi2).max(0.0) {
                        continue;
                    }
                    // The move over its variance: the regression's (sigma^2 / F) and the model's
                    // own error (a model wrong by a few percent under large commands is no
                    // change). Not the model's standard errors: at the paper's noise they are
                    // 5-10 % of a column and the rotation was then never found. The share is
                    // of the judged rows' move, against the whole column.
                    let floor = self.s.model_floor * col_norm[i];
                    let (mut chi2, mut d2) = (0.0, 0.0);
                    // The variance calibrated against the water (a factor 1 without).
                    for j in (0..3).filter(|&j| c.rows[j]) {
                        let s = c.sum_phi_e[i][j] - c.sum_phi[i] * c.sum_e[j] / c.count;
                        let d = s / f;
                        let var = c.calibration.inflation[i][j] / (inv[j] * f);
                        chi2 += d * d / (var + floor * floor);
                        d2 += d * d;
                    }
                    let stat = ChangeStat {
                        thruster: i,
                        chi2,
                        share: d2.sqrt() / col_norm[i],
                        since_s,
                    };
                    if best.is_none_or(|b| chi2 > b.chi2) {
                        best = Some(stat);
                    }
                    if chi2 > self.s.chi2
                        && stat.share >= self.s.min_share
                        && found.is_none_or(|b| chi2 > b.chi2)
                    {
                        found = Some(stat);
                        found_in = Some(ci);
                    }
                }
            }
            // Which thruster, and is the move real: every thruster's move fitted at once. One
            // at a time, thrusters the controller moves together share each other's moves:
            // the controller's answer to a moved thruster (its neighbours taking up the new
            // moment) looks like a change of theirs (holding level at the paper's noise,
            // thruster 5 was named for the rotated thruster 1 in 4 of 5 seeds), and through
            // pitch steps with a realistic IMU the model's small errors under the large trim
            // commands summed to "moves" of 40 % and more of one column, 6-33 % jointly. The
            // joint move must pass `min_share` too; its chi-square is not asked to pass the
            // threshold again (sharing the evidence between correlated thrusters lowers it),
            // only to be significant at 99 % for the rows judged: on four_up through pitch steps
            // joint moves of 40 % with a chi-square of 0 were "changes".
            if let (Some(f), Some(ci)) = (found.as_mut(), found_in) {
                let rows = self.candidates[ci].rows.iter().filter(|&&r| r).count();
                match attribute(&self.candidates[ci], n, &inv, &col_norm, &nameable) {
                    Some(a)
                        if (self.s.min_share..=MAX_JOINT_SHARE).contains(&a.share)
                            && a.chi2 >= JOINT_CHI2_99[rows]
                            && a.lead >= self.s.name_margin =>
                    {
                        f.thruster = a.thruster;
                        f.chi2 = a.chi2;
                        f.share = a.share;
                    }
                    Some(_) => found = None,
                    None => {}
                }
            }
        }
        self.last_stat = best;

        // The innovation's statistics, per row while its axis is held: the first samples
        // average, then a slow forgetting.
        let w = (1.0 / (self.seen + 1) as f64).max(dt / self.s.noise_s.max(dt));
        let mut any = false;
        for j in (0..3).filter(|&j| held[j]) {
            let d = e[j] - self.mean[j];
            self.mean[j] += w * d;
            self.var[j] += w * (d * d - self.var[j]);
            any = true;
        }
        if any {
            self.seen += 1;
        }

        // The observer: correct, then predict the next sample with the commands sent now.
        self.rate += e * gain;
        let a = if self.s.lag_s > 0.0 {
            1.0 - (-dt / self.s.lag_s).exp()
        } else {
            1.0
        };
        let mut abs = 0.0;
        for (l, u) in self.lag.iter_mut().zip(&sent[..n]) {
            *l += a * (DynamicTerms::thrust_shape(k, *u) - *l);
            abs += u.abs();
        }
        self.lag_abs += a * (abs / n as f64 - self.lag_abs);
        let down = attitude.inverse_transform_vector(&Vector3::z());
        terms(
            &Vector3::zeros(),
            &self.rate,
            &down,
            self.lag_abs,
            &mut self.terms,
        );
        let b = &model.effectiveness;
        let mut accel = Vector3::<f64>::zeros();
        for j in 0..3 {
            for i in 0..n {
                accel[j] += b[(j, i)] * self.lag[i];
            }
            if let Some(d) = &model.dynamics {
                if d.coefficients.ncols() == TERMS && d.std_err.shape() == d.coefficients.shape() {
                    for (k, t) in self.terms.iter().enumerate() {
                        accel[j] +=
                            shrunk(d.coefficients[(j, k)], d.std_err[(j, k)], self.s.term_z) * t;
                    }
                }
            }
        }
        if accel.iter().all(|v| v.is_finite()) {
            self.rate += accel * dt;
        }
        if !self.rate.iter().all(|v| v.is_finite()) {
            self.rate = *rate;
        }
        let keep = 1.0 - gain;
        for i in 0..n {
            self.signature[i] = keep * self.signature[i] + dt * self.lag[i];
        }
        for c in self.candidates.iter_mut().filter(|c| c.live) {
            for i in 0..n {
                c.phi[i] = keep * c.phi[i] + dt * self.lag[i];
            }
        }
        found
    }
}

/// A thruster whose column (rotation rows) is below this share of the largest has (almost) no
/// moment in the model: its share of its column means nothing, so it is never named.
const MIN_COLUMN: f64 = 0.05;

/// The largest joint move, as a share of its column, taken for a thruster that moved. A
/// thruster turned around moves its column by 2; a joint fit that needs far more cannot tell
/// the thrusters apart (their commands moved together) and names nobody. Measured: the real
/// changes' joint shares were 0.77-1.27 (AMOUR-5, in process and through the processes); on
/// the unchanged four_up with a realistic IMU (seed 4, through pitch steps) a one-at-a-time
/// move of 50 % was "jointly" a move of 463 times thruster 3's column, chi-square 9.
const MAX_JOINT_SHARE: f64 = 3.0;

/// The chi-square 99 % points for 0-3 degrees of freedom (the rows judged): the joint move
/// of the named thruster must pass its own.
const JOINT_CHI2_99: [f64; 4] = [f64::INFINITY, 6.63, 9.21, 11.34];

/// A term's coefficient `c` (standard error `se`) as the prediction uses it: shrunk towards 0
/// by its significance, `c (1 - (z se / c)^2)` when positive, else 0 (a positive-part
/// James-Stein rule per coefficient). Why: at the paper's noise most terms learned near level
/// under feedback are noise (a roll damping of -6.2 where the truth is -0.24, pairs cancelling
/// at +-85) and predicted "changes" through pitch steps, while with a realistic IMU they are
/// what keeps B's small errors from looking like one. Unknown (non-finite) is 0.
fn shrunk(c: f64, se: f64, z: f64) -> f64 {
    if !c.is_finite() {
        return 0.0;
    }
    if z <= 0.0 {
        return c;
    }
    if !se.is_finite() || c == 0.0 {
        return 0.0;
    }
    let r = z * se / c;
    c * (1.0 - r * r).max(0.0)
}

/// The joint fit of every thruster's column move over one candidate's samples (its judged
/// rows): the thruster whose move is the most significant, its chi-square and its move's
/// share of its column. None when the thrusters' signatures are too collinear to tell apart.
/// Stack only (called on a detection, from the control tick).
// Index loops over the Gram matrix and its right-hand sides read clearer than iterators.
#[allow(clippy::needless_range_loop)]
fn attribute(
    c: &Candidate,
    n: usize,
    inv_var: &[f64; 3],
    col_norm: &[f64; MAX_THRUSTERS],
    nameable: &[bool; MAX_THRUSTERS],
) -> Option<Attribution> {
    use nalgebra::SMatrix;
    if n == 0 || c.count < 3.0 {
        return None;
    }
    // Centred Gram of the signatures; the unused block is the identity (decoupled).
    let mut g = SMatrix::<f64, MAX_THRUSTERS, MAX_THRUSTERS>::identity();
    let mut trace = 0.0;
    for i in 0..n {
        for k in i..n {
            let v = c.sum_cross[i][k] - c.sum_phi[i] * c.sum_phi[k] / c.count;
            g[(i, k)] = v;
            g[(k, i)] = v;
        }
        trace += g[(i, i)];
    }
    if !(trace > 0.0 && trace.is_finite()) {
        return None;
    }
    // A whisker of ridge: thrusters commanded in lockstep are told apart by nothing.
    for i in 0..n {
        g[(i, i)] += 1e-9 * trace / n as f64;
    }
    let ginv = g.cholesky()?.inverse();
    // Every thruster's move is fitted; only a nameable one is named.
    let mut best: Option<Attribution> = None;
    let mut chi2_of = [0.0; MAX_THRUSTERS];
    for i in 0..n {
        if !nameable[i] || ginv[(i, i)] <= 0.0 {
            continue;
        }
        let (mut chi2, mut d2) = (0.0, 0.0);
        for j in (0..3).filter(|&j| c.rows[j]) {
            let mut d = 0.0;
            for k in 0..n {
                let r = c.sum_phi_e[k][j] - c.sum_phi[k] * c.sum_e[j] / c.count;
                d += ginv[(i, k)] * r;
            }
            chi2 += d * d * inv_var[j] / (ginv[(i, i)] * c.calibration.inflation[i][j]);
            d2 += d * d;
        }
        chi2_of[i] = chi2;
        if best.is_none_or(|b| chi2 > b.chi2) {
            best = Some(Attribution {
                thruster: i,
                chi2,
                share: d2.sqrt() / col_norm[i],
                lead: 0.0,
            });
        }
    }
    best.map(|b| {
        let runner_up = (0..n)
            .filter(|&i| i != b.thruster)
            .map(|i| chi2_of[i])
            .fold(0.0, f64::max);
        Attribution {
            lead: b.chi2 - runner_up,
            ..b
        }
    })
}

/// The joint fit's named thruster: its move's chi-square and share of its column, and its
/// lead over the next thruster's chi-square.
#[derive(Debug, Clone, Copy)]
struct Attribution {
    thruster: usize,
    chi2: f64,
    share: f64,
    lead: f64,
}

#[cfg(test)]
mod tests;
