//! The receive thread: blocks on the connection, stamps each message with CLOCK_MONOTONIC
//! the moment it is decoded, forwards the ones the session uses and wakes the driver loop.
//!
//! Sending happens on the loop's thread through the same connection: the `mavlink` crate
//! locks reader and writer separately, so a blocked receive never delays a thrust command.

use std::io::ErrorKind;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::error::MessageReadError;
use mavlink::{MavConnection, MavHeader};

use crate::backend::{BackendError, Waker};
use crate::clock::monotonic_ns;

/// What the receive thread hands to the loop.
#[derive(Debug)]
pub enum Incoming {
    /// A message and its receive time (ns, CLOCK_MONOTONIC).
    Message {
        /// Receive time.
        t_ns: u64,
        /// Sender.
        header: MavHeader,
        /// The message.
        msg: Box<MavMessage>,
    },
    /// The connection is gone (EOF, reset); the thread has ended.
    Closed(String),
}

/// The connection type shared by both threads.
pub type SharedConnection = Arc<dyn MavConnection<MavMessage> + Send + Sync>;

/// Only these reach the session; the rest (dozens of streams a GCS link carries) are
/// dropped here so the loop is woken only for something it uses.
fn wanted(msg: &MavMessage) -> bool {
    matches!(
        msg,
        MavMessage::HEARTBEAT(_)
            | MavMessage::COMMAND_ACK(_)
            | MavMessage::SCALED_IMU(_)
            | MavMessage::SCALED_IMU2(_)
            | MavMessage::RAW_IMU(_)
            | MavMessage::ATTITUDE(_)
            | MavMessage::SCALED_PRESSURE2(_)
            | MavMessage::STATUSTEXT(_)
    )
}

/// Starts the receive thread. It ends when `stop` is set (within one receive timeout), when
/// the loop's receiver is dropped, or when the connection closes.
pub fn spawn(
    conn: SharedConnection,
    tx: Sender<Incoming>,
    waker: Waker,
    stop: Arc<AtomicBool>,
) -> Result<JoinHandle<()>, BackendError> {
    std::thread::Builder::new()
        .name("mavlink-rx".to_string())
        .spawn(move || receive_loop(conn, tx, waker, stop))
        .map_err(|source| BackendError::Thread {
            what: "MAVLink receive",
            source,
        })
}

fn receive_loop(conn: SharedConnection, tx: Sender<Incoming>, waker: Waker, stop: Arc<AtomicBool>) {
    let mut parse_errors = 0u64;
    while !stop.load(Ordering::Relaxed) {
        match conn.recv() {
            Ok((header, msg)) => {
                let t_ns = monotonic_ns();
                if !wanted(&msg) {
                    continue;
                }
                let m = Incoming::Message {
                    t_ns,
                    header,
                    msg: Box::new(msg),
                };
                if tx.send(m).is_err() {
                    return;
                }
                waker.wake();
            }
            Err(MessageReadError::Io(e)) => match e.kind() {
                // Receive timeouts (UDP read timeout, TCP's 100 ms): look at the flag.
                ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted => {}
                ErrorKind::UnexpectedEof
                | ErrorKind::ConnectionReset
                | ErrorKind::ConnectionAborted
                | ErrorKind::BrokenPipe
                | ErrorKind::NotConnected => {
                    let _ = tx.send(Incoming::Closed(e.to_string()));
                    waker.wake();
                    return;
                }
                // Anything else (e.g. ICMP errors reported on a UDP socket) is transient;
                // pause briefly so a persistent one cannot spin this thread.
                _ => {
                    tracing::debug!(error = %e, "MAVLink receive error");
                    std::thread::sleep(Duration::from_millis(10));
                }
            },
            Err(MessageReadError::Parse(e)) => {
                parse_errors += 1;
                if parse_errors.is_power_of_two() {
                    tracing::debug!(error = ?e, parse_errors, "undecodable MAVLink message");
                }
            }
        }
    }
}
