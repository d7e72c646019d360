//! Real-time scheduling for the one thread that answers sensor samples.
//!
//! Under the default scheduler (SCHED_OTHER) a thread that must answer within a period shares
//! its core with whatever else runs: a build, a logger, the bridge. Measured on the 2-core VM
//! with two builds running, the daemon's IMU -> thrust latency at 1 kHz reached p99 10-16 ms
//! and a max of 0.5 s (docs/performance.md, "Real-time scheduling"). A SCHED_FIFO thread runs
//! as soon as it is woken, ahead of every normal thread.
//!
//! Only the calling thread is raised, and with `SCHED_RESET_ON_FORK`: a thread it starts later
//! (a solver, a loader) comes back to normal scheduling, so a long solve can never hold the
//! core the control thread needs. The kernel keeps 5 % of each second for normal threads
//! (`sched_rt_runtime_us`), so even a runaway FIFO thread cannot lock the machine; a thread
//! that blocks on its events between samples uses a few percent of a core.

/// Why the thread could not be given real-time priority.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RealtimeError {
    #[error("priority {0} is outside SCHED_FIFO's 1-99")]
    OutOfRange(u8),
    #[error("SCHED_FIFO priority {priority} refused: {why} (needs root, CAP_SYS_NICE or an RLIMIT_RTPRIO of at least {priority}: systemd LimitRTPRIO={priority}, or `ulimit -r {priority}`)")]
    Refused { priority: u8, why: String },
}

/// The calling thread's scheduling: policy and priority, as the kernel reports them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Scheduling {
    /// SCHED_OTHER, SCHED_FIFO, ... (without the reset-on-fork flag).
    pub policy: i32,
    pub priority: i32,
    /// Threads this one starts come back to normal scheduling.
    pub reset_on_fork: bool,
}

impl Scheduling {
    pub fn is_fifo(&self) -> bool {
        self.policy == libc::SCHED_FIFO
    }
}

/// Raises the calling thread (only it) to SCHED_FIFO at `priority` (1-99), with
/// reset-on-fork so threads it starts later run normally.
pub fn make_this_thread_fifo(priority: u8) -> Result<(), RealtimeError> {
    if !(1..=99).contains(&priority) {
        return Err(RealtimeError::OutOfRange(priority));
    }
    let param = libc::sched_param {
        sched_priority: i32::from(priority),
    };
    // pid 0 is the calling thread (Linux schedules threads, not processes).
    // SAFETY: `param` is a valid sched_param that outlives the call.
    let rc = unsafe {
        libc::sched_setscheduler(0, libc::SCHED_FIFO | libc::SCHED_RESET_ON_FORK, &param)
    };
    if rc != 0 {
        return Err(RealtimeError::Refused {
            priority,
            why: std::io::Error::last_os_error().to_string(),
        });
    }
    Ok(())
}

/// The calling thread's scheduling.
pub fn this_thread() -> Scheduling {
    // SAFETY: plain queries of the calling thread; `param` is a valid out-pointer.
    let raw = unsafe { libc::sched_getscheduler(0) };
    let mut param = libc::sched_param { sched_priority: 0 };
    unsafe { libc::sched_getparam(0, &mut param) };
    Scheduling {
        policy: raw & !libc::SCHED_RESET_ON_FORK,
        priority: param.sched_priority,
        reset_on_fork: raw & libc::SCHED_RESET_ON_FORK != 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn priorities_outside_fifos_range_are_refused_before_the_kernel_sees_them() {
        assert_eq!(make_this_thread_fifo(0), Err(RealtimeError::OutOfRange(0)));
        assert_eq!(
            make_this_thread_fifo(100),
            Err(RealtimeError::OutOfRange(100))
        );
    }

    /// Root (CI runs as root) gets FIFO for the calling thread only, and a thread it starts
    /// afterwards is normal again; an unprivileged user gets a refusal that says what to grant.
    #[test]
    fn only_the_calling_thread_is_raised_and_its_children_run_normally() {
        std::thread::spawn(|| {
            let before = this_thread();
            assert_eq!(before.policy, libc::SCHED_OTHER);
            // SAFETY: geteuid has no preconditions.
            let root = unsafe { libc::geteuid() } == 0;
            match make_this_thread_fifo(10) {
                Ok(()) => {
                    let now = this_thread();
                    assert!(now.is_fifo(), "{now:?}");
                    assert_eq!(now.priority, 10);
                    assert!(now.reset_on_fork);
                    let child = std::thread::spawn(this_thread).join().unwrap();
                    assert_eq!(child.policy, libc::SCHED_OTHER, "{child:?}");
                    assert_eq!(child.priority, 0);
                }
                Err(e) => {
                    assert!(!root, "root was refused: {e}");
                    assert!(e.to_string().contains("LimitRTPRIO=10"), "{e}");
                }
            }
        })
        .join()
        .unwrap();
        // The test's own thread was never touched.
        assert_eq!(this_thread().policy, libc::SCHED_OTHER);
    }
}
