//! Hardware backends behind one trait, so the driver loop, the pure core and the
//! conformance suite (`tests/conformance.rs`) are the same for every kind of hardware (the
//! PX4 / iceoryx2 pattern: several backends, one test suite).
//!
//! - [`mavlink`]: ArduSub (ArduPilot) over MAVLink; UDP, TCP or serial.
//! - [`linux`]: Linux sysfs PWM for the ESCs and IIO for the IMU (and pressure).
//!
//! A further backend, e.g. a Navigator board's PCA9685 on I2C driven from user space,
//! implements [`Backend`]: outputs are pulse widths per configured channel, sensors come as
//! the protocol's [`ImuReading`]s (SI units, body frame, `seq` left 0: the driver numbers
//! what it publishes, and `t_ns` on CLOCK_MONOTONIC); a backend that receives on its own
//! thread calls the [`Waker`] so the loop does not poll.

pub mod linux;
pub mod mavlink;

use std::fmt;
use std::path::PathBuf;
use std::sync::Arc;

use thruster_protocol::ImuReading;

use crate::core::pwm::Pwm;

/// The supply (battery) as the hardware measures it; `None` where it does not.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Supply {
    /// Voltage at the ESCs, V.
    pub voltage_v: Option<f64>,
    /// Current drawn, A (positive: discharging).
    pub current_a: Option<f64>,
}

/// One output as the backend sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputSpec {
    /// The backend's channel number (see `ThrusterConfig::channel`).
    pub channel: u32,
    /// The pulse written by [`Backend::neutral`].
    pub neutral: Pwm,
}

/// State of the link to the hardware, for the status line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkState {
    /// Local hardware: no link to lose.
    Local,
    /// Waiting for the first sign of life.
    Connecting,
    /// Up.
    Up,
    /// Lost (reason).
    Down(String),
}

impl fmt::Display for LinkState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LinkState::Local => f.write_str("local"),
            LinkState::Connecting => f.write_str("connecting"),
            LinkState::Up => f.write_str("up"),
            LinkState::Down(why) => write!(f, "down ({why})"),
        }
    }
}

/// Failures of a backend. Any of them ends the driver (after writing neutral).
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    /// A file (sysfs attribute, device) could not be read or written.
    // The OS error is in the message and not a `source`: a chain printed whole
    // ("{:#}") said it twice.
    #[error("{}: cannot {op}: {error}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// "read", "write", "open", ...
        op: &'static str,
        /// Why.
        error: std::io::Error,
    },
    /// A file held something unexpected.
    #[error("{}: {reason}", path.display())]
    Content {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// Connecting or talking to the autopilot failed.
    #[error("MAVLink {what}: {reason}")]
    Mavlink {
        /// What was attempted.
        what: &'static str,
        /// Why it failed.
        reason: String,
    },
    /// Something did not happen in time.
    #[error("timed out: {0}")]
    Timeout(String),
    /// A background thread could not be started.
    #[error("cannot start the {what} thread: {source}")]
    Thread {
        /// Which thread.
        what: &'static str,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}

/// Wakes the driver loop from another thread (a backend's receive thread) when a reading is
/// ready, so readings are published without polling delay.
#[derive(Clone)]
pub struct Waker(Arc<dyn Fn() + Send + Sync>);

impl Waker {
    /// A waker calling `f`.
    pub fn new(f: impl Fn() + Send + Sync + 'static) -> Self {
        Waker(Arc::new(f))
    }

    /// A waker that does nothing (for backends polled on their deadline, and tests).
    pub fn noop() -> Self {
        Waker::new(|| {})
    }

    /// Wakes the loop.
    pub fn wake(&self) {
        (self.0)()
    }
}

impl fmt::Debug for Waker {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Waker")
    }
}

/// A kind of hardware. All methods are called from the driver loop's thread and must not
/// block for long (a backend that must wait for IO does it on its own thread). Times are
/// ns of CLOCK_MONOTONIC.
///
/// Contract (checked by the conformance suite for every backend):
/// - [`Backend::start`] brings the hardware up; outputs are neutral from then on until
///   [`Backend::write_outputs`] says otherwise.
/// - [`Backend::write_outputs`] gets one pulse per configured output, in configuration
///   order, already clamped to each output's range; the backend keeps them alive (resends
///   them if its link needs it) until the next call.
/// - [`Backend::stop`] (also called after errors) leaves every output at neutral.
pub trait Backend {
    /// Short name for logs ("mavlink", "linux").
    fn name(&self) -> &'static str;

    /// Brings the hardware up (export PWM channels, start receiving) and writes neutral.
    fn start(&mut self, waker: Waker, now_ns: u64) -> Result<(), BackendError>;

    /// The next reading not returned yet, if any; never blocks. Called until `None`.
    fn read_sensors(&mut self, now_ns: u64) -> Result<Option<ImuReading>, BackendError>;

    /// Outputs these pulses from now on.
    fn write_outputs(&mut self, outputs: &[Pwm], now_ns: u64) -> Result<(), BackendError>;

    /// Outputs every channel's neutral pulse now.
    fn neutral(&mut self, now_ns: u64) -> Result<(), BackendError>;

    /// Periodic work (heartbeats, resends, link supervision, command retries). Called at
    /// least at [`Backend::next_deadline_ns`] and after every wake-up.
    fn service(&mut self, now_ns: u64) -> Result<(), BackendError>;

    /// When [`Backend::service`] or [`Backend::read_sensors`] next has work to do without
    /// being woken (a poll period, a resend), if ever.
    fn next_deadline_ns(&self) -> Option<u64>;

    /// The link's state.
    fn link(&self) -> LinkState;

    /// The output device moves the thrusters: false while an autopilot reports itself
    /// disarmed (commands are then accepted but reach nothing), or before it said either.
    /// Hardware without arming is always armed.
    fn armed(&self) -> bool {
        true
    }

    /// Why the output device takes none of our thrust although it is up and armed (an
    /// autopilot setting that would make a crash of ours unsafe): only neutral goes out.
    fn held(&self) -> Option<String> {
        None
    }

    /// The supply's voltage and current as last measured, if the hardware measures them and
    /// the measurement is fresh at `now_ns` (the driver reports it on `driver_status`).
    fn supply(&self, _now_ns: u64) -> Supply {
        Supply::default()
    }

    /// Backend counters for the status line and the final summary (`name=value`).
    fn stats(&self) -> Vec<(&'static str, u64)> {
        Vec::new()
    }

    /// Writes neutral (repeatedly if the link is lossy), undoes what `start` did to the
    /// vehicle (disarm if it armed) and stops background threads. Outputs stay neutral.
    fn stop(&mut self) -> Result<(), BackendError>;
}
