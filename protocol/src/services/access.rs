//! Who may use a namespace: the owner of its iceoryx2 root, or a member of the root's group
//! when the group has full access (on a vehicle: `/run/thrusterd`, `thrusterd:thrusterd`,
//! mode 2770, so the operators are the members of group `thrusterd`).
//!
//! Why a check before joining: a process joining a namespace creates iceoryx2 files (node
//! monitors, sockets, shared memory). Files of a user the daemon is not grouped with either
//! cannot be opened by the daemon (its control loop then waits inside iceoryx2 for each one)
//! or, in the sticky `/dev/shm`, cannot be removed by it after a crash. Root is no exception:
//! root can open anything, but the daemon cannot open or remove what root leaves behind. So
//! the check applies the permission bits as the kernel would to an unprivileged user, and
//! refuses before the first file exists.

use std::ffi::CStr;
use std::os::unix::fs::MetadataExt;

use super::error::AccessDenied;
use super::{IpcConfig, IpcError};

/// Checks that this process may use `ipc`'s namespace, before it creates any file there.
///
/// Looks at the root base and the namespace's root directory, whichever exist; when neither
/// exists no daemon runs there and nothing is refused (the default root under /tmp is made
/// by whoever comes first).
pub fn check_access(ipc: &IpcConfig) -> Result<(), IpcError> {
    let me = Credentials::current();
    for dir in [ipc.root_base(), ipc.root_dir().as_path()] {
        let meta = match std::fs::metadata(dir) {
            Ok(m) => m,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(e) => {
                return Err(IpcError::Io {
                    op: "inspect",
                    path: dir.to_path_buf(),
                    source: e,
                })
            }
        };
        if !me.may_use(meta.uid(), meta.gid(), meta.mode()) {
            return Err(IpcError::AccessDenied(Box::new(AccessDenied {
                path: dir.to_path_buf(),
                user: format!("{} (uid {})", user_name(me.uid), me.uid),
                owner: user_name(meta.uid()),
                group: group_name(meta.gid()),
                mode: meta.mode() & 0o7777,
            })));
        }
    }
    Ok(())
}

/// Whether this process owns the namespace's root base (or it does not exist yet): only then
/// may it remove what dead nodes left (see [`IpcConfig::without_dead_node_cleanup`]).
pub fn owns_root(ipc: &IpcConfig) -> bool {
    match std::fs::metadata(ipc.root_base()) {
        Ok(m) => m.uid() == unsafe { libc::geteuid() },
        Err(_) => true,
    }
}

/// Makes the shared memory segments this process creates belong to the group of the
/// namespace's root base when that directory is setgid and this process is a member of its
/// group (`/run/thrusterd`, `thrusterd:thrusterd`, 2770): the same rule the kernel applies to
/// the files created below a setgid directory, which POSIX shared memory in /dev/shm does not
/// get. With iceoryx2's files at 0660 (vendor/iceoryx2-cal, `group_permissions`) an operator
/// whose primary group is their own would otherwise create segments the daemon cannot open.
/// Otherwise segments keep the creator's group (tests, a root under /tmp).
pub fn adopt_root_group(ipc: &IpcConfig) {
    iceoryx2_cal::dynamic_storage::posix_shared_memory::set_group_owner(root_group(ipc));
}

/// The group [`adopt_root_group`] gives segments: the root base's, if it is setgid and this
/// process is a member of it.
pub fn root_group(ipc: &IpcConfig) -> Option<u32> {
    let meta = std::fs::metadata(ipc.root_base()).ok()?;
    let setgid = meta.mode() & 0o2000 != 0; // S_ISGID
    (setgid && Credentials::current().groups.contains(&meta.gid())).then_some(meta.gid())
}

/// Effective user and groups of a process.
#[derive(Debug, Clone)]
pub(crate) struct Credentials {
    pub uid: u32,
    pub groups: Vec<u32>,
}

impl Credentials {
    fn current() -> Self {
        // SAFETY: plain libc calls; getgroups fills at most `n` entries of the buffer.
        let (uid, egid) = unsafe { (libc::geteuid(), libc::getegid()) };
        let mut groups = vec![egid];
        let n = unsafe { libc::getgroups(0, std::ptr::null_mut()) };
        if n > 0 {
            let mut buf = vec![0 as libc::gid_t; n as usize];
            let got = unsafe { libc::getgroups(n, buf.as_mut_ptr()) };
            if got > 0 {
                groups.extend_from_slice(&buf[..got as usize]);
            }
        }
        Self { uid, groups }
    }

    /// Read, write and search on a directory with these bits, as the kernel decides for an
    /// unprivileged user (root gets no override, see the module comment): the owner's bits
    /// for the owner, else the group's for a member, else the others'.
    pub(crate) fn may_use(&self, owner: u32, group: u32, mode: u32) -> bool {
        let bits = if self.uid == owner {
            mode >> 6
        } else if self.groups.contains(&group) {
            mode >> 3
        } else {
            mode
        };
        bits & 0o7 == 0o7
    }
}

fn user_name(uid: u32) -> String {
    let mut buf = vec![0 as libc::c_char; 4096];
    let mut pw: libc::passwd = unsafe { std::mem::zeroed() };
    let mut out: *mut libc::passwd = std::ptr::null_mut();
    // SAFETY: getpwuid_r writes into `pw` and `buf`, which outlive the use of `out`.
    let rc = unsafe { libc::getpwuid_r(uid, &mut pw, buf.as_mut_ptr(), buf.len(), &mut out) };
    if rc == 0 && !out.is_null() {
        unsafe { CStr::from_ptr(pw.pw_name) }
            .to_string_lossy()
            .into_owned()
    } else {
        uid.to_string()
    }
}

fn group_name(gid: u32) -> String {
    let mut buf = vec![0 as libc::c_char; 4096];
    let mut gr: libc::group = unsafe { std::mem::zeroed() };
    let mut out: *mut libc::group = std::ptr::null_mut();
    // SAFETY: as in user_name.
    let rc = unsafe { libc::getgrgid_r(gid, &mut gr, buf.as_mut_ptr(), buf.len(), &mut out) };
    if rc == 0 && !out.is_null() {
        unsafe { CStr::from_ptr(gr.gr_name) }
            .to_string_lossy()
            .into_owned()
    } else {
        gid.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn user(uid: u32, groups: &[u32]) -> Credentials {
        Credentials {
            uid,
            groups: groups.to_vec(),
        }
    }

    #[test]
    fn owner_and_group_members_may_use_a_group_root() {
        // /run/thrusterd: thrusterd (uid 990, gid 990), mode 2770.
        assert!(user(990, &[990]).may_use(990, 990, 0o2770));
        assert!(user(1000, &[1000, 990]).may_use(990, 990, 0o2770));
    }

    #[test]
    fn root_and_non_members_are_refused() {
        assert!(!user(0, &[0]).may_use(990, 990, 0o2770));
        assert!(!user(1000, &[1000]).may_use(990, 990, 0o2770));
        // A group without write access does not make its members operators.
        assert!(!user(1000, &[990]).may_use(990, 990, 0o2750));
    }

    #[test]
    fn a_world_writable_root_is_anyones() {
        assert!(user(1000, &[1000]).may_use(0, 0, 0o1777));
        assert!(user(0, &[0]).may_use(0, 0, 0o755));
    }
}
