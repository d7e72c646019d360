use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::{
    FileDescriptor, FileDescriptorBased, ServiceName, SignalHandlingMode, WaitSet, WaitSetBuilder,
};
use iceoryx2::service::port_factory::event::PortFactory as EventFactory;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use iceoryx2::service::port_factory::PortFactory as _;

use super::error::{ice, IpcError};
use super::retry::retry_creation;
use super::topics::{
    TopicMessage, EVENT_SUFFIX, MAX_EVENT_PORTS, MAX_NODES, MAX_PUBLISHERS, MAX_SUBSCRIBERS,
};
use super::{Ipc, IpcConfig, IpcNode};

/// Opens (or creates) the pub/sub service of `T`'s topic with the protocol's QoS and
/// returns its full name and port factory, for callers that need raw iceoryx2 ports
/// (e.g. custom subscriber settings). [`Port`] and [`Inbox`] cover the common cases.
pub fn open_topic<T: TopicMessage>(
    node: &IpcNode,
    ipc: &IpcConfig,
) -> Result<(String, PubSubFactory<Ipc, T, ()>), IpcError> {
    let name = ipc.service_name(T::TOPIC.leaf());
    let qos = T::TOPIC.qos();
    let service_name = ServiceName::new(&name).map_err(ice("make service name", &name))?;
    let factory = retry_creation(|| {
        node.service_builder(&service_name)
            .publish_subscribe::<T>()
            // Never block a publisher on a slow reader: a driver must not stall because the
            // daemon does, and vice versa. The oldest sample is dropped instead.
            .enable_safe_overflow(true)
            .history_size(qos.history)
            .subscriber_max_buffer_size(qos.max_buffer)
            .max_publishers(MAX_PUBLISHERS)
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .open_or_create()
    })
    .map_err(ice("open or create publish-subscribe service", &name))?;
    Ok((name, factory))
}

/// Opens (or creates) the event service `<service>/event` paired with the service of
/// full name `service` (e.g. `veh1/imu`).
pub fn open_event(node: &IpcNode, service: &str) -> Result<EventFactory<Ipc>, IpcError> {
    let name = format!("{service}{EVENT_SUFFIX}");
    let service_name = ServiceName::new(&name).map_err(ice("make service name", &name))?;
    retry_creation(|| {
        node.service_builder(&service_name)
            .event()
            .max_notifiers(MAX_EVENT_PORTS)
            .max_listeners(MAX_EVENT_PORTS)
            .max_nodes(MAX_NODES)
            .open_or_create()
    })
    .map_err(ice("open or create event service", &name))
}

/// Creates a wait set with iceoryx2's signal handling disabled (see module docs). Attach
/// [`Inbox::listener`]s to it; `attach_deadline` on the IMU listener is a sensor-dropout
/// watchdog.
pub fn create_waitset() -> Result<WaitSet<Ipc>, IpcError> {
    WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Ipc>()
        .map_err(ice("create wait set", "-"))
}

/// Sending end of a topic: publisher plus notifier of the paired event service. Not
/// `Send`: keep it on the thread that created it.
#[derive(Debug)]
pub struct Port<T: TopicMessage> {
    publisher: Publisher<Ipc, T, ()>,
    notifier: Notifier<Ipc>,
    service: String,
}

impl<T: TopicMessage> Port<T> {
    /// Opens or creates `T`'s topic and its event service and creates the ports.
    pub fn create(node: &IpcNode, ipc: &IpcConfig) -> Result<Self, IpcError> {
        let (service, factory) = open_topic::<T>(node, ipc)?;
        let publisher = factory
            .publisher_builder()
            .create()
            .map_err(ice("create publisher", &service))?;
        let notifier = open_event(node, &service)?
            .notifier_builder()
            .create()
            .map_err(ice("create notifier", &service))?;
        Ok(Self {
            publisher,
            notifier,
            service,
        })
    }

    /// Publishes a copy of `msg`, then wakes listeners. Returns how many subscribers
    /// received it. The notify comes after the publish so a woken reader always finds
    /// the sample.
    pub fn send(&self, msg: &T) -> Result<usize, IpcError> {
        let sample = self
            .publisher
            .loan_uninit()
            .map_err(ice("loan sample", &self.service))?;
        let delivered = sample
            .write_payload(*msg)
            .send()
            .map_err(ice("send sample", &self.service))?;
        self.notifier
            .notify()
            .map_err(ice("notify", &self.service))?;
        Ok(delivered)
    }

    /// Connects subscribers that joined since the last send and hands them the history
    /// (the last model or status). iceoryx2 delivers history only when the publisher
    /// does this (it happens implicitly on every send), so a publisher of rarely changing
    /// state (model) must call it periodically, e.g. once per control tick, or late
    /// joiners wait for the next change.
    pub fn update_connections(&self) -> Result<(), IpcError> {
        self.publisher
            .update_connections()
            .map_err(ice("update connections", &self.service))
    }

    /// Full service name, e.g. `veh1/imu`.
    pub fn service_name(&self) -> &str {
        &self.service
    }

    /// The publisher, for zero-copy loans (`loan_uninit`); remember to notify after send.
    pub fn publisher(&self) -> &Publisher<Ipc, T, ()> {
        &self.publisher
    }

    /// The notifier of the paired event service.
    pub fn notifier(&self) -> &Notifier<Ipc> {
        &self.notifier
    }
}

/// Receiving end of a topic: subscriber plus listener of the paired event service. Not
/// `Send`: keep it on the thread that created it.
///
/// Wake-up loop: when the listener fires (in a wait set or [`Inbox::wait`]), call
/// [`Inbox::drain_events`] first and then [`Inbox::recv`] until `None`; draining events
/// after the samples could swallow the notification of a sample that arrived in
/// between, and not draining them makes a wait set fire again at once (busy loop).
/// Messages are returned unvalidated: validate them (see [`crate::validate`]).
#[derive(Debug)]
pub struct Inbox<T: TopicMessage> {
    reader: Reader<T>,
    listener: Listener<Ipc>,
}

impl<T: TopicMessage> Inbox<T> {
    /// Opens or creates `T`'s topic and its event service with the topic's default
    /// buffer.
    pub fn create(node: &IpcNode, ipc: &IpcConfig) -> Result<Self, IpcError> {
        Self::create_with_buffer(node, ipc, T::TOPIC.qos().default_buffer)
    }

    /// As [`Inbox::create`] with a buffer of `buffer` samples (clamped to
    /// 1..=the topic's maximum); e.g. 1 to always read only the newest status.
    pub fn create_with_buffer(
        node: &IpcNode,
        ipc: &IpcConfig,
        buffer: usize,
    ) -> Result<Self, IpcError> {
        let reader = Reader::create_with_buffer(node, ipc, buffer)?;
        let listener = open_event(node, &reader.service)?
            .listener_builder()
            .create()
            .map_err(ice("create listener", &reader.service))?;
        Ok(Self { reader, listener })
    }

    /// The next buffered message (oldest first), copied out of shared memory so the
    /// sample is released at once; `None` when the buffer is empty.
    pub fn recv(&self) -> Result<Option<T>, IpcError> {
        self.reader.recv()
    }

    /// Drains the buffer and returns the newest message, if any.
    pub fn recv_latest(&self) -> Result<Option<T>, IpcError> {
        let mut latest = None;
        while let Some(msg) = self.recv()? {
            latest = Some(msg);
        }
        Ok(latest)
    }

    /// Consumes pending notifications without blocking; returns how many there were.
    pub fn drain_events(&self) -> Result<u64, IpcError> {
        self.listener
            .try_wait(|_| {})
            .map_err(ice("drain listener", &self.reader.service))
    }

    /// Blocks until notified or `timeout` passes, consuming the notifications; true when
    /// notified. For simple single-input loops; use a wait set for several inputs.
    ///
    /// The timeout is kept to the kernel's high-resolution timers (tens of microseconds),
    /// however short, zero included. Not iceoryx2's `timed_wait`: it blocks in `recvfrom`
    /// under a socket timeout (`SO_RCVTIMEO`), which the kernel counts in scheduler ticks,
    /// so a wait shorter than a tick lasted a tick or two (a 500 us wait: 8 ms on the
    /// development VM). A real-time simulator pacing 1 kHz on it overslept each deadline by
    /// ~7 ms and then published the overdue samples in bursts of eight: the daemon answered
    /// eight samples at once, and seven of its eight commands never reached the plant (see
    /// docs/experiments.md, "Soak through the processes").
    pub fn wait(&self, timeout: Duration) -> Result<bool, IpcError> {
        let drain = || {
            self.listener
                .try_wait(|_| {})
                .map_err(ice("wait on listener", &self.reader.service))
        };
        // A notification already pending (iceoryx2 marks the listener notified and then
        // skips the notifier's syscall, so there may be nothing to poll on): take it now.
        // Draining also re-arms the notifiers, so the next notification writes to the socket.
        if drain()? > 0 {
            return Ok(true);
        }
        if timeout.is_zero() {
            return Ok(false);
        }
        if !poll_readable(self.listener.file_descriptor(), timeout) {
            return Ok(false);
        }
        Ok(drain()? > 0)
    }

    /// Full service name, e.g. `veh1/imu`.
    pub fn service_name(&self) -> &str {
        &self.reader.service
    }

    /// How many publishers the topic has now (see [`Reader::publishers`]).
    pub fn publishers(&self) -> usize {
        self.reader.publishers()
    }

    /// The listener to attach to a wait set.
    pub fn listener(&self) -> &Listener<Ipc> {
        &self.listener
    }

    /// Replaces the listener with a new one on the same event service and returns the old
    /// one (detach it from any wait set first). Every notifier connects to the new listener
    /// on its next notification, as to any listener that joins: a notifier whose connection
    /// to the old one was lost (iceoryx2 drops a connection whose send failed and re-creates
    /// connections only when the service's listeners change) is reached again this way.
    pub fn replace_listener(&mut self, node: &IpcNode) -> Result<Listener<Ipc>, IpcError> {
        let listener = open_event(node, &self.reader.service)?
            .listener_builder()
            .create()
            .map_err(ice("create listener", &self.reader.service))?;
        Ok(std::mem::replace(&mut self.listener, listener))
    }

    /// The subscriber, for zero-copy reads of large messages.
    pub fn subscriber(&self) -> &Subscriber<Ipc, T, ()> {
        &self.reader.subscriber
    }
}

/// Receiving end of a topic without a listener: for a reader that polls on its own clock
/// (the recorder, the bridge). Publishers notify only the listeners of their event service,
/// so a `Reader` costs the publisher's path nothing beyond the sample delivery: no
/// notification is sent to it and no wake-up of its process competes with the daemon for a
/// core at the moment a sample arrives. Poll it more often than its buffer fills (128
/// samples at 1 kHz: 128 ms). Not `Send`.
#[derive(Debug)]
pub struct Reader<T: TopicMessage> {
    subscriber: Subscriber<Ipc, T, ()>,
    service: String,
    /// The service's port factory: who else is connected (`publishers`).
    factory: PubSubFactory<Ipc, T, ()>,
}

impl<T: TopicMessage> Reader<T> {
    /// Opens or creates `T`'s topic and subscribes with a buffer of `buffer` samples (clamped
    /// to 1..=the topic's maximum).
    pub fn create_with_buffer(
        node: &IpcNode,
        ipc: &IpcConfig,
        buffer: usize,
    ) -> Result<Self, IpcError> {
        let (service, factory) = open_topic::<T>(node, ipc)?;
        let qos = T::TOPIC.qos();
        let buffer = buffer.clamp(1, qos.max_buffer);
        let subscriber = factory
            .subscriber_builder()
            .buffer_size(buffer)
            .history_request(qos.history.min(buffer))
            .create()
            .map_err(ice("create subscriber", &service))?;
        Ok(Self {
            subscriber,
            service,
            factory,
        })
    }

    /// How many publishers the topic has now (any process, this one included).
    pub fn publishers(&self) -> usize {
        self.factory.dynamic_config().number_of_publishers()
    }

    /// The next buffered message (oldest first), copied out; `None` when the buffer is empty.
    pub fn recv(&self) -> Result<Option<T>, IpcError> {
        let sample = self
            .subscriber
            .receive()
            .map_err(ice("receive", &self.service))?;
        Ok(sample.map(|s| *s.payload()))
    }

    /// Full service name, e.g. `veh1/imu`.
    pub fn service_name(&self) -> &str {
        &self.service
    }
}

/// True when `fd` became readable within `timeout` (`ppoll`: the high-resolution timer,
/// not a socket timeout's scheduler ticks). An interrupted wait (a signal) or a poll error is
/// a wake-up (false): the caller looks at its inbox and stop flag and waits again.
fn poll_readable(fd: &FileDescriptor, timeout: Duration) -> bool {
    // SAFETY: the descriptor is the listener's own and outlives this call; ppoll only
    // reads it.
    let raw = unsafe { fd.native_handle() };
    let mut pfd = libc::pollfd {
        fd: raw,
        events: libc::POLLIN,
        revents: 0,
    };
    let ts = libc::timespec {
        tv_sec: libc::time_t::try_from(timeout.as_secs()).unwrap_or(libc::time_t::MAX),
        // Below 1e9: fits a c_long everywhere.
        tv_nsec: timeout.subsec_nanos() as libc::c_long,
    };
    // SAFETY: one valid pollfd, a valid timespec, no signal mask change.
    let rc = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
    rc > 0 && pfd.revents & libc::POLLIN != 0
}
