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
        if expected_src.len() <= TEXT_CAPACITY {
            prop_assert_eq!(stored, expected_src);
        } else {
            // Cut: a prefix of the text (trailing space dropped), then "...".
            let kept = stored.strip_suffix("...");
            prop_assert!(kept.is_some(), "a cut text without its ellipsis: {:?}", stored);
            prop_assert!(expected_src.starts_with(kept.unwrap()));
        }
    }
}

// ---- validity, both ways: what passes is exactly what is finite and in range ----------
//
// Each property states the rule independently of the implementation: a message is valid
// if and only if every field in use is finite and within its documented range, so valid
// messages are never dropped and invalid ones never pass. Rejections land in the counter
// the rule implies (NaN/inf -> nonfinite, finite but out of range -> range, ...).

use thruster_protocol::validate::{RejectCategory, SequenceChecker, SequenceConfig, Stamp};

/// Mostly plausible values, with boundaries, slightly-out values and every non-finite one.
fn edgy_f64(max: f64) -> impl Strategy<Value = f64> {
    prop_oneof![
        6 => -max..=max,
        1 => Just(max),
        1 => Just(-max),
        1 => Just(max * (1.0 + 1e-9)),
        1 => max * 1.0001..max * 1e6,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => any::<f64>(),
    ]
}

fn within(x: f64, min: f64, max: f64) -> bool {
    x.is_finite() && (min..=max).contains(&x)
}

proptest! {
    #[test]
    fn imu_sample_valid_iff_all_fields_finite_and_in_range(
        gyro in proptest::array::uniform3(edgy_f64(limits::MAX_GYRO_RAD_S)),
        accel in proptest::array::uniform3(edgy_f64(limits::MAX_ACCEL_M_S2)),
        mag in proptest::array::uniform3(edgy_f64(limits::MAX_MAG_UT)),
        depth in prop_oneof![
            4 => limits::MIN_DEPTH_M..=limits::MAX_DEPTH_M,
            1 => edgy_f64(limits::MAX_DEPTH_M),
        ],
        flags in prop_oneof![4 => 0u64..4, 1 => any::<u64>()],
    ) {
        let s = ImuSample { seq: 1, t_ns: 1, gyro, accel, mag, depth, flags };
        // Checked in field order, each value NaN/inf first, then range; flags last.
        let limits_in_order = gyro.iter().map(|v| (*v, limits::MAX_GYRO_RAD_S))
            .chain(accel.iter().map(|v| (*v, limits::MAX_ACCEL_M_S2)))
            .chain(mag.iter().map(|v| (*v, limits::MAX_MAG_UT)));
        let first_bad = limits_in_order
            .map(|(v, max)| (v, -max, max))
            .chain(std::iter::once((depth, limits::MIN_DEPTH_M, limits::MAX_DEPTH_M)))
            .find(|(v, min, max)| !within(*v, *min, *max));
        let flags_ok = flags & !ImuSample::KNOWN_FLAGS == 0;
        let expected = match first_bad {
            Some((v, _, _)) if !v.is_finite() => Some(RejectCategory::NonFinite),
            Some(_) => Some(RejectCategory::Range),
            None if !flags_ok => Some(RejectCategory::Other),
            None => None,
        };
        match (s.validate(), expected) {
            (Ok(()), None) => {}
            (Ok(()), Some(c)) => prop_assert!(false, "invalid sample accepted ({c:?}): {s:?}"),
            (Err(reason), None) => prop_assert!(false, "valid sample rejected: {reason}"),
            (Err(reason), Some(c)) => {
                prop_assert_eq!(reason.category(), c, "{}", reason);
                prop_assert!(!reason.to_string().is_empty());
            }
        }
    }

    #[test]
    fn thrust_command_valid_iff_count_mode_and_thrust_in_use_are(
        count in prop_oneof![4 => 0u32..=16, 1 => any::<u32>()],
        mode in prop_oneof![4 => 0u32..3, 1 => any::<u32>()],
        thrust in proptest::array::uniform16(edgy_f64(1.0)),
    ) {
        let c = ThrustCommand { seq: 1, imu_seq: 1, t_ns: 1, count, mode, thrust };
        let n = (count as usize).min(MAX_THRUSTERS);
        let ok = count as usize <= MAX_THRUSTERS
            && mode < 3
            && thrust[..n].iter().all(|v| within(*v, -1.0, 1.0));
        match c.validate() {
            Ok(()) => {
                prop_assert!(ok, "invalid command accepted: {c:?}");
                // What a driver applies needs no sanitising: nothing non-finite, nothing beyond 1.
                let mut applied = c.thrusters().to_vec();
                prop_assert_eq!(sanitize_thrust(&mut applied), 0);
            }
            Err(reason) => {
                prop_assert!(!ok, "valid command rejected: {reason}");
                if count as usize > MAX_THRUSTERS {
                    prop_assert_eq!(reason.category(), RejectCategory::Count);
                }
            }
        }
        // A driver configured for `expected` thrusters refuses every other count.
        let expected = 5u32;
        let r = thruster_protocol::validate::expect_count("count", count, expected);
        prop_assert_eq!(r.is_ok(), count == expected);
        if let Err(reason) = r {
            prop_assert_eq!(reason.category(), RejectCategory::Count);
        }
    }

    #[test]
    fn reconfig_valid_iff_kind_index_count_and_geometry_are(
        kind in prop_oneof![4 => 0u32..4, 1 => any::<u32>()],
        thruster in prop_oneof![4 => 0u32..18, 1 => any::<u32>()],
        count in prop_oneof![4 => 0u32..=17, 1 => any::<u32>()],
        has_geometry in prop_oneof![2 => 0u32..2, 1 => any::<u32>()],
        positions in proptest::collection::vec(
            proptest::array::uniform3(edgy_f64(limits::MAX_POSITION_M)), MAX_THRUSTERS),
        unit_dirs in proptest::collection::vec(
            prop_oneof![
                4 => proptest::array::uniform3(-1.0f64..1.0).prop_filter_map("zero", |d| {
                    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                    (n > 1e-3).then(|| [d[0] / n, d[1] / n, d[2] / n])
                }),
                1 => proptest::array::uniform3(edgy_f64(1.0)),
            ],
            MAX_THRUSTERS),
    ) {
        let mut e = ReconfigEvent { seq: 1, kind, thruster, count, has_geometry, ..Default::default() };
        e.position.copy_from_slice(&positions);
        e.direction.copy_from_slice(&unit_dirs);
        let n = (count as usize).min(MAX_THRUSTERS);
        let index_ok = match kind {
            0 => true,
            2 => thruster < count.saturating_add(1).min(MAX_THRUSTERS as u32),
            1 | 3 => thruster < count.min(MAX_THRUSTERS as u32),
            _ => false,
        };
        let geometry_ok = match has_geometry {
            0 => true,
            1 => (0..n).all(|i| {
                let d = e.direction[i];
                let norm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                e.position[i].iter().all(|v| within(*v, -limits::MAX_POSITION_M, limits::MAX_POSITION_M))
                    && d.iter().all(|v| v.is_finite())
                    && (norm - 1.0).abs() <= limits::DIRECTION_NORM_TOLERANCE
            }),
            _ => false,
        };
        let ok = kind < 4 && count as usize <= MAX_THRUSTERS && index_ok && geometry_ok;
        match e.validate() {
            Ok(()) => prop_assert!(ok, "invalid event accepted: kind {kind} thruster {thruster} count {count} geometry {has_geometry}"),
            Err(reason) => {
                prop_assert!(!ok, "valid event rejected: {reason}");
                if kind < 4 && count as usize <= MAX_THRUSTERS && !index_ok {
                    prop_assert_eq!(reason.category(), RejectCategory::Count, "{}", reason);
                }
            }
        }
    }

    #[test]
    fn setpoint_valid_iff_unit_quaternion_depth_in_range_and_known_flags(
        q in proptest::array::uniform4(edgy_f64(1.0)),
        normalise in any::<bool>(),
        depth in edgy_f64(limits::MAX_DEPTH_M),
        flags in prop_oneof![4 => 0u64..2, 1 => any::<u64>()],
    ) {
        let mut attitude = q;
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        if normalise && norm.is_finite() && norm > 1e-3 {
            attitude = q.map(|v| v / norm);
        }
        let s = Setpoint { seq: 1, attitude, depth, flags };
        let n = attitude.iter().map(|v| v * v).sum::<f64>().sqrt();
        let ok = attitude.iter().all(|v| v.is_finite())
            && (n - 1.0).abs() <= limits::QUATERNION_NORM_TOLERANCE
            && within(depth, limits::MIN_DEPTH_M, limits::MAX_DEPTH_M)
            && flags & !Setpoint::KNOWN_FLAGS == 0
            && flags & (Setpoint::HOLD_DEPTH | Setpoint::RELEASE_DEPTH)
                != Setpoint::HOLD_DEPTH | Setpoint::RELEASE_DEPTH;
        match s.validate() {
            Ok(()) => prop_assert!(ok, "invalid setpoint accepted: {s:?}"),
            Err(reason) => {
                prop_assert!(!ok, "valid setpoint rejected: {reason}");
                if !attitude.iter().all(|v| v.is_finite()) {
                    prop_assert_eq!(reason.category(), RejectCategory::NonFinite);
                }
            }
        }
    }

    #[test]
    fn control_request_valid_iff_kind_known_flags_zero_and_value_finite(
        kind in prop_oneof![4 => 0u32..9, 1 => any::<u32>()],
        flags in prop_oneof![4 => Just(0u32), 1 => any::<u32>()],
        value in edgy_f64(1.0),
        text in "[a-z/._]{0,40}",
    ) {
        let req = ControlRequest {
            seq: 1,
            kind,
            flags,
            value,
            text: thruster_protocol::wire::FixedText::from_str_truncated(&text),
        };
        let estimate = kind == RequestKind::Estimate.as_u32();
        let ok = kind < 9
            && flags == 0
            && value.is_finite()
            && (!estimate || (0.0..=1.0).contains(&value));
        match req.validate() {
            Ok(()) => prop_assert!(ok, "invalid request accepted: {req:?}"),
            Err(reason) => prop_assert!(!ok, "valid request rejected: {reason}"),
        }
    }

    #[test]
    fn model_with_any_non_finite_entry_in_use_is_rejected_and_unused_columns_ignored(
        count in 1u32..=16,
        col in 0usize..16,
        row in 0usize..6,
        bad in prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(f64::NEG_INFINITY)],
        which in 0u8..2,
    ) {
        let mut m = ModelMsg {
            seq: 1,
            version: 1,
            count,
            actuated: thruster_protocol::ALL_DOFS_MASK,
            rel_err_rot: 0.05,
            rel_err_acc: 0.1,
            ..Default::default()
        };
        for j in 0..6 {
            for i in 0..count as usize {
                m.effectiveness[j][i] = 1.0;
                m.allocation[i][j] = 0.1;
                m.std_err[j][i] = 0.01;
            }
        }
        prop_assert!(m.validate().is_ok());
        if which == 0 {
            m.effectiveness[row][col] = bad;
        } else {
            m.allocation[col][row] = bad;
        }
        let in_use = col < count as usize;
        match m.validate() {
            Ok(()) => prop_assert!(!in_use, "non-finite entry in use accepted"),
            Err(reason) => {
                prop_assert!(in_use, "unused column rejected: {reason}");
                prop_assert_eq!(reason.category(), RejectCategory::NonFinite);
            }
        }
    }
}

// ---- streams: time and sequence ------------------------------------------------------

fn stream_config() -> SequenceConfig {
    SequenceConfig {
        max_time_jump_ns: 1_000_000_000,
        resync_after: 3,
    }
}

proptest! {
    #[test]
    fn an_ordered_stream_is_always_accepted_and_gaps_counted(
        steps in proptest::collection::vec((1u64..5, 1u64..=1_000_000_000), 1..200),
    ) {
        let mut c = SequenceChecker::new(stream_config());
        let (mut seq, mut t) = (10u64, 10u64);
        let first = Stamp { seq, t_ns: t };
        prop_assert!(c.check(first).is_ok());
        for (dseq, dt) in steps {
            seq += dseq;
            t += dt;
            let a = c.check(Stamp { seq, t_ns: t });
            prop_assert_eq!(a.map(|a| (a.missed, a.resynced)), Ok((dseq - 1, false)));
        }
    }

    #[test]
    fn a_single_bad_stamp_is_rejected_counted_as_time_and_never_poisons_the_stream(
        prefix in 1usize..50,
        kind in 0u8..4,
        amount in 1u64..1_000_000_000_000,
    ) {
        let mut c = SequenceChecker::new(stream_config());
        let period = 5_000_000;
        for k in 0..prefix as u64 {
            let good = Stamp { seq: k + 1, t_ns: (k + 1) * period };
            prop_assert!(c.check(good).is_ok());
        }
        let last = Stamp { seq: prefix as u64, t_ns: prefix as u64 * period };
        let bad = match kind {
            // duplicate sequence number (any time)
            0 => Stamp { seq: last.seq, t_ns: last.t_ns + amount },
            // sequence going backwards
            1 => Stamp { seq: last.seq.saturating_sub(1 + amount % last.seq.max(1)), t_ns: last.t_ns + period },
            // time going backwards or standing still
            2 => Stamp { seq: last.seq + 1, t_ns: last.t_ns.saturating_sub(amount % (last.t_ns + 1)) },
            // time jumping past the maximum
            _ => Stamp { seq: last.seq + 1, t_ns: last.t_ns + 1_000_000_001 + amount },
        };
        let r = c.check(bad);
        prop_assert!(r.is_err(), "{bad:?} after {last:?} accepted");
        prop_assert_eq!(r.unwrap_err().category(), RejectCategory::Time);
        prop_assert_eq!(c.last(), Some(last));
        // The next good sample continues the stream as if the bad one never came.
        let next = Stamp { seq: last.seq + 2, t_ns: last.t_ns + period };
        let a = c.check(next);
        prop_assert_eq!(a.map(|a| a.resynced), Ok(false));
    }

    #[test]
    fn accepted_stamps_only_move_forward_unless_resynced(
        stamps in proptest::collection::vec((0u64..40, 0u64..4_000_000_000), 1..300),
    ) {
        let mut c = SequenceChecker::new(stream_config());
        let mut prev: Option<Stamp> = None;
        for (seq, t_ns) in stamps {
            let s = Stamp { seq, t_ns };
            match c.check(s) {
                Ok(a) => {
                    if let (Some(p), false) = (prev, a.resynced) {
                        prop_assert!(s.seq > p.seq && s.t_ns > p.t_ns, "{p:?} -> {s:?}");
                        prop_assert!(s.t_ns - p.t_ns <= 1_000_000_000);
                        prop_assert_eq!(a.missed, s.seq - p.seq - 1);
                    }
                    prev = Some(s);
                }
                Err(reason) => prop_assert_eq!(reason.category(), RejectCategory::Time),
            }
        }
    }
}
