//! One topic's subscription: drains it into the sink and counts sequence gaps.

use std::sync::Arc;

use schemars::JsonSchema;
use serde::Serialize;
use thruster_protocol::services::{IpcConfig, IpcNode, Reader, TopicMessage};
use thruster_protocol::*;

use crate::schema::{schema_of, to_recorded, ROW_KEY};
use crate::tap::{ChannelInfo, Message};
use crate::RecordError;

/// The sequence number and sender time of a message.
pub trait Stamped {
    /// Whether consecutive messages come from one sender counting 1, 2, 3, ... so that a gap
    /// in `seq` is a lost message. Not so for the operator's setpoint and reconfiguration:
    /// every `thrusterctl` run is a new sender, starting from the wall clock.
    const ONE_STREAM: bool = true;
    fn seq(&self) -> u64;
    /// The sender's time, ns, where the message has one.
    fn t_ns(&self) -> Option<u64>;
}

macro_rules! stamped {
    ($($ty:ty: $t:expr $(=> one_stream: $stream:literal)?),* $(,)?) => {$(
        impl Stamped for $ty {
            $(const ONE_STREAM: bool = $stream;)?
            fn seq(&self) -> u64 {
                self.seq
            }
            #[allow(clippy::redundant_closure_call)]
            fn t_ns(&self) -> Option<u64> {
                ($t)(self)
            }
        }
    )*};
}

stamped! {
    ImuSample: |m: &ImuSample| Some(m.t_ns),
    ThrustCommand: |m: &ThrustCommand| Some(m.t_ns),
    TelemetryMsg: |m: &TelemetryMsg| Some(m.t_ns),
    ModelMsg: |m: &ModelMsg| Some(m.t_ns),
    DynamicsMsg: |m: &DynamicsMsg| Some(m.t_ns),
    DvlSample: |m: &DvlSample| Some(m.t_ns),
    TruthMsg: |m: &TruthMsg| Some(m.t_ns),
    VehicleStateMsg: |m: &VehicleStateMsg| Some(m.t_ns),
    StatusMsg: |_: &StatusMsg| None,
    Setpoint: |_: &Setpoint| None => one_stream: false,
    ReconfigEvent: |_: &ReconfigEvent| None => one_stream: false,
    DriverStatusMsg: |_: &DriverStatusMsg| None,
    InputMsg: |m: &InputMsg| Some(m.t_ns),
    ConfigMsg: |_: &ConfigMsg| None,
    CheckpointMsg: |m: &CheckpointMsg| Some(m.t_ns),
}

/// Sequence-gap accounting of one topic.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct SeqTracker {
    last: Option<u64>,
    /// Messages missing between two received ones.
    pub lost: u64,
    /// Times the sequence went backwards (a sender restarted, or a second sender).
    pub restarts: u64,
}

impl SeqTracker {
    pub fn see(&mut self, seq: u64) {
        match self.last {
            Some(last) if seq > last => self.lost += seq - last - 1,
            Some(_) => self.restarts += 1,
            None => {}
        }
        self.last = Some(seq);
    }
}

/// A topic being recorded.
pub trait Source {
    fn topic(&self) -> &'static str;
    /// Hands every buffered message to `out` as channel `index`; returns how many. `now_ns`
    /// gives the log time.
    fn drain(
        &mut self,
        index: usize,
        out: &mut dyn FnMut(Message),
        now_ns: &dyn Fn() -> u64,
    ) -> Result<usize, RecordError>;
    fn count(&self) -> u64;
    fn seq(&self) -> SeqTracker;
}

/// The subscription to `T`'s topic with the largest buffer the topic allows, without a
/// listener: the recorder polls on its own clock ([`crate::recording`]), so no publisher
/// notifies it and no sample wakes it.
pub struct TopicSource<T: TopicMessage> {
    reader: Reader<T>,
    namespace: String,
    /// Declared from the type ([`channel_info`]).
    channel: Arc<ChannelInfo>,
    /// Whether `T` has a matrix, written in the recorded form ([`to_recorded`]).
    has_rows: bool,
    count: u64,
    seq: SeqTracker,
}

/// The channel of `T`'s topic: its leaf, and the JSON Schema declared from the type.
pub fn channel_info<T: TopicMessage + JsonSchema>() -> Result<ChannelInfo, RecordError> {
    let name = schema_name::<T>();
    let schema =
        serde_json::to_vec(&schema_of::<T>(&name)).map_err(|source| RecordError::Json {
            topic: T::TOPIC.leaf(),
            source,
        })?;
    Ok(ChannelInfo {
        topic: T::TOPIC.leaf(),
        schema_name: name,
        schema,
    })
}

impl<T: TopicMessage + Serialize + Stamped + JsonSchema> TopicSource<T> {
    pub fn open(node: &IpcNode, ipc: &IpcConfig) -> Result<Self, RecordError> {
        let reader =
            Reader::create_with_buffer(node, ipc, T::TOPIC.qos().max_buffer).map_err(|source| {
                RecordError::Ipc {
                    namespace: ipc.namespace().to_string(),
                    source,
                }
            })?;
        let channel = channel_info::<T>()?;
        let has_rows = String::from_utf8_lossy(&channel.schema).contains(&format!("\"{ROW_KEY}\""));
        Ok(Self {
            reader,
            namespace: ipc.namespace().to_string(),
            channel: Arc::new(channel),
            has_rows,
            count: 0,
            seq: SeqTracker::default(),
        })
    }
}

/// `thrusterd.ImuSample`, from the Rust type name.
fn schema_name<T>() -> String {
    let full = std::any::type_name::<T>();
    format!("thrusterd.{}", full.rsplit("::").next().unwrap_or(full))
}

impl<T: TopicMessage + Serialize + Stamped + JsonSchema> Source for TopicSource<T> {
    fn topic(&self) -> &'static str {
        T::TOPIC.leaf()
    }

    fn drain(
        &mut self,
        index: usize,
        out: &mut dyn FnMut(Message),
        now_ns: &dyn Fn() -> u64,
    ) -> Result<usize, RecordError> {
        let topic = self.topic();
        let ipc = |source| RecordError::Ipc {
            namespace: self.namespace.clone(),
            source,
        };
        let mut n = 0;
        while let Some(msg) = self.reader.recv().map_err(ipc)? {
            let json = |source| RecordError::Json { topic, source };
            let channel = Arc::clone(&self.channel);
            // Straight to bytes unless the type has a matrix to rewrite as row objects.
            let data: Arc<[u8]> = if self.has_rows {
                let mut value = serde_json::to_value(msg).map_err(json)?;
                to_recorded(&mut value);
                serde_json::to_vec(&value).map_err(json)?.into()
            } else {
                serde_json::to_vec(&msg).map_err(json)?.into()
            };
            let log_ns = now_ns();
            // Publish time: the sender's clock where the message has one (vehicle time for
            // the simulator), else the receipt.
            out(Message {
                index,
                channel,
                sequence: msg.seq() as u32,
                log_ns,
                publish_ns: msg.t_ns().unwrap_or(log_ns),
                data,
            });
            if T::ONE_STREAM {
                self.seq.see(msg.seq());
            }
            self.count += 1;
            n += 1;
        }
        Ok(n)
    }

    fn count(&self) -> u64 {
        self.count
    }

    fn seq(&self) -> SeqTracker {
        self.seq
    }
}

/// Calls `$m!` with every topic's message type: one list for the subscriptions
/// ([`open_all`]) and the declared channels ([`all_channels`]).
macro_rules! every_topic {
    ($m:ident) => {
        $m!(
            ImuSample,
            ThrustCommand,
            TelemetryMsg,
            ModelMsg,
            StatusMsg,
            ReconfigEvent,
            Setpoint,
            DriverStatusMsg,
            DynamicsMsg,
            DvlSample,
            TruthMsg,
            VehicleStateMsg,
            // What `thrusterd replay` needs besides the IMU stream (docs/recording.md).
            InputMsg,
            ConfigMsg,
            // Where the replay of a recording started late begins.
            CheckpointMsg
        )
    };
}

/// Every topic of the protocol, subscribed on `node`.
pub fn open_all(node: &IpcNode, ipc: &IpcConfig) -> Result<Vec<Box<dyn Source>>, RecordError> {
    macro_rules! open {
        ($($t:ty),*) => {
            vec![$(Box::new(TopicSource::<$t>::open(node, ipc)?) as Box<dyn Source>),*]
        };
    }
    Ok(every_topic!(open))
}

/// The channel of every topic (what a recording or the live view declares for it).
pub fn all_channels() -> Result<Vec<ChannelInfo>, RecordError> {
    macro_rules! channels {
        ($($t:ty),*) => {
            vec![$(channel_info::<$t>()?),*]
        };
    }
    Ok(every_topic!(channels))
}

/// The default message of every topic in the recorded form, with its declared schema, for the
/// tests that hold the two together.
pub fn every_default_message() -> Vec<(&'static str, serde_json::Value, serde_json::Value)> {
    fn one<T: TopicMessage + Serialize + JsonSchema + Default>(
    ) -> (&'static str, serde_json::Value, serde_json::Value) {
        let mut value = serde_json::to_value(T::default()).expect("a message serialises");
        to_recorded(&mut value);
        (T::TOPIC.leaf(), value, schema_of::<T>(&schema_name::<T>()))
    }
    macro_rules! defaults {
        ($($t:ty),*) => {
            vec![$(one::<$t>()),*]
        };
    }
    every_topic!(defaults)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_count_as_losses_and_backward_steps_as_restarts() {
        let mut s = SeqTracker::default();
        for seq in [5, 6, 7, 10, 11, 2, 3] {
            s.see(seq);
        }
        assert_eq!(s.lost, 2);
        assert_eq!(s.restarts, 1);
    }

    #[test]
    fn every_field_of_every_topic_has_its_schema_entry() {
        // The schemas are derived from the types; this holds the JSON each type serialises to
        // (a custom Serialize, a serde attribute, the row rewrite) to its declared schema, so a
        // field that reaches the wire without a schema entry fails here.
        let all = every_default_message();
        assert_eq!(all.len(), 15);
        for (topic, value, schema) in all {
            let mut out = Vec::new();
            crate::schema::mismatches(&schema, &value, topic, &mut out);
            assert!(out.is_empty(), "{topic}: {out:#?}");
            let text = schema.to_string();
            assert!(!text.contains("\"null\""), "{topic}: a null type in {text}");
            assert!(!text.contains("$ref"), "{topic}: a reference in {text}");
        }
    }

    #[test]
    fn schema_names_come_from_the_type() {
        assert_eq!(schema_name::<ImuSample>(), "thrusterd.ImuSample");
    }
}
