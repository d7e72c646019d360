//! The soak run's pure logic (the `soak` binary does the processes and the clock): reading
//! memory figures from /proc, the per-minute sample accounting, and the memory-growth verdict.
//! Kept here so it is unit-tested (`cargo test -p system-tests --lib`).

use serde::Serialize;
use thruster_protocol::StatusMsg;
use thruster_sim::link_stats::{LatencyHistogram, StatsLine};

/// Memory of one process from /proc/PID/status, KiB.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Memory {
    /// Resident set size now (VmRSS).
    pub rss_kib: u64,
    /// Peak resident set size (VmHWM).
    pub hwm_kib: u64,
}

/// Parses VmRSS and VmHWM out of the text of /proc/PID/status; None if either is missing.
pub fn parse_proc_status(text: &str) -> Option<Memory> {
    let field = |name: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|rest| rest.trim().trim_end_matches("kB").trim().parse().ok())
    };
    Some(Memory {
        rss_kib: field("VmRSS:")?,
        hwm_kib: field("VmHWM:")?,
    })
}

/// CPU time of a process (user + system), clock ticks, from the text of /proc/PID/stat.
pub fn parse_proc_stat_cpu_ticks(text: &str) -> Option<u64> {
    // The command name (field 2) is in parentheses and may contain spaces: split after it.
    let rest = &text[text.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // After the name: state is field 3, so utime (14) and stime (15) are at 11 and 12.
    let utime: u64 = fields.get(11)?.parse().ok()?;
    let stime: u64 = fields.get(12)?.parse().ok()?;
    Some(utime + stime)
}

/// The daemon's IMU counters from one status message.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct DaemonCounts {
    /// IMU samples accepted.
    pub accepted: u64,
    /// Messages rejected (every category; in a soak only IMU samples can be).
    pub rejected: u64,
    /// Sequence number of the newest accepted sample, derived from its time (the simulator
    /// takes sample `seq` at `(seq - 1) * period`); 0 before the first.
    pub last_seq: u64,
}

impl DaemonCounts {
    /// Counters of `status`, for samples every `period_ns`.
    pub fn of(status: &StatusMsg, period_ns: u64) -> DaemonCounts {
        DaemonCounts {
            accepted: status.samples,
            rejected: status.rejected_nonfinite
                + status.rejected_range
                + status.rejected_time
                + status.rejected_count
                + status.rejected_other,
            last_seq: if status.samples == 0 {
                0
            } else {
                status.vehicle_time_ns / period_ns.max(1) + 1
            },
        }
    }

    /// Samples up to `last_seq` that the daemon neither accepted nor counted as rejected: lost
    /// on the way without a trace in its counters. Exact at any snapshot, because `last_seq`
    /// and the counters come from the same status message (a rejected sample newer than the
    /// newest accepted one makes this err low by that many, never high).
    pub fn uncounted(&self) -> u64 {
        self.last_seq
            .saturating_sub(self.accepted.saturating_add(self.rejected))
    }
}

/// One minute of the soak.
#[derive(Debug, Clone, Default, Serialize)]
pub struct MinuteRow {
    /// 1-based minute.
    pub minute: u32,
    /// Daemon state at the end of the minute.
    pub state: String,
    /// Model version in use at the end of the minute.
    pub model_version: u64,
    /// Samples published by the simulator during the minute.
    pub published: u64,
    /// Samples answered (first valid answer) during the minute.
    pub answered: u64,
    /// Samples that got no answer within the window, counted by the simulator.
    pub unanswered: u64,
    /// Samples the daemon accepted during the minute.
    pub daemon_accepted: u64,
    /// Samples the daemon rejected (and counted) during the minute.
    pub daemon_rejected: u64,
    /// Samples lost before the daemon without being counted, during the minute.
    pub uncounted: u64,
    /// Sample -> thrust latency, us.
    pub p50_us: Option<f64>,
    /// 99th percentile, us.
    pub p99_us: Option<f64>,
    /// 99.9th percentile, us.
    pub p999_us: Option<f64>,
    /// Largest, us.
    pub max_us: Option<f64>,
    /// Daemon memory at the end of the minute.
    pub daemon_mem: Memory,
    /// Simulator memory at the end of the minute.
    pub sim_mem: Memory,
    /// Daemon CPU over the minute, % of one core.
    pub daemon_cpu_pct: f64,
    /// Simulator CPU over the minute, % of one core.
    pub sim_cpu_pct: f64,
    /// 1-minute load average of the machine at the end of the minute.
    pub load1: f64,
}

/// Cumulative figures at one instant, from which [`MinuteRow`]s are differenced.
#[derive(Debug, Clone, Copy, Default)]
pub struct Snapshot {
    /// Latest simulator stats line's counters: published, answered, unanswered.
    pub published: u64,
    pub answered: u64,
    pub unanswered: u64,
    /// The daemon's counters.
    pub daemon: DaemonCounts,
}

impl Snapshot {
    /// From the latest stats line (if any) and the daemon's counters.
    pub fn new(line: Option<&StatsLine>, daemon: DaemonCounts) -> Snapshot {
        Snapshot {
            published: line.map_or(0, |l| l.published),
            answered: line.map_or(0, |l| l.answered),
            unanswered: line.map_or(0, |l| l.unanswered),
            daemon,
        }
    }

    /// Fills the counting columns of `row` with what happened between `prev` and `self`,
    /// and the latency columns from `latency`.
    pub fn fill(&self, prev: &Snapshot, latency: &LatencyHistogram, row: &mut MinuteRow) {
        row.published = self.published.saturating_sub(prev.published);
        row.answered = self.answered.saturating_sub(prev.answered);
        row.unanswered = self.unanswered.saturating_sub(prev.unanswered);
        row.daemon_accepted = self.daemon.accepted.saturating_sub(prev.daemon.accepted);
        row.daemon_rejected = self.daemon.rejected.saturating_sub(prev.daemon.rejected);
        row.uncounted = self
            .daemon
            .uncounted()
            .saturating_sub(prev.daemon.uncounted());
        row.p50_us = latency.quantile_us(0.5);
        row.p99_us = latency.quantile_us(0.99);
        row.p999_us = latency.quantile_us(0.999);
        row.max_us = latency.max_us();
    }
}

/// Largest memory growth tolerated after the baseline minute: `abs_kib` or `rel` of the
/// baseline, whichever is larger.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct GrowthLimit {
    /// Absolute allowance, KiB.
    pub abs_kib: u64,
    /// Relative allowance (0.1 = 10 %).
    pub rel: f64,
}

/// The memory verdict for one process.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Growth {
    /// RSS at the baseline, KiB.
    pub baseline_kib: u64,
    /// Largest RSS after the baseline, KiB.
    pub peak_after_kib: u64,
    /// Last RSS, KiB.
    pub last_kib: u64,
    /// Least-squares slope of RSS over the minutes from the baseline on, KiB per minute.
    pub slope_kib_per_min: f64,
    /// Growth allowed, KiB.
    pub allowed_kib: u64,
    /// True when the peak after the baseline exceeded baseline + allowance.
    pub exceeded: bool,
}

/// Memory growth of the RSS series `rss_kib` (one value per minute) against entry
/// `baseline` (the first minutes include start-up and the first estimate: buffers are sized
/// and shared-memory pages touched for the first time there). None when there is no entry
/// after the baseline.
pub fn memory_growth(rss_kib: &[u64], baseline: usize, limit: GrowthLimit) -> Option<Growth> {
    let base = *rss_kib.get(baseline)?;
    let after = rss_kib.get(baseline + 1..).filter(|s| !s.is_empty())?;
    let peak = *after.iter().max()?;
    let allowed = limit
        .abs_kib
        .max((base as f64 * limit.rel.max(0.0)).round() as u64);
    let ys = &rss_kib[baseline..];
    let n = ys.len() as f64;
    let mean_x = (n - 1.0) / 2.0;
    let mean_y = ys.iter().map(|&y| y as f64).sum::<f64>() / n;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (i, &y) in ys.iter().enumerate() {
        let dx = i as f64 - mean_x;
        sxy += dx * (y as f64 - mean_y);
        sxx += dx * dx;
    }
    Some(Growth {
        baseline_kib: base,
        peak_after_kib: peak,
        last_kib: *after.last()?,
        slope_kib_per_min: if sxx > 0.0 { sxy / sxx } else { 0.0 },
        allowed_kib: allowed,
        exceeded: peak > base + allowed,
    })
}

/// Baseline minute index for a run of `minutes` rows: the second minute when there are at
/// least three (the first holds start-up and the first estimate), else the first.
pub fn baseline_index(minutes: usize) -> usize {
    if minutes >= 3 {
        1
    } else {
        0
    }
}

/// Spread of a per-minute figure: (min, max) over the rows that have it.
pub fn spread(values: impl IntoIterator<Item = Option<f64>>) -> Option<(f64, f64)> {
    values.into_iter().flatten().fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((f64::min(lo, v), f64::max(hi, v))),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn proc_status_and_stat_parse() {
        let status =
            "Name:\tthrusterd\nVmPeak:\t  300000 kB\nVmHWM:\t   14512 kB\nVmRSS:\t   14000 kB\n";
        assert_eq!(
            parse_proc_status(status),
            Some(Memory {
                rss_kib: 14000,
                hwm_kib: 14512
            })
        );
        assert_eq!(parse_proc_status("Name:\tx\n"), None);
        // A command name with spaces and parentheses must not shift the fields.
        let stat = "42 (thr (d) x) S 1 42 42 0 -1 4194560 100 0 0 0 250 50 0 0 20 0 3 0";
        assert_eq!(parse_proc_stat_cpu_ticks(stat), Some(300));
        assert_eq!(parse_proc_stat_cpu_ticks("garbage"), None);
    }

    #[test]
    fn uncounted_samples_are_what_the_daemon_neither_accepted_nor_rejected() {
        let mut s = StatusMsg {
            samples: 0,
            vehicle_time_ns: 0,
            ..StatusMsg::default()
        };
        assert_eq!(DaemonCounts::of(&s, 1_000_000).uncounted(), 0);
        // Newest accepted sample is seq 1000 (t = 999 ms); 990 accepted + 4 rejected.
        s.samples = 990;
        s.rejected_time = 3;
        s.rejected_range = 1;
        s.vehicle_time_ns = 999_000_000;
        let c = DaemonCounts::of(&s, 1_000_000);
        assert_eq!(c.last_seq, 1000);
        assert_eq!(c.rejected, 4);
        assert_eq!(c.uncounted(), 6);
        // Every sample accounted for.
        s.samples = 996;
        assert_eq!(DaemonCounts::of(&s, 1_000_000).uncounted(), 0);
    }

    #[test]
    fn rows_are_differences_of_snapshots() {
        let a = Snapshot {
            published: 1_000,
            answered: 990,
            unanswered: 2,
            daemon: DaemonCounts {
                accepted: 995,
                rejected: 0,
                last_seq: 1_000,
            },
        };
        let b = Snapshot {
            published: 61_000,
            answered: 60_990,
            unanswered: 3,
            daemon: DaemonCounts {
                accepted: 60_990,
                rejected: 1,
                last_seq: 61_000,
            },
        };
        let mut h = LatencyHistogram::default();
        h.record(25_000);
        let mut row = MinuteRow::default();
        b.fill(&a, &h, &mut row);
        assert_eq!(
            (row.published, row.answered, row.unanswered),
            (60_000, 60_000, 1)
        );
        assert_eq!((row.daemon_accepted, row.daemon_rejected), (59_995, 1));
        // 5 uncounted before, 9 now.
        assert_eq!(row.uncounted, 4);
        assert_eq!(row.p50_us, Some(25.0));
    }

    #[test]
    fn growth_against_the_baseline() {
        let limit = GrowthLimit {
            abs_kib: 1024,
            rel: 0.05,
        };
        // Start-up growth before the baseline is ignored; flat after it passes.
        let flat = [8_000, 20_000, 20_100, 20_050, 20_200];
        let g = memory_growth(&flat, 1, limit).unwrap();
        assert_eq!(g.allowed_kib, 1024);
        assert!(!g.exceeded, "{g:?}");
        assert!(g.slope_kib_per_min.abs() < 100.0);
        // A leak of 400 KiB a minute passes the allowance after a few minutes.
        let leak: Vec<u64> = (0..8).map(|m| 20_000 + m * 400).collect();
        let g = memory_growth(&leak, 1, limit).unwrap();
        assert!(g.exceeded, "{g:?}");
        assert!((g.slope_kib_per_min - 400.0).abs() < 1e-6);
        // The relative allowance wins for a big process.
        let big = [100_000, 100_000, 104_000];
        let g = memory_growth(&big, 1, limit).unwrap();
        assert_eq!(g.allowed_kib, 5_000);
        assert!(!g.exceeded);
        // Nothing after the baseline: no verdict.
        assert_eq!(memory_growth(&[1, 2], 1, limit), None);
        assert_eq!(baseline_index(10), 1);
        assert_eq!(baseline_index(2), 0);
    }

    #[test]
    fn spread_skips_missing() {
        assert_eq!(spread([Some(3.0), None, Some(1.0)]), Some((1.0, 3.0)));
        assert_eq!(spread([None]), None);
    }
}
