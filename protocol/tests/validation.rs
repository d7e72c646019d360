//! Every rejection (and acceptance) of the message validation.

use thruster_protocol::validate::{
    expect_count, limits, Field, ImuSampleValidator, RejectCategory, RejectCounters,
    SequenceChecker, SequenceConfig, Stamp,
};
use thruster_protocol::*;

// ---- valid fixtures ------------------------------------------------------------------

fn imu() -> ImuSample {
    ImuSample {
        seq: 1,
        t_ns: 1_000_000,
        gyro: [0.01, -0.02, 0.003],
        accel: [0.1, -0.05, -9.81],
        mag: [20.0, -3.0, 45.0],
        depth: 2.5,
        flags: ImuSample::HAS_MAG | ImuSample::HAS_DEPTH,
    }
}

fn thrust(count: u32) -> ThrustCommand {
    let mut c = ThrustCommand::neutral(1, 1, 1_000_000, count);
    c.set_mode(ThrustMode::Controlling);
    for (i, t) in c.thrusters_mut().iter_mut().enumerate() {
        *t = 0.1 * i as f64 - 0.3;
    }
    c
}

fn reconfig() -> ReconfigEvent {
    let mut e = ReconfigEvent {
        seq: 1,
        thruster: 4,
        count: 5,
        has_geometry: 1,
        ..Default::default()
    };
    e.set_kind(ReconfigKind::ThrusterAdded);
    for i in 0..5 {
        e.position[i] = [0.2 * i as f64 - 0.4, 0.1, -0.05];
        e.direction[i] = [0.707, 0.707, 0.0];
    }
    e
}

fn model() -> ModelMsg {
    let mut m = ModelMsg {
        seq: 1,
        version: 1,
        count: 4,
        actuated: Dof::Roll.mask() | Dof::Yaw.mask() | Dof::Surge.mask(),
        rel_err_rot: 0.05,
        rel_err_acc: 0.2,
        ..Default::default()
    };
    m.set_source(ModelSource::Estimated);
    m.set_method(ModelMethod::Forward);
    for j in 0..4 {
        for d in 0..DOF_COUNT {
            m.effectiveness[d][j] = 0.5 * (d as f64 - 2.0) + j as f64 * 0.1;
            m.std_err[d][j] = 0.01;
        }
        for dof in [Dof::Roll, Dof::Yaw, Dof::Surge] {
            m.allocation[j][dof.index()] = 0.25;
        }
    }
    m
}

fn status() -> StatusMsg {
    let mut s = StatusMsg {
        seq: 3,
        pulse: 2,
        pulses_planned: 8,
        error_bound: 0.1,
        power: 0.5,
        sigma_rot: 0.25,
        sigma_acc: 0.49,
        imu_rate_hz: 400.0,
        ..Default::default()
    };
    s.set_state(DaemonState::Pulse);
    s.set_text("pulse 3 of 8");
    s
}

fn assert_rejects<T: Validate>(msg: &T, category: RejectCategory, text: &str) {
    let err = msg.validate().expect_err("message should be rejected");
    assert_eq!(err.category(), category, "wrong category for {err}");
    assert_eq!(err.to_string(), text);
}

// ---- IMU -----------------------------------------------------------------------------

#[test]
fn imu_valid_and_boundaries_accepted() {
    imu().validate().unwrap();
    let mut s = imu();
    s.gyro = [limits::MAX_GYRO_RAD_S, -limits::MAX_GYRO_RAD_S, 0.0];
    s.accel = [limits::MAX_ACCEL_M_S2, 0.0, -limits::MAX_ACCEL_M_S2];
    s.mag = [limits::MAX_MAG_UT, 0.0, -limits::MAX_MAG_UT];
    s.depth = limits::MIN_DEPTH_M;
    s.validate().unwrap();
    s.depth = limits::MAX_DEPTH_M;
    s.validate().unwrap();
    // No optional sensors: zeros and no flags are fine.
    let s = ImuSample {
        mag: [0.0; 3],
        depth: 0.0,
        flags: 0,
        ..imu()
    };
    s.validate().unwrap();
    assert!(!s.has_mag() && !s.has_depth());
}

#[test]
fn imu_nonfinite_rejected_with_field_name() {
    let mut s = imu();
    s.gyro[1] = f64::NAN;
    assert_rejects(&s, RejectCategory::NonFinite, "gyro[1] is NaN");
    let mut s = imu();
    s.accel[2] = f64::INFINITY;
    assert_rejects(&s, RejectCategory::NonFinite, "accel[2] is inf");
    let mut s = imu();
    s.mag[0] = f64::NEG_INFINITY;
    assert_rejects(&s, RejectCategory::NonFinite, "mag[0] is -inf");
    // Non-finite is rejected even when the sensor is flagged absent.
    let mut s = imu();
    s.flags = 0;
    s.depth = f64::NAN;
    assert_rejects(&s, RejectCategory::NonFinite, "depth is NaN");
}

#[test]
fn imu_out_of_range_rejected() {
    let mut s = imu();
    s.gyro[2] = 50.5;
    assert_rejects(
        &s,
        RejectCategory::Range,
        "gyro[2] = 50.5 rad/s is outside [-50, 50]",
    );
    let mut s = imu();
    s.accel[0] = -250.0;
    assert_rejects(
        &s,
        RejectCategory::Range,
        "accel[0] = -250 m/s^2 is outside [-200, 200]",
    );
    let mut s = imu();
    s.mag[1] = 6000.0;
    assert_rejects(
        &s,
        RejectCategory::Range,
        "mag[1] = 6000 uT is outside [-5000, 5000]",
    );
    let mut s = imu();
    s.depth = -10.5;
    assert_rejects(
        &s,
        RejectCategory::Range,
        "depth = -10.5 m is outside [-10, 11000]",
    );
    s.depth = 11000.5;
    assert_rejects(
        &s,
        RejectCategory::Range,
        "depth = 11000.5 m is outside [-10, 11000]",
    );
}

#[test]
fn imu_unknown_flags_rejected() {
    let mut s = imu();
    s.flags |= 1 << 7;
    assert_rejects(&s, RejectCategory::Other, "flags has unknown bits 0x80");
}

// ---- thrust --------------------------------------------------------------------------

#[test]
fn thrust_valid_accepted_and_unused_entries_ignored() {
    let mut c = thrust(6);
    c.validate().unwrap();
    c.thrust[6] = f64::NAN; // beyond count: never read
    c.thrust[15] = 7.0;
    c.validate().unwrap();
    ThrustCommand::neutral(1, 1, 1, 0).validate().unwrap();
    c.thrusters_mut()[0] = 1.0;
    c.thrusters_mut()[1] = -1.0;
    c.validate().unwrap();
    assert_eq!(c.thrusters().len(), 6);
}

#[test]
fn thrust_rejections() {
    let mut c = thrust(6);
    c.count = 17;
    assert_rejects(
        &c,
        RejectCategory::Count,
        "count = 17 exceeds MAX_THRUSTERS (16)",
    );
    // thrusters() must stay safe on an unvalidated message.
    assert_eq!(c.thrusters().len(), MAX_THRUSTERS);

    let mut c = thrust(6);
    c.mode = 3;
    assert_rejects(&c, RejectCategory::Other, "mode has unknown value 3");

    let mut c = thrust(6);
    c.thrust[2] = 1.5;
    assert_rejects(
        &c,
        RejectCategory::Range,
        "thrust[2] = 1.5 is outside [-1, 1]",
    );

    let mut c = thrust(6);
    c.thrust[5] = f64::NAN;
    assert_rejects(&c, RejectCategory::NonFinite, "thrust[5] is NaN");

    let err = expect_count("count", 6, 8).unwrap_err();
    assert_eq!(err.category(), RejectCategory::Count);
    assert_eq!(err.to_string(), "count = 6 but 8 thrusters are configured");
    expect_count("count", 8, 8).unwrap();
}

// ---- reconfig ------------------------------------------------------------------------

#[test]
fn reconfig_valid_accepted() {
    reconfig().validate().unwrap();
    // Without geometry, garbage in the geometry arrays is not read.
    let mut e = reconfig();
    e.has_geometry = 0;
    e.position[0][0] = f64::NAN;
    e.direction[1] = [5.0, 0.0, 0.0];
    e.validate().unwrap();
    // Removed: the index may equal the new count (it was the last thruster).
    let mut e = reconfig();
    e.set_kind(ReconfigKind::ThrusterRemoved);
    e.thruster = 5;
    e.validate().unwrap();
    // Unknown: the index is not used.
    let mut e = reconfig();
    e.set_kind(ReconfigKind::Unknown);
    e.thruster = 99;
    e.validate().unwrap();
}

#[test]
fn reconfig_rejections() {
    let mut e = reconfig();
    e.kind = 9;
    assert_rejects(&e, RejectCategory::Other, "kind has unknown value 9");

    let mut e = reconfig();
    e.count = 20;
    assert_rejects(
        &e,
        RejectCategory::Count,
        "count = 20 exceeds MAX_THRUSTERS (16)",
    );

    let mut e = reconfig();
    e.thruster = 5; // added thruster must be below the new count
    assert_rejects(
        &e,
        RejectCategory::Count,
        "thruster = 5 is not below the thruster count 5",
    );

    let mut e = reconfig();
    e.set_kind(ReconfigKind::ThrusterRemoved);
    e.thruster = 6;
    assert_rejects(
        &e,
        RejectCategory::Count,
        "thruster = 6 is not below the thruster count 6",
    );

    let mut e = reconfig();
    e.has_geometry = 2;
    assert_rejects(
        &e,
        RejectCategory::Other,
        "has_geometry = 2 is neither 0 nor 1",
    );

    let mut e = reconfig();
    e.direction[3] = [1.0, 1.0, 0.0];
    let err = e.validate().unwrap_err();
    assert_eq!(err.category(), RejectCategory::Range);
    assert!(
        err.to_string().starts_with("direction[3] has norm 1.414"),
        "{err}"
    );

    let mut e = reconfig();
    e.position[2][1] = 11.0;
    assert_rejects(
        &e,
        RejectCategory::Range,
        "position[2][1] = 11 m is outside [-10, 10]",
    );

    let mut e = reconfig();
    e.direction[4][2] = f64::NAN;
    assert_rejects(&e, RejectCategory::NonFinite, "direction[4][2] is NaN");
}

// ---- model ---------------------------------------------------------------------------

#[test]
fn model_valid_accepted_and_unused_columns_ignored() {
    let mut m = model();
    m.validate().unwrap();
    m.effectiveness[0][4] = f64::NAN; // column 4 >= count
    m.allocation[5] = [f64::NAN; DOF_COUNT];
    m.validate().unwrap();
    assert!(m.is_actuated(Dof::Yaw) && !m.is_actuated(Dof::Heave));
}

#[test]
fn model_rejections() {
    let mut m = model();
    m.count = 0;
    assert_rejects(
        &m,
        RejectCategory::Count,
        "count is 0 but at least one thruster is required",
    );
    m.count = 17;
    assert_rejects(
        &m,
        RejectCategory::Count,
        "count = 17 exceeds MAX_THRUSTERS (16)",
    );

    let mut m = model();
    m.source = 4;
    assert_rejects(&m, RejectCategory::Other, "source has unknown value 4");
    let mut m = model();
    m.method = 3;
    assert_rejects(&m, RejectCategory::Other, "method has unknown value 3");
    let mut m = model();
    m.actuated = 0x40;
    assert_rejects(&m, RejectCategory::Other, "actuated has unknown bits 0x40");

    let mut m = model();
    m.effectiveness[5][3] = f64::NAN;
    assert_rejects(&m, RejectCategory::NonFinite, "effectiveness[5][3] is NaN");
    let mut m = model();
    m.effectiveness[1][0] = 2e3;
    assert_rejects(
        &m,
        RejectCategory::Range,
        "effectiveness[1][0] = 2000 per unit command is outside [-1000, 1000]",
    );
    let mut m = model();
    m.allocation[2][0] = f64::INFINITY;
    assert_rejects(&m, RejectCategory::NonFinite, "allocation[2][0] is inf");
    let mut m = model();
    m.std_err[0][1] = -0.1;
    assert_rejects(
        &m,
        RejectCategory::Range,
        "std_err[0][1] = -0.1 per unit command is outside [0, 1000]",
    );
    let mut m = model();
    m.rel_err_acc = f64::INFINITY;
    assert_rejects(&m, RejectCategory::NonFinite, "rel_err_acc is inf");

    // Heave is not actuated: the allocation must never command it.
    let mut m = model();
    m.allocation[1][Dof::Heave.index()] = 0.3;
    assert_rejects(
        &m,
        RejectCategory::Other,
        "allocation[1][5]: commands a DOF that is not actuated",
    );
}

// ---- truth, status, setpoint -----------------------------------------------------------

#[test]
fn truth_validation() {
    let mut t = TruthMsg {
        count: 3,
        ..Default::default()
    };
    t.effectiveness[2][1] = 1.5;
    t.reverse_effectiveness[2][1] = 1.1;
    t.validate().unwrap();
    t.reverse_effectiveness[4][2] = f64::NEG_INFINITY;
    assert_rejects(
        &t,
        RejectCategory::NonFinite,
        "reverse_effectiveness[4][2] is -inf",
    );
    t.count = 99;
    assert_rejects(
        &t,
        RejectCategory::Count,
        "count = 99 exceeds MAX_THRUSTERS (16)",
    );
}

#[test]
fn supply_fields_validation() {
    // A driver that cannot measure its supply says NaN (the default), and that passes.
    let mut d = DriverStatusMsg::default();
    assert!(d.supply_voltage().is_none() && d.supply_current().is_none());
    d.validate().unwrap();
    d.supply_voltage_v = 15.2;
    d.supply_current_a = -3.0;
    d.validate().unwrap();
    assert_eq!(d.supply_voltage(), Some(15.2));
    d.supply_voltage_v = f64::INFINITY;
    assert_rejects(&d, RejectCategory::NonFinite, "supply_voltage_v is inf");
    d.supply_voltage_v = 150.0;
    assert_rejects(
        &d,
        RejectCategory::Range,
        "supply_voltage_v = 150 V is outside [0, 100]",
    );
    d.supply_voltage_v = f64::NAN;
    d.supply_current_a = 2000.0;
    assert_rejects(
        &d,
        RejectCategory::Range,
        "supply_current_a = 2000 A is outside [-1000, 1000]",
    );
    // The truth's voltage is always known; its battery flag is 0 or 1.
    let mut t = TruthMsg {
        count: 1,
        supply_voltage_v: 16.0,
        battery: 1,
        ..Default::default()
    };
    t.validate().unwrap();
    t.supply_voltage_v = f64::NAN;
    assert_rejects(&t, RejectCategory::NonFinite, "supply_voltage_v is NaN");
    t.supply_voltage_v = 16.0;
    t.battery = 2;
    assert!(t.validate().is_err());
    // The status's voltage may be unknown; its compensation state must be known.
    let mut s = status();
    s.supply_voltage_v = f64::NAN;
    s.validate().unwrap();
    s.supply_compensation = 3;
    assert_rejects(
        &s,
        RejectCategory::Other,
        "supply_compensation has unknown value 3",
    );
}

#[test]
fn status_validation() {
    status().validate().unwrap();
    let mut s = status();
    s.state = 8;
    assert_rejects(&s, RejectCategory::Other, "state has unknown value 8");
    let mut s = status();
    s.power = 1.5;
    assert_rejects(&s, RejectCategory::Range, "power = 1.5 is outside [0, 1]");
    let mut s = status();
    s.sigma_rot = -0.1;
    assert_rejects(
        &s,
        RejectCategory::Range,
        "sigma_rot = -0.1 rad/s is outside [0, 50]",
    );
    // NaN means "not known yet" and passes; infinity never does.
    let mut s = status();
    s.error_bound = f64::NAN;
    s.sigma_rot = f64::NAN;
    s.validate().unwrap();
    s.error_bound = f64::INFINITY;
    assert_rejects(&s, RejectCategory::NonFinite, "error_bound is inf");
    let mut s = status();
    s.text.as_bytes_mut()[0] = 0xff;
    assert_rejects(&s, RejectCategory::Other, "text is not valid UTF-8");
}

// ---- telemetry -----------------------------------------------------------------------

/// Controlling at a 10 deg pitch setpoint, 2 m depth held, 5 thrusters, mid-way through nothing.
fn telemetry() -> TelemetryMsg {
    let pitch = 10f64.to_radians();
    let mut t = TelemetryMsg {
        seq: 7,
        t_ns: 12_000_000_000,
        imu_seq: 2400,
        flags: TelemetryMsg::HAS_SETPOINT
            | TelemetryMsg::HOLD_DEPTH
            | TelemetryMsg::HAS_DEPTH
            | TelemetryMsg::HAS_NOISE,
        count: 5,
        model_version: 1,
        attitude: [1.0, 0.0, 0.0, 0.0],
        rate: [0.01, -0.02, 0.0],
        depth: 2.1,
        setpoint_attitude: [(pitch / 2.0).cos(), 0.0, (pitch / 2.0).sin(), 0.0],
        setpoint_euler: [0.0, pitch, 0.0],
        setpoint_depth: 2.0,
        attitude_error: [0.0, pitch, 0.0],
        attitude_error_angle: pitch,
        depth_error: -0.1,
        sigma_rot: 0.25,
        sigma_acc: 0.49,
        ..TelemetryMsg::default()
    };
    t.set_state(DaemonState::Active);
    t.set_mode(ThrustMode::Controlling);
    t.thrust[..5].copy_from_slice(&[0.3, -0.3, 1.0, -1.0, 0.0]);
    t
}

#[test]
fn telemetry_valid_accepted_and_unused_entries_ignored() {
    telemetry().validate().unwrap();
    TelemetryMsg::default().validate().unwrap();
    // Beyond `count` nothing is read, so nothing is checked.
    let mut t = telemetry();
    t.thrust[5] = f64::NAN;
    t.validate().unwrap();
    // Angles computed in f64 may sit on pi itself.
    let mut t = telemetry();
    t.euler = [std::f64::consts::PI, 0.0, -std::f64::consts::PI];
    t.attitude_error_angle = std::f64::consts::PI;
    t.validate().unwrap();
    // Without a setpoint its quaternion is not read as one (zeros are tolerated), but it
    // must still be finite: a recorder logs every field.
    let mut t = telemetry();
    t.flags &= !TelemetryMsg::HAS_SETPOINT;
    t.setpoint_attitude = [0.0; 4];
    t.validate().unwrap();
    t.setpoint_attitude[2] = f64::INFINITY;
    assert_rejects(&t, RejectCategory::NonFinite, "setpoint_attitude[2] is inf");
}

#[test]
fn telemetry_rejections() {
    type Mutation = fn(&mut TelemetryMsg);
    let cases: Vec<(Mutation, RejectCategory, &str)> = vec![
        (
            |t| t.state = 99,
            RejectCategory::Other,
            "state has unknown value 99",
        ),
        (
            |t| t.mode = 3,
            RejectCategory::Other,
            "mode has unknown value 3",
        ),
        (
            |t| t.flags |= 1 << 40,
            RejectCategory::Other,
            "flags has unknown bits 0x10000000000",
        ),
        (
            |t| t.count = 17,
            RejectCategory::Count,
            "count = 17 exceeds MAX_THRUSTERS (16)",
        ),
        (
            |t| t.attitude[1] = f64::NAN,
            RejectCategory::NonFinite,
            "attitude[1] is NaN",
        ),
        (
            |t| t.attitude = [0.9, 0.0, 0.0, 0.0],
            RejectCategory::Range,
            "attitude has norm 0.9, expected 1 within 0.001",
        ),
        (
            |t| t.setpoint_attitude = [0.5, 0.5, 0.0, 0.0],
            RejectCategory::Range,
            "setpoint_attitude has norm 0.7071067811865476, expected 1 within 0.001",
        ),
        (
            |t| t.euler[1] = 2.0,
            RejectCategory::Range,
            "euler[1] = 2 rad is outside [-1.5707963277948966, 1.5707963277948966]",
        ),
        (
            |t| t.setpoint_euler[2] = f64::NEG_INFINITY,
            RejectCategory::NonFinite,
            "setpoint_euler[2] is -inf",
        ),
        (
            |t| t.rate[2] = 60.0,
            RejectCategory::Range,
            "rate[2] = 60 rad/s is outside [-50, 50]",
        ),
        (
            |t| t.depth = f64::NAN,
            RejectCategory::NonFinite,
            "depth is NaN",
        ),
        (
            |t| t.attitude_error_angle = -0.1,
            RejectCategory::Range,
            "attitude_error_angle = -0.1 rad is outside [0, 3.141592654589793]",
        ),
        (
            |t| t.attitude_error[0] = f64::NAN,
            RejectCategory::NonFinite,
            "attitude_error[0] is NaN",
        ),
        (
            |t| t.depth_error = f64::INFINITY,
            RejectCategory::NonFinite,
            "depth_error is inf",
        ),
        (
            |t| t.thrust[4] = 1.5,
            RejectCategory::Range,
            "thrust[4] = 1.5 is outside [-1, 1]",
        ),
        (
            |t| t.thrust[0] = f64::NAN,
            RejectCategory::NonFinite,
            "thrust[0] is NaN",
        ),
        (
            |t| t.power = 1.5,
            RejectCategory::Range,
            "power = 1.5 is outside [0, 1]",
        ),
        (
            |t| t.error_bound = f64::NAN,
            RejectCategory::NonFinite,
            "error_bound is NaN",
        ),
        (
            |t| t.sigma_acc = -1.0,
            RejectCategory::Range,
            "sigma_acc = -1 m/s^2 is outside [0, 200]",
        ),
    ];
    for (mutate, category, text) in cases {
        let mut t = telemetry();
        mutate(&mut t);
        assert_rejects(&t, category, text);
    }
}

#[test]
fn status_text_truncates_at_char_boundary() {
    let mut s = StatusMsg::default();
    // 127 ASCII bytes then a 2-byte char: the char does not fit in 128 bytes.
    let long = format!("{}é and more", "x".repeat(127));
    s.set_text(&long);
    assert_eq!(s.text(), format!("{}...", "x".repeat(125)));
    // Issue 27: a refusal cut mid-word ("estimate af"). Cut at a word, marked as cut.
    let words = "in fault (the driver reports that its outputs cannot be used: the link has been \
                 down for 2.0 s, thrusters neutral); estimate after it clears";
    assert!(words.len() > 128);
    s.set_text(words);
    let got = s.text();
    let kept = got
        .strip_suffix("...")
        .unwrap_or_else(|| panic!("no ellipsis: {got}"));
    assert!(got.len() <= 128, "{got}");
    assert!(words.starts_with(kept), "{got}");
    assert!(words[kept.len()..].starts_with(' '), "cut mid-word: {got}");
    assert_eq!(got, "in fault (the driver reports that its outputs cannot be used: the link has been down for 2.0 s, thrusters neutral); estimate...");
    s.set_text("fault: IMU stale for 120 ms");
    assert_eq!(s.text(), "fault: IMU stale for 120 ms");
}

#[test]
fn setpoint_validation() {
    Setpoint::default().validate().unwrap();
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let mut p = Setpoint {
        attitude: [h, 0.0, 0.0, h],
        depth: 3.0,
        flags: Setpoint::HOLD_DEPTH,
        ..Default::default()
    };
    p.validate().unwrap();
    assert!(p.hold_depth());
    p.attitude = [1.0, 1.0, 0.0, 0.0];
    let err = p.validate().unwrap_err();
    assert_eq!(err.category(), RejectCategory::Range);
    assert!(
        err.to_string().starts_with("attitude has norm 1.414"),
        "{err}"
    );
    p.attitude = [f64::NAN, 0.0, 0.0, 0.0];
    assert_rejects(&p, RejectCategory::NonFinite, "attitude[0] is NaN");
    let p = Setpoint {
        depth: 12000.0,
        ..Default::default()
    };
    assert_rejects(
        &p,
        RejectCategory::Range,
        "depth = 12000 m is outside [-10, 11000]",
    );
    let p = Setpoint {
        flags: 1 << 5,
        ..Default::default()
    };
    assert_rejects(&p, RejectCategory::Other, "flags has unknown bits 0x20");
    // Hold and release at once is a contradiction, refused rather than guessed.
    let p = Setpoint {
        flags: Setpoint::HOLD_DEPTH | Setpoint::RELEASE_DEPTH,
        ..Default::default()
    };
    assert_rejects(
        &p,
        RejectCategory::Other,
        "flags: HOLD_DEPTH and RELEASE_DEPTH together",
    );
    let p = Setpoint {
        flags: Setpoint::RELEASE_DEPTH,
        ..Default::default()
    };
    p.validate().unwrap();
    assert!(p.release_depth() && !p.hold_depth());
}

// ---- control ---------------------------------------------------------------------------

#[test]
fn control_request_validation() {
    ControlRequest::new(RequestKind::Abort).validate().unwrap();
    ControlRequest::with_value(RequestKind::Estimate, 0.4)
        .validate()
        .unwrap();
    ControlRequest::with_text(RequestKind::Save, "/var/lib/thrusterd/m.json")
        .validate()
        .unwrap();
    // The value is only a power for Estimate.
    ControlRequest::with_value(RequestKind::Status, 2.0)
        .validate()
        .unwrap();

    let mut r = ControlRequest::new(RequestKind::Status);
    r.kind = 99;
    assert_rejects(&r, RejectCategory::Other, "kind has unknown value 99");
    let mut r = ControlRequest::new(RequestKind::Status);
    r.flags = 1;
    assert_rejects(&r, RejectCategory::Other, "flags has unknown bits 0x1");
    let r = ControlRequest::with_value(RequestKind::Hold, f64::NAN);
    assert_rejects(&r, RejectCategory::NonFinite, "value is NaN");
    let r = ControlRequest::with_value(RequestKind::Estimate, 2.0);
    assert_rejects(&r, RejectCategory::Range, "value = 2 is outside [0, 1]");
}

#[test]
fn control_response_validation() {
    let ok = ControlResponse::ok("estimating");
    ok.validate().unwrap();
    assert!(ok.is_ok());
    let rejected = ControlResponse::new(ResponseCode::Rejected, "no model");
    rejected.validate().unwrap();
    assert!(!rejected.is_ok());
    assert_eq!(rejected.ok, 0);

    let mut r = rejected;
    r.ok = 1;
    assert_rejects(&r, RejectCategory::Other, "ok: disagrees with code");
    r.ok = 2;
    assert_rejects(&r, RejectCategory::Other, "ok = 2 is neither 0 nor 1");
    let mut r = ok;
    r.code = 42;
    assert_rejects(&r, RejectCategory::Other, "code has unknown value 42");
}

// ---- enums, fields, counters -----------------------------------------------------------

#[test]
fn enums_round_trip_and_reject_unknown_values() {
    fn check<E>(all: &[E], first_unknown: u32)
    where
        E: Copy + PartialEq + std::fmt::Debug + TryFrom<u32> + Into<u32>,
        <E as TryFrom<u32>>::Error: std::fmt::Debug,
    {
        for (i, &v) in all.iter().enumerate() {
            let raw: u32 = v.into();
            assert_eq!(raw, i as u32, "wire values are dense from 0");
            assert_eq!(E::try_from(raw).unwrap(), v);
        }
        assert!(E::try_from(first_unknown).is_err());
        assert!(E::try_from(u32::MAX).is_err());
    }
    check(ThrustMode::ALL, 3);
    check(ReconfigKind::ALL, 4);
    check(ModelSource::ALL, 4);
    check(ModelMethod::ALL, 3);
    check(DaemonState::ALL, 8);
    check(RequestKind::ALL, 10);
    check(ResponseCode::ALL, 6);
    check(Dof::ALL, 6);
    let err = DaemonState::try_from(9).unwrap_err();
    assert_eq!(err.to_string(), "DaemonState has no variant with value 9");
    assert_eq!(DaemonState::MeasureNoise.to_string(), "MeasureNoise");
    // Zeroed memory decodes to the safe variant.
    assert_eq!(ThrustMode::try_from(0).unwrap(), ThrustMode::Neutral);
    assert_eq!(DaemonState::try_from(0).unwrap(), DaemonState::Idle);
}

#[test]
fn field_display() {
    assert_eq!(Field::new("depth").to_string(), "depth");
    assert_eq!(Field::at("gyro", 1).to_string(), "gyro[1]");
    assert_eq!(Field::at2("position", 3, 2).to_string(), "position[3][2]");
}

#[test]
fn counters_map_onto_status_fields() {
    let mut counters = RejectCounters::default();
    let mut bad = imu();
    bad.gyro[0] = f64::NAN;
    counters.record(&bad.validate().unwrap_err());
    bad.gyro[0] = 99.0;
    counters.record(&bad.validate().unwrap_err());
    counters.record(&bad.validate().unwrap_err());
    let mut c = thrust(4);
    c.count = 40;
    counters.record(&c.validate().unwrap_err());
    c.count = 4;
    c.mode = 77;
    counters.record(&c.validate().unwrap_err());
    let mut seq = SequenceChecker::default();
    seq.check(Stamp { seq: 5, t_ns: 100 }).unwrap();
    counters.record(&seq.check(Stamp { seq: 5, t_ns: 200 }).unwrap_err());

    assert_eq!(
        counters,
        RejectCounters {
            nonfinite: 1,
            range: 2,
            time: 1,
            count: 1,
            other: 1
        }
    );
    assert_eq!(counters.total(), 6);
    let mut s = StatusMsg::default();
    counters.write_to(&mut s);
    assert_eq!(
        (
            s.rejected_nonfinite,
            s.rejected_range,
            s.rejected_time,
            s.rejected_count,
            s.rejected_other
        ),
        (1, 2, 1, 1, 1)
    );
}

// ---- sequence --------------------------------------------------------------------------

const MS: u64 = 1_000_000;

fn st(seq: u64, t_ms: u64) -> Stamp {
    Stamp {
        seq,
        t_ns: t_ms * MS,
    }
}

#[test]
fn sequence_accepts_order_and_reports_gaps() {
    let mut c = SequenceChecker::default();
    assert_eq!(c.check(st(10, 100)).unwrap().missed, 0);
    assert_eq!(c.check(st(11, 102)).unwrap().missed, 0);
    let a = c.check(st(15, 112)).unwrap();
    assert_eq!(a.missed, 3);
    assert!(!a.resynced);
    assert_eq!(c.last(), Some(st(15, 112)));
}

#[test]
fn sequence_rejects_duplicates_backwards_and_jumps() {
    let mut c = SequenceChecker::default();
    c.check(st(10, 100)).unwrap();

    let e = c.check(st(10, 105)).unwrap_err();
    assert_eq!(e.to_string(), "seq 10 duplicates the previous message");
    assert_eq!(e.category(), RejectCategory::Time);

    let e = c.check(st(9, 105)).unwrap_err();
    assert_eq!(e.to_string(), "seq 9 is before the previous message's 10");

    let e = c.check(st(11, 100)).unwrap_err();
    assert_eq!(
        e.to_string(),
        "t_ns 100000000 is not after the previous message's 100000000"
    );
    let e = c.check(st(11, 90)).unwrap_err();
    assert!(matches!(e, RejectReason::TimeBackwards { .. }));

    let e = c.check(st(11, 1101)).unwrap_err();
    assert_eq!(
        e.to_string(),
        "t_ns jumped 1001000000 ns ahead, more than the maximum 1000000000 ns"
    );
    assert_eq!(c.consecutive_rejections(), 5);

    // None of the rejected stamps moved the reference: the next good sample passes.
    let a = c.check(st(11, 102)).unwrap();
    assert_eq!(a.missed, 0);
    assert_eq!(c.consecutive_rejections(), 0);
}

#[test]
fn sequence_ignores_a_single_corrupt_future_timestamp() {
    let mut c = SequenceChecker::default();
    c.check(st(1, 100)).unwrap();
    assert!(c.check(st(2, 9_999_999)).is_err());
    // Good samples continue from the last accepted one, not from the corrupt one.
    for i in 3..10 {
        let a = c.check(st(i, 100 + i)).unwrap();
        assert!(!a.resynced);
    }
}

#[test]
fn sequence_resyncs_to_a_restarted_stream() {
    let mut c = SequenceChecker::new(SequenceConfig {
        max_time_jump_ns: 50 * MS,
        resync_after: 3,
    });
    c.check(st(500, 10_000)).unwrap();
    c.check(st(501, 10_002)).unwrap();
    // Driver restarted: seq and time start again from 0.
    assert!(c.check(st(0, 0)).is_err());
    assert!(c.check(st(1, 2)).is_err());
    let a = c.check(st(2, 4)).unwrap();
    assert!(a.resynced);
    assert_eq!(c.last(), Some(st(2, 4)));
    assert!(!c.check(st(3, 6)).unwrap().resynced);

    // A dropout longer than the maximum jump also resyncs after three samples.
    assert!(c.check(st(4, 1_000)).is_err());
    assert!(c.check(st(5, 1_002)).is_err());
    assert!(c.check(st(6, 1_004)).unwrap().resynced);

    // Out-of-order garbage that is not self-consistent never resyncs.
    let mut c = SequenceChecker::new(SequenceConfig {
        max_time_jump_ns: 50 * MS,
        resync_after: 3,
    });
    c.check(st(100, 1_000)).unwrap();
    for (s, t) in [(3, 5), (2, 900), (7, 1), (1, 2), (0, 0), (5, 3)] {
        assert!(c.check(st(s, t)).is_err(), "({s}, {t}) accepted");
    }
    assert_eq!(c.consecutive_rejections(), 6);
}

#[test]
fn sequence_resync_after_is_at_least_two_and_reset_works() {
    let mut c = SequenceChecker::new(SequenceConfig {
        max_time_jump_ns: MS,
        resync_after: 0,
    });
    assert_eq!(c.config().resync_after, 2);
    c.check(st(5, 5)).unwrap();
    assert!(
        c.check(st(4, 4)).is_err(),
        "one backwards sample must still be rejected"
    );
    c.reset();
    assert_eq!(c.last(), None);
    c.check(st(1, 1)).unwrap();
}

#[test]
fn imu_validator_checks_content_before_order() {
    let mut v = ImuSampleValidator::default();
    let mut s = imu();
    v.check(&s).unwrap();
    s.seq = 2;
    s.t_ns += 2_500_000;
    s.gyro[0] = f64::NAN;
    assert!(matches!(v.check(&s), Err(RejectReason::NonFinite { .. })));
    // The corrupt sample did not advance the stream: the same seq, fixed, is accepted.
    s.gyro[0] = 0.0;
    assert_eq!(v.check(&s).unwrap().missed, 0);
    assert!(matches!(
        v.check(&s),
        Err(RejectReason::DuplicateSeq { seq: 2 })
    ));
}

// ---- sanitize --------------------------------------------------------------------------

#[test]
fn sanitize_thrust_zeroes_nonfinite_and_clamps() {
    let mut t = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        1.5,
        -2.0,
        0.3,
        -0.0,
        1.0,
        -1.0,
    ];
    let changed = sanitize_thrust(&mut t);
    assert_eq!(changed, 5);
    assert_eq!(&t[..6], &[0.0, 0.0, 0.0, 1.0, -1.0, 0.3]);
    assert!(t[6] == 0.0 && t[6].is_sign_negative());
    assert_eq!(&t[7..], &[1.0, -1.0]);
    assert_eq!(sanitize_thrust(&mut t), 0);
}
