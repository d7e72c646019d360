//! The season soak's pure logic (the `season` binary does the processes and the clock): the
//! operator's schedule in vehicle time, the simulator's reconfiguration scenario, the
//! accounting of shared-memory files, the checkpoint rows and the "nothing grows" verdict.
//! Kept here so it is unit-tested (`cargo test -p system-tests --lib season`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// Nanoseconds per vehicle second.
pub const NS_PER_S: u64 = 1_000_000_000;

/// Intervals of a season, vehicle seconds. [`Plan::pool_day`] is what the issue asks for; a
/// short run scales every interval but the poll's by the same factor (see [`Plan::scaled`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Plan {
    /// Length of the run, vehicle s.
    pub duration_s: f64,
    /// A checkpoint row (the "vehicle-hour" of the report) every this many vehicle s.
    pub checkpoint_s: f64,
    /// An operator estimate every this many vehicle s, at half an interval's offset (so it
    /// never coincides with a reconfiguration, which re-estimates by itself).
    pub estimate_s: f64,
    /// A reconfiguration of the vehicle every this many vehicle s (the first one at this
    /// time, not at 0).
    pub reconfig_s: f64,
    /// A fresh operator client asks for the status every this many vehicle s.
    pub poll_s: f64,
    /// A new `thrusterctl watch` every this many vehicle s ...
    pub watch_every_s: f64,
    /// ... which lives this long before it is signalled (so two overlap now and then).
    pub watch_life_s: f64,
    /// A recorder session starts this long into every checkpoint interval ...
    pub record_at_s: f64,
    /// ... and records for this long (vehicle time).
    pub record_for_s: f64,
}

impl Plan {
    /// A pool day's rhythm for `hours` vehicle-hours: checkpoints every hour, an estimate
    /// every 20 minutes, a reconfiguration every hour, a status poll every second, a watch
    /// client every 7 minutes living 11, a 2-minute recording 40 minutes into each hour.
    pub fn pool_day(hours: f64) -> Plan {
        Plan {
            duration_s: hours * 3600.0,
            checkpoint_s: 3600.0,
            estimate_s: 1200.0,
            reconfig_s: 3600.0,
            poll_s: 1.0,
            watch_every_s: 420.0,
            watch_life_s: 660.0,
            record_at_s: 2400.0,
            record_for_s: 120.0,
        }
    }

    /// Every interval except the poll's multiplied by `factor` (a short CI run keeps the
    /// operator's per-second polling, which is what would leak, and compresses the rest).
    pub fn scaled(self, factor: f64) -> Plan {
        Plan {
            duration_s: self.duration_s,
            checkpoint_s: self.checkpoint_s * factor,
            estimate_s: self.estimate_s * factor,
            reconfig_s: self.reconfig_s * factor,
            poll_s: self.poll_s,
            watch_every_s: self.watch_every_s * factor,
            watch_life_s: self.watch_life_s * factor,
            record_at_s: self.record_at_s * factor,
            record_for_s: self.record_for_s * factor,
        }
    }

    /// Checks the plan makes sense (positive intervals, events inside their interval).
    pub fn validate(&self) -> Result<(), String> {
        let all = [
            ("duration", self.duration_s),
            ("checkpoint", self.checkpoint_s),
            ("estimate", self.estimate_s),
            ("reconfig", self.reconfig_s),
            ("poll", self.poll_s),
            ("watch every", self.watch_every_s),
            ("watch life", self.watch_life_s),
            ("record for", self.record_for_s),
        ];
        for (name, v) in all {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} interval must be positive, got {v}"));
            }
        }
        if !(self.record_at_s >= 0.0 && self.record_at_s + self.record_for_s < self.checkpoint_s) {
            return Err("the recording must start and end inside each checkpoint interval".into());
        }
        Ok(())
    }

    /// Vehicle ns of the end of the run.
    pub fn end_ns(&self) -> u64 {
        secs_ns(self.duration_s)
    }
}

/// Vehicle seconds as ns (rounded).
pub fn secs_ns(s: f64) -> u64 {
    (s * NS_PER_S as f64).round() as u64
}

/// A periodic event in vehicle time: occurrence k (from 0) is due at `first + k * period`,
/// while before `end`. Catching up after a stall hands out the missed occurrences one by one
/// (each is counted, none is skipped), so a run's counts depend on vehicle time only.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ticker {
    first_ns: u64,
    period_ns: u64,
    end_ns: u64,
    next: u64,
}

impl Ticker {
    /// Occurrences at `first_s + k * period_s` before `end_s`.
    pub fn new(first_s: f64, period_s: f64, end_s: f64) -> Ticker {
        Ticker {
            first_ns: secs_ns(first_s),
            period_ns: secs_ns(period_s).max(1),
            end_ns: secs_ns(end_s),
            next: 0,
        }
    }

    /// Due instant of occurrence `k`, ns.
    pub fn at(&self, k: u64) -> u64 {
        self.first_ns + k * self.period_ns
    }

    /// The next occurrence due at or before `now_ns` (its index and due instant), advancing;
    /// None when nothing is due.
    pub fn due(&mut self, now_ns: u64) -> Option<(u64, u64)> {
        let at = self.at(self.next);
        if at <= now_ns && at < self.end_ns {
            self.next += 1;
            Some((self.next - 1, at))
        } else {
            None
        }
    }

    /// Occurrences handed out so far.
    pub fn count(&self) -> u64 {
        self.next
    }

    /// Occurrences the whole run holds.
    pub fn total(&self) -> u64 {
        if self.end_ns <= self.first_ns {
            0
        } else {
            (self.end_ns - self.first_ns).div_ceil(self.period_ns)
        }
    }
}

/// How a watch client is ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Ending {
    /// SIGTERM: it must leave cleanly (exit 0, its node removed).
    Term,
    /// SIGKILL: it leaves a dead node whose resources someone else must remove.
    Kill,
}

impl Ending {
    /// Every third watch client is killed, the others terminated: the same run every time.
    pub fn of_watch(index: u64) -> Ending {
        if index % 3 == 2 {
            Ending::Kill
        } else {
            Ending::Term
        }
    }

    /// The signal name for kill(1).
    pub fn signal(self) -> &'static str {
        match self {
            Ending::Term => "TERM",
            Ending::Kill => "KILL",
        }
    }
}

/// The simulator's scenario for a season: thruster `thruster` rotated by `angle_deg` about
/// the body x axis at every reconfiguration, the sign alternating, so the vehicle swaps
/// between two configurations (the daemon's cache then swaps the known model back at once,
/// and re-estimates). Every event is announced (a ReconfigEvent with the new geometry), as
/// `thrusterctl reconfigure` would.
pub fn scenario_toml(plan: &Plan, thruster: &str, angle_deg: f64) -> String {
    let mut out = String::from(
        "# Generated by the season soak (tests/src/season.rs): a reconfiguration every interval.\n",
    );
    let mut t = Ticker::new(plan.reconfig_s, plan.reconfig_s, plan.duration_s);
    while let Some((k, at)) = t.due(u64::MAX) {
        let angle = if k % 2 == 0 { angle_deg } else { -angle_deg };
        let _ = write!(
            out,
            "\n[[event]]\nt_s = {:.3}\nannounce = true\naction = {{ kind = \"rotate\", thruster = \"{thruster}\", axis = [1, 0, 0], angle_deg = {angle} }}\n",
            at as f64 / NS_PER_S as f64
        );
    }
    out
}

/// Files of a namespace on disk, split into /dev/shm and the ipc root.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Census {
    /// Files in /dev/shm with the namespace's prefix.
    pub shm_files: u64,
    /// Their apparent size (st_size), bytes.
    pub shm_bytes: u64,
    /// Files (not folders) under the namespace's ipc root.
    pub root_files: u64,
    /// Their size, bytes.
    pub root_bytes: u64,
    /// Folders under (and including) the root.
    pub root_dirs: u64,
}

/// One entry of `namespace_files` with its metadata.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Entry {
    pub path: PathBuf,
    pub is_dir: bool,
    pub len: u64,
}

impl Census {
    /// Counts `entries`: those under `shm_dir` as shared memory, the rest as the root's.
    pub fn of(entries: &[Entry], shm_dir: &Path) -> Census {
        let mut c = Census::default();
        for e in entries {
            if e.path.starts_with(shm_dir) {
                if !e.is_dir {
                    c.shm_files += 1;
                    c.shm_bytes += e.len;
                }
            } else if e.is_dir {
                c.root_dirs += 1;
            } else {
                c.root_files += 1;
                c.root_bytes += e.len;
            }
        }
        c
    }
}

/// Counters of one process, from /proc.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ProcFigures {
    /// Resident set size, KiB.
    pub rss_kib: u64,
    /// Open file descriptors.
    pub fds: u64,
}

/// The link's counters at one instant.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Link {
    /// IMU samples the simulator has published (from the daemon's newest sample time, see
    /// [`crate::soak::DaemonCounts`]).
    pub published: u64,
    /// Accepted by the daemon.
    pub accepted: u64,
    /// Sequence gaps the daemon saw between accepted samples.
    pub missed: u64,
    /// Rejected (and counted) by the daemon.
    pub rejected: u64,
    /// Published but neither accepted nor rejected.
    pub uncounted: u64,
    /// Commands the simulator applied (its driver status).
    pub commands_applied: u64,
    /// Commands it rejected (wrong sample, count, non-finite ...).
    pub commands_rejected: u64,
    /// Lockstep samples with no answer within the simulator's timeout.
    pub unanswered: u64,
}

impl Link {
    /// Samples lost on the way to the daemon: gaps it saw plus samples it never counted.
    pub fn imu_lost(&self) -> u64 {
        self.missed + self.uncounted
    }

    /// Commands that did not answer their sample in time: rejected or never came.
    pub fn commands_late(&self) -> u64 {
        self.commands_rejected + self.unanswered
    }
}

/// One row of the report: the state at a checkpoint.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Row {
    /// "start", "h1", "h2", ..., "end".
    pub label: String,
    /// Vehicle time, s.
    pub vehicle_s: f64,
    /// Wall time since the start row, s.
    pub wall_s: f64,
    /// Daemon state name and model version.
    pub state: String,
    pub model_version: u64,
    pub link: Link,
    pub daemon: ProcFigures,
    pub sim: ProcFigures,
    pub files: Census,
    /// Operator polls so far: real `thrusterctl status` processes and in-process fresh
    /// clients; polls that failed.
    pub polls_process: u64,
    pub polls_inproc: u64,
    pub polls_failed: u64,
    /// Watch clients started so far, and alive at this row.
    pub watches_started: u64,
    pub watches_alive: u64,
    /// Estimates asked for (refused ones in `estimates_refused`), reconfigurations seen.
    pub estimates: u64,
    pub estimates_refused: u64,
    pub reconfigs: u64,
    /// Recorder sessions so far and the files they rotated through.
    pub recordings: u64,
    pub recorded_files: u64,
}

/// What the verdict tolerates. Rationale in docs/reliability.md ("Season soak").
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Limits {
    /// RSS may exceed its value at the first checkpoint by this much (KiB) ...
    pub rss_abs_kib: u64,
    /// ... or this share of it, whichever is larger.
    pub rss_rel: f64,
    /// Open descriptors at the end (every client gone) may exceed the start by this many.
    /// Not judged at the checkpoints: each connected client holds a few of the daemon's, and
    /// how many clients are connected at a checkpoint's instant varies.
    pub fd_slack: u64,
    /// Files in /dev/shm and under the root at the end (every client gone) may exceed the
    /// start (same processes up) by this many: 0, nothing per call may stay.
    pub file_slack: u64,
    /// ... and bytes by this many.
    pub byte_slack: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            rss_abs_kib: 2048,
            rss_rel: 0.10,
            fd_slack: 8,
            file_slack: 0,
            byte_slack: 0,
        }
    }
}

/// What a failed check found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    /// Short name of what grew or went wrong, e.g. "daemon RSS".
    pub what: String,
    /// The figures.
    pub detail: String,
}

/// The season's verdict over its rows: `rows[0]` the start (daemon and simulator up, no
/// client yet), `rows[last]` the end (every client gone, daemon and simulator still up), the
/// checkpoints between. Memory is judged from the first checkpoint on (the first interval
/// holds the first estimate, reconfiguration, recording and the model cache filling);
/// descriptors, files and bytes at the end against the start. Empty when nothing grew.
pub fn verdict(rows: &[Row], limits: &Limits) -> Vec<Finding> {
    let mut out = Vec::new();
    let (Some(start), Some(end)) = (rows.first(), rows.last()) else {
        return vec![Finding {
            what: "rows".into(),
            detail: "no rows".into(),
        }];
    };
    if end.link.imu_lost() > 0 {
        out.push(Finding {
            what: "IMU samples lost".into(),
            detail: format!(
                "{} ({} gaps seen by the daemon, {} uncounted)",
                end.link.imu_lost(),
                end.link.missed,
                end.link.uncounted
            ),
        });
    }
    if end.link.commands_late() > 0 {
        out.push(Finding {
            what: "commands late".into(),
            detail: format!(
                "{} ({} rejected by the simulator, {} unanswered)",
                end.link.commands_late(),
                end.link.commands_rejected,
                end.link.unanswered
            ),
        });
    }
    if end.polls_failed > 0 {
        out.push(Finding {
            what: "operator polls failed".into(),
            detail: format!("{}", end.polls_failed),
        });
    }
    // The reference for memory and descriptors: the first checkpoint after the start (or the
    // start when the run had none).
    let reference = rows.get(1).filter(|_| rows.len() > 2).unwrap_or(start);
    let after = rows
        .iter()
        .skip_while(|r| !std::ptr::eq(*r, reference))
        .skip(1);
    for (name, get) in [
        ("daemon", (|r: &Row| r.daemon) as fn(&Row) -> ProcFigures),
        ("simulator", |r: &Row| r.sim),
    ] {
        let base = get(reference);
        let allowed = limits
            .rss_abs_kib
            .max((base.rss_kib as f64 * limits.rss_rel).round() as u64);
        if let Some(peak) = after.clone().max_by_key(|r| get(r).rss_kib) {
            if get(peak).rss_kib > base.rss_kib + allowed {
                out.push(Finding {
                    what: format!("{name} RSS"),
                    detail: format!(
                        "{} KiB at {} against {} KiB at {} (allowed +{allowed} KiB)",
                        get(peak).rss_kib,
                        peak.label,
                        base.rss_kib,
                        reference.label
                    ),
                });
            }
        }
        let (s, e) = (get(start).fds, get(end).fds);
        if e > s + limits.fd_slack {
            out.push(Finding {
                what: format!("{name} open file descriptors"),
                detail: format!(
                    "{s} at the start, {e} at the end after every client left (allowed +{})",
                    limits.fd_slack
                ),
            });
        }
    }
    let (a, b) = (start.files, end.files);
    for (what, s, e, slack) in [
        (
            "/dev/shm files",
            a.shm_files,
            b.shm_files,
            limits.file_slack,
        ),
        (
            "/dev/shm bytes",
            a.shm_bytes,
            b.shm_bytes,
            limits.byte_slack,
        ),
        (
            "ipc root files",
            a.root_files,
            b.root_files,
            limits.file_slack,
        ),
        (
            "ipc root bytes",
            a.root_bytes,
            b.root_bytes,
            limits.byte_slack,
        ),
    ] {
        if e > s + slack {
            let calls = end.polls_process + end.polls_inproc;
            out.push(Finding {
                what: what.into(),
                detail: format!(
                    "{s} at the start, {e} at the end after every client left (+{}; {:.2} per 1000 operator polls)",
                    e - s,
                    (e - s) as f64 * 1000.0 / calls.max(1) as f64
                ),
            });
        }
    }
    out
}

/// The report's table header (Markdown).
pub const HEADER: &str = "| row | vehicle h | wall s | state | model | IMU published | IMU lost | commands late | daemon RSS KiB | daemon fds | sim RSS KiB | sim fds | /dev/shm files | /dev/shm KiB | root files | root KiB | polls (proc + in-proc) | watches | estimates | reconfigs | recordings (files) |";

/// One row of the table.
pub fn row_text(r: &Row) -> String {
    format!(
        "| {} | {:.2} | {:.0} | {} | v{} | {} | {} | {} | {} | {} | {} | {} | {} | {:.0} | {} | {:.0} | {} + {} | {} ({} alive) | {} ({} refused) | {} | {} ({}) |",
        r.label,
        r.vehicle_s / 3600.0,
        r.wall_s,
        r.state,
        r.model_version,
        r.link.published,
        r.link.imu_lost(),
        r.link.commands_late(),
        r.daemon.rss_kib,
        r.daemon.fds,
        r.sim.rss_kib,
        r.sim.fds,
        r.files.shm_files,
        r.files.shm_bytes as f64 / 1024.0,
        r.files.root_files,
        r.files.root_bytes as f64 / 1024.0,
        r.polls_process,
        r.polls_inproc,
        r.watches_started,
        r.watches_alive,
        r.estimates,
        r.estimates_refused,
        r.reconfigs,
        r.recordings,
        r.recorded_files,
    )
}

/// Vehicle-time lag of the operator's actions: how far behind their due instant they ran.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Lag {
    /// Actions recorded.
    pub count: u64,
    /// Sum and largest lag, vehicle s.
    pub sum_s: f64,
    pub max_s: f64,
}

impl Lag {
    /// Records an action due at `due_ns` that ran at `now_ns`.
    pub fn record(&mut self, due_ns: u64, now_ns: u64) {
        let lag = now_ns.saturating_sub(due_ns) as f64 / NS_PER_S as f64;
        self.count += 1;
        self.sum_s += lag;
        self.max_s = self.max_s.max(lag);
    }

    /// Mean lag, vehicle s.
    pub fn mean_s(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum_s / self.count as f64
        }
    }
}

/// The number after `key=` in a log line of `key=value` fields (quotes allowed), e.g. the
/// simulator's `thruster-sim stopped ... samples=120001 applied=120001 stale=0`.
pub fn field_u64(line: &str, key: &str) -> Option<u64> {
    line.split_whitespace()
        .find_map(|f| f.strip_prefix(key)?.strip_prefix('='))
        .and_then(|v| v.trim_matches('"').parse().ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tickers_hand_out_every_occurrence_once_in_vehicle_time() {
        // Estimates at 10, 30, 50 min of a 1 h run.
        let mut t = Ticker::new(600.0, 1200.0, 3600.0);
        assert_eq!(t.total(), 3);
        assert_eq!(t.due(secs_ns(599.999)), None);
        assert_eq!(t.due(secs_ns(600.0)), Some((0, secs_ns(600.0))));
        assert_eq!(t.due(secs_ns(600.0)), None);
        // A stall past two due instants catches up one by one, never skipping.
        assert_eq!(t.due(secs_ns(3000.0)), Some((1, secs_ns(1800.0))));
        assert_eq!(t.due(secs_ns(3000.0)), Some((2, secs_ns(3000.0))));
        assert_eq!(t.due(u64::MAX), None, "nothing at or after the end");
        assert_eq!(t.count(), 3);
        // Polls every second of 8 h: 28,800.
        assert_eq!(Ticker::new(1.0, 1.0, 8.0 * 3600.0 + 0.5).total(), 28_800);
        assert_eq!(Ticker::new(5.0, 1.0, 5.0).total(), 0);
    }

    #[test]
    fn the_plan_of_a_pool_day_and_its_short_version() {
        let p = Plan::pool_day(8.0);
        assert_eq!(p.end_ns(), 8 * 3600 * NS_PER_S);
        p.validate().unwrap();
        let s = Plan::pool_day(0.25).scaled(1.0 / 16.0);
        s.validate().unwrap();
        assert_eq!(s.checkpoint_s, 225.0);
        assert_eq!(s.estimate_s, 75.0);
        assert_eq!(s.poll_s, 1.0, "polls stay every vehicle second");
        // A recording that would run past its interval is refused.
        let bad = Plan {
            record_at_s: 3500.0,
            ..p
        };
        assert!(bad.validate().is_err());
        assert!(Plan { poll_s: 0.0, ..p }.validate().is_err());
    }

    #[test]
    fn the_scenario_alternates_and_loads() {
        let p = Plan::pool_day(3.0);
        let text = scenario_toml(&p, "T", 45.0);
        // Reconfigurations at 1 h and 2 h (not at the end, 3 h): +45 then -45 degrees.
        assert_eq!(text.matches("[[event]]").count(), 2, "{text}");
        assert!(text.contains("t_s = 3600.000"), "{text}");
        assert!(text.contains("t_s = 7200.000"), "{text}");
        assert!(text.contains("angle_deg = 45 }"), "{text}");
        assert!(text.contains("angle_deg = -45 }"), "{text}");
        // The simulator's own parser accepts it (and finds the events).
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("season.toml");
        std::fs::write(&path, &text).unwrap();
        let sc = thruster_sim::scenario::Scenario::load(&path).unwrap();
        assert_eq!(sc.events().len(), 2);
    }

    #[test]
    fn every_third_watch_is_killed() {
        let e: Vec<Ending> = (0..6).map(Ending::of_watch).collect();
        assert_eq!(
            e,
            [
                Ending::Term,
                Ending::Term,
                Ending::Kill,
                Ending::Term,
                Ending::Term,
                Ending::Kill
            ]
        );
        assert_eq!(Ending::Kill.signal(), "KILL");
    }

    #[test]
    fn census_splits_shm_and_root() {
        let e = |p: &str, is_dir, len| Entry {
            path: PathBuf::from(p),
            is_dir,
            len,
        };
        let entries = [
            e("/dev/shm/thr_ns_a.dynamic", false, 4096),
            e("/dev/shm/thr_ns_b.data", false, 8192),
            e("/tmp/iceoryx2/thr/ns", true, 4096),
            e("/tmp/iceoryx2/thr/ns/nodes", true, 4096),
            e("/tmp/iceoryx2/thr/ns/services/thr_ns_x.service", false, 300),
        ];
        let c = Census::of(&entries, Path::new("/dev/shm"));
        assert_eq!(
            c,
            Census {
                shm_files: 2,
                shm_bytes: 12288,
                root_files: 1,
                root_bytes: 300,
                root_dirs: 2
            }
        );
    }

    fn row(label: &str, rss: u64, fds: u64, shm: u64) -> Row {
        Row {
            label: label.into(),
            daemon: ProcFigures { rss_kib: rss, fds },
            sim: ProcFigures {
                rss_kib: 8000,
                fds: 20,
            },
            files: Census {
                shm_files: shm,
                shm_bytes: shm * 4096,
                ..Census::default()
            },
            polls_inproc: 4000,
            ..Row::default()
        }
    }

    #[test]
    fn a_flat_season_passes() {
        // Start-up growth before the first checkpoint is not judged.
        let rows = [
            row("start", 10_000, 30, 50),
            row("h1", 14_000, 40, 58),
            // Clients connected at a checkpoint hold descriptors of the daemon's: not judged.
            row("h2", 14_100, 70, 57),
            row("end", 14_200, 38, 50),
        ];
        assert_eq!(verdict(&rows, &Limits::default()), vec![]);
    }

    #[test]
    fn what_grew_is_named() {
        let rows = [
            row("start", 10_000, 30, 50),
            row("h1", 14_000, 40, 58),
            row("h2", 17_000, 80, 4058),
            row("end", 17_000, 41, 4050),
        ];
        let f = verdict(&rows, &Limits::default());
        let names: Vec<&str> = f.iter().map(|f| f.what.as_str()).collect();
        assert_eq!(
            names,
            [
                "daemon RSS",
                "daemon open file descriptors",
                "/dev/shm files",
                "/dev/shm bytes"
            ],
            "{f:?}"
        );
        assert!(f[2].detail.contains("+4000"), "{}", f[2].detail);
        assert!(f[2].detail.contains("1000.00 per 1000"), "{}", f[2].detail);
    }

    #[test]
    fn lost_samples_late_commands_and_failed_polls_fail() {
        let mut end = row("end", 10_000, 30, 50);
        end.link = Link {
            missed: 1,
            uncounted: 2,
            unanswered: 1,
            ..Link::default()
        };
        end.polls_failed = 1;
        let rows = [row("start", 10_000, 30, 50), end];
        let f = verdict(&rows, &Limits::default());
        let names: Vec<&str> = f.iter().map(|f| f.what.as_str()).collect();
        assert_eq!(
            names,
            ["IMU samples lost", "commands late", "operator polls failed"]
        );
        assert!(f[0].detail.starts_with("3 "));
        assert_eq!(verdict(&[], &Limits::default()).len(), 1);
    }

    #[test]
    fn lag_is_measured_in_vehicle_time() {
        let mut l = Lag::default();
        l.record(secs_ns(10.0), secs_ns(10.5));
        l.record(secs_ns(11.0), secs_ns(11.0));
        l.record(secs_ns(12.0), secs_ns(11.0)); // early counts as none
        assert_eq!(l.count, 3);
        assert!((l.max_s - 0.5).abs() < 1e-9);
        assert!((l.mean_s() - 0.5 / 3.0).abs() < 1e-9);
    }

    #[test]
    fn fields_of_the_simulators_summary_line() {
        let l = "INFO thruster_sim::driver: thruster-sim stopped reason=Signal vehicle_s=600.0 wall_s=\"5.516\" samples=120001 applied=120000 timeouts=0 rejected=0 stale=3 clipped=0";
        assert_eq!(field_u64(l, "samples"), Some(120_001));
        assert_eq!(field_u64(l, "applied"), Some(120_000));
        assert_eq!(field_u64(l, "stale"), Some(3));
        assert_eq!(field_u64(l, "wall_s"), None, "not an integer");
        assert_eq!(field_u64(l, "missing"), None);
        assert_eq!(field_u64(l, "ple"), None, "whole keys only");
    }

    #[test]
    fn rows_print_as_markdown() {
        let r = row("h1", 14_000, 40, 58);
        let cols = |s: &str| s.matches('|').count();
        assert_eq!(cols(&row_text(&r)), cols(HEADER));
    }
}
