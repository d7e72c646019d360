//! A fake sysfs tree in a temp dir: a PWM chip whose "kernel" (a thread watching the tree
//! with inotify) creates `pwmM/` when `M` is written to `export` and records every
//! attribute write with its CLOCK_MONOTONIC time, plus IIO devices whose raw values the
//! test sets. Files on a tmpfs accept any write, so the fake holds each write to the rules
//! the kernel's `drivers/pwm/core.c` applies (`export_store`, `__pwm_apply`, the attribute
//! stores) and records what the kernel would have refused; a test that ends with such a
//! write fails when the fake is dropped, unless it said it expects them. The IIO devices:
//! - iio:device0 "icm20602": anglvel and accel, shared scales;
//! - iio:device1 "ak09916": magn (gauss after scale);
//! - iio:device2 "ms5837": in_pressure_input (kPa).

use std::collections::HashMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use thruster_hw::clock::monotonic_ns;

use super::inotify::Inotify;

pub const GYRO_SCALE: f64 = 0.000133158; // rad/s per LSB
pub const ACCEL_SCALE: f64 = 0.000598550; // m/s^2 per LSB
pub const MAGN_SCALE: f64 = 0.0015; // gauss per LSB
pub const SURFACE_KPA: f64 = 101.325;
pub const DENSITY: f64 = 997.0;
const MAX_LIFETIME: Duration = Duration::from_secs(120);

/// One write seen by the fake kernel. `channel` is None for chip attributes (`export`).
#[derive(Debug, Clone, PartialEq)]
pub struct Write {
    pub t_ns: u64,
    pub channel: Option<u32>,
    pub attr: String,
    pub value: String,
}

pub struct FakeSysfs {
    dir: tempfile::TempDir,
    log: Arc<Mutex<Vec<Write>>>,
    /// Writes the kernel would have refused, each with the errno and why.
    refusals: Arc<Mutex<Vec<String>>>,
    /// A test that provokes refusals on purpose says so; otherwise any fails it at drop.
    refusals_expected: AtomicBool,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl FakeSysfs {
    /// The tree; with `kernel`, exports create channels (without, they never appear).
    pub fn new(kernel: bool) -> FakeSysfs {
        // In memory like sysfs: on ext4 a truncating rewrite costs ~0.4 ms (its
        // replace-via-truncate flush), which would be measured as driver latency.
        let dir = tempfile::Builder::new()
            .prefix("thruster-hw-sysfs")
            .tempdir_in("/dev/shm")
            .or_else(|_| tempfile::tempdir())
            .unwrap();
        let root = dir.path();
        let chip = root.join("class/pwm/pwmchip0");
        fs::create_dir_all(&chip).unwrap();
        fs::write(chip.join("export"), "").unwrap();
        fs::write(chip.join("npwm"), "16\n").unwrap();
        let imu = iio_dev(root, 0, "icm20602");
        for kind in ["anglvel", "accel"] {
            for axis in ["x", "y", "z"] {
                fs::write(imu.join(format!("in_{kind}_{axis}_raw")), "0\n").unwrap();
            }
        }
        fs::write(imu.join("in_anglvel_scale"), format!("{GYRO_SCALE}\n")).unwrap();
        fs::write(imu.join("in_accel_scale"), format!("{ACCEL_SCALE}\n")).unwrap();
        let mag = iio_dev(root, 1, "ak09916");
        for axis in ["x", "y", "z"] {
            fs::write(mag.join(format!("in_magn_{axis}_raw")), "0\n").unwrap();
        }
        fs::write(mag.join("in_magn_scale"), format!("{MAGN_SCALE}\n")).unwrap();
        let p = iio_dev(root, 2, "ms5837");
        fs::write(p.join("in_pressure_input"), format!("{SURFACE_KPA}\n")).unwrap();
        let log = Arc::new(Mutex::new(Vec::new()));
        let refusals = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let thread = kernel.then(|| {
            // Watching before returning: a driver started right after must not write
            // `export` before anyone listens.
            let ino = Inotify::new();
            let chip_wd = ino.watch_writes(&chip);
            let kernel = Kernel {
                chip: chip.clone(),
                log: log.clone(),
                refusals: refusals.clone(),
                channels: HashMap::new(),
            };
            let stop = stop.clone();
            std::thread::spawn(move || kernel.run(ino, chip_wd, &stop))
        });
        let fake = FakeSysfs {
            dir,
            log,
            refusals,
            refusals_expected: AtomicBool::new(false),
            stop,
            thread,
        };
        fake.set_imu([0.0; 3], [0.0, 0.0, -9.81], [0.0; 3], 0.0);
        fake
    }

    pub fn root(&self) -> &Path {
        self.dir.path()
    }

    pub fn chip(&self) -> PathBuf {
        self.root().join("class/pwm/pwmchip0")
    }

    /// Every write so far.
    pub fn writes(&self) -> Vec<Write> {
        self.log.lock().unwrap().clone()
    }

    /// The writes the kernel would have refused so far ("pwm0/period = 1000: EINVAL, ...").
    pub fn refusals(&self) -> Vec<String> {
        self.refusals.lock().unwrap().clone()
    }

    /// This test provokes writes the kernel refuses: they do not fail it at drop.
    pub fn expect_refusals(&self) {
        self.refusals_expected.store(true, Ordering::Relaxed);
    }

    /// Forgets the writes seen so far (a test's own set-up writes, e.g. [`Self::pre_export`],
    /// which the watcher may or may not have seen depending on when it added its watch).
    pub fn clear_writes(&self) {
        self.log.lock().unwrap().clear();
    }

    /// The pulse a channel outputs now, us (None before it is enabled).
    pub fn pulse_us(&self, channel: u32) -> Option<u16> {
        let d = self.chip().join(format!("pwm{channel}"));
        let enabled = fs::read_to_string(d.join("enable")).ok()?.trim() == "1";
        let duty: u64 = fs::read_to_string(d.join("duty_cycle"))
            .ok()?
            .trim()
            .parse()
            .ok()?;
        enabled.then_some((duty / 1000) as u16)
    }

    /// Makes the sensors read this body-frame state (FRD; the chip is mounted face up, so
    /// the sensor frame is x, -y, -z). Gyro rad/s, accel m/s^2, mag uT, depth m.
    pub fn set_imu(&self, gyro: [f64; 3], accel: [f64; 3], mag_ut: [f64; 3], depth_m: f64) {
        let flu = |v: [f64; 3]| [v[0], -v[1], -v[2]];
        let imu = self.root().join("bus/iio/devices/iio:device0");
        let mag = self.root().join("bus/iio/devices/iio:device1");
        for (i, axis) in ["x", "y", "z"].iter().enumerate() {
            let g = (flu(gyro)[i] / GYRO_SCALE).round() as i64;
            let a = (flu(accel)[i] / ACCEL_SCALE).round() as i64;
            let m = (flu(mag_ut)[i] / 100.0 / MAGN_SCALE).round() as i64;
            fs::write(imu.join(format!("in_anglvel_{axis}_raw")), format!("{g}\n")).unwrap();
            fs::write(imu.join(format!("in_accel_{axis}_raw")), format!("{a}\n")).unwrap();
            fs::write(mag.join(format!("in_magn_{axis}_raw")), format!("{m}\n")).unwrap();
        }
        let kpa = SURFACE_KPA + depth_m * DENSITY * 9.80665 / 1000.0;
        fs::write(
            self.root()
                .join("bus/iio/devices/iio:device2/in_pressure_input"),
            format!("{kpa:.6}\n"),
        )
        .unwrap();
    }

    /// A channel exported before the driver starts (e.g. by an earlier run).
    pub fn pre_export(&self, channel: u32, period: u64, duty: u64, enable: bool) {
        let d = self.chip().join(format!("pwm{channel}"));
        fs::create_dir_all(&d).unwrap();
        fs::write(d.join("period"), format!("{period}\n")).unwrap();
        fs::write(d.join("duty_cycle"), format!("{duty}\n")).unwrap();
        fs::write(d.join("enable"), if enable { "1\n" } else { "0\n" }).unwrap();
        fs::write(d.join("polarity"), "normal\n").unwrap();
    }
}

impl Drop for FakeSysfs {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        let refusals = self.refusals();
        if !refusals.is_empty()
            && !self.refusals_expected.load(Ordering::Relaxed)
            && !std::thread::panicking()
        {
            panic!("writes a kernel would have refused: {refusals:?}");
        }
    }
}

fn iio_dev(root: &Path, n: u32, name: &str) -> PathBuf {
    let d = root.join(format!("bus/iio/devices/iio:device{n}"));
    fs::create_dir_all(&d).unwrap();
    fs::write(d.join("name"), format!("{name}\n")).unwrap();
    d
}

/// One exported channel's state as the kernel keeps it (`struct pwm_state`).
#[derive(Debug, Clone, Copy)]
struct ChannelState {
    period: u64,
    duty: u64,
}

/// The fake kernel: the chip's channels, what it saw written, and what it would refuse.
struct Kernel {
    chip: PathBuf,
    log: Arc<Mutex<Vec<Write>>>,
    refusals: Arc<Mutex<Vec<String>>>,
    /// Watch descriptor -> channel index and its state.
    channels: HashMap<i32, (u32, ChannelState)>,
}

/// What `npwm` says: the kernel refuses an export at or above it (ENODEV).
const NPWM: u32 = 16;

impl Kernel {
    fn run(mut self, ino: Inotify, chip_wd: i32, stop: &AtomicBool) {
        let end = Instant::now() + MAX_LIFETIME;
        while !stop.load(Ordering::Relaxed) && Instant::now() < end {
            // Channels exported by the test itself (`pre_export`) are watched from the next
            // round on (tests wait a little before starting the driver), with the state
            // their files hold.
            for m in 0..NPWM {
                let d = self.chip.join(format!("pwm{m}"));
                if d.is_dir() && !self.channels.values().any(|&(c, _)| c == m) {
                    let read = |a: &str| {
                        fs::read_to_string(d.join(a))
                            .ok()
                            .and_then(|v| v.trim().parse().ok())
                            .unwrap_or(0)
                    };
                    let state = ChannelState {
                        period: read("period"),
                        duty: read("duty_cycle"),
                    };
                    self.channels.insert(ino.watch_writes(&d), (m, state));
                }
            }
            for ev in ino.read(Duration::from_millis(20)) {
                let t_ns = monotonic_ns();
                if ev.wd == chip_wd {
                    if ev.name == "export" {
                        self.export(&ino, t_ns);
                    }
                } else if self.channels.contains_key(&ev.wd) {
                    self.attribute(ev.wd, &ev.name, t_ns);
                }
            }
        }
    }

    fn refuse(&self, what: String) {
        self.refusals.lock().unwrap().push(what);
    }

    /// `export_store`: a number below npwm, not exported yet; the channel appears.
    fn export(&mut self, ino: &Inotify, t_ns: u64) {
        let value = fs::read_to_string(self.chip.join("export")).unwrap_or_default();
        let value = value.trim().to_string();
        self.log.lock().unwrap().push(Write {
            t_ns,
            channel: None,
            attr: "export".into(),
            value: value.clone(),
        });
        let Ok(m) = value.parse::<u32>() else {
            return self.refuse(format!("export = {value:?}: EINVAL, not a number"));
        };
        if m >= NPWM {
            return self.refuse(format!("export = {m}: ENODEV, npwm is {NPWM}"));
        }
        let dir = self.chip.join(format!("pwm{m}"));
        if dir.exists() {
            return self.refuse(format!("export = {m}: EBUSY, pwm{m} is exported already"));
        }
        // Built under another name, watched, then renamed: the driver sees the channel
        // only when all attributes exist and every write is observed. A fresh channel's
        // period is 0 here, as a driver without `get_state` leaves it; the PCA9685's reads
        // its prescaler, so writing the period first is right on both.
        let staging = self.chip.join(format!(".pwm{m}.new"));
        fs::create_dir_all(&staging).unwrap();
        for (attr, v) in [
            ("period", "0"),
            ("duty_cycle", "0"),
            ("enable", "0"),
            ("polarity", "normal"),
        ] {
            fs::write(staging.join(attr), format!("{v}\n")).unwrap();
        }
        let wd = ino.watch_writes(&staging);
        fs::rename(&staging, &dir).unwrap();
        let state = ChannelState { period: 0, duty: 0 };
        self.channels.insert(wd, (m, state));
    }

    /// The attribute stores: each applies the channel's whole state, and `__pwm_apply`
    /// refuses a period of 0 or a duty longer than the period (EINVAL); `enable` takes 0
    /// or 1, `polarity` "normal" or "inversed". A refused write leaves the state as it
    /// was (the file here keeps what was written: only the refusal is recorded). These are
    /// the rules of the kernels the audit read (6.8). Kernels since `pwm_state_valid`
    /// (2025) accept any period and duty while the channel is disabled, so for a disabled
    /// channel the fake is the stricter of the two, and a driver order it accepts is
    /// accepted by both.
    fn attribute(&mut self, wd: i32, attr: &str, t_ns: u64) {
        let (m, state) = self.channels[&wd];
        let path = self.chip.join(format!("pwm{m}")).join(attr);
        // Read after the event: the writer's next write may have truncated the file and not
        // yet written it (a sysfs store is atomic; a tmpfs rewrite is not). Empty is that
        // moment, never a value: read again briefly, and judge nothing if it stays empty.
        let mut value = String::new();
        for _ in 0..20 {
            value = fs::read_to_string(&path)
                .unwrap_or_default()
                .trim()
                .to_string();
            if !value.is_empty() {
                break;
            }
            std::thread::sleep(Duration::from_micros(250));
        }
        self.log.lock().unwrap().push(Write {
            t_ns,
            channel: Some(m),
            attr: attr.to_string(),
            value: value.clone(),
        });
        if value.is_empty() {
            return;
        }
        let mut next = state;
        match attr {
            "period" | "duty_cycle" => {
                let Ok(v) = value.parse::<u64>() else {
                    return self.refuse(format!("pwm{m}/{attr} = {value:?}: EINVAL"));
                };
                if attr == "period" {
                    next.period = v;
                } else {
                    next.duty = v;
                }
            }
            "enable" if !matches!(value.as_str(), "0" | "1") => {
                return self.refuse(format!("pwm{m}/enable = {value:?}: EINVAL"));
            }
            "polarity" if !matches!(value.as_str(), "normal" | "inversed") => {
                return self.refuse(format!("pwm{m}/polarity = {value:?}: EINVAL"));
            }
            _ => {}
        }
        if next.period == 0 || next.duty > next.period {
            return self.refuse(format!(
                "pwm{m}/{attr} = {value}: EINVAL, the state would be duty {} ns of period {} ns",
                next.duty, next.period
            ));
        }
        self.channels.insert(wd, (m, next));
    }
}
