//! A client whose files the daemon cannot open, and who may use a namespace at all.

use std::os::unix::fs::PermissionsExt;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use thruster_protocol::services::*;
use thruster_protocol::ImuSample;

fn shm_files(ipc: &IpcConfig) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(SHM_DIR)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(&ipc.prefix()))
        .map(|e| e.path())
        .collect();
    v.sort();
    v
}

/// The daemon meets another user's mode-0600 files (a `sudo thrusterctl`) inside a receive
/// call: iceoryx2 takes an unreadable segment for one still being initialised and waits for
/// it. Mode 0200 (iceoryx2's own "initialising" mode) makes every user, root included, see
/// that state. The wait must be short: it is spent in the control loop. With iceoryx2's
/// default of 1 s it was 1 s; measured here about 20-25 ms.
#[test]
fn a_sender_whose_files_cannot_be_opened_costs_the_receiver_a_short_bounded_wait() {
    let ns = NamespaceGuard::unique_for_test("acc").unwrap();
    let daemon_node = ns.create_node("daemon").unwrap();
    let inbox = Inbox::<ImuSample>::create(&daemon_node, &ns).unwrap();
    assert_eq!(inbox.recv().unwrap(), None);
    let before = shm_files(&ns);

    let client_node = ns.create_node("client").unwrap();
    let port = Port::<ImuSample>::create(&client_node, &ns).unwrap();
    let made: Vec<PathBuf> = shm_files(&ns)
        .into_iter()
        .filter(|p| !before.contains(p))
        .collect();
    assert!(!made.is_empty(), "the publisher made no shared memory");
    for p in &made {
        std::fs::set_permissions(p, std::fs::Permissions::from_mode(0o200)).unwrap();
    }

    let start = Instant::now();
    let _ = inbox.recv();
    let took = start.elapsed();
    eprintln!("receive with an unopenable sender: {took:?}");
    for p in &made {
        std::fs::set_permissions(p, std::fs::Permissions::from_mode(0o600)).unwrap();
    }
    drop(port);
    drop(client_node);
    assert!(
        took >= CONNECTION_TIMEOUT,
        "took {took:?}: the sender's files were not in the way, the test tests nothing"
    );
    assert!(
        took < CONNECTION_TIMEOUT * 4 + Duration::from_millis(50),
        "a bad sender stalled the receiver for {took:?}"
    );
}

/// A root directory of another user and group (on a vehicle: /run/thrusterd,
/// thrusterd:thrusterd, 2770) is refused to everyone else, root included, with the path and
/// the fix in the message; nothing is created.
#[test]
fn a_user_outside_the_ipc_roots_group_is_refused_before_any_file_exists() {
    let base = tempfile::tempdir().unwrap();
    let root_base = base.path().join("run");
    std::fs::create_dir(&root_base).unwrap();
    foreign_owner(&root_base);
    let ipc = IpcConfig::with_root_base("acc", &root_base).unwrap();
    let err = check_access(&ipc).expect_err("refused");
    let text = err.to_string();
    assert!(matches!(err, IpcError::AccessDenied(_)), "{err:?}");
    assert!(text.contains(&root_base.display().to_string()), "{text}");
    assert!(text.contains("usermod -aG"), "{text}");
    assert!(!ipc.root_dir().exists());
    // The owner's own directory is fine.
    let ok = IpcConfig::with_root_base("acc", base.path()).unwrap();
    check_access(&ok).unwrap();
}

/// Root: give `dir` to nobody:nogroup with mode 2770. Anyone else cannot chown; a directory
/// whose owner bits are empty refuses its owner by the same rule.
fn foreign_owner(dir: &std::path::Path) {
    if unsafe { libc::geteuid() } == 0 {
        std::os::unix::fs::chown(dir, Some(65534), Some(65534)).unwrap();
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o2770)).unwrap();
    } else {
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o070)).unwrap();
    }
}
