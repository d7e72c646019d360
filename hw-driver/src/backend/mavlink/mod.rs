//! The MAVLink backend: ArduSub (ArduPilot) as the IO board.
//!
//! IMU and depth come from the autopilot's SCALED_IMU2 (or SCALED_IMU / RAW_IMU), ATTITUDE
//! and SCALED_PRESSURE2 streams; thrust goes out as MAV_CMD_DO_MOTOR_TEST per thruster or
//! RC_CHANNELS_OVERRIDE. The protocol logic is the pure [`session::Session`]; this module
//! owns the connection and the receive thread ([`io`]). No autopilot parameter is changed.

pub mod convert;
pub mod io;
pub mod session;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{Connectable, ConnectionAddress, MavConnection};

use self::io::{Incoming, SharedConnection};
use self::session::{Session, SessionCounters};
use super::{Backend, BackendError, LinkState, OutputSpec, SensorReading, Waker};
use crate::clock::monotonic_ns;
use crate::config::MavlinkConfig;
use crate::core::pwm::Pwm;
use crate::log_limit::LogLimiter;

/// How often the final neutral is sent on stop, and the gap between sends: UDP may drop
/// one datagram, not three in a row.
const STOP_REPEATS: u32 = 3;
const STOP_GAP: Duration = Duration::from_millis(20);

/// Longest wait for the receive thread to end on stop. A serial receive only returns with
/// a message, so the thread may outlive this; it is then left to end with the process.
const JOIN_WAIT: Duration = Duration::from_millis(300);

/// See the module docs.
pub struct MavlinkBackend {
    cfg: MavlinkConfig,
    outputs: Vec<OutputSpec>,
    conn: Option<SharedConnection>,
    rx: Option<Receiver<Incoming>>,
    rx_stop: Arc<AtomicBool>,
    rx_thread: Option<JoinHandle<()>>,
    session: Option<Session>,
    send_errors: u64,
    send_log: LogLimiter,
    stopped: bool,
}

impl std::fmt::Debug for MavlinkBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MavlinkBackend")
            .field("address", &self.cfg.address)
            .field("session", &self.session)
            .finish_non_exhaustive()
    }
}

impl MavlinkBackend {
    /// A backend for `outputs` (thruster order). Connects on `start`.
    pub fn new(cfg: MavlinkConfig, outputs: Vec<OutputSpec>) -> Self {
        MavlinkBackend {
            cfg,
            outputs,
            conn: None,
            rx: None,
            rx_stop: Arc::new(AtomicBool::new(false)),
            rx_thread: None,
            session: None,
            send_errors: 0,
            send_log: LogLimiter::default(),
            stopped: false,
        }
    }

    /// The session's counters (zero before `start`).
    pub fn counters(&self) -> SessionCounters {
        self.session
            .as_ref()
            .map(Session::counters)
            .unwrap_or_default()
    }

    fn connect(&self) -> Result<SharedConnection, BackendError> {
        let err = |reason: String| BackendError::Mavlink {
            what: "connect",
            reason,
        };
        let addr = ConnectionAddress::parse_address(&self.cfg.address)
            .map_err(|e| err(format!("{:?}: {e}", self.cfg.address)))?;
        let addr = match addr {
            // A receive timeout lets the thread see the stop flag (TCP has its own 100 ms;
            // a serial receive retries internally).
            ConnectionAddress::Udp(udp) => ConnectionAddress::Udp(
                udp.read_timeout(Duration::from_millis(self.cfg.read_timeout_ms)),
            ),
            other => other,
        };
        let mut conn = addr
            .connect::<MavMessage>()
            .map_err(|e| err(format!("{}: {e}", self.cfg.address)))?;
        // ArduPilot answers in the version it is spoken to; accept both anyway.
        conn.set_allow_recv_any_version(true);
        Ok(Arc::new(conn))
    }

    /// Sends what the session queued. Send failures are counted and logged, not fatal: a
    /// lossy tether shows up as a lost link (HEARTBEAT timeout), which is supervised.
    fn flush(&mut self) {
        let (Some(session), Some(conn)) = (self.session.as_mut(), self.conn.as_ref()) else {
            return;
        };
        let header = session.header();
        for msg in session.drain_outgoing() {
            if let Err(e) = conn.send(&header, &msg) {
                self.send_errors += 1;
                if let Some(suppressed) = self.send_log.allow() {
                    tracing::warn!(error = %e, suppressed, total = self.send_errors, "MAVLink send failed");
                }
            }
        }
    }

    fn drain_incoming(&mut self) -> Result<(), BackendError> {
        let (Some(rx), Some(session)) = (self.rx.as_ref(), self.session.as_mut()) else {
            return Ok(());
        };
        loop {
            match rx.try_recv() {
                Ok(Incoming::Message { t_ns, header, msg }) => {
                    session.on_message(t_ns, &header, &msg)
                }
                Ok(Incoming::Closed(reason)) => {
                    return Err(BackendError::Mavlink {
                        what: "connection",
                        reason: format!("closed: {reason}"),
                    })
                }
                Err(TryRecvError::Empty) => return Ok(()),
                Err(TryRecvError::Disconnected) => {
                    return Err(BackendError::Mavlink {
                        what: "connection",
                        reason: "the receive thread ended".to_string(),
                    })
                }
            }
        }
    }

    fn join_receiver(&mut self) {
        self.rx_stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.rx_thread.take() {
            let end = Instant::now() + JOIN_WAIT;
            while !h.is_finished() && Instant::now() < end {
                std::thread::sleep(Duration::from_millis(5));
            }
            if h.is_finished() {
                let _ = h.join();
            }
        }
    }
}

impl Backend for MavlinkBackend {
    fn name(&self) -> &'static str {
        "mavlink"
    }

    fn start(&mut self, waker: Waker, now_ns: u64) -> Result<(), BackendError> {
        let conn = self.connect()?;
        let (tx, rx) = mpsc::channel();
        self.rx_thread = Some(io::spawn(conn.clone(), tx, waker, self.rx_stop.clone())?);
        self.rx = Some(rx);
        self.conn = Some(conn);
        self.session = Some(Session::new(self.cfg.clone(), self.outputs.clone(), now_ns));
        tracing::info!(
            address = %self.cfg.address,
            output = ?self.cfg.output,
            imu = ?self.cfg.imu_message,
            "MAVLink connection open; waiting for the autopilot's HEARTBEAT"
        );
        self.service(now_ns)
    }

    fn read_sensors(&mut self, _now_ns: u64) -> Result<Option<SensorReading>, BackendError> {
        self.drain_incoming()?;
        // ACKs processed above may have queued the next request.
        self.flush();
        Ok(self.session.as_mut().and_then(Session::take_reading))
    }

    fn write_outputs(&mut self, outputs: &[Pwm], now_ns: u64) -> Result<(), BackendError> {
        if let Some(s) = self.session.as_mut() {
            s.set_outputs(outputs);
            // At once, not at the next resend: this is the command path's latency.
            s.service(now_ns);
        }
        self.flush();
        Ok(())
    }

    fn neutral(&mut self, now_ns: u64) -> Result<(), BackendError> {
        let neutral: Vec<Pwm> = self.outputs.iter().map(|o| o.neutral).collect();
        self.write_outputs(&neutral, now_ns)
    }

    fn service(&mut self, now_ns: u64) -> Result<(), BackendError> {
        if let Some(s) = self.session.as_mut() {
            s.service(now_ns);
        }
        self.flush();
        Ok(())
    }

    fn next_deadline_ns(&self) -> Option<u64> {
        self.session.as_ref().map(Session::next_deadline_ns)
    }

    fn link(&self) -> LinkState {
        self.session
            .as_ref()
            .map_or(LinkState::Connecting, Session::link)
    }

    fn stop(&mut self) -> Result<(), BackendError> {
        if self.stopped {
            return Ok(());
        }
        self.stopped = true;
        for i in 0..STOP_REPEATS {
            if i > 0 {
                std::thread::sleep(STOP_GAP);
            }
            if let Some(s) = self.session.as_mut() {
                s.shutdown(monotonic_ns());
            }
            self.flush();
        }
        self.join_receiver();
        Ok(())
    }
}

impl Drop for MavlinkBackend {
    /// Safety net for panics and early returns: neutral, then stop receiving.
    fn drop(&mut self) {
        let _ = self.stop();
    }
}
