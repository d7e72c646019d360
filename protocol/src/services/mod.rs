//! iceoryx2 services: names under one namespace, QoS, node creation, typed ports and
//! cleanup.
//!
//! Every process of one vehicle builds the same [`IpcConfig`] from the same namespace and
//! gets the same service names, file prefix and root directory, so processes find each
//! other while other vehicles and tests on the same machine stay isolated.
//!
//! Wake-up: a [`iceoryx2::waitset::WaitSet`] attaches listeners, not subscribers, so every
//! pub/sub service has a paired event service (`<ns>/<topic>/event`). [`Port::send`]
//! publishes and then notifies; an [`Inbox`] holds the subscriber and the listener to
//! attach. Request/response has no wake-up of its own either: [`ControlClient`] notifies
//! `<ns>/control/event` after each request.
//!
//! Threads: everything here uses `ipc::Service`, whose ports are not `Send`. Create
//! nodes and ports on the thread that uses them and keep them there (the estimator
//! thread or the control loop), or talk to that thread through channels.
//!
//! Signals: nodes and wait sets are created with iceoryx2's signal handling disabled,
//! because its handler would replace the process's own (ctrlc) SIGINT/SIGTERM handlers.

mod access;
mod cleanup;
mod config;
mod control;
mod error;
mod ports;
mod retry;
mod topics;
mod unfinished;

pub use access::{adopt_root_group, check_access, owns_root, root_group};
pub use cleanup::{
    cleanup_dead_nodes, namespace_files, purge_namespace, tidy_residue, NamespaceGuard, NodeCensus,
    PurgeReport, TidyOnDrop,
};
pub use config::{IpcConfig, CONNECTION_TIMEOUT, DEFAULT_ROOT_BASE, MAX_NAMESPACE_LEN, SHM_DIR};
pub use control::{ControlClient, ControlServer, Reply, ServeCount, CONTROL_LEAF};
pub use error::{AccessDenied, IpcError};
pub use ports::{create_waitset, open_event, open_topic, Inbox, Port, Reader};
pub use topics::{
    Topic, TopicMessage, TopicQos, EVENT_SUFFIX, MAX_NODES, MAX_PUBLISHERS, MAX_SUBSCRIBERS,
};
pub use unfinished::{remove_unfinished_nodes, UNFINISHED_AFTER};

/// The iceoryx2 service variant used everywhere: inter-process, ports not `Send`.
pub type Ipc = iceoryx2::service::ipc::Service;

/// A node of [`Ipc`] services.
pub type IpcNode = iceoryx2::node::Node<Ipc>;
