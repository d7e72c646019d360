//! Property tests: any bytes in shared memory decode and validate without panicking,
//! and whatever passes validation is finite and in range.

use proptest::prelude::*;
use thruster_protocol::validate::limits;
use thruster_protocol::*;

/// Reads a message from arbitrary bytes, as a reader does from shared memory written by
/// another process. Sound only because every message field is an integer, a float or an
/// array of them: any bit pattern is a valid value. This is the property the test pins.
fn from_bytes<T: Copy>(bytes: &[u8]) -> T {
    assert_eq!(bytes.len(), std::mem::size_of::<T>());
    // SAFETY: T is one of the protocol messages (plain integers and floats only), and
    // read_unaligned copes with the Vec's alignment.
    unsafe { std::ptr::read_unaligned(bytes.as_ptr().cast::<T>()) }
}

fn bytes_of<T>() -> impl Strategy<Value = Vec<u8>> {
    proptest::collection::vec(any::<u8>(), std::mem::size_of::<T>())
}

macro_rules! garbage_never_panics {
    ($name:ident, $ty:ty) => {
        proptest! {
            #[test]
            fn $name(bytes in bytes_of::<$ty>()) {
                let msg: $ty = from_bytes(&bytes);
                let _ = msg.validate();
                let _ = format!("{msg:?}");
            }
        }
    };
}

garbage_never_panics!(garbage_imu, ImuSample);
garbage_never_panics!(garbage_thrust, ThrustCommand);
garbage_never_panics!(garbage_reconfig, ReconfigEvent);
garbage_never_panics!(garbage_model, ModelMsg);
garbage_never_panics!(garbage_truth, TruthMsg);
garbage_never_panics!(garbage_status, StatusMsg);
garbage_never_panics!(garbage_setpoint, Setpoint);
garbage_never_panics!(garbage_request, ControlRequest);
garbage_never_panics!(garbage_response, ControlResponse);

fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -300.0f64..300.0,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => any::<f64>(),
    ]
}

proptest! {
    #[test]
    fn accepted_imu_samples_are_finite_and_in_range(
        g in proptest::array::uniform3(any_f64()),
        a in proptest::array::uniform3(any_f64()),
        depth in any_f64(),
    ) {
        let s = ImuSample { gyro: g, accel: a, depth, ..Default::default() };
        if s.validate().is_ok() {
            prop_assert!(g.iter().all(|x| x.abs() <= limits::MAX_GYRO_RAD_S));
            prop_assert!(a.iter().all(|x| x.abs() <= limits::MAX_ACCEL_M_S2));
            prop_assert!((limits::MIN_DEPTH_M..=limits::MAX_DEPTH_M).contains(&depth));
        } else {
            // Written with ranges so NaN counts as outside.
            let within = |x: &f64, max: f64| (-max..=max).contains(x);
            let bad = g.iter().any(|x| !within(x, limits::MAX_GYRO_RAD_S))
                || a.iter().any(|x| !within(x, limits::MAX_ACCEL_M_S2))
                || !(limits::MIN_DEPTH_M..=limits::MAX_DEPTH_M).contains(&depth);
            prop_assert!(bad, "valid sample rejected: {:?}", s.validate());
        }
    }

    #[test]
    fn sanitized_thrust_is_always_safe(mut t in proptest::collection::vec(any_f64(), 0..20)) {
        let before = t.clone();
        let changed = sanitize_thrust(&mut t);
        prop_assert!(t.iter().all(|x| x.is_finite() && (-1.0..=1.0).contains(x)));
        let expected = before.iter().filter(|x| !(x.is_finite() && (-1.0..=1.0).contains(*x))).count();
        prop_assert_eq!(changed, expected);
    }

    #[test]
    fn accepted_commands_are_safe_to_apply(
        count in 0u32..20,
        t in proptest::array::uniform16(any_f64()),
    ) {
        let mut c = ThrustCommand::neutral(1, 1, 1, count);
        c.thrust = t;
        if c.validate().is_ok() {
            let mut applied = c.thrusters().to_vec();
            prop_assert_eq!(sanitize_thrust(&mut applied), 0);
        }
    }

    #[test]
    fn text_never_panics_and_round_trips(s in ".{0,200}") {
        let mut status = StatusMsg::default();
        status.set_text(&s);
        let stored = status.text();
        prop_assert!(stored.len() <= TEXT_CAPACITY);
        let expected_src = s.split('\0').next().unwrap();
        prop_assert!(expected_src.starts_with(stored));
        if expected_src.len() <= TEXT_CAPACITY {
            prop_assert_eq!(stored, expected_src);
        }
    }
}
