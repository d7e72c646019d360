use std::fmt::Debug;

use iceoryx2::prelude::ZeroCopySend;

use crate::messages::*;

/// Most publishers per pub/sub service: the owner plus operators and tests injecting
/// messages (iceoryx2's default of 2 is too few).
pub const MAX_PUBLISHERS: usize = 8;
/// Most subscribers per pub/sub service.
pub const MAX_SUBSCRIBERS: usize = 16;
/// Most nodes (processes, roughly) that may open one service.
pub const MAX_NODES: usize = 32;
/// Most notifiers and listeners per event service (one per publisher / subscriber).
pub const MAX_EVENT_PORTS: usize = MAX_SUBSCRIBERS;
/// Appended to a topic's service name to name its paired event service.
pub const EVENT_SUFFIX: &str = "/event";

/// The pub/sub topics of the protocol. Each has a paired event service
/// `<ns>/<leaf>/event` that is notified after every message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Topic {
    /// [`ImuSample`], driver -> daemon.
    Imu,
    /// [`ThrustCommand`], daemon -> driver.
    Thrust,
    /// [`ReconfigEvent`], driver or operator -> daemon.
    Reconfig,
    /// [`ModelMsg`], daemon -> all, history 1.
    Model,
    /// [`StatusMsg`], daemon -> all, history 1.
    Status,
    /// [`TruthMsg`], simulator -> anyone, history 1.
    Truth,
    /// [`Setpoint`], operator -> daemon, history 1.
    Setpoint,
    /// [`VehicleStateMsg`], simulator -> anyone: the true vehicle state per sample.
    Vehicle,
    /// [`DriverStatusMsg`], driver -> daemon and operators, history 1.
    DriverStatus,
    /// [`DynamicsMsg`], daemon -> all, history 1: the dynamic coefficients of the model.
    Dynamics,
    /// [`DvlSample`], driver -> daemon (optional: only vehicles with a DVL).
    Dvl,
    /// [`TelemetryMsg`], daemon -> anyone: what the daemon does, every `telemetry.every_n`-th
    /// IMU sample.
    Telemetry,
    /// [`InputMsg`], daemon -> anyone: every input the state machine took besides the IMU
    /// samples, placed by IMU sample count (the input journal a replay needs).
    Input,
    /// [`ConfigMsg`], daemon -> anyone, history 1: the daemon's effective configuration.
    Config,
    /// [`CheckpointMsg`], daemon -> anyone: the state machine's state in parts, at each
    /// model swap and periodically, where a late recording's replay starts.
    Checkpoint,
}

/// Quality-of-service settings of a topic. Every process opens services with the same
/// settings; iceoryx2 checks them against the existing service (as minimum
/// requirements), so a process from an incompatible build fails to open instead of
/// misbehaving.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicQos {
    /// Samples a late-joining subscriber receives on connection (0 or 1).
    pub history: usize,
    /// Largest subscriber buffer the service supports, samples.
    pub max_buffer: usize,
    /// Buffer an [`super::Inbox`] requests, samples. With safe overflow the oldest
    /// sample is dropped when it is full; publishers never block.
    pub default_buffer: usize,
}

impl Topic {
    /// Every topic.
    pub const ALL: [Topic; 15] = [
        Topic::Imu,
        Topic::Thrust,
        Topic::Reconfig,
        Topic::Model,
        Topic::Status,
        Topic::Truth,
        Topic::Setpoint,
        Topic::Vehicle,
        Topic::DriverStatus,
        Topic::Dynamics,
        Topic::Dvl,
        Topic::Telemetry,
        Topic::Input,
        Topic::Config,
        Topic::Checkpoint,
    ];

    /// Service name below the namespace, e.g. `imu`.
    pub const fn leaf(self) -> &'static str {
        match self {
            Topic::Imu => "imu",
            Topic::Thrust => "thrust",
            Topic::Reconfig => "reconfig",
            Topic::Model => "model",
            Topic::Status => "status",
            Topic::Truth => "truth",
            Topic::Setpoint => "setpoint",
            Topic::Vehicle => "vehicle",
            Topic::DriverStatus => "driver_status",
            Topic::Dynamics => "dynamics",
            Topic::Dvl => "dvl",
            Topic::Telemetry => "telemetry",
            Topic::Input => "input",
            Topic::Config => "config",
            Topic::Checkpoint => "checkpoint",
        }
    }

    /// The topic's QoS.
    pub const fn qos(self) -> TopicQos {
        match self {
            // Streams: every sample matters, buffer 128 ms at 1 kHz so a reader descheduled
            // for a while, or a real-time driver catching up after a stall with a burst of
            // overdue samples, loses nothing (16 lost 2 % of the samples in a 12-minute soak
            // on a loaded VM); no history (stale samples are useless).
            Topic::Imu | Topic::Thrust | Topic::Vehicle => TopicQos {
                history: 0,
                max_buffer: 128,
                default_buffer: 128,
            },
            // A stream a recorder must log without loss even when the daemon publishes it at
            // the IMU rate (`every_n = 1` at 1 kHz): buffered like the sensor streams. No
            // history: a stale sample is no news; the next comes within a few ms. Readers
            // that only show the newest (`thrusterctl watch`) ask for a buffer of one.
            Topic::Telemetry => TopicQos {
                history: 0,
                max_buffer: 128,
                default_buffer: 128,
            },
            // A slow stream (a DVL reports at a few Hz): a few buffered, no history.
            Topic::Dvl => TopicQos {
                history: 0,
                max_buffer: 16,
                default_buffer: 8,
            },
            // Discrete events: keep a few, but do not replay old ones to a new reader.
            Topic::Reconfig => TopicQos {
                history: 0,
                max_buffer: 16,
                default_buffer: 8,
            },
            // The input journal: a replay needs every entry, and a solve result is journaled
            // for every job, several per sample in a burst; room for the recorder (which asks
            // for the maximum) to be descheduled for a while. No history: a journal joined
            // late cannot be replayed anyway (the machine's state at the join is unknown).
            Topic::Input => TopicQos {
                history: 0,
                max_buffer: 64,
                default_buffer: 8,
            },
            // State: a late joiner gets the latest value; readers want the newest. The
            // recorder asks for the maximum: 16 hold 1.6 s of driver status at 10 Hz (4 lost
            // one in a paced demo recording on a loaded 2-core machine).
            Topic::Model
            | Topic::Status
            | Topic::Truth
            | Topic::Setpoint
            | Topic::DriverStatus
            | Topic::Dynamics => TopicQos {
                history: 1,
                max_buffer: 16,
                default_buffer: 2,
            },
            // Checkpoints: a burst of parts (16 KiB each) every few vehicle seconds; room for a
            // whole one of the largest size (`CHECKPOINT_MAX_PARTS`) while the recorder is
            // descheduled. No history: the next comes within the period, and a reader that
            // joined late needs one taken after it joined (its journal starts there).
            Topic::Checkpoint => TopicQos {
                history: 0,
                max_buffer: 64,
                default_buffer: 8,
            },
            // The configuration: once per daemon start, 16 KiB a message.
            Topic::Config => TopicQos {
                history: 1,
                max_buffer: 4,
                default_buffer: 2,
            },
        }
    }
}

/// A message type bound to its topic, so a port can only carry the right type.
pub trait TopicMessage: ZeroCopySend + Debug + Copy + 'static {
    /// The topic that carries this type.
    const TOPIC: Topic;
}

impl TopicMessage for ImuSample {
    const TOPIC: Topic = Topic::Imu;
}
impl TopicMessage for ThrustCommand {
    const TOPIC: Topic = Topic::Thrust;
}
impl TopicMessage for ReconfigEvent {
    const TOPIC: Topic = Topic::Reconfig;
}
impl TopicMessage for ModelMsg {
    const TOPIC: Topic = Topic::Model;
}
impl TopicMessage for StatusMsg {
    const TOPIC: Topic = Topic::Status;
}
impl TopicMessage for TruthMsg {
    const TOPIC: Topic = Topic::Truth;
}
impl TopicMessage for Setpoint {
    const TOPIC: Topic = Topic::Setpoint;
}
impl TopicMessage for VehicleStateMsg {
    const TOPIC: Topic = Topic::Vehicle;
}
impl TopicMessage for DriverStatusMsg {
    const TOPIC: Topic = Topic::DriverStatus;
}
impl TopicMessage for DynamicsMsg {
    const TOPIC: Topic = Topic::Dynamics;
}
impl TopicMessage for DvlSample {
    const TOPIC: Topic = Topic::Dvl;
}
impl TopicMessage for TelemetryMsg {
    const TOPIC: Topic = Topic::Telemetry;
}
impl TopicMessage for InputMsg {
    const TOPIC: Topic = Topic::Input;
}
impl TopicMessage for ConfigMsg {
    const TOPIC: Topic = Topic::Config;
}
impl TopicMessage for CheckpointMsg {
    const TOPIC: Topic = Topic::Checkpoint;
}
