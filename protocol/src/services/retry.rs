//! Retry of iceoryx2 creation calls that can lose a race against another process.
//!
//! `open_or_create` of a service (and node creation) is not atomic across processes in
//! iceoryx2 0.10: when the daemon and a driver start at the same moment, both may find the
//! service missing, and the one that loses the creation race gets an error although the
//! service is usable a moment later (upstream eclipse-iceoryx/iceoryx2 #108, #1578, #1650). On
//! a vehicle that is exactly what systemd does at boot, so every creation here is retried for
//! a short while. A permanent error (incompatible types, a full namespace) costs only that
//! delay before it is reported.

use std::time::{Duration, Instant};

/// How long a creation keeps being retried.
pub(crate) const CREATION_RETRY_FOR: Duration = Duration::from_secs(2);
/// Pause between attempts.
const CREATION_RETRY_PAUSE: Duration = Duration::from_millis(10);

/// `attempt` until it succeeds or `CREATION_RETRY_FOR` has passed; the last error otherwise.
pub(crate) fn retry_creation<T, E>(attempt: impl FnMut() -> Result<T, E>) -> Result<T, E> {
    retry_for(CREATION_RETRY_FOR, CREATION_RETRY_PAUSE, attempt)
}

fn retry_for<T, E>(
    limit: Duration,
    pause: Duration,
    mut attempt: impl FnMut() -> Result<T, E>,
) -> Result<T, E> {
    let deadline = Instant::now() + limit;
    loop {
        match attempt() {
            Ok(v) => return Ok(v),
            Err(e) if Instant::now() >= deadline => return Err(e),
            Err(_) => std::thread::sleep(pause),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_transient_failure_is_retried_until_it_succeeds() {
        let mut calls = 0;
        let r: Result<u32, &str> = retry_for(Duration::from_secs(5), Duration::ZERO, || {
            calls += 1;
            if calls < 4 {
                Err("lost the race")
            } else {
                Ok(7)
            }
        });
        assert_eq!(r, Ok(7));
        assert_eq!(calls, 4);
    }

    #[test]
    fn a_permanent_failure_is_returned_after_the_limit() {
        let start = Instant::now();
        let mut calls = 0;
        let r: Result<(), &str> =
            retry_for(Duration::from_millis(50), Duration::from_millis(5), || {
                calls += 1;
                Err("incompatible")
            });
        assert_eq!(r, Err("incompatible"));
        assert!(calls >= 2, "{calls}");
        assert!(start.elapsed() >= Duration::from_millis(50));
    }
}
