//! thruster-bridge: the live view over the tether. A process of its own beside the daemon
//! (which keeps `IPAddressDeny=any`): it subscribes to every topic of a namespace with the
//! recorder's sources, streams them to the Foxglove app through the Foxglove SDK's WebSocket
//! server, offers the operator's requests as WebSocket services, and can record the same
//! messages to MCAP. One drain of the subscribers feeds both, each consumer behind a bounded
//! queue, so neither a slow client nor a slow disk can slow the draining (or the daemon, which
//! never waits for a subscriber).
//!
//! Modules, one job each: [`config`] (the TOML file), [`layout`] (the Foxglove layout for a
//! vehicle), [`live`] (messages onto Foxglove channels), [`services`] (the operator's requests as services), [`bridge`] (starting and
//! stopping the parts around the recorder's drain).

pub mod bridge;
pub mod config;
pub mod layout;
pub mod live;
pub mod services;

/// What the live view's own parts can fail with.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error("creating the Foxglove channel {topic}: {source}")]
    Channel {
        topic: &'static str,
        #[source]
        source: foxglove::FoxgloveError,
    },
    #[error("starting the WebSocket server on {addr}: {source}")]
    Server {
        addr: std::net::SocketAddr,
        #[source]
        source: foxglove::FoxgloveError,
    },
}
