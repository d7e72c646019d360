//! A Doppler velocity log: the body velocity over ground at a few Hz with white noise, from a
//! seeded RNG stream of its own (so turning it on does not change the IMU's noise).

use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use thruster_protocol::validate::limits::MAX_DVL_SPEED;

use crate::load::{Checker, LoadError, Range};

/// DVL settings (`[sensors.dvl]`); absent: the vehicle has no DVL.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DvlConfig {
    /// Output rate, Hz, in (0, 50]. Default 5 (a small-vehicle DVL).
    pub rate_hz: f64,
    /// White noise per axis, m/s, >= 0. Default 0.01.
    pub std_mps: f64,
}

impl Default for DvlConfig {
    fn default() -> Self {
        DvlConfig {
            rate_hz: 5.0,
            std_mps: 0.01,
        }
    }
}

impl DvlConfig {
    pub fn validate(&self, origin: &str) -> Result<(), LoadError> {
        self.check(&Checker::new(origin, ""), "")
    }

    /// Checks ranges, locating a bad value in `c.text`; `prefix` is the path of the table
    /// holding `[dvl]` (`"sensors."`). Noise within the protocol's `MAX_DVL_SPEED`.
    pub(crate) fn check(&self, c: &Checker, prefix: &str) -> Result<(), LoadError> {
        c.range(
            &format!("{prefix}dvl.rate_hz"),
            self.rate_hz,
            Range::above_to(0.0, 50.0),
        )?;
        c.range(
            &format!("{prefix}dvl.std_mps"),
            self.std_mps,
            Range::closed(0.0, MAX_DVL_SPEED),
        )
    }
}

/// RNG stream of the DVL (the IMU uses stream 1).
const DVL_STREAM: u64 = 2;

/// The instrument with its noise state and schedule.
#[derive(Debug, Clone)]
pub struct Dvl {
    config: DvlConfig,
    rng: ChaCha8Rng,
    next_ns: u64,
}

impl Dvl {
    /// `config` must be validated.
    pub fn new(config: DvlConfig, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(DVL_STREAM);
        Dvl {
            config,
            rng,
            next_ns: 0,
        }
    }

    /// A measurement of `velocity` (body, m/s) when one is due at `t_ns`, else None.
    pub fn measure(&mut self, t_ns: u64, velocity: &Vector3<f64>) -> Option<Vector3<f64>> {
        if t_ns < self.next_ns {
            return None;
        }
        let period = (1e9 / self.config.rate_hz).round() as u64;
        self.next_ns = t_ns + period.max(1);
        let std = self.config.std_mps;
        let mut noise = || std * self.rng.sample::<f64, _>(StandardNormal);
        Some(velocity + Vector3::new(noise(), noise(), noise()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn measures_at_its_rate_around_the_truth() {
        let mut d = Dvl::new(
            DvlConfig {
                rate_hz: 5.0,
                std_mps: 0.01,
            },
            3,
        );
        let v = Vector3::new(0.3, -0.1, 0.05);
        let mut got = Vec::new();
        for k in 0..=1000u64 {
            // 1 kHz for 1 s.
            if let Some(m) = d.measure(k * 1_000_000, &v) {
                got.push(m);
            }
        }
        assert_eq!(got.len(), 6, "t = 0, 0.2, ..., 1.0 s");
        for m in &got {
            assert!((m - v).norm() < 0.06, "{m}");
        }
        assert!(got.iter().any(|m| *m != v), "noise is applied");
    }

    #[test]
    fn bad_settings_are_named() {
        let e = DvlConfig {
            rate_hz: 0.0,
            std_mps: 0.01,
        }
        .validate("sim.toml")
        .unwrap_err();
        assert!(e.to_string().contains("dvl.rate_hz"), "{e}");
    }
}
