//! The recorder: subscribes to every topic of a namespace and writes MCAP.
//!
//! One channel per topic (named by the topic's leaf, e.g. `imu`), messages as JSON
//! (`message_encoding = "json"`) with a JSON Schema per channel (`schema encoding =
//! "jsonschema"`), so Foxglove plots any field without configuration. The recorder is a
//! subscriber only: iceoryx2 publishers never block on a full subscriber buffer (safe
//! overflow drops the subscriber's oldest sample), so a slow recorder can lose samples but
//! never slow the daemon. Every message carries `seq` (+1 per message from its sender), so
//! a loss shows as a gap, counted per topic ([`Losses`]) and written into the file.
//!
//! Modules, one job each: [`schema`] (JSON Schema of a message), [`sink`] (the MCAP files and
//! their rotation), [`source`] (a topic's subscription and its loss count), [`tap`] (a
//! consumer's bounded queue, drops counted), [`recording`] (the loop that ties them together).

pub mod recording;
pub mod schema;
pub mod sink;
pub mod source;
pub mod tap;

pub use recording::{
    record, record_on, stream_on, RecordOptions, RecordSummary, TapSummary, TopicSummary,
    DEFAULT_QUEUE,
};
pub use sink::{rotated_path, Compression, McapSink};
pub use tap::{ChannelInfo, Message, Tap};

use std::path::PathBuf;

/// What can stop a recording.
///
/// Each message names the object and leaves its cause to [`std::error::Error::source`], so an
/// `anyhow` chain printed with `{:#}` reads `cannot write FILE: No space left on device (os
/// error 28)`, once (a message repeating its source printed the OS error twice).
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// A file could not be created or written (a full disk: `ENOSPC`).
    #[error("cannot write {path}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("MCAP writer on {path}")]
    Mcap {
        path: PathBuf,
        #[source]
        source: mcap::McapError,
    },
    #[error("serialising a {topic} message")]
    Json {
        topic: &'static str,
        #[source]
        source: serde_json::Error,
    },
    #[error("subscribing on namespace {namespace}")]
    Ipc {
        namespace: String,
        #[source]
        source: thruster_protocol::services::IpcError,
    },
    #[error("{0}")]
    Options(String),
    /// The recording had started and stopped on `source`; `summary` accounts for what it received
    /// and what reached the files before that ([`RecordSummary::written`]).
    #[error(
        "stopped with {} messages in {} file(s)",
        .summary.written,
        .summary.files.len()
    )]
    Stopped {
        summary: Box<RecordSummary>,
        #[source]
        source: Box<RecordError>,
    },
}

impl RecordError {
    /// What a recording that had started received and wrote before it stopped on this error
    /// (None: it never started). Every front end prints its line, so a failed recording still
    /// says how much of it is on disk.
    pub fn summary(&self) -> Option<&RecordSummary> {
        match self {
            RecordError::Stopped { summary, .. } => Some(summary),
            _ => None,
        }
    }
}
