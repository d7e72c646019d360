//! The vehicle's steady velocity through the water when the run began, which no IMU sees.
//!
//! The navigation starts its velocity from zero at the rest before the pulses: an
//! accelerometer measures acceleration, and a vehicle towed at a steady speed (a tether's
//! pull on an idle vehicle) is at rest to it. Its velocity through the water is then wrong by
//! that speed for the whole run, fixed in the world, and the damping and Coriolis terms act
//! on the wrong velocity. Measured on AMOUR-5 towed by a 10 N tether after 125 s idle at a
//! realistic IMU (docs/study.md, "A tether's tow at the start"): the navigation's velocity
//! 0.69 m/s off (the whole tow), the lag learned 2-4 % long and the rotation rows 2.1x their
//! bound; the lag learned again on the log with that start error taken out: 4.1 % -> 2.1 %
//! off on the RMS, and the fit's own score lowest near the true start velocity.
//!
//! So the start velocity is searched as the lag is: the log refitted with the velocity moved
//! by a world-fixed horizontal v0 (the depth sensor holds the vertical), on a grid made finer
//! twice about its best point, scored by the lag's profile score (the fit's summed ln
//! residual variances). The vertical is left alone: the depth sensor aids it.

use nalgebra::Vector3;

use super::lag_search::profile_score;
use super::DynamicRun;

/// The grid's half-width in steps, the first pass and the finer ones.
const COARSE_HALF: i32 = 4;
const FINE_HALF: i32 = 2;
/// Each finer pass's step is the one before over this.
const REFINE: f64 = 4.0;
/// Passes after the coarse one.
const FINE_PASSES: usize = 2;

/// The best start velocity the log supports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartVelocity {
    /// The velocity through the water at the run's start the navigation missed, NED, m/s
    /// (vertical 0).
    pub velocity_ned_mps: Vector3<f64>,
    /// ln of the likelihood ratio of the fit with it against the fit without (the log's rows
    /// over two times the scores' difference); >= 0.
    pub log_likelihood_ratio: f64,
}

/// `run` with its log's velocity moved by `v0_ned` held fixed in the world (through each
/// sample's attitude), not refitted (refit or restate it). None without a log.
pub fn with_start_velocity(run: &DynamicRun, v0_ned: &Vector3<f64>) -> Option<DynamicRun> {
    run.with_log_mapped(|s| {
        let mut out = *s;
        out.velocity = s.velocity + s.attitude.inverse_transform_vector(v0_ned);
        out
    })
}

/// The horizontal start velocity within `max_mps` that fits `run`'s log best at `lags`:
/// a grid of 9 x 9 steps of `max_mps / 4`, then twice a 5 x 5 grid a quarter the step about
/// the best point (about 120 refits). None without a log or a score at zero.
pub fn search_start_velocity(
    run: &DynamicRun,
    lags: &[f64],
    max_mps: f64,
) -> Option<StartVelocity> {
    let (velocity_ned_mps, log_likelihood_ratio) =
        best_horizontal(run, lags, max_mps, with_start_velocity)?;
    Some(StartVelocity {
        velocity_ned_mps,
        log_likelihood_ratio,
    })
}

/// The horizontal vector within `max` (norm) at which `moved(run, v)` refitted at `lags`
/// has the lowest profile score, and the ln likelihood ratio of that fit against the fit at
/// zero (the log's rows over two times the scores' difference; >= 0): a grid of 9 x 9 steps
/// of `max / 4` about zero, then twice a 5 x 5 grid a quarter the step about the best point
/// (about 120 refits). None without a log, a finite positive `max` or a score at zero.
/// Shared by the start velocity's search and the velocity drift's
/// ([`super::velocity_drift`]).
pub(super) fn best_horizontal(
    run: &DynamicRun,
    lags: &[f64],
    max: f64,
    moved: impl Fn(&DynamicRun, &Vector3<f64>) -> Option<DynamicRun>,
) -> Option<(Vector3<f64>, f64)> {
    if !(max.is_finite() && max > 0.0) {
        return None;
    }
    let score_at = |v: &Vector3<f64>| -> Option<f64> {
        profile_score(&moved(run, v)?.refit(lags)?).filter(|s| s.is_finite())
    };
    let zero = Vector3::zeros();
    let s0 = score_at(&zero)?;
    let mut best = (zero, s0);
    let mut step = max / COARSE_HALF as f64;
    let mut half = COARSE_HALF;
    for _ in 0..=FINE_PASSES {
        let centre = best.0;
        for i in -half..=half {
            for j in -half..=half {
                let v = centre + Vector3::new(i as f64 * step, j as f64 * step, 0.0);
                if (i == 0 && j == 0) || v.xy().norm() > max * (1.0 + 1e-9) {
                    continue;
                }
                if let Some(s) = score_at(&v) {
                    if s < best.1 {
                        best = (v, s);
                    }
                }
            }
        }
        step /= REFINE;
        half = FINE_HALF;
    }
    let rows = run.samples() as f64;
    Some((best.0, (0.5 * rows * (s0 - best.1)).max(0.0)))
}
