//! The solver thread: runs the machine's solve jobs (`thrusterd_core::machine::SolveJob`: an
//! estimate, a stop decision, a final model; 0.5-4 ms each) off the control thread, so the
//! sample that ends a pulse is answered as fast as any other.
//!
//! Two bounded queues: jobs in (`try_send`, the loop never waits to hand one over), results
//! out (the loop takes them with `try_recv`, or in lockstep waits for a due one with a
//! timeout). The thread runs at a lower scheduling priority than the control thread: on a
//! small computer they share a core, and the control thread's sample must win.
//!
//! Every allocation is freed on the thread that made it. glibc frees a block into the arena it
//! came from, under that arena's lock, and a normal-priority thread preempted inside malloc
//! holds its lock for as long as it is preempted: `perf sched` caught the FIFO control thread
//! asleep 44.6 ms on the solver's arena lock, freeing a result (docs/performance.md). So the
//! spent job comes back with its result and is dropped on the control thread, and the result
//! is copied there (a few tens of kB) and the worker's own copy sent back to be dropped on the
//! worker. Neither thread ever touches the other's arena.
//!
//! A panic in a job ends the thread; the loop learns it from the closed result queue, faults
//! the machine (neutral) with the panic's message, and starts a fresh thread for what comes
//! next.

use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender, TryRecvError, TrySendError};
use std::thread::JoinHandle;
use std::time::Duration;

use thrusterd_core::machine::{SolveJob, SolveResult, MAX_OUTSTANDING};

/// Jobs and results in flight at most. The machine keeps at most [`MAX_OUTSTANDING`] jobs
/// outstanding (every owner, estimation and refinement, at its limit), but a job it cancelled
/// (a run that ended, a refinement reset by a model swap) stays queued here until the thread
/// reaches it; four times that is room for a starved thread, and a full queue still means
/// one that stopped taking work. (It was 8, one owner's limit: with three busy loops on the
/// 2-core VM the daemon faulted with "the solver thread has 8 jobs queued" while the thread
/// was only slow.) Allocated once, at start.
const QUEUE: usize = 4 * MAX_OUTSTANDING;

/// Niceness of the solver and loading threads (0 is the control thread's): their work, when
/// it shares a core with the control thread, runs in the control thread's idle time.
const NICE: i32 = 10;

/// The solver is gone or cannot take work; the text says why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SolverLost(pub String);

impl std::fmt::Display for SolverLost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// What runs a job (the real one is `SolveJob::compute`; tests put in one that panics).
pub type Runner = fn(&SolveJob) -> SolveResult;

/// What the control thread sends the worker.
enum ToWorker {
    Job(SolveJob),
    /// The worker's own copy of a result, applied on the control thread from a copy made
    /// there: dropped on the worker, where it was allocated (box and all).
    Free(Box<SolveResult>),
}

/// What the worker sends back: the result and the spent job (made on the control thread,
/// dropped there).
struct Done {
    /// Boxed on the worker, so that what goes back to it is the worker's own allocation.
    result: Box<SolveResult>,
    job: SolveJob,
}

pub struct SolverThread {
    to_worker: Option<SyncSender<ToWorker>>,
    results: Receiver<Done>,
    /// Jobs handed over whose result has not been taken: what the "queued" limit counts
    /// (the channel also carries results going back to be freed).
    queued: usize,
    handle: Option<JoinHandle<()>>,
    runner: Runner,
}

impl SolverThread {
    /// The solver thread, running each job with `SolveJob::compute`.
    pub fn spawn() -> std::io::Result<Self> {
        Self::spawn_with(SolveJob::compute)
    }

    /// The solver thread, running each job with `runner`.
    pub fn spawn_with(runner: Runner) -> std::io::Result<Self> {
        // Room for QUEUE jobs and as many results on their way back to be freed.
        let (to_worker, rx) = mpsc::sync_channel::<ToWorker>(2 * QUEUE);
        let (result_tx, results) = mpsc::sync_channel::<Done>(QUEUE);
        let handle = std::thread::Builder::new()
            .name("thrusterd-solve".into())
            .spawn(move || {
                lower_priority();
                // Ends when the loop drops its sender (shutdown) or stops reading results.
                for msg in rx {
                    match msg {
                        ToWorker::Job(job) => {
                            let result = Box::new(runner(&job));
                            if result_tx.send(Done { result, job }).is_err() {
                                break;
                            }
                        }
                        ToWorker::Free(result) => drop(result),
                    }
                }
            })?;
        Ok(SolverThread {
            to_worker: Some(to_worker),
            results,
            queued: 0,
            handle: Some(handle),
            runner,
        })
    }

    /// Hands `job` over without waiting.
    pub fn submit(&mut self, job: SolveJob) -> Result<(), SolverLost> {
        let Some(to_worker) = self.to_worker.as_ref() else {
            return Err(SolverLost("the solver thread is stopped".into()));
        };
        if self.queued >= QUEUE {
            return Err(SolverLost(format!(
                "the solver thread has {QUEUE} jobs queued and takes no more"
            )));
        }
        match to_worker.try_send(ToWorker::Job(job)) {
            Ok(()) => {
                self.queued += 1;
                Ok(())
            }
            Err(TrySendError::Full(_)) => Err(SolverLost(format!(
                "the solver thread has {QUEUE} jobs and results queued and takes no more"
            ))),
            Err(TrySendError::Disconnected(_)) => Err(self.lost()),
        }
    }

    /// A result, if one is back (never waits).
    pub fn try_result(&mut self) -> Result<Option<SolveResult>, SolverLost> {
        match self.results.try_recv() {
            Ok(done) => Ok(Some(self.take(done))),
            Err(TryRecvError::Empty) => Ok(None),
            Err(TryRecvError::Disconnected) => Err(self.lost()),
        }
    }

    /// A result, waiting up to `timeout` for one (None: none came).
    pub fn wait_result(&mut self, timeout: Duration) -> Result<Option<SolveResult>, SolverLost> {
        match self.results.recv_timeout(timeout) {
            Ok(done) => Ok(Some(self.take(done))),
            Err(RecvTimeoutError::Timeout) => Ok(None),
            Err(RecvTimeoutError::Disconnected) => Err(self.lost()),
        }
    }

    /// The control thread's copy of a result; the worker's copy goes back to be freed there,
    /// the spent job is freed here, where it was made.
    fn take(&mut self, done: Done) -> SolveResult {
        self.queued = self.queued.saturating_sub(1);
        let Done { result, job } = done;
        drop(job);
        let mine = SolveResult::clone(&result);
        // Never waits: with the queue full (it holds as many frees as jobs, so only when the
        // worker is stuck) or the worker gone, the copy is freed here.
        if let Some(tx) = self.to_worker.as_ref() {
            let _ = tx.try_send(ToWorker::Free(result));
        }
        mine
    }

    /// A fresh thread in place of a dead one (jobs of the old one are gone with it).
    pub fn restart(&mut self) -> std::io::Result<()> {
        self.stop();
        *self = Self::spawn_with(self.runner)?;
        Ok(())
    }

    /// Why the thread is gone: its panic message when it panicked.
    fn lost(&mut self) -> SolverLost {
        let why = match self.handle.take().map(JoinHandle::join) {
            Some(Err(panic)) => {
                let msg = panic
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "no message".into());
                format!("the solver thread panicked: {msg}")
            }
            _ => "the solver thread ended".into(),
        };
        SolverLost(why)
    }

    /// Lets the thread end: no more jobs; it finishes the one under way and ends when it
    /// finds the job queue closed or its results unread (the receiver replaced or dropped).
    /// Never waits for it: a job that does not return (the reason a lockstep wait gave up)
    /// must not hold the control thread too; such a thread is left to itself.
    fn stop(&mut self) {
        self.to_worker = None;
        if let Some(h) = self.handle.take() {
            if h.is_finished() {
                let _ = h.join();
            }
        }
    }
}

impl Drop for SolverThread {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Lowers the calling thread's scheduling priority to [`NICE`]. Best effort: without it the
/// work still runs, it only competes with the control thread on equal terms.
pub fn lower_priority() {
    // SAFETY: gettid and setpriority only read their integer arguments; on Linux
    // PRIO_PROCESS with a thread id applies to that thread alone.
    let rc = unsafe {
        let tid = libc::gettid();
        libc::setpriority(libc::PRIO_PROCESS, tid as libc::id_t, NICE)
    };
    if rc != 0 {
        tracing::debug!(
            "solver thread priority unchanged: {}",
            std::io::Error::last_os_error()
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use thrusterd_core::machine::{ImuInput, Machine, MachineSetup, Request, SolverMode};

    /// The first job of a real estimation: a machine for four thrusters at rest (a noisy
    /// gyro), asked to estimate, up to the end of its first pulse.
    fn job() -> SolveJob {
        let mut m = Machine::new(MachineSetup {
            thrusters: 4,
            ..MachineSetup::default()
        });
        m.set_solver_mode(SolverMode::External);
        let mut noise = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || {
            noise ^= noise << 13;
            noise ^= noise >> 7;
            noise ^= noise << 17;
            (noise >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for k in 1..=2_000u64 {
            let s = ImuInput {
                seq: k,
                t_ns: k * 5_000_000,
                gyro: [0.01 * next(), 0.01 * next(), 0.01 * next()],
                accel: [0.05 * next(), 0.05 * next(), -9.80665 + 0.05 * next()],
                mag: None,
                depth: Some(2.0 + 0.001 * next()),
            };
            m.on_imu(&s);
            if k == 1 {
                m.on_request(Request::Estimate).unwrap();
            }
            if let Some(job) = m.take_job() {
                return job;
            }
        }
        panic!("no job after 10 s of estimation");
    }

    fn panicking(_: &SolveJob) -> SolveResult {
        panic!("singular matrix in a test job");
    }

    #[test]
    fn a_panicking_job_reports_the_thread_lost_with_its_message_and_a_restart_works() {
        let job = job();
        let mut solver = SolverThread::spawn_with(panicking).unwrap();
        solver.submit(job.clone()).unwrap();
        let lost = solver
            .wait_result(Duration::from_secs(10))
            .expect_err("the thread died");
        assert!(
            lost.0.contains("panicked: singular matrix in a test job"),
            "{lost}"
        );
        assert!(solver.submit(job.clone()).is_err(), "no thread takes work");
        solver.runner = SolveJob::compute;
        solver.restart().unwrap();
        solver.submit(job.clone()).unwrap();
        let r = solver
            .wait_result(Duration::from_secs(10))
            .unwrap()
            .expect("a result");
        assert_eq!(r.id(), job.id());
    }

    #[test]
    fn results_equal_the_inline_run_of_the_same_job() {
        let job = job();
        let inline = job.clone().run();
        let mut solver = SolverThread::spawn().unwrap();
        solver.submit(job).unwrap();
        let r = solver
            .wait_result(Duration::from_secs(10))
            .unwrap()
            .expect("a result");
        assert_eq!(
            r.estimate().effectiveness,
            inline.estimate().effectiveness,
            "bit for bit"
        );
    }
}
