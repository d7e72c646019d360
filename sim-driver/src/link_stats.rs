//! Link statistics of a real-time run: which IMU samples got an answer, and how long the
//! answer took (sample published -> thrust command received by the driver, the plant's view of
//! the daemon's latency).
//!
//! Pure (times are nanoseconds from any origin the caller picks), so the soak tool and the
//! unit tests use the same accounting and percentiles as the driver that records them. The
//! driver writes one [`StatsLine`] (JSON) per second with `thruster-sim run --stats-file`;
//! the soak (`cargo run --release -p system-tests --bin soak`) merges them per minute.

use serde::{Deserialize, Serialize};

/// Histogram bucket count: 1 us buckets below 1 ms, 100 us below 100 ms, 10 ms below 10 s,
/// and one overflow bucket. Fine where latencies live (tens of microseconds), bounded where a
/// stall would put them.
const BUCKETS: usize = 1000 + 990 + 990 + 1;

/// Bucket of a latency in microseconds.
fn bucket(us: u64) -> usize {
    match us {
        0..1_000 => us as usize,
        1_000..100_000 => 1_000 + ((us - 1_000) / 100) as usize,
        100_000..10_000_000 => 1_990 + ((us - 100_000) / 10_000) as usize,
        _ => BUCKETS - 1,
    }
}

/// Upper edge of bucket `i`, microseconds (the overflow bucket has none: `f64::INFINITY`).
fn bucket_upper_us(i: usize) -> f64 {
    match i {
        0..1_000 => (i + 1) as f64,
        1_000..1_990 => 1_000.0 + ((i - 1_000 + 1) * 100) as f64,
        1_990..2_980 => 100_000.0 + ((i - 1_990 + 1) * 10_000) as f64,
        _ => f64::INFINITY,
    }
}

/// Latency histogram with mergeable buckets and the exact maximum.
///
/// Serialised sparse (only non-empty buckets), so a one-second window of a 1 kHz stream is a
/// few hundred bytes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(from = "SparseHistogram", into = "SparseHistogram")]
pub struct LatencyHistogram {
    counts: Vec<u64>,
    count: u64,
    sum_ns: u64,
    max_ns: u64,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        LatencyHistogram {
            counts: vec![0; BUCKETS],
            count: 0,
            sum_ns: 0,
            max_ns: 0,
        }
    }
}

impl LatencyHistogram {
    /// Adds one latency, ns.
    pub fn record(&mut self, ns: u64) {
        self.counts[bucket(ns / 1_000)] += 1;
        self.count += 1;
        self.sum_ns = self.sum_ns.saturating_add(ns);
        self.max_ns = self.max_ns.max(ns);
    }

    /// Adds every latency of `other`.
    pub fn merge(&mut self, other: &LatencyHistogram) {
        for (a, b) in self.counts.iter_mut().zip(&other.counts) {
            *a += b;
        }
        self.count += other.count;
        self.sum_ns = self.sum_ns.saturating_add(other.sum_ns);
        self.max_ns = self.max_ns.max(other.max_ns);
    }

    /// Latencies recorded.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Largest latency, us (exact); None when empty.
    pub fn max_us(&self) -> Option<f64> {
        (self.count > 0).then(|| self.max_ns as f64 / 1e3)
    }

    /// Mean latency, us; None when empty.
    pub fn mean_us(&self) -> Option<f64> {
        (self.count > 0).then(|| self.sum_ns as f64 / self.count as f64 / 1e3)
    }

    /// The `q` quantile (0..=1), us: the upper edge of the bucket holding it (never above the
    /// exact maximum), so it errs high by at most one bucket width. None when empty.
    pub fn quantile_us(&self, q: f64) -> Option<f64> {
        if self.count == 0 {
            return None;
        }
        // Rank of the quantile, 1-based: the smallest value with at least q of the samples
        // at or below it.
        let rank = ((q.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (i, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return Some(bucket_upper_us(i).min(self.max_ns as f64 / 1e3));
            }
        }
        self.max_us()
    }
}

/// Wire form of [`LatencyHistogram`]: `[bucket index, count]` pairs of non-empty buckets.
#[derive(Serialize, Deserialize)]
struct SparseHistogram {
    buckets: Vec<(u32, u64)>,
    count: u64,
    sum_ns: u64,
    max_ns: u64,
}

impl From<LatencyHistogram> for SparseHistogram {
    fn from(h: LatencyHistogram) -> Self {
        SparseHistogram {
            buckets: h
                .counts
                .iter()
                .enumerate()
                .filter(|(_, &c)| c > 0)
                .map(|(i, &c)| (i as u32, c))
                .collect(),
            count: h.count,
            sum_ns: h.sum_ns,
            max_ns: h.max_ns,
        }
    }
}

impl From<SparseHistogram> for LatencyHistogram {
    fn from(s: SparseHistogram) -> Self {
        let mut h = LatencyHistogram {
            count: s.count,
            sum_ns: s.sum_ns,
            max_ns: s.max_ns,
            ..LatencyHistogram::default()
        };
        // Out-of-range indices (a file from a build with more buckets) land in overflow.
        for (i, c) in s.buckets {
            h.counts[(i as usize).min(BUCKETS - 1)] += c;
        }
        h
    }
}

/// Samples remembered for matching answers: an answer later than this many sample periods
/// (256 ms at 1 kHz) counts its sample as unanswered.
pub const ANSWER_WINDOW: usize = 256;

#[derive(Debug, Clone, Copy, Default)]
struct Slot {
    seq: u64,
    published_ns: u64,
    answered: bool,
}

/// Matches thrust commands to the IMU samples they answer (by `imu_seq`) and counts every
/// sample exactly once: answered, unanswered (no answer within [`ANSWER_WINDOW`] samples) or
/// still pending.
#[derive(Debug, Clone)]
pub struct AnswerTracker {
    slots: Vec<Slot>,
    published: u64,
    answered: u64,
    unanswered: u64,
    /// Latencies of answers since the last [`AnswerTracker::take_window`].
    window: LatencyHistogram,
}

impl Default for AnswerTracker {
    fn default() -> Self {
        AnswerTracker {
            slots: vec![Slot::default(); ANSWER_WINDOW],
            published: 0,
            answered: 0,
            unanswered: 0,
            window: LatencyHistogram::default(),
        }
    }
}

impl AnswerTracker {
    /// Sample `seq` (>= 1, increasing) was published at `t_ns`.
    pub fn published(&mut self, seq: u64, t_ns: u64) {
        let slot = &mut self.slots[(seq % ANSWER_WINDOW as u64) as usize];
        if slot.seq != 0 && !slot.answered {
            self.unanswered += 1;
        }
        *slot = Slot {
            seq,
            published_ns: t_ns,
            answered: false,
        };
        self.published += 1;
    }

    /// A command answering sample `imu_seq` arrived at `t_ns`; the latency when it is the
    /// first answer to a sample still in the window (repeats and very late answers: None).
    pub fn answered(&mut self, imu_seq: u64, t_ns: u64) -> Option<u64> {
        let slot = &mut self.slots[(imu_seq % ANSWER_WINDOW as u64) as usize];
        if imu_seq == 0 || slot.seq != imu_seq || slot.answered {
            return None;
        }
        slot.answered = true;
        self.answered += 1;
        let latency = t_ns.saturating_sub(slot.published_ns);
        self.window.record(latency);
        Some(latency)
    }

    /// Samples published.
    pub fn published_count(&self) -> u64 {
        self.published
    }

    /// Samples answered.
    pub fn answered_count(&self) -> u64 {
        self.answered
    }

    /// Samples whose answer did not come within the window.
    pub fn unanswered_count(&self) -> u64 {
        self.unanswered
    }

    /// Samples still waiting for their answer (published - answered - unanswered).
    pub fn pending_count(&self) -> u64 {
        self.published - self.answered - self.unanswered
    }

    /// The latencies since the last call, and a fresh window.
    pub fn take_window(&mut self) -> LatencyHistogram {
        std::mem::take(&mut self.window)
    }
}

/// One line of `thruster-sim run --stats-file` (JSON lines). Counters are cumulative since
/// the start; `latency` covers only the answers since the previous line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StatsLine {
    /// Wall time since the first sample, s.
    pub wall_s: f64,
    /// Vehicle (simulation) time, s.
    pub vehicle_s: f64,
    /// IMU samples published.
    pub published: u64,
    /// Samples answered by a valid thrust command (first answer per sample).
    pub answered: u64,
    /// Samples with no valid answer within [`ANSWER_WINDOW`] samples.
    pub unanswered: u64,
    /// Samples still waiting for an answer when the line was written.
    pub pending: u64,
    /// Thrust commands applied (accepted by the gate).
    pub applied: u64,
    /// Valid but late commands dropped.
    pub stale: u64,
    /// Commands rejected by the gate (every category).
    pub rejected: u64,
    /// Sample -> answer latency of the answers since the previous line.
    pub latency: LatencyHistogram,
    /// How late each sample since the previous line was published after its due instant
    /// (wall clock against vehicle time): the driver's own pacing. Added when a sleep on a
    /// socket timeout was found to oversleep 1 kHz deadlines by ~7 ms, invisibly to
    /// `latency` (a burst of overdue samples is answered quickly). Absent in older files.
    #[serde(default)]
    pub pacing: LatencyHistogram,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_are_monotonic_and_cover_the_range() {
        let mut last = 0;
        for us in [
            0, 1, 999, 1_000, 1_099, 1_100, 99_999, 100_000, 9_999_999, 10_000_000,
        ] {
            let b = bucket(us);
            assert!(b >= last, "{us}");
            assert!(
                bucket_upper_us(b) > us as f64,
                "{us} above its bucket's edge"
            );
            last = b;
        }
        assert_eq!(bucket(u64::MAX), BUCKETS - 1);
        assert_eq!(bucket_upper_us(BUCKETS - 2), 10_000_000.0);
    }

    #[test]
    fn quantiles_of_known_values() {
        let mut h = LatencyHistogram::default();
        assert_eq!(h.quantile_us(0.5), None);
        // 1..=100 us, one each.
        for us in 1..=100u64 {
            h.record(us * 1_000 + 300);
        }
        assert_eq!(h.count(), 100);
        // The 50th value is 50.3 us: its bucket [50, 51) reports 51.
        assert_eq!(h.quantile_us(0.5), Some(51.0));
        assert_eq!(h.quantile_us(0.99), Some(100.0));
        // The top quantile never exceeds the exact maximum.
        assert_eq!(h.quantile_us(1.0), Some(100.3));
        assert_eq!(h.max_us(), Some(100.3));
        assert!((h.mean_us().unwrap() - 50.8).abs() < 1e-9);
    }

    #[test]
    fn merge_equals_recording_everything_once_and_survives_json() {
        let mut a = LatencyHistogram::default();
        let mut b = LatencyHistogram::default();
        let mut all = LatencyHistogram::default();
        for (i, ns) in [5_000u64, 20_000, 2_500_000, 150_000_000, 40_000]
            .into_iter()
            .enumerate()
        {
            if i % 2 == 0 {
                a.record(ns);
            } else {
                b.record(ns);
            }
            all.record(ns);
        }
        let json = serde_json::to_string(&a).unwrap();
        let mut merged: LatencyHistogram = serde_json::from_str(&json).unwrap();
        merged.merge(&b);
        assert_eq!(merged, all);
        assert_eq!(merged.max_us(), Some(150_000.0));
    }

    #[test]
    fn every_sample_is_counted_once() {
        let mut t = AnswerTracker::default();
        t.published(1, 0);
        t.published(2, 1_000_000);
        assert_eq!(t.answered(1, 30_000), Some(30_000));
        // A repeated answer and one for an unknown sample count nothing.
        assert_eq!(t.answered(1, 40_000), None);
        assert_eq!(t.answered(99, 40_000), None);
        assert_eq!(t.pending_count(), 1);
        // Sample 2 is never answered: it turns unanswered when its slot is reused.
        for seq in 3..(3 + ANSWER_WINDOW as u64) {
            t.published(seq, seq * 1_000_000);
            t.answered(seq, seq * 1_000_000 + 20_000);
        }
        assert_eq!(t.unanswered_count(), 1);
        assert_eq!(t.answered_count(), 1 + ANSWER_WINDOW as u64);
        assert_eq!(t.published_count(), 2 + ANSWER_WINDOW as u64);
        assert_eq!(t.pending_count(), 0);
        let w = t.take_window();
        assert_eq!(w.count(), t.answered_count());
        assert_eq!(t.take_window().count(), 0);
    }
}
