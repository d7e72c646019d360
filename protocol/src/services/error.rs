use std::path::PathBuf;
use std::time::Duration;

use crate::validate::RejectReason;

/// Failures of the IPC layer.
#[derive(Debug, thiserror::Error)]
pub enum IpcError {
    /// The namespace string is not usable.
    #[error("invalid namespace {namespace:?}: {reason}")]
    InvalidNamespace {
        /// The rejected namespace.
        namespace: String,
        /// Why.
        reason: &'static str,
    },
    /// A path iceoryx2 would create is too long (unix socket paths are limited to 107
    /// bytes).
    #[error("iceoryx2 paths under {root} would reach {len} bytes, more than {max}")]
    PathTooLong {
        /// The root directory.
        root: String,
        /// Longest path iceoryx2 may create there.
        len: usize,
        /// Limit.
        max: usize,
    },
    /// An iceoryx2 call failed.
    #[error("{what} failed for \"{name}\": {source}")]
    Iceoryx {
        /// The operation, e.g. "open or create publish-subscribe service".
        what: &'static str,
        /// The service, node or path concerned.
        name: String,
        /// The iceoryx2 error.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A control request found no server (the daemon is not running in this namespace).
    #[error("no server is connected to \"{service}\"")]
    NoServer {
        /// The control service name.
        service: String,
    },
    /// No response arrived in time.
    #[error("no response on \"{service}\" within {timeout:?}")]
    Timeout {
        /// The control service name.
        service: String,
        /// How long we waited.
        timeout: Duration,
    },
    /// A response failed validation or answered another request.
    #[error("invalid response on \"{service}\": {reason}")]
    InvalidResponse {
        /// The control service name.
        service: String,
        /// What was wrong.
        reason: RejectReason,
    },
    /// The response's sequence number does not match the request's.
    #[error("response on \"{service}\" answers request {got}, expected {expected}")]
    ResponseMismatch {
        /// The control service name.
        service: String,
        /// Request seq that was sent.
        expected: u64,
        /// Seq in the response.
        got: u64,
    },
    /// Purging a namespace that live processes still use.
    #[error("namespace \"{namespace}\" is in use by {alive} live node(s)")]
    NamespaceInUse {
        /// The namespace.
        namespace: String,
        /// Live nodes found.
        alive: usize,
    },
    /// This user may not use the namespace's files (see [`super::check_access`]).
    #[error("{0}")]
    AccessDenied(Box<AccessDenied>),
    /// A file system operation failed.
    #[error("{op} {path}: {source}")]
    Io {
        /// The operation, e.g. "remove".
        op: &'static str,
        /// The path concerned.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// The refusal of [`super::check_access`], with what the operator needs to fix it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AccessDenied {
    /// The directory the user may not use.
    pub path: PathBuf,
    /// The user asking, e.g. "root (uid 0)".
    pub user: String,
    /// Owner of `path`, e.g. "thrusterd".
    pub owner: String,
    /// Group of `path`, e.g. "thrusterd".
    pub group: String,
    /// Permission bits of `path` (with setgid/sticky), e.g. 0o2770.
    pub mode: u32,
}

impl std::fmt::Display for AccessDenied {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "user {} may not use the iceoryx2 files at {} ({}:{}, mode {:04o}): files it \
             made there could not be opened or removed by the daemon. Operate as a member of \
             group {} (sudo usermod -aG {} USER, then log in again) or as user {} \
             (sudo -u {} thrusterctl ...)",
            self.user,
            self.path.display(),
            self.owner,
            self.group,
            self.mode,
            self.group,
            self.group,
            self.owner,
            self.owner,
        )
    }
}

/// `map_err` adapter wrapping an iceoryx2 error with context.
pub(crate) fn ice<'a, E>(what: &'static str, name: &'a str) -> impl FnOnce(E) -> IpcError + 'a
where
    E: std::error::Error + Send + Sync + 'static,
{
    move |e| IpcError::Iceoryx {
        what,
        name: name.to_string(),
        source: Box::new(e),
    }
}
