//! Whether a depth the operator asked to hold is measured.
//!
//! The controller holds only a depth it measures: a sample without one leaves the vertical
//! axis to the vehicle's buoyancy. A driver sends none when there is no sensor, and also when
//! it refuses one it does not trust (thruster-hw on a Cube, whose Bar30 ArduSub reports in no
//! message; a pressure thinner than any water's). Without this watch the status said the depth
//! was held while nothing held it. Pure: sample times in, a note out.

use serde::{Deserialize, Serialize};

/// How long a depth hold may go without a depth before the status says so, ns: longer than a
/// pressure sensor's gaps (a slow conversion, a MAVLink message lost), short enough for an
/// operator watching the vehicle sink.
pub const UNMEASURED_AFTER_NS: u64 = 1_000_000_000;

/// When the last sample with a depth came.
#[derive(Debug, Default, Clone, PartialEq, Serialize, Deserialize)]
pub struct DepthWatch {
    last_depth_ns: Option<u64>,
    /// The first sample seen, so a hold asked before any depth ever came is judged from it.
    first_sample_ns: Option<u64>,
}

impl DepthWatch {
    /// A sample at `t_ns`, with or without a depth.
    pub fn on_sample(&mut self, t_ns: u64, depth: Option<f64>) {
        self.first_sample_ns.get_or_insert(t_ns);
        if depth.is_some() {
            self.last_depth_ns = Some(t_ns);
        }
    }

    /// What the status adds at `now_ns` when `asked` (the target's depth, m) is not measured:
    /// none while a depth came within [`UNMEASURED_AFTER_NS`] or none is asked.
    pub fn note(&self, now_ns: u64, asked: Option<f64>) -> Option<String> {
        let asked = asked?;
        let since = self.last_depth_ns.or(self.first_sample_ns)?;
        let gap = now_ns.saturating_sub(since);
        (gap > UNMEASURED_AFTER_NS).then(|| {
            let what = if self.last_depth_ns.is_some() {
                format!("no depth for {:.1} s", gap as f64 * 1e-9)
            } else {
                "the driver sends no depth".to_string()
            };
            format!("depth {asked:.1} m not held: {what}")
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: u64 = 1_000_000_000;

    #[test]
    fn a_depth_hold_without_a_depth_is_said_after_a_second() {
        let mut w = DepthWatch::default();
        assert_eq!(w.note(5 * S, Some(2.0)), None, "no sample yet");
        w.on_sample(S, Some(1.9));
        assert_eq!(w.note(S + S / 2, Some(2.0)), None);
        assert_eq!(w.note(3 * S, None), None, "no depth asked");
        w.on_sample(2 * S, None);
        assert_eq!(
            w.note(2 * S, Some(2.0)),
            None,
            "a gap of a second is a sensor's"
        );
        assert_eq!(
            w.note(3 * S + S / 2, Some(2.0)).unwrap(),
            "depth 2.0 m not held: no depth for 2.5 s"
        );
        w.on_sample(4 * S, Some(2.0));
        assert_eq!(w.note(4 * S, Some(2.0)), None, "back");
        // A driver that never sent one.
        let mut w = DepthWatch::default();
        w.on_sample(10 * S, None);
        w.on_sample(12 * S, None);
        assert_eq!(
            w.note(12 * S, Some(3.25)).unwrap(),
            "depth 3.2 m not held: the driver sends no depth"
        );
    }
}
