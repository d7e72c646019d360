//! What the season soak measures of its processes and namespace: RSS and descriptors, the
//! namespace's files, the machine's load.

use std::path::Path;
use std::time::Duration;

use anyhow::Result;
use system_tests::season::{Census, Entry, ProcFigures};
use system_tests::soak::parse_proc_status;
use thruster_protocol::services::{namespace_files, IpcConfig, SHM_DIR};

/// RSS and open descriptors of a process now (zeros once it is gone).
pub(crate) fn proc_figures(pid: u32) -> ProcFigures {
    let rss_kib = std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|t| parse_proc_status(&t))
        .map_or(0, |m| m.rss_kib);
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |d| d.count() as u64);
    ProcFigures { rss_kib, fds }
}

/// The namespace's files now, in /dev/shm and under its root.
pub(crate) fn census(ipc: &IpcConfig) -> Result<Census> {
    // Clients come and go while the tree is walked: a file that vanished mid-walk fails the
    // listing; list again.
    let mut tries = 0;
    let files = loop {
        match namespace_files(ipc) {
            Ok(f) => break f,
            Err(_) if tries < 20 => {
                tries += 1;
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(e) => return Err(e.into()),
        }
    };
    let entries: Vec<Entry> = files
        .into_iter()
        .filter_map(|path| {
            // A file may go between the listing and this (a client leaving): not counted.
            let m = path.symlink_metadata().ok()?;
            Some(Entry {
                is_dir: m.is_dir(),
                len: if m.is_dir() { 0 } else { m.len() },
                path,
            })
        })
        .collect();
    Ok(Census::of(&entries, Path::new(SHM_DIR)))
}

/// Names (with sizes) of the namespace's files now: "path (bytes)".
pub(crate) fn file_names(ipc: &IpcConfig) -> std::collections::BTreeSet<String> {
    namespace_files(ipc)
        .unwrap_or_default()
        .into_iter()
        .filter_map(|p| {
            let m = p.symlink_metadata().ok()?;
            (!m.is_dir()).then(|| format!("{} ({} B)", p.display(), m.len()))
        })
        .collect()
}

pub(crate) fn load1() -> f64 {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse().ok()))
        .unwrap_or(f64::NAN)
}
