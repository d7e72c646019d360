//! The driver's clock: CLOCK_MONOTONIC in nanoseconds.
//!
//! Not `Instant`: its value is opaque, while CLOCK_MONOTONIC is shared by every process on
//! the machine, so a test (or a log reader) can compare a sample's `t_ns` with its own
//! clock, and latency between processes is measured on one time base.

/// Nanoseconds of CLOCK_MONOTONIC (time since boot, not counting suspend).
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux,
    // so the call cannot fail (checked in debug builds).
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    debug_assert_eq!(rc, 0);
    (ts.tv_sec as u64)
        .saturating_mul(1_000_000_000)
        .saturating_add(ts.tv_nsec as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn advances_with_real_time() {
        let a = monotonic_ns();
        std::thread::sleep(std::time::Duration::from_millis(5));
        let b = monotonic_ns();
        assert!(b - a >= 5_000_000, "{a} -> {b}");
        assert!(b - a < 1_000_000_000);
    }
}
