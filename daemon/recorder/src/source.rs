//! One topic's subscription: drains it into the sink and counts sequence gaps.

use std::sync::Arc;

use serde::Serialize;
use thruster_protocol::services::{IpcConfig, IpcNode, Reader, TopicMessage};
use thruster_protocol::*;

use crate::schema::json_schema;
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
/// listener: the recorder polls on its own clock ([`crate::session`]), so no publisher
/// notifies it and no sample wakes it.
pub struct TopicSource<T: TopicMessage> {
    reader: Reader<T>,
    namespace: String,
    /// Known from the first message (its JSON shape gives the schema).
    channel: Option<Arc<ChannelInfo>>,
    count: u64,
    seq: SeqTracker,
}

impl<T: TopicMessage + Serialize + Stamped> TopicSource<T> {
    pub fn open(node: &IpcNode, ipc: &IpcConfig) -> Result<Self, RecordError> {
        let reader =
            Reader::create_with_buffer(node, ipc, T::TOPIC.qos().max_buffer).map_err(|source| {
                RecordError::Ipc {
                    namespace: ipc.namespace().to_string(),
                    source,
                }
            })?;
        Ok(Self {
            reader,
            namespace: ipc.namespace().to_string(),
            channel: None,
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

impl<T: TopicMessage + Serialize + Stamped> Source for TopicSource<T> {
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
            let channel = match &self.channel {
                Some(c) => Arc::clone(c),
                None => {
                    let value = serde_json::to_value(msg).map_err(json)?;
                    let name = schema_name::<T>();
                    let schema = serde_json::to_vec(&json_schema(&name, &value)).map_err(json)?;
                    let c = Arc::new(ChannelInfo {
                        topic,
                        schema_name: name,
                        schema,
                    });
                    self.channel = Some(Arc::clone(&c));
                    c
                }
            };
            let data: Arc<[u8]> = serde_json::to_vec(&msg).map_err(json)?.into();
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

/// Every topic of the protocol, subscribed on `node`.
pub fn open_all(node: &IpcNode, ipc: &IpcConfig) -> Result<Vec<Box<dyn Source>>, RecordError> {
    Ok(vec![
        Box::new(TopicSource::<ImuSample>::open(node, ipc)?),
        Box::new(TopicSource::<ThrustCommand>::open(node, ipc)?),
        Box::new(TopicSource::<TelemetryMsg>::open(node, ipc)?),
        Box::new(TopicSource::<ModelMsg>::open(node, ipc)?),
        Box::new(TopicSource::<StatusMsg>::open(node, ipc)?),
        Box::new(TopicSource::<ReconfigEvent>::open(node, ipc)?),
        Box::new(TopicSource::<Setpoint>::open(node, ipc)?),
        Box::new(TopicSource::<DriverStatusMsg>::open(node, ipc)?),
        Box::new(TopicSource::<DynamicsMsg>::open(node, ipc)?),
        Box::new(TopicSource::<DvlSample>::open(node, ipc)?),
        Box::new(TopicSource::<TruthMsg>::open(node, ipc)?),
        Box::new(TopicSource::<VehicleStateMsg>::open(node, ipc)?),
        // What `thrusterd replay` needs besides the IMU stream (docs/recording.md).
        Box::new(TopicSource::<InputMsg>::open(node, ipc)?),
        Box::new(TopicSource::<ConfigMsg>::open(node, ipc)?),
    ])
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
    fn schema_names_come_from_the_type() {
        assert_eq!(schema_name::<ImuSample>(), "thrusterd.ImuSample");
    }
}
