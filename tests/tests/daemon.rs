//! thrusterd as its users meet it: real `thrusterd` and `thruster-sim` processes over real
//! iceoryx2, each test on its own namespace, every child reaped, nothing left on disk.

use std::time::{Duration, Instant};

use system_tests::vehicle_clock::STEPPED_DAEMON;
use system_tests::{model_error, state, Operator, World};
use thruster_protocol::services::{Inbox, Port};
use thruster_protocol::{
    DaemonState, ImuSample, ModelSource, ReconfigEvent, RequestKind, Setpoint, ThrustCommand,
    ThrustMode,
};

const LONG: Duration = Duration::from_secs(60);

#[test]
fn estimation_from_request_to_swapped_model_and_restart_loads_it() {
    let world = World::new("est");
    let op = Operator::new(&world);
    let mut daemon = world.daemon(&STEPPED_DAEMON);
    // In vehicle time: the request lands at the same sample in every run.
    let (mut sim, mut clock) =
        world.stepped_sim("amour5", &["--noise", "paper", "--duration", "100000"]);

    // The daemon is up and answering samples, idle.
    let idle = clock
        .run_until(&op.status, 5.0, |s| {
            s.samples > 50 && state(s) == DaemonState::Idle
        })
        .unwrap_or_else(|| panic!("no idle status\n{}", daemon.log_text()));
    assert_eq!(idle.model_version, 0);

    let r = op.request(RequestKind::Estimate);
    assert!(r.is_ok(), "{}", r.text());
    let active = clock
        .run_until(&op.status, 30.0, |s| {
            state(s) == DaemonState::Active && s.model_version >= 1
        })
        .unwrap_or_else(|| panic!("no model\n{}", daemon.log_text()));
    assert_eq!(active.model_version, 1);
    println!(
        "model after {:.2} vehicle-s, {} pulses",
        clock.now_s() - idle.vehicle_time_ns as f64 * 1e-9,
        active.pulse
    );
    let model = op
        .wait_model(LONG, |m| m.version == active.model_version)
        .expect("model published");
    assert_eq!(model.source(), Ok(ModelSource::Estimated));
    assert_eq!(model.count, 5);
    let truth = op.latest_truth(LONG).expect("truth published");
    let (e_rot, e_acc) = (
        model_error(&model, &truth, 0),
        model_error(&model, &truth, 3),
    );
    println!("errors rot {e_rot:.3} acc {e_acc:.3}");
    // Paper noise, seed 1 (the default), in vehicle time (the same every run): measured 0.032 / 0.061 after
    // 7.46 vehicle-s. The bound is 1.5x that; a 2x regression fails.
    assert!(
        e_rot < 0.05 && e_acc < 0.09,
        "errors rot {e_rot:.3} acc {e_acc:.3}"
    );

    let learned_terms = op
        .wait_dynamics(LONG, |d| d.model_version == active.model_version)
        .expect("the learned model's dynamic terms published");

    // SIGTERM: neutral, final status, model saved, exit 0.
    let status = daemon.stop();
    assert!(
        status.success(),
        "daemon exit {status:?}\n{}",
        daemon.log_text()
    );
    assert!(world.path("state/model.json").exists());
    assert!(daemon.log_text().contains("model saved"));

    // A restarted daemon loads it and publishes it at once.
    let mut daemon2 = world.daemon(&[]);
    let loaded = op
        .wait_model(LONG, |m| m.source() == Ok(ModelSource::Loaded))
        .unwrap_or_else(|| panic!("saved model not loaded\n{}", daemon2.log_text()));
    assert_eq!(loaded.effectiveness, model.effectiveness);
    // And with it what it was learned with (file format 2): the lag, the damping, the IMU's
    // position. A file with B only was refined and change-tested with the configured lag
    // (core tests/restart_keeps_the_lag.rs).
    let loaded_terms = op
        .wait_dynamics(LONG, |d| d.model_version == loaded.version)
        .unwrap_or_else(|| {
            panic!(
                "no dynamic terms for the loaded model\n{}",
                daemon2.log_text()
            )
        });
    // To the bit (NaN marks what was not carried, and NaN != NaN).
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(loaded_terms.spin_up_s, learned_terms.spin_up_s);
    assert_eq!(loaded_terms.spin_up_learned, learned_terms.spin_up_learned);
    for r in 0..6 {
        assert_eq!(
            bits(&loaded_terms.coefficients[r].to_terms()),
            bits(&learned_terms.coefficients[r].to_terms()),
            "row {r}"
        );
    }
    assert_eq!(
        bits(&loaded_terms.imu_position_m),
        bits(&learned_terms.imu_position_m)
    );
    // And the operator's `model` prints them for the loaded model.
    let out = system_tests::cli::ctl(&world, &["model", "--json"]);
    let m: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "model --json: {e}: {}",
            system_tests::cli::text(&out.stderr)
        )
    });
    assert_eq!(m["source"], "Loaded", "{m}");
    assert_eq!(
        m["dynamics"]["spin_up_s"].as_f64(),
        Some(learned_terms.spin_up_s),
        "{m}"
    );
    assert!(daemon2.stop().success());
    assert!(sim.stop().success());
    drop(op);
    let node = world.node.as_ref().map(|_| ());
    assert!(node.is_some());
}

#[test]
fn corrupt_saved_model_gives_a_warning_and_a_clean_start() {
    let world = World::new("corrupt");
    std::fs::create_dir_all(world.path("state")).unwrap();
    std::fs::write(
        world.path("state/model.json"),
        "{\"format\": \"thrusterd-model\", \"format_ver",
    )
    .unwrap();
    let op = Operator::new(&world);
    let mut daemon = world.daemon(&[]);
    let s = op
        .wait_status(LONG, |_| true)
        .expect("daemon publishes status");
    assert_eq!(s.model_version, 0);
    assert!(daemon.is_running());
    assert!(daemon.stop().success());
    assert!(
        daemon.log_text().contains("saved model ignored"),
        "{}",
        daemon.log_text()
    );
}

#[test]
fn reconfiguration_mid_control_leads_to_a_new_model() {
    let world = World::new("reconf");
    let op = Operator::new(&world);
    // The shipped scenario's event (t = 30 s) can land mid-estimation; here the rotation comes
    // once the vehicle is surely under control with its first model.
    let scenario = world.path("top45_late.toml");
    std::fs::write(
        &scenario,
        "[[event]]\nt_s = 120.0\nannounce = true\naction = { kind = \"rotate\", thruster = \"T\", axis = [1, 0, 0], angle_deg = 45 }\n",
    )
    .unwrap();
    // `--estimate` starts at the first sample and the event comes at a vehicle time; stepped,
    // the simulator waits for every answer and the daemon for every late solve: the run is
    // the same on any machine.
    let mut daemon = world.daemon(&[&["--estimate"], &STEPPED_DAEMON[..]].concat());
    let (mut sim, mut clock) = world.stepped_sim(
        "amour5",
        &[
            "--noise",
            "paper",
            "--duration",
            "100000",
            "--scenario",
            scenario.to_str().unwrap(),
        ],
    );
    let first = clock
        .run_until(&op.model, 60.0, |m| {
            m.source() == Ok(ModelSource::Estimated)
        })
        .unwrap_or_else(|| panic!("no first model\n{}", daemon.log_text()));
    // At t = 120 s the top thruster turns 45 degrees and the event declares the new geometry:
    // the nominal model for it comes in at once, then a re-estimated one.
    let nominal = clock
        .run_until(&op.model, 130.0, |m| m.source() == Ok(ModelSource::Nominal))
        .unwrap_or_else(|| panic!("no nominal swap\n{}", daemon.log_text()));
    assert!(nominal.version > first.version);
    let second = clock
        .run_until(&op.model, 60.0, |m| {
            m.source() == Ok(ModelSource::Estimated) && m.version > nominal.version
        })
        .unwrap_or_else(|| panic!("no re-estimated model\n{}", daemon.log_text()));
    let truth = op.latest_truth(LONG).unwrap();
    let e_new = model_error(&second, &truth, 0);
    let e_old = model_error(&first, &truth, 0);
    println!(
        "re-estimated {e_new:.3} under its bound {:.3} (v{} at {:.3} vehicle-s; first v{}, nominal v{}), first model \
         against the new truth {e_old:.3}",
        second.rel_err_rot,
        second.version,
        clock.now_s(),
        first.version,
        nominal.version
    );
    // Identified under control at the paper's noise, the same every run: measured 0.059 under
    // its own bound of 0.057 (the old model: 0.380 against the new truth). Before 2026-12-05,
    // with the acceleration rows stopping at 0.06 instead of 0.07, 0.033: the first model and
    // the identification now stop sooner (docs/study.md, "The acceleration rows' target at
    // 0.07"). Asserted: the identification's stop (a rotation bound at the 0.06 target) and
    // the error within 1.5x that bound (issue 32's honest bound).
    assert!(
        second.rel_err_rot <= 0.061,
        "the identification's bound {:.3}",
        second.rel_err_rot
    );
    assert!(
        e_new < 1.5 * second.rel_err_rot,
        "re-estimated model vs new truth: {e_new:.3} under its bound {:.3}",
        second.rel_err_rot
    );
    assert!(
        e_new < e_old,
        "the new model must fit the new truth better ({e_new:.3} vs {e_old:.3})"
    );
    assert!(sim.stop().success());
    assert!(daemon.stop().success());
}

/// The test process is the driver: it publishes IMU samples itself and reads the thrust.
struct ScriptedDriver {
    imu: Port<ImuSample>,
    thrust: Inbox<ThrustCommand>,
    seq: u64,
    t_ns: u64,
}

impl ScriptedDriver {
    fn new(world: &World) -> Self {
        ScriptedDriver {
            imu: Port::create(world.node(), world.ipc()).unwrap(),
            thrust: Inbox::create(world.node(), world.ipc()).unwrap(),
            seq: 0,
            t_ns: 1_000_000_000,
        }
    }

    fn at_rest(&mut self) -> ImuSample {
        self.seq += 1;
        self.t_ns += 5_000_000;
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

    /// Publish in (roughly) real time for `secs`; every thrust answer is checked for sanity.
    fn run_for(&mut self, secs: f64, answers: &mut Vec<ThrustCommand>) {
        let start = Instant::now();
        while start.elapsed().as_secs_f64() < secs {
            let s = self.at_rest();
            self.imu.send(&s).unwrap();
            std::thread::sleep(Duration::from_millis(5));
            self.drain(answers);
        }
    }

    fn drain(&self, answers: &mut Vec<ThrustCommand>) {
        while let Some(c) = self.thrust.recv().unwrap() {
            for v in c.thrusters() {
                assert!(v.is_finite() && v.abs() <= 1.0, "thrust {v}");
            }
            answers.push(c);
        }
    }
}

#[test]
fn imu_stopping_mid_pulse_goes_neutral_and_faults_then_recovers() {
    let world = World::new("stale");
    let op = Operator::new(&world);
    let mut daemon = world.daemon(&["--thrusters", "4"]);
    let mut driver = ScriptedDriver::new(&world);
    let mut answers = Vec::new();
    driver.run_for(0.3, &mut answers);
    assert!(op.request(RequestKind::Estimate).is_ok());
    // Noise phase (2 s), then the first pulse.
    let start = Instant::now();
    while !answers
        .iter()
        .any(|c| c.mode() == Ok(ThrustMode::Estimating) && c.thrusters().iter().any(|v| *v != 0.0))
    {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "no pulse\n{}",
            daemon.log_text()
        );
        driver.run_for(0.05, &mut answers);
    }
    // Mid-pulse the driver stops publishing.
    answers.clear();
    std::thread::sleep(Duration::from_millis(400));
    driver.drain(&mut answers);
    let last = answers
        .last()
        .expect("the daemon answers a stale IMU with a command");
    assert_eq!(last.mode(), Ok(ThrustMode::Neutral));
    assert!(last.thrusters().iter().all(|v| *v == 0.0));
    op.wait_status(Duration::from_secs(5), |s| state(s) == DaemonState::Fault)
        .unwrap_or_else(|| panic!("no fault\n{}", daemon.log_text()));
    // Samples return (after a time gap): the interrupted estimation restarts from rest.
    driver.run_for(0.5, &mut answers);
    op.wait_status(Duration::from_secs(5), |s| {
        state(s) == DaemonState::MeasureNoise
    })
    .unwrap_or_else(|| panic!("no recovery\n{}", daemon.log_text()));
    assert!(daemon.stop().success());
}

#[test]
fn garbage_on_every_input_is_counted_and_rejected_while_serving() {
    let world = World::new("garbage");
    let op = Operator::new(&world);
    let mut daemon = world.daemon(&["--thrusters", "4"]);
    let mut driver = ScriptedDriver::new(&world);
    let reconfig: Port<ReconfigEvent> = Port::create(world.node(), world.ipc()).unwrap();
    let setpoint: Port<Setpoint> = Port::create(world.node(), world.ipc()).unwrap();
    let mut answers = Vec::new();
    driver.run_for(0.3, &mut answers);
    assert!(op.request(RequestKind::Estimate).is_ok());
    driver.run_for(2.5, &mut answers); // into the pulses

    let mut bad = Vec::new();
    let mut nan = driver.at_rest();
    nan.gyro[1] = f64::NAN;
    bad.push(nan);
    let mut inf = driver.at_rest();
    inf.accel[0] = f64::INFINITY;
    bad.push(inf);
    let mut huge = driver.at_rest();
    huge.accel[2] = 1e9;
    bad.push(huge);
    let mut back = driver.at_rest();
    back.t_ns -= 1_000_000_000; // time going backwards
    bad.push(back);
    let dup = driver.at_rest();
    bad.push(dup);
    bad.push(dup); // duplicated sequence number
    for s in &bad {
        driver.imu.send(s).unwrap();
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut wrong_count = ReconfigEvent {
        count: 40,
        ..ReconfigEvent::default()
    };
    wrong_count.thruster = 99;
    reconfig.send(&wrong_count).unwrap();
    let nan_sp = Setpoint {
        attitude: [f64::NAN, 0.0, 0.0, 0.0],
        ..Setpoint::default()
    };
    setpoint.send(&nan_sp).unwrap();
    driver.run_for(0.5, &mut answers);

    let s = op
        .wait_status(Duration::from_secs(5), |s| {
            s.rejected_nonfinite >= 3
                && s.rejected_range >= 1
                && s.rejected_time >= 2
                && s.rejected_count >= 1
        })
        .unwrap_or_else(|| panic!("rejections not counted\n{}", daemon.log_text()));
    // Still serving: estimating, answering every valid sample.
    assert!(matches!(
        state(&s),
        DaemonState::Pulse | DaemonState::Settle | DaemonState::MeasureNoise | DaemonState::Active
    ));
    assert!(daemon.is_running());
    let r = op.request(RequestKind::Status);
    assert!(r.is_ok());
    assert!(answers.len() > 400, "answers {}", answers.len());
    assert!(daemon.stop().success());
    drop(reconfig);
    drop(setpoint);
}

#[test]
fn requests_in_the_wrong_state_are_refused_with_a_reason() {
    let world = World::new("refuse");
    let op = Operator::new(&world);
    let mut daemon = world.daemon(&[]);
    op.wait_status(LONG, |_| true).expect("status");
    let r = op.request(RequestKind::Abort);
    assert!(
        !r.is_ok() && r.text().contains("nothing to abort"),
        "{}",
        r.text()
    );
    let r = op.request(RequestKind::Hold);
    assert!(!r.is_ok() && r.text().contains("no model"), "{}", r.text());
    let r = op.request(RequestKind::Revert);
    assert!(!r.is_ok(), "{}", r.text());
    let r = op.request(RequestKind::Shutdown);
    assert!(r.is_ok());
    let status = daemon
        .wait_timeout(Duration::from_secs(5))
        .expect("exits on Shutdown");
    assert!(status.success());
}

#[test]
fn nothing_is_left_behind() {
    let world = World::new("clean");
    {
        let op = Operator::new(&world);
        let mut daemon = world.daemon(&["--lockstep"]);
        let mut sim = world.sim("amour5", &["--lockstep", "--duration", "5"]);
        op.wait_status(LONG, |s| s.samples > 10).expect("running");
        let _ = sim.wait_timeout(Duration::from_secs(30));
        assert!(daemon.stop().success());
    }
    world.assert_nothing_left();
}
