//! Every file a namespace's processes create is for the owner and the ipc root's group only
//! (vendor/iceoryx2-cal, feature `group_permissions`; docs/reliability.md, "Access").
//!
//! One test in its own binary: the group given to shared memory is process-wide, and another
//! test creating a node under a plain root would change it midway.

use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};

use thruster_protocol::services::*;
use thruster_protocol::{ImuSample, StatusMsg};

/// The group the root base gets: as root, `nogroup` (65534), added to this process's
/// supplementary groups so that it is a member (as an operator is of `thrusterd`) and it is
/// not the process's own group, so a segment that kept its creator's group shows. Otherwise
/// the user's own group (the check then sees the modes, not the hand-over).
fn test_group() -> u32 {
    if unsafe { libc::geteuid() } == 0 {
        let groups = [0 as libc::gid_t, 65534];
        // SAFETY: a valid array of two gids.
        assert_eq!(unsafe { libc::setgroups(2, groups.as_ptr()) }, 0);
        65534
    } else {
        unsafe { libc::getegid() }
    }
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        out.push(p.clone());
        if e.file_type().unwrap().is_dir() {
            walk(&p, out);
        }
    }
}

#[test]
fn files_are_owner_and_group_only_and_belong_to_the_setgid_roots_group() {
    let group = test_group();
    let base = tempfile::tempdir().unwrap();
    let root_base = base.path().join("run");
    std::fs::create_dir(&root_base).unwrap();
    std::os::unix::fs::chown(&root_base, None, Some(group)).unwrap();
    std::fs::set_permissions(&root_base, std::fs::Permissions::from_mode(0o2770)).unwrap();
    let ns = NamespaceGuard::new(IpcConfig::with_root_base("perm", &root_base).unwrap());
    assert_eq!(root_group(&ns), Some(group));

    // What a daemon and an operator make: a node each, topics both ways with their events.
    let daemon = ns.create_node("daemon").unwrap();
    let imu_in = Inbox::<ImuSample>::create(&daemon, &ns).unwrap();
    let status_out = Port::<StatusMsg>::create(&daemon, &ns).unwrap();
    let operator = ns.create_node("operator").unwrap();
    let imu_out = Port::<ImuSample>::create(&operator, &ns).unwrap();
    let status_in = Inbox::<StatusMsg>::create(&operator, &ns).unwrap();
    imu_out.send(&ImuSample::default()).unwrap();
    status_out.send(&StatusMsg::default()).unwrap();
    let _ = imu_in.recv().unwrap();
    let _ = status_in.recv().unwrap();

    let mut files = namespace_files(&ns).unwrap();
    walk(&ns.root_dir(), &mut files);
    files.sort();
    files.dedup();
    let shm = files.iter().filter(|p| p.starts_with(SHM_DIR)).count();
    assert!(shm >= 8, "too few segments to judge: {files:?}");
    assert!(
        files.len() >= shm + 8,
        "too few root files to judge: {files:?}"
    );
    let mut wrong = Vec::new();
    for p in &files {
        let m = std::fs::symlink_metadata(p).unwrap();
        let mode = m.mode() & 0o7777;
        if mode & 0o007 != 0 {
            wrong.push(format!("{}: mode {mode:o} lets others in", p.display()));
        }
        if m.gid() != group {
            wrong.push(format!("{}: group {} not {group}", p.display(), m.gid()));
        }
        if m.is_dir() && mode & 0o2000 == 0 {
            wrong.push(format!("{}: directory {mode:o} not setgid", p.display()));
        }
        if !m.is_dir() && mode & 0o060 == 0 {
            wrong.push(format!(
                "{}: mode {mode:o} shuts the group out",
                p.display()
            ));
        }
    }
    eprintln!("{} files checked ({shm} in {SHM_DIR})", files.len());
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));

    drop((imu_in, status_out, imu_out, status_in));
    drop((daemon, operator));
}
