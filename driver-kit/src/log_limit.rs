//! Rate limiting of repeated warnings (a daemon sending garbage at 200 Hz must not fill the
//! journal).

use std::time::{Duration, Instant};

/// Allows a few occurrences per window, then counts the suppressed ones.
#[derive(Debug)]
pub struct LogLimiter {
    window: Duration,
    per_window: u32,
    window_end: Option<Instant>,
    logged: u32,
    suppressed: u64,
}

impl LogLimiter {
    /// `per_window` occurrences per `window`.
    pub fn new(per_window: u32, window: Duration) -> Self {
        LogLimiter {
            window,
            per_window,
            window_end: None,
            logged: 0,
            suppressed: 0,
        }
    }

    /// `Some(suppressed since the last logged one)` when this occurrence may be logged.
    pub fn allow(&mut self) -> Option<u64> {
        let now = Instant::now();
        if self.window_end.is_none_or(|end| now >= end) {
            self.window_end = Some(now + self.window);
            self.logged = 0;
        }
        if self.logged < self.per_window {
            self.logged += 1;
            Some(std::mem::take(&mut self.suppressed))
        } else {
            self.suppressed += 1;
            None
        }
    }
}

impl Default for LogLimiter {
    /// Five per ten seconds.
    fn default() -> Self {
        LogLimiter::new(5, Duration::from_secs(10))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn allows_a_few_then_counts() {
        let mut l = LogLimiter::new(2, Duration::from_secs(60));
        assert_eq!(l.allow(), Some(0));
        assert_eq!(l.allow(), Some(0));
        assert_eq!(l.allow(), None);
        assert_eq!(l.allow(), None);
        let mut l2 = LogLimiter::new(1, Duration::from_millis(1));
        assert_eq!(l2.allow(), Some(0));
        assert_eq!(l2.allow(), None);
        std::thread::sleep(Duration::from_millis(3));
        assert_eq!(l2.allow(), Some(1));
    }
}
