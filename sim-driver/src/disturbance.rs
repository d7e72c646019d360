//! Environmental disturbances: a constant water current, wave-like forcing (a sum of
//! sinusoids) and a tether's pull at its attachment point. All are off by default.

use nalgebra::{UnitQuaternion, Vector3, Vector6};
use serde::{Deserialize, Serialize};

use thruster_protocol::validate::limits::{MAX_DVL_SPEED, MAX_POSITION_M};

use crate::load::{symmetric, Checker, LoadError, Range};

/// Fastest water current per axis, m/s: the fastest tidal races. A vehicle drifting with it
/// stays within the DVL's range (the protocol's `MAX_DVL_SPEED`, 10 m/s).
pub const MAX_CURRENT_MPS: f64 = MAX_DVL_SPEED / 2.0;

/// Largest wave force or moment amplitude and tether pull per axis, N or N m (about a
/// tonne-force; the lab's strongest tether is 1000 N, its rough swell 20 N).
pub const MAX_FORCING: f64 = 1e4;

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

/// A tether pulling at a point of the vehicle (`[disturbance.tether]`): a force fixed in the
/// world that varies slowly (the cable's drag as the current and the slack change), applied
/// at `attach_m`, so it also turns the vehicle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TetherConfig {
    /// Attachment point, body frame from the CO, m. Default [-0.3, 0, 0] (the stern).
    #[serde(default = "default_attach")]
    pub attach_m: [f64; 3],
    /// Mean pull, NED, N (required).
    pub pull_ned_n: [f64; 3],
    /// Amplitude of the slow variation around the mean, NED, N. Default [0, 0, 0].
    #[serde(default)]
    pub vary_ned_n: [f64; 3],
    /// Period of the variation, s (> 0). Default 20.
    #[serde(default = "default_tether_period")]
    pub period_s: f64,
}

fn default_attach() -> [f64; 3] {
    [-0.3, 0.0, 0.0]
}

fn default_tether_period() -> f64 {
    20.0
}

/// Named water conditions (issue 32), the lab's `--water` presets:
/// - `still`: no current, no waves;
/// - `current`: a 0.3 m/s current from the south (NED +x);
/// - `moderate`: that current and a 0.15 Hz swell pushing 10 N (surge and heave, 7.1 N each)
///   and turning 1 N m (roll and pitch, 0.71 N m each);
/// - `rough`: a 0.5 m/s current and the same swell at 20 N / 2 N m.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum WaterPreset {
    #[default]
    Still,
    Current,
    Moderate,
    Rough,
}

impl WaterPreset {
    pub fn name(self) -> &'static str {
        match self {
            WaterPreset::Still => "still",
            WaterPreset::Current => "current",
            WaterPreset::Moderate => "moderate",
            WaterPreset::Rough => "rough",
        }
    }

    /// The disturbance of this preset.
    pub fn disturbance(self) -> DisturbanceConfig {
        let swell = |force_n: f64, torque_nm: f64| WaveComponent {
            frequency_hz: 0.15,
            phase_rad: 0.0,
            force_ned_n: [force_n / 2f64.sqrt(), 0.0, force_n / 2f64.sqrt()],
            torque_body_nm: [torque_nm / 2f64.sqrt(), torque_nm / 2f64.sqrt(), 0.0],
        };
        let (current, waves) = match self {
            WaterPreset::Still => (0.0, vec![]),
            WaterPreset::Current => (0.3, vec![]),
            WaterPreset::Moderate => (0.3, vec![swell(10.0, 1.0)]),
            WaterPreset::Rough => (0.5, vec![swell(20.0, 2.0)]),
        };
        DisturbanceConfig {
            current_ned_mps: [current, 0.0, 0.0],
            waves,
            tether: None,
        }
    }
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
    /// A tether's pull (`[disturbance.tether]`). Default none.
    pub tether: Option<TetherConfig>,
}

impl DisturbanceConfig {
    /// True when there is neither current nor forcing.
    pub fn is_off(&self) -> bool {
        self.current_ned_mps == [0.0; 3] && !self.has_forcing()
    }

    /// True when waves or a tether push the vehicle.
    pub fn has_forcing(&self) -> bool {
        !self.waves.is_empty() || self.tether.is_some()
    }

    /// Checks ranges; `origin` names the source in errors.
    pub fn validate(&self, origin: &str) -> Result<(), LoadError> {
        self.check(&Checker::new(origin, ""), "")
    }

    /// Checks ranges, locating a bad value in `c.text`; `prefix` is the path of the table
    /// holding `[disturbance]` (`"sim."` in thruster-sim's config file). The bounds: a
    /// current of at most [`MAX_CURRENT_MPS`] per axis, forces and moments of at most
    /// [`MAX_FORCING`] (N, N m), periods of 0.1 s (a wave) to a day (a tether), attachment
    /// within the protocol's `MAX_POSITION_M`.
    pub(crate) fn check(&self, c: &Checker, prefix: &str) -> Result<(), LoadError> {
        let key = |k: &str| format!("{prefix}disturbance.{k}");
        let forcing = symmetric(MAX_FORCING);
        c.each(
            &key("current_ned_mps"),
            &self.current_ned_mps,
            symmetric(MAX_CURRENT_MPS),
        )?;
        for (i, w) in self.waves.iter().enumerate() {
            let key = |k: &str| key(&format!("wave[{i}].{k}"));
            c.range(
                &key("frequency_hz"),
                w.frequency_hz,
                Range::above_to(0.0, 10.0),
            )?;
            c.range(&key("phase_rad"), w.phase_rad, symmetric(1e3))?;
            c.each(&key("force_ned_n"), &w.force_ned_n, forcing)?;
            c.each(&key("torque_body_nm"), &w.torque_body_nm, forcing)?;
        }
        if let Some(t) = &self.tether {
            let key = |k: &str| key(&format!("tether.{k}"));
            c.each(&key("attach_m"), &t.attach_m, symmetric(MAX_POSITION_M))?;
            c.each(&key("pull_ned_n"), &t.pull_ned_n, forcing)?;
            c.each(&key("vary_ned_n"), &t.vary_ned_n, forcing)?;
            c.range(&key("period_s"), t.period_s, Range::closed(0.1, 86_400.0))?;
        }
        Ok(())
    }

    /// The current, NED, m/s.
    pub fn current_ned(&self) -> Vector3<f64> {
        Vector3::from(self.current_ned_mps)
    }

    /// Wave and tether generalised force at time `t_s` (s) for `attitude`: body frame, Fossen
    /// order `[X Y Z K M N]`, N and N m.
    pub fn forcing(&self, t_s: f64, attitude: &UnitQuaternion<f64>) -> Vector6<f64> {
        let mut f_ned = Vector3::zeros();
        let mut m_body = Vector3::zeros();
        for w in &self.waves {
            let s = (std::f64::consts::TAU * w.frequency_hz * t_s + w.phase_rad).sin();
            f_ned += Vector3::from(w.force_ned_n) * s;
            m_body += Vector3::from(w.torque_body_nm) * s;
        }
        let mut f = attitude.inverse_transform_vector(&f_ned);
        if let Some(t) = &self.tether {
            let s = (std::f64::consts::TAU * t_s / t.period_s).sin();
            let pull_ned = Vector3::from(t.pull_ned_n) + Vector3::from(t.vary_ned_n) * s;
            let pull = attitude.inverse_transform_vector(&pull_ned);
            f += pull;
            m_body += Vector3::from(t.attach_m).cross(&pull);
        }
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
            d.forcing(1.0, &UnitQuaternion::identity()),
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
            tether: None,
        };
        d.validate("d").expect("valid");
        let f = d.forcing(1.0, &UnitQuaternion::identity());
        assert!((f[0] - 2.0).abs() < 1e-12 && (f[5] - 0.5).abs() < 1e-12);
        // NED force seen from a vehicle heading east lands on body -y.
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let f = d.forcing(1.0, &q);
        assert!((f[1] + 2.0).abs() < 1e-12);
    }

    #[test]
    fn a_tether_pulls_at_its_attachment_and_turns_the_vehicle() {
        let d = DisturbanceConfig {
            tether: Some(TetherConfig {
                attach_m: [-0.3, 0.0, 0.0],
                pull_ned_n: [0.0, 0.0, 5.0],
                vary_ned_n: [0.0, 0.0, 2.0],
                period_s: 20.0,
            }),
            ..DisturbanceConfig::default()
        };
        d.validate("d").expect("valid");
        assert!(!d.is_off());
        // At t = 5 s the variation peaks: 7 N down at the stern pitches the nose up.
        let f = d.forcing(5.0, &UnitQuaternion::identity());
        assert!((f[2] - 7.0).abs() < 1e-9, "{f}");
        assert!((f[4] - 0.3 * 7.0).abs() < 1e-9, "{f}");
        assert!(f[3].abs() < 1e-12 && f[5].abs() < 1e-12, "{f}");
        let bad = DisturbanceConfig {
            tether: Some(TetherConfig {
                period_s: 0.0,
                ..d.tether.clone().unwrap()
            }),
            ..DisturbanceConfig::default()
        };
        let e = bad.validate("f.toml").unwrap_err().to_string();
        assert!(e.contains("disturbance.tether.period_s"), "{e}");
    }
}
