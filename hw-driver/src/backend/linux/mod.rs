//! The Linux backend: ESCs on sysfs PWM channels, IMU (and optionally pressure) from IIO.
//!
//! Local hardware: the loop calls [`Backend::read_sensors`] at the deadline this backend
//! gives (one sample per `1 / rate_hz`: the gyro and accelerometer), and every output change
//! is one `duty_cycle` write. The magnetometer, pressure and supply, whose reads take
//! milliseconds, are read on a thread of their own ([`slow_sensors`]). The sysfs root is
//! configurable so the tests run on fake trees.

pub mod iio;
pub mod mount_matrix;
pub mod pwm;
pub mod slow_sensors;
pub mod stall_guard;
pub mod sysfs;
pub mod water_pressure;

use std::time::Duration;

use self::iio::{find_device, Channel, Pressure, Vector3};
use self::mount_matrix::MountMatrix;
use self::pwm::PwmChannel;
use self::slow_sensors::{Latest, SlowChannels, SlowSensors};
use self::stall_guard::StallGuard;
use thruster_protocol::ImuReading;

use super::{Backend, BackendError, LinkState, OutputSpec, Supply, Waker};
use crate::clock::monotonic_ns;
use crate::config::LinuxConfig;
use crate::core::axes::AxisMap;
use crate::core::pwm::Pwm;
use thruster_driver_kit::LogLimiter;

/// Gauss -> microtesla.
const UT_PER_GAUSS: f64 = 100.0;

/// Consecutive failed IMU reads tolerated (skipped samples) before the backend fails.
/// I2C sensors return an occasional EIO; an IMU that is gone fails within this many
/// periods (0.1 s at 200 Hz), and the daemon's stale-IMU fault sees the gap meanwhile.
pub const MAX_READ_FAILURES: u32 = 20;

/// How long `start` waits for the slow sensors' first values: a few conversions.
const FIRST_SLOW_READ: Duration = Duration::from_millis(200);

/// A supply reading older than this is reported unknown, ns (reads have been failing).
const SUPPLY_STALE_NS: u64 = 1_000_000_000;

/// The IIO channels the loop reads for each sample, each with its body axes from the chip's:
/// the kernel's mounting matrix (chip to board), then `imu_axes` (board to body).
#[derive(Debug)]
struct Sensors {
    gyro: Vector3,
    accel: Vector3,
    gyro_to_body: MountMatrix,
    accel_to_body: MountMatrix,
    mag_to_body: MountMatrix,
}

/// See the module docs.
#[derive(Debug)]
pub struct LinuxBackend {
    cfg: LinuxConfig,
    outputs: Vec<OutputSpec>,
    channels: Vec<PwmChannel>,
    sensors: Option<Sensors>,
    period_ns: u64,
    next_due_ns: u64,
    read_failures: u32,
    read_log: LogLimiter,
    /// Samples sent without depth because the pressure was implausible, and their log.
    depth_refused: u64,
    depth_log: LogLimiter,
    /// The magnetometer, pressure and supply, read on their own thread (started in `start`).
    slow: Option<SlowSensors>,
    /// Their newest values as the loop last took them.
    slow_latest: Latest,
    stopped: bool,
    /// The longest the loop may stop calling in before a thread of its own takes the
    /// outputs neutral (`stall_guard`); None: no guard (the in-process tests).
    stall_limit: Option<Duration>,
    guard: Option<StallGuard>,
    /// The outputs last written, to write again after the guard took them neutral.
    last_outputs: Vec<Pwm>,
}

impl LinuxBackend {
    /// A backend for `outputs` (in thruster order). Touches nothing until `start`.
    pub fn new(cfg: LinuxConfig, outputs: Vec<OutputSpec>) -> Self {
        let period_ns = (1e9 / cfg.rate_hz).round().max(1.0) as u64;
        LinuxBackend {
            cfg,
            outputs,
            channels: Vec::new(),
            sensors: None,
            period_ns,
            next_due_ns: 0,
            read_failures: 0,
            read_log: LogLimiter::default(),
            depth_refused: 0,
            depth_log: LogLimiter::default(),
            slow: None,
            slow_latest: Latest::default(),
            stopped: false,
            stall_limit: None,
            guard: None,
            last_outputs: Vec::new(),
        }
    }

    /// With the stall guard (`stall_guard`): the outputs go neutral once the loop has not
    /// called into the backend for `limit` (the driver gives its `watchdog_ms`).
    pub fn with_stall_guard(mut self, limit: Duration) -> Self {
        self.stall_limit = Some(limit);
        self
    }

    /// The loop is alive.
    fn beat(&self) {
        if let Some(guard) = &self.guard {
            guard.beat();
        }
    }

    /// Whether the guard took the outputs neutral since the last look; if so the channels'
    /// cached duties are forgotten, so the next writes happen. Looked at where the loop
    /// writes (its outputs then replace the guard's) and at the end of its round (`service`:
    /// its watchdog has decided by then, and the outputs it had are written again).
    fn took_neutral(&mut self) -> bool {
        let taken = self
            .guard
            .as_ref()
            .is_some_and(StallGuard::take_neutralized);
        if taken {
            for ch in &mut self.channels {
                ch.forget();
            }
        }
        taken
    }

    fn chip_dir(&self) -> std::path::PathBuf {
        self.cfg
            .sysfs_root
            .join(format!("class/pwm/pwmchip{}", self.cfg.pwm_chip))
    }

    /// `thruster-hw neutral`: every configured channel that is exported gets the neutral
    /// duty (see [`pwm::neutral_left_channel`]); one line per channel, or the first error
    /// after trying them all.
    pub fn neutral_left_outputs(&self) -> Result<Vec<String>, BackendError> {
        let chip = self.chip_dir();
        let mut lines = Vec::new();
        let mut first_err = None;
        for o in &self.outputs {
            match pwm::neutral_left_channel(&chip, o.channel, o.neutral) {
                Ok(pwm::LeftChannel::Neutral) => {
                    lines.push(format!("pwm{}: neutral ({} us)", o.channel, o.neutral.us()))
                }
                Ok(pwm::LeftChannel::NotExported) => {
                    lines.push(format!("pwm{}: not exported, nothing to write", o.channel))
                }
                Err(e) => {
                    first_err.get_or_insert(e);
                }
            }
        }
        first_err.map_or(Ok(lines), Err)
    }

    /// The outputs the loop last wrote, again (after the guard took them neutral while the
    /// loop was only slow).
    fn write_last_outputs(&mut self) -> Result<(), BackendError> {
        tracing::warn!("the driver loop runs again: its outputs written again");
        for (ch, &p) in self.channels.iter_mut().zip(&self.last_outputs) {
            ch.set(p)?;
        }
        Ok(())
    }

    /// Opens every channel: a wrong device name fails here, before any output is touched.
    fn open_sensors(&self) -> Result<(Sensors, SlowChannels), BackendError> {
        let root = &self.cfg.sysfs_root;
        let gyro_dev = find_device(root, &self.cfg.gyro_device)?;
        let accel_dev = find_device(root, self.cfg.accel_device())?;
        let to_body = |device: &std::path::Path, kind: &str, axes: AxisMap| {
            MountMatrix::read(device, kind).map(|m| {
                let body = MountMatrix(axes.matrix()).after(&m);
                if m != MountMatrix::IDENTITY {
                    tracing::info!(
                        device = %device.display(),
                        kernel_mount_matrix = ?m.0,
                        "{kind}: the kernel's mounting matrix applied before imu_axes"
                    );
                }
                body
            })
        };
        let (mag, mag_to_body) = match &self.cfg.mag_device {
            Some(spec) => {
                let dev = find_device(root, spec)?;
                let to_body = to_body(&dev, "magn", self.cfg.mag_axes())?;
                (Some(Vector3::open(&dev, "magn")?), to_body)
            }
            None => (None, MountMatrix::IDENTITY),
        };
        let pressure = match &self.cfg.pressure_device {
            Some(spec) => Some(Pressure::open(&find_device(root, spec)?)?),
            None => None,
        };
        // A configured supply channel that is not there is a configuration error, like a
        // missing IMU: said at start, not hidden behind an unknown voltage forever.
        let supply = match &self.cfg.supply_device {
            Some(spec) => Some(Channel::open_voltage(
                &find_device(root, spec)?,
                self.cfg.supply_channel,
            )?),
            None => None,
        };
        let sensors = Sensors {
            gyro: Vector3::open(&gyro_dev, "anglvel")?,
            accel: Vector3::open(&accel_dev, "accel")?,
            gyro_to_body: to_body(&gyro_dev, "anglvel", self.cfg.imu_axes)?,
            accel_to_body: to_body(&accel_dev, "accel", self.cfg.imu_axes)?,
            mag_to_body,
        };
        Ok((
            sensors,
            SlowChannels {
                mag,
                pressure,
                supply,
            },
        ))
    }

    /// The depth to attach to a sample read at `t_ns`: the newest pressure if fresh and
    /// plausible ([`water_pressure`]), else none (a refusal is counted and said).
    fn depth_at(&mut self, t_ns: u64) -> Option<f64> {
        let formula = self.cfg.pressure_formula;
        let kpa = Latest::fresh(self.slow_latest.pressure_kpa, t_ns, slow_sensors::STALE_NS)
            .map(|reported| water_pressure::corrected_kpa(reported, formula))?;
        if let Some(why) = water_pressure::implausible(kpa, formula) {
            self.depth_refused += 1;
            if let Some(suppressed) = self.depth_log.allow() {
                tracing::warn!(suppressed, "no depth: {why}");
            }
            return None;
        }
        Some(water_pressure::depth_m(
            kpa,
            self.cfg.surface_pressure_kpa,
            self.cfg.fluid_density_kg_m3,
        ))
    }

    fn read(&self, sensors: &Sensors) -> Result<ImuReading, BackendError> {
        // Stamped before the first (gyro) read: the gyro is what the controller reacts to.
        let t_ns = monotonic_ns();
        let gyro = sensors.gyro_to_body.apply(sensors.gyro.read()?);
        let accel = sensors.accel_to_body.apply(sensors.accel.read()?);
        let slow = &self.slow_latest;
        let mag = Latest::fresh(slow.mag, t_ns, slow_sensors::STALE_NS)
            .map(|m| sensors.mag_to_body.apply(m).map(|g| g * UT_PER_GAUSS));
        // Depth is attached by `read_sensors` (`depth_at`), which counts refusals.
        let depth = None;
        Ok(ImuReading {
            seq: 0,
            t_ns,
            gyro,
            accel,
            mag,
            depth,
        })
    }
}

impl Backend for LinuxBackend {
    fn name(&self) -> &'static str {
        "linux"
    }

    fn start(&mut self, _waker: Waker, now_ns: u64) -> Result<(), BackendError> {
        // Sensors first: a wrong device name fails before any output is touched.
        let (sensors, slow) = self.open_sensors()?;
        self.sensors = Some(sensors);
        let chip = self.chip_dir();
        let mut slow = SlowSensors::start(slow).map_err(|e| BackendError::Content {
            path: self.cfg.sysfs_root.clone(),
            reason: format!("cannot start the slow sensors' thread: {e}"),
        })?;
        // The first samples carry the magnetometer and depth when the sensors answer within
        // a read's time; a slower one joins later (its value is attached once it comes).
        if !slow.wait_first(FIRST_SLOW_READ) {
            tracing::warn!(
                "a magnetometer, pressure or supply read took over {FIRST_SLOW_READ:?}: the \
                 first samples go out without it"
            );
        }
        self.slow_latest = slow.latest();
        self.slow = Some(slow);
        // A pressure no water has is a configuration error (the wrong formula for the part),
        // said at start, before any output is touched; later ones only cost the depth.
        if let Some((_, reported)) = self.slow_latest.pressure_kpa {
            let formula = self.cfg.pressure_formula;
            let kpa = water_pressure::corrected_kpa(reported, formula);
            if let Some(reason) = water_pressure::implausible(kpa, formula) {
                let spec = self.cfg.pressure_device.clone().unwrap_or_default();
                return Err(BackendError::Content {
                    path: find_device(&self.cfg.sysfs_root, &spec)?,
                    reason: format!("pressure_device {spec:?}: {reason}"),
                });
            }
        }
        let timeout = Duration::from_millis(self.cfg.export_timeout_ms);
        for o in &self.outputs {
            let ch =
                PwmChannel::open(&chip, o.channel, self.cfg.pwm_period_ns, o.neutral, timeout)?;
            self.channels.push(ch);
        }
        self.next_due_ns = now_ns;
        self.last_outputs = self.outputs.iter().map(|o| o.neutral).collect();
        if let Some(limit) = self.stall_limit {
            let duties = self
                .channels
                .iter()
                .zip(&self.outputs)
                .map(|(ch, o)| (ch.duty_path().to_path_buf(), o.neutral))
                .collect();
            self.guard =
                Some(
                    StallGuard::start(duties, limit).map_err(|e| BackendError::Content {
                        path: chip.clone(),
                        reason: format!("cannot start the stall guard thread: {e}"),
                    })?,
                );
        }
        tracing::info!(
            chip = %chip.display(),
            channels = ?self.outputs.iter().map(|o| o.channel).collect::<Vec<_>>(),
            period_ns = self.cfg.pwm_period_ns,
            rate_hz = self.cfg.rate_hz,
            "sysfs PWM enabled at neutral, IIO sensors open"
        );
        Ok(())
    }

    fn read_sensors(&mut self, now_ns: u64) -> Result<Option<ImuReading>, BackendError> {
        // Before the reads: a read that hangs leaves this heartbeat to age. Nothing is
        // written again here: after a long stall the loop's watchdog first decides on neutral.
        self.beat();
        if let Some(slow) = &mut self.slow {
            self.slow_latest = slow.latest();
        }
        let Some(sensors) = &self.sensors else {
            return Ok(None);
        };
        if now_ns < self.next_due_ns {
            return Ok(None);
        }
        let result = self.read(sensors).map(|r| ImuReading {
            depth: self.depth_at(r.t_ns),
            ..r
        });
        self.next_due_ns += self.period_ns;
        if self.next_due_ns <= now_ns {
            // Fell behind (the process was descheduled): restart the grid from now rather
            // than reading a burst of back-to-back samples.
            self.next_due_ns = now_ns + self.period_ns;
        }
        match result {
            Ok(reading) => {
                self.read_failures = 0;
                Ok(Some(reading))
            }
            Err(e) => {
                self.read_failures += 1;
                if self.read_failures > MAX_READ_FAILURES {
                    return Err(e);
                }
                if let Some(suppressed) = self.read_log.allow() {
                    tracing::warn!(
                        suppressed,
                        failures = self.read_failures,
                        "sensor read failed, sample skipped: {e}"
                    );
                }
                Ok(None)
            }
        }
    }

    fn write_outputs(&mut self, outputs: &[Pwm], _now_ns: u64) -> Result<(), BackendError> {
        self.beat();
        self.took_neutral();
        for (last, &p) in self.last_outputs.iter_mut().zip(outputs) {
            *last = p;
        }
        for (ch, &p) in self.channels.iter_mut().zip(outputs) {
            ch.set(p)?;
        }
        Ok(())
    }

    fn neutral(&mut self, _now_ns: u64) -> Result<(), BackendError> {
        self.beat();
        self.took_neutral();
        for (last, o) in self.last_outputs.iter_mut().zip(&self.outputs) {
            *last = o.neutral;
        }
        // Try every channel even if one fails, then report the first failure.
        let mut first_err = None;
        for (ch, o) in self.channels.iter_mut().zip(&self.outputs) {
            if let Err(e) = ch.set(o.neutral) {
                first_err.get_or_insert(e);
            }
        }
        first_err.map_or(Ok(()), Err)
    }

    fn service(&mut self, _now_ns: u64) -> Result<(), BackendError> {
        self.beat();
        if self.took_neutral() {
            self.write_last_outputs()?;
        }
        Ok(())
    }

    fn next_deadline_ns(&self) -> Option<u64> {
        self.sensors.as_ref().map(|_| self.next_due_ns)
    }

    fn link(&self) -> LinkState {
        LinkState::Local
    }

    fn stats(&self) -> Vec<(&'static str, u64)> {
        let failed = self.slow.as_ref().map_or(0, SlowSensors::failures);
        vec![
            ("slow_read_failures", failed),
            ("depth_refused", self.depth_refused),
        ]
    }

    fn supply(&self, now_ns: u64) -> Supply {
        // The ADC's volts times the divider's ratio; an implausible value is unknown.
        let v = Latest::fresh(self.slow_latest.supply_adc_v, now_ns, SUPPLY_STALE_NS)
            .map(|v| v * self.cfg.supply_gain)
            .filter(|v| v.is_finite() && *v >= 0.0);
        Supply {
            voltage_v: v,
            current_a: None,
        }
    }

    fn stop(&mut self) -> Result<(), BackendError> {
        self.stopped = true;
        // The guard's thread is joined before the last writes: none of its may follow them.
        self.guard = None;
        self.neutral(monotonic_ns())
    }
}

impl Drop for LinuxBackend {
    /// Safety net for panics and early returns: outputs neutral.
    fn drop(&mut self) {
        self.guard = None;
        if !self.stopped && !self.channels.is_empty() {
            let _ = self.neutral(0);
        }
    }
}
