//! The dead-reckoned velocity's drift over an open-loop run, which no IMU sees.
//!
//! The navigation integrates the accelerometer from zero at the rest. A tilt left after the
//! rest of a milliradian leaks a hundredth of a m/s^2 of gravity into the horizontal, fixed in
//! the world, and the velocity the damping and Coriolis terms act on walks away from the truth
//! as a ramp from the run's start. Measured on AMOUR-5 at a 0.2 s lag and a realistic IMU,
//! seed 5 of the lag table at a reach of 0.025 (docs/study.md, "The velocity's drift
//! searched, and a reach for slow thrusters"): 0.022 m/s RMS off, a ramp of 0.006 m/s^2 per horizontal axis, 0.005 m/s RMS left
//! once the ramp is taken out; the lag learned 0.1936 s (0.1977 s on the true velocity) and the
//! model 0.038 off under a bound of 0.046, where a perfect DVL made it 0.013.
//!
//! So the drift's rate is searched as the start velocity is
//! ([`super::start_velocity`]): the log refitted with the velocity moved by a world-fixed
//! horizontal ramp `-r (t - t0)` from the log's first sample, on the same grid, scored by the
//! lag's profile score. The vertical is left alone: the depth sensor aids it.

use nalgebra::Vector3;

use super::start_velocity::best_horizontal;
use super::DynamicRun;

/// The drift rate the log supports best.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VelocityDrift {
    /// The rate at which the navigation's velocity ran away from the truth, NED, m/s^2
    /// (vertical 0): the navigated velocity at time t was `rate (t - t0)` too large.
    pub rate_ned_mps2: Vector3<f64>,
    /// ln of the likelihood ratio of the fit with it against the fit without; >= 0.
    pub log_likelihood_ratio: f64,
}

/// `run` with its log's velocity less the ramp `rate_ned (t - t0)`, held fixed in the world
/// (through each sample's attitude), t0 the log's first sample; not refitted. None without a
/// log.
pub fn without_drift(run: &DynamicRun, rate_ned: &Vector3<f64>) -> Option<DynamicRun> {
    let t0 = run.log()?.iter().next().map_or(0.0, |s| s.t_s);
    run.with_log_mapped(|s| {
        let mut out = *s;
        out.velocity = s.velocity
            - s.attitude
                .inverse_transform_vector(&(rate_ned * (s.t_s - t0)));
        out
    })
}

/// The horizontal drift rate within `max_mps2` that fits `run`'s log best at `lags` (the
/// start velocity's grid, about 120 refits). None without a log or a score at zero.
pub fn search_velocity_drift(
    run: &DynamicRun,
    lags: &[f64],
    max_mps2: f64,
) -> Option<VelocityDrift> {
    let (rate_ned_mps2, log_likelihood_ratio) =
        best_horizontal(run, lags, max_mps2, without_drift)?;
    Some(VelocityDrift {
        rate_ned_mps2,
        log_likelihood_ratio,
    })
}
