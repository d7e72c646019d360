//! The link to the autopilot and the receive thread.
//!
//! The receive thread blocks on the link, stamps each message with CLOCK_MONOTONIC the
//! moment it is decoded, forwards the ones the conversation uses and wakes the driver loop.
//! Sending happens on the loop's thread through the same link.
//!
//! UDP is ours, not the `mavlink` crate's, because a datagram is input like any other and
//! anyone who can reach the port can send one:
//! - the crate's `udpin` replies to the source of the last datagram received, whatever it
//!   held, so any sender captured our motor tests (the autopilot saw them lapse and
//!   disarmed). Here `udpin` replies only to the address the autopilot's HEARTBEAT came
//!   from (locked until the link is lost) and drops every other sender's datagrams;
//!   `udpout` uses a connected socket, so the kernel drops other senders;
//! - the crate ends the connection on an empty datagram ("unexpected end of file"). Here
//!   an empty, undecodable or foreign datagram is counted ([`LinkCounters`]) and dropped.
//!
//! TCP and serial go through the crate; there an end of stream is a real failure of the
//! configured link, which ends the conversation (the backend reconnects).

use std::io::ErrorKind;
use std::net::{SocketAddr, ToSocketAddrs, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use super::conversation::Conversation;
use mavlink::dialects::ardupilotmega::{MavAutopilot, MavMessage};
use mavlink::error::MessageReadError;
use mavlink::{
    Connectable, Connection, ConnectionAddress, MavConnection, MavHeader, MavlinkReader,
    MavlinkVersion,
};
use tracing::{debug, info};

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

/// Datagrams and frames dropped at the link, for the status line and tests.
#[derive(Debug, Default)]
pub struct LinkCounters {
    /// Zero-length datagrams.
    pub empty: AtomicU64,
    /// Datagrams (or stream frames) with no decodable MAVLink message.
    pub malformed: AtomicU64,
    /// Datagrams from an address other than the autopilot's (udpin after the lock).
    pub foreign: AtomicU64,
}

impl LinkCounters {
    fn bump(c: &AtomicU64) {
        c.fetch_add(1, Ordering::Relaxed);
    }

    /// (empty, malformed, foreign).
    pub fn snapshot(&self) -> (u64, u64, u64) {
        (
            self.empty.load(Ordering::Relaxed),
            self.malformed.load(Ordering::Relaxed),
            self.foreign.load(Ordering::Relaxed),
        )
    }
}

/// One receive: messages, or nothing (timeout, a dropped datagram), or the end.
pub enum Recv {
    /// Decoded messages (a datagram may carry several).
    Messages(Vec<(MavHeader, MavMessage)>),
    /// Nothing this time.
    Nothing,
    /// The link failed for good.
    Closed(String),
}

/// A link to the autopilot, shared by the receive thread and the loop.
pub trait Link: Send + Sync {
    /// Blocks until something arrives or the read timeout passes.
    fn recv(&self) -> Recv;
    /// Sends one message (the sequence number is filled in here).
    fn send(&self, header: &MavHeader, msg: &MavMessage) -> Result<(), String>;
    /// Forgets the autopilot's address (udpin): the next autopilot HEARTBEAT sets it again.
    fn forget_peer(&self) {}
    /// Counters of dropped input.
    fn counters(&self) -> &LinkCounters;
}

/// The link type shared by both threads.
pub type SharedLink = Arc<dyn Link>;

/// Opens `address` ("udpin:ADDR:PORT", "udpout:HOST:PORT", or anything the `mavlink` crate
/// takes: "tcpout:", "tcpin:", "serial:"). `target` is the configured autopilot (0 = any)
/// for udpin's peer lock.
pub fn open(address: &str, read_timeout: Duration, target: (u8, u8)) -> Result<SharedLink, String> {
    if let Some(rest) = address.strip_prefix("udpin:") {
        return UdpLink::open(rest, false, read_timeout, target).map(|l| Arc::new(l) as SharedLink);
    }
    if let Some(rest) = address.strip_prefix("udpout:") {
        return UdpLink::open(rest, true, read_timeout, target).map(|l| Arc::new(l) as SharedLink);
    }
    let addr =
        ConnectionAddress::parse_address(address).map_err(|e| format!("{address:?}: {e}"))?;
    let mut conn = addr
        .connect::<MavMessage>()
        .map_err(|e| format!("{address}: {e}"))?;
    // ArduPilot answers in the version it is spoken to; accept both anyway.
    conn.set_allow_recv_any_version(true);
    Ok(Arc::new(StreamLink {
        conn,
        counters: LinkCounters::default(),
    }))
}

/// UDP, see the module docs.
pub struct UdpLink {
    socket: UdpSocket,
    /// udpout: the socket is connected to the configured address.
    connected: bool,
    /// udpin: where the autopilot's HEARTBEAT came from.
    peer: Mutex<Option<SocketAddr>>,
    target: (u8, u8),
    seq: AtomicU8,
    buf: Mutex<Vec<u8>>,
    counters: LinkCounters,
}

/// Largest UDP payload.
const MAX_DATAGRAM: usize = 65_536;

/// Most messages taken from one datagram (a MAVLink frame is at least 8 bytes; this bounds
/// the work a hostile datagram can cause).
const MAX_PER_DATAGRAM: usize = 64;

impl UdpLink {
    fn open(
        hostport: &str,
        out: bool,
        read_timeout: Duration,
        target: (u8, u8),
    ) -> Result<UdpLink, String> {
        let resolve = |s: &str| -> Result<SocketAddr, String> {
            s.to_socket_addrs()
                .map_err(|e| format!("{s}: {e}"))?
                .next()
                .ok_or_else(|| format!("{s}: no address"))
        };
        let socket = if out {
            let dest = resolve(hostport)?;
            let any: SocketAddr = if dest.is_ipv4() {
                "0.0.0.0:0".parse().expect("literal")
            } else {
                "[::]:0".parse().expect("literal")
            };
            let s = UdpSocket::bind(any).map_err(|e| format!("bind: {e}"))?;
            // Connected: the kernel delivers only the configured peer's datagrams.
            s.connect(dest)
                .map_err(|e| format!("connect {dest}: {e}"))?;
            s
        } else {
            let at = resolve(hostport)?;
            UdpSocket::bind(at).map_err(|e| format!("bind {at}: {e}"))?
        };
        socket
            .set_read_timeout(Some(read_timeout))
            .map_err(|e| format!("read timeout: {e}"))?;
        Ok(UdpLink {
            socket,
            connected: out,
            peer: Mutex::new(None),
            target,
            seq: AtomicU8::new(0),
            buf: Mutex::new(vec![0; MAX_DATAGRAM]),
            counters: LinkCounters::default(),
        })
    }

    /// The autopilot's HEARTBEAT (what udpin locks onto): not a ground station's or a
    /// companion's (MAV_AUTOPILOT_INVALID), and the configured ids if any.
    fn is_autopilot_heartbeat(&self, h: &MavHeader, m: &MavMessage) -> bool {
        let MavMessage::HEARTBEAT(hb) = m else {
            return false;
        };
        let fits = |want: u8, got: u32| want == 0 || u32::from(want) == got;
        hb.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID
            && fits(self.target.0, h.system_id)
            && fits(self.target.1, u32::from(h.component_id))
    }

    fn peer(&self) -> Option<SocketAddr> {
        *self.peer.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// Every message in one datagram.
fn decode_datagram(bytes: &[u8]) -> Vec<(MavHeader, MavMessage)> {
    let mut reader = MavlinkReader::new(bytes);
    let mut out = Vec::new();
    for _ in 0..MAX_PER_DATAGRAM {
        match reader.read_any_message::<MavMessage>() {
            Ok(m) => out.push(m),
            // End of the datagram (a partial frame included).
            Err(MessageReadError::Io(_)) => break,
            // A frame with a valid checksum but an unknown or broken payload: skip it.
            Err(MessageReadError::Parse(_)) => {}
        }
    }
    out
}

impl Link for UdpLink {
    fn recv(&self) -> Recv {
        let mut buf = self.buf.lock().unwrap_or_else(|e| e.into_inner());
        let (n, from) = match self.socket.recv_from(&mut buf) {
            Ok(r) => r,
            Err(e) => {
                match e.kind() {
                    ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted => {}
                    // ICMP errors reported on the socket (nobody listening yet, ...) are
                    // transient on UDP; pause so a persistent one cannot spin this thread.
                    _ => {
                        debug!(error = %e, "UDP receive error");
                        std::thread::sleep(Duration::from_millis(10));
                    }
                }
                return Recv::Nothing;
            }
        };
        if n == 0 {
            LinkCounters::bump(&self.counters.empty);
            return Recv::Nothing;
        }
        let locked = self.peer();
        if !self.connected && locked.is_some_and(|p| p != from) {
            LinkCounters::bump(&self.counters.foreign);
            return Recv::Nothing;
        }
        let msgs = decode_datagram(&buf[..n]);
        if msgs.is_empty() {
            LinkCounters::bump(&self.counters.malformed);
            return Recv::Nothing;
        }
        if !self.connected
            && locked.is_none()
            && msgs.iter().any(|(h, m)| self.is_autopilot_heartbeat(h, m))
        {
            info!(%from, "autopilot HEARTBEAT: replies go to this address only");
            *self.peer.lock().unwrap_or_else(|e| e.into_inner()) = Some(from);
        }
        Recv::Messages(msgs)
    }

    fn send(&self, header: &MavHeader, msg: &MavMessage) -> Result<(), String> {
        let mut h = *header;
        h.sequence = self.seq.fetch_add(1, Ordering::Relaxed);
        let mut frame = Vec::with_capacity(280);
        mavlink::write_versioned_msg(&mut frame, MavlinkVersion::V2, h, msg)
            .map_err(|e| format!("encode: {e}"))?;
        let sent = if self.connected {
            self.socket.send(&frame)
        } else {
            match self.peer() {
                Some(p) => self.socket.send_to(&frame, p),
                // No autopilot heard yet: nobody to talk to.
                None => return Ok(()),
            }
        };
        sent.map(|_| ()).map_err(|e| e.to_string())
    }

    fn forget_peer(&self) {
        if !self.connected {
            *self.peer.lock().unwrap_or_else(|e| e.into_inner()) = None;
        }
    }

    fn counters(&self) -> &LinkCounters {
        &self.counters
    }
}

/// TCP or serial through the `mavlink` crate.
struct StreamLink {
    conn: Connection<MavMessage>,
    counters: LinkCounters,
}

impl Link for StreamLink {
    fn recv(&self) -> Recv {
        match self.conn.recv() {
            Ok(m) => Recv::Messages(vec![m]),
            Err(MessageReadError::Io(e)) => match e.kind() {
                // Receive timeouts (TCP's 100 ms): look at the stop flag.
                ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted => {
                    Recv::Nothing
                }
                ErrorKind::UnexpectedEof
                | ErrorKind::ConnectionReset
                | ErrorKind::ConnectionAborted
                | ErrorKind::BrokenPipe
                | ErrorKind::NotConnected => Recv::Closed(e.to_string()),
                _ => {
                    debug!(error = %e, "MAVLink receive error");
                    std::thread::sleep(Duration::from_millis(10));
                    Recv::Nothing
                }
            },
            Err(MessageReadError::Parse(e)) => {
                LinkCounters::bump(&self.counters.malformed);
                debug!(error = ?e, "undecodable MAVLink message");
                Recv::Nothing
            }
        }
    }

    fn send(&self, header: &MavHeader, msg: &MavMessage) -> Result<(), String> {
        self.conn
            .send(header, msg)
            .map(|_| ())
            .map_err(|e| e.to_string())
    }

    fn counters(&self) -> &LinkCounters {
        &self.counters
    }
}

/// Starts the receive thread. It ends when `stop` is set (within one receive timeout), when
/// the loop's receiver is dropped, or when the link closes.
pub fn spawn(
    link: SharedLink,
    tx: Sender<Incoming>,
    waker: Waker,
    stop: Arc<AtomicBool>,
) -> Result<JoinHandle<()>, BackendError> {
    std::thread::Builder::new()
        .name("mavlink-rx".to_string())
        .spawn(move || receive_loop(link, tx, waker, stop))
        .map_err(|source| BackendError::Thread {
            what: "MAVLink receive",
            source,
        })
}

fn receive_loop(link: SharedLink, tx: Sender<Incoming>, waker: Waker, stop: Arc<AtomicBool>) {
    while !stop.load(Ordering::Relaxed) {
        match link.recv() {
            Recv::Messages(msgs) => {
                let t_ns = monotonic_ns();
                let mut any = false;
                for (header, msg) in msgs.into_iter().filter(|(_, m)| Conversation::takes(m)) {
                    let m = Incoming::Message {
                        t_ns,
                        header,
                        msg: Box::new(msg),
                    };
                    if tx.send(m).is_err() {
                        return;
                    }
                    any = true;
                }
                if any {
                    waker.wake();
                }
            }
            Recv::Nothing => {}
            Recv::Closed(reason) => {
                let _ = tx.send(Incoming::Closed(reason));
                waker.wake();
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::{
        MavModeFlag, MavState, MavType, HEARTBEAT_DATA, SCALED_IMU2_DATA,
    };

    fn hb(autopilot: MavAutopilot) -> MavMessage {
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_SUBMARINE,
            autopilot,
            base_mode: MavModeFlag::empty(),
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        })
    }

    fn frame(sys: u8, msg: &MavMessage) -> Vec<u8> {
        let h = MavHeader {
            system_id: u32::from(sys),
            component_id: 1,
            sequence: 0,
        };
        let mut v = Vec::new();
        mavlink::write_versioned_msg(&mut v, MavlinkVersion::V2, h, msg).unwrap();
        v
    }

    #[test]
    fn datagrams_decode_to_every_frame_and_garbage_to_nothing() {
        let mut two = frame(1, &hb(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA));
        two.extend(frame(
            1,
            &MavMessage::SCALED_IMU2(SCALED_IMU2_DATA::DEFAULT),
        ));
        assert_eq!(decode_datagram(&two).len(), 2);
        assert!(decode_datagram(&[]).is_empty());
        assert!(decode_datagram(&[0xfd, 9, 0, 0, 1]).is_empty());
        assert!(decode_datagram(&[0x55; 300]).is_empty());
        // A frame cut short: nothing, no error.
        assert!(decode_datagram(&two[..10]).is_empty());
    }

    #[test]
    fn udpin_locks_onto_the_autopilot_and_drops_the_rest() {
        let link = UdpLink::open("127.0.0.1:0", false, Duration::from_millis(200), (0, 0)).unwrap();
        let at = link.socket.local_addr().unwrap();
        let ap = UdpSocket::bind("127.0.0.1:0").unwrap();
        let stray = UdpSocket::bind("127.0.0.1:0").unwrap();
        stray
            .set_read_timeout(Some(Duration::from_millis(50)))
            .unwrap();
        ap.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        // Loopback delivers at once; a few receive timeouts at most.
        let recv_one = || {
            for _ in 0..20 {
                if let r @ Recv::Messages(_) = link.recv() {
                    return r;
                }
            }
            Recv::Nothing
        };
        // Before the lock a ground station's heartbeat passes (the conversation ignores it)
        // but locks nothing; our sends go nowhere.
        stray
            .send_to(&frame(255, &hb(MavAutopilot::MAV_AUTOPILOT_INVALID)), at)
            .unwrap();
        assert!(matches!(recv_one(), Recv::Messages(_)));
        assert_eq!(link.peer(), None);
        // The autopilot's heartbeat locks.
        ap.send_to(
            &frame(1, &hb(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA)),
            at,
        )
        .unwrap();
        assert!(matches!(recv_one(), Recv::Messages(_)));
        assert_eq!(link.peer(), Some(ap.local_addr().unwrap()));
        // Empty, garbage and foreign datagrams are counted and dropped.
        stray.send_to(&[], at).unwrap();
        assert!(matches!(link.recv(), Recv::Nothing));
        ap.send_to(&[1, 2, 3], at).unwrap();
        assert!(matches!(link.recv(), Recv::Nothing));
        stray
            .send_to(
                &frame(1, &hb(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA)),
                at,
            )
            .unwrap();
        assert!(matches!(link.recv(), Recv::Nothing));
        assert_eq!(link.counters.snapshot(), (1, 1, 1));
        // Replies go to the autopilot only.
        let h = MavHeader::default();
        link.send(&h, &hb(MavAutopilot::MAV_AUTOPILOT_INVALID))
            .unwrap();
        let mut b = [0u8; 300];
        assert!(ap.recv_from(&mut b).is_ok());
        assert!(
            stray.recv_from(&mut b).is_err(),
            "the stray sender got a reply"
        );
        // After a link loss the next autopilot heartbeat locks again.
        link.forget_peer();
        assert_eq!(link.peer(), None);
    }
}
