//! `record`: every topic of the namespace into MCAP files, until Ctrl-C, SIGTERM or
//! `--duration-s` (the recorder itself is the `thruster-recorder` library).

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, Result};
use thruster_protocol::services::{check_access, owns_root, IpcConfig, IpcError, TidyOnDrop};
use thruster_recorder::RecordOptions;

use crate::client::Target;
use crate::console::say;
use crate::exit::{self, Failure};

/// Largest `--max-mb` (1 TiB): a typo guard.
const MAX_MB: f64 = 1024.0 * 1024.0;
/// Longest `--duration-s` (a week).
const MAX_DURATION_S: f64 = 7.0 * 24.0 * 3600.0;

/// The recording options from the command line, checked before anything is opened.
pub fn options(
    out: PathBuf,
    max_mb: Option<f64>,
    duration_s: Option<f64>,
) -> Result<RecordOptions, Failure> {
    let max_bytes = match max_mb {
        Some(mb) if !(mb.is_finite() && mb > 0.0 && mb <= MAX_MB) => {
            return Err(Failure::usage(format!(
                "--max-mb must be in (0, {MAX_MB}], got {mb}"
            )))
        }
        Some(mb) => Some((mb * 1024.0 * 1024.0) as u64),
        None => None,
    };
    let duration = match duration_s {
        Some(s) if !(s.is_finite() && s > 0.0 && s <= MAX_DURATION_S) => {
            return Err(Failure::usage(format!(
                "--duration-s must be in (0, {MAX_DURATION_S}], got {s}"
            )))
        }
        Some(s) => Some(Duration::from_secs_f64(s)),
        None => None,
    };
    if out.as_os_str().is_empty() || out.is_dir() {
        return Err(Failure::usage(format!(
            "--out must name a file, got {:?}",
            out.display()
        )));
    }
    Ok(RecordOptions {
        out,
        max_bytes,
        duration,
        queue: thruster_recorder::DEFAULT_QUEUE,
        compression: thruster_recorder::Compression::default(),
    })
}

/// Records `target`'s namespace until `stop` (Ctrl-C/SIGTERM) or the duration; prints the
/// summary line (counts and losses) at the end. A daemon need not run: the recorder waits for
/// whatever is published. A write error (a full disk) ends the recording at once: the summary
/// line (how many messages reached the files) is printed, then the error naming the file and
/// the OS error (exit 1).
pub fn run(target: &Target, options: &RecordOptions, stop: Arc<AtomicBool>) -> Result<()> {
    let ipc = IpcConfig::with_root_base(&target.namespace, &target.root_base)
        .map_err(|e| Failure::usage(format!("--namespace/--ipc-root: {e}")))?;
    check_access(&ipc).map_err(|e| match e {
        IpcError::AccessDenied(denied) => Failure::new(exit::FORBIDDEN, denied.to_string()),
        other => Failure::new(exit::GENERIC, other.to_string()),
    })?;
    let ipc = if owns_root(&ipc) {
        ipc
    } else {
        ipc.without_dead_node_cleanup()
    };
    // Declared before the recording's node, so it drops after it: the last process to leave
    // the namespace removes iceoryx2's residue.
    let _tidy = TidyOnDrop::new(&ipc);
    let summary = match thruster_recorder::record(&ipc, options, &stop) {
        Ok(summary) => summary,
        Err(e) => {
            if let Some(summary) = e.summary() {
                // What was recorded before the error stays accounted for; the error matters more
                // than a closed stdout.
                let _ = say(&summary.line());
            }
            return Err(e).with_context(|| format!("recording namespace {}", target.namespace));
        }
    };
    say(&summary.line())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_limits_are_named() {
        let out = PathBuf::from("x.mcap");
        let e = options(out.clone(), Some(0.0), None).unwrap_err();
        assert!(e.to_string().contains("--max-mb"), "{e}");
        let e = options(out.clone(), None, Some(-1.0)).unwrap_err();
        assert!(e.to_string().contains("--duration-s"), "{e}");
        let e = options(PathBuf::from("/"), None, None).unwrap_err();
        assert!(e.to_string().contains("--out"), "{e}");
        let ok = options(out, Some(1.5), Some(2.0)).unwrap();
        assert_eq!(ok.max_bytes, Some(1_572_864));
        assert_eq!(ok.duration, Some(Duration::from_secs(2)));
    }
}
