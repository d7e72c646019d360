//! JSON output. These structs are the stable interface scripts rely on: fields are named
//! here, not derived from the wire structs, so a protocol change cannot silently rename
//! or drop a key. Non-finite numbers become `null`.

use serde::Serialize;
use thruster_protocol::{
    DaemonState, Dof, DriverStatusMsg, ModelMsg, StatusMsg, TelemetryMsg, DOF_COUNT, MAX_THRUSTERS,
};

/// One status message.
#[derive(Serialize, Debug, PartialEq)]
pub struct StatusJson {
    pub seq: u64,
    /// DaemonState name ("Idle", "MeasureNoise", "Pulse", ...).
    pub state: String,
    /// 0-based index of the current pulse.
    pub pulse: u32,
    pub pulses_planned: u32,
    pub error_bound: Option<f64>,
    pub power: Option<f64>,
    pub sigma_rot: Option<f64>,
    pub sigma_acc: Option<f64>,
    pub samples: u64,
    pub samples_missed: u64,
    pub rejected_nonfinite: u64,
    pub rejected_range: u64,
    pub rejected_time: u64,
    pub rejected_count: u64,
    pub rejected_other: u64,
    /// Operator requests refused (invalid, wrong state or failed).
    pub requests_refused: u32,
    pub model_version: u64,
    pub imu_rate_hz: Option<f64>,
    pub vehicle_time_ns: u64,
    pub text: String,
    /// The supply voltage the daemon last heard, V; null when none.
    pub supply_voltage_v: Option<f64>,
    /// "Off", "NoReading" or "Active": whether commands are referred to the reference voltage.
    pub supply_compensation: String,
}

impl From<&StatusMsg> for StatusJson {
    fn from(s: &StatusMsg) -> Self {
        Self {
            seq: s.seq,
            state: state_name(s.state),
            pulse: s.pulse,
            pulses_planned: s.pulses_planned,
            error_bound: finite(s.error_bound),
            power: finite(s.power),
            sigma_rot: finite(s.sigma_rot),
            sigma_acc: finite(s.sigma_acc),
            samples: s.samples,
            samples_missed: s.samples_missed,
            rejected_nonfinite: s.rejected_nonfinite,
            rejected_range: s.rejected_range,
            rejected_time: s.rejected_time,
            rejected_count: s.rejected_count,
            rejected_other: s.rejected_other,
            requests_refused: s.requests_refused,
            model_version: s.model_version,
            imu_rate_hz: finite(s.imu_rate_hz),
            vehicle_time_ns: s.vehicle_time_ns,
            text: s.text().to_string(),
            supply_voltage_v: finite(s.supply_voltage_v),
            supply_compensation: s
                .supply_compensation()
                .map(|c| format!("{c:?}"))
                .unwrap_or_else(|e| format!("Unknown({})", e.value)),
        }
    }
}

/// `status --json`: the daemon's status and, beside it, the driver's own report.
#[derive(Serialize, Debug, PartialEq)]
pub struct StatusReportJson {
    #[serde(flatten)]
    pub status: StatusJson,
    /// The driver's report on its outputs; null when no driver published one.
    pub driver: Option<DriverJson>,
}

/// One driver status message.
#[derive(Serialize, Debug, PartialEq)]
pub struct DriverJson {
    pub driver: String,
    pub thruster_count: u32,
    /// OutputState name ("Active", "Neutral", "Disarmed", "LinkDown", ...).
    pub output_state: String,
    pub commands_accepted: u64,
    pub commands_rejected: u64,
    pub watchdog_expiries: u64,
    pub link_up: bool,
    pub armed: bool,
    pub time_ns: u64,
    pub text: String,
    /// Supply voltage, V; null when the driver does not measure it.
    pub supply_voltage_v: Option<f64>,
    /// Supply current, A; null when not measured.
    pub supply_current_a: Option<f64>,
}

impl From<&DriverStatusMsg> for DriverJson {
    fn from(d: &DriverStatusMsg) -> Self {
        Self {
            driver: d.driver().to_string(),
            thruster_count: d.thruster_count,
            output_state: d
                .output_state()
                .map(|s| format!("{s:?}"))
                .unwrap_or_else(|e| format!("Unknown({})", e.value)),
            commands_accepted: d.commands_accepted,
            commands_rejected: d.commands_rejected,
            watchdog_expiries: d.watchdog_expiries,
            link_up: d.link_up == 1,
            armed: d.armed == 1,
            time_ns: d.time_ns,
            text: d.text().to_string(),
            supply_voltage_v: d.supply_voltage(),
            supply_current_a: d.supply_current(),
        }
    }
}

/// Actuated or not, per DOF, in the protocol's DOF order.
#[derive(Serialize, Debug, PartialEq)]
pub struct DofFlags {
    pub roll: bool,
    pub pitch: bool,
    pub yaw: bool,
    pub surge: bool,
    pub sway: bool,
    pub heave: bool,
}

/// One model message: matrices as arrays of rows, only the `count` thrusters in use.
#[derive(Serialize, Debug, PartialEq)]
pub struct ModelJson {
    pub seq: u64,
    pub version: u64,
    pub t_ns: u64,
    pub count: u32,
    pub source: String,
    pub method: String,
    /// Row order of `effectiveness` and `std_err`, column order of `allocation`.
    pub dofs: Vec<String>,
    pub actuated: DofFlags,
    /// 6 rows (DOFs) x count columns; rad/s^2 or m/s^2 per unit command.
    pub effectiveness: Vec<Vec<Option<f64>>>,
    /// Same shape; null where unknown.
    pub std_err: Vec<Vec<Option<f64>>>,
    /// count rows (thrusters) x 6 columns; command per unit of DOF motion.
    pub allocation: Vec<Vec<Option<f64>>>,
    pub rel_err_rot: Option<f64>,
    pub rel_err_acc: Option<f64>,
    /// Pulses of the estimation that made the model; 0 for a nominal one.
    pub pulses: u32,
    /// Where the model came from, in words.
    pub provenance: String,
}

impl From<&ModelMsg> for ModelJson {
    fn from(m: &ModelMsg) -> Self {
        let n = m.thruster_count();
        let rows = |mat: &[[f64; MAX_THRUSTERS]; DOF_COUNT]| -> Vec<Vec<Option<f64>>> {
            mat.iter()
                .map(|row| row[..n].iter().copied().map(finite).collect())
                .collect()
        };
        Self {
            seq: m.seq,
            version: m.version,
            t_ns: m.t_ns,
            count: m.count,
            source: m
                .source()
                .map_or_else(|e| e.to_string(), |s| s.name().into()),
            method: m
                .method()
                .map_or_else(|e| e.to_string(), |s| s.name().into()),
            dofs: Dof::ALL.iter().map(|d| dof_key(*d)).collect(),
            actuated: DofFlags {
                roll: m.is_actuated(Dof::Roll),
                pitch: m.is_actuated(Dof::Pitch),
                yaw: m.is_actuated(Dof::Yaw),
                surge: m.is_actuated(Dof::Surge),
                sway: m.is_actuated(Dof::Sway),
                heave: m.is_actuated(Dof::Heave),
            },
            effectiveness: rows(&m.effectiveness),
            std_err: rows(&m.std_err),
            allocation: m.allocation[..n]
                .iter()
                .map(|row| row.iter().copied().map(finite).collect())
                .collect(),
            rel_err_rot: finite(m.rel_err_rot),
            rel_err_acc: finite(m.rel_err_acc),
            pulses: m.pulses,
            provenance: m.provenance().to_string(),
        }
    }
}

/// One telemetry message, as `watch --json` prints it: `{"telemetry": {...}}`, so a line is
/// told from a status line (which never has that key) without guessing. SI units, named in
/// the keys; what the daemon does not know (no setpoint, no depth sensor, no estimation) is
/// null.
#[derive(Serialize, Debug, PartialEq)]
pub struct TelemetryLineJson {
    pub telemetry: TelemetryJson,
}

#[derive(Serialize, Debug, PartialEq)]
pub struct TelemetryJson {
    pub seq: u64,
    /// Vehicle time (the IMU sample's), ns.
    pub t_ns: u64,
    pub imu_seq: u64,
    /// DaemonState name, as in status.
    pub state: String,
    /// ThrustMode name of the commands ("Neutral", "Estimating", "Controlling").
    pub mode: String,
    pub model_version: u64,
    /// Attitude estimate `[w, x, y, z]`, body to NED.
    pub attitude: [f64; 4],
    /// Roll, pitch, yaw of the estimate, rad.
    pub euler_rad: [f64; 3],
    /// Body rate, bias removed, rad/s.
    pub rate_rad_s: [f64; 3],
    pub depth_m: Option<f64>,
    /// What the controller tracks; null while it does not control.
    pub setpoint: Option<SetpointJson>,
    /// Rotation from estimate to setpoint, body-frame rotation vector, rad.
    pub attitude_error_rad: Option<[f64; 3]>,
    /// Its angle, rad.
    pub attitude_error_angle_rad: Option<f64>,
    /// Setpoint depth minus depth, m.
    pub depth_error_m: Option<f64>,
    /// The commands sent, one per thruster, in [-1, 1].
    pub thrust: Vec<f64>,
    pub estimation: Option<EstimationJson>,
}

#[derive(Serialize, Debug, PartialEq)]
pub struct SetpointJson {
    pub attitude: [f64; 4],
    pub euler_rad: [f64; 3],
    /// Null when depth is not held.
    pub depth_m: Option<f64>,
}

#[derive(Serialize, Debug, PartialEq)]
pub struct EstimationJson {
    pub pulse: u32,
    pub pulses_planned: u32,
    pub power: f64,
    pub error_bound: Option<f64>,
    pub sigma_rot: Option<f64>,
    pub sigma_acc: Option<f64>,
}

impl From<&TelemetryMsg> for TelemetryLineJson {
    fn from(t: &TelemetryMsg) -> Self {
        let has = |f| t.has(f);
        let sp = has(TelemetryMsg::HAS_SETPOINT);
        let noise = has(TelemetryMsg::HAS_NOISE);
        Self {
            telemetry: TelemetryJson {
                seq: t.seq,
                t_ns: t.t_ns,
                imu_seq: t.imu_seq,
                state: state_name(t.state),
                mode: t
                    .mode()
                    .map_or_else(|e| format!("Unknown({})", e.value), |m| m.name().into()),
                model_version: t.model_version,
                attitude: t.attitude,
                euler_rad: t.euler,
                rate_rad_s: t.rate,
                depth_m: has(TelemetryMsg::HAS_DEPTH).then_some(t.depth),
                setpoint: sp.then(|| SetpointJson {
                    attitude: t.setpoint_attitude,
                    euler_rad: t.setpoint_euler,
                    depth_m: has(TelemetryMsg::HOLD_DEPTH).then_some(t.setpoint_depth),
                }),
                attitude_error_rad: sp.then_some(t.attitude_error),
                attitude_error_angle_rad: sp.then_some(t.attitude_error_angle),
                depth_error_m: has(TelemetryMsg::HOLD_DEPTH | TelemetryMsg::HAS_DEPTH)
                    .then_some(t.depth_error),
                thrust: t.thrusters().to_vec(),
                estimation: has(TelemetryMsg::ESTIMATING).then(|| EstimationJson {
                    pulse: t.pulse,
                    pulses_planned: t.pulses_planned,
                    power: t.power,
                    error_bound: has(TelemetryMsg::HAS_ERROR_BOUND).then_some(t.error_bound),
                    sigma_rot: noise.then_some(t.sigma_rot),
                    sigma_acc: noise.then_some(t.sigma_acc),
                }),
            },
        }
    }
}

/// Lower-case DOF name, as used in JSON keys and text output.
pub fn dof_key(dof: Dof) -> String {
    dof.name().to_ascii_lowercase()
}

/// The state's name, or a visible marker for a value this build does not know.
pub fn state_name(state: u32) -> String {
    DaemonState::try_from(state).map_or_else(|_| format!("Unknown({state})"), |s| s.name().into())
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::{json, Value};
    use thruster_protocol::{ModelMethod, ModelSource};

    #[test]
    fn status_has_every_field_and_state_as_string() {
        let mut s = StatusMsg {
            seq: 9,
            pulse: 2,
            pulses_planned: 8,
            error_bound: 0.05,
            power: 0.5,
            samples: 1234,
            rejected_range: 3,
            model_version: 4,
            imu_rate_hz: 400.0,
            vehicle_time_ns: 1_500_000_000,
            supply_voltage_v: 15.5,
            supply_compensation: thruster_protocol::SupplyCompensation::Active.as_u32(),
            ..StatusMsg::default()
        };
        s.set_state(DaemonState::Pulse);
        s.set_text("pulsing");
        let v = serde_json::to_value(StatusJson::from(&s)).unwrap();
        assert_eq!(
            v,
            json!({
                "seq": 9, "state": "Pulse", "pulse": 2, "pulses_planned": 8,
                "error_bound": 0.05, "power": 0.5, "sigma_rot": 0.0, "sigma_acc": 0.0,
                "samples": 1234, "samples_missed": 0, "rejected_nonfinite": 0, "rejected_range": 3,
                "rejected_time": 0, "rejected_count": 0, "rejected_other": 0,
                "requests_refused": 0,
                "model_version": 4, "imu_rate_hz": 400.0, "vehicle_time_ns": 1_500_000_000u64,
                "text": "pulsing", "supply_voltage_v": 15.5, "supply_compensation": "Active"
            })
        );
        // Every wire field except padding is exported.
        let wire = serde_json::to_value(s).unwrap();
        for key in wire.as_object().unwrap().keys() {
            if key.starts_with("reserved") {
                continue;
            }
            assert!(v.get(key).is_some(), "missing {key}");
        }
        s.state = 77;
        assert_eq!(StatusJson::from(&s).state, "Unknown(77)");
    }

    #[test]
    fn model_matrices_are_rows_of_count_with_nan_as_null() {
        let mut m = ModelMsg {
            version: 3,
            count: 2,
            actuated: Dof::Yaw.mask() | Dof::Surge.mask(),
            rel_err_rot: 0.04,
            rel_err_acc: 0.2,
            ..ModelMsg::default()
        };
        m.set_source(ModelSource::Estimated);
        m.set_method(ModelMethod::Forward);
        m.effectiveness[Dof::Yaw.index()][..2].copy_from_slice(&[1.5, -1.5]);
        m.effectiveness[Dof::Surge.index()][..2].copy_from_slice(&[0.8, 0.8]);
        m.effectiveness[0][5] = 9.0; // beyond count: must not appear
        m.std_err[Dof::Yaw.index()][..2].copy_from_slice(&[0.01, f64::NAN]);
        m.allocation[0][Dof::Yaw.index()] = 0.3;
        m.allocation[1][Dof::Surge.index()] = 0.6;
        let v: Value = serde_json::to_value(ModelJson::from(&m)).unwrap();
        assert_eq!(v["source"], "Estimated");
        assert_eq!(v["method"], "Forward");
        assert_eq!(
            v["dofs"],
            json!(["roll", "pitch", "yaw", "surge", "sway", "heave"])
        );
        assert_eq!(
            v["actuated"],
            json!({"roll": false, "pitch": false, "yaw": true, "surge": true,
                   "sway": false, "heave": false})
        );
        let eff = v["effectiveness"].as_array().unwrap();
        assert_eq!(eff.len(), 6);
        assert!(eff.iter().all(|row| row.as_array().unwrap().len() == 2));
        assert_eq!(eff[0], json!([0.0, 0.0]));
        assert_eq!(eff[2], json!([1.5, -1.5]));
        assert_eq!(v["std_err"][2], json!([0.01, null]));
        let alloc = v["allocation"].as_array().unwrap();
        assert_eq!(alloc.len(), 2);
        assert_eq!(alloc[0], json!([0.0, 0.0, 0.3, 0.0, 0.0, 0.0]));
        assert_eq!(v["rel_err_rot"], 0.04);
        // The text is valid JSON that round-trips through a parser.
        let text = serde_json::to_string(&ModelJson::from(&m)).unwrap();
        assert_eq!(serde_json::from_str::<Value>(&text).unwrap(), v);
    }

    #[test]
    fn telemetry_is_one_keyed_object_with_unknowns_as_null() {
        let mut t = TelemetryMsg {
            seq: 4,
            t_ns: 2_000_000_000,
            count: 2,
            flags: TelemetryMsg::HAS_SETPOINT | TelemetryMsg::HAS_DEPTH,
            depth: 1.5,
            attitude_error_angle: 0.1,
            attitude_error: [0.0, 0.1, 0.0],
            ..TelemetryMsg::default()
        };
        t.set_state(DaemonState::Active);
        t.set_mode(thruster_protocol::ThrustMode::Controlling);
        t.thrust[..2].copy_from_slice(&[0.5, -0.5]);
        let v = serde_json::to_value(TelemetryLineJson::from(&t)).unwrap();
        let tel = &v["telemetry"];
        assert_eq!(v.as_object().unwrap().len(), 1, "{v}");
        assert_eq!(tel["state"], "Active");
        assert_eq!(tel["mode"], "Controlling");
        assert_eq!(tel["thrust"], serde_json::json!([0.5, -0.5]));
        assert_eq!(tel["depth_m"], 1.5);
        assert_eq!(tel["attitude_error_angle_rad"], 0.1);
        assert_eq!(tel["setpoint"]["depth_m"], serde_json::Value::Null);
        // Depth is measured but not held: no depth error; not estimating: no estimation.
        assert_eq!(tel["depth_error_m"], serde_json::Value::Null);
        assert_eq!(tel["estimation"], serde_json::Value::Null);
    }
}
