//! Operator angles to the protocol's setpoint.

use thruster_protocol::Setpoint;

use crate::cli::{Depth, SetpointArgs};

/// Unit quaternion `[w, x, y, z]` of the body-to-NED rotation for ZYX (yaw, pitch, roll)
/// Euler angles in radians: R = Rz(yaw) Ry(pitch) Rx(roll), the aerospace convention and
/// nalgebra's `from_euler_angles`. Returned with `w >= 0` so the same attitude always
/// prints the same (q and -q are one rotation).
pub fn quaternion_from_euler(roll: f64, pitch: f64, yaw: f64) -> [f64; 4] {
    let (sr, cr) = (roll / 2.0).sin_cos();
    let (sp, cp) = (pitch / 2.0).sin_cos();
    let (sy, cy) = (yaw / 2.0).sin_cos();
    let q = [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ];
    if q[0] < 0.0 {
        q.map(|v| -v)
    } else {
        q
    }
}

/// The setpoint message for checked operator arguments (degrees, metres). `seq` is the
/// caller's: each thrusterctl run is a new sender.
pub fn setpoint(args: &SetpointArgs, seq: u64) -> Setpoint {
    // An angle left out is sent as 0 with its KEEP_* flag: the daemon keeps what it holds.
    let angle = |a: Option<f64>| a.unwrap_or(0.0).to_radians();
    let attitude = quaternion_from_euler(
        angle(args.roll_deg),
        angle(args.pitch_deg),
        angle(args.yaw_deg),
    );
    let mut flags = 0;
    for (value, flag) in [
        (args.roll_deg, Setpoint::KEEP_ROLL),
        (args.pitch_deg, Setpoint::KEEP_PITCH),
        (args.yaw_deg, Setpoint::KEEP_YAW),
    ] {
        if value.is_none() {
            flags |= flag;
        }
    }
    // Neither depth flag: the daemon keeps the depth it holds.
    let depth = match args.depth {
        Depth::Keep => 0.0,
        Depth::Free => {
            flags |= Setpoint::RELEASE_DEPTH;
            0.0
        }
        Depth::Hold(d) => {
            flags |= Setpoint::HOLD_DEPTH;
            d
        }
    };
    Setpoint {
        seq,
        attitude,
        depth,
        flags,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector3};
    use thruster_protocol::Validate;

    fn close(a: [f64; 4], b: [f64; 4]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
    }

    #[test]
    fn single_axis_rotations() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let d = f64::to_radians;
        assert!(close(
            quaternion_from_euler(0.0, 0.0, 0.0),
            [1.0, 0.0, 0.0, 0.0]
        ));
        assert!(close(
            quaternion_from_euler(d(90.0), 0.0, 0.0),
            [h, h, 0.0, 0.0]
        ));
        assert!(close(
            quaternion_from_euler(0.0, d(90.0), 0.0),
            [h, 0.0, h, 0.0]
        ));
        assert!(close(
            quaternion_from_euler(0.0, 0.0, d(90.0)),
            [h, 0.0, 0.0, h]
        ));
        // A full turn is the identity, printed with w >= 0.
        assert!(close(
            quaternion_from_euler(0.0, 0.0, d(360.0)),
            [1.0, 0.0, 0.0, 0.0]
        ));
    }

    #[test]
    fn matches_nalgebra_zyx_and_rotates_body_to_ned() {
        for &(r, p, y) in &[(0.3, -0.2, 1.0), (-2.5, 1.2, -3.0), (1.0, 0.0, 2.0)] {
            let q = quaternion_from_euler(r, p, y);
            let n = UnitQuaternion::from_euler_angles(r, p, y);
            let sign = n.w.signum();
            assert!(
                close(q, [n.w, n.i, n.j, n.k].map(|v| sign * v)),
                "{r} {p} {y}"
            );
        }
        // Yaw 90 deg (heading east): the body's forward axis points east in NED.
        let q = quaternion_from_euler(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let rot =
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
        let forward_ned = rot * Vector3::x();
        assert!((forward_ned - Vector3::y()).norm() < 1e-12);
    }

    #[test]
    fn depth_hold_flag_follows_depth() {
        let args = SetpointArgs {
            roll_deg: Some(0.0),
            pitch_deg: Some(10.0),
            yaw_deg: Some(-45.0),
            depth: Depth::Hold(2.5),
        };
        let sp = setpoint(&args, 7);
        assert_eq!(sp.seq, 7);
        assert!(sp.hold_depth());
        assert_eq!(sp.depth, 2.5);
        sp.validate().unwrap();
        let free = setpoint(
            &SetpointArgs {
                depth: Depth::Free,
                ..args
            },
            8,
        );
        assert!(!free.hold_depth());
        assert_eq!(free.flags, Setpoint::RELEASE_DEPTH);
        free.validate().unwrap();
        let kept = setpoint(
            &SetpointArgs {
                depth: Depth::Keep,
                ..args
            },
            8,
        );
        assert_eq!(kept.flags, 0, "neither hold nor release: keep");
        kept.validate().unwrap();
        // Angles left out are flagged to be kept, and only those.
        let pitch_only = setpoint(
            &SetpointArgs {
                roll_deg: None,
                pitch_deg: Some(10.0),
                yaw_deg: None,
                depth: Depth::Keep,
            },
            9,
        );
        assert_eq!(pitch_only.kept_angles(), [true, false, true]);
        assert!(!pitch_only.hold_depth() && !pitch_only.release_depth());
        pitch_only.validate().unwrap();
    }
}
