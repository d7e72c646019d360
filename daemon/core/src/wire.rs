//! Conversions between the pure core's types and the protocol's shared-memory messages.

use nalgebra::UnitQuaternion;
use thruster_protocol::{
    DaemonState, DynamicsMsg, DynamicsRow, ImuSample, ModelMethod, ModelMsg,
    ModelSource as WireSource, ReconfigEvent, ReconfigKind, Setpoint, StatusMsg, ThrustCommand,
    ThrustMode, DOF_COUNT, MAX_THRUSTERS,
};

use crate::estimator::Method;
use crate::machine::{Command, Geometry, ImuInput, Mode, Reconfig, State, StatusSnapshot};
use crate::model::{Model, ModelSource};

pub fn imu_input(s: &ImuSample) -> ImuInput {
    ImuInput {
        seq: s.seq,
        t_ns: s.t_ns,
        gyro: s.gyro,
        accel: s.accel,
        mag: s.has_mag().then_some(s.mag),
        depth: s.has_depth().then_some(s.depth),
    }
}

/// The thrust message answering IMU sample `imu`.
pub fn thrust_command(seq: u64, imu_seq: u64, t_ns: u64, cmd: &Command) -> ThrustCommand {
    let count = cmd.count.min(MAX_THRUSTERS);
    let mut msg = ThrustCommand::neutral(seq, imu_seq, t_ns, count as u32);
    msg.set_mode(match cmd.mode {
        Mode::Neutral => ThrustMode::Neutral,
        Mode::Estimating => ThrustMode::Estimating,
        Mode::Controlling => ThrustMode::Controlling,
    });
    msg.thrust[..count].copy_from_slice(&cmd.thrust[..count]);
    msg
}

pub fn daemon_state(s: State) -> DaemonState {
    match s {
        State::Idle => DaemonState::Idle,
        State::MeasureNoise => DaemonState::MeasureNoise,
        State::Pulse => DaemonState::Pulse,
        State::Settle => DaemonState::Settle,
        State::Solve => DaemonState::Solve,
        State::Active => DaemonState::Active,
        State::Fault => DaemonState::Fault,
        State::Identify => DaemonState::Identify,
    }
}

pub fn status_msg(seq: u64, s: &StatusSnapshot) -> StatusMsg {
    // The protocol has NaN for "not known yet"; an infinite bound (not every thruster pulsed
    // yet) is exactly that.
    let known = |v: f64| if v.is_finite() { v } else { f64::NAN };
    let mut m = StatusMsg {
        seq,
        pulse: s.pulse as u32,
        pulses_planned: s.pulses_planned as u32,
        error_bound: known(s.error_bound),
        power: s.power,
        sigma_rot: known(s.sigma_rot),
        sigma_acc: known(s.sigma_acc),
        samples: s.samples,
        model_version: s.model_version,
        imu_rate_hz: s.imu_rate_hz,
        vehicle_time_ns: s.vehicle_time_ns,
        ..StatusMsg::default()
    };
    m.set_state(daemon_state(s.state));
    m.set_text(&s.text);
    m
}

pub fn model_msg(seq: u64, model: &Model) -> ModelMsg {
    let n = model.thrusters().min(MAX_THRUSTERS);
    let known = |v: f64| if v.is_finite() { v } else { f64::NAN };
    let mut m = ModelMsg {
        seq,
        version: model.version,
        t_ns: model.made_t_ns,
        pulses: u32::try_from(model.pulses).unwrap_or(u32::MAX),
        count: n as u32,
        actuated: model.actuated.bits() as u32,
        rel_err_rot: known(model.rel_err_rot),
        rel_err_acc: known(model.rel_err_acc),
        ..ModelMsg::default()
    };
    m.provenance.set(&model.provenance());
    m.set_source(match model.source {
        ModelSource::Nominal => WireSource::Nominal,
        ModelSource::Estimated => WireSource::Estimated,
        ModelSource::Cache => WireSource::Cache,
        ModelSource::Loaded => WireSource::Loaded,
    });
    m.set_method(match model.method {
        Method::Paper => ModelMethod::Paper,
        Method::Forward => ModelMethod::Forward,
        Method::Dynamic => ModelMethod::Dynamic,
    });
    for j in 0..DOF_COUNT {
        for i in 0..n {
            m.effectiveness[j][i] = model.effectiveness[(j, i)];
            m.std_err[j][i] = known(model.std_err[(j, i)]);
            m.allocation[i][j] = model.allocation[(i, j)];
        }
    }
    m
}

/// The dynamic coefficients of `model`, when its method learned any.
pub fn dynamics_msg(seq: u64, model: &Model) -> Option<DynamicsMsg> {
    let d = model.dynamics.as_ref()?;
    let row = |m: &nalgebra::DMatrix<f64>, r: usize| {
        // NaN marks "unknown" on the wire (an infinite standard error: a term never excited).
        let terms: Vec<f64> = m
            .row(r)
            .iter()
            .map(|v| if v.is_finite() { *v } else { f64::NAN })
            .collect();
        DynamicsRow::from_terms(&terms)
    };
    Some(DynamicsMsg {
        seq,
        model_version: model.version,
        t_ns: model.made_t_ns,
        coefficients: std::array::from_fn(|r| row(&d.coefficients, r)),
        std_err: std::array::from_fn(|r| row(&d.std_err, r)),
        max_tilt_rad: d.max_tilt_rad,
        max_heading_change_rad: d.max_heading_change_rad,
    })
}

/// A validated reconfiguration event for the machine.
pub fn reconfig(e: &ReconfigEvent) -> Reconfig {
    let count = (e.count as usize).min(MAX_THRUSTERS);
    let geometry = e.geometry_declared().then(|| Geometry {
        positions: e.position[..count].to_vec(),
        directions: e.direction[..count].to_vec(),
    });
    let kind = e.kind().unwrap_or(ReconfigKind::Unknown);
    Reconfig {
        count,
        geometry,
        what: format!("reconfiguration ({}, thruster {})", kind.name(), e.thruster),
    }
}

/// Attitude and optional depth of a validated setpoint.
pub fn setpoint(s: &Setpoint) -> crate::machine::SetpointInput {
    let [w, x, y, z] = s.attitude;
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    let depth = (s.flags & Setpoint::HOLD_DEPTH != 0).then_some(s.depth);
    crate::machine::SetpointInput {
        attitude: q,
        keep: s.kept_angles(),
        depth,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::{Machine, MachineSetup};
    use crate::model::{nominal_effectiveness, RigidBody};
    use thruster_protocol::validate::Validate;

    #[test]
    fn what_the_daemon_publishes_passes_the_protocols_checks() {
        // A fresh machine: nothing measured yet (NaN levels, no bound).
        let m = Machine::new(MachineSetup {
            thrusters: 3,
            ..MachineSetup::default()
        });
        let status = status_msg(1, &m.status());
        status.validate().unwrap();
        assert!(status.error_bound.is_nan() && status.sigma_rot.is_nan());
        // A nominal model: unknown standard errors and bounds.
        let pos = [[0.0, -0.2, 0.0], [0.0, 0.2, 0.0], [0.1, 0.0, -0.1]];
        let dir = [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]];
        let mut model = Model::nominal(
            nominal_effectiveness(&RigidBody::default(), &pos, &dir),
            None,
        );
        model.rel_err_acc = f64::INFINITY;
        let msg = model_msg(1, &model);
        msg.validate().unwrap();
        assert_eq!(msg.count, 3);
        assert!(msg.rel_err_acc.is_nan());
    }
}
