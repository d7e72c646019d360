//! Environmental disturbances: a constant water current and wave-like forcing (a sum of
//! sinusoids). Both are off by default.

use nalgebra::{UnitQuaternion, Vector3, Vector6};
use serde::{Deserialize, Serialize};

use crate::load::{check_finite, LoadError};

/// One sinusoidal forcing component: `amplitude * sin(2 pi f t + phase)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WaveComponent {
    /// Frequency, Hz (> 0). Ocean swell is roughly 0.05-0.3 Hz.
    pub frequency_hz: f64,
    /// Phase at t = 0, rad. Default 0.
    #[serde(default)]
    pub phase_rad: f64,
    /// Force amplitude in NED (fixed in the world, like a wave orbit), N. Default 0.
    #[serde(default)]
    pub force_ned_n: [f64; 3],
    /// Moment amplitude about the body axes, N m. Default 0.
    #[serde(default)]
    pub torque_body_nm: [f64; 3],
}

/// Disturbance settings (`[disturbance]` table).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DisturbanceConfig {
    /// Constant, irrotational water current in NED, m/s. Default [0, 0, 0].
    pub current_ned_mps: [f64; 3],
    /// Wave forcing components (`[[disturbance.wave]]`). Default none.
    #[serde(rename = "wave")]
    pub waves: Vec<WaveComponent>,
}

impl DisturbanceConfig {
    /// True when there is neither current nor wave forcing.
    pub fn is_off(&self) -> bool {
        self.current_ned_mps == [0.0; 3] && self.waves.is_empty()
    }

    /// Checks ranges; `origin` names the source in errors.
    pub fn validate(&self, origin: &str) -> Result<(), LoadError> {
        check_finite(origin, "disturbance.current_ned_mps", &self.current_ned_mps)?;
        for (i, w) in self.waves.iter().enumerate() {
            let key = format!("disturbance.wave[{i}]");
            if !(w.frequency_hz.is_finite() && w.frequency_hz > 0.0) {
                return Err(LoadError::invalid(
                    origin,
                    format!("{key}.frequency_hz"),
                    "must be > 0",
                ));
            }
            check_finite(origin, &format!("{key}.phase_rad"), &[w.phase_rad])?;
            check_finite(origin, &format!("{key}.force_ned_n"), &w.force_ned_n)?;
            check_finite(origin, &format!("{key}.torque_body_nm"), &w.torque_body_nm)?;
        }
        Ok(())
    }

    /// The current, NED, m/s.
    pub fn current_ned(&self) -> Vector3<f64> {
        Vector3::from(self.current_ned_mps)
    }

    /// Wave generalised force at time `t_s` (s) for `attitude`: body frame, Fossen order
    /// `[X Y Z K M N]`, N and N m.
    pub fn wave_force(&self, t_s: f64, attitude: &UnitQuaternion<f64>) -> Vector6<f64> {
        let mut f_ned = Vector3::zeros();
        let mut m_body = Vector3::zeros();
        for w in &self.waves {
            let s = (std::f64::consts::TAU * w.frequency_hz * t_s + w.phase_rad).sin();
            f_ned += Vector3::from(w.force_ned_n) * s;
            m_body += Vector3::from(w.torque_body_nm) * s;
        }
        let f = attitude.inverse_transform_vector(&f_ned);
        Vector6::new(f.x, f.y, f.z, m_body.x, m_body.y, m_body.z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn off_by_default_and_sinusoidal() {
        let d = DisturbanceConfig::default();
        assert!(d.is_off());
        assert_eq!(
            d.wave_force(1.0, &UnitQuaternion::identity()),
            Vector6::zeros()
        );
        let d = DisturbanceConfig {
            current_ned_mps: [0.0; 3],
            waves: vec![WaveComponent {
                frequency_hz: 0.25,
                phase_rad: 0.0,
                force_ned_n: [2.0, 0.0, 0.0],
                torque_body_nm: [0.0, 0.0, 0.5],
            }],
        };
        d.validate("d").expect("valid");
        let f = d.wave_force(1.0, &UnitQuaternion::identity());
        assert!((f[0] - 2.0).abs() < 1e-12 && (f[5] - 0.5).abs() < 1e-12);
        // NED force seen from a vehicle heading east lands on body -y.
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let f = d.wave_force(1.0, &q);
        assert!((f[1] + 2.0).abs() < 1e-12);
    }
}
