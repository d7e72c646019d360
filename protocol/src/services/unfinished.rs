//! Nodes whose process was killed while iceoryx2 was still creating them, and the global
//! configuration iceoryx2 falls back to when it cleans up a node it cannot read.
//!
//! Found by killing `thrusterctl watch` 2-9 ms after its start, 24 times (a probe; the shipped
//! test is `tests/tests/thrusterctl.rs`,
//! `clients_killed_while_joining_leave_only_what_the_daemon_reports`): 9 left files the
//! daemon's reaper never removed, in two kinds of state.
//! - **Unfinished**: killed before or inside iceoryx2's liveness guard
//!   (`ProcessGuard::create`): its three files still have their initial permissions (owner
//!   write only) and an empty context, so iceoryx2 takes the node for one that is starting,
//!   forever, and lists it as not existing. [`remove_unfinished_nodes`] removes such a node
//!   once its files are older than a starting node could be and no process holds its lock,
//!   and a folder of details with no guard at all (killed before the guard) likewise. Neither
//!   has a service or port yet (the guard comes before them), so their files are all there is.
//! - **Without details**: a dead node whose details file is gone, its service and port tags
//!   left. iceoryx2 then cleans it with its *global* configuration (another root and prefix),
//!   finds nothing there, and says it was already cleaned: the reaper reported "removed" every
//!   2 s, and the files stayed. [`IpcConfig::install_as_global`] makes the global
//!   configuration this namespace's, so that fallback looks in the right place (where
//!   iceoryx2 then fails on a node killed while it joined a service, and says so).

use std::fs;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::time::{Duration, SystemTime};

use iceoryx2::config::Config;
use iceoryx2::prelude::{FilePath, SemanticString};

use super::IpcConfig;

/// How old an unfinished node's files must be before they are taken for a dead process's: a
/// live one finishes its guard within microseconds, so this only spares a process stopped
/// (SIGSTOP, a debugger) right there.
pub const UNFINISHED_AFTER: Duration = Duration::from_secs(10);

/// The permissions iceoryx2 creates a liveness guard's files with, before its final ones
/// (`iceoryx2-bb-posix` `process_state::INIT_PERMISSION`, owner write).
const INIT_MODE: u32 = 0o200;

impl IpcConfig {
    /// Makes this namespace's configuration iceoryx2's global one in this process, which
    /// iceoryx2 uses to clean up a dead node whose details it cannot read (see the module's
    /// doc). Call it before anything of iceoryx2 runs: the global configuration is set once
    /// per process. False when another was set first (the fallback then looks elsewhere).
    pub fn install_as_global(&self) -> bool {
        let Ok(text) = toml::to_string(self.iceoryx_config()) else {
            return false;
        };
        let nanos = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let path = std::env::temp_dir().join(format!(
            "thrusterd-iceoryx2-{}-{nanos}.toml",
            std::process::id()
        ));
        if fs::write(&path, text).is_err() {
            return false;
        }
        let set = FilePath::new(path.as_os_str().as_bytes())
            .ok()
            .and_then(|p| Config::setup_global_config_from_file(&p).ok())
            .is_some_and(|c| c == self.iceoryx_config());
        let _ = fs::remove_file(&path);
        set
    }
}

/// Removes the files of nodes of `ipc` left unfinished (see the module's doc) at least
/// `older_than` ago; returns how many nodes. A node whose files this process may not open,
/// whose lock is held, or whose folder holds anything but its details is left alone.
pub fn remove_unfinished_nodes(ipc: &IpcConfig, older_than: Duration) -> usize {
    let nodes = ipc.root_dir().join("nodes");
    let Ok(entries) = fs::read_dir(&nodes) else {
        return 0;
    };
    let prefix = ipc.prefix();
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name();
        // A node killed before its guard existed: its folder of details and nothing else.
        if let Some(id) = name
            .to_str()
            .filter(|n| n.bytes().all(|b| b.is_ascii_digit()))
        {
            let monitor = nodes.join(format!("{prefix}{id}.node_monitor"));
            let dir = entry.path();
            if fs::symlink_metadata(&monitor).is_err()
                && older(&dir, older_than)
                && only_details(&dir, &prefix)
                && fs::remove_dir_all(&dir).is_ok()
            {
                removed += 1;
            }
            continue;
        }
        let Some(id) = name
            .to_str()
            .and_then(|n| n.strip_prefix(&prefix))
            .and_then(|n| n.strip_suffix(".node_monitor"))
        else {
            continue;
        };
        let monitor = entry.path();
        let context = nodes.join(format!("{prefix}{id}.node_monitor_context"));
        let owner = nodes.join(format!("{prefix}{id}.node_monitor_owner_lock"));
        let details_dir = nodes.join(id);
        if unfinished(&monitor, &context, older_than)
            && !locked(&monitor)
            && only_details(&details_dir, &prefix)
        {
            // The guard's files last: until they go, the node is still found unfinished.
            let _ = fs::remove_dir_all(&details_dir);
            let _ = fs::remove_file(&owner);
            let _ = fs::remove_file(&context);
            if fs::remove_file(&monitor).is_ok() {
                removed += 1;
            }
        }
    }
    removed
}

/// The guard's state and context files still have their initial permissions, and are older
/// than `older_than`.
fn unfinished(monitor: &Path, context: &Path, older_than: Duration) -> bool {
    [monitor, context].iter().all(|p| {
        fs::metadata(p).is_ok_and(|m| m.permissions().mode() & 0o777 == INIT_MODE)
            && older(p, older_than)
    })
}

/// `path` was last changed at least `older_than` ago.
fn older(path: &Path, older_than: Duration) -> bool {
    fs::symlink_metadata(path)
        .and_then(|m| m.modified())
        .is_ok_and(|t| {
            SystemTime::now()
                .duration_since(t)
                .is_ok_and(|age| age >= older_than)
        })
}

/// Whether some process holds a lock on `path` (the guard's state file is write-locked for
/// its process's life). Not openable counts as locked: what cannot be checked is left.
fn locked(path: &Path) -> bool {
    use std::os::fd::AsRawFd;
    let Ok(file) = fs::OpenOptions::new().write(true).open(path) else {
        return true;
    };
    // SAFETY: a plain F_GETLK on an open descriptor with a zeroed flock describing the whole
    // file; the kernel only writes into `lock`.
    let mut lock: libc::flock = unsafe { std::mem::zeroed() };
    lock.l_type = libc::F_WRLCK as libc::c_short;
    lock.l_whence = libc::SEEK_SET as libc::c_short;
    let r = unsafe { libc::fcntl(file.as_raw_fd(), libc::F_GETLK, &mut lock) };
    // This process holds no lock on another node's guard, so closing `file` releases none.
    r != 0 || lock.l_type != libc::F_UNLCK as libc::c_short
}

/// `dir` holds nothing but the node's details file (or does not exist).
fn only_details(dir: &Path, prefix: &str) -> bool {
    match fs::read_dir(dir) {
        Err(e) => e.kind() == std::io::ErrorKind::NotFound,
        Ok(entries) => entries
            .flatten()
            .all(|e| e.file_name().to_str() == Some(&format!("{prefix}node.details"))),
    }
}
