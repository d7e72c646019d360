//! `--stats-file`: the real-time loop's link statistics, one JSON line per second.
//!
//! Added for the soak run (docs/reliability.md): the driver is the one place that knows both
//! when a sample was published and when its answer arrived, so the plant-side latency and the
//! unanswered samples are measured here. Off unless the flag is given; when on, the cost per
//! sample is two slot writes and a histogram increment (the file is written once a second).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::link_stats::{AnswerTracker, LatencyHistogram, StatsLine};

/// How often a line is written, wall time.
const PERIOD: Duration = Duration::from_secs(1);

/// Failure to create or write the stats file.
#[derive(Debug, thiserror::Error)]
// The OS error is in the message and not a `source`: a chain printed whole ("{:#}") said it
// twice.
#[error("stats file {path}: {error}")]
pub struct StatsFileError {
    path: PathBuf,
    error: std::io::Error,
}

/// The tracker and its file.
#[derive(Debug)]
pub struct StatsFile {
    path: PathBuf,
    out: BufWriter<File>,
    tracker: AnswerTracker,
    pacing: LatencyHistogram,
    origin: Instant,
    next_write: Instant,
}

impl StatsFile {
    /// Creates (truncates) `path`.
    pub fn create(path: &Path) -> Result<StatsFile, StatsFileError> {
        let file = File::create(path).map_err(|error| StatsFileError {
            path: path.to_path_buf(),
            error,
        })?;
        let now = Instant::now();
        Ok(StatsFile {
            path: path.to_path_buf(),
            out: BufWriter::new(file),
            tracker: AnswerTracker::default(),
            pacing: LatencyHistogram::default(),
            origin: now,
            next_write: now + PERIOD,
        })
    }

    fn now_ns(&self) -> u64 {
        u64::try_from(self.origin.elapsed().as_nanos()).unwrap_or(u64::MAX)
    }

    /// Sample `seq` was just published.
    pub fn published(&mut self, seq: u64) {
        let t = self.now_ns();
        self.tracker.published(seq, t);
    }

    /// A sample was published `late` after its due instant.
    pub fn paced(&mut self, late: Duration) {
        self.pacing
            .record(u64::try_from(late.as_nanos()).unwrap_or(u64::MAX));
    }

    /// A valid command answering `imu_seq` arrived at `at`.
    pub fn answered(&mut self, imu_seq: u64, at: Instant) {
        let t =
            u64::try_from(at.saturating_duration_since(self.origin).as_nanos()).unwrap_or(u64::MAX);
        self.tracker.answered(imu_seq, t);
    }

    /// Writes a line when one is due (or `force`). `counters` = (applied, stale, rejected) of
    /// the command gate; times in s.
    pub fn tick(
        &mut self,
        force: bool,
        wall_s: f64,
        vehicle_s: f64,
        counters: (u64, u64, u64),
    ) -> Result<(), StatsFileError> {
        let now = Instant::now();
        if !force && now < self.next_write {
            return Ok(());
        }
        self.next_write = now + PERIOD;
        let (applied, stale, rejected) = counters;
        let line = StatsLine {
            wall_s,
            vehicle_s,
            published: self.tracker.published_count(),
            answered: self.tracker.answered_count(),
            unanswered: self.tracker.unanswered_count(),
            pending: self.tracker.pending_count(),
            applied,
            stale,
            rejected,
            latency: self.tracker.take_window(),
            pacing: std::mem::take(&mut self.pacing),
        };
        // Serialising plain numbers cannot fail; writing can.
        let text = serde_json::to_string(&line).unwrap_or_default();
        writeln!(self.out, "{text}")
            .and_then(|()| self.out.flush())
            .map_err(|error| StatsFileError {
                path: self.path.clone(),
                error,
            })
    }
}
