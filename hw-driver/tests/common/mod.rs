//! Shared by the integration tests: the real `thruster-hw` process, the test playing the
//! daemon over real iceoryx2, fake hardware for each backend, and the backend fixtures the
//! conformance suite is generic over.
#![allow(dead_code)] // each test binary uses a different part

pub mod fake_autopilot;
pub mod fake_sysfs;
pub mod inotify;

use std::fs;
use std::path::Path;
use std::process::ExitStatus;
use std::time::{Duration, Instant};

use thruster_driver_kit::test_process::TestProcess;
use thruster_hw::clock::monotonic_ns;
use thruster_protocol::services::{Inbox, IpcConfig, IpcNode, NamespaceGuard, Port};
use thruster_protocol::{DriverStatusMsg, ImuSample, ThrustCommand, ThrustMode};

use fake_autopilot::FakeAutopilot;
use fake_sysfs::FakeSysfs;

pub const BIN: &str = env!("CARGO_BIN_EXE_thruster-hw");
pub const TIMEOUT: Duration = Duration::from_secs(10);
pub const MS: u64 = 1_000_000;

// ---- the child process -------------------------------------------------------------------

/// The `thruster-hw` child: the one test launcher's (`TestProcess`: always killed and reaped,
/// its log printed when the test panics), and the folder its config file lives in (removed
/// after the process is gone: fields drop in order).
pub struct Proc(TestProcess, tempfile::TempDir);

impl Proc {
    /// Writes `config` to a file and runs `thruster-hw run --config FILE extra...`.
    pub fn run(config: &str, extra: &[&str]) -> Proc {
        let dir = tempfile::tempdir().unwrap();
        let cfg = dir.path().join("thruster-hw.toml");
        fs::write(&cfg, config).unwrap();
        let mut args = vec!["run", "--config", cfg.to_str().unwrap()];
        args.extend_from_slice(extra);
        Proc(TestProcess::spawn(BIN, &args).unwrap(), dir)
    }

    pub fn pid(&self) -> i32 {
        self.0.pid() as i32
    }

    pub fn signal(&self, sig: i32) {
        self.0.signal_number(sig);
    }

    /// Waits for the exit (reaping the child); `None` if still running at `within`.
    pub fn wait_exit(&mut self, within: Duration) -> Option<ExitStatus> {
        self.0.wait_timeout(within)
    }

    /// SIGTERM; asserts a clean exit (code 0) within a second.
    pub fn terminate(&mut self) {
        self.0.stop_cleanly(Duration::from_secs(1));
    }

    pub fn log(&self) -> String {
        self.0.log_text()
    }

    /// Where its config file is.
    pub fn dir(&self) -> &Path {
        self.1.path()
    }

    /// The value of `key=` in the final summary line.
    pub fn summary_value(&self, key: &str) -> u64 {
        self.0.summary_value("thruster-hw stopped", key)
    }
}

// ---- the test playing the daemon ---------------------------------------------------------

pub struct Daemon {
    imu: Inbox<ImuSample>,
    status: Inbox<DriverStatusMsg>,
    thrust: Port<ThrustCommand>,
    seq: u64,
    _node: IpcNode,
}

impl Daemon {
    pub fn new(ns: &IpcConfig) -> Daemon {
        let node = ns.create_node("test-daemon").unwrap();
        Daemon {
            imu: Inbox::create(&node, ns).unwrap(),
            status: Inbox::create(&node, ns).unwrap(),
            thrust: Port::create(&node, ns).unwrap(),
            seq: 0,
            _node: node,
        }
    }

    /// The next sample within `within`, if any.
    pub fn try_sample(&self, within: Duration) -> Option<ImuSample> {
        let end = Instant::now() + within;
        loop {
            if let Some(s) = self.imu.recv().unwrap() {
                return Some(s);
            }
            let now = Instant::now();
            if now >= end {
                return None;
            }
            self.imu.drain_events().unwrap();
            if let Some(s) = self.imu.recv().unwrap() {
                return Some(s);
            }
            let _ = self.imu.wait((end - now).min(Duration::from_millis(20)));
        }
    }

    /// Every driver status received since the last call, oldest first.
    pub fn statuses(&self) -> Vec<DriverStatusMsg> {
        let mut v = Vec::new();
        while let Some(m) = self.status.recv().unwrap() {
            v.push(m);
        }
        v
    }

    /// Waits for a driver status satisfying `pred`; panics after `within`.
    pub fn wait_status(
        &self,
        within: Duration,
        pred: impl Fn(&DriverStatusMsg) -> bool,
    ) -> DriverStatusMsg {
        let end = Instant::now() + within;
        let mut last = None;
        loop {
            for m in self.statuses() {
                if pred(&m) {
                    return m;
                }
                last = Some(m);
            }
            assert!(
                Instant::now() < end,
                "no matching driver status within {within:?}; last {last:?}"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Drops buffered samples and returns the next fresh one.
    pub fn fresh_sample(&self) -> ImuSample {
        while self.imu.recv().unwrap().is_some() {}
        self.try_sample(TIMEOUT)
            .expect("no IMU sample within the timeout")
    }

    /// A command answering `s`.
    pub fn command(&mut self, s: &ImuSample, thrust: &[f64]) -> ThrustCommand {
        self.seq += 1;
        let mut c = ThrustCommand::neutral(self.seq, s.seq, s.t_ns, thrust.len() as u32);
        c.set_mode(ThrustMode::Controlling);
        c.thrusters_mut().copy_from_slice(thrust);
        c
    }

    /// Sends `cmd`; returns the CLOCK_MONOTONIC time just before publishing.
    pub fn send(&self, cmd: &ThrustCommand) -> u64 {
        let t = monotonic_ns();
        self.thrust.send(cmd).unwrap();
        t
    }

    /// Answers the next fresh sample with `thrust`; returns the sample and the send time.
    pub fn answer(&mut self, thrust: &[f64]) -> (ImuSample, u64) {
        let s = self.fresh_sample();
        let c = self.command(&s, thrust);
        (s, self.send(&c))
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
}

/// Every process of the namespace has exited and dropped its ports (the driver contract's
/// suite checks the same).
pub use thruster_driver_kit::conformance::assert_namespace_clean;

// ---- backend fixtures ----------------------------------------------------------------------

/// The body-frame IMU state a fixture makes its hardware report.
#[derive(Debug, Clone, Copy)]
pub struct Imu {
    pub gyro: [f64; 3],
    pub accel: [f64; 3],
    pub mag_ut: [f64; 3],
    pub depth_m: f64,
}

/// Fake hardware for one backend: config section, observed pulses, injected sensor values.
pub trait Fixture {
    const BACKEND: &'static str;
    /// Output channels of the conformance suite's four thrusters.
    const CHANNELS: [u32; 4];
    /// Quantisation of the hardware: gyro rad/s, accel m/s^2, mag uT, depth m.
    const TOLERANCE: [f64; 4];

    fn new() -> Self;
    /// The backend's config section for this fake, with `extra` lines inside it.
    fn section(&self, extra: &str) -> String;
    /// The pulse each thruster's output carries now, us (None until all are seen).
    fn pulses(&self) -> Option<Vec<u16>>;
    /// Every pulse the hardware got: (CLOCK_MONOTONIC ns, thruster index, us).
    fn history(&self) -> Vec<(u64, usize, u16)>;
    /// Makes the hardware report `imu` from now on.
    fn set_imu(&self, imu: &Imu);
}

pub struct Mavlink(pub FakeAutopilot);

/// DO_MOTOR_TEST param1 ArduSub expects for config channel `ch` (its 0-based motor index).
pub fn motor_index(ch: u32) -> f32 {
    (ch - 1) as f32
}

impl Fixture for Mavlink {
    const BACKEND: &'static str = "mavlink";
    const CHANNELS: [u32; 4] = [1, 2, 3, 4];
    // 1 mrad/s, 1 mG, 1 mgauss steps; pressure as f32 hPa.
    const TOLERANCE: [f64; 4] = [0.0006, 0.0060, 0.06, 0.001];

    fn new() -> Self {
        Mavlink(FakeAutopilot::start())
    }

    fn section(&self, extra: &str) -> String {
        format!(
            "[mavlink]\naddress = \"{}\"\nimu_rate_hz = 100.0\ncommand_timeout_ms = 300\n{extra}\n",
            self.0.address()
        )
    }

    /// Until the driver's first motor test ArduSub drives its outputs itself, at neutral
    /// (nothing commands them: the driver stays out of motor-test mode while it has nothing
    /// to command), so a channel without a motor test reads its neutral.
    fn pulses(&self) -> Option<Vec<u16>> {
        let tests = self.0.with(|s| s.motor_tests());
        Self::CHANNELS
            .iter()
            .enumerate()
            .map(|(k, &ch)| {
                let last = tests
                    .iter()
                    .rev()
                    .find(|(_, c)| c.param1 == motor_index(ch))
                    .map(|(_, c)| c.param3 as u16);
                Some(last.unwrap_or(NEUTRAL[k]))
            })
            .collect()
    }

    fn history(&self) -> Vec<(u64, usize, u16)> {
        self.0
            .with(|s| s.motor_tests())
            .into_iter()
            .filter_map(|(t, c)| {
                let i = Self::CHANNELS
                    .iter()
                    .position(|&ch| c.param1 == motor_index(ch))?;
                Some((t, i, c.param3 as u16))
            })
            .collect()
    }

    fn set_imu(&self, imu: &Imu) {
        let mg = |v: f64| (v / 9.80665 * 1000.0).round() as i16;
        self.0.with(|s| {
            s.gyro = imu.gyro.map(|v| (v * 1000.0).round() as i16);
            s.acc = imu.accel.map(mg);
            s.mag = imu.mag_ut.map(|v| (v * 10.0).round() as i16);
            s.press_hpa = (1013.25 + imu.depth_m * 997.0 * 9.80665 / 100.0) as f32;
        });
    }
}

pub struct Linux(pub FakeSysfs);

impl Fixture for Linux {
    const BACKEND: &'static str = "linux";
    const CHANNELS: [u32; 4] = [0, 1, 2, 5];
    const TOLERANCE: [f64; 4] = [
        fake_sysfs::GYRO_SCALE,
        fake_sysfs::ACCEL_SCALE,
        fake_sysfs::MAGN_SCALE * 100.0,
        1e-5,
    ];

    fn new() -> Self {
        Linux(FakeSysfs::new(true))
    }

    fn section(&self, extra: &str) -> String {
        format!(
            "[linux]\nsysfs_root = \"{}\"\nrate_hz = 100.0\ngyro_device = \"icm20602\"\n\
             mag_device = \"iio:device1\"\npressure_device = \"ms5837\"\n\
             fluid_density_kg_m3 = {}\nsurface_pressure_kpa = {}\n{extra}\n",
            self.0.root().display(),
            fake_sysfs::DENSITY,
            fake_sysfs::SURFACE_KPA,
        )
    }

    fn pulses(&self) -> Option<Vec<u16>> {
        Self::CHANNELS
            .iter()
            .map(|&ch| self.0.pulse_us(ch))
            .collect()
    }

    fn history(&self) -> Vec<(u64, usize, u16)> {
        self.0
            .writes()
            .into_iter()
            .filter(|w| w.attr == "duty_cycle")
            .filter_map(|w| {
                let i = Self::CHANNELS
                    .iter()
                    .position(|&ch| Some(ch) == w.channel)?;
                let ns: u64 = w.value.parse().ok()?;
                Some((w.t_ns, i, (ns / 1000) as u16))
            })
            .collect()
    }

    fn set_imu(&self, imu: &Imu) {
        self.0.set_imu(imu.gyro, imu.accel, imu.mag_ut, imu.depth_m);
    }
}

/// The conformance suite's four thrusters on `channels`: plain; reversed; trim +10 us;
/// range 1200-1800 us.
pub fn thrusters(channels: [u32; 4]) -> String {
    format!(
        "[[thruster]]\nchannel = {}\n\
         [[thruster]]\nchannel = {}\nreversed = true\n\
         [[thruster]]\nchannel = {}\ntrim_us = 10\n\
         [[thruster]]\nchannel = {}\nmin_us = 1200\nmax_us = 1800\n",
        channels[0], channels[1], channels[2], channels[3]
    )
}

/// Neutral of those thrusters.
pub const NEUTRAL: [u16; 4] = [1500, 1500, 1510, 1500];
/// Their ranges.
pub const RANGES: [(u16, u16); 4] = [(1100, 1900), (1100, 1900), (1100, 1900), (1200, 1800)];

/// The driver's config file for fake hardware `fx` on `ns`: the four thrusters, a 200 ms
/// watchdog, `arming_ms`, `extra` top-level lines and `section_extra` lines in the backend's
/// section.
pub fn config<F: Fixture>(
    ns: &IpcConfig,
    arming_ms: u64,
    extra: &str,
    section_extra: &str,
    fx: &F,
) -> String {
    format!(
        "namespace = \"{}\"\nbackend = \"{}\"\nwatchdog_ms = 200\narming_ms = {arming_ms}\n\
         status_period_ms = 1000\n{extra}\n{}{}",
        ns.namespace(),
        F::BACKEND,
        thrusters(F::CHANNELS),
        fx.section(section_extra)
    )
}

/// A backend on its fake hardware as the driver contract's conformance suite
/// (`thruster_driver_kit::conformance`) starts it: the four thrusters, IMU at 100 Hz, a
/// 100 ms arming hold. The config file lives in `dir`, removed with it.
pub struct Contract<F: Fixture> {
    pub fx: F,
    dir: tempfile::TempDir,
}

impl<F: Fixture> thruster_driver_kit::conformance::DriverUnderTest for Contract<F> {
    const NAME: &'static str = F::BACKEND;
    const RATE_HZ: f64 = 100.0;
    const THRUSTERS: usize = 4;

    fn start(ns: &IpcConfig) -> (Self, thruster_driver_kit::conformance::DriverProcess) {
        let fx = F::new();
        let dir = tempfile::tempdir().unwrap();
        let cfg = dir.path().join("thruster-hw.toml");
        fs::write(&cfg, config(ns, 100, "", "", &fx)).unwrap();
        let proc = thruster_driver_kit::conformance::DriverProcess::spawn(
            BIN,
            &["run", "--config", cfg.to_str().unwrap()],
        )
        .unwrap();
        (Contract { fx, dir }, proc)
    }
}

impl<F: Fixture> Contract<F> {
    /// Where the config file is.
    pub fn dir(&self) -> &Path {
        self.dir.path()
    }
}

/// A running driver on fake hardware with the test as its daemon. Fields drop in order:
/// process first, then our ports, the fake hardware, and last the namespace (purged).
pub struct Harness<F: Fixture> {
    pub proc: Proc,
    pub daemon: Daemon,
    pub fx: F,
    pub ns: NamespaceGuard,
}

impl<F: Fixture> Harness<F> {
    /// Starts a driver with `arming_ms` and the fixture's section (plus `extra` TOML lines
    /// at the top level).
    pub fn start(arming_ms: u64, extra: &str) -> Harness<F> {
        Self::start_with(arming_ms, extra, "", |_| {})
    }

    /// As [`Harness::start`], with `section_extra` lines in the backend's section and
    /// `setup` applied to the fake hardware before the driver starts.
    pub fn start_with(
        arming_ms: u64,
        extra: &str,
        section_extra: &str,
        setup: impl FnOnce(&F),
    ) -> Harness<F> {
        let fx = F::new();
        setup(&fx);
        Self::start_fx(arming_ms, extra, section_extra, fx)
    }

    /// As [`Harness::start_with`] with fake hardware made by the test.
    pub fn start_fx(arming_ms: u64, extra: &str, section_extra: &str, fx: F) -> Harness<F> {
        let ns = NamespaceGuard::unique_for_test(F::BACKEND).unwrap();
        let config = config(&ns, arming_ms, extra, section_extra, &fx);
        let daemon = Daemon::new(&ns);
        let proc = Proc::run(&config, &[]);
        Harness {
            proc,
            daemon,
            fx,
            ns,
        }
    }

    /// Waits until the observed pulses satisfy `pred`; returns them.
    pub fn wait_pulses(&self, within: Duration, pred: impl Fn(&[u16]) -> bool) -> Vec<u16> {
        let end = Instant::now() + within;
        loop {
            let p = self.fx.pulses();
            if let Some(p) = &p {
                if pred(p) {
                    return p.clone();
                }
            }
            assert!(
                Instant::now() < end,
                "pulses {p:?} did not reach the expected state within {within:?}\n{}",
                self.proc.log()
            );
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// Answers samples with `thrust` until the pulses equal `expected`.
    pub fn drive_to(&mut self, thrust: &[f64], expected: [u16; 4]) {
        let end = Instant::now() + TIMEOUT;
        loop {
            let (_, _) = self.daemon.answer(thrust);
            if self.fx.pulses().is_some_and(|p| p == expected) {
                return;
            }
            assert!(
                Instant::now() < end,
                "pulses {:?}, expected {expected:?}\n{}",
                self.fx.pulses(),
                self.proc.log()
            );
        }
    }

    /// SIGTERM, clean exit, our ports dropped, nothing of the namespace left; returns the
    /// process (for its log) and the fixture (for what the hardware saw).
    pub fn finish(self) -> (Proc, F) {
        let Harness {
            mut proc,
            daemon,
            fx,
            ns,
        } = self;
        proc.terminate();
        drop(daemon);
        assert_namespace_clean(&ns);
        (proc, fx)
    }
}
