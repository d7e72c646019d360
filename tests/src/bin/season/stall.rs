//! A stalled link ends the season as a failure, with what the processes held at that moment.
//!
//! Why: in lockstep the simulator waits for each answer; if the daemon stops being woken by
//! the IMU notifications it answers only when its loop wakes for something else (100 ms), and
//! vehicle time crawls at a fraction of real time. The run then lasts hours instead of a
//! minute, and CI waits for its own limit with nothing said (seen twice: docs/reliability.md,
//! "The same stall on glibc"). A run that advanced less than [`MIN_RATE`] times real time for
//! [`WINDOW`] of wall time is stopped and named stalled; its descriptors, sockets and threads
//! are written out so the cause can be read afterwards.

use std::fmt::Write as _;
use std::time::{Duration, Instant};

/// Wall time over which progress is judged.
pub(crate) const WINDOW: Duration = Duration::from_secs(60);
/// Vehicle seconds per wall second below which the run is stalled. A loaded 2-core VM runs the
/// CI season at 5-20x; a link that answers only on the daemon's 100 ms wake-ups runs at 0.05x.
pub(crate) const MIN_RATE: f64 = 0.1;

/// Watches vehicle time against the wall clock.
pub(crate) struct StallWatch {
    since: Instant,
    at_ns: u64,
}

impl StallWatch {
    pub(crate) fn new(now_ns: u64) -> Self {
        Self {
            since: Instant::now(),
            at_ns: now_ns,
        }
    }

    /// `Some(why)` once vehicle time has advanced less than `MIN_RATE` x the wall time for a
    /// whole `WINDOW`.
    pub(crate) fn check(&mut self, now_ns: u64) -> Option<String> {
        let needed_ns = (WINDOW.as_secs_f64() * MIN_RATE * 1e9) as u64;
        let advanced = now_ns.saturating_sub(self.at_ns);
        if advanced >= needed_ns {
            *self = Self::new(now_ns);
            return None;
        }
        let wall = self.since.elapsed();
        (wall >= WINDOW).then(|| {
            format!(
                "the link stalled: vehicle time advanced {:.2} s in {:.0} s of wall time \
                 ({:.3}x, under {MIN_RATE}x), from vehicle {:.1} s",
                advanced as f64 / 1e9,
                wall.as_secs_f64(),
                advanced as f64 / 1e9 / wall.as_secs_f64(),
                self.at_ns as f64 / 1e9
            )
        })
    }
}

/// What `pids` hold now: every descriptor and what it points at, the unix sockets among them
/// with their addresses and queues (/proc/net/unix), and each thread's wait channel.
pub(crate) fn describe(pids: &[(&str, u32)]) -> String {
    let mut text = String::new();
    let unix = std::fs::read_to_string("/proc/net/unix").unwrap_or_default();
    for (name, pid) in pids {
        let _ = writeln!(text, "== {name} (pid {pid})");
        let mut fds: Vec<(u32, String)> = std::fs::read_dir(format!("/proc/{pid}/fd"))
            .map(|d| {
                d.filter_map(|e| {
                    let e = e.ok()?;
                    let fd = e.file_name().to_string_lossy().parse().ok()?;
                    let target = std::fs::read_link(e.path()).ok()?;
                    Some((fd, target.display().to_string()))
                })
                .collect()
            })
            .unwrap_or_default();
        fds.sort();
        for (fd, target) in &fds {
            let _ = write!(text, "fd {fd} -> {target}");
            // socket:[inode]: its line of /proc/net/unix (refcount, state, path).
            if let Some(inode) = target
                .strip_prefix("socket:[")
                .and_then(|s| s.strip_suffix(']'))
            {
                if let Some(line) = unix
                    .lines()
                    .find(|l| l.split_whitespace().nth(6) == Some(inode))
                {
                    let _ = write!(text, "  [{}]", line.trim());
                }
            }
            text.push('\n');
        }
        if let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) {
            for t in tasks.flatten() {
                let read = |f: &str| {
                    std::fs::read_to_string(t.path().join(f))
                        .unwrap_or_default()
                        .trim()
                        .to_string()
                };
                let _ = writeln!(
                    text,
                    "thread {} {}: wchan {}",
                    t.file_name().to_string_lossy(),
                    read("comm"),
                    read("wchan")
                );
            }
        }
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn progress_at_the_minimum_rate_is_not_a_stall() {
        let mut w = StallWatch::new(0);
        // Just enough vehicle time: the window starts again.
        let enough = (WINDOW.as_secs_f64() * MIN_RATE * 1e9) as u64;
        assert_eq!(w.check(enough), None);
        assert_eq!(w.at_ns, enough);
    }

    #[test]
    fn a_window_without_progress_is_a_stall() {
        let mut w = StallWatch::new(5_000_000_000);
        assert_eq!(w.check(5_100_000_000), None, "not a whole window yet");
        w.since = Instant::now() - WINDOW;
        let why = w.check(5_100_000_000).expect("stalled");
        assert!(why.contains("advanced 0.10 s"), "{why}");
        assert!(why.contains("from vehicle 5.0 s"), "{why}");
    }

    #[test]
    fn this_process_is_described() {
        let text = describe(&[("self", std::process::id())]);
        assert!(
            text.contains("fd 0 ->") || text.contains("fd 1 ->"),
            "{text}"
        );
        assert!(text.contains("thread "), "{text}");
    }
}
