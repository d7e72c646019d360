//! The MAVLink backend: ArduSub (ArduPilot) as the IO board.
//!
//! IMU and depth come from the autopilot's SCALED_IMU2 (or SCALED_IMU / RAW_IMU), ATTITUDE
//! and SCALED_PRESSURE2 streams; thrust goes out as MAV_CMD_DO_MOTOR_TEST per thruster or
//! RC_CHANNELS_OVERRIDE. The protocol logic is the pure [`conversation::Conversation`]; this module
//! owns the connection and the receive thread ([`io`]). No autopilot parameter is changed.
//!
//! A connection that fails after start (TCP closed, serial unplugged) ends the conversation, not
//! the driver: the link is reported down and the connection is opened again every
//! [`RECONNECT_PERIOD`]. Only a connection that cannot be opened at start is an error (a
//! wrong address in the configuration).

pub mod battery;
pub mod conversation;
pub mod convert;
pub mod io;
pub mod motor_test;
pub mod override_hold;
pub mod params;
pub mod rate_watch;
pub mod rc_override;
pub mod water_baro;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use self::conversation::{Conversation, ConversationCounters};
use self::io::{Incoming, SharedLink};
use thruster_protocol::ImuReading;

use super::{Backend, BackendError, LinkState, OutputSpec, Supply, Waker};
use crate::clock::monotonic_ns;
use crate::config::MavlinkConfig;
use crate::core::pwm::Pwm;
use thruster_driver_kit::LogLimiter;

/// How often the final neutral is sent on stop, and the gap between sends: UDP may drop
/// one datagram, not three in a row.
const STOP_REPEATS: u32 = 3;
const STOP_GAP: Duration = Duration::from_millis(20);

/// Longest wait for the receive thread to end on stop. A serial receive only returns with
/// a message, so the thread may outlive this; it is then left to end with the process.
const JOIN_WAIT: Duration = Duration::from_millis(300);

/// How often a lost connection is opened again.
pub const RECONNECT_PERIOD: Duration = Duration::from_secs(1);

/// See the module docs.
pub struct MavlinkBackend {
    cfg: MavlinkConfig,
    outputs: Vec<OutputSpec>,
    conn: Option<SharedLink>,
    /// While the connection is lost: when to try again (ns).
    reconnect_at_ns: Option<u64>,
    reconnects: u64,
    waker: Option<Waker>,
    /// Link state last seen, to forget udpin's peer when the link goes down.
    was_up: bool,
    rx: Option<Receiver<Incoming>>,
    rx_stop: Arc<AtomicBool>,
    rx_thread: Option<JoinHandle<()>>,
    conversation: Option<Conversation>,
    send_errors: u64,
    send_log: LogLimiter,
    stopped: bool,
}

impl std::fmt::Debug for MavlinkBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MavlinkBackend")
            .field("address", &self.cfg.address)
            .field("conversation", &self.conversation)
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
            reconnect_at_ns: None,
            reconnects: 0,
            waker: None,
            was_up: false,
            rx: None,
            rx_stop: Arc::new(AtomicBool::new(false)),
            rx_thread: None,
            conversation: None,
            send_errors: 0,
            send_log: LogLimiter::default(),
            stopped: false,
        }
    }

    /// The conversation's counters (zero before `start`).
    pub fn counters(&self) -> ConversationCounters {
        self.conversation
            .as_ref()
            .map(Conversation::counters)
            .unwrap_or_default()
    }

    fn connect(&self) -> Result<SharedLink, BackendError> {
        // A receive timeout lets the thread see the stop flag (TCP has its own 100 ms; a
        // serial receive retries internally).
        io::open(
            &self.cfg.address,
            Duration::from_millis(self.cfg.read_timeout_ms),
            (self.cfg.target_system, self.cfg.target_component),
        )
        .map_err(|reason| BackendError::Mavlink {
            what: "connect",
            reason,
        })
    }

    /// Opens the connection and starts its receive thread.
    fn open(&mut self) -> Result<(), BackendError> {
        let conn = self.connect()?;
        let (tx, rx) = mpsc::channel();
        self.rx_stop = Arc::new(AtomicBool::new(false));
        let waker = self.waker.clone().unwrap_or_else(Waker::noop);
        self.rx_thread = Some(io::spawn(conn.clone(), tx, waker, self.rx_stop.clone())?);
        self.rx = Some(rx);
        self.conn = Some(conn);
        Ok(())
    }

    /// The connection failed: the conversation's link is down at once, the receive thread is
    /// gone, and the connection is opened again from [`Backend::service`].
    fn lost(&mut self, reason: &str, now_ns: u64) {
        tracing::warn!(
            address = %self.cfg.address,
            "MAVLink connection lost: {reason}; reconnecting every {} ms",
            RECONNECT_PERIOD.as_millis()
        );
        if let Some(s) = self.conversation.as_mut() {
            // Nothing can reach the autopilot any more: the neutral round ArduSub would get
            // is its own, 500 ms after our last motor test (documented).
            s.on_disconnect(reason);
            s.drain_outgoing();
        }
        self.join_receiver();
        self.rx = None;
        self.conn = None;
        self.reconnect_at_ns = Some(now_ns + RECONNECT_PERIOD.as_nanos() as u64);
    }

    fn try_reconnect(&mut self, now_ns: u64) {
        let Some(at) = self.reconnect_at_ns else {
            return;
        };
        if now_ns < at {
            return;
        }
        match self.open() {
            Ok(()) => {
                self.reconnects += 1;
                self.reconnect_at_ns = None;
                tracing::info!(address = %self.cfg.address, "MAVLink connection open again");
            }
            Err(e) => {
                if let Some(suppressed) = self.send_log.allow() {
                    tracing::warn!(suppressed, "reconnect failed: {e}");
                }
                self.reconnect_at_ns = Some(now_ns + RECONNECT_PERIOD.as_nanos() as u64);
            }
        }
    }

    /// udpin replies only to the autopilot's address; once the link is lost that lock is
    /// released, so an autopilot (or router) that comes back from another port is found.
    fn watch_link(&mut self) {
        let up = self
            .conversation
            .as_ref()
            .is_some_and(|s| s.link() == LinkState::Up);
        if self.was_up && !up {
            if let Some(c) = self.conn.as_ref() {
                c.forget_peer();
            }
        }
        self.was_up = up;
    }

    /// Sends what the conversation queued. Send failures are counted and logged, not fatal: a
    /// lossy tether shows up as a lost link (HEARTBEAT timeout), which is supervised.
    fn flush(&mut self) {
        let (Some(conversation), Some(conn)) = (self.conversation.as_mut(), self.conn.as_ref())
        else {
            return;
        };
        let header = conversation.header();
        for msg in conversation.drain_outgoing() {
            if let Err(e) = conn.send(&header, &msg) {
                self.send_errors += 1;
                if let Some(suppressed) = self.send_log.allow() {
                    tracing::warn!(error = %e, suppressed, total = self.send_errors, "MAVLink send failed");
                }
            }
        }
    }

    fn drain_incoming(&mut self) -> Result<(), BackendError> {
        let (Some(rx), Some(conversation)) = (self.rx.as_ref(), self.conversation.as_mut()) else {
            return Ok(());
        };
        let lost = loop {
            match rx.try_recv() {
                Ok(Incoming::Message { t_ns, header, msg }) => {
                    conversation.on_message(t_ns, &header, &msg)
                }
                Ok(Incoming::Closed(reason)) => break format!("closed: {reason}"),
                Err(TryRecvError::Empty) => return Ok(()),
                Err(TryRecvError::Disconnected) => break "the receive thread ended".to_string(),
            }
        };
        self.lost(&lost, monotonic_ns());
        Ok(())
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
        self.waker = Some(waker);
        self.open()?;
        self.conversation = Some(Conversation::new(
            self.cfg.clone(),
            self.outputs.clone(),
            now_ns,
        ));
        tracing::info!(
            address = %self.cfg.address,
            output = ?self.cfg.output,
            imu = ?self.cfg.imu_message,
            "MAVLink connection open; waiting for the autopilot's HEARTBEAT"
        );
        self.service(now_ns)
    }

    fn read_sensors(&mut self, _now_ns: u64) -> Result<Option<ImuReading>, BackendError> {
        self.drain_incoming()?;
        // ACKs processed above may have queued the next request.
        self.flush();
        Ok(self
            .conversation
            .as_mut()
            .and_then(Conversation::take_reading))
    }

    fn write_outputs(&mut self, outputs: &[Pwm], now_ns: u64) -> Result<(), BackendError> {
        if let Some(s) = self.conversation.as_mut() {
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
        self.try_reconnect(now_ns);
        if let Some(s) = self.conversation.as_mut() {
            s.service(now_ns);
        }
        // Before the peer is forgotten: the link-down neutral round goes to the autopilot.
        self.flush();
        self.watch_link();
        Ok(())
    }

    fn next_deadline_ns(&self) -> Option<u64> {
        let conversation = self
            .conversation
            .as_ref()
            .map(Conversation::next_deadline_ns);
        [conversation, self.reconnect_at_ns]
            .into_iter()
            .flatten()
            .min()
    }

    fn supply(&self, now_ns: u64) -> Supply {
        self.conversation
            .as_ref()
            .map_or_else(Supply::default, |s| s.supply(now_ns))
    }

    fn armed(&self) -> bool {
        self.conversation
            .as_ref()
            .is_some_and(Conversation::autopilot_armed)
    }

    fn held(&self) -> Option<String> {
        self.conversation.as_ref().and_then(Conversation::held)
    }

    fn stats(&self) -> Vec<(&'static str, u64)> {
        let c = self.counters();
        let (empty, malformed, foreign) = self
            .conn
            .as_ref()
            .map_or((0, 0, 0), |l| l.counters().snapshot());
        vec![
            ("imu_implausible", c.imu_implausible),
            ("mag_implausible", c.mag_implausible),
            ("datagrams_empty", empty),
            ("datagrams_malformed", malformed),
            ("datagrams_foreign", foreign),
            ("motor_test_refused", c.motor_test_refused),
            ("link_losses", c.link_losses),
            ("reconnects", self.reconnects),
        ]
    }

    fn link(&self) -> LinkState {
        self.conversation
            .as_ref()
            .map_or(LinkState::Connecting, Conversation::link)
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
            if let Some(s) = self.conversation.as_mut() {
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
