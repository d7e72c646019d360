//! What the navigation's own errors leave in B, which the fit's bound does not count.
//!
//! The fit's standard errors are those of least squares on white (segment-clustered) noise in
//! its outputs. Its inputs come from a dead-reckoning navigation: "down" carried by the gyro
//! from a rest that measured the gyro's bias, the velocity integrated from the accelerometer
//! less that gravity. At a noisy gyro those inputs are wrong by a slow error no segment's
//! intercept takes: the bias's error from a 1-2 s rest turns "down" by a few degrees over a
//! run, the gravity that leaks in moves the acceleration rows' output and, integrated, the
//! velocity the damping terms act on. Measured at the paper's noise (AMOUR-5, six_dof and
//! eight_vectored, seeds 1-10; docs/study.md "The navigation's errors in the bound"): the
//! acceleration rows' error against the truth was 1.25x their statistical bound on the RMS,
//! 1.00 with the truth's velocity and gravity in place of the navigation's; with the spread
//! drawn here added in quadrature, 1.01.
//!
//! How: the same log is fitted again `draws` times, each time with a draw of those errors
//! for the IMU's measured noise (the bias's error constant, sd gyro / sqrt(rest samples) or the
//! long idle rest's where that gave the bias; the
//! gyro's white noise integrated into "down"; the starting tilt's error, sd accelerometer / g
//! / sqrt(rest samples); the leaked gravity and the accelerometer's white noise integrated
//! into the velocity), and B's variance over the draws is the part of its error the bound
//! misses. Deterministic: the draws come from a fixed seed, so one run gives one bound.

use nalgebra::{DMatrix, Vector3};

use super::DynamicRun;

/// The IMU's noise and the rest that measured its bias, as the navigation's errors come from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavigationNoise {
    /// The gyro's white noise per sample (RMS of the axes), rad/s.
    pub gyro_sd: f64,
    /// The accelerometer's white noise per sample (RMS of the axes), m/s^2.
    pub accel_sd: f64,
    /// The error of the gyro's bias the navigation subtracts, rad/s per axis (a 1-2 s rest's:
    /// `gyro_sd / sqrt(rest samples)`; a long idle rest's is far smaller).
    pub bias_sd: f64,
    /// Samples of the rest the starting "down" was measured from.
    pub rest_samples: f64,
    /// Gravity, m/s^2.
    pub gravity: f64,
}

/// B's variance per entry (6 x n) over `draws` refits of `run`'s log, each with a draw of
/// the navigation's errors for `noise`, about the refit without them; `fit` refits a log and
/// returns its B. None without a log, with fewer than two samples, or when no draw fitted.
pub fn navigation_variance(
    run: &DynamicRun,
    noise: &NavigationNoise,
    draws: usize,
    seed: u64,
    fit: impl Fn(&DynamicRun) -> Option<DMatrix<f64>>,
) -> Option<DMatrix<f64>> {
    let log = run.log()?;
    let len = log.len();
    let (first, last) = (log.iter().next()?.t_s, log.iter().last()?.t_s);
    if len < 2 || last <= first {
        return None;
    }
    let dt = (last - first) / (len - 1) as f64;
    let base = fit(run)?;
    let mut rng = Gaussian::new(seed);
    let mut sum = DMatrix::<f64>::zeros(base.nrows(), base.ncols());
    let mut got = 0usize;
    for _ in 0..draws {
        let Some(drawn) = with_drawn_errors(run, noise, dt, &mut rng) else {
            continue;
        };
        let Some(b) = fit(&drawn) else { continue };
        if b.shape() != base.shape() || b.iter().any(|v| !v.is_finite()) {
            continue;
        }
        sum += (&b - &base).map(|x| x * x);
        got += 1;
    }
    (got > 0).then(|| sum / got as f64)
}

/// `run` with its log's inputs moved by one draw of the navigation's errors for `noise`
/// (samples `dt` apart): what [`navigation_variance`] refits, and what the lab's probe holds
/// against the navigation's errors against the truth. None without a log.
pub fn with_drawn_errors(
    run: &DynamicRun,
    noise: &NavigationNoise,
    dt: f64,
    rng: &mut Gaussian,
) -> Option<DynamicRun> {
    let rest = noise.rest_samples.max(1.0);
    let bias = rng.vector(noise.bias_sd);
    let tilt = rng.vector(noise.accel_sd / noise.gravity.max(1.0) / rest.sqrt());
    // About the body's horizontal axes only: a heading error does not move gravity.
    let mut theta = Vector3::new(tilt.x, tilt.y, 0.0);
    let mut dv = Vector3::zeros();
    let (sd_turn, sd_kick) = (noise.gyro_sd * dt, noise.accel_sd * dt);
    run.with_log_mapped(|s| {
        let mut out = *s;
        theta += bias * dt + rng.vector(sd_turn);
        let down = (s.down + theta.cross(&s.down)).normalize();
        let leak = (down - s.down) * noise.gravity;
        dv += leak * dt + rng.vector(sd_kick);
        out.rate += bias;
        out.down = down;
        out.motion += leak;
        out.velocity += dv;
        out
    })
}

/// Standard normal draws: xorshift64 and Box-Muller (no dependency for a few hundred draws a
/// run; the seed makes them the same on every machine).
pub struct Gaussian(u64);

impl Gaussian {
    pub fn new(seed: u64) -> Self {
        // xorshift must not start at zero.
        Gaussian(seed ^ 0x9E37_79B9_7F4A_7C15)
    }

    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        // In (0, 1]: the logarithm below never sees 0.
        ((self.0 >> 11) as f64 + 1.0) / (1u64 << 53) as f64
    }

    fn sample(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }

    fn vector(&mut self, sd: f64) -> Vector3<f64> {
        Vector3::new(self.sample(), self.sample(), self.sample()) * sd
    }
}

#[cfg(test)]
mod tests {
    use super::Gaussian;

    #[test]
    fn the_draws_are_standard_normal_and_the_same_for_a_seed() {
        let mut g = Gaussian::new(7);
        let xs: Vec<f64> = (0..20_000).map(|_| g.sample()).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
        assert!(mean.abs() < 0.03, "{mean}");
        assert!((var - 1.0).abs() < 0.05, "{var}");
        let mut again = Gaussian::new(7);
        assert_eq!(again.sample(), xs[0]);
        assert!(xs.iter().all(|x| x.is_finite()));
    }
}
