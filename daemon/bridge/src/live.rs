//! The live view: the recorder's drained messages onto Foxglove channels of a context whose
//! one sink is the WebSocket server.
//!
//! One thread of its own takes the messages from the bounded queue the draining loop fills
//! ([`thruster_recorder::tap`]) and logs each on its channel; the SDK queues it per
//! subscribed client (dropping a slow client's oldest, see `websocket.backlog`). The channels
//! are the recorder's: named by the topic's leaf (`imu`, `telemetry`, ...), JSON messages with
//! the same JSON Schema (`thrusterd.<Type>`), so a Foxglove layout works on a live vehicle and
//! on a recording alike. The log time is the recorder's receipt time, as in the file.

use std::collections::BTreeMap;
use std::sync::mpsc::Receiver;
use std::sync::Arc;

use foxglove::{ChannelBuilder, Context, PartialMetadata, RawChannel, Schema};
use thruster_recorder::sink::{MESSAGE_ENCODING, SCHEMA_ENCODING};
use thruster_recorder::Message;

use crate::BridgeError;

/// Logs every message of `rx` on the channel of its topic in `context`, until the draining
/// loop hangs up. Returns how many messages it logged.
pub fn forward(context: &Arc<Context>, rx: &Receiver<Message>) -> Result<u64, BridgeError> {
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
