//! thrusterd.toml: every section optional, every key documented with its default, unknown keys
//! rejected with the file, line and key named.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::attitude::AttitudeConfig;
use crate::controller::ControllerConfig;
use crate::estimator::EstimatorConfig;
use crate::machine::{Geometry, MachineConfig, MachineSetup, MAX_THRUSTERS};
use crate::model::RigidBody;

/// The whole file.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DaemonConfig {
    pub ipc: IpcSection,
    pub runtime: RuntimeSection,
    pub vehicle: VehicleSection,
    pub body: RigidBody,
    pub machine: MachineConfig,
    pub estimator: EstimatorConfig,
    pub controller: ControllerConfig,
    pub attitude: AttitudeConfig,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IpcSection {
    /// iceoryx2 namespace shared with the drivers and thrusterctl (default "thrusterd";
    /// 1-16 characters of A-Z a-z 0-9 -).
    pub namespace: String,
    /// Folder for iceoryx2's sockets and service files (default: iceoryx2's, under /tmp).
    /// Under systemd with PrivateTmp, use a shared folder such as /run/thrusterd.
    pub root: Option<PathBuf>,
}

impl Default for IpcSection {
    fn default() -> Self {
        IpcSection {
            namespace: "thrusterd".into(),
            root: None,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RuntimeSection {
    /// Where the current model is saved and loaded from (default "/var/lib/thrusterd";
    /// systemd's StateDirectory).
    pub state_dir: PathBuf,
    /// No IMU sample for this long is a sensor dropout: neutral thrust and Fault (default 100).
    pub imu_timeout_ms: u64,
    /// Publish status at least this often, wall clock (default 100).
    pub status_period_ms: u64,
    /// Low-latency mode: poll for the next IMU sample for up to this long before blocking on
    /// the event (default 0 = always block). An event wake-up costs ~50 us on a small VM,
    /// polling ~2 us, at the price of a busy core.
    pub spin_us: u64,
    /// Load the saved model at start (default true).
    pub load_model: bool,
}

impl Default for RuntimeSection {
    fn default() -> Self {
        RuntimeSection {
            state_dir: PathBuf::from("/var/lib/thrusterd"),
            imu_timeout_ms: 100,
            status_period_ms: 100,
            spin_us: 0,
            load_model: true,
        }
    }
}

/// The thrusters the vehicle starts with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VehicleSection {
    /// Number of thrusters (default 5; 1-16). Ignored when thrusters are declared below.
    pub thrusters: usize,
    /// Declared layout (optional): `[[vehicle.thruster]]` with `position_m` (from the centre of
    /// mass, body frame x fwd, y stbd, z down) and `direction` (thrust direction). With it the
    /// daemon starts with the nominal model and can check directions.
    pub thruster: Vec<ThrusterDecl>,
}

impl Default for VehicleSection {
    fn default() -> Self {
        VehicleSection {
            thrusters: 5,
            thruster: Vec::new(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThrusterDecl {
    pub position_m: [f64; 3],
    pub direction: [f64; 3],
}

/// A config file that cannot be used, with where and why.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{path}: cannot read: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Parse { path: String, message: String },
    #[error("{path}: {key} = {value}: {why}")]
    Invalid {
        path: String,
        key: String,
        value: String,
        why: String,
    },
}

impl DaemonConfig {
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Parse and check; `origin` names the file in errors. toml's own messages carry the line,
    /// column and offending key.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let cfg: DaemonConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: origin.to_string(),
            message: e.to_string().trim_end().to_string(),
        })?;
        cfg.validate(origin)?;
        Ok(cfg)
    }

    fn validate(&self, origin: &str) -> Result<(), ConfigError> {
        let invalid = |key: &str, value: String, why: &str| ConfigError::Invalid {
            path: origin.to_string(),
            key: key.to_string(),
            value,
            why: why.to_string(),
        };
        self.estimator
            .validate()
            .map_err(|e| invalid(&format!("estimator.{}", e.key), e.value, e.why))?;
        let n = self.thruster_count();
        if !(1..=MAX_THRUSTERS).contains(&n) {
            return Err(invalid("vehicle.thrusters", n.to_string(), "must be 1..16"));
        }
        for (i, t) in self.vehicle.thruster.iter().enumerate() {
            let d = t.direction;
            let norm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if !(norm.is_finite() && norm > 1e-6 && t.position_m.iter().all(|v| v.is_finite())) {
                return Err(invalid(
                    &format!("vehicle.thruster[{i}]"),
                    format!("{t:?}"),
                    "position must be finite and direction non-zero",
                ));
            }
        }
        let m = &self.machine;
        for (key, v, ok) in [
            ("machine.noise_s", m.noise_s, m.noise_s > 0.0),
            ("machine.pulse_s", m.pulse_s, m.pulse_s > 0.0),
            (
                "machine.settle_max_s",
                m.settle_max_s,
                m.settle_max_s >= m.settle_min_s,
            ),
            (
                "machine.max_swap_rel_err",
                m.max_swap_rel_err,
                m.max_swap_rel_err > 0.0,
            ),
            (
                "machine.deadband",
                m.deadband,
                (0.0..0.5).contains(&m.deadband),
            ),
            ("body.mass_kg", self.body.mass_kg, self.body.mass_kg > 0.0),
            (
                "body.max_thrust_n",
                self.body.max_thrust_n,
                self.body.max_thrust_n > 0.0,
            ),
        ] {
            if !(v.is_finite() && ok) {
                return Err(invalid(
                    key,
                    v.to_string(),
                    "out of range (see config/thrusterd.toml)",
                ));
            }
        }
        if self.runtime.imu_timeout_ms == 0 {
            return Err(invalid("runtime.imu_timeout_ms", "0".into(), "must be > 0"));
        }
        Ok(())
    }

    pub fn thruster_count(&self) -> usize {
        if self.vehicle.thruster.is_empty() {
            self.vehicle.thrusters
        } else {
            self.vehicle.thruster.len()
        }
    }

    /// What the state machine is built from.
    pub fn machine_setup(&self) -> MachineSetup {
        let geometry = (!self.vehicle.thruster.is_empty()).then(|| Geometry {
            positions: self.vehicle.thruster.iter().map(|t| t.position_m).collect(),
            directions: self.vehicle.thruster.iter().map(|t| t.direction).collect(),
        });
        MachineSetup {
            machine: self.machine.clone(),
            estimator: self.estimator.clone(),
            controller: self.controller.clone(),
            attitude: self.attitude.clone(),
            body: self.body.clone(),
            thrusters: self.thruster_count(),
            geometry,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_config_parses() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/thrusterd.toml");
        let cfg = DaemonConfig::load(&path).unwrap();
        assert_eq!(cfg.ipc.namespace, "thrusterd");
    }

    #[test]
    fn empty_file_is_all_defaults() {
        let cfg = DaemonConfig::from_toml_str("", "x.toml").unwrap();
        assert_eq!(cfg, DaemonConfig::default());
    }

    #[test]
    fn errors_name_file_line_and_key() {
        let e = DaemonConfig::from_toml_str("[machine]\npulse_s = 0.1\npulse_len = 2\n", "d.toml")
            .unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("d.toml: "), "{msg}");
        assert!(msg.contains("line 3") && msg.contains("pulse_len"), "{msg}");
        let e = DaemonConfig::from_toml_str("[estimator]\nk_sigma = -1\n", "d.toml").unwrap_err();
        assert!(e.to_string().contains("estimator.k_sigma = -1"), "{e}");
        let e =
            DaemonConfig::from_toml_str("[machine]\npulse_s = \"long\"\n", "d.toml").unwrap_err();
        assert!(e.to_string().contains("line 2"), "{e}");
        let e = DaemonConfig::from_toml_str("[vehicle]\nthrusters = 17\n", "d.toml").unwrap_err();
        assert!(e.to_string().contains("vehicle.thrusters = 17"), "{e}");
    }
}
