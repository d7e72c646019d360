//! thrusterd.toml: every section optional, every key documented with its default, unknown keys
//! rejected with the file, line and key named.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::attitude::AttitudeConfig;
use crate::controller::ControllerConfig;
use crate::estimator::EstimatorConfig;
use crate::machine::{Geometry, MachineConfig, MachineSetup, MAX_THRUSTERS};
use crate::model::RigidBody;
use crate::monitor::MonitorConfig;

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
    pub monitor: MonitorConfig,
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
    /// After a crash while controlling or estimating (the session marker in `state_dir` was
    /// left behind), hold attitude with the saved model as soon as the IMU is up (default
    /// true: a vehicle in the water must not drift). false: start idle whatever happened,
    /// e.g. on a bench or where an operator must confirm.
    pub resume_after_crash: bool,
}

impl Default for RuntimeSection {
    fn default() -> Self {
        RuntimeSection {
            state_dir: PathBuf::from("/var/lib/thrusterd"),
            imu_timeout_ms: 100,
            status_period_ms: 100,
            spin_us: 0,
            load_model: true,
            resume_after_crash: true,
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
            ("machine.level_max_s", m.level_max_s, m.level_max_s >= 0.0),
            (
                "machine.level_tilt_deg",
                m.level_tilt_deg,
                m.level_tilt_deg > 0.0 && m.level_tilt_deg < 90.0,
            ),
            (
                "machine.level_hold_s",
                m.level_hold_s,
                m.level_hold_s >= 0.0,
            ),
            ("machine.pulse_s", m.pulse_s, m.pulse_s > 0.0),
            // Before settle_max_s, which is compared with it: a NaN here is named here.
            (
                "machine.settle_min_s",
                m.settle_min_s,
                m.settle_min_s >= 0.0,
            ),
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
        // TOML has `nan` and `inf`: every float the daemon computes with must be finite and in
        // its range, or a hand-edited file could put NaN into the controller (commands are
        // sanitised before the wire, but a bad file must be refused, not limped along with).
        let b = &self.body;
        let c = &self.controller;
        let a = &self.attitude;
        let mut floats: Vec<(String, f64, bool)> = vec![
            (
                "machine.settle_quiet_s".into(),
                m.settle_quiet_s,
                m.settle_quiet_s >= 0.0,
            ),
            (
                "machine.max_sample_gap_s".into(),
                m.max_sample_gap_s,
                m.max_sample_gap_s > 0.0,
            ),
            ("controller.kp_depth".into(), c.kp_depth, c.kp_depth >= 0.0),
            ("controller.kd_depth".into(), c.kd_depth, c.kd_depth >= 0.0),
            ("controller.ki_depth".into(), c.ki_depth, c.ki_depth >= 0.0),
            (
                "controller.integral_limit".into(),
                c.integral_limit,
                c.integral_limit >= 0.0,
            ),
            ("attitude.kp".into(), a.kp, a.kp >= 0.0),
            ("attitude.ki".into(), a.ki, a.ki >= 0.0),
            (
                "attitude.accel_trust_m_s2".into(),
                a.accel_trust_m_s2,
                a.accel_trust_m_s2 > 0.0,
            ),
        ];
        for (name, values, positive) in [
            ("body.inertia_kg_m2", b.inertia_kg_m2, true),
            ("body.added_mass_kg", b.added_mass_kg, false),
            ("body.added_inertia_kg_m2", b.added_inertia_kg_m2, false),
            ("controller.kp_att", c.kp_att, false),
            ("controller.kd_att", c.kd_att, false),
            ("controller.ki_att", c.ki_att, false),
        ] {
            for (i, v) in values.into_iter().enumerate() {
                let ok = if positive { v > 0.0 } else { v >= 0.0 };
                floats.push((format!("{name}[{i}]"), v, ok));
            }
        }
        for (key, v, ok) in self.monitor.checks() {
            floats.push((key.into(), v, ok));
        }
        for (key, v, ok) in floats {
            if !(v.is_finite() && ok) {
                return Err(invalid(
                    &key,
                    v.to_string(),
                    "must be finite and not negative (see config/thrusterd.toml)",
                ));
            }
        }
        let r = &self.runtime;
        // Upper bounds keep every duration far from overflow in the event loop's arithmetic; a
        // longer IMU timeout would be no watchdog at all.
        for (key, v, max) in [
            ("runtime.imu_timeout_ms", r.imu_timeout_ms, 60_000),
            ("runtime.status_period_ms", r.status_period_ms, 60_000),
            ("runtime.spin_us", r.spin_us, 1_000_000),
        ] {
            if v > max {
                return Err(invalid(key, v.to_string(), &format!("must be <= {max}")));
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
            monitor: self.monitor.clone(),
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
        // The file says "the values shown are the defaults": hold it to that (its [monitor]
        // thresholds once lagged behind the code's).
        assert_eq!(cfg, DaemonConfig::default());
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

    #[test]
    fn non_finite_and_negative_values_are_refused_with_the_key() {
        for (text, key) in [
            (
                "[machine]\nsettle_min_s = -inf\n",
                "machine.settle_min_s = -inf",
            ),
            (
                "[machine]\nsettle_quiet_s = nan\n",
                "machine.settle_quiet_s = NaN",
            ),
            (
                "[machine]\nmax_sample_gap_s = 0.0\n",
                "machine.max_sample_gap_s = 0",
            ),
            (
                "[controller]\nkp_att = [1.0, nan, 1.0]\n",
                "controller.kp_att[1] = NaN",
            ),
            (
                "[controller]\nki_depth = inf\n",
                "controller.ki_depth = inf",
            ),
            ("[attitude]\nkp = -1.0\n", "attitude.kp = -1"),
            (
                "[body]\ninertia_kg_m2 = [0.1, 0.0, 0.1]\n",
                "body.inertia_kg_m2[1] = 0",
            ),
            (
                "[body]\nadded_mass_kg = [1, 2, nan]\n",
                "body.added_mass_kg[2] = NaN",
            ),
            (
                "[runtime]\nimu_timeout_ms = 9223372036854775807\n",
                "runtime.imu_timeout_ms",
            ),
            (
                "[runtime]\nspin_us = 5000000\n",
                "runtime.spin_us = 5000000",
            ),
        ] {
            let e = DaemonConfig::from_toml_str(text, "d.toml").unwrap_err();
            let msg = e.to_string();
            assert!(
                msg.starts_with("d.toml: ") && msg.contains(key),
                "{text:?}: {msg}"
            );
        }
    }
}
