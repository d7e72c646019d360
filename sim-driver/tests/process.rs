//! The real `thruster-sim` binary as a child process, talked to over real iceoryx2 from the
//! test, which plays the daemon. Each test uses its own namespace and checks at the end that
//! no process and no file of the namespace is left.
//!
//! Most tests run in lockstep with noise-free sensors and compare every received sample with
//! a replica `Simulator` in the test driven by the same commands: that checks, to the last
//! digit, which command the driver applied during which period (and that garbage never was).

use std::fs;
use std::path::PathBuf;
use std::process::{Command, ExitStatus};
use std::time::{Duration, Instant};
use thruster_driver_kit::test_process::{Launch, TestProcess};

use thruster_protocol::services::{
    cleanup_dead_nodes, namespace_files, purge_namespace, Inbox, IpcConfig, IpcNode,
    NamespaceGuard, Port, SHM_DIR,
};
use thruster_protocol::{
    DriverStatusMsg, ImuSample, ReconfigEvent, ReconfigKind, ThrustCommand, ThrustMode, TruthMsg,
    Validate, VehicleStateMsg,
};
use thruster_sim::driver::shutdown::Shutdown;
use thruster_sim::driver::wait::{recv_until, Received};
use thruster_sim::{NoisePreset, SensorConfig, Simulator, Vehicle};

const BIN: &str = env!("CARGO_BIN_EXE_thruster-sim");
const TIMEOUT: Duration = Duration::from_secs(10);
const PERIOD_NS: u64 = 5_000_000; // 200 Hz, the driver's default rate

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn vehicle_path(name: &str) -> PathBuf {
    repo().join(format!("config/vehicles/{name}.toml"))
}

fn scenario_path(name: &str) -> PathBuf {
    repo().join(format!("config/scenarios/{name}.toml"))
}

/// The simulator the driver builds for `vehicle` at 200 Hz, default options.
fn replica(vehicle: &str, noise: NoisePreset, seed: u64) -> Simulator {
    let v = Vehicle::load(vehicle_path(vehicle)).unwrap();
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise,
        ..SensorConfig::default()
    };
    Simulator::new(v, sensors, seed).unwrap()
}

// ---- child processes -------------------------------------------------------------------

/// thruster-sim as a child process: the one test launcher's (`TestProcess`: always killed and
/// reaped, its log printed when the test panics), with what these tests ask of it.
struct Proc(TestProcess);

impl Proc {
    fn spawn(args: &[&str]) -> Proc {
        Proc(TestProcess::spawn(BIN, args).unwrap())
    }

    fn run(ns: &IpcConfig, vehicle: &str, extra: &[&str]) -> Proc {
        let v = vehicle_path(vehicle);
        let mut args = vec![
            "run",
            "--namespace",
            ns.namespace(),
            "--vehicle",
            v.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        Proc::spawn(&args)
    }

    fn signal(&self, sig: &str) {
        self.0.signal(sig);
    }

    /// Waits for the exit (reaping the child); `None` when it is still running at `within`.
    fn wait_exit(&mut self, within: Duration) -> Option<ExitStatus> {
        self.0.wait_timeout(within)
    }

    /// SIGTERM; asserts exit code 0 within a second.
    fn terminate(&mut self) {
        let t0 = Instant::now();
        self.0.stop_cleanly(Duration::from_secs(1));
        assert!(t0.elapsed() < Duration::from_secs(1));
    }

    fn log(&self) -> String {
        self.0.log_text()
    }

    /// The value of `key=` in the final summary line.
    fn summary_value(&self, key: &str) -> u64 {
        self.0.summary_value("thruster-sim stopped", key)
    }
}

// ---- the test's side of the protocol ---------------------------------------------------

/// The test playing the daemon: IMU, truth and reconfig inboxes, a thrust port.
struct Peer {
    imu: Inbox<ImuSample>,
    truth: Inbox<TruthMsg>,
    reconfig: Inbox<ReconfigEvent>,
    vehicle: Inbox<VehicleStateMsg>,
    thrust: Port<ThrustCommand>,
    seq: u64,
    stop: Shutdown,
    _node: IpcNode,
}

impl Peer {
    fn new(ns: &IpcConfig) -> Peer {
        let node = ns.create_node("test-peer").unwrap();
        Peer {
            truth: Inbox::create(&node, ns).unwrap(),
            reconfig: Inbox::create(&node, ns).unwrap(),
            vehicle: Inbox::create(&node, ns).unwrap(),
            thrust: Port::create(&node, ns).unwrap(),
            imu: Inbox::create(&node, ns).unwrap(),
            seq: 0,
            stop: Shutdown::new(),
            _node: node,
        }
    }

    fn try_next<T: thruster_protocol::services::TopicMessage>(
        &self,
        inbox: &Inbox<T>,
        within: Duration,
    ) -> Option<T> {
        match recv_until(
            inbox,
            Instant::now() + within,
            Duration::from_micros(100),
            &self.stop,
        )
        .unwrap()
        {
            Received::Message(m) => Some(m),
            _ => None,
        }
    }

    fn sample(&self) -> ImuSample {
        let s = self
            .try_next(&self.imu, TIMEOUT)
            .expect("no IMU sample within the timeout");
        assert!(s.validate().is_ok(), "invalid sample {s:?}");
        s
    }

    fn truth(&self) -> TruthMsg {
        self.try_next(&self.truth, TIMEOUT)
            .expect("no truth message within the timeout")
    }

    fn command(&mut self, s: &ImuSample, u: &[f64]) -> ThrustCommand {
        self.seq += 1;
        let mut c = ThrustCommand::neutral(self.seq, s.seq, s.t_ns, u.len() as u32);
        c.set_mode(ThrustMode::Estimating);
        c.thrusters_mut().copy_from_slice(u);
        c
    }

    fn answer(&mut self, s: &ImuSample, u: &[f64]) {
        let c = self.command(s, u);
        self.thrust.send(&c).unwrap();
    }
}

/// Every process of the namespace has exited and dropped its ports: only iceoryx2's own
/// residue (the global_mgmt segment and empty directories) is left, which the purge removes.
fn assert_namespace_clean(ns: &IpcConfig) {
    let census = cleanup_dead_nodes(ns).unwrap();
    assert_eq!(
        (census.alive, census.dead_cleaned, census.dead_failed),
        (0, 0, 0),
        "nodes left: {census:?}"
    );
    let files = namespace_files(ns).unwrap();
    let leftovers: Vec<&PathBuf> = files
        .iter()
        .filter(|p| !p.is_dir())
        .filter(|p| {
            let name = p.file_name().unwrap().to_string_lossy();
            !(p.starts_with(SHM_DIR) && name.ends_with(".global_mgmt"))
        })
        .collect();
    assert!(leftovers.is_empty(), "files left: {leftovers:#?}");
    let report = purge_namespace(ns).unwrap();
    assert!(report.kept.is_empty(), "kept {:?}", report.kept);
    assert_eq!(namespace_files(ns).unwrap(), Vec::<PathBuf>::new());
}

fn assert_matches_replica(got: &ImuSample, want: &thruster_protocol::ImuReading) {
    let want = want.to_sample();
    assert_eq!(got.t_ns, want.t_ns, "seq {}", got.seq);
    let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-9);
    assert!(
        close(&got.gyro, &want.gyro)
            && close(&got.accel, &want.accel)
            && close(&got.mag, &want.mag)
            && close(&[got.depth], &[want.depth]),
        "sample {} differs from the replica:\n got {got:?}\nwant {want:?}",
        got.seq
    );
}

// ---- tests -------------------------------------------------------------------------------

#[test]
fn samples_at_rest_read_gravity_on_an_exact_clock() {
    let ns = NamespaceGuard::unique_for_test("rest").unwrap();
    {
        let mut peer = Peer::new(&ns);
        let mut sim = Proc::run(&ns, "amour5", &["--lockstep", "--noise", "none"]);
        for k in 1..=100u64 {
            let s = peer.sample();
            assert_eq!(s.seq, k);
            assert_eq!(s.t_ns, (k - 1) * PERIOD_NS);
            assert_eq!(s.flags, ImuSample::HAS_MAG | ImuSample::HAS_DEPTH);
            // Level and at rest: specific force is minus gravity (the 2 N of buoyancy lift
            // the vehicle by less than 0.1 m/s^2).
            assert!(s.accel[0].abs() < 1e-3 && s.accel[1].abs() < 1e-3, "{s:?}");
            assert!((s.accel[2] + 9.81).abs() < 0.1, "{s:?}");
            assert!(s.gyro.iter().all(|g| g.abs() < 1e-4), "{s:?}");
            assert!((s.depth - 30.0).abs() < 0.05, "{s:?}");
            assert!((s.mag[0] - 20.0).abs() < 1e-6 && (s.mag[2] - 45.0).abs() < 1e-6);
            peer.answer(&s, &[0.0; 5]);
        }
        sim.terminate();
        assert_eq!(sim.summary_value("rejected"), 0);
        assert_eq!(sim.summary_value("applied"), 100);
    }
    assert_namespace_clean(&ns);
}

#[test]
fn full_forward_thrust_moves_the_vehicle_as_the_truth_says() {
    // T (index 0): up at the front top, pitch and heave; L (index 3): forward at port, yaw
    // and surge.
    for j in [0usize, 3] {
        let ns = NamespaceGuard::unique_for_test("push").unwrap();
        {
            let mut peer = Peer::new(&ns);
            let mut sim = Proc::run(&ns, "amour5", &["--lockstep", "--noise", "none"]);
            let truth = peer.truth();
            let mut twin = replica("amour5", NoisePreset::None, 1);
            let rest = twin.sample();
            let mut u = [0.0; 5];
            u[j] = 1.0;
            let mut last = peer.sample();
            assert_matches_replica(&last, &rest);
            for _ in 0..40 {
                peer.answer(&last, &u);
                twin.set_commands(&u).unwrap();
                twin.step(PERIOD_NS);
                last = peer.sample();
                assert_matches_replica(&last, &twin.sample());
                // The true state of the same instant came just before the sample.
                let state = peer
                    .vehicle
                    .recv_latest()
                    .unwrap()
                    .expect("no vehicle state");
                assert!(state.validate().is_ok());
                assert_eq!((state.seq, state.t_ns), (last.seq, last.t_ns));
                let close =
                    |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9);
                assert!(close(&state.attitude, &twin.attitude_wxyz()), "{state:?}");
                assert!(close(&state.rate, twin.angular_velocity().as_slice()));
                assert!(close(&state.position_ned, twin.position_ned().as_slice()));
                assert!(close(&state.velocity, twin.linear_velocity().as_slice()));
                // Noise-free gyro = true rate.
                assert!(close(&state.rate, &last.gyro));
            }
            // 0.2 s of full thrust: the rate about the axis the truth says this thruster
            // turns most has that sign, and so has the change of specific force along its
            // main translation.
            let col = |dof: usize| truth.effectiveness[dof][j];
            let rot = (0..3)
                .max_by(|&a, &b| col(a).abs().total_cmp(&col(b).abs()))
                .unwrap();
            let lin = (3..6)
                .max_by(|&a, &b| col(a).abs().total_cmp(&col(b).abs()))
                .unwrap();
            assert!(col(rot).abs() > 10.0 && col(lin).abs() > 1.0, "{truth:?}");
            assert!(
                last.gyro[rot] * col(rot).signum() > 0.3,
                "thruster {j}: gyro {:?}, truth column rot {}",
                last.gyro,
                col(rot)
            );
            let d_accel = last.accel[lin - 3] - rest.accel[lin - 3];
            assert!(
                d_accel * col(lin).signum() > 0.2,
                "thruster {j}: accel {:?} vs rest {:?}, truth column lin {}",
                last.accel,
                rest.accel,
                col(lin)
            );
            // The other rotations stay small (not zero: once moving, the CG offset and the
            // Munk moment couple surge into pitch, about 10 % for L after 0.2 s).
            for other in (0..3).filter(|&a| a != rot) {
                assert!(
                    last.gyro[other].abs() < 0.2 * last.gyro[rot].abs(),
                    "thruster {j}: gyro {:?}",
                    last.gyro
                );
            }
            sim.terminate();
        }
        assert_namespace_clean(&ns);
    }
}

#[test]
fn truth_matches_the_simulator_for_each_vehicle_and_is_republished_at_exit() {
    for vehicle in ["amour5", "aligned", "eight_vectored"] {
        let ns = NamespaceGuard::unique_for_test("tru").unwrap();
        {
            let peer = Peer::new(&ns);
            let mut sim = Proc::run(&ns, vehicle, &["--realtime"]);
            let t = peer.truth();
            assert!(t.validate().is_ok());
            let (fwd, rev) = replica(vehicle, NoisePreset::None, 1).truth();
            assert_eq!(t.thruster_count(), fwd.ncols(), "{vehicle}");
            assert_eq!((t.seq, t.t_ns), (1, 0));
            for d in 0..6 {
                for i in 0..fwd.ncols() {
                    assert!((t.effectiveness[d][i] - fwd[(d, i)]).abs() < 1e-12);
                    assert!((t.reverse_effectiveness[d][i] - rev[(d, i)]).abs() < 1e-12);
                }
                assert!(t.effectiveness[d][fwd.ncols()..].iter().all(|&x| x == 0.0));
            }
            // Reverse thrust is weaker (T200: 4.1 vs 5.25 kgf).
            let ratio = t.reverse_effectiveness[5][0] / t.effectiveness[5][0];
            assert!((ratio - 4.1 / 5.25).abs() < 1e-9 || t.effectiveness[5][0] == 0.0);
            for _ in 0..10 {
                peer.sample();
            }
            sim.terminate();
            let last = peer.truth();
            assert_eq!(last.seq, 2);
            assert!(last.t_ns > 0);
            assert_eq!(last.effectiveness, t.effectiveness);
        }
        assert_namespace_clean(&ns);
    }
}

/// Runs amour5 with a shipped top45 scenario in lockstep up to just past its event.
/// Also returns the `--truth-file` JSON.
fn run_top45(
    scenario: &str,
) -> (
    Vec<ReconfigEvent>,
    Vec<TruthMsg>,
    Vec<ImuSample>,
    serde_json::Value,
) {
    let ns = NamespaceGuard::unique_for_test("top").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let truth_file = dir.path().join("truth.json");
    let result;
    {
        let mut peer = Peer::new(&ns);
        let sc = scenario_path(scenario);
        let mut sim = Proc::run(
            &ns,
            "amour5",
            &[
                "--lockstep",
                "--noise",
                "none",
                "--scenario",
                sc.to_str().unwrap(),
                "--duration",
                "30.5",
                "--truth-file",
                truth_file.to_str().unwrap(),
            ],
        );
        let mut events = Vec::new();
        let mut truths = vec![peer.truth()];
        let mut samples = Vec::new();
        loop {
            let s = peer.sample();
            // Everything the driver published before this sample is already delivered.
            while let Some(e) = peer.reconfig.recv().unwrap() {
                events.push(e);
            }
            while let Some(t) = peer.truth.recv().unwrap() {
                truths.push(t);
            }
            samples.push(s);
            peer.answer(&s, &[0.0; 5]);
            if s.t_ns >= 30_500_000_000 {
                break;
            }
        }
        // The run ends by itself at --duration with exit code 0.
        let status = sim.wait_exit(TIMEOUT).expect("no exit at --duration");
        assert_eq!(status.code(), Some(0), "{}", sim.log());
        while let Some(t) = peer.truth.recv().unwrap() {
            truths.push(t);
        }
        let json = serde_json::from_str(&fs::read_to_string(&truth_file).unwrap()).unwrap();
        result = (events, truths, samples, json);
    }
    assert_namespace_clean(&ns);
    result
}

#[test]
fn announced_scenario_event_is_published_with_the_new_geometry() {
    let (events, truths, samples, json) = run_top45("top45_announced");
    assert_eq!(events.len(), 1, "{events:?}");
    let e = events[0];
    assert!(e.validate().is_ok());
    assert_eq!(e.kind().unwrap(), ReconfigKind::ThrusterMoved);
    assert_eq!((e.thruster, e.count, e.has_geometry), (0, 5, 1));
    // The declared geometry is amour5_top45's, positions measured from the CG.
    let top45 = Vehicle::load(vehicle_path("amour5_top45")).unwrap();
    let cg = top45.body.cg_m;
    for (i, t) in top45.thrusters.iter().enumerate() {
        let want_position: [f64; 3] = std::array::from_fn(|k| t.position_m[k] - cg[k]);
        let close =
            |a: &[f64; 3], b: &[f64; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12);
        assert!(close(&e.position[i], &want_position), "{e:?}");
        assert!(close(&e.direction[i], &t.direction), "{e:?}");
    }
    let h = std::f64::consts::FRAC_1_SQRT_2;
    assert!((e.direction[0][1] - h).abs() < 1e-12 && (e.direction[0][2] + h).abs() < 1e-12);
    // Truth: start, the change (valid from t = 30 s, published before the sample of 30 s),
    // and the final one.
    assert_eq!(truths.len(), 3, "{truths:?}");
    assert_eq!(truths[1].t_ns, 30_000_000_000);
    let (fwd, _) = Simulator::new(top45, SensorConfig::ideal(200.0), 1)
        .unwrap()
        .truth();
    for d in 0..6 {
        for i in 0..5 {
            assert!((truths[1].effectiveness[d][i] - fwd[(d, i)]).abs() < 1e-9);
        }
    }
    assert_ne!(truths[0].effectiveness, truths[1].effectiveness);
    assert_eq!(samples.last().unwrap().seq, 6101);
    // The truth file holds the same three truths.
    let entries = json["truth"].as_array().unwrap();
    let causes: Vec<&str> = entries
        .iter()
        .map(|e| e["cause"].as_str().unwrap())
        .collect();
    assert_eq!(causes, ["start", "rotate", "final"]);
    assert_eq!(json["vehicle"], "amour5");
    for (entry, msg) in entries.iter().zip(&truths) {
        assert_eq!(entry["t_ns"].as_u64().unwrap(), msg.t_ns);
        for d in 0..6 {
            for i in 0..5 {
                let x = entry["effectiveness"][d][i].as_f64().unwrap();
                assert!((x - msg.effectiveness[d][i]).abs() < 1e-12);
                let r = entry["reverse_effectiveness"][d][i].as_f64().unwrap();
                assert!((r - msg.reverse_effectiveness[d][i]).abs() < 1e-12);
            }
        }
    }
}

#[test]
fn silent_scenario_event_changes_only_the_truth() {
    let (events, truths, _, _) = run_top45("top45_silent");
    assert!(events.is_empty(), "{events:?}");
    assert_eq!(truths.len(), 3);
    assert_eq!(truths[1].t_ns, 30_000_000_000);
    // Yaw (row 2) of T (column 0): zero before, non-zero after the rotation.
    assert!(truths[0].effectiveness[2][0].abs() < 1e-12);
    assert!(truths[1].effectiveness[2][0].abs() > 1.0);
}

#[test]
fn garbage_commands_are_rejected_counted_and_neutral_is_held() {
    let ns = NamespaceGuard::unique_for_test("junk").unwrap();
    {
        let mut peer = Peer::new(&ns);
        let mut sim = Proc::run(&ns, "amour5", &["--lockstep", "--noise", "none"]);
        let mut twin = replica("amour5", NoisePreset::None, 1);
        let full = [1.0, 0.0, 0.0, 0.0, 0.0];
        let mut s = peer.sample();
        assert_matches_replica(&s, &twin.sample());
        let mut rejected = 0;
        for k in 1..=60u64 {
            // Every 5th answer is garbage of some kind; the rest ask for full thrust on T.
            let mut c = peer.command(&s, &full);
            let garbage = match k % 10 {
                5 => {
                    c.thrust[1] = f64::NAN;
                    true
                }
                0 => {
                    match (k / 10) % 4 {
                        0 => c.count = 4,       // wrong count
                        1 => c.thrust[2] = 1.5, // out of range
                        2 => c.thrust[4] = f64::NEG_INFINITY,
                        _ => c.t_ns += 1, // not the sample's time
                    }
                    true
                }
                _ => false,
            };
            if k == 33 {
                // A command for a sample not published yet is rejected but is not the answer:
                // the real answer that follows is applied.
                let mut future = peer.command(&s, &full);
                future.imu_seq += 3;
                future.t_ns += 3 * PERIOD_NS;
                peer.thrust.send(&future).unwrap();
                rejected += 1;
            }
            peer.thrust.send(&c).unwrap();
            if garbage {
                rejected += 1;
                twin.set_commands(&[0.0; 5]).unwrap();
            } else {
                twin.set_commands(&full).unwrap();
            }
            twin.step(PERIOD_NS);
            s = peer.sample();
            assert_matches_replica(&s, &twin.sample());
        }
        sim.terminate();
        assert_eq!(sim.summary_value("rejected"), rejected);
        assert_eq!(sim.summary_value("applied"), 60 - (rejected - 1));
        assert!(sim.log().contains("thrust[1] is NaN"), "{}", sim.log());
    }
    assert_namespace_clean(&ns);
}

#[test]
fn lockstep_waits_for_a_subscriber_then_survives_a_silent_daemon() {
    let ns = NamespaceGuard::unique_for_test("wait").unwrap();
    {
        let dir = tempfile::tempdir().unwrap();
        let cfg = dir.path().join("sim.toml");
        fs::write(
            &cfg,
            "mode = \"lockstep\"\n[sensors]\nnoise = \"none\"\n\
             [lockstep]\ntimeout_ms = 300\nidle_period_ms = 20\n",
        )
        .unwrap();
        let mut sim = Proc::run(&ns, "amour5", &["--config", cfg.to_str().unwrap()]);
        // Nobody is there for a while (the simulator waits for a thrust publisher and sends
        // nothing), then the peer takes longer than the timeout
        // to answer the first sample: no vehicle time may pass meanwhile.
        std::thread::sleep(Duration::from_millis(400));
        let mut peer = Peer::new(&ns);
        let first = peer.sample();
        assert_eq!((first.seq, first.t_ns), (1, 0));
        std::thread::sleep(Duration::from_millis(500));
        assert!(
            peer.imu.recv().unwrap().is_none(),
            "sample published unanswered"
        );
        peer.answer(&first, &[0.0; 5]);
        let second = peer.sample();
        assert_eq!((second.seq, second.t_ns), (2, PERIOD_NS));
        let mut s = second;
        for _ in 0..5 {
            peer.answer(&s, &[1.0, 0.0, 0.0, 0.0, 0.0]);
            s = peer.sample();
        }
        // Stop answering: the first unanswered sample waits the timeout, later ones the idle
        // period, and thrust is neutral meanwhile.
        let t0 = Instant::now();
        let next = peer.sample();
        let waited = t0.elapsed();
        assert_eq!(next.seq, s.seq + 1);
        assert!(
            waited >= Duration::from_millis(250) && waited < Duration::from_secs(3),
            "{waited:?}"
        );
        let t1 = Instant::now();
        let mut last = next;
        for _ in 0..10 {
            last = peer.sample();
        }
        let per_sample = t1.elapsed() / 10;
        assert!(
            per_sample >= Duration::from_millis(15) && per_sample < Duration::from_millis(200),
            "{per_sample:?}"
        );
        // Answers resume lockstep at full speed: 50 round trips take less than the 50 idle
        // periods (1 s) a simulator still pacing idle would need at the least. Measured 3.1
        // ms in all, 4.2 ms with three busy loops beside it (`cargo test -p thruster-sim --test
        // process -- --nocapture lockstep_waits`); the speed of a round trip itself is a
        // bench's figure (tests/benches/latency.rs), not this test's.
        let t2 = Instant::now();
        for _ in 0..50 {
            peer.answer(&last, &[0.0; 5]);
            last = peer.sample();
        }
        eprintln!("50 lockstep round trips in {:?}", t2.elapsed());
        assert!(
            t2.elapsed() < Duration::from_millis(50 * 20),
            "{:?}",
            t2.elapsed()
        );
        sim.terminate();
        assert!(sim.summary_value("timeouts") >= 11);
        // Nothing was sent before the peer (its thrust publisher) was there.
        assert!(sim
            .log()
            .contains("waiting for a publisher of thrust commands"));
        assert!(sim
            .log()
            .contains("waiting for the answer to the first sample"));
        assert!(sim.log().contains("answers are back"));
    }
    assert_namespace_clean(&ns);
}

#[test]
fn sigterm_and_sigint_exit_zero_within_a_second_in_every_wait() {
    // Lockstep blocked on an answer that never comes (2 s timeout), lockstep waiting for a
    // subscriber, and real time (with nobody answering).
    let cases: [(&str, &[&str], bool); 3] = [
        ("TERM", &["--lockstep"], true),
        ("INT", &["--lockstep"], false),
        ("TERM", &["--realtime"], true),
    ];
    for (sig, args, subscribe) in cases {
        let ns = NamespaceGuard::unique_for_test("sig").unwrap();
        {
            let mut peer = subscribe.then(|| Peer::new(&ns));
            let mut sim = Proc::run(&ns, "amour5", args);
            if let Some(p) = &mut peer {
                // Answer the first sample so the lockstep run is mid-way, blocked on the
                // answer to the second.
                let first = p.sample();
                p.answer(&first, &[0.0; 5]);
                p.sample();
            } else {
                std::thread::sleep(Duration::from_millis(300));
            }
            sim.signal(sig);
            let t0 = Instant::now();
            let status = sim.wait_exit(Duration::from_secs(1));
            assert!(
                status.is_some(),
                "SIG{sig} {args:?}: still running\n{}",
                sim.log()
            );
            assert_eq!(status.unwrap().code(), Some(0), "{}", sim.log());
            assert!(t0.elapsed() < Duration::from_secs(1));
            assert!(sim.log().contains("reason=Signal"), "{}", sim.log());
        }
        assert_namespace_clean(&ns);
    }
}

#[test]
fn realtime_paces_by_the_wall_clock_and_the_watchdog_goes_neutral() {
    let ns = NamespaceGuard::unique_for_test("rt").unwrap();
    {
        let mut peer = Peer::new(&ns);
        let mut sim = Proc::run(
            &ns,
            "amour5",
            &["--realtime", "--noise", "none", "--duration", "1.0"],
        );
        let first = peer.sample();
        let t0 = Instant::now();
        // One full-thrust command, then silence: the watchdog stops it after 200 ms.
        peer.answer(&first, &[1.0, 0.0, 0.0, 0.0, 0.0]);
        let mut samples = vec![first];
        while samples.last().unwrap().t_ns < 1_000_000_000 {
            samples.push(peer.sample());
        }
        let wall = t0.elapsed();
        eprintln!("1 s of vehicle time in real time took {wall:?} of wall time");
        let status = sim.wait_exit(TIMEOUT).expect("no exit at --duration");
        assert_eq!(status.code(), Some(0));
        // 201 samples (t = 0 .. 1 s) over about one wall second, none lost. Never faster
        // than the wall clock (0.9 s: our receipt of the first sample may be late, the
        // simulator is not early); the upper bound leaves a loaded machine room (was 1.3 s)
        // and still fails a simulator at half speed. Measured 1.001 s, and 1.005 s with three
        // busy loops beside it.
        assert_eq!(samples.len(), 201);
        assert!(samples.windows(2).all(|w| w[1].seq == w[0].seq + 1));
        assert!(
            wall > Duration::from_millis(900) && wall < Duration::from_millis(2000),
            "{wall:?}"
        );
        // Pitch rate rises while the command is held, then decays once the watchdog cut it.
        let pitch = |t_ms: u64| samples[(t_ms / 5) as usize].gyro[1];
        assert!(pitch(150) > 0.5, "{}", pitch(150));
        assert!(
            pitch(1000) < 0.5 * pitch(300),
            "{} {}",
            pitch(300),
            pitch(1000)
        );
        assert!(sim
            .log()
            .contains("no valid thrust command within the watchdog"));
        assert_eq!(sim.summary_value("applied"), 1);
    }
    assert_namespace_clean(&ns);
}

#[test]
fn the_respond_subcommand_drives_a_lockstep_run_to_its_end() {
    let ns = NamespaceGuard::unique_for_test("resp").unwrap();
    {
        let mut responder = Proc::spawn(&["respond", "--namespace", ns.namespace(), "--neutral"]);
        let mut sim = Proc::run(
            &ns,
            "six_dof",
            &["--lockstep", "--noise", "paper", "--duration", "5"],
        );
        let status = sim.wait_exit(TIMEOUT).expect("no exit at --duration");
        assert_eq!(status.code(), Some(0), "{}", sim.log());
        assert_eq!(sim.summary_value("samples"), 1001);
        assert_eq!(sim.summary_value("applied"), 1001);
        assert_eq!(sim.summary_value("timeouts"), 0);
        responder.terminate();
        assert!(
            responder.log().contains("answered=1001"),
            "{}",
            responder.log()
        );
    }
    assert_namespace_clean(&ns);
}

/// Exit 2 (`EXIT_CONFIG`), as thrusterd's: the units' `RestartPreventExitStatus=2` does not
/// restart what a restart cannot fix, and a script tells a config from a failure.
#[test]
fn bad_configuration_fails_with_file_line_and_key() {
    let ns = NamespaceGuard::unique_for_test("bad").unwrap();
    let x = ns.namespace();
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("bad.toml");
    fs::write(&cfg, "[lockstep]\ntimeout_ms = 100\nspin = 3\n").unwrap();
    let run = |args: &[&str]| {
        let out = Command::new(BIN).args(args).output().unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).to_string(),
        )
    };
    let v = vehicle_path("amour5");
    let (code, err) = run(&[
        "run",
        "--config",
        cfg.to_str().unwrap(),
        "--vehicle",
        v.to_str().unwrap(),
        "--namespace",
        x,
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains(&format!("{}:3:", cfg.display())) && err.contains("spin"),
        "{err}"
    );

    fs::write(&cfg, "[sensors]\nrate_hz = 2000\n").unwrap();
    let (code, err) = run(&["run", "--config", cfg.to_str().unwrap()]);
    assert_eq!(code, Some(2));
    assert!(
        err.contains(&format!("{}:2:", cfg.display())) && err.contains("rate_hz"),
        "{err}"
    );

    let bad_vehicle = dir.path().join("v.toml");
    fs::write(
        &bad_vehicle,
        "[[thruster]]\nname = \"a\"\nposition_m = [0, 0, 0]\ndirection = [0, 0, 0]\n",
    )
    .unwrap();
    let (code, err) = run(&[
        "run",
        "--namespace",
        x,
        "--vehicle",
        bad_vehicle.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(2));
    assert!(
        err.contains("v.toml") && err.contains("thruster[0]") && err.contains("direction"),
        "{err}"
    );

    let (code, err) = run(&["run", "--vehicle", v.to_str().unwrap()]);
    assert_eq!(code, Some(2));
    assert!(err.contains("--namespace"), "{err}");

    // A scenario naming a thruster the vehicle lacks fails before anything runs.
    let sc = dir.path().join("s.toml");
    fs::write(
        &sc,
        "[[event]]\nt_s = 1\naction = { kind = \"kill\", thruster = \"Q\" }\n",
    )
    .unwrap();
    let (code, err) = run(&[
        "run",
        "--namespace",
        x,
        "--vehicle",
        v.to_str().unwrap(),
        "--scenario",
        sc.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(2));
    assert!(err.contains("event[0]") && err.contains("\"Q\""), "{err}");
    // Nothing got as far as creating IPC resources.
    assert_eq!(namespace_files(&ns).unwrap(), Vec::<PathBuf>::new());
}

/// A vehicle with a DVL (`[sensors.dvl]` in the config): the driver publishes its velocity on
/// the `dvl` topic at the configured rate, just before the IMU sample it was taken with, and
/// it reads what the simulator's truth says (noise-free here).
#[test]
fn a_configured_dvl_publishes_the_true_velocity_at_its_rate() {
    let ns = NamespaceGuard::unique_for_test("dvl").unwrap();
    {
        let mut peer = Peer::new(&ns);
        let node = ns.create_node("test-dvl").unwrap();
        let dvl: Inbox<thruster_protocol::DvlSample> = Inbox::create(&node, &ns).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let config = dir.path().join("sim.toml");
        fs::write(
            &config,
            "[sensors]\nrate_hz = 200.0\nnoise = \"none\"\n[sensors.dvl]\nrate_hz = 10.0\nstd_mps = 0.0\n",
        )
        .unwrap();
        let mut sim = Proc::run(
            &ns,
            "amour5",
            &["--lockstep", "--config", config.to_str().unwrap()],
        );
        let mut got = Vec::new();
        let mut last_state = None;
        for _ in 0..200 {
            let s = peer.sample();
            while let Some(v) = peer.vehicle.recv().unwrap() {
                last_state = Some(v);
            }
            while let Some(d) = dvl.recv().unwrap() {
                assert!(d.validate().is_ok(), "{d:?}");
                assert_eq!(d.t_ns, s.t_ns, "taken with the sample that follows it");
                let v = last_state.expect("vehicle state before the sample");
                for a in 0..3 {
                    assert!(
                        (d.velocity[a] - v.velocity[a]).abs() < 1e-9,
                        "{d:?} vs {v:?}"
                    );
                }
                got.push(d);
            }
            // Full forward thrust on L and R: the vehicle surges, so the velocity is not zero.
            peer.answer(&s, &[0.0, 0.0, 0.0, 1.0, 1.0]);
        }
        // 200 samples at 200 Hz = 1 s at 10 Hz: t = 0, 0.1, ..., 0.9 s.
        assert_eq!(got.len(), 10, "{got:?}");
        assert_eq!(
            got.iter().map(|d| d.seq).collect::<Vec<_>>(),
            (1..=10).collect::<Vec<_>>()
        );
        assert!(got.last().unwrap().velocity[0] > 0.05, "{got:?}");
        sim.terminate();
    }
    assert_namespace_clean(&ns);
}

/// A vehicle with T200 thrusters on a battery: the driver reports the battery's voltage and
/// current on driver_status (a fixed supply reports none), the truth carries the voltage and is
/// republished as full thrust sags it, and it matches a replica driven the same way.
#[test]
fn a_battery_vehicle_reports_its_supply_and_the_truth_follows_it() {
    for (vehicle, battery) in [("amour5_t200", true), ("amour5", false)] {
        let ns = NamespaceGuard::unique_for_test("bat").unwrap();
        {
            let node = ns.create_node("test-supply").unwrap();
            let status: Inbox<DriverStatusMsg> = Inbox::create(&node, &ns).unwrap();
            let mut peer = Peer::new(&ns);
            let mut sim = Proc::run(&ns, vehicle, &["--lockstep", "--noise", "none"]);
            let first = peer.truth();
            assert_eq!(first.battery, u32::from(battery), "{vehicle}");
            let mut twin = replica(vehicle, NoisePreset::None, 1);
            assert!((first.supply_voltage_v - twin.supply_voltage_v()).abs() < 1e-9);
            let mut last = peer.sample();
            // 0.5 s at full thrust.
            for _ in 0..100 {
                peer.answer(&last, &[1.0; 5]);
                twin.set_commands(&[1.0; 5]).unwrap();
                twin.step(PERIOD_NS);
                last = peer.sample();
            }
            let mut report = None;
            while let Some(r) = peer.try_next(&status, Duration::from_millis(200)) {
                assert!(r.validate().is_ok(), "{r:?}");
                report = Some(r);
            }
            let report = report.expect("driver status");
            if battery {
                let v = report.supply_voltage().expect("a battery is measured");
                // Full thrust sags 16.8 V by about 2 V (sim-driver/tests/battery.rs).
                assert!((14.3..14.9).contains(&v), "{v}");
                assert!(report.supply_current().unwrap() > 80.0);
                assert!((v - twin.supply_voltage_v()).abs() < 0.05, "{v}");
                let mut truth = first;
                while let Some(t) = peer.try_next(&peer.truth, Duration::from_millis(200)) {
                    truth = t;
                }
                assert!(truth.seq > first.seq, "republished as the voltage sagged");
                assert!((truth.supply_voltage_v - v).abs() < 0.05);
                let (fwd, _) = twin.truth_at(truth.supply_voltage_v);
                assert!((truth.effectiveness[0][0] - fwd[(0, 0)]).abs() < 1e-9);
                // Weaker than at rest, as the table says for the lower voltage.
                assert!(truth.effectiveness[1][0].abs() < first.effectiveness[1][0].abs());
            } else {
                assert!(report.supply_voltage().is_none() && report.supply_current().is_none());
                assert_eq!(first.supply_voltage_v, 16.0);
            }
            sim.terminate();
        }
        assert_namespace_clean(&ns);
    }
}

/// `--stepped` (issue 27): the simulator takes exactly the samples its controller allows,
/// reports where it holds, takes none while it waits, refuses a bad line with a message that
/// names it, and stops cleanly when its controller closes standard input.
#[test]
fn a_stepped_run_takes_exactly_the_samples_it_is_allowed() {
    use std::io::{BufRead, BufReader, Write};
    use std::sync::mpsc;

    let ns = NamespaceGuard::unique_for_test("step").unwrap();
    {
        let mut responder = Proc::spawn(&["respond", "--namespace", ns.namespace(), "--neutral"]);
        let spawn = || {
            let v = vehicle_path("six_dof");
            Launch::new(std::path::Path::new(BIN))
                .args(&["run", "--namespace", ns.namespace(), "--vehicle"])
                .args(&[v.to_str().unwrap()])
                .args(&["--noise", "none", "--lockstep", "--stepped"])
                .spawn_piped()
                .unwrap()
        };
        let (mut sim, mut to_sim, out) = spawn();
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for l in BufReader::new(out).lines().map_while(Result::ok) {
                let _ = tx.send(l);
            }
        });
        let next = || {
            lines
                .recv_timeout(TIMEOUT)
                .expect("a line from the simulator")
        };
        assert_eq!(next(), "at 1 0", "the first hold is after sample 1");
        for (n, want_seq) in [(8u64, 9u64), (2, 11)] {
            writeln!(to_sim, "run {n}").unwrap();
            assert_eq!(
                next(),
                format!("at {want_seq} {}", (want_seq - 1) * PERIOD_NS)
            );
        }
        // Held: nothing is taken while the controller thinks.
        std::thread::sleep(Duration::from_millis(300));
        assert!(lines.try_recv().is_err(), "a line while held");
        writeln!(to_sim, "run 1").unwrap();
        assert_eq!(next(), format!("at 12 {}", 11 * PERIOD_NS));
        writeln!(to_sim, "walk 3").unwrap();
        let status = sim.wait_timeout(TIMEOUT).expect("no exit on a bad line");
        let text = sim.log_text();
        assert!(!status.success(), "a bad line must fail the run\n{text}");
        assert!(
            text.contains("walk 3"),
            "the message names the line\n{text}"
        );

        // A controller that goes away (its end of stdin closed) ends the run cleanly.
        let (mut sim, to_sim, out) = spawn();
        let mut from_sim = BufReader::new(out);
        let mut first = String::new();
        from_sim.read_line(&mut first).unwrap();
        assert_eq!(first.trim(), "at 1 0");
        drop(to_sim);
        let status = sim
            .wait_timeout(TIMEOUT)
            .expect("no exit when stdin closed");
        assert!(status.success(), "{}", sim.log_text());
        responder.terminate();
    }
    assert_namespace_clean(&ns);
}
