//! The driver contract's conformance suite: the same tests against every driver process (the
//! simulator and each hardware backend), each test file implementing [`DriverUnderTest`] and
//! instantiating the suite with [`conformance_suite!`](crate::conformance_suite) (the
//! iceoryx2 pattern: one contract, one suite, run from every backend's own test file).
//!
//! The suite plays the daemon over real iceoryx2 and sees the driver only through the
//! protocol: the IMU samples it publishes and its `driver_status`. What a driver does to its
//! hardware (pulses, a serial link) is the backend's own tests' business. The contract:
//! - IMU samples at the configured rate, `seq` +1 and `t_ns` strictly increasing, valid;
//! - valid answers are applied (status `Active`, counted as accepted);
//! - a command that fails the command gate (NaN, infinity, out of range, wrong count, an
//!   unpublished sample) is counted as rejected and the outputs go neutral at once;
//! - when commands stop, the watchdog takes the outputs to neutral and counts the expiry;
//! - SIGTERM ends the process with code 0, leaving no node and no file of its namespace.
//!
//! Each test has its own iceoryx2 namespace ([`NamespaceGuard::unique_for_test`]) and the
//! process is killed and reaped in a `Drop` guard if the test fails.

use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use thruster_protocol::services::{
    cleanup_dead_nodes, namespace_files, Inbox, IpcConfig, IpcNode, NamespaceGuard, Port, SHM_DIR,
};
use thruster_protocol::{
    DriverStatusMsg, ImuSample, OutputState, ThrustCommand, ThrustMode, Validate,
};

/// How long the suite waits for anything a driver should do promptly.
pub const TIMEOUT: Duration = Duration::from_secs(10);

/// The watchdog every driver under test is configured with, ms.
pub const WATCHDOG_MS: u64 = 200;

/// A driver process for the suite: how to start it on a namespace.
pub trait DriverUnderTest: Sized {
    /// Short name, for namespaces and messages ("sim", "mavlink", "linux").
    const NAME: &'static str;
    /// The IMU rate it is configured for, Hz.
    const RATE_HZ: f64;
    /// Thrusters it is configured for.
    const THRUSTERS: usize;

    /// Starts the driver on `ns` with a watchdog of [`WATCHDOG_MS`], its IMU at
    /// [`Self::RATE_HZ`] and a short arming hold (if it has one); returns the fixture (fake
    /// hardware, kept alive for the test) and the process.
    fn start(ns: &IpcConfig) -> (Self, DriverProcess);
}

/// A driver's process: the one test launcher's ([`crate::test_process`]).
pub use crate::test_process::TestProcess as DriverProcess;

/// The test in the daemon's place: receives IMU samples and driver status, sends commands.
pub struct TestDaemon {
    imu: Inbox<ImuSample>,
    status: Inbox<DriverStatusMsg>,
    thrust: Port<ThrustCommand>,
    seq: u64,
    last_status: Option<DriverStatusMsg>,
    _node: IpcNode,
}

impl TestDaemon {
    /// Ports on `ns`.
    pub fn new(ns: &IpcConfig) -> TestDaemon {
        let node = ns.create_node("conformance-daemon").expect("node");
        TestDaemon {
            imu: Inbox::create(&node, ns).expect("imu inbox"),
            status: Inbox::create(&node, ns).expect("driver_status inbox"),
            thrust: Port::create(&node, ns).expect("thrust port"),
            seq: 0,
            last_status: None,
            _node: node,
        }
    }

    /// The next sample within `within`, if any.
    pub fn try_sample(&self, within: Duration) -> Option<ImuSample> {
        let end = Instant::now() + within;
        loop {
            if let Some(s) = self.imu.recv().expect("imu recv") {
                return Some(s);
            }
            let now = Instant::now();
            if now >= end {
                return None;
            }
            std::thread::sleep((end - now).min(Duration::from_millis(1)));
        }
    }

    /// Drops buffered samples and returns the next one.
    pub fn fresh_sample(&self) -> ImuSample {
        while self.imu.recv().expect("imu recv").is_some() {}
        self.try_sample(TIMEOUT).expect("no IMU sample within 10 s")
    }

    /// A command answering `s` with `thrust`.
    pub fn command(&mut self, s: &ImuSample, thrust: &[f64]) -> ThrustCommand {
        self.seq += 1;
        let mut c = ThrustCommand::neutral(self.seq, s.seq, s.t_ns, thrust.len() as u32);
        c.set_mode(ThrustMode::Controlling);
        c.thrusters_mut().copy_from_slice(thrust);
        c
    }

    /// Sends `cmd`.
    pub fn send(&self, cmd: &ThrustCommand) {
        self.thrust.send(cmd).expect("thrust send");
    }

    /// Answers every sample with `thrust` for `duration`.
    pub fn hold(&mut self, thrust: &[f64], duration: Duration) {
        let end = Instant::now() + duration;
        while Instant::now() < end {
            if let Some(s) = self.try_sample(Duration::from_millis(50)) {
                let c = self.command(&s, thrust);
                self.send(&c);
            }
        }
    }

    /// The newest driver status received so far.
    pub fn status(&mut self) -> Option<DriverStatusMsg> {
        while let Some(m) = self.status.recv().expect("status recv") {
            self.last_status = Some(m);
        }
        self.last_status
    }

    /// Answers samples with `thrust` (when `Some`) until a driver status satisfies `pred`;
    /// panics after `within`.
    pub fn until_status(
        &mut self,
        thrust: Option<&[f64]>,
        within: Duration,
        pred: impl Fn(&DriverStatusMsg) -> bool,
    ) -> DriverStatusMsg {
        let end = Instant::now() + within;
        loop {
            if let Some(m) = self.status().filter(|m| pred(m)) {
                return m;
            }
            assert!(
                Instant::now() < end,
                "no matching driver status within {within:?}; last {:?}",
                self.last_status
            );
            match thrust {
                Some(t) => {
                    if let Some(s) = self.try_sample(Duration::from_millis(20)) {
                        let c = self.command(&s, t);
                        self.send(&c);
                    }
                }
                None => std::thread::sleep(Duration::from_millis(5)),
            }
        }
    }
}

/// Every process of the namespace has exited and dropped its ports: only iceoryx2's own
/// residue (the global_mgmt segment and empty directories) is left, which the guard purges.
pub fn assert_namespace_clean(ns: &IpcConfig) {
    let census = cleanup_dead_nodes(ns).expect("node census");
    assert_eq!(
        (census.alive, census.dead_cleaned, census.dead_failed),
        (0, 0, 0),
        "nodes left: {census:?}"
    );
    let leftovers: Vec<PathBuf> = namespace_files(ns)
        .expect("namespace files")
        .into_iter()
        .filter(|p| !p.is_dir())
        .filter(|p| {
            let name = p.file_name().unwrap_or_default().to_string_lossy();
            !(p.starts_with(SHM_DIR) && name.ends_with(".global_mgmt"))
        })
        .collect();
    assert!(leftovers.is_empty(), "files left: {leftovers:#?}");
}

static SERIAL: Mutex<()> = Mutex::new(());

/// The suite's tests run one at a time: they measure rates and delays on a small machine.
fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

/// A running driver with the test as its daemon. Fields drop in order: the process first,
/// then our ports, the fixture, and last the namespace (purged).
pub struct Run<D: DriverUnderTest> {
    /// The driver process.
    pub proc: DriverProcess,
    /// The test's ports.
    pub daemon: TestDaemon,
    /// The driver's fake hardware, if any.
    pub fixture: D,
    /// The test's namespace.
    pub ns: NamespaceGuard,
}

impl<D: DriverUnderTest> Run<D> {
    /// Starts `D` on a fresh namespace with the test's ports.
    pub fn start() -> Run<D> {
        let ns = NamespaceGuard::unique_for_test(D::NAME).expect("namespace");
        let daemon = TestDaemon::new(&ns);
        let (fixture, proc) = D::start(&ns);
        Run {
            proc,
            daemon,
            fixture,
            ns,
        }
    }

    /// Answers with `thrust` until the driver reports its outputs active (past any arming
    /// hold) and returns that status.
    pub fn drive(&mut self, thrust: &[f64]) -> DriverStatusMsg {
        self.daemon.until_status(Some(thrust), TIMEOUT, |m| {
            m.output_state() == Ok(OutputState::Active) && m.commands_accepted > 0
        })
    }

    /// SIGTERM, a clean exit, our ports dropped, nothing of the namespace left; returns the
    /// process's log.
    pub fn finish(self) -> String {
        let Run {
            mut proc,
            daemon,
            fixture,
            ns,
        } = self;
        let status = proc.terminate(Duration::from_secs(2));
        let log = proc.log_text();
        assert!(
            status.is_some(),
            "{}: no exit within 2 s of SIGTERM\n{log}",
            D::NAME
        );
        assert_eq!(status.and_then(|s| s.code()), Some(0), "{log}");
        drop(daemon);
        drop(fixture);
        assert_namespace_clean(&ns);
        log
    }
}

/// A thrust of `u` on every thruster of `D`.
fn all<D: DriverUnderTest>(u: f64) -> Vec<f64> {
    vec![u; D::THRUSTERS]
}

/// IMU samples come at the configured rate, numbered +1, strictly increasing in time, each
/// valid.
pub fn publishes_imu_at_its_rate<D: DriverUnderTest>() {
    let _s = serial();
    let run = Run::<D>::start();
    let first = run.daemon.fresh_sample();
    let t0 = Instant::now();
    let mut samples = vec![first];
    while samples.len() < 50 {
        samples.push(run.daemon.try_sample(TIMEOUT).expect("samples stopped"));
    }
    let rate = 49.0 / t0.elapsed().as_secs_f64();
    assert!(
        (0.6 * D::RATE_HZ..=1.4 * D::RATE_HZ).contains(&rate),
        "{rate:.1} Hz, configured {} Hz",
        D::RATE_HZ
    );
    for w in samples.windows(2) {
        assert_eq!(w[1].seq, w[0].seq + 1, "consecutive seq");
        assert!(w[1].t_ns > w[0].t_ns, "time advances: {:?}", w);
    }
    for s in &samples {
        s.validate().expect("a valid sample");
    }
    run.finish();
}

/// Valid answers are applied: the status says active and counts them.
pub fn applies_valid_commands<D: DriverUnderTest>() {
    let _s = serial();
    let mut run = Run::<D>::start();
    let status = run.drive(&all::<D>(0.3));
    assert_eq!(status.thruster_count as usize, D::THRUSTERS);
    assert_eq!(status.commands_rejected, 0, "{status:?}");
    run.finish();
}

type MakeCommand = fn(&mut TestDaemon, usize) -> ThrustCommand;

/// Every kind of garbage is rejected, counted, and takes the outputs neutral at once.
pub fn refuses_garbage_and_goes_neutral<D: DriverUnderTest>() {
    let _s = serial();
    let mut run = Run::<D>::start();
    let garbage: [(&str, MakeCommand); 6] = [
        ("NaN", |d, n| {
            let s = d.fresh_sample();
            let mut u = vec![0.5; n];
            u[0] = f64::NAN;
            d.command(&s, &u)
        }),
        ("-inf", |d, n| {
            let s = d.fresh_sample();
            let mut u = vec![0.5; n];
            u[n - 1] = f64::NEG_INFINITY;
            d.command(&s, &u)
        }),
        ("1e9", |d, n| {
            let s = d.fresh_sample();
            let mut u = vec![0.5; n];
            u[0] = 1e9;
            d.command(&s, &u)
        }),
        ("wrong count", |d, n| {
            let s = d.fresh_sample();
            d.command(&s, &vec![0.5; n - 1])
        }),
        ("unpublished sample", |d, n| {
            let s = d.fresh_sample();
            let mut c = d.command(&s, &vec![0.5; n]);
            c.imu_seq += 1000;
            c
        }),
        ("wrong sample time", |d, n| {
            let s = d.fresh_sample();
            let mut c = d.command(&s, &vec![0.5; n]);
            c.t_ns += 1;
            c
        }),
    ];
    for (name, make) in garbage {
        let before = run.drive(&all::<D>(0.5)).commands_rejected;
        let cmd = make(&mut run.daemon, D::THRUSTERS);
        run.daemon.send(&cmd);
        let t = Instant::now();
        let status = run.daemon.until_status(None, Duration::from_secs(2), |m| {
            m.commands_rejected > before && m.output_state() == Ok(OutputState::Neutral)
        });
        // Well before the watchdog could have acted.
        assert!(
            t.elapsed() < Duration::from_millis(WATCHDOG_MS),
            "{name}: neutral after {:?}",
            t.elapsed()
        );
        assert_eq!(status.commands_rejected, before + 1, "{name}: {status:?}");
    }
    run.finish();
}

/// When commands stop, the watchdog takes the outputs neutral and counts the expiry.
pub fn watchdog_goes_neutral_when_commands_stop<D: DriverUnderTest>() {
    let _s = serial();
    let mut run = Run::<D>::start();
    let active = run.drive(&all::<D>(0.4));
    let t = Instant::now();
    let status = run.daemon.until_status(None, Duration::from_secs(3), |m| {
        m.output_state() == Ok(OutputState::Neutral)
    });
    let after = t.elapsed();
    assert!(
        after >= Duration::from_millis(WATCHDOG_MS / 2),
        "neutral {after:?} after the last command, watchdog {WATCHDOG_MS} ms"
    );
    assert_eq!(
        status.watchdog_expiries,
        active.watchdog_expiries + 1,
        "{status:?}"
    );
    assert_eq!(status.commands_rejected, 0, "{status:?}");
    run.finish();
}

/// SIGTERM while commanded: exit code 0 and nothing of the namespace left (checked by
/// [`Run::finish`]).
pub fn sigterm_exits_cleanly<D: DriverUnderTest>() {
    let _s = serial();
    let mut run = Run::<D>::start();
    run.drive(&all::<D>(0.2));
    // Commanded right up to the signal.
    run.daemon.hold(&all::<D>(0.2), Duration::from_millis(100));
    run.finish();
}

/// Instantiates the suite for each `name: Fixture` pair as a module of tests.
#[macro_export]
macro_rules! conformance_suite {
    ($($name:ident: $driver:ty),* $(,)?) => {$(
        mod $name {
            // The fixture type is named in the test file's scope.
            #[allow(unused_imports)]
            use super::*;
            use $crate::conformance as suite;
            #[test]
            fn publishes_imu_at_its_rate() {
                suite::publishes_imu_at_its_rate::<$driver>()
            }
            #[test]
            fn applies_valid_commands() {
                suite::applies_valid_commands::<$driver>()
            }
            #[test]
            fn refuses_garbage_and_goes_neutral() {
                suite::refuses_garbage_and_goes_neutral::<$driver>()
            }
            #[test]
            fn watchdog_goes_neutral_when_commands_stop() {
                suite::watchdog_goes_neutral_when_commands_stop::<$driver>()
            }
            #[test]
            fn sigterm_exits_cleanly() {
                suite::sigterm_exits_cleanly::<$driver>()
            }
        }
    )*};
}
