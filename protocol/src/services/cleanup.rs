//! Removing what iceoryx2 leaves behind.
//!
//! What iceoryx2 0.10 creates for a namespace (prefix `thr_<ns>_`, root `<base>/<ns>/`):
//! - `/dev/shm/<prefix>*`: dynamic service state (`.dynamic`), publisher data segments
//!   (`.data`), connections (`.connection`), event bitsets (`.event_mgmt`), and one
//!   `<prefix><hash>_node.<version>.global_mgmt` node counter that iceoryx2 never removes.
//! - `<root>/services/<prefix><hash>.service`: static service configuration.
//! - `<root>/nodes/<prefix><id>.node_monitor*` and `<root>/nodes/<id>/`: node liveness
//!   (file locks), node details, service and port tags used for dead-node cleanup.
//! - `<root>/<prefix><id>.event`: the unix datagram socket of each listener.
//!
//! When every port, service and node is dropped normally, only the global_mgmt segment
//! and the empty `nodes/` and `services/` directories remain. A process that dies leaves
//! all of its resources; any new node of the namespace removes them on creation, or call
//! [`cleanup_dead_nodes`]. [`purge_namespace`] removes everything once nothing runs.

use std::fs;
use std::path::{Path, PathBuf};

use iceoryx2::node::{NodeCleanupFailure, NodeState};
use iceoryx2::prelude::{CallbackProgression, Node};

use super::config::SHM_DIR;
use super::error::{ice, IpcError};
use super::{Ipc, IpcConfig};

/// Nodes found in a namespace by [`cleanup_dead_nodes`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NodeCensus {
    /// Nodes whose process is alive.
    pub alive: usize,
    /// Dead nodes whose resources were removed (by us or concurrently by another).
    pub dead_cleaned: usize,
    /// Dead nodes whose resources could not be removed (see the log).
    pub dead_failed: usize,
    /// Nodes we may not inspect (other user) or in an undefined state.
    pub unknown: usize,
    /// Nodes left unfinished by a process killed while iceoryx2 created them, whose files
    /// were removed ([`super::remove_unfinished_nodes`]).
    pub unfinished_removed: usize,
}

/// Outcome of [`purge_namespace`].
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PurgeReport {
    /// Nodes found before purging (none alive, or purging is refused).
    pub census: NodeCensus,
    /// Files and directories removed.
    pub removed: Vec<PathBuf>,
    /// Entries left because they are not iceoryx2's (no namespace prefix), with their
    /// parent directories.
    pub kept: Vec<PathBuf>,
}

/// Lists the namespace's nodes and removes the stale resources of dead ones (processes
/// that crashed or were killed). Safe while other processes run. A child process that
/// exited but was not reaped (`wait()`) still counts as alive.
pub fn cleanup_dead_nodes(ipc: &IpcConfig) -> Result<NodeCensus, IpcError> {
    let mut census = NodeCensus::default();
    if !ipc.root_dir().join("nodes").exists() {
        // Nothing was ever created; listing would only create directories.
        return Ok(census);
    }
    let mut dead = Vec::new();
    Node::<Ipc>::list(ipc.iceoryx_config(), |state| {
        match state {
            NodeState::Alive(_) => census.alive += 1,
            NodeState::Dead(view) => dead.push(view),
            NodeState::Inaccessible(_) | NodeState::Undefined(_) => census.unknown += 1,
        }
        CallbackProgression::Continue
    })
    .map_err(ice("list nodes", ipc.namespace()))?;
    census.unfinished_removed = super::remove_unfinished_nodes(ipc, super::UNFINISHED_AFTER);
    for view in dead {
        match view.try_remove_stale_resources() {
            Ok(()) | Err(NodeCleanupFailure::ResourcesAlreadyCleanedUp) => census.dead_cleaned += 1,
            Err(e) => {
                tracing::warn!(namespace = ipc.namespace(), error = ?e, "could not remove a dead node's resources");
                census.dead_failed += 1;
            }
        }
    }
    Ok(census)
}

/// Every file and directory the namespace has on disk: `/dev/shm/<prefix>*` and
/// everything under the root directory. Empty after [`purge_namespace`]; tests use it to
/// prove nothing is left behind.
pub fn namespace_files(ipc: &IpcConfig) -> Result<Vec<PathBuf>, IpcError> {
    let mut out = shm_files(ipc)?;
    let root = ipc.root_dir();
    if root.symlink_metadata().is_ok() {
        out.push(root.clone());
        walk(&root, &mut out)?;
    }
    out.sort();
    Ok(out)
}

/// Removes everything the namespace has on disk, after cleaning up dead nodes. Refuses
/// with [`IpcError::NamespaceInUse`] while any node of the namespace is alive (including
/// this process's own: drop them first). Only files carrying the namespace prefix are
/// removed, then directories left empty, so a misconfigured root never loses foreign
/// files. Not for use while processes may start in the namespace: removing the
/// global_mgmt segment under a starting node would confuse its id generation.
pub fn purge_namespace(ipc: &IpcConfig) -> Result<PurgeReport, IpcError> {
    let census = cleanup_dead_nodes(ipc)?;
    if census.alive > 0 {
        return Err(IpcError::NamespaceInUse {
            namespace: ipc.namespace().to_string(),
            alive: census.alive,
        });
    }
    let mut report = PurgeReport {
        census,
        ..PurgeReport::default()
    };
    for path in shm_files(ipc)? {
        remove(&path, false)?;
        report.removed.push(path);
    }
    let root = ipc.root_dir();
    if root.symlink_metadata().is_ok() {
        purge_dir(&root, &ipc.prefix(), &mut report)?;
    }
    Ok(report)
}

/// Removes what iceoryx2 0.10 leaves of a namespace after its last process dropped its node
/// normally: the empty `nodes/` and `services/` folders, the root folder, and the
/// world-writable `<prefix>*.global_mgmt` segment in /dev/shm. Only when that residue is all
/// there is and no node is alive; anything else (a live process, a service, a dead node's
/// files) leaves everything as it is. Returns whether it removed the residue.
///
/// Each of our processes calls it as it leaves (through [`TidyOnDrop`]), so a cleanly
/// stopped vehicle leaves nothing. The window in which a process starting at that very
/// moment could have opened the global segment but not yet created its node is a few
/// microseconds; such a process then finds a fresh segment, which iceoryx2 tolerates.
pub fn tidy_residue(ipc: &IpcConfig) -> Result<bool, IpcError> {
    let files = namespace_files(ipc)?;
    let root = ipc.root_dir();
    let residue = |p: &PathBuf| {
        *p == root
            || *p == root.join("nodes")
            || *p == root.join("services")
            || (p.starts_with(SHM_DIR)
                && p.file_name()
                    .is_some_and(|n| n.to_string_lossy().ends_with(".global_mgmt")))
    };
    if files.is_empty() || !files.iter().all(residue) {
        return Ok(false);
    }
    match purge_namespace(ipc) {
        Ok(_) => Ok(true),
        // Someone joined meanwhile: theirs now.
        Err(IpcError::NamespaceInUse { .. }) => Ok(false),
        Err(e) => Err(e),
    }
}

/// Calls [`tidy_residue`] when dropped. Declare it before the process's node (a local
/// declared earlier, or a struct field after the node) so it runs once the node is gone.
/// Failures are ignored: an operator of another user cannot remove the daemon's files, and
/// must not be stopped for it.
#[derive(Debug)]
pub struct TidyOnDrop {
    ipc: IpcConfig,
}

impl TidyOnDrop {
    /// Tidies `ipc` on drop.
    pub fn new(ipc: &IpcConfig) -> Self {
        Self { ipc: ipc.clone() }
    }
}

impl Drop for TidyOnDrop {
    fn drop(&mut self) {
        match tidy_residue(&self.ipc) {
            Ok(true) => tracing::debug!(
                namespace = self.ipc.namespace(),
                "namespace residue removed"
            ),
            Ok(false) => {}
            Err(e) => {
                tracing::debug!(namespace = self.ipc.namespace(), error = %e, "namespace residue not removed")
            }
        }
    }
}

/// Purges a namespace when dropped: create it before any node of the test (so it drops
/// after them) and every test leaves nothing behind, even when it fails.
#[derive(Debug)]
pub struct NamespaceGuard {
    ipc: IpcConfig,
}

impl NamespaceGuard {
    /// Guards `ipc`.
    pub fn new(ipc: IpcConfig) -> Self {
        Self { ipc }
    }

    /// Guards a fresh namespace from [`IpcConfig::unique_for_test`].
    pub fn unique_for_test(tag: &str) -> Result<Self, IpcError> {
        Ok(Self::new(IpcConfig::unique_for_test(tag)?))
    }

    /// The guarded configuration.
    pub fn config(&self) -> &IpcConfig {
        &self.ipc
    }
}

impl std::ops::Deref for NamespaceGuard {
    type Target = IpcConfig;

    fn deref(&self) -> &IpcConfig {
        &self.ipc
    }
}

impl Drop for NamespaceGuard {
    fn drop(&mut self) {
        if let Err(e) = purge_namespace(&self.ipc) {
            tracing::warn!(namespace = self.ipc.namespace(), error = %e, "namespace not purged");
        }
    }
}

fn shm_files(ipc: &IpcConfig) -> Result<Vec<PathBuf>, IpcError> {
    let prefix = ipc.prefix();
    let dir = Path::new(SHM_DIR);
    let entries = fs::read_dir(dir).map_err(io("list", dir))?;
    let mut out = Vec::new();
    for entry in entries {
        let entry = entry.map_err(io("list", dir))?;
        if entry.file_name().to_string_lossy().starts_with(&prefix) {
            out.push(entry.path());
        }
    }
    Ok(out)
}

/// Every path below `dir`. Processes may be creating and removing files meanwhile (the
/// daemon's reaper removes a dead client's while a test lists them): an entry that is gone
/// by the time it is looked at is not listed, rather than failing the whole listing (CI saw
/// `stat ... .event: No such file or directory` once).
fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> Result<(), IpcError> {
    let gone = |e: &std::io::Error| e.kind() == std::io::ErrorKind::NotFound;
    let entries = match fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) if gone(&e) => return Ok(()),
        Err(e) => return Err(io("list", dir)(e)),
    };
    for entry in entries {
        let entry = match entry {
            Ok(entry) => entry,
            Err(e) if gone(&e) => continue,
            Err(e) => return Err(io("list", dir)(e)),
        };
        let path = entry.path();
        // The kind from the directory listing itself: no second look that could race.
        let kind = match entry.file_type() {
            Ok(kind) => kind,
            Err(e) if gone(&e) => continue,
            Err(e) => return Err(io("stat", &path)(e)),
        };
        out.push(path.clone());
        if kind.is_dir() {
            walk(&path, out)?;
        }
    }
    Ok(())
}

/// Removes prefixed files below `dir`, then `dir` itself if that left it empty.
fn purge_dir(dir: &Path, prefix: &str, report: &mut PurgeReport) -> Result<(), IpcError> {
    for entry in fs::read_dir(dir).map_err(io("list", dir))? {
        let path = entry.map_err(io("list", dir))?.path();
        if path.symlink_metadata().map_err(io("stat", &path))?.is_dir() {
            purge_dir(&path, prefix, report)?;
        } else if path
            .file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with(prefix))
        {
            remove(&path, false)?;
            report.removed.push(path);
        } else {
            report.kept.push(path);
        }
    }
    let empty = fs::read_dir(dir).map_err(io("list", dir))?.next().is_none();
    if empty {
        remove(dir, true)?;
        report.removed.push(dir.to_path_buf());
    } else {
        report.kept.push(dir.to_path_buf());
    }
    Ok(())
}

fn remove(path: &Path, is_dir: bool) -> Result<(), IpcError> {
    let result = if is_dir {
        fs::remove_dir(path)
    } else {
        fs::remove_file(path)
    };
    match result {
        // Another cleaner (or the owner) got there first: the goal is reached.
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        other => other.map_err(io("remove", path)),
    }
}

fn io(op: &'static str, path: &Path) -> impl FnOnce(std::io::Error) -> IpcError {
    let path = path.to_path_buf();
    move |source| IpcError::Io { op, path, source }
}
