//! The live view: the recorder's drained messages onto Foxglove channels of a context whose
//! one sink is the WebSocket server.
//!
//! One thread of its own takes the messages from the bounded queue the draining loop fills
//! ([`thruster_recorder::tap`]) and logs each on its channel; the SDK queues it per
//! subscribed client (dropping a slow client's oldest, see `websocket.backlog`). The channels
//! are the recorder's: named by the topic's leaf (`imu`, `telemetry`, ...), JSON messages with
//! the same JSON Schema (`thrusterd.<Type>`), so a Foxglove layout works on a live vehicle and
//! on a recording alike. The log time is the recorder's receipt time, as in the file.
//!
//! State topics are latched ([`Latest`]): a client that subscribes after the daemon published
//! its model (an operator's app opened topside after the vehicle was set up) gets the last one
//! at once, as a late iceoryx2 subscriber gets the topic's history, instead of an empty model
//! panel until the next swap (never, while idle). The SDK's server keeps no last message.

use std::collections::{BTreeMap, HashMap};
use std::sync::mpsc::Receiver;
use std::sync::{Arc, Mutex};

use foxglove::websocket::{ChannelView, Client, ServerListener};
use foxglove::{ChannelBuilder, Context, PartialMetadata, RawChannel, Schema};
use thruster_recorder::sink::{MESSAGE_ENCODING, SCHEMA_ENCODING};
use thruster_recorder::Message;

use crate::BridgeError;

/// The topics whose last message a newly subscribed client gets at once: the daemon's state
/// (each history 1 in the protocol, published on change or slowly), not the sample streams.
pub const LATCHED: [&str; 7] = [
    "config",
    "model",
    "dynamics",
    "status",
    "driver_status",
    "setpoint",
    "truth",
];

/// The last message of each latched topic, with its channel: filled by [`forward`], read by the
/// server's subscribe callback.
#[derive(Default, Clone)]
pub struct Latest(Arc<Mutex<HashMap<String, Last>>>);

/// A latched topic's channel, its last message and that message's log time (ns).
type Last = (Arc<RawChannel>, Vec<u8>, u64);

impl Latest {
    fn keep(&self, channel: &Arc<RawChannel>, data: &[u8], log_ns: u64) {
        let topic = channel.topic();
        if !LATCHED.contains(&topic) {
            return;
        }
        // A poisoned lock only means a panicking callback; the map itself is whole.
        let mut map = self.0.lock().unwrap_or_else(|e| e.into_inner());
        map.insert(
            topic.to_string(),
            (Arc::clone(channel), data.to_vec(), log_ns),
        );
    }
}

/// The server's listener: on a subscription to a latched topic, its last message again. It
/// goes to every subscriber of the channel (the SDK logs per channel, not per client); a
/// repeated state message is harmless to the others.
impl ServerListener for Latest {
    fn on_subscribe(&self, _client: Client, channel: ChannelView) {
        let last = {
            let map = self.0.lock().unwrap_or_else(|e| e.into_inner());
            map.get(channel.topic()).cloned()
        };
        if let Some((logger, data, log_ns)) = last {
            logger.log_with_meta(
                &data,
                PartialMetadata {
                    log_time: Some(log_ns),
                },
            );
        }
    }
}

/// Logs every message of `rx` on the channel of its topic in `context`, until the draining
/// loop hangs up, keeping the latched topics' last in `latest`. Returns how many messages it
/// logged.
pub fn forward(
    context: &Arc<Context>,
    rx: &Receiver<Message>,
    latest: &Latest,
) -> Result<u64, BridgeError> {
    let mut channels: BTreeMap<usize, Arc<RawChannel>> = BTreeMap::new();
    let mut logged = 0;
    for m in rx {
        let logger = match channels.entry(m.index) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(e) => e.insert(channel(context, &m)?),
        };
        logger.log_with_meta(
            &m.data,
            PartialMetadata {
                log_time: Some(m.log_ns),
            },
        );
        latest.keep(logger, &m.data, m.log_ns);
        logged += 1;
    }
    for c in channels.values() {
        c.close();
    }
    Ok(logged)
}

/// The channel of `m`'s topic: created on the topic's first message the live view sees (the
/// schema comes from the message's JSON shape), advertised to every client from then on.
fn channel(context: &Arc<Context>, m: &Message) -> Result<Arc<RawChannel>, BridgeError> {
    let info = &m.channel;
    ChannelBuilder::new(info.topic)
        .message_encoding(MESSAGE_ENCODING)
        .schema(Schema::new(
            info.schema_name.clone(),
            SCHEMA_ENCODING,
            info.schema.clone(),
        ))
        .context(context)
        .build_raw()
        .map_err(|source| BridgeError::Channel {
            topic: info.topic,
            source,
        })
}
