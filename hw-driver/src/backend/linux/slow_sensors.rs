//! The sensors whose reads take milliseconds, read on a thread of their own: the IMU loop reads
//! only the gyro and accelerometer, and attaches the newest magnetometer and depth while they
//! are fresh ([`STALE_NS`]).
//!
//! Why: a kernel IIO read is a conversion, not a register. The MS5837's (`ms5637` driver,
//! `ms_sensors_convert_and_read`) sleeps twice for up to 16.4 ms each; an ak8975-family
//! magnetometer starts a measurement per axis and polls it every 10 ms, up to 500 ms
//! (`ak8975.c`); an ADS1015's single-shot conversion sleeps one sample period. Read in the
//! loop at 200 Hz, a pressure sensor and a magnetometer cut the IMU rate to about 15 Hz, and one
//! slow magnetometer read (500 ms) outlasted the command watchdog, so the stall guard took the
//! thrusters neutral (an audit against the kernel sources, docs/hardware.md). The fake sysfs of
//! the tests answers at once, which is why the tests never saw it.
//!
//! The loop never waits here: it takes the newest values with `try_lock` (the thread holds the
//! lock only to copy numbers in), keeping its last copy when the lock is busy. A read that hangs
//! stops only this thread: its values go stale and the samples go out without them. A failed
//! read is logged (rate-limited) and counted; the driver goes on without that sensor's values.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use thruster_driver_kit::LogLimiter;

use super::iio::{Channel, Pressure, Vector3};
use crate::clock::monotonic_ns;

/// How often the magnetometer and pressure are read, ns (20 Hz: the depth rate the MAVLink
/// backend asks ArduSub for; a read that takes longer just makes it slower).
pub const PERIOD_NS: u64 = 50_000_000;
/// How often the supply voltage is read, ns (a battery moves slowly; reported every 100 ms).
pub const SUPPLY_PERIOD_NS: u64 = 100_000_000;
/// A magnetometer or depth value older than this is not attached to a sample, ns.
pub const STALE_NS: u64 = 500_000_000;

/// The newest values, each with the time it was read (CLOCK_MONOTONIC, ns).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Latest {
    /// Gauss, sensor axes.
    pub mag: Option<(u64, [f64; 3])>,
    pub pressure_kpa: Option<(u64, f64)>,
    /// Volts at the ADC's input, before the divider's gain is undone (mV / 1000).
    pub supply_adc_v: Option<(u64, f64)>,
}

impl Latest {
    /// The value if it was read within `max_age_ns` of `now_ns`.
    pub fn fresh<T: Copy>(v: Option<(u64, T)>, now_ns: u64, max_age_ns: u64) -> Option<T> {
        v.filter(|(t, _)| now_ns.saturating_sub(*t) <= max_age_ns)
            .map(|(_, v)| v)
    }
}

/// What the thread reads.
#[derive(Debug)]
pub struct SlowChannels {
    pub mag: Option<Vector3>,
    pub pressure: Option<Pressure>,
    pub supply: Option<Channel>,
}

impl SlowChannels {
    fn is_empty(&self) -> bool {
        self.mag.is_none() && self.pressure.is_none() && self.supply.is_none()
    }
}

/// See the module docs.
#[derive(Debug)]
pub struct SlowSensors {
    shared: Arc<Mutex<Latest>>,
    /// The loop's last copy (kept when the lock is busy).
    copy: Latest,
    stop: Arc<AtomicBool>,
    failures: Arc<AtomicU64>,
    /// Which of mag, pressure, supply the thread reads.
    reads: [bool; 3],
    /// Not joined on drop: a read that hangs would hold the process's exit. The thread sees
    /// `stop` after its current read and ends.
    _thread: Option<JoinHandle<()>>,
}

impl SlowSensors {
    /// Starts the thread for `channels`; no thread when there is nothing to read.
    pub fn start(channels: SlowChannels) -> std::io::Result<SlowSensors> {
        let shared = Arc::new(Mutex::new(Latest::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let failures = Arc::new(AtomicU64::new(0));
        let reads = [
            channels.mag.is_some(),
            channels.pressure.is_some(),
            channels.supply.is_some(),
        ];
        let thread = if channels.is_empty() {
            None
        } else {
            let (shared, stop, failures) = (shared.clone(), stop.clone(), failures.clone());
            Some(
                std::thread::Builder::new()
                    .name("thruster-hw-slow-sensors".into())
                    .spawn(move || run(&channels, &shared, &stop, &failures))?,
            )
        };
        Ok(SlowSensors {
            shared,
            copy: Latest::default(),
            stop,
            failures,
            reads,
            _thread: thread,
        })
    }

    /// Waits up to `within` for a first value of every sensor read (at start, so the first
    /// samples carry them); true when all came.
    pub fn wait_first(&mut self, within: Duration) -> bool {
        let end = std::time::Instant::now() + within;
        loop {
            let l = self.latest();
            let have = [
                l.mag.is_some(),
                l.pressure_kpa.is_some(),
                l.supply_adc_v.is_some(),
            ];
            if self.reads.iter().zip(have).all(|(want, got)| !want || got) {
                return true;
            }
            if std::time::Instant::now() >= end {
                return false;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// The newest values; never waits.
    pub fn latest(&mut self) -> Latest {
        if let Ok(guard) = self.shared.try_lock() {
            self.copy = *guard;
        }
        self.copy
    }

    /// Failed reads so far.
    pub fn failures(&self) -> u64 {
        self.failures.load(Ordering::Relaxed)
    }
}

impl Drop for SlowSensors {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn run(ch: &SlowChannels, shared: &Mutex<Latest>, stop: &AtomicBool, failures: &AtomicU64) {
    let mut log = LogLimiter::default();
    let mut next_supply_ns = 0;
    let mut fail = |what: &str, e: &dyn std::fmt::Display| {
        failures.fetch_add(1, Ordering::Relaxed);
        if let Some(suppressed) = log.allow() {
            tracing::warn!(suppressed, "{what} read failed, its value goes stale: {e}");
        }
    };
    let put = |f: &dyn Fn(&mut Latest)| {
        // The loop only copies under the lock: a poisoned lock still holds plain numbers.
        let mut g = shared.lock().unwrap_or_else(|e| e.into_inner());
        f(&mut g);
    };
    while !stop.load(Ordering::Relaxed) {
        let started = monotonic_ns();
        if let Some(m) = &ch.mag {
            match m.read() {
                Ok(v) => put(&|l| l.mag = Some((monotonic_ns(), v))),
                Err(e) => fail("magnetometer", &e),
            }
        }
        if let Some(p) = &ch.pressure {
            match p.read_kpa() {
                Ok(v) => put(&|l| l.pressure_kpa = Some((monotonic_ns(), v))),
                Err(e) => fail("pressure", &e),
            }
        }
        if let Some(s) = &ch.supply {
            if started >= next_supply_ns {
                next_supply_ns = started + SUPPLY_PERIOD_NS;
                match s.read() {
                    Ok(mv) => put(&|l| l.supply_adc_v = Some((monotonic_ns(), mv / 1000.0))),
                    Err(e) => fail("supply voltage", &e),
                }
            }
        }
        let next = started
            + if ch.mag.is_some() || ch.pressure.is_some() {
                PERIOD_NS
            } else {
                SUPPLY_PERIOD_NS
            };
        let wait = next.saturating_sub(monotonic_ns());
        if wait > 0 {
            std::thread::sleep(Duration::from_nanos(wait));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_value_is_fresh_within_its_age_only() {
        assert_eq!(Latest::fresh(Some((100, 1.5)), 600, 500), Some(1.5));
        assert_eq!(Latest::fresh(Some((100, 1.5)), 601, 500), None);
        assert_eq!(Latest::fresh::<f64>(None, 0, 500), None);
        // A value stamped after `now` (read between the loop's clock and this call) is fresh.
        assert_eq!(Latest::fresh(Some((700, 2.0)), 600, 500), Some(2.0));
    }
}
