//! The IMU stream's rate, watched. ArduPilot keeps message intervals per link and per stream;
//! a ground station that connects after us and sends REQUEST_DATA_STREAM resets them
//! (`GCS_MAVLINK::initialise_message_intervals_for_stream`): SCALED_IMU2 is in the
//! RAW_SENSORS stream, 2 Hz on ArduSub by default, so our 100 Hz IMU would drop to 2 Hz with no
//! word from anyone. When the IMU messages of a [`WINDOW_NS`] window come at under half the
//! rate asked for, the conversation asks for its rates again.

/// How long a window of counted IMU messages is, ns.
pub const WINDOW_NS: u64 = 2_000_000_000;

/// See the module docs.
#[derive(Debug, Clone, PartialEq)]
pub struct RateWatch {
    asked_hz: f64,
    /// Start of the window being counted; None while there is no link.
    window_start_ns: Option<u64>,
    count: u64,
}

impl RateWatch {
    pub fn new(asked_hz: f64) -> Self {
        RateWatch {
            asked_hz,
            window_start_ns: None,
            count: 0,
        }
    }

    /// Counting starts (again) at `now_ns`: at link-up, and after the rates were asked for.
    pub fn restart(&mut self, now_ns: u64) {
        self.window_start_ns = Some(now_ns);
        self.count = 0;
    }

    /// No link: nothing to count.
    pub fn stop(&mut self) {
        self.window_start_ns = None;
    }

    /// An IMU message came.
    pub fn counted(&mut self) {
        self.count += 1;
    }

    /// When the window being counted closes.
    pub fn next_deadline_ns(&self) -> Option<u64> {
        self.window_start_ns.map(|t| t + WINDOW_NS)
    }

    /// At `now_ns`: the rate measured over a window that has closed, when it was under half
    /// the rate asked for (a new window starts either way).
    pub fn starved(&mut self, now_ns: u64) -> Option<f64> {
        let start = self.window_start_ns?;
        if now_ns < start + WINDOW_NS {
            return None;
        }
        let hz = self.count as f64 * 1e9 / (now_ns - start) as f64;
        self.restart(now_ns);
        (hz < 0.5 * self.asked_hz).then_some(hz)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_under_half_the_rate_asked_for_is_starved_and_one_above_is_not() {
        let mut w = RateWatch::new(100.0);
        assert_eq!(w.starved(10 * WINDOW_NS), None, "no link, no verdict");
        w.restart(0);
        for _ in 0..199 {
            w.counted();
        }
        assert_eq!(w.starved(WINDOW_NS - 1), None, "the window is still open");
        assert_eq!(w.starved(WINDOW_NS), None, "99.5 Hz");
        for _ in 0..4 {
            w.counted();
        }
        let hz = w.starved(2 * WINDOW_NS).expect("2 Hz is starved");
        assert!((hz - 2.0).abs() < 1e-9, "{hz}");
        assert_eq!(w.next_deadline_ns(), Some(3 * WINDOW_NS));
        w.stop();
        assert_eq!(w.next_deadline_ns(), None);
    }
}
