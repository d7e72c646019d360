//! Noise levels and baselines measured while the vehicle is at rest (the paper's first step).

use nalgebra::Vector3;
use serde::Serialize;

/// Per-axis mean and standard deviation of the gyro and the accelerometer at rest.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct NoiseLevels {
    /// Gyro reading at rest (its bias), rad/s.
    pub gyro_baseline: [f64; 3],
    /// Accelerometer reading at rest (gravity as specific force, plus bias), m/s^2.
    pub accel_baseline: [f64; 3],
    /// Per-axis gyro standard deviation, rad/s.
    pub gyro_sigma: [f64; 3],
    /// Per-axis accelerometer standard deviation, m/s^2.
    pub accel_sigma: [f64; 3],
    /// Per-axis gyro noise from successive differences (their standard deviation / sqrt 2),
    /// rad/s: white noise alone, whatever slow motion the rest had (a swell rocking the
    /// vehicle goes into `gyro_sigma`, not here).
    pub gyro_white_sigma: [f64; 3],
    /// Samples the levels were measured from.
    pub samples: u64,
}

impl NoiseLevels {
    /// Levels for a known, isotropic, zero-mean noise (used by the study and tests).
    pub fn isotropic(sigma_rot: f64, sigma_acc: f64) -> Self {
        NoiseLevels {
            gyro_baseline: [0.0; 3],
            accel_baseline: [0.0; 3],
            gyro_sigma: [sigma_rot; 3],
            accel_sigma: [sigma_acc; 3],
            gyro_white_sigma: [sigma_rot; 3],
            samples: 0,
        }
    }

    /// The paper's scalar sigma_rot: RMS of the per-axis standard deviations, rad/s.
    pub fn sigma_rot(&self) -> f64 {
        rms(&self.gyro_sigma)
    }

    /// The paper's scalar sigma_acc: RMS of the per-axis standard deviations, m/s^2.
    pub fn sigma_acc(&self) -> f64 {
        rms(&self.accel_sigma)
    }

    /// Gyro reading with the at-rest baseline removed.
    pub fn gyro_delta(&self, gyro: &[f64; 3]) -> Vector3<f64> {
        Vector3::from(*gyro) - Vector3::from(self.gyro_baseline)
    }

    /// Accelerometer reading with the at-rest baseline removed.
    pub fn accel_delta(&self, accel: &[f64; 3]) -> Vector3<f64> {
        Vector3::from(*accel) - Vector3::from(self.accel_baseline)
    }
}

fn rms(v: &[f64; 3]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / 3.0).sqrt()
}

/// Running mean and variance per axis (Welford), so the rest phase needs no sample buffer.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct NoiseMeter {
    n: u64,
    gyro: [Welford; 3],
    accel: [Welford; 3],
    /// Successive differences of the gyro, and its last sample.
    gyro_diff: [Welford; 3],
    last_gyro: Option<[f64; 3]>,
}

#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
struct Welford {
    mean: f64,
    m2: f64,
}

impl Welford {
    fn push(&mut self, n: u64, x: f64) {
        let d = x - self.mean;
        self.mean += d / n as f64;
        self.m2 += d * (x - self.mean);
    }

    fn sigma(&self, n: u64) -> f64 {
        if n < 2 {
            0.0
        } else {
            (self.m2 / (n - 1) as f64).sqrt()
        }
    }
}

impl NoiseMeter {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn push(&mut self, gyro: &[f64; 3], accel: &[f64; 3]) {
        self.n += 1;
        for a in 0..3 {
            self.gyro[a].push(self.n, gyro[a]);
            self.accel[a].push(self.n, accel[a]);
        }
        if let Some(last) = self.last_gyro {
            for a in 0..3 {
                self.gyro_diff[a].push(self.n - 1, gyro[a] - last[a]);
            }
        }
        self.last_gyro = Some(*gyro);
    }

    pub fn samples(&self) -> u64 {
        self.n
    }

    /// Current levels; sigmas are zero until two samples have arrived.
    pub fn levels(&self) -> NoiseLevels {
        NoiseLevels {
            gyro_baseline: std::array::from_fn(|a| self.gyro[a].mean),
            accel_baseline: std::array::from_fn(|a| self.accel[a].mean),
            gyro_sigma: std::array::from_fn(|a| self.gyro[a].sigma(self.n)),
            accel_sigma: std::array::from_fn(|a| self.accel[a].sigma(self.n)),
            gyro_white_sigma: std::array::from_fn(|a| {
                self.gyro_diff[a].sigma(self.n.saturating_sub(1)) / std::f64::consts::SQRT_2
            }),
            samples: self.n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn meter_recovers_mean_and_sigma() {
        let mut m = NoiseMeter::new();
        // Alternating +-1 around a baseline: sigma is exactly sqrt(n/(n-1)).
        for i in 0..1000 {
            let s = if i % 2 == 0 { 1.0 } else { -1.0 };
            m.push(&[0.1 + s, 0.0, 0.0], &[0.0, 0.0, -9.81 + 0.5 * s]);
        }
        let l = m.levels();
        assert!((l.gyro_baseline[0] - 0.1).abs() < 1e-12);
        assert!((l.accel_baseline[2] + 9.81).abs() < 1e-12);
        let expect = (1000.0_f64 / 999.0).sqrt();
        assert!((l.gyro_sigma[0] - expect).abs() < 1e-9);
        assert!((l.accel_sigma[2] - 0.5 * expect).abs() < 1e-9);
        assert_eq!(l.gyro_sigma[1], 0.0);
        assert!((l.sigma_rot() - expect / 3f64.sqrt()).abs() < 1e-9);
    }

    #[test]
    fn a_slow_rocking_is_not_white_noise() {
        let mut m = NoiseMeter::new();
        let mut x: u64 = 12345;
        for i in 0..400 {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let e = if (x >> 33) & 1 == 0 { 0.002 } else { -0.002 };
            let swell = 0.1 * (std::f64::consts::TAU * 0.15 * i as f64 * 0.005).sin();
            m.push(&[e + swell, e, 0.0], &[0.0, 0.0, -9.81]);
        }
        let l = m.levels();
        // The rocking is in the standard deviation, not in the white part.
        assert!(l.gyro_sigma[0] > 0.02, "{:?}", l.gyro_sigma);
        assert!(
            (l.gyro_white_sigma[0] - 0.002).abs() < 0.0005,
            "{:?}",
            l.gyro_white_sigma
        );
        assert!((l.gyro_white_sigma[1] - l.gyro_sigma[1]).abs() < 0.0003);
    }
}
