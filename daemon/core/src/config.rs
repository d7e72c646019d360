//! thrusterd.toml: every section optional, every key documented with its default, unknown keys
//! rejected with the file, line and key named.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use thruster_driver_kit::{parse_toml, LoadError, Range};
use thruster_protocol::services::{IpcConfig, IpcError, DEFAULT_ROOT_BASE};
use thruster_protocol::validate::limits::MAX_POSITION_M;

use crate::adaptation::identification::IdentificationConfig;
use crate::adaptation::monitor::MonitorConfig;
use crate::adaptation::refinement::RefinementConfig;
use crate::attitude::AttitudeConfig;
use crate::controller::ControllerConfig;
use crate::estimator::EstimatorConfig;
use crate::machine::{Geometry, MachineConfig, MachineSetup};
use crate::model::RigidBody;
use crate::supply::SupplyConfig;
use thruster_protocol::MAX_THRUSTERS;

/// The whole file.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DaemonConfig {
    pub ipc: IpcSection,
    pub runtime: RuntimeSection,
    pub telemetry: TelemetrySection,
    pub vehicle: VehicleSection,
    pub body: RigidBody,
    pub machine: MachineConfig,
    pub estimator: EstimatorConfig,
    pub controller: ControllerConfig,
    pub attitude: AttitudeConfig,
    pub monitor: MonitorConfig,
    pub identification: IdentificationConfig,
    pub refinement: RefinementConfig,
    pub supply: SupplyConfig,
    pub checkpoint: CheckpointSection,
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
    /// Not judged in lockstep, where no vehicle time passes while the driver is silent.
    pub imu_timeout_ms: u64,
    /// Publish status at least this often, wall clock (default 100); vehicle time in lockstep,
    /// where status goes out with the samples.
    pub status_period_ms: u64,
    /// Low-latency mode: poll for the next IMU sample for up to this long before blocking on
    /// the event (default 0 = always block). An event wake-up costs ~50 us on a small VM,
    /// polling ~2 us, at the price of a busy core.
    pub spin_us: u64,
    /// Load the saved model at start (default true).
    pub load_model: bool,
    /// After a crash while controlling or estimating (the resume marker in `state_dir` was
    /// left behind), hold attitude with the saved model as soon as the IMU is up (default
    /// true: a vehicle in the water must not drift). false: start idle whatever happened,
    /// e.g. on a bench or where an operator must confirm.
    pub resume_after_crash: bool,
    /// The driver runs in lockstep (default false): it waits for the answer to each sample
    /// before it steps (`thruster-sim run --lockstep`, the lab, the tests). Vehicle time then
    /// runs as fast as the daemon answers, so a solve's result could be late by vehicle time
    /// however fast the solver thread is: in lockstep the loop waits for a result due by a
    /// sample's time before it handles the sample (up to `lockstep_wait_ms`), and one seed
    /// gives one outcome under any load. In real time (false) it never waits: a late result is
    /// applied when it comes and counted. `thrusterd run --lockstep` sets it.
    pub lockstep: bool,
    /// In lockstep, the longest wait for a due solve, ms of wall time (default 1000, at most
    /// 600000). Keep it below the simulator's answer timeout (`[lockstep] timeout_ms`, 2000
    /// by default; a stepped simulator waits 600000), so it never steps past a waiting
    /// daemon. Past it the machine faults (neutral), saying so. The lab's stepped runs use
    /// 300000: a solve starved by a loaded machine must not change the result.
    pub lockstep_wait_ms: u64,
    /// Run the control thread (the one that answers IMU samples) at this SCHED_FIFO priority
    /// (default 0 = normal scheduling; 1-99). Under normal scheduling anything else on the
    /// computer (a build, the bridge, a logger) can hold the control thread off its core for
    /// milliseconds; a FIFO thread runs as soon as its sample comes. Only the control thread
    /// is raised: solves, saves and loads stay on normal threads. Needs root, CAP_SYS_NICE or
    /// an RLIMIT_RTPRIO of at least this (the shipped unit: `LimitRTPRIO=50`); refused, the
    /// daemon logs why and runs on at normal priority. Use it with `spin_us = 0`: a FIFO thread
    /// that spins holds its core, and the kernel leaves normal threads only 5 % of it.
    pub realtime_priority: u8,
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
            lockstep: false,
            lockstep_wait_ms: 1000,
            realtime_priority: 0,
        }
    }
}

/// `[telemetry]`: what the daemon publishes on the `telemetry` topic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TelemetrySection {
    /// Publish telemetry after every n-th accepted IMU sample (default 10: 20 Hz at a 200 Hz
    /// IMU, 100 Hz at 1 kHz; 1 = every sample; 0 = off; at most 10000). Publishing never
    /// waits for a reader (a full reader loses its oldest message), so the cost to the
    /// control loop is one copy into shared memory and one wake-up per message.
    pub every_n: u64,
}

impl Default for TelemetrySection {
    fn default() -> Self {
        TelemetrySection { every_n: 10 }
    }
}

/// The thrusters the vehicle starts with.
/// Checkpoints of the state machine on the `checkpoint` topic, where the replay of a
/// recording started late begins (docs/recording.md, "Checkpoints").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CheckpointSection {
    /// Publish checkpoints at all (default true). false: a recording that did not start with
    /// the daemon cannot be replayed.
    pub enabled: bool,
    /// One every `period_s` vehicle seconds (default 10; 0: only after model swaps), taken at
    /// the first sample after that where the state is small: no estimation under way and no
    /// refinement window open (their sample logs are megabytes). Also one after each model
    /// swap, with the same rule. 0-3600.
    pub period_s: f64,
}

impl Default for CheckpointSection {
    fn default() -> Self {
        CheckpointSection {
            enabled: true,
            period_s: 10.0,
        }
    }
}

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

/// A config file that cannot be used, with where and why: `file:line:col: key: must be in
/// [a, b], got x`, the form every binary of the project uses (thruster_driver_kit::load).
pub type ConfigError = LoadError;

impl DaemonConfig {
    /// Parse and check; `origin` names the file in errors, which give the line and column of
    /// the offending value and its key (and for a number the allowed range).
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let cfg: DaemonConfig = parse_toml(text, origin)?;
        cfg.validate(text, origin)?;
        Ok(cfg)
    }

    /// What `run` refuses beyond the values themselves, so `check-config` catches it too:
    /// a namespace and ipc root iceoryx2 cannot use (too long a socket path), a state
    /// directory that is not a directory, a pulse limit too short for the thruster count
    /// (which `--thrusters` may change after the file is read). `text` is the file's, to locate the key.
    pub fn check_runnable(&self, text: &str, origin: &str) -> Result<(), ConfigError> {
        // Every range again, with the command line applied: `thrusterd run --spin-us` and
        // the like set keys the file's check has already passed (u64::MAX started).
        self.validate(text, origin)?;
        let root = self
            .ipc
            .root
            .clone()
            .unwrap_or_else(|| PathBuf::from(DEFAULT_ROOT_BASE));
        if let Err(e) = IpcConfig::with_root_base(&self.ipc.namespace, &root) {
            // A relative root is the root's fault; a socket path too long for the pair is
            // named by the root, where the fix usually is.
            let key = match e {
                IpcError::InvalidNamespace { .. } if root.is_absolute() => "ipc.namespace",
                _ => "ipc.root",
            };
            return Err(LoadError::value(origin, text, key, e.to_string()));
        }
        let dir = &self.runtime.state_dir;
        if dir.symlink_metadata().is_ok() && !dir.is_dir() {
            return Err(LoadError::value(
                origin,
                text,
                "runtime.state_dir",
                format!("{} is not a directory", dir.display()),
            ));
        }
        // With the command line applied: `--thrusters` sets the count the plan is for.
        self.check_pulse_limit()
            .map_err(|why| LoadError::value(origin, text, "estimator.max_pulses", why))?;
        Ok(())
    }

    /// The dynamic method's pulse limit against its excitation for the thrusters in force: a limit
    /// that ends before the pulses can tell every thruster apart leaves a model the machine
    /// always refuses (`ExcitationPlan::confounded`; eight_vectored at 16 pulses was 0.71 off
    /// under a 0.02 bound before the machine refused it).
    fn check_pulse_limit(&self) -> Result<(), String> {
        use crate::estimator::{ExcitationPlan, Method};
        let e = &self.estimator;
        let n = self.thruster_count();
        if e.method != Method::Dynamic {
            return Ok(());
        }
        let plan = ExcitationPlan::new(e.excitation, n);
        let need = plan.spanned_at(1);
        if e.max_pulses < need {
            return Err(format!(
                "{} is below the {need} pulses the {} excitation needs to tell {n} thrusters apart",
                e.max_pulses,
                plan.kind().name()
            ));
        }
        Ok(())
    }

    fn validate(&self, text: &str, origin: &str) -> Result<(), ConfigError> {
        let out_of_range = |key: &str, range: Range, v: &dyn std::fmt::Display| {
            LoadError::out_of_range(origin, text, key, range, v)
        };
        for (key, v, range) in self.estimator.checks() {
            if !range.contains(v) {
                return Err(out_of_range(&format!("estimator.{key}"), range, &v));
            }
        }
        if let Some(p) = self.supply.power_law_exponent {
            if !SupplyConfig::EXPONENT_RANGE.contains(p) {
                return Err(out_of_range(
                    "supply.power_law_exponent",
                    SupplyConfig::EXPONENT_RANGE,
                    &p,
                ));
            }
            if self.supply.compensation != crate::supply::CompensationModel::None {
                return Err(LoadError::value(
                    origin,
                    text,
                    "supply.power_law_exponent",
                    "another make's curve has no voltage table: set supply.compensation = \"none\"",
                ));
            }
        }
        self.estimator
            .check_dof_priority()
            .map_err(|e| LoadError::value(origin, text, "estimator.dof_priority", e.why))?;
        let n = self.thruster_count();
        if !(1..=MAX_THRUSTERS).contains(&n) {
            let key = if self.vehicle.thruster.is_empty() {
                "vehicle.thrusters"
            } else {
                "vehicle.thruster"
            };
            return Err(out_of_range(
                key,
                Range::closed(1.0, MAX_THRUSTERS as f64),
                &n,
            ));
        }
        for (i, t) in self.vehicle.thruster.iter().enumerate() {
            // Within the protocol's reach, as the IMU's position: a position the model
            // bounds would refuse (a units slip, 1e9 m) is named here, not found at start as
            // "model rejected" with no starting model.
            let reach = Range::closed(-MAX_POSITION_M, MAX_POSITION_M);
            for (j, &v) in t.position_m.iter().enumerate() {
                if !reach.contains(v) {
                    let key = format!("vehicle.thruster[{i}].position_m[{j}]");
                    return Err(LoadError::value(
                        origin,
                        text,
                        &key,
                        format!("must be in {reach} m, got {v}"),
                    ));
                }
            }
            let d = t.direction;
            let norm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if !(norm.is_finite() && norm > 1e-6) {
                let key = format!("vehicle.thruster[{i}].direction");
                return Err(LoadError::value(
                    origin,
                    text,
                    &key,
                    format!("must be finite and non-zero, got {d:?}"),
                ));
            }
        }
        // TOML has `nan` and `inf`: every float the daemon computes with must be finite and in
        // its range, or a hand-edited file could put NaN into the controller (commands are
        // sanitised before the wire, but a bad file must be refused, not limped along with).
        // Ranges are checked in order, so a value another is compared with comes first: a NaN
        // is named where it is.
        let m = &self.machine;
        let b = &self.body;
        let c = &self.controller;
        let a = &self.attitude;
        let mut floats: Vec<(String, f64, Range)> = vec![
            ("machine.noise_s".into(), m.noise_s, Range::above(0.0)),
            (
                "machine.gyro_bias_rest_s".into(),
                m.gyro_bias_rest_s,
                Range::closed(0.0, 3600.0),
            ),
            (
                "checkpoint.period_s".into(),
                self.checkpoint.period_s,
                Range::closed(0.0, 3600.0),
            ),
            (
                "supply.reference_voltage_v".into(),
                self.supply.reference_voltage_v,
                SupplyConfig::REFERENCE_RANGE,
            ),
            (
                "supply.sag_prior_ohm".into(),
                self.supply.sag_prior_ohm,
                SupplyConfig::SAG_PRIOR_RANGE,
            ),
            (
                "machine.level_max_s".into(),
                m.level_max_s,
                Range::at_least(0.0),
            ),
            (
                "machine.level_tilt_deg".into(),
                m.level_tilt_deg,
                Range {
                    lo: 0.0,
                    hi: 90.0,
                    lo_open: true,
                    hi_open: true,
                },
            ),
            (
                "machine.level_hold_s".into(),
                m.level_hold_s,
                Range::at_least(0.0),
            ),
            ("machine.pulse_s".into(), m.pulse_s, Range::above(0.0)),
            (
                "machine.settle_min_s".into(),
                m.settle_min_s,
                Range::at_least(0.0),
            ),
            (
                "machine.settle_max_s".into(),
                m.settle_max_s,
                Range::at_least(m.settle_min_s),
            ),
            (
                "machine.max_swap_rel_err".into(),
                m.max_swap_rel_err,
                Range::above(0.0),
            ),
            (
                "machine.max_unexplained_rate_radps".into(),
                m.max_unexplained_rate_radps,
                Range::above(0.0),
            ),
            (
                "machine.max_lag_gap_over_bound".into(),
                m.max_lag_gap_over_bound,
                Range::at_least(0.0),
            ),
            (
                "machine.max_still_sway".into(),
                m.max_still_sway,
                Range::at_least(0.0),
            ),
            (
                "machine.max_rest_swing_radps".into(),
                m.max_rest_swing_radps,
                Range::at_least(0.0),
            ),
            (
                "machine.max_moving_water_tilt_deg".into(),
                m.max_moving_water_tilt_deg,
                Range::closed(0.0, 180.0),
            ),
            (
                "machine.deadband".into(),
                m.deadband,
                Range::from_below(0.0, 0.5),
            ),
            (
                "machine.solve_budget_s".into(),
                m.solve_budget_s,
                Range {
                    lo: 0.0,
                    hi: 1.0,
                    lo_open: true,
                    hi_open: false,
                },
            ),
            ("body.mass_kg".into(), b.mass_kg, Range::above(0.0)),
            (
                "body.max_thrust_n".into(),
                b.max_thrust_n,
                Range::above(0.0),
            ),
            (
                "machine.lost_hold_deg".into(),
                m.lost_hold_deg,
                Range {
                    lo: 0.0,
                    hi: 180.0,
                    lo_open: true,
                    hi_open: false,
                },
            ),
            (
                "machine.lost_hold_s".into(),
                m.lost_hold_s,
                Range::at_least(0.0),
            ),
            (
                "machine.settle_quiet_s".into(),
                m.settle_quiet_s,
                Range::at_least(0.0),
            ),
            (
                "machine.max_sample_gap_s".into(),
                m.max_sample_gap_s,
                Range::above(0.0),
            ),
            (
                "controller.kp_depth".into(),
                c.kp_depth,
                Range::at_least(0.0),
            ),
            (
                "controller.kd_depth".into(),
                c.kd_depth,
                Range::at_least(0.0),
            ),
            (
                "controller.ki_depth".into(),
                c.ki_depth,
                Range::at_least(0.0),
            ),
            (
                "controller.integral_limit".into(),
                c.integral_limit,
                Range::at_least(0.0),
            ),
            ("attitude.kp".into(), a.kp, Range::at_least(0.0)),
            ("attitude.ki".into(), a.ki, Range::at_least(0.0)),
            (
                "attitude.accel_trust_m_s2".into(),
                a.accel_trust_m_s2,
                Range::above(0.0),
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
                let range = if positive {
                    Range::above(0.0)
                } else {
                    Range::at_least(0.0)
                };
                floats.push((format!("{name}[{i}]"), v, range));
            }
        }
        for (key, v, range) in self.monitor.checks() {
            floats.push((key.into(), v, range));
        }
        for (key, v, range) in self.identification.checks() {
            floats.push((key.into(), v, range));
        }
        for (key, v, range) in self.refinement.checks() {
            floats.push((key.into(), v, range));
        }
        for (key, v, range) in floats {
            if !range.contains(v) {
                return Err(out_of_range(&key, range, &v));
            }
        }
        let r = &self.runtime;
        // Upper bounds keep every duration far from overflow in the event loop's arithmetic; a
        // longer IMU timeout would be no watchdog at all.
        for (key, v, lo, hi) in [
            ("runtime.imu_timeout_ms", r.imu_timeout_ms, 1, 60_000),
            ("runtime.status_period_ms", r.status_period_ms, 0, 60_000),
            ("runtime.spin_us", r.spin_us, 0, 1_000_000),
            ("runtime.lockstep_wait_ms", r.lockstep_wait_ms, 1, 600_000),
            (
                "runtime.realtime_priority",
                u64::from(r.realtime_priority),
                0,
                99,
            ),
            ("telemetry.every_n", self.telemetry.every_n, 0, 10_000),
        ] {
            if !(lo..=hi).contains(&v) {
                return Err(out_of_range(key, Range::closed(lo as f64, hi as f64), &v));
            }
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
            identification: self.identification.clone(),
            refinement: self.refinement.clone(),
            body: self.body.clone(),
            thrusters: self.thruster_count(),
            geometry,
            supply: self.supply.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_config_parses() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/thrusterd.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        let cfg = DaemonConfig::from_toml_str(&text, &path.display().to_string()).unwrap();
        assert_eq!(cfg.ipc.namespace, "thrusterd");
        // The file says "the values shown are the defaults": hold it to that (its [monitor]
        // thresholds once lagged behind the code's).
        assert_eq!(cfg, DaemonConfig::default());
    }

    #[test]
    fn an_unknown_choice_names_its_place_and_the_choices() {
        let e = DaemonConfig::from_toml_str(
            "[identification]\nat_limit_unannounced = \"maybe\"\n",
            "d.toml",
        )
        .unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("d.toml:2:"), "{msg}");
        assert!(msg.contains("maybe"), "{msg}");
        assert!(msg.contains("keep_old") && msg.contains("swap"), "{msg}");
        let ok = DaemonConfig::from_toml_str(
            "[identification]\nat_limit_unannounced = \"swap\"\n",
            "d.toml",
        )
        .unwrap();
        assert_eq!(
            ok.identification.at_limit_unannounced,
            crate::adaptation::identification::AtLimit::Swap
        );
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
        assert!(msg.starts_with("d.toml:3:1: "), "{msg}");
        assert!(msg.contains("pulse_len"), "{msg}");
        let e = DaemonConfig::from_toml_str("[estimator]\nk_sigma = -1\n", "d.toml").unwrap_err();
        assert_eq!(
            e.to_string(),
            "d.toml:2:11: estimator.k_sigma: must be in (0, inf), got -1"
        );
        let e = DaemonConfig::from_toml_str("[supply]\nreference_voltage_v = 24\n", "d.toml")
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "d.toml:2:23: supply.reference_voltage_v: must be in [10, 20], got 24"
        );
        let e = DaemonConfig::from_toml_str(
            "[supply]\nlinearize = true\npower_law_exponent = 1.5\n",
            "d.toml",
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "d.toml:3:22: supply.power_law_exponent: another make's curve has no voltage table: \
             set supply.compensation = \"none\""
        );
        let e = DaemonConfig::from_toml_str(
            "[supply]\ncompensation = \"none\"\npower_law_exponent = 4\n",
            "d.toml",
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "d.toml:3:22: supply.power_law_exponent: must be in [0.5, 3], got 4"
        );
        let e = DaemonConfig::from_toml_str("[supply]\ncompensation = \"linear\"\n", "d.toml")
            .unwrap_err();
        assert!(e.to_string().starts_with("d.toml:2:"), "{e}");
        let e =
            DaemonConfig::from_toml_str("[machine]\npulse_s = \"long\"\n", "d.toml").unwrap_err();
        assert!(e.to_string().starts_with("d.toml:2:"), "{e}");
        let e = DaemonConfig::from_toml_str("[vehicle]\nthrusters = 17\n", "d.toml").unwrap_err();
        assert_eq!(
            e.to_string(),
            "d.toml:2:13: vehicle.thrusters: must be in [1, 16], got 17"
        );
        // The example: no line and no range before.
        let e = DaemonConfig::from_toml_str("\n[machine]\npulse_s = -3\n", "d.toml").unwrap_err();
        assert_eq!(
            e.to_string(),
            "d.toml:3:11: machine.pulse_s: must be in (0, inf), got -3"
        );
    }

    #[test]
    fn check_runnable_refuses_what_run_refuses() {
        let text = "[ipc]\nnamespace = \"0123456789abcdefXYZ\"\n";
        // Parses (a namespace is a string), but iceoryx2 could not use it.
        let cfg = DaemonConfig::from_toml_str(text, "d.toml").unwrap();
        let e = cfg.check_runnable(text, "d.toml").unwrap_err().to_string();
        assert!(
            e.starts_with("d.toml:2:13: ipc.namespace: ") && e.contains("longer than 16"),
            "{e}"
        );
        let file = tempfile::NamedTempFile::new().unwrap();
        let text = format!("[runtime]\nstate_dir = \"{}\"\n", file.path().display());
        let cfg = DaemonConfig::from_toml_str(&text, "d.toml").unwrap();
        let e = cfg.check_runnable(&text, "d.toml").unwrap_err().to_string();
        assert!(
            e.starts_with("d.toml:2:13: runtime.state_dir: ") && e.contains("not a directory"),
            "{e}"
        );
        DaemonConfig::default().check_runnable("", "d").unwrap();
        // A pulse limit short of what tells the thrusters apart, for the count in force.
        let text = "[estimator]\nmax_pulses = 16\n[vehicle]\nthrusters = 8\n";
        let mut cfg = DaemonConfig::from_toml_str(text, "d.toml").unwrap();
        let e = cfg.check_runnable(text, "d.toml").unwrap_err();
        assert_eq!(
            e.to_string(),
            "d.toml:2:14: estimator.max_pulses: 16 is below the 29 pulses the doublet_pairs \
             excitation needs to tell 8 thrusters apart"
        );
        // Five thrusters (`--thrusters 5`): five Hadamard rows (20 pulses) tell them apart;
        // 16 pulses, four rows, do not.
        cfg.vehicle.thrusters = 5;
        let e = cfg.check_runnable(text, "d.toml").unwrap_err().to_string();
        assert!(e.contains("below the 17 pulses"), "{e}");
        cfg.estimator.max_pulses = 20;
        cfg.check_runnable(text, "d.toml").unwrap();
    }

    #[test]
    fn non_finite_and_negative_values_are_refused_with_the_key() {
        for (text, want) in [
            (
                "[machine]\nsettle_min_s = -inf\n",
                "d.toml:2:16: machine.settle_min_s: must be in [0, inf), got -inf",
            ),
            (
                "[machine]\nsettle_quiet_s = nan\n",
                "d.toml:2:18: machine.settle_quiet_s: must be in [0, inf), got NaN",
            ),
            (
                "[machine]\nlost_hold_deg = 0.0\n",
                "d.toml:2:17: machine.lost_hold_deg: must be in (0, 180], got 0",
            ),
            (
                "[machine]\nlost_hold_s = -1.0\n",
                "d.toml:2:15: machine.lost_hold_s: must be in [0, inf), got -1",
            ),
            (
                "[machine]\nmax_sample_gap_s = 0.0\n",
                "d.toml:2:20: machine.max_sample_gap_s: must be in (0, inf), got 0",
            ),
            (
                "[controller]\nkp_att = [1.0, nan, 1.0]\n",
                "d.toml:2:16: controller.kp_att[1]: must be in [0, inf), got NaN",
            ),
            (
                "[controller]\nki_depth = inf\n",
                "d.toml:2:12: controller.ki_depth: must be in [0, inf), got inf",
            ),
            (
                "[attitude]\nkp = -1.0\n",
                "d.toml:2:6: attitude.kp: must be in [0, inf), got -1",
            ),
            (
                "[body]\ninertia_kg_m2 = [0.1, 0.0, 0.1]\n",
                "d.toml:2:23: body.inertia_kg_m2[1]: must be in (0, inf), got 0",
            ),
            (
                "[body]\nadded_mass_kg = [1, 2, nan]\n",
                "d.toml:2:24: body.added_mass_kg[2]: must be in [0, inf), got NaN",
            ),
            (
                "[runtime]\nimu_timeout_ms = 9223372036854775807\n",
                "d.toml:2:18: runtime.imu_timeout_ms: must be in [1, 60000], got 9223372036854775807",
            ),
            (
                "[runtime]\nspin_us = 5000000\n",
                "d.toml:2:11: runtime.spin_us: must be in [0, 1000000], got 5000000",
            ),
            (
                "[telemetry]\nevery_n = 20000\n",
                "d.toml:2:11: telemetry.every_n: must be in [0, 10000], got 20000",
            ),
            (
                "[telemetry]\nevery_n = 10\nrate_hz = 20\n",
                "d.toml:3:1: unknown field `rate_hz`, expected `every_n`",
            ),
            (
                "[monitor]\nwindow_s = 0.01\n",
                "d.toml:2:12: monitor.window_s: must be in [0.1, inf), got 0.01",
            ),
            (
                "[[vehicle.thruster]]\nposition_m = [0, 0, 0]\ndirection = [0, 0, 0]\n",
                "d.toml:3:13: vehicle.thruster[0].direction: must be finite and non-zero, got [0.0, 0.0, 0.0]",
            ),
            (
                "[[vehicle.thruster]]\nposition_m = [1e9, 0, 0]\ndirection = [1, 0, 0]\n",
                "d.toml:2:15: vehicle.thruster[0].position_m[0]: must be in [-10, 10] m, got 1000000000",
            ),
            (
                "[[vehicle.thruster]]\nposition_m = [0, nan, 0]\ndirection = [1, 0, 0]\n",
                "d.toml:2:18: vehicle.thruster[0].position_m[1]: must be in [-10, 10] m, got NaN",
            ),
        ] {
            let e = DaemonConfig::from_toml_str(text, "d.toml").unwrap_err();
            assert_eq!(e.to_string(), want, "{text:?}");
        }
    }
}
