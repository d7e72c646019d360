//! Logging setup shared by every thrusterd process (thrusterd, thruster-hw, thruster-sim).
//!
//! Under systemd, stderr is connected to the journal and systemd says so in `JOURNAL_STREAM`
//! (`<device>:<inode>` of that stream, see systemd.exec(5)). Then the process logs to journald
//! directly, with structured fields (every tracing field becomes a journal field, and the
//! level its PRIORITY), instead of flat text lines. systemd's documentation asks to compare
//! the variable with stderr's own device and inode, since a child that inherited the variable
//! may have had stderr redirected elsewhere. If the journal socket cannot be reached, logging
//! falls back to stderr (which still ends up in the journal, as text) and says why. Anywhere
//! else, logs go to stderr as before.
//!
//! The filter is `RUST_LOG` when set, else the caller's default (e.g. "info").

use std::io::{self, IsTerminal};

use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::EnvFilter;

/// Where the logs went.
#[derive(Debug)]
pub enum LogOutput {
    /// stderr, text lines (not under systemd, or stderr redirected away from the journal).
    Stderr,
    /// journald, structured.
    Journald,
    /// stderr because stderr is the journal but its socket could not be used (why).
    StderrFallback(io::Error),
}

/// The device and inode named by a `JOURNAL_STREAM` value (`"<dev>:<ino>"`, decimal).
pub fn parse_journal_stream(value: &str) -> Option<(u64, u64)> {
    let (dev, ino) = value.trim().split_once(':')?;
    Some((dev.parse().ok()?, ino.parse().ok()?))
}

/// True when `journal_stream` (the variable's value, if set) names `stderr_id` (device and
/// inode of this process's stderr, if it could be read): stderr is the journal.
pub fn stderr_is_journal(journal_stream: Option<&str>, stderr_id: Option<(u64, u64)>) -> bool {
    match (journal_stream.and_then(parse_journal_stream), stderr_id) {
        (Some(named), Some(actual)) => named == actual,
        _ => false,
    }
}

/// The decision, with the journald layer when it was made: `connect` is only called when
/// stderr is the journal, and its failure selects the fallback.
pub fn choose<L>(
    journal_stream: Option<&str>,
    stderr_id: Option<(u64, u64)>,
    connect: impl FnOnce() -> io::Result<L>,
) -> (LogOutput, Option<L>) {
    if !stderr_is_journal(journal_stream, stderr_id) {
        return (LogOutput::Stderr, None);
    }
    match connect() {
        Ok(layer) => (LogOutput::Journald, Some(layer)),
        Err(e) => (LogOutput::StderrFallback(e), None),
    }
}

/// Device and inode of this process's stderr.
fn stderr_id() -> Option<(u64, u64)> {
    use std::os::fd::AsFd;
    use std::os::unix::fs::MetadataExt;
    let fd = io::stderr().as_fd().try_clone_to_owned().ok()?;
    let meta = std::fs::File::from(fd).metadata().ok()?;
    Some((meta.dev(), meta.ino()))
}

/// Installs the global subscriber (journald or stderr, as above) with `RUST_LOG` or
/// `default_filter`, and returns where logs go. A fallback is also logged as a warning. Does
/// nothing (but still answers) if a subscriber is already installed.
pub fn init(default_filter: &str) -> LogOutput {
    let filter =
        || EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default_filter));
    let journal_stream = std::env::var("JOURNAL_STREAM").ok();
    let (output, journald) = choose(
        journal_stream.as_deref(),
        stderr_id(),
        tracing_journald::layer,
    );
    match journald {
        Some(layer) => {
            let _ = tracing_subscriber::registry()
                .with(filter())
                .with(layer)
                .try_init();
        }
        None => {
            let _ = tracing_subscriber::fmt()
                .with_env_filter(filter())
                .with_writer(io::stderr)
                .with_ansi(io::stderr().is_terminal())
                .try_init();
        }
    }
    if let LogOutput::StderrFallback(e) = &output {
        tracing::warn!("stderr is the journal but its socket is unusable ({e}); logging to stderr");
    }
    output
}

/// Log calls made on the calling thread never wait for journald from now on: a message that
/// finds journald's queue full is dropped (other threads wait up to 500 ms for room first;
/// vendor/README.md). For control loops: a stalled journald must not stall them.
pub fn never_wait_on_this_thread() {
    tracing_journald::never_wait_on_this_thread();
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stalled journald (a socket nobody reads: the kernel queues `net.unix.max_dgram_qlen`
    /// datagrams, 10 by default) never blocks a log call on a control loop's thread: the
    /// journald layer's socket is non-blocking (vendor/tracing-journald), so later messages
    /// are dropped and counted. With the published crate the eleventh call blocks until
    /// journald reads, and the thread never finishes here.
    #[test]
    fn a_stalled_journald_never_blocks_the_thread_that_logs() {
        use std::os::unix::net::UnixDatagram;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("journal.socket");
        let journald = UnixDatagram::bind(&path).unwrap(); // bound, never read while logging
        let layer = tracing_journald::Layer::with_socket_path(&path).unwrap();
        let dispatch = tracing::Dispatch::new(tracing_subscriber::registry().with(layer));
        let logging = dispatch.clone();
        const LINES: u64 = 1000;
        let (done, finished) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            never_wait_on_this_thread();
            tracing::dispatcher::with_default(&logging, || {
                for k in 0..LINES {
                    tracing::warn!(k, "a warning while journald is stalled");
                }
            });
            let _ = done.send(());
        });
        assert!(
            finished
                .recv_timeout(std::time::Duration::from_secs(30))
                .is_ok(),
            "logging to a stalled journald blocked the thread that logs"
        );
        let dropped = dispatch
            .downcast_ref::<tracing_journald::Layer>()
            .expect("the journald layer")
            .dropped();
        // What journald would read once it wakes: the messages that were queued.
        journald.set_nonblocking(true).unwrap();
        let mut buf = vec![0u8; 64 * 1024];
        let mut queued = 0;
        while let Ok(n) = journald.recv(&mut buf) {
            if n > 0 {
                queued += 1;
            }
        }
        println!("{LINES} warnings to a stalled journald: {queued} queued, {dropped} dropped");
        assert!(dropped > 0, "nothing was dropped: the queue never filled");
        assert_eq!(
            queued + dropped,
            LINES,
            "every message either queued or counted as dropped ({queued} queued, {dropped} dropped)"
        );
    }

    /// Any other thread waits a little for a busy journald (a burst of start-up lines beyond
    /// the kernel's queue) and loses nothing; a stalled one costs it at most 500 ms a message.
    #[test]
    fn other_threads_wait_a_bounded_time_for_a_busy_journald() {
        use std::os::unix::net::UnixDatagram;
        use std::time::{Duration, Instant};
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("journal.socket");
        let journald = UnixDatagram::bind(&path).unwrap();
        let layer = tracing_journald::Layer::with_socket_path(&path).unwrap();
        let dispatch = tracing::Dispatch::new(tracing_subscriber::registry().with(layer));
        let logging = dispatch.clone();
        const LINES: u64 = 64;
        let (done, finished) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            tracing::dispatcher::with_default(&logging, || {
                for k in 0..LINES {
                    tracing::info!(k, "start-up line");
                }
            });
            let _ = done.send(());
        });
        // Journald reads only from 30 ms on: the queue is full by then.
        std::thread::sleep(Duration::from_millis(30));
        journald.set_nonblocking(true).unwrap();
        let mut buf = vec![0u8; 64 * 1024];
        let mut read = 0;
        let until = Instant::now() + Duration::from_secs(20);
        while read < LINES && Instant::now() < until {
            match journald.recv(&mut buf) {
                Ok(n) if n > 0 => read += 1,
                _ => std::thread::sleep(Duration::from_millis(1)),
            }
        }
        assert!(finished.recv_timeout(Duration::from_secs(20)).is_ok());
        let dropped = dispatch
            .downcast_ref::<tracing_journald::Layer>()
            .expect("the journald layer")
            .dropped();
        println!("{LINES} start-up lines, journald 30 ms late: {read} read, {dropped} dropped");
        assert_eq!((read, dropped), (LINES, 0), "a busy journald lost lines");
    }

    #[test]
    fn journal_stream_values() {
        assert_eq!(parse_journal_stream("8:12345"), Some((8, 12345)));
        assert_eq!(parse_journal_stream(" 8:12345\n"), Some((8, 12345)));
        for bad in ["", "8", "8:", ":1", "a:b", "8:1:2", "-1:5"] {
            assert_eq!(parse_journal_stream(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn stderr_only_counts_as_the_journal_when_the_ids_match() {
        assert!(stderr_is_journal(Some("8:99"), Some((8, 99))));
        // Variable absent, unreadable stderr, garbage, or stderr redirected elsewhere.
        assert!(!stderr_is_journal(None, Some((8, 99))));
        assert!(!stderr_is_journal(Some("8:99"), None));
        assert!(!stderr_is_journal(Some("garbage"), Some((8, 99))));
        assert!(!stderr_is_journal(Some("8:99"), Some((8, 100))));
    }

    #[test]
    fn journald_when_stderr_is_the_journal_and_the_socket_works() {
        let (out, layer) = choose(Some("3:7"), Some((3, 7)), || Ok("layer"));
        assert!(matches!(out, LogOutput::Journald), "{out:?}");
        assert_eq!(layer, Some("layer"));
    }

    #[test]
    fn stderr_without_systemd_never_touches_the_socket() {
        let (out, layer) = choose::<()>(None, Some((3, 7)), || panic!("must not connect"));
        assert!(matches!(out, LogOutput::Stderr), "{out:?}");
        assert!(layer.is_none());
        let (out, _) = choose::<()>(Some("3:8"), Some((3, 7)), || panic!("must not connect"));
        assert!(matches!(out, LogOutput::Stderr), "{out:?}");
    }

    #[test]
    fn missing_socket_falls_back_to_stderr_with_the_reason() {
        let (out, layer) = choose::<()>(Some("3:7"), Some((3, 7)), || {
            Err(io::Error::new(io::ErrorKind::NotFound, "no journal socket"))
        });
        match out {
            LogOutput::StderrFallback(e) => assert_eq!(e.kind(), io::ErrorKind::NotFound),
            other => panic!("{other:?}"),
        }
        assert!(layer.is_none());
    }

    #[test]
    fn the_real_socket_check_agrees_with_the_machine() {
        // The real constructor either reaches a journald socket or reports why not; with a
        // matching stream id the decision follows it (this machine may or may not run
        // systemd).
        let socket = std::path::Path::new("/run/systemd/journal/socket").exists();
        let (out, _) = choose(Some("1:2"), Some((1, 2)), tracing_journald::layer);
        match out {
            LogOutput::Journald => assert!(socket),
            // No socket, or one this user may not write to.
            LogOutput::StderrFallback(_) => {}
            LogOutput::Stderr => panic!("ids matched"),
        }
    }
}
