use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

use iceoryx2::config::Config;
use iceoryx2::prelude::{FileName, NodeBuilder, NodeName, SemanticString, SignalHandlingMode};

use super::error::{ice, IpcError};
use super::retry::retry_creation;
use super::{Ipc, IpcNode};

/// Where namespaces put their iceoryx2 files (static service configs, node monitors,
/// unix sockets) unless told otherwise: `<base>/<namespace>/`. Beside iceoryx2's own
/// default root `/tmp/iceoryx2/`. Under systemd, `PrivateTmp=yes` gives each unit its
/// own /tmp: use a shared base such as `/run/thrusterd` there.
pub const DEFAULT_ROOT_BASE: &str = "/tmp/iceoryx2/thr";

/// Directory of POSIX shared memory on Linux, where iceoryx2 puts data segments,
/// dynamic service state and a per-prefix global management segment.
pub const SHM_DIR: &str = "/dev/shm";

/// How long iceoryx2 waits for another process's shared resource (a connection or data
/// segment, a service being created) to become usable: its `global.creation_timeout`.
///
/// iceoryx2's default is 1 s, and it is spent inside whatever port call meets the resource:
/// a client whose files the daemon cannot open (another user's mode-0600 files read as "not
/// initialised yet") cost the daemon's control loop 1 s per connection, long enough for its
/// IMU deadline and systemd's watchdog. A healthy process finishes a resource in well under
/// a millisecond, so this bounds a bad client to a short stall per new port it opens. A
/// connection that does give up is retried when the port list changes next; service
/// creation is retried by [`super::retry`] anyway.
pub const CONNECTION_TIMEOUT: std::time::Duration = std::time::Duration::from_millis(20);

/// Longest namespace, bytes. Kept short because iceoryx2 binds unix datagram sockets at
/// `<root><prefix><39-digit id>.event`, and a socket path is limited to 107 bytes.
pub const MAX_NAMESPACE_LEN: usize = 16;

/// `sun_path` is 108 bytes including the terminating NUL.
const MAX_SOCKET_PATH: usize = 107;
/// Longest file name iceoryx2 appends to the prefix in the root directory: a u128
/// port id in decimal (39 digits) and ".event".
const LONGEST_ROOT_FILE_TAIL: usize = 39 + ".event".len();

/// IPC settings of one namespace (one vehicle, or one test).
///
/// - Service names: `<namespace>/<topic>`, e.g. `veh1/imu`, `veh1/imu/event`.
/// - iceoryx2 `global.prefix`: `thr_<namespace>_`, so every file of the namespace in
///   /dev/shm starts with it.
/// - iceoryx2 root path: `<root base>/<namespace>/` (default base
///   [`DEFAULT_ROOT_BASE`]).
///
/// A namespace is 1 to [`MAX_NAMESPACE_LEN`] ASCII letters, digits or `-`, starting with
/// a letter or digit. `_` is excluded so that no namespace's prefix is a prefix of
/// another's (`thr_a_` vs `thr_a-b_`), which keeps prefix-based cleanup exact.
#[derive(Debug, Clone)]
pub struct IpcConfig {
    namespace: String,
    root_base: PathBuf,
    iceoryx: Config,
}

impl IpcConfig {
    /// Settings for `namespace` under [`DEFAULT_ROOT_BASE`].
    pub fn new(namespace: &str) -> Result<Self, IpcError> {
        Self::with_root_base(namespace, DEFAULT_ROOT_BASE)
    }

    /// Settings for `namespace` under another root base directory (absolute path).
    pub fn with_root_base(namespace: &str, root_base: impl AsRef<Path>) -> Result<Self, IpcError> {
        check_namespace(namespace)?;
        let root_base = root_base.as_ref().to_path_buf();
        if !root_base.is_absolute() {
            return Err(IpcError::InvalidNamespace {
                namespace: namespace.to_string(),
                reason: "the root base directory must be an absolute path",
            });
        }
        let mut cfg = Self {
            namespace: namespace.to_string(),
            root_base,
            iceoryx: Config::default(),
        };
        let root = cfg.root_dir();
        let root_str = format!("{}/", root.display());
        let longest = root_str.len() + cfg.prefix().len() + LONGEST_ROOT_FILE_TAIL;
        if longest > MAX_SOCKET_PATH {
            return Err(IpcError::PathTooLong {
                root: root_str,
                len: longest,
                max: MAX_SOCKET_PATH,
            });
        }
        let prefix = cfg.prefix();
        cfg.iceoryx.global.prefix =
            FileName::new(prefix.as_bytes()).map_err(ice("set iceoryx2 prefix", &prefix))?;
        let root_path = iceoryx2::prelude::Path::new(root_str.as_bytes())
            .map_err(ice("set iceoryx2 root path", &root_str))?;
        cfg.iceoryx.global.set_root_path(&root_path);
        cfg.iceoryx.global.creation_timeout = CONNECTION_TIMEOUT;
        Ok(cfg)
    }

    /// A fresh namespace for one test: `<tag><pid><counter><time>`, unique across
    /// concurrent test processes and reruns. `tag` is cut to 4 characters.
    pub fn unique_for_test(tag: &str) -> Result<Self, IpcError> {
        static COUNTER: AtomicU32 = AtomicU32::new(0);
        let tag: String = tag
            .chars()
            .filter(|c| c.is_ascii_alphanumeric())
            .take(4)
            .collect();
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.subsec_nanos())
            .unwrap_or(0);
        let ns = format!(
            "{}{}-{}{}",
            if tag.is_empty() { "t" } else { &tag },
            base36(u64::from(std::process::id())),
            base36(u64::from(n % (36 * 36 * 36))),
            // Three base-36 digits of the clock guard against pid reuse across runs.
            &base36(u64::from(nanos) % (36 * 36 * 36) + 36 * 36 * 36)[1..],
        );
        Self::new(&ns)
    }

    /// The namespace.
    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    /// The iceoryx2 file prefix, `thr_<namespace>_`.
    pub fn prefix(&self) -> String {
        format!("thr_{}_", self.namespace)
    }

    /// The base directory holding the namespaces' root directories (e.g. `/run/thrusterd`).
    pub fn root_base(&self) -> &Path {
        &self.root_base
    }

    /// The same namespace for a process that must not remove dead nodes' resources: an
    /// operator of another user than the daemon's. In the sticky /dev/shm only a file's owner
    /// may remove it, so an operator that starts removing a crashed daemon's service leaves
    /// it marked for destruction, and the restarted daemon can never open it again (seen
    /// under systemd: kill -9, then every restart failed with IsMarkedForDestruction).
    pub fn without_dead_node_cleanup(mut self) -> Self {
        let node = &mut self.iceoryx.global.node;
        node.cleanup_dead_nodes_on_creation = false;
        node.cleanup_dead_nodes_on_destruction = false;
        self.iceoryx.global.service.cleanup_dead_nodes_on_open = false;
        self
    }

    /// The iceoryx2 root directory of this namespace, `<root base>/<namespace>`.
    pub fn root_dir(&self) -> PathBuf {
        self.root_base.join(&self.namespace)
    }

    /// Full service name for a leaf such as `imu` or `imu/event`: `<namespace>/<leaf>`.
    pub fn service_name(&self, leaf: &str) -> String {
        format!("{}/{}", self.namespace, leaf)
    }

    /// The iceoryx2 configuration (prefix and root path set). Pass it to every iceoryx2
    /// call that takes a config, e.g. `Node::list`.
    pub fn iceoryx_config(&self) -> &Config {
        &self.iceoryx
    }

    /// Creates a node in this namespace. `name` is informational (shown by node
    /// listings), e.g. "thrusterd" or "thruster-sim". Signal handling is disabled so the
    /// process keeps its own SIGINT/SIGTERM handlers. Creating a node also removes the
    /// stale resources of dead nodes of this namespace (iceoryx2 default).
    pub fn create_node(&self, name: &str) -> Result<IpcNode, IpcError> {
        let node_name = NodeName::new(name).map_err(ice("make node name", name))?;
        super::access::adopt_root_group(self);
        retry_creation(|| {
            NodeBuilder::new()
                .name(&node_name)
                .config(&self.iceoryx)
                .signal_handling_mode(SignalHandlingMode::Disabled)
                .create::<Ipc>()
        })
        .map_err(ice("create node", name))
    }
}

fn check_namespace(ns: &str) -> Result<(), IpcError> {
    let reason = if ns.is_empty() {
        Some("it is empty")
    } else if ns.len() > MAX_NAMESPACE_LEN {
        Some("it is longer than 16 bytes")
    } else if !ns.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-') {
        Some("only ASCII letters, digits and '-' are allowed")
    } else if !ns.as_bytes()[0].is_ascii_alphanumeric() {
        Some("it must start with a letter or digit")
    } else {
        None
    };
    match reason {
        Some(reason) => Err(IpcError::InvalidNamespace {
            namespace: ns.to_string(),
            reason,
        }),
        None => Ok(()),
    }
}

fn base36(mut v: u64) -> String {
    const DIGITS: &[u8; 36] = b"0123456789abcdefghijklmnopqrstuvwxyz";
    let mut out = Vec::new();
    loop {
        out.push(DIGITS[(v % 36) as usize]);
        v /= 36;
        if v == 0 {
            break;
        }
    }
    out.reverse();
    String::from_utf8(out).expect("ASCII digits")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn namespace_rules() {
        assert!(IpcConfig::new("veh1").is_ok());
        assert!(IpcConfig::new("a-b-c").is_ok());
        assert!(IpcConfig::new("0123456789abcdef").is_ok());
        for bad in ["", "a_b", "a/b", "-ab", "a b", "ä", "0123456789abcdefg"] {
            assert!(
                matches!(IpcConfig::new(bad), Err(IpcError::InvalidNamespace { .. })),
                "{bad:?} accepted"
            );
        }
    }

    #[test]
    fn names_prefix_and_root() {
        let c = IpcConfig::new("veh1").unwrap();
        assert_eq!(c.service_name("imu/event"), "veh1/imu/event");
        assert_eq!(c.prefix(), "thr_veh1_");
        assert_eq!(c.root_dir(), PathBuf::from("/tmp/iceoryx2/thr/veh1"));
        assert_eq!(c.iceoryx_config().global.prefix.as_str(), "thr_veh1_");
        assert_eq!(
            c.iceoryx_config().global.creation_timeout,
            CONNECTION_TIMEOUT
        );
        assert_eq!(
            c.iceoryx_config().global.root_path().to_string(),
            "/tmp/iceoryx2/thr/veh1/"
        );
    }

    #[test]
    fn long_root_is_rejected() {
        let base = format!("/tmp/{}", "x".repeat(60));
        assert!(matches!(
            IpcConfig::with_root_base("veh1", base),
            Err(IpcError::PathTooLong { .. })
        ));
        assert!(IpcConfig::with_root_base("veh1", "relative/dir").is_err());
    }

    #[test]
    fn unique_namespaces_are_valid_and_distinct() {
        let a = IpcConfig::unique_for_test("pingpong").unwrap();
        let b = IpcConfig::unique_for_test("pingpong").unwrap();
        assert_ne!(a.namespace(), b.namespace());
        assert!(a.namespace().starts_with("ping"));
        assert!(a.namespace().len() <= MAX_NAMESPACE_LEN);
    }
}
