//! The machine's solves on the solver thread: handed over after a sample's answer, results
//! collected without waiting (in lockstep waited for, bounded), a lost solver faulted.

// The daemon's fields, ports and imports are the parent's: these are its methods, by job.
use super::*;

impl Daemon {
    /// Hands the machine the solve results that are back (never waits).
    pub(super) fn collect_solves(&mut self) {
        loop {
            match self.solver.try_result() {
                Ok(Some(r)) => self.deliver(r),
                Ok(None) => return,
                Err(lost) => return self.solver_lost(&lost.0),
            }
        }
    }

    /// Lockstep: the results due by `t_ns` are waited for, each up to
    /// `runtime.lockstep_wait_ms`, so the outcome is the inline one (see `runtime.lockstep`).
    pub(super) fn wait_for_due_solves(&mut self, t_ns: u64) {
        // The configuration's own range (checked at load); clamped again so no value can
        // make the wait unbounded or zero.
        let wait = Duration::from_millis(self.cfg.runtime.lockstep_wait_ms.clamp(1, 600_000));
        while let Some(id) = self.machine.awaiting_result(t_ns) {
            match self.solver.wait_result(wait) {
                Ok(Some(r)) => self.deliver(r),
                Ok(None) => {
                    let why = format!(
                        "solve {id} not back after {} ms in lockstep (runtime.lockstep_wait_ms)",
                        wait.as_millis()
                    );
                    return self.solver_lost(&why);
                }
                Err(lost) => return self.solver_lost(&lost.0),
            }
        }
    }

    /// Hands a solve's result to the machine and journals when it did: a result back after
    /// its due sample is applied at the next one, which a replay can only reproduce from the
    /// journal.
    pub(super) fn deliver(&mut self, r: SolveResult) {
        let id = r.id();
        self.machine.deliver(r);
        self.journal(|j| {
            j.record(InputKind::SolveDelivered, false, |m| {
                m.code = u32::try_from(id).unwrap_or(u32::MAX)
            })
        });
    }

    /// Gives the solver thread the jobs the last sample made; logs late results.
    pub(super) fn dispatch_solves(&mut self) {
        while let Some(job) = self.machine.take_job() {
            if let Err(lost) = self.solver.submit(job) {
                return self.solver_lost(&lost.0);
            }
        }
        let late = self.machine.late_solves();
        if late > self.late_logged {
            // Logged sparingly: on a machine that cannot keep up, every solve is late.
            if self.late_logged < 10 || late.ilog2() != self.late_logged.ilog2() {
                warn!(
                    late,
                    "a solve's result was not back by its due sample (machine.solve_budget_s): applied when it comes"
                );
            }
            self.late_logged = late;
        }
    }

    /// The solver thread died or did not answer: what waited for it faults (neutral), and a
    /// fresh thread takes what comes next.
    pub(super) fn solver_lost(&mut self, why: &str) {
        error!("{why}; thrusters neutral");
        self.machine.on_solver_lost(why);
        if let Err(e) = self.solver.restart() {
            error!("the solver thread could not be restarted: {e}");
        }
    }
}
