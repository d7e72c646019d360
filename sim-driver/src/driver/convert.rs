//! Simulator values to protocol messages (pure functions, unit-tested).

use nalgebra::DMatrix;
use thruster_protocol::validate::limits::{
    MAX_ACCEL_M_S2, MAX_DEPTH_M, MAX_GYRO_RAD_S, MAX_MAG_UT, MIN_DEPTH_M,
};
use thruster_protocol::{
    ImuReading, ImuSample, ReconfigEvent, ReconfigKind, TruthMsg, VehicleStateMsg, MAX_THRUSTERS,
};

use crate::sim::{Change, ChangeKind, Simulator};
use crate::vehicle::Vehicle;

/// An IMU sample for `reading`, numbered `seq`, and how many values had to be clipped to the
/// protocol's ranges.
///
/// Clipping models sensor saturation (a real gyro clips at its full scale) and keeps every
/// published sample valid. The one value that leaves its range in practice is depth: the
/// simulator has no free surface, so a positively buoyant vehicle left alone rises through
/// it and would read below `MIN_DEPTH_M`. The clipped reading goes on the wire through the
/// protocol's one conversion ([`ImuReading::to_sample`]).
pub fn imu_sample(seq: u64, reading: &ImuReading) -> (ImuSample, usize) {
    let mut clipped = 0;
    let mut clip = |v: f64, lo: f64, hi: f64| {
        let c = v.clamp(lo, hi);
        if c != v {
            clipped += 1;
        }
        c
    };
    let saturated = ImuReading {
        seq,
        t_ns: reading.t_ns,
        gyro: reading
            .gyro
            .map(|v| clip(v, -MAX_GYRO_RAD_S, MAX_GYRO_RAD_S)),
        accel: reading
            .accel
            .map(|v| clip(v, -MAX_ACCEL_M_S2, MAX_ACCEL_M_S2)),
        mag: reading
            .mag
            .map(|m| m.map(|v| clip(v, -MAX_MAG_UT, MAX_MAG_UT))),
        depth: reading.depth.map(|d| clip(d, MIN_DEPTH_M, MAX_DEPTH_M)),
    };
    (saturated.to_sample(), clipped)
}

/// The true state of `sim` now, for the IMU sample `seq` taken at the same instant.
pub fn vehicle_state(seq: u64, sim: &Simulator) -> VehicleStateMsg {
    VehicleStateMsg {
        seq,
        t_ns: sim.time_ns(),
        attitude: sim.attitude_wxyz(),
        rate: sim.angular_velocity().into(),
        position_ned: sim.position_ned().into(),
        velocity: sim.linear_velocity().into(),
    }
}

/// The truth message for `(B_fwd, B_rev)` (6 x N, DOF order) valid from `t_ns`, at supply
/// voltage `supply_v` (`battery`: whether a battery model gives it).
pub fn truth_msg(
    seq: u64,
    t_ns: u64,
    fwd: &DMatrix<f64>,
    rev: &DMatrix<f64>,
    supply_v: f64,
    battery: bool,
) -> TruthMsg {
    let n = fwd.ncols().min(MAX_THRUSTERS);
    let mut msg = TruthMsg {
        seq,
        t_ns,
        count: n as u32,
        supply_voltage_v: supply_v,
        battery: u32::from(battery),
        ..TruthMsg::default()
    };
    for dof in 0..6 {
        for j in 0..n {
            msg.effectiveness[dof][j] = fwd[(dof, j)];
            msg.reverse_effectiveness[dof][j] = rev[(dof, j)];
        }
    }
    msg
}

/// The protocol kind of a simulator change. A killed thruster has no kind of its own in the
/// protocol: it is announced as `Unknown` (re-estimate everything) without geometry, because
/// the declared geometry would still describe a working thruster.
pub fn reconfig_kind(kind: ChangeKind) -> ReconfigKind {
    match kind {
        ChangeKind::Moved => ReconfigKind::ThrusterMoved,
        ChangeKind::Added => ReconfigKind::ThrusterAdded,
        ChangeKind::Removed => ReconfigKind::ThrusterRemoved,
        ChangeKind::Killed | ChangeKind::Weakened => ReconfigKind::Unknown,
    }
}

/// The reconfiguration event announcing `change`, with the new declared geometry of
/// `vehicle` (the vehicle after the change) unless the change is a kill.
///
/// The protocol measures positions from the centre of mass and gives the direction of the
/// force for a positive command; the simulator measures from the CO and lets a left-handed
/// (`reversed`) thruster push against its `direction`. Both are converted here.
pub fn reconfig_event(seq: u64, change: &Change, vehicle: &Vehicle) -> ReconfigEvent {
    let kind = reconfig_kind(change.kind);
    let mut ev = ReconfigEvent {
        seq,
        thruster: change.index as u32,
        count: change.thruster_count.min(MAX_THRUSTERS) as u32,
        ..ReconfigEvent::default()
    };
    ev.set_kind(kind);
    if !matches!(change.kind, ChangeKind::Killed | ChangeKind::Weakened) {
        ev.has_geometry = 1;
        for (i, (p, d)) in vehicle
            .declared_geometry()
            .into_iter()
            .take(MAX_THRUSTERS)
            .enumerate()
        {
            ev.position[i] = p;
            ev.direction[i] = d;
        }
    }
    ev
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::ThrusterSpec;
    use thruster_protocol::Validate;

    fn reading() -> ImuReading {
        ImuReading {
            seq: 0,
            t_ns: 5_000_000,
            gyro: [0.1, -0.2, 0.3],
            accel: [0.0, 0.0, -9.81],
            mag: Some([20.0, 0.0, 45.0]),
            depth: Some(5.0),
        }
    }

    #[test]
    fn sample_copies_values_and_sets_flags() {
        let (s, clipped) = imu_sample(7, &reading());
        assert_eq!(clipped, 0);
        assert_eq!((s.seq, s.t_ns), (7, 5_000_000));
        assert_eq!(s.gyro, [0.1, -0.2, 0.3]);
        assert_eq!(s.accel, [0.0, 0.0, -9.81]);
        assert_eq!(s.depth, 5.0);
        assert!(s.has_mag() && s.has_depth());
        assert!(s.validate().is_ok());
    }

    #[test]
    fn out_of_range_values_saturate_to_a_valid_sample() {
        let mut r = reading();
        r.gyro[2] = 80.0;
        r.depth = Some(-25.0);
        let (s, clipped) = imu_sample(1, &r);
        assert_eq!(clipped, 2);
        assert_eq!(s.gyro[2], MAX_GYRO_RAD_S);
        assert_eq!(s.depth, MIN_DEPTH_M);
        assert!(s.validate().is_ok());
    }

    #[test]
    fn vehicle_state_is_the_simulators() {
        let v = crate::random_vehicle(4, 3).unwrap();
        let mut sim = Simulator::new(v, crate::SensorConfig::ideal(200.0), 1).unwrap();
        sim.set_commands(&[1.0, -1.0, 0.5, 0.0]).unwrap();
        sim.step(300_000_000);
        let m = vehicle_state(61, &sim);
        assert_eq!((m.seq, m.t_ns), (61, 300_000_000));
        assert_eq!(m.attitude, sim.attitude_wxyz());
        assert_eq!(m.rate, <[f64; 3]>::from(sim.angular_velocity()));
        assert_eq!(m.position_ned[2], sim.position_ned().z);
        assert_eq!(m.velocity, <[f64; 3]>::from(sim.linear_velocity()));
        assert!(m.rate.iter().any(|&r| r != 0.0));
        assert!(m.validate().is_ok());
    }

    #[test]
    fn truth_copies_both_matrices() {
        let fwd = DMatrix::from_fn(6, 3, |i, j| (i * 10 + j) as f64);
        let rev = &fwd * 0.5;
        let t = truth_msg(2, 99, &fwd, &rev, 16.0, false);
        assert_eq!((t.seq, t.t_ns, t.count), (2, 99, 3));
        assert_eq!(t.effectiveness[4][2], 42.0);
        assert_eq!(t.reverse_effectiveness[4][2], 21.0);
        assert_eq!(t.effectiveness[4][3], 0.0);
        assert!(t.validate().is_ok());
    }

    #[test]
    fn event_declares_geometry_about_the_cg_with_reversed_directions() {
        let mut v = Vehicle {
            name: "t".into(),
            description: String::new(),
            body: Default::default(),
            thrusters: vec![
                ThrusterSpec::new("a", [0.2, 0.0, -0.15], [0.0, 0.0, -1.0]),
                ThrusterSpec::new("b", [0.0, 0.2, 0.0], [1.0, 0.0, 0.0]),
            ],
            battery: None,
        };
        v.thrusters[1].reversed = true;
        let change = Change {
            kind: ChangeKind::Moved,
            index: 1,
            thruster_count: 2,
        };
        let ev = reconfig_event(3, &change, &v);
        assert_eq!(ev.kind().unwrap(), ReconfigKind::ThrusterMoved);
        assert_eq!(
            (ev.seq, ev.thruster, ev.count, ev.has_geometry),
            (3, 1, 2, 1)
        );
        let cg_z = v.body.cg_m[2];
        assert_eq!(ev.position[0], [0.2, 0.0, -0.15 - cg_z]);
        assert_eq!(ev.direction[1], [-1.0, 0.0, 0.0]);
        assert!(ev.validate().is_ok());

        let killed = Change {
            kind: ChangeKind::Killed,
            ..change
        };
        let ev = reconfig_event(4, &killed, &v);
        assert_eq!(ev.kind().unwrap(), ReconfigKind::Unknown);
        assert_eq!(ev.has_geometry, 0);
        assert!(ev.validate().is_ok());
    }
}
