//! A consumer of the drained messages behind a bounded queue: the MCAP writer thread, or a
//! live view (the Foxglove bridge).
//!
//! The draining loop must never wait for a consumer: it has to empty the 128-sample
//! subscriber buffers faster than the daemon fills them. So every hand-over is a `try_send`
//! into a queue of fixed capacity; when the consumer is behind (a slow disk, a slow network)
//! the message is dropped for that consumer alone and counted per topic. Memory stays bounded
//! by the capacity, and the other consumers still get every message.

use std::collections::BTreeMap;
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::Arc;

/// A channel as the consumers learn it: with every message, so a consumer that missed the
/// first message of a topic (dropped) still knows its channel from the next one.
#[derive(Debug)]
pub struct ChannelInfo {
    /// The topic's leaf, e.g. `imu`.
    pub topic: &'static str,
    /// `thrusterd.<Type>`.
    pub schema_name: String,
    /// JSON Schema of the messages, serialised.
    pub schema: Vec<u8>,
}

/// One drained message, serialised once and shared by every consumer.
#[derive(Debug, Clone)]
pub struct Message {
    /// The recording-wide channel index (one per topic).
    pub index: usize,
    pub channel: Arc<ChannelInfo>,
    /// The sender's `seq` (low 32 bits).
    pub sequence: u32,
    /// When the recorder received it, ns since the Unix epoch.
    pub log_ns: u64,
    /// The sender's time where the message has one, else `log_ns`.
    pub publish_ns: u64,
    /// The message as JSON.
    pub data: Arc<[u8]>,
}

/// The sending end of a consumer's bounded queue, owned by the draining loop.
pub struct Tap<T> {
    name: &'static str,
    tx: SyncSender<T>,
    /// Messages dropped because the queue was full, per topic.
    dropped: BTreeMap<&'static str, u64>,
    /// Set once the consumer has hung up (it stopped; its own thread reports why).
    closed: bool,
}

/// A tap named `name` (for the summary) and the consumer's end, holding at most `capacity`
/// items.
pub fn bounded<T>(name: &'static str, capacity: usize) -> (Tap<T>, Receiver<T>) {
    let (tx, rx) = mpsc::sync_channel(capacity);
    (
        Tap {
            name,
            tx,
            dropped: BTreeMap::new(),
            closed: false,
        },
        rx,
    )
}

impl<T> Tap<T> {
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// Hands `item` over without waiting; a full queue drops it (counted under `topic`).
    pub fn offer(&mut self, topic: &'static str, item: T) {
        match self.tx.try_send(item) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => *self.dropped.entry(topic).or_insert(0) += 1,
            Err(TrySendError::Disconnected(_)) => self.closed = true,
        }
    }

    /// Hands `item` over, waiting for room: only for the end of a recording, never per message.
    pub fn send_blocking(&self, item: T) -> bool {
        self.tx.send(item).is_ok()
    }

    /// Dropped messages of `topic`.
    pub fn dropped(&self, topic: &str) -> u64 {
        self.dropped.get(topic).copied().unwrap_or(0)
    }

    /// Dropped messages over every topic.
    pub fn dropped_total(&self) -> u64 {
        self.dropped.values().sum()
    }

    /// Whether the consumer has stopped taking items.
    pub fn closed(&self) -> bool {
        self.closed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_queue_drops_and_counts_without_waiting() {
        let (mut tap, rx) = bounded::<u32>("test", 2);
        for i in 0..5 {
            tap.offer(if i % 2 == 0 { "imu" } else { "thrust" }, i);
        }
        // The first two went in, the other three were dropped.
        assert_eq!(rx.try_iter().collect::<Vec<_>>(), vec![0, 1]);
        assert_eq!(tap.dropped("imu"), 2);
        assert_eq!(tap.dropped("thrust"), 1);
        assert_eq!(tap.dropped_total(), 3);
        tap.offer("imu", 9);
        assert_eq!(rx.try_recv().unwrap(), 9);
        drop(rx);
        tap.offer("imu", 10);
        assert!(tap.closed());
        assert_eq!(tap.dropped("imu"), 2);
    }
}
