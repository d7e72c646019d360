//! Bad input, with real processes (issue 7): every kind of garbage a neighbour can send the
//! daemon (IMU samples, reconfiguration events, setpoints, operator requests), bad files
//! (config, saved model) and thrust commands a driver must refuse. Each is injected by the
//! test over the real iceoryx2 services; each must raise its own status counter (and only
//! that one), the daemon must keep serving (status keeps coming, a valid request still
//! works) and every thrust command it emits must be finite and in [-1, 1].
//! Each test has its own namespace, reaps every child and checks nothing is left behind.

use std::time::{Duration, Instant};

use system_tests::{state, Operator, Proc, World};
use thruster_protocol::services::{Inbox, Port};
use thruster_protocol::{
    ControlRequest, DaemonState, ImuSample, ReconfigEvent, ReconfigKind, RequestKind, ResponseCode,
    Setpoint, StatusMsg, ThrustCommand, ThrustMode,
};

const THRUSTERS: u32 = 4;
const PERIOD_NS: u64 = 5_000_000;

/// The status counters this file checks, in one comparable value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct Counters {
    nonfinite: u64,
    range: u64,
    time: u64,
    count: u64,
    other: u64,
    refused: u64,
}

impl Counters {
    fn of(s: &StatusMsg) -> Self {
        Counters {
            nonfinite: s.rejected_nonfinite,
            range: s.rejected_range,
            time: s.rejected_time,
            count: s.rejected_count,
            other: s.rejected_other,
            refused: u64::from(s.requests_refused),
        }
    }
}

/// Which counter a bad input must raise.
#[derive(Debug, Clone, Copy)]
enum Counter {
    NonFinite,
    Range,
    Time,
    Count,
    Other,
    Refused,
}

impl Counters {
    fn plus(mut self, which: Counter, n: u64) -> Self {
        let c = match which {
            Counter::NonFinite => &mut self.nonfinite,
            Counter::Range => &mut self.range,
            Counter::Time => &mut self.time,
            Counter::Count => &mut self.count,
            Counter::Other => &mut self.other,
            Counter::Refused => &mut self.refused,
        };
        *c += n;
        self
    }
}

/// The test is the driver: it publishes IMU samples (5 ms apart in vehicle time, paced in
/// wall time so the daemon's 100 ms IMU watchdog never fires) and checks every answer.
struct Driver {
    imu: Port<ImuSample>,
    thrust: Inbox<ThrustCommand>,
    seq: u64,
    t_ns: u64,
    answers: Vec<ThrustCommand>,
}

impl Driver {
    fn new(world: &World) -> Self {
        Driver {
            imu: Port::create(world.node(), world.ipc()).unwrap(),
            thrust: Inbox::create(world.node(), world.ipc()).unwrap(),
            seq: 0,
            t_ns: 1_000_000_000,
            answers: Vec::new(),
        }
    }

    /// The next good sample (vehicle at rest, a little noise).
    fn next(&mut self) -> ImuSample {
        self.seq += 1;
        self.t_ns += PERIOD_NS;
        ImuSample {
            seq: self.seq,
            t_ns: self.t_ns,
            gyro: [0.001 * (self.seq % 7) as f64, -0.002, 0.0015],
            accel: [0.01 * (self.seq % 3) as f64, 0.0, -9.80665],
            mag: [20.0, 0.0, 45.0],
            depth: 5.0,
            flags: ImuSample::HAS_MAG | ImuSample::HAS_DEPTH,
        }
    }

    fn send(&mut self, s: &ImuSample) {
        self.imu.send(s).unwrap();
        std::thread::sleep(Duration::from_millis(5));
        self.drain();
    }

    /// Good samples for `secs` of wall time.
    fn pump(&mut self, secs: f64) {
        let start = Instant::now();
        while start.elapsed().as_secs_f64() < secs {
            let s = self.next();
            self.send(&s);
        }
    }

    /// Collects the daemon's answers; nothing non-finite or out of range, ever.
    fn drain(&mut self) {
        while let Some(c) = self.thrust.recv().unwrap() {
            assert_eq!(c.count, THRUSTERS, "thrust count {c:?}");
            for v in c.thrusters() {
                assert!(v.is_finite() && v.abs() <= 1.0, "thrust {v} in {c:?}");
            }
            self.answers.push(c);
        }
    }

    /// Pumps good samples until a status satisfies `pred`.
    fn until_status(
        &mut self,
        op: &Operator,
        timeout: Duration,
        pred: impl Fn(&StatusMsg) -> bool,
    ) -> Option<StatusMsg> {
        let start = Instant::now();
        while start.elapsed() < timeout {
            while let Some(s) = op.status.recv().unwrap() {
                if pred(&s) {
                    return Some(s);
                }
            }
            let s = self.next();
            self.send(&s);
        }
        None
    }

    /// The counters of a status published after this call (pumping meanwhile).
    fn counters_now(&mut self, op: &Operator) -> Counters {
        while op.status.recv().unwrap().is_some() {}
        let first = self
            .until_status(op, Duration::from_secs(5), |_| true)
            .expect("status keeps coming");
        // One more, so the snapshot is not one the daemon wrote before our last input.
        let s = self
            .until_status(op, Duration::from_secs(5), |s| s.seq > first.seq)
            .expect("status keeps coming");
        Counters::of(&s)
    }

    /// `inject` sends one kind of bad input; afterwards exactly `which` has risen by `n`, the
    /// daemon is still accepting good samples, and the answers stayed safe.
    fn expect_counted(
        &mut self,
        op: &Operator,
        daemon: &Proc,
        what: &str,
        which: Counter,
        n: u64,
        inject: impl FnOnce(&mut Driver),
    ) {
        let before = self.counters_now(op);
        let samples_before = self
            .until_status(op, Duration::from_secs(5), |_| true)
            .expect("status")
            .samples;
        inject(self);
        let want = before.plus(which, n);
        let got = self.until_status(op, Duration::from_secs(5), |s| {
            Counters::of(s) == want && s.samples > samples_before + 5
        });
        assert!(
            got.is_some(),
            "{what}: expected {which:?} +{n}: {want:?}, last {:?}\n{}",
            self.counters_now(op),
            daemon.log_text()
        );
    }
}

#[test]
fn bad_imu_samples_each_raise_their_counter_and_the_daemon_keeps_serving() {
    let world = World::new("badimu");
    {
        let op = Operator::new(&world);
        let mut daemon = world.daemon(&["--thrusters", "4"]);
        let mut d = Driver::new(&world);
        d.until_status(&op, Duration::from_secs(30), |s| s.samples > 20)
            .unwrap_or_else(|| panic!("daemon not serving\n{}", daemon.log_text()));
        // Estimating, so the daemon is pulsing (non-zero commands) while garbage arrives.
        assert!(op.request(RequestKind::Estimate).is_ok());
        d.until_status(&op, Duration::from_secs(10), |s| {
            state(s) == DaemonState::Pulse
        })
        .unwrap_or_else(|| panic!("no pulse\n{}", daemon.log_text()));

        type Edit = fn(&mut ImuSample);
        let single: [(&str, Counter, Edit); 11] = [
            ("gyro NaN", Counter::NonFinite, |s| s.gyro[1] = f64::NAN),
            ("accel +inf", Counter::NonFinite, |s| {
                s.accel[0] = f64::INFINITY
            }),
            ("depth -inf", Counter::NonFinite, |s| {
                s.depth = f64::NEG_INFINITY
            }),
            ("mag NaN (flag unset)", Counter::NonFinite, |s| {
                s.flags = 0;
                s.mag[2] = f64::NAN;
            }),
            ("accel 1e9 m/s^2", Counter::Range, |s| s.accel[2] = 1e9),
            ("gyro 51 rad/s", Counter::Range, |s| s.gyro[0] = 51.0),
            ("mag 1e6 uT", Counter::Range, |s| s.mag[1] = 1e6),
            ("depth -100 m", Counter::Range, |s| s.depth = -100.0),
            ("time 1 s backwards", Counter::Time, |s| {
                s.t_ns -= 1_000_000_000
            }),
            ("time 10 s ahead", Counter::Time, |s| {
                s.t_ns += 10_000_000_000
            }),
            ("unknown flag bits", Counter::Other, |s| s.flags |= 1 << 7),
        ];
        for (what, which, edit) in single {
            d.expect_counted(&op, &daemon, what, which, 1, |d| {
                let mut bad = d.next();
                edit(&mut bad);
                d.send(&bad);
                d.pump(0.05);
                // The answer to a rejected sample is neutral: garbage never keeps a pulse on.
                let answer = d
                    .answers
                    .iter()
                    .rev()
                    .find(|c| c.imu_seq == bad.seq)
                    .unwrap_or_else(|| panic!("{what}: rejected sample not answered"));
                assert_eq!(answer.mode(), Ok(ThrustMode::Neutral), "{what}");
                assert!(answer.thrusters().iter().all(|v| *v == 0.0), "{what}");
            });
        }
        d.expect_counted(&op, &daemon, "duplicated seq", Counter::Time, 1, |d| {
            let s = d.next();
            d.send(&s);
            let mut dup = s;
            dup.t_ns += PERIOD_NS / 2;
            d.send(&dup);
            d.t_ns = dup.t_ns;
        });
        d.expect_counted(&op, &daemon, "seq backwards", Counter::Time, 1, |d| {
            let mut back = d.next();
            back.seq -= 10;
            d.send(&back);
        });
        d.expect_counted(&op, &daemon, "same time twice", Counter::Time, 1, |d| {
            let s = d.next();
            d.send(&s);
            let mut same = d.next();
            same.t_ns = s.t_ns;
            d.send(&same);
        });
        // Samples lost on the way (a sequence gap) are not bad input but must not go
        // unnoticed either: status counts them.
        let missed_before = d
            .until_status(&op, Duration::from_secs(5), |_| true)
            .expect("status")
            .samples_missed;
        d.seq += 7;
        d.t_ns += 7 * PERIOD_NS;
        let s = d
            .until_status(&op, Duration::from_secs(5), |s| {
                s.samples_missed > missed_before
            })
            .expect("a gap of 7 samples is counted in status");
        assert_eq!(s.samples_missed, missed_before + 7);

        // Still serving: estimating on, answering, a request works.
        assert!(daemon.is_running());
        let r = op.request(RequestKind::Status);
        assert!(r.is_ok(), "{}", r.text());
        // Garbage never faults the daemon. (A stale-IMU fault can happen when this test
        // process is descheduled for over 100 ms on a loaded machine: that is the watchdog
        // doing its job, not a reaction to bad input, and recovery follows.)
        let log = daemon.log_text();
        for line in log.lines().filter(|l| l.contains("-> fault")) {
            assert!(
                line.contains("no IMU sample for"),
                "fault on bad input: {line}"
            );
        }
        assert!(
            d.answers
                .iter()
                .any(|c| c.mode() == Ok(ThrustMode::Estimating)
                    && c.thrusters().iter().any(|v| *v != 0.0)),
            "pulses went out between the garbage"
        );
        assert!(d.answers.len() > 300, "answers {}", d.answers.len());
        assert!(daemon.stop().success(), "{}", daemon.log_text());
        let log = daemon.log_text();
        for reason in [
            "gyro[1] is NaN",
            "accel[2] = 1000000000 m/s^2 is outside",
            "is not after the previous message",
            "ns ahead, more than the maximum 1000000000 ns",
            "duplicates the previous message",
            "flags has unknown bits 0x80",
        ] {
            assert!(log.contains(reason), "no {reason:?} in the log\n{log}");
        }
    }
    world.assert_nothing_left();
}

#[test]
fn bad_reconfig_events_setpoints_and_requests_are_counted_and_refused() {
    let world = World::new("badctl");
    // Files for Load requests: truncated, future version, missing.
    let real = std::fs::read_to_string(
        system_tests::workspace().join("fuzz/corpus/model_parse/model.json"),
    )
    .unwrap();
    let truncated = world.path("truncated.json");
    std::fs::write(&truncated, &real[..real.len() / 3]).unwrap();
    let future = world.path("future.json");
    std::fs::write(
        &future,
        real.replacen("\"format_version\": 1", "\"format_version\": 7", 1),
    )
    .unwrap();
    {
        let op = Operator::new(&world);
        let mut daemon = world.daemon(&["--thrusters", "4"]);
        let mut d = Driver::new(&world);
        let reconfig: Port<ReconfigEvent> = Port::create(world.node(), world.ipc()).unwrap();
        let setpoint: Port<Setpoint> = Port::create(world.node(), world.ipc()).unwrap();
        d.until_status(&op, Duration::from_secs(30), |s| s.samples > 20)
            .unwrap_or_else(|| panic!("daemon not serving\n{}", daemon.log_text()));

        // Reconfiguration events.
        let event = |kind: ReconfigKind, thruster: u32, count: u32| {
            let mut e = ReconfigEvent {
                thruster,
                count,
                ..ReconfigEvent::default()
            };
            e.set_kind(kind);
            e
        };
        let with_geometry = |edit: fn(&mut ReconfigEvent)| {
            let mut e = event(ReconfigKind::ThrusterMoved, 1, THRUSTERS);
            e.has_geometry = 1;
            let n = THRUSTERS as usize;
            for (i, p) in e.position[..n].iter_mut().enumerate() {
                *p = [0.1 * i as f64, 0.0, 0.0];
            }
            e.direction[..n].fill([1.0, 0.0, 0.0]);
            edit(&mut e);
            e
        };
        let bad_events: Vec<(&str, Counter, ReconfigEvent)> = vec![
            (
                "moved thruster 4 of 4",
                Counter::Count,
                event(ReconfigKind::ThrusterMoved, 4, 4),
            ),
            (
                "added thruster 9 of 5",
                Counter::Count,
                event(ReconfigKind::ThrusterAdded, 9, 5),
            ),
            (
                "removed thruster 6 of 4",
                Counter::Count,
                event(ReconfigKind::ThrusterRemoved, 6, 4),
            ),
            (
                "count 17",
                Counter::Count,
                event(ReconfigKind::Unknown, 0, 17),
            ),
            (
                "count 0",
                Counter::Count,
                event(ReconfigKind::Unknown, 0, 0),
            ),
            (
                "thruster u32::MAX",
                Counter::Count,
                event(ReconfigKind::ThrusterMoved, u32::MAX, 4),
            ),
            (
                "position NaN",
                Counter::NonFinite,
                with_geometry(|e| e.position[2][1] = f64::NAN),
            ),
            (
                "position 1 km",
                Counter::Range,
                with_geometry(|e| e.position[0][0] = 1000.0),
            ),
            (
                "direction not unit",
                Counter::Range,
                with_geometry(|e| e.direction[3] = [0.6, 0.6, 0.0]),
            ),
            (
                "has_geometry 7",
                Counter::Other,
                with_geometry(|e| e.has_geometry = 7),
            ),
            ("kind 99", Counter::Other, {
                let mut e = event(ReconfigKind::Unknown, 0, 4);
                e.kind = 99;
                e
            }),
        ];
        for (what, which, e) in &bad_events {
            d.expect_counted(&op, &daemon, what, *which, 1, |_| {
                reconfig.send(e).unwrap();
            });
        }

        // Setpoints.
        let sp = |edit: fn(&mut Setpoint)| {
            let mut s = Setpoint::default();
            edit(&mut s);
            s
        };
        for (what, which, s) in [
            (
                "attitude NaN",
                Counter::NonFinite,
                sp(|s| s.attitude[0] = f64::NAN),
            ),
            (
                "depth inf",
                Counter::NonFinite,
                sp(|s| s.depth = f64::INFINITY),
            ),
            (
                "quaternion norm 2",
                Counter::Range,
                sp(|s| s.attitude = [2.0, 0.0, 0.0, 0.0]),
            ),
            ("depth 20 km", Counter::Range, sp(|s| s.depth = 20_000.0)),
            ("unknown flags", Counter::Other, sp(|s| s.flags = 1 << 40)),
        ] {
            d.expect_counted(&op, &daemon, what, which, 1, |_| {
                setpoint.send(&s).unwrap();
            });
        }

        // Operator requests: invalid ones and ones the state does not allow.
        let call = |req: ControlRequest| {
            op.client
                .call(req, Duration::from_secs(5))
                .expect("the daemon answers")
        };
        let mut kind99 = ControlRequest::new(RequestKind::Status);
        kind99.kind = 99;
        let mut flags = ControlRequest::new(RequestKind::Status);
        flags.flags = 1;
        let requests: Vec<(&str, ControlRequest, ResponseCode, &str)> = vec![
            (
                "unknown kind",
                kind99,
                ResponseCode::InvalidRequest,
                "kind has unknown value 99",
            ),
            (
                "flags set",
                flags,
                ResponseCode::InvalidRequest,
                "flags has unknown bits",
            ),
            (
                "estimate at NaN power",
                ControlRequest::with_value(RequestKind::Estimate, f64::NAN),
                ResponseCode::InvalidRequest,
                "value is NaN",
            ),
            (
                "estimate at power 3",
                ControlRequest::with_value(RequestKind::Estimate, 3.0),
                ResponseCode::InvalidRequest,
                "value = 3 is outside [0, 1]",
            ),
            (
                "abort while idle",
                ControlRequest::new(RequestKind::Abort),
                ResponseCode::Rejected,
                "nothing to abort",
            ),
            (
                "hold without a model",
                ControlRequest::new(RequestKind::Hold),
                ResponseCode::Rejected,
                "no model",
            ),
            (
                "revert without a previous model",
                ControlRequest::new(RequestKind::Revert),
                ResponseCode::Rejected,
                "",
            ),
            (
                "save without a model",
                ControlRequest::new(RequestKind::Save),
                ResponseCode::Rejected,
                "no model to save",
            ),
            (
                "load a truncated file",
                ControlRequest::with_text(RequestKind::Load, truncated.to_str().unwrap()),
                ResponseCode::Failed,
                "not a thrusterd model file",
            ),
            (
                "load a future version",
                ControlRequest::with_text(RequestKind::Load, future.to_str().unwrap()),
                ResponseCode::Failed,
                "format version 7 is newer",
            ),
            (
                "load a missing file",
                ControlRequest::with_text(RequestKind::Load, "/nonexistent/model.json"),
                ResponseCode::Failed,
                "no such file",
            ),
        ];
        for (what, req, code, text) in requests {
            d.expect_counted(&op, &daemon, what, Counter::Refused, 1, |_| {
                let r = call(req);
                assert_eq!(r.code(), Ok(code), "{what}: {}", r.text());
                assert!(!r.is_ok(), "{what}");
                assert!(
                    r.text().contains(text) && !r.text().is_empty(),
                    "{what}: {}",
                    r.text()
                );
            });
        }

        // Still serving, and valid input still works: a status request, then a valid
        // reconfiguration starts re-estimation.
        let r = op.request(RequestKind::Status);
        assert!(r.is_ok(), "{}", r.text());
        let before = d.counters_now(&op);
        reconfig
            .send(&event(ReconfigKind::ThrusterMoved, 1, THRUSTERS))
            .unwrap();
        d.until_status(&op, Duration::from_secs(5), |s| {
            state(s) == DaemonState::MeasureNoise && s.text().contains("reconfiguration")
        })
        .unwrap_or_else(|| panic!("valid reconfiguration ignored\n{}", daemon.log_text()));
        assert_eq!(d.counters_now(&op), before, "a valid event counted as bad");
        assert!(daemon.is_running());
        assert!(daemon.stop().success(), "{}", daemon.log_text());
        let log = daemon.log_text();
        for reason in [
            "thruster = 4 is not below the thruster count 4",
            "count = 17 exceeds MAX_THRUSTERS",
            "position[2][1] is NaN",
            "direction[3] has norm 0.84",
            "attitude has norm 2",
            "operator request refused",
        ] {
            assert!(log.contains(reason), "no {reason:?} in the log\n{log}");
        }
    }
    world.assert_nothing_left();
}

#[test]
fn bad_saved_models_are_refused_at_start_counted_and_the_daemon_serves() {
    let world = World::new("badmodel");
    let real = std::fs::read_to_string(
        system_tests::workspace().join("fuzz/corpus/model_parse/model.json"),
    )
    .unwrap();
    assert!(real.contains("\"thrusters\": 5"));
    let mut corrupt = real.clone().into_bytes();
    corrupt[real.len() / 2] = b'}';
    // A well-formed file whose physics is absurd (a units mistake, a hand edit): refused
    // with the entry named, by the same bounds the protocol applies.
    let absurd = {
        let mut v: serde_json::Value = serde_json::from_str(&real).unwrap();
        // Cut to this daemon's 4 thrusters, so the count is right and the physics is not.
        v["thrusters"] = serde_json::json!(4);
        for key in ["effectiveness", "std_err"] {
            for row in v[key].as_array_mut().unwrap() {
                row.as_array_mut().unwrap().truncate(4);
            }
        }
        v["allocation"].as_array_mut().unwrap().truncate(4);
        v["effectiveness"][2][3] = serde_json::json!(1e300);
        serde_json::to_string_pretty(&v).unwrap().into_bytes()
    };
    let variants: [(&str, Vec<u8>, &str); 6] = [
        (
            "truncated",
            real.as_bytes()[..real.len() - 40].to_vec(),
            "not a thrusterd model file",
        ),
        ("corrupt byte", corrupt, "not a thrusterd model file"),
        (
            "future version",
            real.replacen("\"format_version\": 1", "\"format_version\": 4", 1)
                .into_bytes(),
            "format version 4 is newer than this daemon's 3",
        ),
        (
            "not UTF-8",
            vec![0xff, 0xfe, b'{', 0x80],
            "stream did not contain valid UTF-8",
        ),
        (
            "absurd effectiveness",
            absurd,
            "model not used: model effectiveness[2][3] = 1e300 is outside the physical bound",
        ),
        // A well-formed file for another vehicle (5 thrusters; this daemon has 4).
        (
            "wrong thruster count",
            real.into_bytes(),
            "model not used: model has 5 thrusters",
        ),
    ];
    std::fs::create_dir_all(world.path("state")).unwrap();
    {
        let op = Operator::new(&world);
        for (what, bytes, reason) in variants {
            std::fs::write(world.path("state/model.json"), &bytes).unwrap();
            let mut daemon = world.daemon(&["--thrusters", "4"]);
            let s = op
                .wait_status(Duration::from_secs(30), |s| !s.text().contains("stopped"))
                .unwrap_or_else(|| panic!("{what}: no status\n{}", daemon.log_text()));
            assert_eq!(s.requests_refused, 1, "{what}");
            assert_eq!(s.model_version, 0, "{what}");
            assert_eq!(state(&s), DaemonState::Idle, "{what}");
            let r = op.request(RequestKind::Status);
            assert!(r.is_ok(), "{what}: {}", r.text());
            assert!(daemon.is_running(), "{what}");
            assert!(daemon.stop().success(), "{what}\n{}", daemon.log_text());
            // Forget this daemon's statuses (its last one says "stopped").
            while op.status.recv().unwrap().is_some() {}
            let log = daemon.log_text();
            assert!(
                log.contains("saved model ignored, starting without it") && log.contains(reason),
                "{what}: no {reason:?}\n{log}"
            );
            // The refused file is left for a human to look at, not overwritten.
            assert_eq!(
                std::fs::read(world.path("state/model.json")).unwrap(),
                bytes,
                "{what}"
            );
        }
    }
    world.assert_nothing_left();
}

#[test]
fn bad_config_files_are_refused_with_file_line_and_key() {
    let world = World::new("badcfg");
    let shipped =
        std::fs::read_to_string(system_tests::workspace().join("config/thrusterd.toml")).unwrap();
    let cut = shipped.find("pulse_s").unwrap() + 4;
    // `file:line:col: key: ...`, the form every binary uses: the line of a key's value.
    let at = |key: &str| {
        let line = shipped[..shipped.find(key).unwrap()].matches('\n').count() + 1;
        format!(".toml:{line}:")
    };
    let (pulse, kp_depth, timeout) = (
        at("pulse_s = 0.1"),
        at("kp_depth = 2.0"),
        at("imu_timeout_ms = 100"),
    );
    let variants: [(&str, Vec<u8>, Vec<&str>); 6] = [
        (
            "truncated mid-key",
            shipped.as_bytes()[..cut].to_vec(),
            vec![".toml:", "expected"],
        ),
        (
            "corrupt: a value replaced by text",
            shipped
                .replacen("pulse_s = 0.1", "pulse_s = 0.1x", 1)
                .into_bytes(),
            vec![&pulse],
        ),
        (
            "future version: a key this daemon does not know",
            format!("{shipped}\n[estimator2]\nformat_version = 2\n").into_bytes(),
            vec![".toml:", "unknown field `estimator2`"],
        ),
        (
            "NaN gain",
            shipped
                .replacen("kp_depth = 2.0", "kp_depth = nan", 1)
                .into_bytes(),
            vec![
                &kp_depth,
                "controller.kp_depth: must be in [0, inf), got NaN",
            ],
        ),
        (
            "infinite timeout",
            shipped
                .replacen("imu_timeout_ms = 100", "imu_timeout_ms = 999999999", 1)
                .into_bytes(),
            vec![
                &timeout,
                "runtime.imu_timeout_ms: must be in [1, 60000], got 999999999",
            ],
        ),
        (
            "not UTF-8",
            vec![b'[', 0xff, 0xfe, b']'],
            vec!["cannot read", "valid UTF-8"],
        ),
    ];
    for edited in ["pulse_s = 0.1", "kp_depth = 2.0", "imu_timeout_ms = 100"] {
        assert!(
            shipped.contains(edited),
            "the shipped config changed: {edited}"
        );
    }
    for (i, (what, bytes, expect)) in variants.iter().enumerate() {
        let path = world.path(&format!("bad{i}.toml"));
        std::fs::write(&path, bytes).unwrap();
        let path_s = path.to_str().unwrap();
        // The check command and the daemon itself both refuse it, naming the file.
        let mut check = Proc::spawn("thrusterd", &["check-config", path_s], world.dir.path());
        let status = check.wait_timeout(Duration::from_secs(10)).expect("exits");
        assert!(!status.success(), "{what}: check-config accepted it");
        let mut daemon = world.daemon(&["--config", path_s]);
        let status = daemon
            .wait_timeout(Duration::from_secs(10))
            .unwrap_or_else(|| panic!("{what}: the daemon runs with a bad config"));
        assert!(!status.success(), "{what}");
        for log in [check.log_text(), daemon.log_text()] {
            assert!(log.contains(path_s), "{what}: file not named\n{log}");
            for e in expect {
                assert!(log.contains(e), "{what}: no {e:?}\n{log}");
            }
        }
    }
    // The command line's overrides pass the same ranges as the file's keys (a spin of
    // u64::MAX us started, a lockstep wait of 0 was clamped without a word).
    for (flags, expect) in [
        (
            ["--spin-us", "18446744073709551615"],
            "command line: runtime.spin_us: must be in [0, 1000000], got 18446744073709551615",
        ),
        (
            ["--lockstep-wait-ms", "0"],
            "command line: runtime.lockstep_wait_ms: must be in [1, 600000], got 0",
        ),
    ] {
        let mut daemon = world.daemon(&flags);
        let status = daemon
            .wait_timeout(Duration::from_secs(10))
            .unwrap_or_else(|| panic!("{flags:?}: the daemon runs"));
        assert_eq!(status.code(), Some(2), "{flags:?}\n{}", daemon.log_text());
        assert!(daemon.log_text().contains(expect), "{}", daemon.log_text());
    }
    world.assert_nothing_left();
}

#[test]
fn thrust_commands_with_wrong_counts_are_rejected_by_the_driver() {
    let world = World::new("badthrust");
    {
        let imu: Inbox<ImuSample> = Inbox::create(world.node(), world.ipc()).unwrap();
        let thrust: Port<ThrustCommand> = Port::create(world.node(), world.ipc()).unwrap();
        // The test is the daemon: thruster-sim (5 thrusters) waits for its answer each tick.
        let mut sim = world.sim("amour5", &["--lockstep", "--noise", "none"]);
        let mut sent_bad = 0;
        let mut answered = 0u64;
        let start = Instant::now();
        while answered < 80 {
            assert!(
                start.elapsed() < Duration::from_secs(30),
                "sim stalled\n{}",
                sim.log_text()
            );
            let Some(s) = imu.recv().unwrap() else {
                std::thread::sleep(Duration::from_micros(200));
                continue;
            };
            answered += 1;
            let mut c = ThrustCommand::neutral(answered, s.seq, s.t_ns, 5);
            c.set_mode(ThrustMode::Controlling);
            c.thrust[..5].copy_from_slice(&[0.2, -0.2, 0.1, 0.0, 0.0]);
            match answered % 8 {
                1 => c.count = 4,  // one thruster short
                3 => c.count = 6,  // one too many
                5 => c.count = 17, // beyond MAX_THRUSTERS
                7 => c.count = 0,  // none
                _ => {}
            }
            if c.count != 5 {
                sent_bad += 1;
            }
            thrust.send(&c).unwrap();
        }
        sim.signal("TERM");
        let status = sim
            .wait_timeout(Duration::from_secs(10))
            .expect("sim exits");
        assert!(status.success(), "{}", sim.log_text());
        let log = sim.log_text();
        let summary = log
            .lines()
            .find(|l| l.contains("thruster-sim stopped"))
            .unwrap_or_else(|| panic!("no summary\n{log}"));
        assert!(
            summary.contains(&format!(" rejected={sent_bad}")),
            "expected {sent_bad} rejections: {summary}"
        );
        for reason in [
            "count = 4 but 5 thrusters are configured",
            "count = 17 exceeds MAX_THRUSTERS",
        ] {
            assert!(log.contains(reason), "no {reason:?}\n{log}");
        }
    }
    world.assert_nothing_left();
}
